"""Runs every ``bash`` block of the README's "User's guide" section, as a reader would.

    python tests/docs_check.py [README.md]

Each block runs with ``bash -euo pipefail`` in one scratch folder (shared across blocks, so a
file one block writes is there for the next) that links the repository's ``examples/`` and
``diagrams/``; ``romoco`` is the one on PATH. A block that exits non-zero or outruns
``BLOCK_TIMEOUT_S`` fails the check. `.ci/run` runs this after the test suite.
"""

from __future__ import annotations

import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
SECTION = "## User's guide"
BLOCK_TIMEOUT_S = 900


def guide_blocks(readme: Path) -> list[str]:
    """The ``bash`` blocks between the guide's heading and the next top-level section."""
    text = readme.read_text()
    start = text.index(SECTION)
    end = text.find("\n## ", start + len(SECTION))
    section = text[start:end if end >= 0 else None]
    return re.findall(r"```bash\n(.*?)```", section, flags=re.S)


def main(argv: list[str]) -> int:
    readme = Path(argv[0]) if argv else REPO / "README.md"
    blocks = guide_blocks(readme)
    failed = 0
    with tempfile.TemporaryDirectory(prefix="romoco-docs-") as tmp:
        for name in ("examples", "diagrams"):
            (Path(tmp) / name).symlink_to(REPO / name)
        for i, block in enumerate(blocks, 1):
            first = block.strip().splitlines()[0]
            t0 = time.monotonic()
            try:
                run = subprocess.run(["bash", "-euo", "pipefail", "-c", block], cwd=tmp, capture_output=True,
                                     text=True, timeout=BLOCK_TIMEOUT_S)
                ok, tail = run.returncode == 0, (run.stderr or run.stdout).strip().splitlines()[-15:]
            except subprocess.TimeoutExpired:
                ok, tail = False, [f"timed out after {BLOCK_TIMEOUT_S} s"]
            status = "ok" if ok else "FAILED"
            print(f"[{status}] block {i}/{len(blocks)} ({time.monotonic() - t0:.0f} s): {first}", flush=True)
            if not ok:
                failed += 1
                print("    " + "\n    ".join(tail))
    print(f"docs check: {len(blocks) - failed}/{len(blocks)} blocks ran")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
