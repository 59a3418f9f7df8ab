"""tracker calibrate scale: an approximate straight-down calibration from a scale, marked as such."""

from __future__ import annotations

import numpy as np
import pytest

from tracker import calibration as calib_io
from tracker.cli import main
from tracker.undistort import BeltMapper


def test_a_part_of_known_length_sets_the_scale_and_the_file_says_approximate(tmp_path, capsys):
    out = tmp_path / "approx.yaml"
    assert main(["calibrate", "scale", "--size", "960x540", "--length-px", "250", "--length-mm", "100",
                 "--out", str(out)]) == 0
    calib = calib_io.load(out)
    assert calib.approximate and calib.size == (960, 540)
    # 250 px anywhere along a row is 100 mm on the belt; the image centre is the origin.
    mapper = BeltMapper(calib)
    mm = mapper.to_mm(np.array([[479.5, 269.5], [479.5 + 250, 269.5], [100.0, 400.0], [100.0, 150.0]]))
    assert mm[0] == pytest.approx([0.0, 0.0], abs=1e-9)
    assert mm[1] - mm[0] == pytest.approx([100.0, 0.0], abs=1e-9)
    assert mm[2] - mm[3] == pytest.approx([0.0, 100.0], abs=1e-9)
    capsys.readouterr()
    assert main(["calibrate", "show", str(out)]) == 0
    assert "APPROXIMATE" in capsys.readouterr().out
    # A board calibration is not approximate.
    calib_io.save(calib_io.Calibration(960, 540, calib.camera_matrix, calib.dist_coeffs, None, calib.belt_rvec,
                                       calib.belt_tvec, calib.belt_homography), tmp_path / "board.yaml")
    assert not calib_io.load(tmp_path / "board.yaml").approximate


@pytest.mark.parametrize("args,needle", [
    (["--size", "960x540"], "give --mm-per-px S, or both"),
    (["--size", "960x540", "--length-px", "250"], "give --mm-per-px S, or both"),
    (["--size", "960x540", "--mm-per-px", "0.4", "--length-px", "2", "--length-mm", "1"], "give --mm-per-px"),
    (["--size", "960x540", "--mm-per-px", "-1"], "expected 0.001 to 1000 mm per pixel"),
    (["--size", "960x540", "--length-px", "0", "--length-mm", "100"], "expected positive lengths"),
    (["--size", "big", "--mm-per-px", "0.4"], "--size: expected WIDTHxHEIGHT"),
    (["--size", "0x540", "--mm-per-px", "0.4"], "--size: expected a positive"),
])
def test_bad_scale_input_is_one_line_and_writes_nothing(tmp_path, capsys, args, needle):
    out = tmp_path / "c.yaml"
    assert main(["calibrate", "scale", *args, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert needle in err and len(err.strip().splitlines()) == 1
    assert not out.exists()


def test_a_belt_pose_is_not_fitted_through_approximate_intrinsics(tmp_path, capsys):
    # Its focal length is a guess: the pose came out 2518 mm above a belt 700 mm away, and the file lost
    # the mark that has every part measured flat.
    import cv2
    from calib_support import belt_view

    out, image = tmp_path / "approx.yaml", tmp_path / "belt.png"
    assert main(["calibrate", "scale", "--size", "640x480", "--mm-per-px", "0.5", "--out", str(out)]) == 0
    assert cv2.imwrite(str(image), belt_view())
    before = out.read_bytes()
    capsys.readouterr()
    assert main(["calibrate", "belt", str(image), "--pattern", "9x6", "--square", "40", "--calibration",
                 str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "APPROXIMATE" in err[0] and "calibrate the intrinsics first" in err[0], err
    assert out.read_bytes() == before
