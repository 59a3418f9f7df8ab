"""What ``calibrate capture --web`` shows: the newest frame with the board's corners (green when the
view was kept, orange otherwise), the coverage grid with the cells reached tinted, and the progress,
in the shape the live view's page reads (tracker/web: ``jpeg()`` and ``state_json()``)."""

from __future__ import annotations

import json
import threading
import time

import cv2
import numpy as np

from tracker.calibrate.capture import CaptureSettings, Progress

KEPT = (80, 200, 80)
REFUSED = (0, 160, 255)
REACHED = (60, 120, 60)
MAX_WIDTH_PX = 960


class CaptureView:
    def __init__(self, settings: CaptureSettings) -> None:
        self.settings = settings
        self._lock = threading.Lock()
        self._latest: tuple[int, np.ndarray, np.ndarray | None, Progress, np.ndarray] | None = None
        self._started = time.monotonic()

    # ---- the capture loop's side: only a reference is stored ----
    def submit(self, index: int, image: np.ndarray, corners: np.ndarray | None, progress: Progress,
               cells: np.ndarray) -> None:
        snapshot = Progress(progress.frames, progress.kept, progress.cells, progress.tilt_directions,
                            dict(progress.rejected), progress.last)
        with self._lock:
            self._latest = (index, image, corners, snapshot, cells.copy())

    # ---- the server's side ----
    def jpeg(self) -> bytes | None:
        with self._lock:
            latest = self._latest
        if latest is None:
            return None
        _, image, corners, progress, cells = latest
        scale = min(1.0, MAX_WIDTH_PX / image.shape[1])
        colour = cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)
        h, w = image.shape[:2]
        n = cells.shape[0]
        tint = colour.copy()
        for r, c in zip(*np.nonzero(cells), strict=True):
            cv2.rectangle(tint, (c * w // n, r * h // n), ((c + 1) * w // n - 1, (r + 1) * h // n - 1), REACHED, -1)
        colour = cv2.addWeighted(colour, 0.7, tint, 0.3, 0)
        for k in range(1, n):
            cv2.line(colour, (k * w // n, 0), (k * w // n, h - 1), REACHED, 1)
            cv2.line(colour, (0, k * h // n), (w - 1, k * h // n), REACHED, 1)
        if corners is not None:
            mark = KEPT if progress.last == "kept" else REFUSED
            for x, y in corners:
                cv2.circle(colour, (int(round(x)), int(round(y))), 3, mark, -1, cv2.LINE_AA)
        if scale < 1.0:
            colour = cv2.resize(colour, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
        ok, data = cv2.imencode(".jpg", colour, [cv2.IMWRITE_JPEG_QUALITY, 80])
        return data.tobytes() if ok else None

    def state_json(self) -> bytes:
        return json.dumps(self.state()).encode()

    def state(self) -> dict:
        """The live view page's fields (parts, PLC and belt empty) plus ``capture``: the progress."""
        with self._lock:
            latest = self._latest
        s = self.settings
        frame = None if latest is None else latest[0]
        p = Progress() if latest is None else latest[3]
        line = (f"capture: {p.kept}/{s.target_views} views, coverage {p.cells}/{s.coverage_cells ** 2} cells, "
                f"tilted {p.tilt_directions}/4 directions; last: {p.last or '-'}")
        return {
            "frame": frame, "frames": p.frames,
            "fps": round(p.frames / max(time.monotonic() - self._started, 1e-9), 1),
            "health": {"running": True, "camera_ok": True, "recording_ok": False, "fault": 0,
                       "fault_text": "none", "overruns": 0},
            "sinks": [line], "plc": None, "parts": [], "belt": None, "scene_fault": False,
            "capture": {"views": p.kept, "target_views": s.target_views, "cells": p.cells,
                        "min_cells": s.min_cells, "tilt_directions": p.tilt_directions,
                        "min_tilt_directions": s.min_tilt_directions, "last": p.last,
                        "refused": p.rejected},
        }
