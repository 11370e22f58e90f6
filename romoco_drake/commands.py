"""What the ``romoco`` subcommands share (each subcommand is registered beside what it runs:
``register`` in :mod:`~romoco_drake.runner` and each :mod:`~romoco_drake.bench` module)."""

from __future__ import annotations

import json
import sys
from pathlib import Path

from romoco_drake.errors import RomocoError


def names(text: str | None, default, what: str, known) -> list[str]:
    """A comma-separated list of names (``default`` if None), each one of ``known``."""
    chosen = list(default) if text is None else [n.strip() for n in text.split(",") if n.strip()]
    for n in chosen:
        if n not in known:
            raise RomocoError(f"unknown {what} '{n}' (known: {', '.join(known)})")
    return chosen


def numbers(text: str, flag: str) -> tuple[float, ...]:
    """A comma-separated list of numbers, or one line saying what is wrong."""
    try:
        values = tuple(float(v) for v in text.split(","))
    except ValueError:
        raise RomocoError(f"{flag}: '{text}' is not a comma-separated list of numbers") from None
    return values


def count(value: int, flag: str, lo: int = 1, hi: int = 10_000_000) -> int:
    """An integer option within [``lo``, ``hi``], or one line saying what is wrong."""
    if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= hi:
        raise RomocoError(f"{flag} must be an integer in [{lo}, {hi}], got {value}")
    return value


def output_dir(path: Path | None, flag: str) -> Path | None:
    """``path`` made a directory before the command's work starts (None passes through), or one
    line saying why it cannot be: a command that would fail writing its results fails at once."""
    if path is not None:
        try:
            path.mkdir(parents=True, exist_ok=True)
        except OSError as e:
            raise RomocoError(f"{flag} {path}: cannot make the directory ({e.strerror})") from None
    return path


def output_file(path: Path | None, flag: str) -> Path | None:
    """``path``'s directory made before the command's work starts (None passes through), or one
    line saying why a file cannot be written there."""
    if path is not None:
        if path.is_dir():
            raise RomocoError(f"{flag} {path}: is a directory, not a file")
        output_dir(path.parent, flag)
    return path


def print_rows(as_json: bool, rows: list[dict], header: str, line) -> int:
    """A bench's rows: one JSON list, or ``header`` and ``line(row)`` for each row."""
    if as_json:
        print(json.dumps(rows))
        return 0
    print(header)
    for r in rows:
        print(line(r))
    return 0


def live_meshcat(wanted: bool):
    """A Meshcat server (its URL printed) if ``wanted``, else None."""
    if not wanted:
        return None
    from pydrake.geometry import Meshcat

    meshcat = Meshcat()
    print(f"Meshcat: {meshcat.web_url()}", file=sys.stderr, flush=True)
    return meshcat


def fall_text(summary: dict) -> str:
    if not summary["fell"]:
        return "stayed up"
    return f"FELL at {summary['fall_time_s']:.2f} s ({summary['fall_reason']})"
