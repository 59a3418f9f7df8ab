"""Values <-> 16-bit holding registers, driven by the register map.

Inside a register the bytes are big-endian (Modbus). A 32-bit value spans two
registers: ``ABCD`` puts the high word first (the contract's default), ``CDAB``
the low word first (what many PLCs call "word swap").
"""

from __future__ import annotations

import math
import struct
from collections.abc import Mapping, Sequence
from enum import Enum

from plc.registers import (
    BLOCK_WORDS,
    ENTRY_MAP,
    ENTRY_START,
    ENTRY_WORDS,
    QUEUE_ENTRIES,
    QUEUE_HEADER,
    QUEUE_START,
    QUEUE_WORDS,
    REGISTER_MAP,
    Field,
    RegType,
)


class WordOrder(Enum):
    ABCD = "ABCD"
    CDAB = "CDAB"


def _split(raw: bytes, order: WordOrder) -> list[int]:
    hi, lo = struct.unpack(">HH", raw)
    return [hi, lo] if order is WordOrder.ABCD else [lo, hi]


def _join(words: Sequence[int], order: WordOrder) -> bytes:
    hi, lo = (words[0], words[1]) if order is WordOrder.ABCD else (words[1], words[0])
    return struct.pack(">HH", hi, lo)


def encode_u16(value: int) -> list[int]:
    if not 0 <= value <= 0xFFFF:
        raise ValueError(f"uint16: expected 0..65535, got {value}")
    return [value]


def encode_u32(value: int, order: WordOrder = WordOrder.ABCD) -> list[int]:
    if not 0 <= value <= 0xFFFFFFFF:
        raise ValueError(f"uint32: expected 0..4294967295, got {value}")
    return _split(struct.pack(">I", value), order)


def encode_f32(value: float, order: WordOrder = WordOrder.ABCD) -> list[int]:
    if not math.isfinite(value):
        raise ValueError(f"float32: expected a finite number, got {value}")
    return _split(struct.pack(">f", value), order)


def decode_u32(words: Sequence[int], order: WordOrder = WordOrder.ABCD) -> int:
    return struct.unpack(">I", _join(words, order))[0]


def decode_f32(words: Sequence[int], order: WordOrder = WordOrder.ABCD) -> float:
    return struct.unpack(">f", _join(words, order))[0]


def encode_fields(fields: Sequence[Field], values: Mapping[str, int | float | Sequence[float]],
                  order: WordOrder, what: str = "register block") -> list[int]:
    """Consecutive registers from a value per field name (a sequence for fields with count > 1)."""
    missing = [f.name for f in fields if f.name not in values]
    if missing:
        raise ValueError(f"{what}: missing values for {', '.join(missing)}")
    out: list[int] = []
    for f in fields:
        value = values[f.name]
        items = list(value) if f.count > 1 else [value]  # type: ignore[arg-type]
        if len(items) != f.count:
            raise ValueError(f"{what}: {f.name} expects {f.count} values, got {len(items)}")
        for item in items:
            if f.type is RegType.UINT16:
                out += encode_u16(int(item))
            elif f.type is RegType.UINT32:
                out += encode_u32(int(item), order)
            else:
                out += encode_f32(float(item), order)
    return out


def decode_fields(fields: Sequence[Field], words: Sequence[int], order: WordOrder,
                  first: int = 0) -> dict[str, int | float | list[float]]:
    """The inverse of ``encode_fields``; ``words[0]`` is register ``first``."""
    out: dict[str, int | float | list[float]] = {}
    for f in fields:
        vals = []
        for i in range(f.count):
            at = f.address - first + i * f.type.words
            if f.type is RegType.UINT16:
                vals.append(words[at])
            elif f.type is RegType.UINT32:
                vals.append(decode_u32(words[at:at + 2], order))
            else:
                vals.append(decode_f32(words[at:at + 2], order))
        out[f.name] = vals if f.count > 1 else vals[0]
    return out


def encode_block(values: Mapping[str, int | float | Sequence[float]], order: WordOrder) -> list[int]:
    """Registers 0..BLOCK_WORDS-1 from a value per field name (a sequence for fields with count > 1)."""
    return encode_fields(REGISTER_MAP, values, order)


def decode_block(words: Sequence[int], order: WordOrder) -> dict[str, int | float | list[float]]:
    """The inverse of ``encode_block`` (for the simulator's log and the tests)."""
    if len(words) < BLOCK_WORDS:
        raise ValueError(f"register block: expected {BLOCK_WORDS} registers, got {len(words)}")
    return decode_fields(REGISTER_MAP, words, order)


def encode_queue(header: Mapping[str, int], entries: Sequence[Mapping[str, int | float]],
                 order: WordOrder) -> list[int]:
    """Registers 100-219 (contract section 4b): the header, then QUEUE_ENTRIES entries, unused ones all zero."""
    if len(entries) > QUEUE_ENTRIES:
        raise ValueError(f"queue: expected at most {QUEUE_ENTRIES} entries, got {len(entries)}")
    out = encode_fields(QUEUE_HEADER, header, order, "queue")
    for entry in entries:
        out += encode_fields(ENTRY_MAP, entry, order, "queue entry")
    return out + [0] * (QUEUE_WORDS - len(out))


def decode_queue(words: Sequence[int], order: WordOrder) -> dict:
    """The inverse of ``encode_queue``: the header's fields and ``entries`` (the first queue_count of them)."""
    if len(words) < QUEUE_WORDS:
        raise ValueError(f"queue: expected {QUEUE_WORDS} registers, got {len(words)}")
    out = decode_fields(QUEUE_HEADER, words, order, QUEUE_START)
    at = ENTRY_START - QUEUE_START
    out["entries"] = [decode_fields(ENTRY_MAP, words[at + k * ENTRY_WORDS:at + (k + 1) * ENTRY_WORDS], order)
                      for k in range(min(int(out["queue_count"]), QUEUE_ENTRIES))]
    return out
