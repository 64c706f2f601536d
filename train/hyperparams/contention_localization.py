"""PPO settings for ``contention_localization`` (set by reasoning and two 1M-timestep probes on validation
episodes; never the evaluation seeds).

* ``communication_cost=0`` (``--cost-range none``): the medium itself prices a frame (a frame that collides
  destroys another's), so the decision already trades off without an extra price; ``always`` and ``silent``
  give the same error there (docs/contention.md), ``round_robin`` halves it.
* ``ACTIONS = "sampled"``: every UAV runs the same network on observations that differ little, so a
  deterministic policy sends or stays silent in step with its neighbours, and on one slot that is a collision
  or silence. A probe at 1M timesteps (cost range below, seed 0; 16 validation episodes, seeds 2 * 10^6 + e)
  took its most likely actions to silence at every cost from 10 up (25.88 m) and to 0.30 frames per agent-step
  at cost 1 (19.98 m), while the same network's sampled actions gave 16.95 / 14.40 / 17.84 / 24.50 m at costs
  1 / 10 / 30 / 100 with 0.31 / 0.12 / 0.054 / 0.008 frames per agent-step: a random-access policy whose rate
  follows the price. The learning curve therefore scores sampled actions, and evaluation plays them.
* ``COST_RANGE = (1, 300)`` per frame, log-uniform: the validation frontier (``coloc frontier
  contention_localization --seed 2000000 --quick --episodes 16 --bound-episodes 1``) has chords of 214 (``silent``
  to ``aloha:0.05``) and 131 m per frame per agent-step (``aloha:0.05`` to ``paper``); a UAV pays for its own
  frames but its reward is its own error, which a frame of its own lowers by between 1/N and all of the
  team's change, so the prices that move its choice lie between ~13 and ~214. The range reaches past both ends.
* ``COST_REWARD_SCALE = 30``: each step's reward is divided by 1 + c / 30, so at c = 300 a priced step stays
  within a factor ~10 of the error (tens of metres) and the expensive episodes do not set the advantage scale.
* 2M timesteps, twice the probe's budget (the trained models' learning curves flatten after 200k).
* Reward: each UAV's own realized error of the centre's estimate (the composition's ``reward="error"``); the
  centre's estimate is shared, so every UAV's decision moves every UAV's error. The second probe, on
  ``reward="trace"``, gave the same regime (14.56 m at 0.13 frames per agent-step at cost 10).
* A delivered reading mostly helps the current step and, through the joint UKF's covariance, the next few:
  gamma 0.9, GAE 0.95; 30-step episodes.
* 10 agents x 8 copies = 80 sub-envs, n_steps 60 (two episodes) -> 4,800 transitions per update (batches of
  600); small networks (64, 64): the observation has 3N + 7 + 1 world feature + 1 acknowledgement = 39 numbers.
"""

from train.hyperparams import ppo

ENV_CONFIG: dict = {}

HYPERPARAMS = ppo(n_steps=60, batch_size=600, gamma=0.9, ent_coef=0.01)

NUM_COPIES = 8
TIMESTEPS = 2_000_000
COST_RANGE = (1.0, 300.0)
COST_REWARD_SCALE = 30.0
ACTIONS = "sampled"

# The leaderboard's target for a learned policy: (what it says, the largest |paired error difference| relative to
# the baseline's mean that counts as matching it, the communication saving a match needs).
LEADERBOARD_TARGET = ("beat the strongest baseline, or match it with 30 % fewer frames", 0.02, 0.30)

# ``coloc bench``: its batch sizes (the joint UKF over 10 UAVs at B = 1024 would take minutes per row).
BENCH_BATCHES = (1, 8, 64)
