"""The calibration board as data: ChArUco or plain chessboard, its parameters, and board files.

A :class:`Board` is validated data (pydantic, unknown keys are errors). Sizes are in metres; they set the
printed size and the metric scale of the board poses, never the intrinsics (only the marker/square ratio
matters to a ChArUco detector). ``squares_x`` x ``squares_y`` always count **squares** (columns x rows),
for both kinds: a chessboard with 9 x 6 inner corners (OpenCV's pattern size) has 10 x 7 squares.

Board files (``--board-file``): YAML, TOML or JSON holding :class:`Board`'s fields, or a caliscope
``charuco.toml`` (keys ``columns``, ``rows``, ``board_width``, ``board_height``, ``units``, ``aruco_scale``,
``square_size_override_cm``, ``inverted``, ``dictionary``), which is converted.
"""

from __future__ import annotations

import json
import logging
import re
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from pipeline.errors import InputError

if TYPE_CHECKING:
    import cv2
    import numpy as np

log = logging.getLogger("orca.calibration")

# OpenCV's predefined ArUco dictionaries and how many markers each holds (a ChArUco board needs one marker
# per white square, so the dictionary bounds the board's size).
DICTIONARIES: dict[str, int] = {
    **{f"DICT_{b}X{b}_{n}": n for b in (4, 5, 6, 7) for n in (50, 100, 250, 1000)},
    "DICT_ARUCO_ORIGINAL": 1024,
    "DICT_APRILTAG_16h5": 30,
    "DICT_APRILTAG_25h9": 35,
    "DICT_APRILTAG_36h10": 2320,
    "DICT_APRILTAG_36h11": 587,
    "DICT_ARUCO_MIP_36h12": 250,
}
_DICT_BY_UPPER = {name.upper(): name for name in DICTIONARIES}

DEFAULT_MARKER_RATIO = 0.75  # marker side / square side when marker_size is not given


class Board(BaseModel):
    """A planar calibration target. Lengths in metres; the board frame has x along columns, y along rows."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    kind: Literal["charuco", "chessboard"] = "charuco"
    squares_x: int = Field(5, ge=3, le=200, description="squares per row (columns)")
    squares_y: int = Field(7, ge=3, le=200, description="squares per column (rows)")
    square_size: float = Field(0.03, gt=0, le=2.0, description="side of one square, metres")
    marker_size: float | None = Field(
        None, gt=0, description=f"ChArUco marker side, metres (default {DEFAULT_MARKER_RATIO} x square_size)"
    )
    dictionary: str = Field("DICT_4X4_50", description="ArUco dictionary of the ChArUco markers")
    inverted: Literal["auto"] | bool = Field(
        "auto",
        description="white markers on black squares (the negative of OpenCV's board): true, false, or 'auto' "
        "(try both on every photo)",
    )
    legacy_pattern: bool = Field(
        False, description="board drawn by OpenCV < 4.6 (changes the pattern of boards with an even squares_y)"
    )

    @field_validator("dictionary")
    @classmethod
    def _known_dictionary(cls, v: str) -> str:
        key = v.strip().upper()
        key = key if key.startswith("DICT_") else f"DICT_{key}"
        if key not in _DICT_BY_UPPER:
            raise ValueError(f"unknown ArUco dictionary {v!r}; one of: {', '.join(DICTIONARIES)}")
        return _DICT_BY_UPPER[key]

    @model_validator(mode="after")
    def _consistent(self) -> Board:
        if self.kind == "charuco":
            if self.marker_length >= self.square_size:
                raise ValueError(
                    f"marker_size {self.marker_length} must be smaller than square_size {self.square_size}"
                )
            if self.n_markers > DICTIONARIES[self.dictionary]:
                raise ValueError(
                    f"a {self.squares_x}x{self.squares_y} ChArUco board needs {self.n_markers} markers but "
                    f"{self.dictionary} holds {DICTIONARIES[self.dictionary]}"
                )
        return self

    # ---------------------------------------------------------------------------------------------- derived

    @property
    def marker_length(self) -> float:
        """Marker side in metres (the explicit size, or the default ratio of the square)."""
        return self.marker_size if self.marker_size is not None else DEFAULT_MARKER_RATIO * self.square_size

    @property
    def n_markers(self) -> int:
        return self.squares_x * self.squares_y // 2

    @property
    def inner_corners(self) -> tuple[int, int]:
        """(columns, rows) of inner chessboard corners: OpenCV's ``patternSize``."""
        return self.squares_x - 1, self.squares_y - 1

    @property
    def n_corners(self) -> int:
        cx, cy = self.inner_corners
        return cx * cy

    def describe(self) -> str:
        """One line a person can check against the printed board."""
        mm = 1000.0
        size = f"{self.squares_x}x{self.squares_y} squares of {self.square_size * mm:.2f} mm"
        if self.kind == "chessboard":
            cx, cy = self.inner_corners
            return f"chessboard, {size} ({cx}x{cy} inner corners)"
        inv = {True: ", inverted (white markers on black)", False: "", "auto": ", inverted: auto"}[self.inverted]
        legacy = ", legacy pattern" if self.legacy_pattern else ""
        return f"ChArUco, {size}, markers {self.marker_length * mm:.2f} mm, {self.dictionary}{inv}{legacy}"

    def to_json(self) -> dict[str, Any]:
        """The board as stored in calibration.json / board.yaml (marker size resolved)."""
        doc = self.model_dump(mode="json")
        if self.kind == "charuco":
            doc["marker_size"] = self.marker_length
        else:
            doc.pop("marker_size")
            doc.pop("dictionary")
            doc.pop("legacy_pattern")
            doc.pop("inverted")  # a chessboard is a chessboard either way round
        return doc

    # ------------------------------------------------------------------------------------------ OpenCV objects

    def aruco_dictionary(self) -> cv2.aruco.Dictionary:
        import cv2

        return cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, self.dictionary))

    def charuco_board(self) -> cv2.aruco.CharucoBoard:
        import cv2

        board = cv2.aruco.CharucoBoard(
            (self.squares_x, self.squares_y), self.square_size, self.marker_length, self.aruco_dictionary()
        )
        board.setLegacyPattern(self.legacy_pattern)
        return board

    def chessboard_object_points(self) -> np.ndarray:
        """(N, 3) float32 inner corners in the board frame, row by row (OpenCV's corner order), metres."""
        import numpy as np

        cx, cy = self.inner_corners
        grid = np.mgrid[1 : cx + 1, 1 : cy + 1].T.reshape(-1, 2)  # (cy*cx, 2), x fastest
        pts = np.zeros((cx * cy, 3), np.float32)
        pts[:, :2] = grid * self.square_size
        return pts


# ------------------------------------------------------------------------------------------------ board files


def load_board_file(path: str | Path) -> dict[str, Any]:
    """Read a board file into :class:`Board` fields (not yet validated, so CLI flags can override them).

    YAML (.yaml/.yml), TOML (.toml) or JSON (.json); caliscope's ``charuco.toml`` is converted.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError("board file not found", path, fix="pass a YAML/TOML/JSON board file (see `orca board`)")
    text = path.read_text(encoding="utf-8")
    try:
        if path.suffix.lower() == ".toml":
            data = _toml_loads(text)
        elif path.suffix.lower() == ".json":
            data = json.loads(text)
        else:
            data = yaml.safe_load(text)
    except (ValueError, yaml.YAMLError) as e:  # TOMLDecodeError and JSONDecodeError are ValueErrors
        raise InputError(f"cannot parse the board file: {e}", path, fix="fix its syntax") from e
    if not isinstance(data, dict):
        raise InputError("a board file must hold a mapping of board parameters", path)
    if "board" in data and isinstance(data["board"], dict) and len(data) == 1:
        data = data["board"]  # also accept a calibration.json-like {"board": {...}}
    if "columns" in data and "rows" in data:
        return _from_caliscope(data, path)
    return data


def _toml_loads(text: str) -> Any:
    try:
        import tomllib
    except ModuleNotFoundError:  # Python 3.10: the same parser as a package
        import tomli as tomllib
    return tomllib.loads(text)


def board_from(fields: dict[str, Any], source: str | Path | None = None) -> Board:
    """Validate board fields into a :class:`Board`; errors name the source (file or flags) and the field."""
    try:
        return Board.model_validate(fields)
    except ValidationError as e:
        problems = "; ".join(f"{'.'.join(map(str, err['loc'])) or 'board'}: {err['msg']}" for err in e.errors())
        raise InputError(
            f"invalid board: {problems}",
            source,
            fix="correct the board parameters (squares_x, squares_y, square_size, marker_size, dictionary, "
            "inverted, kind)",
        ) from e


_CALISCOPE_KEYS = {
    "columns", "rows", "board_height", "board_width", "dictionary", "units", "aruco_scale",
    "square_size_override_cm", "square_size_overide_cm", "inverted", "legacy_pattern",
}
_UNIT_M = {"inch": 0.0254, "in": 0.0254, "cm": 0.01, "mm": 0.001, "m": 1.0}


def _from_caliscope(data: dict[str, Any], path: Path) -> dict[str, Any]:
    """caliscope's Charuco: size=(columns, rows); the square is the override (cm) or the largest square that
    fits board_width x board_height in ``units``; marker = aruco_scale x square."""
    unknown = set(data) - _CALISCOPE_KEYS
    if unknown:
        log.warning("%s: ignoring caliscope keys this reader does not know: %s", path, ", ".join(sorted(unknown)))
    override = data.get("square_size_override_cm", data.get("square_size_overide_cm"))
    if override:
        square = float(override) / 100.0
    else:
        units = str(data.get("units", "inch"))
        if units not in _UNIT_M:
            raise InputError(f"unknown units {units!r}", path, fix=f"use one of {', '.join(_UNIT_M)}")
        try:
            w, h = float(data["board_width"]), float(data["board_height"])
        except KeyError as e:
            raise InputError(f"caliscope board file without {e.args[0]} or square_size_override_cm", path) from e
        square = min(w / int(data["columns"]), h / int(data["rows"])) * _UNIT_M[units]
    out: dict[str, Any] = {
        "kind": "charuco",
        "squares_x": int(data["columns"]),
        "squares_y": int(data["rows"]),
        "square_size": square,
        "marker_size": square * float(data.get("aruco_scale", DEFAULT_MARKER_RATIO)),
        "dictionary": data.get("dictionary", "DICT_4X4_50"),  # caliscope's default
        "inverted": bool(data.get("inverted", False)),
    }
    if "legacy_pattern" in data:
        out["legacy_pattern"] = bool(data["legacy_pattern"])
    return out


def write_board_file(path: str | Path, board: Board) -> Path:
    """Write ``board`` as YAML (atomically): the file ``orca calibrate --board-file`` reads back."""
    from pipeline.artifacts import atomic_path

    path = Path(path)
    with atomic_path(path) as tmp:
        tmp.write_text(
            f"# {board.describe()}\n# lengths in metres; for `orca calibrate PHOTOS --board-file {path.name}`\n"
            + yaml.safe_dump(board.to_json(), sort_keys=False),
            encoding="utf-8",
        )
    return path


_LENGTH = re.compile(r"^\s*([0-9]*\.?[0-9]+(?:[eE][-+]?[0-9]+)?)\s*(mm|cm|m|in|inch)?\s*$")


def parse_length(text: str) -> float:
    """'30mm', '3 cm', '0.03', '0.03m', '1.5in' -> metres. A bare number is metres; above 2 it is refused
    (a 30 m square is surely 30 mm)."""
    m = _LENGTH.match(str(text))
    if not m:
        raise ValueError(f"not a length: {text!r} (e.g. 30mm, 3cm, 0.03)")
    value, unit = float(m.group(1)), m.group(2) or "m"
    if unit == "m" and m.group(2) is None and value > 2:
        raise ValueError(f"{text!r} would be {value} metres; give a unit, e.g. {m.group(1)}mm")
    return value * _UNIT_M[unit]
