"""``semlab evaluate``: run trackers on the scene-family corpus (issue 13), its options and texts."""

from __future__ import annotations

import argparse
import json
import os
import time
from datetime import UTC, datetime
from pathlib import Path

from semlab.cli._common import (
    COMMAND_HELP,
    EXIT_INTERRUPTED,
    EXIT_OK,
    EXIT_OUTPUT,
    EXIT_SCHEDULER,
    EXIT_USAGE,
    _check_output,
    _CLIError,
    _param_arg,
    _sha256,
    _tmp_name,
    _version,
)
from semlab.environment import describe as describe_environment

EVALUATE_DESCRIPTION = """\
Run trackers on the scene-family corpus (semlab.evaluation) and write one CSV row per family x seed
x tracker: family, seed, split, tracker, rmse_px, crb_px, lost_fraction, silent_fraction,
ms_per_frame, and more (n_frames, rmse_over_crb, std_px, std_over_crb, median/p90/max_err_px,
flagged_fraction, coverage95, crb_x_px, crb_y_px, n_visible, bias_px: the error every frame shares,
held_fraction: the share of the probe's own motion not followed, error). Prints the summary per family
(median, p90 and worst RMSE / Cramer-Rao bound, lost and silent rates, ms/frame) with the trackers
side by side.

Seeds: the test seeds 0-9 by default (report these); --split dev selects the dev seeds 100-119
(tune on these). Tasks (one per family x seed) run on a dask LocalCluster on this machine, or on an
existing cluster with --scheduler tcp://HOST:PORT ('dask scheduler' + 'dask worker', semlab
installed on the workers), or in this process with --scheduler inline.

Next to OUT the command writes OUT.json: semlab version, command line, families with their
parameter ranges, seeds, trackers and parameters, scheduler, the parameters drawn for every
sequence, times, and the SHA-256 of the CSV. Everything is written under temporary names and
renamed when complete: an interrupted run leaves no output that looks complete.
"""

EVALUATE_EXAMPLES = f"""\
examples:
  semlab evaluate --out corpus.csv                                   # all families, test seeds, 5 trackers
  semlab evaluate --families still,semi_real --seeds 0-1 --out small.csv
  semlab evaluate --split dev --trackers semlab --param huber=3 --out dev.csv
  semlab evaluate --scheduler tcp://127.0.0.1:8786 --out corpus.csv --figure corpus.png
exit codes: {EXIT_OK} success, {EXIT_USAGE} usage (unknown family/tracker, bad seeds or --param),
  {EXIT_OUTPUT} output not writable, {EXIT_SCHEDULER} dask scheduler unreachable, {EXIT_INTERRUPTED} interrupted
"""


def _seeds_arg(text: str) -> list[int]:
    from semlab.evaluation.runner import parse_seeds

    try:
        return parse_seeds(text)
    except ValueError as e:
        raise argparse.ArgumentTypeError(f"--seeds: {e}") from None


def _add_evaluate_parser(sub, fmt) -> None:
    e = sub.add_parser("evaluate", help=COMMAND_HELP["evaluate"],
                       description=EVALUATE_DESCRIPTION, epilog=EVALUATE_EXAMPLES, formatter_class=fmt)
    e.add_argument("--families", metavar="NAME,...", help="families (default: all; see semlab.evaluation.FAMILIES)")
    seeds = e.add_mutually_exclusive_group()
    seeds.add_argument("--seeds", type=_seeds_arg, metavar="0-9", help="seeds, e.g. 0-9 or 0,3,5-8 (default: test)")
    seeds.add_argument("--split", choices=("test", "dev"), help="the split's seeds: test 0-9, dev 100-119")
    e.add_argument("--trackers", metavar="NAME,...",
                   help="trackers (default semlab,ncc,sqdiff,ecc,phasecorr; also 'paper')")
    e.add_argument("--param", type=_param_arg, action="append", default=[], metavar="KEY=VALUE",
                   help="a semlab.Tracker parameter for the 'semlab' tracker (repeatable)")
    e.add_argument("--without", metavar="PART,...",
                   help="take parts out of every scene, every other draw kept (an ablation): texture, occluder, "
                        "line_noise, photometric_jitter, noise (all of it but a 50x dose's shot noise and a tenth of the "
                        "read noise)")
    e.add_argument("--scheduler", metavar="ADDRESS",
                   help="tcp://HOST:PORT of a running dask scheduler, or 'inline' (default: a LocalCluster)")
    e.add_argument("--workers", type=int, metavar="N", help="LocalCluster workers (default: the cores, at most 2)")
    e.add_argument("--out", "-o", required=True, metavar="OUT.csv", help="output CSV; OUT.csv.json beside it")
    e.add_argument("--per-frame", metavar="FRAMES.csv", help="also write the per-frame errors")
    e.add_argument("--summary", metavar="SUMMARY.csv", help="also write the per-family summary")
    e.add_argument("--figure", metavar="FIG.png", help="also save the figure (RMSE / bound per family)")
    e.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")
    e.add_argument("--quiet", "-q", action="store_true", help="no summary on stdout")


def _cmd_evaluate(args, argv) -> int:
    started = time.time()
    out = Path(args.out)
    sidecar = out.with_name(out.name + ".json")
    extras = [Path(p) for p in (args.per_frame, args.summary, args.figure) if p]
    for path in (out, *extras):
        _check_output(path)
    params = dict(args.param)

    from semlab import evaluation as ev
    from semlab.evaluation.runner import resolve_families, resolve_seeds
    from semlab.evaluation.trackers import resolve_trackers

    try:  # every name and parameter checked before any work
        families = resolve_families(args.families)
        seeds = resolve_seeds(args.seeds, args.split)
        resolve_trackers(args.trackers, params)
        without = ev.families.check_ablations(families, [p for p in (args.without or "").split(",") if p])
    except ValueError as e:
        raise _CLIError(EXIT_USAGE, str(e)) from None
    if args.workers is not None and args.workers < 1:
        raise _CLIError(EXIT_USAGE, f"--workers must be >= 1, got {args.workers}")
    try:
        result = ev.evaluate(families, seeds, args.trackers, params=params, scheduler=args.scheduler,
                             n_workers=args.workers, per_frame=bool(args.per_frame), progress=not args.no_progress,
                             without=without)
        df, frames = result if args.per_frame else (result, None)
    except ev.SchedulerUnreachable as e:
        raise _CLIError(EXIT_SCHEDULER, str(e)) from None
    summary = ev.summarise(df)

    temps = []  # (temporary, final), the CSV last: a complete CSV means everything else is there
    try:
        try:
            if args.per_frame:
                temps.append((_tmp_name(Path(args.per_frame)), Path(args.per_frame)))
                frames.to_csv(temps[-1][0], index=False, float_format="%.6g", lineterminator="\n")
            if args.summary:
                temps.append((_tmp_name(Path(args.summary)), Path(args.summary)))
                summary.to_csv(temps[-1][0], index=False, float_format="%.6g", lineterminator="\n")
            if args.figure:
                temps.append((_tmp_name(Path(args.figure)), Path(args.figure)))
                _save_corpus_figure(summary, temps[-1][0], Path(args.figure).suffix)
            tmp_csv, tmp_json = _tmp_name(out), _tmp_name(sidecar)
            df.to_csv(tmp_csv, index=False, float_format="%.6g", lineterminator="\n")
            record = {
                "semlab_version": _version(),
                "created_utc": datetime.now(UTC).isoformat(timespec="seconds"),
                "command": ["semlab", *argv],
                "cwd": os.getcwd(),
                "families": {f: {"title": ev.FAMILIES[f].title,
                                 "ranges": {k: str(v) for k, v in ev.FAMILIES[f].ranges.items()}} for f in families},
                "seeds": seeds,
                "splits": {str(s): ev.split_of(s) for s in seeds},
                "trackers": list(dict.fromkeys(df["tracker"])),
                "params": params,
                "without": list(without),
                "scheduler": df.attrs.get("scheduler"),
                "sequences": df.attrs.get("sequences"),
                "output": {"csv": out.name, "sha256": _sha256(tmp_csv), "columns": list(df.columns), "rows": len(df)},
                "environment": {**describe_environment(), **_dask_versions()},
                "elapsed_s": round(time.time() - started, 3),
            }
            tmp_json.write_text(json.dumps(record, indent=1, default=str) + "\n")
            temps += [(tmp_json, sidecar), (tmp_csv, out)]
            for tmp, final in temps:
                os.replace(tmp, final)
        except OSError as e:
            raise _CLIError(EXIT_OUTPUT, f"{out}: cannot write output ({e.strerror or e})") from None
    finally:
        for tmp, _ in temps:
            if tmp.exists():
                tmp.unlink()
        for tmp in (_tmp_name(out), _tmp_name(sidecar)):
            if tmp.exists():
                tmp.unlink()

    if not args.quiet:
        print(ev.summary_markdown(summary))
        print(f"\n{len(df)} rows ({len(families)} families x {len(seeds)} seeds x "
              f"{df['tracker'].nunique()} trackers) on {df.attrs.get('scheduler')} in {time.time() - started:.0f} s; "
              f"wrote {out} and {sidecar.name}")
    return EXIT_OK


def _dask_versions() -> dict:
    import dask
    import distributed

    return {"dask": dask.__version__, "distributed": distributed.__version__}


def _save_corpus_figure(summary, path: Path, suffix: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from semlab.evaluation.figures import plot_corpus

    fig, ax = plt.subplots(figsize=(11, 4.5), layout="constrained")
    plot_corpus(summary, ax)
    fig.savefig(path, format=(suffix.lstrip(".") or "png"), dpi=120)
    plt.close(fig)
