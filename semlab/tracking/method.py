"""What a tracking method is to the :class:`~semlab.tracking.Tracker`: the steps it drives.

The Tracker runs every frame through the same states — predicted → (followed) → searched →
re-acquired → verdict — and asks its method object (one per algorithm, chosen once: ``"ic"`` in
:mod:`semlab.tracking.ic`, ``"contour"``, ``"ssd"`` and ``"hb"`` in :mod:`semlab.tracking.paper`)
what each state means. :class:`Method` is that interface with its defaults: a method that only
searches (the paper's) overrides :meth:`Method.search` and :meth:`Method.verdict`. A new model
of the scene is a new module with a new :class:`Method`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..subpixel import NoiseModel
from ..template import ContourTemplate
from .options import TrackerOptions

__all__ = ["Method", "Motion", "Setup", "Verdict"]


@dataclass
class Motion:
    """The target's motion state, which only the Tracker changes.

    Attributes
    ----------
    shift : (2,) ndarray
        The template's last shift against the ROI of frame 0 (px).
    velocity : (2,) ndarray
        The last frame-to-frame shift (0 after a loss).
    lost : bool
        The last frame was lost: the next one is searched over the whole image.
    n_lost : int
        Frames lost so far.
    prediction_error : float
        How far (px) the last answer was from its prediction (inf after a loss or a
        re-acquisition).
    miss : float
        How far (px) the last answer was from its prediction, re-acquired or not (inf after a loss).
    """

    shift: np.ndarray = field(default_factory=lambda: np.zeros(2))
    velocity: np.ndarray = field(default_factory=lambda: np.zeros(2))
    lost: bool = False
    n_lost: int = 0
    prediction_error: float = np.inf
    miss: float = np.inf

    def record_miss(self, shift, predicted, reacquired: bool, steady_px: float) -> tuple[float, float]:
        """Note how far the accepted ``shift`` is from its ``predicted`` one, and return ``(off, expected)``
        (px): how far it is off the track, from both the prediction and the last position (a frame after
        a jump is predicted as far again), and the move the track expected, its speed when its last
        prediction held to ``steady_px`` (0 after a jump, whose speed is no motion to extrapolate).
        Called before the state moves on to ``shift``."""
        missed = float(np.hypot(*(np.asarray(shift, float) - predicted)))
        off = min(missed, float(np.hypot(*(np.asarray(shift, float) - self.shift))))
        expected = float(np.hypot(*(predicted - self.shift))) if self.miss <= steady_px else 0.0
        self.prediction_error = np.inf if reacquired else missed
        self.miss = missed
        return off, expected


@dataclass(frozen=True)
class Verdict:
    """A frame's outcome as the method judged it: a shift and a score, or the reason it is lost.

    ``reacquired``: found by the re-acquisition fallback (its prediction error is unknown).
    ``found``: what the method found (e.g. the registration's :class:`FitResult`), for
    :meth:`Method.after_accept`.
    ``drifted``: re-acquired where the registration matches the template but drifts away: the
    cost has no clear minimum there, as along a shaft.
    """

    ok: bool
    shift: np.ndarray | None = None
    score: float = 0.0
    reason: str = ""
    reacquired: bool = False
    found: object = None
    drifted: bool = False

    @classmethod
    def accept(cls, shift, score: float, *, reacquired: bool = False, found=None,
               drifted: bool = False) -> Verdict:
        return cls(True, np.asarray(shift, float), score, "", reacquired, found, drifted)

    @classmethod
    def lose(cls, reason: str) -> Verdict:
        return cls(False, reason=reason)


@dataclass(frozen=True)
class Setup:
    """What the Tracker measured on frame 0 for its method.

    Attributes
    ----------
    image : (H, W) ndarray of float32
        Frame 0.
    roi : (x, y, w, h)
    patch : (h, w) ndarray of float32
        The ROI of frame 0: the first template.
    contour : ContourTemplate
    band : (h, w) ndarray of bool
        The registration band (:func:`semlab.tracking.band.registration_band`).
    widths : (int, int)
        The band's reach ``(background, object)``.
    noise : NoiseModel
        The frames' noise as the method uses it.
    to_8bit : (float, float)
        ``(low, scale)``: how the contour identification mapped frame 0's gray levels on 0-255.
    texture : float
        The background's texture over the noise (:func:`semlab.tracking.band.background_texture`).
    """

    image: np.ndarray
    roi: tuple
    patch: np.ndarray
    contour: ContourTemplate
    band: np.ndarray
    widths: tuple[int, int]
    noise: NoiseModel
    to_8bit: tuple[float, float]
    texture: float = 0.0
    #: The edge's blur (px, :func:`~semlab.tracking.band.edge_blur`), NaN when not measured.
    edge_sigma: float = float("nan")
    #: The particles frame 0's cut took off the region (ROI-sized bool mask; None: none), which the band keeps
    #: clear of (:mod:`semlab.tracking.attached`).
    attached: np.ndarray | None = None


class Method:
    """One tracking algorithm: its offline set-up and what each state of a frame means to it.

    Attributes (after :meth:`start`)
    --------------------------------
    template : (h, w) ndarray
        The template the method matches (averaged over frames by ``"ic"``).
    contour, band
        Its contour template and registration band.
    origin : (2,) ndarray
        The shift at which the template sits in frame 0 (``"ic"`` re-registers frame 0 against
        every averaged template); positions are ``ROI centre + shift − origin``.
    """

    name = ""
    #: Whether an answer whose :meth:`sigma` is too large is flagged (``"ic"``; the paper's methods
    #: keep their own verdicts, exactly as the paper has them, and only report the uncertainty).
    flags_uncertain = False
    #: Whether a frame the search window did not find it in is searched over the whole frame before
    #: it is lost (``"ic"``; the paper's methods search their window, as the paper has them).
    widens_search = False
    #: Whether particles touching the object in frame 0 are cut off its contour region before the band
    #: is drawn (``"ic"``, with ``cut_attached``: :mod:`semlab.tracking.attached`; the paper's methods
    #: keep the paper's contour).
    cuts_attached = False
    #: Whether frame 0's background is strongly textured (``"ic"`` flattens it for its band model and
    #: judges a falling match there: :meth:`~semlab.tracking.trust.Judge.doubt_match`).
    flatten = False

    def __init__(self, options: TrackerOptions):
        self.options = options
        self.origin = np.zeros(2)

    def start(self, setup: Setup) -> None:
        """The offline set-up on frame 0."""
        self.roi, self.contour, self.band = setup.roi, setup.contour, setup.band
        self.template = setup.patch

    def predict(self, motion: Motion) -> np.ndarray:
        """Where the template is expected (the search window is centred there): the last shift."""
        return motion.shift

    def prepare(self, arr, predicted, motion: Motion) -> np.ndarray:
        """The frame the method registers (``"ic"``: the static background's texture taken off,
        :mod:`semlab.tracking.layer`); :meth:`after_accept` still sees ``arr`` as it came."""
        return arr

    def follow(self, arr, predicted, motion: Motion):
        """Track from the prediction (not called after a loss); None: nothing to refine."""
        return

    def good(self, found) -> bool:
        """Whether what :meth:`follow` found makes a search unnecessary."""
        return False

    def typical_score(self) -> float | None:
        """The score a match of the object reaches on this track, or None when the method keeps none."""
        return None

    def track_score(self) -> float | None:
        """The median match score of the track's first frames, or None when the method keeps none."""
        return None

    def search(self, arr, window, predicted, found):
        """Search ``window`` (the whole image after a loss); returns what is found (or ``found``)."""
        raise NotImplementedError

    def acceptable(self, found) -> bool:
        """Whether ``found`` may stand without a re-acquisition (asked unless lost)."""
        return True

    def clearly_better(self, other, found) -> bool:
        """Whether ``other`` (from a wider search) beats an acceptable ``found`` by more than a tie."""
        return False

    def reacquire(self, arr, window, predicted) -> Verdict | None:
        """The fallback when ``found`` is not acceptable: an accepted verdict, or None."""
        return None

    def verdict(self, arr, found, predicted) -> Verdict:
        """Accept ``found`` or say why the frame is lost."""
        raise NotImplementedError

    def sigma(self, verdict: Verdict):
        """The accepted position's :class:`~semlab.tracking.uncertainty.Uncertainty`, or None when
        the method cannot tell."""
        return

    def after_accept(self, arr, verdict: Verdict) -> np.ndarray | None:
        """Work on an accepted frame (``"ic"``: the template averaging); returns the change of
        :attr:`origin` the motion state must follow, or None."""
        return None
