"""PPO settings for ``nlos_horizon`` (set by reasoning, not tuned on evaluation seeds).

* ``reward="error"`` (the default): the choice of horizon trades the turn lag of long
  horizons against the noise of short ones, and the estimator's own covariance
  (``"trace"``) knows nothing of the lag (its CV model assumes sigma_a = 0.3 m/s^2 while the
  turns need ~1-2 m/s^2), so only the realized error rewards the right trade-off.
* Episodes are 1000 steps; a horizon choice only changes the output at that step (the DFIR
  stack is shared by every horizon), while a keep/drop choice changes the next D + N_max
  steps: gamma 0.95 (horizon ~ 20 steps), GAE 0.95.
* 4 agents x 4 copies = 16 sub-envs, n_steps 256 -> 4096 transitions per update,
  minibatches of 512: the squared-error reward is heavy-tailed (NLOS outliers).
* Small networks (64, 64): the observation has 36 numbers.
* A little entropy (0.01) keeps the 27-way horizon choice from collapsing early.
"""

ENV_CONFIG: dict = {}

HYPERPARAMS = {
    "n_steps": 256,
    "batch_size": 512,
    "n_epochs": 10,
    "learning_rate": 3e-4,
    "gamma": 0.95,
    "gae_lambda": 0.95,
    "ent_coef": 0.01,
    "clip_range": 0.2,
    "policy_kwargs": {"net_arch": [64, 64]},
}

NUM_COPIES = 4
