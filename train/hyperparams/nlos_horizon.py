"""PPO settings for ``nlos_horizon`` (set by reasoning, not tuned on evaluation seeds).

* ``reward="error"`` (the default): the choice of window N trades the turn lag of long
  windows against the noise of short ones, and the estimator's own covariance
  (``"trace"``) knows nothing of the lag (its CV model assumes sigma_a = 0.3 m/s^2 while the
  turns need ~1-2 m/s^2), so only the realized error rewards the right trade-off.
* Episodes are 1000 steps; a window choice only changes the output at that step (the DFIR
  stack is shared by every window: the window is a contextual bandit), while a keep/drop
  choice changes the next D + N_max steps, and keeping every packet is already right at
  ``communication_cost = 0``: gamma 0.5 (credit over ~2 steps), GAE 0.95. Measured on the validation
  seeds (learning curves, 16 episodes, seeds 0 and 1): gamma 0.95 with learning rate 3e-4 and
  200k steps oscillated between 8.6 and 21 m^2 and ended at 11.0 / 13.8 (the best constant
  window is 6.87 there); gamma 0.5 with 1e-4 and 500k steps fell steadily to 4.87 / 4.99.
* Learning rate 1e-4 and entropy 0.005: the 27-way window choice is learnt from a
  heavy-tailed squared-error reward; the larger step size made it jump between windows.
* 500k timesteps (``TIMESTEPS``): about 7 CPU-minutes, inside the 10-minute budget.
* 4 agents x 4 copies = 16 sub-envs, n_steps 256 -> 4096 transitions per update,
  minibatches of 512: the squared-error reward is heavy-tailed (NLOS outliers).
* Small networks (64, 64): the observation has 46 numbers (the AHG costs of the group among them).
"""

ENV_CONFIG: dict = {}

HYPERPARAMS = {
    "n_steps": 256,
    "batch_size": 512,
    "n_epochs": 10,
    "learning_rate": 1e-4,
    "gamma": 0.5,
    "gae_lambda": 0.95,
    "ent_coef": 0.005,
    "clip_range": 0.2,
    "policy_kwargs": {"net_arch": [64, 64]},
}

NUM_COPIES = 4
TIMESTEPS = 500_000

# The leaderboard's target for a learned policy: (what it says, the largest |paired error difference| relative to
# the baseline's mean that counts as matching it, the communication saving a match needs).
LEADERBOARD_TARGET = ("beat the strongest baseline, or match it with 30 % fewer packets", 0.02, 0.30)

# ``make demo`` (train.demo): (training timesteps, evaluation episodes), reduced from the budgets above.
DEMO_RUN = (20_000, 6)
