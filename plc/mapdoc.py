"""The register map as text: for ``tracker plc map`` (table or CSV) and the README (Markdown).

One table: the block (0-44), the queue header (100-109), the fields of queue entry k (110 + 22k,
k = 0..4; the CSV lists all five entries with their own addresses, for tag import) and the PLC's
own ``taken_id`` (290-291).
"""

from __future__ import annotations

import csv
import io
from dataclasses import dataclass

from plc.registers import (
    ENTRY_MAP,
    ENTRY_START,
    ENTRY_WORDS,
    MANUAL_BASE,
    QUEUE_ENTRIES,
    QUEUE_HEADER,
    REGISTER_MAP,
    TAKEN,
    Field,
)

FORMATS = ("text", "csv", "markdown")
CSV_HEADER = ("address", "last_address", "register", "last_register", "type", "count", "name", "unit", "meaning")


@dataclass(frozen=True)
class Row:
    field: Field
    first: int
    name: str
    stride: str = ""  # "+ 22k" for the entry fields of the tables

    @property
    def last(self) -> int:
        return self.first + self.field.words - 1


def _rows(base: int, every_entry: bool) -> list[Row]:
    rows = [Row(f, base + f.address, f.name) for f in REGISTER_MAP + QUEUE_HEADER]
    for k in range(QUEUE_ENTRIES if every_entry else 1):
        at = base + ENTRY_START + ENTRY_WORDS * k
        rows += [Row(f, at + f.address, f"entry{k if every_entry else '[k]'}.{f.name}",
                     "" if every_entry else f" + {ENTRY_WORDS}k") for f in ENTRY_MAP]
    return rows + [Row(TAKEN, base + TAKEN.address, TAKEN.name)]


def _span(first: int, last: int, stride: str = "") -> str:
    return (str(first) if first == last else f"{first}-{last}") + stride


def render(fmt: str = "text", base: int = 0) -> str:
    if fmt == "csv":
        out = io.StringIO()
        w = csv.writer(out, lineterminator="\n")
        w.writerow(CSV_HEADER)
        for r in _rows(base, every_entry=True):
            f = r.field
            w.writerow((r.first, r.last, MANUAL_BASE + r.first, MANUAL_BASE + r.last, f.type.value, f.count, r.name,
                        f.unit, f.meaning))
        return out.getvalue()
    rows = _rows(base, every_entry=False)
    cells = [(_span(r.first, r.last, r.stride), _span(MANUAL_BASE + r.first, MANUAL_BASE + r.last, r.stride),
              r.field.type_text, r.name, r.field.unit, r.field.meaning) for r in rows]
    if fmt == "markdown":
        lines = ["| addr | register | type | name | unit | meaning |", "|---|---|---|---|---|---|"]
        lines += [f"| {a} | {reg} | {t} | `{n}` | {u} | {m} |" for a, reg, t, n, u, m in cells]
        return "\n".join(lines) + "\n"
    if fmt != "text":
        raise ValueError(f"register map: expected a format in {FORMATS}, got {fmt!r}")
    table = [("addr", "register", "type", "name", "unit", "meaning"), *cells]
    widths = [max(len(row[i]) for row in table) for i in range(5)]
    return "".join("  ".join(c.ljust(w) for c, w in zip(row[:5], widths, strict=True)) + "  " + row[5] + "\n"
                   for row in table)
