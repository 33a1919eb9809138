"""The error budget's reductions (semlab.evaluation.budget) on per-frame tables of known errors."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from semlab.evaluation.budget import (
    MIN_FRAMES,
    SKIP_FRAMES,
    budget_table,
    error_budget,
    sequence_errors,
)

N_FRAMES = 400


def _per_frame(family, seed, bias, sd, rng, n=N_FRAMES):
    frames = np.arange(n)
    ex = bias[0] + sd[0] * rng.standard_normal(n)
    ey = bias[1] + sd[1] * rng.standard_normal(n)
    ex[:SKIP_FRAMES] = 50.0  # a young template's frames: left out
    return pd.DataFrame({"family": family, "seed": seed, "tracker": "semlab", "frame": frames, "ex": ex, "ey": ey,
                         "ok": True, "sigma_x": 0.1, "sigma_y": 0.1, "visible": True})


def test_each_sequence_splits_into_its_bias_and_its_scatter():
    rng = np.random.default_rng(0)
    table = pd.concat([_per_frame("wander", 1, (0.3, -0.1), (0.2, 0.05), rng),
                       _per_frame("still", 2, (0.0, 0.0), (0.04, 0.08), rng)])
    table.loc[table["frame"] == SKIP_FRAMES + 1, "ok"] = False  # flagged frames are left out
    hidden = (table["frame"] == SKIP_FRAMES + 2) & (table["seed"] == 1)  # and frames where the tip is hidden
    table.loc[hidden, ["ex", "visible"]] = (90.0, False)
    seq = sequence_errors(table).set_index("seed")
    # sample mean and sd of ~395 normal draws: within 4 of their standard errors (sd/sqrt(n), sd/sqrt(2n))
    n = N_FRAMES - SKIP_FRAMES
    assert seq.loc[1, "bias_x"] == pytest.approx(0.3, abs=4 * 0.2 / np.sqrt(n))
    assert seq.loc[1, "bias_y"] == pytest.approx(-0.1, abs=4 * 0.05 / np.sqrt(n))
    assert seq.loc[1, "scatter_x"] == pytest.approx(0.2, rel=4 / np.sqrt(2 * n))
    assert seq.loc[2, "scatter_y"] == pytest.approx(0.08, rel=4 / np.sqrt(2 * n))
    assert seq.loc[1, "n"] == n - 2 and seq.loc[2, "n"] == n - 1


def test_a_sequence_with_too_few_frames_has_no_scatter():
    short = _per_frame("jumps", 3, (0.0, 0.0), (0.1, 0.1), np.random.default_rng(1), n=SKIP_FRAMES + MIN_FRAMES - 1)
    row = sequence_errors(short).iloc[0]
    assert row["n"] == MIN_FRAMES - 1 and np.isnan(row["scatter_x"]) and np.isnan(row["bias_y"])


def test_every_condition_is_put_over_the_bound_of_the_scene_as_drawn():
    rng = np.random.default_rng(2)
    bound = pd.DataFrame({"family": ["wander"], "seed": [1], "crb_x_px": [0.1], "crb_y_px": [0.05]})
    runs = {"as drawn": _per_frame("wander", 1, (0.1, 0.05), (0.2, 0.1), rng),
            "without noise": _per_frame("wander", 1, (0.0, 0.0), (0.05, 0.025), rng)}
    budget = error_budget(runs, bound).set_index("condition")
    tol = 4 / np.sqrt(2 * (N_FRAMES - SKIP_FRAMES))
    assert budget.loc["as drawn", "scatter_over_crb"] == pytest.approx(2.0, rel=tol)  # both axes 2x their bound
    assert budget.loc["as drawn", "bias_over_crb"] == pytest.approx(1.0, abs=0.1)
    assert budget.loc["without noise", "scatter_over_crb"] == pytest.approx(0.5, rel=tol)
    table = budget_table(budget.reset_index(), floor="without noise").set_index("condition")
    floor, scatter = table.loc["without noise", "scatter_over_crb"], table.loc["as drawn", "scatter_over_crb"]
    assert table.loc["as drawn", "noise_share"] == pytest.approx(np.sqrt(scatter ** 2 - floor ** 2))
    assert table.loc["without noise", "noise_share"] == 0.0


def test_the_table_is_the_median_over_the_seeds():
    rng = np.random.default_rng(3)
    bound = pd.DataFrame({"family": "still", "seed": [1, 2, 3], "crb_x_px": 0.1, "crb_y_px": 0.1})
    runs = {"as drawn": pd.concat([_per_frame("still", s, (0, 0), (sd, sd), rng) for s, sd in ((1, 0.1), (2, 0.2), (3, 0.9))])}
    table = budget_table(error_budget(runs, bound))
    assert table["scatter_over_crb"].iloc[0] == pytest.approx(2.0, rel=0.1) and "noise_share" not in table


def test_no_run_is_a_clear_error():
    bound = pd.DataFrame({"family": ["still"], "seed": [1], "crb_x_px": [0.1], "crb_y_px": [0.1]})
    with pytest.raises(ValueError, match="at least one run"):
        error_budget({}, bound)
