"""Where the default tracker's time goes: per-frame wall time by kind of frame, and a cProfile.

Run ``PYTHONPATH=$PWD python benchmarks/profile_tracker.py [--sequence moves_200px] [--cprofile]``.
Frames are classed as "averaging" (the template is still being averaged, the first
``template_frames`` registered frames), "move" (the constant-velocity prediction was off by more
than 1 px, so the smoothed first stage or the coarse search ran) or "steady".
"""

from __future__ import annotations

import argparse
import cProfile
import pstats
import time

import numpy as np
import pandas as pd

from semlab.metrics import run_tracker
from semlab.peers import MatchTemplatePeer
from semlab.sim import make_sequence
from semlab.tracking import Tracker


def profile(kind: str, seed: int = 0, repeats: int = 3, clock=time.perf_counter) -> pd.DataFrame:
    """Median ms per frame of ``Tracker()`` over ``repeats`` runs, grouped by kind of frame.

    ``clock=time.process_time`` counts CPU time instead of wall time (steadier on a shared
    machine, but blind to OpenCV's worker threads waiting for a core).
    """
    seq = make_sequence(kind, seed=seed)
    times, classes = [], None
    for _ in range(repeats):
        t = Tracker()
        t.init(seq.frames[0], seq.roi)
        run, cls = [], []
        for frame in seq.frames[1:]:
            averaging = t.algorithm.averager is not None
            steady = t.motion.prediction_error < 1.0
            t0 = clock()
            t.update(frame)
            run.append(1e3 * (clock() - t0))
            cls.append("averaging" if averaging else ("steady" if steady else "move"))
        times.append(run)
        classes = cls
    ms = np.median(np.array(times), axis=0)
    df = pd.DataFrame({"kind": classes, "ms": ms})
    out = df.groupby("kind")["ms"].agg(["count", "mean", "median", "sum"])
    out.loc["all"] = [len(df), df.ms.mean(), df.ms.median(), df.ms.sum()]
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sequence", default="moves_200px")
    ap.add_argument("--cprofile", action="store_true")
    ap.add_argument("--cpu", action="store_true", help="CPU time (process_time) instead of wall time")
    args = ap.parse_args(argv)
    clock = time.process_time if args.cpu else time.perf_counter
    print(f"# {args.sequence}: {'CPU' if args.cpu else 'wall'} ms per update by kind of frame "
          "(median of 3 runs per frame)")
    print(profile(args.sequence, clock=clock).round(3).to_string())
    seq = make_sequence(args.sequence, seed=0)
    duel = {"Tracker()": [], "opencv TM_CCOEFF_NORMED": []}
    for _ in range(3):
        duel["Tracker()"].append(run_tracker(Tracker(), seq.frames, seq.roi)[1])
        duel["opencv TM_CCOEFF_NORMED"].append(run_tracker(MatchTemplatePeer("TM_CCOEFF_NORMED"), seq.frames, seq.roi)[1])
    print("# ms per frame, median of 3 interleaved runs: "
          + ", ".join(f"{k} {np.median(v):.2f}" for k, v in duel.items()))
    if args.cprofile:
        seq = make_sequence(args.sequence, seed=0)
        t = Tracker()
        t.init(seq.frames[0], seq.roi)
        pr = cProfile.Profile()
        pr.enable()
        for frame in seq.frames[1:]:
            t.update(frame)
        pr.disable()
        pstats.Stats(pr).sort_stats("tottime").print_stats(25)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
