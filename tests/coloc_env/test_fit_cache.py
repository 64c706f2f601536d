"""The on-disk fit cache (coloc_env.data.fit_cache) and the MRCLAM likelihood fit through it."""

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from coloc_env.data import fit_cache
from tests.conftest import REPO_ROOT, SHIPPED_FIT_CACHE, needs_mrclam


def _sound(value):
    return isinstance(value, dict) and value.get("scale", 0) > 0


class Counting:
    """A compute function that counts its calls."""

    def __init__(self, value):
        self.value, self.calls = value, 0

    def __call__(self):
        self.calls += 1
        return dict(self.value)


def test_a_stored_value_is_read_back_instead_of_computed(tmp_path):
    compute = Counting({"scale": 2.5})
    assert fit_cache.cached("fit", "a" * 64, compute, _sound, tmp_path) == {"scale": 2.5}
    assert fit_cache.cached("fit", "a" * 64, compute, _sound, tmp_path) == {"scale": 2.5}
    assert compute.calls == 1
    assert [p.name for p in tmp_path.glob("*.json")] == [f"fit-{'a' * 32}.json"]
    assert not list(tmp_path.glob(".tmp-*"))


@pytest.mark.parametrize("damage", ["truncated", "value edited", "digest edited", "other key", "refused", "not json"])
def test_a_corrupt_or_stale_entry_is_computed_again_and_replaced(tmp_path, damage):
    key = "b" * 64
    fit_cache.cached("fit", key, Counting({"scale": 2.5}), _sound, tmp_path)
    path = fit_cache.entry_path(str(tmp_path), "fit", key)
    with open(path) as fh:
        text = fh.read()
    entry = json.loads(text)
    if damage == "truncated":
        text = text[: len(text) // 2]
    elif damage == "value edited":  # the digest no longer matches
        entry["value"]["scale"] = 9.0
        text = json.dumps(entry)
    elif damage == "digest edited":
        entry["digest"] = "0" * 64
        text = json.dumps(entry)
    elif damage == "other key":  # the same file name (the key's first 32 digits), another key: stale
        other = "b" * 32 + "c" * 32
        text = json.dumps({**entry, "key": other, "digest": fit_cache._digest(other, entry["value"])})
    elif damage == "refused":  # sound on disk, but the caller's check refuses the value
        value = {"scale": -1.0}
        text = json.dumps({**entry, "value": value, "digest": fit_cache._digest(key, value)})
    else:
        text = "\x00\xff not json"
    with open(path, "w") as fh:
        fh.write(text)
    compute = Counting({"scale": 2.5})
    assert fit_cache.cached("fit", key, compute, _sound, tmp_path) == {"scale": 2.5}
    assert compute.calls == 1
    assert fit_cache.read(path, key, _sound) == {"scale": 2.5}  # replaced by a sound entry


def _arrays():
    rng = np.random.default_rng(0)
    return {"poses": rng.normal(size=(4, 2, 3)), "accepted": rng.random(5) < 0.5}


def _sound_arrays(arrays):
    return set(arrays) == {"poses", "accepted"} and arrays["poses"].shape == (4, 2, 3)


@pytest.mark.parametrize("damage", [None, "truncated", "array edited", "other key", "refused"])
def test_stored_arrays_come_back_bit_for_bit_and_a_bad_entry_is_computed_again(tmp_path, damage):
    key = "d" * 64
    expected = _arrays()
    compute = Counting(expected)
    first = fit_cache.cached_arrays("nav", key, compute, _sound_arrays, tmp_path)
    path = fit_cache.entry_path(str(tmp_path), "nav", key, ".npz")
    assert os.path.exists(path) and not list(tmp_path.glob(".tmp-*"))
    if damage == "truncated":
        with open(path, "rb") as fh:
            data = fh.read()
        with open(path, "wb") as fh:
            fh.write(data[: len(data) // 2])
    elif damage is not None:
        changed = {name: value.copy() for name, value in expected.items()}
        entry_key = key
        if damage == "array edited":  # stored under the old digest: no longer matches
            with np.load(path) as entry:
                meta = str(entry["__entry__"])
            changed["poses"][0, 0, 0] += 1e-12
            np.savez(path, __entry__=np.array(meta), **changed)  # path ends in .npz: written as it is
        else:
            if damage == "other key":
                entry_key = "d" * 32 + "e" * 32
            else:  # refused: a sound entry the caller's check rejects
                changed = {"poses": np.zeros((1, 1, 3)), "accepted": changed["accepted"]}
            fit_cache.write_arrays(path, entry_key, changed)
    second = fit_cache.cached_arrays("nav", key, compute, _sound_arrays, tmp_path)
    assert compute.calls == (1 if damage is None else 2)
    for arrays in (first, second):
        assert set(arrays) == set(expected)
        for name in expected:
            assert arrays[name].dtype == expected[name].dtype and np.array_equal(arrays[name], expected[name])


def test_the_folder_comes_from_the_argument_then_the_variable_then_the_user_cache(tmp_path, monkeypatch):
    monkeypatch.delenv(fit_cache.ENV_VAR, raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert fit_cache.cache_dir() == os.path.join(str(tmp_path / "xdg"), "coloc", "fits")
    monkeypatch.setenv(fit_cache.ENV_VAR, str(tmp_path / "env"))
    assert fit_cache.cache_dir() == str(tmp_path / "env")
    assert fit_cache.cache_dir(tmp_path / "arg") == str(tmp_path / "arg")
    monkeypatch.setenv(fit_cache.ENV_VAR, "off")
    assert fit_cache.cache_dir() is None
    compute = Counting({"scale": 1.0})
    fit_cache.cached("fit", "d" * 64, compute, _sound)
    fit_cache.cached("fit", "d" * 64, compute, _sound)
    assert compute.calls == 2  # off: nothing stored


def test_an_unwritable_folder_computes_and_stores_nothing(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("")
    compute = Counting({"scale": 1.0})
    assert fit_cache.cached("fit", "e" * 64, compute, _sound, blocker / "cache") == {"scale": 1.0}
    assert compute.calls == 1


PARALLEL_WORKER = """
import sys, time
from coloc_env.data import fit_cache

def compute():
    with open(sys.argv[2], "a") as fh:
        fh.write("computed\\n")
    time.sleep(0.5)  # long enough that the other process asks while this one computes
    return {"scale": 3.0}

print(fit_cache.cached("fit", "f" * 64, compute, lambda v: v["scale"] > 0, sys.argv[1]))
"""


def test_processes_that_miss_at_once_compute_once(tmp_path):
    """Two processes ask for one missing entry at the same time: one computes under the lock, the other waits
    and reads what it wrote."""
    log = tmp_path / "log"
    children = [subprocess.Popen([sys.executable, "-c", PARALLEL_WORKER, str(tmp_path / "cache"), str(log)],
                                 cwd=REPO_ROOT, stdout=subprocess.PIPE, text=True) for _ in range(2)]
    outputs = [child.communicate(timeout=120)[0] for child in children]
    assert [child.returncode for child in children] == [0, 0]
    assert outputs == ["{'scale': 3.0}\n"] * 2
    assert log.read_text() == "computed\n"


FIT_WORKER = """
import json, sys
from coloc_env.data import fit_cache, mrclam, mrclam_noise

d = mrclam.load_cached(sys.argv[1])
noise = mrclam_noise.calibrate_noise(d, 60.0)
fit = mrclam_noise.fit_noise_scales(d, noise, 10, cache_dir=sys.argv[2])
print(json.dumps({"fit": fit, "stats": dict(fit_cache.STATS)}))
"""


@needs_mrclam
def test_a_second_process_reads_the_mrclam_fit_instead_of_fitting(tmp_path, mrclam_dataset6):
    """fit_noise_scales on a 10-step window (a second of fitting) in two processes, one after the other, with one
    cache folder: the first fits, the second reads its result (fit_cache.STATS: nothing computed) bit for bit."""
    def run():
        done = subprocess.run([sys.executable, "-c", FIT_WORKER, mrclam_dataset6, str(tmp_path)], cwd=REPO_ROOT,
                              capture_output=True, text=True, check=True, timeout=300)
        return json.loads(done.stdout.strip().splitlines()[-1])

    first, second = run(), run()
    assert first["stats"] == {"computed": 1}
    assert second["stats"] == {"disk": 1}
    assert second["fit"] == first["fit"]
    assert len(list(tmp_path.glob("mrclam-likelihood-*.json"))) == 1


@needs_mrclam
def test_the_shipped_dataset6_fit_is_current(mrclam_dataset6):
    """The tests read dataset 6's default likelihood fit from tests/data/fit_cache (conftest): it must be the entry of
    the current code and data, or every process fits for 17-24 s. When this fails the fit's code or inputs
    changed: run the MRCLAM tests once (they write the new entry there), commit it and delete the stale one."""
    from coloc_env.data import mrclam, mrclam_noise
    d = mrclam.load_cached(mrclam_dataset6)
    noise = mrclam_noise.calibrate_noise(d, mrclam_noise.calibration_seconds(d, "likelihood"))
    steps = int(round(noise["calibration_s"] / d.dt))
    key = mrclam_noise._fit_key(d, noise, steps, 0.01, mrclam_noise.GATE_999)
    path = fit_cache.entry_path(SHIPPED_FIT_CACHE, "mrclam-likelihood", key)
    fit = fit_cache.read(path, key, lambda v: mrclam_noise._sound_fit(v, steps))
    assert fit is not None, f"no current entry {os.path.basename(path)} in {SHIPPED_FIT_CACHE}"
    assert fit["likelihood_converged"] and fit["likelihood_steps"] == steps
