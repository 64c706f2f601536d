"""Every flag that takes a count or a seed parses exactly the integers of its stated range: hypothesis draws
integers around and far beyond the bounds, and text that is not an integer (derandomized: the same examples on
every run). An accepted value is the integer given; a refused one exits 2 naming the flag and its range."""

from __future__ import annotations

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from train.cli import MAX_CURVE_POINTS, MAX_HORIZON, MAX_RUNS, MAX_SEED, MAX_TIMESTEPS, build_parser, main

settings.register_profile("cli_counts", max_examples=60, deadline=None, derandomize=True,
                          suppress_health_check=list(HealthCheck))

STUDY = ["study", "--world", "circles", "--network", "relay", "--backends", "ukf_dcl"]
# (command line before the flag, flag, attribute, low, high)
FLAGS = [
    (["reproduce", "zhao2020"], "--runs", "runs", 1, MAX_RUNS),
    (["reproduce", "zhao2020"], "--seed", "seed", 0, MAX_SEED),
    (["train", "relay_ukf"], "--timesteps", "timesteps", 1, MAX_TIMESTEPS),
    (["train", "relay_ukf"], "--seed", "seed", 0, MAX_SEED),
    (["train", "relay_ukf"], "--curve-points", "curve_points", 0, MAX_CURVE_POINTS),
    (["evaluate", "relay_ukf"], "--episodes", "episodes", 2, MAX_RUNS),
    (["bench", "--against", "HEAD"], "--rounds", "rounds", 1, 20),
    (STUDY, "--episodes", "episodes", 2, MAX_RUNS),
    (STUDY, "--seed", "seed", 0, MAX_SEED),
    (STUDY, "--horizon", "horizon", 1, MAX_HORIZON),
]


def values(low: int, high: int):
    near = st.integers(low - 3, low + 3) | st.integers(high - 3, high + 3)
    far = st.integers(-10**40, 10**40) | st.integers(high, 10**40)
    as_text = (near | far).map(str)
    not_integers = st.sampled_from(["", " ", "1.5", "1e3", "0x10", "abc", "--", "1_000", "٣", "+-1", "nan", "inf"])
    return as_text | not_integers | st.text(max_size=4)


@pytest.mark.parametrize("prefix, flag, attribute, low, high", FLAGS, ids=lambda v: v if isinstance(v, str) else None)
def test_a_count_flag_takes_exactly_its_range(prefix, flag, attribute, low, high, capsys):
    parser = build_parser()

    @settings(settings.get_profile("cli_counts"))
    @given(values(low, high))
    def check(text):
        stripped = text.strip()
        body = stripped[1:] if stripped[:1] in "+-" else stripped
        in_range = body.isascii() and body.isdigit() and low <= int(stripped) <= high
        if in_range:
            assert getattr(parser.parse_args([*prefix, f"{flag}={text}"]), attribute) == int(stripped)
            return
        with pytest.raises(SystemExit) as exit_info:
            main([*prefix, f"{flag}={text}"])
        assert exit_info.value.code == 2
        err = capsys.readouterr().err
        expected = ("expected a value, got '--'" if text == "--"
                    else f"must be an integer in [{low}, {high}], got {text!r}")
        assert f"argument {flag}: {expected}" in err, err

    check()
