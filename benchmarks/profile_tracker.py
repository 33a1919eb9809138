"""Where the default tracker's time goes: per-frame wall time by kind of frame, and a cProfile.

Run ``PYTHONPATH=$PWD python benchmarks/profile_tracker.py [--sequence moves_200px] [--cprofile]``, or
``--family wander --seed 100`` for a sequence of the evaluation corpus (where the speed target is judged:
tune on its development seeds).
Frames are classed as "averaging" (the template is still being averaged, the first
``template_frames`` registered frames), "move" (the last frame's constant-velocity prediction was off
by more than 1 px, so the smoothed first stage or the coarse search ran), "jump" (it held, but this
frame's missed by more than 1 px: the steady fit gave up and the coarse search ran) or "steady".
"""

from __future__ import annotations

import argparse
import cProfile
import pstats
import time

import numpy as np
import pandas as pd

from semlab.evaluation import DEV_SEEDS, make_family_sequence
from semlab.metrics import run_tracker
from semlab.peers import MatchTemplatePeer
from semlab.sim import make_sequence
from semlab.tracking import Tracker
from semlab.tracking.ic import STEADY_PX


def load(kind: str, seed: int = 0, family: str | None = None):
    """The simulator's sequence ``kind`` (:func:`semlab.sim.make_sequence`), or the corpus's ``family``
    at ``seed`` (:func:`semlab.evaluation.make_family_sequence`) when one is given."""
    return make_sequence(kind, seed=seed) if family is None else make_family_sequence(family, seed)


def profile(kind: str, seed: int = 0, repeats: int = 3, clock=time.perf_counter, family: str | None = None) -> pd.DataFrame:
    """Median ms per frame of ``Tracker()`` over ``repeats`` runs, grouped by kind of frame.

    ``clock=time.process_time`` counts CPU time instead of wall time (steadier on a shared
    machine, but blind to OpenCV's worker threads waiting for a core). ``family``: a corpus
    family instead of the sequence ``kind`` (:func:`load`).
    """
    seq = load(kind, seed, family)
    times, classes = [], None
    for _ in range(repeats):
        t = Tracker()
        t.init(seq.frames[0], seq.roi)
        run, cls = [], []
        for frame in seq.frames[1:]:
            averaging = t.algorithm.averager is not None
            steady = t.motion.prediction_error < STEADY_PX
            t0 = clock()
            t.update(frame)
            run.append(1e3 * (clock() - t0))
            held = t.motion.prediction_error < STEADY_PX  # this frame's prediction (inf when lost)
            cls.append("averaging" if averaging else ("move" if not steady else ("steady" if held else "jump")))
        times.append(run)
        classes = cls
    ms = np.median(np.array(times), axis=0)
    df = pd.DataFrame({"kind": classes, "ms": ms})
    out = df.groupby("kind")["ms"].agg(["count", "mean", "median", "sum"])
    out.loc["all"] = [len(df), df.ms.mean(), df.ms.median(), df.ms.sum()]
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sequence", default="moves_200px", help="a sequence of semlab.sim.make_sequence (seed 0)")
    ap.add_argument("--family", help="a family of the evaluation corpus instead of --sequence")
    ap.add_argument("--seed", type=int, default=None, help="--family's seed (default: the first development seed)")
    ap.add_argument("--cprofile", action="store_true")
    ap.add_argument("--cpu", action="store_true", help="CPU time (process_time) instead of wall time")
    args = ap.parse_args(argv)
    clock = time.process_time if args.cpu else time.perf_counter
    seed = (DEV_SEEDS[0] if args.seed is None else args.seed) if args.family else 0
    name = f"{args.family} seed {seed}" if args.family else args.sequence
    print(f"# {name}: {'CPU' if args.cpu else 'wall'} ms per update by kind of frame "
          "(median of 3 runs per frame)")
    print(profile(args.sequence, seed, clock=clock, family=args.family).round(3).to_string())
    seq = load(args.sequence, seed, args.family)
    duel = {"Tracker()": [], "opencv TM_CCOEFF_NORMED": []}
    for _ in range(3):
        duel["Tracker()"].append(run_tracker(Tracker(), seq.frames, seq.roi)[1])
        duel["opencv TM_CCOEFF_NORMED"].append(run_tracker(MatchTemplatePeer("TM_CCOEFF_NORMED"), seq.frames, seq.roi)[1])
    print("# ms per frame, median of 3 interleaved runs: "
          + ", ".join(f"{k} {np.median(v):.2f}" for k, v in duel.items()))
    if args.cprofile:
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
