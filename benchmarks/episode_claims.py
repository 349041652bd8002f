"""Can what an episode saw tell how far its claim is off? A study on the suite's own rows.

    bve-mj scenarios --seeds 20 --seed 101 --json cal101.json     # calibration seeds
    bve-mj scenarios --seeds 20 --seed 202 --json cal202.json
    bve-mj scenarios --seeds 20 --seed 31337 --json held.json     # held out
    python benchmarks/episode_claims.py cal101.json cal202.json --check held.json

The claim's scales are calibrated on episode-like draws of the calibration views; its mean
NEES is right pooled and wrong per scene (docs/honesty.md). This fits, on the calibration
seeds' episodes (never the held-out ones), a scale of each episode's claimed covariance from
what the loop saw of the fruit in the views its claim fused (``claim_features`` of the
suite's rows): ln g = w · (1, f₁, …), fitted by the Gaussian likelihood of the errors under
the scaled claim (g's mean is the NEES' second moment over 3, as the claim's scales are).
It prints, per scene on the held-out rows, the mean NEES of the claim as it is and as it
would be with g (NEES / g), the 95% band for that many episodes, and the success outcomes
outside their scaled 99.9% region; then the same with each scene's g fitted without that
scene's calibration rows (a scene the fit has not seen). Nothing here changes the loop: it
measures whether an episode-conditioned claim would be worth building, and on what.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from scipy.optimize import minimize

from bve_mj.cli.script import ScriptParser, guarded
from bve_mj.estimation.claim_shape import claim_region
from bve_mj.estimation.metrics import nees_band

FEATURES = ("neighbour_share", "refused_share", "nis_per_dof", "radius_px", "arc_deg", "accepted")
SUCCESS = ("converged", "stable", "approached")


def _terms(f: dict) -> list[float] | None:
    x = [f.get(k) for k in FEATURES]
    if any(v is None for v in x):
        return None
    nb, refused, nis, r_px, arc, n = (float(v) for v in x)  # type: ignore[arg-type]
    lnis, lr = math.log(max(nis, 1e-3)), math.log(max(r_px, 1.0))
    return [1.0, nb, nb * nb, refused, lnis, lr, arc / 360.0, n / 10.0]


def load_rows(paths: Sequence[Path]) -> list[dict]:
    """The rows of ``bve-mj scenarios --json`` files that have a claim and its features."""
    out = []
    for path in paths:
        try:
            doc = json.loads(path.read_text())
        except json.JSONDecodeError as exc:
            raise ValueError(f"{path}: not JSON ({exc.msg}, line {exc.lineno})") from None
        scenarios = doc.get("scenarios") if isinstance(doc, dict) else None
        if not isinstance(scenarios, dict):
            raise ValueError(f"{path}: not a `bve-mj scenarios --json` file")
        for name, summary in scenarios.items():
            for r in summary.get("runs", []):
                nees, features = r.get("nees"), r.get("claim_features")
                if r.get("outcome") in ("failed", "crashed") or nees is None:
                    continue
                if not isinstance(features, dict):
                    raise ValueError(f"{path}: rows without claim_features (made before they were written)")
                terms = _terms(features)
                if terms is None:  # no view fused: the claim is the prior's
                    continue
                out.append({"scenario": name, "nees": float(nees), "x": terms, "dof": r.get("claim_dof"),
                            "success": r.get("outcome") in SUCCESS})  # fmt: skip
    if not out:
        raise ValueError("no rows with a claim")
    return out


def fit(rows: Sequence[dict], ridge: float = 1.0) -> np.ndarray:
    """w of ln g = w·x: the scaled claim's Gaussian negative log-likelihood, with a ridge on
    every term but the constant."""
    X = np.array([r["x"] for r in rows])
    nees = np.array([r["nees"] for r in rows])
    mu, sd = X[:, 1:].mean(0), X[:, 1:].std(0) + 1e-9
    Z = np.hstack([np.ones((len(X), 1)), (X[:, 1:] - mu) / sd])

    def nll(w: np.ndarray) -> tuple[float, np.ndarray]:
        lg = Z @ w
        e = nees * np.exp(-lg)
        val = float(np.sum(1.5 * lg + 0.5 * e) + 0.5 * ridge * w[1:] @ w[1:])
        grad = Z.T @ (1.5 - 0.5 * e) + ridge * np.r_[0.0, w[1:]]
        return val, grad

    w = minimize(nll, np.zeros(Z.shape[1]), jac=True, method="L-BFGS-B").x
    # back to the raw terms: ln g = w0 + Σ wk (xk - μk)/σk
    raw = np.r_[w[0] - np.sum(w[1:] * mu / sd), w[1:] / sd]
    return raw


def report(rows: Sequence[dict], w_of: dict[str, np.ndarray], title: str) -> None:
    print(f"\n{title}")
    head = ("scene", "n", "NEES now", "scaled", "band", "silent now", "scaled")
    print("{:22s} {:>3s} {:>8s} {:>7s} {:>11s} {:>10s} {:>6s}".format(*head))
    names = sorted({r["scenario"] for r in rows})
    inside_now = inside_scaled = 0
    pooled_now, pooled_scaled = [], []
    for name in names:
        rs = [r for r in rows if r["scenario"] == name]
        nees = np.array([r["nees"] for r in rs])
        g = np.exp(np.array([r["x"] for r in rs]) @ w_of[name])
        lo, hi = nees_band(len(rs), tail_dofs=[r["dof"] for r in rs])
        silent = [r["success"] and r["nees"] > claim_region(r["dof"] or math.inf, 0.999) for r in rs]
        silent_g = [r["success"] and r["nees"] / gi > claim_region(r["dof"] or math.inf, 0.999)
                    for r, gi in zip(rs, g, strict=True)]  # fmt: skip
        now, scaled = float(nees.mean()), float((nees / g).mean())
        inside_now += lo <= now <= hi
        inside_scaled += lo <= scaled <= hi
        pooled_now += list(nees)
        pooled_scaled += list(nees / g)
        band = f"{lo:5.2f}-{hi:5.2f}"
        n_silent = f"{sum(silent):10d} {sum(silent_g):6d}"
        print(f"{name:22s} {len(rs):3d} {now:8.2f} {scaled:7.2f} {band:>11s} {n_silent}")
    print(f"in the band: {inside_now} -> {inside_scaled} of {len(names)}; pooled mean NEES "
          f"{np.mean(pooled_now):.2f} -> {np.mean(pooled_scaled):.2f} (median {np.median(pooled_now):.2f} -> "
          f"{np.median(pooled_scaled):.2f})")  # fmt: skip


def main() -> None:
    ap = ScriptParser(description=__doc__)
    ap.add_argument("calibration", type=Path, nargs="+", help="`bve-mj scenarios --json` files to fit on")
    ap.add_argument("--check", type=Path, required=True, help="a held-out `bve-mj scenarios --json` file")
    ap.add_argument("--ridge", type=float, default=1.0, help="ridge on the standardised terms (default 1)")
    args = ap.parse_args()
    if not (math.isfinite(args.ridge) and args.ridge >= 0.0):
        ap.error(f"--ridge: got {args.ridge}; allowed: a finite number >= 0")
    for name, paths in (("calibration", args.calibration), ("--check", [args.check])):
        try:
            rows = load_rows(paths)
        except (OSError, ValueError) as exc:
            detail = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
            ap.error(f"{name}: {detail}; allowed: `bve-mj scenarios --json` files with claim_features")
        if name == "calibration":
            cal = rows
        else:
            held = rows
    w = fit(cal, args.ridge)
    names = sorted({r["scenario"] for r in held})
    terms = ("1", "nb", "nb²", "refused", "ln nis", "ln r_px", "arc", "n/10")
    fitted = " + ".join(f"{c:+.3f}·{t}" for c, t in zip(w, terms, strict=True))
    print(f"{len(cal)} calibration episodes, {len(held)} held out; ln g = {fitted}")
    report(held, dict.fromkeys(names, w), "held-out seed, g fitted on every calibration scene")
    w_loo = {n: fit([r for r in cal if r["scenario"] != n], args.ridge) for n in names}
    report(held, w_loo, "held-out seed, each scene's g fitted without that scene")


if __name__ == "__main__":
    guarded(main)
