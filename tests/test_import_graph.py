"""No import cycle inside ``coloc_env``: the graph of every module's imports, at the top level and inside functions
(an import moved into a function to dodge a cycle is still an edge) and ``importlib.import_module`` of a name
written out, has no cycle.

An edge goes from a module to each ``coloc_env`` module it names: ``import a.b`` and ``from a import b`` name
``a.b`` where that is a module (or package), ``from a.b import name`` names ``a.b`` otherwise. A package's own
``__init__`` is the package's node. Importing ``a.b`` also runs ``a``'s ``__init__``; that implicit edge is left out,
since every module would otherwise sit on a cycle through its package's ``__init__``.
"""

from __future__ import annotations

import ast
import os

REPO_ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PACKAGE = "coloc_env"

# Modules left out of the check, each with the reason why (none: every module of coloc_env is in the graph).
EXCLUDED: tuple[str, ...] = ()


def _modules() -> dict[str, str]:
    """Module name -> file, for every module and package of ``coloc_env``."""
    found = {}
    for folder, _, files in os.walk(os.path.join(REPO_ROOT, PACKAGE)):
        for file in files:
            if not file.endswith(".py"):
                continue
            path = os.path.join(folder, file)
            parts = os.path.relpath(path, REPO_ROOT)[:-3].split(os.sep)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            found[".".join(parts)] = path
    return found


def _imports(name: str, path: str, modules: dict[str, str]) -> set[str]:
    """The ``coloc_env`` modules that module ``name`` imports anywhere in its source."""
    with open(path) as f:
        tree = ast.parse(f.read(), path)
    is_package = path.endswith("__init__.py")
    named = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            named.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = name.split(".")[: len(name.split(".")) - node.level + (1 if is_package else 0)]
                module = ".".join(base + ([node.module] if node.module else []))
            else:
                module = node.module or ""
            for alias in node.names:
                named.add(f"{module}.{alias.name}" if f"{module}.{alias.name}" in modules else module)
        elif (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr == "import_module"
              and node.args and isinstance(node.args[0], ast.Constant) and isinstance(node.args[0].value, str)):
            named.add(node.args[0].value)  # importlib.import_module("coloc_env....") with the name written out
    return {target for target in named if target in modules and target != name}


def _excluded(name: str) -> bool:
    return any(name == prefix or name.startswith(prefix + ".") for prefix in EXCLUDED)


def import_graph() -> dict[str, set[str]]:
    modules = _modules()
    return {name: {t for t in _imports(name, path, modules) if not _excluded(t)}
            for name, path in modules.items() if not _excluded(name)}


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan's algorithm, iterative)."""
    index, low, on_stack, stack, found = {}, {}, set(), [], []
    counter = [0]
    for root in sorted(graph):
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = counter[0]
        counter[0] += 1
        stack.append(root)
        on_stack.add(root)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = counter[0]
                    counter[0] += 1
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph[child]))))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
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
    return found


def test_the_cycle_finder_finds_a_cycle_and_only_cycles():
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}, "e": set()}
    assert cycles(graph) == [["a", "b", "c"]]
    assert cycles({"a": {"b"}, "b": set()}) == []


def test_the_graph_sees_function_level_and_relative_imports():
    graph = import_graph()
    # coloc_env/__init__.py imports coloc_env.env inside make_core and coloc_env.vector inside vector_env
    assert {"coloc_env.env", "coloc_env.vector", "coloc_env.registry"} <= graph["coloc_env"]
    assert "coloc_env.scenarios.binding" in graph["coloc_env.scenarios"]


def test_no_import_cycle_inside_coloc_env():
    found = cycles(import_graph())
    assert found == [], "import cycles inside coloc_env (each a group of modules that import each other):\n" + \
        "\n".join(" <-> ".join(c) for c in found)
