"""The code describes itself as it is: no issue numbers, reconstruction-spec sections, session talk or
references to design notes a user of the clone does not have, in any module (``help()`` shows them)."""

from __future__ import annotations

import glob
import os
import re

REPO_ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PACKAGES = ("coloc_env", "estimators", "agents", "train")
HISTORY = re.compile(r"\bissue[- ]?\d|spec §|\bsession \d|DESIGN\.md|shared/specs", re.IGNORECASE)


def history_lines(package_paths) -> list[str]:
    hits = []
    for path in package_paths:
        with open(path, encoding="utf-8") as handle:
            for number, line in enumerate(handle, start=1):
                if HISTORY.search(line):
                    hits.append(f"{os.path.relpath(path, REPO_ROOT)}:{number}: {line.strip()[:100]}")
    return hits


def test_history_pattern_catches_what_it_is_for():
    for text in ("(issue 15 §1)", "Issue 34's target", "the issue-15 note", "spec §12", "as in session 3",
                 "see DESIGN.md", "../shared/specs/gao2016_afge.md"):
        assert HISTORY.search(text), text
    for text in ("an issue of units", "issues arise", "the session's seed", "spec_dict", "the design's rule",
                 "shared/data"):
        assert not HISTORY.search(text), text


def test_no_development_history_in_code():
    paths = sorted(path for package in PACKAGES
                   for path in glob.glob(os.path.join(REPO_ROOT, package, "**", "*.py"), recursive=True))
    assert paths
    hits = history_lines(paths)
    assert not hits, f"{len(hits)} lines carry development history:\n" + "\n".join(hits)
