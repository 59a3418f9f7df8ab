"""``tracker calibrate board``: a printable sheet with the board at true scale and its settings on it.

The sheet is a PNG of the paper at the stated DPI with that DPI recorded in it (a pHYs chunk), so a
printer prints it at true size at 100 %. A square is a whole number of printer dots, so the printed
square may differ from the one asked for by up to half a dot: the sheet says what it measures, and
that is the size to give the calibration commands (after checking it with a ruler).
"""

from __future__ import annotations

import struct
import zlib
from dataclasses import dataclass

import cv2
import numpy as np

from tracker.calibrate.board import Pattern
from tracker.calibrate.charuco import CharucoSpec
from tracker.errors import BadInput

PAPERS_MM = {"A4": (210.0, 297.0), "A3": (297.0, 420.0), "letter": (215.9, 279.4)}
# Unprintable border of most printers, and the room the text lines need (mm).
_MARGIN_MM = 8.0
_TEXT_MM = 24.0


@dataclass(frozen=True)
class Sheet:
    image: np.ndarray  # 8-bit grey, the whole paper
    dpi: int
    square_mm: float  # as printed: a whole number of dots
    lines: tuple[str, ...]


def make_sheet(board: Pattern | CharucoSpec, dpi: int, paper: str) -> Sheet:
    if not 72 <= dpi <= 1200:
        raise BadInput(f"--dpi: expected 72 to 1200, got {dpi}")
    if paper not in PAPERS_MM:
        raise BadInput(f"--paper: expected one of {', '.join(PAPERS_MM)}, got {paper!r}")
    dots_per_mm = dpi / 25.4
    square_px = round(board.square_mm * dots_per_mm)
    cols, rows = _squares(board)
    board_px = _board_image(board, square_px)
    paper_w, paper_h = PAPERS_MM[paper]
    # Turn the paper when the board fits it better lying down.
    if (cols > rows) != (paper_w > paper_h):
        paper_w, paper_h = paper_h, paper_w
    need_w = cols * square_px / dots_per_mm + 2 * _MARGIN_MM
    need_h = rows * square_px / dots_per_mm + 2 * _MARGIN_MM + _TEXT_MM
    if need_w > paper_w or need_h > paper_h:
        given = (f"--board {board}" if isinstance(board, CharucoSpec)
                 else f"--pattern {board} --square {board.square_mm:g}")
        raise BadInput(f"{given}: needs {need_w:.0f} x {need_h:.0f} mm with margins and text, "
                       f"{paper} is {paper_w:g} x {paper_h:g} mm: use smaller squares or a larger paper")
    sheet = np.full((round(paper_h * dots_per_mm), round(paper_w * dots_per_mm)), 255, dtype=np.uint8)
    top = round(_MARGIN_MM * dots_per_mm)
    left = (sheet.shape[1] - board_px.shape[1]) // 2
    sheet[top:top + board_px.shape[0], left:left + board_px.shape[1]] = board_px
    printed = square_px / dots_per_mm
    lines = (f"tracker calibrate board: {_spec_text(board)}",
             f"{paper} at {dpi} dpi: print at 100 % (no 'fit to page').",
             f"One square measures {printed:.3f} mm: check it with a ruler and give what you measure",
             "to the calibration commands. Glue the sheet flat to something stiff.")
    y = top + board_px.shape[0] + round(6 * dots_per_mm)
    scale = dots_per_mm * 0.12  # text about 3 mm high
    for line in lines:
        cv2.putText(sheet, line, (left, y), cv2.FONT_HERSHEY_SIMPLEX, scale, 0, max(1, round(scale * 2)),
                    cv2.LINE_AA)
        y += round(4.5 * dots_per_mm)
    return Sheet(sheet, dpi, printed, lines)


def png_bytes(sheet: Sheet) -> bytes:
    """The sheet as PNG, with its DPI recorded (pHYs, dots per metre) right after the header chunk."""
    ok, data = cv2.imencode(".png", sheet.image)
    if not ok:
        raise BadInput("board: cannot encode the sheet as PNG")
    data = data.tobytes()
    per_metre = round(sheet.dpi / 0.0254)
    body = b"pHYs" + struct.pack(">IIB", per_metre, per_metre, 1)
    chunk = struct.pack(">I", 9) + body + struct.pack(">I", zlib.crc32(body) & 0xFFFFFFFF)
    end_of_header = 8 + 8 + 13 + 4  # signature, IHDR length+type, IHDR data, CRC
    return data[:end_of_header] + chunk + data[end_of_header:]


def _squares(board: Pattern | CharucoSpec) -> tuple[int, int]:
    if isinstance(board, CharucoSpec):
        return board.squares_x, board.squares_y
    return board.cols + 1, board.rows + 1


def _board_image(board: Pattern | CharucoSpec, square_px: int) -> np.ndarray:
    cols, rows = _squares(board)
    if isinstance(board, CharucoSpec):
        return board.board().generateImage((cols * square_px, rows * square_px), marginSize=0, borderBits=1)
    # Square (0, 0) black, as the chessboard renderer and detect()'s canonical order assume.
    black = (np.add.outer(np.arange(rows), np.arange(cols)) % 2 == 0)
    return np.where(np.kron(black, np.ones((square_px, square_px), dtype=bool)), 0, 255).astype(np.uint8)


def _spec_text(board: Pattern | CharucoSpec) -> str:
    if isinstance(board, CharucoSpec):
        return f"--board {board}"
    return f"--pattern {board} --square {board.square_mm:g} (chessboard, inner corners)"
