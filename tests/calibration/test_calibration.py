"""Camera calibration: rendered ChArUco views with known intrinsics, the real chessboard and ChArUco photo
sets, the pixel convention, bad input, the CLI, and the printable board read back by the detector."""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml
from helpers import TESTDATA

from calibration import Board, CalibrateOptions, load_calibration, run_calibration
from calibration.board import load_board_file
from calibration.detect import Detection, Detector
from calibration.printable import board_image, render_page
from calibration.run import calibrate
from pipeline.cli import main as orca
from pipeline.errors import InputError

PHOTOS = TESTDATA / "calibration"
needs_testdata = pytest.mark.skipif(
    not PHOTOS.is_dir(), reason=f"real calibration photos not found at {PHOTOS} (clone the repo next to shared/)"
)

SIZE = (640, 480)
# True intrinsics in the project's convention (top-left pixel centre at (0.5, 0.5)); fx != fy and an
# off-centre principal point so a swap or a lost offset shows.
FX, FY, CX, CY = 560.0, 555.0, 331.0, 236.0
K_OPENCV = np.array([[FX, 0, CX - 0.5], [0, FY, CY - 0.5], [0, 0, 1]])
DIST = np.array([-0.12, 0.0, 0.0, 0.0, 0.0])  # mild barrel distortion, like a phone's main camera
BOARD = Board(squares_x=7, squares_y=5, square_size=0.03, dictionary="DICT_4X4_50")


# ------------------------------------------------------------------------------------------- rendering views


def board_poses(board: Board, n: int = 10, distance: float = 0.36) -> list[tuple[np.ndarray, np.ndarray]]:
    """n board-to-camera poses (R, t): tilted 20-45 degrees about varied axes, spread over the frame."""
    angles = [(25, 0, 0), (-30, 0, 5), (0, 30, -5), (0, -35, 0), (20, 20, 10), (-25, 25, -10), (30, -20, 0),
              (-20, -30, 5), (40, 10, 0), (10, -40, -5)]
    offsets = [(0.05, 0.03), (-0.05, -0.03), (0.05, -0.03), (-0.05, 0.03), (0, 0.04), (0.06, 0), (-0.06, 0),
               (0, -0.04), (0.03, 0.02), (-0.03, -0.02)]
    centre = np.array([board.squares_x, board.squares_y, 0]) * board.square_size / 2
    poses = []
    for (ax, ay, az), (ox, oy) in list(zip(angles, offsets))[:n]:
        R = cv2.Rodrigues(np.radians([ax, 0, 0]))[0] @ cv2.Rodrigues(np.radians([0, ay, 0]))[0] \
            @ cv2.Rodrigues(np.radians([0, 0, az]))[0]
        poses.append((R, np.array([ox, oy, distance]) - R @ centre))
    return poses


def render_views(
    board: Board, K: np.ndarray, dist: np.ndarray, poses: list, *, inverted: bool = False, ss: int = 2
) -> list[np.ndarray]:
    """Photos of a flat board: K [r1 r2 t] maps the board plane to the (undistorted) image, distortion is
    applied by a remap, and each pixel averages ss x ss samples. K in OpenCV's convention. -> (H, W) uint8.

    Exact by construction: a sample at hi-res pixel u_hi sits at u = (u_hi + 0.5) / ss - 0.5 in the photo.
    """
    w, h = SIZE
    square_px = 64
    pad = square_px // 2  # white quiet zone around the board, then a grey table
    art = board_image(board, square_px)
    texture = cv2.copyMakeBorder(255 - art if inverted else art, pad, pad, pad, pad, cv2.BORDER_CONSTANT, value=255)
    s = square_px / board.square_size
    board_to_texture = np.array([[s, 0, pad - 0.5], [0, s, pad - 0.5], [0, 0, 1]])
    K_hi = np.array([[ss, 0, ss / 2 - 0.5], [0, ss, ss / 2 - 0.5], [0, 0, 1]]) @ K
    margin = max(w, h) * ss // 4  # the undistorted view reaches beyond the frame
    shift = np.array([[1, 0, margin], [0, 1, margin], [0, 0, 1.0]])
    maps = None
    if np.any(dist):
        u, v = np.meshgrid(np.arange(w * ss, dtype=np.float64), np.arange(h * ss, dtype=np.float64))
        criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 20, 1e-10)
        ideal = cv2.undistortPoints(np.stack([u, v], -1).reshape(-1, 1, 2), K_hi, dist, P=K_hi, criteria=criteria)
        ideal = ideal.reshape(h * ss, w * ss, 2) + margin
        maps = ideal[..., 0].astype(np.float32), ideal[..., 1].astype(np.float32)
    views = []
    for R, t in poses:
        H = shift @ K_hi @ np.column_stack([R[:, 0], R[:, 1], t]) @ np.linalg.inv(board_to_texture)
        canvas = (w * ss + 2 * margin, h * ss + 2 * margin)
        ideal_view = cv2.warpPerspective(texture, H, canvas, flags=cv2.INTER_LINEAR, borderValue=110)
        hi = cv2.remap(ideal_view, *maps, cv2.INTER_LINEAR) if maps is not None else \
            ideal_view[margin:-margin, margin:-margin]
        views.append(cv2.resize(hi, SIZE, interpolation=cv2.INTER_AREA))
    return views


def write_views(folder: Path, views: list[np.ndarray]) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    for i, v in enumerate(views):
        cv2.imwrite(str(folder / f"view_{i:02d}.png"), v)
    return folder


@pytest.fixture(scope="module")
def rendered(tmp_path_factory) -> tuple[Path, list]:
    poses = board_poses(BOARD)
    folder = write_views(tmp_path_factory.mktemp("rendered") / "photos", render_views(BOARD, K_OPENCV, DIST, poses))
    return folder, poses


# ------------------------------------------------------------------------------------------------ synthetic


def test_rendered_charuco_recovers_known_intrinsics(rendered, tmp_path):
    photos, _ = rendered
    cal = run_calibration(photos, tmp_path / "cal", BOARD)
    err = np.array([cal.fx / FX, cal.fy / FY, cal.cx / CX, cal.cy / CY]) - 1
    assert np.all(np.abs(err) < 0.005), f"relative errors fx, fy, cx, cy: {err}"
    assert abs(cal.dist[0] - DIST[0]) < 0.015, cal.dist
    assert cal.rms_reprojection_px < 0.2 and cal.images_used == 10
    doc = json.loads((tmp_path / "cal" / "calibration.json").read_text())
    assert doc["images_rejected"] == [] and doc["pixel_convention"] == "colmap"
    assert all(p["corners"] == BOARD.n_corners and p["inverted"] is False for p in doc["per_image"])
    assert (tmp_path / "cal" / "calibration.png").stat().st_size > 10_000
    assert len(list((tmp_path / "cal" / "detections").glob("*.jpg"))) == 10


def test_detected_corners_sit_where_the_camera_projects_them(rendered):
    """The detector's pixel convention is OpenCV's: no half-pixel shift between corners found in the
    rendered photos and cv2.projectPoints of the true camera (which calibrateCamera fits)."""
    photos, poses = rendered
    detector = Detector(BOARD)
    residuals = []
    for path, (R, t) in zip(sorted(photos.glob("*.png")), poses):
        d = detector.detect(cv2.imread(str(path), cv2.IMREAD_GRAYSCALE))
        true = cv2.projectPoints(d.object_points.astype(np.float64), cv2.Rodrigues(R)[0], t, K_OPENCV, DIST)[0]
        residuals.append(d.image_points - true.reshape(-1, 2))
    r = np.concatenate(residuals)
    assert np.all(np.abs(r.mean(axis=0)) < 0.03), f"mean offset {r.mean(axis=0)} px"
    assert np.sqrt(np.mean(np.sum(r**2, axis=1))) < 0.15


def test_calibration_json_is_in_the_project_pixel_convention():
    """Exact corners (no image, no noise): the fit reproduces K to 1e-4 px, and the stored cx, cy are
    OpenCV's + 0.5; scaling to half size keeps (0, 0) at the image corner."""
    poses = board_poses(BOARD)
    obj = BOARD.charuco_board().getChessboardCorners().astype(np.float32)
    detections = {}
    for i, (R, t) in enumerate(poses):
        img = cv2.projectPoints(obj.astype(np.float64), cv2.Rodrigues(R)[0], t, K_OPENCV, DIST)[0].reshape(-1, 2)
        detections[f"v{i}"] = Detection(img.astype(np.float32), obj, inverted=False)
    cal = calibrate(detections, SIZE, CalibrateOptions()).calibration
    assert cal.cx == pytest.approx(CX, abs=2e-3) and cal.cy == pytest.approx(CY, abs=2e-3)
    assert cal.fx == pytest.approx(FX, abs=2e-3) and cal.fy == pytest.approx(FY, abs=2e-3)
    np.testing.assert_allclose(cal.opencv_camera_matrix(), K_OPENCV, atol=2e-3)
    half = cal.scaled_to(320, 240)
    assert (half.fx, half.cx, half.cy) == pytest.approx((cal.fx / 2, cal.cx / 2, cal.cy / 2))
    model, params = cal.colmap_params()
    assert model == "OPENCV" and params[:4] == [cal.fx, cal.fy, cal.cx, cal.cy]
    with pytest.raises(InputError, match="aspect ratio"):
        cal.scaled_to(480, 640)  # a portrait photo is not this calibration


def test_inverted_board_is_found_automatically_and_not_when_told_otherwise(tmp_path):
    poses = board_poses(BOARD, n=6)
    photos = write_views(tmp_path / "photos", render_views(BOARD, K_OPENCV, np.zeros(5), poses, inverted=True))
    cal = run_calibration(photos, tmp_path / "cal", BOARD, CalibrateOptions(min_images=5))  # inverted: auto
    assert cal.images_used == 6
    doc = json.loads((tmp_path / "cal" / "calibration.json").read_text())
    assert all(p["inverted"] is True for p in doc["per_image"])
    with pytest.raises(InputError) as e:
        run_calibration(photos, tmp_path / "cal2", BOARD.model_copy(update={"inverted": False}))
    assert "white on black" in str(e.value) and "--inverted yes" in str(e.value)
    assert not (tmp_path / "cal2").exists()


# --------------------------------------------------------------------------------------------- real photos


@needs_testdata
def test_real_chessboard_photos_calibrate_under_one_pixel(tmp_path):
    board = Board(kind="chessboard", squares_x=10, squares_y=7, square_size=0.025)  # 9 x 6 inner corners
    cal = run_calibration(PHOTOS / "chessboard_opencv", tmp_path / "cal", board)
    assert cal.rms_reprojection_px < 1.0
    assert cal.images_used >= 12 and (cal.width, cal.height) == (640, 480)
    assert abs(cal.fx / cal.fy - 1) < 0.01  # square pixels
    assert 500 < cal.fx < 570 and abs(cal.cx - 320) < 40 and abs(cal.cy - 240) < 30


@needs_testdata
def test_real_charuco_frames_through_the_cli_and_loader(tmp_path):
    """caliscope's charuco.toml (4 x 5 squares, 5.4 cm, DICT_4X4_1000, inverted) via `orca calibrate`."""
    out = tmp_path / "captures" / "mug" / "calibration"
    folder = PHOTOS / "charuco_cam0"
    assert orca(["calibrate", str(folder), "--out", str(out), "--board-file", str(folder / "charuco.toml")]) == 0
    cal = load_calibration(out)  # the folder, as the poses stage will pass it
    doc = json.loads((out / "calibration.json").read_text())
    assert cal.rms_reprojection_px == doc["rms_reprojection_px"] < 1.0
    assert (cal.width, cal.height, cal.fx, cal.cy) == (1280, 720, doc["fx"], doc["cy"])
    assert cal.images_used == len(doc["per_image"]) >= 15
    assert all(p["inverted"] for p in doc["per_image"])
    assert doc["board"]["squares_x"] == 4 and doc["board"]["dictionary"] == "DICT_4X4_1000"
    assert set(doc["images_rejected"]) == set(doc["rejection_reasons"])
    assert (out / "manifest.json").is_file() and (out / "calibration.png").is_file()


@needs_testdata
def test_caliscope_board_file_is_read():
    fields = load_board_file(PHOTOS / "charuco_cam0" / "charuco.toml")
    board = Board(**fields)
    assert (board.squares_x, board.squares_y, board.dictionary, board.inverted) == (4, 5, "DICT_4X4_1000", True)
    assert board.square_size == pytest.approx(0.054) and board.marker_length == pytest.approx(0.0405)


# ----------------------------------------------------------------------------------------------- bad input


def test_board_not_found_names_the_folder_and_the_fixes(tmp_path):
    photos = tmp_path / "blank"
    write_views(photos, [np.full(SIZE[::-1], v, np.uint8) for v in (40, 90, 128, 170, 200, 240)])
    out = tmp_path / "cal"
    with pytest.raises(InputError) as e:
        run_calibration(photos, out, BOARD)
    msg = str(e.value)
    assert str(photos) in msg and "found in 0 of 6 photos" in msg
    for fix in ("--squares-x", "--dictionary", "--inverted", "blur", "lit"):
        assert fix in msg, f"the message should mention {fix}: {msg}"
    assert not out.exists()


@needs_testdata
def test_wrong_dictionary_is_diagnosed(tmp_path):
    photos = tmp_path / "frames"
    photos.mkdir()
    for p in sorted((PHOTOS / "charuco_cam0").glob("*.jpg"))[:6]:
        shutil.copy(p, photos)
    board = Board(squares_x=4, squares_y=5, square_size=0.054, dictionary="DICT_5X5_100", inverted=True)
    with pytest.raises(InputError) as e:
        run_calibration(photos, tmp_path / "cal", board)
    assert str(photos) in str(e.value) and "try --dictionary DICT_4X4_50" in str(e.value)


def test_mixed_sizes_and_unsafe_output_folders_are_refused(rendered, tmp_path):
    photos, _ = rendered
    mixed = tmp_path / "mixed"
    shutil.copytree(photos, mixed)
    cv2.imwrite(str(mixed / "portrait.png"), np.full((640, 480), 128, np.uint8))
    with pytest.raises(InputError, match=r"different sizes: 10 are 640x480 .*portrait\.png \(480x640\)"):
        run_calibration(mixed, tmp_path / "cal", BOARD)
    # The output folder is replaced whole: never the photos' folder, nor a folder that is not a result.
    with pytest.raises(InputError, match="output folder holds the calibrate stage's input"):
        run_calibration(mixed, tmp_path, BOARD)
    (tmp_path / "notes").mkdir()
    (tmp_path / "notes" / "todo.txt").write_text("keep me")
    with pytest.raises(InputError, match="holds files the calibrate stage did not write"):
        run_calibration(photos, tmp_path / "notes", BOARD)
    assert (tmp_path / "notes" / "todo.txt").read_text() == "keep me"


def test_load_calibration_errors_name_the_file_and_convert_opencv_files(tmp_path):
    with pytest.raises(InputError, match="calibration file not found"):
        load_calibration(tmp_path)
    bad = tmp_path / "calibration.json"
    bad.write_text(json.dumps({"width": 640, "height": 480, "fx": -1, "fy": 500, "cx": 320, "cy": 240}))
    with pytest.raises(InputError, match=re.escape(str(bad)) + r".*fx"):
        load_calibration(bad)
    opencv = {"width": 640, "height": 480, "fx": 500, "fy": 500, "cx": 319.5, "cy": 239.5,
              "pixel_convention": "opencv"}
    bad.write_text(json.dumps(opencv))
    cal = load_calibration(bad)
    assert (cal.cx, cal.cy, cal.dist) == (320.0, 240.0, (0.0,) * 5)


# ------------------------------------------------------------------------------------------- printed board


@pytest.mark.parametrize(
    "flags, kind, inverted",
    [
        ([], "charuco", False),
        (["--inverted", "yes", "--squares-x", "6", "--squares-y", "8", "--square-size", "25mm"], "charuco", True),
        (["--board", "chessboard", "--squares-x", "10", "--squares-y", "7", "--square-size", "2cm"],
         "chessboard", False),
    ],
)
def test_printed_board_is_found_by_the_detector_at_its_stated_size(tmp_path, flags, kind, inverted):
    dpi = 100
    png = tmp_path / "board.png"
    assert orca(["board", "--out", str(png), "--dpi", str(dpi), *flags]) == 0
    board = Board(**load_board_file(tmp_path / "board.yaml"))  # the parameters written beside the picture
    assert board.kind == kind and (kind == "chessboard" or board.inverted is inverted)
    page = cv2.imread(str(png), cv2.IMREAD_GRAYSCALE)
    assert sorted(page.shape) == [round(210 / 25.4 * dpi), round(297 / 25.4 * dpi)]  # A4 (the chessboard: landscape)
    from PIL import Image

    assert Image.open(png).info["dpi"] == pytest.approx((dpi, dpi), abs=0.01)  # stored per metre
    d = Detector(board).detect(page)
    assert d.n == board.n_corners and (kind == "chessboard" or d.inverted is inverted)
    # Neighbouring corners are one square apart on paper: square_size at the stated DPI.
    grid = d.image_points[np.lexsort(d.object_points[:, :2].T)]  # row by row
    step = np.linalg.norm(np.diff(grid.reshape(board.squares_y - 1, board.squares_x - 1, 2), axis=1), axis=-1)
    assert step.mean() == pytest.approx(board.square_size / 0.0254 * dpi, abs=0.1)


def test_board_pdf_has_the_paper_size_and_oversized_boards_are_refused(tmp_path):
    pdf = tmp_path / "board.pdf"
    assert orca(["board", "--out", str(pdf), "--paper", "letter", "--dpi", "150"]) == 0
    box = re.search(rb"/MediaBox\s*\[\s*0\s+0\s+([\d.]+)\s+([\d.]+)\s*\]", pdf.read_bytes())
    assert box and (float(box[1]), float(box[2])) == pytest.approx((612, 792), abs=1.0)  # 8.5 x 11 in
    assert yaml.safe_load((tmp_path / "board.yaml").read_text())["squares_x"] == 5
    with pytest.raises(InputError, match="does not fit on A4"):
        render_page(Board(squares_x=8, squares_y=10, square_size=0.03), dpi=72)
    assert orca(["board", "--out", str(tmp_path / "big.png"), "--square-size", "80mm"]) == 2  # clean error
