"""Finding the board's corners in one photo: ChArUco (cv2.aruco.CharucoDetector) or chessboard.

Image points come back in **OpenCV's pixel convention** (the top-left pixel's centre is (0, 0)); the
conversion to the project's convention happens once, when the intrinsics are written (see
:mod:`calibration.result`).

Inverted boards (white markers on black) are found by inverting the photo: the corners are the same
points, and ArUco's detector looks for black-bordered markers only.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .board import Board


@dataclass(frozen=True)
class Detection:
    """The board's corners found in one image."""

    image_points: np.ndarray  # (N, 2) float32, pixels, OpenCV convention (pixel centres at integers)
    object_points: np.ndarray  # (N, 3) float32, board frame, metres, z = 0
    inverted: bool  # found in the inverted photo

    @property
    def n(self) -> int:
        return len(self.image_points)


class BoardNotFound(Exception):
    """The board was not found in one image; the message says what was seen instead."""


class Detector:
    """Detects one :class:`Board` in grayscale images; remembers which polarity worked last, so a set of
    photos of an inverted board costs one failed attempt, not one per photo."""

    def __init__(self, board: Board, *, min_corners: int = 6, max_detect_side: int = 2000):
        """``min_corners``: fewer corners reject the image. ``max_detect_side``: chessboards are searched in a
        copy downscaled to this long side (then refined at full size), which keeps 24 MP photos fast."""
        self.board = board
        self.min_corners = min_corners
        self.max_detect_side = max_detect_side
        self._prefer_inverted = board.inverted is True
        if board.kind == "charuco":
            import cv2

            self._cv_board = board.charuco_board()
            self._charuco = cv2.aruco.CharucoDetector(self._cv_board)

    def detect(self, gray: np.ndarray) -> Detection:
        """(H, W) uint8 -> :class:`Detection`; raises :class:`BoardNotFound` with the reason."""
        if gray.ndim != 2 or gray.dtype != np.uint8:
            raise ValueError(f"expected an (H, W) uint8 image, got {gray.shape} {gray.dtype}")
        if self.board.kind == "chessboard":
            return self._chessboard(gray)
        return self._charuco_any_polarity(gray)

    # ------------------------------------------------------------------------------------------------ ChArUco

    def _polarities(self) -> list[bool]:
        if self.board.inverted == "auto":
            return [self._prefer_inverted, not self._prefer_inverted]
        return [bool(self.board.inverted)]

    def _charuco_any_polarity(self, gray: np.ndarray) -> Detection:
        reasons: list[str] = []
        best: Detection | None = None
        for inverted in self._polarities():
            try:
                found = self._charuco_once(255 - gray if inverted else gray, inverted)
            except BoardNotFound as e:
                reasons.append(f"{'inverted' if inverted else 'as is'}: {e}")
                continue
            if best is None or found.n > best.n:
                best = found
            if found.n == self.board.n_corners:
                break  # every corner found: the other polarity cannot do better
        if best is None:
            raise BoardNotFound("; ".join(reasons))
        self._prefer_inverted = best.inverted
        return best

    def _charuco_once(self, gray: np.ndarray, inverted: bool) -> Detection:
        corners, ids, _, marker_ids = self._charuco.detectBoard(gray)
        n_markers = 0 if marker_ids is None else len(marker_ids)
        n = 0 if ids is None else len(ids)
        if n_markers == 0:
            raise BoardNotFound("no markers")
        if n < self.min_corners:
            off_board = sorted(int(i) for i in marker_ids.ravel() if i >= self.board.n_markers)
            extra = f", marker ids {off_board[:5]} are not on this board (too few squares?)" if off_board else ""
            raise BoardNotFound(f"{n_markers} markers but only {n} corners (need {self.min_corners}){extra}")
        if self._cv_board.checkCharucoCornersCollinear(ids):
            raise BoardNotFound(f"the {n} corners found lie on one line")
        obj, img = self._cv_board.matchImagePoints(corners, ids)
        return Detection(img.reshape(-1, 2).astype(np.float32), obj.reshape(-1, 3).astype(np.float32), inverted)

    # ---------------------------------------------------------------------------------------------- chessboard

    def _chessboard(self, gray: np.ndarray) -> Detection:
        import cv2

        pattern = self.board.inner_corners
        scale = min(1.0, self.max_detect_side / max(gray.shape))
        small = gray if scale == 1.0 else cv2.resize(gray, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
        # The sector-based detector is the more accurate one; the classic one (plus cornerSubPix) rescues
        # photos it misses (low contrast, strong distortion).
        ok, corners = cv2.findChessboardCornersSB(small, pattern, flags=cv2.CALIB_CB_NORMALIZE_IMAGE)
        refine = scale != 1.0
        if not ok:
            flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
            ok, corners = cv2.findChessboardCorners(small, pattern, flags=flags)
            refine = True
        if not ok:
            raise BoardNotFound(f"no {pattern[0]}x{pattern[1]} inner-corner chessboard")
        pts = corners.reshape(-1, 2).astype(np.float32)
        if scale != 1.0:
            pts = (pts + 0.5) / scale - 0.5  # pixel centres at integers in both images
        if refine:
            pts = _refine_corners(gray, pts, pattern)
        return Detection(pts, self.board.chessboard_object_points(), inverted=False)


def _refine_corners(gray: np.ndarray, pts: np.ndarray, pattern: tuple[int, int]) -> np.ndarray:
    """cornerSubPix with a window well inside one square (a window reaching the next corner pulls the
    estimate towards it). (N, 2) -> (N, 2)."""
    import cv2

    grid = pts.reshape(pattern[1], pattern[0], 2)
    spacing = min(
        float(np.linalg.norm(np.diff(grid, axis=1), axis=-1).min()),
        float(np.linalg.norm(np.diff(grid, axis=0), axis=-1).min()),
    )
    half = int(np.clip(0.3 * spacing, 2, 15))
    criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 50, 1e-3)
    out = cv2.cornerSubPix(gray, pts.reshape(-1, 1, 2).copy(), (half, half), (-1, -1), criteria)
    return out.reshape(-1, 2)


# One dictionary per marker family: OpenCV's DICT_NxN_50/100/250 are the first markers of DICT_NxN_1000, so
# the largest of a family finds them all and the ids found name the smallest dictionary that holds them.
_PROBE_FAMILIES = (
    "DICT_4X4_1000", "DICT_5X5_1000", "DICT_6X6_1000", "DICT_7X7_1000", "DICT_ARUCO_ORIGINAL",
    "DICT_APRILTAG_36h11", "DICT_APRILTAG_36h10", "DICT_APRILTAG_25h9", "DICT_APRILTAG_16h5", "DICT_ARUCO_MIP_36h12",
)


def probe_dictionaries(gray: np.ndarray, min_markers: int = 3) -> dict[str, tuple[int, bool]]:
    """{dictionary name: (markers found, found in the inverted image)} for the marker families seen in
    ``gray``, for the board-not-found message. Families with fewer than ``min_markers`` markers are left out
    (noise); each family is named by its smallest dictionary holding the ids found. Most markers first."""
    import cv2

    from .board import DICTIONARIES

    scale = min(1.0, 1200 / max(gray.shape))  # markers big enough to calibrate with survive this
    if scale < 1:
        gray = cv2.resize(gray, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
    found: dict[str, tuple[int, bool]] = {}
    for family in _PROBE_FAMILIES:
        detector = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, family)))
        ids, inverted = np.zeros(0, int), False
        for inv, img in ((False, gray), (True, 255 - gray)):
            _, got, _ = detector.detectMarkers(img)
            if got is not None and len(got) > len(ids):
                ids, inverted = got.ravel(), inv
        if len(ids) >= min_markers:
            name = family
            if family.endswith("_1000"):
                stem = family.removesuffix("1000")
                name = next(f"{stem}{n}" for n in (50, 100, 250, 1000) if int(ids.max()) < DICTIONARIES[f"{stem}{n}"])
            found[name] = (len(ids), inverted)
    return dict(sorted(found.items(), key=lambda kv: -kv[1][0]))


def dictionary_family(name: str) -> str:
    """'DICT_4X4_250' -> 'DICT_4X4' (the sizes of one family share their first markers); others unchanged."""
    head, _, size = name.rpartition("_")
    return head if size in {"50", "100", "250", "1000"} else name


def draw_detection(
    image: np.ndarray, detection: Detection | None, reprojected: np.ndarray | None, label: str
) -> np.ndarray:
    """An overlay for people: detected corners (green circles), reprojected corners (red crosses), a label.

    ``image``: (H, W) uint8 -> (H', W', 3) uint8 BGR, downscaled to at most 1280 px wide.
    """
    import cv2

    scale = min(1.0, 1280 / image.shape[1])
    out = cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)
    if scale != 1.0:
        out = cv2.resize(out, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
    r = max(3, int(round(0.006 * out.shape[1])))
    if detection is not None:
        for x, y in (detection.image_points + 0.5) * scale - 0.5:
            cv2.circle(out, (int(round(x)), int(round(y))), r, (0, 200, 0), 2, cv2.LINE_AA)
    if reprojected is not None:
        for x, y in (reprojected + 0.5) * scale - 0.5:
            cv2.drawMarker(
                out, (int(round(x)), int(round(y))), (0, 0, 255), cv2.MARKER_CROSS, 2 * r, 1, cv2.LINE_AA
            )
    # Yellow text on a black band: readable on any photo (an outline drawn with a thicker pen would not line
    # up, Hershey glyph spacing grows with the pen).
    font_scale = max(0.5, out.shape[1] / 1600)
    (tw, th), base = cv2.getTextSize(label, cv2.FONT_HERSHEY_SIMPLEX, font_scale, 1)
    cv2.rectangle(out, (0, 0), (min(out.shape[1], tw + 20), th + base + 14), (0, 0, 0), -1)
    cv2.putText(out, label, (10, th + 7), cv2.FONT_HERSHEY_SIMPLEX, font_scale, (0, 255, 255), 1, cv2.LINE_AA)
    return out
