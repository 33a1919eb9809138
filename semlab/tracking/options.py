"""The tracker's options: frozen, validated groups, every default a named constant.

:class:`semlab.tracking.Tracker` takes its options as keywords (the contract); here they are
sorted into the concern each belongs to, checked once, and normalised (integers made integers,
the per-method defaults resolved), so the modules that use them read ``options.band.inner_px``
instead of a loose attribute. An unknown keyword is refused with the list of the allowed ones.
Why each default is what it is, and what it was measured against, is in the benchmarks
(``benchmarks/bench_tracking.py``, ``benchmarks/bench_tracking_seeds.py``).
"""

from __future__ import annotations

import dataclasses
import inspect
from dataclasses import dataclass, field

from ..template import CONTOUR_CHOICES
from .consistency import MAX_INFLUENCE_PX
from .trimming import MISFIT_P_VALUE
from .uncertainty import (
    AMBIGUOUS_JUMP_PX,
    MAX_TEXTURED_SCORE_DROP,
    MIN_RESOLVED_CONTRAST,
    MIN_TRACK_SCORE,
    SIGMA_LIMIT_PX,
)

__all__ = [
    "CANNY_SIGMA",
    "DEFAULT_METHOD",
    "METHODS",
    "AveragingOptions",
    "BandOptions",
    "ContourOptions",
    "JacobianOptions",
    "LossOptions",
    "PhotometryOptions",
    "SearchOptions",
    "StageOptions",
    "TemplateOptions",
    "TrackerOptions",
]

METHODS = ("ic", "contour", "ssd", "hb")
#: The method :class:`~semlab.tracking.Tracker` uses unless told otherwise: the best measured one.
DEFAULT_METHOD = "ic"
PHOTOMETRY_MODES = ("regression", "regions", "instrument")

#: The paper's search window: 300×300 px around the last position (its Fig. 4).
SEARCH_SIZE_PX = 300
#: Smallest search window: a 16-px window cannot hold a template that carries a contour.
MIN_SEARCH_SIZE_PX = 16
#: ``"ic"``'s coarse search runs on images block-averaged by this factor (a quarter: 16× less work,
#: and a 200-px template still holds 50×50 px of shape).
COARSE_FACTOR = 4
#: Gaussian smoothing (px) before the contour template's Otsu threshold (paper, Fig. 2).
TEMPLATE_SIGMA = 2.0
#: Gaussian smoothing (px) before Canny in the ``"contour"`` method — and in the
#: :class:`semlab.widgets.TemplateExplorer`, whose parameters go straight into :func:`~semlab.track`.
CANNY_SIGMA = 2.0
#: Band pixels reach this deep on the object's side at least (its gray level, the photometric
#: nuisance, is pinned by them); 0: as deep as on the background's side.
INNER_PX = 0
#: Side (px) of the background tiles that each get their own level (the substrate's texture and
#: shading at the scale of a few px); 0: one level for all the background.
BACKGROUND_TILE_PX = 8
#: Huber threshold in robust standard deviations: 2 keeps ~95 % efficiency on Gaussian noise and
#: bounds an occluder's influence.
HUBER = 2.0
#: Frames averaged into the ``"ic"`` template (the one-frame template's noise enters every estimate).
TEMPLATE_FRAMES = 20
#: Gauss–Newton iterations per stage and frame.
MAX_ITERATIONS = 20
#: Lowest score of a frame, per method, unless ``min_score`` is given: normalised correlation
#: (``"ic"``: it holds low-dose frames that are right; the others' scores run higher) or the
#: fraction of contour pixels on an edge (``"contour"``).
MIN_SCORE = {"ic": 0.1, "contour": 0.3, "ssd": 0.3, "hb": 0.3}
#: ``"ic"``: a frame is also lost below this fraction of the first frames' typical score.
MIN_RELATIVE_SCORE = 0.5
#: ``"ic"``: smoothing (px) of the finest smoothed registration level (the ladder is 4, 2, 1 × it).
COARSE_SIGMA = 1.0
#: ``"ic"``: the Jacobian's smoothing (px) grows with the template's noise between these two:
#: an averaged, clean template gets the first, a noisy one-frame template at most the second.
JACOBIAN_SIGMA = 0.7
JACOBIAN_SIGMA_FIRST = 2.0
#: ``"ic"``: NL-means strength of the Jacobian's template, in standard deviations of its noise.
JACOBIAN_DENOISE = 0.8
#: ``"ic"``: a band pixel whose early and late means differ by more than this many standard errors
#: is static background (Welch's t; 6: a false alarm about once in 10⁹ pixels).
CONSISTENCY_CUT = 6.0


def _is_count(value, lowest: int) -> bool:
    return int(value) == value and value >= lowest


def _refuse(name: str, value, needs: str):
    raise ValueError(f"{name} must {needs}, got {value!r}")


def _normalise(group, **converted):
    for name, value in converted.items():
        object.__setattr__(group, name, value)


@dataclass(frozen=True)
class SearchOptions:
    """Where a frame is searched: the window around the prediction (paper: 300 px) and the
    ``"ic"`` coarse search's downsampling."""

    search_size: int = SEARCH_SIZE_PX
    coarse_factor: int = COARSE_FACTOR

    def __post_init__(self):
        if not _is_count(self.search_size, MIN_SEARCH_SIZE_PX):
            _refuse("search_size", self.search_size, f"be an integer of at least {MIN_SEARCH_SIZE_PX} px")
        if not _is_count(self.coarse_factor, 1):
            _refuse("coarse_factor", self.coarse_factor, "be a positive integer")
        _normalise(self, search_size=int(self.search_size), coarse_factor=int(self.coarse_factor))


@dataclass(frozen=True)
class TemplateOptions:
    """Contour template identification (:func:`semlab.template.identify_contour_template`)."""

    sigma: float = TEMPLATE_SIGMA
    threshold: float | None = None
    morph_kernel: int = 3
    morph_iterations: int = 1
    bright_object: bool = True
    #: Which external contour is the object: None resolves per method ("central" for ``"ic"``,
    #: the paper's "largest" for the paper's methods).
    choose: str | None = None

    def __post_init__(self):
        if self.choose is not None and self.choose not in CONTOUR_CHOICES:
            _refuse("choose", self.choose, f"be one of {CONTOUR_CHOICES} or None")

    def as_kwargs(self) -> dict:
        """The keywords of :func:`~semlab.template.identify_contour_template`."""
        return dataclasses.asdict(self)


@dataclass(frozen=True)
class ContourOptions:
    """The ``"contour"`` method's edges (:func:`semlab.edges.canny_edges`, eq. 10), its match, and
    whether ``"contour"``/``"ssd"`` refine the integer match by eq. 9 (None: per method)."""

    canny_sigma: float = CANNY_SIGMA
    canny_low: float | None = None
    canny_high: float | None = None
    contour_tolerance: int = 0
    subpixel: bool | None = None

    def __post_init__(self):
        _normalise(self, contour_tolerance=int(self.contour_tolerance))

    def canny_kwargs(self) -> dict:
        """The keywords of :func:`~semlab.edges.canny_edges`."""
        return {"sigma": self.canny_sigma, "low": self.canny_low, "high": self.canny_high}


@dataclass(frozen=True)
class BandOptions:
    """The registration band around the contour (:mod:`semlab.tracking.band`)."""

    band_px: int | None = None
    inner_px: int = INNER_PX
    background_tile: int = BACKGROUND_TILE_PX
    #: ``"ic"``: particles touching the probe in frame 0 are cut off the contour region and the band
    #: keeps clear of them (:mod:`semlab.tracking.attached`).
    cut_attached: bool = True
    #: ``"ic"``: once the object has moved, the background beside it is learned in frame coordinates and
    #: its texture taken off the frames, the template's flattened (:mod:`semlab.tracking.layer`), where frame
    #: 0's background is textured (:data:`~semlab.tracking.layer.MIN_TEXTURE`).
    static_background: bool = True

    def __post_init__(self):
        if self.band_px is not None and not _is_count(self.band_px, 1):
            _refuse("band_px", self.band_px, "be a positive integer or None")
        if not _is_count(self.background_tile, 0):
            _refuse("background_tile", self.background_tile, "be a non-negative integer")
        _normalise(self, band_px=None if self.band_px is None else int(self.band_px),
                   inner_px=int(self.inner_px), background_tile=int(self.background_tile),
                   cut_attached=bool(self.cut_attached), static_background=bool(self.static_background))


@dataclass(frozen=True)
class PhotometryOptions:
    """``"ic"``'s model of the gray levels: gain and offset per frame (how), the scan line's noise
    correlation undone, pixels weighted by their shot-noise variance."""

    photometric: bool = True
    photometry: str = "regions"
    whiten: bool = True
    noise_weights: bool = True

    def __post_init__(self):
        if self.photometry not in PHOTOMETRY_MODES:
            raise ValueError(f"photometry must be 'regression', 'regions' or 'instrument', got {self.photometry!r}")
        _normalise(self, photometric=bool(self.photometric), whiten=bool(self.whiten),
                   noise_weights=bool(self.noise_weights))


@dataclass(frozen=True)
class JacobianOptions:
    """``"ic"``'s Jacobian (the template's gradients, eq. 5's ``M₀``): its smoothing, the edge-normal
    projection and the NL-means denoising of the averaged template."""

    jacobian_sigma: float = JACOBIAN_SIGMA
    jacobian_sigma_first: float = JACOBIAN_SIGMA_FIRST
    normal_sigma: float = 0.0
    jacobian_denoise: float | None = JACOBIAN_DENOISE

    def __post_init__(self):
        if self.jacobian_denoise is not None and not self.jacobian_denoise >= 0:
            _refuse("jacobian_denoise", self.jacobian_denoise, "be >= 0 or None")
        _normalise(self, jacobian_sigma=float(self.jacobian_sigma),
                   jacobian_sigma_first=float(self.jacobian_sigma_first), normal_sigma=float(self.normal_sigma))


@dataclass(frozen=True)
class StageOptions:
    """``"ic"``'s Gauss–Newton stages: the smoothed coarse-to-fine ladder (0: none), the iterations
    per stage (also ``"hb"``'s), the robust loss and the misfit tiles' trimming
    (:mod:`semlab.tracking.trimming`)."""

    coarse_sigma: float = COARSE_SIGMA
    max_iterations: int = MAX_ITERATIONS
    huber: float | None = HUBER
    misfit_p_value: float | None = MISFIT_P_VALUE

    def __post_init__(self):
        if self.huber is not None and not self.huber > 0:
            _refuse("huber", self.huber, "be > 0 or None")
        if self.misfit_p_value is not None and not 0 < self.misfit_p_value < 1:
            _refuse("misfit_p_value", self.misfit_p_value, "be in (0, 1) or None")
        if not _is_count(self.max_iterations, 1):
            _refuse("max_iterations", self.max_iterations, "be a positive integer")
        _normalise(self, coarse_sigma=float(self.coarse_sigma), max_iterations=int(self.max_iterations))


@dataclass(frozen=True)
class AveragingOptions:
    """``"ic"``'s template averaging (:mod:`semlab.tracking.averaging`)."""

    template_frames: int = TEMPLATE_FRAMES
    consistency_cut: float | None = CONSISTENCY_CUT
    reidentify: bool = False

    def __post_init__(self):
        if self.consistency_cut is not None and not self.consistency_cut > 0:
            _refuse("consistency_cut", self.consistency_cut, "be > 0 or None")
        _normalise(self, template_frames=max(int(self.template_frames), 1), reidentify=bool(self.reidentify))


@dataclass(frozen=True)
class LossOptions:
    """When a frame counts as lost: an absolute score (None: the method's :data:`MIN_SCORE`) and,
    for ``"ic"``, a fraction of the first frames' typical score; and when an answer is too
    uncertain to trust (``"ic"``: either axis's sigma above ``max_sigma`` px, None: never) or too
    inconsistent (``"ic"``: one quadrant of the band moving the answer by more than ``max_influence``
    px, significantly; None: never), or unresolved (``"ic"``: frame 0's object standing less than
    ``min_resolved_contrast`` noise standard deviations above its background, every frame; None: never),
    or unexplained (``"ic"``: the track's median match score so far under ``min_track_score``; None:
    never), or ambiguous (``"ic"``: more than ``max_poor_jump`` px, and more than the move the track expected,
    from both its prediction and its last position, at a match scoring under the track's typical one;
    before the track has one, more than ``UNVOUCHED_JUMP_PX`` = 1 px at any match; None: never), or slid
    (``"ic"``, over a strongly textured substrate only: a match scoring more than ``max_textured_drop`` under
    the track's first frames' median; None: never)."""

    min_score: float | None = None
    min_relative_score: float = MIN_RELATIVE_SCORE
    max_sigma: float | None = SIGMA_LIMIT_PX
    max_influence: float | None = MAX_INFLUENCE_PX
    min_resolved_contrast: float | None = MIN_RESOLVED_CONTRAST
    min_track_score: float | None = MIN_TRACK_SCORE
    max_poor_jump: float | None = AMBIGUOUS_JUMP_PX
    max_textured_drop: float | None = MAX_TEXTURED_SCORE_DROP

    def __post_init__(self):
        if not 0 <= self.min_relative_score < 1:
            _refuse("min_relative_score", self.min_relative_score, "lie in [0, 1)")
        if self.max_sigma is not None and not self.max_sigma > 0:
            _refuse("max_sigma", self.max_sigma, "be > 0 px or None")
        if self.max_influence is not None and not self.max_influence > 0:
            _refuse("max_influence", self.max_influence, "be > 0 px or None")
        if self.min_resolved_contrast is not None and not self.min_resolved_contrast > 0:
            _refuse("min_resolved_contrast", self.min_resolved_contrast, "be > 0 or None")
        if self.min_track_score is not None and not 0 < self.min_track_score < 1:
            _refuse("min_track_score", self.min_track_score, "lie in (0, 1) or None")
        if self.max_poor_jump is not None and not self.max_poor_jump >= 0:
            _refuse("max_poor_jump", self.max_poor_jump, "be >= 0 px or None")
        if self.max_textured_drop is not None and not 0 <= self.max_textured_drop < 1:
            _refuse("max_textured_drop", self.max_textured_drop, "lie in [0, 1) or None")
        _normalise(self, min_relative_score=float(self.min_relative_score),
                   max_sigma=None if self.max_sigma is None else float(self.max_sigma),
                   max_influence=None if self.max_influence is None else float(self.max_influence),
                   min_resolved_contrast=None if self.min_resolved_contrast is None
                   else float(self.min_resolved_contrast),
                   min_track_score=None if self.min_track_score is None else float(self.min_track_score),
                   max_poor_jump=None if self.max_poor_jump is None else float(self.max_poor_jump),
                   max_textured_drop=None if self.max_textured_drop is None else float(self.max_textured_drop))


#: The groups in the order the Tracker's signature lists them: ``TrackerOptions`` field -> class.
GROUPS = {"search": SearchOptions, "template": TemplateOptions, "contour": ContourOptions,
          "band": BandOptions, "photometry": PhotometryOptions, "jacobian": JacobianOptions,
          "stages": StageOptions, "averaging": AveragingOptions, "loss": LossOptions}
#: Every keyword the Tracker takes besides ``method``, and the group it belongs to.
KEYWORD_GROUP = {f.name: group for group, cls in GROUPS.items() for f in dataclasses.fields(cls)}


@dataclass(frozen=True)
class TrackerOptions:
    """All of a :class:`~semlab.tracking.Tracker`'s options, by concern (see each group)."""

    method: str = DEFAULT_METHOD
    search: SearchOptions = field(default_factory=SearchOptions)
    template: TemplateOptions = field(default_factory=TemplateOptions)
    contour: ContourOptions = field(default_factory=ContourOptions)
    band: BandOptions = field(default_factory=BandOptions)
    photometry: PhotometryOptions = field(default_factory=PhotometryOptions)
    jacobian: JacobianOptions = field(default_factory=JacobianOptions)
    stages: StageOptions = field(default_factory=StageOptions)
    averaging: AveragingOptions = field(default_factory=AveragingOptions)
    loss: LossOptions = field(default_factory=LossOptions)

    @classmethod
    def from_keywords(cls, method: str = DEFAULT_METHOD, **keywords) -> TrackerOptions:
        """Sort the Tracker's keywords into their groups and validate them.

        Raises
        ------
        TypeError
            An unknown keyword (the message lists the allowed ones).
        ValueError
            An unknown method or a bad value.
        """
        if method not in METHODS:
            raise ValueError(f"unknown method {method!r}; choose one of {METHODS}")
        unknown = sorted(set(keywords) - set(KEYWORD_GROUP))
        if unknown:
            raise TypeError(f"Tracker got unknown keyword(s) {unknown}; allowed: method, "
                            f"{', '.join(KEYWORD_GROUP)}")
        by_group = {group: {} for group in GROUPS}
        for name, value in keywords.items():
            by_group[KEYWORD_GROUP[name]][name] = value
        groups = {group: GROUPS[group](**values) for group, values in by_group.items()}
        contour, loss = groups["contour"], groups["loss"]
        if contour.subpixel is None:  # eq. 9 refines "contour"; "ssd" is integer-only as conventionally used
            groups["contour"] = dataclasses.replace(contour, subpixel=method == "contour")
        else:
            groups["contour"] = dataclasses.replace(contour, subpixel=bool(contour.subpixel))
        if groups["template"].choose is None:  # the paper's methods keep the paper's largest contour
            groups["template"] = dataclasses.replace(groups["template"],
                                                     choose="central" if method == "ic" else "largest")
        min_score = MIN_SCORE[method] if loss.min_score is None else float(loss.min_score)
        groups["loss"] = dataclasses.replace(loss, min_score=min_score)
        return cls(method=method, **groups)

    @staticmethod
    def signature(first: inspect.Parameter) -> inspect.Signature:
        """``(first, method=DEFAULT_METHOD, *, <every keyword with its default>)``: the Tracker's
        constructor as :func:`inspect.signature` and ``help`` show it."""
        params = [first, inspect.Parameter("method", inspect.Parameter.POSITIONAL_OR_KEYWORD,
                                           default=DEFAULT_METHOD, annotation="str")]
        for cls in GROUPS.values():
            params += [inspect.Parameter(f.name, inspect.Parameter.KEYWORD_ONLY, default=f.default,
                                         annotation=f.type) for f in dataclasses.fields(cls)]
        return inspect.Signature(params)
