"""pipeline.alignment: Umeyama similarity, pose errors and camera alignment on known transforms."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import moved_cameras, orbit_cameras, random_rotation, rotation

from pipeline.alignment import (
    Similarity,
    align_cameras,
    compare_poses,
    fit_similarity,
    mean_rotation,
    rotation_angle_deg,
)
from pipeline.cameras import CameraSet, look_at
from pipeline.errors import InputError


def test_fit_similarity_recovers_a_known_similarity():
    rng = np.random.default_rng(0)
    truth = Similarity(2.7, random_rotation(rng), rng.normal(size=3) * 5)
    src = rng.normal(size=(20, 3))
    fit = fit_similarity(src, truth.apply(src))
    assert fit.scale == pytest.approx(2.7, rel=1e-12)
    np.testing.assert_allclose(fit.rotation, truth.rotation, atol=1e-12)
    np.testing.assert_allclose(fit.translation, truth.translation, atol=1e-10)
    np.testing.assert_allclose(fit.inverse().apply(truth.apply(src)), src, atol=1e-10)
    np.testing.assert_allclose(Similarity.from_matrix(fit.matrix).matrix, fit.matrix, atol=1e-12)


def test_fit_similarity_with_noise_and_rigid_mode():
    rng = np.random.default_rng(1)
    truth = Similarity(1.0, random_rotation(rng), rng.normal(size=3))
    src = rng.normal(size=(200, 3))
    dst = truth.apply(src) + rng.normal(scale=1e-3, size=src.shape)
    fit = fit_similarity(src, dst, with_scale=False)
    assert fit.scale == 1.0
    assert rotation_angle_deg(fit.rotation.T @ truth.rotation) < 0.01


def test_fit_similarity_refuses_degenerate_input():
    with pytest.raises(ValueError, match="at least 3"):
        fit_similarity(np.zeros((2, 3)), np.zeros((2, 3)))
    line = np.outer(np.arange(5.0), [1, 2, 3])
    with pytest.raises(ValueError, match="collinear"):
        fit_similarity(line, line)


def test_rotation_angle_is_accurate_near_zero_and_180():
    for deg in (1e-6, 0.1, 90.0, 179.9, 180.0):
        a = np.deg2rad(deg)
        r = np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])
        assert rotation_angle_deg(r) == pytest.approx(deg, rel=1e-6, abs=1e-9)


def test_compare_poses_is_zero_for_the_same_cameras_in_another_frame():
    rng = np.random.default_rng(2)
    c2w = np.stack([look_at(rng.normal(size=3) * 4, np.zeros(3)) for _ in range(8)])
    sim = Similarity(0.3, random_rotation(rng), rng.normal(size=3))
    err = compare_poses(sim.apply_c2w(c2w), c2w)
    assert err.rotation_deg.max() < 1e-6 and err.center.max() < 1e-9
    assert err.similarity.scale == pytest.approx(1 / 0.3)
    s = err.summary(scale=4.0)
    assert s["center_max_fraction"] < 1e-9
    err = compare_poses(sim.apply_c2w(c2w), c2w, rotation_from="orientations")
    assert err.rotation_deg.max() < 1e-6 and err.center.max() < 1e-9


def test_orientation_alignment_keeps_centre_noise_out_of_rotation_errors():
    """Noisy centres tilt a centre-only alignment; aligning rotations on the orientations does not."""
    rng = np.random.default_rng(3)
    c2w = np.stack([look_at(6 * np.array([np.cos(a), np.sin(a), 0.5]), np.zeros(3))
                    for a in np.linspace(0, 2 * np.pi, 16, endpoint=False)])
    noisy = c2w.copy()
    noisy[:, :3, 3] += rng.normal(scale=0.03, size=(16, 3))
    by_centres = compare_poses(noisy, c2w)
    by_orientations = compare_poses(noisy, c2w, rotation_from="orientations")
    assert by_orientations.rotation_deg.max() < 1e-9 < np.median(by_centres.rotation_deg)
    assert by_orientations.center.max() < 3 * 0.03 * np.sqrt(3)


def test_mean_rotation_of_equal_rotations_is_that_rotation():
    r = random_rotation(np.random.default_rng(4))
    np.testing.assert_allclose(mean_rotation(np.stack([r, r, r])), r, atol=1e-12)


def test_alignment_moves_cameras_into_the_model_frame():
    r = rotation([0, 1, 0], 30.0)
    s, t = 2.5, np.array([0.3, -1.0, 2.0])
    m = np.eye(4)
    m[:3, :3], m[:3, 3] = s * r, t
    align = Similarity.from_matrix(m)
    c2w_gt = look_at(np.array([3.0, 1.0, 2.0]), np.zeros(3))
    c2w_model = align.apply_inverse_c2w(c2w_gt)
    assert np.allclose(c2w_model[:3, :3].T @ c2w_model[:3, :3], np.eye(3)), "still rigid"
    # a point 2 model units in front of the model camera is 2 * s in front of the ground-truth one
    p_model = c2w_model[:3, 3] + 2 * c2w_model[:3, 2]
    p_gt = m[:3, :3] @ p_model + t
    assert np.allclose(p_gt, c2w_gt[:3, 3] + 2.0 * align.scale * c2w_gt[:3, 2])
    assert np.allclose(align.rotate(c2w_model[:3, 2]), c2w_gt[:3, 2])
    assert np.allclose(Similarity.identity().apply_inverse_c2w(c2w_gt), c2w_gt)
    with pytest.raises(InputError, match="similarity"):
        Similarity.from_matrix(np.diag([1.0, 2.0, 1.0, 1.0]))


def test_alignment_recovers_a_known_similarity_and_names_missing_cameras():
    sim = Similarity(1.7, rotation([1, 2, 3], 40.0), np.array([0.5, -1.0, 2.0]))
    truth = orbit_cameras(8, prefix="IMG_")  # in the model's frame; the ground truth's is sim of it
    result = CameraSet(cameras=truth.cameras[:6])  # SfM lost two photos
    align, report = align_cameras(result, moved_cameras(truth, sim), centre=sim.translation)
    np.testing.assert_allclose(align.matrix, sim.matrix, atol=1e-9)
    assert align.scale == pytest.approx(1.7)
    assert report["missing"] == ["IMG_6", "IMG_7"] and report["summary"]["cameras"] == 6
    assert report["summary"]["orbit_radius"] == pytest.approx(3.0 * 1.7)
    assert report["summary"]["rotation_deg_max"] < 1e-6
    # noisy centres: the errors are reported, in % of the orbit radius
    rng = np.random.default_rng(1)
    noisy = []
    for c in truth.cameras:
        c2w = c.c2w.copy()
        c2w[:3, 3] += rng.normal(0, 0.03, 3)
        noisy.append(c.model_copy(update={"camera_to_world": c2w.tolist()}))
    noisy = CameraSet(cameras=noisy)
    _, report = align_cameras(noisy, truth, centre=np.zeros(3))
    assert 0.2 < report["summary"]["center_median_percent"] < 3.0  # ~ 0.03 x sqrt(3) / 3 = 1.7 %
    with pytest.raises(InputError, match="in common"):
        align_cameras(orbit_cameras(3, prefix="other"), truth)
