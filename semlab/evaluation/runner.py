"""``semlab.evaluate``: every tracker on every (family, seed) of the corpus, on dask.distributed.

One task per (family, seed): the worker simulates the sequence once, runs every tracker on it and
returns one row per tracker (and, on request, the per-frame errors). By default the tasks run on
a :class:`distributed.LocalCluster` on this machine (one single-threaded worker process per core,
at most :data:`MAX_LOCAL_WORKERS`); ``scheduler="tcp://host:port"`` sends them to an existing
cluster (``dask scheduler`` + ``dask worker``; the workers need semlab installed);
``scheduler="inline"`` runs them in this process, one after the other (debugging, tests).
"""

from __future__ import annotations

import logging
import os
import time
from collections.abc import Mapping

import pandas as pd

from .families import (
    DEV_SEEDS,
    FAMILY_NAMES,
    TEST_SEEDS,
    check_ablations,
    make_family_sequence,
    split_of,
)
from .scoring import COLUMNS, PER_FRAME_COLUMNS, frame_errors, run_tracker, score
from .trackers import resolve_trackers

__all__ = ["SchedulerUnreachable", "evaluate", "evaluate_sequence", "parse_seeds", "resolve_families", "resolve_seeds"]

#: Workers of the default LocalCluster at most (the team's machine has 2 cores).
MAX_LOCAL_WORKERS = 2
#: Seconds to wait for an existing scheduler before giving up (the CLI promises an error in 30 s).
CONNECT_TIMEOUT_S = 10


class SchedulerUnreachable(ConnectionError):
    """The dask scheduler at the given address could not be reached."""


def resolve_families(families=None) -> list[str]:
    """Family names from None (all), a comma-separated string or a list; ValueError lists the valid ones."""
    if families is None:
        return list(FAMILY_NAMES)
    if isinstance(families, str):
        families = [f.strip() for f in families.split(",") if f.strip()]
    families = list(families)
    bad = [f for f in families if f not in FAMILY_NAMES]
    if bad or not families:
        what = f"unknown family {bad[0]!r}" if bad else "no families selected"
        raise ValueError(f"{what}; valid: {', '.join(FAMILY_NAMES)}")
    return families


def parse_seeds(text: str) -> list[int]:
    """Seeds from ``"0-9"``, ``"3"`` or ``"0,3,5-8"``; ValueError otherwise."""
    seeds = []
    for part in str(text).split(","):
        lo, sep, hi = part.strip().partition("-")
        try:
            a, b = int(lo), int(hi if sep else lo)
        except ValueError:
            raise ValueError(f"seeds need N, N-M or a comma-separated list, got {text!r}") from None
        if a < 0 or b < a:
            raise ValueError(f"seed range {part.strip()!r} is empty or negative")
        seeds += range(a, b + 1)
    return seeds


def resolve_seeds(seeds=None, split=None) -> list[int]:
    """Seeds from a list/range, or a split ("test": :data:`TEST_SEEDS`, "dev": :data:`DEV_SEEDS`).

    Neither: the test seeds. Both: ValueError.
    """
    if seeds is not None and split is not None:
        raise ValueError("give seeds or a split, not both")
    if seeds is None:
        split = "test" if split is None else split
        if split not in ("test", "dev"):
            raise ValueError(f"unknown split {split!r}; valid: test, dev")
        return list(TEST_SEEDS if split == "test" else DEV_SEEDS)
    out = []
    for s in seeds:
        if isinstance(s, bool) or int(s) != s or s < 0:
            raise ValueError(f"seeds must be non-negative integers, got {s!r}")
        out.append(int(s))
    if not out:
        raise ValueError("no seeds selected")
    return list(dict.fromkeys(out))


def _single_threaded_in_worker():
    """In a dask worker, let OpenCV use one thread: the workers already fill the cores."""
    try:
        from distributed import get_worker

        get_worker()
    except (ImportError, ValueError):
        return
    import cv2

    cv2.setNumThreads(1)


def evaluate_sequence(family: str, seed: int, factories: Mapping, per_frame: bool = False, without=()):
    """Every tracker on one (family, seed): ``(rows, per_frame_errors or None, sequence_meta)``.

    This is the unit of work of :func:`evaluate` (one dask task); ``without``: as
    :func:`~semlab.evaluation.make_family_sequence`'s.
    """
    _single_threaded_in_worker()
    cpu0, wall0 = time.process_time(), time.perf_counter()
    seq = make_family_sequence(family, seed, without=without)
    rows, frames = [], []
    for name, factory in factories.items():
        track, ms, error = run_tracker(factory, seq.frames, seq.roi)
        errors = frame_errors(track, seq.truth, seq.roi)
        row = {"family": family, "seed": seed, "split": split_of(seed), "tracker": name}
        row.update(score(errors, seq.crb, ms))
        row["error"] = error
        rows.append(row)
        if per_frame:
            errors.insert(0, "tracker", name)
            errors.insert(0, "seed", seed)
            errors.insert(0, "family", family)
            frames.append(errors[PER_FRAME_COLUMNS])
    meta = {k: v for k, v in seq.meta.items() if k not in ("family", "seed")}
    # the task's own CPU time: on a shared machine, its wall time says more about the others
    meta["task_cpu_s"] = round(time.process_time() - cpu0, 3)
    meta["task_wall_s"] = round(time.perf_counter() - wall0, 3)
    return rows, (pd.concat(frames, ignore_index=True) if per_frame else None), meta


def _progress(iterable, total, enabled):
    if not enabled:
        return iterable
    from tqdm.auto import tqdm

    return tqdm(iterable, total=total, desc="corpus (family x seed)", unit="seq")


def _run_inline(jobs, factories, per_frame, progress, without):
    for family, seed in _progress(jobs, len(jobs), progress):
        yield (family, seed), evaluate_sequence(family, seed, factories, per_frame, without)


def _connect(scheduler, n_workers):
    """``(client, cluster or None, description)`` for a scheduler address or a new LocalCluster."""
    from distributed import Client, LocalCluster

    if scheduler in (None, "local"):
        n = n_workers or min(os.cpu_count() or 1, MAX_LOCAL_WORKERS)
        # dashboard on a free port: the default 8787 may be taken by another cluster on the machine
        cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=":0",
                               silence_logs=logging.ERROR)
        return Client(cluster), cluster, f"LocalCluster({n} workers x 1 thread)"
    try:
        client = Client(scheduler, timeout=CONNECT_TIMEOUT_S)
    except (OSError, TimeoutError) as e:
        raise SchedulerUnreachable(f"cannot reach the dask scheduler at {scheduler} within "
                                   f"{CONNECT_TIMEOUT_S} s ({type(e).__name__}: {e})") from None
    n = len(client.scheduler_info().get("workers", {}))
    return client, None, f"dask scheduler {scheduler} ({n} workers at start)"


def _run_dask(jobs, factories, per_frame, progress, scheduler, n_workers, info, without):
    from distributed import as_completed

    client, cluster, description = _connect(scheduler, n_workers)
    info["scheduler"] = description
    try:
        futures = {client.submit(evaluate_sequence, f, s, factories, per_frame, without, pure=False): (f, s)
                   for f, s in jobs}
        try:
            for fut in _progress(as_completed(futures), len(futures), progress):
                yield futures[fut], fut.result()
        except BaseException:
            client.cancel(list(futures))
            raise
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def evaluate(families=None, seeds=None, trackers=None, *, split: str | None = None, params: Mapping | None = None,
             scheduler: str | None = None, n_workers: int | None = None, per_frame: bool = False,
             progress: bool = True, without=()):
    """Run trackers on the scene-family corpus; one row per family x seed x tracker.

    Parameters
    ----------
    families : None, str or list of str
        Family names (:data:`semlab.evaluation.FAMILY_NAMES`); None: all.
    seeds : iterable of int or None
        None: the test seeds (:data:`semlab.evaluation.TEST_SEEDS`), or those of ``split``.
    trackers : None, str, list of str, or dict name -> factory
        Names from :data:`semlab.evaluation.TRACKER_NAMES` (None: semlab and the four peers), or
        factories (zero-argument callables returning an object with ``init(frame, roi)`` and
        ``update(frame)``), e.g. ``{"semlab-huber3": lambda: Tracker(huber=3)}``.
    split : {"test", "dev"} or None
        Select the split's seeds (instead of ``seeds``).
    params : dict or None
        :class:`semlab.tracking.Tracker` keywords for the ``semlab`` tracker.
    scheduler : None, "local", "inline" or "tcp://host:port"
        Where the tasks run (see the module docstring).
    n_workers : int or None
        Workers of the LocalCluster (default: the cores, at most 2).
    per_frame : bool
        Also return the per-frame errors.
    progress : bool
        A tqdm bar over the (family, seed) tasks.
    without : str or sequence of str
        Parts taken out of every scene, every other draw kept (an ablation:
        :data:`semlab.evaluation.families.ABLATIONS`, checked against each family before anything runs).

    Returns
    -------
    pandas.DataFrame, or (DataFrame, DataFrame) with ``per_frame``
        Columns ``family, seed, split, tracker, rmse_px, crb_px, lost_fraction, silent_fraction,
        ms_per_frame`` and more (:mod:`semlab.evaluation.scoring` defines them), ordered by
        family, seed and tracker as given. ``df.attrs["sequences"]`` holds each sequence's drawn
        parameters and bound, ``df.attrs["scheduler"]`` where it ran. The per-frame table has
        ``family, seed, tracker, frame, ex, ey, ok, sigma_x, sigma_y, visible, reason``
        (:data:`semlab.evaluation.PER_FRAME_COLUMNS`; ``reason``: why the frame was flagged, ''
        when it is ok).

    Raises
    ------
    ValueError
        Unknown family or tracker (the message lists the valid ones), bad seeds, bad params.
    SchedulerUnreachable
        No dask scheduler at ``scheduler`` within :data:`CONNECT_TIMEOUT_S` s.

    Examples
    --------
    >>> import semlab
    >>> df = semlab.evaluate(families="still", seeds=[0], trackers="ncc", scheduler="inline",
    ...                      progress=False)
    >>> list(df.columns[:4]), len(df)
    (['family', 'seed', 'split', 'tracker'], 1)
    """
    families = resolve_families(families)
    seeds = resolve_seeds(seeds, split)
    factories = resolve_trackers(trackers, params)
    without = check_ablations(families, without)
    jobs = [(f, s) for f in families for s in seeds]
    info = {"scheduler": "inline (this process)"}
    if scheduler == "inline":
        results = _run_inline(jobs, factories, per_frame, progress, without)
    else:
        results = _run_dask(jobs, factories, per_frame, progress, scheduler, n_workers, info, without)
    rows, frames, sequences = [], [], {}
    for (family, seed), (r, pf, meta) in results:
        rows += r
        if pf is not None:
            frames.append(pf)
        sequences[f"{family}/{seed}"] = meta
    order = {"family": {f: i for i, f in enumerate(families)}, "tracker": {t: i for i, t in enumerate(factories)}}
    df = pd.DataFrame(rows, columns=COLUMNS)
    df = df.sort_values(["family", "seed", "tracker"],
                        key=lambda c: c.map(order[c.name]) if c.name in order else c).reset_index(drop=True)
    df.attrs["sequences"] = sequences
    df.attrs["scheduler"] = info["scheduler"]
    if not per_frame:
        return df
    pf = pd.concat(frames, ignore_index=True) if frames else pd.DataFrame(columns=PER_FRAME_COLUMNS)
    pf = pf.sort_values(["family", "seed", "tracker", "frame"],
                        key=lambda c: c.map(order[c.name]) if c.name in order else c).reset_index(drop=True)
    return df, pf
