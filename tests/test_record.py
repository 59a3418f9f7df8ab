"""Recording every frame to MCAP, replaying it bit-exactly, and surviving kills and full disks."""

import contextlib
import dataclasses
import errno
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory

from tracker import calibration as calib_io
from tracker.cli import main
from tracker.config import TrackerConfig
from tracker.health import FAULT_RECORDING, Health
from tracker.pipeline import Pipeline
from tracker.recording.replay import first_difference
from tracker.recording.source import McapSource
from tracker.recording.writer import Recorder, RunInfo
from tracker.runner import Runner
from tracker.sources import ImageSequenceSource

ROOT = Path(__file__).resolve().parent.parent


def _tracker(*args, **kw):
    return subprocess.run([sys.executable, "-m", "tracker", *args], capture_output=True, text=True, timeout=300, **kw)


@pytest.fixture(scope="module")
def recorded(scene_dir, tmp_path_factory):
    """A live run on the scene's frames: (recording, live pose stream)."""
    out = tmp_path_factory.mktemp("rec")
    rec, poses = out / "run.mcap", out / "live.jsonl"
    proc = _tracker("run", "--source", str(scene_dir / "frames" / "%05d.png"), "--calibration",
                    str(scene_dir / "calibration.yaml"), "--fps", "30", "--no-plc", "--quiet",
                    "--record", str(rec), "--poses", str(poses))
    assert proc.returncode == 0, proc.stderr
    return rec, poses


def test_replay_is_byte_identical_to_the_live_run(recorded, tmp_path, capsys):
    rec, live = recorded
    replayed = tmp_path / "replayed.jsonl"
    assert main(["replay", str(rec), "--check", "--poses", str(replayed)]) == 0
    assert replayed.read_bytes() == live.read_bytes()
    assert "identical" in capsys.readouterr().out


def test_frames_come_back_bit_exact_with_their_capture_times(recorded, scene_dir):
    rec, _ = recorded
    original = ImageSequenceSource(str(scene_dir / "frames" / "%05d.png"), fps=30.0)
    source = McapSource(str(rec), None)
    pairs = list(zip(original, source, strict=True))
    assert len(pairs) > 40
    for a, b in pairs:
        assert a.index == b.index and a.t_ns == b.t_ns
        assert a.image.dtype == b.image.dtype and np.array_equal(a.image, b.image)
    # The recording carries its own calibration and configuration: nothing else is needed.
    assert np.array_equal(source.calibration.belt_homography,
                          calib_io.load(scene_dir / "calibration.yaml").belt_homography)
    assert source.config == TrackerConfig()


def test_recording_opens_with_the_mcap_reader_as_foxglove_types(recorded, scene_dir):
    """The official reader, with the official protobuf decoder built from the schemas in the file
    alone, reads Foxglove's binary types; our own types are JSON."""
    rec, live = recorded
    with open(rec, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        encodings = {s.name: s.encoding for s in summary.schemas.values()}
        assert encodings == {"foxglove.RawImage": "protobuf", "foxglove.ImageAnnotations": "protobuf",
                             "tracker.FramePoses": "jsonschema", "tracker.TrackPoint": "jsonschema"}
        n_live = len(live.read_text().splitlines())
        by_topic = {}
        for schema, channel, message, decoded in reader.iter_decoded_messages(
                topics=["/camera/image", "/tracker/annotations"]):
            by_topic.setdefault(channel.topic, []).append((schema.name, message, decoded))
        tracks = [m for _, c, m in reader.iter_messages(topics=["/tracker/track"])]
        metadata = {m.name: m.metadata for m in reader.iter_metadata()}
        attachments = {a.name: a for a in reader.iter_attachments()}
    images = by_topic["/camera/image"]
    assert len(images) == n_live and all(s == "foxglove.RawImage" for s, _, _ in images)
    first = images[0][2]
    assert first.encoding == "mono8" and first.step == first.width and first.frame_id == "camera"
    # The pixels are the frame's own, and the stamps its capture time.
    original = ImageSequenceSource(str(scene_dir / "frames" / "%05d.png"), fps=30.0)
    frame1 = list(zip(range(2), original, strict=False))[1][1]
    pixels = np.frombuffer(images[1][2].data, np.uint8).reshape(images[1][2].height, images[1][2].width)
    assert np.array_equal(pixels, frame1.image)
    assert images[1][2].timestamp.ToNanoseconds() == images[1][1].log_time == round(1e9 / 30)
    assert images[0][1].log_time == 0
    assert [m.sequence for _, m, _ in images] == list(range(n_live))
    annotations = [d for _, _, d in by_topic["/tracker/annotations"]]
    assert len(annotations) == n_live and any(a.points for a in annotations)
    # A part's rectangle is a closed polygon of 4 image points, beside its centroid and id.
    drawn = next(a for a in annotations if a.points)
    assert any(len(p.points) == 4 and p.type == p.LINE_LOOP for p in drawn.points) and drawn.texts
    assert drawn.texts[0].text.startswith("#")
    # One message per tracked object per frame, each with its own sequence number on its channel.
    assert tracks and len({m.sequence for m in tracks}) == len(tracks)
    assert {"frame", "id", "x_mm"} <= set(json.loads(tracks[0].data))
    # Settings, version and calibration travel with the file.
    run = metadata["tracker.run"]
    assert json.loads(run["config"]) == TrackerConfig().to_dict() and run["version"]
    assert "calibration.yaml" in attachments and "overruns" in metadata["tracker.end"]


def test_check_names_the_first_differing_frame_and_field(recorded, tmp_path, capsys):
    rec, _ = recorded
    # The same frames recorded with a result the pipeline would not produce.
    source = McapSource(str(rec), None)
    tampered = tmp_path / "tampered.mcap"
    info = RunInfo(source.calibration, source.config, "tampered", 30.0)
    recorder = Recorder.open(str(tampered), info)
    pipeline = Pipeline(source.calibration, source.config)
    changed = None
    for frame in source:
        result = pipeline.process(frame.index, frame.image, frame.t_ns)
        if result.objects and changed is None:
            changed = frame.index
            obj = result.objects[0]
            result = dataclasses.replace(result, objects=(dataclasses.replace(obj, y_mm=obj.y_mm + 0.5),))
        recorder.submit(frame, result)
    recorder.close()
    assert main(["replay", str(tampered), "--check"]) == 1
    err = capsys.readouterr().err
    assert f"frame {changed}" in err and "y_mm" in err
    # A tolerance (for replays on another CPU type) accepts small differences, not large ones.
    capsys.readouterr()
    assert main(["replay", str(tampered), "--check", "--tolerance", "0.6", "--quiet"]) == 0
    assert "poses within 0.6 of the live run" in capsys.readouterr().out  # not "identical"
    assert main(["replay", str(tampered), "--check", "--tolerance", "0.4"]) == 1
    assert main(["replay", str(tampered), "--check", "--tolerance", "-1"]) == 2
    assert main(["replay", str(tampered), "--tolerance", "0.6"]) == 2  # a tolerance means nothing unchecked
    assert first_difference({"a": [1, {"b": 2}]}, {"a": [1, {"b": 3}]}) == "a[1].b: live 2, replay 3"


@pytest.mark.parametrize("fraction", [0.3, 0.55, 0.8, 0.999])
def test_a_cut_recording_replays_up_to_where_it_ends(recorded, tmp_path, fraction):
    rec, live = recorded
    data = rec.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: int(len(data) * fraction)])
    poses = tmp_path / "poses.jsonl"
    proc = _tracker("replay", str(cut), "--check", "--poses", str(poses))
    assert proc.returncode == 0, proc.stderr
    assert "without its summary" in proc.stderr or "cut short" in proc.stderr
    replayed = poses.read_text().splitlines()
    assert replayed == live.read_text().splitlines()[: len(replayed)]
    if fraction > 0.75:  # past the first chunk (~1 s of frames)
        assert len(replayed) >= 25


def test_sigkill_leaves_a_recording_that_replays(tmp_path):
    rec = tmp_path / "killed.mcap"
    # The bundled demo played at its recorded rate (8 s) is long enough to be killed in the middle.
    proc = subprocess.Popen([sys.executable, "-m", "tracker", "run", "--source", str(ROOT / "recordings" / "demo.mcap"),
                             "--realtime", "--no-plc", "--quiet", "--record", str(rec)],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 120
    # The file appears under its name with its first chunk (~1 s of frames); wait for the second.
    while time.monotonic() < deadline and (not rec.exists() or rec.stat().st_size < 2 * _first_chunk_end(rec)):
        if proc.poll() is not None:
            pytest.fail("tracker run ended before it could be killed")
        time.sleep(0.05)
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=30)
    out = tmp_path / "poses.jsonl"
    replay = _tracker("replay", str(rec), "--poses", str(out))
    assert replay.returncode == 0, replay.stderr
    assert "cut short" in replay.stderr or "without its summary" in replay.stderr
    assert len(out.read_text().splitlines()) >= 30
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []


def _first_chunk_end(path) -> int:
    """Bytes up to the end of the first chunk's message indexes (0 while there is none)."""
    from tracker.recording.mcapio import ReadEnd, iter_records

    end = ReadEnd()
    with contextlib.suppress(OSError), open(path, "rb") as f:
        for record in iter_records(f, end, emit_chunks=True):
            if type(record).__name__ == "Chunk":
                return end.position
    return 10**12


class FullDisk:
    """A file that accepts ``limit`` bytes, then fails like a full disk."""

    def __init__(self, path, limit):
        self.f = open(path, "wb")  # noqa: SIM115
        self.limit = limit

    def write(self, data):
        if self.f.tell() + len(data) > self.limit:
            raise OSError(errno.ENOSPC, "No space left on device")
        return self.f.write(data)

    def truncate(self, size):
        self.f.truncate(size)
        self.f.seek(size)

    def close(self):
        self.f.close()


def test_full_disk_stops_the_recording_and_tracking_goes_on(recorded, tmp_path, caplog):
    rec, live = recorded
    source = McapSource(str(rec), None)
    health = Health()
    path = tmp_path / "full.mcap"
    recorder = Recorder(FullDisk(path, 400_000), str(path), RunInfo(source.calibration, source.config, "x", 30.0),
                        health)
    poses = tmp_path / "poses.jsonl"
    from tracker.pose_sink import PoseSink

    runner = Runner(source, Pipeline(source.calibration, source.config), [recorder, PoseSink(str(poses))], health)
    with pytest.raises(Exception, match="recording stopped: .*No space left on device"):
        runner.run()
    # Tracking went on to the end: every frame has its pose line.
    assert poses.read_bytes() == live.read_bytes()
    assert health.fault == FAULT_RECORDING and not health.recording_ok
    errors = [r for r in caplog.records if r.levelname == "ERROR"]
    assert len(errors) == 1 and "No space left" in errors[0].getMessage()
    # What reached the disk replays.
    assert main(["replay", str(path), "--check"]) == 0


def test_full_tmpfs_for_real(recorded, tmp_path):
    if os.geteuid() != 0:
        pytest.skip("mounting a tmpfs needs root")
    mnt = tmp_path / "small"
    mnt.mkdir()
    rec, live = recorded
    # Room for the first chunk of the same recording, not for the second.
    size = _first_chunk_end(rec) + 1_000_000
    assert size < rec.stat().st_size
    if subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(mnt)],
                      capture_output=True).returncode:
        pytest.skip("cannot mount a tmpfs here")
    try:
        poses = tmp_path / "poses.jsonl"
        proc = _tracker("run", "--source", str(rec), "--no-plc", "--quiet", "--record", str(mnt / "r.mcap"),
                        "--poses", str(poses))
        assert proc.returncode == 1
        assert "No space left on device" in proc.stderr and "Traceback" not in proc.stderr
        assert poses.read_bytes() == live.read_bytes()  # tracking continued to the last frame
        assert main(["replay", str(mnt / "r.mcap"), "--check"]) == 0
        assert [p.name for p in mnt.iterdir()] == ["r.mcap"]  # no temporary file left behind
    finally:
        subprocess.run(["umount", str(mnt)], check=False)


def test_unwritable_path_is_bad_input_and_leaves_nothing(tmp_path, scene_dir, capsys):
    target = tmp_path / "missing" / "r.mcap"
    code = main(["run", "--source", str(scene_dir / "frames" / "%05d.png"), "--calibration",
                 str(scene_dir / "calibration.yaml"), "--fps", "30", "--no-plc", "--quiet", "--record", str(target)])
    assert code == 2
    err = capsys.readouterr().err
    assert "cannot write the recording" in err and len(err.strip().splitlines()) == 1
    assert not target.parent.exists()


def test_recording_as_a_camera_and_the_bundled_demos_replay_exactly(tmp_path):
    recordings = sorted((ROOT / "recordings").glob("*.mcap"))
    assert recordings, "recordings/ must hold the bundled demo"
    for rec in recordings:
        assert rec.stat().st_size <= 5 * 2**20
        assert main(["replay", str(rec), "--check"]) == 0, rec
    poses = tmp_path / "p.jsonl"
    assert main(["run", "--source", str(recordings[0]), "--no-plc", "--quiet", "--poses", str(poses)]) == 0
    assert any(json.loads(line)["objects"] for line in poses.read_text().splitlines())


def test_unreadable_recording_is_bad_input(tmp_path, capsys):
    junk = tmp_path / "junk.mcap"
    junk.write_bytes(b"not an mcap file at all")
    assert main(["replay", str(junk)]) == 2
    assert "junk.mcap: not an MCAP recording" in capsys.readouterr().err  # not "cut before its header"
    assert main(["replay", str(tmp_path)]) == 2
    assert "is a folder" in capsys.readouterr().err
    empty = tmp_path / "empty.mcap"
    empty.write_bytes(b"")
    assert main(["replay", str(empty)]) == 2
    assert "empty.mcap: not a readable recording (it ends at byte 0" in capsys.readouterr().err


def test_a_recording_cut_before_its_first_frame_is_nothing_to_run_on(recorded, tmp_path, capsys):
    # "0 frames" and exit 0 hid it; the pose file beside it is left as it was.
    rec, _ = recorded
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(rec.read_bytes()[: _chunk_starts(rec)[0] + 100])
    poses = tmp_path / "poses.jsonl"
    poses.write_text("kept\n")
    assert main(["run", "--source", str(cut), "--no-plc", "--quiet", "--poses", str(poses)]) == 2
    assert "ended before its first frame" in capsys.readouterr().err
    assert poses.read_text() == "kept\n"


def _chunk_starts(path) -> list[int]:
    """Byte offsets where the recording's chunks begin."""
    from tracker.recording.mcapio import ReadEnd, iter_records

    starts, end, before = [], ReadEnd(), 0
    with open(path, "rb") as f:
        for record in iter_records(f, end, emit_chunks=True):
            if type(record).__name__ == "Chunk":
                starts.append(before)
            before = end.position
    return starts


def _damaged_copy(rec, tmp_path, offset: int, nbytes: int = 4, only_xor: int = 0xFF):
    data = bytearray(rec.read_bytes())
    for i in range(offset, offset + nbytes):
        data[i] ^= only_xor
    out = tmp_path / "damaged.mcap"
    out.write_bytes(bytes(data))
    return out


@pytest.mark.parametrize("which", [0, 1])
def test_flipped_bytes_at_a_chunks_start_fail_the_check_naming_the_byte(recorded, tmp_path, capsys, which):
    rec, live = recorded
    starts = _chunk_starts(rec)
    assert len(starts) >= 2
    damaged = _damaged_copy(rec, tmp_path, starts[which])
    poses = tmp_path / "p.jsonl"
    assert main(["replay", str(damaged), "--check", "--quiet", "--poses", str(poses)]) == 1
    err = capsys.readouterr().err
    assert f"damaged at byte {starts[which]}" in err and len(err.strip().splitlines()) == 1
    # A run on the damaged file says so too, after tracking the frames before the damage.
    assert main(["run", "--source", str(damaged), "--no-plc", "--quiet", "--poses", str(poses)]) == 1
    err = capsys.readouterr().err
    assert f"damaged at byte {starts[which]}" in err
    lines = poses.read_text().splitlines()
    assert lines == live.read_text().splitlines()[: len(lines)] and (len(lines) >= 25) == (which == 1)


def test_a_chunk_whose_type_byte_is_wrong_is_missing_frames_not_a_clean_end(recorded, tmp_path, capsys):
    """An unknown record type is skipped by MCAP readers: the frames it held would vanish silently."""
    rec, _ = recorded
    starts = _chunk_starts(rec)
    damaged = _damaged_copy(rec, tmp_path, starts[0], nbytes=1, only_xor=0x80)
    assert main(["replay", str(damaged), "--check"]) == 1
    err = capsys.readouterr().err
    assert "frames 0-" in err and "missing" in err


def test_bytes_flipped_inside_a_chunk_fail_replay_and_run(recorded, tmp_path, capsys):
    rec, _ = recorded
    starts = _chunk_starts(rec)
    damaged = _damaged_copy(rec, tmp_path, starts[1] + 5000, nbytes=4)
    assert main(["replay", str(damaged), "--check"]) == 1
    assert f"damaged at byte {starts[1]}" in capsys.readouterr().err
    assert main(["run", "--source", str(damaged), "--no-plc", "--quiet"]) == 1
    err = capsys.readouterr().err
    assert f"damaged at byte {starts[1]}" in err and "Traceback" not in err


@pytest.mark.parametrize("cut", [1, 4, 7])
def test_a_file_cut_inside_its_closing_magic_is_reported_as_cut(recorded, tmp_path, capsys, cut):
    rec, live = recorded
    short = tmp_path / "short.mcap"
    short.write_bytes(rec.read_bytes()[:-cut])
    poses = tmp_path / "p.jsonl"
    assert main(["replay", str(short), "--check", "--poses", str(poses)]) == 0
    assert "cut short" in capsys.readouterr().err
    assert poses.read_bytes() == live.read_bytes()  # every frame is there all the same


def test_recordings_in_the_json_encoding_of_earlier_versions_still_replay(recorded, tmp_path, capsys):
    from tracker.recording.writer import RecorderConfig

    rec, live = recorded
    source = McapSource(str(rec), None)
    old = tmp_path / "json.mcap"
    recorder = Recorder.open(str(old), RunInfo(source.calibration, source.config, "old", 30.0),
                             config=RecorderConfig(message_encoding="json"))
    pipeline = Pipeline(source.calibration, source.config)
    for frame in source:
        recorder.submit(frame, pipeline.process(frame.index, frame.image, frame.t_ns))
    recorder.close()
    with open(old, "rb") as f:
        assert {s.encoding for s in make_reader(f).get_summary().schemas.values()} == {"jsonschema"}
    replayed = tmp_path / "p.jsonl"
    assert main(["replay", str(old), "--check", "--poses", str(replayed)]) == 0
    assert replayed.read_bytes() == live.read_bytes()
    pairs = zip(McapSource(str(old)), McapSource(str(rec)), strict=True)
    assert all(np.array_equal(a.image, b.image) for a, b in pairs)


def test_a_recording_stopped_before_its_first_chunk_leaves_an_existing_file_alone(recorded, tmp_path):
    rec, _ = recorded
    source = McapSource(str(rec), None)
    target = tmp_path / "keep.mcap"
    target.write_bytes(b"an earlier recording")
    recorder = Recorder.open(str(target), RunInfo(source.calibration, source.config, "x", 30.0))
    assert target.read_bytes() == b"an earlier recording"  # not touched at open
    recorder.close()  # no frame: nothing to keep
    assert target.read_bytes() == b"an earlier recording"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["keep.mcap"]



@pytest.mark.parametrize("shape", [(720, 1280), (3, 5), (1, 200)])
def test_the_image_message_parses_as_the_librarys_own(shape):
    """The pixels are appended after the library's encoding of the other fields: the same message."""
    from foxglove_schemas_protobuf.RawImage_pb2 import RawImage

    from tracker.recording import schemas

    image = np.random.default_rng(1).integers(0, 256, shape, dtype=np.uint8)
    expected = RawImage(frame_id="camera", width=shape[1], height=shape[0], encoding="mono8", step=shape[1],
                        data=image.tobytes())
    expected.timestamp.FromNanoseconds(5_000_000_123)
    assert RawImage.FromString(schemas.encode_image_pb(image, 5_000_000_123)) == expected
    assert np.array_equal(schemas.decode_image(schemas.encode_image_pb(image, 0), "x", "protobuf"), image)
