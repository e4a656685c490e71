"""The test suite's own rules: shared helpers live in non-test modules (`dqmath`, `reference`),
so no test module is imported by another (importing one runs its module-level setup and
collects its tests twice under another name)."""

from __future__ import annotations

import ast
from pathlib import Path

HERE = Path(__file__).resolve().parent


def imported_modules(path: Path) -> set[str]:
    tree = ast.parse(path.read_text(), filename=str(path))
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names |= {alias.name.split(".")[0] for alias in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module.split(".")[0])
    return names


def test_no_test_module_imports_another():
    tests = {p.stem for p in HERE.glob("test_*.py")}
    offenders = {p.name: sorted(imported_modules(p) & tests) for p in HERE.glob("*.py")}
    assert {k: v for k, v in offenders.items() if v} == {}
