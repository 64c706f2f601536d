"""Imports flow down the layers (docs/architecture.md): estimators know nothing of the env, the env nothing of
the policies or the command line, the parts nothing of the presets, the world and network building blocks only
the checks, their own kind and the estimators. Every import statement counts, also one inside a function."""

from __future__ import annotations

import ast
import glob
import os

import pytest

REPO_ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def imported_modules(source: str) -> set[str]:
    """The absolute module names a module's import statements name (``from a.b import c`` names a.b and
    a.b.c, since c may be a module)."""
    names = set()
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.add(node.module)
            names.update(f"{node.module}.{alias.name}" for alias in node.names)
    return names


def offenders(folder: str, refused) -> list[str]:
    found = []
    for path in sorted(glob.glob(os.path.join(REPO_ROOT, folder, "**", "*.py"), recursive=True)):
        with open(path, encoding="utf-8") as handle:
            bad = sorted(name for name in imported_modules(handle.read()) if refused(name))
        found += [f"{os.path.relpath(path, REPO_ROOT)} imports {name}" for name in bad]
    return found


def under(name: str, *packages: str) -> bool:
    return any(name == p or name.startswith(p + ".") for p in packages)


def test_imported_modules_reads_every_form():
    source = ("import numpy as np\nfrom coloc_env.config import check_range\n"
              "def f():\n    from coloc_env.scenarios import base\n    import agents.generic\n"
              "from . import sibling\n")
    assert imported_modules(source) == {"numpy", "coloc_env.config", "coloc_env.config.check_range",
                                        "coloc_env.scenarios", "coloc_env.scenarios.base", "agents.generic"}


def test_estimators_import_neither_the_env_nor_the_policies_nor_the_command_line():
    assert not offenders("estimators", lambda name: under(name, "coloc_env", "agents", "train"))


def test_the_env_imports_neither_the_policies_nor_the_command_line():
    assert not offenders("coloc_env", lambda name: under(name, "agents", "train"))


@pytest.mark.parametrize("part", ["worlds", "networks", "backends", os.path.join("bounds", "models")])
def test_parts_import_no_preset(part):
    found = offenders(os.path.join("coloc_env", part),
                      lambda name: under(name, "coloc_env.scenarios", "coloc_env.presets", "coloc_env.envs"))
    assert not found, "\n".join(found)


@pytest.mark.parametrize("kind", ["worlds", "networks"])
def test_blocks_import_only_the_checks_their_own_kind_and_the_estimators(kind):
    first_party = ("coloc_env", "estimators", "agents", "train")
    allowed = ("coloc_env.config", f"coloc_env.{kind}.blocks", "estimators")
    found = offenders(os.path.join("coloc_env", kind, "blocks"),
                      lambda name: under(name, *first_party) and not under(name, *allowed))
    assert not found, "\n".join(found)


def test_the_old_primitives_paths_import_the_moved_modules_with_a_warning():
    import importlib
    import sys

    for name in [n for n in sys.modules if n == "coloc_env.primitives" or n.startswith("coloc_env.primitives.")]:
        del sys.modules[name]
    with pytest.warns(DeprecationWarning, match=r"coloc_env.primitives is deprecated: import the blocks from "
                                                r"coloc_env.worlds.blocks and coloc_env.networks.blocks"):
        primitives = importlib.import_module("coloc_env.primitives")
    from coloc_env.networks.blocks.relay_chain import RelayChain
    from coloc_env.worlds.blocks.unicycle import UnicycleMotion

    assert importlib.import_module("coloc_env.primitives.relay").RelayChain is RelayChain
    import coloc_env.primitives.relay  # the statement form reads the package's attribute

    assert coloc_env.primitives.relay.RelayChain is RelayChain
    assert primitives.UnicycleMotion is UnicycleMotion
    for old, new in primitives.MOVED.items():
        assert importlib.import_module(f"coloc_env.primitives.{old}") is importlib.import_module(new)


def test_no_module_rebinds_its_globals():
    """Compiled kernels take their compiled helpers from a namespace of their own
    (``estimators.compiled.in_namespace``), and lazily built state is cached by ``functools.cache``: no
    ``global`` statement rebinds a module's names after import."""
    found = []
    for package in ("estimators", "coloc_env", "agents", "train"):
        for path in sorted(glob.glob(os.path.join(REPO_ROOT, package, "**", "*.py"), recursive=True)):
            with open(path, encoding="utf-8") as handle:
                tree = ast.parse(handle.read())
            found += [f"{os.path.relpath(path, REPO_ROOT)}:{node.lineno} global {', '.join(node.names)}"
                      for node in ast.walk(tree) if isinstance(node, ast.Global)]
    assert not found, "\n".join(found)
