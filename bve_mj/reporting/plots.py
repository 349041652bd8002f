"""Figures (matplotlib, an optional extra: ``pip install bve_mj[plots]``), imported lazily."""

from __future__ import annotations

import textwrap
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from bve_mj.atomic import atomic_path
from bve_mj.errors import ConfigError
from bve_mj.loop.episode import EpisodeResult

__all__ = [
    "draw_path",
    "path_legend",
    "plot_consistency",
    "plot_episode",
    "plot_sample_paths",
    "require_matplotlib",
    "wrap_title",
]


def require_matplotlib(field: str = "plots", value: object = "matplotlib", alternative: str = "") -> None:
    """Raise a ConfigError naming ``field`` unless matplotlib can be imported."""
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        raise ConfigError(
            field, value, "matplotlib installed: pip install 'bve_mj[plots]'" + alternative
        ) from None


def _pyplot():  # type: ignore[no-untyped-def]
    require_matplotlib()
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(fig: Any, path: Path) -> None:
    """Save a figure atomically (never a half-written PNG) and close it."""
    import matplotlib.pyplot as plt

    try:
        with atomic_path(path) as tmp:
            fig.savefig(tmp)
    finally:
        plt.close(fig)


def wrap_title(text: str, width_in: float, fontsize: float) -> str:
    """``text`` broken into lines that fit ``width_in`` inches at ``fontsize`` points (each
    existing line wrapped on its own; a character is taken as 0.6 em wide, a safe upper bound
    for DejaVu Sans)."""
    chars = max(12, int(width_in * 72.0 / (0.6 * fontsize)))
    return "\n".join(textwrap.fill(line, chars) if line else line for line in text.split("\n"))


def path_legend(fig: Any, ax: Any, fontsize: float = 8) -> None:
    """One legend for a figure of :func:`draw_path` panels, below them (never over a curve),
    in as many columns as the figure's width holds."""
    handles, labels = ax.get_legend_handles_labels()
    if handles:
        entry_in = max(len(lab) for lab in labels) * 0.6 * fontsize / 72.0 + 0.6
        ncol = max(1, min(len(handles), int(fig.get_figwidth() / entry_in)))
        fig.legend(handles, labels, loc="outside lower center", ncol=ncol, fontsize=fontsize)


def draw_path(
    ax: Any,
    cams: np.ndarray,
    est: np.ndarray,
    truth: np.ndarray,
    title: str,
    legend: bool = False,
    workspace: tuple[np.ndarray, float] | None = None,
) -> None:
    """On a 3-D axis: camera positions (blue, light to dark in time), estimates (green,
    prior first), true fruit (red), equal axes; optionally the workspace sphere [m].

    A camera that never moved (every view from its start: a planner that found no reachable
    viewpoint) is said so in the panel, since its path is a single point under the start
    marker. The truth is drawn over the estimate (they coincide once converged); create the
    axis with ``computed_zorder=False`` for that to hold in 3-D.
    """
    cams = np.asarray(cams, dtype=float).reshape(-1, 3)
    est = np.asarray(est, dtype=float).reshape(-1, 3)
    if len(cams):
        ax.plot(*cams.T, "-", color="#4aa3df", lw=1.0, zorder=2)
        shade = np.linspace(0.35, 1.0, len(cams))
        ax.scatter(*cams.T, c=shade, cmap="Blues", vmin=0.0, vmax=1.0, s=14, zorder=3,
                   depthshade=False, label="camera at each view (light → dark)")  # fmt: skip
        ax.scatter(*cams[0], color="k", marker="^", s=36, zorder=4, depthshade=False, label="camera start")
    if workspace is not None:
        centre, radius = workspace
        u, v = np.meshgrid(np.linspace(0, 2 * np.pi, 24), np.linspace(0, np.pi, 12))
        ax.plot_wireframe(
            centre[0] + radius * np.cos(u) * np.sin(v),
            centre[1] + radius * np.sin(u) * np.sin(v),
            centre[2] + radius * np.cos(v),
            color="0.8",
            lw=0.3,
            label="workspace sphere",
        )
    ax.plot(*est.T, "-", color="#2ca02c", lw=1.0, zorder=2, label="estimate (prior → final)")
    ax.scatter(*est[-1], color="#2ca02c", s=40, zorder=5, depthshade=False, label="final estimate")
    ax.scatter(*truth, color="#d62728", s=70, marker="*", zorder=6, depthshade=False, label="true fruit")
    still = len(cams) > 1 and float(np.ptp(cams, axis=0).max()) < 1e-6
    if still:  # said in the title: a note inside a 3-D axis lands on its tick labels
        title = f"{title}\ncamera never moved: all {len(cams)} views from its start"
    ax.set_title(title, fontsize=9, color="#b03000" if still else "black")
    ax.set_xlabel("x [m]", fontsize=8)
    ax.set_ylabel("y [m]", fontsize=8)
    ax.set_zlabel("z [m]", fontsize=8)
    ax.tick_params(labelsize=7)
    pts = np.vstack([cams, est, truth[None, :]])
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    mid, half = (lo + hi) / 2, max(float((hi - lo).max()) / 2 * 1.05, 0.05)
    ax.set_xlim(mid[0] - half, mid[0] + half)
    ax.set_ylim(mid[1] - half, mid[1] + half)
    ax.set_zlim(mid[2] - half, mid[2] + half)
    ax.set_box_aspect((1, 1, 1), zoom=0.9)
    from matplotlib.ticker import MaxNLocator

    for axis in (ax.xaxis, ax.yaxis, ax.zaxis):  # fewer ticks: labels that do not run together
        axis.set_major_locator(MaxNLocator(5))
    if legend:
        ax.legend(fontsize=7, loc="upper left")


def plot_sample_paths(
    episodes: Sequence[tuple[str, EpisodeResult, np.ndarray]],
    path: str | Path,
    columns: int = 2,
    workspace: tuple[np.ndarray, float] | None = None,
) -> Path:
    """The paper's Fig. 4 (:func:`draw_path` per episode); optionally the workspace sphere
    (centre, radius) [m].

    ``episodes``: (title, result, true fruit position) triples. Writes a PNG; returns its path.
    """
    plt = _pyplot()
    columns = max(1, min(columns, len(episodes)))
    rows = (len(episodes) + columns - 1) // columns
    width = 5.0 * columns
    fig = plt.figure(figsize=(width, 4.4 * rows + 0.5), dpi=110, layout="constrained")
    ax = None
    for i, (title, result, truth) in enumerate(episodes):
        ax = fig.add_subplot(rows, columns, i + 1, projection="3d", computed_zorder=False)
        cams = np.array([v.p_world_camera for v in result.views])
        est = np.array([result.prior.centre_m] + [v.belief.centre_m for v in result.views])
        err_mm = 1e3 * float(np.linalg.norm(result.final.centre_m - truth))
        draw_path(
            ax,
            cams,
            est,
            truth,
            wrap_title(f"{title}\nfinal error {err_mm:.1f} mm", 4.6, 9),
            False,
            workspace,
        )
    if ax is not None:
        path_legend(fig, ax)
    out = Path(path)
    _save(fig, out)
    return out


def _episode_label(doc: dict[str, object]) -> str:
    """ "E5 localise, bve planner, camera, seed 0" from an episode document (what it has)."""
    settings = doc.get("settings")
    parts: list[str] = []
    if isinstance(settings, dict):
        ep, planner, meas = (settings.get(k) or {} for k in ("episode", "planner", "measurement"))
        if ep.get("experiment"):
            parts.append(f"{ep['experiment']} {'approach' if ep.get('approach') else 'localise'}")
        if planner.get("kind"):
            parts.append(f"{planner['kind']} planner")
        if meas.get("kind"):
            parts.append(f"{meas['kind']} measurement")
    if "seed" in doc:
        parts.append(f"seed {doc['seed']}")
    return ", ".join(parts)


def plot_episode(doc: dict[str, object], prefix: str | Path) -> tuple[Path, Path]:
    """From an episode's JSON document: ``PREFIX_path.png`` (camera path, truth, estimates)
    and ``PREFIX_error.png`` (error and largest σ against view number; with the radius in
    the state, the radius' error and σ too)."""
    plt = _pyplot()
    from matplotlib.ticker import MaxNLocator

    views = doc["views"]
    assert isinstance(views, list)
    cams = np.array([v["camera_position_m"] for v in views if "camera_position_m" in v]).reshape(-1, 3)
    est = np.array([v["estimate_m"] for v in views])
    truth = np.array(views[0]["truth_m"])
    err = np.array([v["error_mm"] for v in views])
    sig = np.array([1e3 * np.sqrt(np.linalg.eigvalsh(np.array(v["covariance_m2"]))[-1]) for v in views])
    prefix = Path(prefix)
    path_png = prefix.with_name(prefix.name + "_path.png")
    err_png = prefix.with_name(prefix.name + "_error.png")
    what = _episode_label(doc)
    head = f"{what}: " if what else ""
    title = f"{head}outcome {doc['outcome']}, final error {doc['final_error_mm']:.1f} mm"

    fig = plt.figure(figsize=(6.4, 5.6), dpi=110, layout="constrained")
    ax = fig.add_subplot(projection="3d", computed_zorder=False)
    if len(cams):
        ax.plot(*cams.T, "-o", color="#4aa3df", ms=3, label="camera at each view", zorder=2)
        ax.scatter(*cams[0], color="k", marker="^", s=36, label="camera start", zorder=3, depthshade=False)
        for i, p in enumerate(cams):
            ax.text(*p, f" {i}", fontsize=7, color="#1f5f8f", zorder=4)
    ax.plot(*est.T, "-", color="#2ca02c", label="estimate after each view", zorder=2)
    ax.scatter(*est[-1], color="#2ca02c", s=30, label="final estimate", zorder=4, depthshade=False)
    ax.scatter(*truth, color="#d62728", marker="*", s=90, label="true fruit", zorder=5, depthshade=False)
    pts = np.vstack([cams, est, truth[None]])
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    mid, half = (lo + hi) / 2, max(float((hi - lo).max()) / 2 * 1.05, 0.05)
    for setlim, m in zip((ax.set_xlim, ax.set_ylim, ax.set_zlim), mid, strict=True):
        setlim(m - half, m + half)
    ax.set_box_aspect((1, 1, 1), zoom=0.88)
    for axis in (ax.xaxis, ax.yaxis, ax.zaxis):
        axis.set_major_locator(MaxNLocator(6))
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_zlabel("z [m]")
    ax.tick_params(labelsize=8)
    fig.legend(loc="outside lower center", ncol=3, fontsize=8)
    ax.set_title(wrap_title(title + " (numbers: view)", 6.0, 9), fontsize=9)
    _save(fig, path_png)

    fig, ax2 = plt.subplots(figsize=(6.4, 3.8), dpi=110, layout="constrained")
    n = np.arange(len(views))
    ax2.semilogy(n, err, "-o", label="error ‖estimate − truth‖")
    ax2.semilogy(n, sig, "--s", ms=3, label="largest posterior σ")
    if all(v.get("radius_error_mm") is not None for v in views):
        r_err = np.array([abs(v["radius_error_mm"]) for v in views])
        r_sig = np.array([v["radius_sigma_mm"] for v in views])
        ax2.semilogy(n, np.maximum(r_err, 1e-4), "-^", ms=4, color="#9467bd", label="radius error |r̂ − r|")
        ax2.semilogy(n, r_sig, ":", color="#9467bd", label="radius σ")
    ax2.set_xlabel("view (0 = from the start pose)")
    ax2.set_ylabel("error and σ [mm], log scale")
    ax2.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax2.grid(True, which="both", alpha=0.3)
    ax2.legend(loc="best", fontsize=8)
    ax2.set_title(wrap_title(title, 6.0, 9), fontsize=9)
    _save(fig, err_png)
    return path_png, err_png


def plot_consistency(curves: dict[str, list[tuple[float, float]]], path: str | Path, title: str = "") -> Path:
    """The consistency plot: for each named curve (a scenario, a filter, ...; from
    :func:`bve_mj.estimation.metrics.consistency_curve`), the share of episodes whose truth lies inside
    the final p-ellipsoid against p. An honest filter lies on the diagonal; below it, the
    covariance claims too much. Written as PNG to ``path``."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(6.4, 5.2), dpi=110, layout="constrained")
    ax.plot([0.5, 1.0], [0.5, 1.0], color="0.3", lw=1.2, ls="--", label="honest")
    colours = plt.get_cmap("tab20").colors
    for k, (name, points) in enumerate(curves.items()):
        p = [x for x, _ in points]
        share = [y for _, y in points]
        if name == "all":
            ax.plot(p, share, marker="o", ms=4, lw=2.6, color="black", label=name, zorder=5)
        else:
            ax.plot(
                p, share, marker="o", ms=3, lw=1.1, color=colours[(2 * k) % 20 + (k // 10) % 2], label=name
            )
    ax.set_xlim(0.48, 1.005)
    ax.set_ylim(0.0, 1.02)
    ax.set_xlabel("p (the claim's region holding the truth with probability p, if honest)")
    ax.set_ylabel("share of episodes with the truth inside it")
    ax.set_title(wrap_title(title or "consistency of the final covariance", 6.0, 11), fontsize=11)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, ncols=2, loc="lower right")
    out = Path(path)
    _save(fig, out)
    return out
