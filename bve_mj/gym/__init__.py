"""Gymnasium environments (the optional extra ``bve_mj[gym]``).

Importing this package registers ``BveMj/ViewPlanning-v0`` (:class:`~bve_mj.gym.env.
ViewPlanningEnv`), as Gymnasium's own environment packages do::

    import gymnasium as gym
    import bve_mj.gym  # noqa: F401  (registers the environment)

    env = gym.make("BveMj/ViewPlanning-v0", scenario="clean")
"""

from __future__ import annotations

try:
    import gymnasium
except ImportError as exc:  # pragma: no cover - depends on the install
    raise ImportError("bve_mj.gym needs gymnasium: pip install 'bve_mj[gym]'") from exc

__all__ = ["ENV_ID"]

ENV_ID = "BveMj/ViewPlanning-v0"
"""The registered id of :class:`~bve_mj.gym.env.ViewPlanningEnv`."""

if ENV_ID not in gymnasium.registry:
    gymnasium.register(id=ENV_ID, entry_point="bve_mj.gym.env:ViewPlanningEnv")
