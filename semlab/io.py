"""Reading SEM frames from disk: image files, folders, globs, multi-page TIFFs and videos.

The one entry point a notebook or the command line needs is :func:`read_frames`; it returns a
:class:`FrameSequence` holding an ``(N, H, W)`` stack of 2-D frames (``frame[y, x]``), the file each
frame came from, and the pixel size in nm together with where that number came from.

Conversions (documented once, applied everywhere)
-------------------------------------------------
* ``uint8`` and ``uint16`` frames keep their dtype and values (a 16-bit detector signal stays 16-bit;
  the tracker accepts both).
* ``bool`` becomes ``uint8`` (0 / 255).
* Floating-point frames become ``float64``; other integer types (int8/int16/int32/uint32/...) become
  ``float64`` with their values unchanged.
* RGB / RGBA / BGR inputs become luminance, ``Y = 0.299 R + 0.587 G + 0.114 B`` (ITU-R BT.601, the
  weights of OpenCV's ``COLOR_BGR2GRAY``), rounded back to the input dtype; alpha is dropped. When the
  three channels are equal (a grey SEM image saved as RGB, the usual case) the first channel is
  returned exactly. Two-channel (grey + alpha) images keep the grey channel.
* Videos are decoded with OpenCV (``cv2.VideoCapture``) and converted to ``uint8`` luminance.
  Lossy video codecs change pixel values; prefer lossless frame files for measurements.

Pixel size
----------
Read from vendor TIFF metadata (FEI / Thermo Fisher, Zeiss, ImageJ calibration) by
:mod:`semlab.pixelsize`.

An explicit ``pixel_size_nm=`` overrides the metadata. PNG, JPEG and video files carry no pixel size;
then :attr:`FrameSequence.pixel_size_nm` is ``None`` and :attr:`FrameSequence.pixel_size_source` says so.

Errors
------
Every problem with an input raises :class:`FrameReadError` (a :class:`ValueError`) whose message is one
line naming the file and the reason, e.g. ``"scan_07.png: truncated or corrupt PNG"``.
"""

from __future__ import annotations

import contextlib
import glob as _glob
import logging
import math
import os
import re
import warnings
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .pixelsize import tiff_pixel_size

__all__ = [
    "IMAGE_SUFFIXES",
    "ORDERS",
    "PIXEL_SIZE_HINT",
    "VIDEO_SUFFIXES",
    "FrameReadError",
    "FrameSequence",
    "data_path",
    "expand_inputs",
    "list_samples",
    "load_sample",
    "natural_order",
    "natural_sort_key",
    "read_frames",
    "read_image",
    "read_pixel_size",
]

PathLike = str | os.PathLike

TIFF_SUFFIXES = (".tif", ".tiff")
PNG_SUFFIXES = (".png",)
JPEG_SUFFIXES = (".jpg", ".jpeg")
IMAGE_SUFFIXES = TIFF_SUFFIXES + PNG_SUFFIXES + JPEG_SUFFIXES + (".bmp",)
VIDEO_SUFFIXES = (".avi", ".mp4", ".mov", ".mkv", ".m4v", ".mpg", ".mpeg", ".wmv", ".webm")
SUPPORTED_SUFFIXES = IMAGE_SUFFIXES + VIDEO_SUFFIXES

_BT601 = np.array([0.299, 0.587, 0.114])

#: How :func:`read_frames` orders its files: ``"natural"`` sorts them all (``frame_2`` before ``frame_10``),
#: ``"given"`` keeps a list as given (folders and patterns still contribute their files in natural order).
ORDERS = ("natural", "given")

#: The hint an unknown pixel size carries; the command line swaps it for the flag its user types.
PIXEL_SIZE_HINT = "pass pixel_size_nm"


class FrameReadError(ValueError):
    """An input file or folder cannot be turned into frames.

    Attributes
    ----------
    path : str
        The file, folder or pattern at fault.
    reason : str
        Why, in a few words.
    """

    def __init__(self, path: PathLike, reason: str):
        self.path = str(path)
        self.reason = reason
        super().__init__(f"{self.path}: {reason}")


@dataclass
class FrameSequence:
    """A stack of frames read from disk, with where they came from and their pixel size.

    Attributes
    ----------
    frames : (N, H, W) ndarray
        The frames, ``frames[i][y, x]``; dtype ``uint8``, ``uint16`` or ``float64`` (see module notes).
    paths : list of pathlib.Path
        The input file of each frame (length N; a multi-page TIFF or a video repeats its path).
    pixel_size_nm : float or None
        Size of one pixel in nm, or None when unknown.
    pixel_size_source : str
        Where ``pixel_size_nm`` came from, e.g. ``"FEI metadata [Scan] PixelWidth (x.tif)"``,
        ``"explicit pixel_size_nm"`` or ``"unknown: ..."``.
    meta : dict
        Everything else: ``files`` (the distinct input files in order), ``page`` (index of each frame
        inside its file), ``format`` per file, the vendor metadata of the first file (``vendor``),
        ``pixel_size_nm_per_file``, and for samples ``roi``, ``crb``, ``kind``, ...
    truth : pandas.DataFrame or None
        Ground truth for synthetic samples (columns frame, x, y in px), else None.
    """

    frames: np.ndarray
    paths: list[Path]
    pixel_size_nm: float | None = None
    pixel_size_source: str = "unknown"
    meta: dict[str, Any] = field(default_factory=dict)
    truth: Any = None

    def __len__(self) -> int:
        return int(self.frames.shape[0])

    def __getitem__(self, i):
        return self.frames[i]

    def __iter__(self) -> Iterator[np.ndarray]:
        return iter(self.frames)

    @property
    def shape(self) -> tuple[int, int, int]:
        """``(N, H, W)``."""
        return tuple(self.frames.shape)  # type: ignore[return-value]

    @property
    def dtype(self) -> np.dtype:
        return self.frames.dtype

    @property
    def files(self) -> list[Path]:
        """The distinct input files, in reading order."""
        return list(dict.fromkeys(self.paths))

    @property
    def roi(self):
        """The sample's suggested ROI ``(x, y, w, h)`` when it has one, else None."""
        return self.meta.get("roi")

    def to_nm(self, px):
        """Convert a length or coordinate in px to nm (NaN when the pixel size is unknown)."""
        scale = np.nan if self.pixel_size_nm is None else self.pixel_size_nm
        return np.asarray(px, dtype=float) * scale

    def __repr__(self) -> str:
        n, h, w = self.frames.shape
        ps = "unknown" if self.pixel_size_nm is None else f"{self.pixel_size_nm:.4g} nm"
        return (
            f"FrameSequence({n} frames of {w}x{h} px, {self.frames.dtype}, "
            f"pixel size {ps}, from {len(self.files)} file(s))"
        )


# ----------------------------------------------------------------------------------------------
# locating inputs


def natural_sort_key(path: PathLike) -> tuple:
    """Sort key putting ``frame_2`` before ``frame_10`` (digit runs compare as integers).

    Examples
    --------
    >>> sorted(["f_10.png", "f_2.png", "f_1.png"], key=natural_sort_key)
    ['f_1.png', 'f_2.png', 'f_10.png']
    """
    parts = re.split(r"(\d+)", str(path).lower())
    # re.split with a capture group alternates text, digits, text, ...: positions never mix types.
    return tuple(int(p) if i % 2 else p for i, p in enumerate(parts))


def _has_glob(s: str) -> bool:
    return any(c in s for c in "*?[")


def _folder_files(folder: Path) -> list[Path]:
    files = [
        p
        for p in folder.iterdir()
        if p.is_file() and not p.name.startswith(".") and p.suffix.lower() in SUPPORTED_SUFFIXES
    ]
    return sorted(files, key=lambda p: natural_sort_key(p.name))


def natural_order(paths: Iterable[PathLike]) -> list[Path]:
    """``paths`` sorted by :func:`natural_sort_key` of their full path (stable for equal keys).

    A shell expands ``frame_*.png`` in character order (``frame_0, frame_1, frame_10, frame_2``); this puts
    ``frame_2`` before ``frame_10``, and files of one folder together.
    """
    return sorted((Path(p) for p in paths), key=natural_sort_key)


def expand_inputs(inputs: PathLike | Iterable[PathLike], *, order: str = "natural") -> list[Path]:
    """Turn a path, a folder, a glob pattern or a list of these into an ordered list of files.

    Folders contribute their supported image/video files in natural order (hidden files and other
    files such as LICENSE or README are skipped); glob patterns their matches in natural order;
    files themselves.

    Parameters
    ----------
    inputs : str, path-like, or list of them
    order : {"natural", "given"}
        ``"natural"`` (default) sorts all the files naturally (:func:`natural_order`), so a list that a
        shell expanded as ``0, 1, 10, 2`` is read as ``0, 1, 2, ..., 10``; ``"given"`` keeps the order of
        the list.

    Raises
    ------
    FrameReadError
        For a missing file, an empty folder, a pattern that matches nothing, an unsupported format.
    ValueError
        An unknown ``order``.
    """
    if order not in ORDERS:
        raise ValueError(f"order must be one of {ORDERS}, got {order!r}")
    if isinstance(inputs, (str, os.PathLike)):
        items = [inputs]
    else:
        items = list(inputs)
        if not items:
            raise FrameReadError("<inputs>", "no input files given")
    out: list[Path] = []
    for item in items:
        s = os.fspath(item)
        p = Path(s).expanduser()
        if p.is_dir():
            files = _folder_files(p)
            if not files:
                raise FrameReadError(
                    p, "folder contains no image or video files (" + ", ".join(IMAGE_SUFFIXES) + ")"
                )
            out.extend(files)
        elif p.exists():
            if not p.is_file():
                raise FrameReadError(p, "not a regular file")
            _check_suffix(p)
            out.append(p)
        elif _has_glob(s):
            matches = [Path(m) for m in _glob.glob(os.path.expanduser(s))]
            matches = [m for m in matches if m.is_file() and m.suffix.lower() in SUPPORTED_SUFFIXES]
            if not matches:
                raise FrameReadError(s, "pattern matches no image or video files")
            out.extend(sorted(matches, key=natural_sort_key))
        else:
            raise FrameReadError(p, "no such file or folder")
    return natural_order(out) if order == "natural" else out


def _check_suffix(p: Path) -> None:
    if p.suffix.lower() not in SUPPORTED_SUFFIXES:
        shown = p.suffix or "(no extension)"
        raise FrameReadError(
            p,
            f"unsupported format {shown!s}; supported: images "
            + " ".join(IMAGE_SUFFIXES)
            + ", videos "
            + " ".join(VIDEO_SUFFIXES),
        )


# ----------------------------------------------------------------------------------------------
# dtype / colour conversion


def _to_gray(img: np.ndarray, *, bgr: bool) -> np.ndarray:
    """Colour (H, W, C) → luminance (H, W) in the input dtype; see the module notes."""
    if img.ndim == 2:
        return img
    c = img.shape[-1]
    if c == 1:
        return img[..., 0]
    if c == 2:  # grey + alpha
        return img[..., 0]
    rgb = img[..., :3]
    if bgr:
        rgb = rgb[..., ::-1]
    if np.array_equal(rgb[..., 0], rgb[..., 1]) and np.array_equal(rgb[..., 0], rgb[..., 2]):
        return np.ascontiguousarray(rgb[..., 0])
    y = rgb.astype(np.float64) @ _BT601
    if np.issubdtype(img.dtype, np.integer):
        info = np.iinfo(img.dtype)
        return np.clip(np.rint(y), info.min, info.max).astype(img.dtype)
    return y


def _normalise_dtype(img: np.ndarray) -> np.ndarray:
    if img.dtype == np.uint8 or img.dtype == np.uint16 or img.dtype == np.float64:
        return img
    if img.dtype == bool:
        return img.astype(np.uint8) * np.uint8(255)
    if np.issubdtype(img.dtype, np.floating) or np.issubdtype(img.dtype, np.integer):
        return img.astype(np.float64)
    raise TypeError(f"unsupported pixel type {img.dtype}")


# ----------------------------------------------------------------------------------------------
# readers


class _CollectWarnings(logging.Handler):
    def __init__(self):
        super().__init__(logging.WARNING)
        self.messages: list[str] = []

    def emit(self, record):
        self.messages.append(record.getMessage())


_CORRUPT_HINTS = (
    "invalid page offset",
    "failed to read",
    "truncat",
    "corrupt",
    "invalid tag",
    "unexpected end",
)


@contextlib.contextmanager
def _tifffile_warnings():
    logger = logging.getLogger("tifffile")
    handler = _CollectWarnings()
    old_propagate = logger.propagate
    logger.addHandler(handler)
    logger.propagate = False
    try:
        yield handler.messages
    finally:
        logger.removeHandler(handler)
        logger.propagate = old_propagate


def _series_frames(series) -> tuple[np.ndarray, bool]:
    """One tifffile series → (N, H, W) or (N, H, W, S) and whether S (colour samples) is present.

    Frames = every axis but Y, X and S, flattened in order (pages, time, z, channels...).
    """
    data = series.asarray()
    axes = series.axes
    samples = "S" in axes
    keep = [axes.index("Y"), axes.index("X")] + ([axes.index("S")] if samples else [])
    lead = [i for i in range(data.ndim) if i not in keep]
    data = np.transpose(data, lead + keep)
    return data.reshape((-1,) + data.shape[len(lead) :]), samples


def _read_tiff(p: Path) -> tuple[np.ndarray, dict]:
    import tifffile

    try:
        with _tifffile_warnings() as messages, tifffile.TiffFile(p) as tif:
            if not tif.series:
                raise FrameReadError(p, "TIFF holds no image data")
            data, samples = _series_frames(tif.series[0])
            parts, skipped = [data], 0
            # Pages written one by one form one series each; further series of the same frame
            # shape and type are more frames, anything else (thumbnails, masks) is skipped.
            for series in tif.series[1:]:
                more, more_samples = _series_frames(series)
                if (
                    more_samples == samples
                    and more.shape[1:] == data.shape[1:]
                    and more.dtype == data.dtype
                ):
                    parts.append(more)
                else:
                    skipped += 1
            if len(parts) > 1:
                data = np.concatenate(parts)
            width = data.shape[2]
            ps, src, vendor = tiff_pixel_size(tif, tif.pages.first, width)
            bad = [m for m in messages if any(h in m.lower() for h in _CORRUPT_HINTS)]
            if bad:
                raise FrameReadError(p, f"truncated or corrupt TIFF ({bad[0].strip()})")
    except FrameReadError:
        raise
    except (tifffile.TiffFileError, ValueError, OSError, EOFError, KeyError, IndexError) as e:
        reason = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
        raise FrameReadError(p, f"unreadable or truncated TIFF ({reason})") from None
    if samples:
        data = np.stack([_to_gray(f, bgr=False) for f in data])
    info = {"format": "TIFF", "pixel_size_nm": ps, "pixel_size_source": src, **vendor}
    if samples:
        info["converted"] = "RGB to luminance (BT.601)"
    if skipped:
        info["skipped_series"] = skipped
    return data, info


@contextlib.contextmanager
def _quiet_cv2():
    import cv2

    try:
        old = cv2.utils.logging.getLogLevel()
        cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_SILENT)
    except AttributeError:  # pragma: no cover - very old OpenCV
        yield
        return
    try:
        yield
    finally:
        cv2.utils.logging.setLogLevel(old)


def _read_raster(p: Path) -> tuple[np.ndarray, dict]:
    """PNG / JPEG / BMP through OpenCV, with explicit truncation checks."""
    import cv2

    try:
        raw = p.read_bytes()
    except OSError as e:
        raise FrameReadError(p, f"cannot read file ({e.strerror or e})") from None
    if not raw:
        raise FrameReadError(p, "file is empty")
    suffix = p.suffix.lower()
    kind = {".png": "PNG", ".jpg": "JPEG", ".jpeg": "JPEG", ".bmp": "BMP"}[suffix]
    if kind == "PNG":
        if not raw.startswith(b"\x89PNG\r\n\x1a\n"):
            raise FrameReadError(p, "not a PNG file (bad signature)")
        if b"IEND" not in raw[-4096:]:
            raise FrameReadError(p, "truncated or corrupt PNG (no IEND chunk at the end)")
    elif kind == "JPEG":
        if not raw.startswith(b"\xff\xd8"):
            raise FrameReadError(p, "not a JPEG file (bad signature)")
        if b"\xff\xd9" not in raw[-4096:]:
            raise FrameReadError(p, "truncated or corrupt JPEG (no end-of-image marker)")
    with _quiet_cv2():
        img = cv2.imdecode(np.frombuffer(raw, np.uint8), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise FrameReadError(p, f"unreadable or corrupt {kind} (OpenCV could not decode it)")
    info: dict[str, Any] = {"format": kind}
    if img.ndim == 3 and img.shape[-1] >= 3:
        info["converted"] = "colour to luminance (BT.601)"
    img = _to_gray(img, bgr=True)
    return img[np.newaxis], info


def _read_video(p: Path) -> tuple[np.ndarray, dict]:
    import cv2

    with _quiet_cv2():
        cap = cv2.VideoCapture(str(p))
        try:
            if not cap.isOpened():
                raise FrameReadError(p, "unreadable video (OpenCV cannot open it)")
            fps = cap.get(cv2.CAP_PROP_FPS)
            expected = int(cap.get(cv2.CAP_PROP_FRAME_COUNT) or 0)
            frames = []
            while True:
                ok, img = cap.read()
                if not ok:
                    break
                if img.ndim == 3:
                    img = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
                frames.append(img)
        finally:
            cap.release()
    if not frames:
        raise FrameReadError(p, "video has no decodable frames")
    info: dict[str, Any] = {"format": "video", "fps": fps if fps and fps > 0 else None}
    if expected and expected != len(frames):
        info["frame_count_in_header"] = expected
    return np.stack(frames), info


def _read_file(p: Path) -> tuple[np.ndarray, dict]:
    p = Path(p)
    if not p.exists():
        raise FrameReadError(p, "no such file")
    if p.is_dir():
        raise FrameReadError(p, "is a folder, not an image file (use read_frames for folders)")
    _check_suffix(p)
    suffix = p.suffix.lower()
    if suffix in TIFF_SUFFIXES:
        data, info = _read_tiff(p)
    elif suffix in VIDEO_SUFFIXES:
        data, info = _read_video(p)
    else:
        data, info = _read_raster(p)
    if data.shape[0] == 0 or data.shape[1] == 0 or data.shape[2] == 0:
        raise FrameReadError(p, f"image has no pixels (shape {data.shape})")
    try:
        data = _normalise_dtype(data)
    except TypeError as e:
        raise FrameReadError(p, str(e)) from None
    if "pixel_size_nm" not in info:
        info["pixel_size_nm"] = None
        info["pixel_size_source"] = f"no pixel size in {info['format']} files"
    return data, info


def _check_pixel_size(pixel_size_nm) -> float:
    try:
        v = float(pixel_size_nm)
    except (TypeError, ValueError):
        raise ValueError(
            f"pixel_size_nm must be a positive number, got {pixel_size_nm!r}"
        ) from None
    if not (math.isfinite(v) and v > 0):
        raise ValueError(
            f"pixel_size_nm must be a positive finite number of nm, got {pixel_size_nm!r}"
        )
    return v


def read_image(path: PathLike) -> np.ndarray:
    """Read one 2-D frame from an image file.

    Parameters
    ----------
    path : str or path-like
        A PNG, JPEG, BMP or TIFF file. For a multi-page TIFF or a video, the first frame is returned
        (use :func:`read_frames` for all of them).

    Returns
    -------
    frame : (H, W) ndarray
        ``uint8``, ``uint16`` or ``float64``; colour converted to luminance (see the module notes).

    Raises
    ------
    FrameReadError
        Missing, unsupported, unreadable or truncated file.
    """
    data, _ = _read_file(Path(path))
    return data[0]


def read_pixel_size(path: PathLike) -> tuple[float | None, str]:
    """Pixel size in nm from one file's metadata, and where it came from.

    Returns
    -------
    pixel_size_nm : float or None
        None when the file carries no pixel size (every PNG/JPEG/video, TIFFs without vendor tags).
    source : str
        e.g. ``"FEI metadata [Scan] PixelWidth"`` or the reason it is unknown.
    """
    _, info = _read_file(Path(path))
    return info["pixel_size_nm"], info["pixel_size_source"]


def read_frames(
    inputs: PathLike | Sequence[PathLike],
    *,
    pixel_size_nm: float | None = None,
    progress: bool = False,
    order: str = "natural",
) -> FrameSequence:
    """Read a recording: files, a folder, a glob pattern or a list of these, in natural order.

    Parameters
    ----------
    inputs : str, path-like, or list of them
        A file (PNG/JPEG/BMP/TIFF, multi-page TIFF, video ``.avi``/``.mp4``/...), a folder (its image and
        video files; other files are ignored), a glob pattern such as ``"run/frame_*.png"``, or a list of
        any of these. The files are read in natural order (``frame_2`` before ``frame_10``), whatever
        order a list gives them in (a shell expands ``frame_*.png`` as ``frame_0, frame_1, frame_10,
        frame_2``); ``meta["reordered"]`` says whether that changed the order given.
    pixel_size_nm : float, optional
        Pixel size in nm; overrides whatever the metadata says.
    progress : bool
        Show a ``tqdm`` progress bar over the files.
    order : {"natural", "given"}
        ``"given"`` keeps a list in the order given (see :func:`expand_inputs`).

    Returns
    -------
    FrameSequence
        ``.frames`` (N, H, W), ``.paths``, ``.pixel_size_nm`` (None when unknown), ``.pixel_size_source``
        and ``.meta``. The pixel size of a sequence is that of its first file; when later files disagree
        by more than 0.1 % a :class:`UserWarning` is issued (all values are in
        ``meta["pixel_size_nm_per_file"]``). ``meta["reordered"]`` is True when natural order changed
        the order of the files given, and ``meta["given_order"]`` then lists them as given.

    Raises
    ------
    FrameReadError
        Missing file, empty folder, pattern without matches, unsupported format, unreadable or truncated
        image, frames of different sizes or pixel types. The message names the file and the reason.
    ValueError
        ``pixel_size_nm`` not a positive number.

    Examples
    --------
    >>> seq = read_frames("data/real-sem/contact_brightness_seq/")
    ... # doctest: +SKIP
    >>> seq.frames.shape  # doctest: +SKIP
    (11, 717, 1075)
    """
    override = None if pixel_size_nm is None else _check_pixel_size(pixel_size_nm)
    given = expand_inputs(inputs, order="given")
    files = natural_order(given) if order == "natural" else given
    stack = _read_stack(files, progress)
    first_info, first_path = stack.infos[0], files[0]
    meta_ps = first_info["pixel_size_nm"]
    per_file_ps = {str(p): info["pixel_size_nm"] for p, info in zip(files, stack.infos)}
    known = [v for v in per_file_ps.values() if v is not None]
    if meta_ps is not None and any(abs(v - meta_ps) > 1e-3 * meta_ps for v in known):
        warnings.warn(
            f"pixel size differs between files ({min(known):.4g}-{max(known):.4g} nm); "
            f"using {meta_ps:.4g} nm of {first_path.name}",
            UserWarning,
            stacklevel=2,
        )
    meta: dict[str, Any] = {
        "files": [str(p) for p in dict.fromkeys(stack.paths)],
        "page": stack.pages,
        "format": {str(p): info["format"] for p, info in zip(files, stack.infos)},
        "pixel_size_nm_per_file": per_file_ps,
        "metadata_pixel_size_nm": meta_ps,
        "metadata_pixel_size_source": first_info["pixel_size_source"],
        "reordered": files != given,
    }
    if meta["reordered"]:
        meta["given_order"] = [str(p) for p in given]
    for key in ("vendor", "fei_metadata", "sem_metadata", "fps", "converted"):
        if key in first_info:
            meta[key] = first_info[key]
    ps, src = _chosen_pixel_size(override, first_info, first_path)
    return FrameSequence(
        frames=stack.frames, paths=stack.paths, pixel_size_nm=ps, pixel_size_source=src, meta=meta
    )


@dataclass
class _Stack:
    """The frames of every file, the file and page of each frame, and each file's reader info."""

    frames: np.ndarray
    paths: list[Path]
    pages: list[int]
    infos: list[dict]


def _read_stack(files: list[Path], progress: bool) -> _Stack:
    """Read ``files`` in order into one stack; FrameReadError when a file's frames differ in size or
    pixel type from the first file's."""
    it: Iterable[Path] = files
    if progress and len(files) > 1:
        from tqdm.auto import tqdm

        it = tqdm(files, desc="reading", unit="file")
    stacks: list[np.ndarray] = []
    paths: list[Path] = []
    pages: list[int] = []
    infos: list[dict] = []
    for p in it:
        data, info = _read_file(p)
        if stacks:
            _check_like_first(p, data, stacks[0], files[0])
        stacks.append(data)
        paths.extend([p] * data.shape[0])
        pages.extend(range(data.shape[0]))
        infos.append(info)
    frames = stacks[0] if len(stacks) == 1 else np.concatenate(stacks, axis=0)
    return _Stack(frames, paths, pages, infos)


def _check_like_first(p: Path, data: np.ndarray, first: np.ndarray, first_path: Path) -> None:
    if data.shape[1:] != first.shape[1:]:
        raise FrameReadError(
            p,
            f"frame size {data.shape[2]}x{data.shape[1]} px differs from "
            f"{first.shape[2]}x{first.shape[1]} px of the first frame ({first_path.name})",
        )
    if data.dtype != first.dtype:
        raise FrameReadError(
            p,
            f"pixel type {data.dtype} differs from {first.dtype} of the first frame ({first_path.name})",
        )


def _chosen_pixel_size(override: float | None, first_info: dict, first_path: Path) -> tuple[float | None, str]:
    """The sequence's pixel size and its source: the explicit one, else the first file's metadata."""
    if override is not None:
        return override, "explicit pixel_size_nm"
    if first_info["pixel_size_nm"] is not None:
        return first_info["pixel_size_nm"], f"{first_info['pixel_size_source']} ({first_path.name})"
    return None, f"unknown: {first_info['pixel_size_source']} ({first_path.name}); {PIXEL_SIZE_HINT}"


# ----------------------------------------------------------------------------------------------
# bundled samples (data/ at the repository root)


def data_path(name: str = "") -> Path:
    """Path of a file or folder under semlab's ``data/`` directory.

    The directory is ``$SEMLAB_DATA`` when set, else ``data/`` beside the ``semlab`` package (a source
    checkout or editable install).

    Raises
    ------
    FileNotFoundError
        When the data directory or the named entry does not exist.
    """
    env = os.environ.get("SEMLAB_DATA")
    root = Path(env) if env else Path(__file__).resolve().parents[1] / "data"
    if not root.is_dir():
        raise FileNotFoundError(
            f"semlab data directory not found at {root}; set SEMLAB_DATA or use a source checkout"
        )
    p = root / name
    if not p.exists():
        raise FileNotFoundError(f"{p}: no such sample file or folder (see {root / 'README.md'})")
    return p


# name -> (relative path, description)
_REAL_SAMPLES = {
    "contact_brightness_seq": (
        "real-sem/contact_brightness_seq/liftout_contact_brightness_*_ib.png",
        (
            "11 ion-beam frames (1075x717, ~52 nm/px inferred) of a tungsten needle moving onto a "
            "lamella (DeMarcoLab AutoLiftout, MIT)"
        ),
    ),
    "contact_brightness_reference": (
        "real-sem/contact_brightness_reference/needle_liftout_land_ib.png",
        "the reference frame taken before the first move of contact_brightness_seq (not one of its frames)",
    ),
    "charge_neutralisation_seq": (
        "real-sem/charge_neutralisation_seq/*_charge_neutralisation_*_eb.png",
        (
            "10 electron-beam frames (768x512, ~104 nm/px inferred) of a STATIC needle with a lamella: "
            "true motion zero, very low SNR, brightness decaying 96 -> 90 (DeMarcoLab AutoLiftout, MIT)"
        ),
    ),
    "fei_needle": (
        "real-sem/fibsem/detection_test_image_2.tif",
        "FEI/TFS TIFF 1536x1024, 97.66 nm/px from its metadata (DeMarcoLab OpenFIBSEM, MIT)",
    ),
}

# Pixel sizes of the real PNGs inferred from the run's configuration (see data/real-sem/PROVENANCE.md).
_INFERRED_PS = {"contact_brightness_seq": 80e3 / 1536, "contact_brightness_reference": 80e3 / 1536,
                "charge_neutralisation_seq": 80e3 / 768}


def list_samples() -> dict[str, str]:
    """Names accepted by :func:`load_sample`, with a one-line description of each."""
    out = {k: v[1] for k, v in _REAL_SAMPLES.items()}
    with contextlib.suppress(FileNotFoundError):
        syn = data_path("synthetic")
        for meta in sorted(syn.glob("*.json"), key=natural_sort_key):
            out[meta.stem] = f"synthetic sequence (semlab.sim.make_sequence), see {meta.name}"
    return out


def load_sample(name: str, *, pixel_size_nm: float | None = None) -> FrameSequence:
    """Load one of the small samples shipped in ``data/`` without hard-coded paths.

    Parameters
    ----------
    name : str
        ``"contact_brightness_seq"`` (real needle frames, MIT licence, DeMarcoLab AutoLiftout),
        ``"contact_brightness_reference"``, ``"fei_needle"`` (an FEI TIFF with metadata, 97.66 nm/px),
        or a synthetic sequence from ``data/synthetic/`` (see :func:`list_samples`).
    pixel_size_nm : float, optional
        Overrides the pixel size. For the real PNG frames, which carry no metadata, the default is the
        value inferred from the run's configuration (about 52 nm/px), marked as inferred.

    Returns
    -------
    FrameSequence
        Synthetic samples also carry ``.truth`` (DataFrame frame, x, y of probe 0's tip in px) and
        ``meta["roi"]``, ``meta["crb"]``, ``meta["kind"]``.
    """
    import json

    if name in _REAL_SAMPLES:
        rel = _REAL_SAMPLES[name][0]
        root = data_path()
        seq = read_frames(str(root / rel), pixel_size_nm=pixel_size_nm)
        if pixel_size_nm is None and name in _INFERRED_PS:
            seq.pixel_size_nm = _INFERRED_PS[name]
            seq.pixel_size_source = (
                "inferred from the AutoLiftout run configuration (HFW 80 um over 1536 px); "
                "see data/real-sem/PROVENANCE.md"
            )
        seq.meta["sample"] = name
        return seq
    try:
        meta_file = data_path(f"synthetic/{name}.json")
    except FileNotFoundError:
        raise ValueError(
            f"unknown sample {name!r}; available: {', '.join(sorted(list_samples()))}"
        ) from None
    import pandas as pd

    info = json.loads(meta_file.read_text())
    seq = read_frames(meta_file.with_name(info["frames_file"]), pixel_size_nm=pixel_size_nm)
    if pixel_size_nm is None and info.get("pixel_size_nm") is not None:
        seq.pixel_size_nm = float(info["pixel_size_nm"])
        seq.pixel_size_source = f"simulator setting ({meta_file.name})"
    seq.truth = pd.read_csv(meta_file.with_name(info["truth_file"]))
    seq.meta.update(
        sample=name,
        kind=info.get("kind"),
        roi=tuple(info["roi"]) if info.get("roi") is not None else None,
        crb=tuple(info["crb"]) if info.get("crb") is not None else None,
        seed=info.get("seed"),
        sim_meta=info.get("meta"),
    )
    return seq
