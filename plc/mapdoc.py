"""The register map as text: for ``tracker plc map`` (table or CSV) and the README (Markdown)."""

from __future__ import annotations

import csv
import io

from plc.registers import MANUAL_BASE, REGISTER_MAP, Field

FORMATS = ("text", "csv", "markdown")
CSV_HEADER = ("address", "last_address", "register", "last_register", "type", "count", "name", "unit", "meaning")


def _rows(base: int) -> list[tuple[Field, int, int]]:
    return [(f, base + f.address, base + f.last) for f in REGISTER_MAP]


def _span(first: int, last: int) -> str:
    return str(first) if first == last else f"{first}-{last}"


def render(fmt: str = "text", base: int = 0) -> str:
    if fmt == "csv":
        out = io.StringIO()
        w = csv.writer(out, lineterminator="\n")
        w.writerow(CSV_HEADER)
        for f, first, last in _rows(base):
            w.writerow((first, last, MANUAL_BASE + first, MANUAL_BASE + last, f.type.value, f.count, f.name,
                        f.unit, f.meaning))
        return out.getvalue()
    if fmt == "markdown":
        lines = ["| addr | register | type | name | unit | meaning |", "|---|---|---|---|---|---|"]
        for f, first, last in _rows(base):
            lines.append(f"| {_span(first, last)} | {_span(MANUAL_BASE + first, MANUAL_BASE + last)} | "
                         f"{f.type_text} | `{f.name}` | {f.unit} | {f.meaning} |")
        return "\n".join(lines) + "\n"
    if fmt != "text":
        raise ValueError(f"register map: expected a format in {FORMATS}, got {fmt!r}")
    table = [("addr", "register", "type", "name", "unit", "meaning")]
    table += [(_span(first, last), _span(MANUAL_BASE + first, MANUAL_BASE + last), f.type_text, f.name, f.unit,
               f.meaning) for f, first, last in _rows(base)]
    widths = [max(len(row[i]) for row in table) for i in range(5)]
    return "".join("  ".join(c.ljust(w) for c, w in zip(row[:5], widths, strict=True)) + "  " + row[5] + "\n"
                   for row in table)
