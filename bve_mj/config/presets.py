"""The worlds' presets: the value each world-dependent setting takes where it is left unset.

One file of settings serves both worlds: a world-dependent setting left unset (``"auto"`` for
a choice, absent, i.e. ``None``, for a number) takes its world's value here when a runner
resolves the settings (:meth:`bve_mj.config.Settings.for_world`; every runner does, first).
Each value is written once, in :data:`PRESETS`; a value set in a file or in Python wins in
both worlds.

=============================  ==================  =====================================
setting                        ``synthetic``       ``mujoco``
                               (paper protocol)    (greenhouse closed loop)
=============================  ==================  =====================================
measurement.kind               range               camera
filter.state                   centre              centre_radius
filter.gate_probability        off                 0.99999
constraints.band_distance_m    1.0                 0.30
constraints.band_tolerance_m   0.1                 0.08
constraints.step_m             0.2                 0.10
measurement.reference_range_m  1.0                 the band distance
planner.upright_weight         0                   0.1
=============================  ==================  =====================================

:meth:`Settings.paper` and :meth:`Settings.greenhouse` are the defaults resolved for each
world. Settings no world resolved (a planner built by hand from ``Settings()``) read as the
synthetic world's, the paper's, as ``measurement.kind = "auto"`` reads as its range
measurement there.
"""

from __future__ import annotations

from dataclasses import dataclass

from bve_mj.config.fields import MeasurementKind, StateKind, WorldName

__all__ = ["PRESETS", "WorldPreset"]


@dataclass(frozen=True, kw_only=True)
class WorldPreset:
    """What a world's unset settings become (see the module's table)."""

    measurement_kind: MeasurementKind
    """``measurement.kind``: the paper's range-only EKF; in the rendered closed loop the camera
    measurement (bearing + range), where range alone cannot recover from the unknown radius."""
    state: StateKind
    """``filter.state``: the paper's 3-D state; in MuJoCo the fruit's radius estimated with it."""
    gate_probability: float | None
    """``filter.gate_probability`` (None: off). Off in the paper's Gaussian protocol; in the
    closed loop it rejects false detections (NIS in the thousands) but not the true ones a
    wrong fruit-radius guess biases in range (NIS up to ~20 seen at 0.999)."""
    band_distance_m: float
    """``constraints.band_distance_m``: the paper's l_dist; in MuJoCo adapted to the arm
    (0.645 m reach, fruit at ~0.45 m)."""
    band_tolerance_m: float
    """``constraints.band_tolerance_m``: the band's half-width."""
    step_m: float
    """``constraints.step_m``: the paper's r_d; in MuJoCo ~20 deg of view change at 0.3 m."""
    reference_range_m: float | None
    """``measurement.reference_range_m``, where Σc is taken (None: the band distance, where
    the closed loop keeps the camera)."""
    upright_weight: float
    """``planner.upright_weight``: none in the paper's protocol (its E5/E10 table is the
    paper's); in MuJoCo the eye-in-hand image is turned upright where the arm allows (on the
    held-out seed 9137 it cost no convergence: docs/arm.md, upright images)."""


PRESETS: dict[WorldName, WorldPreset] = {
    "synthetic": WorldPreset(
        measurement_kind="range",
        state="centre",
        gate_probability=None,
        band_distance_m=1.0,
        band_tolerance_m=0.1,
        step_m=0.2,
        reference_range_m=1.0,
        upright_weight=0.0,
    ),
    "mujoco": WorldPreset(
        measurement_kind="camera",
        state="centre_radius",
        gate_probability=0.99999,
        band_distance_m=0.30,
        band_tolerance_m=0.08,
        step_m=0.10,
        reference_range_m=None,
        upright_weight=0.1,
    ),
}
"""Each world's preset: the one place these values are written."""
