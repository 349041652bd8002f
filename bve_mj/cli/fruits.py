"""``bve-mj episode --fruits all``: every ripe fruit of the truss, its table, JSON and video."""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from bve_mj.atomic import write_json_atomic
from bve_mj.cli.args import EXIT_NOT_LOCALISED, EXIT_OK
from bve_mj.loop.outcomes import Outcome

if TYPE_CHECKING:
    from bve_mj.config import Settings

__all__ = ["run_every_fruit_cli"]


def run_every_fruit_cli(
    settings: Settings,
    seed: int,
    json_path: Path | None,
    *,
    quiet: bool = False,
    video_path: Path | None = None,
) -> int:
    """Run the every-fruit episode, print its views and fruit, write its JSON and (with
    ``video_path``) its video; the exit status from the outcome (what the robot knows: 3 for
    ``incomplete``, ``never_detected``, ``unreachable``), as the one-target episode's."""
    from bve_mj.loop.mujoco_fruits import run_every_fruit_episode

    recorder = None
    if video_path is not None:
        from bve_mj.reporting.fruits_video import FruitsRecorder

        recorder = FruitsRecorder(video_path)
    try:
        episode = run_every_fruit_episode(settings, seed, recorder=recorder)
    finally:
        frames = recorder.close() if recorder is not None else 0
    doc = episode.to_json()
    s = episode.settings
    print(
        f"bve-mj episode --fruits all: seed {seed}, {s.episode.experiment}, planner={s.planner.kind}, "
        f"work zone {1e3 * s.tracking.zone_m:.0f} mm around the target's prior; "
        f"{len(doc['fruits'])} ripe fruit there"
    )
    if not quiet:
        print(f"{'view':>4} {'plan':>13} {'for':>6} {'detected':>8} {'tracks':>6} {'localised':>9}  events")
        for v in doc["views"]:
            tracks = v["tracks"]
            events = [e for e in v["events"] if not e.startswith("updated")]
            print(
                f"{v['view']:>4} {v['plan_status'] or 'start'!s:>13} {_planned_for(v['planned_for']):>6} "
                f"{v['detections']:>8} "
                f"{len(tracks):>6} {sum(t['localised'] for t in tracks):>9}  {' '.join(events)[:60]}"
            )
    head = f"{'fruit':>12} {'colour':>9} {'track':>5} {'error mm':>9} {'NEES':>7}"
    print(f"{head} {'radius mm':>17} {'localised':>9}")
    for f in doc["fruits"]:
        if f["track"] is None:
            print(f"{f['name']:>12} {f['colour']:>9} {'-':>5} {'-':>9} {'-':>7} {'-':>17} {'no':>9}")
            continue
        radius = f"{f['radius_estimate_mm']:6.2f} ± {f['radius_sigma_mm']:4.2f} ({f['radius_mm']:.1f})"
        print(
            f"{f['name']:>12} {f['colour']:>9} {f['track']:>5} {f['error_mm']:9.2f} {f['nees']:7.2f} "
            f"{radius:>17} {'yes' if f['localised'] else 'no':>9}"
        )
    within = sum(
        1 for f in doc["fruits"] if f["localised"] and f["error_mm"] is not None and f["error_mm"] <= 5.0
    )
    n = len(doc["fruits"])
    print(
        f"outcome: {doc['outcome']}; {within} of {n} ripe fruit localised within 5 mm; "
        f"{len(doc['unmatched_tracks'])} false tracks, {len(doc['other_tracks'])} on less ripe fruit; "
        f"{len(doc['views'])} views; wall {doc['wall_s']:.2f} s"
    )
    if doc["zone_framed"] is not None:
        print(f"work zone framed by the views: {100 * doc['zone_framed']:.0f}%")
    for h in doc["seen_in_part"]:
        at = ", ".join(f"{x:.3f}" for x in h["estimate_m"])
        print(
            f"seen in part, never measured: a fruit near ({at}) m (sigma max {h['sigma_max_mm']:.0f} mm, "
            f"{h['hits']} views)"
        )
    plan = [v["plan_s"] for v in doc["views"][1:]]
    track = [v["track_s"] for v in doc["views"]]
    assign = [v["assign_s"] for v in doc["views"]]
    print(
        f"median per view: plan {1e3 * float(np.median(plan)) if plan else math.nan:.1f} ms, "
        f"association {1e3 * float(np.median(assign)):.2f} ms, "
        f"tracker step (association, updates, merges) {1e3 * float(np.median(track)):.2f} ms"
    )
    if doc["harvest"] is not None:
        h = doc["harvest"]
        print(f"harvest order ({h['rule']}): {h['order']}")
        for visit in h["visits"]:
            c = visit["clearance_m"]
            clear = f">= {1e3 * c:.0f}" if c >= 0.05 else f"{1e3 * c:.1f}"
            took = "" if visit.get("picked") is None else f"; picked {visit['picked']}"
            print(
                f"  {'round ' + str(visit['round']) + ', ' if visit.get('round') else ''}track "
                f"{visit['track']}: {'reached' if visit['reached'] else 'not reached'}, camera "
                f"{1e3 * visit['distance_m']:.0f} mm from its estimate, least clearance of the arm to "
                f"any fruit {clear} mm" + (f" ({visit['reason']})" if visit["reason"] else "") + took
            )
    if video_path is not None and frames == 0:
        print(f"no video written to {video_path}: the episode ended before its first view")
    elif video_path is not None:
        record = [(v["timings_s"] or {}).get("record_s", 0.0) for v in doc["views"][1:]]
        per_view = f"; recording {1e3 * float(np.median(record)):.0f} ms per move (median)" if record else ""
        print(f"wrote {video_path} ({frames} frames{per_view})")
    if json_path is not None:
        write_json_atomic(json_path, doc)
        print(f"wrote {json_path}")
    outcome = Outcome(doc["outcome"])
    if outcome.note is not None:
        print(outcome.note)
    return EXIT_OK if outcome.localised else EXIT_NOT_LOCALISED


def _planned_for(key: int | None) -> str:
    """A view's ``planned_for`` as the table shows it: a track id, ``zone`` (exploring),
    ``part:N`` (fruit N seen in part) or ``-`` (the start)."""
    from bve_mj.loop.every_fruit import seen_in_part_id
    from bve_mj.planning.every_fruit import EXPLORE

    if key is None:
        return "-"
    if key == EXPLORE:
        return "zone"
    return f"part:{seen_in_part_id(key)}" if key < EXPLORE else str(key)
