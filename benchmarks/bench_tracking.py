"""Tracking accuracy and speed on the simulated SEM: semlab beside the paper's methods and the
tools people would use instead (Ru et al. 2012, "Tracking Performance").

Run::

    .venv/bin/python benchmarks/bench_tracking.py            # full: ~1.5 min on 2 cores
    SEMLAB_FAST=1 .venv/bin/python benchmarks/bench_tracking.py   # fewer frames (CI)

Sequences (:func:`semlab.sim.make_sequence`, seed ``--seed``): ``static`` (the still probe, 100
frames: the paper's repeatability), ``moves_200px`` (five 200-px A-B-A moves: the paper's Fig. 7),
and ``low_dose``, ``gray_fluctuation`` and ``clutter_occluder`` with the probe MOVING (60 frames of
the default sweep: manipulator 0's x piezo takes the probe from rest to ~61 px by frame 40 and
half-way back, at most ~3 px per frame). Then, for reference only, the same three with the probe
still (``"<kind> (probe still)"``, 40 frames, semlab's default and the peers only):
on a still probe an estimator biased towards "no motion" can score below the Cramér–Rao bound
(which binds unbiased estimators), so the "0.5 x best peer" comparison means nothing there; the
run prints findTransformECC's measured static RMSE beside its bound to show it.

Peers are used as a user tracks with them: the template is frame 0's ROI, each frame starts from
the previous frame's estimate (ECC's initial warp; ``matchTemplate`` searches the 300×300 window
around the last position; ``phase_cross_correlation`` compares with the ROI-sized patch at the last
integer position) -- see :mod:`semlab.peers`.

Prints ONE table: per sequence and tracker, RMSE, standard deviation and mean error (px, 2-D,
against the simulator's ground truth, frame 0 as the origin of displacements), loss rate
(error > 2 px or no position), ms per frame (mean of ``update`` over the sequence, template
building included) and the Cramér–Rao bound of one frame's estimate inside the ROI
(``seq.crb``: frame 0's, from the noise-free render and the noise model; along the sweep the
bound of the ROI moved with the probe is 1.00-1.13 x frame 0's, seed 0). Then the issue's
targets for the default method on ``static`` and the four moving sequences as PASS/FAIL lines,
a timing duel with OpenCV ``TM_CCOEFF_NORMED`` on the same 640×480 frames, 300×300 window and
200×200 template, and the paper's figures beside ours.
"""

from __future__ import annotations

import argparse
import math
import os
import time
import warnings

import numpy as np
import pandas as pd

from semlab.metrics import run_tracker, summarize_errors, tracking_errors
from semlab.peers import ECCPeer, MatchTemplatePeer, PhaseCorrelationPeer
from semlab.sim import make_sequence
from semlab.tracking import DEFAULT_METHOD, Tracker

FAST = os.environ.get("SEMLAB_FAST", "") not in ("", "0")
DEFAULT = f"semlab {DEFAULT_METHOD} (default)"
TRACKERS = {
    DEFAULT: lambda: Tracker(),
    "paper contour (eq. 9-10)": lambda: Tracker("contour"),
    "paper hb (eqs. 2-5)": lambda: Tracker("hb"),
    "paper ssd (integer)": lambda: Tracker("ssd"),
    "opencv TM_CCOEFF_NORMED": lambda: MatchTemplatePeer("TM_CCOEFF_NORMED"),
    "opencv TM_SQDIFF": lambda: MatchTemplatePeer("TM_SQDIFF"),
    "opencv findTransformECC": lambda: ECCPeer(),
    "skimage phase_cross_corr": lambda: PhaseCorrelationPeer(),
}
PEERS = ["opencv TM_CCOEFF_NORMED", "opencv TM_SQDIFF", "opencv findTransformECC", "skimage phase_cross_corr"]
PAPER = {"repeatability std": 0.2268, "repeatability mean error": 0.0412, "std at B": 0.6255}


STILL = " (probe still)"
MOVING = ["moves_200px", "low_dose", "gray_fluctuation", "clutter_occluder"]


def sequences(seed: int):
    """The issue's five sequences (the probe moves in all but "static"), then the still-probe
    variants of the last three, labelled ``"<kind> (probe still)"``."""
    n = 40 if FAST else 100  # the paper's 100 detections of a still probe
    n_sweep = 30 if FAST else 60  # the 80-frame sweep: up 0 -> ~61 px by frame 40, then half-way back
    n_still = 20 if FAST else 40
    cycles = {"n_cycles": 2} if FAST else {}
    seqs = {
        "static": make_sequence("static", n_frames=n, seed=seed),
        "moves_200px": make_sequence("moves_200px", seed=seed, **cycles),
    }
    for kind in MOVING[1:]:  # manipulator 0's x piezo sweeps the probe (semlab.sim.sequences)
        seqs[kind] = make_sequence(kind, n_frames=n_sweep, seed=seed)
    for kind in MOVING[1:]:
        seqs[kind + STILL] = make_sequence(kind, n_frames=n_still, seed=seed, motion="still")
    return seqs


def at_b(seq, track):
    """The paper's Fig. 7 figure: spread at B, the dwell frames at the far end of the moves."""
    u = seq.commands.set_index("frame")["u"]
    dwell = u[u >= u.max() - 1e-6 * max(abs(u.max()), 1.0)].index  # the DAC quantises the command
    t = track.set_index("frame").loc[dwell]
    truth = seq.truth.set_index("frame").loc[dwell]
    cx = seq.roi[0] + (seq.roi[2] - 1) / 2
    x0 = float(seq.truth["x"].iloc[0])
    error = (t["x"] - cx) - (truth["x"] - x0)
    # The last dwell frame of each visit: the tracked B position, five times (the paper's figure
    # includes the manipulator's own scatter, which the simulated piezo has too).
    visits = np.split(dwell.to_numpy(), np.nonzero(np.diff(dwell.to_numpy()) > 1)[0] + 1)
    last = [v[-1] for v in visits]
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # a tracker lost at every B visit: NaN
        return float(np.nanstd(error, ddof=1)), float(np.nanstd(track.set_index("frame").loc[last, "x"], ddof=1))


def duel(seq, repeats=3):
    """ms per frame of the default tracker and of TM_CCOEFF_NORMED, interleaved (shared CPU)."""
    times = {DEFAULT: [], "opencv TM_CCOEFF_NORMED": []}
    for _ in range(repeats):
        for name, runs in times.items():
            _, ms = run_tracker(TRACKERS[name](), seq.frames, seq.roi)
            runs.append(ms)
    return {k: float(np.median(v)) for k, v in times.items()}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    t_start = time.perf_counter()
    seqs = sequences(args.seed)
    rows, b_figures = [], {}
    for kind, seq in seqs.items():
        crb = math.hypot(*seq.crb)
        for name, factory in TRACKERS.items():
            if kind.endswith(STILL) and name not in [DEFAULT] + PEERS:
                continue  # reference rows: the default beside the peers (keeps the run short)
            track, ms = run_tracker(factory(), seq.frames, seq.roi)
            s = summarize_errors(tracking_errors(track, seq.truth, seq.roi), seq.crb)
            rows.append({"sequence": kind, "tracker": name, "rmse_px": s["rmse"], "std_px": s["std"],
                         "mean_err_px": s["mean_error"], "std_x_px": s["std_x"], "std_y_px": s["std_y"],
                         "loss_rate": s["loss_rate"], "ms_per_frame": ms, "crb_px": crb,
                         "rmse_over_crb": s["rmse"] / crb, "frames": len(seq)})
            if kind == "moves_200px":
                b_figures[name] = at_b(seq, track)
    table = pd.DataFrame(rows)
    pd.set_option("display.width", 220)
    pd.set_option("display.max_columns", 30)
    pd.set_option("display.max_rows", 200)
    print(f"# bench_tracking: seed {args.seed}, SEMLAB_FAST={int(FAST)}; px against ground truth, "
          "2-D (std/rmse = sqrt of the sum over x and y); CRB = Cramér–Rao bound of one frame in the ROI "
          "(frame 0's)")
    for k in MOVING[1:]:
        dx = seqs[k].truth["x"] - seqs[k].truth["x"].iloc[0]
        print(f"# {k}: the probe moves {dx.min():.1f} .. {dx.max():.1f} px along x (x-piezo sweep from rest, "
              f"up to {dx.diff().abs().max():.1f} px per frame)")
    print(table.drop(columns=["std_x_px", "std_y_px"]).round(4).to_string(index=False))

    still_rows = [k for k in seqs if k.endswith(STILL)]
    if still_rows:
        ecc = table[(table.sequence == "static") & (table.tracker == "opencv findTransformECC")].iloc[0]
        print(f"\n# rows '...{STILL}': the probe stands still (only the ~0.05 px/s image drift moves it), "
              "so an estimator biased towards 'no motion' can score below the Cramér–Rao bound, which "
              f"binds unbiased estimators only (here findTransformECC on 'static': RMSE {ecc.rmse_px:.3f} px vs "
              f"CRB {ecc.crb_px:.3f} px, {ecc.rmse_px / ecc.crb_px:.2f} x), so '0.5 x best peer' means nothing "
              "there: these rows are for reference and take no part in the targets below.")

    d = table[table.tracker == DEFAULT].set_index("sequence").loc[["static"] + MOVING]
    checks = [("no loss on any sequence", bool((d.loss_rate == 0).all()),
               ", ".join(f"{k} {v:.1%}" for k, v in d.loss_rate.items()))]
    checks.append(("static: std <= 1.5 x CRB", bool(d.std_px["static"] <= 1.5 * d.crb_px["static"]),
                   f"{d.std_px['static']:.3f} vs {1.5 * d.crb_px['static']:.3f} px"))
    for k in MOVING:
        checks.append((f"{k}: RMSE <= 2 x CRB", bool(d.rmse_px[k] <= 2 * d.crb_px[k]),
                       f"{d.rmse_px[k]:.3f} vs {2 * d.crb_px[k]:.3f} px"))
    for k in MOVING:
        peers = table[(table.sequence == k) & table.tracker.isin(PEERS)]
        best = peers.loc[peers.rmse_px.idxmin()]
        checks.append((f"{k}: RMSE <= 0.5 x best peer ({best.tracker})",
                       bool(d.rmse_px[k] <= 0.5 * best.rmse_px), f"{d.rmse_px[k]:.3f} vs 0.5 x {best.rmse_px:.3f} px"))
    speed = duel(seqs["moves_200px"])
    duel_label = ("ms/frame <= TM_CCOEFF_NORMED (same 640x480 frames, 300x300 window, 200x200 template; "
                  "median of 3 interleaved runs on moves_200px)")
    checks.append((duel_label,
                   speed[DEFAULT] <= speed["opencv TM_CCOEFF_NORMED"],
                   f"{speed[DEFAULT]:.2f} vs {speed['opencv TM_CCOEFF_NORMED']:.2f} ms"))
    print("\n# targets for the default method (issue 3)")
    for what, ok, detail in checks:
        print(f"{'PASS' if ok else 'FAIL'}  {what}: {detail}")
    print("# (the CRB above is one frame's; a displacement from frame 0 also carries frame 0's own error, "
          "which no later frame can remove: its bound is sqrt(2) x CRB, so '2 x CRB' is 1.41 x the "
          "displacement's bound. The targets keep the stricter one-frame reading.)")

    st = table[table.sequence == "static"].set_index("tracker")
    paper = pd.DataFrame({
        "paper (Ru et al. 2012)": [PAPER["repeatability std"], PAPER["repeatability mean error"], PAPER["std at B"],
                                   float("nan")],
        **{name: [float(np.hypot(st.std_x_px[name], st.std_y_px[name])) / math.sqrt(2),
                  float(st.mean_err_px[name]), b_figures[name][1], b_figures[name][0]]
           for name in (DEFAULT, "paper contour (eq. 9-10)", "opencv TM_CCOEFF_NORMED")},
    }, index=["repeatability std, static (px, per axis)", "repeatability mean error, static (px)",
              "std of the tracked B position over the visits (px)", "std of the tracking error at B (px)"])
    print("\n# the paper's figures beside ours (the paper's: 100 detections of a still probe at 3,000x, "
          "66 nm/px; five 200-px moves A->B)")
    print(paper.round(4).to_string())
    print(f"\n# {time.perf_counter() - t_start:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
