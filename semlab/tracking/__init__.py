"""The tracker users call: :class:`Tracker` and :func:`track` (Ru et al. 2012, Fig. 4).

Methods
-------
``"ic"`` (the default of :class:`Tracker`, :func:`track`, the CLI and the widgets)
    Beyond the paper, and measured best (``benchmarks/bench_tracking.py``): inverse-compositional
    Gauss–Newton (eq. 2 with the paper's offline matrix ``M₀`` of eqs. 4-5 as its Jacobian) on the
    contour band — the pixels within ``band_px`` of the contour template, where nearly all the
    positional information is — started from the constant-velocity prediction and, when that
    fails, from a coarse masked normalised-correlation search at quarter resolution (the whole
    image after a loss), through a coarse-to-fine smoothed stage; exact Keys bicubic
    interpolation; gain and offset from the object and background levels (gray-level
    fluctuation, charging); Huber weights (occlusion, clutter); the image whitened along the scan
    line and weighted by the shot-noise variance (both estimated from the first frame); a
    Jacobian smoothed in proportion to the template's noise; and a template averaged over the
    first registered frames with frame 0 re-registered against it as the origin (a one-frame
    template doubles the variance of every estimate). Particles touching the probe in frame 0
    are cut off its contour region first (they do not move with it). When Gauss–Newton fails both from the
    prediction and from the coarse search (an edge's contrast vanishing at contact with a
    sample, a brightness jump), a masked normalised correlation of the object's neighbourhood
    over the whole search window — blind to gain and offset — re-acquires it if its peak stands
    out, and Gauss–Newton restarts from there.
``"contour"`` (the paper's method), ``"ssd"``, ``"hb"``
    The paper's method (adaptive-threshold Canny, eq. 10, the contour-template match, one step of
    eq. 9 on the contour band), the conventional full-template SSD at integer positions (eq. 2)
    that it improves on, and its parametric SSD tracker (eqs. 2-5, Hager & Belhumeur 1998): see
    :mod:`semlab.tracking.paper`.

A lost target (occlusion, the probe leaving the window, contact, an unusable frame) never
raises: the row says ``ok=False`` with NaN position and a low score, and the next frame is
searched over the whole image to re-acquire it. Several targets (the rig's four probes) are
tracked in one pass over the frames by giving :func:`track` a list of ROIs (one independent
:class:`Tracker` per ROI, a ``target`` column in the result).

Modules
-------
``options``
    The Tracker's options in validated, frozen groups; every default a named constant.
``result``
    :class:`TrackResult`, one frame's answer.
``frames``
    Frame validation, float crops, iteration over a sequence.
``attached``
    Particles touching the probe in frame 0: cut off the contour region, the band kept clear of them.
``band``
    The registration band around the contour and the band model built on it, offline.
``registration``
    :func:`~semlab.tracking.registration.register`: shift, gain and offset fitted from a start,
    down the coarse-to-fine ladder; its :class:`~semlab.tracking.registration.FitResult`.
``search``
    The search window, the coarse search and the re-acquisition: candidates, no tracker state.
``averaging``
    Template averaging over the first frames and the consistency of the band's pixels.
``method``
    The interface the Tracker drives, the motion state and a frame's verdict.
``trimming``
    The band's misfit tiles dropped and the frame refitted.
``layer``
    The static background beside a moving probe, learned in frame coordinates, its texture taken off the frames.
``uncertainty``, ``consistency``
    Each frame's ``sigma_x``, ``sigma_y`` and the tests behind the flags; whether the band's quadrants agree.
``trust``
    :class:`~semlab.tracking.trust.Judge`: whether a followed answer may be reported, or why not.
``lifecycle``
    The ``"ic"`` template through its life: built, averaged, flattened, its loose pieces cut.
``pieces``
    Pieces of frame 0's object that do not move with it, judged by the frames and cut.
``ic``, ``paper``
    One object per algorithm: ``"ic"`` (its per-frame steps over the lifecycle); ``"contour"``, ``"ssd"``, ``"hb"``.
``stepper``
    :class:`~semlab.tracking.stepper.Stepper`: one frame through predicted → (followed) → searched →
    re-acquired → verdict, judged and reported.
``tracker``
    :class:`Tracker`: frame 0's set-up; every later frame through its stepper.
``run``
    :func:`track` and the frame loop it shares with :func:`semlab.metrics.run_tracker`.
"""

from __future__ import annotations

from .band import DEFAULT_BAND_PX, DENOISE_FROM_FRAMES, MIN_BAND_PIXELS, NARROW_BAND_TEXTURE
from .options import DEFAULT_METHOD, METHODS
from .registration import STAGE1_TOLERANCE
from .result import TrackResult
from .run import track, track_with_reasons
from .tracker import Tracker

__all__ = ["DEFAULT_BAND_PX", "DEFAULT_METHOD", "DENOISE_FROM_FRAMES", "METHODS", "MIN_BAND_PIXELS",
           "NARROW_BAND_TEXTURE", "STAGE1_TOLERANCE", "TrackResult", "Tracker", "track",
           "track_with_reasons"]
