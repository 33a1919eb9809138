"""The scene-family corpus: semlab's default tracker beside the four peers, per family (issue 13).

Run::

    nice -n 10 .venv/bin/python benchmarks/bench_corpus.py             # standard: 11 families x test seeds 0-9
    nice -n 10 .venv/bin/python benchmarks/bench_corpus.py --seeds 0-1  # small (CI): seeds 0-1
    .venv/bin/python benchmarks/bench_corpus.py --scheduler tcp://127.0.0.1:8786   # an existing cluster

Every family of :data:`semlab.evaluation.FAMILIES` (the issue's list; the parameter ranges are in
the code and in the JSON sidecar of ``semlab evaluate``), the TEST seeds unless ``--seeds`` says
otherwise, semlab (``Tracker()`` with its defaults at run time) and OpenCV ``TM_CCOEFF_NORMED``,
``TM_SQDIFF``, ``findTransformECC`` and scikit-image ``phase_cross_correlation`` in the same run, on a
dask ``LocalCluster`` (2 single-threaded workers). Prints the per-family table (median, p90 and worst
RMSE / single-frame Cramér–Rao bound over the seeds, mean lost and silent rates, the share of
sequences with any silent frame, median ms/frame), where semlab is ahead of the best peer, and the
wall time against the issue's budget (15 min standard, 3 min for ``--seeds 0-1``, 2 cores). ms/frame
is measured inside workers that share the cores with each other (and, on a shared machine, with
everyone else): compare within one run only.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

from semlab.evaluation import FAMILY_NAMES, TEST_SEEDS, evaluate, summarise, summary_markdown
from semlab.evaluation.runner import parse_seeds

#: The issue's wall-time budgets (s) on 2 cores: the standard corpus and --seeds 0-1.
BUDGET_STANDARD_S = 15 * 60
BUDGET_SMALL_S = 3 * 60


def _semlab_vs_best_peer(summary) -> list[str]:
    lines = []
    for fam in dict.fromkeys(summary["family"]):
        g = summary[summary["family"] == fam].set_index("tracker")
        if "semlab" not in g.index or len(g) < 2:
            continue
        peers = g.drop(index="semlab")
        best = peers["rmse_over_crb_median"].idxmin()
        ours, theirs = g.loc["semlab", "rmse_over_crb_median"], peers.loc[best, "rmse_over_crb_median"]
        ratio = ours / theirs if np.isfinite(theirs) and theirs > 0 else float("nan")
        lines.append(f"{fam:15s} semlab {ours:7.2f}  best peer {best:9s} {theirs:7.2f}  ratio {ratio:5.2f}")
    return lines


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=parse_seeds, default=list(TEST_SEEDS), help="e.g. 0-9 (default: the test seeds)")
    ap.add_argument("--families", default=",".join(FAMILY_NAMES), help="comma-separated (default: all)")
    ap.add_argument("--trackers", default=None, help="comma-separated (default: semlab and the four peers)")
    ap.add_argument("--scheduler", default=None, help="tcp://HOST:PORT, 'inline', or a LocalCluster (default)")
    ap.add_argument("--workers", type=int, default=None)
    ap.add_argument("--out", default=None, help="also write the per-sequence rows as CSV")
    args = ap.parse_args(argv)

    t0 = time.perf_counter()
    df = evaluate(args.families, args.seeds, args.trackers, scheduler=args.scheduler, n_workers=args.workers,
                  progress=sys.stderr.isatty())
    wall = time.perf_counter() - t0
    if args.out:
        df.to_csv(args.out, index=False)
    summary = summarise(df)
    n_fam, n_seeds, n_trk = df["family"].nunique(), df["seed"].nunique(), df["tracker"].nunique()
    print(f"# corpus: {n_fam} families x {n_seeds} seeds ({', '.join(sorted(set(df['split'])))}) x {n_trk} trackers "
          f"on {df.attrs['scheduler']}")
    print(summary_markdown(summary))
    if (df["error"] != "").any():
        print("\n# runs cut short or refused by a tracker")
        for _, r in df[df["error"] != ""].iterrows():
            print(f"{r.family}/{r.seed} {r.tracker}: {r.error[:140]}")
    print("\n# median RMSE / bound: semlab beside the best peer (ratio < 1: semlab ahead)")
    print("\n".join(_semlab_vs_best_peer(summary)))
    budget = BUDGET_SMALL_S if n_seeds <= 2 else BUDGET_STANDARD_S
    verdict = "within" if wall <= budget else "OVER"
    cpu = sum(m.get("task_cpu_s", 0.0) for m in df.attrs["sequences"].values())
    print(f"\n# wall time {wall:.0f} s ({verdict} the {budget / 60:.0f}-min budget for {n_seeds} seeds; "
          f"load average at the end {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores)")
    print(f"# CPU time of the tasks {cpu:.0f} s: {cpu / 2:.0f} s of wall time on 2 otherwise idle cores "
          "(+ the cluster's start-up)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
