"""Import every module of a parts package, so that each part registers itself when its package loads.

The order of a registry (``coloc_env.WORLDS`` and friends) follows ``preferred``
(the order the package's ``__init__`` gives), then the remaining modules alphabetically; a new part
is a new module, and no list has to be edited.
"""

from __future__ import annotations

import importlib
import pkgutil


def import_parts(package: str, path, preferred: tuple[str, ...] = ()) -> None:
    names = [m.name for m in pkgutil.iter_modules(path)
             if not m.ispkg and not m.name.startswith("_") and m.name != "base"]  # blocks/: no parts
    rank = {name: i for i, name in enumerate(preferred)}
    for name in sorted(names, key=lambda n: (rank.get(n, len(rank)), n)):
        importlib.import_module(f"{package}.{name}")
