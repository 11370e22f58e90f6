"""Size limits on the hand-written code: modules ≤ 450 lines, functions ≤ 60 lines (issue 31)."""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parent.parent / "romoco_drake"
GENERATED = PACKAGE / "interfaces" / "lcmtypes"
MAX_MODULE_LINES = 450
MAX_FUNCTION_LINES = 60

# "path" (a module) or "path::qualname" (a function, methods and nested functions included),
# paths relative to romoco_drake/, each with the reason it may stay over its limit.
EXCEPTIONS: dict[str, str] = {}


def _modules() -> list[Path]:
    return sorted(p for p in PACKAGE.rglob("*.py") if GENERATED not in p.parents)


def _functions(tree: ast.AST, prefix: str = ""):
    """(qualname, lines) of every function in ``tree``, nested ones and methods included."""
    for node in ast.iter_child_nodes(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            name = prefix + node.name
            yield name, node.end_lineno - node.lineno + 1
            yield from _functions(node, name + ".<locals>.")
        elif isinstance(node, ast.ClassDef):
            yield from _functions(node, prefix + node.name + ".")
        else:
            yield from _functions(node, prefix)


def _offenders() -> dict[str, str]:
    """Every module and function over its limit, with its size."""
    found = {}
    for path in _modules():
        rel = path.relative_to(PACKAGE).as_posix()
        text = path.read_text()
        lines = len(text.splitlines())
        if lines > MAX_MODULE_LINES:
            found[rel] = f"module of {lines} lines"
        for name, length in _functions(ast.parse(text, filename=str(path))):
            if length > MAX_FUNCTION_LINES:
                found[f"{rel}::{name}"] = f"function of {length} lines"
    return found


def test_modules_and_functions_are_within_their_limits():
    over = {key: size for key, size in _offenders().items() if key not in EXCEPTIONS}
    assert not over, (f"over {MAX_MODULE_LINES} lines a module or {MAX_FUNCTION_LINES} a function "
                      f"(split it, or list it in EXCEPTIONS with a reason): {over}")


def test_every_exception_still_applies_and_has_a_reason():
    stale = sorted(set(EXCEPTIONS) - set(_offenders()))
    assert not stale, f"EXCEPTIONS entries that are within their limits now (remove them): {stale}"
    assert all(reason.strip() for reason in EXCEPTIONS.values())
