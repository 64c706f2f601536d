"""numba's disk cache files a compiled function by its qualified name: a threaded form compiled from a copy that
kept the serial form's qualified name shares the serial form's entry, and one process may load the other's code
(a threaded kernel running on one thread). Every threaded form of dNBP has its own qualified name (afge's:
tests/estimators/test_afge_fast.py)."""

from __future__ import annotations

import pytest

import estimators.dnbp_kernels as dnbp_kernels
from estimators.compiled import in_namespace


def _pairs():
    pairs = dict(dnbp_kernels.compiled_kernels() or {})
    fused = dnbp_kernels.fused_kernels() or {}
    pairs.update({f"fused {k}": v for k, v in fused.items() if isinstance(v, tuple)})
    return pairs


def test_every_threaded_form_is_a_parallel_copy_under_its_own_qualified_name():
    pairs = _pairs()
    if not pairs:
        pytest.skip("numba is not installed")
    assert len(pairs) == 6  # three row kernels, three fused ones
    for name, (serial, threaded) in pairs.items():
        assert not serial.targetoptions.get("parallel"), name
        assert threaded.targetoptions.get("parallel"), name
        assert threaded.py_func.__qualname__ == serial.py_func.__qualname__ + "_threaded", name
        assert threaded.py_func.__name__ == serial.py_func.__name__ + "_threaded", name


def test_in_namespace_renames_and_rebinds_globals():
    def source(x):
        return helper(x) + 1  # noqa: F821 - resolved in the namespace

    copy = in_namespace(source, {"helper": lambda x: 10 * x}, "_threaded")
    assert copy(2) == 21
    assert copy.__name__ == "source_threaded" and copy.__qualname__.endswith("source_threaded")
    assert copy.__module__ == source.__module__
