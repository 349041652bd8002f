"""A campaign's outputs: per-cell metrics, ``runs.csv``, ``summary.json`` and plots.

Everything here reads the rows of a :class:`~bve_mj.campaigns.runner.CampaignResult` and writes
atomically, so an output file is always a whole one."""

from __future__ import annotations

import csv
import io
import math
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from bve_mj.atomic import write_json_atomic, write_text_atomic
from bve_mj.campaigns.runner import CampaignResult
from bve_mj.campaigns.spec import Cell
from bve_mj.config import settings_to_dict
from bve_mj.config.experiments import PAPER_RESULTS
from bve_mj.estimation.metrics import consistency_metrics, euclidean_metrics, paper_metrics

__all__ = [
    "CSV_COLUMNS",
    "cell_summary",
    "format_cells",
    "summary_document",
    "write_campaign_outputs",
    "write_runs_csv",
]

CSV_COLUMNS = (
    "world", "experiment", "planner", "measurement", "initial_error_m", "approach", "run", "seed",
    "episode_seed", "outcome", "views", "error_mm", "error_x_mm", "error_y_mm", "error_z_mm", "nees",
    "sigma_max_mm", "plan_ms_median", "restoring_steps", "fallback_steps", "detected_views",
    "accepted_views", "joint_limit_violation_rad", "min_camera_fruit_distance_m", "wall_s", "message",
)  # fmt: skip

"""``runs.csv``: one line per run; errors are estimate - truth [mm]; blank where a run failed."""


def _ok(rows: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    return [r for r in rows if r["outcome"] not in ("failed", "crashed")]


def cell_summary(rows: Sequence[dict[str, Any]], recovered_mm: float) -> dict[str, Any]:
    """Metrics of one cell's runs: the paper's (per axis), Euclidean, consistency, outcomes,
    the share of runs ending within ``recovered_mm`` and the median error after each view."""
    ok = _ok(rows)
    outcomes: dict[str, int] = {}
    for r in rows:
        outcomes[r["outcome"]] = outcomes.get(r["outcome"], 0) + 1
    out: dict[str, Any] = {"runs": len(rows), "finished_runs": len(ok), "outcomes": outcomes}
    if not ok:
        return out
    truth = np.array([r["truth_m"] for r in ok])
    est = np.array([r["estimate_m"] for r in ok])
    cov = np.array([r["cov_m2"] for r in ok])
    err = np.array([r["error_mm"] for r in ok])
    out.update(paper_metrics(truth, est))
    out.update(euclidean_metrics(truth, est))
    out.update(consistency_metrics(truth, est, cov))
    out["recovered_pct"] = float(np.mean(err <= recovered_mm) * 100.0)
    out["views_median"] = float(np.median([r["views"] for r in ok]))
    out["plan_ms_median"] = float(np.median([r["plan_ms_median"] for r in ok]))
    out["wall_s_mean"] = float(np.mean([r["wall_s"] for r in ok]))
    n = max(len(r["error_by_view_mm"]) for r in ok)
    # a run that stopped early keeps its last error for the later views
    padded = np.array([r["error_by_view_mm"] + [r["error_by_view_mm"][-1]] * (n - len(r["error_by_view_mm"]))
                       for r in ok])  # fmt: skip
    out["error_by_view_median_mm"] = np.median(padded, axis=0).tolist()
    out["error_by_view_p25_mm"] = np.percentile(padded, 25, axis=0).tolist()
    out["error_by_view_p75_mm"] = np.percentile(padded, 75, axis=0).tolist()
    return out


def _clean(x: Any) -> Any:
    """NaN and infinities as JSON null (strict JSON readers reject NaN)."""
    if isinstance(x, float) and not math.isfinite(x):
        return None
    if isinstance(x, dict):
        return {k: _clean(v) for k, v in x.items()}
    if isinstance(x, list):
        return [_clean(v) for v in x]
    return x


_PATHS = ("error_by_view_mm", "camera_path_m", "estimate_path_m", "cov_m2", "prior_m")


def summary_document(result: CampaignResult) -> dict[str, Any]:
    """``summary.json``: spec, settings, per-cell metrics, and every run's errors and timings."""
    cells = []
    for cell in result.cells:
        cells.append(
            {
                "cell": {k: getattr(cell, k) for k in Cell.__dataclass_fields__},
                "label": cell.label,
                **cell_summary(result.cell_rows(cell), result.spec.recovered_mm),
            }
        )
    return _clean(
        {
            "spec": result.spec.as_dict(),
            "settings": settings_to_dict(result.settings),
            "cells": cells,
            "runs": [{k: v for k, v in r.items() if k not in _PATHS} for r in result.rows],
            "paper": PAPER_RESULTS,
            "resumed_runs": result.resumed_runs,
            "computed_runs": result.computed_runs,
            "crashed": list(result.crashed),
            "wall_s": result.wall_s,
            "created_unix_s": time.time(),
        }
    )


def write_runs_csv(result: CampaignResult, path: Path) -> Path:
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=CSV_COLUMNS, extrasaction="ignore", lineterminator="\n")
    w.writeheader()
    for r in result.rows:
        row = dict(r)
        for axis, v in zip("xyz", r.get("error_xyz_mm") or [None] * 3, strict=True):
            row[f"error_{axis}_mm"] = v
        w.writerow({k: ("" if isinstance(v, float) and not math.isfinite(v) else v) for k, v in row.items()})
    return write_text_atomic(path, buf.getvalue())


def format_cells(result: CampaignResult) -> list[str]:
    """One line per cell: runs, Euclidean error, per-axis RMSE, consistency, views, time."""
    head = (
        f"{'cell':<44} {'runs':>5} {'fail':>4} | {'eucl mean':>9} {'median':>7} {'p95':>7} "
        f"{'RMSE':>6} | {'NEES':>6} {'rec%':>5} | {'views':>5} {'plan ms':>7} {'run s':>6}"
    )
    lines = [head, "-" * len(head)]
    for cell in result.cells:
        s = cell_summary(result.cell_rows(cell), result.spec.recovered_mm)
        fail = s["runs"] - s["finished_runs"]
        if "euclid_mean_mm" not in s:
            lines.append(f"{cell.label:<44} {s['runs']:5d} {fail:4d} | no finished runs")
            continue
        lines.append(
            f"{cell.label:<44} {s['runs']:5d} {fail:4d} | {s['euclid_mean_mm']:9.2f} "
            f"{s['euclid_median_mm']:7.2f} {s['euclid_p95_mm']:7.2f} {s['rmse_mm']:6.1f} | "
            f"{s['nees_mean']:6.2f} {s['recovered_pct']:5.0f} | {s['views_median']:5.0f} "
            f"{s['plan_ms_median']:7.2f} {s['wall_s_mean']:6.2f}"
        )
    lines.append(
        "errors in mm: eucl = ‖estimate - truth‖ per run, RMSE per axis (paper eq. 36); NEES mean "
        f"(3 if consistent); rec% = runs ending within {result.spec.recovered_mm:g} mm; run s = wall per run"
    )
    return lines


def write_campaign_outputs(result: CampaignResult, plots: bool = True) -> list[Path]:
    """``runs.csv``, ``summary.json`` and (``plots``) the figures in the campaign directory."""
    d = result.directory
    written = [
        write_runs_csv(result, d / "runs.csv"),
        write_json_atomic(d / "summary.json", summary_document(result)),
    ]
    if plots:
        from bve_mj.reporting.campaign_plots import plot_campaign  # it reads cell_summary from here

        written += plot_campaign(result)
    return written
