"""``mrclam_relay`` as a PettingZoo environment module: ``parallel_env``, ``raw_env`` and ``env``.

``max_cycles`` sets ``window_steps`` (the replayed window); the data come from ``data=`` or
``$COLOC_MRCLAM_DATA``. See ``coloc_env.envs``.
"""

from coloc_env.envs import constructors

parallel_env, raw_env, env = constructors("mrclam_relay")

__all__ = ["env", "parallel_env", "raw_env"]
