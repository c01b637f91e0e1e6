"""Procedural poster-like textures: shapes of many sizes in strong, flat colours (and plain tiles).

Why posters and not noise: SfM on low-resolution, noisy Monte Carlo renders needs features that survive
both. Fine random noise averages out to grey at a distance and is drowned by render noise up close (a
40-view 320x240 test of such a room registered 11 views). Posters (blobs, stripes, rings, letters) have
edges and corners at every scale, so every distance finds structure of its own size.

Everything is drawn with OpenCV on an 8-bit sRGB canvas (anti-aliased) and returned as *linear* reflectance
``(H, W, 3)`` float32, mapped into ``[lo, hi]`` so no surface is a perfect black or a perfect white.
"""

from __future__ import annotations

import string
from dataclasses import dataclass

import cv2
import numpy as np

from ..imageio import srgb_to_linear

# A high-contrast palette (sRGB 8-bit): darks, lights and saturated colours, like printed posters.
POSTER_PALETTE: tuple[tuple[int, int, int], ...] = (
    (20, 20, 24),
    (245, 243, 235),
    (220, 40, 40),
    (250, 200, 30),
    (30, 90, 200),
    (40, 160, 70),
    (240, 120, 30),
    (130, 50, 160),
    (40, 190, 200),
    (250, 150, 180),
    (90, 60, 40),
    (150, 150, 150),
)

_GLYPHS = string.ascii_uppercase + string.digits + "#&@%?"
_FONTS = (
    cv2.FONT_HERSHEY_SIMPLEX,
    cv2.FONT_HERSHEY_DUPLEX,
    cv2.FONT_HERSHEY_COMPLEX,
    cv2.FONT_HERSHEY_TRIPLEX,
    cv2.FONT_HERSHEY_PLAIN,
)
SHAPE_KINDS = ("disc", "ring", "rect", "stripes", "triangle", "blob", "glyphs", "checker")


@dataclass(frozen=True)
class PosterStyle:
    """How a poster looks. Scales are fractions of the texture's shorter side."""

    shapes_per_megapixel: float = 900.0  # density of shapes (more for bigger textures, so detail stays)
    min_scale: float = 0.006  # smallest shape (a few texels on a 1k texture: fine detail up close)
    max_scale: float = 0.45  # largest shape (coarse structure seen from across the room)
    glyph_weight: float = 0.25  # share of shapes that are letters/digits
    reflectance: tuple[float, float] = (0.04, 0.8)  # linear reflectance range the sRGB [0, 1] maps onto
    palette: tuple[tuple[int, int, int], ...] = POSTER_PALETTE


def poster(width: int, height: int, seed: int, style: PosterStyle = PosterStyle()) -> np.ndarray:
    """A ``(height, width, 3)`` float32 linear-reflectance poster, deterministic in ``seed``.

    Shapes are drawn from the largest to the smallest, so large areas carry small details on top.
    """
    if width < 8 or height < 8:
        raise ValueError(f"poster: texture too small ({width}x{height})")
    rng = np.random.default_rng(seed)
    palette = np.asarray(style.palette, dtype=np.int32)
    side = min(width, height)
    canvas = np.empty((height, width, 3), np.uint8)
    canvas[:] = palette[rng.integers(len(palette))]

    n = max(12, int(style.shapes_per_megapixel * width * height / 1e6))
    # Log-uniform sizes: as many shapes per octave of size, i.e. structure at every scale.
    scales = np.exp(rng.uniform(np.log(style.min_scale), np.log(style.max_scale), size=n)) * side
    scales = np.sort(scales)[::-1]
    weights = np.ones(len(SHAPE_KINDS))
    # glyph_weight is the glyphs' share of all shapes; the other kinds share the rest equally.
    weights[SHAPE_KINDS.index("glyphs")] = style.glyph_weight * (len(SHAPE_KINDS) - 1) / (1 - style.glyph_weight)
    kinds = rng.choice(len(SHAPE_KINDS), size=n, p=weights / weights.sum())
    for size, kind in zip(scales, kinds):
        colour = tuple(int(c) for c in palette[rng.integers(len(palette))])
        centre = np.array([rng.uniform(0, width), rng.uniform(0, height)])
        _DRAW[SHAPE_KINDS[kind]](canvas, rng, centre, float(max(size, 2.0)), colour, palette)

    lo, hi = style.reflectance
    return (lo + (hi - lo) * srgb_to_linear(canvas.astype(np.float32) / 255.0)).astype(np.float32)


def tile(size_px: int, grout_px: float, colour, grout_colour) -> np.ndarray:
    """One ``(size_px, size_px, 3)`` float32 tile of linear ``colour`` framed by half a grout line of
    ``grout_colour`` on each side, so that repeating it draws a regular grid of identical tiles with grout lines
    ``grout_px`` texels wide. Texels on a line's edge hold the area-weighted mix (anti-aliased)."""
    if size_px < 4 or not 0 < grout_px < size_px:
        raise ValueError(f"tile: need size_px >= 4 and 0 < grout_px < size_px, got {size_px}, {grout_px}")
    lo = np.arange(size_px, dtype=np.float64)
    half = grout_px / 2
    # overlap of texel [i, i + 1] with the grout bands [0, half) and [size - half, size)
    band = np.clip(half - lo, 0, 1) + np.clip(lo + 1 - (size_px - half), 0, 1)
    grout = 1 - np.outer(1 - band, 1 - band)  # a texel is grout where either direction's band covers it
    c, g = np.asarray(colour, np.float64), np.asarray(grout_colour, np.float64)
    return (c * (1 - grout[..., None]) + g * grout[..., None]).astype(np.float32)


def _pt(p: np.ndarray) -> tuple[int, int]:
    # OpenCV draws with sub-pixel precision when given `shift` bits; 4 bits = 1/16 px.
    return int(round(p[0] * 16)), int(round(p[1] * 16))


def _poly(canvas: np.ndarray, pts: np.ndarray, colour: tuple[int, int, int]) -> None:
    cv2.fillPoly(canvas, [np.round(pts * 16).astype(np.int32)], colour, lineType=cv2.LINE_AA, shift=4)


def _rot(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s], [s, c]])


def _disc(canvas, rng, centre, size, colour, palette):
    cv2.circle(canvas, _pt(centre), int(size * 8), colour, -1, lineType=cv2.LINE_AA, shift=4)


def _ring(canvas, rng, centre, size, colour, palette):
    thick = max(1, int(size * rng.uniform(0.08, 0.3)))
    cv2.circle(canvas, _pt(centre), int(size * 8), colour, thick, lineType=cv2.LINE_AA, shift=4)
    if rng.random() < 0.5:  # concentric target
        inner = tuple(int(c) for c in palette[rng.integers(len(palette))])
        cv2.circle(canvas, _pt(centre), int(size * 3), inner, -1, lineType=cv2.LINE_AA, shift=4)


def _rect(canvas, rng, centre, size, colour, palette):
    half = np.array([size, size * rng.uniform(0.2, 1.0)]) / 2
    corners = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) * half
    _poly(canvas, corners @ _rot(rng.uniform(0, np.pi)).T + centre, colour)


def _stripes(canvas, rng, centre, size, colour, palette):
    count = int(rng.integers(3, 8))
    angle = rng.uniform(0, np.pi)
    length = size * rng.uniform(0.8, 1.6)
    pitch = size / count
    other = tuple(int(c) for c in palette[rng.integers(len(palette))])
    for i in range(count):
        c = tuple(colour) if i % 2 == 0 else other
        offset = (i - (count - 1) / 2) * pitch
        corners = np.array([[-length / 2, offset - pitch / 2], [length / 2, offset - pitch / 2],
                            [length / 2, offset + pitch / 2], [-length / 2, offset + pitch / 2]])
        _poly(canvas, corners @ _rot(angle).T + centre, c)


def _triangle(canvas, rng, centre, size, colour, palette):
    angles = rng.uniform(0, 2 * np.pi) + np.array([0, 2, 4]) * np.pi / 3 + rng.uniform(-0.4, 0.4, 3)
    pts = np.stack([np.cos(angles), np.sin(angles)], -1) * size / 2
    _poly(canvas, pts + centre, colour)


def _blob(canvas, rng, centre, size, colour, palette):
    # A star-shaped closed curve: radius = 1 + a few low-frequency harmonics.
    t = np.linspace(0, 2 * np.pi, 64, endpoint=False)
    r = np.ones_like(t)
    for k in range(2, 6):
        r += rng.uniform(0, 0.35 / k * 2) * np.cos(k * t + rng.uniform(0, 2 * np.pi))
    r = np.clip(r, 0.25, None) * size / 2 / r.max()
    _poly(canvas, np.stack([r * np.cos(t), r * np.sin(t)], -1) + centre, colour)


def _glyphs(canvas, rng, centre, size, colour, palette):
    font = _FONTS[rng.integers(len(_FONTS))]
    text = "".join(rng.choice(list(_GLYPHS), size=int(rng.integers(1, 4))))
    base_h = cv2.getTextSize("H", font, 1.0, 1)[0][1]
    font_scale = size / max(base_h, 1) * 0.8
    thick = max(1, int(font_scale * rng.uniform(1.0, 3.0)))
    (tw, th), _ = cv2.getTextSize(text, font, font_scale, thick)
    org = (int(centre[0] - tw / 2), int(centre[1] + th / 2))
    cv2.putText(canvas, text, org, font, font_scale, colour, thick, lineType=cv2.LINE_AA)


def _checker(canvas, rng, centre, size, colour, palette):
    cells = int(rng.integers(2, 5))
    cell = size / cells
    angle = rng.uniform(0, np.pi)
    other = tuple(int(c) for c in palette[rng.integers(len(palette))])
    for i in range(cells):
        for j in range(cells):
            c = colour if (i + j) % 2 == 0 else other
            x0, y0 = (i - cells / 2) * cell, (j - cells / 2) * cell
            corners = np.array([[x0, y0], [x0 + cell, y0], [x0 + cell, y0 + cell], [x0, y0 + cell]])
            _poly(canvas, corners @ _rot(angle).T + centre, c)


_DRAW = {
    "disc": _disc,
    "ring": _ring,
    "rect": _rect,
    "stripes": _stripes,
    "triangle": _triangle,
    "blob": _blob,
    "glyphs": _glyphs,
    "checker": _checker,
}
