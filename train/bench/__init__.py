"""``coloc bench``: throughput of every registered scenario, measured in one run.

Per scenario, in env-steps per second (one copy advancing one time step with
all its agents; agent-steps = env-steps x N):

* ``parallel_env``  a Python loop over the PettingZoo env (B = 1);
* ``supersuit``     SuperSuit's ``concat_vec_envs_v1`` over B copies;
* ``vector_env``    coloc's batched SB3 VecEnv at B = 1, 64, 1024 (copy b plays
  the episode of seed b, as in training);
* ``vector_env, one episode``  the same with every copy playing episode 0, for
  the scenarios whose work per copy depends on the episode
  (``ONE_EPISODE_ROWS``: gps_denied_nbp), so that the rows at different B
  time the same work per copy and show what batching itself buys;
* ``estimator step``  the raw batched estimator step at the same B, where the
  scenario registers one in ``ESTIMATOR_STEPS``; the table's ``env / est.``
  column (``env_time_over_estimator`` in the JSON, on the vector_env row) is the
  env's time per step over it, so the env's overhead is read off directly.
  Every preset's row but gps_denied_nbp's replays the estimator calls its
  backend made in a recorded vector_env rollout at that B
  (``BACKEND_CALLS``, ``record_backend_calls``, ``replay_step``):
  the same functions on the same shapes and inputs as the env's step
  (relay_ukf, mrclam_relay, nlos_horizon, lossy_fusion, bandwidth_fusion).
  gps_denied_nbp's steps dNBP over its own sampled episode at the env's sizes;
* peers            for relay_ukf, filterpy's ``UnscentedKalmanFilter`` doing one
  full-chain range update one copy at a time (``PEERS``), beside our
  ``dcl_update`` doing the same update for the B copies at once;
* ``construction, warm fit cache``  mrclam_relay only: seconds to build the env at its defaults in a fresh
  process once the likelihood fit is in the disk cache (``coloc_env.data.fit_cache``), the best of 3
  (``construction_s``; the row's rate is its inverse);
* ``pcrb, one episode``  ``coloc_env.pcrb`` of one episode (its play, backend idle where it
  may be, and the recursion), in env-steps per second, beside the backend's step; where messages carry
  estimates it includes the backend's own run (its deliveries define the information sets) and the sets'
  forward passes of the information-set delivered bound (docs/bounds.md, its cost before and after);
* ``vmas``          VMAS's batched ``simple_spread`` with 4 agents on the CPU at
  the same B, when ``vmas`` is installed (``pip install 'coloc[bench]'``).

Every env is driven by its ``paper`` policy's actions, computed once and tiled,
except where those change over an episode and use no measurement at reset
(relay_ukf, mrclam_relay: ``ActionSource``).
Writes ``OUT/bench/bench.json`` (atomic) and ``OUT/bench/throughput.png``.
No test asserts a speed: this is where speed is reported.

``coloc bench --against REF`` (``run_against``) measures the current
tree and a previous commit side by side in one run: REF is exported with
``git archive`` into a temporary folder, and per scenario the same rows are
measured for the current tree and for REF, each in its own subprocess of the
same interpreter with that tree first on ``sys.path`` (so the same installed
libraries, the same batches and the same machine load), in two alternating
rounds (current, REF, REF, current) keeping each row's best rate. Writes
``OUT/bench/against.json`` with both rates and the ratio current / REF per
(scenario, what, batch).

One module per kind of measurement, behind the one ``coloc bench`` command: ``throughput`` (the rows above,
``bench_scenario`` and ``run``), ``replay`` (a rollout's estimator calls recorded and replayed, and the
actions that drive the rows), ``peers`` (VMAS and filterpy), ``against`` (``--against REF``), ``scaling``
(``--scaling``) and ``measure`` (``per_second``, the rate every row reports).
"""

from coloc_env.config import module_names
from train.bench.against import bench_tree, compare_rows, export_commit, repository_root, run_against
from train.bench.measure import BATCHES, per_second
from train.bench.peers import PEERS, bench_vmas
from train.bench.replay import (
    BACKEND_CALLS,
    ActionSource,
    BackendTape,
    paper_actions,
    record_backend_calls,
    replay_step,
)
from train.bench.scaling import growth_exponent, run_scaling, scaling_compositions, scaling_row, scaling_world
from train.bench.throughput import (
    ESTIMATOR_STEPS,
    ONE_EPISODE,
    ONE_EPISODE_ROWS,
    SCENARIO_BATCHES,
    add_overheads,
    bench_scenario,
    one_episode_rate,
    run,
)

__all__ = ["BACKEND_CALLS", "BATCHES", "ESTIMATOR_STEPS", "ONE_EPISODE", "ONE_EPISODE_ROWS", "PEERS",
           "SCENARIO_BATCHES", "ActionSource", "BackendTape", "add_overheads", "bench_scenario", "bench_tree",
           "bench_vmas", "compare_rows", "export_commit", "growth_exponent", "one_episode_rate", "paper_actions",
           "per_second", "record_backend_calls", "replay_step", "repository_root", "run", "run_against", "run_scaling",
           "scaling_compositions", "scaling_row", "scaling_world"]


# the name of ``per_second`` when train.bench was one module
__getattr__ = module_names(__name__, {"_rate": lambda: per_second},
                           deprecated={"_rate": "it is train.bench.measure.per_second"})
