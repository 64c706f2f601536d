"""PPO settings for ``relay_ukf`` (set by reasoning, not tuned on evaluation seeds).

* ``reward="error"``: the team's mean distance error, the paper's metric. The
  filter's own covariance (``"trace"``) would be a less noisy signal, but the
  filter is overconfident under turn-rate noise (see the wang2019 report), so
  it would reward the wrong thing.
* ``hop_cost=0.01`` m per delivered hop: the target is the full chain's error
  with fewer hops, and without a price on hops a hop that helps by a hair is
  still worth sending. One centimetre is small against the ~1.5 m mean error,
  so only hops that move the team's mean error by less than 1 cm are worth
  dropping. The leaderboard reports the error without this term (the
  scenario's ``error`` info) and the hops separately.
* Episodes are 800 steps and a relay decision pays off over the following
  tens of steps (until the next measurements overwrite it): gamma 0.99
  (horizon ~ 100 steps), GAE 0.95.
* 4 agents x 4 copies = 16 sub-envs, n_steps 128 -> 2048 transitions per update.
* Small networks (64, 64): the observation has 2N + 3 = 11 numbers.
* A little entropy (0.01): the relay choice only matters when the location
  information reaches the agent, so most samples carry no gradient and the
  policy should not collapse early.
"""

ENV_CONFIG = {"reward": "error", "hop_cost": 0.01}

HYPERPARAMS = {
    "n_steps": 128,
    "batch_size": 256,
    "n_epochs": 10,
    "learning_rate": 3e-4,
    "gamma": 0.99,
    "gae_lambda": 0.95,
    "ent_coef": 0.01,
    "clip_range": 0.2,
    "policy_kwargs": {"net_arch": [64, 64]},
}

NUM_COPIES = 4
