"""semlab.control.step_metrics on hand-built responses whose figures are known in closed form.

Every response here is an exact formula (a first-order lag, a damped oscillation, a plateau with a
known alternating ripple), so the response times, the overshoot and the final statistics follow
from algebra, not from a run; the only tolerance is float rounding.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from semlab.control import step_metrics

FRAME_PERIOD = 0.077  # s (13 Hz, the paper's frame rate)


def response(displacement, target, *, ok=True, first_frame=0, t0=0.0):
    n = len(displacement)
    frames = first_frame + np.arange(n)
    return pd.DataFrame({"frame": frames, "t": t0 + FRAME_PERIOD * np.arange(n), "u": 0.0, "x": 0.0, "y": 0.0,
                         "displacement": np.asarray(displacement, float), "target": target, "ok": ok})


def first_order(step, a, n):
    """d_k = S (1 - a^k): |error_k| = |S| a^k, inside ±tol from k = ceil(log(tol/|S|)/log a)."""
    return step * (1.0 - a ** np.arange(n))


@pytest.mark.parametrize("step", [100.0, -40.0])
def test_first_order_lag_response_times(step):
    a, n = 0.7, 80
    resp = response(first_order(step, a, n), step, first_frame=120, t0=9.5)
    m = step_metrics(resp)
    k1 = math.ceil(math.log(1.0 / abs(step)) / math.log(a))
    k05 = math.ceil(math.log(0.5 / abs(step)) / math.log(a))
    # times run from the first row (frame 120 at t = 9.5 s), not from frame 0 or t = 0
    assert m["response_frames_1px"] == k1 and m["response_frames_0p5px"] == k05
    assert m["response_time_1px_s"] == pytest.approx(k1 * FRAME_PERIOD, rel=1e-12)
    assert m["response_time_0p5px_s"] == pytest.approx(k05 * FRAME_PERIOD, rel=1e-12)
    assert m["overshoot_px"] == 0.0  # a first-order lag never passes the target
    assert m["step_px"] == step
    tail = first_order(step, a, n)[-30:]  # the default final_frames = 30
    assert m["final_mean_px"] == pytest.approx(np.mean(tail), rel=1e-12)
    assert m["final_std_px"] == pytest.approx(np.std(tail, ddof=1), rel=1e-9, abs=1e-15)
    assert m["final_error_px"] == pytest.approx(np.mean(tail) - step, abs=1e-12)
    assert m["n_lost"] == 0


@pytest.mark.parametrize("step", [50.0, -50.0])
def test_damped_oscillation_overshoot(step):
    # d_k = S (1 - r^k cos(π k / P)): the first peak beyond the target is at k = P, |S| r^P past it
    # (with cos(π/P) < r the neighbouring integers are lower, and later peaks are smaller still).
    r, period, n = 0.96, 10, 400
    k = np.arange(n)
    d = step * (1.0 - r ** k * np.cos(np.pi * k / period))
    m = step_metrics(response(d, step))
    assert m["overshoot_px"] == pytest.approx(abs(step) * r ** period, rel=1e-12)
    # last excursion beyond ±tol: the largest k with |S| r^k |cos(πk/P)| > tol; one frame later
    # the response is inside for good
    out_1 = np.flatnonzero(np.abs(step) * r ** k * np.abs(np.cos(np.pi * k / period)) > 1.0)
    out_05 = np.flatnonzero(np.abs(step) * r ** k * np.abs(np.cos(np.pi * k / period)) > 0.5)
    assert m["response_frames_1px"] == out_1[-1] + 1
    assert m["response_frames_0p5px"] == out_05[-1] + 1


def test_plateau_ripple_gives_the_final_mean_and_std():
    # After a jump the response sits at S + 0.2 (-1)^k: mean S exactly over an even number of
    # frames, and the sample std of ±0.2 over n frames is 0.2 sqrt(n / (n - 1)).
    step, n = 20.0, 40
    d = np.array([0.0] + [step + 0.2 * (-1) ** j for j in range(1, n)])
    for final in (10, 30):
        m = step_metrics(response(d, step), final_frames=final)
        assert m["final_mean_px"] == pytest.approx(step, abs=1e-12)
        assert m["final_std_px"] == pytest.approx(0.2 * math.sqrt(final / (final - 1)), rel=1e-12)
        assert m["final_error_px"] == pytest.approx(0.0, abs=1e-12)
    assert m["response_frames_0p5px"] == 1 and m["overshoot_px"] == pytest.approx(0.2)


def test_band_edges_are_exactly_half_and_one_pixel():
    # error exactly at the band edge counts as inside (|e| <= tol); 0.55 px is outside ±0.5 px
    # (and would be inside a 0.6 px band), 1.05 px is outside ±1 px.
    step = 10.0
    err = np.array([-10.0, -3.0, 1.05, 0.5, -0.5, 0.55, 1.0, -1.0, 0.3, 0.0, 0.25, 0.0])
    m = step_metrics(response(step + err, step))
    assert m["response_frames_1px"] == 3  # after the 1.05 at frame 2; 1.0 at frames 6-7 is inside
    assert m["response_frames_0p5px"] == 8  # after frame 7's -1.0 (the 0.55 at frame 5 also counts)
    err2 = err.copy()
    err2[6:8] = 0.0
    assert step_metrics(response(step + err2, step))["response_frames_0p5px"] == 6  # after the 0.55
    err3 = err2.copy()
    err3[5] = 0.5
    assert step_metrics(response(step + err3, step))["response_frames_0p5px"] == 3  # after the 1.05
    assert m["overshoot_px"] == pytest.approx(1.05)


def test_lost_frames_are_skipped_and_counted():
    step, n = 30.0, 40
    d = first_order(step, 0.5, n)
    ok = np.ones(n, bool)
    ok[[15, 16, 30]] = False
    d[[15, 16, 30]] = 500.0  # garbage on lost frames must not count as a violation or overshoot
    d[35] = np.nan  # a NaN position counts as lost even if the tracker said ok
    m = step_metrics(response(d, step, ok=ok))
    assert m["n_lost"] == 4
    assert m["overshoot_px"] == 0.0
    assert m["response_frames_1px"] == math.ceil(math.log(1 / step) / math.log(0.5))
    valid = d[ok & np.isfinite(d)]
    assert m["final_mean_px"] == pytest.approx(np.mean(valid[-30:]), rel=1e-12)
    m10 = step_metrics(response(d, step, ok=ok), final_frames=10)
    assert m10["final_mean_px"] == pytest.approx(np.mean(valid[-10:]), rel=1e-12)
    assert m10["final_std_px"] == pytest.approx(np.std(valid[-10:], ddof=1), rel=1e-9, abs=1e-15)


def test_a_response_that_ends_outside_the_band_never_settled():
    step = 10.0
    d = np.full(20, step)
    d[0] = 0.0
    d[-1] = step + 0.8  # the last valid frame is outside ±0.5 px but inside ±1 px
    m = step_metrics(response(d, step))
    assert np.isnan(m["response_frames_0p5px"]) and np.isnan(m["response_time_0p5px_s"])
    assert m["response_frames_1px"] == 1
    # a lost last frame does not hide that the last valid one was outside
    d2 = np.append(d, step)
    ok = np.ones(21, bool)
    ok[-1] = False
    assert np.isnan(step_metrics(response(d2, step, ok=ok))["response_frames_0p5px"])
    # ... and a bad frame followed only by lost frames is the last valid one
    d3 = np.append(np.full(20, step), [step + 3.0, step, step])
    d3[0] = 0.0
    ok3 = np.ones(23, bool)
    ok3[-2:] = False
    assert np.isnan(step_metrics(response(d3, step, ok=ok3))["response_frames_1px"])


def test_a_response_inside_from_the_start_and_an_all_lost_response():
    step = 0.3  # a move smaller than the band: row 0 (error 0.3) is already inside
    m = step_metrics(response(np.full(10, 0.3) - np.r_[0.3, np.zeros(9)], step))
    assert m["response_frames_0p5px"] == 0 and m["response_time_0p5px_s"] == 0.0
    lost = step_metrics(response(np.full(5, np.nan), 10.0, ok=False))
    assert lost["n_lost"] == 5
    for key in ("response_frames_1px", "response_time_0p5px_s", "overshoot_px", "final_mean_px",
                "final_std_px", "final_error_px"):
        assert np.isnan(lost[key]), key
    one_valid = np.full(5, np.nan)
    one_valid[-1] = 10.0
    single = step_metrics(response(one_valid, 10.0, ok=np.isfinite(one_valid)))
    assert single["final_mean_px"] == 10.0 and np.isnan(single["final_std_px"])  # one sample: no std


def test_the_error_is_against_each_row_target_and_the_step_is_the_last_target():
    # A target that changes during the run (a macro hand-over then the nano move): rows compare with
    # their own target, the step is the final one.
    d = np.array([0.0, 5.0, 9.0, 14.0, 18.0, 20.4, 20.0, 20.0])
    target = np.array([10.0, 10.0, 10.0, 20.0, 20.0, 20.0, 20.0, 20.0])
    m = step_metrics(response(d, target))
    assert m["step_px"] == 20.0
    assert m["response_frames_1px"] == 5 and m["response_frames_0p5px"] == 5
    assert m["overshoot_px"] == pytest.approx(0.4)
    assert m["final_error_px"] == pytest.approx(np.mean(d) - 20.0)


def test_overshoot_direction_for_small_and_zero_steps():
    # a positive step smaller than 1 px is still a positive step; a zero step counts excursions
    # above the target (the direction of rising displacement)
    d = np.array([0.0, 0.3, 0.9, 0.6, 0.5, 0.5])
    assert step_metrics(response(d, 0.5))["overshoot_px"] == pytest.approx(0.4)
    assert step_metrics(response(np.array([0.0, 0.4, -0.7, 0.1]), 0.0))["overshoot_px"] == pytest.approx(0.4)


def test_the_step_is_the_last_rows_target_and_two_frames_give_a_std():
    d = np.array([0.0, 5.0, 9.8, 10.1, 10.3])
    target = np.array([10.0, 10.0, 10.0, 10.0, 10.5])  # the target moved in the last row
    m = step_metrics(response(d, target))
    assert m["step_px"] == 10.5
    assert m["final_error_px"] == pytest.approx(np.mean(d) - 10.5)
    ok = np.array([False, False, False, True, True])
    two = step_metrics(response(d, target, ok=ok))
    assert two["final_std_px"] == pytest.approx(np.std([10.1, 10.3], ddof=1))


def test_an_index_that_is_not_a_range_changes_nothing():
    d = first_order(12.0, 0.6, 30)
    resp = response(d, 12.0)
    shuffled_index = resp.set_axis(np.arange(30)[::-1] * 7 + 3)
    pd.testing.assert_series_equal(step_metrics(shuffled_index), step_metrics(resp))


def test_bad_input_is_refused():
    resp = response(first_order(5.0, 0.5, 10), 5.0)
    with pytest.raises(TypeError, match=r"^response must be a DataFrame from step_response$"):
        step_metrics(resp.to_numpy())
    for col in ("frame", "t", "displacement", "target", "ok"):
        with pytest.raises(ValueError, match=f"lacks column.*{col}"):
            step_metrics(resp.drop(columns=col))
    with pytest.raises(ValueError, match=r"^response has fewer than 2 rows$"):
        step_metrics(resp.iloc[:1])
    step_metrics(resp.iloc[:2])  # two rows are enough
