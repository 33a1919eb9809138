"""Particles that touch the probe in frame 0: cut off the contour region and left out of the band.

Otsu's threshold (paper, Fig. 2) takes whatever is bright in the ROI of frame 0. A particle touching
the probe's edge there joins the object region as a bump, and the band is drawn around it. But the
particle stays where it is (or drifts) when the probe moves: every later frame is then registered
partly on a feature that does not move with the probe, and along the shaft, where only the apex
tells the position, a bump of a few px holds the template back by a pixel or more while the fit
reports a good match (the corpus's clutter family: static particles touching the edge in frame 0).

A bump is what a morphological opening of the region's main part with a disc leaves out (a particle
smaller than the disc is shaved off, a larger one survives the erosion apart from the main part), at
each of :data:`OPENINGS`: a small disc takes off a particle that touches the edge, a
larger one the cap of a particle sunk into the flank, which a small disc leaves joined to the shaft
by a wide neck. A piece is cut when it is compact (a fraction of its enclosing circle), of a
particle's size (up to :data:`MAX_PIECE_PX`), away from the apex (the region's point farthest from
where it enters the ROI, which the opening also shaves: a wedge's tip is a compact piece too) and from the ROI's border, and dimmer
than the probe (:data:`MAX_RELATIVE_LEVEL` of the probe's contrast over the background: another
material or a rounded particle, where a gripper's jaw or a blunt tip's corner, which the opening
also takes off, is the probe's own material), or as bright as the probe and disc-like
(:data:`MIN_BRIGHT_ROUNDNESS`: a jaw's end is square or narrower). Such a piece is cut off the region
(:func:`without_attached`) and the band keeps :data:`BAND_CLEARANCE_PX` away from it. Only where
the outline is resolved above the noise (:data:`MAX_OUTLINE_NOISE` of the contrast): at low dose
the noise itself makes bumps of the region's outline.

A particle at the apex of a thin tip escapes the openings: the disc shaves the tip together with it,
one piece that touches the apex, and the tip of a wedge is as bright as a particle (the rim). There
the probe's own shape tells them apart (:func:`apex_bumps`): the flanks of a tip 14-44 px behind
its apex (:data:`WEDGE_FIT_PX`) are extrapolated to the apex as a wedge (its axis and half-width,
each linear in the distance from the apex; each flank the inner of its least-squares and
repeated-medians lines, :func:`_inner_flank`, so that a particle on a flank does not widen the
wedge over itself), and what the region holds outside that wedge near the apex
(:data:`BUMP_REACH_PX`), of a particle's size and round, is a particle. Only where the wedge
describes the probe: the region fills the wedge between its flanks (:data:`MIN_WEDGE_FILL`; a
gripper's gap does not) and the tip is thin (:data:`MAX_WEDGE_HALF_WIDTH_PX`; a wide end face fixes
both axes by itself). Left in the template, such a particle holds the answer back along the shaft,
where only the apex tells the position, by a pixel or more with a good score (the corpus's clutter
family at low beam current: ``benchmarks/bench_corpus.py``). Smaller or less round pieces outside the
wedge (:func:`apex_pieces`) are left for the frames to judge (:mod:`semlab.tracking.pieces`).

Over a textured substrate Otsu's level, pulled down by the many background pixels, joins the bright
grains beside the probe to it: the region reaches over them, often by more than the probe's own area
(:func:`substrate_pieces`). The brightest of three Otsu classes (Liao et al. 2001) then separates the
probe from them, and its contour runs along the probe's edges, stronger than the grains' fainter
ones (:func:`~semlab.template.edge_strength`). What Otsu's region holds beyond
:data:`SUBSTRATE_REACH_PX` of that class's region, where it is thicker than an edge's transition
(:data:`SUBSTRATE_MIN_THICKNESS_PX`), is substrate and is cut, apart from what lies within
:data:`BAND_CLEARANCE_PX` of a particle the cut above takes (a particle at a thin tip's apex: the
tip's end beside it, dimmer than its shaft, is below the brightest class's level, and stays). Where the brightest class only cuts a
shaded probe in two, its contour runs across the probe's smooth inside, on weaker edges than Otsu's,
and nothing is cut.
"""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import cv2
import numpy as np
from scipy.stats import siegelslopes

from ..template import ContourTemplate, brightest_of_three, edge_strength, identify_contour_template

__all__ = ["BAND_CLEARANCE_PX", "MAX_OUTLINE_NOISE", "apex_bumps", "apex_pieces", "attached_pieces", "clear_band", "cut_off",
           "substrate_pieces", "without_attached"]


class Opening(NamedTuple):
    """One morphological opening of the region, and what a piece it shaves off must be to be a particle."""

    #: Radius (px) of the opening's disc.
    radius: int
    #: Least area (px²) of a particle's piece.
    min_area: int
    #: Least fraction of its enclosing circle a piece fills (a disc fills 1, a sliver far less).
    min_roundness: float
    #: A piece at most this many px from the apex is the probe's end, which the opening also shaves.
    apex_clearance: float


#: The openings. At 4 px particles of a few px touching the edge come off and the shaft stays (a
#: probe's shaft is wider than 10 px); its least area keeps the outline's own roughness and the
#: corners it shaves (the real needle's in ``data/real-sem/contact_brightness_seq``: 10 px). A
#: particle of 5-8 px in radius half sunk into the flank (the corpus's clutter and charging scenes)
#: survives that disc, joined to the shaft by a neck wider than it, and only the larger discs shave
#: its cap: a segment of a disc, 8 px and more when it is sunk deep, which fills less of its circle
#: than a whole particle does. They also shave the far corner of a flat end (the real needle's:
#: 11.5-13.4 px from its apex, a 15-22-px piece at 6-8 px, dim at its edge like a particle), hence
#: their apex clearance.
OPENINGS = (Opening(4, 15, 0.45, 3), Opening(6, 8, 0.3, 16), Opening(8, 8, 0.3, 16))
#: A piece larger than this (px²) is a part of the probe (a jaw, a shoulder).
MAX_PIECE_PX = 160
#: A piece whose median level (the ROI smoothed by 1 px) reaches this fraction of the probe's
#: contrast over the background is the probe's own material; particles touching the probe on the
#: development scenes are at 0.45-0.87 of it, gripper jaws' tips at 0.9-1.2.
MAX_RELATIVE_LEVEL = 0.9
#: ... up to this fraction (as bright as the probe), a piece is still a particle when it is disc-like: it
#: fills at least :data:`MIN_BRIGHT_ROUNDNESS` of its enclosing circle. The ends of gripper jaws that the
#: openings shave are squares or narrower (a square fills 2/π ≈ 0.64; 0.41-0.71 on the corpus's gripper
#: scenes, spare seeds 251, 282, 291), bright particles on a flank 0.79-0.88 (a pixelated disc; spare seeds
#: of the charging, clutter and wander families, whose particles at 0.91-0.99 of the probe held it back
#: by up to 3 px).
MAX_BRIGHT_LEVEL = 1.0
MIN_BRIGHT_ROUNDNESS = 0.75
#: The band keeps this many px away from a cut piece: the particle's blurred rim reaches that far...
BAND_CLEARANCE_PX = 4
#: ... unless that leaves fewer than this many px on its background side (:func:`clear_band`): as many as a
#: whole band needs (:data:`semlab.tracking.band.MIN_BAND_PIXELS`). Substrates spare seed 219 registers
#: well on the 92 of its 1404 it keeps.
MIN_CLEARED_BACKGROUND_PX = 30
#: The cut only where the smoothed noise is at most this fraction of the object's contrast (0.02-0.045
#: on the development scenes at standard dose, 0.08-0.17 at low dose, where noise bumps the outline).
MAX_OUTLINE_NOISE = 0.06
#: The wedge of a tip is fitted to its body (the region opened by the first opening's disc) between
#: these distances (px) from the apex: behind the particles at the apex, in front of the ROI's border.
WEDGE_FIT_PX = (14.0, 44.0)
#: Fewest body pixels, and distance bins (2 px each), the wedge is fitted to.
MIN_WEDGE_PIXELS = 30
MIN_WEDGE_BINS = 5
WEDGE_BIN_PX = 2.0
#: The wedge reaches this many px beyond its fitted flanks (the outline's roughness) and behind the apex.
WEDGE_MARGIN_PX = 1.0
WEDGE_BEHIND_APEX_PX = 2.0
#: The region fills at least this fraction of the wedge's core (1 px inside its flanks) where it was
#: fitted: a tapering tip 0.95-1 on the development scenes, gripper jaws with their gap 0.73-0.89.
MIN_WEDGE_FILL = 0.94
#: The wedge's half-width at :data:`BUMP_REACH_PX` from the apex is at most this (px): a thin tip
#: (4-8 px on the development scenes' probes); the semi-real needle's end face is 10-11 px.
MAX_WEDGE_HALF_WIDTH_PX = 10.0
#: Bumps outside the wedge are looked for this near (px) the apex.
BUMP_REACH_PX = 25.0
#: A bump is a particle when it has at least this area (px², as the first opening's pieces) and fills
#: at least this fraction of its enclosing circle: particles on the development scenes 0.4-0.94, a
#: blunt end's corner outside a tapering fit 0.16, the outline's noise at low dose 0.09-0.14.
MIN_BUMP_PX = 15
MIN_BUMP_ROUNDNESS = 0.3
#: Otsu's region is substrate where it lies more than this many px from the brightest Otsu class's region
#: (the probe's edge, blurred by the beam and the smoothing, spans the two levels within that)...
SUBSTRATE_REACH_PX = 2
#: ... and is at least this many px thick there (a grain; the outline's slivers along an edge and a thin
#: tip's end, dimmer than its shaft, are narrower).
SUBSTRATE_MIN_THICKNESS_PX = 2
#: The probe's and the background's levels: this far (px) inside the region, and outside it.
LEVEL_MARGIN_PX = 3
LEVEL_SMOOTHING_PX = 1.0


def _disc(radius: int) -> np.ndarray:
    return cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius + 1, 2 * radius + 1))


def _apex(region: np.ndarray) -> tuple[int, int] | None:
    """The region's pixel ``(x, y)`` farthest from where it touches the ROI's border (None: it does not)."""
    edge = np.zeros(region.shape, bool)
    edge[[0, -1], :] = edge[:, [0, -1]] = True
    by, bx = np.nonzero(region & edge)
    if bx.size == 0:
        return None
    to_base = np.ones(region.shape, np.uint8)
    to_base[by, bx] = 0
    distance = cv2.distanceTransform(to_base, cv2.DIST_L2, 5)
    distance[~region] = -1.0
    y, x = np.unravel_index(int(np.argmax(distance)), distance.shape)
    return int(x), int(y)


def _distance_to_apex(region: np.ndarray, apex) -> np.ndarray | None:
    """Every pixel's distance (px) to ``apex`` (None: no apex, no map). The 3×3 chamfer metric is
    symmetric, so the apex's distance to a piece is this map's least value over it."""
    if apex is None:
        return None
    away = np.ones(region.shape, np.uint8)
    away[apex[1], apex[0]] = 0
    return cv2.distanceTransform(away, cv2.DIST_L2, 3)


def _body(region: np.ndarray, radius: int) -> np.ndarray:
    """The opening of the region's main part with a disc of ``radius``: its largest component after
    the erosion, dilated back. A particle wider than the disc survives the erosion as a component of
    its own, and so is not body."""
    disc = _disc(radius)
    eroded = cv2.erode(region.astype(np.uint8), disc)
    n, labels, stats, _ = cv2.connectedComponentsWithStats(eroded, connectivity=8)
    if n < 2:
        return np.zeros(region.shape, bool)
    main = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    return cv2.dilate((labels == main).astype(np.uint8), disc).astype(bool) & region


def _levels(region: np.ndarray, smoothed: np.ndarray) -> tuple[float, float] | None:
    """Median levels of the probe (inside the region) and of the background (outside it)."""
    inner = cv2.erode(region.astype(np.uint8), _disc(LEVEL_MARGIN_PX)).astype(bool)
    outer = ~cv2.dilate(region.astype(np.uint8), _disc(LEVEL_MARGIN_PX + 1)).astype(bool)
    if not inner.any() or not outer.any():
        return None
    return float(np.median(smoothed[inner])), float(np.median(smoothed[outer]))


def attached_pieces(region, patch) -> np.ndarray:
    """The pixels of the particles attached to ``region`` (see the module docstring).

    Parameters
    ----------
    region : (h, w) array_like of bool
        The contour template's region (:attr:`semlab.template.ContourTemplate.region`).
    patch : (h, w) array_like
        The ROI of frame 0 the region was found in.

    Returns
    -------
    (h, w) ndarray of bool
        The pieces to cut (all False when there are none).
    """
    region = np.asarray(region, bool)
    cut = np.zeros(region.shape, bool)
    smoothed = cv2.GaussianBlur(np.asarray(patch, np.float32), (0, 0), LEVEL_SMOOTHING_PX)
    levels = _levels(region, smoothed)
    if levels is None or levels[0] == levels[1]:
        return cut
    probe, background = levels
    apex = _apex(region)
    to_apex = _distance_to_apex(region, apex)
    for opening in OPENINGS:
        shaved = (region & ~_body(region, opening.radius)).astype(np.uint8)
        n, labels, stats, _ = cv2.connectedComponentsWithStats(shaved, connectivity=4)
        for i in range(1, n):
            if _particle_sized(stats[i], opening.min_area, region.shape):
                piece = labels == i
                if _is_particle(piece, int(stats[i, cv2.CC_STAT_AREA]), opening, to_apex, smoothed,
                                (probe, background)):
                    cut |= piece
    if apex is not None:
        cut |= apex_bumps(region, apex)
    return cut


def substrate_pieces(contour: ContourTemplate, *, bright_object: bool = True, morph_kernel: int = 3,
                     morph_iterations: int = 1) -> np.ndarray:
    """The parts of the substrate that Otsu's region joined to the probe (see the module docstring).

    Parameters
    ----------
    contour : ContourTemplate
        Frame 0's contour template; only one found at Otsu's level (``otsu_classes == 2``) is judged.
    bright_object, morph_kernel, morph_iterations
        As it was identified with (:func:`~semlab.template.identify_contour_template`).

    Returns
    -------
    (h, w) ndarray of bool
        The pixels to cut (all False when there are none).
    """
    none = np.zeros(contour.region.shape, bool)
    if contour.otsu_classes != 2:
        return none
    brightest = brightest_of_three(contour.smoothed, bright_object, morph_kernel, morph_iterations)
    if brightest is None or not (edge_strength(contour.smoothed, brightest.mask)
                                 > edge_strength(contour.smoothed, contour.mask)):
        return none
    near = cv2.dilate(brightest.region.astype(np.uint8), _disc(SUBSTRATE_REACH_PX)).astype(bool)
    beyond = (contour.region & ~near).astype(np.uint8)
    thick = cv2.morphologyEx(beyond, cv2.MORPH_OPEN, _disc(SUBSTRATE_MIN_THICKNESS_PX))
    return cv2.dilate(thick, _disc(SUBSTRATE_MIN_THICKNESS_PX)).astype(bool) & beyond.astype(bool)


def _inner_flank(s: np.ndarray, edge: np.ndarray, outward: float) -> np.ndarray:
    """One flank of the wedge as a line ``(slope, intercept)`` in the distance from the apex.

    A particle sitting on the flank only ever pushes its bins' ``edge`` outward. The least-squares
    line follows it a little; the repeated-medians line (Siegel 1982) ignores it while it covers under
    half of the bins, and is pulled further than least squares when it covers more. Of the two, the
    one lying further inside near the apex (at :data:`BUMP_REACH_PX`) is the flank.
    """
    least_squares = np.polyfit(s, edge, 1)
    repeated_medians = np.array(siegelslopes(edge, s))
    inside = [outward * np.polyval(line, BUMP_REACH_PX) for line in (least_squares, repeated_medians)]
    return (least_squares, repeated_medians)[int(np.argmin(inside))]


def _wedge(region: np.ndarray, apex: tuple[int, int]) -> np.ndarray | None:
    """The wedge the tip's flanks draw to its ``apex`` (bool mask), or None where no thin, filled
    wedge describes the region (see the module docstring)."""
    ys, xs = np.nonzero(_body(region, OPENINGS[0].radius))
    offsets = np.column_stack([xs - apex[0], ys - apex[1]]).astype(np.float64)
    distance = np.hypot(offsets[:, 0], offsets[:, 1])
    near, far = WEDGE_FIT_PX
    fitted = (distance >= near) & (distance <= far)
    if fitted.sum() < MIN_WEDGE_PIXELS:
        return None
    axis = offsets[fitted].mean(axis=0)
    axis /= np.linalg.norm(axis)
    normal = np.array([-axis[1], axis[0]])
    along, across = offsets[fitted] @ axis, offsets[fitted] @ normal
    bins = np.floor(along / WEDGE_BIN_PX).astype(np.int64)
    rows = []  # per bin: mean distance from the apex, the two flanks across the axis
    for b in np.unique(bins):
        in_bin = bins == b
        if in_bin.sum() >= 3:
            rows.append((along[in_bin].mean(), across[in_bin].min(), across[in_bin].max()))
    if len(rows) < MIN_WEDGE_BINS:
        return None
    s, lo, hi = np.array(rows).T
    # Whether the tip is thin is asked of the bins' mean width, by least squares: where the region is no
    # wedge (a wide end's corner), its bins' flanks are no lines for a median to choose among.
    if np.polyval(np.polyfit(s, 0.5 * (hi - lo + 1.0), 1), BUMP_REACH_PX) > MAX_WEDGE_HALF_WIDTH_PX:
        return None
    lo_line, hi_line = _inner_flank(s, lo, outward=-1.0), _inner_flank(s, hi, outward=+1.0)
    half_width = 0.5 * (hi_line - lo_line) + np.array([0.0, 0.5])
    centre_line = 0.5 * (hi_line + lo_line)
    yy, xx = np.mgrid[:region.shape[0], :region.shape[1]]
    s_all = (xx - apex[0]) * axis[0] + (yy - apex[1]) * axis[1]
    off_axis = np.abs((xx - apex[0]) * normal[0] + (yy - apex[1]) * normal[1] - np.polyval(centre_line, s_all))
    width = np.maximum(np.polyval(half_width, s_all), 0.0)
    core = (s_all >= near) & (s_all <= far) & (off_axis <= width - WEDGE_MARGIN_PX)
    if (region & core).sum() < MIN_WEDGE_FILL * core.sum():
        return None
    return (s_all >= -WEDGE_BEHIND_APEX_PX) & (off_axis <= width + WEDGE_MARGIN_PX)


def apex_bumps(region, apex=None) -> np.ndarray:
    """The particles at the apex of a thin tip: what ``region`` holds outside the wedge of the tip's
    flanks near its ``apex`` (see the module docstring).

    Parameters
    ----------
    region : (h, w) array_like of bool
        The contour template's region.
    apex : (x, y), optional
        The region's apex, its pixel farthest from where it enters the ROI (found when not given).

    Returns
    -------
    (h, w) ndarray of bool
        The bumps to cut (all False when the region is no thin wedge, has no apex or no bump).
    """
    region = np.asarray(region, bool)
    cut = np.zeros(region.shape, bool)
    for bump in apex_pieces(region, apex, min_area=MIN_BUMP_PX, min_roundness=MIN_BUMP_ROUNDNESS):
        cut |= bump
    return cut


def apex_pieces(region, apex=None, *, min_area: int, min_roundness: float,
                reach: float = BUMP_REACH_PX) -> list[np.ndarray]:
    """The pieces of ``region`` outside the wedge of a thin tip's flanks within ``reach`` px of its
    ``apex`` (near it: :data:`BUMP_REACH_PX`), of at least ``min_area`` px² (up to :data:`MAX_PIECE_PX`,
    off the ROI's border) that fill at least ``min_roundness`` of their enclosing circle: ROI-sized bool
    masks, none where the region is no thin wedge or has no apex (:func:`apex_bumps` cuts those of a
    particle's size and shape near the apex; :mod:`semlab.tracking.pieces` lets the frames judge smaller
    ones, and those further along the flanks)."""
    region = np.asarray(region, bool)
    apex = _apex(region) if apex is None else apex
    wedge = None if apex is None else _wedge(region, apex)
    if wedge is None:
        return []
    yy, xx = np.mgrid[:region.shape[0], :region.shape[1]]
    outside = region & ~wedge & (np.hypot(xx - apex[0], yy - apex[1]) <= reach)
    n, labels, stats, _ = cv2.connectedComponentsWithStats(outside.astype(np.uint8), connectivity=4)
    pieces = []
    for i in range(1, n):
        bump = labels == i
        if (_particle_sized(stats[i], min_area, region.shape)
                and _round(bump, int(stats[i, cv2.CC_STAT_AREA]), min_roundness)):
            pieces.append(bump)
    return pieces


def _particle_sized(stats, min_area: int, shape) -> bool:
    """Whether a piece (its ``stats`` row of ``connectedComponentsWithStats``) has a particle's area,
    ``min_area`` to :data:`MAX_PIECE_PX`, and stays off the ROI's border."""
    x, y, bw, bh, area = (int(v) for v in stats)
    h, w = shape
    return min_area <= area <= MAX_PIECE_PX and x > 0 and y > 0 and x + bw < w and y + bh < h


def _round(piece, area: int, min_roundness: float) -> bool:
    """Whether ``piece`` (``area`` px) fills at least ``min_roundness`` of its enclosing circle."""
    points = np.column_stack(np.nonzero(piece)[::-1]).astype(np.float32)
    _, radius = cv2.minEnclosingCircle(points)
    return area >= min_roundness * np.pi * max(radius, 0.5) ** 2


def _is_particle(piece, area: int, opening: Opening, to_apex, smoothed, levels) -> bool:
    """Whether a particle-sized shaved ``piece`` of ``area`` px is an attached particle: more than
    the opening's clearance from the apex (``to_apex``: every pixel's distance to it; None: no
    apex), round enough, and dimmer than the probe (``levels``: the probe's and the background's), or
    as bright as the probe and disc-like."""
    if to_apex is not None and float(to_apex[piece].min()) <= opening.apex_clearance:
        return False
    if not _round(piece, area, opening.min_roundness):
        return False
    probe, background = levels
    level = (float(np.median(smoothed[piece])) - background) / (probe - background)
    if level < MAX_RELATIVE_LEVEL:
        return True
    return level < MAX_BRIGHT_LEVEL and _round(piece, area, MIN_BRIGHT_ROUNDNESS)


def without_attached(contour: ContourTemplate, patch, *, choose: str = "central", outline_resolved: bool = True,
                     **segmentation) -> tuple[ContourTemplate, np.ndarray | None]:
    """``(contour, pieces)``: the contour template with the substrate Otsu's level joined to it
    (:func:`substrate_pieces`, given the ``segmentation``'s ``bright_object``, ``morph_kernel`` and
    ``morph_iterations``) and, where its outline is resolved above the noise (``outline_resolved``:
    see :data:`MAX_OUTLINE_NOISE`), its attached particles cut off the region (the external contour of
    what remains that ``choose`` picks, as in :func:`~semlab.template.identify_contour_template`), and
    the pixels cut; ``(contour, None)`` unchanged when there are none."""
    particles = attached_pieces(contour.region, patch) if outline_resolved else np.zeros(contour.region.shape, bool)
    beside = cv2.dilate(particles.astype(np.uint8), _disc(BAND_CLEARANCE_PX)).astype(bool)
    pieces = particles | (substrate_pieces(contour, **segmentation) & ~beside)
    if not pieces.any():
        return contour, None
    cut = cut_off(contour, pieces, choose=choose)
    return (contour, None) if cut is None else (cut, pieces)


def cut_off(contour: ContourTemplate, pieces, *, choose: str = "central") -> ContourTemplate | None:
    """``contour`` with ``pieces`` (ROI-sized bool mask) and the 1-px neck that joined them cut off its
    region: the external contour of what remains that ``choose`` picks; None when nothing usable remains."""
    # One px more than the piece: the neck that joined it goes too.
    neck = cv2.dilate(np.asarray(pieces, np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
    remaining = np.where(contour.region & ~neck, 255, 0).astype(np.uint8)
    try:  # what remains, chosen as frame 0's contour was (no smoothing, no morphology)
        found = identify_contour_template(remaining, sigma=0, threshold=127, morph_kernel=0, choose=choose)
    except ValueError:
        return None
    return dataclasses.replace(contour, points=found.points, mask=found.mask, region=found.region,
                               hierarchy=found.hierarchy, contours=found.contours, area=found.area)


def clear_band(band, pieces, region=None) -> np.ndarray:
    """``band`` without the pixels within :data:`BAND_CLEARANCE_PX` of ``pieces`` (None: unchanged).

    With the object's ``region``, the band is left whole when clearing it would keep fewer than
    :data:`MIN_CLEARED_BACKGROUND_PX` pixels on its background side: a probe lying along the substrate
    it was cut from would have no edge left to register.
    """
    if pieces is None:
        return band
    near = cv2.dilate(np.asarray(pieces, np.uint8), _disc(BAND_CLEARANCE_PX)).astype(bool)
    cleared = band & ~near
    if region is not None:
        background = ~np.asarray(region, bool)
        if (cleared & background).sum() < MIN_CLEARED_BACKGROUND_PX:
            return band
    return cleared
