"""The clustered (cluster-robust sandwich) covariance of the band's fit (issue 14)."""

from __future__ import annotations

import numpy as np
import pytest

from semlab.tracking.uncertainty import band_tiles, clustered_covariance, least_squares_covariance


def _band(n=900, seed=0):
    rng = np.random.default_rng(seed)
    pts = np.stack([rng.integers(0, 60, n), rng.integers(0, 60, n)], axis=1).astype(float)
    jac = rng.normal(0, 2.0, (n, 2))
    return pts, jac, band_tiles(pts)


def test_tiles_group_the_points_by_square():
    pts = np.array([[0, 0], [3, 3], [4, 0], [0, 4], [7.9, 7.9]])
    labels = band_tiles(pts, 4)
    assert labels[0] == labels[1] and len({labels[0], labels[2], labels[3]}) == 3 and labels[2] != labels[4]
    assert sorted(set(labels)) == list(range(len(set(labels))))


def _scatter(jac, labels, draw, trials=400, seed=1):
    """The least-squares shifts' covariance over draws of the residual, and the estimators' means."""
    rng = np.random.default_rng(seed)
    w = np.ones(len(jac))
    shifts, clustered, plain = [], [], []
    normal = jac.T @ jac
    for _ in range(trials):
        r = draw(rng)
        delta = np.linalg.solve(normal, jac.T @ r)
        shifts.append(delta)
        clustered.append(np.diag(clustered_covariance(jac, r - jac @ delta, w, labels)))
        plain.append(np.diag(least_squares_covariance(jac, r - jac @ delta)))
    return np.var(shifts, axis=0), np.mean(clustered, axis=0), np.mean(plain, axis=0)


def test_with_independent_noise_it_agrees_with_the_least_squares_covariance():
    _, jac, labels = _band()
    true, clustered, plain = _scatter(jac, labels, lambda rng: rng.normal(0, 3.0, len(jac)))
    # every estimator right within the 400 draws' sampling error (~7 % on a variance) and the
    # clustered one's own bias (a few % with ~200 clusters)
    assert clustered == pytest.approx(plain, rel=0.1)
    assert clustered == pytest.approx(true, rel=0.2)


def test_a_misfit_shared_within_tiles_is_seen_where_the_least_squares_covariance_misses_it():
    # Each tile's pixels share one misfit level along the Jacobian (a correlated texture): the shift
    # scatters several times more than s²(JᵀJ)⁻¹ says; the clustered covariance holds it.
    _, jac, labels = _band()
    n_tiles = labels.max() + 1

    def draw(rng):
        shared = rng.normal(0, 1.0, (n_tiles, 2))[labels]
        return rng.normal(0, 1.0, len(jac)) + np.sum(jac * shared, axis=1) * 0.5

    true, clustered, plain = _scatter(jac, labels, draw)
    assert np.all(plain < 0.5 * true)
    assert clustered == pytest.approx(true, rel=0.25)


def test_too_few_tiles_or_a_singular_system_give_infinity():
    _, jac, _ = _band(n=50)
    r = np.ones(50)
    assert np.all(np.isinf(clustered_covariance(jac, r, np.ones(50), np.zeros(50, int))))
    flat = np.stack([jac[:, 0], np.zeros(50)], axis=1)
    assert np.all(np.isinf(clustered_covariance(flat, r, np.ones(50), np.arange(50) % 5)))
