"""The servo benchmark runs and prints its tables (a smoke test with the ground-truth 'tracker', one
rig, fast mode: the figures are the benchmark's business, not a unit test's)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

SCRIPT = Path(__file__).resolve().parents[1] / "benchmarks" / "bench_servo.py"


def test_bench_servo_prints_every_section_per_rig_and_the_verdict():
    env = {**os.environ, "SEMLAB_FAST": "1"}
    # the four-probe section (six more characterisations) is left out here: move_probes_to has its own
    # tests, and notebook 10 runs it on the simulated rig
    out = subprocess.run([sys.executable, str(SCRIPT), "--rigs", "prandtl-ishlinskii:3", "--tracker", "oracle",
                          "--workers", "1", "--sections", "1d,2d,ab,macro"],
                         capture_output=True, text=True, timeout=900, check=True, env=env).stdout
    for heading in ("## 1-D 100-px steps", "## 2-D moves to points", "## 1-D beside the paper",
                    "## steps back to where a characterisation ended", "## A->B moves of 200 px",
                    "## macro/nano hand-over", "## verdict"):
        assert heading in out, heading
    assert "prandtl-ishlinskii:3 FF+PID" in out and "PID only" in out
    assert "5.23" in out and "0.4584" in out  # the paper's figures printed beside ours


def test_bench_servo_refuses_an_unknown_rig():
    run = subprocess.run([sys.executable, str(SCRIPT), "--rigs", "piezo:0"], capture_output=True, text=True,
                         timeout=120, check=False)
    assert run.returncode != 0 and "unknown piezo family" in run.stderr
