"""What the queue of contract section 4b lists, and in which order.

Pick order: the part first in line to leave the view comes first. Parts on a belt move together,
so "first to leave" is "furthest downstream": the position along the belt's direction of motion,
largest first. The direction is the mean velocity of the parts that move; it is remembered, so a
frame with only new (not yet moving) tracks keeps the order. Before anything has moved, the oldest
track (lowest id) comes first. Parts the PLC has taken are never listed again.
"""

from __future__ import annotations

import math
from collections.abc import Iterable

from plc.registers import FLAG_HEIGHT_NOT_CONVERGED, FLAG_NOT_PICKABLE
from tracker.poses import TrackedObject

U16_MAX = 0xFFFF


class PickOrder:
    def __init__(self, min_speed_mm_s: float) -> None:
        # Slower parts say nothing about the belt's direction (a new track's velocity starts at 0).
        self.min_speed_mm_s = min_speed_mm_s
        self.direction: tuple[float, float] | None = None

    def order(self, objects: Iterable[TrackedObject], taken: set[int] | frozenset[int] = frozenset()
              ) -> list[TrackedObject]:
        """The objects not taken, next to pick first."""
        listed = [o for o in objects if o.id not in taken]
        moving = [o for o in listed if math.hypot(o.vx_mm_s, o.vy_mm_s) >= self.min_speed_mm_s]
        if moving:
            vx = sum(o.vx_mm_s for o in moving) / len(moving)
            vy = sum(o.vy_mm_s for o in moving) / len(moving)
            speed = math.hypot(vx, vy)
            if speed >= self.min_speed_mm_s:
                self.direction = (vx / speed, vy / speed)
        if self.direction is None:
            return sorted(listed, key=lambda o: o.id)
        ux, uy = self.direction
        return sorted(listed, key=lambda o: (-(o.x_mm * ux + o.y_mm * uy), o.id))


def flags(obj: TrackedObject) -> int:
    return (FLAG_NOT_PICKABLE if not obj.pickable else 0) | (FLAG_HEIGHT_NOT_CONVERGED if not obj.height_converged
                                                               else 0)


def entry_fields(obj: TrackedObject) -> dict:
    """One queue entry: the pose stream's rounded values, so registers hold float32(<pose stream value>)."""
    d = obj.to_dict()
    return {"id": d["id"], "x_mm": d["x_mm"], "y_mm": d["y_mm"], "angle_deg": d["angle_deg"],
            "vx_mm_s": d["vx_mm_s"], "vy_mm_s": d["vy_mm_s"], "length_mm": d["length_mm"],
            "width_mm": d["width_mm"], "height_mm": d["height_mm"], "measured": int(d["measured"]),
            "age_frames": min(max(obj.age_frames, 0), U16_MAX), "flags": flags(obj), "reserved": 0}
