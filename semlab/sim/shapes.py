"""Probe outlines other than the tapered tungsten needle: blunt tip, gripper jaws, AFM-like tip.

Each outline is a union of convex polygons in the probe's own frame -- ``u`` along the
direction the probe points (the ground-truth point at ``u = 0``, the body at ``u < 0``), ``v``
across it -- rounded by a corner radius (a Minkowski sum with a disc, as the tapered probe of
:mod:`semlab.sim.scene` is a wedge plus its tip circle). The renderer evaluates the exact signed
distance to each polygon at the pixel centres (distance to the nearest edge segment, negative
inside), subtracts the corner radius and folds in the Gaussian beam blur with the same closed form
as the tapered probe, ``Phi(-d / sigma)`` plus the blurred rim. Translating the probe evaluates the
same function at shifted coordinates: the ground truth is exact, no pixel grid is interpolated.

The union's distance is the minimum over its polygons: exact outside the union; inside, it is the
distance to the nearest polygon's own boundary, so the polygons overlap by more than the rim's
reach wherever they join (no false rim along a seam).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .scene import edge_terms, polygons_bbox, sample_grid

__all__ = ["AFMTip", "BluntProbe", "GripperJaws", "ProbeShape", "polygon_signed_distance",
           "render_shape", "shape_signed_distance"]

#: How far behind the tip (in frame diagonals) the body's polygons reach: beyond any frame edge.
_FAR_DIAGONALS = 3.0


class ProbeShape:
    """An outline made of convex polygons in the probe's frame (see the module docstring).

    Subclasses define :meth:`polygons_nm`; the body reaches ``far_nm`` behind the tip.
    """

    corner_radius_nm: float = 0.0

    def polygons_nm(self, far_nm: float) -> list[np.ndarray]:  # pragma: no cover - abstract
        raise NotImplementedError

    def polygons_px(self, pixel_size_nm: float, far_px: float) -> list[np.ndarray]:
        """The polygons' ``(u, v)`` vertices in px (counter-clockwise or clockwise, convex)."""
        return [np.asarray(p, float) / pixel_size_nm for p in self.polygons_nm(far_px * pixel_size_nm)]

    def corner_radius_px(self, pixel_size_nm: float) -> float:
        return self.corner_radius_nm / pixel_size_nm

    def half_width_nm(self) -> float:  # pragma: no cover - abstract
        """Half the body's width (for the shading across it)."""
        raise NotImplementedError


def _check_positive(obj, *names):
    for name in names:
        v = getattr(obj, name)
        if not (np.isfinite(v) and v > 0):
            raise ValueError(f"{type(obj).__name__}.{name} must be > 0, got {v!r}")


@dataclass(frozen=True)
class BluntProbe(ProbeShape):
    """A flat-ended cylindrical probe (a worn or cut tip) seen from above.

    Parameters
    ----------
    width_nm : float
        Diameter of the shaft; the end face is this wide.
    corner_radius_nm : float
        Rounding of the end face's corners (< half the width).

    The ground-truth point is the centre of the end face.
    """

    width_nm: float = 600.0
    corner_radius_nm: float = 80.0

    def __post_init__(self):
        _check_positive(self, "width_nm")
        if not 0 <= self.corner_radius_nm < 0.5 * self.width_nm:
            raise ValueError("BluntProbe.corner_radius_nm must lie in [0, width_nm / 2)")

    def half_width_nm(self) -> float:
        return 0.5 * self.width_nm

    def polygons_nm(self, far_nm):
        r = self.corner_radius_nm
        h = 0.5 * self.width_nm - r
        return [np.array([(-r, -h), (-r, h), (-far_nm, h), (-far_nm, -h)])]


@dataclass(frozen=True)
class GripperJaws(ProbeShape):
    """Microgripper (tweezer) jaws: two tapered fingers with a gap, on a wider body.

    Parameters
    ----------
    jaw_length_nm : float
        Length of the fingers from the body to their ends.
    jaw_width_nm : float
        Width of each finger where it leaves the body.
    jaw_tip_width_nm : float
        Width of each finger at its end (< ``jaw_width_nm``: tapered fingers).
    gap_nm : float
        Gap between the fingers' inner edges.
    corner_radius_nm : float
        Rounding of all corners.

    The ground-truth point is the midpoint between the ends of the fingers (in the gap, on
    the axis): what a servo closing the jaws on an object aims at.
    """

    jaw_length_nm: float = 2500.0
    jaw_width_nm: float = 700.0
    jaw_tip_width_nm: float = 400.0
    gap_nm: float = 600.0
    corner_radius_nm: float = 60.0

    def __post_init__(self):
        _check_positive(self, "jaw_length_nm", "jaw_width_nm", "jaw_tip_width_nm", "gap_nm")
        if self.jaw_tip_width_nm > self.jaw_width_nm:
            raise ValueError("GripperJaws.jaw_tip_width_nm must be <= jaw_width_nm")
        if not 0 <= self.corner_radius_nm < 0.5 * self.jaw_tip_width_nm:
            raise ValueError("GripperJaws.corner_radius_nm must lie in [0, jaw_tip_width_nm / 2)")

    def half_width_nm(self) -> float:
        return 0.5 * self.gap_nm + self.jaw_width_nm

    def polygons_nm(self, far_nm):
        r = self.corner_radius_nm
        g = 0.5 * self.gap_nm + r  # inner edge of a finger, before rounding
        L = self.jaw_length_nm
        outer0 = 0.5 * self.gap_nm + self.jaw_width_nm - r
        outer1 = 0.5 * self.gap_nm + self.jaw_tip_width_nm - r
        # the fingers reach into the body by one finger width (an overlap beyond the rim's reach)
        into = L + self.jaw_width_nm
        upper = np.array([(-r, g), (-r, outer1), (-into, outer0), (-into, g)])
        lower = upper * np.array([1.0, -1.0])
        half_body = outer0 + 0.5 * self.jaw_width_nm
        body = np.array([(-L - r, -half_body), (-L - r, half_body), (-far_nm, half_body),
                         (-far_nm, -half_body)])
        return [upper, lower[::-1], body]


@dataclass(frozen=True)
class AFMTip(ProbeShape):
    """An AFM-like probe seen from above: a cantilever beam ending in a pointed (triangular) end.

    Parameters
    ----------
    cantilever_width_nm : float
        Width of the beam.
    point_length_nm : float
        Length of the triangular end, from where the beam narrows to its apex.
    corner_radius_nm : float
        Rounding of the apex and corners.

    The ground-truth point is the apex.
    """

    cantilever_width_nm: float = 2000.0
    point_length_nm: float = 1500.0
    corner_radius_nm: float = 50.0

    def __post_init__(self):
        _check_positive(self, "cantilever_width_nm", "point_length_nm")
        if not 0 <= self.corner_radius_nm < 0.25 * self.cantilever_width_nm:
            raise ValueError("AFMTip.corner_radius_nm must lie in [0, cantilever_width_nm / 4)")

    def half_width_nm(self) -> float:
        return 0.5 * self.cantilever_width_nm

    def polygons_nm(self, far_nm):
        r = self.corner_radius_nm
        h = 0.5 * self.cantilever_width_nm - r
        L = self.point_length_nm
        # the rounding (a disc of radius r around every point) reaches r ahead of the apex vertex
        apex = -r
        return [np.array([(apex, 0.0), (apex - L, h), (-far_nm, h), (-far_nm, -h), (apex - L, -h)])]


def polygon_signed_distance(X, Y, vertices) -> np.ndarray:
    """Exact signed distance (px) from points to a convex polygon, negative inside.

    Parameters
    ----------
    X, Y : ndarray
        Coordinates (broadcastable).
    vertices : (n, 2) array_like
        The polygon's corners in order (either orientation), convex.

    Returns
    -------
    ndarray
        Distance to the nearest edge segment, with the sign of the inside test.
    """
    P = np.asarray(vertices, float)
    area2 = float(np.sum(P[:, 0] * np.roll(P[:, 1], -1) - np.roll(P[:, 0], -1) * P[:, 1]))
    if area2 < 0:  # make it counter-clockwise in (x, y): inside is left of every edge
        P = P[::-1]
    dist2 = None
    inside = None
    for (ax, ay), (bx, by) in zip(P, np.roll(P, -1, axis=0)):
        ex, ey = bx - ax, by - ay
        px, py = X - ax, Y - ay
        t = np.clip((px * ex + py * ey) / (ex * ex + ey * ey), 0.0, 1.0)
        qx, qy = px - t * ex, py - t * ey
        d2 = qx * qx + qy * qy
        left = (ex * py - ey * px) >= 0
        dist2 = d2 if dist2 is None else np.minimum(dist2, d2)
        inside = left if inside is None else inside & left
    d = np.sqrt(dist2)
    return np.where(inside, -d, d)


def _to_image(poly_uv, tip_xy, angle_rad):
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    u, v = poly_uv[:, 0], poly_uv[:, 1]
    return np.column_stack([tip_xy[0] + u * c - v * s, tip_xy[1] + u * s + v * c])


def shape_signed_distance(X, Y, shape: ProbeShape, tip_xy, angle_rad, pixel_size_nm, far_px):
    """Signed distance (px) to ``shape`` placed with its ground-truth point at ``tip_xy``.

    Returns ``(d, across)``: the distance (negative inside) and the position across the body,
    about -1 to 1 from one side to the other (for the shading).
    """
    polys = [_to_image(p, tip_xy, angle_rad) for p in shape.polygons_px(pixel_size_nm, far_px)]
    d = None
    for P in polys:
        dp = polygon_signed_distance(X, Y, P)
        d = dp if d is None else np.minimum(d, dp)
    d = d - shape.corner_radius_px(pixel_size_nm)
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    across = ((Y - tip_xy[1]) * c - (X - tip_xy[0]) * s) / (shape.half_width_nm() / pixel_size_nm)
    return d, across


def render_shape(buf, shape: ProbeShape, tip_xy, angle_rad, pixel_size_nm, sigma_px, level,
                 rim_amp, rim_w_px, row_shift=None, shading=0.0):
    """Composite a probe of outline ``shape`` onto a yield image in place (its bounding box only).

    Parameters are those of :func:`semlab.sim.scene.render_probe`, with ``shape`` and the pixel
    size (nm/px) in place of the tapered probe's radius and half-angle.

    Returns
    -------
    tuple or None
        The bounding box ``(x0, x1, y0, y1)`` rendered, or ``None`` when the probe is off the frame.
    """
    h, w = buf.shape
    tx, ty = float(tip_xy[0]), float(tip_xy[1])
    far_px = _FAR_DIAGONALS * math.hypot(w, h) + math.hypot(tx, ty)
    margin = 5.0 * sigma_px + 3.0 * rim_w_px + 2.0 + shape.corner_radius_px(pixel_size_nm)
    if row_shift is not None and len(row_shift):
        margin += float(np.max(np.abs(row_shift)))
    polygons = [[tuple(q) for q in _to_image(P, (tx, ty), angle_rad)]
                for P in shape.polygons_px(pixel_size_nm, far_px)]
    box = polygons_bbox(polygons, margin, w, h)
    if box is None:
        return None
    x0, x1, y0, y1 = box
    X, Y = sample_grid(x0, x1, y0, y1, row_shift, np.float64)
    d, across = shape_signed_distance(X, Y, shape, (tx, ty), angle_rad, pixel_size_nm, far_px)
    d = d.astype(buf.dtype)
    if shading > 0:
        level = level * (1.0 + shading * np.clip(across, -1.0, 1.0).astype(buf.dtype))
    cov, rim = edge_terms(d, sigma_px, 0.0, rim_amp, rim_w_px)
    sub = buf[y0:y1, x0:x1]
    sub += cov * (level - sub)
    if rim is not None:
        sub += rim
    return x0, x1, y0, y1
