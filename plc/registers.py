"""The register map of contract section 4, defined once.

Everything else comes from ``REGISTER_MAP``: the encoder (``plc.encode``), the
``tracker plc map`` listing and the README table (a test checks they agree).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum


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
    Field(2, U16, "fault", "code", "0 none, 1 camera lost, 2 frame size differs from calibration, "
                                   "3 recording stopped, 4 overrun"),
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
)

FIELDS: dict[str, Field] = {f.name: f for f in REGISTER_MAP}
# Registers 0..BLOCK_WORDS-1 are written together in one write-multiple-registers request.
BLOCK_WORDS = REGISTER_MAP[-1].last + 1
# Registers 100-299 are reserved for a queue of several objects; a stand-in PLC holds at least these.
RESERVED_QUEUE = (100, 299)
SERVER_REGISTERS = RESERVED_QUEUE[1] + 1
# The largest base such that the block still fits in the 16-bit address space.
MAX_BASE = 0x10000 - BLOCK_WORDS


def _check_map() -> None:
    """The map is contiguous and non-overlapping: a mistake here must fail at import, not on the wire."""
    expected = 0
    for f in REGISTER_MAP:
        if f.address != expected:
            raise AssertionError(f"register map: {f.name} at {f.address}, expected {expected}")
        expected = f.last + 1


_check_map()
