"""What the pipeline produces per frame, and the pose stream of contract section 2."""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field

import numpy as np

from tracker.measure import Measurement

# Decimals written to the pose stream: 0.1 um and 1e-4 deg are far below what is measurable.
_MM_DECIMALS = 4
_T_DECIMALS = 9


@dataclass(frozen=True)
class TrackedObject:
    id: int
    x_mm: float
    y_mm: float
    angle_deg: float
    length_mm: float
    width_mm: float
    corners_mm: np.ndarray  # 4x2, counter-clockwise (positive signed area)
    vx_mm_s: float
    vy_mm_s: float
    measured: bool
    # The raw measurement of this frame before filtering (None when predicted).
    raw: Measurement | None = field(default=None, compare=False)
    # Height of the top face above the belt that the pose was computed with (contract section 2).
    height_mm: float = 0.0
    # False while the tracker's own height estimate is still settling (PLC queue flag bit 1).
    height_converged: bool = True
    # False when the part touches or overlaps another, so its pose is not safe to pick (queue flag bit 0).
    pickable: bool = True
    # Frames since the part was last measured (0 when measured in this frame).
    age_frames: int = 0

    def to_dict(self) -> dict:
        r = _MM_DECIMALS
        return {
            "id": self.id,
            "x_mm": round(self.x_mm, r), "y_mm": round(self.y_mm, r),
            "angle_deg": _round_angle(self.angle_deg),
            "length_mm": round(self.length_mm, r), "width_mm": round(self.width_mm, r),
            "corners_mm": [[round(float(x), r), round(float(y), r)] for x, y in self.corners_mm],
            "vx_mm_s": round(self.vx_mm_s, r), "vy_mm_s": round(self.vy_mm_s, r),
            "height_mm": round(self.height_mm, r), "measured": self.measured,
            "pickable": self.pickable, "height_converged": self.height_converged,
        }


def _round_angle(angle_deg: float) -> float:
    """Rounded, still in (-90, 90]: -89.99996 must not become -90."""
    a = round(angle_deg, _MM_DECIMALS)
    return 90.0 if a <= -90.0 else a


@dataclass(frozen=True)
class FrameResult:
    frame: int
    t_ns: int
    objects: tuple[TrackedObject, ...]
    measurements: tuple[Measurement, ...] = ()
    # The belt's velocity (mm/s, world frame) measured from the images; None where not measured.
    belt_mm_s: tuple[float, float] | None = None
    # The foreground covered most of the region of interest: nothing was measured (fault 5).
    scene_fault: bool = False

    def to_dict(self) -> dict:
        out = {"frame": self.frame, "t": round(self.t_ns / 1e9, _T_DECIMALS),
               "objects": [o.to_dict() for o in self.objects]}
        if self.belt_mm_s is not None:
            vx, vy = self.belt_mm_s
            out["belt"] = {"vx_mm_s": round(vx, _MM_DECIMALS), "vy_mm_s": round(vy, _MM_DECIMALS)}
        return out

    def to_json_line(self) -> str:
        return json.dumps(self.to_dict(), allow_nan=False, separators=(", ", ": ")) + "\n"


class PoseLineError(ValueError):
    """A line of a pose file that is not JSON; ``line``: its number in the file (from 1)."""

    def __init__(self, line: int, why: str) -> None:
        super().__init__(f"line {line}: not JSON ({why})")
        self.line = line


def read_poses(path: str | os.PathLike) -> list[dict]:
    """Each line of a JSON Lines file (blank lines skipped); PoseLineError names the file's line."""
    frames = []
    with open(path, encoding="utf-8") as f:
        for n, line in enumerate(f, 1):
            if line.strip():
                try:
                    frames.append(json.loads(line))
                except json.JSONDecodeError as exc:
                    raise PoseLineError(n, exc.msg) from None
    return frames
