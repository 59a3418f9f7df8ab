"""The recorder: every frame the pipeline processes, and its result, to an MCAP file.

It runs beside the real-time loop. ``submit`` only puts the frame and its result
in a bounded queue. An encoder thread turns them into messages (``schemas``) and groups
them into chunks of about a second; a disk thread compresses each chunk and
writes it (compression releases the GIL, so the two overlap). If the disk cannot
keep up, the full queue holds the loop back rather than dropping a frame: a
recording with a hole could not be replayed. A live camera counts the frames it
delivered meanwhile as overruns (fault 4). A write error (disk full, device gone)
stops the recording with one line and fault 3; tracking goes on.
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import queue
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from tracker import __version__
from tracker import calibration as calib_io
from tracker.atomic import replacing_mode
from tracker.calibration import Calibration
from tracker.config import TrackerConfig
from tracker.errors import BadInput, RecordingError
from tracker.health import FAULT_RECORDING, Health
from tracker.poses import FrameResult
from tracker.recording import schemas
from tracker.recording.mcapio import COMPRESSIONS, Compression, McapWriter, OpenChunk, Output, RawFile
from tracker.segment.roi import roi_polygon_px
from tracker.sources import Frame

log = logging.getLogger(__name__)

# Names of the records that make a recording replayable on its own.
META_RUN = "tracker.run"
META_END = "tracker.end"
ATTACH_CALIBRATION = "calibration.yaml"
ATTACH_CONFIG = "config.json"
# How long ``submit`` waits at a time on a full queue before checking the recorder is alive.
_PUT_POLL_S = 0.1


@dataclass(frozen=True)
class RecorderConfig:
    # Frames waiting for the encoder; a full queue holds the loop back (~60 MB at 1280x720).
    queue_frames: int = 64
    # A chunk is closed after this much capture time (what a SIGKILL can lose at most)...
    chunk_duration_ns: int = 1_000_000_000
    # ...or this many uncompressed bytes, whichever comes first (bounds memory and loss).
    chunk_max_bytes: int = 48 << 20
    # Chunks compressed but not yet written (between the encoder and disk threads).
    disk_queue_chunks: int = 2
    # Chunk compression; zstd level 1 measured best for size at the speed needed (bench/record_bench.py:
    # negative levels save little time and double the file; level 3 takes three times as long).
    compression: str = "zstd"
    zstd_level: int = 1
    # zstd's own worker threads: they compress without Python's lock (the streaming call made on
    # the disk thread with 0 workers holds it), so the loop runs meanwhile; 2 measured fastest.
    zstd_threads: int = 2
    # Images and annotations as protobuf (a copy per frame); "json" writes the format of
    # earlier versions (base64 images, 1.2 ms more per 720p frame and a third more bytes).
    message_encoding: str = "protobuf"

    def __post_init__(self) -> None:
        if self.compression not in COMPRESSIONS:
            raise BadInput(f"recorder compression: expected one of {COMPRESSIONS}, got {self.compression!r}")
        if not -7 <= self.zstd_level <= 22:
            raise BadInput(f"recorder zstd level: expected -7 to 22, got {self.zstd_level}")
        if self.message_encoding not in schemas.ENCODINGS:
            raise BadInput(f"recorder message_encoding: expected one of {schemas.ENCODINGS}, "
                           f"got {self.message_encoding!r}")
        for name in ("queue_frames", "chunk_duration_ns", "chunk_max_bytes", "disk_queue_chunks"):
            if getattr(self, name) <= 0:
                raise BadInput(f"RecorderConfig.{name}: expected > 0, got {getattr(self, name)}")

    def compression_spec(self) -> Compression:
        return Compression(self.compression, self.zstd_level, self.zstd_threads)


def calibration_bytes(calibration: Calibration) -> bytes:
    """The calibration file exactly as ``tracker.calibration.save`` writes it (YAML)."""
    with tempfile.TemporaryDirectory(prefix="tracker-rec-") as tmp:
        path = Path(tmp) / ATTACH_CALIBRATION
        calib_io.save(calibration, path)
        return path.read_bytes()


@dataclass(frozen=True)
class RunInfo:
    """Everything a replay needs besides the frames."""

    calibration: Calibration
    config: TrackerConfig
    source_name: str = "?"
    fps: float | None = None
    # Stamp the start and end with the wall clock, and count the submits the disk held back.
    # A synthetic recording does neither: the same command then writes the same bytes.
    wall_clock: bool = True

    def metadata(self) -> dict[str, str]:
        meta = {
            "software": "belt-tracker", "version": __version__, "source": self.source_name,
            "fps": "" if self.fps is None else repr(float(self.fps)),
            "image_width": str(self.calibration.image_width), "image_height": str(self.calibration.image_height),
            "config": json.dumps(self.config.to_dict(), sort_keys=True),
        }
        if self.wall_clock:
            meta["started_unix_ns"] = str(time.time_ns())
        return meta


class _Stop:
    """Queue sentinel."""


class Recorder:
    """A ``Sink`` that records every submitted frame and result. Open it with ``Recorder.open``."""

    def __init__(self, out: Output, path: str, info: RunInfo, health: Health | None = None,
                 config: RecorderConfig | None = None, overruns=lambda: 0, temporary: str | None = None) -> None:
        self.path = path
        # ``out`` writes to ``temporary`` (beside ``path``), renamed over ``path`` once the first
        # chunk is on disk: until there is something to keep, an existing file stays as it was.
        self._temporary = temporary
        self.info = info
        self.config = config or RecorderConfig()
        self.health = health or Health()
        self._out = out
        self._overruns = overruns
        self._overlay = schemas.Overlay(info.calibration, info.config.measure.part_height_mm,
                                        roi_polygon_px(info.config.segment, info.calibration))
        self._frames_in: queue.Queue[Any] = queue.Queue(self.config.queue_frames)
        self._chunks_out: queue.Queue[Any] = queue.Queue(self.config.disk_queue_chunks)
        self._spares: queue.SimpleQueue[bytearray] = queue.SimpleQueue()  # written chunks' buffers
        self._failed: str = ""
        self._closed = False
        self.frames_submitted = 0
        self.frames_written = 0  # in chunks that reached the OS
        self.held_back = 0  # submits that found the queue full
        self._writer = McapWriter(out, self.config.compression_spec())
        self._writer.start()
        self._channels = {}
        for topic, schema_name in schemas.CHANNELS.items():
            schema_encoding, data, message_encoding = schemas.channel_schema(schema_name, self.config.message_encoding)
            schema_id = self._writer.add_schema(schema_name, schema_encoding, data)
            self._channels[topic] = self._writer.add_channel(topic, message_encoding, schema_id)
        binary = self.config.message_encoding == "protobuf"
        self._encode_image = schemas.image_pb_parts if binary else schemas.encode_image
        self._encode_annotations = self._overlay.encode_pb if binary else self._overlay.encode
        # /tracker/track carries one message per object: its own sequence, unique on its channel.
        self._track_sequence = 0
        self._writer.add_metadata(META_RUN, info.metadata())
        self._writer.add_attachment(ATTACH_CALIBRATION, "application/x-yaml", calibration_bytes(info.calibration))
        self._writer.add_attachment(ATTACH_CONFIG, "application/json",
                                    json.dumps(info.config.to_dict(), indent=1, sort_keys=True).encode())
        self._encoder = threading.Thread(target=self._encode_loop, name="recorder-encode", daemon=True)
        self._disk = threading.Thread(target=self._disk_loop, name="recorder-disk", daemon=True)
        self._encoder.start()
        self._disk.start()

    @classmethod
    def open(cls, path: str, info: RunInfo, health: Health | None = None, config: RecorderConfig | None = None,
             overruns=lambda: 0) -> Recorder:
        """Record to ``path``: to a temporary file beside it, moved over ``path`` when the first
        chunk reaches the disk. An unwritable path is bad input (exit 2) and leaves no file behind;
        a run that ends before its first chunk leaves ``path`` as it was."""
        target = Path(path)
        try:
            fd, temporary = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".part", dir=target.parent or ".")
            os.close(fd)
            out = RawFile(temporary)
        except OSError as exc:
            raise BadInput(f"--record {path}: cannot write the recording: {exc.strerror}") from None
        try:
            return cls(out, path, info, health, config, overruns, temporary)
        except OSError as exc:
            out.close()
            _remove(temporary)
            raise BadInput(f"--record {path}: cannot write the recording: {exc.strerror}") from None

    # --- the loop's side -----------------------------------------------------------------------
    def submit(self, frame: Frame, result: FrameResult) -> None:
        if self._failed or self._closed:
            return
        self.frames_submitted += 1
        item = (frame, result)
        try:
            self._frames_in.put_nowait(item)
            return
        except queue.Full:
            self.held_back += 1
        # The disk is behind: wait (never drop a frame), but not on a recorder that has died.
        while not self._failed:
            try:
                self._frames_in.put(item, timeout=_PUT_POLL_S)
                return
            except queue.Full:
                continue

    def status(self) -> str:
        if self._failed:
            return "rec STOPPED"
        mb = self._writer.bytes_written / 1e6
        return f"rec {mb:.0f} MB q {self._frames_in.qsize()}/{self.config.queue_frames}"

    @property
    def failed(self) -> str:
        return self._failed

    def close(self) -> None:
        """Write what is queued, the end metadata and the summary. Raises RecordingError if the
        recording stopped early (the file then replays up to its last complete chunk)."""
        if self._closed:
            return
        self._closed = True
        self._put_always(self._frames_in, _Stop)
        self._encoder.join()
        self._disk.join()
        try:
            if not self._failed:
                try:
                    end = {"frames": str(self.frames_written), "overruns": str(int(self._overruns()))}
                    if self.info.wall_clock:
                        end |= {"held_back": str(self.held_back), "ended_unix_ns": str(time.time_ns())}
                    self._writer.add_metadata(META_END, end)
                    self._writer.finish()
                except OSError as exc:
                    self._fail(exc)
        finally:
            close = getattr(self._out, "close", None)
            if close:
                close()
            if self._temporary:  # no chunk reached the disk: nothing to keep
                _remove(self._temporary)
                self._temporary = None
        if self._failed:
            raise RecordingError(self._failed)
        log.debug("recording %s: %d frames, %d bytes", self.path, self.frames_written, self._writer.bytes_written)

    # --- the recorder's threads ----------------------------------------------------------------
    def _put_always(self, q: queue.Queue, item: Any) -> None:
        while True:
            try:
                q.put(item, timeout=_PUT_POLL_S)
                return
            except queue.Full:
                if q is self._chunks_out and not self._disk.is_alive():
                    return

    def _encode_loop(self) -> None:
        # Each chunk's buffer is sized like the last one: allocated once, not grown frame by frame,
        # and reused once the disk thread has written it.
        capacity = 1 << 20
        chunk, frames = OpenChunk(capacity), 0
        cfg = self.config
        try:
            while True:
                item = self._frames_in.get()
                if item is _Stop:
                    break
                if self._failed:
                    continue  # drain, so the loop is never held back by a dead recorder
                frame, result = item
                self._add_frame(chunk, frame, result)
                frames += 1
                if chunk.size >= cfg.chunk_max_bytes or chunk.end_ns - chunk.start_ns >= cfg.chunk_duration_ns:
                    self._put_always(self._chunks_out, (chunk, frames))
                    capacity = min(chunk.size + chunk.size // 8, cfg.chunk_max_bytes + (8 << 20))
                    chunk, frames = OpenChunk(capacity, self._spare()), 0
        except Exception as exc:  # an encoder bug must not kill the loop: stop recording, say why
            log.exception("recorder: encoding failed")
            self._fail(exc)
        finally:
            if frames and not self._failed:
                self._put_always(self._chunks_out, (chunk, frames))
            self._put_always(self._chunks_out, _Stop)

    def _add_frame(self, chunk: OpenChunk, frame: Frame, result: FrameResult) -> None:
        # The image's sequence is the frame index (a replay reads it back from there).
        ch, t, seq = self._channels, frame.t_ns, frame.index
        chunk.add(ch[schemas.TOPIC_IMAGE], t, self._encode_image(frame.image, t), seq)
        chunk.add(ch[schemas.TOPIC_POSES], t, schemas.encode_poses(result), seq)
        chunk.add(ch[schemas.TOPIC_ANNOTATIONS], t, self._encode_annotations(result), seq)
        for obj in result.objects:
            self._track_sequence += 1
            chunk.add(ch[schemas.TOPIC_TRACK], t, schemas.encode_track(result, obj), self._track_sequence)

    def _spare(self) -> bytearray | None:
        try:
            return self._spares.get_nowait()
        except queue.Empty:
            return None

    def _disk_loop(self) -> None:
        while True:
            item = self._chunks_out.get()
            if item is _Stop:
                return
            if self._failed:
                continue
            chunk, frames = item
            good = self._writer.bytes_written
            try:
                self._writer.write_chunk(chunk)
                self._spares.put(chunk.buffer)
                self.frames_written += frames
                if self._temporary:
                    os.chmod(self._temporary, replacing_mode(self.path))  # mkstemp made it private
                    os.replace(self._temporary, self.path)
                    self._temporary = None
            except OSError as exc:
                self._fail(exc)
                # Cut the partial chunk off: the file stays a clean (summary-less) recording, and
                # on a full disk the space goes back to the system.
                truncate = getattr(self._out, "truncate", None)
                if truncate:
                    with contextlib.suppress(OSError):
                        truncate(good)
            except Exception as exc:
                log.exception("recorder: writing failed")
                self._fail(exc)

    def _fail(self, exc: BaseException) -> None:
        if self._failed:
            return
        why = exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc)
        kept = ("the file replays up to there" if self.frames_written or not self._temporary
                else "nothing was recorded, an existing file is left as it was")
        self._failed = f"recording stopped: {self.path}: {why} (after {self.frames_written} frames); {kept}"
        self.health.recording_ok = False
        self.health.set_fault(FAULT_RECORDING)
        log.error("%s; tracking continues", self._failed)


def _remove(path: str) -> None:
    with contextlib.suppress(OSError):
        os.unlink(path)
