"""The multi-seed benchmark script runs and prints its tables (a smoke test: the figures themselves
are the benchmark's business, not a unit test's)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

SCRIPT = Path(__file__).resolve().parents[1] / "benchmarks" / "bench_tracking_seeds.py"


def test_bench_tracking_seeds_prints_both_trackers_and_the_comparison():
    out = subprocess.run([sys.executable, str(SCRIPT), "--seeds", "0", "--kinds", "static", "--param", "band_px=3",
                          "--workers", "1"], capture_output=True, text=True, timeout=300, check=True).stdout
    assert "# default: RMSE / one-frame CRB per seed" in out
    assert "# variant band_px=3: RMSE / one-frame CRB per seed" in out
    assert "# seeds on which the variant is better (of 1): static" in out
    # one row per seed: the static spread over the bound is a positive number of order 1
    row = next(line for line in out.splitlines() if line.startswith("0 "))
    assert 0.3 < float(row.split()[1]) < 5.0


def test_bench_tracking_seeds_refuses_a_malformed_param():
    run = subprocess.run([sys.executable, str(SCRIPT), "--param", "band_px"], capture_output=True, text=True, timeout=60,
                         check=False)
    assert run.returncode != 0 and "key=value" in run.stderr
