"""Readers of semlab.io: every input kind, the vendor pixel sizes, and every bad input."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest
import tifffile

from semlab.io import (
    FrameReadError,
    FrameSequence,
    data_path,
    expand_inputs,
    list_samples,
    load_sample,
    natural_sort_key,
    read_frames,
    read_image,
    read_pixel_size,
)

SHARED = Path(__file__).resolve().parents[2] / "shared"
REPO = Path(__file__).resolve().parents[1]


def _real(rel_shared: str, rel_data: str) -> Path:
    """A real file from ../shared (as CI clones it), else its copy in data/."""
    for p in (SHARED / "real-sem" / rel_shared, REPO / "data" / "real-sem" / rel_data):
        if p.exists():
            return p
    pytest.skip(f"real SEM file {rel_shared} not available")


FEI_TIFF_REL = ("fibsem/detection_test_image_2.tif", "fibsem/detection_test_image_2.tif")


def _frame(seed: int, shape=(24, 32), dtype=np.uint8) -> np.ndarray:
    rng = np.random.default_rng(seed)
    hi = np.iinfo(dtype).max
    return rng.integers(0, hi, size=shape, endpoint=True).astype(dtype)


def _write_pngs(folder: Path, indices, shape=(24, 32)) -> dict[int, np.ndarray]:
    folder.mkdir(parents=True, exist_ok=True)
    frames = {}
    for i in indices:
        f = _frame(i, shape)
        assert cv2.imwrite(str(folder / f"frame_{i}.png"), f)
        frames[i] = f
    return frames


# --------------------------------------------------------------------------- ordering / locating


def test_natural_sort_key_orders_numbers_as_numbers():
    names = ["frame_10.png", "frame_2.png", "frame_1.png", "Frame_3.png", "frame_100.png"]
    assert sorted(names, key=natural_sort_key) == [
        "frame_1.png",
        "frame_2.png",
        "Frame_3.png",
        "frame_10.png",
        "frame_100.png",
    ]


def test_png_folder_reads_in_natural_order_and_skips_other_files(tmp_path):
    frames = _write_pngs(tmp_path / "run", [10, 2, 1, 11, 3])
    (tmp_path / "run" / "LICENSE").write_text("MIT")
    (tmp_path / "run" / ".hidden.png").write_bytes(b"junk")
    seq = read_frames(tmp_path / "run")
    assert isinstance(seq, FrameSequence)
    assert [p.name for p in seq.files] == [f"frame_{i}.png" for i in (1, 2, 3, 10, 11)]
    assert seq.frames.shape == (5, 24, 32) and seq.frames.dtype == np.uint8
    for k, i in enumerate((1, 2, 3, 10, 11)):
        np.testing.assert_array_equal(seq.frames[k], frames[i])
    assert seq.pixel_size_nm is None
    assert seq.pixel_size_source.startswith("unknown")


def test_glob_reads_matches_in_natural_order(tmp_path):
    frames = _write_pngs(tmp_path, [2, 10, 1])
    _write_pngs(tmp_path / "other", [5])
    seq = read_frames(str(tmp_path / "frame_*.png"))
    assert [p.name for p in seq.paths] == ["frame_1.png", "frame_2.png", "frame_10.png"]
    np.testing.assert_array_equal(seq.frames[2], frames[10])


def test_a_list_in_shell_glob_order_is_read_in_natural_order(tmp_path):
    frames = _write_pngs(tmp_path, [0, 1, 2, 10])
    # What `semlab track frame_*.png` receives from a shell: character order, 10 before 2.
    shell = [tmp_path / f"frame_{i}.png" for i in (0, 1, 10, 2)]
    seq = read_frames([str(p) for p in shell])
    assert [p.name for p in seq.paths] == ["frame_0.png", "frame_1.png", "frame_2.png", "frame_10.png"]
    np.testing.assert_array_equal(seq.frames, np.stack([frames[i] for i in (0, 1, 2, 10)]))
    assert seq.meta["reordered"] is True
    assert [Path(p).name for p in seq.meta["given_order"]] == [p.name for p in shell]
    assert expand_inputs(shell) == [tmp_path / f"frame_{i}.png" for i in (0, 1, 2, 10)]


def test_order_given_keeps_a_list_as_given(tmp_path):
    frames = _write_pngs(tmp_path, [1, 2, 3])
    seq = read_frames([tmp_path / "frame_3.png", str(tmp_path / "frame_1.png")], order="given")
    np.testing.assert_array_equal(seq.frames, np.stack([frames[3], frames[1]]))
    assert seq.meta["reordered"] is False and "given_order" not in seq.meta
    assert expand_inputs([tmp_path / "frame_2.png"]) == [tmp_path / "frame_2.png"]
    with pytest.raises(ValueError, match="order"):
        expand_inputs([tmp_path / "frame_2.png"], order="alphabetical")


def test_a_folder_or_natural_list_is_not_reported_as_reordered(tmp_path):
    _write_pngs(tmp_path / "run", [2, 10, 1])
    assert read_frames(tmp_path / "run").meta["reordered"] is False
    files = sorted((tmp_path / "run").glob("*.png"), key=natural_sort_key)
    assert read_frames(files).meta["reordered"] is False


def test_multipage_tiff_gives_one_frame_per_page(tmp_path):
    stack = np.stack([_frame(i, (20, 30), np.uint16) for i in range(7)])
    tifffile.imwrite(tmp_path / "stack.tif", stack)
    seq = read_frames(tmp_path / "stack.tif")
    assert seq.frames.shape == (7, 20, 30)
    assert seq.frames.dtype == np.uint16
    np.testing.assert_array_equal(seq.frames, stack)
    assert seq.meta["page"] == list(range(7))
    np.testing.assert_array_equal(read_image(tmp_path / "stack.tif"), stack[0])


def test_multipage_tiff_written_page_by_page(tmp_path):
    with tifffile.TiffWriter(tmp_path / "pages.tif") as tw:
        for i in range(4):
            tw.write(_frame(i, (16, 16)), contiguous=False)
    assert read_frames(tmp_path / "pages.tif").frames.shape == (4, 16, 16)


def test_16bit_png_and_tiff_stay_uint16(tmp_path):
    f = _frame(3, (20, 25), np.uint16)
    assert f.max() > 255
    assert cv2.imwrite(str(tmp_path / "a.png"), f)
    tifffile.imwrite(tmp_path / "b.tiff", f)
    for name in ("a.png", "b.tiff"):
        img = read_image(tmp_path / name)
        assert img.dtype == np.uint16
        np.testing.assert_array_equal(img, f)


def test_float_and_signed_tiffs_become_float64(tmp_path):
    f = np.linspace(-1, 1, 12 * 10).reshape(12, 10).astype(np.float32)
    tifffile.imwrite(tmp_path / "f.tif", f)
    img = read_image(tmp_path / "f.tif")
    assert img.dtype == np.float64
    np.testing.assert_array_equal(img, f.astype(np.float64))
    tifffile.imwrite(tmp_path / "i.tif", (f * 1000).astype(np.int16))
    assert read_image(tmp_path / "i.tif").dtype == np.float64


def test_rgb_becomes_bt601_luminance(tmp_path):
    rng = np.random.default_rng(1)
    rgb = rng.integers(0, 256, size=(10, 12, 3), dtype=np.uint8)
    expected = np.clip(np.rint(rgb @ np.array([0.299, 0.587, 0.114])), 0, 255).astype(np.uint8)
    cv2.imwrite(str(tmp_path / "c.png"), rgb[..., ::-1])  # OpenCV writes BGR
    tifffile.imwrite(tmp_path / "c.tif", rgb, photometric="rgb")
    for name in ("c.png", "c.tif"):
        img = read_image(tmp_path / name)
        assert img.shape == (10, 12) and img.dtype == np.uint8
        np.testing.assert_array_equal(img, expected)


def test_grey_saved_as_rgba_is_returned_exactly(tmp_path):
    g = _frame(5, (9, 11))
    rgba = np.dstack([g, g, g, np.full_like(g, 255)])
    cv2.imwrite(str(tmp_path / "g.png"), rgba)
    np.testing.assert_array_equal(read_image(tmp_path / "g.png"), g)


def test_jpeg_reads_close_to_original(tmp_path):
    yy, xx = np.mgrid[0:40, 0:60]
    g = (100 + 50 * np.sin(xx / 7.0) * np.cos(yy / 9.0)).astype(np.uint8)
    cv2.imwrite(str(tmp_path / "s.jpg"), g, [cv2.IMWRITE_JPEG_QUALITY, 95])
    img = read_image(tmp_path / "s.jpg")
    assert img.shape == g.shape and img.dtype == np.uint8
    assert np.abs(img.astype(int) - g).mean() < 2.0  # JPEG q95 on a smooth image


def test_video_frames_via_opencv(tmp_path):
    path = tmp_path / "rec.avi"
    w, h, n = 64, 48, 6
    vw = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 10.0, (w, h), True)
    assert vw.isOpened()
    levels = [30 + 35 * i for i in range(n)]
    for v in levels:
        vw.write(np.full((h, w, 3), v, np.uint8))
    vw.release()
    seq = read_frames(path)
    assert seq.frames.shape == (n, h, w) and seq.frames.dtype == np.uint8
    # Flat grey frames survive MJPEG up to a grey level or two.
    np.testing.assert_allclose(seq.frames.mean(axis=(1, 2)), levels, atol=2.0)
    assert seq.meta["fps"] == pytest.approx(10.0)
    assert seq.pixel_size_nm is None
    assert read_frames(tmp_path).frames.shape[0] == n  # a folder holding one video


# --------------------------------------------------------------------------- pixel size


def test_real_fei_tiff_pixel_size_is_97_66_nm():
    path = _real(*FEI_TIFF_REL)
    seq = read_frames(path)
    assert seq.frames.shape == (1, 1024, 1536) and seq.frames.dtype == np.uint8
    assert seq.pixel_size_nm == pytest.approx(97.6562, abs=1e-3)
    assert "PixelWidth" in seq.pixel_size_source
    assert seq.meta["vendor"] == "FEI/Thermo Fisher"
    ps, _ = read_pixel_size(path)
    assert round(ps, 2) == 97.66


def _fei_text(scan: str = "PixelWidth=2.5e-09\nPixelHeight=2.5e-09\n", beam: str = "") -> str:
    return (
        "[User]\nDate=12/14/2022\n"
        "[Beam]\nHV=5000\n"
        + beam
        + "[Scan]\nDwelltime=1e-06\n"
        + scan
        + "[Image]\nResolutionX=40\n"
    )


def _write_fei(path: Path, text: str, shape=(30, 40)) -> np.ndarray:
    img = _frame(7, shape)
    tifffile.imwrite(path, img, extratags=[(34682, "s", 0, text, True)])
    return img


def test_synthetic_fei_pixelwidth(tmp_path):
    img = _write_fei(tmp_path / "fei.tif", _fei_text())
    seq = read_frames(tmp_path / "fei.tif")
    np.testing.assert_array_equal(seq.frames[0], img)
    assert seq.pixel_size_nm == pytest.approx(2.5)
    assert seq.pixel_size_source.startswith("FEI metadata [Scan] PixelWidth")


def test_synthetic_fei_falls_back_to_hfw_over_resolution(tmp_path):
    # 10 um horizontal field width over ResolutionX = 40 px -> 250 nm/px
    _write_fei(tmp_path / "fei.tif", _fei_text(scan="Dummy=1\n", beam="HFW=1e-05\n"))
    ps, src = read_pixel_size(tmp_path / "fei.tif")
    assert ps == pytest.approx(250.0)
    assert "HFW" in src and "ResolutionX" in src


def _write_zeiss(path: Path, lines: str, shape=(30, 40)) -> None:
    tifffile.imwrite(path, _frame(8, shape), extratags=[(34118, "s", 0, lines, True)])


def test_synthetic_zeiss_image_pixel_size(tmp_path):
    _write_zeiss(
        tmp_path / "z.tif",
        "0\n0\nAP_IMAGE_PIXEL_SIZE\nImage Pixel Size = 12.34 nm\nAP_MAG\nMag = 25.00 K X\n",
    )
    seq = read_frames(tmp_path / "z.tif")
    assert seq.pixel_size_nm == pytest.approx(12.34)
    assert "CZ_SEM" in seq.pixel_size_source and seq.meta["vendor"] == "Zeiss"


def test_synthetic_zeiss_micrometre_units_and_width_fallback(tmp_path):
    _write_zeiss(tmp_path / "um.tif", "AP_PIXEL_SIZE\nPixel Size = 1.5 um\n")
    assert read_pixel_size(tmp_path / "um.tif")[0] == pytest.approx(1500.0)
    # field width 8 um over 40 px -> 200 nm/px
    _write_zeiss(tmp_path / "w.tif", "AP_WIDTH\nWidth = 8.000 um\n")
    ps, src = read_pixel_size(tmp_path / "w.tif")
    assert ps == pytest.approx(200.0) and "ap_width" in src


def test_imagej_calibration(tmp_path):
    tifffile.imwrite(
        tmp_path / "ij.tif", _frame(9, (10, 10)), imagej=True, resolution=(1 / 0.05, 1 / 0.05),
        metadata={"unit": "um"},
    )  # fmt: skip
    assert read_pixel_size(tmp_path / "ij.tif")[0] == pytest.approx(50.0)


def test_explicit_pixel_size_overrides_metadata(tmp_path):
    _write_fei(tmp_path / "fei.tif", _fei_text())
    seq = read_frames(tmp_path / "fei.tif", pixel_size_nm=66.0)
    assert seq.pixel_size_nm == 66.0
    assert seq.pixel_size_source == "explicit pixel_size_nm"
    assert seq.meta["metadata_pixel_size_nm"] == pytest.approx(2.5)
    _write_pngs(tmp_path / "p", [1])
    assert read_frames(tmp_path / "p", pixel_size_nm=6.6).pixel_size_nm == 6.6
    np.testing.assert_allclose(read_frames(tmp_path / "p", pixel_size_nm=6.6).to_nm(10), 66.0)
    for bad in (0, -1, float("nan"), "abc"):
        with pytest.raises(ValueError, match="pixel_size_nm"):
            read_frames(tmp_path / "p", pixel_size_nm=bad)


def test_plain_tiff_pixel_size_unknown(tmp_path):
    tifffile.imwrite(tmp_path / "plain.tif", _frame(1))
    seq = read_frames(tmp_path / "plain.tif")
    assert seq.pixel_size_nm is None
    assert "unknown" in seq.pixel_size_source and "plain.tif" in seq.pixel_size_source
    assert np.isnan(seq.to_nm(3.0))


def test_pixel_size_disagreeing_between_files_warns(tmp_path):
    _write_fei(tmp_path / "a_1.tif", _fei_text())
    _write_fei(tmp_path / "a_2.tif", _fei_text(scan="PixelWidth=5e-09\n"))
    with pytest.warns(UserWarning, match="pixel size differs"):
        seq = read_frames(tmp_path)
    assert seq.pixel_size_nm == pytest.approx(2.5)


# --------------------------------------------------------------------------- bad input


def test_missing_file(tmp_path):
    with pytest.raises(FrameReadError, match=r"nope\.png: no such file"):
        read_frames(tmp_path / "nope.png")
    with pytest.raises(FrameReadError, match="no such file"):
        read_image(tmp_path / "nope.png")


def test_empty_folder(tmp_path):
    (tmp_path / "empty").mkdir()
    (tmp_path / "empty" / "notes.txt").write_text("no frames here")
    with pytest.raises(FrameReadError, match="empty: folder contains no image"):
        read_frames(tmp_path / "empty")


def test_glob_without_matches(tmp_path):
    with pytest.raises(FrameReadError, match="pattern matches no"):
        read_frames(str(tmp_path / "frame_*.png"))


def test_unsupported_format(tmp_path):
    (tmp_path / "scan.xyz").write_bytes(b"\x00" * 16)
    with pytest.raises(FrameReadError, match=r"scan\.xyz: unsupported format \.xyz"):
        read_frames(tmp_path / "scan.xyz")


@pytest.mark.parametrize("suffix", [".png", ".jpg", ".tif"])
def test_truncated_image(tmp_path, suffix):
    path = tmp_path / f"t{suffix}"
    img = _frame(2, (64, 64))
    if suffix == ".tif":
        tifffile.imwrite(path, np.stack([img] * 4), photometric="minisblack")
    else:
        cv2.imwrite(str(path), img)
    raw = path.read_bytes()
    path.write_bytes(raw[: len(raw) // 2])
    with pytest.raises(FrameReadError, match=rf"t\{suffix}: .*(truncated|corrupt|unreadable)"):
        read_frames(path)


@pytest.mark.parametrize("suffix", [".png", ".tif", ".avi"])
def test_garbage_file(tmp_path, suffix):
    path = tmp_path / f"g{suffix}"
    path.write_bytes(b"this is not an image" * 10)
    with pytest.raises(FrameReadError, match=rf"g\{suffix}: "):
        read_frames(path)


def test_empty_file(tmp_path):
    (tmp_path / "e.png").write_bytes(b"")
    with pytest.raises(FrameReadError, match="e.png: file is empty"):
        read_image(tmp_path / "e.png")


def test_mixed_frame_sizes(tmp_path):
    _write_pngs(tmp_path, [1, 2], shape=(24, 32))
    cv2.imwrite(str(tmp_path / "frame_3.png"), _frame(3, (25, 32)))
    with pytest.raises(
        FrameReadError, match=r"frame_3\.png: frame size 32x25 px differs from 32x24"
    ):
        read_frames(tmp_path)


def test_mixed_pixel_types(tmp_path):
    _write_pngs(tmp_path, [1])
    cv2.imwrite(str(tmp_path / "frame_2.png"), _frame(2, (24, 32), np.uint16))
    with pytest.raises(FrameReadError, match=r"frame_2\.png: pixel type uint16 differs"):
        read_frames(tmp_path)


def test_frame_read_error_is_a_one_line_value_error(tmp_path):
    with pytest.raises(ValueError) as info:
        read_frames(tmp_path / "missing.tif")
    assert "\n" not in str(info.value)
    assert info.value.path.endswith("missing.tif") and info.value.reason == "no such file or folder"


# --------------------------------------------------------------------------- bundled samples


def test_data_path_and_real_samples():
    try:
        root = data_path()
    except FileNotFoundError:
        pytest.skip("no data/ directory")
    assert (root / "README.md").exists()
    if not (root / "real-sem").exists():
        pytest.skip("real samples not copied yet")
    seq = load_sample("contact_brightness_seq")
    assert seq.frames.shape == (11, 717, 1075)
    assert seq.files[-1].name == "liftout_contact_brightness_10_ib.png"
    # The reference frame is not one of the motion frames: reading the folder gives the 11 frames.
    folder = read_frames(root / "real-sem" / "contact_brightness_seq")
    assert [p.name for p in folder.files] == [f"liftout_contact_brightness_{k}_ib.png" for k in range(11)]
    np.testing.assert_array_equal(folder.frames, seq.frames)
    ref = load_sample("contact_brightness_reference")
    assert ref.frames.shape == (1, 717, 1075)
    assert ref.files[0].parent.name == "contact_brightness_reference"
    assert not any(np.array_equal(ref.frames[0], f) for f in seq.frames)
    assert seq.pixel_size_nm == pytest.approx(80e3 / 1536) and "inferred" in seq.pixel_size_source
    fei = load_sample("fei_needle")
    assert round(fei.pixel_size_nm, 2) == 97.66
    assert "fei_needle" in list_samples()
    with pytest.raises(ValueError, match="unknown sample"):
        load_sample("no_such_sample")
    with pytest.raises(FileNotFoundError):
        data_path("no/such/file")


def test_synthetic_samples_load_with_truth():
    try:
        names = [n for n in list_samples() if n.startswith("synthetic_")]
    except FileNotFoundError:
        names = []
    if not names:
        pytest.skip("no synthetic samples generated yet")
    seq = load_sample(names[0])
    assert seq.frames.ndim == 3 and seq.frames.dtype == np.uint8
    assert len(seq.truth) == len(seq) and {"frame", "x", "y"} <= set(seq.truth.columns)
    x, y, w, h = seq.roi
    assert 0 <= x and 0 <= y and x + w <= seq.frames.shape[2] and y + h <= seq.frames.shape[1]
    assert seq.pixel_size_nm is not None and seq.pixel_size_nm > 0


def test_synthetic_samples_regenerate_bit_identically():
    """data/make_synthetic.py reproduces the stored frames exactly (else: rerun the script)."""
    import hashlib
    import importlib.util

    script = REPO / "data" / "make_synthetic.py"
    meta_file = REPO / "data" / "synthetic" / "synthetic_static.json"
    if not (script.exists() and meta_file.exists()):
        pytest.skip("synthetic samples not present")
    spec = importlib.util.spec_from_file_location("make_synthetic", script)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    files = module.render("synthetic_static")
    stored = json.loads(meta_file.read_text())
    fresh = json.loads(files["synthetic_static.json"])
    assert fresh["frames_sha256"] == stored["frames_sha256"], (
        "the simulator changed: run `python data/make_synthetic.py` and commit data/synthetic/"
    )
    seq = load_sample("synthetic_static")
    assert hashlib.sha256(seq.frames.tobytes()).hexdigest() == stored["frames_sha256"]
    assert (
        files["synthetic_static_truth.csv"]
        == (meta_file.with_name("synthetic_static_truth.csv")).read_bytes()
    )
