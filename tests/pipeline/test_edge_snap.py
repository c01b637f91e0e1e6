"""A working-size mask brought up to the photo's size and its outline moved onto the photo's edges
(pipeline.masking.scale.full_size_mask, snap_to_edges)."""

import cv2
import numpy as np

from pipeline.config import MasksConfig
from pipeline.masking.scale import edge_snap, full_size_mask, reduce
from pipeline.metrics import iou

SIZE, WORK = 256, 64  # the photo and the working size: 4x, as a 2000 px photo segmented at 480
SNAP = edge_snap(MasksConfig())  # the shipped defaults


def textured(colour, shape, seed):
    """``shape`` (H, W) of ``colour`` with blocks of +-20 levels of texture."""
    rng = np.random.default_rng(seed)
    blocks = rng.integers(-20, 21, (shape[0] // 8, shape[1] // 8, 3))
    texture = np.kron(blocks, np.ones((8, 8, 1), int))
    return np.clip(np.asarray(colour) + texture, 0, 255)


def photo_of(mask, object_colour=(200, 120, 40), room_colour=(40, 90, 160), blur=0.0):
    """A textured object (``mask`` (H, W) bool) on a textured room, as uint8 RGB, optionally blurred."""
    image = np.where(mask[..., None], textured(object_colour, mask.shape, 1), textured(room_colour, mask.shape, 2))
    image = image.astype(np.float32)
    if blur:
        image = cv2.GaussianBlur(image, (0, 0), blur)
    return np.round(image).astype(np.uint8)


def blob(radius, centre=(128.4, 121.7)):
    y, x = np.mgrid[0:SIZE, 0:SIZE]
    return np.hypot((x - centre[0]) / 1.3, y - centre[1]) < radius


def working_mask(truth, grow_px):
    """``truth`` at the working size, its outline a working pixel or so off (as segmentation leaves it)."""
    small = reduce(truth, (WORK, WORK)).astype(np.uint8)
    return cv2.dilate(small, np.ones((2 * grow_px + 1,) * 2, np.uint8)) > 0


def assert_left_as_brought_up(small, photo):
    """The snap leaves ``small``'s outline where the guided filter brought it up, and says so."""
    brought_up, _ = full_size_mask(small, photo)
    kept_mask, kept = full_size_mask(small, photo, SNAP)
    assert not kept and np.array_equal(kept_mask, brought_up)


def test_an_outline_a_working_pixel_off_is_moved_onto_the_photos_edge():
    truth = blob(70)
    photo = photo_of(truth)
    small = working_mask(truth, 1)
    brought_up, snapped_flag = full_size_mask(small, photo)
    snapped, kept = full_size_mask(small, photo, SNAP)
    assert not snapped_flag and kept
    assert iou(brought_up, truth) < 0.95  # 4 px too far out all round
    assert iou(snapped, truth) > 0.985
    # the band bounds what moves: nothing added beyond band_px working pixels (8 px here) of the outline
    far = cv2.dilate(brought_up.astype(np.uint8), np.ones((19, 19), np.uint8)) > 0
    assert not (snapped & ~far).any()


def test_a_soft_edge_keeps_the_outline_brought_up():
    """A blurred edge has its strongest gradient where the outline already is: no clearly stronger edge, no snap."""
    truth = blob(70)
    photo = photo_of(truth, blur=6.0)
    assert_left_as_brought_up(reduce(truth, (WORK, WORK)), photo)


def test_a_small_object_is_not_snapped():
    """An object a few working pixels across: the band would be most of it, so its outline stays."""
    truth = blob(14)
    photo = photo_of(truth)
    assert_left_as_brought_up(working_mask(truth, 1), photo)


def test_a_mask_at_the_photos_size_is_returned_as_is():
    truth = blob(70)
    mask, kept = full_size_mask(truth, photo_of(truth), SNAP)
    assert mask is truth and not kept
