"""ChArUco boards: intrinsics from partly hidden views and the belt pose, against the true camera, and
the printable sheet from `tracker calibrate board`."""

from __future__ import annotations

import functools
import struct

import cv2
import numpy as np
import pytest
from calib_support import true_calibration

from tracker import calibration as calib_io
from tracker.calibrate.charuco import CharucoSpec, parse_board
from tracker.calibrate.synthetic_board import look_at_pose
from tracker.calibrate.synthetic_charuco import CharucoRenderer
from tracker.cli import main
from tracker.undistort import BeltMapper

VIEW_BOARD = CharucoSpec(11, 8, 20.0, 14.0, "DICT_5X5_100")
BELT_BOARD = CharucoSpec(11, 8, 40.0, 28.0, "DICT_5X5_100")
N_VIEWS = 14


@functools.cache
def _renderer(spec: CharucoSpec) -> CharucoRenderer:
    c = true_calibration()
    return CharucoRenderer(c.camera_matrix, c.dist_coeffs, c.size, spec)


def _pose(centre_cam_mm, tilt, direction, spin, spec: CharucoSpec):
    # look_at_pose centres a chessboard Pattern; the same placement for a ChArUco board's centre.
    rvec, tvec = look_at_pose(np.asarray(centre_cam_mm, float), tilt, direction, spin, _renderer(spec).pattern)
    rot = cv2.Rodrigues(rvec)[0]
    shift = rot @ np.array([spec.square_mm, spec.square_mm, 0.0])  # its chessboard's corner (0,0) is (1,1) squares in
    return rvec, tvec - shift.reshape(3, 1)


@functools.cache
def _views() -> tuple[np.ndarray, ...]:
    """Views 430-490 mm away, tilted 20-45 deg; every third partly covered (a hand), every fourth partly
    outside the image."""
    rng = np.random.default_rng(7)
    c = true_calibration()
    w, h = c.size
    f = c.camera_matrix[0, 0]
    images = []
    for i in range(N_VIEWS):
        z = 430 + 60 * rng.random()
        ang = 2 * np.pi * i / N_VIEWS
        rad = 0.0 if i == 0 else (0.2 if i % 2 else 0.32)
        if i % 4 == 3:
            rad = 0.5  # a third of the board beyond the image's edge
        x, y = z * rad * np.cos(ang) * (w / f), z * rad * np.sin(ang) * (h / f)
        tilt = 20 + 25 * ((i * 5) % N_VIEWS) / (N_VIEWS - 1)
        rvec, tvec = _pose([x, y, z], tilt, rng.uniform(0, 360), rng.uniform(-30, 30), VIEW_BOARD)
        image = _renderer(VIEW_BOARD).render(rvec, tvec, seed=i)
        if i % 3 == 1:
            u, v = int(w / 2 + x * f / z), int(h / 2 + y * f / z)
            image[v - 40:v + 60, u - 90:u + 10] = 120  # a hand over part of the board
        images.append(image)
    return tuple(images)


def _write(folder, images) -> list[str]:
    paths = []
    for i, image in enumerate(images):
        paths.append(str(folder / f"v{i:02d}.png"))
        cv2.imwrite(paths[-1], image)
    return paths


@pytest.fixture(scope="module")
def intrinsics(tmp_path_factory):
    folder = tmp_path_factory.mktemp("charuco")
    paths = _write(folder, _views())
    out = folder / "cam.yaml"
    code = main(["calibrate", "intrinsics", *paths, "--board", str(VIEW_BOARD), "--out", str(out),
                 "--preview", str(folder / "preview")])
    return code, out, folder


def test_partial_views_count_and_give_the_true_camera(intrinsics):
    code, out, folder = intrinsics
    assert code == 0
    views = _views()
    partial = [i for i in range(N_VIEWS) if i % 3 == 1 or i % 4 == 3]
    found = [len(cv2.aruco.CharucoDetector(VIEW_BOARD.board()).detectBoard(views[i])[1]) for i in partial]
    assert all(n < 70 for n in found), "those views do not show the whole board"
    true = true_calibration().camera_matrix
    got = calib_io.load(out, require_belt=False).camera_matrix
    assert abs(got[0, 0] / true[0, 0] - 1) < 0.003 and abs(got[1, 1] / true[1, 1] - 1) < 0.003, got
    assert abs(got[0, 2] - true[0, 2]) < 1.0 and abs(got[1, 2] - true[1, 2]) < 1.0, got
    assert len(list((folder / "preview").glob("*.png"))) == N_VIEWS


def _belt_pose() -> tuple[np.ndarray, np.ndarray]:
    """The belt board lying on the belt, turned 10 deg, centred where the optical axis meets the belt."""
    c = true_calibration()
    r_wb = cv2.Rodrigues(np.array([0.0, 0.0, np.radians(10.0)]))[0]
    w_mm, h_mm = BELT_BOARD.size_mm
    t_wb = -r_wb @ np.array([w_mm / 2, h_mm / 2, 0.0])
    r_cw = cv2.Rodrigues(c.belt_rvec)[0]
    return cv2.Rodrigues(r_cw @ r_wb)[0], (r_cw @ t_wb + c.belt_tvec.reshape(3)).reshape(3, 1)


@pytest.mark.parametrize("intrinsics_from", ["true camera", "charuco views"])
def test_the_belt_pose_from_a_charuco_board_maps_the_belt_within_0_1_mm(tmp_path, intrinsics, intrinsics_from):
    """With the true intrinsics (the belt pose alone: 0.05 mm measured) and with those calibrated from the
    partly hidden views above (the whole chain: 0.08 mm)."""
    c = true_calibration()
    intr = tmp_path / "intrinsics.yaml"
    calib_io.save(calib_io.Calibration(c.image_width, c.image_height, c.camera_matrix, c.dist_coeffs, 0.1), intr)
    if intrinsics_from == "charuco views":
        intr = intrinsics[1]
    rvec, tvec = _belt_pose()
    image = _renderer(BELT_BOARD).render(rvec, tvec, seed=5)
    image[300:380, 250:330] = 120  # something lying on part of the board
    cv2.imwrite(str(tmp_path / "belt.png"), image)
    out = tmp_path / "cell.yaml"
    assert main(["calibrate", "belt", str(tmp_path / "belt.png"), "--board", str(BELT_BOARD),
                 "--calibration", str(intr), "--out", str(out)]) == 0
    est = calib_io.load(out)
    # Truth: the board's own frame on the belt (world = board frame), from the pose it was rendered at.
    truth = c.with_belt(rvec, tvec)
    u, v = np.meshgrid(np.linspace(40, 600, 15), np.linspace(40, 440, 11))
    px = np.column_stack([u.ravel(), v.ravel()])
    err = np.linalg.norm(BeltMapper(est).to_mm(px) - BeltMapper(truth).to_mm(px), axis=1)
    assert err.mean() < 0.1 and np.percentile(err, 95) < 0.3, (err.mean(), np.percentile(err, 95))


def test_the_printed_board_is_true_to_scale_and_detected(tmp_path, capsys):
    out = tmp_path / "board.png"
    assert main(["calibrate", "board", "--board", str(VIEW_BOARD), "--out", str(out), "--dpi", "200"]) == 0
    assert "one square prints" in capsys.readouterr().out
    data = out.read_bytes()
    at = data.index(b"pHYs")
    per_metre = struct.unpack(">II", data[at + 4:at + 12])
    assert per_metre == (round(200 / 0.0254),) * 2
    sheet = cv2.imread(str(out), cv2.IMREAD_GRAYSCALE)
    assert sheet.shape == (round(210 / 25.4 * 200), round(297 / 25.4 * 200))  # A4, turned for a wide board
    corners, ids, _, _ = cv2.aruco.CharucoDetector(VIEW_BOARD.board()).detectBoard(sheet)
    assert len(ids) == 70
    where = dict(zip(ids.ravel().tolist(), corners.reshape(-1, 2), strict=True))
    spacing = np.linalg.norm(where[9] - where[0]) / 9  # corners 0 and 9: one row, 9 squares apart
    assert spacing == pytest.approx(round(20 / 25.4 * 200), abs=0.05)


@pytest.mark.parametrize(("argv", "message"), [
    (["--board", "charuco:11x8:20:25:DICT_5X5_100"], "expected 0 < marker < square"),
    (["--board", "charuco:11x8:20:14:DICT_9X9_1"], "unknown dictionary"),
    (["--board", "charuco:11x8:20:DICT_5X5_100"], "expected charuco:COLSxROWS"),
    (["--board", "charuco:30x30:20:14:DICT_4X4_50"], "has 50 markers"),
    (["--board", "charuco:11x8:40:28:DICT_5X5_100"], "A4 is"),
    (["--pattern", "9x6", "--square", "25"], "--pattern 9x6 --square 25: needs"),  # the options given
    (["--board", "charuco:11x8:20:14:DICT_5X5_100", "--pattern", "9x6"], "not both"),
])
def test_bad_boards_are_one_line_exit_2(tmp_path, capsys, argv, message):
    out = tmp_path / "b.png"
    assert main(["calibrate", "board", *argv, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0], err
    assert not out.exists()


def test_the_spec_reads_back_as_written():
    assert parse_board(str(VIEW_BOARD)) == VIEW_BOARD


def test_a_printed_chessboard_is_found_with_the_pattern_it_states(tmp_path, capsys):
    out = tmp_path / "chess.png"
    assert main(["calibrate", "board", "--pattern", "9x6", "--square", "20", "--out", str(out), "--dpi", "150"]) == 0
    sheet = cv2.imread(str(out), cv2.IMREAD_GRAYSCALE)
    ok, corners = cv2.findChessboardCorners(sheet, (9, 6))
    assert ok
    step = np.linalg.norm(np.diff(corners.reshape(6, 9, 2), axis=1), axis=2)
    assert np.allclose(step, round(20 / 25.4 * 150), atol=0.5)
