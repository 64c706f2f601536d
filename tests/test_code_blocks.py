"""Every code block of README.md and docs/ runs: each ```python block on its own (a fresh namespace, so a
block that relies on the one before it fails), each ```bash / ```sh / ```shell block through bash with
`coloc` and `python` meaning this tree's (in a temporary folder).

An HTML comment on the line right above a fence says more about its block:

    <!-- docs-test: skip (REASON) -->          it cannot run here (it installs packages, runs for minutes, or
                                               is an outline rather than code): skipped with that reason
    <!-- docs-test: needs-mrclam (REASON) -->  it reads the MRCLAM data: run with COLOC_MRCLAM_DATA set to the
                                               tests' dataset-6 folder (tests/conftest.py), skipped without it
    <!-- docs-test: prints (TEXT) -->          its output must contain TEXT

Blocks without a language (usage synopses, trees) are text.
"""

from __future__ import annotations

import glob
import os
import re
import subprocess
import sys

import pytest

from tests.conftest import MRCLAM_DATA_ENV, MRCLAM_DATASET6, MRCLAM_SKIP_REASON

REPO_ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PYTHON_LANGS = {"python", "py"}
SHELL_LANGS = {"bash", "sh", "shell"}
FENCE = re.compile(r"^```(\w*)\s*$")
MARKER = re.compile(r"^<!--\s*docs-test:\s*(skip|needs-mrclam|prints)\s*\((.+)\)\s*-->\s*$")


def markdown_files() -> list[str]:
    return [os.path.join(REPO_ROOT, "README.md"),
            *sorted(glob.glob(os.path.join(REPO_ROOT, "docs", "**", "*.md"), recursive=True))]


def code_blocks(path: str) -> list[tuple[int, str, str, tuple[str, str] | None]]:
    """[(line of the opening fence, language, code, (marker kind, its text) or None)] of one Markdown file."""
    with open(path, encoding="utf-8") as handle:
        lines = handle.read().splitlines()
    blocks, i = [], 0
    while i < len(lines):
        opening = FENCE.match(lines[i])
        if not opening:
            i += 1
            continue
        end = next((j for j in range(i + 1, len(lines)) if lines[j].startswith("```")), None)
        assert end is not None, f"{os.path.relpath(path, REPO_ROOT)}:{i + 1}: a code block is never closed"
        marker = MARKER.match(lines[i - 1]) if i else None
        blocks.append((i + 1, opening.group(1).lower(), "\n".join(lines[i + 1:end]) + "\n",
                       marker.groups() if marker else None))
        i = end + 1
    return blocks


def runnable_blocks() -> list:
    params = []
    for path in markdown_files():
        for line, lang, code, marker in code_blocks(path):
            if lang in PYTHON_LANGS | SHELL_LANGS:
                ident = f"{os.path.relpath(path, REPO_ROOT)}:{line}"
                kind, text = marker or (None, None)
                marks = []
                if kind == "skip":
                    marks = [pytest.mark.skip(reason=f"{ident}: {text}")]
                elif kind == "needs-mrclam":
                    marks = [pytest.mark.skipif(not os.path.isdir(MRCLAM_DATASET6),
                                                reason=f"{ident}: {MRCLAM_SKIP_REASON}")]
                params.append(pytest.param(lang, code, kind == "needs-mrclam", text if kind == "prints" else None,
                                           id=ident, marks=marks))
    return params


def test_every_skip_marker_sits_above_a_runnable_block():
    """A marker must be right above a python or shell fence (a stray one would skip nothing)."""
    for path in markdown_files():
        with open(path, encoding="utf-8") as handle:
            lines = handle.read().splitlines()
        for i, line in enumerate(lines):
            if "docs-test" in line:
                assert MARKER.match(line), (f"{path}:{i + 1}: write <!-- docs-test: skip (REASON) -->, "
                                            "needs-mrclam (REASON) or prints (TEXT)")
                fence = FENCE.match(lines[i + 1]) if i + 1 < len(lines) else None
                assert fence and fence.group(1).lower() in PYTHON_LANGS | SHELL_LANGS, (
                    f"{os.path.relpath(path, REPO_ROOT)}:{i + 1}: the marker is not right above a python or "
                    "shell code block")


@pytest.mark.parametrize(("lang", "code", "data", "prints"), runnable_blocks())
def test_code_block_runs(lang, code, data, prints, tmp_path, monkeypatch, capfd):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("MPLBACKEND", "Agg")
    if data:
        monkeypatch.setenv(MRCLAM_DATA_ENV, MRCLAM_DATASET6)
    if lang in PYTHON_LANGS:
        exec(compile(code, "<code block>", "exec"), {"__name__": "__main__"})  # noqa: S102
        if prints is not None:
            assert prints in capfd.readouterr().out, f"the block's output has no {prints!r}"
        return
    # installs and the commands that run for minutes (reproductions, training, benchmarks) must be marked
    slow = re.findall(r"^\s*(?:\S+/)?(?:pip install|make\b|python3? -m venv|coloc (?:reproduce|train|bench)\b)",
                      code, re.MULTILINE)
    assert not slow, f"the block runs {slow}: mark it <!-- docs-test: skip (REASON) --> rather than run it here"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([REPO_ROOT, *filter(None, [os.environ.get("PYTHONPATH")])]),
           "DOCS_TEST_PYTHON": sys.executable}
    prelude = ('coloc() { "$DOCS_TEST_PYTHON" -m train.cli "$@"; }\n'
               'python() { "$DOCS_TEST_PYTHON" "$@"; }\npython3() { "$DOCS_TEST_PYTHON" "$@"; }\n')
    done = subprocess.run(["bash", "-e", "-o", "pipefail", "-c", prelude + code], cwd=tmp_path, env=env,
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, f"exit {done.returncode}\n{done.stdout[-2000:]}\n{done.stderr[-2000:]}"
    if prints is not None:
        assert prints in done.stdout, f"the block's output has no {prints!r}"


def test_blocks_and_their_markers_are_read(tmp_path):
    page = tmp_path / "page.md"
    page.write_text("# t\n\n```python\nx = 1\n```\n\n<!-- docs-test: skip (needs a GPU) -->\n```bash\nnvidia-smi\n```\n"
                    "\n<!-- docs-test: prints (hello) -->\n```sh\necho hello\n```\n\n```\ncoloc list\n```\n")
    assert code_blocks(str(page)) == [(3, "python", "x = 1\n", None),
                                      (8, "bash", "nvidia-smi\n", ("skip", "needs a GPU")),
                                      (13, "sh", "echo hello\n", ("prints", "hello")),
                                      (17, "", "coloc list\n", None)]
