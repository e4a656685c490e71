"""The Blender add-on's structure, read from its source (no Blender needed):

- dependencies point one way, through the layers `addon/dq_skin/__init__.py` names, with no
  import cycle (function-level imports included);
- no module uses another module's private names;
- no module is longer than about 450 lines;
- no module keeps mutable state at module level but `session.py` (the one owner);
- `model` imports nothing of Blender's, so these tests can run its decisions.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ADDON = Path(__file__).resolve().parents[2] / "addon" / "dq_skin"
# Each module's layer, by its first path component (a package, or a top-level module).
LAYERS = {
    "dqskin": 0,
    "model": 0,
    "progress": 0,
    "blender": 1,
    "routes": 2,
    "engine": 3,
    "session": 4,
    "scheduling": 5,
    "exports": 5,
    "ops": 6,
    "ui": 6,
    "tools": 6,
    "cli": 6,
    "__init__": 7,
}
MAX_LINES = 450
MUTABLE_CALLS = {"dict", "list", "set", "defaultdict", "OrderedDict", "deque", "Lock", "RLock", "Event", "Thread"}


def modules() -> dict[str, Path]:
    """Dotted name within the add-on (`engine.pipeline`, `__init__`) -> file."""
    out = {}
    for path in sorted(ADDON.rglob("*.py")):
        parts = path.relative_to(ADDON).with_suffix("").parts
        name = ".".join(parts[:-1]) if parts[-1] == "__init__" and len(parts) > 1 else ".".join(parts)
        out[name] = path
    return out


def package_of(name: str, path: Path) -> list[str]:
    parts = name.split(".") if name != "__init__" else []
    return parts if path.name == "__init__.py" else parts[:-1]


def layer(name: str) -> int:
    return LAYERS[name.split(".")[0]]


def imports_of(name: str, path: Path):
    """(line, imported module, names taken from it) of every relative import, at any depth."""
    tree = ast.parse(path.read_text())
    found = []
    names = set(modules())
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.level:
            base = package_of(name, path)
            base = base[: len(base) - (node.level - 1)] if node.level > 1 else base
            target = ".".join([*base, *(node.module.split(".") if node.module else [])])
            for alias in node.names:
                sub = f"{target}.{alias.name}" if target else alias.name
                if sub in names:  # `from . import x`: the module x
                    found.append((node.lineno, sub, ()))
                else:
                    found.append((node.lineno, target or "__init__", (alias.name,)))
    return found


MODULES = modules()


def test_every_module_has_a_layer():
    assert {n.split(".")[0] for n in MODULES} <= set(LAYERS), set(n.split(".")[0] for n in MODULES) - set(LAYERS)


@pytest.mark.parametrize("name", sorted(MODULES))
def test_dependencies_point_down(name):
    path = MODULES[name]
    for line, target, _names in imports_of(name, path):
        assert target in MODULES, f"{path.name}:{line} imports {target}, which is not a module of the add-on"
        assert layer(target) <= layer(name), f"{name} (layer {layer(name)}) imports {target} (layer {layer(target)}) at line {line}"


def test_no_import_cycles():
    graph = {n: {t for _l, t, _ in imports_of(n, p) if t != n} for n, p in MODULES.items()}
    state: dict[str, int] = {}

    def visit(n, trail):
        state[n] = 1
        for m in sorted(graph[n]):
            if state.get(m) == 1:
                cycle = trail[trail.index(m) :] + [m] if m in trail else [n, m]
                raise AssertionError("import cycle: " + " -> ".join(cycle))
            if m not in state:
                visit(m, trail + [m])
        state[n] = 2

    for n in sorted(graph):
        if n not in state:
            visit(n, [n])


@pytest.mark.parametrize("name", sorted(MODULES))
def test_no_private_names_of_other_modules(name):
    path = MODULES[name]
    tree = ast.parse(path.read_text())
    ours = {}
    for line, target, taken in imports_of(name, path):
        for t in taken:
            assert not t.startswith("_"), f"{name}:{line} takes the private name {t} from {target}"
        if not taken:
            ours[target.split(".")[-1]] = target
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id in ours:
            assert not (node.attr.startswith("_") and not node.attr.startswith("__")), (
                f"{name}:{node.lineno} uses {ours[node.value.id]}.{node.attr}, a private name"
            )


@pytest.mark.parametrize("name", sorted(MODULES))
def test_modules_stay_small(name):
    lines = len(MODULES[name].read_text().splitlines())
    assert lines <= MAX_LINES, f"{name} has {lines} lines (at most about {MAX_LINES}: one concern per file)"


@pytest.mark.parametrize("name", sorted(n for n in MODULES if n != "session"))
def test_no_module_level_mutable_state(name):
    tree = ast.parse(MODULES[name].read_text())
    for node in ast.walk(tree):
        assert not isinstance(node, ast.Global), f"{name}:{node.lineno}: `global` (state belongs to the session)"
    for node in tree.body:
        if not isinstance(node, (ast.Assign, ast.AnnAssign)) or node.value is None:
            continue
        v = node.value
        mutable = isinstance(v, (ast.List, ast.Dict, ast.Set, ast.ListComp, ast.DictComp, ast.SetComp))
        if isinstance(v, ast.Call):
            f = v.func
            called = f.id if isinstance(f, ast.Name) else f.attr if isinstance(f, ast.Attribute) else ""
            mutable |= called in MUTABLE_CALLS
        assert not mutable, f"{name}:{node.lineno}: mutable state at module level (it belongs to the session)"


def test_model_does_not_import_blender():
    for name, path in MODULES.items():
        if name.split(".")[0] != "model":
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                assert not any(a.name.split(".")[0] in ("bpy", "mathutils", "bmesh") for a in node.names), name
            if isinstance(node, ast.ImportFrom) and not node.level:
                assert node.module.split(".")[0] not in ("bpy", "mathutils", "bmesh"), name
