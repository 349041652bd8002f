"""The scenario suite for every fruit: ``bve-mj scenarios --fruits all``.

Each scenario runs ``seeds`` every-fruit episodes (:func:`bve_mj.loop.mujoco_fruits.
run_every_fruit_episode`; episode ``i`` seeded as the one-target suite seeds it, so the same
scene), and reports per scenario, over every true ripe fruit of the work zone of every
episode: the share localised (a localised track within 5 mm of it), the share of episodes
with no false track (a confirmed track on no fruit), the views per episode, the radius
error, the fruit's NEES and the share inside the 3σ ellipsoid, the **silent** fruit (localised
with the truth outside its claim's 99.9% region), and the planning and association times.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import partial
from typing import TYPE_CHECKING, Any, get_args

import numpy as np

from bve_mj.campaigns.runs import radius_metrics
from bve_mj.campaigns.scenarios import SILENT_PROBABILITY, Scenario, crashed_rows, run_chunk, run_rows
from bve_mj.campaigns.spec import episode_seed
from bve_mj.config import PlannerKind, Settings, with_overrides
from bve_mj.errors import BveError, ConfigError
from bve_mj.estimation.belief import Belief
from bve_mj.sim.true_boxes import ripe_colours

if TYPE_CHECKING:
    from bve_mj.loop.mujoco_fruits import FruitsEpisode

__all__ = [
    "FruitSuiteResult",
    "compare_fruit_planners",
    "format_fruit_suite",
    "format_harvests",
    "run_fruit_suite",
    "run_fruit_suites",
]

LOCALISED_MM = 5.0
"""A ripe fruit counts as localised when a localised track lies within this of it [mm]."""

BUDGET_VIEWS = 10
"""The views (the start's counted) a truss should be localised in: issue 14's target."""


def _run_one(name: str, settings: Settings, seed: int, run: int) -> dict[str, Any]:
    from bve_mj.loop.mujoco_fruits import run_every_fruit_episode

    ep_seed = episode_seed(seed, run)
    try:
        ep = run_every_fruit_episode(settings, ep_seed)
    except BveError as exc:
        return {
            "scenario": name,
            "run": run,
            "episode_seed": ep_seed,
            "outcome": "failed",
            "message": str(exc),
        }
    (matches, other, false), silent_nees = ep.matches(), ep.result.shape.region(SILENT_PROBABILITY)
    visits = () if ep.harvest is None else ep.harvest.visits
    picked = {v.picked for v in visits if v.picked is not None}
    fruits = []
    for m in matches:
        t = m.track
        fruits.append(
            {
                "picked": m.fruit.name in picked,
                "error_mm": m.error_mm if t is not None else None,
                "nees": m.nees if t is not None else None,
                "filter_nees": m.filter_nees if t is not None else None,
                "localised": bool(t is not None and t.localised),
                "outside_claim": bool(t is not None and m.nees > silent_nees),
                "within": m.localised_within(LOCALISED_MM),
                **_radius_fields(m.claim, m.fruit.radius_m),
            }
        )
    views = ep.result.views
    return {
        "scenario": name,
        "run": run,
        "episode_seed": ep_seed,
        "outcome": ep.result.outcome,
        "views": len(views),
        "views_to_truss": ep.views_to_localise(LOCALISED_MM),
        "localised_in_budget": ep.localised_after(BUDGET_VIEWS, LOCALISED_MM),
        "ripe": len(matches),
        "fruits": fruits,
        "false_tracks": len(false),
        "other_tracks": len(other),
        "seen_in_part": len(ep.result.unmeasured),
        "harvest": ep.harvest is not None,
        **_picked_others(ep, picked - {m.fruit.name for m in matches}),
        "touched": sum(1 for v in visits if v.clearance_m <= 0.0),
        "plan_ms": [1e3 * v.plan_s for v in views[1:]],
        "track_ms": [1e3 * v.track_s for v in views],
        "assign_ms": [1e3 * v.tracking.assign_s for v in views],
        "tracks_max": max((len(v.fruits) for v in views), default=0),
        "wall_s": ep.result.wall_s,
    }


def _picked_others(ep: FruitsEpisode, names: set[str]) -> dict[str, int]:
    """Of the fruit picked that were not the zone's ripe ones: those less ripe than the
    detector's ripe class, and those ripe but outside the work zone (a neighbouring truss's)."""
    ripe = ripe_colours(ep.settings.detector.ripe_class)
    colours = {f.name: f.colour for f in ep.info.fruits}
    unripe = sum(1 for n in names if colours[n] not in ripe)
    return {"picked_unripe": unripe, "picked_outside": len(names) - unripe}


def _harvest_summary(rows: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """The harvests of the episodes that had one (approach mode): the share of the ripe fruit
    picked, the fruit picked that were not (less ripe, or outside the zone), and the visits
    in which the arm touched a fruit; empty without a harvest."""
    rows = [r for r in rows if r.get("harvest")]
    if not rows:
        return {}
    fruits = [f for r in rows for f in r["fruits"]]
    return {
        "picked_pct": 100.0 * float(np.mean([f["picked"] for f in fruits])) if fruits else math.nan,
        "picked_unripe": int(sum(r["picked_unripe"] for r in rows)),
        "picked_outside": int(sum(r["picked_outside"] for r in rows)),
        "touched": int(sum(r["touched"] for r in rows)),
    }


def format_harvests(summaries: dict[str, dict[str, Any]]) -> list[str]:
    """A line per scenario whose episodes harvested: ripe fruit picked, others picked, touches."""
    return [
        f"{name}: harvest picked {s['picked_pct']:.1f}% of the zone's ripe fruit; also picked "
        f"{s['picked_unripe']} less ripe (tracked as ripe) and {s['picked_outside']} ripe outside the zone; "
        f"{s['touched']} visits touched a fruit"
        for name, s in summaries.items()
        if "picked_pct" in s
    ]


def _radius_fields(belief: Belief | None, radius_m: float) -> dict[str, float | None]:
    """A tracked fruit's radius error [mm] and NEES (:func:`~bve_mj.campaigns.runs.radius_metrics`
    of its claimed belief); None for a fruit without a track."""
    if belief is None:
        return {"radius_error_mm": None, "radius_nees": None}
    metrics = radius_metrics(belief, radius_m)
    return {"radius_error_mm": metrics["radius_error_mm"], "radius_nees": metrics["radius_nees"]}


@dataclass(frozen=True)
class FruitSuiteResult:
    """Every scenario's every-fruit episode rows (in run order)."""

    scenarios: tuple[Scenario, ...]
    rows: dict[str, tuple[dict[str, Any], ...]]
    seed: int
    seeds: int
    wall_s: float

    def summary(self, name: str) -> dict[str, Any]:
        rows = self.rows[name]
        ok = [r for r in rows if r["outcome"] not in ("failed", "crashed")]
        fruits = [f for r in ok for f in r["fruits"]]
        tracked = [f for f in fruits if f["error_mm"] is not None]
        nees = np.array([f["nees"] for f in tracked]) if tracked else np.array([math.nan])
        own = [f.get("filter_nees") for f in tracked]
        filter_nees = np.array([x for x in own if x is not None]) if tracked else np.array([math.nan])
        r_err = np.array([abs(f["radius_error_mm"]) for f in tracked]) if tracked else np.array([math.nan])
        r_nees = np.array([f["radius_nees"] for f in tracked if f.get("radius_nees") is not None])
        outcomes: dict[str, int] = {}
        for r in rows:
            outcomes[str(r["outcome"])] = outcomes.get(str(r["outcome"]), 0) + 1
        plan = [x for r in ok for x in r["plan_ms"]]
        track = [x for r in ok for x in r["track_ms"]]
        assign = [x for r in ok for x in r.get("assign_ms", ())]
        in_budget = sum(r.get("localised_in_budget", 0) for r in ok)  # after BUDGET_VIEWS views
        return {
            "outcomes": outcomes,
            "ripe_fruit": len(fruits),
            "localised_pct": 100.0 * float(np.mean([f["within"] for f in fruits])) if fruits else math.nan,
            "localised_in_budget_pct": 100.0 * in_budget / len(fruits) if fruits else math.nan,
            "all_localised_pct": 100.0 * float(np.mean([all(f["within"] for f in r["fruits"]) for r in ok]))
            if ok
            else math.nan,
            "no_false_track_pct": 100.0 * float(np.mean([r["false_tracks"] == 0 for r in ok]))
            if ok
            else math.nan,
            "false_tracks": int(sum(r["false_tracks"] for r in ok)),
            "wrong_complete": sum(
                1 for r in ok if r["outcome"] == "converged" and not all(f["within"] for f in r["fruits"])
            ),
            "views_median": float(np.median([r["views"] for r in ok])) if ok else math.nan,
            "truss_pct": 100.0 * float(np.mean([r["views_to_truss"] is not None for r in ok]))
            if ok
            else math.nan,
            "views_to_truss_median": _median_views(ok),
            "error_mm_median": float(np.median([f["error_mm"] for f in tracked])) if tracked else math.nan,
            "radius_error_mm_median": float(np.median(r_err)),
            "nees_mean": float(np.mean(nees)),
            "filter_nees_mean": float(np.mean(filter_nees)) if filter_nees.size else math.nan,
            "radius_nees_mean": float(np.mean(r_nees)) if r_nees.size else math.nan,
            "inside_3sigma_pct": 100.0 * float(np.mean(nees <= 9.0)),
            "silent": int(sum(1 for f in tracked if f["localised"] and f["outside_claim"])),
            "plan_ms_median": float(np.median(plan)) if plan else math.nan,
            "track_ms_median": float(np.median(track)) if track else math.nan,
            "assign_ms_median": float(np.median(assign)) if assign else math.nan,
            "tracks_max": max((r["tracks_max"] for r in ok), default=0),
            **_harvest_summary(ok),
            "wall_s": float(sum(r.get("wall_s", 0.0) for r in rows)),
            "runs": list(rows),
        }

    @property
    def crashed(self) -> list[str]:
        return crashed_rows(self.rows)


def run_fruit_suite(
    scenarios: Sequence[Scenario],
    *,
    seeds: int = 20,
    seed: int = 0,
    workers: int = 1,
    planner: PlannerKind | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> FruitSuiteResult:
    """Run ``seeds`` every-fruit episodes of every scenario (camera measurement, the radius in
    the state: the files' measurement and state are overridden; ``planner``: the planner for
    every scenario, default each file's)."""
    if planner is not None and planner not in get_args(PlannerKind):
        raise ConfigError("planner", planner, f"one of {', '.join(get_args(PlannerKind))}")
    runs = run_fruit_suites(scenarios, (planner,), seeds=seeds, seed=seed, workers=workers, progress=progress)
    return runs[planner]


def run_fruit_suites(
    scenarios: Sequence[Scenario],
    planners: Sequence[PlannerKind | None],
    *,
    seeds: int = 20,
    seed: int = 0,
    workers: int = 1,
    progress: Callable[[int, int], None] | None = None,
    pick_rounds: int | None = None,
) -> dict[PlannerKind | None, FruitSuiteResult]:
    """:func:`run_fruit_suite` for each of ``planners`` (None: each file's) on the same seeds,
    in one pool: a task runs a few runs of one scenario, every planner on each run in turn,
    so the worker builds each run's scene once (:data:`bve_mj.loop.start.KEPT_SCENES`). Each
    result's ``wall_s`` is the whole comparison's. ``pick_rounds``: approach mode with that
    many picking rounds (``tracking.pick_rounds``) for every scenario; None: each file's."""
    for name, value, lo in (("seeds", seeds, 1), ("seed", seed, 0), ("workers", workers, 1)):
        if isinstance(value, bool) or not isinstance(value, int) or value < lo:
            raise ConfigError(name, value, f"an integer >= {lo}")
    allowed = get_args(PlannerKind)
    if (
        not planners
        or len(set(planners)) != len(planners)
        or any(p not in (None, *allowed) for p in planners)
    ):
        raise ConfigError("planners", list(planners), f"distinct names from {', '.join(allowed)}")
    t0 = time.perf_counter()
    base = {sc.name: sc.settings("camera", None, "centre_radius") for sc in scenarios}

    def chosen(p: PlannerKind | None) -> dict[str, dict[str, object]]:
        return {} if p is None else {"planner": {"kind": p}}

    tracking: dict[str, object] = {"fruits": "all"}
    picking: dict[str, dict[str, object]] = {}
    if pick_rounds is not None:
        tracking["pick_rounds"] = pick_rounds
        picking = {"episode": {"approach": True}}
    settings = {
        name: tuple(with_overrides(s, tracking=tracking, **picking, **chosen(p)) for p in planners)
        for name, s in base.items()
    }
    by_variant = run_rows(partial(run_chunk, _run_one), scenarios, settings, seed, seeds, workers, progress)
    wall = time.perf_counter() - t0
    return {
        p: FruitSuiteResult(tuple(scenarios), rows, seed, seeds, wall)
        for p, rows in zip(planners, by_variant, strict=True)
    }


def format_fruit_suite(summaries: dict[str, dict[str, Any]]) -> list[str]:
    """The every-fruit table: scenario | outcomes | ripe fruit | localised % at the end and
    after :data:`BUDGET_VIEWS` views | episodes with
    every one % | no false track % | wrong done | views | error and radius error medians |
    radius NEES | NEES of the claims and of the tracks' own beliefs | in 3σ % | silent | plan, association and
    tracker ms."""

    def num(x: Any, spec: str) -> str:
        return "-" if x is None or (isinstance(x, float) and math.isnan(x)) else format(x, spec)

    cols = ("scenario", "outcomes", "ripe", "loc%", f"loc%@{BUDGET_VIEWS}", "all%", "nofalse%", "wrong done",
            "views", "err mm", "r err mm", "r NEES", "NEES", "filter", "in3σ%", "silent", "plan ms",
            "assoc ms", "track ms")  # fmt: skip
    rows = [
        (
            name,
            " ".join(f"{k}:{v}" for k, v in sorted(s["outcomes"].items())),
            str(s["ripe_fruit"]),
            num(s["localised_pct"], ".1f"),
            num(s.get("localised_in_budget_pct"), ".1f"),
            num(s["all_localised_pct"], ".0f"),
            num(s["no_false_track_pct"], ".0f"),
            str(s.get("wrong_complete", "-")),
            num(s["views_median"], ".1f"),
            num(s["error_mm_median"], ".2f"),
            num(s["radius_error_mm_median"], ".2f"),
            num(s.get("radius_nees_mean"), ".2f"),
            num(s["nees_mean"], ".2f"),
            num(s.get("filter_nees_mean"), ".2f"),
            num(s["inside_3sigma_pct"], ".0f"),
            str(s["silent"]),
            num(s["plan_ms_median"], ".0f"),
            num(s.get("assign_ms_median", math.nan), ".2f"),
            num(s["track_ms_median"], ".2f"),
        )
        for name, s in summaries.items()
    ]
    widths = [max(len(c), *(len(r[i]) for r in rows)) for i, c in enumerate(cols)]
    fmt = "  ".join(f"{{:<{w}}}" if i < 2 else f"{{:>{w}}}" for i, w in enumerate(widths))
    head = fmt.format(*cols)
    note = (
        "ripe: true ripe fruit in the work zones; loc%: of them, localised (a localised track within "
        f"{LOCALISED_MM:g} mm) at the episode's end; loc%@{BUDGET_VIEWS}: the same after its first "
        f"{BUDGET_VIEWS} views (the start's counted); all%: episodes with every one localised; "
        "nofalse%: episodes with no false track (a confirmed track on no fruit); wrong done: episodes"
        " that ended converged (every fruit found) with a ripe fruit of the zone not localised; "
        "views: median per episode; err, r err: median centre and |radius| error of the tracked "
        "fruit; r NEES: mean radius NEES of the claims (1 if honest); NEES: mean over them (3 if "
        "honest); filter: the same of the tracks' own beliefs, before the claims; silent: fruit "
        "claimed localised with the truth outside the claim's 99.9% region; plan: median per view (every "
        "candidate's BVE with the arm); assoc: the association per view (every track's NIS against "
        "every detection and the optimal assignment); track: the tracker's whole step per view "
        "(association, updates, starts, merges, deletions)"
    )
    return [head, "-" * len(head), *(fmt.format(*r) for r in rows), note]


def _views_or_inf(row: dict[str, Any]) -> float:
    v = row.get("views_to_truss")
    return math.inf if v is None else float(v)


def _median_views(rows: Sequence[dict[str, Any]]) -> float:
    """The median views to the whole truss localised, an episode that never got there counted
    as infinitely many (the median is ∞ when half of them never did)."""
    return float(np.median([_views_or_inf(r) for r in rows])) if rows else math.nan


def compare_fruit_planners(results: dict[str, FruitSuiteResult], reference: str = "bve") -> list[str]:
    """The paired comparison of planners on the same seeds (the same scenes): per scenario and
    planner, the episodes with every ripe fruit localised within 5 mm, the median views until
    then (∞: half never), the ripe fruit localised, and against ``reference`` per paired
    seed: fewer / as many / more views (an episode that never localised the truss counts as
    more than any that did; two that never did, as many), with the one-sided sign test's p
    (ties dropped) that the reference needs fewer."""
    from scipy.stats import binomtest

    if reference not in results:
        raise ConfigError("planners", ",".join(results), f"a list that includes {reference}")
    ref = results[reference]
    head = (
        f"{'scenario':<16} {'planner':<7} {'truss%':>6} {'views':>6} {'loc%':>6}  "
        f"{reference} fewer/same/more  sign-test p"
    )
    lines = [head, "-" * len(head)]
    for sc in ref.scenarios:
        base = {r["run"]: r for r in ref.rows[sc.name] if r["outcome"] not in ("failed", "crashed")}
        for name, res in results.items():
            s = res.summary(sc.name)
            views = s["views_to_truss_median"]
            text = f"{sc.name:<16} {name:<7} {s['truss_pct']:6.0f} {views:6.1f} {s['localised_pct']:6.1f}"
            if name == reference:
                lines.append(text)
                continue
            fewer = same = more = 0
            for r in res.rows[sc.name]:
                b = base.get(r["run"])
                if b is None or r["outcome"] in ("failed", "crashed"):
                    continue
                a, o = _views_or_inf(b), _views_or_inf(r)
                fewer += a < o
                same += a == o
                more += a > o
            p = (
                binomtest(fewer, fewer + more, 0.5, alternative="greater").pvalue
                if fewer + more
                else math.nan
            )
            lines.append(f"{text}  {fewer:>6}/{same}/{more:<6}  {p:.3g}")
    lines.append(
        "truss%: episodes with every ripe fruit of the zone localised within "
        f"{LOCALISED_MM:g} mm; views: median views until then (inf: half never); loc%: ripe fruit "
        f"localised; paired by seed against {reference}"
    )
    return lines
