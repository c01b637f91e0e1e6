"""Files a person opens without this code: depth and normal pictures, H.264 videos, coloured point clouds, and
the export's overview figure."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .imageio import linear_to_srgb, to_srgb8, write_exr, write_png


def depth_scale(depths: list[np.ndarray]) -> tuple[float, float]:
    """One colour scale for depth pictures: the 1st and 99th percentiles of every finite depth."""
    finite = np.concatenate([d[np.isfinite(d)].ravel() for d in depths]) if depths else np.zeros(0)
    if finite.size == 0:
        return 0.0, 1.0
    lo, hi = (float(x) for x in np.percentile(finite, [1, 99]))
    return lo, hi if hi > lo else lo + 1.0


def depth_png(depth: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """``(H, W)`` depth -> ``(H, W, 3)`` uint8 turbo colours on [lo, hi]; non-finite depth black."""
    from matplotlib import colormaps

    t = np.clip((np.nan_to_num(depth, nan=hi, posinf=hi) - lo) / (hi - lo), 0, 1)
    rgb = colormaps["turbo"](t)[..., :3]
    rgb[~np.isfinite(depth)] = 0
    return np.round(rgb * 255).astype(np.uint8)


def normal_png(normal: np.ndarray) -> np.ndarray:
    """World unit normals ``(H, W, 3)`` -> ``(n + 1) / 2`` as uint8 (zero normals: black)."""
    rgb = np.round(np.clip(normal * 0.5 + 0.5, 0, 1) * 255).astype(np.uint8)
    rgb[np.linalg.norm(normal, axis=-1) < 1e-6] = 0
    return rgb


def write_video(path: Path, frames: list[np.ndarray], fps: int) -> Path:
    """``(H, W, 3)`` uint8 frames -> H.264 MP4 (imageio-ffmpeg's bundled ffmpeg, yuv420p for players)."""
    import imageio_ffmpeg

    h, w = frames[0].shape[:2]
    writer = imageio_ffmpeg.write_frames(str(path), (w, h), fps=fps, codec="libx264", pix_fmt_out="yuv420p",
                                         macro_block_size=2, quality=8)
    writer.send(None)
    try:
        for frame in frames:
            writer.send(np.ascontiguousarray(frame, np.uint8))
    finally:
        writer.close()
    return path


def write_environment_view(folder: Path, name: str, view: dict[str, np.ndarray], scale: tuple[float, float]) -> None:
    """``<name>_rgb.exr``, ``_depth.exr``, ``_rgb.png`` (sRGB) and ``_depth.png`` (turbo on ``scale``)."""
    write_exr(folder / f"{name}_rgb.exr", view["rgb"].astype(np.float32))
    write_exr(folder / f"{name}_depth.exr", view["depth"].astype(np.float32))
    write_png(folder / f"{name}_rgb.png", to_srgb8(view["rgb"]))
    write_png(folder / f"{name}_depth.png", depth_png(view["depth"], *scale))


def write_point_cloud(path: Path, points: np.ndarray, colors: np.ndarray, transform: np.ndarray | None = None) -> Path:
    """Points ``(N, 3)`` with colours ``(N, 3)`` in [0, 1] as a binary PLY, moved by the 4x4 ``transform``."""
    import open3d as o3d

    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    pcd.colors = o3d.utility.Vector3dVector(colors)
    if transform is not None:
        pcd.transform(np.asarray(transform, np.float64))
    if not o3d.io.write_point_cloud(str(path), pcd, write_ascii=False):
        raise OSError(f"{path}: open3d could not write the point cloud")
    return path


def overview(path: Path, panorama: dict[str, np.ndarray], env_views: dict[str, dict[str, np.ndarray]],
             objects: dict[str, dict[str, np.ndarray]], scale: tuple[float, float]) -> Path:
    """One picture: the panorama (RGB, depth), the cube faces (RGB, depth), the first object render's parts."""
    from matplotlib.figure import Figure

    cube = [n for n in env_views if n.startswith("cube_")]
    columns = max(len(cube), 4)
    columns += columns % 2
    rows = 3 + (1 if objects else 0)
    tile = 1.8
    fig = Figure(figsize=(columns * tile, (rows + 0.6) * tile), dpi=110, layout="constrained")
    grid = fig.add_gridspec(rows, columns, height_ratios=[1.6] + [1] * (rows - 1))
    half = columns // 2
    ax = fig.add_subplot(grid[0, :half])
    ax.imshow(linear_to_srgb(panorama["rgb"]), interpolation="nearest")
    ax.set_title("panorama from the centre (environment field)", fontsize=8)
    ax.set_axis_off()
    ax = fig.add_subplot(grid[0, half:])
    im = ax.imshow(np.where(np.isfinite(panorama["depth"]), panorama["depth"], np.nan), cmap="turbo",
                   vmin=scale[0], vmax=scale[1], interpolation="nearest")
    fig.colorbar(im, ax=ax, fraction=0.03, pad=0.01, label="depth (object radii)")
    ax.set_title("panorama depth", fontsize=8)
    ax.set_axis_off()
    for c, name in enumerate(cube):
        for r, (image, kw) in enumerate(((linear_to_srgb(env_views[name]["rgb"]), {}),
                                         (env_views[name]["depth"], {"cmap": "turbo", "vmin": scale[0],
                                                                     "vmax": scale[1]}))):
            ax = fig.add_subplot(grid[1 + r, c])
            ax.imshow(image, interpolation="nearest", **kw)
            ax.set_axis_off()
            if r == 0:
                ax.set_title(name, fontsize=8)
    if objects:
        name, view = next(iter(objects.items()))
        parts = [("combined", linear_to_srgb(view["rgb"])), ("diffuse", linear_to_srgb(view["diffuse"])),
                 ("specular", linear_to_srgb(view["specular"])), ("normals", normal_png(view["normal"]))]
        for c, (title, image) in enumerate(parts):
            ax = fig.add_subplot(grid[3, c])
            ax.imshow(image, interpolation="nearest")
            ax.set_title(f"{name}: {title}", fontsize=8)
            ax.set_axis_off()
    fig.savefig(path)
    return path
