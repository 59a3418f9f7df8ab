"""Options and inputs that are wrong give one line naming the option and the allowed range, exit 2."""

from __future__ import annotations

import io
import json
import logging

import pytest

from tracker.cli import main
from tracker.runner import StatusLine


def _run(scene_dir, *extra):
    return ["run", "--source", str(scene_dir / "frames" / "%05d.png"), "--calibration",
            str(scene_dir / "calibration.yaml"), "--no-plc", "--quiet", *extra]


@pytest.mark.parametrize("extra,needle", [
    (["--fps", "1e-300"], "--fps: expected a number from 0.01 to 100000"),
    (["--fps", "inf"], "--fps: expected a number from 0.01 to 100000"),
    (["--fps", "nan"], "--fps: expected a number"),
    (["--max-frames", "0"], "--max-frames: expected an integer >= 1"),
    (["--max-frames", "-1"], "--max-frames: expected an integer >= 1"),
    (["--max-frames", "2.5"], "--max-frames: expected an integer >= 1"),
    (["--no-such-option"], "unrecognized arguments: --no-such-option"),
])
def test_bad_options_are_one_line(scene_dir, capsys, extra, needle):
    assert main(_run(scene_dir, *extra)) == 2
    err = capsys.readouterr().err
    assert needle in err and len(err.strip().splitlines()) == 1 and "usage:" not in err, err


@pytest.mark.parametrize("source,needle", [
    ("2147483648", "expected a camera index from 0 to 1023"),
    ("9", "camera 9: cannot open"),
])
def test_bad_camera_is_one_line_without_opencv_noise(scene_dir, source, needle):
    # A subprocess: OpenCV's and FFmpeg's own log lines go straight to file descriptor 2.
    import subprocess
    import sys

    proc = subprocess.run([sys.executable, "-m", "tracker.cli", "run", "--source", source, "--calibration",
                           str(scene_dir / "calibration.yaml"), "--no-plc"], capture_output=True, text=True,
                          timeout=60)
    assert proc.returncode == 2
    assert needle in proc.stderr and len(proc.stderr.strip().splitlines()) == 1, proc.stderr


def test_evaluate_refuses_swapped_arguments_and_another_scenes_truth(scene_dir, tmp_path, capsys):
    poses = tmp_path / "poses.jsonl"
    assert main(_run(scene_dir, "--fps", "30", "--poses", str(poses))) == 0
    truth = scene_dir / "truth.jsonl"
    assert main(["evaluate", str(poses), str(truth)]) == 0
    capsys.readouterr()
    assert main(["evaluate", str(truth), str(poses)]) == 2
    assert "arguments swapped" in capsys.readouterr().err
    # The same frames, but every true part 500 mm away: not this scene's truth.
    moved = tmp_path / "other_truth.jsonl"
    frames = [json.loads(line) for line in truth.read_text().splitlines()]
    for frame in frames:
        for obj in frame["objects"]:
            obj["y_mm"] += 500.0
    moved.write_text("".join(json.dumps(f) + "\n" for f in frames))
    assert main(["evaluate", str(poses), str(moved)]) == 2
    assert "no reported object is near any true part" in capsys.readouterr().err


def test_evaluate_names_the_files_line_and_writes_no_nan(scene_dir, tmp_path, capsys):
    poses = tmp_path / "poses.jsonl"
    assert main(_run(scene_dir, "--fps", "30", "--poses", str(poses), "--max-frames", "8")) == 0
    lines = poses.read_text().splitlines()
    broken = tmp_path / "broken.jsonl"
    broken.write_text("\n".join(lines[:5] + ['{"frame": 5, "objects": [}'] + lines[6:]) + "\n")
    capsys.readouterr()
    assert main(["evaluate", str(broken), str(scene_dir / "truth.jsonl")]) == 2
    assert "broken.jsonl: line 6: not JSON" in capsys.readouterr().err
    # Every part-frame within --skip-first: no error to state, and the JSON is JSON (no NaN).
    assert main(["evaluate", str(poses), str(scene_dir / "truth.jsonl"), "--skip-first", "100", "--json"]) == 0
    summary = json.loads(capsys.readouterr().out, parse_constant=lambda name: pytest.fail(f"{name} in JSON"))
    assert summary["centroid_mean_mm"] is None and summary["visible_frames"] > 0
    assert main(["evaluate", str(poses), str(scene_dir / "truth.jsonl"), "--skip-first", "100"]) == 0
    assert "centroid error: mean none mm" in capsys.readouterr().out


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_a_log_line_never_lands_on_the_status_line():
    term = _Terminal()
    handler = logging.StreamHandler(term)
    root = logging.getLogger()
    root.addHandler(handler)
    try:
        status = StatusLine(term)
        status.show("frame 1 | 60 fps", force=True)
        logging.getLogger("plc").warning("PLC lost")
        status.show("frame 2 | 60 fps", force=True)
        status.end()
    finally:
        root.removeHandler(handler)
    # What a terminal shows: carriage returns go back to the start of the line.
    screen = [line.split("\r")[-1].rstrip() for line in term.getvalue().split("\n")]
    assert screen == ["PLC lost", "frame 2 | 60 fps", ""], screen
