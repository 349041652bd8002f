"""The figures are readable: every cell drawn, titles inside the figure, paths shown.

Campaign results are made up (no episodes run), so these tests take about a second each.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

pytest.importorskip("matplotlib")

import matplotlib

matplotlib.use("Agg")

from matplotlib.lines import Line2D
from matplotlib.text import Text

import bve_mj.reporting.plots as plots
from bve_mj.campaigns.runner import CampaignResult
from bve_mj.campaigns.spec import CampaignSpec, Cell
from bve_mj.config import Settings
from bve_mj.reporting.campaign_plots import plot_campaign


def _row(cell: Cell, run: int, rng: np.random.Generator, still: bool = False) -> dict[str, Any]:
    truth = rng.uniform(-0.5, 0.5, 3)
    views = 8
    errs = list(50.0 * np.exp(-0.5 * np.arange(views)) + rng.uniform(0.1, 1.0, views))
    est = truth + rng.normal(0, 1e-3, 3)
    start = truth + np.array([0.3, 0.0, 0.1])
    path = [start.tolist()] * views if still else (start + rng.normal(0, 0.05, (views, 3))).tolist()
    return {
        "key": cell.key(run),
        **{k: getattr(cell, k) for k in Cell.__dataclass_fields__},
        "run": run,
        "seed": 0,
        "outcome": "max_views",
        "views": views,
        "error_mm": float(np.linalg.norm(est - truth) * 1e3),
        "truth_m": truth.tolist(),
        "estimate_m": est.tolist(),
        "cov_m2": (1e-6 * np.eye(3)).tolist(),
        "prior_m": (truth + 0.05).tolist(),
        "error_by_view_mm": errs,
        "camera_path_m": path,
        "estimate_path_m": [(truth + 0.05 * 0.5**i).tolist() for i in range(views)],
        "plan_ms_median": 1.0,
        "wall_s": 0.1,
    }


def _result(tmp_path: Path, cells: list[Cell], runs: int = 2, still: tuple[str, ...] = ()) -> CampaignResult:
    rng = np.random.default_rng(0)
    rows = tuple(_row(c, r, rng, c.planner in still) for c in cells for r in range(runs))
    spec = CampaignSpec(
        experiments=tuple(dict.fromkeys(c.experiment for c in cells)),
        worlds=tuple(dict.fromkeys(c.world for c in cells)),
        planners=tuple(dict.fromkeys(c.planner for c in cells)),
        measurements=tuple(dict.fromkeys(c.measurement for c in cells)),
        initial_errors_m=tuple(sorted({c.initial_error_m for c in cells})),
        runs=runs,
    )
    return CampaignResult(spec, Settings(), tuple(cells), rows, len(rows), 0, (), 0.0, tmp_path)


@pytest.fixture
def figures(monkeypatch: pytest.MonkeyPatch) -> Iterator[dict[str, Any]]:
    """The figures plot functions save, by file name, kept open for inspection."""
    import matplotlib.pyplot as plt

    kept: dict[str, Any] = {}
    monkeypatch.setattr(plots, "_save", lambda fig, path: kept.__setitem__(Path(path).name, fig))
    yield kept
    for fig in kept.values():
        plt.close(fig)


def _outside_texts(fig: Any) -> list[str]:
    """Titles, labels and legend texts whose box reaches outside the figure, and "(ticks)"
    when the drawn tick labels do (both drawn with Agg; texts placed in 3-D are left out:
    their 2-D box is not where they are drawn)."""
    from matplotlib.axis import Tick
    from mpl_toolkits.mplot3d.art3d import Text3D  # type: ignore[import-untyped]

    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    box = fig.bbox
    ticks = {id(t) for tick in fig.findobj(Tick) for t in (tick.label1, tick.label2)}
    out = []
    for t in fig.findobj(Text):
        if id(t) in ticks or isinstance(t, Text3D) or not t.get_visible() or not t.get_text().strip():
            continue
        bb = t.get_window_extent(renderer)
        if bb.x0 < box.x0 - 1 or bb.x1 > box.x1 + 1 or bb.y0 < box.y0 - 1 or bb.y1 > box.y1 + 1:
            out.append(t.get_text())
    tight, whole = fig.get_tightbbox(renderer), fig.bbox_inches
    if tight.x0 < -0.01 or tight.y0 < -0.01 or tight.x1 > whole.x1 + 0.01 or tight.y1 > whole.y1 + 0.01:
        out.append("(ticks)")
    return out


def _curves(fig: Any) -> list[Line2D]:
    return [
        ln for ax in fig.axes for ln in ax.get_lines() if len(ln.get_xdata()) > 0 and ax.get_legend() is None
    ]


SIXTEEN = [
    Cell(w, e, p, m, 0.1)
    for w in ("synthetic", "mujoco")
    for e in ("E1", "E5")
    for p in ("bve", "random")
    for m in ("range", "camera")
]


def test_error_by_view_draws_every_cell_in_a_panel_per_world_and_experiment(
    tmp_path: Path, figures: dict[str, Any]
) -> None:
    result = _result(tmp_path, SIXTEEN)
    plot_campaign(result)
    fig = figures["error_by_view.png"]
    panels = [ax for ax in fig.axes if ax.get_lines()]
    assert sorted(ax.get_title() for ax in panels) == sorted(
        f"{w} {e}" for w in ("synthetic", "mujoco") for e in ("E1", "E5")
    )
    lines = _curves(fig)
    assert len(lines) == len(SIXTEEN)  # the old figure stopped at 12
    styles = {(ln.get_label(), ln.get_color(), ln.get_linestyle()) for ln in lines}
    assert len({(c, s) for _, c, s in styles}) == len({lab for lab, _, _ in styles}) == 4
    legend = fig.legends[0]
    assert {t.get_text() for t in legend.get_texts()} == {lab for lab, _, _ in styles}
    # the legend sits outside every panel
    fig.canvas.draw()
    lb = legend.get_window_extent()
    assert not any(lb.overlaps(ax.get_window_extent()) for ax in panels)
    assert _outside_texts(fig) == []


def test_many_panels_are_capped_with_a_title_that_says_so(tmp_path: Path, figures: dict[str, Any]) -> None:
    import bve_mj.reporting.campaign_plots as report

    cells = [Cell("synthetic", f"E{i}", "bve", "range", 0.1) for i in range(1, 11)]
    result = _result(tmp_path, cells, runs=1)
    old = report.MAX_PANELS
    report.MAX_PANELS = 4
    try:
        plot_campaign(result)
    finally:
        report.MAX_PANELS = old
    fig = figures["error_by_view.png"]
    assert len(_curves(fig)) == 4
    assert "first 4 of 10" in fig._suptitle.get_text().replace("\n", " ")


def test_recoverability_titles_fit_in_a_one_panel_figure(tmp_path: Path, figures: dict[str, Any]) -> None:
    cells = [Cell("synthetic", "E5", "bve", "range", e, True) for e in (0.0, 0.1, 0.2)]
    plot_campaign(_result(tmp_path, cells))
    fig = figures["recoverability.png"]
    assert "recoverability" in fig._suptitle.get_text()
    assert _outside_texts(fig) == []
    # the legend does not cover the curves
    fig.canvas.draw()
    ax = fig.axes[0]
    assert ax.get_legend() is None and fig.legends
    assert not fig.legends[0].get_window_extent().overlaps(ax.get_window_extent())
    # a one-panel sample-path figure keeps its legend inside the figure too
    assert _outside_texts(figures["sample_paths.png"]) == []


def test_sample_paths_show_every_cell_and_say_when_the_camera_never_moved(
    tmp_path: Path, figures: dict[str, Any]
) -> None:
    cells = [Cell(w, "E5", p, m, 0.1) for w in ("synthetic", "mujoco") for p in ("bve", "random", "circle")
             for m in ("range", "camera")]  # fmt: skip
    plot_campaign(_result(tmp_path, cells, still=("circle",)))
    fig = figures["sample_paths.png"]
    panels = [ax for ax in fig.axes if ax.name == "3d"]
    assert len(panels) == len(cells)  # the old figure showed the first six
    for ax in panels:
        title = ax.get_title()
        paths = [ln for ln in ax.get_lines() if ln.get_color() == "#4aa3df"]
        assert len(paths) == 1
        xs = np.asarray(paths[0].get_data_3d()).T
        if "circle" in title:
            assert "never moved" in title and np.ptp(xs, axis=0).max() == 0
        else:
            assert "never moved" not in title and np.ptp(xs, axis=0).max() > 0
    assert _outside_texts(fig) == []


def test_episode_figures_fit_and_contain_the_whole_path(tmp_path: Path, figures: dict[str, Any]) -> None:
    truth = np.array([0.45, 0.1, 0.15])
    cams = [truth + d for d in ([-0.25, -0.1, 0.2], [-0.2, 0.05, 0.15], [-0.1, 0.0, 0.05], [-0.05, 0.0, 0.0])]
    views = [
        {"camera_position_m": c.tolist(), "estimate_m": (truth + 0.01 / (i + 1)).tolist(),
         "truth_m": truth.tolist(), "error_mm": 10.0 / (i + 1), "covariance_m2": (1e-6 * np.eye(3)).tolist()}
        for i, c in enumerate(cams)
    ]  # fmt: skip
    settings = {"episode": {"experiment": "E5", "approach": True}, "planner": {"kind": "bve"}}
    doc = {"views": views, "outcome": "approached", "final_error_mm": 2.5, "seed": 3, "settings": settings}
    plots.plot_episode(doc, tmp_path / "ep")
    path_fig, err_fig = figures["ep_path.png"], figures["ep_error.png"]
    for fig in (path_fig, err_fig):
        assert _outside_texts(fig) == []
    ax = path_fig.axes[0]
    for lim, col in zip((ax.get_xlim(), ax.get_ylim(), ax.get_zlim()), np.array(cams).T, strict=True):
        assert lim[0] <= col.min() and col.max() <= lim[1]
    assert "E5" in ax.get_title() and "seed 3" in ax.get_title()
    ax2 = err_fig.axes[0]
    ticks = [t for t in ax2.get_xticks() if ax2.get_xlim()[0] <= t <= ax2.get_xlim()[1]]
    assert all(float(t).is_integer() for t in ticks)
    assert "mm" in ax2.get_ylabel()


def test_wrap_title_fits_the_width() -> None:
    text = "recoverability: final error against initial error (10 runs a point, seed 0)"
    lines = plots.wrap_title(text, 4.2, 10).split("\n")
    assert len(lines) > 1 and all(len(line) * 0.6 * 10 / 72 <= 4.2 for line in lines)


def test_video_framing_and_projection() -> None:
    from bve_mj.reporting.overlay import _axes, _frame, _View

    rng = np.random.default_rng(1)
    pts = np.array([0.4, 0.0, 0.3]) + rng.uniform(-0.15, 0.15, (30, 3))
    az, el, fovy, w, h = 30.0, -25.0, 45.0, 640, 480
    lookat, dist = _frame(pts, az, el, fovy, w / h)
    fwd, right, up = _axes(az, el)
    focal = (h / 2) / np.tan(np.radians(fovy) / 2)
    view = _View(lookat - dist * fwd, right, up, fwd, focal, ((w - 1) / 2, (h - 1) / 2))
    uv, z = view.project(pts)
    assert np.all(z > 0)
    assert np.all((uv[:, 0] >= 0) & (uv[:, 0] < w) & (uv[:, 1] >= 0) & (uv[:, 1] < h))
    (c,), _ = view.project(lookat)
    assert np.allclose(c, ((w - 1) / 2, (h - 1) / 2))
    # a 3σ ellipse of an isotropic covariance is a circle of 3σ·f/z pixels
    ell = view.ellipse(lookat, (0.01**2) * np.eye(3))
    assert ell is not None
    assert np.allclose(ell[1][:2], 3 * 0.01 * focal / dist, rtol=1e-6)


def test_eye_overlay_says_which_range_is_measured_and_which_true(monkeypatch: pytest.MonkeyPatch) -> None:
    import cv2

    from bve_mj.perception.detection import Detection, NoDetection
    from bve_mj.reporting.overlay import draw_detection

    written: list[str] = []
    real = cv2.putText

    def put_text(img: np.ndarray, text: str, *args: Any, **kwargs: Any) -> Any:
        written.append(text)
        return real(img, text, *args, **kwargs)

    monkeypatch.setattr(cv2, "putText", put_text)
    img = np.zeros((120, 320, 3), np.uint8)
    out = draw_detection(img, NoDetection("too small"), "view 1", true_range_m=0.268, true_radius_m=0.03)
    assert out.shape == img.shape and out.any()
    assert any(t.startswith("true range 0.268 m") for t in written)
    assert any("no detection: too small" in t for t in written)
    det = Detection(np.array([160.0, 60.0]), 20.0, np.array([0.0, 0.0, 1.0]), 0.1, 0.351,
                    np.array([0.0, 0.0, 0.351]), 1e-6 * np.eye(3), 1200, 60, 0.0)  # fmt: skip
    written.clear()
    draw_detection(img, det, "view 2", assumed_radius_m=0.035, true_range_m=0.3, true_radius_m=0.03)
    assert any(t.startswith("measured range 0.351 m (assumes r = 35.0 mm)") for t in written)
    assert any(t.startswith("true range 0.300 m (true r = 30.0 mm)") for t in written)
