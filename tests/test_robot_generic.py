"""No robot-name special case in the control stack: a new robot is a YAML, not a code change."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

from romoco_drake.robots.model import robot_names

PACKAGE = Path(__file__).resolve().parents[1] / "romoco_drake"
# The layers that must work for any robot (robot-specific data, e.g. a trained inertia network,
# lives in robots/*.yaml, models/ and romoco_drake/inertia).
GENERIC = ("rom", "planners", "embedding", "control", "estimation", "interfaces", "robots")
FILES = sorted(p for layer in GENERIC for p in (PACKAGE / layer).rglob("*.py"))


def _docstrings(tree: ast.AST) -> set[int]:
    return {id(node.body[0].value) for node in ast.walk(tree)
            if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef))
            and node.body and isinstance(node.body[0], ast.Expr)
            and isinstance(node.body[0].value, ast.Constant)}


def _robot_names_in(source: str, names: set[str]) -> list[tuple[int, str]]:
    """(line, name) of each string literal in ``source`` that is a robot name (docstrings aside)."""
    tree = ast.parse(source)
    docs = _docstrings(tree)
    return [(node.lineno, node.value) for node in ast.walk(tree)
            if isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in docs
            and node.value.strip().lower() in names]


def test_the_check_finds_a_special_case():
    source = '''def gain(robot):
    """On G1 this is 2."""
    return 2.0 if robot.name == "g1" else 1.0
'''
    assert _robot_names_in(source, {"g1"}) == [(3, "g1")]


@pytest.mark.parametrize("path", FILES, ids=lambda p: str(p.relative_to(PACKAGE)))
def test_no_robot_name_in_code(path):
    names = set(robot_names())
    assert {"g1", "h1", "cassie", "icub", "talos"} <= names
    found = _robot_names_in(path.read_text(), names)
    assert not found, f"{path.name}: robot names in code (a special case?): {found}"
