"""The product's exception hierarchy.

Expected failures (bad input, a dead camera, an unwritable path) are raised as a
``TrackerError`` subclass carrying the CLI exit code; the CLI prints their
message as one line, without a traceback.
"""

from __future__ import annotations


class TrackerError(Exception):
    """Base of every expected failure. ``exit_code`` is what the CLI returns."""

    exit_code = 1


class BadInput(TrackerError):
    """The user gave us something we cannot use (contract: exit code 2)."""

    exit_code = 2


class CalibrationError(BadInput):
    """A calibration file is missing, malformed or inconsistent."""


class SourceError(BadInput):
    """A frame source cannot be opened, or delivered a frame we cannot use."""


class FrameSizeError(SourceError):
    """A frame's size differs from the calibration's."""


class SourceLost(TrackerError):
    """A live source (camera) stopped delivering frames mid-run."""


class StoppedMidRun(TrackerError):
    """Bad input (a frame that cannot be read, or of another size) met after frames were processed:
    the outputs hold those frames, so it is no longer "bad input, nothing written" (exit 1, as a
    camera lost mid-run)."""


class RecordingError(TrackerError):
    """A recording cannot be written or read."""
