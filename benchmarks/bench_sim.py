"""Benchmark of the simulated SEM: milliseconds per 640x480 frame with ground truth.

Run: ``.venv/bin/python benchmarks/bench_sim.py`` (``SEMLAB_FAST=1`` for fewer repetitions).
Target (issue 2): <= 20 ms per frame with ground truth on one core, default noise.
Each configuration grabs ``n`` frames from a :class:`semlab.sim.SimulatedRig` (piezo
update, rendering of all probes, noise, truth table) after a warm-up, ``reps`` times;
the table reports the median and the best repetition.
"""

from __future__ import annotations

import os
import time

import numpy as np
import pandas as pd

from semlab.sim import Clutter, SEMNoise, SimulatedRig


def _configs():
    return [
        ("default: 4 probes, default noise", {}),
        ("1 probe, default noise", {"n_manipulators": 1}),
        ("4 probes, noise off", {"noise": SEMNoise.off()}),
        ("low dose (10 pA, exact Poisson)", {"noise": SEMNoise(beam_current_pA=10.0)}),
        ("gray fluctuation + charging", {"noise": SEMNoise(gain_fluctuation=0.15,
                                                            offset_fluctuation_gray=15.0,
                                                            charging_amplitude=0.5)}),
        ("dense clutter + drifting + occluder", {"clutter": Clutter(n_static=120, n_drifting=8,
                                                                     occluder=True)}),
        ("30,000x (6.6 nm/px), 4 probes", {"pixel_size_nm": 6.6}),
        ("uint16 output", {"dtype": np.uint16}),
    ]


def bench(n_frames: int, reps: int) -> pd.DataFrame:
    rows = []
    for name, kw in _configs():
        rig = SimulatedRig(seed=0, **kw)
        ax = rig.axis(0, "x")
        for _ in range(3):  # warm-up (allocations, caches)
            rig.microscope.grab()
        times = []
        for r in range(reps):
            t0 = time.perf_counter()
            for k in range(n_frames):
                ax.apply(10.0 + 5.0 * ((k + r) % 2))  # keep the piezos busy
                rig.microscope.grab()
                _ = rig.truth
            times.append((time.perf_counter() - t0) / n_frames * 1e3)
        rows.append({"configuration": name, "ms_per_frame_median": float(np.median(times)),
                         "ms_per_frame_best": float(np.min(times)),
                         "fps": 1e3 / float(np.median(times)), "frames": n_frames * reps})
    return pd.DataFrame(rows)


def main():
    fast = os.environ.get("SEMLAB_FAST") == "1"
    n_frames, reps = (10, 3) if fast else (40, 5)
    try:  # one core, as the requirement says
        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})
    except (AttributeError, OSError):
        pass
    import cv2
    cv2.setNumThreads(1)
    df = bench(n_frames, reps)
    pd.set_option("display.width", 120)
    print("Simulated SEM, 640x480 frames with ground truth (target <= 20 ms/frame, one core)")
    print(df.to_string(index=False, float_format=lambda v: f"{v:.2f}"))
    return df


if __name__ == "__main__":
    main()
