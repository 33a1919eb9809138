"""The imaged scene: tungsten probes, substrate and clutter, rendered analytically.

Everything that is ground truth (the probes, the drifting particles, the occluder) is
rendered from a signed distance ``d`` (px, negative inside) evaluated at the pixel
centres in continuous coordinates. The Gaussian beam blur of standard deviation
``sigma`` is folded in analytically: a straight edge blurred by a Gaussian has the
coverage ``Phi(-d / sigma)`` (``Phi`` the normal CDF), so translating a probe by a
sub-pixel amount re-evaluates the same closed form at shifted coordinates -- it is
exact, not an interpolation of a pixel grid. The render is in *yield* units (the
detected secondary-electron signal per primary electron, ~0.2 substrate, ~0.55
tungsten); :mod:`semlab.sim.noise` turns it into gray levels.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np
from scipy.special import erfc

__all__ = [
    "DEFAULT_PROBE_ANGLES_DEG",
    "Clutter",
    "ProbeGeometry",
    "clip_polygon",
    "edge_terms",
    "make_substrate",
    "polygons_bbox",
    "probe_bbox",
    "probe_signed_distance",
    "render_disc",
    "render_probe",
    "sample_grid",
]

#: Direction in which each manipulator's probe points (degrees, image frame: 0 = +x,
#: 90 = +y = down). Probe 0 enters from the left edge, 1 from the right, 2 from the
#: top and 3 from the bottom, as on a four-manipulator rig.
DEFAULT_PROBE_ANGLES_DEG = (10.0, 190.0, 95.0, -80.0)

_SQRT2 = math.sqrt(2.0)


@dataclass(frozen=True)
class ProbeGeometry:
    """Shape and brightness of a tungsten probe (the paper's Picoprobe T-4-5).

    Parameters
    ----------
    tip_diameter_nm : float
        Diameter of the rounded tip; the paper's probe is 200 nm across at the tip.
    half_angle_deg : float
        Half opening angle of the tapered shaft (5-12 degrees for etched tungsten).
    brightness : float
        Secondary-electron yield of the probe body (the substrate is ~0.2).
    rim_amplitude : float
        Extra yield of the SEM edge brightening, a bright rim just inside the edge.
    rim_width_nm : float
        Thickness (Gaussian sigma) of that rim; it sits one width inside the edge.
    shading : float
        Relative brightness difference across the shaft, from its right-hand side
        (facing the Everhart-Thornley detector) to its left-hand side: the body's yield
        is ``brightness * (1 + shading * s)`` with ``s`` in [-1, 1] across the shaft.
    shape : semlab.sim.shapes.ProbeShape or None
        Another outline (blunt tip, gripper jaws, AFM-like tip; :mod:`semlab.sim.shapes`)
        instead of the tapered probe; ``tip_diameter_nm`` and ``half_angle_deg`` are then
        unused. ``None``: the tapered probe with a rounded tip.
    """

    tip_diameter_nm: float = 200.0
    half_angle_deg: float = 8.0
    brightness: float = 0.55
    rim_amplitude: float = 0.3
    rim_width_nm: float = 50.0
    shading: float = 0.15
    shape: object = None

    def __post_init__(self):
        if not self.tip_diameter_nm > 0:
            raise ValueError(f"tip_diameter_nm must be > 0, got {self.tip_diameter_nm}")
        if not 0.5 <= self.half_angle_deg <= 45:
            raise ValueError(f"half_angle_deg must lie in [0.5, 45], got {self.half_angle_deg}")
        if self.brightness < 0 or self.rim_amplitude < 0 or self.rim_width_nm <= 0:
            raise ValueError("brightness and rim_amplitude must be >= 0 and rim_width_nm > 0")
        if not 0 <= self.shading < 1:
            raise ValueError(f"shading must lie in [0, 1), got {self.shading}")


@dataclass(frozen=True)
class Clutter:
    """Objects other than the probes: the paper's "clutter" (background and foreground).

    Parameters
    ----------
    n_static : int
        Static particles on the substrate (part of the static background).
    n_drifting : int
        Particles that drift across the field (e.g. charged debris), rendered per frame.
    drift_speed_px_s : float
        Speed of the drifting particles in px/s.
    occluder : bool
        A foreground object (out of focus, above the probe) that passes over part of
        the probe.
    occluder_radius_px : float
        Its radius.
    occluder_path : ((x0, y0), (x1, y1)) or None
        Segment it travels back and forth along, in px. ``None``: a vertical pass at
        ``x = 0.2 * width`` (over the shaft of probe 0 in the default rig).
    occluder_period_s : float
        Time for one back-and-forth pass.
    occluder_blur_px : float
        Defocus blur of the foreground object.
    texture : float
        Amplitude of the substrate texture (yield units); 0 = flat substrate.
    """

    n_static: int = 30
    n_drifting: int = 0
    drift_speed_px_s: float = 8.0
    occluder: bool = False
    occluder_radius_px: float = 22.0
    occluder_path: tuple | None = None
    occluder_period_s: float = 8.0
    occluder_blur_px: float = 3.0
    texture: float = 0.03

    def __post_init__(self):
        for name in ("n_static", "n_drifting"):
            v = getattr(self, name)
            if int(v) != v or v < 0:
                raise ValueError(f"Clutter.{name} must be a non-negative integer, got {v!r}")
        for name in ("drift_speed_px_s", "occluder_radius_px", "occluder_period_s",
                     "occluder_blur_px", "texture"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v >= 0):
                raise ValueError(f"Clutter.{name} must be finite and >= 0, got {v!r}")
        if self.occluder and not self.occluder_period_s > 0:
            raise ValueError("Clutter.occluder_period_s must be > 0")

    @classmethod
    def none(cls) -> Clutter:
        """No clutter at all: flat substrate, no particles, no occluder."""
        return cls(n_static=0, n_drifting=0, occluder=False, texture=0.0)


def probe_signed_distance(X, Y, tip_xy, angle_rad, tip_radius_px, half_angle_rad,
                          return_across=False):
    """Signed distance (px) to a tapered probe with a rounded tip.

    The shape is a wedge of half-angle ``half_angle_rad`` offset (Minkowski sum) by a
    disc of radius ``tip_radius_px``: a cone whose sides are tangent to the tip circle.
    The distance is exact everywhere (convex shape).

    Parameters
    ----------
    X, Y : ndarray
        Coordinates in px (broadcastable).
    tip_xy : (float, float)
        Extreme point of the tip (the ground-truth tip position).
    angle_rad : float
        Direction in which the probe points (from shaft to tip).
    tip_radius_px, half_angle_rad : float
        Tip radius and shaft half-angle.
    return_across : bool
        Also return the position across the shaft, about -1 on its left edge and 1 on
        its right edge (looking from the shaft to the tip; smooth, not clipped).

    Returns
    -------
    ndarray, or (ndarray, ndarray)
        Signed distance, negative inside the probe (and the across-shaft position).
    """
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    dx = X - tip_xy[0]
    dy = Y - tip_xy[1]
    # u: distance behind the wedge apex (the tip circle centre) along the shaft
    u = -(dx * c + dy * s) - tip_radius_px
    v_signed = dy * c - dx * s
    v = np.abs(v_signed)
    ca, sa = math.cos(half_angle_rad), math.sin(half_angle_rad)
    side = v * ca - u * sa
    apex = np.sqrt(u * u + v * v)
    d = np.where(u * ca + v * sa >= 0, side, apex) - tip_radius_px
    if not return_across:
        return d
    # a smooth stand-in for the local half-width (max(u, 0) would put a crease on the
    # probe); the ratio is left unclipped so it stays smooth across the edge, where the
    # blurred coverage takes over
    u_pos = 0.5 * (u + np.sqrt(u * u + tip_radius_px * tip_radius_px))
    half_width = tip_radius_px / ca + u_pos * (sa / ca)
    return d, v_signed / half_width


def clip_polygon(points, xmin, xmax, ymin, ymax) -> list[tuple[float, float]]:
    """Sutherland-Hodgman clipping of a convex polygon to an axis-aligned rectangle.

    Parameters
    ----------
    points : sequence of (x, y)
        The convex polygon's vertices, in order (either orientation).
    xmin, xmax, ymin, ymax : float
        The rectangle (closed: a vertex on its boundary is inside).

    Returns
    -------
    list of (x, y)
        The clipped polygon's vertices, in the input's orientation; ``[]`` when the polygon and the
        rectangle do not overlap.
    """
    def clip(pts, inside, cross):
        out = []
        for i, p in enumerate(pts):
            q = pts[i - 1]
            if inside(p):
                if not inside(q):
                    out.append(cross(q, p))
                out.append(p)
            elif inside(q):
                out.append(cross(q, p))
        return out

    def at_x(x0):
        return lambda q, p: (x0, q[1] + (p[1] - q[1]) * (x0 - q[0]) / (p[0] - q[0]))

    def at_y(y0):
        return lambda q, p: (q[0] + (p[0] - q[0]) * (y0 - q[1]) / (p[1] - q[1]), y0)

    pts = list(points)
    for inside, cross in ((lambda p: p[0] >= xmin, at_x(xmin)), (lambda p: p[0] <= xmax, at_x(xmax)),
                          (lambda p: p[1] >= ymin, at_y(ymin)), (lambda p: p[1] <= ymax, at_y(ymax))):
        pts = clip(pts, inside, cross)
        if not pts:
            return []
    return pts


def probe_bbox(tip_xy, angle_rad, tip_radius_px, half_angle_rad, margin_px, width, height):
    """Bounding box ``(x0, x1, y0, y1)`` (half-open, clipped) of a probe inside the frame.

    The shaft's cone, widened by ``margin_px`` (blur, rim, jitter) and the tip radius, is
    clipped to the frame; returns ``None`` when the probe does not reach into the frame.
    """
    tx, ty = float(tip_xy[0]), float(tip_xy[1])
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    m = margin_px + tip_radius_px
    # long enough to leave the frame from anywhere
    far = math.hypot(width, height) + math.hypot(max(abs(tx), abs(tx - width)),
                                                   max(abs(ty), abs(ty - height)))
    # the probe is the sharp cone with apex at the tip circle's centre, dilated by the
    # tip radius; dilate by the margin too, i.e. clip the sharp cone to the frame grown
    # by R and grow the clipped polygon's bbox by R
    R = m
    cx, cy = tx - tip_radius_px * c, ty - tip_radius_px * s
    half = far * math.tan(half_angle_rad)
    bx, by = cx - far * c, cy - far * s
    tri = [(cx, cy), (bx - half * s, by + half * c), (bx + half * s, by - half * c)]
    return polygons_bbox([tri], R, width, height)


def polygons_bbox(polygons, margin_px, width, height):
    """Bounding box ``(x0, x1, y0, y1)`` (half-open, clipped) of convex polygons dilated by a margin.

    Each polygon is clipped (:func:`clip_polygon`) to the frame grown by ``margin_px``, so a body
    reaching far beyond the frame counts only where it can touch it; the clipped polygons' box grows by
    ``margin_px`` and is clipped to the ``width`` x ``height`` frame. ``None`` when nothing reaches in.
    """
    m = margin_px
    pts = [q for P in polygons for q in clip_polygon(P, -m, width - 1 + m, -m, height - 1 + m)]
    if not pts:
        return None
    xs, ys = zip(*pts)
    x0 = max(math.floor(min(xs) - m), 0)
    x1 = min(math.ceil(max(xs) + m) + 1, width)
    y0 = max(math.floor(min(ys) - m), 0)
    y1 = min(math.ceil(max(ys) + m) + 1, height)
    if x0 >= x1 or y0 >= y1:
        return None
    return x0, x1, y0, y1


def edge_terms(d, sigma, level, rim_amp, rim_w):
    """Blurred coverage and rim for a signed distance map (see module docstring); shared by every
    rendered outline (the probe here, other shapes in :mod:`semlab.sim.shapes`)."""
    if sigma > 0:
        # erfc is costly: evaluate it only in the band where it differs from 0/1 by
        # more than ~1e-12 (|d| < 7 sigma); the band boundary is a fixed distance from
        # the edge, so translations stay exact
        z = d * np.float32(1.0 / (_SQRT2 * sigma))
        cov = (z <= 0).astype(d.dtype)
        band = np.abs(z) < 5.0
        cov[band] = 0.5 * erfc(z[band])
    else:
        cov = (d <= 0).astype(d.dtype)
    if rim_amp > 0:
        # a Gaussian rim of width w blurred by a Gaussian beam of width sigma
        s2 = rim_w * rim_w + sigma * sigma
        amp = rim_amp * rim_w / math.sqrt(s2)
        rim = amp * np.exp((d + rim_w) ** 2 * np.float32(-0.5 / s2))
    else:
        rim = None
    return cov, rim


def sample_grid(x0, x1, y0, y1, row_shift, dtype):
    """The pixel centres ``(xs, ys)`` of the box ``[x0, x1) × [y0, y1)`` (broadcastable), each
    scan line shifted by ``row_shift[y]`` (the scan's line jitter) when given."""
    xs = np.arange(x0, x1, dtype=dtype)[None, :]
    ys = np.arange(y0, y1, dtype=dtype)[:, None]
    if row_shift is not None:
        # per-line scan jitter: row y is sampled at x + shift[y]
        xs = xs + row_shift[y0:y1, None].astype(dtype)
    return xs, ys


def render_probe(buf, tip_xy, angle_rad, tip_radius_px, half_angle_rad, sigma_px,
                 level, rim_amp, rim_w_px, row_shift=None, shading=0.0):
    """Composite one probe onto a yield image in place (only inside its bounding box).

    Parameters
    ----------
    buf : (H, W) ndarray of float
        Yield image, modified in place.
    tip_xy : (float, float)
        Tip position in px.
    angle_rad, tip_radius_px, half_angle_rad : float
        Geometry (see :func:`probe_signed_distance`).
    sigma_px : float
        Gaussian beam blur.
    level, rim_amp, rim_w_px : float
        Body yield, edge brightening amplitude and width.
    row_shift : (H,) ndarray or None
        Per-line horizontal scan jitter in px.
    shading : float
        Relative brightness gradient across the shaft (see :class:`ProbeGeometry`).

    Returns
    -------
    tuple or None
        The bounding box that was rendered, or ``None`` if the probe is off the frame.
    """
    h, w = buf.shape
    margin = 5.0 * sigma_px + 3.0 * rim_w_px + 2.0
    if row_shift is not None:
        margin += float(np.max(np.abs(row_shift))) if len(row_shift) else 0.0
    bbox = probe_bbox(tip_xy, angle_rad, tip_radius_px, half_angle_rad, margin, w, h)
    if bbox is None:
        return None
    x0, x1, y0, y1 = bbox
    X, Y = sample_grid(x0, x1, y0, y1, row_shift, buf.dtype)
    if shading > 0:
        d, across = probe_signed_distance(X, Y, tip_xy, angle_rad, tip_radius_px,
                                          half_angle_rad, return_across=True)
        level = level * (1.0 + shading * across.astype(buf.dtype))
    else:
        d = probe_signed_distance(X, Y, tip_xy, angle_rad, tip_radius_px, half_angle_rad)
    cov, rim = edge_terms(d, sigma_px, 0.0, rim_amp, rim_w_px)
    sub = buf[y0:y1, x0:x1]
    sub += cov * (level - sub)
    if rim is not None:
        sub += rim
    return bbox


def render_disc(buf, centre_xy, radius_px, sigma_px, level, rim_amp=0.0, rim_w_px=1.0,
                row_shift=None):
    """Composite a blurred disc (particle, occluder) onto a yield image in place."""
    h, w = buf.shape
    m = radius_px + 5.0 * sigma_px + 3.0 * rim_w_px + 2.0
    if row_shift is not None and len(row_shift):
        m += float(np.max(np.abs(row_shift)))
    cx, cy = float(centre_xy[0]), float(centre_xy[1])
    x0, x1 = max(math.floor(cx - m), 0), min(math.ceil(cx + m) + 1, w)
    y0, y1 = max(math.floor(cy - m), 0), min(math.ceil(cy + m) + 1, h)
    if x0 >= x1 or y0 >= y1:
        return None
    X, Y = sample_grid(x0, x1, y0, y1, row_shift, buf.dtype)
    d = np.sqrt((X - cx) ** 2 + (Y - cy) ** 2) - radius_px
    cov, rim = edge_terms(d, sigma_px, level, rim_amp, rim_w_px)
    sub = buf[y0:y1, x0:x1]
    sub += cov * (level - sub)
    if rim is not None:
        sub += rim
    return x0, x1, y0, y1


def make_substrate(width, height, clutter: Clutter, sigma_px, rng, base_yield=0.2,
                   particle_rim_w_px=0.8):
    """The static background: a textured substrate with static particles (yield units).

    The texture is band-limited noise at two scales plus a gentle detector shading
    gradient; the particles are blurred discs with SEM edge brightening.

    Parameters
    ----------
    width, height : int
        Frame size.
    clutter : Clutter
        ``texture`` and ``n_static`` are used.
    sigma_px : float
        Beam blur.
    rng : numpy.random.Generator
        Source of randomness (the scene is reproducible from the seed).

    Returns
    -------
    (H, W) ndarray of float32
    """
    img = np.full((height, width), base_yield, np.float32)
    if clutter.texture > 0:
        fine = rng.standard_normal((height, width)).astype(np.float32)
        coarse = rng.standard_normal((height, width)).astype(np.float32)
        fine = cv2.GaussianBlur(fine, (0, 0), 1.2)
        coarse = cv2.GaussianBlur(coarse, (0, 0), 6.0)
        fine *= 1.0 / max(float(fine.std()), 1e-12)
        coarse *= 1.0 / max(float(coarse.std()), 1e-12)
        yy, xx = np.mgrid[0:height, 0:width].astype(np.float32)
        shading = (xx / width - 0.5) * 0.3 + (yy / height - 0.5) * 0.2
        img += clutter.texture * (0.6 * fine + 0.8 * coarse + shading)
    for _ in range(int(clutter.n_static)):
        c = (rng.uniform(0, width), rng.uniform(0, height))
        r = float(rng.uniform(1.0, 5.0))
        render_disc(img, c, r, sigma_px, float(rng.uniform(0.3, 0.5)),
                    rim_amp=0.15, rim_w_px=particle_rim_w_px)
    return img
