"""semlab's error budget on the corpus: what each part of the scene costs, over the bound (issue 14).

Run::

    nice -n 10 .venv/bin/python benchmarks/bench_error_budget.py                 # 7 families x dev seeds 100-109
    nice -n 10 .venv/bin/python benchmarks/bench_error_budget.py --seeds 100-101 --families still,wander

semlab's default tracker on the same seeds, once as drawn and once each with a part of the scene
taken out (``without``: the substrate's texture, the line noise, the frames' photometric jitter,
the noise nearly all, and texture and noise together), every other draw kept
(:mod:`semlab.evaluation.budget`). Each sequence's error splits into its bias and its scatter about
it; both are given over the one-frame Cramér–Rao bound of the scene as drawn, medians over the
seeds. An estimator at the bound scatters by 1. "noise share" is the scatter's part the noise makes,
``sqrt(scatter² − floor²)``, the floor being the scatter without the noise. The development seeds
by default: this is a tool to find where the error comes from, not a figure to report.
"""

from __future__ import annotations

import argparse
import sys
import time

from semlab.evaluation import DEV_SEEDS, evaluate
from semlab.evaluation.budget import budget_table, error_budget
from semlab.evaluation.runner import parse_seeds

#: The families whose scene and noise the simulator draws, so that every part can be taken out
#: (not substrates, whose substrate is its own, nor the semi-real needle), and whose probe is
#: resolved (not the two low-dose families, where semlab flags nearly every frame: no scatter).
FAMILIES = "still,moves_200px,wander,jumps,shapes,gray_charging,clutter"
#: Condition name -> what it takes out.
CONDITIONS = {
    "as drawn": (),
    "without texture": ("texture",),
    "without line noise": ("line_noise",),
    "without photometric jitter": ("photometric_jitter",),
    "without noise": ("noise",),
    "without texture and noise": ("texture", "noise"),
}
FLOOR = "without noise"


def _markdown(table) -> str:
    lines = ["| family | " + " | ".join(table.columns) + " |", "| --- |" + " ---: |" * len(table.columns)]
    lines += [f"| {family} | " + " | ".join(f"{v:.2f}" for v in row) + " |" for family, row in table.iterrows()]
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=parse_seeds, default=list(DEV_SEEDS)[:10], help="e.g. 100-109 (default)")
    ap.add_argument("--families", default=FAMILIES, help=f"comma-separated (default: {FAMILIES})")
    ap.add_argument("--scheduler", default=None, help="tcp://HOST:PORT, 'inline', or a LocalCluster (default)")
    ap.add_argument("--out", default=None, help="also write the per-sequence rows as CSV")
    args = ap.parse_args(argv)
    families = args.families.split(",")
    started = time.perf_counter()
    runs, bound = {}, None
    for name, without in CONDITIONS.items():
        print(f"# {name}", file=sys.stderr)
        rows, per_frame = evaluate(families=families, seeds=args.seeds, trackers="semlab", per_frame=True,
                                   scheduler=args.scheduler, without=without)
        runs[name] = per_frame
        if not without:
            bound = rows
    budget = error_budget(runs, bound)
    if args.out:
        budget.to_csv(args.out, index=False)
    table = budget_table(budget, floor=FLOOR)
    wide = table.pivot(index="family", columns="condition", values="scatter_over_crb")[list(CONDITIONS)]
    bias = table.pivot(index="family", columns="condition", values="bias_over_crb")[list(CONDITIONS)]
    share = table[table["condition"] == "as drawn"].set_index("family")["noise_share"]
    print(f"# scatter / CRB of the scene as drawn (median over seeds {args.seeds[0]}-{args.seeds[-1]}; 1 = the bound)")
    print(_markdown(wide.assign(**{"noise share": share})))
    print("\n# bias / CRB (the error every frame of a sequence shares; frame 0's own error alone is about 1)")
    print(_markdown(bias))
    print(f"\n# wall time {time.perf_counter() - started:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
