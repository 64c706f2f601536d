"""``relay_ukf`` as a PettingZoo environment module: ``parallel_env``, ``raw_env`` and ``env``.

``max_cycles`` sets ``horizon``. See ``coloc_env.envs``.
"""

from coloc_env.envs import constructors

parallel_env, raw_env, env = constructors("relay_ukf")

__all__ = ["env", "parallel_env", "raw_env"]
