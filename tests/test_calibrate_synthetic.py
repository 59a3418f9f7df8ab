"""calibrate intrinsics + belt on views rendered through a known camera: the results against the truth."""

from __future__ import annotations

import contextlib
import functools
import io
import json
import tempfile
from pathlib import Path

import cv2
import numpy as np
import pytest
from calib_support import (
    BELT_PATTERN,
    belt_board_pose,
    belt_view,
    intrinsic_views,
    true_calibration,
    write_views,
)

from tracker import calibration
from tracker.cli import main
from tracker.undistort import BeltMapper


@functools.cache
def _intrinsics_run() -> tuple[Path, str, dict]:
    """(calibration file, printed report, JSON report) of one CLI run over the views plus a blank image."""
    folder = Path(tempfile.mkdtemp(prefix="calib-synth-"))
    paths = write_views(folder, intrinsic_views())
    blank = folder / "blank.png"
    cv2.imwrite(str(blank), np.full((480, 640), 110, np.uint8))
    out, rep = folder / "cam.yaml", folder / "report.json"
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        code = main(["calibrate", "intrinsics", *paths, str(blank), "--pattern", "9x6", "--square", "20",
                     "--out", str(out), "--report", str(rep), "--preview", str(folder / "preview")])
    assert code == 0, buf.getvalue()
    return out, buf.getvalue(), json.loads(rep.read_text())


@pytest.fixture(scope="session")
def intrinsics_run():
    return _intrinsics_run()


def test_intrinsics_recover_the_true_camera(intrinsics_run):
    out, text, report = intrinsics_run
    truth = true_calibration().camera_matrix
    calib = calibration.load(out, require_belt=False)
    k = calib.camera_matrix
    assert abs(k[0, 0] / truth[0, 0] - 1) < 1e-3
    assert abs(k[1, 1] / truth[1, 1] - 1) < 1e-3
    assert abs(k[0, 2] - truth[0, 2]) < 1.0 and abs(k[1, 2] - truth[1, 2]) < 1.0
    assert calib.rms_reprojection_error_px < 0.2
    # The blank image is listed and skipped; the 15 views are used; previews are written for all 16.
    assert "blank.png" in text and "no board found: skipped" in text
    assert report["all_views"]["n_views"] == 15
    assert len(list((out.parent / "preview").glob("*.png"))) == 16
    tilts = [v["tilt_deg"] for v in report["views"] if v["tilt_deg"] is not None]
    assert min(tilts) > 19 and max(tilts) < 46


def test_belt_mapping_matches_the_true_camera(intrinsics_run, tmp_path, capsys):
    cam, _, _ = intrinsics_run
    image = tmp_path / "belt.png"
    cv2.imwrite(str(image), belt_view())
    out, preview = tmp_path / "cell.yaml", tmp_path / "axes.png"
    code = main(["calibrate", "belt", str(image), "--pattern", "9x6", "--square", "40", "--calibration", str(cam),
                 "--out", str(out), "--preview", str(preview)])
    text = capsys.readouterr().out
    assert code == 0, text
    got = calibration.load(out)
    # The true camera expressed in the board's frame.
    truth = true_calibration()
    rvec, tvec = belt_board_pose()
    true_in_board = calibration.Calibration(truth.image_width, truth.image_height, truth.camera_matrix,
                                            truth.dist_coeffs).with_belt(rvec, tvec)
    # Pixels covering the board's area (its outer squares included).
    s = BELT_PATTERN.square_mm
    gx, gy = np.meshgrid(np.linspace(-s, BELT_PATTERN.cols * s, 25), np.linspace(-s, BELT_PATTERN.rows * s, 17))
    board_mm = np.column_stack([gx.ravel(), gy.ravel()])
    px, _ = cv2.projectPoints(np.column_stack([board_mm, np.zeros(len(board_mm))]), rvec, tvec,
                              truth.camera_matrix, truth.dist_coeffs)
    px = px.reshape(-1, 2)
    want = BeltMapper(true_in_board).to_mm(px)
    assert np.abs(want - board_mm).max() < 1e-3  # the true mapping is exact
    err = np.linalg.norm(BeltMapper(got).to_mm(px) - want, axis=1)
    assert err.mean() <= 0.2
    assert abs(got.camera_height_mm() - true_in_board.camera_height_mm()) < 3.0
    assert abs(got.tilt_deg() - true_in_board.tilt_deg()) < 0.3
    assert "camera height above the belt" in text and "residual on the belt" in text
    assert cv2.imread(str(preview)).shape == (480, 640, 3)
    # The intrinsics file was left alone (--out given).
    assert not calibration.load(cam, require_belt=False).has_belt


def test_belt_from_point_pairs_rejects_a_wrong_pair(intrinsics_run, tmp_path, capsys):
    cam, _, _ = intrinsics_run
    truth = true_calibration()
    world = np.array([[-200, -150], [220, -140], [210, 160], [-190, 150], [0, 0], [100, -60], [-80, 90]], float)
    px, _ = cv2.projectPoints(np.column_stack([world, np.zeros(len(world))]), truth.belt_rvec, truth.belt_tvec,
                              truth.camera_matrix, truth.dist_coeffs)
    px = px.reshape(-1, 2)
    px[5] += [25.0, 0.0]  # a mistyped pair
    pairs = tmp_path / "pairs.csv"
    pairs.write_text(
        "u,v,X,Y\n" + "".join(f"{u:.3f},{v:.3f},{x},{y}\n" for (u, v), (x, y) in zip(px, world, strict=True))
    )
    target = tmp_path / "cell.yaml"
    target.write_bytes(Path(cam).read_bytes())
    assert main(["calibrate", "belt", "--points", str(pairs), "--calibration", str(target)]) == 0
    text = capsys.readouterr().out
    got = calibration.load(target)  # updated in place
    assert "6 " in text and "  outlier" in text and "1 pair(s) left out as outliers" in text
    grid = np.array([[x, y] for x in range(-200, 201, 50) for y in range(-150, 151, 50)], float)
    gpx, _ = cv2.projectPoints(np.column_stack([grid, np.zeros(len(grid))]), truth.belt_rvec, truth.belt_tvec,
                               truth.camera_matrix, truth.dist_coeffs)
    err = np.linalg.norm(BeltMapper(got).to_mm(gpx.reshape(-1, 2)) - grid, axis=1)
    assert err.mean() < 1.0
    assert abs(got.camera_height_mm() - 700.0) < 5.0


def test_a_view_from_another_lens_is_rejected_as_an_outlier(tmp_path, capsys):
    from calib_support import VIEW_PATTERN

    from tracker.calibrate.synthetic_board import BoardRenderer, look_at_pose

    # One view taken through a different lens (focal +15 %, other distortion): it cannot fit the others.
    c = true_calibration()
    k_other = c.camera_matrix.copy()
    k_other[0, 0] *= 1.15
    k_other[1, 1] *= 1.15
    other = BoardRenderer(k_other, np.array([[0.1, 0.0, 0.0, 0.0, 0.0]]), c.size, VIEW_PATTERN)
    rvec, tvec = look_at_pose(np.array([60.0, -40.0, 420.0]), 35.0, 120.0, 10.0, VIEW_PATTERN)
    odd = other.render(rvec, tvec, seed=7)
    paths = write_views(tmp_path, intrinsic_views()) + write_views(tmp_path, [odd], prefix="odd")
    out, rep = tmp_path / "cam.yaml", tmp_path / "report.json"
    assert main(["calibrate", "intrinsics", *paths, "--pattern", "9x6", "--square", "20",
                 "--out", str(out), "--report", str(rep)]) == 0
    text = capsys.readouterr().out
    report = json.loads(rep.read_text())
    rejected = [v for v in report["views"] if v["rejected"]]
    assert [Path(v["file"]).name for v in rejected] == ["odd00.png"]
    assert "odd00.png" in text and "REJECTED" in text
    assert report["written"] == "without_outliers" and report["without_outliers"]["n_views"] == 15
    # Without it, the written camera is the true one again; with it, the fit was worse.
    truth = c.camera_matrix[0, 0]
    fx = calibration.load(out, require_belt=False).camera_matrix[0, 0]
    assert abs(fx / truth - 1) < 1e-3
    assert report["all_views"]["rms_px"] > 2 * report["without_outliers"]["rms_px"]
