"""The claim's shape refitted from calibration rows under a noise model, without rendering again.

    bve-mj calibrate --scenes 10 --views 25 --seed 1 --twin-views 0 --json rows.json
    python benchmarks/claim_moments.py rows.json [--model default] [--write model.json]

``bve-mj calibrate`` fits every part of the noise model, the claim's tail and moment scales
last; a model whose other parts were refitted elsewhere (the views' nearby correlation from
``bench_view_twins.py``, the outliers from ``--every-fruit``) gets its claim's scales from the
rows under it here (:func:`bve_mj.estimation.noise_tail.fit_claim_shape`: episode-like draws
of 3-6 views of each calibration fruit, and single views). Prints, of episodes (the camera
measurement) and of single views (size-only episodes): κ² (the bound), m (the second moment
over the claim before κ²), ρ = κ²/m and the Student-t's ν; of episodes also m_r, the radius'
own, and ρ_r = κ²/m_r (a size-only episode claims its radius as its centre). ``--groups``
also prints the draws by calibration scenario and by the fruit's mean neighbour share: how
many fruits, their m, and their 99.9% quantile over χ²₃'s (κ² before the bootstrap's bound),
to see which fruits set κ². ``--write``
saves the model with the refitted moment scales (its κ², the bound the loop decides with,
kept as calibrated; its source told so).
"""

from __future__ import annotations

import json
from dataclasses import replace
from functools import partial
from pathlib import Path

import numpy as np

from bve_mj.atomic import write_json_atomic
from bve_mj.cli.script import ScriptParser, guarded
from bve_mj.config import Settings
from bve_mj.estimation.metrics import chi2_quantile
from bve_mj.estimation.noise import NoiseModel, load_noise_model
from bve_mj.estimation.noise_fit import split_gross
from bve_mj.estimation.noise_tail import (
    TAIL_PROBABILITY,
    episode_draws,
    fit_claim_shape,
    fruit_key,
    row_sigmas,
)

MOMENTS = ("moment_scale", "view_moment_scale", "radius_moment_scale")


def _rows(path: Path) -> list[dict]:
    doc = json.loads(path.read_text())
    rows = doc.get("rows") if isinstance(doc, dict) else None
    if not isinstance(rows, list) or not rows or not all(isinstance(r, dict) for r in rows):
        raise ValueError("no list of rows")
    return [r for r in rows if r.get("source") != "every"]  # the target's, as the fit takes them


def _line(name: str, tail: float, moment: float | None, radius: float | None, model: NoiseModel) -> str:
    shape = model.claim_shape if radius is not None else model.view_claim_shape
    if moment is None:
        return f"{name:13s} κ² {tail:.3f}: too few draws for the moments (Gaussian claim)"
    line = f"{name:13s} κ² {tail:.3f}  m {moment:.4f}  ρ {shape.bound_scale:.2f}  ν {shape.dof:.2f}"
    if radius is None:
        return line + "  (the radius claimed as the centre)"
    return line + f"  m_r {radius:.4f}  ρ_r {tail / radius:.2f}"


NEIGHBOUR_BINS = ((0.0, 0.02), (0.02, 0.2), (0.2, 0.4), (0.4, 1.01))
"""The bins of a fruit's mean neighbour share over its views (``--groups``)."""


def _groups(kept: list[dict], refused: list[dict], model: NoiseModel, focal_px: float) -> None:
    draws = episode_draws(kept, refused, model, focal_px, partial(row_sigmas, model))
    share: dict = {}
    for r in kept:
        share.setdefault(fruit_key(r), []).append(float(r.get("neighbour_share", 0.0)))
    chi2 = float(chi2_quantile(TAIL_PROBABILITY, 3))

    def line(name: str, keys: list) -> str:
        if not keys:
            return f"  {name:24s} no fruit"
        nees = np.array([draws[k][0] for k in keys])
        q = float(np.quantile(nees, TAIL_PROBABILITY)) / chi2
        return f"  {name:24s} fruits {len(keys):3d}  m {nees.mean() / 3.0:.3f}  q99.9/χ²₃ {q:.2f}"

    print("episode-like draws by calibration scenario:")
    for scenario in sorted({str(k[0]) for k in draws}):
        print(line(scenario, [k for k in draws if str(k[0]) == scenario]))
    print("by the fruit's mean neighbour share:")
    for lo, hi in NEIGHBOUR_BINS:
        keys = [k for k in draws if lo <= float(np.mean(share[k])) < hi]
        print(line(f"[{lo:g}, {min(hi, 1.0):g}{')' if hi < 1.0 else ']'}", keys))


def main() -> None:
    ap = ScriptParser(description=__doc__)
    ap.add_argument("rows_json", type=Path, help="a `bve-mj calibrate --json` file")
    ap.add_argument("--model", default="default", help="the noise model the rows are read under")
    ap.add_argument("--groups", action="store_true", help="the draws by scenario and neighbour share too")
    ap.add_argument("--write", type=Path, help="save the model with the refitted scales here (.json)")
    args = ap.parse_args()
    if args.write is not None and args.write.suffix.lower() != ".json":
        ap.error(f"--write: got '{args.write}'; allowed: a path ending in .json")
    try:
        rows = _rows(args.rows_json)
    except (OSError, ValueError) as exc:
        ap.error(f"rows_json: got '{args.rows_json}'; allowed: a `bve-mj calibrate --json` file ({exc})")
    model = load_noise_model(args.model)
    camera = Settings().camera
    model.check_camera(camera, args.model)
    kept, refused = split_gross(rows, camera)  # as bve-mj calibrate splits them
    fitted = fit_claim_shape(kept, refused, model, camera.focal_px)
    print(f"{len(kept)} detections within 6σ of a first fit, {len(refused)} views refused ({args.rows_json})")
    print(_line("episodes", fitted.tail_scale, fitted.moment_scale, fitted.radius_moment_scale, fitted))
    view = (fitted.view_tail_scale, fitted.view_moment_scale, None)
    print(_line("single views", *view, fitted))
    print(f"(shipped: κ² {model.tail_scale:.3f}, m {model.moment_scale}, m_r {model.radius_moment_scale})")
    if args.groups:
        _groups(kept, refused, model, camera.focal_px)
    if args.write is not None:
        source = f"{model.source}; moment scales refitted (benchmarks/claim_moments.py {args.rows_json.name})"
        moments = {k: getattr(fitted, k) for k in MOMENTS}
        write_json_atomic(args.write, replace(model, source=source, **moments).to_json())
        print(f"wrote {args.write}")


if __name__ == "__main__":
    guarded(main)
