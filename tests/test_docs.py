"""The project explains itself: README.md and docs/ link only to files a user has, the presets table is
complete, and the install instructions of the README, the Makefile and pyproject.toml agree."""

from __future__ import annotations

import glob
import importlib.util
import os
import re
import shutil
import subprocess
import sys
import tomllib

import pytest

import coloc_env
from coloc_env.scenarios import REGISTRY

REPO_ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
README = os.path.join(REPO_ROOT, "README.md")
DOCS = os.path.join(REPO_ROOT, "docs")
MAKEFILE = os.path.join(REPO_ROOT, "Makefile")
PYPROJECT = os.path.join(REPO_ROOT, "pyproject.toml")
DOC_PAGES = ("getting-started.md", "architecture.md", "presets.md", "wan2014.md", "gao2016.md", "compositions.md",
             "learning.md", "bounds.md", "cli.md")

# [text](target) outside code; an image ![alt](target) has the same target syntax
LINK = re.compile(r"\[[^\]]*\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)")
EXTERNAL = re.compile(r"^(?:[a-z][a-z0-9+.-]*:|#)", re.IGNORECASE)


def read(path: str) -> str:
    with open(path, encoding="utf-8") as handle:
        return handle.read()


def markdown_files() -> list[str]:
    return [README, *sorted(glob.glob(os.path.join(DOCS, "*.md")))]


def without_code(text: str) -> str:
    """The text with fenced code blocks and inline code removed: links are only read from prose."""
    text = re.sub(r"^```.*?^```", "", text, flags=re.DOTALL | re.MULTILINE)
    return re.sub(r"`[^`\n]*`", "", text)


def relative_links(path: str) -> list[str]:
    return [target for target in LINK.findall(without_code(read(path))) if not EXTERNAL.match(target)]


def test_every_documentation_page_exists_and_the_readme_links_it():
    readme_links = {os.path.normpath(target.split("#")[0]) for target in relative_links(README)}
    for page in DOC_PAGES:
        assert os.path.isfile(os.path.join(DOCS, page)), f"docs/{page} is missing"
        assert os.path.normpath(f"docs/{page}") in readme_links, f"README.md does not link docs/{page}"


@pytest.mark.parametrize("path", markdown_files(), ids=lambda p: os.path.relpath(p, REPO_ROOT))
def test_every_relative_link_resolves(path):
    links = relative_links(path)
    missing = [target for target in links
               if not os.path.exists(os.path.join(os.path.dirname(path), target.split("#")[0]))]
    assert not missing, f"{os.path.relpath(path, REPO_ROOT)} links to files that do not exist: {missing}"


@pytest.mark.parametrize("path", markdown_files(), ids=lambda p: os.path.relpath(p, REPO_ROOT))
def test_documentation_names_no_file_a_user_does_not_have(path):
    """The shared design notes, the reconstruction specs and the issue tracker are not in the clone (the
    tests' default data folder beside the clone, ``../shared/data/``, is documented where the data are)."""
    text = read(path)
    for pattern in (r"DESIGN\.md", r"shared/(?!data/)", r"specs/", r"spec §", r"\bissue \d+"):
        hits = [line.strip() for line in text.splitlines() if re.search(pattern, line)]
        assert not hits, f"{os.path.relpath(path, REPO_ROOT)} refers to {pattern!r}: {hits[:3]}"


def presets_table() -> dict[str, str]:
    """{preset: paper key} from the first table of docs/presets.md (its first two columns)."""
    rows = {}
    lines = read(os.path.join(DOCS, "presets.md")).splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("| preset |"))
    for line in lines[start + 2:]:
        if not line.startswith("|"):
            break
        cells = [cell.strip().strip("`") for cell in line.strip("|").split("|")]
        rows[cells[0]] = cells[1]
    return rows


def test_presets_table_lists_every_preset_with_its_paper_key():
    table = presets_table()
    assert set(table) == set(coloc_env.PRESETS), (
        f"docs/presets.md's table has {sorted(table)}, coloc_env.PRESETS has {sorted(coloc_env.PRESETS)}")
    for name in coloc_env.PRESETS:
        assert table[name] == REGISTRY[name].paper, (
            f"docs/presets.md gives {name} the paper key {table[name]!r}; the scenario says {REGISTRY[name].paper!r}")


def readme_torch_install() -> tuple[str, str]:
    """(version, index URL) of the README's `pip install torch==X --index-url URL`."""
    found = re.findall(r"pip install torch==(\S+) --index-url (\S+)", read(README))
    assert len(found) == 1, f"expected one torch install command in README.md, found {found}"
    return found[0]


def test_readme_makefile_and_pyproject_agree_on_the_torch_pin_and_index():
    version, index = readme_torch_install()
    makefile = read(MAKEFILE)
    make_version = re.search(r"^TORCH_VERSION\s*:?=\s*(\S+)", makefile, re.MULTILINE)
    make_index = re.search(r"^TORCH_INDEX\s*\?=\s*(\S*)", makefile, re.MULTILINE)
    assert make_version and make_index, "the Makefile sets TORCH_VERSION and TORCH_INDEX ?= ..."
    assert make_version.group(1) == version, f"Makefile torch {make_version.group(1)}, README torch {version}"
    assert make_index.group(1) == index, f"Makefile TORCH_INDEX {make_index.group(1)}, README --index-url {index}"
    with open(PYPROJECT, "rb") as handle:
        project = tomllib.load(handle)["project"]
    pins = [dep for dep in project["dependencies"] if re.match(r"torch\b", dep)]
    assert pins == [f"torch=={version}"], f"pyproject.toml pins {pins}, the README installs torch=={version}"


def test_pyproject_names_no_index_and_ray_only_in_its_extra():
    text = read(PYPROJECT)
    assert "index-url" not in text and "download.pytorch.org" not in text
    with open(PYPROJECT, "rb") as handle:
        project = tomllib.load(handle)["project"]
    assert not [dep for dep in project["dependencies"] if re.match(r"ray\b", dep)]
    assert [dep for dep in project["optional-dependencies"]["ray"] if re.match(r"ray\b", dep)]
    # besides the ray extra only rllib's (RLlib is part of Ray, installed in its own venv)
    assert not [dep for name, deps in project["optional-dependencies"].items() if name not in ("ray", "rllib")
                for dep in deps if re.match(r"ray\b", dep)]


@pytest.mark.skipif(shutil.which("make") is None, reason="make is not installed")
@pytest.mark.parametrize("override", [None, ""], ids=["default", "TORCH_INDEX="])
def test_makefile_installs_the_readme_torch(override):
    """`make -n` prints the install commands without running them: the default installs the README's
    torch from the README's index; `TORCH_INDEX=` leaves the index to pip's own configuration."""
    version, index = readme_torch_install()
    command = ["make", "-n", "-B", "install"] + ([] if override is None else [f"TORCH_INDEX={override}"])
    printed = subprocess.run(command, cwd=REPO_ROOT, capture_output=True, text=True, check=True).stdout
    torch_lines = [line for line in printed.splitlines() if "pip install" in line and "torch==" in line]
    assert len(torch_lines) == 1, printed
    words = torch_lines[0].split()
    assert f"torch=={version}" in words
    if override is None:
        assert words[words.index("--index-url") + 1] == index
    else:
        assert "--index-url" not in words and "--extra-index-url" not in words


README_MAX_LINES = 160
# a commit hash: 7 to 40 hex digits with at least one letter and one digit (so no plain number matches)
COMMIT_HASH = re.compile(r"\b(?=[0-9a-f]*[a-f])(?=[0-9a-f]*[0-9])[0-9a-f]{7,40}\b")
DATE = re.compile(r"\b(?:19|20)\d\d-\d\d-\d\d\b|\b(?:January|February|March|April|May|June|July|August|September|"
                  r"October|November|December) (?:\d{1,2}, )?(?:19|20)\d\d\b")


def test_readme_is_short():
    lines = read(README).splitlines()
    assert len(lines) <= README_MAX_LINES, (
        f"README.md has {len(lines)} lines; keep it to {README_MAX_LINES} (details go to docs/)")


@pytest.mark.parametrize("path", [README, *(os.path.join(DOCS, page) for page in ("learning.md", "cli.md"))],
                         ids=lambda p: os.path.relpath(p, REPO_ROOT))
def test_current_results_carry_no_history(path):
    """The README and the pages of current results hold current numbers with their commands: no commit hashes,
    no dates of runs, no session talk (dated run logs stay out of the documentation)."""
    for number, line in enumerate(read(path).splitlines(), 1):
        where = f"{os.path.relpath(path, REPO_ROOT)}:{number}"
        assert not COMMIT_HASH.search(line), f"{where} names a commit: {COMMIT_HASH.search(line).group()!r}"
        assert not DATE.search(line), f"{where} dates a run: {DATE.search(line).group()!r}"
        assert not re.search(r"\bsessions?\b", line, re.IGNORECASE), f"{where} mentions a session: {line.strip()!r}"


def test_history_checks_catch_what_they_are_for():
    assert COMMIT_HASH.search("timed at f0a75bd") and COMMIT_HASH.search("against 6f148d7,")
    assert not COMMIT_HASH.search("1000000 episodes, 3e-13 m, cu128, 1,217 passed, facade")
    assert DATE.search("(2026-12-03, f0a75bd)") and DATE.search("on December 3, 2026")
    assert not DATE.search("seeds 10^6 + e, 2,048 transitions, k = 0..99")


def test_readme_ppo_snippet_states_its_rollout_size():
    """The README's PPO snippet says how many SB3 envs and transitions per rollout it makes: check both."""
    text = read(README)
    snippet = re.search(r"```python\n(from stable_baselines3 import PPO\n.*?)```", text, re.DOTALL).group(1)
    name, copies = re.search(r'vector_env\("(\w+)", num_envs=(\d+)', snippet).groups()
    n_steps = int(re.search(r"n_steps=(\d+)", snippet).group(1))
    stated_copies, stated_agents, stated_envs = map(int, re.search(
        r"# (\d+) copies x (\d+) agents = (\d+) SB3 envs", snippet).groups())
    envs, steps, transitions = re.search(r"(\d+) envs x (\d+) steps = ([\d,]+) transitions", snippet).groups()
    venv = coloc_env.vector_env(name, num_envs=int(copies), seed=0)
    try:
        agents = len(coloc_env.parallel_env(name).possible_agents)
        assert (stated_copies, stated_agents) == (int(copies), agents)
        assert stated_envs == venv.num_envs == int(copies) * agents
        assert (int(envs), int(steps)) == (venv.num_envs, n_steps)
        assert int(transitions.replace(",", "")) == venv.num_envs * n_steps
    finally:
        venv.close()


def test_tests_look_for_the_mrclam_data_in_one_place():
    """Only tests/conftest.py says where the MRCLAM data are (COLOC_MRCLAM_DATA, else its default beside the
    clone): every other test imports MRCLAM_DATASET6 from there and skips with its one reason."""
    offenders = []
    for path in glob.glob(os.path.join(REPO_ROOT, "tests", "**", "*.py"), recursive=True):
        if os.path.basename(path) == "conftest.py":
            continue
        code = re.sub(r'"""(?:.|\n)*?"""', "", read(path))  # docstrings may name the default folder
        for pattern in (r"[\"']MRCLAM_Dataset6[\"']", r"[\"']shared[\"']\s*,\s*[\"']data[\"']",
                        r"environ(?:\.get)?\(\s*(?:mrclam\.ENV_VAR|[\"']COLOC_MRCLAM_DATA[\"'])\s*\)"):
            if re.search(pattern, code):
                offenders.append((os.path.relpath(path, REPO_ROOT), pattern))
    assert not offenders, f"tests that find the MRCLAM data on their own (use tests.conftest.MRCLAM_DATASET6): " \
                          f"{offenders}"


@pytest.mark.skipif(importlib.util.find_spec("mkdocs") is None or importlib.util.find_spec("mkdocstrings") is None,
                    reason="mkdocs / mkdocstrings-python are not installed (pip install -e '.[test]')")
def test_documentation_site_builds_strictly(tmp_path):
    """`make docs`'s build: every page and every docstring the API reference renders, with warnings as errors
    (a broken link, an unresolved cross-reference, a module that does not import)."""
    env = {**os.environ, "NO_MKDOCS_2_WARNING": "1", "PYTHONPATH": os.pathsep.join(
        [REPO_ROOT, *filter(None, [os.environ.get("PYTHONPATH")])])}
    done = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(tmp_path / "site")],
                          cwd=REPO_ROOT, capture_output=True, text=True, env=env)
    assert done.returncode == 0, done.stderr[-3000:]
    for page in ("index.html", "getting-started/index.html", "env-ids/index.html", "api/coloc_env/index.html",
                 "api/parts/index.html", "api/presets/index.html", "api/estimators/index.html",
                 "api/agents/index.html"):
        assert (tmp_path / "site" / page).is_file(), page
    # the presets' and parts' option tables are rendered from their docstrings
    assert read(str(tmp_path / "site" / "api" / "presets" / "index.html")).count("<table>") >= len(coloc_env.SCENARIOS)


@pytest.mark.skipif(shutil.which("make") is None, reason="make is not installed")
def test_make_docs_builds_strictly():
    printed = subprocess.run(["make", "-n", "-B", "docs"], cwd=REPO_ROOT, capture_output=True, text=True,
                             check=True).stdout
    assert [line for line in printed.splitlines() if "-m mkdocs build --strict" in line], printed


def test_navigation_leaves_out_pages_that_do_not_exist(tmp_path):
    """Pages the navigation names before they are written are dropped from it, sections left empty too."""
    sys.path.insert(0, REPO_ROOT)
    try:
        import mkdocs_hooks
    finally:
        sys.path.remove(REPO_ROOT)
    (tmp_path / "a.md").write_text("# a\n")
    (tmp_path / "api").mkdir()
    (tmp_path / "api" / "b.md").write_text("# b\n")
    nav = [{"A": "a.md"}, {"Missing": "missing.md"}, "a.md", "gone.md",
           {"Section": [{"B": "api/b.md"}, {"C": "api/c.md"}]}, {"Empty": [{"D": "d.md"}]},
           {"Site": "https://example.org"}]
    assert mkdocs_hooks._existing(nav, str(tmp_path)) == [
        {"A": "a.md"}, "a.md", {"Section": [{"B": "api/b.md"}]}, {"Site": "https://example.org"}]


SPHINX_ROLE = re.compile(r":(?:py:)?(?:func|class|meth|mod|data|attr|exc|obj|const|ref|doc):`")


def test_docstrings_use_no_sphinx_roles():
    """The API reference renders docstrings as Markdown, where a Sphinx role (:func:`x`) prints as it is
    written: names are code spans (``x``) or Markdown cross-references ([`x`][full.path])."""
    hits = []
    for package in ("coloc_env", "estimators", "agents", "train"):
        for path in sorted(glob.glob(os.path.join(REPO_ROOT, package, "**", "*.py"), recursive=True)):
            for number, line in enumerate(read(path).splitlines(), start=1):
                if SPHINX_ROLE.search(line):
                    hits.append(f"{os.path.relpath(path, REPO_ROOT)}:{number}: {line.strip()[:80]}")
    assert not hits, f"{len(hits)} Sphinx roles left, e.g.:\n" + "\n".join(hits[:10])
