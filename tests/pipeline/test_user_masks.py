"""User masks (pipeline.mask_file, pipeline.user_masks): every encoding reads the same, another scale is resized
and another aspect refused, mask files must match the photos."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from pipeline.errors import InputError
from pipeline.imageio import write_png
from pipeline.mask_file import read_mask
from pipeline.metrics import iou
from pipeline.user_masks import find_user_masks


def disc_mask(h: int = 36, w: int = 48) -> np.ndarray:
    y, x = np.mgrid[:h, :w]
    return (x - 20) ** 2 + (y - 18) ** 2 < 10**2


@pytest.mark.parametrize("encoding", ["0/255", "0/1", "16-bit", "rgb", "alpha", "la"])
def test_every_mask_encoding_reads_the_same(tmp_path, encoding):
    truth = disc_mask()
    m = truth.astype(np.uint8)
    path = tmp_path / "IMG_0001.png"
    if encoding == "0/255":
        write_png(path, m * 255)
    elif encoding == "0/1":
        write_png(path, m)
    elif encoding == "16-bit":
        write_png(path, m.astype(np.uint16) * 65535)
    elif encoding == "rgb":
        write_png(path, np.dstack([m * 255] * 3))
    elif encoding == "alpha":  # a cut-out: the photo in RGB, the object in alpha
        photo = np.random.default_rng(0).integers(0, 255, (36, 48, 3), dtype=np.uint8)
        write_png(path, np.dstack([photo, m * 255]))
    else:  # grey + alpha, as some editors save (OpenCV cannot write it: Pillow)
        from PIL import Image

        Image.fromarray(np.dstack([np.full_like(m, 128), m * 255]), mode="LA").save(path)
    np.testing.assert_array_equal(read_mask(path, (48, 36)), truth)


def test_a_mask_at_another_scale_is_resized_and_another_aspect_is_refused(tmp_path):
    big = cv2.resize(disc_mask().astype(np.uint8) * 255, (96, 72), interpolation=cv2.INTER_NEAREST)
    write_png(tmp_path / "a.png", big)
    assert iou(read_mask(tmp_path / "a.png", (48, 36)), disc_mask()) > 0.95
    write_png(tmp_path / "b.png", np.zeros((48, 36), np.uint8))  # rotated: 36x48 for a 48x36 photo
    with pytest.raises(InputError, match=r"b\.png.*36x48.*48x36.*aspect ratio"):
        read_mask(tmp_path / "b.png", (48, 36))
    (tmp_path / "c.png").write_bytes(b"not a png")
    with pytest.raises(InputError, match=r"c\.png.*not a readable image"):
        read_mask(tmp_path / "c.png", (48, 36))


def test_a_0_255_mask_resized_by_a_fraction_stays_8_bit(tmp_path):
    # An area resize by 111/300 sums 255s into 255.00003: still an 8-bit mask, not a nearly empty 16-bit one.
    big = np.zeros((200, 300), np.uint8)
    big[50:150, 75:225] = 255
    write_png(tmp_path / "a.png", big)
    small = read_mask(tmp_path / "a.png", (111, 74))
    assert 0.2 < small.mean() < 0.3


def test_mask_names_must_match_the_photos(tmp_path):
    names = ["IMG_0001", "IMG_0002"]
    for f in ("IMG_0001.png", "IMG_0002.jpg.png"):  # our naming, and COLMAP's <image>.png
        write_png(tmp_path / f, disc_mask().astype(np.uint8) * 255)
    (tmp_path / "notes.txt").write_text("skipped with a warning")
    found = find_user_masks(tmp_path, names)
    assert sorted(found) == names and found["IMG_0002"].name == "IMG_0002.jpg.png"
    write_png(tmp_path / "IMG_0001_mask.png", disc_mask().astype(np.uint8))
    with pytest.raises(InputError, match=r"1 mask file\(s\) match no photo: IMG_0001_mask\.png.*photos: IMG_0001"):
        find_user_masks(tmp_path, names)
    with pytest.raises(InputError, match="user masks folder not found"):
        find_user_masks(tmp_path / "nope", names)
