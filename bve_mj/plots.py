"""Figures (matplotlib, an optional extra: ``pip install bve_mj[plots]``), imported lazily."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from bve_mj.atomic import atomic_path
from bve_mj.episode import EpisodeResult
from bve_mj.errors import ConfigError

__all__ = ["draw_path", "plot_episode", "plot_sample_paths", "require_matplotlib"]


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
    prior first), true fruit (red), equal axes; optionally the workspace sphere [m]."""
    ax.plot(*cams.T, "-", color="#4aa3df", lw=0.8)
    shade = np.linspace(0.25, 1.0, len(cams))
    ax.scatter(*cams.T, c=shade, cmap="Blues", vmin=0.0, vmax=1.0, s=12, label="camera (light→dark)")
    ax.scatter(*cams[0], color="k", marker="^", s=30, label="start")
    if workspace is not None:
        centre, radius = workspace
        u, v = np.meshgrid(np.linspace(0, 2 * np.pi, 24), np.linspace(0, np.pi, 12))
        ax.plot_wireframe(
            centre[0] + radius * np.cos(u) * np.sin(v),
            centre[1] + radius * np.sin(u) * np.sin(v),
            centre[2] + radius * np.cos(v),
            color="0.8",
            lw=0.3,
        )
    ax.plot(*est.T, "-", color="#2ca02c", lw=0.8)
    ax.scatter(*est[-1], color="#2ca02c", s=40, label="final estimate")
    ax.scatter(*truth, color="#d62728", s=60, marker="*", label="true fruit")
    ax.set_title(title, fontsize=9)
    ax.set_xlabel("x [m]", fontsize=8)
    ax.set_ylabel("y [m]", fontsize=8)
    ax.set_zlabel("z [m]", fontsize=8)
    ax.tick_params(labelsize=7)
    pts = np.vstack([cams, est, truth[None, :]])
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    mid, half = (lo + hi) / 2, max(float((hi - lo).max()) / 2, 0.05)
    ax.set_xlim(mid[0] - half, mid[0] + half)
    ax.set_ylim(mid[1] - half, mid[1] + half)
    ax.set_zlim(mid[2] - half, mid[2] + half)
    ax.set_box_aspect((1, 1, 1))
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
    rows = (len(episodes) + columns - 1) // columns
    fig = plt.figure(figsize=(5.0 * columns, 4.4 * rows), dpi=110)
    for i, (title, result, truth) in enumerate(episodes):
        ax = fig.add_subplot(rows, columns, i + 1, projection="3d")
        cams = np.array([v.p_world_camera for v in result.views])
        est = np.array([result.prior.mean] + [v.belief.mean for v in result.views])
        err_mm = 1e3 * float(np.linalg.norm(result.final.mean - truth))
        draw_path(ax, cams, est, truth, f"{title}\nfinal error {err_mm:.0f} mm", i == 0, workspace)
    fig.tight_layout()
    out = Path(path)
    _save(fig, out)
    return out


def plot_episode(doc: dict[str, object], prefix: str | Path) -> tuple[Path, Path]:
    """From an episode's JSON document: ``PREFIX_path.png`` (camera path, truth, estimates)
    and ``PREFIX_error.png`` (error and largest σ against view number)."""
    plt = _pyplot()
    views = doc["views"]
    assert isinstance(views, list)
    cams = np.array([v["camera_position_m"] for v in views if "camera_position_m" in v])
    est = np.array([v["estimate_m"] for v in views])
    truth = np.array(views[0]["truth_m"])
    err = np.array([v["error_mm"] for v in views])
    sig = np.array([1e3 * np.sqrt(np.linalg.eigvalsh(np.array(v["covariance_m2"]))[-1]) for v in views])
    prefix = Path(prefix)
    path_png = prefix.with_name(prefix.name + "_path.png")
    err_png = prefix.with_name(prefix.name + "_error.png")

    fig = plt.figure(figsize=(6, 5), dpi=110)
    ax = fig.add_subplot(projection="3d")
    if len(cams):
        ax.plot(*cams.T, "-o", color="#4aa3df", ms=3, label="camera")
    ax.plot(*est.T, "-", color="#2ca02c", label="estimate")
    ax.scatter(*truth, color="#d62728", marker="*", s=80, label="true fruit")
    pts = np.vstack([cams, est, truth[None]]) if len(cams) else np.vstack([est, truth[None]])
    mid, half = pts.mean(axis=0), max(float(np.ptp(pts, axis=0).max()) / 2, 0.05)
    for setlim, m in zip((ax.set_xlim, ax.set_ylim, ax.set_zlim), mid, strict=True):
        setlim(m - half, m + half)
    ax.set_box_aspect((1, 1, 1))
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_zlabel("z [m]")
    ax.legend(fontsize=8)
    ax.set_title(f"outcome {doc['outcome']}, final error {doc['final_error_mm']:.1f} mm", fontsize=9)
    fig.tight_layout()
    _save(fig, path_png)

    fig, ax2 = plt.subplots(figsize=(6, 3.5), dpi=110)
    n = np.arange(len(views))
    ax2.semilogy(n, err, "-o", label="error ‖estimate - truth‖")
    ax2.semilogy(n, sig, "--", label="largest posterior σ")
    ax2.set_xlabel("view")
    ax2.set_ylabel("mm")
    ax2.grid(True, which="both", alpha=0.3)
    ax2.legend()
    fig.tight_layout()
    _save(fig, err_png)
    return path_png, err_png
