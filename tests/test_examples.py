"""Every example script runs."""

import runpy
from pathlib import Path

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def test_stand_in_python_example():
    module = runpy.run_path(str(EXAMPLES / "stand_in_python.py"))
    summary = module["main"]("h1")
    assert summary["fell"] is False and summary["base_height_drift_m"] < 0.02
