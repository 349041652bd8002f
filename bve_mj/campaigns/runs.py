"""One run of a cell, reduced to its row (outcome, errors, consistency, views, timings)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from bve_mj.campaigns.spec import Cell, cell_settings, episode_seed
from bve_mj.config import Settings
from bve_mj.config.experiments import EXPERIMENTS
from bve_mj.errors import BveError
from bve_mj.estimation.belief import Belief
from bve_mj.loop.episode import EpisodeResult
from bve_mj.loop.synthetic import synthetic_episode
from bve_mj.robot import arm_kinematics

__all__ = ["radius_metrics", "run_cell"]


def _row(
    cell: Cell,
    run: int,
    seed: int,
    truth: np.ndarray,
    result: EpisodeResult,
    ep_seed: int | None,
    joint_violation_rad: float = 0.0,
    true_radius_m: float | None = None,
) -> dict[str, Any]:
    final = result.final_claim.position
    d = final.mean - truth
    planned = result.views[1:]
    errors = [float(np.linalg.norm(v.belief.centre_m - truth)) * 1e3 for v in result.views]
    finite = all(
        np.all(np.isfinite(v.belief.mean)) and np.all(np.isfinite(v.belief.cov)) for v in result.views
    )
    return {
        "key": cell.key(run),
        "world": cell.world,
        "experiment": cell.experiment,
        "planner": cell.planner,
        "measurement": cell.measurement,
        "initial_error_m": cell.initial_error_m,
        "approach": cell.approach,
        "run": run,
        "seed": seed,
        "episode_seed": ep_seed,
        "outcome": result.outcome,
        "views": len(result.views),
        "error_mm": float(np.linalg.norm(d)) * 1e3,
        "error_xyz_mm": (d * 1e3).tolist(),
        "nees": float(d @ np.linalg.solve(final.cov, d)),
        "claim_dof": None if math.isinf(result.shape.dof) else result.shape.dof,
        "sigma_max_mm": float(np.sqrt(np.linalg.eigvalsh(final.cov)[-1])) * 1e3,
        "plan_ms_median": float(np.median([v.plan_s for v in planned])) * 1e3 if planned else 0.0,
        "plan_ms": [v.plan_s * 1e3 for v in planned],
        "restoring_steps": sum(v.plan_status == "restoring" for v in planned),
        "best_feasible_steps": sum(v.plan_status == "best_feasible" for v in planned),
        "ever_feasible": any(v.plan_feasible for v in planned),
        "fallback_steps": sum(v.plan_status == "fallback" for v in planned),
        "events": result.event_counts(),
        "belief_finite": bool(finite),
        "joint_limit_violation_rad": joint_violation_rad,
        "min_camera_fruit_distance_m": min(
            (float(np.linalg.norm(v.p_world_camera - truth)) for v in result.views), default=float("nan")
        ),
        "detected_views": sum(v.measured for v in result.views),
        "accepted_views": sum(v.accepted for v in result.views),
        "wall_s": result.wall_s,
        "truth_m": truth.tolist(),
        "estimate_m": final.mean.tolist(),
        "cov_m2": final.cov.tolist(),
        "prior_m": result.prior.centre_m.tolist(),
        "error_by_view_mm": errors,
        "camera_path_m": [v.p_world_camera.tolist() for v in result.views],
        "estimate_path_m": [v.belief.centre_m.tolist() for v in result.views],
        **radius_metrics(result.final_claim, true_radius_m),
    }


def radius_metrics(final: Belief, true_radius_m: float | None) -> dict[str, float | None]:
    """The final radius estimate, its σ, its error [mm] and NEES (None where the state holds
    no radius or the truth is unknown)."""
    r, sd = final.radius_m, final.radius_sigma_m
    if r is None or sd is None or true_radius_m is None:
        return {"radius_mm": r and 1e3 * r, "radius_sigma_mm": sd and 1e3 * sd, "radius_error_mm": None,
                "radius_nees": None}  # fmt: skip
    err = r - true_radius_m
    return {"radius_mm": 1e3 * r, "radius_sigma_mm": 1e3 * sd, "radius_error_mm": 1e3 * err,
            "radius_nees": (err / sd) ** 2}  # fmt: skip


def run_cell(settings: Settings, cell: Cell, seed: int, run: int) -> dict[str, Any]:
    """Run ``run`` of ``cell`` and return its JSON-ready row.

    A run that fails on purpose (a :class:`BveError`: no reachable start pose, say) is a
    row with outcome ``"failed"`` and the message; its errors are NaN.
    """
    s = cell_settings(settings, cell)
    try:
        if cell.world == "synthetic":
            scenario, result = synthetic_episode(s, EXPERIMENTS[cell.experiment], seed, run)
            return _row(cell, run, seed, scenario.p_world_fruit, result, None)
        from bve_mj.loop.mujoco import run_mujoco_episode

        ep_seed = episode_seed(seed, run)
        episode = run_mujoco_episode(s, ep_seed)
        kin = arm_kinematics(s.robot.name, s.robot.limit_set)
        violation = 0.0
        for v in episode.result.views:
            q = (v.world or {}).get("q_rad")
            if q is not None:
                qa = np.asarray(q)
                below, above = kin.limits.lower - qa, qa - kin.limits.upper
                violation = max(violation, float(np.max(np.maximum(below, above))))
        return _row(
            cell,
            run,
            seed,
            episode.truth,
            episode.result,
            ep_seed,
            max(violation, 0.0),
            episode.true_radius_m,
        )
    except BveError as exc:
        return _failed_row(cell, seed, run, "failed", str(exc))


def _failed_row(cell: Cell, seed: int, run: int, outcome: str, message: str) -> dict[str, Any]:
    return {
        "key": cell.key(run), "world": cell.world, "experiment": cell.experiment,
        "planner": cell.planner, "measurement": cell.measurement,
        "initial_error_m": cell.initial_error_m, "approach": cell.approach, "run": run,
        "seed": seed, "episode_seed": episode_seed(seed, run) if cell.world == "mujoco" else None,
        "outcome": outcome, "message": message, "views": 0,
        "error_mm": float("nan"), "nees": float("nan"), "wall_s": 0.0,
    }  # fmt: skip
