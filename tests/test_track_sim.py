"""The tracker on the simulated SEM (semlab.sim.make_sequence), against ground truth and the
Cramér–Rao bound of one frame (seq.crb). Short sequences; benchmarks/bench_tracking.py has the
full ones and the peers."""

from __future__ import annotations

import functools
import math

import numpy as np
import pytest

from semlab.metrics import summarize_errors, tracking_errors
from semlab.peers import MatchTemplatePeer
from semlab.roi import roi_from_motion
from semlab.sim import SimulatedRig, make_sequence
from semlab.tracking import Tracker, track


def _stats(seq, method="ic", **params):
    df = track(seq.frames, seq.roi, method=method, progress=False, **params)
    return summarize_errors(tracking_errors(df, seq.truth, seq.roi), seq.crb)


def test_static_repeatability_near_the_bound():
    # 60 frames of a still probe: the spread of the default tracker is within 1.5x the one-frame
    # bound (template averaged over 20 frames: factor ~1.02; 60-frame std: ±9 % sampling error).
    seq = make_sequence("static", n_frames=60, seed=3)
    s = _stats(seq)
    assert s["loss_rate"] == 0
    assert s["std"] <= 1.5 * s["crb"]
    # The displacement carries frame 0's own noise once (the origin): RMSE ~ sqrt(2) x bound.
    assert s["rmse"] <= 2.0 * s["crb"]


def test_moves_200px_tracked_and_beats_plain_template_matching():
    # One A-B-A cycle of the paper's Fig. 7: 200-px moves in 6 frames (up to ~45 px per frame).
    # Seed 0 as everywhere else. Known limitation: where the probe lands next to static clutter
    # particles (other seeds) the RMSE reaches 2-5x the bound (see the report of issue 3).
    seq = make_sequence("moves_200px", seed=0, n_cycles=1)
    s = _stats(seq)
    assert s["loss_rate"] == 0
    assert s["rmse"] <= 2.0 * s["crb"]
    # OpenCV's normalised correlation with a 3-point parabola, run the same way: its 200x200
    # template holds the static background, which pulls it back as the probe moves away.
    peer = MatchTemplatePeer("TM_CCOEFF_NORMED")
    peer.init(seq.frames[0], seq.roi)
    rows = [(0, *(np.array(seq.roi[:2]) + (np.array(seq.roi[2:]) - 1) / 2), 1.0, True)]
    for k in range(1, len(seq)):
        r = peer.update(seq.frames[k])
        rows.append((k, r.x, r.y, r.score, r.ok))
    import pandas as pd

    peer_stats = summarize_errors(tracking_errors(pd.DataFrame(rows, columns=["frame", "x", "y", "score", "ok"]),
                                                  seq.truth, seq.roi), seq.crb)
    assert s["rmse"] <= 0.5 * peer_stats["rmse"]


@pytest.mark.parametrize("kind", ["gray_fluctuation", "clutter_occluder"])
def test_fluctuation_and_clutter_probe_still(kind):
    # The robustness itself, the probe held still (motion="still"): per-frame gain/offset
    # fluctuation with charging, or dense clutter, drifting particles and an occluder over the
    # shaft, cost the default tracker neither lock nor accuracy: RMSE within 2x the one-frame
    # bound (the displacement carries frame 0's noise once: ~sqrt(2) x bound; see the static test).
    seq = make_sequence(kind, n_frames=50, seed=2, motion="still")
    df = track(seq.frames, seq.roi, progress=False)
    s = summarize_errors(tracking_errors(df, seq.truth, seq.roi), seq.crb)
    assert s["rmse"] <= 2.0 * s["crb"]
    _flagged_only_under_the_occluder(df)


@functools.cache
def _moving_stats(kind, seed=2):
    # The default sweep of these kinds: the x piezo moves the probe from rest 0 -> ~61 px over
    # frames 0-40 (raised-cosine voltage, up to ~2.7 px per frame), then back.
    seq = make_sequence(kind, n_frames=50, seed=seed)
    assert seq.meta["motion"] == "sweep"
    assert np.ptp(seq.truth["x"]) > 55
    df = track(seq.frames, seq.roi, progress=False)
    return summarize_errors(tracking_errors(df, seq.truth, seq.roi), seq.crb), df


#: The template's similarity while the occluder is off the band (measured >= 0.93 on these scenes;
#: it falls to ~0.7 where the occluder covers the shaft).
CLEAR_SCORE = 0.9


def _flagged_only_under_the_occluder(df):
    """A frame is flagged only for information its data lack: where the occluder covers the band
    (the score below CLEAR_SCORE) its precision may pass SIGMA_LIMIT_PX; while the band is clear, at
    most 2 % of the frames (issue 14's target) are flagged."""
    clear = df["score"] >= CLEAR_SCORE
    assert (~df["ok"][clear]).mean() <= 0.02
    flagged = ~df["ok"]
    assert not flagged.any() or df["score"][flagged].max() < CLEAR_SCORE


@pytest.mark.parametrize("kind", ["gray_fluctuation", "clutter_occluder"])
def test_fluctuation_and_clutter_moving_probe_followed(kind):
    # The same conditions with the probe travelling ~60 px: the tracker stays on it in every
    # frame (no error above 2 px, ~20x the bound; a tracker held by the static background,
    # as the 200x200 ROI's clutter holds OpenCV's ECC, would be tens of px off).
    s, df = _moving_stats(kind)
    _flagged_only_under_the_occluder(df)
    assert s["max_error"] <= 2.0


@pytest.mark.parametrize("seed", [0, 2])
@pytest.mark.parametrize("kind", ["gray_fluctuation", "clutter_occluder"])
def test_fluctuation_and_clutter_moving_probe_near_the_bound(kind, seed):
    # Issue 3's target: RMSE <= 2x the one-frame bound. Theory: the displacement carries frame
    # 0's error as well as frame k's (sqrt(2) x the bound for an efficient estimator; along the
    # sweep the moved ROI's bound is up to 13 % above frame 0's), so 2x leaves ~25 % for the
    # static background's pull (measured, 50 frames: seed 0 1.87x / 1.65x, seed 2 1.81x / 1.79x).
    s, df = _moving_stats(kind, seed=seed)
    _flagged_only_under_the_occluder(df)
    assert s["rmse"] <= 2.0 * s["crb"]


@pytest.mark.xfail(strict=True, reason=(
    "known limitation, measured (seed 1, 50 frames): RMSE 3.81x the one-frame bound on gray_fluctuation "
    "and 2.77x on clutter_occluder with the probe moving (seeds 0-5: 1.4-8.2x; seeds 0, 2, 4 within 2x; "
    "seed 1 has a particle touching the apex, seed 3 a thin probe nearly parallel to x). The static "
    "background beside the object pulls the estimate back while the probe is within a few px of where the "
    "template was taken. A matter for semlab/tracking/."))
def test_fluctuation_and_clutter_moving_probe_near_the_bound_particle_at_the_apex():
    assert all(_moving_stats(kind, seed=1)[0]["rmse"] <= 2.0 * _moving_stats(kind, seed=1)[0]["crb"]
               for kind in ("gray_fluctuation", "clutter_occluder"))


def test_four_probes_in_one_stream():
    rig = SimulatedRig(n_manipulators=4, seed=5)
    frames = [rig.microscope.grab() for _ in range(8)]
    truth0 = rig.truth  # last frame's truth; the probes stand still apart from drift
    rig2 = SimulatedRig(n_manipulators=4, seed=5)
    rig2.microscope.grab()
    tips = rig2.truth[["x", "y"]].to_numpy()
    rois = []
    h, w = frames[0].shape
    for x, y in tips:
        rx = int(min(max(round(x - 59.5), 0), w - 120))
        ry = int(min(max(round(y - 59.5), 0), h - 120))
        rois.append((rx, ry, 120, 120))
    df = track(frames, rois, method="ic", progress=False)
    assert df["ok"].all() and sorted(df["target"].unique()) == [0, 1, 2, 3]
    last = df[df.frame == 7].set_index("target")
    for k, (x0, y0) in enumerate(tips):
        cx, cy = rois[k][0] + 59.5, rois[k][1] + 59.5
        x1, y1 = truth0[["x", "y"]].to_numpy()[k]
        err = math.hypot((last.loc[k, "x"] - cx) - (x1 - x0), (last.loc[k, "y"] - cy) - (y1 - y0))
        assert err < 0.5  # several times the bound of a 120x120 ROI; no probe confused with another


def test_roi_from_motion_on_the_rig():
    # The paper's second ROI method: step manipulator 0 along x, subtract the still background.
    rig = SimulatedRig(n_manipulators=4, seed=6)
    ax = rig.axis(0, "x")
    lo, hi = ax.limits
    frames = []
    for k in range(8):
        ax.apply(lo + (hi - lo) * 0.02 * k)
        frames.append(rig.microscope.grab())
    tip = rig.truth[["x", "y"]].to_numpy()[0]
    x, y, w, h = roi_from_motion(frames, size=200)
    assert x <= tip[0] <= x + w - 1 and y <= tip[1] <= y + h - 1
    t = Tracker()
    t.init(frames[-1], (x, y, w, h))  # and the ROI holds a usable contour template


def test_low_dose_thin_probe_is_followed_or_flagged():
    # Either the tracker follows (error <= 2 px, ~9x this bound) or it says it cannot (ok=False):
    # no frame may be more than 2 px off while flagged ok. At low dose (10 pA) a thin probe nearly
    # parallel to x (seed 1) carries its x information in the apex only: the fit scatters along the
    # shaft, which its uncertainty (sigma_x) says; the frames too uncertain to trust are flagged.
    seq = make_sequence("low_dose", n_frames=30, seed=1, motion="still")
    df = track(seq.frames, seq.roi, method="ic", progress=False)
    err = tracking_errors(df, seq.truth, seq.roi)
    assert not (err["ok"] & (err["error"] > 2.0)).any()
