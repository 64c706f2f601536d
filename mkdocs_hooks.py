"""MkDocs hooks of the documentation site (mkdocs.yml ``hooks``).

``on_config`` drops from the navigation every page that does not exist, so that pages other parts of the
project add later (their entries are already in ``nav``) never break a build; an empty section is dropped
too. ``on_page_markdown`` fills the marker ``<!-- registered parts -->`` of the parts page with one section per
kind of part listing every registered part's module (``parts_reference``), so a new part appears without an
edit of the page. ``[text] [id]`` (a space between) is not a cross-reference (``_AdjacentReferenceIds``). Everything
else stays strict: a broken link or reference in an existing page fails ``make docs``.
"""

from __future__ import annotations

import os
import re

from markdown import Extension


def _existing(nav, docs_dir: str):
    kept = []
    for entry in nav:
        if isinstance(entry, str):
            if os.path.isfile(os.path.join(docs_dir, entry)):
                kept.append(entry)
            continue
        ((title, target),) = entry.items()
        if isinstance(target, list):
            children = _existing(target, docs_dir)
            if children:
                kept.append({title: children})
        elif "://" in target or os.path.isfile(os.path.join(docs_dir, target)):
            kept.append({title: target})
    return kept


PARTS_MARKER = "<!-- registered parts -->"
KIND_TITLES = (("world", "Worlds", "worlds"), ("network", "Networks", "networks"), ("backend", "Backends", "backends"))


def _module_block(module: str) -> list[str]:
    return [f"::: {module}", "    options:", "      members: false", "      heading_level: 3", ""]


def parts_reference() -> str:
    """The parts page's sections: per kind, its package, its base module and each registered part's module
    (``coloc_env.parts``' registries, in name order; a module holding several parts once)."""
    from coloc_env.parts import BACKENDS, NETWORKS, WORLDS

    registries = {"world": WORLDS, "network": NETWORKS, "backend": BACKENDS}
    lines = []
    for kind, title, package in KIND_TITLES:
        modules = [f"coloc_env.{package}", f"coloc_env.{package}.base"]
        for name in sorted(registries[kind]):
            module = registries[kind][name].__module__
            if module not in modules:
                modules.append(module)
        lines += [f"## {title}", ""]
        for module in modules:
            lines += _module_block(module)
    return "\n".join(lines)


def on_page_markdown(markdown, page, config, files):
    if PARTS_MARKER in markdown:
        return markdown.replace(PARTS_MARKER, parts_reference())
    return markdown


def on_config(config):
    if config["nav"]:
        config["nav"] = _existing(config["nav"], config["docs_dir"])
    # the same list object the mkdocstrings handler renders docstrings with, after autorefs' extension
    config["markdown_extensions"].append(_AdjacentReferenceIds())
    return config


class _AdjacentReferenceIds(Extension):
    """Cross-references as CommonMark reads them: ``[text][id]`` with nothing between the brackets.

    Python-Markdown (and so autorefs) also reads ``[text] [id]``, with a space, as a reference: the
    docstrings' tables write an interval before a provenance tag (``in [-1e4, 1e4] [chosen]``), which would
    become a reference to ``chosen``. Registered after autorefs' own extension, this drops the space."""

    def extendMarkdown(self, md):  # noqa: N802 (Python-Markdown's name)
        if "mkdocs-autorefs" in md.inlinePatterns:
            processor = md.inlinePatterns["mkdocs-autorefs"]
            processor.RE_LINK = re.compile(r"\[([^\]]*)\]", re.DOTALL | re.UNICODE)
