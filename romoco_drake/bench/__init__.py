"""Benchmarks behind ``romoco bench``: they print numbers; tests never assert wall-clock times."""
