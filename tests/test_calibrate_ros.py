"""tracker calibrate show --format ros: the calibration as a ROS camera_info file, read back by a
YAML parser with the field names ROS uses."""

from __future__ import annotations

import numpy as np
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
