"""Build docs/demo.png, the README's picture: photos of the demo capture (decoded from its DNGs) and the
ground truth that comes with them (normals, diffuse, specular, an environment view and its depth).

    python docs/make_figure.py [--capture captures/demo] [--out docs/demo.png]
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import cv2
import numpy as np

from pipeline.config import DecodeConfig
from pipeline.imageio import read_exr, to_srgb8, write_png
from pipeline.results import load_decode
from pipeline.stages.decode import run_decode

TILE_HEIGHT = 180


def _fit(img: np.ndarray) -> np.ndarray:
    h, w = img.shape[:2]
    return cv2.resize(img, (round(w * TILE_HEIGHT / h), TILE_HEIGHT), interpolation=cv2.INTER_AREA)


def _label(img: np.ndarray, text: str) -> np.ndarray:
    img = img.copy()
    cv2.putText(img, text, (6, 18), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (0, 0, 0), 3, cv2.LINE_AA)
    cv2.putText(img, text, (6, 18), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 255, 255), 1, cv2.LINE_AA)
    return img


def _depth_colour(depth: np.ndarray) -> np.ndarray:
    finite = np.isfinite(depth) & (depth > 0)
    d = np.where(finite, depth, np.nan)
    lo, hi = np.nanpercentile(d, 2), np.nanpercentile(d, 98)
    norm = np.nan_to_num((d - lo) / max(hi - lo, 1e-6), nan=1.0).clip(0, 1)
    return cv2.cvtColor(cv2.applyColorMap((255 * (1 - norm)).astype(np.uint8), cv2.COLORMAP_VIRIDIS), cv2.COLOR_BGR2RGB)


def make_figure(capture: Path, out: Path) -> Path:
    gt = capture / "ground_truth"
    with tempfile.TemporaryDirectory() as tmp:
        run_decode(capture, Path(tmp) / "decode", DecodeConfig())
        dec = load_decode(Path(tmp) / "decode")
        names = dec.names
        picks = [names[i * len(names) // 4] for i in range(4)]
        photos = [_label(_fit(dec.srgb(n)), f"photo {n} (DNG)") for n in picks]
    name = picks[0]
    scale = float(np.median(read_exr(gt / "linear" / f"{name}.exr")))  # same exposure for the three renders
    normal = read_exr(gt / "normals" / f"{name}.exr")[..., :3]
    mask = np.isfinite(normal).all(-1) & (np.abs(normal).sum(-1) > 0)
    normal_rgb = np.where(mask[..., None], np.nan_to_num(normal) * 0.5 + 0.5, 0.0)
    truth = [
        _label(_fit(np.round(normal_rgb.clip(0, 1) * 255).astype(np.uint8)), "normals"),
        _label(_fit(to_srgb8(read_exr(gt / "diffuse" / f"{name}.exr")[..., :3] * 0.18 / scale)), "diffuse"),
        _label(_fit(to_srgb8(read_exr(gt / "specular" / f"{name}.exr")[..., :3] * 0.18 / scale)), "specular"),
    ]
    env_rgb = sorted((gt / "environment" / "rgb").glob("*.exr"))
    env_view = env_rgb[0]
    env = read_exr(env_view)[..., :3]
    truth += [
        _label(_fit(to_srgb8(env * 0.18 / max(float(np.median(env)), 1e-6))), f"environment {env_view.stem}"),
        _label(_fit(_depth_colour(read_exr(gt / "environment" / "depth" / env_view.name))), "its depth"),
    ]

    def row(tiles):
        return np.concatenate(tiles, axis=1)

    top, bottom = row(photos), row(truth)
    width = max(top.shape[1], bottom.shape[1])
    pad = lambda r: np.pad(r, ((0, 0), (0, width - r.shape[1]), (0, 0)), constant_values=255)  # noqa: E731
    return write_png(out, np.concatenate([pad(top), pad(bottom)], axis=0))


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--capture", type=Path, default=Path("captures/demo"))
    ap.add_argument("--out", type=Path, default=Path("docs/demo.png"))
    a = ap.parse_args()
    print(make_figure(a.capture, a.out))
