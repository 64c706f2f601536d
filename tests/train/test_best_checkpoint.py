"""``coloc train`` keeps the best checkpoint on the validation seeds as model.zip (issue 15), not the last one."""

import json
import os

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
