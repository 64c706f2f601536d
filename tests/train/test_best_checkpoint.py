"""``coloc train`` keeps the best checkpoint on the validation seeds as model.zip, not the last one."""

import json
import os

import pytest

from train.training import train


def test_model_zip_is_the_checkpoint_with_the_lowest_validation_cost(tmp_path):
    path = train("bandwidth_fusion", timesteps=2 * 2048, seed=0, out=str(tmp_path), progress_bar=False,
                 curve_points=2)
    folder = os.path.dirname(path)
    with open(os.path.join(folder, "curve.json")) as handle:
        points = json.load(handle)["points"]
    with open(os.path.join(folder, "model.json")) as handle:
        chosen = json.load(handle)["checkpoint"]
    assert len(points) >= 2
    best = min(points, key=lambda p: p["mean_cost"])
    assert chosen["selected"] == "best on the validation seeds"
    assert chosen["timesteps"] == best["timesteps"] and chosen["validation_mean_cost"] == best["mean_cost"]
    with open(path, "rb") as a, open(os.path.join(folder, "best.zip"), "rb") as b:
        assert a.read() == b.read()
    assert os.path.isfile(os.path.join(folder, "last.zip"))


def test_without_a_curve_model_zip_is_the_last_weights(tmp_path):
    path = train("bandwidth_fusion", timesteps=1, seed=0, out=str(tmp_path), progress_bar=False, curve_points=0)
    with open(os.path.join(os.path.dirname(path), "model.json")) as handle:
        assert json.load(handle)["checkpoint"]["selected"] == "last (no validation curve)"
    assert not os.path.exists(os.path.join(os.path.dirname(path), "best.zip"))


def test_a_settings_module_sets_how_many_validation_episodes_score_each_point(tmp_path, monkeypatch):
    import train.hyperparams.bandwidth_fusion as settings

    monkeypatch.setattr(settings, "CURVE_EPISODES", 4, raising=False)
    path = train("bandwidth_fusion", timesteps=2 * 2048, seed=0, out=str(tmp_path), progress_bar=False,
                 curve_points=2)
    folder = os.path.dirname(path)
    with open(os.path.join(folder, "curve.json")) as handle:
        assert json.load(handle)["episodes"] == 4
    with open(os.path.join(folder, "model.json")) as handle:
        assert json.load(handle)["checkpoint"]["validation_episodes"] == 4


@pytest.mark.parametrize("bad", [1, 0, True, "16", 1e308, None, 16.0])
def test_a_bad_curve_episodes_setting_is_refused_before_training(tmp_path, monkeypatch, bad):
    import train.hyperparams.bandwidth_fusion as settings

    monkeypatch.setattr(settings, "CURVE_EPISODES", bad, raising=False)
    with pytest.raises(ValueError, match=r"CURVE_EPISODES of train/hyperparams/bandwidth_fusion.py must be an "
                                         r"integer >= 2"):
        train("bandwidth_fusion", timesteps=2048, seed=0, out=str(tmp_path), progress_bar=False)
    assert os.listdir(tmp_path) == []
