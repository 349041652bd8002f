"""Settings of the detector: the colour segmentation of ripe fruit, the separation of touching
fruit, the fit and the checks that refuse a poor one (or, studied, a synthetic box detector)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from bve_mj.config.fields import (
    DetectorKind,
    _choice,
    _non_negative,
    _number,
    _open_interval,
    _positive,
    _positive_int,
    _why,
)
from bve_mj.errors import ConfigError

__all__ = ["RED_CLASSES", "DetectorConfig"]


RED_CLASSES = (None, "red")
"""The ripe classes that admit only fruit red all over (None: the default, ``red_hue_max``)."""


@dataclass(frozen=True, kw_only=True)
class DetectorConfig:
    """Which detector measures the fruit, and the built-in one's settings: colour segmentation,
    separation of touching fruit (outline arcs grouped into circles), and circle (cone) fit of
    the target tomato, with the checks that refuse a poor one. ``kind = "synthetic_boxes"``
    replaces it with boxes from the true projection of the fruit in view (``box_noise_px``,
    ``miss_p``, ``false_positives``) through the box adapter
    (:mod:`bve_mj.perception.adapters`): a learned detector's effect, studied."""

    kind: DetectorKind = field(
        default="builtin",
        metadata=_why(
            "builtin: the colour detector (silhouette arcs, cone fit); synthetic_boxes: bounding "
            "boxes from the true projection of every ripe fruit in view, with corner noise, misses "
            "and false positives, measured by the box adapter (a learned detector, simulated)"
        ),
    )
    red_hue_max: int = field(default=8, metadata=_why("ripe red: OpenCV hue <= this or >= red_hue_min_wrap"))
    red_hue_min_wrap: int = field(default=170, metadata=_why("ripe red wraps around hue 180"))
    min_saturation: int = field(default=110, metadata=_why("excludes pinkish highlights and grey", "0-255"))
    min_value: int = field(
        default=16, metadata=_why("excludes black: the darkest pixel that can be ripe", "0-255")
    )
    min_chroma: int = field(
        default=17,
        metadata=_why(
            "a ripe pixel's colour stands this far out of grey (max - min of R, G, B): a red fruit "
            "in the canopy's shade is dark but red, where camera noise gives dark grey any hue",
            "0-255",
        ),
    )
    min_area_px: int = field(default=25, metadata=_why("smaller blobs are noise", "px"))
    min_boundary_points: int = field(default=12, metadata=_why("fewest silhouette points for a fit"))
    outlier_px: float = field(
        default=1.5,
        metadata=_why("boundary points this far inside the fitted circle are occluder edges", "px"),
    )
    extend_hue_max: int = field(
        default=25,
        metadata=_why(
            "skin up to this hue (orange-yellow: a highlight, a blush, uneven colour) counts as ripe "
            "where it touches ripe pixels, so a red fruit's silhouette is whole; <= the ripe hue "
            "limit turns it off (stems and leaves start at 38)",
            "0-180",
        ),
    )
    ripe_class: str | None = field(
        default=None,
        metadata=_why(
            "the least ripe class that counts as ripe (red, light_red, pink, turning; orange = turning): "
            "its hue limit (ripe_hue_limits) replaces red_hue_max; None: red_hue_max decides"
        ),
    )
    corner_px: float = field(
        default=1.5,
        metadata=_why(
            "concave corners of a ripe blob's outline deeper than this cut it into arcs (where two "
            "touching fruit meet, a calyx notch, a leaf tip)",
            "px",
        ),
    )
    junction_margin: int = field(
        default=4,
        metadata=_why("outline points left out at each end of an arc at a corner (blended with a neighbour)"),
    )
    arc_tol_px: float = field(
        default=2.0,
        metadata=_why(
            "an arc belongs to a fruit's circle when half its points or more lie within this of it "
            "(or 4% of the radius) and almost none further outside",
            "px",
        ),
    )
    interior_edge: float = field(
        default=80.0,
        metadata=_why(
            "Canny threshold on the brightness (HSV value, 3x3 Sobel magnitude) of edges inside the "
            "ripe mask that count as a fruit's rim over a ripe neighbour (red on red: no outline "
            "there); such an edge joins a fruit whose circle it lies on, never makes one; 0: off",
            ">= 0",
        ),
    )
    shape_grouping: bool = field(
        default=True,
        metadata=_why(
            "group outline arcs into fruit with the fruit type's mean shape undone where the world's "
            "vertical is known (its silhouette, an ellipse, made a circle: a plum is 1.2-1.6 times as "
            "tall as wide); false: as circles, which cut an elongated fruit in two"
        ),
    )
    min_arc_deg: float = field(
        default=150.0,
        metadata=_why("fewest degrees of the target's outline seen (after trimming) to measure it", "deg"),
    )
    max_fit_rms_px: float = field(
        default=0.8, metadata=_why("largest rms residual of the silhouette points kept in the fit", "px")
    )
    max_fit_sigma_px: float = field(
        default=1.0,
        metadata=_why(
            "largest 1-sigma centre uncertainty of the fit itself (short or ragged arcs: a fruit "
            "touching ripe neighbours shows no outline against them); a looser fit is refused "
            "rather than reported, a fit within it measured with its own sigma in the covariance. "
            "0.5 refused most views of whole fruit in a truss (ripe_truss: 88-95% of ripe fruit "
            "localised against 97-100% at 1.0)",
            "px",
        ),
    )
    max_outside_share: float = field(
        default=0.05,
        metadata=_why(
            "largest share of the target's outline points more than outlier_px outside its fitted "
            "circle (more: the outline is not one fruit, a merged blob)"
        ),
    )
    min_radius_px: float = field(
        default=6.0,
        metadata=_why(
            "smallest apparent radius of a fruit (a 15 mm cherry at 1.2 m); smaller circles are specks "
            "of colour",
            "px",
        ),
    )
    size_tolerance_rel: float = field(
        default=0.5,
        metadata=_why(
            "when the caller passes the expected apparent radius, a fitted radius off by more than this "
            "share (either way) is not the target (a fragment, a merged blob, another fruit)"
        ),
    )

    ambiguity_ratio: float = field(
        default=20.0,
        metadata=_why(
            "when the estimate allows two fruit and the likelier is less than this many times as "
            "likely (3-D Mahalanobis distance of each to the estimate), the view is ambiguous and "
            "measures nothing"
        ),
    )

    box_noise_px: float = field(
        default=2.0,
        metadata=_why(
            "synthetic_boxes: Gaussian sigma of each box corner coordinate; the box adapter declares "
            "it (centre sigma = this / sqrt 2, apparent radius sigma = this / 2 near the optical axis)",
            "px",
        ),
    )
    miss_p: float = field(
        default=0.0, metadata=_why("synthetic_boxes: probability that a fruit in view gets no box")
    )
    false_positives: float = field(
        default=0.0,
        metadata=_why(
            "synthetic_boxes: mean number of false boxes per image (Poisson), fruit-sized, anywhere "
            "in the image"
        ),
    )

    @staticmethod
    def ripe_hue_limits() -> dict[str, int]:
        """The OpenCV hue (0-180) up to which the coloured skin of each ripeness class reaches,
        measured on the scene's rendered skins (``bve_mj.sim.textures``) in white light: red and
        the red of light red 1-8, the yellow-orange of light red and pink up to 30-34, turning
        (and the legacy orange) 33-37; breaker and green 38-45 with the stems, leaves 45-60,
        never ripe. ``ripe_class`` picks one."""
        return {"red": 8, "light_red": 30, "pink": 34, "turning": 37, "orange": 37}

    def __post_init__(self) -> None:
        _choice("detector", "kind", self.kind, DetectorKind)
        if not 0.0 <= _number("detector", "box_noise_px", self.box_noise_px) <= 100.0:
            raise ConfigError("detector.box_noise_px", self.box_noise_px, "a number in [0, 100]")
        if not 0.0 <= _number("detector", "miss_p", self.miss_p) <= 1.0:
            raise ConfigError("detector.miss_p", self.miss_p, "a probability in [0, 1]")
        if not 0.0 <= _number("detector", "false_positives", self.false_positives) <= 100.0:
            raise ConfigError("detector.false_positives", self.false_positives, "a number in [0, 100]")
        for name in (
            "red_hue_max",
            "red_hue_min_wrap",
            "min_saturation",
            "min_value",
            "min_chroma",
            "extend_hue_max",
        ):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or not 0 <= v <= 255:
                raise ConfigError(f"detector.{name}", v, "an integer in [0, 255]")
        _positive_int("detector", "min_area_px", self.min_area_px)
        _positive_int("detector", "min_boundary_points", self.min_boundary_points)
        _positive("detector", "outlier_px", self.outlier_px)
        limits = self.ripe_hue_limits()
        known = isinstance(self.ripe_class, str) and self.ripe_class in limits
        if self.ripe_class is not None and not known:
            raise ConfigError("detector.ripe_class", self.ripe_class, "one of " + ", ".join(limits))
        _open_interval("detector", "max_outside_share", self.max_outside_share, 0.0, 1.0, "a share in (0, 1)")
        _positive("detector", "corner_px", self.corner_px)
        _positive_int("detector", "junction_margin", self.junction_margin)
        _positive("detector", "arc_tol_px", self.arc_tol_px)
        _non_negative("detector", "interior_edge", self.interior_edge)
        if not isinstance(self.shape_grouping, bool):
            raise ConfigError("detector.shape_grouping", self.shape_grouping, "true or false")
        _open_interval("detector", "min_arc_deg", self.min_arc_deg, 0.0, 360.0, "a number in (0, 360)")
        _positive("detector", "max_fit_rms_px", self.max_fit_rms_px)
        _positive("detector", "max_fit_sigma_px", self.max_fit_sigma_px)
        _non_negative("detector", "min_radius_px", self.min_radius_px)
        _positive("detector", "size_tolerance_rel", self.size_tolerance_rel)
        if isinstance(self.ambiguity_ratio, bool) or not (
            isinstance(self.ambiguity_ratio, (int, float)) and 1.0 < self.ambiguity_ratio < math.inf
        ):
            raise ConfigError("detector.ambiguity_ratio", self.ambiguity_ratio, "a finite number > 1")

    @property
    def partial_colour(self) -> bool:
        """Whether the ripe class admits fruit coloured only in part (a class short of red)."""
        return self.ripe_class not in RED_CLASSES

    @property
    def ripe_hue_max(self) -> int:
        """The hue limit of ripe pixels: that of ``ripe_class``, else ``red_hue_max``."""
        return self.red_hue_max if self.ripe_class is None else self.ripe_hue_limits()[self.ripe_class]
