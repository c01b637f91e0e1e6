"""``orca calibrate`` (photos of a board -> calibration.json) and ``orca board`` (a board to print)."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

CALIBRATE_EPILOG = """\
examples:
  orca board --out board.pdf                     # print it (100 %), photograph it 15-30 times, then:
  orca calibrate board_photos/ --out captures/mug/calibration --board-file board.yaml
  orca calibrate left/ --out cal/ --board chessboard --squares-x 10 --squares-y 7     # 9x6 inner corners
  orca calibrate frames/ --out cal/ --board-file charuco.toml                          # a caliscope board
  orca calibrate frames/ --out cal/ --squares-x 4 --squares-y 5 --square-size 54mm --marker-size 40.5mm \\
                 --dictionary DICT_4X4_1000 --inverted yes

Board: --board-file (YAML/TOML/JSON with the Board fields, or caliscope's charuco.toml) and/or the flags (flags
win). With neither, a board file inside PHOTOS (board.yaml, board.toml, charuco.toml) is used if there is one,
else the default board of `orca board`. --squares-x/-y count squares (columns x rows), for chessboards too.
Lengths take units: 30mm, 3cm, 0.03 (metres), 1.2in; they scale the board poses only, not the intrinsics.

Output (replaced whole, only on success): calibration.json (fx, fy, cx, cy with the top-left pixel's centre at
(0.5, 0.5), dist [k1, k2, p1, p2, k3], RMS and per-photo errors, rejected photos), calibration.png,
detections/*.jpg, manifest.json. The poses stage uses captures/<name>/calibration/calibration.json.
"""

BOARD_EPILOG = """\
examples:
  orca board --out board.pdf                      # ChArUco 5x7, 30 mm squares, DICT_4X4_50, on A4
  orca board --out board.png --paper letter --dpi 600
  orca board --out chess.pdf --board chessboard --squares-x 10 --squares-y 7 --square-size 25mm
  orca board --out big.png --paper fit --squares-x 8 --squares-y 11 --square-size 60mm

Also writes the board's parameters beside the picture (board.pdf -> board.yaml), for
`orca calibrate PHOTOS --board-file board.yaml`. Print at 100 % (actual size); the margin states the square
size and holds a 100 mm bar to check the print. Glue the print to something flat.
"""

BOARD_FILE_NAMES = ("board.yaml", "board.yml", "board.toml", "charuco.toml")


def _length(text: str) -> float:
    from .board import parse_length

    try:
        return parse_length(text)
    except ValueError as e:
        raise argparse.ArgumentTypeError(str(e)) from e


def _add_board_arguments(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("board")
    g.add_argument("--board-file", type=Path, default=None, help="board parameters (YAML/TOML/JSON; caliscope TOML)")
    g.add_argument("--board", dest="kind", choices=["charuco", "chessboard"], default=None,
                   help="board kind (default charuco)")
    g.add_argument("--squares-x", type=int, default=None, help="squares per row, i.e. columns (default 5)")
    g.add_argument("--squares-y", type=int, default=None, help="squares per column, i.e. rows (default 7)")
    g.add_argument("--square-size", type=_length, default=None, help="side of a square, e.g. 30mm (default)")
    g.add_argument("--marker-size", type=_length, default=None, help="ChArUco marker side (default 0.75 x square)")
    g.add_argument("--dictionary", default=None, help="ArUco dictionary of the markers (default DICT_4X4_50)")
    g.add_argument("--inverted", choices=["auto", "yes", "no"], default=None,
                   help="white markers on black squares (default auto when calibrating: try both; no when printing)")
    g.add_argument("--legacy-pattern", action="store_const", const=True, default=None,
                   help="board drawn by OpenCV < 4.6 (matters for an even number of rows)")


def board_from_arguments(args: argparse.Namespace, search_dir: Path | None = None) -> Any:
    """--board-file (or a board file found in ``search_dir`` when no board option is given) <- flags."""
    import logging

    from .board import board_from, load_board_file

    flags = {
        "kind": args.kind, "squares_x": args.squares_x, "squares_y": args.squares_y,
        "square_size": args.square_size, "marker_size": args.marker_size, "dictionary": args.dictionary,
        "inverted": args.inverted, "legacy_pattern": args.legacy_pattern,
    }
    flags = {k: v for k, v in flags.items() if v is not None}
    board_file = args.board_file
    if board_file is None and not flags and search_dir is not None:
        board_file = next((search_dir / n for n in BOARD_FILE_NAMES if (search_dir / n).is_file()), None)
        if board_file is not None:
            logging.getLogger("orca.calibration").info("using the board file %s", board_file)
    fields = load_board_file(board_file) if board_file is not None else {}
    fields.update(flags)
    return board_from(fields, board_file if board_file is not None else "board options")


def register(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "calibrate",
        help="photos of a ChArUco/chessboard board -> camera intrinsics (calibration.json)",
        description="Calibrate one camera (focal lengths, principal point, lens distortion) from photos of a "
        "ChArUco board or a chessboard.",
        epilog=CALIBRATE_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument(
        "images", type=Path, metavar="PHOTOS", help="folder of board photos (JPEG/PNG/TIFF), one camera, one resolution"
    )
    p.add_argument("--out", type=Path, required=True, help="output folder, e.g. captures/<name>/calibration")
    _add_board_arguments(p)
    g = p.add_argument_group("solver")
    g.add_argument("--min-images", type=int, default=None, help="fewer photos with the board is an error (default 5)")
    g.add_argument("--min-corners", type=int, default=None, help="photos with fewer corners are rejected (default 6)")
    g.add_argument("--k3", dest="fit_k3", action="store_const", const=True, default=None,
                   help="also fit the radial k3 term (wide-angle lenses, many photos; model FULL_OPENCV)")
    p.set_defaults(func=main_calibrate)

    b = subparsers.add_parser(
        "board",
        help="a calibration board to print (PNG or PDF) for `orca calibrate`",
        description="Draw a ChArUco board or chessboard at its true printed size, with its parameters in the margin.",
        epilog=BOARD_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    b.add_argument("--out", type=Path, required=True, help="board.png or board.pdf")
    b.add_argument("--paper", choices=["a4", "letter", "fit"], default="a4", help="page size (default a4)")
    b.add_argument("--dpi", type=int, default=300, help="printer dots per inch (default 300)")
    _add_board_arguments(b)
    b.set_defaults(func=main_board)


def main_calibrate(args: argparse.Namespace) -> Any:
    from pydantic import ValidationError

    from pipeline.errors import InputError

    from .run import CalibrateOptions, run_calibration

    board = board_from_arguments(args, search_dir=args.images if args.images.is_dir() else None)
    given = {"min_images": args.min_images, "min_corners": args.min_corners, "fit_k3": args.fit_k3}
    try:
        options = CalibrateOptions(**{k: v for k, v in given.items() if v is not None})
    except ValidationError as e:
        problems = "; ".join(
            f"--{'-'.join(map(str, err['loc'])).replace('_', '-')}: {err['msg']}" for err in e.errors()
        )
        raise InputError(f"invalid option: {problems}") from e
    return run_calibration(args.images, args.out, board, options)


def main_board(args: argparse.Namespace) -> Path:
    import logging

    from .board import write_board_file
    from .printable import render_page, write_page

    board = board_from_arguments(args)
    page = render_page(board, dpi=args.dpi, paper=args.paper)
    write_page(args.out, page)
    sidecar = write_board_file(args.out.with_suffix(".yaml"), page.board)
    h, w = page.image.shape
    logging.getLogger("orca.calibration").info(
        "board: %s -> %s (%.0f x %.0f mm at %d DPI) and %s", page.board.describe(), args.out,
        w / args.dpi * 25.4, h / args.dpi * 25.4, args.dpi, sidecar,
    )
    return args.out
