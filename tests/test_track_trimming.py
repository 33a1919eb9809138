"""The band's misfit tiles are dropped and the frame refitted (semlab.tracking.trimming, issue 14)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.stats import kstest
from test_track_consistency import _wedge_with_a_static_blob
from test_track_uncertainty import CENTRE, ROI, wedge_frame

from semlab.tracking import Tracker
from semlab.tracking.trimming import (
    MAX_DROPPED_TILES,
    MISFIT_P_VALUE,
    tile_p_values,
    tile_rms,
    tile_sums,
    trim_misfit_tiles,
)
from semlab.tracking.uncertainty import band_tiles


def _tiles(n_side=40):
    ys, xs = np.mgrid[:n_side, :n_side]
    points = np.stack([xs.ravel(), ys.ravel()], axis=1).astype(float)
    return points, band_tiles(points)


def test_tile_p_values_are_uniform_under_the_noise():
    # Under the noise model a tile's weighted squared residuals are chi-squared with as many degrees of
    # freedom as it has pixels: the p-values are uniform, whatever the pixels' own variances.
    points, labels = _tiles()
    rng = np.random.default_rng(0)
    prior = rng.uniform(0.3, 1.0, len(points))  # inverse variances (relative)
    p = np.concatenate([tile_p_values(tile_sums(rng.normal(0, 2.0, len(points)) / np.sqrt(prior), prior, labels), 4.0)
                        for _ in range(20)])
    assert kstest(p, "uniform").pvalue > 1e-3
    assert np.mean(p < MISFIT_P_VALUE) < 5 * MISFIT_P_VALUE + 3 / len(p)


def test_a_tile_off_by_two_noise_sd_is_improbable_and_dropped_pixels_do_not_count():
    points, labels = _tiles()
    rng = np.random.default_rng(1)
    residual = rng.normal(0, 1.0, len(points))
    tile = labels == labels[len(points) // 2]
    residual[tile] += 2.0  # a patch each pixel of which is inside Huber's linear range (2 sd)
    p = tile_p_values(tile_sums(residual, np.ones(len(points)), labels), 1.0)
    assert p[labels[tile][0]] < MISFIT_P_VALUE / 10 and np.median(p) > 0.2
    prior = np.where(tile, 0.0, 1.0)
    assert tile_p_values(tile_sums(residual, prior, labels), 1.0)[labels[tile][0]] == 1.0


class _Fit:
    """What trim_misfit_tiles reads of a FitResult: a linear model's answer on the kept pixels."""

    def __init__(self, design, data, keep):
        self.coef = np.linalg.lstsq(design[keep], data[keep], rcond=None)[0]
        self.residual = data - design @ self.coef
        self.converged = True
        self._scale = float(np.mean(self.residual[keep] ** 2))

    def covariance_scale(self):
        return self._scale


def test_trimming_drops_the_worst_tiles_first_and_recovers_the_clean_answer():
    # A location fit (one parameter) whose data three tiles corrupt by different amounts: the trimming
    # drops exactly those, worst first, and the answer is the clean pixels' mean.
    points, labels = _tiles()
    rng = np.random.default_rng(2)
    design = np.ones((len(points), 1))
    data = 5.0 + rng.normal(0, 1.0, len(points))
    bad = [labels[k] for k in (0, 800, 1599)]
    for tile, extra in zip(bad, (3.0, 5.0, 4.0)):
        data[labels == tile] += extra
    dropped_order = []

    def refit(keep, last):
        dropped_order.append(sorted(set(labels[~keep])))
        return _Fit(design, data, keep)

    fit, keep = trim_misfit_tiles(_Fit(design, data, np.ones(len(data), bool)), refit, labels, None)
    assert dropped_order == [[bad[1]], sorted([bad[1], bad[2]]), sorted(bad)]
    assert len(dropped_order) <= MAX_DROPPED_TILES
    clean = ~np.isin(labels, bad)
    assert np.array_equal(keep, clean) and fit.coef[0] == pytest.approx(data[clean].mean())


def test_a_misfit_below_the_floor_is_kept():
    # At very low noise a tile a few percent of the contrast off is improbable under the noise, and
    # still the template's own shape error, not another object: the floor keeps it.
    points, labels = _tiles()
    rng = np.random.default_rng(4)
    design = np.ones((len(points), 1))
    data = rng.normal(0, 0.01, len(points))
    data[labels == 7] += 0.05
    rms = tile_rms(tile_sums(data - data.mean(), np.ones(len(data)), labels))
    assert rms[7] == pytest.approx(0.05, abs=0.01) and np.median(rms) == pytest.approx(0.01, rel=0.2)
    fit0 = _Fit(design, data, np.ones(len(data), bool))
    assert trim_misfit_tiles(fit0, lambda keep, last: _Fit(design, data, keep), labels, None)[1] is not None
    fit, keep = trim_misfit_tiles(fit0, lambda keep, last: pytest.fail("trimmed below the floor"), labels, None,
                                  floor=0.1)
    assert fit is fit0 and keep is None


def test_a_clean_fit_is_not_trimmed():
    points, labels = _tiles()
    rng = np.random.default_rng(3)
    design = np.ones((len(points), 1))
    data = rng.normal(0, 1.0, len(points))
    fit0 = _Fit(design, data, np.ones(len(data), bool))
    fit, keep = trim_misfit_tiles(fit0, lambda keep, last: pytest.fail("refitted a clean fit"), labels, None)
    assert fit is fit0 and keep is None


def test_the_static_blob_no_longer_pulls_the_answer():
    # tests/test_track_consistency.py's scene: frame 0's contour takes a static blob for part of the
    # wedge. Without trimming several frames are more than 1 px off (and flagged "inconsistent"); with
    # it no frame is, and the mean error drops by more than half. (The blob's soft flank reads as a
    # blurred edge, which would widen the band to 4 px and halve its pull: band_px=3 keeps the scene. The
    # cut of particles attached at the apex, which takes the blob out of the template, is off.)
    frames = [_wedge_with_a_static_blob(0.6 * k, seed=k) for k in range(12)]
    errors = {}
    for p_value in (None, MISFIT_P_VALUE):
        t = Tracker(template_frames=1, max_influence=None, max_sigma=None, misfit_p_value=p_value, band_px=3,
                    cut_attached=False)
        t.init(frames[0], ROI)
        errors[p_value] = np.array([abs(t.update(f).x - CENTRE[0] - 0.6 * (k + 1)) for k, f in enumerate(frames[1:])])
    assert (errors[None] > 1.0).sum() >= 2
    assert errors[MISFIT_P_VALUE].max() < 1.0 and errors[MISFIT_P_VALUE].mean() < 0.5 * errors[None].mean()


def test_trimming_leaves_a_clean_track_as_it_was():
    # On frames the template explains a tile is rarely improbable: the track is (nearly) the untrimmed one.
    frames = [wedge_frame(0.6 * k, 0.3 * k, noise=2.0, seed=k) for k in range(12)]
    xs = {}
    for p_value in (None, MISFIT_P_VALUE):
        t = Tracker(misfit_p_value=p_value)
        t.init(frames[0], ROI)
        xs[p_value] = np.array([t.update(f).x for f in frames[1:]])
    assert np.mean(xs[None] == xs[MISFIT_P_VALUE]) >= 0.75
    assert np.max(np.abs(xs[None] - xs[MISFIT_P_VALUE])) < 0.05


@pytest.mark.parametrize("bad", [0.0, 1.0, -0.1, float("nan")])
def test_misfit_p_value_must_be_a_probability_or_none(bad):
    with pytest.raises(ValueError, match="misfit_p_value"):
        Tracker(misfit_p_value=bad)
    assert Tracker(misfit_p_value=None).options.stages.misfit_p_value is None
    assert math.isclose(Tracker().options.stages.misfit_p_value, MISFIT_P_VALUE)
