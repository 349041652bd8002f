"""Worlds the episode loop runs in: the synthetic (paper) world; later the MuJoCo world."""

from bve_mj.sim.synthetic import SyntheticWorld
from bve_mj.sim.world import Observation, Scenario, World

__all__ = ["Observation", "Scenario", "SyntheticWorld", "World"]
