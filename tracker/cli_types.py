"""Argument types for the command line: numbers checked for range and finiteness where they are
parsed, so a bad value is one line naming the option, never an error deep in the run."""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable


def number(low: float, high: float, integer: bool = False) -> Callable[[str], float | int]:
    """A parser for a finite number in [low, high] (an integer when ``integer``)."""
    kind = "an integer" if integer else "a number"
    bounds = f"from {low:g} to {high:g}" if high < 2**31 else f">= {low:g}"

    def parse(text: str) -> float | int:
        try:
            value = int(text) if integer else float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {kind} {bounds}, got {text!r}") from None
        if not (math.isfinite(value) and low <= value <= high):
            raise argparse.ArgumentTypeError(f"expected {kind} {bounds}, got {text}")
        return value

    parse.__name__ = "integer" if integer else "number"
    return parse


# Frame rates a file's timestamps may be given in: below 0.01 fps (a frame every 100 s) or above
# 100,000 fps no camera delivers, and the timestamps would overflow or collapse to 0.
FPS = number(0.01, 100_000.0)
FRAME_COUNT = number(1, 2**62, integer=True)
# Camera indices OpenCV accepts (a larger number is a typo, not a device).
CAMERA_INDEX_MAX = 1023


def endpoint(text: str) -> str:
    """HOST:PORT, not empty (the full check, with the PLC's own messages, is plc.options.parse_endpoint):
    an empty --plc must not silently mean "no PLC"."""
    if not text.strip():
        raise argparse.ArgumentTypeError(f"expected HOST:PORT (e.g. 192.168.0.10:502), got {text!r}")
    return text


def part_height(text: str) -> float | str:
    """``--part-height``: a height in mm (0 to 5000), or ``"auto"``."""
    if text.strip().lower() == "auto":
        return "auto"
    try:
        return float(number(0.0, 5000.0)(text))
    except argparse.ArgumentTypeError:
        raise argparse.ArgumentTypeError(f"expected a height in mm from 0 to 5000 or 'auto', got {text!r}") from None
