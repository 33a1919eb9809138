"""Tracking accuracy and speed on the simulated SEM, semlab beside its peers (paper: "Tracking Performance").

Run: ``.venv/bin/python benchmarks/bench_tracking.py`` (``SEMLAB_FAST=1`` for fewer frames;
``--seed N``). One table: per sequence and tracker, RMSE, standard deviation and mean error
(px, against the simulator's ground truth), loss rate (error > 2 px or ok=False), ms per frame and
the Cramér–Rao bound of one frame's estimate inside the ROI. Then the issue's targets for the
default method as PASS/FAIL lines, and the paper's figures beside ours.
"""

from __future__ import annotations

import argparse
import os

import numpy as np
import pandas as pd

from semlab.metrics import run_tracker, summarise_errors, tracking_errors
from semlab.peers import TRACKERS, make_tracker
from semlab.sim import make_sequence

FAST = os.environ.get("SEMLAB_FAST", "") not in ("", "0")
DEFAULT = "semlab ic (default)"
PEERS = ["opencv TM_CCOEFF_NORMED", "opencv TM_SQDIFF", "opencv ECC", "skimage phase corr."]
PAPER = {"repeatability_std_px": 0.2268, "repeatability_mean_err_px": 0.0412, "std_at_B_px": 0.6255}


def sequences(seed: int):
    n = 40 if FAST else 100
    yield "static", make_sequence("static", n_frames=n, seed=seed)
    yield "moves_200px", make_sequence("moves_200px", seed=seed, **({"n_cycles": 2} if FAST else {}))
    yield "low_dose", make_sequence("low_dose", n_frames=n, seed=seed)
    yield "gray_fluctuation", make_sequence("gray_fluctuation", n_frames=n, seed=seed)
    yield "clutter_occluder", make_sequence("clutter_occluder", n_frames=n, seed=seed)


def std_at_b(seq, tracks) -> float:
    """Spread of the tracked position over the dwell frames at B (the paper's Fig. 7 figure)."""
    u = seq.commands.set_index("frame")["u"]
    at_b = u[u == u.max()].index
    t = tracks.set_index("frame").loc[at_b]
    truth = seq.truth.set_index("frame").loc[at_b]
    # Error at B, so that creep and drift while dwelling do not count as tracker spread.
    x0 = seq.truth.iloc[0]
    cx = seq.roi[0] + (seq.roi[2] - 1) / 2
    ex = (t["x"] - cx) - (truth["x"] - x0["x"])
    return float(ex.std(ddof=1))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    rows, b_spread = [], {}
    for kind, seq in sequences(args.seed):
        for name in TRACKERS:
            tracks, ms = run_tracker(make_tracker(name), seq.frames, seq.roi)
            stats = summarise_errors(tracking_errors(tracks, seq.truth, seq.roi))
            rows.append({"sequence": kind, "tracker": name, **stats, "ms_per_frame": ms,
                         "crb_x_px": seq.crb[0], "crb_y_px": seq.crb[1], "frames": len(seq)})
            if kind == "moves_200px":
                b_spread[name] = std_at_b(seq, tracks)
    table = pd.DataFrame(rows)
    pd.set_option("display.width", 200)
    pd.set_option("display.max_columns", 20)
    print(f"# bench_tracking: seed {args.seed}, fast mode {FAST}; errors in px against ground truth")
    print(table.round(4).to_string(index=False))

    # The targets for the default method.
    print("\n# targets for the default method")
    d = table[table.tracker == DEFAULT].set_index("sequence")
    checks = []
    checks.append(("no loss on any sequence", bool((d.loss_rate == 0).all()),
                   ", ".join(f"{k}: {v:.2%}" for k, v in d.loss_rate.items())))
    crb_total = np.hypot(d.crb_x_px, d.crb_y_px)
    moving = [k for k in d.index if k != "static"]
    for k in moving:
        checks.append((f"{k}: RMSE <= 2 x CRB", bool(d.rmse_px[k] <= 2 * crb_total[k]),
                       f"{d.rmse_px[k]:.3f} vs {2 * crb_total[k]:.3f}"))
    for ax in "xy":
        checks.append((f"static std_{ax} <= 1.5 x CRB_{ax}", bool(d.loc['static', f'std_{ax}_px'] <= 1.5 * d.loc['static', f'crb_{ax}_px']),
                       f"{d.loc['static', f'std_{ax}_px']:.3f} vs {1.5 * d.loc['static', f'crb_{ax}_px']:.3f}"))
    for k in moving:
        peers = table[(table.sequence == k) & table.tracker.isin(PEERS)]
        best = peers.rmse_px.min()
        checks.append((f"{k}: RMSE <= 0.5 x best peer", bool(d.rmse_px[k] <= 0.5 * best),
                       f"{d.rmse_px[k]:.3f} vs 0.5 x {best:.3f}"))
    tm = table[table.tracker == "opencv TM_CCOEFF_NORMED"].set_index("sequence").ms_per_frame
    checks.append(("ms/frame <= TM_CCOEFF_NORMED's (median over sequences)",
                   bool(d.ms_per_frame.median() <= tm.median()),
                   f"{d.ms_per_frame.median():.2f} vs {tm.median():.2f} ms"))
    for what, ok, detail in checks:
        print(f"{'PASS' if ok else 'FAIL'}  {what}: {detail}")

    print("\n# the paper's figures beside ours (px)")
    st = table[table.sequence == "static"].set_index("tracker")
    paper = pd.DataFrame([
        {"figure": "repeatability std (static)", "paper": PAPER["repeatability_std_px"],
         **{n: float(np.hypot(st.std_x_px[n], st.std_y_px[n])) for n in TRACKERS}},
        {"figure": "repeatability |mean error| (static)", "paper": PAPER["repeatability_mean_err_px"],
         **{n: float(np.hypot(st.mean_err_x_px[n], st.mean_err_y_px[n])) for n in TRACKERS}},
        {"figure": "std at B (200-px moves, x)", "paper": PAPER["std_at_B_px"], **b_spread},
    ])
    print(paper.round(4).set_index("figure").T.to_string())
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
