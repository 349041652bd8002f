"""``BveMj/ViewPlanning-v0``: next-best-view planning for one fruit as a Gymnasium environment.

The environment is the MuJoCo episode (:mod:`bve_mj.loop.mujoco`) one view at a time: the same
seeded scene, ready pose, prior, detector, filter (the camera measurement, the fruit's centre
and radius in the state) and claims; only the choice of the next view is the agent's.

- **Observation** (a dict): ``image``, the eye-in-hand image of the last view (H, W, 3,
  uint8); ``belief_mean`` (4,), the filter's centre [m] and radius [m]; ``belief_cov`` (4, 4)
  its covariance [m²]; ``q`` (nq,), the arm's joint angles as the encoders read them [rad].
- **Action**: the camera's next displacement in the world frame, in units of the step limit
  ``constraints.step_m`` (a vector longer than 1 is scaled to length 1: the step limit). The
  camera then looks at the current estimate; the arm reaches the pose by look-at IK and the
  position controller in physics (a pose it cannot reach leaves the camera where the IK got
  it, event ``ik_failed`` in ``info``). Displacement rather than joint targets: the BVE and
  the baselines plan camera positions, so any of them runs as a policy (:meth:`ViewPlanningEnv.
  planner_action`), and a displacement is bounded the way the paper bounds a step.
- **Reward**: the information the view gave, ln det P_c(before) − ln det P_c(after) [nats] of
  the centre's covariance (the D-optimal criterion the every-fruit planner sums), minus
  ``motion_cost`` per step length the camera moved.
- **Termination**: the fruit is localised (the claimed σmax below ``episode.stop_sigma_m``
  with at least ``episode.converge_after`` accepted measurements, the episode's own rule);
  **truncation**: ``episode.views`` views taken.
- ``info`` (the active-perception convention of ap_gym): ``target`` the true centre [m],
  ``target_radius_m``, ``error_m``, ``sigma_max_m`` (claimed), ``measured``, ``accepted``,
  ``view``, ``events``; at the end ``outcome`` (the episode's, :class:`~bve_mj.loop.outcomes.
  Outcome`).
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from bve_mj.config import Settings, load_settings, with_overrides
from bve_mj.errors import ConfigError
from bve_mj.estimation.belief import Belief
from bve_mj.loop.episode import EpisodeLoop, StopRules, ViewRecord
from bve_mj.loop.mujoco import EpisodeParts, episode_parts, episode_settings
from bve_mj.loop.outcomes import Outcome
from bve_mj.loop.start import start_episode
from bve_mj.planning.plan import ViewPlan
from bve_mj.robot import arm_kinematics

__all__ = ["ViewPlanningEnv"]

_MAX_SEED = 2**31 - 1
_BOUND_M = 10.0  # the observation's bound on a position [m] (the greenhouse is a few metres)
_Q_SLACK_RAD = 0.1  # encoders may read a little past a joint limit


def _scenario_settings(scenario: str | Path | None, settings: Settings | None) -> Settings:
    """The settings of a suite scenario's name, a TOML file, or ``settings`` (default: the
    default scene), with the camera measurement and the radius in the state."""
    if scenario is not None and settings is not None:
        raise ConfigError("scenario", str(scenario), "either a scenario or settings, not both")
    if scenario is None:
        base = settings if settings is not None else Settings()
    elif Path(scenario).suffix == ".toml":
        base = load_settings(scenario)
    else:
        from bve_mj.campaigns.scenarios import load_suite

        (sc,) = load_suite(only=[str(scenario)])
        base = load_settings(sc.path)
    s = with_overrides(base, measurement={"kind": "camera"}, filter={"state": "centre_radius"})
    return episode_settings(with_overrides(s, episode={"approach": False}))


class ViewPlanningEnv(gym.Env[dict[str, np.ndarray], np.ndarray]):
    """Next-best-view planning for one fruit in the rendered greenhouse (module docstring).

    Args:
        scenario: a suite scenario's name (``bve-mj scenarios`` lists them) or a settings TOML.
        settings: settings instead of a scenario (default: the default scene).
        motion_cost: reward lost per step length moved [nats].
        render_mode: ``"rgb_array"`` (the eye-in-hand image) or None.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 4}  # noqa: RUF012 (Gymnasium's convention)

    def __init__(
        self,
        scenario: str | Path | None = None,
        settings: Settings | None = None,
        motion_cost: float = 0.1,
        render_mode: str | None = None,
    ) -> None:
        if isinstance(motion_cost, bool) or not isinstance(motion_cost, int | float) or not motion_cost >= 0:
            raise ConfigError("motion_cost", motion_cost, "a number >= 0")
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ConfigError("render_mode", render_mode, "rgb_array or None")
        self.settings = _scenario_settings(scenario, settings)
        self.motion_cost = float(motion_cost)
        self.render_mode = render_mode
        s = self.settings
        kin = arm_kinematics(s.robot.name, s.robot.limit_set)
        h, w = s.camera.height_px, s.camera.width_px
        self.observation_space = spaces.Dict(  # type: ignore[assignment]
            {
                "image": spaces.Box(0, 255, (h, w, 3), np.uint8),
                "belief_mean": spaces.Box(-_BOUND_M, _BOUND_M, (4,), np.float64),
                "belief_cov": spaces.Box(-(_BOUND_M**2), _BOUND_M**2, (4, 4), np.float64),
                "q": spaces.Box(
                    kin.limits.lower - _Q_SLACK_RAD, kin.limits.upper + _Q_SLACK_RAD, dtype=np.float64
                ),
            }
        )
        self.action_space = spaces.Box(-1.0, 1.0, (3,), np.float32)
        self._parts: EpisodeParts | None = None
        self._loop: EpisodeLoop | None = None
        self._target_m = np.zeros(3)
        self._radius_m = 0.0
        self._q_start = np.zeros(kin.nq)
        self.episode_seed: int | None = None

    # ------------------------------------------------------------------ gymnasium API
    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        """A new episode: the scene, ready pose and prior of episode seed ``seed`` (as
        ``bve-mj episode --seed``), or one drawn from the environment's generator. ``options``
        may hold ``{"episode_seed": int}`` to pick the scene without reseeding the generator."""
        super().reset(seed=seed)
        chosen = (options or {}).get("episode_seed", seed)
        if chosen is None:
            chosen = int(self.np_random.integers(0, _MAX_SEED))
        if isinstance(chosen, bool) or not isinstance(chosen, int | np.integer) or chosen < 0:
            raise ConfigError("episode_seed", chosen, "an integer >= 0")
        self.close()
        start = start_episode(self.settings, int(chosen))
        if start.q_start is None:
            raise ConfigError("episode_seed", chosen, "a seed whose fruit the arm can look at (unreachable)")
        self.episode_seed = int(chosen)
        self._parts = episode_parts(start, start.q_start, keep_images=True)
        self._target_m = start.info.target.centre_m.copy()
        self._radius_m = float(start.info.target.radius_m)
        self._q_start = start.q_start.copy()
        p = self._parts
        self._loop = EpisodeLoop(
            p.loop_world, start.prior, self.settings.filter, p.planner, None, p.claims, p.correlation,
            prior_bound=start.prior_bound,
        )  # fmt: skip
        record = self._loop.start()
        return self._observation(), self._info(record)

    def step(self, action: np.ndarray) -> tuple[dict[str, np.ndarray], float, bool, bool, dict[str, Any]]:
        loop = self._running()
        a = np.asarray(action, dtype=float).reshape(-1)
        if a.shape != (3,) or not np.all(np.isfinite(a)):
            raise ConfigError("action", np.asarray(action).tolist(), "3 finite numbers")
        norm = float(np.linalg.norm(a))
        if norm > 1.0:
            a = a / norm
        step_m = self.settings.step_m
        before = loop.world.p_world_camera
        info_before = _log_volume(loop.belief)
        plan = ViewPlan(before + step_m * a, loop.belief.centre_m.copy(), "optimal", True, 0.0)
        record = loop.step(plan)
        gained = info_before - _log_volume(loop.belief)
        moved = float(np.linalg.norm(loop.world.p_world_camera - before)) / step_m
        reward = gained - self.motion_cost * moved
        s = self.settings
        terminated = self._localised()
        truncated = not terminated and len(loop.views) - 1 >= s.episode.views
        info = self._info(record)
        if terminated or truncated:
            result = loop.finish(Outcome.CONVERGED if terminated else None)
            info["outcome"] = str(result.outcome)
        return self._observation(), float(reward), terminated, truncated, info

    def render(self) -> np.ndarray | None:
        """The eye-in-hand image of the last view (``render_mode="rgb_array"``)."""
        if self.render_mode != "rgb_array" or self._parts is None:
            return None
        return self._image()

    def close(self) -> None:
        if self._parts is not None:
            self._parts.world.close()
        self._parts, self._loop = None, None

    # ------------------------------------------------------------------ policies
    def planner_action(self) -> np.ndarray:
        """The action the episode's own planner (``planner.kind``: the BVE with the arm's
        kinematics, or a baseline) would take now: its next viewpoint as a displacement in
        step lengths (the BVE as a policy)."""
        loop = self._running()
        assert self._parts is not None
        p = loop.world.p_world_camera
        plan = self._parts.planner.plan(loop.belief, p, len(loop.views))
        a = (np.asarray(plan.p_world_camera, dtype=float) - p) / self.settings.step_m
        return np.clip(a, -1.0, 1.0).astype(np.float32)

    # ------------------------------------------------------------------ internals
    def _running(self) -> EpisodeLoop:
        if self._loop is None:
            raise RuntimeError("call reset() before step()")
        return self._loop

    def _localised(self) -> bool:
        """The episode's ``converged`` rule: claimed σmax below the threshold with enough
        accepted measurements since the last belief reset, with any one of them left out
        too, and no dispute standing."""
        ep = self.settings.episode
        rule = StopRules.for_episode(dataclasses.replace(ep, approach=False), self.settings.measurement.kind)
        loop = self._running()
        return rule.outcome(loop.views, loop.leave_one_out) == Outcome.CONVERGED

    def _image(self) -> np.ndarray:
        assert self._parts is not None
        image = self._parts.world.last.image
        if image is None:
            s = self.settings.camera
            return np.zeros((s.height_px, s.width_px, 3), np.uint8)
        return np.ascontiguousarray(image, dtype=np.uint8)

    def _observation(self) -> dict[str, np.ndarray]:
        loop = self._running()
        assert self._parts is not None
        q = self._parts.world.q_measured
        return {
            "image": self._image(),
            "belief_mean": loop.belief.mean[:4].astype(np.float64).copy(),
            "belief_cov": loop.belief.cov[:4, :4].astype(np.float64).copy(),
            "q": (self._q_start if q is None else q).astype(np.float64).copy(),
        }

    def _info(self, record: ViewRecord) -> dict[str, Any]:
        b = record.belief
        return {
            "target": self._target_m.copy(),
            "target_radius_m": self._radius_m,
            "error_m": float(np.linalg.norm(b.centre_m - self._target_m)),
            "sigma_max_m": float(b.sigma_max_m),
            "measured": record.measured,
            "accepted": record.accepted,
            "view": record.iteration,
            "events": [str(e) for e in record.events],
            "episode_seed": self.episode_seed,
        }


def _log_volume(belief: Belief) -> float:
    """ln det of the centre's covariance [ln m⁶]."""
    sign, logdet = np.linalg.slogdet(belief.cov[:3, :3])
    return float(logdet) if sign > 0 else -math.inf
