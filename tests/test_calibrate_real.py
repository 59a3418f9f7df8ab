"""calibrate intrinsics on OpenCV's own sample views, against OpenCV's published test values (recipe A)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tracker import calibration
from tracker.cli import main

K_REF = np.array([[532.80992189, 0, 342.4952186], [0, 532.93346422, 233.8879292], [0, 0, 1]])
D_REF = np.array([-2.81325576e-01, 2.91130406e-02, 1.21234330e-03, -1.40825372e-04, 1.54865844e-01])
RMS_REF = 0.196334638034


def test_opencv_left_views_match_reference(shared_data, tmp_path, capsys):
    images = sorted(str(p) for p in (shared_data / "opencv_calib").glob("left*.jpg"))
    assert len(images) == 13
    out, rep = tmp_path / "left.yaml", tmp_path / "report.json"
    code = main(["calibrate", "intrinsics", *images, "--pattern", "9x6", "--square", "1",
                 "--out", str(out), "--report", str(rep)])
    text = capsys.readouterr().out
    assert code == 0
    report = json.loads(rep.read_text())
    every = report["all_views"]
    assert every["n_views"] == 13
    assert abs(every["rms_px"] - RMS_REF) < 0.05
    assert np.abs(np.array(every["camera_matrix"]) - K_REF).sum() < 10
    assert np.abs(np.array(every["dist_coeffs"]) - D_REF).sum() < 0.05
    # The file holds the final calibration, readable without a belt pose, with its RMS.
    calib = calibration.load(out, require_belt=False)
    final = report["without_outliers"] or every
    assert np.allclose(calib.camera_matrix, final["camera_matrix"])
    assert abs(calib.rms_reprojection_error_px - final["rms_px"]) < 1e-9
    assert not calib.has_belt
    # The report: a row per view with its corner count, the coverage grid and a verdict.
    assert all(f"left{n:02d}.jpg" in text for n in (1, 2, 3, 4, 5, 6, 7, 8, 9, 11, 12, 13, 14))
    assert text.count(" 54 ") >= 13
    assert "coverage" in text and "verdict:" in text
    # OpenCV's views never reach the image's left border (see the coverage grid): the report says so.
    assert "left" in report["borders_missed"]

    assert main(["calibrate", "show", str(out)]) == 0
    shown = capsys.readouterr().out
    assert f"fx {calib.camera_matrix[0, 0]:.3f}" in shown and "belt pose: none" in shown


def test_wide_angle_views_match_opencv_used_directly(shared_data, tmp_path):
    """50 real views through a strongly distorting lens (../shared/data/wide_angle_calib): OpenCV used
    directly (cornerSubPix with an 11 px half window) reaches RMS 0.234 px over all 50; so must we,
    rejecting at most one view."""
    views = sorted((shared_data / "wide_angle_calib").glob("left-*.png"))
    if len(views) < 50:
        pytest.skip(f"{shared_data / 'wide_angle_calib'} is absent or incomplete")
    report = tmp_path / "report.json"
    code = main(["calibrate", "intrinsics", *map(str, views), "--pattern", "9x6", "--square", "25",
                 "--out", str(tmp_path / "wide.yaml"), "--report", str(report)])
    assert code == 0
    data = json.loads(report.read_text())
    assert data["all_views"]["rms_px"] <= 0.2345 and data["all_views"]["n_views"] == 50
    assert data["without_outliers"]["n_views"] >= 49
    assert data["without_outliers"]["rms_px"] <= 0.234


def test_a_pattern_smaller_than_the_board_is_warned(shared_data, tmp_path, capsys):
    """--pattern 8x6 on OpenCV's 9x6 board: corners are found, but the checker goes on past them."""
    images = sorted(str(p) for p in (shared_data / "opencv_calib").glob("left*.jpg"))
    for pattern, warned in (("8x6", True), ("9x6", False)):
        rep = tmp_path / f"{pattern}.json"
        assert main(["calibrate", "intrinsics", *images, "--pattern", pattern, "--square", "25",
                     "--out", str(tmp_path / f"{pattern}.yaml"), "--report", str(rep)]) == 0
        warnings = json.loads(rep.read_text())["warnings"]
        assert any("more inner corners than --pattern" in w for w in warnings) == warned, warnings
    assert "more inner corners" in capsys.readouterr().out
