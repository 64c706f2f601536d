"""PPO settings for ``gps_denied_nbp`` (set by reasoning, not tuned on evaluation seeds).

* ``communication_cost=0.02`` m per broadcast: without a price on the channel the
  paper's schedule (broadcast whenever allowed) is already the best a policy
  can do in expectation, so there would be nothing to learn. The price should
  be small against the few-metre error of a localized fault UAV and against
  the tens of metres of a lost one, so a policy stays silent only where its
  message adds little (e.g. a normal UAV whose fault neighbours already hear
  three anchors). The target asks for the error of the 20 m ``threshold``
  rule within 5 %; at 20 broadcasts per step 0.05 m weighs 1 m a step
  against a ~6 m error, so policies trained at 0.05 m bought their 64 %
  saving with 4 % more error. Chosen on validation episodes
  that neither training nor the learning curve uses (256 episodes at M = 100,
  ``train.evaluate.evaluate_policy("gps_denied_nbp", policy, 256,
  VALIDATION_SEED_BASE + 10_000)``, each model paired against ``threshold``),
  seeds 0..2, otherwise these settings:

  | setting | seed 0 | seed 1 | seed 2 | broadcasts/step |
  |---|---|---|---|---|
  | 0.05 | +0.340 m | (= seed 0's policy) | +0.331 m | 7.6 / 7.4 |
  | 0.02 | +0.133 m | +0.029 m | -0.115 m | 8.8 / 11.8 / 8.1 |
  | 0.05, ``CURVE_EPISODES = 64`` | +0.340 m | +0.084 m | +0.331 m | 7.6 / 12.0 / 7.4 |
  | 0.02, ``CURVE_EPISODES = 64`` | +0.340 m | +0.029 m | +0.070 m | 7.6 / 11.8 / 10.4 |

  (``threshold`` there: 6.290 m at 20.5 broadcasts per step.) The training
  curves hop between a few deterministic behaviours (the same validation
  errors recur across seeds and settings, e.g. 6.84 m and 9.01 m on the 16
  curve episodes), so the kept checkpoint matters as much as the price; more
  curve episodes did not pick better ones here, so ``CURVE_EPISODES`` stays
  at the default.
* ``COST_RANGE = (0.01, 100)`` metres per broadcast, log-uniform, drawn per episode and observed, so one network
  serves every price; ``communication_cost=0.02`` stays the cost of ``coloc train gps_denied_nbp --cost-range
  none`` (the table's models). The reward charges lambda per broadcast of the whole team (10 UAVs), so the
  fixed schedules' best choice changes where 10 lambda equals a chord slope of their frontier: on validation
  episodes (``coloc frontier gps_denied_nbp --seed 2000000 --quick --episodes 16 --bound-episodes 1``, never the
  evaluation seeds) the slopes run from 0.38 m per broadcast per agent-step (``send_on_delta:3.375`` to
  ``threshold``) to 331 (``silent`` to ``value:9.809``), lambda 0.038 to 33. The range reaches a few times past
  both ends.
* ``COST_REWARD_SCALE = 0.5`` m per broadcast: each step's reward is divided by 1 + lambda / 0.5. At lambda = 100
  and ~20 broadcasts a step the cost term is ~2000 m against an error of 5-30 m; scaled, a priced step stays within
  a factor ~20 of the error, so the expensive episodes do not set every batch's advantage scale.
* 1.2M timesteps with the cost range (300k at one fixed cost): one network learns every price, and
  ``circles/broadcast/ukf_ccl`` needed four times its fixed-cost budget for the same.
* ``num_particles=50``: training needs many environment steps and dNBP costs
  O(M^2) per message; the decisions (who talks when) do not depend on M.
* The team reward (mean fault-UAV error) is shared and noisy; 10 agents x 4
  copies = 40 sub-envs, n_steps 60 (two 30-step episodes) -> 2400
  transitions per update, minibatches of 600.
* A message mostly helps the current step and, through the prior, the next
  few: gamma 0.9, GAE 0.95.
* Small networks (64, 64): the observation has 8 + N + 5 = 23 numbers.
"""

ENV_CONFIG = {"communication_cost": 0.02, "num_particles": 50}

HYPERPARAMS = {
    "n_steps": 60,
    "batch_size": 600,
    "n_epochs": 10,
    "learning_rate": 3e-4,
    "gamma": 0.9,
    "gae_lambda": 0.95,
    "ent_coef": 0.0,
    "clip_range": 0.2,
    "policy_kwargs": {"net_arch": [64, 64]},
}

COST_RANGE = (0.01, 100.0)
COST_REWARD_SCALE = 0.5

NUM_COPIES = 4
TIMESTEPS = 1_200_000  # with COST_RANGE; the fixed-cost models of docs/learning.md's table: --cost-range none
                       # --timesteps 300000

# The leaderboard's target for a learned policy: (what it says, the largest |paired error difference| relative to
# the baseline's mean that counts as matching it, the communication saving a match needs).
LEADERBOARD_TARGET = (("the strongest baseline's error (within 5 %) with 30 % fewer broadcasts, or lower "
                      "error"), 0.05, 0.30)

# ``make demo`` (train.demo): (training timesteps, evaluation episodes), reduced from the budgets above.
DEMO_RUN = (4_800, 6)

# ``coloc bench``: its batch sizes (dNBP's M x M kernel per message is too expensive per step for B = 1024), and
# a row with every copy playing episode 0 (the work per copy depends on the episode: how many messages arrive,
# how many proposals the truncated kernel prunes).
BENCH_BATCHES = (1, 4, 64)
BENCH_ONE_EPISODE = True

# ``coloc evaluate --policy all``'s extra row: the threshold rule at 5 m used 40 % fewer broadcasts than the paper's
# schedule at an error not distinguishable from it on the validation seeds (agents/gps_denied_nbp.py), the
# comparison for any policy that claims the paper's error with fewer broadcasts.
EVALUATE_EXTRA_ROWS = ("threshold:5",)
