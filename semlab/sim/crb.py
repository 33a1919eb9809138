"""Cramér–Rao bound of the probe's 2-D translation from one frame.

:func:`fisher_information` takes any clean render ``m(t)`` and per-pixel noise model (the
semi-real composites of :mod:`semlab.sim.composite` use it with their own);
:func:`translation_fisher` / :func:`translation_crb` apply it to :class:`SimulatedSEM`.

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

__all__ = ["check_roi", "crb_from_fisher", "fisher_information", "sem_has_photometric_nuisance",
           "translation_crb", "translation_fisher"]


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


def fisher_information(render, white_variance, roi, *, nuisance=False, black_level=0.0,
                       line_correlation=0.0, line_offset_gray=0.0, line_jitter_px=0.0, h=1e-2):
    """Fisher information of a translation from one frame, for any clean render and noise model.

    The frame is ``I = m(t) + n``: ``m`` the noise-free image with the object translated by
    ``t = (t_x, t_y)`` px, ``n`` Gaussian (or Poisson, see the module docstring) noise whose
    covariance is a per-pixel white variance, optionally filtered along the scan line by an
    AR(1) process and with per-line offsets and jitter (the rank-2 row terms of the module
    docstring). ``F = J^T C^-1 J`` over the pixels of ``roi``.

    Parameters
    ----------
    render : callable ``(dx, dy) -> (H, W) ndarray``
        The clean image with the object translated by ``(dx, dy)`` px from where the bound is
        wanted; ``render(0, 0)`` is ``m``. ``J`` is its central difference at ``+-h``.
    white_variance : (H, W) ndarray or callable ``m -> (H, W) ndarray``
        Variance of the white part of the noise per pixel (before the line filter), e.g. shot
        noise ``g_e (m - black)`` + read noise + quantisation.
    roi : (x, y, w, h)
        Pixels that the estimator uses (inside the frame).
    nuisance : bool
        Also estimate the frame's gain and offset (columns ``m - black_level`` and 1).
    black_level : float
        Gray level of zero signal (the gain multiplies ``m - black_level``).
    line_correlation, line_offset_gray, line_jitter_px : float
        AR(1) coefficient along x, per-line offset std (gray levels) and per-line horizontal
        jitter std (px).
    h : float
        Step (px) of the central difference.

    Returns
    -------
    (p, p) ndarray
        Fisher matrix of ``(t_x, t_y[, gain, offset])``.
    """
    if not h > 0:
        raise ValueError("h must be > 0")
    m = np.asarray(render(0.0, 0.0), float)
    height, width = m.shape
    x0, y0, w, hh = check_roi(roi, width, height)
    jx = (np.asarray(render(h, 0.0), float) - np.asarray(render(-h, 0.0), float)) / (2 * h)
    jy = (np.asarray(render(0.0, h), float) - np.asarray(render(0.0, -h), float)) / (2 * h)
    white = white_variance(m) if callable(white_variance) else np.asarray(white_variance, float)
    if white.shape != m.shape:
        raise ValueError(f"white_variance has shape {white.shape}, the frame {m.shape}")
    if not np.all(white > 0):
        raise ValueError("the noise model has zero variance somewhere: the bound is infinite")

    cols = [jx, jy]
    if nuisance:
        cols += [m - black_level, np.ones_like(m)]
    sl = (slice(y0, y0 + hh), slice(x0, x0 + w))
    J = np.stack([c[sl] for c in cols], axis=-1)  # (hh, w, p)
    D = white[sl]
    rho = float(line_correlation)

    rank = []
    if line_offset_gray > 0:
        rank.append((np.ones((hh, w)), line_offset_gray**2))
    if line_jitter_px > 0:
        gx = np.gradient(m, axis=1)[sl]
        rank.append((gx, line_jitter_px**2))

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


def crb_from_fisher(F) -> tuple[float, float]:
    """``(sigma_x, sigma_y)`` px: the translation's bound from a Fisher matrix (nuisances marginalised).

    ``inf`` when the matrix is singular (the translation cannot be estimated).
    """
    try:
        cov = np.linalg.inv(np.asarray(F, float))
    except np.linalg.LinAlgError:
        return float("inf"), float("inf")
    var = np.diag(cov)[:2]
    if np.any(var <= 0) or not np.all(np.isfinite(var)):
        return float("inf"), float("inf")
    return float(np.sqrt(var[0])), float(np.sqrt(var[1]))


def sem_has_photometric_nuisance(noise) -> bool:
    """Whether a :class:`SEMNoise` changes the frame's gain/offset (fluctuation, jitter or charging)."""
    return (noise.gain_fluctuation > 0 or noise.offset_fluctuation_gray > 0
            or noise.gain_jitter > 0 or noise.offset_jitter_gray > 0 or noise.charging_amplitude > 0)


def translation_fisher(sem, tips, roi, probe=0, *, t=None, h=1e-2, nuisance="auto", charge=1.0):
    """Fisher information matrix of ``(t_x, t_y[, gain, offset])`` for one frame's ROI.

    Parameters are those of :func:`translation_crb`.

    Returns
    -------
    (p, p) ndarray
        Fisher matrix; the first two parameters are the translation in px.
    """
    tips = sem.check_tips(tips)
    if isinstance(probe, bool) or not isinstance(probe, (int, np.integer)) or not 0 <= probe < len(tips):
        raise ValueError(f"probe {probe!r} is not one of the {len(tips)} tips")
    check_roi(roi, sem.width, sem.height)
    tx, ty = tips[probe]
    if not (0 <= tx <= sem.width - 1 and 0 <= ty <= sem.height - 1):
        raise ValueError(f"probe {probe}'s tip ({tx:.1f}, {ty:.1f}) px is off the "
                         f"{sem.width}x{sem.height} frame")
    nz = sem.noise
    t = sem.time if t is None else float(t)

    def render(dx, dy):
        tt = tips.copy()
        tt[probe] += (dx, dy)
        return sem.render_clean(tt, t=t, charge=charge)

    def white(m):
        # white variance per pixel (whole frame, for the stationary start of each row)
        var = np.full(m.shape, nz.read_noise_gray**2 + sem.quantisation_variance)
        if nz.shot_noise:
            var = var + sem.gain_gray_per_electron * np.maximum(m - nz.brightness, 0.0)
        return var

    if nuisance == "auto":
        nuisance = sem_has_photometric_nuisance(nz)
    return fisher_information(render, white, roi, nuisance=bool(nuisance), black_level=nz.brightness,
                              line_correlation=nz.line_correlation,
                              line_offset_gray=nz.line_offset_gray,
                              line_jitter_px=nz.line_jitter_px, h=h)


def translation_crb(sem, tips, roi, probe=0, *, t=None, h=1e-2, nuisance="auto", charge=1.0):
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
        "auto" = when the noise model has gain/offset fluctuation or jitter, or charging.
    charge : float
        Charging factor of the probes in this frame (``sem.noise.charging_factor(t)`` for a
        frame that :meth:`SimulatedSEM.acquire` scanned at ``t``; 1 = uncharged).

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
    return crb_from_fisher(translation_fisher(sem, tips, roi, probe, t=t, h=h, nuisance=nuisance,
                                              charge=charge))
