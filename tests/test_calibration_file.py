"""The calibration file of contract section 1: round trip and every rejection."""

import cv2
import numpy as np
import pytest

from tracker import calibration as calib_io
from tracker.cli import main
from tracker.errors import CalibrationError
from tracker.synthetic import STRONG_DISTORTION, CameraSpec


@pytest.fixture(scope="module")
def calib():
    return CameraSpec(dist_coeffs=STRONG_DISTORTION, tilt_deg=12, yaw_deg=40).calibration()


@pytest.mark.parametrize("suffix", [".yaml", ".yml", ".xml"])
def test_round_trip_is_exact(tmp_path, calib, suffix):
    path = tmp_path / f"calib{suffix}"
    calib_io.save(calib, path)
    back = calib_io.load(path)
    for name in ("camera_matrix", "dist_coeffs", "belt_rvec", "belt_tvec", "belt_homography"):
        assert np.array_equal(getattr(back, name), getattr(calib, name)), name
    assert back.size == calib.size
    # Any OpenCV program reads it: plain FileStorage, the contract's node names.
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    assert int(fs.getNode("image_width").real()) == calib.image_width
    assert fs.getNode("belt_homography").mat().shape == (3, 3)
    fs.release()


def test_homography_matches_its_definition(calib):
    rot, _ = cv2.Rodrigues(calib.belt_rvec)
    expected = np.linalg.inv(calib.camera_matrix @ np.column_stack([rot[:, 0], rot[:, 1], calib.belt_tvec[:, 0]]))
    assert np.allclose(calib.belt_homography, expected / expected[2, 2])
    assert calib.belt_homography[2, 2] == 1.0
    assert calib.camera_height_mm() == pytest.approx(700.0)
    assert calib.tilt_deg() == pytest.approx(12.0)


def _write(path, nodes: dict):
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    for name, value in nodes.items():
        fs.write(name, value)
    fs.release()


def _nodes(calib):
    return {
        "image_width": calib.image_width, "image_height": calib.image_height,
        "camera_matrix": calib.camera_matrix, "dist_coeffs": calib.dist_coeffs,
        "belt_rvec": calib.belt_rvec, "belt_tvec": calib.belt_tvec, "belt_homography": calib.belt_homography,
    }


BAD = {
    "missing node": (lambda n: n.pop("camera_matrix"), "camera_matrix: missing"),
    "missing belt node": (lambda n: n.pop("belt_tvec"), "belt_tvec: missing"),
    "wrong shape": (lambda n: n.update(camera_matrix=np.eye(4)), "camera_matrix: expected a 3x3 matrix, got 4x4"),
    "wrong dist length": (lambda n: n.update(dist_coeffs=np.zeros((1, 6))), "dist_coeffs: expected 1xN"),
    "non-finite": (
        lambda n: n.update(belt_tvec=np.array([[0.0], [np.nan], [700.0]])), "belt_tvec: contains non-finite"
    ),
    "homography inconsistent": (
        lambda n: n.update(belt_homography=n["belt_homography"] @ np.diag([1.01, 1.0, 1.0])),
        "belt_homography: disagrees with belt_rvec/belt_tvec",
    ),
    "not a matrix": (lambda n: n.update(belt_rvec=3), "belt_rvec: expected a matrix"),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_rejections_name_file_and_node(tmp_path, calib, case):
    mutate, message = BAD[case]
    nodes = _nodes(calib)
    mutate(nodes)
    path = tmp_path / "bad.yaml"
    _write(path, nodes)
    with pytest.raises(CalibrationError) as err:
        calib_io.load(path)
    assert str(path) in str(err.value) and message in str(err.value)
    assert "\n" not in str(err.value)


def test_missing_and_corrupt_files(tmp_path):
    with pytest.raises(CalibrationError, match="not found"):
        calib_io.load(tmp_path / "nope.yaml")
    garbage = tmp_path / "garbage.yaml"
    garbage.write_text("%YAML:1.0\n---\ncamera_matrix: [1, 2\n  : : :\n")
    with pytest.raises(CalibrationError, match="garbage.yaml"):
        calib_io.load(garbage)
    with pytest.raises(CalibrationError, match="unsupported extension"):
        calib_io.load(tmp_path / "calib.json")


def test_failed_save_leaves_the_old_file_intact(tmp_path, calib, monkeypatch):
    path = tmp_path / "calib.yaml"
    calib_io.save(calib, path)
    before = path.read_bytes()

    def boom(*_args, **_kw):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(calib_io.os, "replace", boom)
    with pytest.raises(CalibrationError, match="No space left"):
        calib_io.save(calib.with_belt(np.zeros(3), np.array([0, 0, 900.0])), path)
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["calib.yaml"]  # no temp file left behind


def test_frame_size_mismatch_is_rejected(calib):
    calib.check_frame_size(640, 480, "cam")
    with pytest.raises(CalibrationError.__base__, match="frame is 320x240, calibration .* is for 640x480"):
        calib.check_frame_size(320, 240, "cam")


def test_cli_exit_code_2_and_one_line(tmp_path, calib, capsys):
    nodes = _nodes(calib)
    nodes.pop("belt_homography")
    bad = tmp_path / "bad.yml"
    _write(bad, nodes)
    code = main(["run", "--source", str(tmp_path / "x%05d.png"), "--calibration", str(bad), "--no-plc", "--quiet"])
    err = capsys.readouterr().err
    assert code == 2
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1 and "Traceback" not in err


def test_a_belt_behind_the_camera_or_a_mirrored_board_frame_is_refused():
    from tracker.calibration import Calibration, homography_from_pose

    good = CameraSpec(tilt_deg=10).calibration()
    k, d = good.camera_matrix, good.dist_coeffs
    rot, _ = cv2.Rodrigues(good.belt_rvec)
    cases = {
        "behind the camera": (good.belt_rvec, -good.belt_tvec),
        # The same plane with the board frame turned over (Y and Z flipped): the camera on Z > 0.
        "far side of the belt": (cv2.Rodrigues(rot @ np.diag([1.0, -1.0, -1.0]))[0], good.belt_tvec),
    }
    for needle, (rvec, tvec) in cases.items():
        with pytest.raises(CalibrationError, match=needle):
            Calibration(640, 480, k, d, None, rvec, tvec, homography_from_pose(k, rvec, tvec), source="x.yaml")
