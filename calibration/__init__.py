"""Camera intrinsics from photos of a ChArUco board or a chessboard (OpenCV), used by the poses stage.

Run it::

    orca board --out board.pdf                                   # print at 100 %
    orca calibrate board_photos/ --out captures/mug/calibration --board-file board.yaml

or from Python: ``run_calibration(images_dir, out_dir, Board(...), CalibrateOptions())``.

Read the result (this is what the poses stage calls)::

    from calibration import load_calibration
    cal = load_calibration("captures/mug/calibration")       # the folder or its calibration.json
    cal.width, cal.height, cal.fx, cal.fy, cal.cx, cal.cy     # project pixel convention (see below)
    cal.dist                                                 # (k1, k2, p1, p2, k3), OpenCV's order
    cal.opencv_camera_matrix(), cal.dist_coeffs()            # for cv2.undistort & co.
    cal.colmap_params()                                      # ("OPENCV", [fx, fy, cx, cy, k1, k2, p1, p2])
    cal.scaled_to(w, h)                                      # for photos decoded at another resolution

``calibration.json`` (written atomically with ``calibration.png``, ``detections/`` and ``manifest.json``)::

    {"schema": 1, "model": "OPENCV", "width", "height", "fx", "fy", "cx", "cy",
     "dist": [k1, k2, p1, p2, k3], "rms_reprojection_px", "images_used", "pixel_convention": "colmap",
     "intrinsics_std": {...}, "frame_coverage", "per_image": [{"name", "corners", "rms_px", "inverted"}],
     "board": {...}, "images_dir", "images_rejected": [names], "rejection_reasons": {name: reason}, "options": {...}}

**Pixel convention**: the project's (COLMAP's), the top-left pixel's centre at (0.5, 0.5):
``cx = cx_opencv + 0.5``, ``cy = cy_opencv + 0.5``; fx, fy and the distortion do not depend on it.
``model`` is ``OPENCV`` (k3 fixed at 0, the default) or ``FULL_OPENCV`` (``--k3``).

Modules: :mod:`.board` (the board as data, board files), :mod:`.detect` (corners in one photo),
:mod:`.solve` (cv2.calibrateCamera), :mod:`.result` (calibration.json), :mod:`.run` (the command),
:mod:`.printable` (a board to print), :mod:`.figures`, :mod:`.cli`.
"""

from .board import Board
from .result import Calibration, load_calibration
from .run import CalibrateOptions, run_calibration

__all__ = ["Board", "CalibrateOptions", "Calibration", "load_calibration", "run_calibration"]
