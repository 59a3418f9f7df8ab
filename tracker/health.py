"""Health: the shared vocabulary of the status word, the fault word and the status line.

The loop writes it, every sink reads or writes it; it imports nothing of theirs, so
anything may import it (contract section 4: status bits and fault codes).
"""

from __future__ import annotations

from dataclasses import dataclass

# Fault codes of the PLC's fault word (contract section 4).
FAULT_NONE = 0
FAULT_CAMERA_LOST = 1
FAULT_FRAME_SIZE = 2
FAULT_RECORDING = 3
FAULT_OVERRUN = 4
FAULT_SCENE = 5  # foreground covers most of the region of interest
FAULT_POSES = 6  # the pose output stopped (disk full, device failed)

FAULT_TEXT = {
    FAULT_NONE: "none",
    FAULT_CAMERA_LOST: "camera lost",
    FAULT_FRAME_SIZE: "frame size differs from calibration",
    FAULT_RECORDING: "recording stopped",
    FAULT_OVERRUN: "overrun",
    FAULT_SCENE: "scene not understood (foreground covers most of the region of interest)",
    FAULT_POSES: "pose output stopped",
}


@dataclass
class Health:
    """What the status word and the status line report; written by the loop and the sinks."""

    running: bool = True
    camera_ok: bool = True
    calibration_loaded: bool = True
    part_tracked: bool = False
    recording_ok: bool = True
    fault: int = FAULT_NONE
    overruns: int = 0

    def set_fault(self, code: int) -> None:
        # The most serious (lowest non-zero) fault wins.
        if self.fault == FAULT_NONE or code < self.fault:
            self.fault = code

    def clear_fault(self, code: int) -> None:
        """A condition that passes (a scene understood again) clears its own fault, no other."""
        if self.fault == code:
            self.fault = FAULT_NONE
