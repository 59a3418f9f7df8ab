"""Replay: the same pipeline, with the recorded calibration and configuration, on the recorded frames.

The pipeline is deterministic (its output depends only on the frames, their
capture times and the configuration), so a replay must give byte-identical pose
lines; ``check`` compares each with the line logged live and stops at the first
difference, naming the frame and the field.
"""

from __future__ import annotations

import contextlib
import json
import sys
import time
from dataclasses import dataclass, field
from typing import IO, TextIO

from tracker.atomic import atomic_path
from tracker.errors import BadInput, TrackerError
from tracker.pipeline import Pipeline
from tracker.recording.mcapio import ReadEnd
from tracker.recording.schemas import pose_line_of
from tracker.recording.source import Recording, frame_count

PROGRESS_PERIOD_S = 0.2
PROGRESS_PERIOD_PIPE_S = 2.0
BAR_WIDTH = 30


class ReplayMismatch(TrackerError):
    """The replayed poses differ from those logged live (exit 1)."""


@dataclass
class ReplayReport:
    frames: int = 0
    checked: int = 0
    seconds: float = 0.0
    end: ReadEnd = field(default_factory=ReadEnd)
    end_metadata: dict[str, str] = field(default_factory=dict)

    @property
    def fps(self) -> float:
        return self.frames / self.seconds if self.seconds > 0 else 0.0


class Progress:
    """A progress bar on a terminal (carriage return); an occasional line elsewhere."""

    def __init__(self, out: TextIO, total: int | None, label: str = "replay") -> None:
        self._out = out
        self._label = label
        self._total = total
        self._tty = out.isatty()
        self._period = PROGRESS_PERIOD_S if self._tty else PROGRESS_PERIOD_PIPE_S
        self._start = time.monotonic()
        self._next = self._start + self._period
        self._shown = False

    def update(self, done: int, force: bool = False) -> None:
        now = time.monotonic()
        if not force and now < self._next:
            return
        self._next = now + self._period
        fps = done / max(now - self._start, 1e-9)
        if self._total:
            filled = min(BAR_WIDTH, BAR_WIDTH * done // self._total)
            text = (f"{self._label} [{'#' * filled}{'.' * (BAR_WIDTH - filled)}] {done}/{self._total} frames "
                    f"{100 * done / self._total:.0f}% {fps:.0f} fps")
        else:
            text = f"{self._label} {done} frames {fps:.0f} fps"
        self._out.write(("\r" + text) if self._tty else (text + "\n"))
        self._out.flush()
        self._shown = True

    def end(self, done: int) -> None:
        self.update(done, force=True)
        if self._tty and self._shown:
            self._out.write("\n")
            self._out.flush()


def first_difference(live, replayed, where: str = "", tolerance: float = 0.0) -> str | None:
    """The path of the first field that differs (``objects[0].x_mm``) with both values; numbers
    within ``tolerance`` of each other are equal."""
    if isinstance(live, dict) and isinstance(replayed, dict):
        for key in list(live) + [k for k in replayed if k not in live]:
            if key not in live or key not in replayed:
                side = "replay" if key in replayed else "live run"
                return f"{where}{'.' if where else ''}{key}: present only in the {side}"
            found = first_difference(live[key], replayed[key], f"{where}{'.' if where else ''}{key}", tolerance)
            if found:
                return found
        return None
    if isinstance(live, list) and isinstance(replayed, list):
        for i, (a, b) in enumerate(zip(live, replayed, strict=False)):
            found = first_difference(a, b, f"{where}[{i}]", tolerance)
            if found:
                return found
        if len(live) != len(replayed):
            return f"{where}: {len(live)} items live, {len(replayed)} in the replay"
        return None
    numbers = (int, float)
    if (tolerance and isinstance(live, numbers) and isinstance(replayed, numbers)
            and not isinstance(live, bool) and not isinstance(replayed, bool)):
        return None if abs(live - replayed) <= tolerance else f"{where}: live {live!r}, replay {replayed!r}"
    if type(live) is not type(replayed) or live != replayed:
        return f"{where}: live {live!r}, replay {replayed!r}"
    return None


def _line(d: dict) -> str:
    # The pose stream's own serialisation (poses.FrameResult.to_json_line).
    return json.dumps(d, allow_nan=False, separators=(", ", ": ")) + "\n"


def replay(path: str, poses_out: str | None = None, check: bool = False, tolerance: float = 0.0,
           progress_out: TextIO | None = sys.stderr) -> ReplayReport:
    recording = Recording(path)
    info = recording.info
    pipeline = Pipeline(info.calibration, info.config)
    report = ReplayReport()
    progress = Progress(progress_out, frame_count(path)) if progress_out is not None else None
    with contextlib.ExitStack() as stack:
        # The replayed poses are written to a temporary file renamed over ``poses_out`` when the
        # replay succeeds: never a half-written file.
        out = _open_poses(stack, poses_out)
        started = time.monotonic()
        try:
            for recorded in recording.frames():
                frame = recorded.frame
                w, h = frame.image.shape[1], frame.image.shape[0]
                info.calibration.check_frame_size(w, h, f"{path} frame {frame.index}")
                result = pipeline.process(frame.index, frame.image, frame.t_ns)
                line = result.to_json_line()
                if out is not None:
                    out.write(line)
                if check:
                    _compare(path, frame.index, recorded.poses, result.to_dict(), line, tolerance)
                    report.checked += 1
                report.frames += 1
                if progress:
                    progress.update(report.frames)
        finally:
            report.seconds = time.monotonic() - started
            report.end = recording.end
            report.end_metadata = recording.end_metadata
            if progress:
                progress.end(report.frames)
    return report


def _compare(path: str, index: int, live: dict | None, replayed: dict, line: str, tolerance: float = 0.0) -> None:
    if live is None:
        raise ReplayMismatch(f"{path}: frame {index}: no poses were logged live for this frame")
    logged = pose_line_of(live)
    if _line(logged) == line:
        return
    where = first_difference(logged, replayed, tolerance=tolerance)
    if tolerance and where is None:
        return
    where = where or "the serialised line differs"
    raise ReplayMismatch(f"{path}: frame {index}: replayed poses differ from the live run at {where}")


def _open_poses(stack: contextlib.ExitStack, path: str | None) -> IO[str] | None:
    if path is None:
        return None
    try:
        tmp = stack.enter_context(atomic_path(path))
    except OSError as exc:
        raise BadInput(f"--poses {path}: cannot write the pose stream: {exc.strerror}") from None
    return stack.enter_context(open(tmp, "w", encoding="utf-8"))  # noqa: SIM115 - closed by the stack
