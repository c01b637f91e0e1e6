"""``orca frames``: a capture folder's photos from one or more videos (:mod:`pipeline.video`)."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from .errors import InputError
from .video import VIDEO_SUFFIXES, extract_frames

DEFAULT_COUNT = 60  # photos per video: a walk-around's worth (SfM matches up to 100 photos exhaustively)

EPILOG = """\
examples:
  orca frames walkaround.mov captures/can            # 60 frames -> captures/can/walkaround_0001.jpg ...
  orca frames a.mp4 b.mp4 captures/can --count 40    # 40 from each
  orca decode captures/can                           # then the pipeline as for photos

The video is cut into COUNT stretches of equal length and the sharpest frame of each is kept (the variance of
its Laplacian): even spacing, the blurriest dropped. A phone video's rotation is applied. Frame files that
exist already are refused, never overwritten.
"""


def run_frames(videos: list[Path], capture_dir: Path, count: int) -> list[Path]:
    """Extract ``count`` frames from each video into ``capture_dir``; the files written.

    Raises:
        InputError: a file that is not a video, or one ffmpeg cannot read.
    """
    for v in videos:
        if not v.is_file():
            raise InputError("video not found", v, fix="pass the video file's path")
        if v.suffix.lower() not in VIDEO_SUFFIXES:
            raise InputError(f"not a video file ({', '.join(sorted(VIDEO_SUFFIXES))})", v,
                             fix="pass MP4/MOV videos; photos go into the capture folder as they are")
    return [p for v in videos for p in extract_frames(v, capture_dir, count)]


def main(args: argparse.Namespace) -> None:
    run_frames(args.videos, args.capture, args.count)


def register(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "frames",
        help="video(s) -> photos of a capture folder: evenly spaced frames, the sharpest of each stretch",
        description="Make a capture's photos from a video: evenly spaced frames, the blurriest dropped.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("videos", type=Path, nargs="+", help="video files (MP4, MOV, ...)")
    p.add_argument("capture", type=Path, help="capture folder the frames are written to (created if missing)")
    p.add_argument("--count", type=int, default=DEFAULT_COUNT, help=f"frames per video (default {DEFAULT_COUNT})")
    p.set_defaults(func=main)
