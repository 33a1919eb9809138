"""The semlab command line: info, track, exit codes, and no partial output on failure."""

from __future__ import annotations

import argparse
import hashlib
import json
import shutil
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pandas as pd
import pytest
import tifffile

from semlab.cli import (
    COMMAND_HELP,
    EXIT_INPUT,
    EXIT_OK,
    EXIT_OUTPUT,
    EXIT_ROI,
    EXIT_TRACKING,
    EXIT_USAGE,
    build_parser,
    main,
)

SHARED = Path(__file__).resolve().parents[2] / "shared"
REPO = Path(__file__).resolve().parents[1]
COLUMNS = ["frame", "x", "y", "x_nm", "y_nm", "score", "ok", "file"]


def _real(rel_shared: str, rel_data: str) -> Path:
    for p in (SHARED / "real-sem" / rel_shared, REPO / "data" / "real-sem" / rel_data):
        if p.exists():
            return p
    pytest.skip(f"real SEM data {rel_shared} not available")


def _fei_tiff() -> Path:
    return _real("fibsem/detection_test_image_2.tif", "fibsem/detection_test_image_2.tif")


def _contact_seq() -> Path:
    """The motion sequence as semlab ships it in data/ (../shared keeps the reference frame beside it)."""
    folder = REPO / "data" / "real-sem" / "contact_brightness_seq"
    if not folder.is_dir():
        pytest.skip("data/real-sem/contact_brightness_seq is not available")
    return folder


def _probe_frames(n=4, shift=(2.0, 1.0), shape=(120, 160)):
    """A bright smooth blob (a stand-in probe tip) moving by ``shift`` px per frame."""
    yy, xx = np.mgrid[0 : shape[0], 0 : shape[1]].astype(float)
    frames = []
    for k in range(n):
        cx, cy = 70 + shift[0] * k, 55 + shift[1] * k
        r2 = ((xx - cx) / 14) ** 2 + ((yy - cy) / 9) ** 2
        frames.append((40 + 160 / (1 + np.exp(6 * (np.sqrt(r2) - 1)))).round().astype(np.uint8))
    return frames


def _write_seq(folder: Path, frames, fmt="png") -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    for k, f in enumerate(frames):
        assert cv2.imwrite(str(folder / f"frame_{k}.{fmt}"), f)
    return folder


def _outputs(folder: Path) -> list[str]:
    return sorted(
        p.name for p in folder.iterdir() if p.suffix in (".csv", ".json") or "partial" in p.name
    )


def _err_line(capsys) -> str:
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0, err  # one line
    assert err.startswith("semlab: error: ")
    return err


# --------------------------------------------------------------------------- help / usage


def test_help_documents_commands_and_exit_codes(capsys):
    assert main(["--help"]) == EXIT_OK
    out = capsys.readouterr().out
    assert "track" in out and "info" in out
    for code in ("0", "2", "3", "4", "5", "6"):
        assert f"\n  {code} " in out
    assert main(["track", "--help"]) == EXIT_OK
    out = capsys.readouterr().out
    for option in (
        "--roi",
        "--click",
        "--roi-size",
        "--method",
        "--param",
        "--pixel-size",
        "--out",
    ):
        assert option in out
    assert "x_nm" in out and "sha-256" in out.lower()


def test_help_lists_every_subcommand_on_one_line(capsys, monkeypatch):
    # every subcommand the parser knows (not a hand-kept list: a new one without a help line fails),
    # and at least the three whose output columns are contracts
    monkeypatch.setenv("COLUMNS", "80")  # argparse wraps help to the terminal's width
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    commands = set(sub.choices)
    assert {"track", "info", "evaluate"} <= commands
    assert main(["--help"]) == EXIT_OK
    lines = capsys.readouterr().out.splitlines()
    for name in commands:
        listed = [ln for ln in lines if ln.split()[:1] == [name] and ln.startswith("    ")]
        assert len(listed) == 1, f"semlab --help does not list {name!r}"
        assert listed[0].split(None, 1)[1] == COMMAND_HELP[name]  # the whole description, unwrapped


def test_usage_errors_exit_2(tmp_path, capsys):
    img = tmp_path / "a.png"
    cv2.imwrite(str(img), _probe_frames(1)[0])
    out = str(tmp_path / "t.csv")
    assert main([]) == EXIT_USAGE
    assert main(["track", str(img), "--out", out]) == EXIT_USAGE  # neither --roi nor --click
    assert main(["track", str(img), "--roi", "1,2,3", "--out", out]) == EXIT_USAGE
    assert main(["track", str(img), "--roi", "a,b,c,d", "--out", out]) == EXIT_USAGE
    assert (
        main(["track", str(img), "--roi", "1,2,30,30", "--click", "5,5", "--out", out])
        == EXIT_USAGE
    )
    assert main(["track", str(img), "--roi", "1,2,30,30"]) == EXIT_USAGE  # no --out
    assert (
        main(["track", str(img), "--roi", "1,2,30,30", "--pixel-size", "-3", "--out", out])
        == EXIT_USAGE
    )
    assert (
        main(["track", str(img), "--roi", "1,2,30,30", "--param", "nonsense=1", "--out", out])
        == EXIT_USAGE
    )
    assert (
        main(["track", str(img), "--roi", "1,2,30,30", "--method", "magic", "--out", out])
        == EXIT_USAGE
    )
    assert main(["frobnicate"]) == EXIT_USAGE
    capsys.readouterr()
    assert _outputs(tmp_path) == []


def test_version(capsys):
    assert main(["--version"]) == EXIT_OK
    assert capsys.readouterr().out.startswith("semlab ")


# --------------------------------------------------------------------------- info


def test_info_prints_97_66_nm_for_the_fei_tiff(capsys):
    assert main(["info", str(_fei_tiff())]) == EXIT_OK
    out = capsys.readouterr().out
    assert "97.66 nm" in out and "1536 x 1024 px" in out and "uint8" in out
    assert "frames      1" in out and "FEI" in out


def test_info_json_and_unknown_pixel_size(tmp_path, capsys):
    folder = _write_seq(tmp_path / "seq", _probe_frames(3))
    assert main(["info", "--json", str(folder)]) == EXIT_OK
    report = json.loads(capsys.readouterr().out)
    assert report["frames"] == 3 and report["width_px"] == 160 and report["height_px"] == 120
    assert report["pixel_size_nm"] is None and "unknown" in report["pixel_size_source"]
    assert main(["info", str(folder / "frame_0.png")]) == EXIT_OK
    assert "pixel size  unknown" in capsys.readouterr().out


# --------------------------------------------------------------------------- bad input


def _bad_inputs(tmp_path: Path) -> dict[str, tuple[list[str], str]]:
    frames = _probe_frames(3)
    _write_seq(tmp_path / "good", frames)
    mixed = _write_seq(tmp_path / "mixed", frames)
    cv2.imwrite(str(mixed / "frame_3.png"), np.zeros((121, 160), np.uint8))
    trunc = _write_seq(tmp_path / "trunc", frames)
    raw = (trunc / "frame_1.png").read_bytes()
    (trunc / "frame_1.png").write_bytes(raw[: len(raw) // 2])
    (tmp_path / "empty").mkdir()
    (tmp_path / "scan.xyz").write_bytes(b"\x00" * 64)
    garbage = tmp_path / "garbage.tif"
    garbage.write_bytes(b"not a tiff at all" * 8)
    return {
        "missing": ([str(tmp_path / "nope.png")], "nope.png: no such file"),
        "truncated": ([str(trunc)], "frame_1.png: truncated"),
        "unreadable": ([str(garbage)], "garbage.tif: unreadable"),
        "mixed": ([str(mixed)], "frame_3.png: frame size 160x121 px differs"),
        "unsupported": ([str(tmp_path / "scan.xyz")], "scan.xyz: unsupported format"),
        "empty": ([str(tmp_path / "empty")], "empty: folder contains no image"),
        "no-match": ([str(tmp_path / "good" / "shot_*.png")], "shot_*.png: pattern matches no"),
    }


@pytest.mark.parametrize(
    "case", ["missing", "truncated", "unreadable", "mixed", "unsupported", "empty", "no-match"]
)
def test_bad_input_exit_3_one_line_no_output(tmp_path, capsys, case):
    inputs, message = _bad_inputs(tmp_path)[case]
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    out = out_dir / "tracks.csv"
    assert (
        main(["track", *inputs, "--roi", "40,30,60,50", "--out", str(out), "--no-progress"])
        == EXIT_INPUT
    )
    assert message in _err_line(capsys)
    assert list(out_dir.iterdir()) == []
    assert main(["info", *inputs]) == EXIT_INPUT
    assert message in _err_line(capsys)


@pytest.mark.parametrize(
    ("where", "message"),
    [
        (["--roi", "120,30,60,50"], "ROI 120,30,60,50 is not inside the 160x120 px frame"),
        (["--roi=-1,30,60,50"], "is not inside"),
        (["--roi", "10,10,4,40"], "smaller than 8x8"),
        (["--click", "500,20"], "--click 500,20"),
        (["--click", "50,50", "--roi-size", "300"], "does not fit"),
    ],
)
def test_roi_off_the_image_exit_4(tmp_path, capsys, where, message):
    folder = _write_seq(tmp_path / "seq", _probe_frames(2))
    out = tmp_path / "t.csv"
    assert main(["track", str(folder), *where, "--out", str(out), "--no-progress"]) == EXIT_ROI
    err = _err_line(capsys)
    assert "frame_0.png" in err and message in err
    assert _outputs(tmp_path) == []


def test_featureless_roi_is_a_tracking_failure_exit_5(tmp_path, capsys):
    folder = _write_seq(tmp_path / "flat", [np.full((80, 100), 120, np.uint8)] * 3)
    out = tmp_path / "t.csv"
    assert (
        main(["track", str(folder), "--roi", "10,10,50,50", "--out", str(out), "--no-progress"])
        == EXIT_TRACKING
    )
    assert "tracking cannot start" in _err_line(capsys)
    assert _outputs(tmp_path) == []


def test_unwritable_output_exit_6(tmp_path, capsys):
    folder = _write_seq(tmp_path / "seq", _probe_frames(2))
    args = ["track", str(folder), "--roi", "40,30,60,50", "--no-progress"]
    assert main([*args, "--out", str(tmp_path / "no_such_dir" / "t.csv")]) == EXIT_OUTPUT
    assert "does not exist" in _err_line(capsys)
    assert main([*args, "--out", str(tmp_path)]) == EXIT_OUTPUT
    assert "is a folder" in _err_line(capsys)


def test_failure_while_writing_leaves_no_partial_output(tmp_path, capsys, monkeypatch):
    folder = _write_seq(tmp_path / "seq", _probe_frames(3))
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    (out_dir / "tracks.csv").write_text("an older result\n")

    def disk_full(src, dst):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr("semlab.cli.os.replace", disk_full)
    code = main(
        [
            "track",
            str(folder),
            "--roi",
            "40,30,60,50",
            "--out",
            str(out_dir / "tracks.csv"),
            "--no-progress",
        ]
    )
    assert code == EXIT_OUTPUT
    assert "No space left" in _err_line(capsys)
    # the old result is untouched, no temporary files remain, no sidecar claims a new result
    assert sorted(p.name for p in out_dir.iterdir()) == ["tracks.csv"]
    assert (out_dir / "tracks.csv").read_text() == "an older result\n"


# --------------------------------------------------------------------------- tracking


def _read_result(out: Path):
    df = pd.read_csv(out)
    meta = json.loads(out.with_name(out.name + ".json").read_text())
    assert list(df.columns) == COLUMNS
    assert meta["output"]["sha256"] == hashlib.sha256(out.read_bytes()).hexdigest()
    return df, meta


def test_track_moving_blob_with_pixel_size_and_sidecar(tmp_path, capsys):
    frames = _probe_frames(5, shift=(2.0, 1.0))
    folder = _write_seq(tmp_path / "seq", frames)
    out = tmp_path / "tracks.csv"
    roi = (40, 30, 61, 51)  # centre (70, 55) = the blob's centre in frame 0
    code = main(["track", str(folder), "--roi", ",".join(map(str, roi)), "--pixel-size", "6.6",
                 "--out", str(out), "--no-progress"])  # fmt: skip
    assert code == EXIT_OK
    assert "wrote" in capsys.readouterr().out
    df, meta = _read_result(out)
    assert len(df) == 5 and df["frame"].tolist() == list(range(5))
    assert df["ok"].all()
    assert df.loc[0, "x"] == pytest.approx(70.0) and df.loc[0, "y"] == pytest.approx(55.0)
    # A noise-free blob moving by whole pixels: any sub-pixel tracker lands within 0.25 px.
    np.testing.assert_allclose(df["x"], 70 + 2.0 * np.arange(5), atol=0.25)
    np.testing.assert_allclose(df["y"], 55 + 1.0 * np.arange(5), atol=0.25)
    np.testing.assert_allclose(df["x_nm"], df["x"] * 6.6, rtol=1e-6, atol=1e-5)
    np.testing.assert_allclose(df["y_nm"], df["y"] * 6.6, rtol=1e-6, atol=1e-5)
    assert df["file"].tolist() == [f"frame_{k}.png" for k in range(5)]
    assert meta["pixel_size_nm"] == 6.6 and meta["pixel_size_source"] == "--pixel-size"
    assert meta["roi"] == list(roi) and meta["n_frames"] == 5 and meta["n_ok"] == 5
    assert [Path(i["path"]).name for i in meta["inputs"]] == [f"frame_{k}.png" for k in range(5)]
    for item in meta["inputs"]:
        assert item["sha256"] == hashlib.sha256(Path(item["path"]).read_bytes()).hexdigest()
    assert meta["semlab_version"] and meta["created_utc"] and meta["method"]
    assert [p.name for p in tmp_path.iterdir() if "partial" in p.name] == []


def test_track_click_uses_roi_from_click_and_nm_empty_when_unknown(tmp_path, capsys):
    from semlab.roi import roi_from_click

    frames = _probe_frames(3)
    folder = _write_seq(tmp_path / "seq", frames)
    out = tmp_path / "c.csv"
    code = main(["track", str(folder / "frame_*.png"), "--click", "70,55", "--roi-size", "60x50",
                 "--method", "contour", "--out", str(out), "--no-progress", "--quiet"])  # fmt: skip
    assert code == EXIT_OK
    assert capsys.readouterr().out == ""
    df, meta = _read_result(out)
    assert meta["roi"] == list(roi_from_click(frames[0], (70, 55), size=(60, 50)))
    assert meta["method"] == "contour" and meta["click"] == [70.0, 55.0]
    assert meta["pixel_size_nm"] is None and df["x_nm"].isna().all() and df["y_nm"].isna().all()


def test_track_multipage_tiff_with_imagej_pixel_size(tmp_path):
    stack = np.stack(_probe_frames(4, shift=(1.0, 0.0)))
    tifffile.imwrite(
        tmp_path / "s.tif",
        stack,
        imagej=True,
        resolution=(1 / 0.05, 1 / 0.05),
        metadata={"unit": "um"},
    )
    out = tmp_path / "s.csv"
    assert (
        main(
            [
                "track",
                str(tmp_path / "s.tif"),
                "--roi",
                "40,30,61,51",
                "--out",
                str(out),
                "--no-progress",
            ]
        )
        == 0
    )
    df, meta = _read_result(out)
    assert meta["pixel_size_nm"] == pytest.approx(50.0)
    np.testing.assert_allclose(df["x_nm"], df["x"] * 50.0, rtol=1e-6)
    assert meta["inputs"][0]["frames"] == 4 and len(meta["inputs"]) == 1


def test_track_real_contact_brightness_folder(tmp_path, capsys):
    folder = _contact_seq()
    out = tmp_path / "real.csv"
    code = main(
        ["track", str(folder), "--roi", "400,180,160,200", "--out", str(out), "--no-progress"]
    )
    assert code == EXIT_OK
    df, meta = _read_result(out)
    # The 11 motion frames, in natural order; the reference frame lives in its own folder.
    assert len(df) == 11 and len(meta["inputs"]) == 11
    assert df["file"].tolist() == [f"liftout_contact_brightness_{k}_ib.png" for k in range(11)]
    assert (df.loc[0, "x"], df.loc[0, "y"]) == pytest.approx((479.5, 279.5))
    assert meta["pixel_size_nm"] is None and df["x_nm"].isna().all()
    assert "pass --pixel-size NM" in meta["pixel_size_source"]
    assert "pixel_size_nm" not in capsys.readouterr().out
    # The needle advances to the right (+x) in frames 1-3 by ~4-10 px per step (PROVENANCE.md).
    early = df.iloc[1:4]
    early = early[early["ok"]]
    assert len(early) >= 1
    steps = (early["x"] - 479.5) / early["frame"]
    assert ((steps > 2) & (steps < 15)).all()


def test_track_real_fei_tiff_gives_nm(tmp_path):
    out = tmp_path / "fei.csv"
    code = main(
        [
            "track",
            str(_fei_tiff()),
            "--roi",
            "600,300,200,200",
            "--out",
            str(out),
            "--no-progress",
            "-q",
        ]
    )
    assert code == EXIT_OK
    df, meta = _read_result(out)
    assert len(df) == 1 and df.loc[0, "ok"]
    assert round(meta["pixel_size_nm"], 2) == 97.66 and "PixelWidth" in meta["pixel_size_source"]
    assert df.loc[0, "x_nm"] == pytest.approx(699.5 * meta["pixel_size_nm"], rel=1e-6)


# --------------------------------------------------------------------------- installed entry points


def _console_script() -> str:
    exe = Path(sys.executable).with_name("semlab")
    if exe.exists():
        return str(exe)
    found = shutil.which("semlab")
    if not found:
        pytest.skip("the semlab console script is not installed")
    return found


def test_console_script_and_python_m(tmp_path):
    res = subprocess.run(
        [
            _console_script(),
            "track",
            str(tmp_path / "missing.png"),
            "--roi",
            "0,0,20,20",
            "--out",
            str(tmp_path / "t.csv"),
        ],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert res.returncode == EXIT_INPUT
    assert (
        res.stderr.strip() == f"semlab: error: {tmp_path / 'missing.png'}: no such file or folder"
    )
    assert not (tmp_path / "t.csv").exists()
    res = subprocess.run(
        [sys.executable, "-m", "semlab", "info", str(_fei_tiff())],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert res.returncode == 0 and "97.66 nm" in res.stdout


# --------------------------------------------------------------------------- order, parameters, wording


def test_files_in_shell_glob_order_are_tracked_in_natural_order_with_a_note(tmp_path, capsys):
    frames = _probe_frames(11, shift=(1.0, 0.0))
    folder = _write_seq(tmp_path / "seq", frames)
    shell = sorted(str(p) for p in folder.glob("frame_*.png"))  # how a shell expands frame_*.png
    assert [Path(p).name for p in shell[:3]] == ["frame_0.png", "frame_1.png", "frame_10.png"]
    out = tmp_path / "t.csv"
    assert main(["track", *shell, "--roi", "40,30,61,51", "--out", str(out), "--no-progress"]) == EXIT_OK
    err = capsys.readouterr().err
    assert "not in natural order" in err and "--keep-order" in err
    df, meta = _read_result(out)
    assert df["file"].tolist() == [f"frame_{k}.png" for k in range(11)]
    assert meta["input_order"] == "natural"
    # The blob steps +1 px per frame: in natural order x grows monotonically.
    assert (np.diff(df["x"]) > 0).all()

    out2 = tmp_path / "kept.csv"
    assert main(["track", *shell, "--roi", "40,30,61,51", "--out", str(out2), "--no-progress",
                 "--keep-order", "-q"]) == EXIT_OK  # fmt: skip
    assert "natural order" not in capsys.readouterr().err
    kept, meta2 = _read_result(out2)
    assert kept["file"].tolist() == [Path(p).name for p in shell] and meta2["input_order"] == "given"


def test_a_folder_in_natural_order_gets_no_note(tmp_path, capsys):
    folder = _write_seq(tmp_path / "seq", _probe_frames(3))
    out = tmp_path / "t.csv"
    assert main(["track", str(folder), "--roi", "40,30,61,51", "--out", str(out), "--no-progress"]) == 0
    assert "natural order" not in capsys.readouterr().err


@pytest.mark.parametrize(
    ("param", "message"),
    [
        ("sigma=abc", "sigma needs float, got str"),
        ("sigma=true", "sigma needs float, got bool"),
        ("search_size=2.5", "search_size needs int, got float"),
        ("band_px=[3]", "band_px needs int or none, got list"),
        ("whiten=1", "whiten needs bool, got int"),
        ("photometry=3", "photometry needs str, got int"),
        ("nonsense=1", "not a tracker parameter"),
        ("search_size=4", "search_size must be an integer of at least 16"),  # the Tracker's own check
    ],
)
def test_a_bad_param_is_a_usage_error_before_reading_or_tracking(tmp_path, capsys, param, message):
    out = tmp_path / "t.csv"
    # The input does not exist: a parameter checked before reading answers 2, not 3 (input error).
    code = main(["track", str(tmp_path / "missing.png"), "--roi", "0,0,20,20", "--param", param,
                 "--out", str(out)])  # fmt: skip
    assert code == EXIT_USAGE
    err = _err_line(capsys)
    assert message in err, err
    assert _outputs(tmp_path) == []


def test_good_params_of_every_type_are_accepted(tmp_path, capsys):
    folder = _write_seq(tmp_path / "seq", _probe_frames(3))
    out = tmp_path / "t.csv"
    code = main(["track", str(folder), "--roi", "40,30,61,51", "--out", str(out), "--no-progress", "-q",
                 "--param", "sigma=1", "--param", "search_size=200.0", "--param", "threshold=none",
                 "--param", "whiten=false", "--param", "photometry=regions"])  # fmt: skip
    assert code == EXIT_OK, capsys.readouterr().err
    _, meta = _read_result(out)
    assert meta["params"] == {"sigma": 1, "search_size": 200.0, "threshold": None, "whiten": False,
                              "photometry": "regions"}


def test_unknown_pixel_size_names_the_flag(tmp_path, capsys):
    folder = _write_seq(tmp_path / "seq", _probe_frames(3))
    assert main(["info", str(folder)]) == EXIT_OK
    out = capsys.readouterr().out
    assert "pass --pixel-size NM" in out and "pixel_size_nm" not in out
    assert main(["track", str(folder), "--roi", "40,30,61,51", "--out", str(tmp_path / "t.csv"),
                 "--no-progress"]) == EXIT_OK  # fmt: skip
    out = capsys.readouterr().out
    assert "pass --pixel-size NM" in out and "pixel_size_nm" not in out


#: The ROI of the probe of :func:`_probe_frames` the --sigma and --reason tests track.
TRACKED_ROI = (40, 30, 61, 51)


def _tracked_csv(tmp_path, frames, *flags) -> pd.DataFrame:
    """``semlab track`` of ``frames`` (written as a folder) in :data:`TRACKED_ROI` with ``flags``: its CSV."""
    folder = _write_seq(tmp_path / "seq", frames)
    out = tmp_path / "t.csv"
    code = main(["track", str(folder), "--roi", ",".join(map(str, TRACKED_ROI)), *flags, "--out", str(out),
                 "--no-progress", "--quiet"])  # fmt: skip
    assert code == EXIT_OK
    return pd.read_csv(out)


def test_track_sigma_adds_the_libraries_uncertainty(tmp_path):
    # --sigma: the same sigma_x, sigma_y as semlab.track on the same frames (the CLI and the library
    # agree), after the contract's columns; a noisy blob so that the uncertainty is not zero.
    import semlab

    rng = np.random.default_rng(7)
    frames = [np.clip(f + rng.normal(0, 6, f.shape), 0, 255).round().astype(np.uint8) for f in _probe_frames(5)]
    df = _tracked_csv(tmp_path, frames, "--sigma")
    assert list(df.columns) == [*COLUMNS, "sigma_x", "sigma_y"]
    ref = semlab.track(np.stack(frames), TRACKED_ROI, progress=False)
    np.testing.assert_allclose(df[["sigma_x", "sigma_y"]], ref[["sigma_x", "sigma_y"]], atol=6e-7)  # six decimals
    ok = df["ok"].to_numpy()
    assert ok[1:].any() and (df.loc[ok, "sigma_x"].iloc[1:] > 0).all()


def test_track_reason_says_why_a_frame_is_not_ok(tmp_path):
    # --reason: the library's reason (semlab.tracking.run.track_with_reasons) after the contract's columns; a
    # frame without the probe is lost and says why, the others are ok and say nothing.
    from semlab.tracking.run import track_with_reasons

    frames = _probe_frames(5)
    frames[3] = np.full_like(frames[3], int(np.median(frames[3])))
    df = _tracked_csv(tmp_path, frames, "--reason")
    assert list(df.columns) == [*COLUMNS, "reason"]
    df["reason"] = df["reason"].fillna("")  # an empty field reads as NaN
    assert not df.loc[3, "ok"] and df.loc[3, "reason"] != ""
    assert (df.loc[df["ok"], "reason"] == "").all() and df["ok"].sum() == 4
    ref = track_with_reasons(np.stack(frames), TRACKED_ROI, progress=False)
    assert list(ref.columns) == ["frame", "x", "y", "score", "ok", "sigma_x", "sigma_y", "reason"]
    assert df["reason"].tolist() == ref["reason"].tolist()
