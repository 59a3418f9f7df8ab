"""What goes into registers 0-44: the reported object, the counters and the status word.

Which object is reported when several are tracked: the first entry of the queue (``plc.queue``,
contract section 4b), i.e. the next part to pick; the writer passes it in.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from plc.encode import WordOrder, encode_block
from plc.registers import (
    STATUS_CALIBRATION_LOADED,
    STATUS_CAMERA_OK,
    STATUS_FAULT,
    STATUS_PART_TRACKED,
    STATUS_RECORDING_OK,
    STATUS_RUNNING,
)
from tracker.health import FAULT_NONE, Health
from tracker.poses import TrackedObject

U16_MASK = 0xFFFF
U32_MASK = 0xFFFFFFFF
NS_PER_MS = 1_000_000

# Object fields before the first pose (the PLC sees zeros and seq 0).
_NO_OBJECT: dict = {"id": 0, "x_mm": 0.0, "y_mm": 0.0, "angle_deg": 0.0, "vx_mm_s": 0.0, "vy_mm_s": 0.0,
                    "length_mm": 0.0, "width_mm": 0.0, "corners_mm": [0.0] * 8, "measured": 0,
                    "height_mm": 0.0}


def ms_u32(monotonic_ns: int) -> int:
    """Milliseconds on the tracker's monotonic clock, as the PLC sees them (uint32, wraps after ~49.7 days)."""
    return (monotonic_ns // NS_PER_MS) & U32_MASK


@dataclass(frozen=True)
class Pose:
    """One processed frame as the writer needs it: objects and the capture time (ms, uint32)."""

    t_capture_ms: int
    objects: tuple[TrackedObject, ...]
    # Full-resolution monotonic arrival time, for the capture-to-register latency figures.
    arrival_ns: int = 0

    def __post_init__(self) -> None:
        if not 0 <= self.t_capture_ms <= U32_MASK:
            raise ValueError(f"Pose: t_capture_ms must be a uint32, got {self.t_capture_ms}")


def object_fields(obj: TrackedObject) -> dict:
    # The pose stream's rounded values, so the registers hold exactly float32(<pose stream value>).
    d = obj.to_dict()
    return {"id": d["id"], "x_mm": d["x_mm"], "y_mm": d["y_mm"], "angle_deg": d["angle_deg"],
            "vx_mm_s": d["vx_mm_s"], "vy_mm_s": d["vy_mm_s"], "length_mm": d["length_mm"],
            "width_mm": d["width_mm"], "corners_mm": [v for xy in d["corners_mm"] for v in xy],
            "measured": int(d["measured"]), "height_mm": d["height_mm"]}


def status_word(health: Health, running: bool, part_tracked: bool) -> int:
    word = 0
    for bit, on in ((STATUS_RUNNING, running), (STATUS_CAMERA_OK, health.camera_ok),
                    (STATUS_CALIBRATION_LOADED, health.calibration_loaded), (STATUS_PART_TRACKED, part_tracked),
                    (STATUS_RECORDING_OK, health.recording_ok), (STATUS_FAULT, health.fault != FAULT_NONE)):
        if on:
            word |= bit
    return word


@dataclass(frozen=True)
class BlockState:
    heartbeat: int = 0
    seq: int = 0
    count: int = 0  # objects tracked in the frame; 0 when the queue is empty (contract section 4)
    t_capture_ms: int = 0
    obj: dict = field(default_factory=lambda: dict(_NO_OBJECT))


@dataclass(frozen=True)
class Prepared:
    """A block ready to write, and the state it becomes once the PLC has accepted it."""

    registers: list[int]
    values: dict
    state: BlockState
    new_pose: bool


class BlockBuilder:
    """Keeps heartbeat, seq and the last object; state advances only when a write succeeded
    (``commit``), so seq counts poses the PLC actually received."""

    def __init__(self, order: WordOrder) -> None:
        self.order = order
        self.state = BlockState()

    def prepare(self, pose: Pose | None, health: Health, running: bool, t_write_ms: int,
                first: TrackedObject | None = None) -> Prepared:
        """``pose`` None: a heartbeat-only write (same object fields, same seq). ``first``: the object to
        report (the queue's first entry), None when the queue is empty (object fields and seq kept)."""
        s = self.state
        seq, count, t_capture_ms, obj = s.seq, s.count, s.t_capture_ms, s.obj
        new_pose = False
        if pose is not None:
            # "When the queue is empty, count is 0" (all parts taken, or none in view).
            count = len(pose.objects) if first is not None else 0
            if first is not None:
                seq = (seq + 1) & U32_MASK
                t_capture_ms = pose.t_capture_ms
                obj = object_fields(first)
                new_pose = True
        state = BlockState((s.heartbeat + 1) & U16_MASK, seq, count, t_capture_ms, obj)
        values = {"heartbeat": state.heartbeat, "status": status_word(health, running, count > 0),
                  "fault": health.fault, "count": min(count, U16_MASK), "seq": seq,
                  "t_capture_ms": t_capture_ms, "t_write_ms": t_write_ms & U32_MASK} | obj
        return Prepared(encode_block(values, self.order), values, state, new_pose)

    def commit(self, prepared: Prepared) -> None:
        self.state = prepared.state
