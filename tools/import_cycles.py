#!/usr/bin/env python3
"""Import cycles between the modules of a package, from the source alone (nothing is imported).

    python tools/import_cycles.py [PACKAGE_DIR] [--lazy]

Builds the graph module -> modules it imports with `ast`: every import at module level, those
under `if TYPE_CHECKING:` and in try/except included (a cycle of type annotations is a cycle of the
design, even if Python never runs it). With `--lazy`, imports inside functions count as well.
`from P import name` is an edge to the submodule P.name when there is one, else to P (its
__init__); `from . import x` and `from ..a import b` are resolved relative to the module. Only
edges inside the package count. Prints each cycle (one strongly connected component, as a chain of
modules through it) and exits 1 if there is one; 0 and "no import cycle" otherwise.
"""

from __future__ import annotations

import argparse
import ast
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent


def module_names(package_dir: Path) -> dict[str, Path]:
    """Dotted module name -> file, for every .py file under the package."""
    root = package_dir.parent
    names = {}
    for path in sorted(package_dir.rglob("*.py")):
        parts = list(path.relative_to(root).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts.pop()
        names[".".join(parts)] = path
    return names


def _top_level_imports(tree: ast.Module, lazy: bool) -> list[ast.Import | ast.ImportFrom]:
    """The import statements run when the module is imported (or read by a type checker); with
    `lazy`, those inside functions too."""
    found = []

    def visit(nodes):
        for node in nodes:
            if isinstance(node, (ast.Import, ast.ImportFrom)):
                found.append(node)
            elif isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
                if lazy:
                    found.extend(n for n in ast.walk(node) if isinstance(n, (ast.Import, ast.ImportFrom)))
            elif isinstance(node, ast.ClassDef):
                visit(node.body)
            else:
                for field in ("body", "orelse", "finalbody", "handlers"):
                    visit(getattr(node, field, []) or [])

    visit(tree.body)
    return found


def imports_of(name: str, path: Path, modules: dict[str, Path], lazy: bool) -> set[str]:
    """The package's modules that module `name` imports."""
    is_package = path.name == "__init__.py"
    out = set()
    for node in _top_level_imports(ast.parse(path.read_text(encoding="utf-8"), str(path)), lazy):
        if isinstance(node, ast.Import):
            targets = [alias.name for alias in node.names]
        else:
            if node.level:
                base = name.split(".") if is_package else name.split(".")[:-1]
                base = base[: len(base) - (node.level - 1)]
                prefix = ".".join(base + ([node.module] if node.module else []))
            else:
                prefix = node.module or ""
            targets = []
            for alias in node.names:
                submodule = f"{prefix}.{alias.name}"
                targets.append(submodule if submodule in modules else prefix)
        for target in targets:
            while target and target not in modules:    # `import a.b.c` of a name inside a module
                target = target.rpartition(".")[0]
            if target and target != name:
                out.add(target)
    return out


def strongly_connected(graph: dict[str, set[str]]) -> list[list[str]]:
    """Tarjan's components of more than one module."""
    index, low, stack, on_stack, result = {}, {}, [], set(), []
    counter = [0]

    def connect(node: str) -> None:
        index[node] = low[node] = counter[0]
        counter[0] += 1
        stack.append(node)
        on_stack.add(node)
        for nxt in sorted(graph.get(node, ())):
            if nxt not in index:
                connect(nxt)
                low[node] = min(low[node], low[nxt])
            elif nxt in on_stack:
                low[node] = min(low[node], index[nxt])
        if low[node] == index[node]:
            component = []
            while True:
                member = stack.pop()
                on_stack.discard(member)
                component.append(member)
                if member == node:
                    break
            if len(component) > 1:
                result.append(sorted(component))

    sys.setrecursionlimit(max(sys.getrecursionlimit(), 10000))
    for node in sorted(graph):
        if node not in index:
            connect(node)
    return result


def cycle_through(component: list[str], graph: dict[str, set[str]]) -> list[str]:
    """One closed chain of imports inside a component, starting at its first module."""
    members, start = set(component), component[0]
    paths, seen = {start: [start]}, {start}
    frontier = [start]
    while frontier:
        following = []
        for node in frontier:
            for nxt in sorted(graph[node] & members):
                if nxt == start:
                    return paths[node] + [start]
                if nxt not in seen:
                    seen.add(nxt)
                    paths[nxt] = paths[node] + [nxt]
                    following.append(nxt)
        frontier = following
    return component


def find_cycles(package_dir: Path, lazy: bool = False) -> list[list[str]]:
    modules = module_names(package_dir)
    graph = {name: imports_of(name, path, modules, lazy) for name, path in modules.items()}
    return [cycle_through(component, graph) for component in strongly_connected(graph)]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("package", nargs="?", default=str(REPO / "hopper_ros"), help="the package's folder")
    parser.add_argument("--lazy", action="store_true", help="count imports inside functions too")
    args = parser.parse_args(argv)
    cycles = find_cycles(Path(args.package), args.lazy)
    for cycle in cycles:
        print("import cycle: " + " -> ".join(cycle))
    if not cycles:
        print("no import cycle")
    return 1 if cycles else 0


if __name__ == "__main__":
    sys.exit(main())
