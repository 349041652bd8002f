"""The scenario suite's table: one line per scenario from its summary (or ``--json``'s
``scenarios``), plain or Markdown, with the legend that says how to read it."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

__all__ = ["format_suite"]


def format_suite(summaries: dict[str, dict[str, Any]], markdown: bool = False) -> list[str]:
    """The table, from :meth:`bve_mj.campaigns.scenarios.SuiteResult.summary` (or
    ``--json``'s ``scenarios``): scenario | outcomes | error median / p95 / max [mm] | mean NEES
    of the claim and of the filter | inside 3σ % | silent failures | median views | wall s."""

    def num(x: Any, spec: str) -> str:
        return "-" if x is None or (isinstance(x, float) and math.isnan(x)) else format(x, spec)

    def flagged(nees: Any, band: Sequence[float]) -> str:  # * outside the band of honest means
        known = nees is not None and math.isfinite(nees) and all(map(math.isfinite, band))
        return num(nees, ".2f") + ("*" if known and not band[0] <= nees <= band[1] else "")

    cols = ("scenario", "outcomes", "median mm", "p95 mm", "max mm", "NEES", "filter", "in3σ%", "silent",
            "exit0 out", "r err mm", "r NEES", "err/CRB", "views", "wall s")  # fmt: skip
    rows = []
    for name, s in summaries.items():
        e = s["error_mm"]
        band = s.get("nees_band_95", (math.nan, math.nan))  # the filter's: Gaussian
        claim_band = s.get("claim_nees_band_95", band)  # the claim's shape's
        r_band = s.get("radius_nees_band_95", (math.nan, math.nan))
        rows.append((
            name, " ".join(f"{k}:{v}" for k, v in sorted(s["outcomes"].items())),
            num(e["median"], ".2f"), num(e["p95"], ".2f"), num(e["max"], ".2f"),
            flagged(s["nees_mean"], claim_band), flagged(s.get("filter_nees_mean"), band),
            num(s["inside_3sigma_pct"], ".0f"), str(s["silent_failures"]),
            str(s.get("answered_outside", "-")),
            num(s.get("radius_error_mm", {}).get("median"), ".2f"),
            flagged(s.get("radius_nees_mean"), r_band),
            num(s.get("error_to_crb_median"), ".2f"), num(s["views_median"], ".1f"), num(s["wall_s"], ".1f"),
        ))  # fmt: skip
    honest = sorted({f"{s.get('inside_3sigma_honest_pct', 97.07):.1f}%" for s in summaries.values()})
    note = (
        "error: final ‖estimate - truth‖ [mm]; NEES: mean (3 if honest; * outside the 95% band of the "
        "mean of that many honest episodes, of the claims' shape: wider for a Student-t than the χ² "
        "band); filter: the same of the filter's own covariance (χ² band), before "
        "the claim adds the fruit's own offset and scales it (innovations, refusals, tails); in3σ%: "
        f"truth inside the final 3σ ellipsoid ({'/'.join(honest)} if honest: 97.1% for a Gaussian "
        "claim, less for a Student-t); silent: a success outcome (converged, stable, approached) with "
        "the truth outside the claim's 99.9% region (its bound's 99.9% ellipsoid); exit0 out: the same for "
        "every outcome that exits 0 (stalled and max_views too: their estimate is an answer, though "
        "not a claim that it is done); r err: median |radius error| [mm] and r NEES its mean NEES (1 "
        "if honest; * as NEES); err/CRB: median of the final error over √tr of the Cramér-Rao bound "
        "of the views taken; views: median per episode; wall: sum of the episodes' wall times"
    )
    if markdown:
        lines = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
        lines += ["| " + " | ".join(r) + " |" for r in rows]
        return [*lines, "", note]
    widths = [max(len(c), *(len(r[i]) for r in rows)) for i, c in enumerate(cols)]
    fmt = "  ".join(f"{{:<{w}}}" if i < 2 else f"{{:>{w}}}" for i, w in enumerate(widths))
    head = fmt.format(*cols)
    return [head, "-" * len(head), *(fmt.format(*r) for r in rows), note]
