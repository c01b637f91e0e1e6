"""Losses: each is zero at its optimum and positive away from it, with gradients in the right direction."""

from __future__ import annotations

import pytest
import torch

from orca.losses import (
    cone_distortion_loss,
    eikonal_loss,
    mask_loss,
    normal_orientation_loss,
    normal_smoothness_loss,
    photometric_loss,
)


def test_photometric_loss_ignores_invalid_pixels():
    pred = torch.tensor([[0.5, 0.5, 0.5], [9.0, 9.0, 9.0]])
    target = torch.tensor([[0.5, 0.5, 0.5], [0.0, 0.0, 0.0]])
    assert photometric_loss(pred, target, torch.tensor([True, False])) < 1e-2
    assert photometric_loss(pred, target, torch.tensor([True, True])) > 4.0
    assert photometric_loss(pred, target, torch.tensor([False, False])) == 0


def test_clipped_pixels_bound_the_prediction_from_below():
    target = torch.tensor([[1.0, 1.0, 1.0], [0.2, 0.2, 0.2]])
    valid = torch.tensor([False, True])
    clipped = torch.tensor([True, False])
    exact = torch.tensor([[1.0, 1.0, 1.0], [0.2, 0.2, 0.2]])
    brighter = torch.tensor([[5.0, 5.0, 5.0], [0.2, 0.2, 0.2]])  # a light source: brighter than recorded is fine
    darker = torch.tensor([[0.3, 0.3, 0.3], [0.2, 0.2, 0.2]])  # a missed highlight is an error
    at = lambda pred: photometric_loss(pred, target, valid, clipped).item()  # noqa: E731
    assert at(brighter) == pytest.approx(at(exact), abs=1e-6)
    assert at(darker) > at(exact) + 0.3
    assert photometric_loss(darker, target, valid).item() == pytest.approx(at(exact), abs=1e-6)  # ignored if not passed


def test_clipped_excess_pulls_an_unbounded_highlight_back_weakly():
    target = torch.tensor([[1.0, 1.0, 1.0], [0.2, 0.2, 0.2]])
    valid = torch.tensor([False, True])
    clipped = torch.tensor([True, False])
    at = lambda pred, w: photometric_loss(pred, target, valid, clipped, w).item()  # noqa: E731
    exact = torch.tensor([[1.0, 1.0, 1.0], [0.2, 0.2, 0.2]])
    brighter = torch.tensor([[5.0, 5.0, 5.0], [0.2, 0.2, 0.2]])
    darker = torch.tensor([[0.6, 0.6, 0.6], [0.2, 0.2, 0.2]])
    # 4 too bright at weight 0.1 costs what 0.4 too dark costs: the lower bound still dominates
    assert at(brighter, 0.1) == pytest.approx(at(darker, 0.1), abs=1e-3)
    assert at(brighter, 0.1) > at(exact, 0.1) + 0.1
    pred = brighter.clone().requires_grad_(True)
    photometric_loss(pred, target, valid, clipped, 0.1).backward()
    assert (pred.grad[0] > 0).all()  # the excess is pulled down


def test_mask_loss_prefers_matching_opacity():
    mask = torch.tensor([1.0, 0.0, 1.0])
    assert mask_loss(torch.tensor([0.99, 0.01, 0.99]), mask) < mask_loss(torch.tensor([0.5, 0.5, 0.5]), mask)
    assert torch.isfinite(mask_loss(torch.tensor([0.0, 1.0, 0.0]), mask))


def test_eikonal_loss_is_zero_for_unit_gradients():
    g = torch.nn.functional.normalize(torch.randn(10, 5, 3), dim=-1)
    assert eikonal_loss(g) < 1e-12
    assert torch.isclose(eikonal_loss(2 * g), torch.tensor(1.0))


def test_normal_orientation_penalizes_back_facing_only():
    d = torch.tensor([[0.0, 0.0, 1.0]])
    w = torch.tensor([[1.0]])
    facing = torch.tensor([[[0.0, 0.0, -1.0]]])
    assert normal_orientation_loss(w, facing, d) == 0
    assert normal_orientation_loss(w, -facing, d) == 1


def test_cone_distortion_loss_prefers_concentrated_weights():
    s = torch.linspace(0, 1, 9)
    spike = torch.zeros(2, 1, 8)
    spike[..., 3] = 1.0
    spread = torch.full((2, 1, 8), 1 / 8)
    assert cone_distortion_loss(spike, s) < cone_distortion_loss(spread, s)


def test_normal_smoothness_is_zero_on_a_plane_and_grows_with_bumps():
    n = torch.nn.functional.normalize(torch.randn(64, 3), dim=-1)
    ones = torch.ones(64)
    assert normal_smoothness_loss(n, n, ones) == 0
    tilt = torch.nn.functional.normalize(n + 0.1 * torch.randn(64, 3), dim=-1)
    more = torch.nn.functional.normalize(n + 0.5 * torch.randn(64, 3), dim=-1)
    assert 0 < normal_smoothness_loss(n, tilt, ones) < normal_smoothness_loss(n, more, ones)
    # rays that miss (zero weight) do not count
    weights = torch.cat([torch.ones(32), torch.zeros(32)])
    mixed = torch.cat([n[:32], more[32:]])
    assert normal_smoothness_loss(n, mixed, weights) == 0


def test_sparse_depth_loss_is_the_weight_missing_from_the_band():
    from orca.losses import sparse_depth_loss

    edges = torch.tensor([[0.0, 1.0, 2.0, 3.0, 4.0]])
    target, band = torch.tensor([2.5]), torch.tensor([0.5])  # the band is exactly the third interval
    at_point = torch.tensor([[0.0, 0.0, 1.0, 0.0]])
    before = torch.tensor([[1.0, 0.0, 0.0, 0.0]])
    split = torch.tensor([[0.0, 0.5, 0.5, 0.0]])
    assert sparse_depth_loss(at_point, edges, target, band) == 0
    assert sparse_depth_loss(before, edges, target, band) == 1
    assert sparse_depth_loss(split, edges, target, band) == pytest.approx(0.5)
    # a band narrower than its interval counts the interval's weight pro rata, and keeps a gradient
    w = torch.tensor([[0.0, 0.0, 1.0, 0.0]], requires_grad=True)
    narrow = sparse_depth_loss(w, edges, target, torch.tensor([0.1]))
    assert narrow.item() == pytest.approx(0.8)
    narrow.backward()
    assert w.grad[0, 2] == pytest.approx(-0.2) and w.grad[0, [0, 1, 3]].eq(0).all()
