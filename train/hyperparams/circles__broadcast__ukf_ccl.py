"""PPO settings for the composition ``circles/broadcast/ukf_ccl``, a cross-combination no paper ran.

wang2019's circling platforms (the ``circles`` world: six platforms, each ranging with one partner per step)
with the centralized UKF (``ukf_ccl``) fed over a lossless ``broadcast`` network: each agent decides per step
which platform to range with (``partner``, the nearest by default) and whether to send that measurement
(``transmit``). A measurement that is not sent is not used. Set by reasoning and by the measurement below,
on validation seeds 2 * 10^6 + e only (16 episodes of 800 steps; the fixed schedules send every p-th step,
the partner at its default):

| schedule            | position error (m) | filter RMS sqrt(tr P_ii) (m) | messages per agent-step |
|---------------------|--------------------|------------------------------|-------------------------|
| ``always`` (p = 1)  | 1.0019             | 0.8957                       | 0.403                   |
| every 2nd step      | 1.1113             | 1.0633                       | 0.201                   |
| every 4th step      | 1.2852             | 1.2744                       | 0.101                   |
| every 8th step      | 1.4807             | 1.5206                       | 0.051                   |
| ``silent``          | 2.9456             | 3.4013                       | 0                       |

The last messages of ``always`` are the least valuable: halving them costs 0.168 m of RMS per agent-step,
0.84 m per message removed, while the next halvings cost 2.1 and 4.9 m per message.

* ``reward="trace"``: -sqrt(tr P_ii), the filter's own RMS, which depends on which measurements reach the
  filter and not on their noise (as for ``relay_ukf``); the leaderboard judges the realized error.
* ``COST_RANGE = (0.05, 50)`` m per message, log-uniform: the cost is drawn per episode and observed, so one
  network learns the whole error-against-messages curve. Priced at c, the schedule of the table that minimizes
  RMS + c x messages per agent-step changes where c crosses a chord's slope: 0.83 (``always`` -> every 2nd
  step), 2.1 (-> every 4th), 4.9 (-> every 8th) and 37 m per message (-> ``silent``); on the position error
  column 0.54, 1.7, 3.9 and 29. The range reaches a decade below the first change (where every message is
  worth its price) and past the last (where silence is), a third of the episodes per decade. The best
  checkpoint is the one with the lowest mean over the validation costs 0.158, 1.58 and 15.8 (the law's
  quantiles at 1/6, 1/2, 5/6: ``train.training.validation_costs``) of error + cost x messages.
* ``COST_REWARD_SCALE = 1.0`` m per message: each training step's reward is divided by 1 + c / 1 m
  (``train.training.cost_balanced_reward``), which leaves every cost's optimal policy as it is (the factor is
  fixed over an episode and c is observed) and balances the gradient between costs: unscaled, an episode at
  c = 50 sends rewards of -50 per message beside RMS terms near -1, so the advantages of the episodes priced
  at 5 to 50 set the per-batch normalization. 1 m is the RMS scale of a step and of what a message is worth
  (the first chord above, 0.84 m per message). Trained unscaled at 1.2M timesteps, the three seeds were below the
  frontier at cost 10 and two of them above it at cost 0.2 (docs/learning.md).
* ``communication_cost=0.5`` m per message where the cost is fixed (``coloc train --cost-range none``): below the
  0.84 m an average one of ``always``'s last messages is worth, so a policy that finds the useful ones keeps them
  and drops those worth less. The target is ``always``'s error with fewer messages, or a lower error than a fixed
  schedule at the same message rate.
* A measurement's effect on the covariance fades over tens of steps of dead reckoning: gamma 0.98, GAE 0.95.
* 6 agents x 8 copies = 48 sub-envs, n_steps 64 -> 3,072 transitions per update (batches of 384).
* Networks (64, 64): the observation has 3N + 7 + features = 26 numbers (the cost among them).
* 2.4M timesteps. At 300k each seed's best validation checkpoint was its last, the validation score still
  falling; at 1.2M seed 1's was again its last, and judged against the frontier seed 0 sat above it at the two
  lowest costs (docs/learning.md). With twice that budget the kept checkpoints (chosen on the validation seeds)
  came at 1.44M, 1.68M and 2.40M timesteps, with validation scores 1.221, 1.178 and 1.203 against 1.278,
  1.178 and 1.206 at 1.2M; 16-22 minutes of wall time per seed on the 2-core machine with a second job beside it.
"""

from train.hyperparams import ppo

ENV_CONFIG = {"reward": "trace", "communication_cost": 0.5}
COST_RANGE = (0.05, 50.0)
COST_REWARD_SCALE = 1.0

HYPERPARAMS = ppo(n_steps=64, batch_size=384, gamma=0.98, ent_coef=0.01)

NUM_COPIES = 8
TIMESTEPS = 2_400_000
