"""PPO settings for ``contention_localization`` (set by reasoning; not tuned, no model trained yet).

* ``communication_cost=0``: the medium itself prices a frame (a frame that collides destroys another's), so
  the decision already trades off without an extra price; ``always`` and ``silent`` give the same error
  there (docs/contention.md), ``round_robin`` halves it.
* Reward: each UAV's own realized error of the centre's estimate (the composition's ``reward="error"``); the
  centre's estimate is shared, so every UAV's decision moves every UAV's error.
* A delivered reading mostly helps the current step and, through the joint UKF's covariance, the next few:
  gamma 0.9, GAE 0.95; 30-step episodes.
* 10 agents x 8 copies = 80 sub-envs, n_steps 60 (two episodes) -> 4,800 transitions per update (batches of
  600); small networks (64, 64): the observation has 3N + 7 + 1 world feature + 1 acknowledgement = 39 numbers.
"""

from train.hyperparams import ppo

ENV_CONFIG: dict = {}

HYPERPARAMS = ppo(n_steps=60, batch_size=600, gamma=0.9, ent_coef=0.01)

NUM_COPIES = 8
TIMESTEPS = 200_000

# The leaderboard's target for a learned policy: (what it says, the largest |paired error difference| relative to
# the baseline's mean that counts as matching it, the communication saving a match needs).
LEADERBOARD_TARGET = ("beat the strongest baseline, or match it with 30 % fewer frames", 0.02, 0.30)

# ``coloc bench``: its batch sizes (the joint UKF over 10 UAVs at B = 1024 would take minutes per row).
BENCH_BATCHES = (1, 8, 64)
