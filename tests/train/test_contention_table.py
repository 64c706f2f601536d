"""``python -m train.contention``: the benchmark table of docs/contention.md, on two episodes."""

import re

import pytest

from train import contention


def _row(text: str, first: str) -> list[str]:
    line = next(line for line in text.splitlines() if line.startswith(f"| {first} |"))
    return [cell.strip() for cell in line.strip("|").split("|")]


def _mean(cell: str) -> float:
    return float(cell.split("±")[0])


def test_the_table_shows_collisions_costing_always_and_round_robin_bound_below(capsys):
    assert contention.main(["--episodes", "2", "--bound-episodes", "1"]) == 0
    text = capsys.readouterr().out
    always, round_robin, silent = (_row(text, f"`{name}`") for name in ("always", "round_robin", "silent"))
    # collisions: every UAV sends every frame under always, yet round robin's fewer frames arrive more often
    assert _mean(always[3]) > _mean(round_robin[3])
    assert _mean(round_robin[4]) > _mean(always[4])
    assert _mean(silent[3]) == 0 and _mean(silent[4]) == 0
    assert _mean(always[2]) == 0  # always's paired difference to itself
    bound_rows = [line for line in text.splitlines()
                  if re.fullmatch(r"\| `(always|round_robin)` \| [0-9.]+ \| [0-9.]+ \| [0-9.]+ \|", line)]
    (_, central_a, _, delivered_a), (_, central_r, _, delivered_r) = (
        [cell.strip() for cell in line.strip("|").split("|")] for line in bound_rows)
    assert central_a == central_r  # the centralized bound does not depend on the schedule
    assert float(central_r) <= float(delivered_r) < float(delivered_a)


@pytest.mark.parametrize("argv", [["--episodes", "1"], ["--bound-episodes", "0"]])
def test_bad_episode_counts_are_refused(argv, capsys):
    with pytest.raises(SystemExit):
        contention.main(argv)
    assert "--episodes must be in 2..100000" in capsys.readouterr().err
