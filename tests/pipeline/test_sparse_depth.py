"""Sparse depth from structure from motion: points projected into the photos that saw them, off the object,
and training rays through them that end at the points."""

from __future__ import annotations

import numpy as np
import torch

from pipeline.cameras import look_at
from pipeline.sparse_depth import SparsePoints, depth_observations

H, W = 60, 80
K = np.array([[70.0, 0, W / 2], [0, 70.0, H / 2], [0, 0, 1]])


def _cameras():
    eyes = [np.array([4.0, 0, 0]), np.array([0, 4.0, 0]), np.array([-4.0, 0, 0])]
    c2w = np.stack([look_at(e, np.zeros(3)) for e in eyes])
    return ["a", "b", "c"], np.stack([K] * 3), c2w


def _project(x, k, c2w):
    p = np.linalg.inv(c2w)[:3] @ np.append(x, 1.0)
    return (k @ (p / p[2]))[:2], float(np.linalg.norm(p))


def test_points_are_projected_into_their_photos_and_points_on_the_object_dropped():
    names, Ks, c2w = _cameras()
    masks = np.zeros((3, H, W), bool)
    masks[:, 25:35, 35:45] = True  # the object in the middle of every photo
    room = np.array([0.6, -0.7, 0.5])  # off the object in a and b
    on_object = np.array([0.0, 0.0, 0.05])  # projects into the mask's middle
    near_object = np.array([0.0, 0.0, 0.0]) + np.array([0.0, 0.0, 6.0 / 70.0 * 4.0])  # 1 px above the mask
    points = SparsePoints(np.stack([room, on_object, near_object]), [["a", "b", "zz"], ["a", "c"], ["b"]])
    obs = depth_observations(points, names, Ks, c2w, masks, object_margin_px=2)
    assert obs.points_used == 1 and obs.points_on_object == 2
    assert obs.image.tolist() == [0, 1]  # the unknown photo "zz" is ignored
    for i, uv, d in zip(obs.image, obs.uv, obs.distance):
        expect_uv, expect_d = _project(room, Ks[i], c2w[i])
        np.testing.assert_allclose(uv, expect_uv, atol=1e-9)
        assert d == np.float64(expect_d)
    # without a margin, the point just above the mask is used
    obs = depth_observations(points, names, Ks, c2w, masks, object_margin_px=0)
    assert obs.points_used == 2 and obs.points_on_object == 1


def test_points_behind_a_camera_or_outside_its_photo_are_not_observations():
    names, Ks, c2w = _cameras()
    masks = np.zeros((3, H, W), bool)
    behind_a = np.array([6.0, 0.0, 0.0])  # behind camera a (at x = 4 looking at the origin)
    outside = np.array([0.0, 0.0, 3.5])  # far above the field of view of all three
    obs = depth_observations(SparsePoints(np.stack([behind_a, outside]), [["a", "c"], ["a", "b"]]), names, Ks,
                             c2w, masks, 2)
    assert obs.image.tolist() == [2] and obs.points_used == 1


def test_sampled_depth_rays_end_at_their_points():
    from orca.data import ImageSet, SparseDepth

    names, Ks, c2w = _cameras()
    rng = np.random.default_rng(0)
    room = rng.uniform(-2, 2, (20, 3)) * np.array([1, 1, 0.3]) + np.array([0, 0, 1.0])
    points = SparsePoints(room, [names] * len(room))
    masks = np.zeros((3, H, W), bool)
    masks[:, 29:31, 39:41] = True
    obs = depth_observations(points, names, Ks, c2w, masks, 0)
    depth = SparseDepth(torch.from_numpy(obs.image), torch.from_numpy(obs.uv).float(),
                        torch.from_numpy(obs.distance).float())
    f = lambda a: torch.from_numpy(np.asarray(a)).float()  # noqa: E731
    data = ImageSet(torch.zeros(3, H, W, 3), torch.from_numpy(masks), torch.ones(3, H, W, dtype=torch.bool), f(Ks),
                    f(c2w), depth=depth)
    batch = data.sample_depth(64, torch.Generator().manual_seed(0))
    ends = batch.origins + batch.distance[:, None] * batch.dirs
    nearest = (ends[:, None] - f(room)[None]).norm(dim=-1).min(dim=1).values
    assert nearest.max() < 1e-4, nearest.max()
    assert data.to("cpu").depth is not None


def test_a_model_without_to_colmap_is_placed_by_its_camera_centres(tmp_path):
    import pytest

    from pipeline.alignment import Similarity
    from pipeline.cameras import Camera, CameraSet
    from pipeline.errors import InputError
    from pipeline.sparse_depth import frame_from_centres

    rng = np.random.default_rng(1)
    centres = rng.normal(size=(6, 3)) * 3
    truth = Similarity(0.5, look_at(np.array([1.0, 2, 3]), np.zeros(3))[:3, :3], np.array([1.0, -2, 0.5]))
    cams = CameraSet(cameras=[
        Camera(name=f"v{i}", image=f"v{i}.png", width=W, height=H, fx=70, fy=70, cx=W / 2, cy=H / 2,
               camera_to_world=look_at(truth.apply(c), np.zeros(3)).tolist()) for i, c in enumerate(centres)])
    model = {f"v{i}": c for i, c in enumerate(centres)}
    np.testing.assert_allclose(frame_from_centres(model, cams, tmp_path), truth.matrix, atol=1e-9)
    shuffled = dict(zip(model, centres[::-1]))  # the model of other photos
    with pytest.raises(InputError, match="do not fit"):
        frame_from_centres(shuffled, cams, tmp_path)
    with pytest.raises(InputError, match="shares 2 photo"):
        frame_from_centres({k: model[k] for k in ("v0", "v1")}, cams, tmp_path)


def test_the_far_bound_is_past_the_farthest_point_but_not_its_outliers():
    import pytest

    from pipeline.sparse_depth import far_bound

    distance = np.concatenate([np.linspace(1.0, 10.0, 5000), [1e4]])  # one bad match near infinity
    assert far_bound(distance, 1.25) == pytest.approx(12.5, rel=0.01)
    with pytest.raises(ValueError):
        far_bound(np.array([]), 1.25)
