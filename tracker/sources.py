"""Frame sources: the edge of the system that touches cameras and files.

Every source yields ``Frame``s of 8-bit grey images with a capture time in
integer nanoseconds (``t_ns``: the source's own clock, which is what the
pipeline sees) and the tracker's monotonic time when the frame arrived
(``arrival_ns``: for latency and the PLC's t_capture_ms; a live camera's, when it captured the
frame, where its driver stamps frames on that clock).
"""

from __future__ import annotations

import dataclasses
import logging
import os
import queue
import re
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass

import cv2
import numpy as np

from tracker.errors import SourceError, SourceLost

log = logging.getLogger(__name__)

DEFAULT_SEQUENCE_FPS = 30.0
# Codecs whose frames OpenCV can hand over as 8-bit grey without conversion.
_RAW_GREY_FOURCC = (b"\0\0\0\0", b"Y800", b"GREY", b"Y8  ")
# Frames decoded ahead of the loop by a file source's reader thread.
PREFETCH_FRAMES = 4
# A live camera that delivers nothing for this long is lost.
CAMERA_TIMEOUT_S = 2.0
# A camera's own timestamp of a frame is its capture time only this little before it arrived (a stamp
# on another clock, or a stream position, lies far off, or in the future).
CAMERA_MAX_LATENCY_NS = 500_000_000


@dataclass(frozen=True)
class Frame:
    index: int
    t_ns: int
    image: np.ndarray
    arrival_ns: int = 0


def to_gray(image: np.ndarray, where: str) -> np.ndarray:
    if image.dtype != np.uint8:
        raise SourceError(f"{where}: expected 8-bit frames, got {image.dtype}")
    if image.ndim == 2:
        return image
    if image.ndim == 3 and image.shape[2] == 3:
        return cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    if image.ndim == 3 and image.shape[2] == 4:
        return cv2.cvtColor(image, cv2.COLOR_BGRA2GRAY)
    if image.ndim == 3 and image.shape[2] == 1:
        return image[:, :, 0]
    raise SourceError(f"{where}: expected a grey or colour image, got shape {image.shape}")


class FrameSource:
    """Base class: iterate for frames; ``live`` sources pace themselves, files do not."""

    name: str = "?"
    live: bool = False
    # Frames the camera delivered that the loop could not take (live sources only).
    overruns: int = 0

    def __iter__(self) -> Iterator[Frame]:
        raise NotImplementedError

    def close(self) -> None:  # noqa: B027 - optional hook
        pass


class VideoFileSource(FrameSource):
    def __init__(self, path: str, fps: float | None = None) -> None:
        self.name = path
        if os.path.isdir(path):
            raise SourceError(f"{path}: is a folder; expected a video file, a camera index or an image pattern "
                              f"(e.g. {os.path.join(path, '%05d.png')})")
        if not os.path.isfile(path):
            raise SourceError(f"{path}: video file not found")
        self._cap = cv2.VideoCapture(path)
        if not self._cap.isOpened():
            raise SourceError(f"{path}: cannot open as a video (unknown format or codec)")
        fourcc = int(self._cap.get(cv2.CAP_PROP_FOURCC)).to_bytes(4, "little")
        if fourcc in _RAW_GREY_FOURCC:
            # Uncompressed grey: take the 8-bit plane as stored (a tenth of the cost of
            # expanding it to BGR and converting back).
            self._cap.set(cv2.CAP_PROP_CONVERT_RGB, 0)
        container_fps = self._cap.get(cv2.CAP_PROP_FPS)
        self._fps = fps
        if fps is None and not (container_fps and container_fps > 0):
            log.warning("%s: no frame rate in the container; assuming %.0f fps (use --fps)", path, DEFAULT_SEQUENCE_FPS)
            self._fps = DEFAULT_SEQUENCE_FPS

    def __iter__(self) -> Iterator[Frame]:
        index = 0
        while True:
            ok, image = self._cap.read()
            if not ok:
                return
            if self._fps is not None:
                t_ns = round(index * 1e9 / self._fps)
            else:
                t_ns = round(self._cap.get(cv2.CAP_PROP_POS_MSEC) * 1e6)
            yield Frame(index, t_ns, to_gray(image, f"{self.name} frame {index}"), time.monotonic_ns())
            index += 1

    def close(self) -> None:
        self._cap.release()


class ImageSequenceSource(FrameSource):
    """A printf-style pattern such as ``frames/%05d.png``, numbered from 0 (or 1).

    The sequence ends at the first missing number after which no numbered file follows. A
    missing number with files after it is a gap: the run stops there with exit 1 naming the
    missing file (skipping it would shift every later frame's number and time)."""

    def __init__(self, pattern: str, fps: float | None = None) -> None:
        self.name = pattern
        try:
            first = [i for i in (0, 1) if os.path.isfile(pattern % i)]
        except (TypeError, ValueError):
            raise SourceError(f"{pattern}: not a valid printf-style image pattern (e.g. frames/%05d.png)") from None
        if not first:
            raise SourceError(f"{pattern}: no image found ({pattern % 0} or {pattern % 1})")
        self._start = first[0]
        self._fps_given = fps is not None
        self._fps = fps or DEFAULT_SEQUENCE_FPS

    def _next_present(self, number: int) -> str | None:
        """The first file of the sequence after ``number``, if any (one directory listing)."""
        folder, base = os.path.split(self.name)
        spec = re.fullmatch(r"(.*?)%0?\d*d(.*)", base)
        try:
            names = os.listdir(folder or ".") if spec else []
        except OSError:
            return None
        numbered = re.compile(re.escape(spec.group(1)) + r"(\d+)" + re.escape(spec.group(2))) if spec else None
        later = sorted(int(m.group(1)) for m in map(numbered.fullmatch, names) if m) if numbered else []
        later = [n for n in later if n > number and os.path.isfile(self.name % n)]
        return self.name % later[0] if later else None

    def __iter__(self) -> Iterator[Frame]:
        if not self._fps_given:
            log.warning("%s: image sequence without --fps; assuming %.0f fps", self.name, DEFAULT_SEQUENCE_FPS)
        index = 0
        while True:
            path = self.name % (self._start + index)
            if not os.path.isfile(path):
                following = self._next_present(self._start + index)
                if following is not None:
                    raise SourceLost(f"{path}: missing from the image sequence ({following} follows); "
                                     f"stopped after {index} frames")
                return
            image = cv2.imread(path, cv2.IMREAD_UNCHANGED)
            if image is None:
                raise SourceError(f"{path}: cannot read the image")
            yield Frame(index, round(index * 1e9 / self._fps), to_gray(image, path), time.monotonic_ns())
            index += 1


class CameraSource(FrameSource):
    """A live camera. A grabber thread keeps only the newest frame: the loop never sees a
    stale, buffered frame; frames it replaced before the loop took them are overruns."""

    live = True

    def __init__(self, index: int, fps: float | None = None) -> None:
        self.name = f"camera {index}"
        self._cap = cv2.VideoCapture(index)
        if not self._cap.isOpened():
            raise SourceError(f"camera {index}: cannot open (no such device, or it is busy)")
        if fps:
            self._cap.set(cv2.CAP_PROP_FPS, fps)
        self._cap.set(cv2.CAP_PROP_BUFFERSIZE, 1)
        self._cond = threading.Condition()
        self._latest: tuple[int, np.ndarray] | None = None
        self._failed = False
        self._running = True
        self._thread = threading.Thread(target=self._grab, name="camera", daemon=True)
        self._thread.start()

    def _grab(self) -> None:
        last_ns = 0
        while self._running:
            ok, image = self._cap.read()
            now = time.monotonic_ns()
            # Capture times only go forward (the Kalman filter's steps), whichever clock gave them.
            captured = last_ns = max(self._captured_ns(now), last_ns + 1) if ok else now
            with self._cond:
                if not ok:
                    self._failed = True
                    self._cond.notify_all()
                    return
                if self._latest is not None:
                    self.overruns += 1
                self._latest = (captured, image)
                self._cond.notify_all()

    def _captured_ns(self, arrival_ns: int) -> int:
        """When the frame was captured: the driver's timestamp where it is on our monotonic clock (V4L2's,
        which OpenCV gives as the position in ms: a USB camera's frame arrives tens of ms after it was
        exposed, millimetres of belt travel in the PLC's "where the part is now"); otherwise, as other
        backends give a stream position or another clock, its arrival."""
        stamp_ns = round(self._cap.get(cv2.CAP_PROP_POS_MSEC) * 1e6)
        return stamp_ns if 0 <= arrival_ns - stamp_ns <= CAMERA_MAX_LATENCY_NS else arrival_ns

    def __iter__(self) -> Iterator[Frame]:
        index = 0
        while self._running:
            with self._cond:
                ready = self._cond.wait_for(lambda: self._latest is not None or self._failed, CAMERA_TIMEOUT_S)
                if self._latest is None:
                    if not self._running:
                        return
                    why = "stopped delivering frames" if self._failed or ready else f"no frame for {CAMERA_TIMEOUT_S} s"
                    raise SourceLost(f"{self.name}: {why}")
                captured, image = self._latest
                self._latest = None
            yield Frame(index, captured, to_gray(image, self.name), captured)
            index += 1

    def close(self) -> None:
        self._running = False
        self._thread.join(timeout=CAMERA_TIMEOUT_S)
        self._cap.release()


class Prefetch(FrameSource):
    """Decodes a file source on a reader thread, a few frames ahead, in order.

    OpenCV releases the GIL while decoding, so decoding overlaps the loop's work on
    another core. Frames and their order are exactly those of the wrapped source.
    """

    _END = object()

    def __init__(self, source: FrameSource, depth: int = PREFETCH_FRAMES) -> None:
        self.source = source
        self.name = source.name
        self.live = source.live
        self._queue: queue.Queue = queue.Queue(maxsize=depth)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._read, name="decode", daemon=True)
        self._started = False

    def __getattr__(self, name: str):
        # calibration, config, ... of the wrapped source
        return getattr(self.source, name)

    def _put(self, item) -> bool:
        while not self._stop.is_set():
            try:
                self._queue.put(item, timeout=0.1)
                return True
            except queue.Full:
                continue
        return False

    def _read(self) -> None:
        try:
            for frame in self.source:
                if not self._put(frame):
                    return
            self._put(self._END)
        except BaseException as exc:  # handed to the loop's thread, raised there
            self._put(exc)

    def __iter__(self) -> Iterator[Frame]:
        if not self._started:
            self._started = True
            self._thread.start()
        while True:
            item = self._queue.get()
            if item is self._END:
                return
            if isinstance(item, BaseException):
                raise item
            # A file has no capture clock: its frame "arrives" when the loop takes it, not
            # when it was decoded ahead (else latency figures would count the read-ahead).
            yield dataclasses.replace(item, arrival_ns=time.monotonic_ns())

    def close(self) -> None:
        self._stop.set()
        if self._started:
            self._thread.join(timeout=5)
        self.source.close()


class Paced(FrameSource):
    """Delivers a file source's frames at their recorded rate, like the camera that made them."""

    def __init__(self, source: FrameSource) -> None:
        self.source = source
        self.name = source.name
        self._stop = threading.Event()

    def __getattr__(self, name: str):
        return getattr(self.source, name)

    def __iter__(self) -> Iterator[Frame]:
        start_wall = start_t = None
        for frame in self.source:
            if start_wall is None:
                start_wall, start_t = time.monotonic_ns(), frame.t_ns
            due_ns = start_wall + (frame.t_ns - start_t) - time.monotonic_ns()
            if due_ns > 0 and self._stop.wait(due_ns / 1e9):
                return
            yield dataclasses.replace(frame, arrival_ns=time.monotonic_ns())

    def close(self) -> None:
        self._stop.set()
        self.source.close()
