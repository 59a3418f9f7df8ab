"""The register map of contract sections 4 and 4b, defined once.

Everything else comes from ``REGISTER_MAP`` (the block 0-44), ``QUEUE_HEADER`` and ``ENTRY_MAP``
(the queue 100-219) and ``TAKEN``: the encoder (``plc.encode``), the ``tracker plc map`` listing
and the README table (a test checks they agree with the contract).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum

from tracker.health import FAULT_TEXT


class RegType(Enum):
    UINT16 = "uint16"
    UINT32 = "uint32"
    FLOAT32 = "float32"

    @property
    def words(self) -> int:
        return 1 if self is RegType.UINT16 else 2


@dataclass(frozen=True)
class Field:
    """One value of the map: ``count`` consecutive values of ``type`` from ``address`` (0-based offset)."""

    address: int
    type: RegType
    name: str
    unit: str
    meaning: str
    count: int = 1

    def __post_init__(self) -> None:
        if self.address < 0 or self.count < 1:
            raise ValueError(f"register field {self.name}: expected address >= 0 and count >= 1, "
                             f"got {self.address}, {self.count}")

    @property
    def words(self) -> int:
        return self.type.words * self.count

    @property
    def last(self) -> int:
        return self.address + self.words - 1

    @property
    def addresses(self) -> str:
        return str(self.address) if self.words == 1 else f"{self.address}-{self.last}"

    @property
    def type_text(self) -> str:
        return self.type.value if self.count == 1 else f"{self.type.value} x {self.count}"


# Manual-style ("4x") number of holding register 0.
MANUAL_BASE = 40001

# Bits of the status word.
STATUS_RUNNING = 1 << 0
STATUS_CAMERA_OK = 1 << 1
STATUS_CALIBRATION_LOADED = 1 << 2
STATUS_PART_TRACKED = 1 << 3
STATUS_RECORDING_OK = 1 << 4
STATUS_FAULT = 1 << 15

U16, U32, F32 = RegType.UINT16, RegType.UINT32, RegType.FLOAT32

REGISTER_MAP: tuple[Field, ...] = (
    Field(0, U16, "heartbeat", "", "+1 (wrapping) at least every 100 ms while the tracker runs, with or without parts"),
    Field(1, U16, "status", "bits", "bit 0 running, 1 camera ok, 2 calibration loaded, 3 part tracked, "
                                    "4 recording ok, 15 fault"),
    Field(2, U16, "fault", "code", ", ".join(f"{code} {text}" for code, text in sorted(FAULT_TEXT.items()))),
    Field(3, U16, "count", "", "objects tracked in this frame"),
    Field(4, U32, "seq", "", "+1 for every pose written: the PLC's \"new data\" signal"),
    Field(6, U32, "t_capture_ms", "ms", "capture time of the frame the pose is from, ms on the tracker's "
                                        "monotonic clock (wraps at 2^32)"),
    Field(8, U32, "t_write_ms", "ms", "time the block was written, same clock (age = t_write_ms - t_capture_ms)"),
    Field(10, U32, "id", "", "track id of the reported object"),
    Field(12, F32, "x_mm", "mm", "centroid, world frame"),
    Field(14, F32, "y_mm", "mm", "centroid, world frame"),
    Field(16, F32, "angle_deg", "deg", "direction of the long side w.r.t. world +X, (-90, 90]"),
    Field(18, F32, "vx_mm_s", "mm/s", "velocity, world X"),
    Field(20, F32, "vy_mm_s", "mm/s", "velocity, world Y"),
    Field(22, F32, "length_mm", "mm", "long side of the footprint"),
    Field(24, F32, "width_mm", "mm", "short side of the footprint"),
    Field(26, F32, "corners_mm", "mm", "x0, y0, x1, y1, x2, y2, x3, y3 (order as in the pose stream)", count=8),
    Field(42, U16, "measured", "", "1 measured in this frame, 0 predicted"),
    Field(43, F32, "height_mm", "mm", "height of the top face used for this pose (pose stream height_mm)"),
)

# Section 4b: the queue of parts, written as one block of QUEUE_WORDS registers from QUEUE_START.
QUEUE_START = 100
QUEUE_ENTRIES = 5
ENTRY_WORDS = 22
QUEUE_HEADER: tuple[Field, ...] = (
    Field(100, U32, "queue_seq", "", "+1 for every queue write"),
    Field(102, U16, "queue_count", "", "valid entries below (0-5)"),
    Field(103, U16, "in_view", "", "parts tracked in this frame that the PLC has not taken (may exceed 5)"),
    Field(104, U32, "t_capture_ms", "ms", "capture time of the frame the queue is from (same clock as the block)"),
    Field(106, U32, "taken_echo", "", "the last taken_id the tracker has acted on (0 none)"),
    Field(108, U32, "t_write_ms", "ms", "time this queue was written"),
)
# One entry, at offsets from its start (entry k starts at ENTRY_START + ENTRY_WORDS * k).
ENTRY_START = QUEUE_HEADER[-1].last + 1
ENTRY_MAP: tuple[Field, ...] = (
    Field(0, U32, "id", "", "track id (the value to write to taken_id)"),
    Field(2, F32, "x_mm", "mm", "centroid, world frame"),
    Field(4, F32, "y_mm", "mm", "centroid, world frame"),
    Field(6, F32, "angle_deg", "deg", "direction of the long side w.r.t. world +X, (-90, 90]"),
    Field(8, F32, "vx_mm_s", "mm/s", "velocity, world X"),
    Field(10, F32, "vy_mm_s", "mm/s", "velocity, world Y"),
    Field(12, F32, "length_mm", "mm", "long side of the footprint"),
    Field(14, F32, "width_mm", "mm", "short side of the footprint"),
    Field(16, F32, "height_mm", "mm", "height of the top face used for this pose"),
    Field(18, U16, "measured", "", "1 measured in this frame, 0 predicted"),
    Field(19, U16, "age_frames", "frames", "frames since the part was last measured (saturating)"),
    Field(20, U16, "flags", "bits", "bit 0 not pickable (touching or overlapping another part), "
                                    "bit 1 height not yet converged; other bits 0"),
    Field(21, U16, "reserved", "", "0"),
)
FLAG_NOT_PICKABLE = 1 << 0
FLAG_HEIGHT_NOT_CONVERGED = 1 << 1
QUEUE_WORDS = ENTRY_START - QUEUE_START + QUEUE_ENTRIES * ENTRY_WORDS
# The PLC's register: the id of the part the arm committed to (the tracker echoes it in taken_echo).
TAKEN = Field(290, U32, "taken_id", "", "written by the PLC: the id of the part the arm has committed to; "
                                         "the tracker stops listing it and echoes it in taken_echo")

FIELDS: dict[str, Field] = {f.name: f for f in REGISTER_MAP}
ENTRY_FIELDS: dict[str, Field] = {f.name: f for f in ENTRY_MAP}
QUEUE_FIELDS: dict[str, Field] = {f.name: f for f in QUEUE_HEADER}
# Registers 0..BLOCK_WORDS-1 are written together in one write-multiple-registers request.
BLOCK_WORDS = REGISTER_MAP[-1].last + 1
# Registers 0-299 belong to the contract (220-289 and 292-299 reserved); a stand-in PLC holds all of them.
SERVER_REGISTERS = 300
# The largest base such that the whole map still fits in the 16-bit address space.
MAX_BASE = 0x10000 - SERVER_REGISTERS


def _check_map(fields: tuple[Field, ...], first: int, words: int) -> None:
    """The map is contiguous and non-overlapping: a mistake here must fail at import, not on the wire."""
    expected = first
    for f in fields:
        if f.address != expected:
            raise AssertionError(f"register map: {f.name} at {f.address}, expected {expected}")
        expected = f.last + 1
    if expected != first + words:
        raise AssertionError(f"register map: ends at {expected - 1}, expected {first + words - 1}")


_check_map(REGISTER_MAP, 0, 45)
_check_map(QUEUE_HEADER, QUEUE_START, 10)
_check_map(ENTRY_MAP, 0, ENTRY_WORDS)
