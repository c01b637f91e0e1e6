"""Photos from a video (a phone's walk-around): frames at an even spacing, the sharpest of each stretch.

A video holds many more frames than SfM and training need, and hand-held ones blur whenever the hand moves
fast. The video is cut into ``count`` stretches of equal length; from each, the frame with the most detail (the
variance of its Laplacian, on a small grey copy) is kept -- even spacing along the path, the blurriest dropped,
as nerfstudio's ``ns-process-data video`` does. Frames are read through imageio-ffmpeg, which applies a phone
video's rotation, and written as JPEG files named ``<video stem>_<k>.jpg`` that decode reads as photos.
"""

from __future__ import annotations

import logging
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from .artifacts import atomic_path
from .errors import InputError
from .qa import write_jpeg

log = logging.getLogger("orca.decode")

VIDEO_SUFFIXES = frozenset(".mp4 .mov .m4v .avi .mkv .webm .mts".split())
SHARPNESS_SIZE = 480  # longest side of the grey copy the sharpness is measured on (noise-robust, fast)
JPEG_QUALITY = 95


def sharpness(frame: np.ndarray, size: int = SHARPNESS_SIZE) -> float:
    """Variance of the Laplacian of ``frame`` ``(H, W, 3)`` uint8, downscaled to ``size`` (longest side): large
    for a sharp frame, small for a blurred one of the same scene."""
    import cv2

    grey = cv2.cvtColor(frame, cv2.COLOR_RGB2GRAY)
    scale = size / max(grey.shape)
    if scale < 1:
        grey = cv2.resize(grey, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
    return float(cv2.Laplacian(grey, cv2.CV_32F).var())


def stretch_of(index: int, total: int, count: int) -> int:
    """Which of ``count`` equal stretches of a ``total``-frame video frame ``index`` lies in."""
    return min(count - 1, index * count // total)


def read_frames(path: Path) -> tuple[dict, Iterator[np.ndarray]]:
    """The video's metadata (imageio-ffmpeg's: ``size`` as delivered, rotation applied; ``fps``, ``duration``)
    and its frames ``(H, W, 3)`` uint8 RGB one by one.

    Raises:
        InputError: ffmpeg cannot read the file.
    """
    import imageio_ffmpeg

    reader = imageio_ffmpeg.read_frames(str(path))
    try:
        meta = next(reader)
    except (OSError, RuntimeError, StopIteration) as e:
        raise InputError(f"not a readable video ({e})", path, fix="copy it again, or convert it to MP4 (H.264)") from e
    w, h = meta["size"]

    def frames() -> Iterator[np.ndarray]:
        for data in reader:
            yield np.frombuffer(data, np.uint8).reshape(h, w, 3)

    return meta, frames()


def count_frames(path: Path) -> int:
    """The number of frames ffmpeg decodes from the video (exact: it decodes them all, quickly)."""
    import imageio_ffmpeg

    try:
        frames, _ = imageio_ffmpeg.count_frames_and_secs(str(path))
    except (OSError, RuntimeError) as e:
        raise InputError(f"not a readable video ({e})", path, fix="copy it again, or convert it to MP4 (H.264)") from e
    if frames < 1:
        raise InputError("the video has no frames", path, fix="record it again")
    return int(frames)


def extract_frames(video: Path, out_dir: Path, count: int) -> list[Path]:
    """The sharpest frame of each of ``count`` equal stretches of ``video`` written to ``out_dir`` as
    ``<stem>_<k>.jpg`` (k from 1, zero-padded); the files written. ffmpeg counts the frames first (the stretches
    need the exact number; a decode without conversion), then one pass keeps one frame per stretch in memory.
    Existing files of those names are refused, not overwritten."""
    total = count_frames(video)
    meta, frames = read_frames(video)
    stretches = min(count, total)
    names = [out_dir / f"{video.stem}_{k + 1:04d}.jpg" for k in range(stretches)]
    taken = [p.name for p in names if p.exists()]
    if taken:
        raise InputError(f"{len(taken)} frame file(s) of this video exist already: {', '.join(taken[:5])}", out_dir,
                         fix="extract into an empty folder, or remove the earlier frames first")
    out_dir.mkdir(parents=True, exist_ok=True)
    written: list[Path] = []
    best: tuple[float, np.ndarray] | None = None
    current = 0
    for i, frame in enumerate(frames):
        k = stretch_of(i, total, stretches)
        if k != current and best is not None:
            written.append(save_frame(best[1], names[current]))
            best = None
        current = k
        score = sharpness(frame)
        if best is None or score > best[0]:
            best = (score, frame.copy())
    if best is not None:
        written.append(save_frame(best[1], names[current]))
    log.info("%s: %d of %d frames (%dx%d, %.0f fps) -> %s", video.name, len(written), total, *meta["size"],
             meta.get("fps", 0), out_dir)
    return written


def save_frame(frame: np.ndarray, path: Path) -> Path:
    """``frame`` ``(H, W, 3)`` uint8 RGB as a JPEG at ``path`` (atomically: an interrupted run leaves no frame
    half-written)."""
    with atomic_path(path) as tmp:
        write_jpeg(tmp, frame, JPEG_QUALITY)
    return path
