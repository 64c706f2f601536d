import os

import numpy as np
import pytest

import estimators.bandwidth_fusion as bf
from coloc_env.config import build_config
from coloc_env.scenarios.bandwidth_fusion import BandwidthFusionConfig

# Where the MRCLAM tests look for UTIAS MRCLAM dataset 6 (their pinned numbers are dataset 6's): the folder
# COLOC_MRCLAM_DATA names if it is set, else ../shared/data/mrclam/MRCLAM_Dataset6 beside the clone (the
# developers' layout). The data are not shipped: http://asrl.utias.utoronto.ca/datasets/mrclam/
REPO_ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
MRCLAM_DATA_ENV = "COLOC_MRCLAM_DATA"
MRCLAM_DATASET6 = os.environ.get(MRCLAM_DATA_ENV) or os.path.normpath(
    os.path.join(REPO_ROOT, "..", "shared", "data", "mrclam", "MRCLAM_Dataset6"))
MRCLAM_SKIP_REASON = (f"MRCLAM dataset 6 not found at {MRCLAM_DATASET6} (set {MRCLAM_DATA_ENV} to a MRCLAM_Dataset6 "
                      "folder from http://asrl.utias.utoronto.ca/datasets/mrclam/)")
# The MRCLAM likelihood fits and the oracle_static searches the tests need, shipped (tests/data/fit_cache,
# digest-checked entries of coloc_env.data.fit_cache): the tests read them instead of fitting for 17-24 s
# (searching for 13 s) per process, unless COLOC_FIT_CACHE names another cache. An entry gone stale (the
# code or inputs changed) is computed again and written there: commit the new file and delete the old one
# (tests/coloc_env/test_fit_cache.py and tests/agents/test_bandwidth_fusion_policies.py say so).
SHIPPED_FIT_CACHE = os.path.join(REPO_ROOT, "tests", "data", "fit_cache")
os.environ.setdefault("COLOC_FIT_CACHE", SHIPPED_FIT_CACHE)
RECORDED_WORLDS = ("mrclam", "mrclam_slices")  # the worlds that replay the MRCLAM data (a `data` field)
needs_mrclam = pytest.mark.skipif(not os.path.isdir(MRCLAM_DATASET6), reason=MRCLAM_SKIP_REASON)


def pytest_report_header(config):
    """The first lines of every run say where the MRCLAM tests look for their data, and whether it is there."""
    found = "found" if os.path.isdir(MRCLAM_DATASET6) else "not found: the MRCLAM tests skip"
    source = f"${MRCLAM_DATA_ENV}" if os.environ.get(MRCLAM_DATA_ENV) else f"default; set ${MRCLAM_DATA_ENV} to change"
    return f"MRCLAM dataset 6: {MRCLAM_DATASET6} ({source}; {found})"


@pytest.fixture
def mrclam_dataset6():
    """The dataset-6 folder, or a skip that names the path looked at and the environment variable."""
    if not os.path.isdir(MRCLAM_DATASET6):
        pytest.skip(MRCLAM_SKIP_REASON)
    return MRCLAM_DATASET6


@pytest.fixture
def paper_config():
    return build_config(BandwidthFusionConfig, {})


@pytest.fixture
def paper_model(paper_config):
    return paper_config.fusion_model()


def random_selection(rng, N=4, n=3):
    """A random T with T_ii = I (any number of components per link)."""
    sel = rng.random((N, N, n)) < 0.5
    sel[np.arange(N), np.arange(N)] = True
    return sel


def random_weights(rng, N=4):
    w = rng.random((N, N)) + 0.05
    return w / w.sum(axis=1, keepdims=True)


__all__ = ["MRCLAM_DATASET6", "MRCLAM_SKIP_REASON", "RECORDED_WORLDS", "bf", "needs_mrclam", "random_selection",
           "random_weights"]
