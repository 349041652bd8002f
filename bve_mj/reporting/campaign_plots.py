"""A campaign's figure: error against initial error, one line per varying axis, faceted
where more than one other axis varies (matplotlib, imported when drawn)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from bve_mj.campaigns.runner import CampaignResult
from bve_mj.campaigns.spec import Cell
from bve_mj.reporting.campaign_report import cell_summary

__all__ = ["MAX_PANELS", "plot_campaign"]

# --------------------------------------------------------------------------- plots
_AXES = ("world", "experiment", "planner", "measurement", "initial_error_m", "approach")


_FACET = ("world", "experiment")


MAX_PANELS = 48

"""At most this many panels in one figure; a figure that leaves some out says so in its title."""


def _value(cell: Cell, key: str) -> str:
    v = getattr(cell, key)
    if key == "approach":
        return "approach" if v else "localise"
    if key == "initial_error_m":
        return f"e0={v:g} m"
    return str(v)


def _label(cell: Cell, varying: Sequence[str]) -> str:
    """The cell's values on the ``varying`` axes (not the initial error), e.g. "bve camera"."""
    parts = [_value(cell, k) for k in varying if k != "initial_error_m"]
    return " ".join(parts) or cell.experiment


def _varying(cells: Sequence[Cell]) -> list[str]:
    """The axes on which ``cells`` take more than one value, in :data:`_AXES` order."""
    return [k for k in _AXES if len({getattr(c, k) for c in cells}) > 1]


def _line_keys(cells: Sequence[Cell]) -> list[str]:
    """The axes that tell the lines of one world x experiment panel apart (planner and
    measurement when nothing varies, so every line still says what it is)."""
    keys = [k for k in _varying(cells) if k not in (*_FACET, "initial_error_m")]
    return keys or ["planner", "measurement"]


def _constant(cells: Sequence[Cell]) -> str:
    """What every cell shares, for a title: "measurement camera, localise"."""
    keys = [k for k in ("planner", "measurement", "approach") if k not in _varying(cells)]
    return ", ".join(_value(cells[0], k) if k == "approach" else f"{k} {_value(cells[0], k)}" for k in keys)


def _styles(labels: Sequence[str]) -> dict[str, tuple[Any, str]]:
    """A distinct (colour, line style) per label: tab10's colours up to 10 labels, tab20's
    beyond, the line style cycling too (curves that coincide stay visible, and no pair
    repeats up to 80 labels)."""
    import matplotlib

    cmap = matplotlib.colormaps["tab10" if len(labels) <= 10 else "tab20"]
    n = cmap.N
    dashes = ("-", "--", "-.", ":")
    return {lab: (cmap(i % n), dashes[(i + i // n) % len(dashes)]) for i, lab in enumerate(labels)}


def _grid(n: int, max_columns: int) -> tuple[int, int]:
    columns = max(1, min(max_columns, n))
    return (n + columns - 1) // columns, columns


def _capped(n: int, what: str) -> str:
    return f"; first {MAX_PANELS} of {n} {what} shown" if n > MAX_PANELS else ""


def _rows(runs_of: Sequence[Sequence[Any]], columns: int) -> list[Any]:
    """Grid slots, row by row: each sequence starts a new row (wrapping at ``columns``),
    None fills a row's end; at most :data:`MAX_PANELS` slots' worth of whole rows."""
    slots: list[Any] = []
    for items in runs_of:
        slots += [*items, *[None] * (-len(items) % columns)]
    return slots[: max(1, MAX_PANELS // columns) * columns]


def plot_campaign(
    result: CampaignResult,
    cells: Sequence[Cell] | None = None,
    directory: Path | None = None,
    prefix: str = "",
) -> list[Path]:
    """``error_by_view.png`` always; ``recoverability.png`` when the initial error varies;
    ``sample_paths.png``: one run of each curve's cell. Of ``cells`` (default: all), in
    ``directory`` (default: the campaign's), each name preceded by ``prefix``.

    The error and path figures have a panel per world x experiment, the planners,
    measurements and modes as distinct lines (one legend, outside the panels); the
    recoverability figure has a panel per sweep. A figure never drops a cell silently: beyond
    :data:`MAX_PANELS` panels its title says how many it shows.
    """
    from bve_mj.reporting.plots import _pyplot, _save, draw_path, path_legend, wrap_title

    plt = _pyplot()
    from matplotlib.ticker import MaxNLocator

    d = result.directory if directory is None else directory
    cells = list(result.cells if cells is None else cells)
    written: list[Path] = []
    if not cells:
        return written
    groups: dict[tuple[Any, ...], list[Cell]] = {}
    for c in cells:
        groups.setdefault((c.world, c.experiment, c.planner, c.measurement, c.approach), []).append(c)
    for group in groups.values():
        group.sort(key=lambda c: c.initial_error_m)
    # per group (an initial-error sweep, or one cell), the cell at its middle initial error
    curve_cells = [group[len(group) // 2] for group in groups.values()]
    swept = [g for g in groups.values() if len(g) > 1]
    line_keys = _line_keys(curve_cells)
    labels = list(dict.fromkeys(_label(c, line_keys) for c in curve_cells))
    styles = _styles(labels)
    facets: dict[tuple[str, str], list[Cell]] = {}
    for c in curve_cells:
        facets.setdefault((c.world, c.experiment), []).append(c)
    runs = f"{result.spec.runs} runs a cell, seed {result.spec.seed}"
    shared = _constant(curve_cells)
    middle = ""
    if swept:
        e0 = sorted({c.initial_error_m for c in curve_cells})
        middle = (
            "; each curve at the middle of its initial-error sweep "
            f"(e0 = {', '.join(f'{e:g}' for e in e0)} m; every e0 in recoverability.png)"
        )

    # -- error against views: a panel per world x experiment, a line per planner/measurement/mode
    per_world: dict[str, list[tuple[str, str]]] = {}
    for key in facets:
        per_world.setdefault(key[0], []).append(key)
    cols = min(4, max(len(v) for v in per_world.values()))
    if cols == 1:  # one experiment a world: side by side rather than a tall column
        cols = min(4, len(facets))
        slots = _rows([list(facets)], cols)
    else:
        slots = _rows(list(per_world.values()), cols)
    rows_n = len(slots) // cols
    width = max(4.3 * cols, 6.4)
    fig = plt.figure(
        figsize=(width, 3.2 * rows_n + 1.0 + 0.2 * math.ceil(len(labels) / 4)), dpi=110, layout="constrained"
    )
    axes = fig.subplots(rows_n, cols, squeeze=False, sharey=True)
    for i, key in enumerate(slots):
        ax = axes[i // cols][i % cols]
        if key is None:
            ax.set_axis_off()
            continue
        for cell in facets[key]:
            label = _label(cell, line_keys)
            colour, dash = styles[label]
            s = cell_summary(result.cell_rows(cell), result.spec.recovered_mm)
            if "error_by_view_median_mm" not in s:
                ax.plot([], [], dash, color=colour, label=f"{label} (no finished run)")
                ax.text(
                    0.5, 0.5, f"{label}: no finished run", transform=ax.transAxes, ha="center", fontsize=8
                )
                continue
            n = np.arange(len(s["error_by_view_median_mm"]))
            ax.semilogy(n, s["error_by_view_median_mm"], dash, color=colour, lw=1.6, label=label)
            ax.fill_between(
                n, s["error_by_view_p25_mm"], s["error_by_view_p75_mm"], color=colour, alpha=0.12, lw=0
            )
        ax.set_title(f"{key[0]} {key[1]}", fontsize=9)
        ax.set_xlabel("view (0 = start)", fontsize=8)
        ax.xaxis.set_major_locator(MaxNLocator(integer=True))
        if i % cols == 0:
            ax.set_ylabel("‖estimate − truth‖ [mm]\nmedian, IQR shaded", fontsize=8)
        ax.tick_params(which="both", labelsize=7, labelleft=True)
        ax.grid(True, which="both", alpha=0.3)
    handles = [plt.Line2D([], [], color=styles[lab][0], ls=styles[lab][1], lw=1.6) for lab in labels]
    fig.legend(handles, labels, loc="outside lower center", ncol=min(4, len(labels)), fontsize=8,
               title=" ".join(line_keys), title_fontsize=8)  # fmt: skip
    placed = sum(k is not None for k in slots)
    left = (
        f"; first {placed} of {len(facets)} world x experiment panels shown" if placed < len(facets) else ""
    )
    title = f"error against views ({runs}{'; ' + shared if shared else ''}{middle}{left})"
    fig.suptitle(wrap_title(title, width - 0.3, 10), fontsize=10)
    written.append(d / f"{prefix}error_by_view.png")
    _save(fig, written[-1])

    # -- recoverability: a panel per initial-error sweep
    if swept:
        rows_n, cols = _grid(min(len(swept), MAX_PANELS), 4)
        width = max(4.4 * cols, 6.0)
        fig = plt.figure(figsize=(width, 3.5 * rows_n + 1.2), dpi=110, layout="constrained")
        for i, group in enumerate(swept[:MAX_PANELS]):
            ax = fig.add_subplot(rows_n, cols, i + 1)
            summaries = [cell_summary(result.cell_rows(c), result.spec.recovered_mm) for c in group]
            x = [c.initial_error_m for c, s in zip(group, summaries, strict=True) if "rmse_mm" in s]
            ss = [s for s in summaries if "rmse_mm" in s]
            ax.plot(x, [s["rmse_mm"] for s in ss], "-", color="#1f77b4", label="RMSE per axis")
            ax.plot(x, [s["mae_mm"] for s in ss], "-", color="#e5ae38", label="MAE per axis")
            ax.plot(x, [s["euclid_median_mm"] for s in ss], "--", color="0.3", label="Euclidean median")
            ax2 = ax.twinx()
            ax2.plot(x, [s["mse_mm2"] for s in ss], "-", color="#d62728", label="MSE (right axis)")
            ax2.set_ylabel("MSE [mm²]", fontsize=8, color="#d62728")
            ax2.tick_params(labelsize=7, colors="#d62728")
            ax.set_xlabel(
                wrap_title("initial error e0 [m] (estimate = truth + U[-e0, e0]³)", 4.0, 7), fontsize=7
            )
            ax.set_ylabel("final error [mm]", fontsize=8)
            ax.tick_params(labelsize=7)
            ax.grid(True, alpha=0.3)
            c = group[0]
            mode = "approach" if c.approach else "localise"
            ax.set_title(wrap_title(f"{c.world} {c.experiment} {c.planner} {c.measurement} {mode}", 4.0, 9),
                         fontsize=9)  # fmt: skip
            if i == 0:
                h1, l1 = ax.get_legend_handles_labels()
                h2, l2 = ax2.get_legend_handles_labels()
                fig.legend(h1 + h2, l1 + l2, loc="outside lower center", ncol=4, fontsize=8)
        title = (
            f"recoverability: final error against initial error ({result.spec.runs} runs a point, "
            f"seed {result.spec.seed}{_capped(len(swept), 'sweeps')})"
        )
        fig.suptitle(wrap_title(title, width - 0.3, 10), fontsize=10)
        written.append(d / f"{prefix}recoverability.png")
        _save(fig, written[-1])

    # -- sample paths: one run of each curve's cell, a row (or more) per world x experiment
    shown: list[tuple[Cell, dict[str, Any]]] = []
    for cell in curve_cells:
        row = next((r for r in result.cell_rows(cell) if r.get("camera_path_m")), None)
        if row is not None:
            shown.append((cell, row))
    if shown:
        per_facet: dict[tuple[str, str], list[tuple[Cell, dict[str, Any]]]] = {}
        for cell, row in shown:
            per_facet.setdefault((cell.world, cell.experiment), []).append((cell, row))
        cols = min(3, max(len(v) for v in per_facet.values()))
        if cols == 1:  # one cell a world x experiment: side by side rather than a tall column
            cols = min(3, len(shown))
            slots = _rows([shown], cols)
        else:
            slots = _rows(list(per_facet.values()), cols)
        placed = sum(s is not None for s in slots)
        rows_n = len(slots) // cols
        width = 4.6 * cols
        fig = plt.figure(figsize=(width, 4.2 * rows_n + 1.0), dpi=110, layout="constrained")
        ax = None
        for i, slot in enumerate(slots):
            if slot is None:
                continue
            cell, r = slot
            ax = fig.add_subplot(rows_n, cols, i + 1, projection="3d", computed_zorder=False)
            title = (
                f"{cell.world} {cell.experiment}: {_label(cell, line_keys)}, run {r['run']}\n"
                f"final error {r['error_mm']:.1f} mm"
            )
            draw_path(
                ax,
                np.array(r["camera_path_m"]),
                np.array([r["prior_m"], *r["estimate_path_m"]]),
                np.array(r["truth_m"]),
                wrap_title(title, 4.4, 9),
            )
        if ax is not None:
            path_legend(fig, ax)
        left = f"; first {placed} of {len(shown)} cells shown" if placed < len(shown) else ""
        title = (
            f"sample paths: one run of each cell ({shared + '; ' if shared else ''}"
            f"seed {result.spec.seed}{left})"
        )
        fig.suptitle(wrap_title(title, width - 0.3, 10), fontsize=10)
        written.append(d / f"{prefix}sample_paths.png")
        _save(fig, written[-1])
    return written
