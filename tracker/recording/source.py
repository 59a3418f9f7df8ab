"""A recording read back: its run information, its frames (a ``FrameSource``) and its live poses.

Reading is sequential and never needs the summary at the end of the file, so a
recording cut short (a SIGKILL, a full disk) still gives every frame up to its
last complete chunk.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import os
import tempfile
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

from mcap.exceptions import EndOfFile, McapError
from mcap.records import Attachment, Channel, Chunk, Message, Metadata, Schema

from tracker import calibration as calib_io
from tracker.calibration import Calibration
from tracker.config import TrackerConfig
from tracker.errors import BadInput, RecordingError, SourceError
from tracker.recording import schemas
from tracker.recording.mcapio import MAGIC, ReadEnd, iter_records
from tracker.recording.writer import ATTACH_CALIBRATION, ATTACH_CONFIG, META_END, META_RUN
from tracker.sources import Frame, FrameSource

log = logging.getLogger(__name__)


@dataclass
class RecordingInfo:
    path: str
    calibration: Calibration
    config: TrackerConfig
    run: dict[str, str] = field(default_factory=dict)
    schemas: dict[int, str] = field(default_factory=dict)  # schema id -> name
    topics: dict[int, str] = field(default_factory=dict)  # channel id -> topic

    @property
    def fps(self) -> float | None:
        text = self.run.get("fps", "")
        return float(text) if text else None


def read_info(path: str) -> RecordingInfo:
    """The calibration, configuration and run metadata stored before the first frame."""
    if os.path.isdir(path):
        raise SourceError(f"{path}: is a folder; expected a recording (.mcap)")
    if not os.path.isfile(path):
        raise SourceError(f"{path}: recording not found")
    if not os.access(path, os.R_OK):
        raise SourceError(f"{path}: cannot read the recording: permission denied")
    with open(path, "rb") as f:
        head = f.read(len(MAGIC))
    if len(head) == len(MAGIC) and head != MAGIC:
        # Another kind of file (an image, a video): not "cut short before its header".
        raise SourceError(f"{path}: not an MCAP recording (it does not start with MCAP's magic bytes)")
    run: dict[str, str] = {}
    attachments: dict[str, bytes] = {}
    schema_names: dict[int, str] = {}
    topics: dict[int, str] = {}
    end = ReadEnd()
    with open(path, "rb") as f:
        for record in iter_records(f, end, emit_chunks=True):
            if isinstance(record, Schema):
                schema_names[record.id] = record.name
            elif isinstance(record, Channel):
                topics[record.id] = record.topic
            elif isinstance(record, Metadata) and record.name == META_RUN:
                run = dict(record.metadata)
            elif isinstance(record, Attachment):
                attachments[record.name] = record.data
            elif isinstance(record, Chunk | Message):
                break  # the run information is all before the first frame
    if end.position == 0 or (end.truncated and not run):
        raise SourceError(f"{path}: not a readable recording (it ends at byte {end.position}, before its header)")
    if ATTACH_CALIBRATION not in attachments:
        raise SourceError(f"{path}: no {ATTACH_CALIBRATION} attachment (not a belt-tracker recording?)")
    calibration = _load_calibration(path, attachments[ATTACH_CALIBRATION])
    config_text = attachments.get(ATTACH_CONFIG) or run.get("config", "").encode()
    try:
        config = TrackerConfig.from_dict(json.loads(config_text)) if config_text else TrackerConfig()
    except (ValueError, TypeError) as exc:
        raise SourceError(f"{path}: {ATTACH_CONFIG}: not a valid configuration ({exc})") from None
    return RecordingInfo(path, calibration, config, run, schema_names, topics)


def _load_calibration(path: str, data: bytes) -> Calibration:
    with tempfile.TemporaryDirectory(prefix="tracker-rec-") as tmp:
        file = Path(tmp) / ATTACH_CALIBRATION
        file.write_bytes(data)
        try:
            calibration = calib_io.load(file)
        except BadInput as exc:
            raise SourceError(f"{path}: {ATTACH_CALIBRATION}: {str(exc).split(': ', 1)[-1]}") from None
    return dataclasses.replace(calibration, source=f"{path} ({ATTACH_CALIBRATION})")


@dataclass(frozen=True)
class RecordedFrame:
    frame: Frame
    poses: dict | None  # the poses message logged live with this frame


class Recording:
    """Iterate a recording frame by frame; ``end`` says afterwards how the file ended."""

    def __init__(self, path: str) -> None:
        self.path = path
        self.info = read_info(path)
        self.end = ReadEnd()
        self.end_metadata: dict[str, str] = {}

    def frames(self) -> Iterator[RecordedFrame]:
        """Frames in file order, each with the poses logged live (messages of one frame are
        written together, image first). Frames missing behind damage (a gap in the frame
        numbers, or fewer frames than the recording's end record counts) make ``end`` damaged:
        a replay that skipped them would not be the run that was recorded."""
        image_ch = poses_ch = None
        image_encoding = "json"
        pending: Frame | None = None
        poses: dict | None = None
        expected = 0  # every recording numbers its frames from 0, one by one
        self.end = ReadEnd()
        with open(self.path, "rb") as f:
            for record in iter_records(f, self.end):
                if isinstance(record, Channel):
                    if record.topic == schemas.TOPIC_IMAGE:
                        image_ch, image_encoding = record.id, record.message_encoding
                    elif record.topic == schemas.TOPIC_POSES:
                        poses_ch = record.id
                elif isinstance(record, Message):
                    if record.channel_id == image_ch:
                        if record.sequence != expected:
                            self._missing(expected, record.sequence)
                            break
                        expected += 1
                        if pending is not None:
                            yield RecordedFrame(pending, poses)
                        pending, poses = self._frame(record, image_encoding), None
                    elif record.channel_id == poses_ch:
                        poses = json.loads(record.data)
                elif isinstance(record, Metadata) and record.name == META_END:
                    self.end_metadata = dict(record.metadata)
        if pending is not None:
            yield RecordedFrame(pending, poses)
        counted = self.end_metadata.get("frames", "")
        if self.end.complete and counted.isdigit() and int(counted) > expected:
            self.end.complete = False
            self.end.damaged = (f"the recording holds {counted} frames, only {expected} could be read "
                                f"(frames {expected}-{int(counted) - 1} are missing)")

    def _missing(self, expected: int, found: int) -> None:
        self.end.complete = self.end.truncated = False
        what = f"frame {expected}" if found == expected + 1 else f"frames {expected}-{found - 1}"
        self.end.damaged = (f"{what} missing (the next frame found is {found})" if found > expected
                            else f"frame {found} found where frame {expected} was expected")

    def _frame(self, message: Message, encoding: str) -> Frame:
        where = f"{self.path} frame {message.sequence}"
        try:
            image = schemas.decode_image(message.data, where, encoding)
        except (ValueError, KeyError, TypeError) as exc:
            raise RecordingError(f"{where}: cannot decode the image ({exc})") from None
        return Frame(message.sequence, message.log_time, image, time.monotonic_ns())


def frame_count(path: str) -> int | None:
    """Frames in a complete recording (from its summary); None when it has no summary."""
    from mcap.reader import make_reader  # noqa: PLC0415 - only for the progress bar

    try:
        with open(path, "rb") as f:
            summary = make_reader(f).get_summary()
            if summary is None or summary.statistics is None:
                return None
            for channel in summary.channels.values():
                if channel.topic == schemas.TOPIC_IMAGE:
                    return summary.statistics.channel_message_counts.get(channel.id, 0)
    except (McapError, EndOfFile, ValueError, OSError, KeyError):
        return None
    return None


class McapSource(FrameSource):
    """A recording as a camera: the recorded frames with their recorded capture times."""

    def __init__(self, path: str, fps: float | None = None) -> None:
        self.name = path
        self._recording = Recording(path)
        self.calibration = self._recording.info.calibration
        self.config = self._recording.info.config
        self._fps = fps
        if fps is not None:
            log.warning("%s: --fps %g replaces the recorded capture times", path, fps)

    @property
    def fps(self) -> float | None:
        return self._fps or self._recording.info.fps

    @property
    def recording(self) -> Recording:
        return self._recording

    def __iter__(self) -> Iterator[Frame]:
        used = 0
        for position, recorded in enumerate(self._recording.frames()):
            used = position + 1
            frame = recorded.frame
            if self._fps is not None:
                frame = dataclasses.replace(frame, t_ns=round(position * 1e9 / self._fps))
            yield frame
        end = self._recording.end
        if end.damaged:
            # Frames behind the damage are lost: the run did not see the whole recording.
            raise RecordingError(f"{end.describe(self.name)}; the run used the {used} frames "
                                 "before it")
        if not end.complete:
            log.warning("%s", end.describe(self.name))
