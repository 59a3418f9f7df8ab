"""The pose stream file (contract section 2), written beside the real-time loop.

``submit`` puts the frame's result in a bounded queue; a thread serialises and writes whole
lines. Like the recorder, a full queue holds the loop back rather than dropping a line (a pose
stream with a hole would mislead whoever reads it). A write error (disk full, device gone)
stops the stream with one log line and fault 6; the file is cut back to its last complete line,
so it stays valid JSON Lines; tracking, the PLC and the recording go on, and the run ends with
exit 1.
"""

from __future__ import annotations

import contextlib
import logging
import os
import queue
import threading

from tracker.errors import BadInput, TrackerError
from tracker.health import FAULT_POSES, Health
from tracker.poses import FrameResult

log = logging.getLogger(__name__)

# Results waiting to be written (a line is ~300 bytes per part: this bounds memory, not speed).
QUEUE_RESULTS = 1024
_STOP = object()


class PoseOutputError(TrackerError):
    """The pose stream stopped during the run (exit 1 at the end)."""


class PoseSink:
    def __init__(self, path: str, health: Health | None = None, label: str = "--poses",
                 shown_as: str | None = None) -> None:
        self.path = path
        self.health = health or Health()
        # What messages call the file (its final name when ``path`` is a staged temporary).
        self._name = f"{label} {shown_as or path}"
        try:
            self._fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        except OSError as exc:
            raise BadInput(f"{self._name}: cannot write the pose stream: {exc.strerror}") from None
        self.lines_written = 0
        self.failed: str | None = None
        self._offset = 0  # bytes of complete lines on disk
        self._queue: queue.Queue = queue.Queue(maxsize=QUEUE_RESULTS)
        self._closed = False
        self._thread = threading.Thread(target=self._write_loop, name="pose-writer", daemon=True)
        self._thread.start()

    def submit(self, frame, result: FrameResult) -> None:
        if self.failed is None and not self._closed:
            self._queue.put(result)

    def status(self) -> str:
        return "poses STOPPED" if self.failed else ""

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        self._queue.put(_STOP)
        self._thread.join()
        try:
            os.close(self._fd)
        except OSError as exc:
            self._fail(exc)
        if self.failed:
            raise PoseOutputError(f"{self._name}: {self.failed}")

    def _write_loop(self) -> None:
        while True:
            batch = [self._queue.get()]
            while True:  # whatever else is waiting goes out in the same write
                try:
                    batch.append(self._queue.get_nowait())
                except queue.Empty:
                    break
            stop = batch[-1] is _STOP
            results = [r for r in batch if r is not _STOP]
            if results and self.failed is None:
                self._write(b"".join(r.to_json_line().encode() for r in results), len(results))
            if stop:
                return

    def _write(self, data: bytes, lines: int) -> None:
        view = memoryview(data)
        try:
            while view:
                view = view[os.write(self._fd, view):]
        except OSError as exc:
            self._fail(exc)
            return
        self._offset += len(data)
        self.lines_written += lines

    def _fail(self, exc: OSError) -> None:
        if self.failed is not None:
            return
        # Cut a partly written line off, so the file ends with a complete line.
        with contextlib.suppress(OSError):
            os.ftruncate(self._fd, self._offset)
        self.failed = f"pose output stopped after {self.lines_written} frames: {exc.strerror or exc}"
        self.health.set_fault(FAULT_POSES)
        log.error("%s: %s; tracking goes on (fault %d)", self._name, self.failed, FAULT_POSES)
