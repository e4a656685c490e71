"""The documentation, held to what it promises (issue 34): the README and the wheel's own page stay
short, their Python examples run as written, every link leads somewhere, the API reference is
the one generated from the stubs, and the stubs match the compiled module. The Blender examples
and the command lines run in tests/blender/test_docs_examples.py."""

from __future__ import annotations

import ast
import email
import importlib.util
import inspect
import re
import subprocess
import sys
import zipfile
from pathlib import Path

import dqskin
import pytest

ROOT = Path(__file__).resolve().parents[2]
README = ROOT / "README.md"
WHEEL_README = ROOT / "python" / "README.md"
PAGES = [README, WHEEL_README, ROOT / "CHANGELOG.md", *sorted((ROOT / "docs").glob("*.md"))]
STUBS = ROOT / "python" / "dqskin" / "_dqskin.pyi"


# The generated half of the API reference shows signatures, not examples.
GENERATED = "<!-- Generated below"


def code_blocks(path: Path, language: str) -> list[str]:
    """The fenced code blocks of one language in a Markdown page (above its generated part), in order."""
    text = path.read_text().split(GENERATED)[0]
    return re.findall(rf"^```{language}\n(.*?)^```$", text, flags=re.S | re.M)


def numpy_examples() -> list[tuple[str, int, str]]:
    """(page, index, code) of every Python example that needs no Blender."""
    found = []
    for page in PAGES:
        for i, code in enumerate(code_blocks(page, "python")):
            if "bpy" not in code:
                found.append((page.relative_to(ROOT).as_posix(), i, code))
    return found


def run_python(code: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", code], cwd=cwd, capture_output=True, text=True, timeout=600)


def test_the_readme_is_at_most_15_kb_and_the_wheels_page_at_most_20_kb():
    assert len(README.read_bytes()) <= 15 * 1024, len(README.read_bytes())
    assert len(WHEEL_README.read_bytes()) <= 20 * 1024, len(WHEEL_README.read_bytes())


def test_the_readmes_first_python_example_runs_as_written(tmp_path):
    first = code_blocks(README, "python")[0]
    r = run_python(first, tmp_path)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip(), "the example prints what it computed"


@pytest.mark.parametrize(
    ("page", "index", "code"), numpy_examples(), ids=lambda v: str(v) if not isinstance(v, str) or "\n" not in v else ""
)
def test_every_numpy_example_runs_as_written(page, index, code, tmp_path):
    r = run_python(code, tmp_path)
    assert r.returncode == 0, f"{page}, Python example {index + 1}:\n{r.stderr}"


def github_anchor(heading: str) -> str:
    """The anchor GitHub gives a Markdown heading."""
    text = re.sub(r"[`*_]", "", heading.strip().lower())
    text = re.sub(r"[^\w\- ]", "", text)
    return text.replace(" ", "-")


def anchors(path: Path) -> set[str]:
    text = re.sub(r"^```.*?^```$", "", path.read_text(), flags=re.S | re.M)
    return {github_anchor(h) for h in re.findall(r"^#+ (.+)$", text, flags=re.M)}


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.relative_to(ROOT).as_posix())
def test_every_link_leads_somewhere(page):
    text = re.sub(r"^```.*?^```$", "", page.read_text(), flags=re.S | re.M)
    broken = []
    for target in re.findall(r"\]\(([^)\s]+)\)", text):
        if re.match(r"^[a-z]+://", target):
            continue
        file, _, anchor = target.partition("#")
        linked = (page.parent / file).resolve() if file else page
        if not linked.exists():
            broken.append(f"{target}: no such file")
        elif anchor and linked.suffix == ".md" and anchor not in anchors(linked):
            broken.append(f"{target}: no such heading")
    assert not broken, broken


def test_the_api_reference_is_the_one_generated_from_the_stubs():
    spec = importlib.util.spec_from_file_location("api_reference", ROOT / "docs" / "api_reference.py")
    api_reference = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(api_reference)
    assert api_reference.PAGE.read_text() == api_reference.page(), "docs/python-api.md is out of date: run python docs/api_reference.py"


def stub_tree() -> dict[str, ast.AST]:
    """Name -> its stub definition (overloads: the first), over the compiled module's stubs
    (`_dqskin.pyi`, and `memory.pyi` for the names `dqskin.memory` re-exports)."""
    defined = {}
    for node in [*ast.parse(STUBS.read_text()).body, *ast.parse(STUBS.with_name("memory.pyi").read_text()).body]:
        name = getattr(node, "name", None) or (node.target.id if isinstance(node, ast.AnnAssign) else None)
        if name is not None and name not in defined:
            defined[name] = node
    return defined


def parameters(signature: inspect.Signature) -> list[tuple[str, object]]:
    return [(p.name, p.kind) for p in signature.parameters.values() if p.name not in ("self", "cls")]


def stub_parameters(node: ast.FunctionDef) -> list[tuple[str, object]]:
    args = node.args
    out = [(a.arg, inspect.Parameter.POSITIONAL_ONLY) for a in args.posonlyargs]
    out += [(a.arg, inspect.Parameter.POSITIONAL_OR_KEYWORD) for a in args.args]
    out += [(a.arg, inspect.Parameter.KEYWORD_ONLY) for a in args.kwonlyargs]
    return [(n, k) for n, k in out if n not in ("self", "cls")]


def test_every_public_name_of_the_module_is_in_the_stubs_and_back():
    stubs = stub_tree()
    public = {n for n in dir(dqskin._dqskin) if not n.startswith("_")} | {"__version__"}
    missing = sorted(public - set(stubs))
    assert not missing, f"in the compiled module but not in the stubs (so not in the API reference): {missing}"
    # Type-only names: aliases, and the TypedDicts that describe the dicts functions return.
    typed_dicts = {
        n for n, node in stubs.items() if isinstance(node, ast.ClassDef) and any(getattr(b, "id", None) == "TypedDict" for b in node.bases)
    }
    aliases = (
        typed_dicts
        | {n for n, node in stubs.items() if isinstance(node, ast.Assign)}
        | {
            "F32Array",
            "IntArray",
            "ArrayLike",
            "Vec3",
            "Quat",
            "MethodName",
        }
    )
    extra = sorted(n for n in stubs if not n.startswith("_") and n not in aliases and not hasattr(dqskin._dqskin, n))
    assert not extra, f"in the stubs but not in the compiled module: {extra}"
    assert set(dqskin.__all__) <= set(stubs)


def test_the_stubs_give_each_function_and_method_its_real_parameters():
    wrong = []
    for name, node in stub_tree().items():
        runtime = getattr(dqskin._dqskin, name, None)
        if isinstance(node, ast.FunctionDef) and callable(runtime) and getattr(runtime, "__text_signature__", None):
            if stub_parameters(node) != parameters(inspect.signature(runtime)):
                wrong.append(name)
        if isinstance(node, ast.ClassDef) and runtime is not None and not issubclass(runtime, BaseException):
            members = {n for n in dir(runtime) if not n.startswith("_")}
            in_stub = {getattr(m, "name", None) or getattr(getattr(m, "target", None), "id", None) for m in node.body}
            if members - in_stub:
                wrong.append(f"{name} lacks {sorted(members - in_stub)}")
            init = next((m for m in node.body if isinstance(m, ast.FunctionDef) and m.name == "__init__"), None)
            if init is not None and getattr(runtime, "__text_signature__", None):
                if stub_parameters(init) != parameters(inspect.signature(runtime)):
                    wrong.append(f"{name}()")
            for m in node.body:
                if getattr(m, "name", "_").startswith("_"):
                    continue  # special methods: their signatures are the operators'
                attr = getattr(runtime, m.name, None)
                if isinstance(m, ast.FunctionDef) and getattr(attr, "__text_signature__", None):
                    try:
                        real = parameters(inspect.signature(attr))
                    except ValueError:
                        continue
                    if stub_parameters(m) != real:
                        wrong.append(f"{name}.{m.name}")
    assert not wrong, f"stubs whose parameters differ from the compiled module: {wrong}"


def test_the_wheels_description_is_its_own_readme():
    wheels = sorted((ROOT / "dist").glob("dqskin-*.whl"))
    assert wheels, "no dqskin wheel in dist/ (run make setup)"
    for wheel in wheels:
        with zipfile.ZipFile(wheel) as z:
            (name,) = [n for n in z.namelist() if n.endswith(".dist-info/METADATA")]
            metadata = email.message_from_string(z.read(name).decode("utf-8"))
        assert metadata["Description-Content-Type"].startswith("text/markdown"), wheel.name
        assert metadata.get_payload().strip() == WHEEL_README.read_text().strip(), f"{wheel.name}: rebuild it (make setup)"
