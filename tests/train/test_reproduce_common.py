"""train.reproduce.common: the blocks, the standard errors and the claims section the reproductions share."""

import numpy as np
import pytest
import scipy.stats

from train.reproduce.common import block_sizes, ci95, claims_section, mean_se


def test_block_sizes_cover_the_runs_with_the_rest_last():
    assert block_sizes(250, 100) == [100, 100, 50]
    assert block_sizes(200, 100) == [100, 100]
    assert block_sizes(7, 25) == [7]
    assert block_sizes(0, 25) == []
    with pytest.raises(ValueError, match="block must be >= 1"):
        block_sizes(10, 0)


def test_mean_se_and_ci95_are_the_sample_mean_and_standard_error():
    values = np.random.default_rng(0).normal(3.0, 2.0, size=37)
    mean, se = mean_se(values)
    assert mean == pytest.approx(values.mean(), rel=1e-12)
    assert se == pytest.approx(scipy.stats.sem(values), rel=1e-12)
    assert ci95(values) == pytest.approx(1.96 * scipy.stats.sem(values), rel=1e-12)
    with pytest.raises(ValueError, match="at least 2 runs"):
        mean_se([1.0])


def test_claims_section_heads_the_claims_table():
    claims = [{"id": "a", "claim": "x beats y", "ours": "1 < 2", "criterion": "smaller", "holds": True}]
    lines = claims_section(claims)
    assert lines[:2] == ["## Claims", ""]
    assert any("x beats y" in line for line in lines[2:])
