"""Plain-text tables: the paper's table beside ours."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

__all__ = ["fmt", "format_table"]

if TYPE_CHECKING:
    pass


def format_table(summaries: dict[str, Any], paper: dict[str, dict[str, float]]) -> list[str]:
    """The paper's table (per-axis, its numbers beside ours), then Euclidean and honesty columns."""
    head = (
        f"{'exp':<4} | {'paper: MAPE%':>12} {'MAE':>6} {'RMSE':>6} {'MSE':>8} "
        f"| {'ours: MAPE%':>11} {'MAE':>6} {'RMSE':>6} {'MSE':>8} "
        f"| {'eucl mean':>9} {'median':>6} {'p95':>6} | {'in3σ%':>5} {'NEES':>5} "
        f"| {'plan ms':>7} {'restor%':>7} {'no-reach':>8}"
    )
    lines = [head, "-" * len(head)]
    for name, s in summaries.items():
        p = paper.get(name, {})
        left = (
            f"{name:<4} | {fmt(p.get('mape_pct'), '12.2f')} {fmt(p.get('mae_mm'), '6.1f')} "
            f"{fmt(p.get('rmse_mm'), '6.1f')} {fmt(p.get('mse_mm2'), '8.1f')} | "
        )
        m = s.metrics
        lines.append(
            left + f"{m['mape_pct']:11.2f} {m['mae_mm']:6.1f} {m['rmse_mm']:6.1f} {m['mse_mm2']:8.1f} "
            f"| {m['euclid_mean_mm']:9.1f} {m['euclid_median_mm']:6.1f} {m['euclid_p95_mm']:6.1f} "
            f"| {m['inside_3sigma_pct']:5.1f} {m['nees_mean']:5.2f} "
            f"| {m['plan_ms_median']:7.2f} {m['restoring_steps_pct']:7.1f} {m['runs_never_feasible']:8.0f}"
        )
    lines.append(
        "per axis: eqs. 34-37 over runs and axes [mm]; eucl: ‖truth - estimate‖ per run [mm]; "
        "in3σ%: truth inside the final 3σ ellipsoid (97.1% if consistent); NEES: mean (3 if consistent); "
        "restor%: planned steps with no feasible viewpoint within the step limit; "
        "no-reach: runs that never found one (E5/E10: reachable by the arm)"
    )
    return lines


def fmt(x: float | None, spec: str) -> str:
    """``x`` formatted with ``spec``, "-" when missing (None or NaN)."""
    return "-" if x is None or (isinstance(x, float) and math.isnan(x)) else format(x, spec)
