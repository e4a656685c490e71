"""Writes the reference part of docs/python-api.md from the `dqskin` package's type stubs and
its pure-Python modules, so that every public function, class, method, property and option the
package has is in the reference with the signature and docstring its stub gives.

The page keeps what is written above the MARKER line; everything below it is generated.
tests/python/test_docs.py checks that the page is up to date and that the stubs match the
compiled module (names, parameters).

Usage: python docs/api_reference.py [--check]
"""

from __future__ import annotations

import argparse
import ast
import io
import re
import sys
import tokenize
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PAGE = ROOT / "docs" / "python-api.md"
PACKAGE = ROOT / "python" / "dqskin"
MARKER = "<!-- Generated below from python/dqskin/*.pyi and pc2.py by docs/api_reference.py: do not edit by hand. -->"
# (module as users import it, its source, what it is for).
MODULES = (
    ("dqskin", PACKAGE / "_dqskin.pyi", "The numpy API (the compiled core; `import dqskin` gives every name below)."),
    ("dqskin.pc2", PACKAGE / "pc2.py", "PC2 point caches, the files Blender's Mesh Cache modifier reads."),
    (
        "dqskin.memory",
        PACKAGE / "memory.pyi",
        "Readers of Blender's memory, for the Blender extension only (they read raw memory of the Blender that wrote the file).",
    ),
)


def is_public(name: str) -> bool:
    return not name.startswith("_") or (name.startswith("__") and name.endswith("__") and name not in DUNDERS_HIDDEN)


# Special methods that say nothing a reader needs (they are the usual ones for the type).
DUNDERS_HIDDEN = {"__init__", "__eq__", "__hash__", "__len__", "__enter__", "__exit__", "__all__"}


def trailing_comments(source: str) -> dict[int, str]:
    """Line number -> the comment ending that line."""
    comments = {}
    for tok in tokenize.generate_tokens(io.StringIO(source).readline):
        if tok.type == tokenize.COMMENT:
            comments[tok.start[0]] = tok.string.lstrip("#").strip()
    return comments


def arguments(args: ast.arguments, skip_first: bool) -> str:
    """The parameter list as the stub writes it (`name: type = default`, `*`, `/`)."""

    def one(arg: ast.arg, default) -> str:
        text = arg.arg + (f": {ast.unparse(arg.annotation)}" if arg.annotation is not None else "")
        if default is not None:
            text += (" = " if arg.annotation is not None else "=") + ast.unparse(default)
        return text

    positional = [*args.posonlyargs, *args.args]
    defaults = [None] * (len(positional) - len(args.defaults)) + list(args.defaults)
    parts = [one(a, d) for a, d in zip(positional, defaults)]
    if args.posonlyargs:
        parts.insert(len(args.posonlyargs), "/")
    if skip_first and positional:
        parts = parts[1:]
        if parts and parts[0] == "/":
            parts = parts[1:]
    if args.vararg is not None:
        parts.append("*" + one(args.vararg, None))
    elif args.kwonlyargs:
        parts.append("*")
    parts += [one(a, d) for a, d in zip(args.kwonlyargs, args.kw_defaults)]
    if args.kwarg is not None:
        parts.append("**" + one(args.kwarg, None))
    return ", ".join(parts)


def signature(node: ast.FunctionDef, owner: str | None = None) -> str:
    """`name(args) -> result` as the stub writes it, without the body; methods lose `self`."""
    is_method = owner is not None and bool(node.args.args) and node.args.args[0].arg in ("self", "cls")
    name = node.name if owner is None else owner if node.name == "__init__" else f"{owner}.{node.name}"
    returns = f" -> {ast.unparse(node.returns)}" if node.returns is not None and node.name != "__init__" else ""
    return f"{name}({arguments(node.args, is_method)}){returns}"


def decorators(node) -> set[str]:
    return {ast.unparse(d) for d in node.decorator_list}


def docstring(node) -> str:
    """The docstring on one line, its reStructuredText roles and literals as Markdown code."""
    text = " ".join(line.strip() for line in (ast.get_docstring(node) or "").splitlines() if line.strip())
    return re.sub(r":(?:func|class|meth|attr):`([^`]+)`", r"`\1`", text).replace("``", "`")


def render_function(out: list[str], group: list[ast.FunctionDef]) -> None:
    """A module-level function (all its overloads)."""
    out.append(f"### `{group[0].name}`\n")
    out.append("```python\n" + "\n".join(signature(n) for n in group) + "\n```\n")
    text = " ".join(filter(None, (docstring(n) for n in group)))
    if text:
        out.append(text + "\n")


def member_line(owner: str, group: list, body: list[ast.stmt], comments: dict[int, str]) -> str:
    """One bullet for a method, property or attribute of a class."""
    first = group[0]
    if isinstance(first, ast.FunctionDef):
        kind = decorators(first)
        if "property" in kind:
            settable = any(d.endswith(".setter") for n in group for d in decorators(n))
            returns = ast.unparse(first.returns) if first.returns is not None else ""
            line = f"`{owner}.{first.name}: {returns}`" + (" (settable)" if settable else " (read-only)")
        else:
            line = " / ".join(f"`{signature(n, owner)}`" for n in group)
            if "staticmethod" in kind:
                line += " (static)"
        text = " ".join(filter(None, (docstring(n) for n in group)))
    else:
        line = f"`{owner}.{first.target.id}: {ast.unparse(first.annotation)}`"
        text = attribute_doc(body, first, comments)
    return f"- {line}" + (f": {text}" if text else "")


def members(body: list[ast.stmt]) -> list[tuple[str, list]]:
    """(name, nodes) in source order, overloads and property setters grouped under one name."""
    grouped: dict[str, list] = {}
    for node in body:
        if isinstance(node, ast.FunctionDef | ast.ClassDef):
            grouped.setdefault(node.name, []).append(node)
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            grouped.setdefault(node.target.id, []).append(node)
        elif isinstance(node, ast.Assign) and len(node.targets) == 1 and isinstance(node.targets[0], ast.Name):
            grouped.setdefault(node.targets[0].id, []).append(node)
    return [(name, nodes) for name, nodes in grouped.items() if is_public(name)]


def attribute_doc(body: list[ast.stmt], node: ast.stmt, comments: dict[int, str]) -> str:
    """An attribute's comment on its line, or the string literal right after it."""
    if node.lineno in comments:
        return comments[node.lineno]
    i = body.index(node)
    after = body[i + 1] if i + 1 < len(body) else None
    if isinstance(after, ast.Expr) and isinstance(after.value, ast.Constant) and isinstance(after.value.value, str):
        return " ".join(after.value.value.split())
    return ""


def render_class(out: list[str], node: ast.ClassDef, comments: dict[int, str]) -> None:
    bases = ", ".join(ast.unparse(b) for b in node.bases)
    out.append(f"### class `{node.name}`" + (f" ({bases})" if bases else "") + "\n")
    if docstring(node):
        out.append(docstring(node) + "\n")
    is_dataclass = any(d.startswith("dataclass") for d in decorators(node))
    if is_dataclass:
        fields = [n for n in node.body if isinstance(n, ast.AnnAssign)]
        out.append(
            "```python\n"
            + f"{node.name}({', '.join(ast.unparse(f.target) + ': ' + ast.unparse(f.annotation) for f in fields)})"
            + "\n```\n"
        )
    init = [n for n in node.body if isinstance(n, ast.FunctionDef) and n.name == "__init__"]
    if init:
        out.append("```python\n" + "\n".join(signature(n, node.name) for n in init) + "\n```\n")
    lines = [
        member_line(node.name, nodes, node.body, comments)
        for name, nodes in members(node.body)
        if name not in DUNDERS_HIDDEN and not (is_dataclass and isinstance(nodes[0], ast.AnnAssign))
    ]
    if lines:
        out.append("\n".join(lines) + "\n")


def render_module(out: list[str], module: str, path: Path, about: str) -> None:
    source = path.read_text()
    tree = ast.parse(source)
    comments = trailing_comments(source)
    out.append(f"## `{module}`\n")
    out.append(about + "\n")
    aliases = []
    for name, nodes in members(tree.body):
        node = nodes[0]
        if isinstance(node, ast.ClassDef):
            render_class(out, node, comments)
        elif isinstance(node, ast.FunctionDef):
            render_function(out, nodes)
        elif isinstance(node, ast.Assign) and path.suffix == ".pyi":
            # A type alias of the stubs, as the stub writes it (ruff also formats the page's code).
            aliases.append(ast.get_source_segment(source, node))
        elif isinstance(node, ast.AnnAssign | ast.Assign):
            shown = f"{name}: {ast.unparse(node.annotation)}" if isinstance(node, ast.AnnAssign) else ast.get_source_segment(source, node)
            note = comments.get(node.lineno, "")
            out.append(f"### `{module}.{name}`\n")
            out.append(f"```python\n{shown}\n```\n" + (f"\n{note[0].upper() + note[1:]}.\n" if note else ""))
    if aliases:
        out.append("### Types used in the signatures\n")
        out.append("```python\n" + "\n".join(aliases) + "\n```\n")


def reference() -> str:
    out: list[str] = []
    for module, path, about in MODULES:
        render_module(out, module, path, about)
    return "\n".join(out)


def page() -> str:
    """The page as it should be: the hand-written part, the marker, the generated reference."""
    head = PAGE.read_text().split(MARKER)[0].rstrip() + "\n\n"
    return head + MARKER + "\n\n" + reference()


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="exit 1 if the page is not up to date")
    args = parser.parse_args()
    wanted = page()
    if args.check:
        if PAGE.read_text() != wanted:
            print(f"{PAGE.relative_to(ROOT)} is out of date: run python docs/api_reference.py", file=sys.stderr)
            return 1
        return 0
    PAGE.write_text(wanted)
    print(f"wrote {PAGE.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
