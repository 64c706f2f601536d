"""train/bounds_table.py: the table of every generative composition, resumable, regenerating the docs' tables."""

import json

import pytest

import coloc_env
from coloc_env.bounds.models import generative_worlds
from train import bounds_table


def test_every_compatible_generative_composition_is_listed_once():
    names = bounds_table.compositions()
    expected = {f"{r['world']}/{r['network']}/{r['backend']}" for r in coloc_env.compatibility()
                if r["ok"] and r["world"] in generative_worlds()}
    assert len(names) == len(set(names)) and set(names) == expected
    assert not any(name.startswith("mrclam") for name in names)  # recorded data: model-based bounds


def test_a_run_writes_its_rows_and_the_table_and_a_rerun_reuses_them(tmp_path, capsys):
    out = str(tmp_path / "table")
    name = "drift/bernoulli_delay/bandwidth_fusion"
    assert bounds_table.main(["--episodes", "2", "--only", name, "--out", out]) == 0
    row = json.loads((tmp_path / "table" / "rows" / "drift_bernoulli_delay_bandwidth_fusion.json").read_text())
    assert row["rmse"] == pytest.approx(row["eff_c"] * row["centralized"], rel=1e-12)
    assert row["rmse"] == pytest.approx(row["eff_d"] * row["delivered"], rel=1e-12)
    assert row["local"] >= row["delivered"] >= row["centralized"] > 0
    assert f"| `{name}` |" in (tmp_path / "table" / "bounds_table.md").read_text()
    assert "1 computed" in capsys.readouterr().out
    assert bounds_table.main(["--episodes", "2", "--only", name, "--out", out]) == 0
    assert "0 computed" in capsys.readouterr().out
    assert bounds_table.main(["--episodes", "3", "--only", name, "--out", out]) == 0  # other settings: computed
    assert "1 computed" in capsys.readouterr().out
    assert bounds_table.main(["--episodes", "3", "--only", name, "--out", out, "--fresh"]) == 0
    assert "1 computed" in capsys.readouterr().out


def test_the_generated_part_of_a_doc_is_replaced_and_a_doc_without_markers_refused(tmp_path):
    doc = tmp_path / "doc.md"
    doc.write_text(f"head\n{bounds_table.BEGIN}\nold\n{bounds_table.END}\ntail\n")
    bounds_table.replace_generated(str(doc), "new\n")
    assert doc.read_text() == f"head\n{bounds_table.BEGIN}\nnew\n{bounds_table.END}\ntail\n"
    doc.write_text("no markers\n")
    with pytest.raises(ValueError, match="no <!-- bounds-table: begin --> ... <!-- bounds-table: end --> markers"):
        bounds_table.replace_generated(str(doc), "new\n")


def test_bad_arguments_are_named(capsys):
    with pytest.raises(SystemExit):
        bounds_table.main(["--episodes", "1"])
    assert "--episodes must be in [2, 1000], got 1" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        bounds_table.main(["--only", "circles/ideal/kalman"])
    assert "--only: not a compatible generative composition: ['circles/ideal/kalman']" in capsys.readouterr().err
