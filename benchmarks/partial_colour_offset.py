"""What a detector of a class short of red errs beyond the model, refitted from calibration rows.

    bve-mj calibrate --only turning --scenes 40 --views 60 --seed 11 --twin-views 0 --json turning.json
    python benchmarks/partial_colour_offset.py turning.json [--model default] [--write model.json]

A detector asked for turning fruit fits the coloured cap of a fruit coloured only in part
(:mod:`bve_mj.estimation.partial_colour`): its views see the apparent radius smaller, and err
more, than the model fitted over every fruit says, and the centre it fits is off by the same
amount from every view. ``bve-mj calibrate`` over every scene sees two or three such fruits
(the detector refuses most views of them), too few to fit that, so it is fitted here from rows
of the ``turning`` scene alone, under a model whose other parts are fitted over every scene
(``--model``, the shipped one by default): first the views' bias and variance scales
(:func:`~bve_mj.estimation.partial_colour.fit_partial_colour_view`), then, under them, the
share of the radius² these fruits' offsets add to the model's own offset for them
(:func:`~bve_mj.estimation.partial_colour.fit_partial_colour_offset`). Prints both, what they
rest on and the share of the fruits' offsets inside the claim's 3σ before and after;
``--write`` saves the model with them.
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np

from bve_mj.atomic import write_json_atomic
from bve_mj.cli.script import ScriptParser, guarded
from bve_mj.config import Settings
from bve_mj.config.detector import RED_CLASSES
from bve_mj.estimation.noise import NoiseModel, load_noise_model
from bve_mj.estimation.noise_fit import fruit_offsets, seen_outlines, split_gross
from bve_mj.estimation.partial_colour import fit_partial_colour, partial_colour_cov


def _inside(kept: list[dict], model: NoiseModel, focal_px: float) -> tuple[float, int]:
    """The share of the partly coloured fruits' offsets inside the 3σ of what the claim adds
    for them (the model's own offset and the partial-colour term), and how many."""
    rows = [r for r in kept if r.get("ripe_class") not in RED_CLASSES]
    model = model.for_partial_colour()  # the views' own scales: each offset's covariance C
    offsets, seen = fruit_offsets(rows, model, focal_px), seen_outlines(rows)
    d2 = [
        float(b @ np.linalg.solve(model.centre_offset_cov(r, *seen[k]) + partial_colour_cov(model, r) + C, b))
        for k, (b, C, r) in offsets.items()
    ]
    return (float(np.mean(np.array(d2) <= 9.0)) if d2 else float("nan")), len(d2)


def main() -> None:
    ap = ScriptParser(description=__doc__)
    ap.add_argument("rows_json", type=Path, help="a `bve-mj calibrate --json` file")
    ap.add_argument("--model", default="default", help="the noise model the rows are read under")
    ap.add_argument("--write", type=Path, help="save the model with the fitted term here (.json)")
    args = ap.parse_args()
    if args.write is not None and args.write.suffix.lower() != ".json":
        ap.error(f"--write: got '{args.write}'; allowed: a path ending in .json")
    try:
        doc = json.loads(args.rows_json.read_text())
        rows = [r for r in doc["rows"] if isinstance(r, dict) and r.get("source") != "every"]
        if not rows:
            raise ValueError("no rows")
    except (OSError, ValueError, KeyError, TypeError) as exc:
        ap.error(f"rows_json: got '{args.rows_json}'; allowed: a `bve-mj calibrate --json` file ({exc})")
    model = load_noise_model(args.model)
    camera = Settings().camera
    model.check_camera(camera, args.model)
    kept, _ = split_gross(rows, camera)
    f = camera.focal_px
    before, _ = _inside(
        kept, replace(model, partial_colour_offset=0.0, partial_colour_view=(0.0, 1.0, 1.0)), f
    )
    fitted, views, fruits = fit_partial_colour(kept, model, f)
    share = fitted.partial_colour_offset
    after, _ = _inside(kept, fitted, f)
    print(f"{views} views of a detector class short of red ({args.rows_json})")
    d, kc, kr = fitted.partial_colour_view
    print(f"their views: apparent radius {d:+.3f} px beyond the bias,", end=" ")
    print(f"variance x{kc:.2f} (centre), x{kr:.2f} (radius)")
    print(f"{fruits} fruits with 6 views or more: their own offset {share:.3e} of the radius²", end=" ")
    print(f"(σ {100 * share**0.5:.2f}% of the radius)")
    print(f"their offsets inside the claim's 3σ: {100 * before:.0f}% without it, {100 * after:.0f}% with it")
    if args.write is not None:
        source = (
            f"{model.source}; the partial-colour offset from python benchmarks/partial_colour_offset.py "
            f"{args.rows_json.name} --write ({views} views, {fruits} fruits of a detector class short of red)"
        )
        write_json_atomic(args.write, replace(fitted, source=source).to_json())
        print(f"wrote {args.write}")


if __name__ == "__main__":
    guarded(main)
