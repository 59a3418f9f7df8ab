"""The calibration as a ROS ``camera_info`` YAML file (camera_calibration_parsers' format), so the
camera can be used in ROS tools. The OpenCV FileStorage file stays the one the tracker reads."""

from __future__ import annotations

import numpy as np

from tracker.calibration import Calibration


def _matrix(name: str, m: np.ndarray) -> list[str]:
    rows, cols = m.shape
    data = ", ".join(f"{float(v):.10g}" for v in m.reshape(-1))
    return [f"{name}:", f"  rows: {rows}", f"  cols: {cols}", f"  data: [{data}]"]


def camera_info_yaml(calib: Calibration, camera_name: str = "belt_camera") -> str:
    """``image_width``, ``image_height``, ``camera_name``, ``camera_matrix``, ``distortion_model``
    (plumb_bob for 5 coefficients, rational_polynomial for 8), ``distortion_coefficients``,
    ``rectification_matrix`` (identity: a monocular camera) and ``projection_matrix`` ([K | 0])."""
    d = calib.dist_coeffs.reshape(1, -1)
    model = "plumb_bob" if d.shape[1] <= 5 else "rational_polynomial"
    if d.shape[1] < 5:
        d = np.hstack([d, np.zeros((1, 5 - d.shape[1]))])
    k = calib.camera_matrix
    lines = [f"image_width: {calib.image_width}", f"image_height: {calib.image_height}",
             f"camera_name: {camera_name}"]
    lines += _matrix("camera_matrix", k)
    lines.append(f"distortion_model: {model}")
    lines += _matrix("distortion_coefficients", d)
    lines += _matrix("rectification_matrix", np.eye(3))
    lines += _matrix("projection_matrix", np.hstack([k, np.zeros((3, 1))]))
    return "\n".join(lines) + "\n"
