"""The default tracker over many simulated scenes: RMSE / Cramér–Rao bound per seed and kind.

One seed is one draw of probe geometry, substrate, clutter and noise: a change that helps seed 0
(``bench_tracking.py``'s) can hurt most others. This prints, for each seed and sequence kind, the
default tracker's RMSE over the one-frame bound (static: the standard deviation over the bound), then
the median and geometric mean over the seeds, and the worst loss rate — and, given ``--param``, the
same for the tracker with those parameters beside it, with the number of seeds on which it is better.

Run::

    .venv/bin/python benchmarks/bench_tracking_seeds.py                      # seeds 0-17, ~1 min on 2 cores
    .venv/bin/python benchmarks/bench_tracking_seeds.py --param band_px=3    # the default beside a variant
    .venv/bin/python benchmarks/bench_tracking_seeds.py --seeds 0-5 --kinds low_dose static

Sequences: ``moves_200px`` (two A-B-A cycles), ``low_dose``, ``gray_fluctuation``,
``clutter_occluder`` (the default ~60-px sweep, 60 frames) and ``static`` (100 frames), as
:func:`semlab.sim.make_sequence` makes them.
"""

from __future__ import annotations

import argparse
import ast
import math
import time
from concurrent.futures import ProcessPoolExecutor

import numpy as np
import pandas as pd

from semlab.metrics import run_tracker, summarize_errors, tracking_errors
from semlab.sim import make_sequence
from semlab.tracking import Tracker

KINDS = ("moves_200px", "low_dose", "gray_fluctuation", "clutter_occluder", "static")


def _sequence(kind: str, seed: int):
    if kind == "moves_200px":
        return make_sequence(kind, seed=seed, n_cycles=2)
    return make_sequence(kind, n_frames=100 if kind == "static" else 60, seed=seed)


def _ratio(job) -> dict:
    """RMSE (static: std) over the one-frame bound of one tracker on one sequence."""
    kind, seed, label, params = job
    seq = _sequence(kind, seed)
    track, _ = run_tracker(Tracker(**params), seq.frames, seq.roi)
    s = summarize_errors(tracking_errors(track, seq.truth, seq.roi), seq.crb)
    crb = math.hypot(*seq.crb)
    return {"tracker": label, "kind": kind, "seed": seed, "ratio": (s["std"] if kind == "static" else s["rmse"]) / crb,
            "loss_rate": s["loss_rate"]}


def _seeds(text: str) -> list[int]:
    seeds = []
    for part in text.split(","):
        lo, _, hi = part.partition("-")
        seeds += list(range(int(lo), int(hi or lo) + 1))
    return seeds


def _param(text: str) -> tuple[str, object]:
    key, sep, value = text.partition("=")
    if not sep:
        raise argparse.ArgumentTypeError(f"--param wants key=value, got {text!r}")
    try:
        return key, ast.literal_eval(value)
    except (ValueError, SyntaxError):
        return key, value


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=_seeds, default=list(range(18)), help="e.g. 0-17 or 0,3,5-8 (default 0-17)")
    ap.add_argument("--kinds", nargs="+", choices=KINDS, default=list(KINDS))
    ap.add_argument("--param", type=_param, action="append", default=[],
                    help="a Tracker parameter of the variant, key=value (repeatable), e.g. band_px=3")
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args(argv)
    trackers = {"default": {}}
    if args.param:
        trackers["variant " + " ".join(f"{k}={v}" for k, v in args.param)] = dict(args.param)
    jobs = [(kind, seed, label, params) for label, params in trackers.items() for seed in args.seeds
            for kind in args.kinds]
    t0 = time.perf_counter()
    with ProcessPoolExecutor(max(args.workers, 1)) as pool:
        rows = list(pool.map(_ratio, jobs))
    df = pd.DataFrame(rows)
    pd.set_option("display.width", 200)
    for label in trackers:
        table = df[df.tracker == label].pivot(index="seed", columns="kind", values="ratio")[list(args.kinds)]
        print(f"# {label}: RMSE / one-frame CRB per seed (static: std / CRB)")
        print(table.round(2).to_string())
        print()
    summary = df.groupby(["tracker", "kind"], sort=False).agg(
        median=("ratio", "median"), geometric_mean=("ratio", lambda r: float(np.exp(np.log(r).mean()))),
        worst=("ratio", "max"), worst_loss_rate=("loss_rate", "max")).unstack("tracker")
    print("# over the seeds")
    print(summary.reindex(list(args.kinds)).round(3).to_string())
    if len(trackers) > 1:
        variant = list(trackers)[1]
        a = df[df.tracker == "default"].set_index(["kind", "seed"]).ratio
        b = df[df.tracker == variant].set_index(["kind", "seed"]).ratio
        better = (b < a).groupby(level="kind").sum().reindex(list(args.kinds))
        print(f"\n# seeds on which the variant is better (of {len(args.seeds)}): "
              + ", ".join(f"{k} {int(v)}" for k, v in better.items()))
    print(f"\n# {len(jobs)} runs, {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
