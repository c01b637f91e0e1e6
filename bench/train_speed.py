"""Training and rendering speed per preset: seconds per iteration, training rays/s, rendering rays/s.
A step draws what `orca train`'s joint phase draws: object, background and sparse-depth rays.

    python bench/train_speed.py                       # every preset, on CUDA if there is a GPU, else CPU
    python bench/train_speed.py --device cpu --presets fast --steps 20
    python bench/train_speed.py --presets fast --results results/demo    # on the demo's own inputs
    python bench/train_speed.py --presets fast --batch-scales 1 4 16 64 --profile    # rays/s against batch size

--batch-scales multiplies every kind of ray a step draws (object, background, sparse depth): on a GPU the rays
per second grow with it for as long as a step is bound by launching kernels rather than by their work.
--profile adds, on a GPU, the kernels one step launches and the share of the step's wall time the GPU is busy;
on a CPU, the operations one step runs on the GPU's code path (views and other metadata-only operations left out):
what a GPU step launches as kernels, measurable without one.

The data are a synthetic ring of posed images of a sphere-sized object (the speed of a step hardly depends on
the pixels' values), so the benchmark needs no capture; --results times the inputs of a DAG's run instead.
Prints a table and writes bench/results/train_speed_<device>.json with the machine's description.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from pathlib import Path

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import numpy as np  # noqa: E402
import torch  # noqa: E402

from orca.data import ImageSet, SparseDepth  # noqa: E402
from orca.model import OrcaModel, objective  # noqa: E402
from pipeline.cameras import intrinsics_from_fov, look_at  # noqa: E402
from pipeline.config import PRESETS, load_config  # noqa: E402

try:
    from pipeline.model_io import loss_weights, model_spec, resolve_device  # noqa: E402
except ImportError:  # an earlier tree (bench/demo_dag.py --baseline) kept them in its train stage
    from pipeline.stages.train import loss_weights, model_spec, resolve_device  # noqa: E402

RESULTS = Path(__file__).parent / "results"
VIEWS, WIDTH, HEIGHT, FOV_DEG, DISTANCE = 16, 320, 240, 40.0, 4.0
DEPTH_POINTS_PER_VIEW = 500


def synthetic_images(device: torch.device) -> ImageSet:
    """``VIEWS`` cameras on a ring looking at the unit sphere; mask = the sphere's silhouette; sparse depth at
    random pixels (as the poses stage's points of the surroundings give it)."""
    fx, fy, cx, cy = intrinsics_from_fov(WIDTH, HEIGHT, FOV_DEG)
    K = np.array([[fx, 0, cx], [0, fy, cy], [0, 0, 1.0]])
    angles = np.linspace(0, 2 * np.pi, VIEWS, endpoint=False)
    c2w = np.stack([look_at(DISTANCE * np.array([np.cos(a), np.sin(a), 0.4]), np.zeros(3)) for a in angles])
    v, u = np.mgrid[0:HEIGHT, 0:WIDTH]
    r = np.hypot(u + 0.5 - cx, v + 0.5 - cy)
    silhouette = r < fx / np.sqrt(DISTANCE**2 * 1.16 - 1)  # the unit sphere's angular radius, roughly
    g = torch.Generator().manual_seed(0)
    images = torch.rand(VIEWS, HEIGHT, WIDTH, 3, generator=g)
    masks = torch.from_numpy(np.broadcast_to(silhouette, (VIEWS, HEIGHT, WIDTH)).copy())
    valid = torch.ones_like(masks)
    f32 = lambda a: torch.from_numpy(np.asarray(a, dtype=np.float32))  # noqa: E731
    points = DEPTH_POINTS_PER_VIEW * VIEWS
    uv = torch.rand(points, 2, generator=g) * torch.tensor([WIDTH, HEIGHT])
    depth = SparseDepth(torch.arange(points) % VIEWS, uv, 2 * DISTANCE * (1 + torch.rand(points, generator=g)))
    return ImageSet(images, masks, valid, f32(np.broadcast_to(K, (VIEWS, 3, 3))), f32(c2w), depth=depth).to(device)


def capture_images(results: Path, cfg):
    """The training inputs `orca train` reads from a DAG's results folder (the images the masks stage's cameras
    point at, as the Snakefile finds them; its masks; the poses stage's points), and ``cfg`` with the
    environment's reach from those points."""
    from pipeline.cameras import load_cameras
    from pipeline.results import image_folder
    from pipeline.training import with_far_from_points
    from pipeline.training_data import load_image_set

    cameras, points = results / "masks" / "cameras.json", results / "poses" / "sparse"
    images = image_folder(load_cameras(cameras), cameras.parent, results / "decode")
    data, _ = load_image_set(images, cameras, results / "masks" / "masks", points, cfg.sampler.depth_object_margin_px)
    return data, with_far_from_points(cfg, data, points)


def scaled(cfg, scale: float):
    """``cfg`` with every kind of ray a step draws multiplied by ``scale``."""
    if scale == 1:
        return cfg
    n = lambda k: max(int(round(k * scale)), 1) if k else 0  # noqa: E731
    sampler = cfg.sampler.model_copy(update={"background_rays": n(cfg.sampler.background_rays),
                                             "depth_rays": n(cfg.sampler.depth_rays)})
    return cfg.model_copy(update={"batch_rays": n(cfg.batch_rays), "sampler": sampler})


def kernel_profile(step, device: torch.device) -> dict:
    """Kernels one ``step`` launches on the GPU and the share of its wall time they keep the GPU busy."""
    from torch.profiler import ProfilerActivity, profile

    torch.cuda.synchronize()
    with profile(activities=[ProfilerActivity.CPU, ProfilerActivity.CUDA]) as prof:
        t0 = time.perf_counter()
        step()
        torch.cuda.synchronize()
        wall = time.perf_counter() - t0
    kernels = [e for e in prof.events() if e.device_type == torch.autograd.DeviceType.CUDA]
    busy = sum(e.device_time for e in kernels) * 1e-6  # device_time is in microseconds
    return {"kernels_per_step": len(kernels), "gpu_busy_fraction": busy / wall, "profiled_step_seconds": wall}


# aten operations that move no data (views, shapes, allocation): no kernel on a GPU
_METADATA_OPS = {"view", "as_strided", "_reshape_alias", "expand", "permute", "t", "transpose", "unsqueeze", "squeeze",
                 "select", "slice", "detach", "alias", "split", "split_with_sizes", "unbind", "view_as_real",
                 "view_as_complex", "_unsafe_view", "diagonal", "unfold", "lift_fresh", "resolve_conj", "resolve_neg",
                 "empty", "empty_strided", "empty_like", "new_empty", "new_empty_strided", "_local_scalar_dense",
                 "is_nonzero", "sym_size", "sym_stride"}


def operation_count(step) -> dict:
    """Operations one ``step`` runs on the CPU through the tensor path a GPU takes (the environment field's fused
    CPU lookup, :mod:`orca.hashgrid_cpu`, is switched off), metadata-only ones left out."""
    from torch.utils._python_dispatch import TorchDispatchMode

    import orca.hashgrid_cpu as fused

    class Count(TorchDispatchMode):
        n = 0

        def __torch_dispatch__(self, func, types, args=(), kwargs=None):
            if func.__name__.split(".")[0] not in _METADATA_OPS:
                Count.n += 1
            return func(*args, **(kwargs or {}))

    usable, fused.usable = fused.usable, lambda *a: False
    try:
        with Count():
            step()
    finally:
        fused.usable = usable
    return {"operations_per_step": Count.n}


def bench_preset(preset: str, device: torch.device, steps: int, warmup: int, results: Path | None = None,
                 scale: float = 1.0, profile: bool = False) -> dict:
    cfg = scaled(load_config(preset=preset).train, scale)
    torch.manual_seed(0)
    if results is None:
        data = synthetic_images(device)
    else:
        data, cfg = capture_images(results, cfg)
        data = data.to(device)
    model = OrcaModel(model_spec(cfg)).to(device)
    optimizer = torch.optim.Adam(model.parameters(), lr=cfg.lr, eps=1e-15)
    weights = loss_weights(cfg)
    g = torch.Generator().manual_seed(0)

    def sync() -> None:
        if device.type == "cuda":
            torch.cuda.synchronize()

    # an earlier tree (bench/demo_dag.py --baseline) kept the sampler's keys in train itself
    sampler = getattr(cfg, "sampler", cfg)
    use_depth = sampler.depth_rays > 0 and cfg.losses.sparse_depth > 0

    def step() -> None:
        batch = data.sample(cfg.batch_rays, sampler.object_fraction, g)
        # the off-object rays of the environment field and the sparse depth's, as `orca train` draws them
        background = data.sample_background(sampler.background_rays, g) if sampler.background_rays else None
        depth = data.sample_depth(sampler.depth_rays, g) if use_depth else None
        total, _, _ = objective(model, batch, weights, "joint", background, depth)
        optimizer.zero_grad(set_to_none=True)
        total.backward()
        torch.nn.utils.clip_grad_norm_(model.parameters(), cfg.grad_clip)
        optimizer.step()

    for _ in range(warmup):
        step()
    sync()
    if device.type == "cuda":
        torch.cuda.reset_peak_memory_stats()
    t0 = time.perf_counter()
    for _ in range(steps):
        step()
    sync()
    per_step = (time.perf_counter() - t0) / steps
    kernels = ({} if not profile else kernel_profile(step, device) if device.type == "cuda"
               else operation_count(step))

    # Rendering (evaluation): object rays, no parameter gradients.
    batch = data.sample(cfg.batch_rays, 1.0, g)
    model.eval()
    with torch.no_grad():
        model(batch.origins, batch.dirs, batch.radii)
        sync()
        t0 = time.perf_counter()
        for _ in range(max(steps // 2, 1)):
            model(batch.origins, batch.dirs, batch.radii)
        sync()
        render_s = (time.perf_counter() - t0) / max(steps // 2, 1)
    return {
        "preset": preset, "batch_scale": scale, "batch_rays": cfg.batch_rays,
        "background_rays": sampler.background_rays, "depth_rays": sampler.depth_rays if use_depth else 0,
        "iterations": cfg.iterations,
        "seconds_per_iteration": per_step, "train_rays_per_second": cfg.batch_rays / per_step,
        "all_rays_per_second": (cfg.batch_rays + sampler.background_rays
                                + (sampler.depth_rays if use_depth else 0)) / per_step,
        "render_rays_per_second": cfg.batch_rays / render_s,
        "full_training_minutes": per_step * cfg.iterations / 60,
        "peak_gpu_memory_gb": torch.cuda.max_memory_allocated() / 2**30 if device.type == "cuda" else None,
        **kernels,
    }


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--presets", nargs="+", default=list(PRESETS), choices=list(PRESETS))
    p.add_argument("--device", default="auto", choices=["auto", "cpu", "cuda"])
    p.add_argument("--steps", type=int, default=10, help="timed iterations per preset")
    p.add_argument("--warmup", type=int, default=3)
    p.add_argument("--out", type=Path, default=None)
    p.add_argument("--results", type=Path, default=None,
                   help="time on a capture's own inputs: a DAG's results/<capture> folder (decode, poses, masks)")
    p.add_argument("--batch-scales", type=float, nargs="+", default=[1.0],
                   help="multiply every kind of ray a step draws by each of these in turn")
    p.add_argument("--profile", action="store_true",
                   help="on a GPU: kernels per step, GPU busy share; on a CPU: operations per step")
    args = p.parse_args()
    device = resolve_device(args.device)
    rows = []
    for preset in args.presets:
        for scale in args.batch_scales:
            row = bench_preset(preset, device, args.steps, args.warmup, args.results, scale, args.profile)
            rows.append(row)
            busy = (f"; {row['kernels_per_step']} kernels, GPU busy {100 * row['gpu_busy_fraction']:.0f} %"
                    if "kernels_per_step" in row
                    else f"; {row['operations_per_step']} operations" if "operations_per_step" in row else "")
            print(f"{preset:9s} x{scale:<4g} {row['seconds_per_iteration']:8.3f} s/it  "
                  f"{row['train_rays_per_second']:9.0f} train rays/s  "
                  f"{row['render_rays_per_second']:9.0f} render rays/s  (batch {row['batch_rays']} + "
                  f"{row['background_rays']} background; "
                  f"{row['iterations']} iterations = {row['full_training_minutes']:.1f} min{busy})", flush=True)
    machine = {
        "device": (torch.cuda.get_device_name(0) if device.type == "cuda"
                   else platform.processor() or platform.machine()),
        "cpu_threads": torch.get_num_threads(), "torch": torch.__version__, "platform": platform.platform(),
    }
    out = args.out or RESULTS / f"train_speed_{device.type}.json"
    out.parent.mkdir(parents=True, exist_ok=True)
    inputs = str(args.results) if args.results else "synthetic ring of 16 views"
    out.write_text(json.dumps({"machine": machine, "steps": args.steps, "inputs": inputs, "results": rows}, indent=2)
                   + "\n")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
