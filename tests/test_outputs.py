"""No output may destroy an input or another output; bad input at start replaces nothing; a pose
file that cannot be written is a fault, not a crash (issue: never destroy a file)."""

from __future__ import annotations

import errno
import json
import os
import shutil
import stat

import numpy as np
import pytest
from conftest import ROOT
from plc_support import Rendered, ScriptedCamera, run_loop, small_scene

from plc.encode import WordOrder, decode_block
from plc.link import ModbusLink
from plc.options import PlcOptions
from plc.sim import PlcSimulator
from plc.writer import PlcWriter
from tracker import pose_sink
from tracker.calibration import load, save
from tracker.cli import main
from tracker.health import FAULT_POSES, Health
from tracker.outputs import PublishOnFirstFrame, StagedFile
from tracker.pose_sink import PoseSink

DEMO = ROOT / "recordings" / "demo.mcap"


@pytest.fixture()
def demo_copy(tmp_path):
    path = tmp_path / "rec.mcap"
    shutil.copy(DEMO, path)
    return path


def _args(scene_dir, *extra):
    return ["run", "--source", str(scene_dir / "frames" / "%05d.png"), "--calibration",
            str(scene_dir / "calibration.yaml"), "--fps", "30", "--no-plc", "--quiet", *extra]


def _one_error_line(capsys, *needles):
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1 and "Traceback" not in err, err
    for needle in needles:
        assert needle in lines[0], lines[0]
    return lines[0]


@pytest.mark.parametrize("argv", [
    ["run", "--source", "{rec}", "--no-plc", "--quiet", "--record", "{rec}"],
    ["run", "--source", "{rec}", "--no-plc", "--quiet", "--record", "{link}"],
    ["run", "--source", "{rec}", "--no-plc", "--quiet", "--poses", "{rec}"],
    ["run", "--source", "{rec}", "--no-plc", "--quiet", "--poses", "{symlink}"],
    ["replay", "{rec}", "--poses", "{rec}"],
    ["replay", "{rec}", "--poses", "{link}"],
])
def test_an_output_on_the_source_is_refused_and_the_source_kept(demo_copy, tmp_path, capsys, argv):
    link, symlink = tmp_path / "hard.mcap", tmp_path / "soft.mcap"
    os.link(demo_copy, link)
    symlink.symlink_to(demo_copy)
    before = demo_copy.read_bytes()
    argv = [a.format(rec=demo_copy, link=link, symlink=symlink) for a in argv]
    assert main(argv) == 2
    _one_error_line(capsys, "it would be overwritten")
    assert demo_copy.read_bytes() == before


def test_outputs_on_the_calibration_or_on_each_other_are_refused(scene_dir, tmp_path, capsys):
    calib = scene_dir / "calibration.yaml"
    before = calib.read_bytes()
    for option in ("--poses", "--record"):
        assert main(_args(scene_dir, option, str(calib))) == 2
        _one_error_line(capsys, option, "--calibration", "it would be overwritten")
    assert calib.read_bytes() == before
    same = tmp_path / "out.x"
    same.write_text("keep me")
    assert main(_args(scene_dir, "--poses", str(same), "--record", str(same))) == 2
    _one_error_line(capsys, "--poses", "--record", "same file")
    assert same.read_text() == "keep me"


def test_a_frame_of_the_source_is_never_an_output(scene_dir, capsys):
    frame = scene_dir / "frames" / "00000.png"
    before = frame.read_bytes()
    assert main(_args(scene_dir, "--record", str(frame))) == 2
    _one_error_line(capsys, "is a frame of --source")
    assert frame.read_bytes() == before


def _existing_outputs(tmp_path):
    poses, record = tmp_path / "old.jsonl", tmp_path / "old.mcap"
    poses.write_text('{"frame": 0, "t": 0.0, "objects": []}\n')
    shutil.copy(DEMO, record)
    return poses, record, poses.read_bytes(), record.read_bytes()


def test_bad_input_at_start_leaves_existing_outputs_as_they_were(scene_dir, tmp_path, capsys):
    poses, record, poses_before, record_before = _existing_outputs(tmp_path)
    # A calibration for another frame size: found at frame 0, after the outputs were set up.
    other = tmp_path / "other.yaml"
    text = (scene_dir / "calibration.yaml").read_text()
    other.write_text(text.replace("image_width: 640", "image_width: 800"))
    argv = _args(scene_dir, "--poses", str(poses), "--record", str(record))
    argv[argv.index("--calibration") + 1] = str(other)
    assert main(argv) == 2
    _one_error_line(capsys, "800")
    # 16-bit frames: the source's first frame is refused.
    frames16 = tmp_path / "f16"
    frames16.mkdir()
    import cv2

    for i in range(3):
        assert cv2.imwrite(str(frames16 / f"{i:05d}.png"), np.full((480, 640), 1000, np.uint16))
    argv = _args(scene_dir, "--poses", str(poses), "--record", str(record))
    argv[argv.index("--source") + 1] = str(frames16 / "%05d.png")
    assert main(argv) == 2
    _one_error_line(capsys, "8-bit")
    # A recording into a missing folder, with an existing pose file beside the command.
    assert main(_args(scene_dir, "--poses", str(poses), "--record", str(tmp_path / "nope" / "r.mcap"))) == 2
    _one_error_line(capsys, "does not exist")
    assert poses.read_bytes() == poses_before and record.read_bytes() == record_before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["f16", "old.jsonl", "old.mcap", "other.yaml"]


def test_outputs_take_their_name_once_the_first_frame_is_processed(scene_dir, tmp_path):
    poses, record, _, record_before = _existing_outputs(tmp_path)
    assert main(_args(scene_dir, "--poses", str(poses), "--record", str(record), "--max-frames", "3")) == 0
    lines = [json.loads(line) for line in poses.read_text().splitlines()]
    assert [p["frame"] for p in lines] == [0, 1, 2]
    assert record.read_bytes() != record_before and main(["replay", str(record), "--check"]) == 0
    assert not [p for p in tmp_path.iterdir() if ".partial" in p.name]


def test_outputs_have_a_new_files_permissions_and_a_replaced_file_keeps_its_own(scene_dir, tmp_path):
    # Written to a private temporary file (mkstemp's 0600) and renamed into place, a pose file or a
    # calibration stayed unreadable to the cell's other users (the PLC programmer's, a service's).
    poses, record, calib = tmp_path / "p.jsonl", tmp_path / "r.mcap", tmp_path / "c.yaml"
    old_mask = os.umask(0o022)
    try:
        assert main(_args(scene_dir, "--poses", str(poses), "--record", str(record), "--max-frames", "2")) == 0
        save(load(scene_dir / "calibration.yaml"), calib)
        assert [stat.S_IMODE(p.stat().st_mode) for p in (poses, record, calib)] == [0o644] * 3
        os.umask(0o027)
        for path, mode in ((poses, 0o664), (record, 0o600), (calib, 0o640)):
            path.chmod(mode)
        assert main(_args(scene_dir, "--poses", str(poses), "--record", str(record), "--max-frames", "2")) == 0
        save(load(scene_dir / "calibration.yaml"), calib)
        assert [stat.S_IMODE(p.stat().st_mode) for p in (poses, record, calib)] == [0o664, 0o600, 0o640]
        fresh = tmp_path / "fresh.jsonl"
        assert main(_args(scene_dir, "--poses", str(fresh), "--max-frames", "1")) == 0
        assert stat.S_IMODE(fresh.stat().st_mode) == 0o640
    finally:
        os.umask(old_mask)


def test_a_read_only_output_is_replaced_and_stays_read_only(scene_dir, tmp_path):
    # Replacing a file needs the folder writable, not the file: the temporary file takes the old one's
    # mode only once written (given it at once, a 0444 one could not be written: "Permission denied").
    import shutil as _shutil
    import subprocess
    import sys

    prefix = []
    if os.geteuid() == 0:  # root writes read-only files all the same: drop that power for the run
        if _shutil.which("setpriv") is None:
            pytest.skip("running as root without setpriv: a read-only file cannot be tried")
        prefix = ["setpriv", "--inh-caps=-all", "--bounding-set=-dac_override,-dac_read_search"]
    poses, record, calib = tmp_path / "p.jsonl", tmp_path / "r.mcap", tmp_path / "c.yaml"
    for path in (poses, record, calib):
        path.write_text("old")
        path.chmod(0o444)
    run = [*prefix, sys.executable, "-m", "tracker"]
    proc = subprocess.run([*run, *_args(scene_dir, "--poses", str(poses), "--record", str(record),
                                         "--max-frames", "2")], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    proc = subprocess.run([*run, "calibrate", "scale", "--size", "640x480", "--mm-per-px", "0.5", "--out", str(calib)],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    for path in (poses, record, calib):
        assert stat.S_IMODE(path.stat().st_mode) == 0o444 and path.read_bytes() != b"old", path
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c.yaml", "p.jsonl", "r.mcap"]


def test_staged_file_is_removed_when_nothing_was_processed(tmp_path):
    target = tmp_path / "p.jsonl"
    target.write_text("old\n")
    staged = StagedFile("--poses", str(target))
    sink = PublishOnFirstFrame(PoseSink(staged.path), staged)
    sink.close()
    assert target.read_text() == "old\n" and list(tmp_path.iterdir()) == [target]


class _DiskFillsAfter:
    """os.write that accepts ``budget`` bytes, writes what fits of the next call, then ENOSPC."""

    def __init__(self, budget: int) -> None:
        self.budget = budget
        self.real = os.write

    def __call__(self, fd, data):
        if self.budget <= 0:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        n = self.real(fd, bytes(data[: self.budget]))
        self.budget -= n
        return n


@pytest.fixture(scope="module")
def rendered():
    return Rendered(small_scene())


def test_full_disk_on_the_pose_file_is_fault_6_and_the_plc_hears_of_it(rendered, tmp_path, monkeypatch, caplog):
    health = Health()
    poses = tmp_path / "poses.jsonl"
    # The disk fills in the middle of a line, after some complete ones.
    monkeypatch.setattr(pose_sink.os, "write", _DiskFillsAfter(20_000))
    with PlcSimulator(port=0) as sim:
        opts = PlcOptions("127.0.0.1", sim.port)
        writer = PlcWriter(ModbusLink(opts), opts, health)
        sink = PoseSink(str(poses), health)
        with pytest.raises(pose_sink.PoseOutputError, match="No space left on device"):
            run_loop(ScriptedCamera(rendered), [sink, writer], health)
        final = decode_block(sim.writes(0)[-1].values, WordOrder.ABCD)
    # Tracking and the PLC went on to the last frame; the PLC's final block says why poses stopped.
    assert writer.stats.submitted == len(rendered.frames)
    assert final["fault"] == FAULT_POSES and final["status"] & 1 == 0 and final["status"] & (1 << 15)
    # The file ends with a complete line: valid JSON Lines, frames 0..n-1 in order.
    text = poses.read_text()
    assert text.endswith("\n") and len(text.encode()) <= 20_000
    frames = [json.loads(line)["frame"] for line in text.splitlines()]
    assert frames == list(range(len(frames))) and 0 < len(frames) < len(rendered.frames)
    errors = [r for r in caplog.records if r.levelname == "ERROR"]
    assert len(errors) == 1 and "pose output stopped" in errors[0].getMessage()
