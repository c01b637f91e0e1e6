"""Photos from a video (pipeline.video, `orca frames`): even spacing, the sharpest frame of each stretch, a
phone video's rotation applied, nothing overwritten, and decode pointing at `orca frames` for a folder of videos."""

from __future__ import annotations

import subprocess
from pathlib import Path

import cv2
import numpy as np
import pytest

from pipeline.cli import main as orca
from pipeline.config import DecodeConfig
from pipeline.errors import InputError
from pipeline.imageio import read_image
from pipeline.stages.decode import run_decode
from pipeline.video import extract_frames, sharpness, stretch_of
from pipeline.video_cli import run_frames

SIZE = (160, 96)  # w, h: multiples of H.264's 16-pixel blocks


def write_video(path: Path, frames: int = 60, blur_all_but_every: int = 3) -> None:
    """A texture panning right, every frame but each ``blur_all_but_every``-th one blurred (a hand moving)."""
    import imageio_ffmpeg

    w, h = SIZE
    rng = np.random.default_rng(0)
    base = (rng.random((h, w, 3)) * 255).astype(np.uint8)
    base[:20, :20] = (255, 0, 0)  # a red top-left corner, to see the rotation
    writer = imageio_ffmpeg.write_frames(str(path), SIZE, fps=30, quality=8, macro_block_size=16)
    writer.send(None)
    for i in range(frames):
        f = np.roll(base, i, axis=1)
        writer.send(np.ascontiguousarray(f if i % blur_all_but_every == 0 else cv2.GaussianBlur(f, (0, 0), 3)))
    writer.close()


def test_a_video_is_cut_into_equal_stretches():
    assert [stretch_of(i, 10, 5) for i in range(10)] == [0, 0, 1, 1, 2, 2, 3, 3, 4, 4]
    assert [stretch_of(i, 7, 3) for i in range(7)] == [0, 0, 0, 1, 1, 2, 2]
    assert [stretch_of(i, 4, 4) for i in range(4)] == [0, 1, 2, 3]


def test_frames_are_evenly_spaced_and_sharp(tmp_path):
    video = tmp_path / "walk.mp4"
    write_video(video)
    written = run_frames([video], tmp_path / "capture", 10)
    assert [p.name for p in written] == [f"walk_{k:04d}.jpg" for k in range(1, 11)]
    frames = [read_image(p) for p in written]
    assert all(f.shape == (SIZE[1], SIZE[0], 3) for f in frames)
    # a sharp frame (every third) is in each stretch of six: every frame kept is one of them
    sharp, blurred = sharpness(frames[0]), sharpness(cv2.GaussianBlur(frames[0], (0, 0), 3))
    assert min(sharpness(f) for f in frames) > 0.5 * sharp > blurred
    # one from each stretch of 6 frames: the red corner, at pixel i in frame i, tells which frame was kept
    corner = [int(np.argmax(f[5, :, 0].astype(int) - f[5, :, 1].astype(int) > 150)) for f in frames]
    assert all(6 * k - 2 <= c <= 6 * k + 7 for k, c in enumerate(corner)) and np.all(np.diff(corner) > 0), corner
    with pytest.raises(InputError, match="exist already"):
        extract_frames(video, tmp_path / "capture", 10)


def test_a_phone_videos_rotation_is_applied(tmp_path):
    import imageio_ffmpeg

    video, rotated = tmp_path / "v.mp4", tmp_path / "IMG_1234.MOV"
    write_video(video, frames=12)
    subprocess.run([imageio_ffmpeg.get_ffmpeg_exe(), "-y", "-v", "error", "-display_rotation:v:0", "90", "-i",
                    str(video), "-c", "copy", "-f", "mov", str(rotated)], check=True)
    assert orca(["frames", str(rotated), str(tmp_path / "capture"), "--count", "3"]) == 0
    frame = read_image(tmp_path / "capture" / "IMG_1234_0001.jpg")
    assert frame.shape == (SIZE[0], SIZE[1], 3)  # portrait: turned as a phone shows it
    assert frame[-10:, :10, 0].mean() > 200 and frame[:10, :10, 0].mean() < 200  # the red corner went down-left


def test_bad_videos_and_a_folder_of_videos_get_the_fix(tmp_path):
    bad = tmp_path / "broken.mp4"
    bad.write_bytes(b"not a video")
    with pytest.raises(InputError, match="broken.mp4.*not a readable video"):
        run_frames([bad], tmp_path / "capture", 10)
    with pytest.raises(InputError, match="not a video file"):
        run_frames([tmp_path / "broken.mp4", Path(__file__)], tmp_path / "capture", 10)
    capture = tmp_path / "only_video"
    capture.mkdir()
    write_video(capture / "walk.mp4", frames=6)
    with pytest.raises(InputError, match="orca frames .*walk.mp4"):
        run_decode(capture, tmp_path / "decode", DecodeConfig())
