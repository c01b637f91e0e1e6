"""Where to cast virtual cones: cost and effect of casting them at the top-k weight samples of each ray.

The paper's code casts one cone per primary sample (~190 per ray). This renders the same random object
pixels of a synthetic capture with a trained model, casting cones at the k highest-weight samples for
several k (k = every sample reproduces the one-cone-per-sample choice), and reports the time per ray and
the specular PSNR against the ground truth and against the every-sample render.

    python bench/cone_samples.py results/demo/train captures/demo --decode results/demo/decode

Writes bench/results/cone_samples.json.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import time
from pathlib import Path

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import numpy as np  # noqa: E402
import torch  # noqa: E402

from orca.rays import camera_rays  # noqa: E402
from pipeline.imageio import read_exr  # noqa: E402
from pipeline.metrics import psnr_linear  # noqa: E402
from pipeline.model_io import load_model  # noqa: E402
from pipeline.training_data import load_image_set  # noqa: E402

RESULTS = Path(__file__).parent / "results"


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("train", type=Path)
    p.add_argument("capture", type=Path, help="synthetic capture folder (with ground_truth/)")
    p.add_argument("--decode", type=Path, required=True)
    p.add_argument("--rays", type=int, default=4096)
    p.add_argument("--ks", type=int, nargs="+", default=[1, 2, 4, 8])
    p.add_argument("--out", type=Path, default=RESULTS / "cone_samples.json")
    args = p.parse_args()

    gt = args.capture / "ground_truth"
    factor = json.loads((gt / "scene.json").read_text())["radiance_to_decoded"]["factor"]
    data, names = load_image_set(args.decode, gt / "cameras.json", gt / "masks")
    # random object pixels, rays through their centres
    g = torch.Generator().manual_seed(0)
    obj = data.masks.reshape(-1).nonzero().squeeze(-1)
    flat = obj[torch.randint(0, obj.numel(), (args.rays,), generator=g)]
    n, h, w = data.shape
    img, row, col = flat // (h * w), flat % (h * w) // w, flat % w
    uv = torch.stack([col, row], -1).float() + 0.5
    origins, dirs, radii = camera_rays(uv, data.K[img], data.c2w[img])
    specular_gt = np.stack([read_exr(gt / "specular" / f"{name}.exr")[..., :3] * factor for name in names])
    target = specular_gt[img.numpy(), row.numpy(), col.numpy()]

    model = load_model(args.train)
    samples = model.spec.render.band_samples or (model.spec.render.n_coarse + model.spec.render.n_fine)
    rows, reference = [], None
    for k in sorted({*args.ks, samples}, reverse=True):
        model.spec = dataclasses.replace(model.spec, render=dataclasses.replace(model.spec.render, cone_samples=k,
                                                                                deterministic=True))
        torch.manual_seed(0)
        t0 = time.perf_counter()
        out = model(origins, dirs, radii)
        seconds = time.perf_counter() - t0
        spec = out.specular.detach().numpy()
        if reference is None:
            reference = spec
        rows.append({"cone_samples": k, "every_sample": k == samples, "ms_per_1k_rays": 1e3 * seconds / args.rays * 1e3,
                     "specular_psnr_vs_gt": psnr_linear(spec, target),
                     "specular_psnr_vs_every_sample": psnr_linear(spec, reference)})
        r = rows[-1]
        print(f"k={k:3d}{' (every sample)' if r['every_sample'] else '':15s} {r['ms_per_1k_rays']:8.1f} ms/1k rays  "
              f"specular PSNR vs GT {r['specular_psnr_vs_gt']:.2f} dB, "
              f"vs every-sample {r['specular_psnr_vs_every_sample']:.2f} dB",
              flush=True)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps({"train": str(args.train), "rays": args.rays, "results": rows}, indent=2) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
