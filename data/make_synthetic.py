"""Regenerate the seeded synthetic samples in ``data/synthetic/`` (bit-identical).

Each sample is made by :func:`semlab.sim.make_sequence` with a fixed seed and saved as

* ``<name>.tif``        the frames, an (N, 480, 640) uint8 multi-page TIFF (deflate, ImageJ-calibrated
                        with the simulator's pixel size, so ``semlab info`` and Fiji both read it);
* ``<name>_truth.csv``  the ground truth of probe 0's tip: frame, t (s), x, y (px), visible;
* ``<name>.json``       how it was made (kind, seed, arguments), the suggested ROI, the Cramér–Rao
                        bound of one frame's translation estimate in that ROI, the simulator's
                        metadata and the SHA-256 of the raw frame array.

Usage::

    python data/make_synthetic.py           # (re)write data/synthetic/
    python data/make_synthetic.py --check   # regenerate in memory and compare with the files

``--check`` exits 1 when any file would differ. Files are written to a temporary name and renamed,
so an interrupted run never leaves a half-written sample.
"""

from __future__ import annotations

import argparse
import hashlib
import io
import json
import os
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
OUT = HERE / "synthetic"

# name -> (kind, make_sequence keyword arguments). Kept small: ~230 kB per noisy 640x480 frame.
SAMPLES = {
    "synthetic_static": ("static", {"n_frames": 5, "seed": 0}),
    "synthetic_moves_200px": (
        "moves_200px",
        {"seed": 0, "n_cycles": 1, "move_frames": 3, "dwell_frames": 2},
    ),
    "synthetic_clutter_occluder": ("clutter_occluder", {"n_frames": 6, "seed": 0, "motion": "still"}),
}


def _jsonable(v):
    if isinstance(v, dict):
        return {str(k): _jsonable(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_jsonable(x) for x in v]
    if isinstance(v, np.generic):
        return v.item()
    return v


def render(name: str) -> dict[str, bytes]:
    """The three files of one sample, as bytes."""
    import tifffile

    from semlab.sim import make_sequence

    kind, kwargs = SAMPLES[name]
    seq = make_sequence(kind, **kwargs)
    frames = np.ascontiguousarray(seq.frames)
    ps_nm = float(seq.meta["pixel_size_nm"])
    buf = io.BytesIO()
    tifffile.imwrite(
        buf,
        frames,
        imagej=True,
        resolution=(1e3 / ps_nm, 1e3 / ps_nm),  # pixels per um
        metadata={"unit": "um", "axes": "TYX", "finterval": float(seq.meta["frame_period"])},
        compression="zlib",
        compressionargs={"level": 9},
    )
    truth = io.StringIO()
    seq.truth.to_csv(truth, index=False, lineterminator="\n")
    info = {
        "name": name,
        "generator": "semlab.sim.make_sequence",
        "kind": kind,
        "arguments": kwargs,
        "seed": kwargs.get("seed", 0),
        "frames_file": f"{name}.tif",
        "truth_file": f"{name}_truth.csv",
        "shape": list(frames.shape),
        "dtype": str(frames.dtype),
        "frames_sha256": hashlib.sha256(frames.tobytes()).hexdigest(),
        "pixel_size_nm": ps_nm,
        "frame_period_s": float(seq.meta["frame_period"]),
        "roi": [int(v) for v in seq.roi],
        "crb": [float(v) for v in seq.crb],
        "meta": _jsonable(seq.meta),
    }
    text = json.dumps(info, indent=1, sort_keys=True) + "\n"
    return {
        f"{name}.tif": buf.getvalue(),
        f"{name}_truth.csv": truth.getvalue().encode(),
        f"{name}.json": text.encode(),
    }


def _atomic_write(path: Path, data: bytes) -> None:
    tmp = path.with_name(f".{path.name}.tmp{os.getpid()}")
    tmp.write_bytes(data)
    os.replace(tmp, path)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--check", action="store_true", help="compare instead of writing")
    parser.add_argument("names", nargs="*", help=f"samples to make (default all: {', '.join(SAMPLES)})")
    args = parser.parse_args(argv)
    names = args.names or list(SAMPLES)
    unknown = [n for n in names if n not in SAMPLES]
    if unknown:
        parser.error(f"unknown sample(s) {unknown}")
    OUT.mkdir(exist_ok=True)
    differ = []
    for name in names:
        for fname, data in render(name).items():
            path = OUT / fname
            if args.check:
                same = path.exists() and path.read_bytes() == data
                print(f"{'same   ' if same else 'DIFFERS'}  {path.relative_to(HERE.parent)}")
                if not same:
                    differ.append(fname)
            else:
                _atomic_write(path, data)
                print(f"wrote {path.relative_to(HERE.parent)} ({len(data) / 1e6:.2f} MB)")
    if differ:
        print(f"{len(differ)} file(s) differ", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
