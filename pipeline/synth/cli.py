"""``orca synth``: render a synthetic capture folder with exact ground truth (Mitsuba 3)."""

from __future__ import annotations

import argparse
from pathlib import Path

EXAMPLES = """\
examples:
  orca synth sphere captures/demo --overwrite          the demo capture (the defaults)
  orca synth blob /tmp/blob --views 60 --width 640 --height 480 --spp 128
  orca synth torus /tmp/torus --format both --seed 3   DNG + JPEG photos, another camera path
  orca synth sphere /tmp/tiny --views 4 --width 64 --height 48 --spp 8 --env-size 32   a quick look

scenes: sphere (glossy textured ball), torus (glossy red ring), blob (textured sphere with bumps and dents)
output: photos IMG_0001.dng ... and ground_truth/ (cameras.json, scene.json, masks, normals, depth,
diffuse/specular/linear renders, object.ply, environment views + depth); see pipeline/synth/render.py.
"""


def register(subparsers: argparse._SubParsersAction) -> None:
    from .render import SynthOptions
    from .scenes import SCENES

    d = SynthOptions()
    p = subparsers.add_parser(
        "synth",
        help="render a synthetic capture (photos + ground truth) with Mitsuba 3",
        description="Render a glossy object in a textured room from a ring of hand-held-like cameras: RAW (DNG) "
        "and/or JPEG photos a phone could have written, plus exact ground truth for evaluation.",
        epilog=EXAMPLES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("scene", choices=sorted(SCENES), help="scene preset")
    p.add_argument("out_dir", type=Path, help="capture folder to write (atomically)")
    p.add_argument("--views", type=int, default=d.views, help=f"number of photos (default {d.views})")
    p.add_argument("--width", type=int, default=d.width, help=f"image width in pixels (default {d.width})")
    p.add_argument("--height", type=int, default=d.height, help=f"image height in pixels (default {d.height})")
    p.add_argument("--spp", type=int, default=d.spp, help=f"samples per pixel (default {d.spp})")
    p.add_argument("--format", choices=("dng", "jpg", "both"), default=d.format, help="photo format (default dng)")
    p.add_argument("--seed", type=int, default=d.seed, help="camera path, exposure and noise seed (default 0)")
    p.add_argument("--env-size", type=int, default=d.env_size, metavar="N",
                   help=f"environment ground-truth views are N x N (default {d.env_size})")
    p.add_argument("--env-spp", type=int, default=None, help="samples per pixel of environment views (default: --spp)")
    p.add_argument("--optics-blur", type=float, default=d.optics_blur_px, metavar="SIGMA",
                   help="lens + optical low-pass blur of the photos, Gaussian sigma in pixels "
                        f"(default {d.optics_blur_px})")
    p.add_argument("--overwrite", action="store_true", help="replace OUT_DIR if it exists")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> None:
    from .render import SynthOptions, render_capture

    options = SynthOptions(views=args.views, width=args.width, height=args.height, spp=args.spp,
                           format=args.format, seed=args.seed, env_size=args.env_size, env_spp=args.env_spp,
                           optics_blur_px=args.optics_blur)
    render_capture(args.scene, args.out_dir, options, overwrite=args.overwrite)
