"""A view that shows a hidden fruit: where the tracks say its outline is not covered.

The BVE plans a fruit's next view from its covariance alone: the view that shrinks it most.
In a compact truss that view is often one from which the fruit is behind its neighbours (a
fruit at the back of a cluster seen from the aisle shows 100-185° of outline, and the detector
wants ``detector.min_arc_deg``), and it is refused view after view while the fruit's belief,
started from one lucky view, never tightens (``truss_cluster`` 3669142227: every view the BVE
chose came from the aisle side; from the side or above the two fruit at the back show
215-360°).

:func:`unhiding_positions` ranks camera positions for such a fruit by the outline the tracks
predict it shows there (:func:`~bve_mj.estimation.visibility.outline_shown_deg`): positions
within one step of the camera that satisfy the task constraints around the fruit's estimate,
drawn at random in the step's ball. Where some show ``min_arc_deg`` or more they come first,
the most outline first; where none does (the side that shows the fruit is more than a step
away), the positions nearest the nearest place on the distance band that shows it come
first, so the camera walks there in steps. The caller reaches them with the arm (IK) and checks the move.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from bve_mj.planning.constraints import Constraint, max_violation

__all__ = ["ShownFn", "UnhideOptions", "unhiding_positions"]

ShownFn = Callable[[int, np.ndarray, np.ndarray, np.ndarray], np.ndarray]
"""``shown(index, centres (n, 3), radii (n,), positions (m, 3))`` → (m,) degrees of fruit
``index``'s outline a camera at each position, looking at it, would see
(:func:`~bve_mj.estimation.visibility.outline_shown_deg`)."""


@dataclass(frozen=True)
class UnhideOptions:
    """How many positions are drawn in the step's ball and on the distance band, and how
    many ranked positions are returned."""

    samples: int = 192
    band_samples: int = 256
    keep: int = 4

    def __post_init__(self) -> None:
        for name in ("samples", "band_samples", "keep"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"UnhideOptions.{name} must be a positive integer, got {value!r}")


def unhiding_positions(
    index: int,
    centres_m: np.ndarray,
    radii_m: np.ndarray,
    p_world_camera: np.ndarray,
    constraints: Sequence[Constraint],
    step_m: float,
    band_distance_m: float,
    shown: ShownFn,
    min_arc_deg: float,
    rng: np.random.Generator,
    options: UnhideOptions | None = None,
    tol: float = 1e-9,
) -> list[tuple[np.ndarray, float]]:
    """Camera positions from which fruit ``index`` of ``centres_m``/``radii_m`` (every fruit
    the robot knows, [m]) would show its outline, best first, each with the degrees of outline
    predicted there: at most ``options.keep``, each within ``step_m`` of ``p_world_camera``
    and satisfying ``constraints`` (the task's, around the fruit's estimate). Positions that
    show ``min_arc_deg`` come first, most outline first; the rest follow by their distance to
    the band position (``band_distance_m`` from the fruit, within ``constraints``) nearest the
    camera of those that show ``min_arc_deg`` (the one that shows most where none does).
    Empty where no drawn position satisfies the constraints."""
    opt = options or UnhideOptions()
    centres = np.atleast_2d(np.asarray(centres_m, dtype=float))
    radii = np.asarray(radii_m, dtype=float).reshape(-1)
    if not 0 <= index < len(centres) or radii.shape[0] != centres.shape[0]:
        raise ValueError(f"fruit index {index} out of range for {len(centres)} fruit")
    for name, value in (("step_m", step_m), ("band_distance_m", band_distance_m)):
        if not (math.isfinite(value) and value > 0.0):
            raise ValueError(f"{name} must be a finite number > 0, got {value!r}")
    if not 0.0 < min_arc_deg <= 360.0:
        raise ValueError(f"min_arc_deg must be in (0, 360], got {min_arc_deg!r}")
    c_now = np.asarray(p_world_camera, dtype=float)
    k = centres[index]

    def outline(positions: list[np.ndarray]) -> list[float]:
        if not positions:
            return []
        return [float(a) for a in shown(index, centres, radii, np.array(positions))]

    d = rng.standard_normal((opt.samples, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    ball = [
        x
        for x in c_now + d * (step_m * rng.random((opt.samples, 1)) ** (1.0 / 3.0))
        if max_violation(constraints, x) <= tol
    ]
    if not ball:
        return []
    near = list(zip(ball, outline(ball), strict=True))
    showing = sorted((c for c in near if c[1] >= min_arc_deg), key=lambda c: -c[1])
    if len(showing) >= opt.keep:
        return showing[: opt.keep]
    e = rng.standard_normal((opt.band_samples, 3))
    e /= np.linalg.norm(e, axis=1, keepdims=True)
    band = [x for x in k + band_distance_m * e if max_violation(constraints, x) <= tol]
    rest = [c for c in near if c[1] < min_arc_deg]
    if band:
        arcs = outline(band)
        showing_band = [x for x, a in zip(band, arcs, strict=True) if a >= min_arc_deg]
        if showing_band:  # the nearest place that shows it: the shortest walk
            goal = min(showing_band, key=lambda x: float(np.linalg.norm(x - c_now)))
        else:
            goal = band[int(np.argmax(arcs))]
        rest.sort(key=lambda c: float(np.linalg.norm(c[0] - goal)))
    else:
        rest.sort(key=lambda c: -c[1])
    return (showing + rest)[: opt.keep]
