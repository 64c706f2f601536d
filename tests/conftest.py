import numpy as np
import pytest

import estimators.bandwidth_fusion as bf
from coloc_env.config import build_config
from coloc_env.scenarios.bandwidth_fusion import BandwidthFusionConfig


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


__all__ = ["bf", "random_selection", "random_weights"]
