"""``tracker run`` end to end through the real CLI: contract format and exit codes."""

import json
import math
import subprocess
import sys

import cv2
import numpy as np
import pytest

from tracker.cli import main
from tracker.config import SegmentConfig
from tracker.evaluate import evaluate


def _run(args):
    return subprocess.run([sys.executable, "-m", "tracker", *args], capture_output=True, text=True, timeout=300)


def test_run_writes_the_contract_pose_stream(scene_dir, tmp_path):
    poses_path = tmp_path / "poses.jsonl"
    proc = _run(["run", "--source", str(scene_dir / "frames" / "%05d.png"), "--calibration",
                 str(scene_dir / "calibration.yaml"), "--no-plc", "--poses", str(poses_path), "--fps", "30"])
    assert proc.returncode == 0, proc.stderr
    lines = poses_path.read_text(encoding="utf-8").splitlines()
    truths = [json.loads(line) for line in (scene_dir / "truth.jsonl").read_text().splitlines()]
    assert len(lines) == len(truths)
    poses = []
    for index, line in enumerate(lines):
        # No NaN/Infinity: strict JSON parsing rejects them.
        pose = json.loads(line, parse_constant=lambda c: pytest.fail(f"non-finite {c}"))
        assert list(pose) == ["frame", "t", "objects"] and pose["frame"] == index
        assert pose["t"] == pytest.approx(index / 30.0, abs=1e-9)
        for obj in pose["objects"]:
            assert list(obj) == ["id", "x_mm", "y_mm", "angle_deg", "length_mm", "width_mm", "corners_mm",
                                 "vx_mm_s", "vy_mm_s", "height_mm", "measured", "pickable", "height_converged"]
            # One part alone: nothing keeps it from the arm once the belt model has settled (auto, the
            # default: over the first segment.auto_frames new frames); its height is estimated (auto, the
            # default) and said to be settled only once it is: flat.
            assert obj["pickable"] is (index >= SegmentConfig().auto_frames)
            assert not obj["height_converged"] or obj["height_mm"] == 0.0, obj
            c = np.array(obj["corners_mm"])
            area = 0.5 * (np.dot(c[:, 0], np.roll(c[:, 1], -1)) - np.dot(c[:, 1], np.roll(c[:, 0], -1)))
            assert area > 0 and -90 < obj["angle_deg"] <= 90
            assert math.isclose(area, obj["length_mm"] * obj["width_mm"], rel_tol=1e-3)
        poses.append(pose)
    converged = [o["height_converged"] for p in poses for o in p["objects"]]
    assert converged[-1] and sum(converged) >= len(converged) / 2, converged
    acc = evaluate(poses, truths, skip_first=2)
    assert acc.visible_frames > 20 and acc.missed_frames == 0
    assert acc.summary()["centroid_mean_mm"] < 0.2
    assert "frames in" in proc.stdout  # the summary line
    # The same figures from the command line.
    report = _run(["evaluate", str(poses_path), str(scene_dir / "truth.jsonl"), "--json"])
    assert report.returncode == 0
    assert json.loads(report.stdout) == pytest.approx(acc.summary())


def test_frame_size_differs_from_calibration(scene_dir, tmp_path):
    small = tmp_path / "small"
    small.mkdir()
    for i in range(3):
        cv2.imwrite(str(small / f"{i:05d}.png"), np.zeros((240, 320), np.uint8))
    proc = _run(["run", "--source", str(small / "%05d.png"), "--calibration", str(scene_dir / "calibration.yaml"),
                 "--no-plc", "--quiet", "--fps", "30"])
    assert proc.returncode == 2
    assert proc.stderr.strip().count("\n") == 0, proc.stderr
    assert "frame is 320x240" in proc.stderr and "640x480" in proc.stderr and "Traceback" not in proc.stderr


@pytest.mark.parametrize(
    "args, message",
    [
        (["--source", "/nonexistent/video.mp4", "--calibration", "CAL"], "video file not found"),
        (["--source", "/nonexistent/%05d.png", "--calibration", "CAL"], "no image found"),
        (["--source", "FRAMES", "--calibration", "/nonexistent/c.yaml"], "calibration file not found"),
        (["--source", "FRAMES"], "--calibration is required"),
        (["--source", "FRAMES", "--calibration", "CAL", "--fps", "-3"], "--fps: expected a number from 0.01"),
    ],
)
def test_bad_input_is_one_line_and_exit_2(scene_dir, capsys, args, message):
    subst = {"CAL": str(scene_dir / "calibration.yaml"), "FRAMES": str(scene_dir / "frames" / "%05d.png")}
    code = main(["run", *(subst.get(a, a) for a in args), "--no-plc", "--quiet"])
    err = capsys.readouterr().err
    assert code == 2
    assert message in err and len(err.strip().splitlines()) == 1


def test_a_folder_where_a_file_is_expected_is_called_a_folder(tmp_path, scene_dir, capsys):
    # Not "not found": the user sees the folder is there.
    (tmp_path / "cell.yaml").mkdir()
    (tmp_path / "clip.mp4").mkdir()
    assert main(["run", "--source", str(tmp_path / "clip.mp4"), "--calibration", str(tmp_path / "cell.yaml"),
                 "--no-plc"]) == 2
    assert "cell.yaml: is a folder; expected a calibration file" in capsys.readouterr().err
    assert main(["run", "--source", str(tmp_path / "clip.mp4"), "--calibration", str(scene_dir / "calibration.yaml"),
                 "--no-plc"]) == 2
    assert "clip.mp4: is a folder; expected a video file" in capsys.readouterr().err


def test_corrupt_video_is_bad_input(tmp_path, scene_dir, capsys):
    bogus = tmp_path / "video.mp4"
    bogus.write_bytes(b"\x00garbage" * 100)
    code = main(["run", "--source", str(bogus), "--calibration", str(scene_dir / "calibration.yaml"), "--no-plc"])
    assert code == 2
    assert "video.mp4" in capsys.readouterr().err


def test_demo_runs_with_no_arguments_but_a_frame_limit(capsys):
    assert main(["run", "--max-frames", "40", "--quiet", "--no-plc"]) == 0
    out = capsys.readouterr().out
    assert "40 frames in" in out
