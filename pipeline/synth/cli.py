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
  orca synth random-7 /tmp/family/7 --views 40 --spp 16 --coverage-spp 16 --truth front_end
                                                       scene 7 of the random family, for poses/masks benchmarks
  orca synth tiles-3 /tmp/tiles3 --truth front_end     the same scene as random-3, in a tiled room

scenes: sphere (glossy textured ball), gold (a polished gold ball in the same room), torus (glossy red ring), blob
  (textured sphere with bumps and dents),
  random-<seed> (the randomized family, pipeline/synth/family.py: sphere, torus, blob, vase or mug; on the floor,
  on a plain table or floating; poster, plain or tiled room; a fifth to two thirds of the frame; one to three
  camera rings with gaps; varied lights and props), tiles-<seed> (random-<seed> in a room of plain tiles);
  FRONT_END_SUITE in family.py lists the seeds of the front-end benchmark
output: photos IMG_0001.dng ... and ground_truth/ (cameras.json, scene.json, masks, normals, depth,
diffuse/specular/linear renders, object.ply, environment views + depth); see pipeline/synth/render.py.
--truth front_end writes only the photos, cameras.json, scene.json, object.ply, masks and coverage.
"""


def register(subparsers: argparse._SubParsersAction) -> None:
    from .render import SynthOptions

    d = SynthOptions()
    p = subparsers.add_parser(
        "synth",
        help="render a synthetic capture (photos + ground truth) with Mitsuba 3",
        description="Render a glossy object in a textured room from a ring of hand-held-like cameras: RAW (DNG) "
        "and/or JPEG photos a phone could have written, plus exact ground truth for evaluation.",
        epilog=EXAMPLES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("scene", help="scene: sphere, torus, blob, random-<seed> or tiles-<seed> (see below)")
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
    p.add_argument("--coverage-spp", type=int, default=d.coverage_spp, metavar="N",
                   help=f"samples per pixel of the mask (coverage) pass (default {d.coverage_spp})")
    p.add_argument("--truth", choices=("full", "front_end"), default=d.truth,
                   help="full: every ground truth; front_end: photos, cameras, scene.json, mesh, masks and coverage "
                        f"only, several times faster (default {d.truth})")
    p.add_argument("--optics-blur", type=float, default=d.optics_blur_px, metavar="SIGMA",
                   help="lens + optical low-pass blur of the photos, Gaussian sigma in pixels "
                        f"(default {d.optics_blur_px})")
    p.add_argument("--overwrite", action="store_true", help="replace OUT_DIR if it exists")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> None:
    from .render import SynthOptions, render_capture
    from .scenes import get_scene

    options = SynthOptions(views=args.views, width=args.width, height=args.height, spp=args.spp,
                           format=args.format, seed=args.seed, env_size=args.env_size, env_spp=args.env_spp,
                           optics_blur_px=args.optics_blur, coverage_spp=args.coverage_spp, truth=args.truth)
    render_capture(get_scene(args.scene), args.out_dir, options, overwrite=args.overwrite)
