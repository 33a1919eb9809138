"""Cramér–Rao bound of the probe's 2-D translation from one simulated frame.

For a frame ``I = m(theta) + n`` with Gaussian noise of covariance ``C``, the Fisher
information of the parameters ``theta`` is ``F = J^T C^-1 J`` with ``J = dm/dtheta``
(for Poisson noise the same expression with ``C = diag(m)`` is exact, because the
variance's own dependence on ``theta`` adds no information to a Poisson count).
Here ``theta = (t_x, t_y)`` is the probe's translation -- the paper's motion vector
``mu = (u, v)`` of Eq. (3) -- optionally with the unknown frame gain and offset as
nuisance parameters; ``J`` is the exact analytic re-render at ``+-h`` shifts (central
difference), and ``C`` is the noise model of :class:`semlab.sim.SEMNoise`:

* white part per pixel: shot noise ``g_e (m - brightness)`` (``g_e`` gray levels per
  electron) + read noise + output quantisation (1/12 LSB^2, treated as white noise
  before the line filter: it is < 2 % of the read-noise variance);
* the line filter (AR(1) along x, coefficient ``rho``): whitened exactly along each ROI
  row with ``(e_n - rho e_{n-1}) / sqrt(1 - rho^2)``; the first pixel of the row uses
  the exact stationary variance from the pixels to its left;
* per-line offsets and per-line jitter: each row gets the rank-2 covariance
  ``s_o^2 1 1^T + s_j^2 g g^T`` (``g = dm/dx``, the linearised effect of a row
  shift), handled with the Woodbury identity.

The bound is for *one* frame with a perfectly known noise-free template; a tracker that
compares two noisy frames has at best ``sqrt(2)`` times this standard deviation on a
displacement, and an estimate over frames with a fixed noisy template has this
standard deviation around a fixed template bias.
"""

from __future__ import annotations

import numpy as np

__all__ = ["check_roi", "translation_crb", "translation_fisher"]


def check_roi(roi, width: int, height: int):
    """Validate an ROI ``(x, y, w, h)`` that must lie inside a ``width x height`` frame."""
    try:
        x, y, w, h = (int(v) for v in roi)
        if any(int(v) != v for v in roi):
            raise ValueError
    except (TypeError, ValueError):
        raise ValueError(f"roi must be four integers (x, y, w, h), got {roi!r}") from None
    if w < 2 or h < 2:
        raise ValueError(f"roi {roi!r}: width and height must be >= 2 px")
    if x < 0 or y < 0 or x + w > width or y + h > height:
        raise ValueError(f"roi {roi!r} is not inside the {width}x{height} frame")
    return x, y, w, h


def translation_fisher(sem, tips, roi, probe=0, *, t=None, h=1e-2, nuisance="auto"):
    """Fisher information matrix of ``(t_x, t_y[, gain, offset])`` for one frame's ROI.

    Parameters are those of :func:`translation_crb`.

    Returns
    -------
    (p, p) ndarray
        Fisher matrix; the first two parameters are the translation in px.
    """
    tips = sem._check_tips(tips)
    if isinstance(probe, bool) or not isinstance(probe, (int, np.integer)) or not 0 <= probe < len(tips):
        raise ValueError(f"probe {probe!r} is not one of the {len(tips)} tips")
    x0, y0, w, hh = check_roi(roi, sem.width, sem.height)
    tx, ty = tips[probe]
    if not (0 <= tx <= sem.width - 1 and 0 <= ty <= sem.height - 1):
        raise ValueError(f"probe {probe}'s tip ({tx:.1f}, {ty:.1f}) px is off the "
                         f"{sem.width}x{sem.height} frame")
    if not h > 0:
        raise ValueError("h must be > 0")
    nz = sem.noise
    t = sem.time if t is None else float(t)

    def render(dx, dy):
        tt = tips.copy()
        tt[probe] += (dx, dy)
        return sem.render_clean(tt, t=t)

    m = render(0.0, 0.0)
    jx = (render(h, 0.0) - render(-h, 0.0)) / (2 * h)
    jy = (render(0.0, h) - render(0.0, -h)) / (2 * h)

    # white variance per pixel (whole frame, for the stationary start of each row)
    white = np.full(m.shape, nz.read_noise_gray**2 + sem.quantisation_variance)
    if nz.shot_noise:
        g_e = sem.gain_gray_per_electron
        white = white + g_e * np.maximum(m - nz.brightness, 0.0)
    if not np.all(white > 0):
        raise ValueError("the noise model has zero variance somewhere: the bound is infinite")

    cols = [jx, jy]
    if nuisance == "auto":
        nuisance = (nz.gain_fluctuation > 0 or nz.offset_fluctuation_gray > 0
                    or nz.charging_amplitude > 0)
    if nuisance:
        cols += [m - nz.brightness, np.ones_like(m)]
    sl = (slice(y0, y0 + hh), slice(x0, x0 + w))
    J = np.stack([c[sl] for c in cols], axis=-1)  # (hh, w, p)
    D = white[sl]
    rho = nz.line_correlation

    rank = []
    if nz.line_offset_gray > 0:
        rank.append((np.ones((hh, w)), nz.line_offset_gray**2))
    if nz.line_jitter_px > 0:
        gx = np.gradient(m, axis=1)[sl]
        rank.append((gx, nz.line_jitter_px**2))

    if rho > 0:
        # stationary variance of the first ROI pixel of each row: sum_k h_k^2 D[x0 - k]
        k = np.arange(0, x0 + 1)
        hk2 = (1 - rho**2) * rho ** (2 * k)
        d0 = white[y0:y0 + hh, x0 - k] @ hk2
        d0 += white[y0:y0 + hh, 0] * rho ** (2 * (x0 + 1))  # reflected tail beyond column 0

        def whiten(a):  # a: (hh, w, ...) -> W a
            out = np.empty_like(a)
            out[:, 0] = a[:, 0] / np.sqrt(d0).reshape((-1,) + (1,) * (a.ndim - 2))
            s = np.sqrt((1 - rho**2) * D[:, 1:]).reshape(D[:, 1:].shape + (1,) * (a.ndim - 2))
            out[:, 1:] = (a[:, 1:] - rho * a[:, :-1]) / s
            return out
    else:
        def whiten(a):
            return a / np.sqrt(D).reshape(D.shape + (1,) * (a.ndim - 2))

    Jw = whiten(J)
    F = np.einsum("rnp,rnq->pq", Jw, Jw)
    if rank:
        U = np.stack([u for u, _ in rank], axis=-1)  # (hh, w, r)
        S_inv = np.diag([1.0 / s for _, s in rank])
        Uw = whiten(U)
        UtU = np.einsum("rna,rnb->rab", Uw, Uw)  # per row
        UtJ = np.einsum("rna,rnp->rap", Uw, Jw)
        M = np.linalg.inv(S_inv[None] + UtU)
        F = F - np.einsum("rap,rab,rbq->pq", UtJ, M, UtJ)
    return F


def translation_crb(sem, tips, roi, probe=0, *, t=None, h=1e-2, nuisance="auto"):
    """Cramér–Rao bound of the probe's translation estimated from ONE frame's ROI.

    Parameters
    ----------
    sem : SimulatedSEM
        Provides the exact noise-free render and the noise model.
    tips : (n, 2) array_like
        True tip positions (px) of all probes in the frame.
    roi : (x, y, w, h)
        Region used by the estimator (must lie inside the frame).
    probe : int
        Which probe is translated.
    t : float or None
        Time for the moving clutter (``None``: the SEM's next frame).
    h : float
        Shift in px of the central difference (the render is analytic, so ``h`` only
        trades round-off against the O(h^2) truncation).
    nuisance : bool or "auto"
        Also estimate the frame's gain and offset (the paper's gray-level fluctuation);
        "auto" = when the noise model has gain/offset fluctuation or charging.

    Returns
    -------
    (float, float)
        ``(sigma_x, sigma_y)`` in px: the smallest standard deviation an unbiased
        estimator of the translation can reach from one frame.

    Raises
    ------
    ValueError
        ROI off the frame, probe tip off the frame, unknown probe, or a noise-free model
        (infinite information).

    Notes
    -----
    See the module docstring for exactly what the bound assumes.
    """
    F = translation_fisher(sem, tips, roi, probe, t=t, h=h, nuisance=nuisance)
    try:
        cov = np.linalg.inv(F)
    except np.linalg.LinAlgError:
        return float("inf"), float("inf")
    var = np.diag(cov)[:2]
    if np.any(var <= 0) or not np.all(np.isfinite(var)):
        return float("inf"), float("inf")
    return float(np.sqrt(var[0])), float(np.sqrt(var[1]))
