"""How long a trained model takes to render a photo (the object over the environment field, as held-out evaluation
renders it) with training's fine samples along each environment cone (what it renders colour with) and with the
render count (``train.render.env_fine_render``, what it renders the environment's depth with), and an environment
view with its depth (always the render count).

    python bench/render_speed.py results/demo/train --cameras results/demo/masks/cameras.json
    python bench/render_speed.py results/blowtorch/train --cameras results/blowtorch/masks/cameras.json --views 2

Renders the first ``--views`` cameras at full size, each setting in turn (the same views, one process, so the two
are measured minutes apart on one machine), and prints seconds per view and rays per second. Appends a JSON line
to bench/results/render_speed.jsonl with the machine's description.
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace
from datetime import datetime
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run as a script: bench.blowtorch's helpers

from bench.blowtorch import append_record, commit, machine  # noqa: E402
from pipeline.cameras import load_cameras  # noqa: E402
from pipeline.rendering import load_renderer, render_composite_view, render_environment_view  # noqa: E402

RESULTS = Path(__file__).parent / "results" / "render_speed.jsonl"


def seconds_per_view(model, cameras, render) -> float:
    started = time.perf_counter()
    for cam in cameras:
        render(model, cam)
    return (time.perf_counter() - started) / len(cameras)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("train", type=Path, help="a train stage's folder")
    parser.add_argument("--cameras", type=Path, required=True, help="the cameras.json it was trained with")
    parser.add_argument("--views", type=int, default=2)
    parser.add_argument("--device", default="cpu")
    args = parser.parse_args()
    model = load_renderer(args.train, args.device)
    cameras = load_cameras(args.cameras).cameras[: args.views]
    spec = model.spec.render
    counts = {"training": spec.env_fine, "render": spec.for_depth().env_fine}
    runs = [("photo", render_composite_view, label, fine) for label, fine in counts.items()]
    runs.append(("environment", render_environment_view, "render", counts["render"]))
    rays = cameras[0].width * cameras[0].height
    rows = []
    for what, render, label, fine in runs:
        model.spec = replace(model.spec, render=replace(spec, env_fine=fine))
        seconds = seconds_per_view(model, cameras, render)
        rows.append({"view": what, "env_fine": fine, "fine_samples": label, "seconds_per_view": seconds,
                     "rays_per_second": rays / seconds})
        print(f"{what:12s} env_fine {fine:4d} ({label:8s}) {seconds:7.2f} s/view  {rays / seconds:8.0f} rays/s",
              flush=True)
    record = {"date": datetime.now().isoformat(timespec="seconds"), "machine": machine(), "commit": commit(),
              "train": str(args.train), "views": [c.name for c in cameras],
              "size": [cameras[0].width, cameras[0].height], "results": rows}
    append_record(RESULTS, record)
    print(f"appended to {RESULTS}")


if __name__ == "__main__":
    main()
