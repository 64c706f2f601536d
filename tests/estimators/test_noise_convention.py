"""The noise convention of ``estimators`` (its package docstring): variances and covariances inside the library;
a standard deviation only where a paper's parameter is one, named so and said so in a docstring."""

from __future__ import annotations

import ast
import glob
import os
import re

import estimators

REPO_ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
STD_NAME = re.compile(r"(?:^|_)std(?:$|_)|(?:^|_)sigma_|_sigma$")  # a parameter named as a standard deviation
SAYS_STD = re.compile(r"standard\s+deviation", re.IGNORECASE)


def std_parameters_not_said(source: str) -> list[tuple[str, str]]:
    """(owner, parameter) for every function argument or dataclass field named as a standard deviation whose
    function's or class's docstring, and the module's, never says "standard deviation"."""
    tree = ast.parse(source)
    module_says = bool(SAYS_STD.search(ast.get_docstring(tree) or ""))
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
            names = [a.arg for a in (*node.args.posonlyargs, *node.args.args, *node.args.kwonlyargs)]
        elif isinstance(node, ast.ClassDef):
            names = [s.target.id for s in node.body if isinstance(s, ast.AnnAssign) and isinstance(s.target, ast.Name)]
        else:
            continue
        if module_says or SAYS_STD.search(ast.get_docstring(node) or ""):
            continue
        found += [(node.name, name) for name in names if STD_NAME.search(name)]
    return found


def test_the_convention_is_stated_in_the_package_docstring():
    doc = estimators.__doc__ or ""
    assert "variance or a covariance" in doc and SAYS_STD.search(doc)


def test_the_check_finds_what_it_is_for():
    assert std_parameters_not_said('def f(range_std, x):\n    """Update."""\n') == [("f", "range_std")]
    assert std_parameters_not_said("class M:\n    sigma_db: float = 2.0\n    nlos_sigma_db: float = 4.0\n"
                                   "    gain_sigma: float = 1.0\n") == [("M", "sigma_db"), ("M", "nlos_sigma_db"),
                                                                     ("M", "gain_sigma")]
    said = 'def f(range_std):\n    """``range_std``: the standard deviation of a range, m."""\n'
    assert std_parameters_not_said(said) == []
    assert std_parameters_not_said('def f(range_var, sigma, stdout):\n    """Update."""\n') == []


def test_every_standard_deviation_parameter_says_so():
    unsaid = []
    for path in sorted(glob.glob(os.path.join(REPO_ROOT, "estimators", "*.py"))):
        with open(path, encoding="utf-8") as handle:
            unsaid += [f"{os.path.relpath(path, REPO_ROOT)}: {owner}.{name}"
                       for owner, name in std_parameters_not_said(handle.read())]
    assert not unsaid, "named as standard deviations, never said so in a docstring:\n" + "\n".join(unsaid)
