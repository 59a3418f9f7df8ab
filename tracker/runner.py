"""The real-time loop: source -> pipeline -> sinks, with health and a live status line.

Sinks (pose file, PLC writer, recorder) take each result; the PLC writer and the
recorder hand it to their own threads, so the loop never waits on the network
and waits on the disk only when the recorder's bounded queue is full.
"""

from __future__ import annotations

import logging
import threading
import time
from dataclasses import dataclass, field
from typing import Protocol, TextIO

import numpy as np

from tracker.errors import BadInput, FrameSizeError, SourceLost, StoppedMidRun
from tracker.health import FAULT_CAMERA_LOST, FAULT_FRAME_SIZE, FAULT_OVERRUN, FAULT_SCENE, FAULT_TEXT, Health
from tracker.pipeline import Pipeline
from tracker.poses import FrameResult
from tracker.sources import Frame, FrameSource

log = logging.getLogger(__name__)

STATUS_PERIOD_S = 0.25
# Fault 4 (overrun) says frames are being dropped now: set at each one, cleared once none has been
# dropped for this long (a PLC polling every second still sees a single dropped frame). Latched, one
# frame dropped in a run (a 90 fps camera's one in a hundred) would flag the cell faulty for good.
OVERRUN_FAULT_HOLD_S = 2.0
# Loop times kept for percentiles (a ring: memory stays flat over any run length).
_LOOP_WINDOW = 4096


class Sink(Protocol):
    def submit(self, frame: Frame, result: FrameResult) -> None: ...

    def status(self) -> str: ...

    def close(self) -> None: ...


@dataclass
class RunSummary:
    frames: int = 0
    seconds: float = 0.0
    track_ids: set[int] = field(default_factory=set)
    measured: int = 0
    loop_ms_p50: float = 0.0
    loop_ms_p99: float = 0.0
    overruns: int = 0
    # Frames whose foreground covered most of the region of interest (nothing measured in them).
    scene_faults: int = 0
    stopped_by: str = "end of source"

    def line(self) -> str:
        fps = self.frames / self.seconds if self.seconds > 0 else 0.0
        parts = f"{len(self.track_ids)} part{'' if len(self.track_ids) == 1 else 's'}"
        return (
            f"{self.frames} frames in {self.seconds:.2f} s ({fps:.1f} fps), {parts} tracked, "
            f"{self.measured} measurements, loop p50 {self.loop_ms_p50:.2f} ms p99 {self.loop_ms_p99:.2f} ms, "
            f"{self.overruns} overruns{self._scene()}; stopped by {self.stopped_by}"
        )

    def _scene(self) -> str:
        return f", {self.scene_faults} frames with the scene not understood" if self.scene_faults else ""


class StatusLine:
    """One live line on a terminal (carriage return), a line per second elsewhere.

    While it is shown on a terminal, a log record first clears it, so a log line never lands at
    the end of the status line; the next status update draws it again below the log line."""

    def __init__(self, out: TextIO) -> None:
        self._out = out
        self._tty = out.isatty()
        self._period = STATUS_PERIOD_S if self._tty else 1.0
        self._next = 0.0
        self._width = 0
        if self._tty:
            for handler in logging.getLogger().handlers:
                handler.addFilter(self)

    def filter(self, record: logging.LogRecord) -> bool:
        """A logging filter that lets every record through, after clearing the status line."""
        if self._width:
            self._out.write("\r" + " " * self._width + "\r")
            self._out.flush()
            self._width = 0
            self._next = 0.0  # redraw at the next frame
        return True

    def due(self) -> bool:
        """Time for a new line (so the loop builds the text only then)."""
        return time.monotonic() >= self._next

    def show(self, text: str, force: bool = False) -> None:
        now = time.monotonic()
        if not force and now < self._next:
            return
        self._next = now + self._period
        if self._tty:
            self._out.write("\r" + text.ljust(self._width))
            self._width = len(text)
        else:
            self._out.write(text + "\n")
        self._out.flush()

    def end(self) -> None:
        if self._tty and self._width:
            self._out.write("\n")
            self._out.flush()
            self._width = 0
        for handler in logging.getLogger().handlers:
            handler.removeFilter(self)


def describe_belt(result: FrameResult) -> str:
    """The belt's measured velocity for the status line ("" when not measured)."""
    if result.belt_mm_s is None:
        return ""
    vx, vy = result.belt_mm_s
    return f"belt {vx:+.0f},{vy:+.0f} mm/s"


def describe(result: FrameResult) -> str:
    if result.scene_fault:
        return f"FAULT {FAULT_SCENE}: {FAULT_TEXT[FAULT_SCENE]}"
    if not result.objects:
        return "no part"
    o = result.objects[0]
    flags = [] if o.measured else ["predicted"]
    if not o.pickable:
        flags.append("not pickable")
    height = ""
    if o.height_mm or not o.height_converged:
        height = f" h={o.height_mm:.1f}" + ("" if o.height_converged else " settling")
    flag = f" ({', '.join(flags)})" if flags else ""
    return f"#{o.id} x={o.x_mm:.1f} y={o.y_mm:.1f} a={o.angle_deg:.1f}{height}{flag}"


class Runner:
    def __init__(self, source: FrameSource, pipeline: Pipeline, sinks: list[Sink],
                 health: Health | None = None, status: StatusLine | None = None,
                 stop: threading.Event | None = None, max_frames: int | None = None,
                 overrun_hold_s: float = OVERRUN_FAULT_HOLD_S) -> None:
        self.source = source
        self.pipeline = pipeline
        self.sinks = sinks
        self.health = health or Health()
        self.status = status
        self.stop = stop or threading.Event()
        self.max_frames = max_frames
        self.summary = RunSummary()
        self._overrun_hold_ns = round(overrun_hold_s * 1e9)
        self._last_overrun_ns: int | None = None

    def _check_overruns(self, health: Health, now_ns: int) -> None:
        """The source's overruns into the health word: fault 4 while frames are being dropped (see
        OVERRUN_FAULT_HOLD_S); the count stays for the status line and the summary."""
        dropped = self.source.overruns > health.overruns
        health.overruns = self.source.overruns
        if dropped:
            self._last_overrun_ns = now_ns
            health.set_fault(FAULT_OVERRUN)
        elif self._last_overrun_ns is not None and now_ns - self._last_overrun_ns >= self._overrun_hold_ns:
            self._last_overrun_ns = None
            health.clear_fault(FAULT_OVERRUN)

    def run(self) -> RunSummary:
        calib = self.pipeline.calibration
        health, summary = self.health, self.summary
        loop_ns = np.zeros(_LOOP_WINDOW, dtype=np.int64)
        started = time.monotonic()
        fps_t, fps_n, fps = started, 0, 0.0
        try:
            for frame in self.source:
                h, w = frame.image.shape[:2]
                if (w, h) != calib.size:
                    health.set_fault(FAULT_FRAME_SIZE)
                    calib.check_frame_size(w, h, f"{self.source.name} frame {frame.index}")
                t0 = time.perf_counter_ns()
                result = self.pipeline.process(frame.index, frame.image, frame.t_ns)
                health.part_tracked = bool(result.objects)
                self._check_overruns(health, t0)
                if result.scene_fault:
                    health.set_fault(FAULT_SCENE)
                    if not summary.scene_faults:
                        log.warning("%s frame %d: scene not understood: the foreground covers most of the region "
                                    "of interest (fault %d); nothing is tracked while it lasts. Check the light, "
                                    "the camera's position and segment settings (model, roi).",
                                    self.source.name, frame.index, FAULT_SCENE)
                    summary.scene_faults += 1
                else:
                    # Understood again (the reference re-learnt, the light back): the fault clears.
                    health.clear_fault(FAULT_SCENE)
                for sink in self.sinks:
                    sink.submit(frame, result)
                this_loop_ns = time.perf_counter_ns() - t0
                loop_ns[summary.frames % _LOOP_WINDOW] = this_loop_ns
                summary.frames += 1
                summary.track_ids.update(o.id for o in result.objects)
                summary.measured += sum(o.measured for o in result.objects)
                fps_n += 1
                now = time.monotonic()
                if now - fps_t >= 0.5:
                    fps, fps_t, fps_n = fps_n / (now - fps_t), now, 0
                if self.status and self.status.due():
                    parts = [f"frame {frame.index}", f"{fps:.0f} fps", f"loop {this_loop_ns / 1e6:.2f} ms",
                             f"objects {len(result.objects)}", describe(result)]
                    parts += [b for b in (describe_belt(result),) if b]
                    parts += [s for s in (sink.status() for sink in self.sinks) if s]
                    if self.source.overruns:
                        parts.append(f"overruns {self.source.overruns}")
                    self.status.show(" | ".join(parts))
                if self.stop.is_set():
                    summary.stopped_by = "signal"
                    break
                if self.max_frames is not None and summary.frames >= self.max_frames:
                    summary.stopped_by = "--max-frames"
                    break
        except SourceLost:
            health.camera_ok = False
            health.set_fault(FAULT_CAMERA_LOST)
            raise
        except BadInput as exc:
            if not summary.frames:
                raise  # nothing processed, nothing written: bad input (exit 2)
            if not isinstance(exc, FrameSizeError):
                health.camera_ok = False
                health.set_fault(FAULT_CAMERA_LOST)
            raise StoppedMidRun(f"{exc}; the run stopped there, after {summary.frames} frames "
                                f"(its outputs hold them)") from None
        except Exception:
            # Any other end of the run (a damaged file, a bad frame, a bug): the PLC's final
            # block must not say "no fault" while the poses have stopped coming.
            health.camera_ok = False
            health.set_fault(FAULT_CAMERA_LOST)
            raise
        finally:
            health.running = False
            summary.seconds = time.monotonic() - started
            summary.overruns = health.overruns = self.source.overruns
            n = min(summary.frames, _LOOP_WINDOW)
            if n:
                summary.loop_ms_p50 = float(np.percentile(loop_ns[:n], 50) / 1e6)
                summary.loop_ms_p99 = float(np.percentile(loop_ns[:n], 99) / 1e6)
            if self.status:
                self.status.end()
            self._close_all()
        return summary

    def _close_all(self) -> None:
        errors = []
        for sink in self.sinks:
            try:
                sink.close()
            except Exception as exc:  # noqa: BLE001 - every other sink still closes (the PLC's final block)
                errors.append(exc)
        self.source.close()
        if errors:
            raise errors[0]
