"""`romoco diagram`: a scenario's wired Drake diagram as Graphviz source or a picture."""

import shutil

import pytest

from romoco_drake.cli import main


def test_diagram_source_shows_every_system_of_the_loop_and_their_connections(tmp_path, capsys):
    out = tmp_path / "g1.dot"
    assert main(["diagram", "g1_walk", "--out", str(out)]) == 0
    assert str(out) in capsys.readouterr().out
    text = out.read_text()
    for name in ("station", "estimator", "state_machine", "planner", "embedding", "controller", "heading",
                 "command_limiter", "kinematics"):
        assert f"name={name}" in text, name
    assert "WholeBodyController" in text and "->" in text
    deeper = tmp_path / "g1_deep.dot"
    assert main(["diagram", "g1_walk", "--out", str(deeper), "--depth", "2"]) == 0
    assert "name=plant" in deeper.read_text() and "name=plant" not in text  # the station opened


@pytest.mark.skipif(shutil.which("dot") is None, reason="no Graphviz dot (.ci/run installs it)")
def test_diagram_renders_svg(tmp_path):
    out = tmp_path / "g1.svg"
    assert main(["diagram", "g1_walk", "--out", str(out)]) == 0
    assert out.read_text().lstrip().startswith(("<?xml", "<svg")) and "controller" in out.read_text()


@pytest.mark.parametrize(("args", "says"), [
    (["g1_walk", "--out", "x.txt"], "written as one of"),
    (["g1_walk", "--out", "x.dot", "--depth", "0"], "--depth must be at least 1"),
    (["nope", "--out", "x.dot"], "unknown scenario"),
])
def test_diagram_bad_input_is_one_line_and_exit_2(tmp_path, capsys, args, says):
    args = [a if not a.startswith("x.") else str(tmp_path / a) for a in args]
    assert main(["diagram", *args]) == 2
    err = capsys.readouterr().err
    assert says in err and len(err.strip().splitlines()) == 1
