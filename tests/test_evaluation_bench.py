"""The small corpus benchmark (``bench_corpus.py --seeds 0-1``) runs and prints its table: CI's run of it.

A smoke test (the figures are the benchmark's business): every family and tracker has its row, and
the wall time is reported against the 3-minute budget. About 1.5-2.5 min on 2 cores.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from semlab.evaluation import DEFAULT_TRACKERS, FAMILY_NAMES

SCRIPT = Path(__file__).resolve().parents[1] / "benchmarks" / "bench_corpus.py"


@pytest.mark.slow
@pytest.mark.timeout(600)
def test_small_corpus_benchmark_prints_every_family_and_tracker():
    out = subprocess.run([sys.executable, str(SCRIPT), "--seeds", "0-1"], capture_output=True, text=True,
                         timeout=540, check=True).stdout
    assert f"# corpus: {len(FAMILY_NAMES)} families x 2 seeds (test) x {len(DEFAULT_TRACKERS)} trackers" in out
    for fam in FAMILY_NAMES:
        for trk in DEFAULT_TRACKERS:
            assert f"| {fam} | {trk} |" in out
    assert "# wall time" in out and "3-min budget" in out
