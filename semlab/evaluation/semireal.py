"""The semi-real family: the real FIB/SEM needle of ``data/real-sem/`` over real backgrounds.

Sources (all MIT, DeMarcoLab; ``data/real-sem/PROVENANCE.md``):

* **needle**: the tungsten EasyLift needle of ``contact_brightness_seq``, cut out of one of the
  six frames taken before it touches anything (the reference frame ``needle_liftout_land_ib`` and
  frames 0-4; from frame 5 on it merges with the lamella), with :func:`semlab.sim.composite.cut_out_object`;
* **backgrounds**, each from a frame other than the needle's: the right-hand part of another
  ``contact_brightness`` frame (trench, lamella, milled surface; the needle never reaches it),
  the landing post and the vacuum beside it in ``fibsem/detection_test_image_2.tif`` (another
  scene, 97.66 nm/px), and the landing post of ``charge_neutralisation_seq`` (the mean of its
  ten frames: a static scene, still noisy), cropped at a drawn place and flipped at random.

The needle is moved by exact Fourier shifts (:class:`semlab.sim.composite.ShiftableLayer`) along
a smooth random wander, composited over the background and given shot noise at a drawn dose
(8-80 detected electrons per pixel at full scale: from a fast scan to the simulator's standard
dose). The real frames are denoised first (:func:`_real_frame`), so that the composite is a clean
image and the added shot noise is the frames' noise, as the bound assumes.
"""

from __future__ import annotations

import functools

import cv2
import numpy as np
import pandas as pd

from semlab.sim.composite import (
    ShiftableLayer,
    add_shot_noise,
    composite,
    composite_crb,
    cut_out_object,
)
from semlab.sim.sequences import Sequence

from . import motion
from .draws import Choice, Draws, Int, LogUniform, Uniform

__all__ = ["BACKGROUNDS", "NEEDLE_FRAMES", "SEMI_REAL_RANGES", "background_image", "needle_cut_out",
           "semi_real_sequence"]

_CONTACT = "real-sem/contact_brightness_seq/{}.png"
#: The frame taken before the first move lives beside the motion sequence, not in it (data/README.md).
_REFERENCE = "real-sem/contact_brightness_reference/{}.png"
#: Frames of contact_brightness_seq in which the needle stands free (before frame 5's contact).
NEEDLE_FRAMES = ("needle_liftout_land_ib",) + tuple(f"liftout_contact_brightness_{i}_ib" for i in range(5))
#: Needle segmentation: a pixel inside the needle's shaft in every source frame, and the gray level
#: between the needle (210-255 after smoothing) and its surroundings (70-190: trench, milled surface).
NEEDLE_SEED_XY = (100, 600)
NEEDLE_THRESHOLD = 175.0
#: Background name -> (file under data/, crop region (x0, y0, x1, y1) in that file).
BACKGROUNDS = {
    "contact_right": (None, (565, 0, 1075, 717)),  # another contact frame: the needle ends at x <= 550
    "detection_post": ("real-sem/fibsem/detection_test_image_2.tif", (780, 0, 1536, 1024)),
    "detection_vacuum": ("real-sem/fibsem/detection_test_image_2.tif", (0, 0, 740, 420)),
    "neutralisation_post": ("real-sem/charge_neutralisation_seq", (300, 0, 768, 512)),
}
#: Frame size (px) of the semi-real sequences and where the needle's end face sits in frame 0.
WIDTH, HEIGHT = 400, 300
ANCHOR = (250.0, 150.0)
#: Largest displacement of the needle (px): the layer's canvas reaches beyond the frame by more.
MAX_SHIFT_PX = 36.0
#: Gray level of the flat background of ``noise_free`` sequences (the ground-truth tests).
NOISE_FREE_BACKGROUND = 60.0
#: Non-local-means strength (gray levels) that removes the real frames' own noise: their
#: high-pass noise is 12-17 gray levels; h = 15 leaves ~2 (h = 10 left 11).
DENOISE_H = 15.0

SEMI_REAL_RANGES = {
    "n_frames": Int(40, 40),
    "needle_frame": Choice(NEEDLE_FRAMES),
    "background": Choice(tuple(BACKGROUNDS)),
    "crop_x_fraction": Uniform(0.0, 1.0),
    "crop_y_fraction": Uniform(0.0, 1.0),
    "flip_lr": Choice((False, True)),
    "flip_ud": Choice((False, True)),
    "anchor_offset_x_px": Uniform(-15.0, 15.0),
    "anchor_offset_y_px": Uniform(-15.0, 15.0),
    "dose_e_per_px": LogUniform(8.0, 80.0),
    "speed_px_per_frame": Uniform(0.5, 2.0),
    "persistence": Uniform(0.7, 0.95),
    "radius_px": Uniform(10.0, 30.0),
}


@functools.cache
def _real_frame(rel: str) -> np.ndarray:
    """A real frame under ``data/``, denoised (cached per process).

    The frames' own noise is removed by OpenCV's non-local means (strength
    :data:`DENOISE_H`: it keeps the edges and the milled texture): left in, it would be frozen
    into the composite, move with the needle and count in the bound as texture no tracker can
    use under the added shot noise.
    """
    from semlab.io import data_path, read_image

    path = data_path(rel)
    if path.is_dir():  # a static sequence: the mean of its frames (less noise, same scene)
        from semlab.io import read_frames

        img = read_frames(path).frames.astype(np.float64).mean(axis=0)
    else:
        img = read_image(path).astype(np.float64)
    img8 = np.clip(np.rint(img), 0, 255).astype(np.uint8)
    return cv2.fastNlMeansDenoising(img8, None, h=DENOISE_H, templateWindowSize=7,
                                    searchWindowSize=21).astype(np.float64)


def _contact_path(frame_name: str) -> str:
    """The data/ path of one of :data:`NEEDLE_FRAMES`."""
    return (_REFERENCE if frame_name == NEEDLE_FRAMES[0] else _CONTACT).format(frame_name)


@functools.cache
def needle_cut_out(frame_name: str):
    """``(source, alpha, anchor_xy)`` of the needle in one contact frame (cached per process).

    ``anchor_xy`` is the middle of the needle's end face: the rightmost column of the matte
    (alpha > 0.5) and the median row of the matte within 6 px of it.
    """
    src = _real_frame(_contact_path(frame_name))
    alpha = cut_out_object(src, NEEDLE_SEED_XY, threshold=NEEDLE_THRESHOLD)
    ys, xs = np.nonzero(alpha > 0.5)
    x_end = xs.max()
    anchor = (float(x_end), float(np.median(ys[xs >= x_end - 6])))
    return src, alpha, anchor


def background_image(name: str, needle_frame: str, crop_fraction, flip_lr: bool, flip_ud: bool) -> np.ndarray:
    """A ``HEIGHT x WIDTH`` crop of real background ``name`` (never from the needle's own frame)."""
    rel, (x0, y0, x1, y1) = BACKGROUNDS[name]
    if rel is None:  # the next contact frame after the needle's, cyclically
        other = NEEDLE_FRAMES[(NEEDLE_FRAMES.index(needle_frame) + 1) % len(NEEDLE_FRAMES)]
        rel = _contact_path(other)
    img = _real_frame(rel)[y0:y1, x0:x1]
    fx, fy = crop_fraction
    cx = round(fx * (img.shape[1] - WIDTH))
    cy = round(fy * (img.shape[0] - HEIGHT))
    crop = img[cy:cy + HEIGHT, cx:cx + WIDTH]
    if flip_lr:
        crop = crop[:, ::-1]
    if flip_ud:
        crop = crop[::-1, :]
    return np.ascontiguousarray(crop)


def needle_layer(frame_name: str, anchor_offset=(0.0, 0.0)) -> tuple[ShiftableLayer, tuple[float, float]]:
    """The needle's shiftable layer with its end face near ``ANCHOR + anchor_offset`` (whole px).

    Returns the layer and where the end face's middle is in frame 0 (px).
    """
    src, alpha, (ax, ay) = needle_cut_out(frame_name)
    at = (ANCHOR[0] + anchor_offset[0], ANCHOR[1] + anchor_offset[1])
    x0, y0 = round(ax - at[0]), round(ay - at[1])
    layer = ShiftableLayer(src, alpha, (x0, y0, WIDTH, HEIGHT), max_shift_px=MAX_SHIFT_PX)
    return layer, (ax - x0, ay - y0)


def semi_real_sequence(d: Draws) -> Sequence:
    """One semi-real sequence from the family's draws (see the module docstring)."""
    from .families import FRAME_PERIOD, ROI_SIZE, combine_bounds, crb_sample_frames, moved_roi

    n = d("n_frames")
    needle = d("needle_frame")
    bg = background_image(d("background"), needle, (d("crop_x_fraction"), d("crop_y_fraction")),
                          d("flip_lr"), d("flip_ud"))
    layer, (tx0, ty0) = needle_layer(needle, (d("anchor_offset_x_px"), d("anchor_offset_y_px")))
    dose = d("dose_e_per_px")
    path = motion.wander(n, d.rng, speed_px=d("speed_px_per_frame"), persistence=d("persistence"),
                         radius_px=d("radius_px"))
    frames = np.empty((n, HEIGHT, WIDTH), np.float32)
    noise_rng = np.random.default_rng(d.rng.integers(2**63))
    noise_free = getattr(d, "noise_free", False)
    if noise_free:  # the ground-truth tests' view: the needle alone over a flat background
        bg = np.full_like(bg, NOISE_FREE_BACKGROUND)
    for k, (dx, dy) in enumerate(path):
        clean = composite(bg, layer, dx, dy)
        frames[k] = clean if noise_free else add_shot_noise(clean, dose, noise_rng)
    truth = pd.DataFrame({"frame": np.arange(n), "t": (np.arange(n) + 0.5) * FRAME_PERIOD,
                          "x": tx0 + path[:, 0], "y": ty0 + path[:, 1], "visible": True})
    half = (ROI_SIZE - 1) / 2
    roi = (round(tx0 - half), round(ty0 - half), ROI_SIZE, ROI_SIZE)
    roi = moved_roi(roi, 0, 0, WIDTH, HEIGHT)
    bounds = []
    for k in crb_sample_frames(n):
        dx, dy = path[k]
        sx, sy = composite_crb(bg, layer, (dx, dy), moved_roi(roi, dx, dy, WIDTH, HEIGHT), dose)
        bounds.append((k, sx, sy))
    meta = {"width": WIDTH, "height": HEIGHT, "pixel_size_nm": 52.08, "frame_period": FRAME_PERIOD,
            "dose_e_per_px": dose, "crb_frames": [{"frame": k, "crb_x_px": sx, "crb_y_px": sy}
                                                  for k, sx, sy in bounds]}
    return Sequence(frames=frames, truth=truth, roi=roi, crb=combine_bounds(bounds), meta=meta)
