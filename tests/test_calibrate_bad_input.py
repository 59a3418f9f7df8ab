"""Every bad input of the calibrate commands: exit 2, one line on stderr, nothing written."""

from __future__ import annotations

import os

import cv2
import numpy as np
import pytest
from calib_support import belt_view, intrinsic_views, write_views

from tracker.cli import main


def _fails(capsys, argv: list[str], *words: str) -> str:
    code = main(argv)
    err = capsys.readouterr().err
    assert code == 2, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("tracker: error:"), err
    for w in words:
        assert w in lines[0], lines[0]
    return lines[0]


@pytest.fixture
def views(tmp_path):
    return write_views(tmp_path, intrinsic_views()[:9])


def _intrinsics(paths, out, *extra):
    return ["calibrate", "intrinsics", *paths, "--pattern", "9x6", "--square", "20", "--out", str(out), *extra]


def test_unreadable_image(tmp_path, views, capsys):
    junk = tmp_path / "junk.png"
    junk.write_text("not an image")
    out = tmp_path / "cam.yaml"
    _fails(capsys, _intrinsics([*views, str(junk)], out), "junk.png", "cannot read")
    _fails(capsys, _intrinsics([*views, str(tmp_path / "gone.png")], out), "gone.png", "not found")
    assert not out.exists()


def test_images_of_different_sizes(tmp_path, views, capsys):
    small = tmp_path / "small.png"
    cv2.imwrite(str(small), cv2.resize(intrinsic_views()[0], (320, 240)))
    out = tmp_path / "cam.yaml"
    _fails(capsys, _intrinsics([*views, str(small)], out), "small.png", "320x240", "640x480")
    assert not out.exists()


def test_too_few_usable_views(tmp_path, views, capsys):
    out, rep = tmp_path / "cam.yaml", tmp_path / "r.json"
    _fails(capsys, _intrinsics(views[:5], out, "--report", str(rep)), "only 5 of 5", "--min-views")
    _fails(capsys, _intrinsics(views, out, "--min-views", "12"), "only 9 of 9", "at least 12")
    assert not out.exists() and not rep.exists()


def test_pattern_that_matches_nothing(tmp_path, views, capsys):
    out = tmp_path / "cam.yaml"
    argv = ["calibrate", "intrinsics", *views[:3], "--pattern", "12x8", "--square", "20", "--out", str(out)]
    _fails(capsys, argv, "12x8", "no board found in any of the 3 images")
    _fails(capsys, _intrinsics(views, out)[:-2] + ["--out", str(out), "--pattern", "9by6"], "--pattern")
    assert not out.exists()


def test_rms_above_the_limit_is_refused(tmp_path, views, capsys):
    out, rep = tmp_path / "cam.yaml", tmp_path / "r.json"
    assert main(_intrinsics(views, out, "--max-rms", "0.001", "--report", str(rep))) == 2
    captured = capsys.readouterr()
    assert "verdict: BAD" in captured.out
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and "exceeds 0.001 px" in lines[0] and "not written" in lines[0]
    assert not out.exists() and not rep.exists()


@pytest.fixture
def cell(tmp_path, views, capsys):
    """A good intrinsics file and a belt view."""
    out = tmp_path / "cam.yaml"
    assert main(_intrinsics(views, out)) == 0
    capsys.readouterr()
    image = tmp_path / "belt.png"
    cv2.imwrite(str(image), belt_view())
    return out, image


def _belt(calib, *extra):
    return ["calibrate", "belt", *extra, "--calibration", str(calib)]


def test_belt_failures_leave_the_file_byte_identical(tmp_path, cell, capsys):
    calib, image = cell
    before = calib.read_bytes()
    blank = tmp_path / "blank.png"
    cv2.imwrite(str(blank), np.full((480, 640), 110, np.uint8))
    small = tmp_path / "small.png"
    cv2.imwrite(str(small), np.full((240, 320), 110, np.uint8))
    board = ["--pattern", "9x6", "--square", "40"]
    _fails(capsys, _belt(calib, str(blank), *board), "blank.png", "no 9x6 board found")
    _fails(capsys, _belt(calib, str(small), *board), "small.png", "320x240", "640x480")
    _fails(capsys, _belt(calib, str(tmp_path / "gone.png"), *board), "gone.png", "not found")
    _fails(capsys, _belt(calib, str(image)), "--pattern")
    few = tmp_path / "few.csv"
    few.write_text("100,100,0,0\n200,100,100,0\n200,200,100,100\n")
    _fails(capsys, _belt(calib, "--points", str(few)), "few.csv", "at least 4", "got 3")
    garbled = tmp_path / "garbled.csv"
    garbled.write_text("100,100,0,0\n200,x,100,0\n")
    _fails(capsys, _belt(calib, "--points", str(garbled)), "garbled.csv:2", "4 numbers")
    inconsistent = tmp_path / "inconsistent.csv"
    inconsistent.write_text("100,100,0,0\n500,100,100,0\n500,400,100,100\n120,380,0,100\n")
    _fails(capsys, _belt(calib, "--points", str(inconsistent)), "inconsistent.csv", "mm RMS")
    assert calib.read_bytes() == before
    out = tmp_path / "cell.yaml"
    _fails(capsys, _belt(calib, str(blank), *board, "--out", str(out)), "blank.png")
    assert not out.exists()
    assert list(tmp_path.glob(".*")) == []  # no temp files left behind


def test_belt_needs_intrinsics(tmp_path, capsys):
    image = tmp_path / "belt.png"
    cv2.imwrite(str(image), belt_view())
    _fails(capsys, _belt(tmp_path / "none.yaml", str(image), "--pattern", "9x6", "--square", "40"), "none.yaml")
    _fails(capsys, ["calibrate", "show", str(tmp_path / "none.yaml")], "none.yaml", "not found")


def test_outputs_that_cannot_be_kept_are_refused_before_any_work(tmp_path, views, cell, capsys):
    # Found by walking through the commands: an existing file as the previews' folder, or a folder or
    # a .txt as the belt's preview, raised a traceback after the calibration had been written.
    calib, image = cell
    before = calib.read_bytes()
    out, rep, taken = tmp_path / "new.yaml", tmp_path / "r.json", tmp_path / "taken.png"
    taken.write_bytes(b"a file")
    _fails(capsys, _intrinsics(views, out, "--report", str(rep), "--preview", str(taken)), "it is a file")
    _fails(capsys, _intrinsics(views, out, "--report", str(tmp_path)), "it is a folder")
    _fails(capsys, _intrinsics(views, out, "--preview", str(tmp_path / "no" / "such")), "does not exist")
    assert not out.exists() and not rep.exists() and taken.read_bytes() == b"a file"
    board = [str(image), "--pattern", "9x6", "--square", "40"]
    (tmp_path / "shots.png").mkdir()
    _fails(capsys, _belt(calib, *board, "--preview", str(tmp_path / "shots.png")), "it is a folder")
    _fails(capsys, _belt(calib, *board, "--preview", str(tmp_path / "axes.txt")), "expected a .png")
    _fails(capsys, ["calibrate", "board", "--pattern", "9x6", "--square", "20", "--out",
                    str(tmp_path / "shots.png")], "it is a folder")
    assert calib.read_bytes() == before
    # A preview that can be written is written, and the calibration with it.
    preview = tmp_path / "axes.png"
    assert main(_belt(calib, *board, "--preview", str(preview))) == 0
    assert cv2.imread(str(preview)) is not None and calib.read_bytes() != before
    if os.geteuid() != 0:  # root writes in a read-only folder all the same
        locked = tmp_path / "locked"
        locked.mkdir(mode=0o555)
        _fails(capsys, ["calibrate", "board", "--pattern", "9x6", "--square", "20", "--out",
                        str(locked / "b.png")], "not writable")


def test_previews_are_written_when_the_calibration_is_refused(tmp_path, views, capsys):
    # They show why: the corners found on each view.
    out, folder = tmp_path / "cam.yaml", tmp_path / "previews"
    assert main(_intrinsics(views, out, "--max-rms", "0.001", "--preview", str(folder))) == 2
    assert "exceeds 0.001 px" in capsys.readouterr().err
    assert not out.exists() and len(list(folder.glob("*.png"))) == len(views)


def test_a_capture_that_cannot_start_leaves_no_views_folder(tmp_path, capsys):
    out = tmp_path / "cap.yaml"
    _fails(capsys, ["calibrate", "capture", "--source", str(tmp_path / "nothere.mp4"), "--pattern", "9x6",
                    "--square", "20", "--out", str(out)], "nothere.mp4")
    assert list(tmp_path.iterdir()) == []
