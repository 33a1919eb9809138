"""The trackers the corpus compares, by name, as zero-argument factories.

``semlab`` is :class:`semlab.tracking.Tracker` with its defaults as they are when the run starts
(or with ``params``), ``paper`` the paper's contour method, and the peers those of
:mod:`semlab.peers`. Any other tracker is a factory: a zero-argument callable returning an object
with ``init(frame, roi)`` and ``update(frame)``, e.g. ``{"semlab-huber3": lambda: Tracker(huber=3)}``.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Mapping

from semlab.peers import ECCPeer, MatchTemplatePeer, PhaseCorrelationPeer
from semlab.tracking import Tracker

__all__ = ["DEFAULT_TRACKERS", "TRACKER_NAMES", "describe_trackers", "resolve_trackers"]

#: name -> (factory maker, what it is). The makers take the ``semlab`` parameters (ignored by the others).
_BUILTIN = {
    "semlab": (lambda params: functools.partial(Tracker, **params), "semlab.tracking.Tracker() (its defaults)"),
    "paper": (lambda params: functools.partial(Tracker, "contour"), "Tracker(method='contour'): the paper's method"),
    "ncc": (lambda params: functools.partial(MatchTemplatePeer, "TM_CCOEFF_NORMED"),
            "OpenCV matchTemplate TM_CCOEFF_NORMED + parabola"),
    "sqdiff": (lambda params: functools.partial(MatchTemplatePeer, "TM_SQDIFF"), "OpenCV matchTemplate TM_SQDIFF + parabola"),
    "ecc": (lambda params: ECCPeer, "OpenCV findTransformECC, translation"),
    "phasecorr": (lambda params: PhaseCorrelationPeer, "scikit-image phase_cross_correlation, upsample 100"),
}
#: Every tracker name the corpus knows.
TRACKER_NAMES = tuple(_BUILTIN)
#: The trackers of a run unless told otherwise: semlab's default and the four peers.
DEFAULT_TRACKERS = ("semlab", "ncc", "sqdiff", "ecc", "phasecorr")


def describe_trackers() -> dict[str, str]:
    """name -> what it is."""
    return {k: v[1] for k, v in _BUILTIN.items()}


def resolve_trackers(trackers=None, params: Mapping | None = None) -> dict[str, Callable]:
    """name -> zero-argument factory, from names, a dict of factories, or a mix.

    Parameters
    ----------
    trackers : None, str, iterable of str, or mapping name -> factory
        ``None``: :data:`DEFAULT_TRACKERS`. A comma-separated string or a list of names from
        :data:`TRACKER_NAMES`; a mapping may give factories and, for built-in names, ``None``.
    params : mapping or None
        Keyword arguments of :class:`semlab.tracking.Tracker` for the ``semlab`` tracker.

    Raises
    ------
    ValueError
        An unknown name (listing the valid ones), an empty selection, a factory that is not
        callable, or ``params`` that :class:`Tracker` refuses.
    """
    params = dict(params or {})
    if trackers is None:
        trackers = DEFAULT_TRACKERS
    if isinstance(trackers, str):
        trackers = [t.strip() for t in trackers.split(",") if t.strip()]
    items = list(trackers.items()) if isinstance(trackers, Mapping) else [(t, None) for t in trackers]
    if not items:
        raise ValueError(f"no trackers selected; valid: {', '.join(TRACKER_NAMES)}")
    out = {}
    for name, factory in items:
        if factory is None:
            if name not in _BUILTIN:
                raise ValueError(f"unknown tracker {name!r}; valid: {', '.join(TRACKER_NAMES)}")
            factory = _BUILTIN[name][0](params)
        elif not callable(factory):
            raise ValueError(f"tracker {name!r}: the factory must be a zero-argument callable")
        out[str(name)] = factory
    if params and "semlab" not in out:
        raise ValueError("tracker parameters apply to the 'semlab' tracker, which is not selected")
    if params:
        try:  # refuse bad parameters before any sequence is simulated
            Tracker(**params)
        except (TypeError, ValueError) as e:
            raise ValueError(f"invalid semlab tracker parameter: {e}") from None
    return out
