"""The house rules (CONTRIBUTING.md, "Where things go"), read from the source without importing it:

- a package imports only the packages below it, as the README's module map ("may import") says;
- no import circle between the modules of a package;
- no function over 80 lines outside the Cython kernels.

Imports inside functions count: a lazy import is still a dependency. Imports under ``if TYPE_CHECKING:``
do not (they never run).
"""

from __future__ import annotations

import ast
import functools
import re
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TESTS = ROOT / "tests"
MAX_FUNCTION_LINES = 80


def packages() -> list[str]:
    """The repository's top-level Python packages (a folder with __init__.py beside tests/)."""
    return sorted(p.parent.name for p in ROOT.glob("*/__init__.py") if p.parent.name != "tests")


def module_name(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def python_files(package: str) -> Iterator[Path]:
    yield from sorted((ROOT / package).rglob("*.py"))


@functools.cache
def syntax(path: Path) -> ast.Module:
    return ast.parse(path.read_text(), str(path))


def _type_checking_only(tree: ast.AST) -> set[int]:
    """ids of the import nodes under ``if TYPE_CHECKING:``."""
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            out.update(id(n) for stmt in node.body for n in ast.walk(stmt))
    return out


def imported(path: Path) -> Iterator[tuple[str, int]]:
    """The absolute module names ``path`` imports (for ``from M import x``: ``M.x``, which may be a name in
    M rather than a module; :func:`resolve` sorts that out), with their line numbers."""
    tree = syntax(path)
    skip = _type_checking_only(tree)
    package = module_name(path).split(".") if path.name == "__init__.py" else module_name(path).split(".")[:-1]
    for node in ast.walk(tree):
        if id(node) in skip:
            continue
        if isinstance(node, ast.Import):
            yield from ((alias.name, node.lineno) for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = package[:len(package) - node.level + 1] if node.level else []
            module = ".".join(base + ([node.module] if node.module else []))
            yield from (((f"{module}.{alias.name}" if alias.name != "*" else module), node.lineno)
                        for alias in node.names)


def resolve(name: str, modules: set[str]) -> str | None:
    """The repository module ``name`` is, or is a name in: its longest prefix that is a module."""
    parts = name.split(".")
    for end in range(len(parts), 0, -1):
        if ".".join(parts[:end]) in modules:
            return ".".join(parts[:end])
    return None


@dataclass(frozen=True)
class Edge:
    source: str  # module
    target: str  # module
    where: str  # file:line


def import_graph() -> list[Edge]:
    files = {module_name(f): f for package in packages() for f in python_files(package)}
    kernels = {module_name(f) for package in packages() for f in (ROOT / package).rglob("*.pyx")}
    modules = set(files) | kernels  # a kernel is a module too (its own imports are not followed)
    edges = {}  # one per import statement and module it names
    for source, path in files.items():
        for name, line in imported(path):
            target = resolve(name, modules)
            if target is not None and target != source:
                edges[Edge(source, target, f"{path.relative_to(ROOT)}:{line}")] = None
    return list(edges)


def module_map() -> dict[str, set[str]]:
    """From the README's module map: each top-level folder's row -> the packages its "may import" cell names."""
    section = (ROOT / "README.md").read_text().split("## Module map", 1)[1].split("\n## ", 1)[0]
    rows = {}
    for line in section.splitlines():
        cells = [c.strip() for c in line.split("|")[1:-1]]
        if len(cells) == 3 and (folder := re.fullmatch(r"`(\w+)/`", cells[0])):
            rows[folder[1]] = set(re.findall(r"`(\w+)`", cells[2]))
    return rows


def test_the_module_map_names_every_package_in_layers():
    rows, project = module_map(), set(packages())
    missing = sorted(project - set(rows))
    assert not missing, f"add a row for {missing} to the README's module map, saying which packages it may import"
    for package in project:
        assert rows[package] <= project - {package}, f"{package} may import {rows[package]}: not other packages"
    allowed = [Edge(package, below, "README.md") for package in project for below in rows[package]]
    assert not cycles(allowed), "the module map lets packages import each other"


def test_no_package_imports_one_above_it():
    """Nor a module of tests/ (a package never reaches into its tests)."""
    rows, project = module_map(), set(packages())
    # what ``import X`` finds in tests/ (pytest puts it on the path): its modules and folders
    test_modules = {p.stem for p in TESTS.iterdir() if p.suffix == ".py" or p.is_dir()} - project
    wrong = set()
    for package in project:
        for path in python_files(package):
            for name, line in imported(path):
                top = name.split(".")[0]
                if (top in project and top != package and top not in rows.get(package, set())) or top in test_modules:
                    wrong.add(f"{path.relative_to(ROOT)}:{line} imports {top}")
    assert not wrong, "imports the README's module map does not allow:\n" + "\n".join(sorted(wrong))


def cycles(edges: list[Edge]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan's algorithm, iterative)."""
    graph: dict[str, list[str]] = {}
    for e in edges:
        graph.setdefault(e.source, []).append(e.target)
        graph.setdefault(e.target, [])
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found = []
    for start in sorted(graph):
        if start in index:
            continue
        work = [(start, iter(graph[start]))]
        index[start] = low[start] = len(index)
        stack.append(start)
        on_stack.add(start)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is None:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[node])
                if low[node] == index[node]:
                    component = []
                    while True:
                        member = stack.pop()
                        on_stack.discard(member)
                        component.append(member)
                        if member == node:
                            break
                    if len(component) > 1:
                        found.append(sorted(component))
            elif child not in index:
                index[child] = low[child] = len(index)
                stack.append(child)
                on_stack.add(child)
                work.append((child, iter(graph[child])))
            elif child in on_stack:
                low[node] = min(low[node], index[child])
    return sorted(found)


def test_cycles_finds_a_circle_and_nothing_else():
    def e(a, b):
        return Edge(a, b, "")

    assert cycles([e("a", "b"), e("b", "c"), e("c", "a"), e("c", "d"), e("d", "e")]) == [["a", "b", "c"]]
    assert cycles([e("a", "b"), e("b", "c"), e("a", "c")]) == []
    assert cycles([e("a", "b"), e("b", "a"), e("c", "d"), e("d", "c")]) == [["a", "b"], ["c", "d"]]


def test_no_import_circle_inside_a_package():
    edges = [e for e in import_graph() if e.source.split(".")[0] == e.target.split(".")[0]]
    found = cycles(edges)
    lines = []
    for component in found:
        members = set(component)
        lines.append(" <-> ".join(component) + ": " + ", ".join(
            f"{e.where} imports {e.target}" for e in edges if e.source in members and e.target in members))
    assert not found, "import circles:\n" + "\n".join(lines)


def long_functions() -> list[str]:
    out = []
    for package in packages():
        for path in python_files(package):  # .py only: the Cython kernels (.pyx, .pxi) are exempt
            for node in ast.walk(syntax(path)):
                if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                    lines = node.end_lineno - node.lineno + 1
                    if lines > MAX_FUNCTION_LINES:
                        out.append(f"{path.relative_to(ROOT)}:{node.lineno} {node.name} ({lines} lines)")
    return out


def test_no_function_over_80_lines():
    """Counted from ``def`` to the last line of the body, docstring and comments included."""
    found = long_functions()
    assert not found, f"functions over {MAX_FUNCTION_LINES} lines (split them):\n" + "\n".join(found)
