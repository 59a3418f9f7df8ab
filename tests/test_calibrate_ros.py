"""tracker calibrate show --format ros: the calibration as a ROS camera_info file, read back by a
YAML parser with the field names ROS uses."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from tracker import calibration as calib_io
from tracker.cli import main
from tracker.synthetic import STRONG_DISTORTION, CameraSpec


def test_camera_info_has_the_ros_fields_and_our_numbers(tmp_path, capsys):
    calib = CameraSpec(dist_coeffs=STRONG_DISTORTION, tilt_deg=10).calibration()
    path = tmp_path / "c.yaml"
    calib_io.save(calib, path)
    assert main(["calibrate", "show", str(path), "--format", "ros"]) == 0
    info = yaml.safe_load(capsys.readouterr().out)
    assert info["image_width"] == 640 and info["image_height"] == 480 and info["camera_name"]
    k = np.array(info["camera_matrix"]["data"]).reshape(info["camera_matrix"]["rows"], info["camera_matrix"]["cols"])
    assert np.allclose(k, calib.camera_matrix, rtol=1e-9)
    assert info["distortion_model"] == "plumb_bob"
    assert np.allclose(info["distortion_coefficients"]["data"], np.ravel(STRONG_DISTORTION), rtol=1e-9)
    assert info["distortion_coefficients"]["rows"] == 1 and info["distortion_coefficients"]["cols"] == 5
    assert np.allclose(np.reshape(info["rectification_matrix"]["data"], (3, 3)), np.eye(3))
    p = np.reshape(info["projection_matrix"]["data"], (3, 4))
    assert np.allclose(p[:, :3], calib.camera_matrix) and np.allclose(p[:, 3], 0)


def test_export_then_import_gives_the_same_intrinsics(tmp_path, capsys):
    calib = CameraSpec(dist_coeffs=STRONG_DISTORTION, tilt_deg=10).calibration()
    src = tmp_path / "c.yaml"
    calib_io.save(calib, src)
    assert main(["calibrate", "show", str(src), "--format", "ros"]) == 0
    info = tmp_path / "camera_info.yaml"
    info.write_text(capsys.readouterr().out)
    out = tmp_path / "imported.yaml"
    assert main(["calibrate", "import-ros", str(info), "--out", str(out)]) == 0
    back = calib_io.load(out, require_belt=False)
    assert back.size == calib.size
    assert np.allclose(back.camera_matrix, calib.camera_matrix, rtol=1e-9)
    assert np.allclose(back.dist_coeffs.ravel(), np.ravel(STRONG_DISTORTION), rtol=1e-9)
    assert back.rms_reprojection_error_px is None and not back.has_belt


# As ROS camera_calibration (camera_calibration_parsers, yaml-cpp) writes it: a data list over two lines,
# a comment, and the rational (8-coefficient) model.
ROS_FILE = """image_width: 1280
image_height: 720
camera_name: belt_cam   # the wide one
camera_matrix:
  rows: 3
  cols: 3
  data: [901.25, 0, 641.5,
         0, 899.75, 355.25, 0, 0, 1]
distortion_model: rational_polynomial
distortion_coefficients:
  rows: 1
  cols: 8
  data: [-0.31, 0.11, 0.0007, -0.0004, -0.02, 0.01, 0.002, -0.001]
rectification_matrix:
  rows: 3
  cols: 3
  data: [1, 0, 0, 0, 1, 0, 0, 0, 1]
projection_matrix:
  rows: 3
  cols: 4
  data: [901.25, 0, 641.5, 0, 0, 899.75, 355.25, 0, 0, 0, 1, 0]
"""


def test_a_file_written_by_ros_imports(tmp_path):
    info = tmp_path / "ost.yaml"
    info.write_text(ROS_FILE)
    out = tmp_path / "c.yml"
    assert main(["calibrate", "import-ros", str(info), "--out", str(out)]) == 0
    back = calib_io.load(out, require_belt=False)
    assert back.size == (1280, 720)
    assert np.allclose(back.camera_matrix, [[901.25, 0, 641.5], [0, 899.75, 355.25], [0, 0, 1]])
    assert np.allclose(back.dist_coeffs.ravel(), [-0.31, 0.11, 0.0007, -0.0004, -0.02, 0.01, 0.002, -0.001])
    # The same numbers as a YAML parser reads them.
    parsed = yaml.safe_load(ROS_FILE)
    assert np.allclose(back.camera_matrix.ravel(), parsed["camera_matrix"]["data"])


@pytest.mark.parametrize(("change", "message"), [
    (("distortion_model: rational_polynomial", "distortion_model: equidistant"), "distortion_model: expected"),
    (("cols: 8", "cols: 5"), "distortion_coefficients: expected 1x8 values"),
    (("image_width: 1280\n", ""), "image_width: expected a positive integer"),
    (("  data: [901.25, 0, 641.5,\n", "  data: [901.25, 0, 641.5\n"), "camera_matrix: rows, cols and data"),
    (("  data: [-0.31", "  data: -0.31"), "distortion_coefficients"),
])
def test_a_bad_camera_info_is_one_line_exit_2_and_nothing_written(tmp_path, capsys, change, message):
    info = tmp_path / "bad.yaml"
    info.write_text(ROS_FILE.replace(*change, 1))
    out = tmp_path / "c.yaml"
    assert main(["calibrate", "import-ros", str(info), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and message in err and str(info) in err, err
    assert not out.exists()


def test_an_unreadable_camera_info_is_exit_2(tmp_path, capsys):
    assert main(["calibrate", "import-ros", str(tmp_path / "absent.yaml"), "--out", str(tmp_path / "c.yaml")]) == 2
    assert "cannot read a ROS camera_info file" in capsys.readouterr().err
