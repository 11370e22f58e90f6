"""The README cannot rot: its commands parse, and the guide's picture shows today's diagram.

The guide's blocks are run end to end by ``tests/docs_check.py`` in `.ci/run`.
"""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import pytest
from docs_check import guide_blocks

from romoco_drake.cli import make_parser
from romoco_drake.scenario import load_scenario, scenario_names
from romoco_drake.wiring import build_diagram

REPO = Path(__file__).resolve().parents[1]
README = REPO / "README.md"


def _commands() -> list[str]:
    """Every ``romoco`` command line in the README's bash blocks, without env, comments or ``&``."""
    out = []
    for block in re.findall(r"```bash\n(.*?)```", README.read_text(), flags=re.S):
        for line in block.splitlines():
            words = shlex.split(line, comments=True)
            while words and re.fullmatch(r"[A-Z_]+=.*", words[0]):
                words = words[1:]
            if words and words[0] == "romoco":
                out.append(" ".join(shlex.quote(w) for w in words if w != "&"))
    return out


def _is_usage(words: list[str]) -> bool:
    """A usage line (``[--json]``, ``a|b``, ``SCENARIO``) rather than a command to run."""
    return any(re.search(r"[\[\]|]|\.\.\.", w) or re.fullmatch(r"[A-Z][A-Z_]+", w) for w in words)


COMMANDS = _commands()


def test_the_readme_has_commands_and_the_guide_has_blocks():
    assert len(COMMANDS) > 30
    blocks = guide_blocks(README)
    assert len(blocks) >= 6 and all("romoco" in b for b in blocks)


@pytest.mark.parametrize("command", COMMANDS)
def test_every_readme_command_parses(command):
    words = shlex.split(command)[1:]
    if _is_usage(words):
        pytest.skip("usage syntax")
    args = make_parser().parse_args(words)
    scenario = getattr(args, "scenario", None)
    if isinstance(scenario, str) and not scenario.endswith(".yaml"):
        assert scenario in scenario_names(), f"{command}: no scenario '{scenario}'"


def test_the_guide_picture_shows_every_system_and_port_of_g1_walk():
    svg = (REPO / "examples" / "g1_walk_diagram.svg").read_text()
    diagram = build_diagram(load_scenario("g1_walk")).diagram
    for system in diagram.GetSystems():
        if system.get_name().startswith("drake/"):
            continue
        assert f"name={system.get_name()}" in svg, system.get_name()
        ports = [system.get_input_port(i).get_name() for i in range(system.num_input_ports())]
        ports += [system.get_output_port(i).get_name() for i in range(system.num_output_ports())]
        for port in ports:
            assert f">{port}</text>" in svg, (system.get_name(), port)
