"""``semlab evaluate``: output and sidecar, bad input, an unreachable scheduler, interruption, and a
dask cluster started by hand (``dask scheduler`` + ``dask worker``)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest

from semlab import cli
from semlab.evaluation import COLUMNS, PER_FRAME_COLUMNS, evaluate

BIN = Path(sys.executable).parent


def _run(args, capsys):
    code = cli.main(["evaluate", *args])
    out, err = capsys.readouterr()
    return code, out, err


def test_writes_the_csv_sidecar_summary_and_figure(tmp_path, capsys):
    out = tmp_path / "r.csv"
    code, stdout, _ = _run(["--families", "still", "--seeds", "0", "--trackers", "ncc,sqdiff", "--scheduler", "inline",
                            "--out", str(out), "--summary", str(tmp_path / "s.csv"), "--figure", str(tmp_path / "f.png"),
                            "--per-frame", str(tmp_path / "p.csv"), "--no-progress"], capsys)
    assert code == 0
    df = pd.read_csv(out)
    assert list(df.columns) == COLUMNS and df["tracker"].tolist() == ["ncc", "sqdiff"]
    meta = json.loads((tmp_path / "r.csv.json").read_text())
    assert meta["seeds"] == [0] and meta["splits"] == {"0": "test"} and meta["trackers"] == ["ncc", "sqdiff"]
    assert "pixel_size_nm" in meta["families"]["still"]["ranges"] and "still/0" in meta["sequences"]
    assert meta["output"]["rows"] == 2 and len(meta["output"]["sha256"]) == 64
    assert (tmp_path / "f.png").stat().st_size > 1000 and len(pd.read_csv(tmp_path / "p.csv")) == 100
    assert "| still | ncc |" in stdout
    assert not list(tmp_path.glob(".*partial*"))


def test_default_cluster_run_without_extras(tmp_path, capsys):
    # the LocalCluster (two worker processes) and only the CSV and its sidecar
    out = tmp_path / "r.csv"
    code, stdout, _ = _run(["--families", "shapes", "--seeds", "1", "--trackers", "sqdiff", "--workers", "1",
                            "--out", str(out), "--no-progress"], capsys)
    assert code == 0 and sorted(p.name for p in tmp_path.iterdir()) == ["r.csv", "r.csv.json"]
    assert "LocalCluster(1 workers" in json.loads((tmp_path / "r.csv.json").read_text())["scheduler"]
    assert "| shapes | sqdiff |" in stdout


@pytest.mark.parametrize("args, valid", [(["--families", "still,marsh"], "still, moves_200px"),
                                         (["--trackers", "semlab,kcf"], "semlab, paper, ncc")])
def test_unknown_names_are_one_line_listing_the_valid_ones(args, valid, tmp_path, capsys):
    code, _, err = _run([*args, "--out", str(tmp_path / "r.csv")], capsys)
    assert code == cli.EXIT_USAGE
    assert len(err.strip().splitlines()) == 1 and valid in err
    assert not (tmp_path / "r.csv").exists()


def test_without_takes_the_part_out_and_says_so(tmp_path, capsys):
    out = tmp_path / "r.csv"
    code, _, _ = _run(["--families", "clutter", "--seeds", "0", "--trackers", "ncc", "--scheduler", "inline",
                       "--without", "occluder", "--out", str(out), "--no-progress", "--quiet"], capsys)
    meta = json.loads((tmp_path / "r.csv.json").read_text())
    assert code == 0 and meta["without"] == ["occluder"] and meta["sequences"]["clutter/0"]["without"] == ["occluder"]
    # a part the family cannot take out (its substrate is not the simulator's clutter): refused before any work
    code, _, err = _run(["--families", "still,substrates", "--without", "texture", "--out", str(out)], capsys)
    assert code == cli.EXIT_USAGE and "'substrates' cannot take out ['texture']" in err


def test_the_per_frame_csv_says_why_each_frame_was_flagged(tmp_path, capsys):
    # low dose: semlab flags every frame after frame 0; the result CSV keeps its columns
    out, frames_csv = tmp_path / "r.csv", tmp_path / "p.csv"
    code, _, _ = _run(["--families", "low_dose", "--seeds", "0", "--trackers", "semlab,ncc", "--scheduler", "inline",
                       "--out", str(out), "--per-frame", str(frames_csv), "--no-progress"], capsys)
    assert code == 0 and list(pd.read_csv(out).columns) == COLUMNS
    frames = pd.read_csv(frames_csv, keep_default_na=False)
    assert list(frames.columns) == PER_FRAME_COLUMNS and PER_FRAME_COLUMNS[-1] == "reason"
    ok = frames["ok"].astype(str) == "True"
    flagged = frames[~ok & (frames["frame"] != 0)]
    assert len(flagged) > 0 and (flagged["reason"] != "").all() and (frames.loc[ok, "reason"] == "").all()


@pytest.mark.parametrize("args", [["--seeds", "5-2"], ["--param", "huber=-1"], ["--trackers", "ncc", "--param", "huber=3"],
                                  ["--seeds", "0", "--split", "dev"]])
def test_bad_seeds_and_params_are_usage_errors(args, tmp_path, capsys):
    code, _, err = _run([*args, "--out", str(tmp_path / "r.csv")], capsys)
    assert code == cli.EXIT_USAGE and err.strip()


def test_an_unreachable_scheduler_is_a_clear_error_within_30_s(tmp_path, capsys):
    address = "tcp://127.0.0.1:9"  # the discard port: nothing listens there
    t0 = time.perf_counter()
    code, _, err = _run(["--families", "still", "--seeds", "0", "--scheduler", address, "--out", str(tmp_path / "r.csv")],
                        capsys)
    assert time.perf_counter() - t0 < 30
    assert code == cli.EXIT_SCHEDULER and address in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "r.csv").exists()


def test_an_interrupted_run_leaves_no_complete_looking_output(tmp_path, capsys, monkeypatch):
    from semlab.evaluation import runner

    calls = []
    real = runner.evaluate_sequence

    def interrupted(family, seed, factories, per_frame=False, without=()):
        calls.append(seed)
        if len(calls) == 2:
            raise KeyboardInterrupt
        return real(family, seed, factories, per_frame, without)

    monkeypatch.setattr(runner, "evaluate_sequence", interrupted)
    out = tmp_path / "r.csv"
    code, _, err = _run(["--families", "still", "--seeds", "0-2", "--trackers", "ncc", "--scheduler", "inline",
                         "--out", str(out), "--no-progress"], capsys)
    assert code == cli.EXIT_INTERRUPTED and "interrupted" in err
    assert list(tmp_path.iterdir()) == []


def test_sigint_to_a_running_evaluate_leaves_nothing(tmp_path):
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    log = tmp_path / "stderr.txt"
    with open(log, "w") as err:
        # the semlab command, with Python's Ctrl-C handler installed even when started as a background
        # job (which inherits SIGINT ignored, and Python then leaves it ignored)
        launcher = ("import signal, sys; signal.signal(signal.SIGINT, signal.default_int_handler); "
                    "from semlab.cli import main; sys.exit(main(sys.argv[1:]))")
        proc = subprocess.Popen([sys.executable, "-c", launcher, "evaluate", "--families", "moves_200px", "--seeds",
                                 "0-9", "--scheduler", "inline", "--out", str(out_dir / "r.csv")],
                                stdout=subprocess.DEVNULL, stderr=err, text=True)
    try:
        for _ in range(600):  # the progress bar appears once the run has started
            if "corpus" in log.read_text():
                break
            time.sleep(0.1)
        time.sleep(1.0)
        proc.send_signal(signal.SIGINT)
        proc.wait(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == cli.EXIT_INTERRUPTED, log.read_text()[-500:]
    assert list(out_dir.iterdir()) == []


@pytest.fixture
def hand_started_cluster(tmp_path):
    """A ``dask scheduler`` and one ``dask worker`` as separate processes, as a user starts them."""
    sched_file = tmp_path / "scheduler.json"
    env = {**os.environ, "PYTHONWARNINGS": "ignore"}
    procs = [subprocess.Popen([str(BIN / "dask"), "scheduler", "--host", "127.0.0.1", "--port", "0",
                               "--no-dashboard", "--scheduler-file", str(sched_file)],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env)]
    try:
        for _ in range(300):
            if sched_file.exists() and sched_file.stat().st_size:
                break
            time.sleep(0.1)
        address = json.loads(sched_file.read_text())["address"]
        procs.append(subprocess.Popen([str(BIN / "dask"), "worker", address, "--nworkers", "1", "--nthreads", "1",
                                       "--no-dashboard", "--no-nanny"],
                                      stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env))
        from distributed import Client

        with Client(address, timeout=30) as c:
            c.wait_for_workers(1, timeout=60)
        yield address
    finally:
        for p in reversed(procs):
            p.terminate()
        for p in reversed(procs):
            try:
                p.wait(timeout=20)
            except subprocess.TimeoutExpired:
                p.kill()


def test_runs_on_a_scheduler_and_worker_started_by_hand(hand_started_cluster):
    kw = {"families": ["still", "semi_real"], "seeds": [1], "trackers": "sqdiff", "progress": False}
    remote = evaluate(scheduler=hand_started_cluster, **kw)
    local = evaluate(scheduler="inline", **kw)
    assert remote.attrs["scheduler"].startswith(f"dask scheduler {hand_started_cluster}")
    timing = ["ms_per_frame"]
    pd.testing.assert_frame_equal(remote.drop(columns=timing), local.drop(columns=timing))
