"""A printable board: the board at its true size on a page, its parameters and a scale bar in the margin.

The square is a whole number of printer dots (``dpi``), so the printed square may differ from the asked
size by up to half a dot; :func:`render_page` returns the board as actually drawn, and that is what the
margin text and ``board.yaml`` state. PNG files carry the DPI (pHYs), PDF pages have the paper's size, so
"print at 100 %" gives the stated size.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np

from pipeline.errors import InputError

from .board import Board

log = logging.getLogger("orca.calibration")

Paper = Literal["a4", "letter", "fit"]
PAPER_MM: dict[str, tuple[float, float]] = {"a4": (210.0, 297.0), "letter": (215.9, 279.4)}
MARGIN_MM = 12.0  # most printers cannot print the outer ~5 mm; a chessboard also needs a white border
TEXT_MM = 2.6  # text height


@dataclass(frozen=True)
class Page:
    image: np.ndarray  # (H, W) uint8, white page with the board and the margin text
    board: Board  # the board as drawn (square size rounded to whole dots)
    dpi: int
    origin_px: tuple[int, int]  # (x, y) of the board's top-left outer corner on the page, pixel edges
    square_px: int


def _mm_to_px(mm: float, dpi: int) -> int:
    return int(round(mm / 25.4 * dpi))


def board_image(board: Board, square_px: int) -> np.ndarray:
    """The board alone, (squares_y * square_px, squares_x * square_px) uint8, exactly one square per
    ``square_px`` pixels; inverted boards (``inverted: true``) drawn white-on-black."""

    w, h = board.squares_x * square_px, board.squares_y * square_px
    if board.kind == "chessboard":
        cells = (np.add.outer(np.arange(board.squares_y), np.arange(board.squares_x)) % 2).astype(np.uint8) * 255
        return np.kron(cells, np.ones((square_px, square_px), np.uint8))  # top-left square black
    img = board.charuco_board().generateImage((w, h), marginSize=0, borderBits=1)
    return 255 - img if board.inverted is True else img


def render_page(board: Board, *, dpi: int = 300, paper: Paper = "a4") -> Page:
    """Lay out ``board`` on a page (portrait or landscape, whichever fits) with its description below."""

    square_px = _mm_to_px(board.square_size * 1000, dpi)
    if square_px < 20:
        raise InputError(
            f"{board.square_size * 1000:.1f} mm squares are only {square_px} dots at {dpi} DPI",
            fix="raise --dpi or the square size",
        )
    drawn_square = square_px / dpi * 0.0254
    update: dict[str, object] = {"square_size": drawn_square}
    if board.kind == "charuco":
        update["marker_size"] = board.marker_length / board.square_size * drawn_square
        update["inverted"] = board.inverted is True  # 'auto' prints the ordinary board
    drawn = board.model_copy(update=update)
    if abs(drawn_square / board.square_size - 1) > 1e-3:
        log.warning("at %d DPI a square is %d dots = %.3f mm (asked %.3f mm)", dpi, square_px,
                    drawn_square * 1000, board.square_size * 1000)

    art = board_image(drawn, square_px)
    bh, bw = art.shape
    margin = _mm_to_px(MARGIN_MM, dpi)
    font_scale = _mm_to_px(TEXT_MM, dpi) / 22.0  # Hershey simplex capitals are ~22 px tall at scale 1
    thickness = max(1, int(round(font_scale * 1.5)))

    def layout(page_w: int) -> list[str]:
        return _wrap(_caption(drawn, dpi), page_w - 2 * margin, font_scale, thickness)

    if paper == "fit":
        page_w = bw + 2 * margin
        lines = layout(page_w)
        page_h = bh + 2 * margin + _text_block_px(len(lines), font_scale, dpi)
    else:
        pw, ph = (_mm_to_px(v, dpi) for v in PAPER_MM[paper])
        for page_w, page_h in ((pw, ph), (ph, pw)):  # portrait first
            lines = layout(page_w)
            if bw + 2 * margin <= page_w and bh + 2 * margin + _text_block_px(len(lines), font_scale, dpi) <= page_h:
                break
        else:
            need = f"{(bw + 2 * margin) / dpi * 25.4:.0f} x {(bh + 2 * margin) / dpi * 25.4:.0f} mm"
            raise InputError(
                f"the board with its margins ({need} plus text) does not fit on {paper.upper()} paper",
                fix="use smaller squares (--square-size), fewer squares, or --paper fit (and a large-format printer)",
            )
    page = np.full((page_h, page_w), 255, np.uint8)
    x0, y0 = (page_w - bw) // 2, margin
    page[y0 : y0 + bh, x0 : x0 + bw] = art
    _draw_caption(page, lines, y0 + bh, margin, font_scale, thickness, dpi)
    return Page(page, drawn, dpi, (x0, y0), square_px)


def _caption(board: Board, dpi: int) -> list[str]:
    """Paragraphs for the margin: what the board is, how to print it, how to use it."""
    flags = f"--board {board.kind} --squares-x {board.squares_x} --squares-y {board.squares_y} " \
        f"--square-size {board.square_size * 1000:.2f}mm"
    if board.kind == "charuco":
        flags += f" --marker-size {board.marker_length * 1000:.2f}mm --dictionary {board.dictionary}"
        flags += f" --inverted {'yes' if board.inverted is True else 'no'}"
        if board.legacy_pattern:
            flags += " --legacy-pattern"
    return [
        f"ORCa calibration board: {board.describe()}.",
        (
            f"Print at 100 % / actual size (not 'fit to page'), {dpi} DPI. The bar is 100 mm: measure it, and "
            "measure a square; keep the board flat (glue it to card or glass)."
        ),
        f"Calibrate: orca calibrate PHOTOS --out FOLDER {flags}",
    ]


def _wrap(paragraphs: list[str], width_px: int, font_scale: float, thickness: int) -> list[str]:
    import cv2

    lines: list[str] = []
    for para in paragraphs:
        line = ""
        for word in para.split(" "):
            trial = f"{line} {word}".strip()
            if line and cv2.getTextSize(trial, cv2.FONT_HERSHEY_SIMPLEX, font_scale, thickness)[0][0] > width_px:
                lines.append(line)
                line = word
            else:
                line = trial
        lines.append(line)
    return lines


def _line_px(font_scale: float) -> int:
    return int(round(22 * font_scale * 1.8))


def _text_block_px(n_lines: int, font_scale: float, dpi: int) -> int:
    bar = _mm_to_px(8, dpi)  # scale bar with ticks and its gap
    return _mm_to_px(4, dpi) + n_lines * _line_px(font_scale) + bar


def _draw_caption(
    page: np.ndarray, lines: list[str], top: int, margin: int, font_scale: float, thickness: int, dpi: int
) -> None:
    import cv2

    y = top + _mm_to_px(4, dpi)
    for line in lines:
        y += _line_px(font_scale)
        cv2.putText(page, line, (margin, y), cv2.FONT_HERSHEY_SIMPLEX, font_scale, 0, thickness, cv2.LINE_AA)
    # 100 mm scale bar with a tick every 10 mm (shortened to 50 mm on narrow pages)
    length_mm = 100 if _mm_to_px(100, dpi) <= page.shape[1] - 2 * margin else 50
    y += _mm_to_px(5, dpi)
    x0, x1 = margin, margin + _mm_to_px(length_mm, dpi)
    line_w = max(1, _mm_to_px(0.3, dpi))
    cv2.line(page, (x0, y), (x1, y), 0, line_w)
    for k in range(0, length_mm + 1, 10):
        x = margin + _mm_to_px(k, dpi)
        tick = _mm_to_px(2.5 if k % 50 == 0 else 1.5, dpi)
        cv2.line(page, (x, y - tick), (x, y), 0, line_w)
    label_at = (x1 + _mm_to_px(2, dpi), y)
    cv2.putText(page, f"{length_mm} mm", label_at, cv2.FONT_HERSHEY_SIMPLEX, font_scale, 0, thickness, cv2.LINE_AA)


def write_page(path: str | Path, page: Page) -> Path:
    """Write the page as PNG (with its DPI) or PDF (one page of the paper's size), atomically."""
    from PIL import Image

    from pipeline.artifacts import atomic_path

    path = Path(path)
    fmt = {".png": "PNG", ".pdf": "PDF"}.get(path.suffix.lower())
    if fmt is None:
        raise InputError("the board file must end in .png or .pdf", path)
    with atomic_path(path) as tmp:
        im = Image.fromarray(page.image)  # (H, W) uint8 -> mode L
        if fmt == "PDF":
            im.save(tmp, format="PDF", resolution=float(page.dpi))
        else:
            im.save(tmp, format="PNG", dpi=(page.dpi, page.dpi))
    return path
