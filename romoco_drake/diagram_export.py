"""``romoco diagram``: the wired Drake diagram of a scenario, as Graphviz source or a picture.

The picture is Drake's own (``System.GetGraphvizString``): every system with its class and name,
every port and connection. ``max_depth`` 1 shows the top level (station, estimator, state
machine, planner, embedding, controller, logs); deeper levels open the nested diagrams (the
station's plant, sensors and scene graph). Rendering needs Graphviz's ``dot`` program (Debian's
``graphviz`` package, which ``.ci/run`` installs); ``.dot`` output does not.
"""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

from romoco_drake.errors import RomocoError
from romoco_drake.scenario import Scenario
from romoco_drake.wiring import build_diagram

FORMATS = ("dot", "svg", "png", "pdf")


def diagram_source(scenario: Scenario, max_depth: int = 1) -> str:
    """The Graphviz source of the scenario's closed loop, nested diagrams opened to ``max_depth``."""
    return build_diagram(scenario).diagram.GetGraphvizString(max_depth=max_depth)


def write_diagram(scenario: Scenario, out: Path, max_depth: int = 1) -> Path:
    """Writes the diagram to ``out``, in the format its suffix names (one of FORMATS)."""
    fmt = out.suffix.lstrip(".").lower()
    if fmt not in FORMATS:
        raise RomocoError(f"{out}: the diagram is written as one of .{', .'.join(FORMATS)}")
    if max_depth < 1:
        raise RomocoError(f"--depth must be at least 1, not {max_depth}")
    if fmt != "dot" and shutil.which("dot") is None:
        raise RomocoError(f"rendering .{fmt} needs Graphviz's dot (Debian: apt install graphviz); "
                          f"--out {out.with_suffix('.dot').name} writes the source instead")
    source = diagram_source(scenario, max_depth)
    out.parent.mkdir(parents=True, exist_ok=True)
    if fmt == "dot":
        out.write_text(source)
        return out
    done = subprocess.run(["dot", f"-T{fmt}", "-o", str(out)], input=source.encode(), capture_output=True)
    if done.returncode != 0:
        first = (done.stderr.decode(errors="replace").strip().splitlines() or ["no message"])[0]
        raise RomocoError(f"dot could not render {out}: {first}")
    return out
