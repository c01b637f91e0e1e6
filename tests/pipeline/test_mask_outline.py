"""The outline's pixels given to the side that covers most of them (pipeline.masking.outline)."""

import numpy as np
import pytest

from pipeline.imageio import linear_to_srgb
from pipeline.masking.outline import coverage, snap_outline

OBJECT, ROOM = np.array([0.7, 0.35, 0.1]), np.array([0.05, 0.15, 0.5])
OPTIONS = {"reach_px": 2, "min_contrast": 0.1, "margin": 0.1, "max_residual": 0.5}


def disc_photo(object_colour, room_colour, size=64, centre=(31.3, 30.6), radius=17.2, samples=8, noise=0.0):
    """An anti-aliased disc: each pixel the mix of the two colours by the share of it the disc covers (``samples``^2
    points per pixel), as sRGB uint8; and that share ``(H, W)``."""
    offsets = (np.arange(samples) + 0.5) / samples
    y, x = np.mgrid[0:size, 0:size].astype(float)
    covered = np.zeros((size, size))
    for dy in offsets:
        for dx in offsets:
            covered += np.hypot(x + dx - centre[0], y + dy - centre[1]) < radius
    share = covered / samples**2
    linear = share[..., None] * object_colour + (1 - share[..., None]) * room_colour
    linear = linear + np.random.default_rng(0).normal(0.0, noise, linear.shape)
    return np.round(linear_to_srgb(linear) * 255).astype(np.uint8), share


def test_a_mix_is_read_off_the_line_between_the_two_colours():
    f, b = np.broadcast_to(OBJECT, (1, 1, 3)), np.broadcast_to(ROOM, (1, 1, 3))
    mixed = 0.25 * f + 0.75 * b
    a, residual, contrast = coverage(mixed, f, b)
    assert a[0, 0] == pytest.approx(0.25) and residual[0, 0] == pytest.approx(0.0, abs=1e-6)
    assert contrast[0, 0] == pytest.approx(np.sqrt(np.mean((OBJECT - ROOM) ** 2)))
    d = OBJECT - ROOM
    across = np.array([d[1], -d[0], 0.0])  # perpendicular to the line: the share stays, the residual grows
    a, residual, _ = coverage(mixed + across, f, b)
    assert a[0, 0] == pytest.approx(0.25)
    assert residual[0, 0] == pytest.approx(np.linalg.norm(across) / np.linalg.norm(d))


@pytest.mark.parametrize("shift", ["grown", "shrunk"])
def test_an_outline_a_pixel_off_is_put_where_half_the_pixel_is_covered(shift):
    import cv2

    photo, share = disc_photo(OBJECT, ROOM, noise=0.005)
    truth = share >= 0.5
    cross = cv2.getStructuringElement(cv2.MORPH_CROSS, (3, 3))
    start = (cv2.dilate if shift == "grown" else cv2.erode)(truth.astype(np.uint8), cross) > 0
    snapped = snap_outline(photo, start, **OPTIONS)
    before, after = np.count_nonzero(start != truth), np.count_nonzero(snapped != truth)
    assert before > 60
    # only pixels the disc covers within the margin of one half may stay on either side
    assert after <= np.count_nonzero(np.abs(share - 0.5) < OPTIONS["margin"]) and after < before / 5


def test_what_is_no_mix_of_the_two_sides_stays():
    import cv2

    cross = cv2.getStructuringElement(cv2.MORPH_CROSS, (3, 3))
    # the two sides alike: no contrast to read a share from
    photo, share = disc_photo(OBJECT, OBJECT * 0.95)
    grown = cv2.dilate((share >= 0.5).astype(np.uint8), cross) > 0
    assert np.array_equal(snap_outline(photo, grown, **OPTIONS), grown)
    # certain background is never added, whatever its colour says
    photo, share = disc_photo(OBJECT, ROOM)
    shrunk = cv2.erode((share >= 0.5).astype(np.uint8), cross) > 0
    assert np.array_equal(snap_outline(photo, shrunk, **OPTIONS, keep_out=np.ones_like(shrunk)) & ~shrunk,
                          np.zeros_like(shrunk))
    # a highlight on the rim (white: off the line between the two colours) keeps its side
    photo, share = disc_photo(OBJECT, ROOM)
    ring = (share > 0.2) & (share < 0.8)
    photo[ring] = 255
    snapped = snap_outline(photo, shrunk, **OPTIONS)
    assert not np.any(snapped[ring] & ~shrunk[ring])
