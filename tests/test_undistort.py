"""Undistortion: exact for measured points, border-preserving for viewed frames."""

import cv2
import numpy as np

from tracker.synthetic import STRONG_DISTORTION, CameraSpec
from tracker.undistort import BeltMapper, FrameUndistorter


def _camera():
    return CameraSpec(dist_coeffs=STRONG_DISTORTION, tilt_deg=20, yaw_deg=30).calibration()


def test_points_map_to_the_belt_exactly_even_in_the_corners():
    calib = _camera()
    mapper = BeltMapper(calib)
    # Belt points seen near the image corners, where the distortion is strongest.
    w, h = calib.size
    px = np.array([[2.0, 2.0], [w - 3.0, 2.0], [w - 3.0, h - 3.0], [2.0, h - 3.0], [w / 2, h / 2]])
    world = mapper.to_mm(px)
    back, _ = cv2.projectPoints(np.column_stack([world, np.zeros(len(world))]), calib.belt_rvec, calib.belt_tvec,
                                calib.camera_matrix, calib.dist_coeffs)
    assert np.abs(back.reshape(-1, 2) - px).max() < 1e-6
    # OpenCV's default (5 iterations) is visibly wrong there: the reason for our criteria.
    norm = cv2.undistortPoints(px.reshape(-1, 1, 2), calib.camera_matrix, calib.dist_coeffs)
    default, _ = cv2.projectPoints(np.column_stack([norm.reshape(-1, 2), np.ones(len(px))]), np.zeros(3),
                                   np.zeros(3), calib.camera_matrix, calib.dist_coeffs)
    assert np.abs(default.reshape(-1, 2) - px).max() > 0.01


def test_plane_above_the_belt_for_tall_parts():
    calib = _camera()
    top = BeltMapper(calib, height_mm=40.0)
    p = np.array([[100.0, 80.0]])
    xy = top.to_mm(p)[0]
    # World Z points into the belt: 40 mm above it is Z = -40.
    back, _ = cv2.projectPoints(np.array([[xy[0], xy[1], -40.0]]), calib.belt_rvec, calib.belt_tvec,
                                calib.camera_matrix, calib.dist_coeffs)
    assert np.abs(back.reshape(2) - p[0]).max() < 1e-6


def test_whole_frame_view_keeps_the_border_that_cv2_undistort_crops():
    calib = _camera()
    w, h = calib.size
    frame = np.full((h, w), 200, np.uint8)
    kept = FrameUndistorter(calib)(frame)
    cropped = cv2.undistort(frame, calib.camera_matrix, calib.dist_coeffs)
    # Every source pixel lands somewhere in the kept view (corners included) ...
    corners = np.array([[0, 0], [w - 1, 0], [w - 1, h - 1], [0, h - 1]], np.float64).reshape(-1, 1, 2)
    und = FrameUndistorter(calib)
    moved = cv2.undistortPoints(corners, calib.camera_matrix, calib.dist_coeffs, P=und.new_camera_matrix)
    assert np.all((moved >= -0.5) & (moved <= [w - 0.5, h - 0.5]))
    # ... while the same K pushes the corners out of the image: that belt area is lost.
    same_k = cv2.undistortPoints(corners, calib.camera_matrix, calib.dist_coeffs, P=calib.camera_matrix)
    assert np.any((same_k < 0) | (same_k > [w, h]))
    assert (kept > 0).sum() < (cropped > 0).sum()  # kept view shows black margins instead of losing content
