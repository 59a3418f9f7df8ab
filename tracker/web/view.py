"""What the live page shows, built on the server's threads from the newest frame the loop handed over.

``submit`` (the loop's side) stores two references under a lock: O(1), no copy, no encoding.
The JPEG is drawn and encoded at most ``MAX_FPS`` times a second, whatever the number of
viewers: they share the newest encoding (latest wins).
"""

from __future__ import annotations

import json
import threading
import time

import cv2
import numpy as np

from plc.options import PlcOptions
from plc.queue import PickOrder
from tracker.calibration import Calibration
from tracker.health import FAULT_TEXT, Health
from tracker.poses import FrameResult
from tracker.sources import Frame

MAX_FPS = 15.0
# The image sent is at most this wide (px); the overlays are drawn at that size.
MAX_WIDTH_PX = 800
JPEG_QUALITY = 80
# BGR colours: measured parts, predicted parts, the belt grid, the region of interest.
MEASURED, PREDICTED, GRID, ROI = (0, 220, 0), (0, 200, 255), (200, 120, 40), (255, 0, 255)
GRID_MM = 100.0


class LiveView:
    """A ``tracker.runner.Sink`` that keeps the newest frame and result for the web server."""

    def __init__(self, calibration: Calibration, health: Health, sinks: list, roi_px: np.ndarray | None = None,
                 part_height_mm: float = 0.0) -> None:
        self.calibration = calibration
        self.health = health
        self.sinks = sinks  # the other sinks, for their status (PLC, recorder)
        self.roi_px = roi_px
        self._part_height_mm = part_height_mm
        self._lock = threading.Lock()
        self._frame: Frame | None = None
        self._result: FrameResult | None = None
        self._frames = 0
        self._started = time.monotonic()
        self._jpeg: tuple[int, float, bytes] | None = None  # (frame index, monotonic time, bytes)
        self._encode_lock = threading.Lock()
        self._state: tuple[float, bytes] | None = None  # (monotonic time, JSON)
        self._grid = self._grid_lines()
        # The PLC queue's own pick order (first in line to leave the view first), for the page.
        self._order = PickOrder(PlcOptions.__dataclass_fields__["min_belt_speed_mm_s"].default)

    # ---- the loop's side ----
    def submit(self, frame: Frame, result: FrameResult) -> None:
        with self._lock:
            self._frame, self._result = frame, result
            self._frames += 1

    def status(self) -> str:
        return ""

    def close(self) -> None:
        pass

    # ---- the server's side ----
    def latest(self) -> tuple[Frame | None, FrameResult | None, int]:
        with self._lock:
            return self._frame, self._result, self._frames

    def jpeg(self) -> bytes | None:
        """The newest frame with its overlays as JPEG, encoded at most MAX_FPS times a second."""
        with self._encode_lock:
            frame, result, _ = self.latest()
            if frame is None or result is None:
                return None
            now = time.monotonic()
            cached = self._jpeg
            if cached and (cached[0] == frame.index or now - cached[1] < 1.0 / MAX_FPS):
                return cached[2]
            image = self.draw(frame.image, result)
            ok, data = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])
            self._jpeg = (frame.index, now, data.tobytes())
            return self._jpeg[2]

    def draw(self, grey: np.ndarray, result: FrameResult) -> np.ndarray:
        """The frame in colour, scaled down, with the belt grid, the region and every part."""
        scale = min(1.0, MAX_WIDTH_PX / grey.shape[1])
        image = cv2.cvtColor(grey, cv2.COLOR_GRAY2BGR)
        if scale < 1.0:
            image = cv2.resize(image, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
        for line in self._grid:
            cv2.polylines(image, [np.round(line * scale).astype(np.int32)], False, GRID, 1, cv2.LINE_AA)
        if self.roi_px is not None:
            cv2.polylines(image, [np.round(np.asarray(self.roi_px) * scale).astype(np.int32)], True, ROI, 1)
        for rank, obj in enumerate(self._ordered(result), 1):
            colour = MEASURED if obj.measured else PREDICTED
            px = self._project(np.vstack([obj.corners_mm, [[obj.x_mm, obj.y_mm]]]), obj.height_mm) * scale
            if not np.all(np.isfinite(px)):
                continue
            cv2.polylines(image, [np.round(px[:4]).astype(np.int32)], True, colour, 2, cv2.LINE_AA)
            cx, cy = (int(round(v)) for v in px[4])
            cv2.circle(image, (cx, cy), 4, colour, -1)
            cv2.putText(image, f"#{obj.id} ({rank})", (cx + 6, cy - 6), cv2.FONT_HERSHEY_SIMPLEX, 0.5, colour, 1,
                        cv2.LINE_AA)
        return image

    def state_json(self) -> bytes:
        """``state()`` as JSON, built at most MAX_FPS times a second whatever the number of viewers."""
        with self._encode_lock:
            now = time.monotonic()
            if self._state is None or now - self._state[0] >= 1.0 / MAX_FPS:
                self._state = (now, json.dumps(self.state()).encode())
            return self._state[1]

    def state(self) -> dict:
        """Everything the page's tables show, as plain JSON types."""
        frame, result, frames = self.latest()
        h = self.health
        elapsed = max(time.monotonic() - self._started, 1e-9)
        out = {
            "frame": None if frame is None else frame.index,
            "frames": frames,
            "fps": round(frames / elapsed, 1),
            "health": {"running": h.running, "camera_ok": h.camera_ok, "recording_ok": h.recording_ok,
                       "fault": h.fault, "fault_text": FAULT_TEXT.get(h.fault, "?"), "overruns": h.overruns},
            "sinks": [s for s in (sink.status() for sink in self.sinks) if s],
            "plc": next((sink.live_state() for sink in self.sinks if hasattr(sink, "live_state")), None),
            "parts": [],
            "belt": None,
            "scene_fault": False,
        }
        if result is not None:
            out["belt"] = None if result.belt_mm_s is None else [round(v, 1) for v in result.belt_mm_s]
            out["scene_fault"] = result.scene_fault
            out["parts"] = [{k: v for k, v in o.to_dict().items() if k != "corners_mm"} for o in self._ordered(result)]
        return out

    def _ordered(self, result: FrameResult) -> list:
        with self._lock:  # PickOrder remembers the belt's direction: one caller at a time
            return self._order.order(result.objects)

    def _project(self, points_mm: np.ndarray, height_mm: float = 0.0) -> np.ndarray:
        c = self.calibration
        pts = np.asarray(points_mm, dtype=np.float64).reshape(-1, 2)
        # World Z points into the belt: a top face h mm high is the plane Z = -h.
        world = np.column_stack([pts, np.full(len(pts), -height_mm)])
        px, _ = cv2.projectPoints(world, c.belt_rvec, c.belt_tvec, c.camera_matrix, c.dist_coeffs)
        return px.reshape(-1, 2)

    def _grid_lines(self) -> list[np.ndarray]:
        """The belt's millimetre grid (every GRID_MM) over the view, as image polylines (full size)."""
        from tracker.undistort import BeltMapper  # noqa: PLC0415 - only for the grid's extent

        outline = BeltMapper(self.calibration).view_outline_mm()
        (x0, y0), (x1, y1) = outline.min(axis=0), outline.max(axis=0)
        lines = []
        for x in np.arange(np.floor(x0 / GRID_MM) * GRID_MM, x1 + GRID_MM, GRID_MM):
            lines.append(np.column_stack([np.full(50, x), np.linspace(y0, y1, 50)]))
        for y in np.arange(np.floor(y0 / GRID_MM) * GRID_MM, y1 + GRID_MM, GRID_MM):
            lines.append(np.column_stack([np.linspace(x0, x1, 50), np.full(50, y)]))
        w, h = self.calibration.size
        out = []
        for line in lines:
            px = self._project(line)
            inside = (px[:, 0] >= -w) & (px[:, 0] <= 2 * w) & (px[:, 1] >= -h) & (px[:, 1] <= 2 * h)
            if inside.sum() >= 2:
                out.append(px[inside])
        return out
