"""Sparse points as mask seeds (pipeline.masking.tracks): labels by position, seeds where each view observed them."""

from __future__ import annotations

import numpy as np

from pipeline.cameras import look_at
from pipeline.masking.tracks import (
    FLOOR,
    OBJECT,
    OUTSIDE,
    UNKNOWN,
    label_points,
    seed_maps,
    track_plane,
    tracks_for_views,
)
from pipeline.masking.views import View
from pipeline.object_frame import pixels_of

FLOOR_Z = -0.6


def ring(n: int = 12, size: tuple[int, int] = (200, 150)) -> list[View]:
    views = []
    w, h = size
    for i in range(n):
        a = 2 * np.pi * i / n
        eye = np.array([4.0 * np.cos(a), 4.0 * np.sin(a), 1.8])
        K = np.array([[150.0, 0, w / 2], [0, 150.0, h / 2], [0, 0, 1]])
        views.append(View(f"v{i}", np.zeros((h, w, 3), np.uint8), K, look_at(eye, np.zeros(3))))
    return views


def scene(rng: np.random.Generator) -> dict[str, np.ndarray]:
    """A floor around the object (out to 2.5), points on a ball just above it, the room far away, and mirror
    images of the floor below it."""
    r = 2.5 * np.sqrt(rng.uniform(0, 1, 600))
    a = rng.uniform(0, 2 * np.pi, 600)
    floor = np.stack([r * np.cos(a), r * np.sin(a), np.full(600, FLOOR_Z)], -1)
    d = rng.normal(size=(80, 3))
    ball = np.array([0.0, 0.0, -0.1]) + 0.4 * d / np.linalg.norm(d, axis=1, keepdims=True)
    a = rng.uniform(0, 2 * np.pi, 100)
    room = np.stack([6 * np.cos(a), 6 * np.sin(a), rng.uniform(-0.5, 2.0, 100)], -1)
    below = np.stack([rng.uniform(-0.3, 0.3, 20), rng.uniform(-0.3, 0.3, 20), np.full(20, FLOOR_Z - 0.3)], -1)
    return {"floor": floor, "ball": ball, "room": room, "below": below}


def observers(points: np.ndarray, views: list[View]) -> list[list[str]]:
    """The views each point projects into (no occlusion: enough for labels and seeds)."""
    out: list[list[str]] = [[] for _ in points]
    for v in views:
        for p in pixels_of(points, v.c2w, v.K, v.shape)[0]:
            out[p].append(v.name)
    return out


def test_points_are_labelled_by_where_they_lie_and_seed_where_they_were_seen():
    views = ring()
    parts = scene(np.random.default_rng(0))
    xyz = np.concatenate(list(parts.values()))
    kinds = np.concatenate([np.full(len(p), k) for k, p in zip((FLOOR, OBJECT, OUTSIDE, UNKNOWN), parts.values())])
    tracks = tracks_for_views(xyz, observers(xyz, views), [v.name for v in views])
    labels = label_points(tracks, track_plane(tracks, views, tolerance=0.02), far=3.0)
    # floor points inside the sphere and beyond it are both background; the room is outside
    expected = np.where((kinds == FLOOR), FLOOR, kinds)
    np.testing.assert_array_equal(labels, expected)

    view = views[3]
    obj, bg = seed_maps(view, tracks, tracks.seen[3], labels, radius_px=1)
    inside, x, y = pixels_of(xyz[tracks.seen[3]], view.c2w, view.K, view.shape)
    seen_kind = kinds[tracks.seen[3]][inside]
    assert obj[y[seen_kind == OBJECT], x[seen_kind == OBJECT]].all()
    assert bg[y[seen_kind == FLOOR], x[seen_kind == FLOOR]].all()
    # each point seeds a 3x3 square: no more pixels than that
    assert obj.sum() <= 9 * (seen_kind == OBJECT).sum()
    # the points below the floor (reflections) seed nothing
    below = seen_kind == UNKNOWN
    assert below.any() and not (obj[y[below], x[below]] | bg[y[below], x[below]]).all()


def test_points_just_above_the_floor_or_just_outside_the_sphere_are_no_evidence():
    """Carpet pile (within twice the plane's thickness above it) may be either; so may a point between the sphere
    and ``far`` (an object reaching past a sphere that is still to grow)."""
    views = ring()
    parts = scene(np.random.default_rng(4))
    tracks = tracks_for_views(parts["floor"], observers(parts["floor"], views), [v.name for v in views])
    plane = track_plane(tracks, views, tolerance=0.02)
    probes = np.array([[0.1, 0.0, FLOOR_Z + 1.5 * plane.thickness], [0.1, 0.0, FLOOR_Z + 3 * plane.thickness],
                       [0.0, 1.5, 0.3], [0.0, 3.5, 0.3]])
    labels = label_points(tracks_for_views(probes, [[]] * 4, []), plane, far=3.0)
    np.testing.assert_array_equal(labels, [UNKNOWN, OBJECT, UNKNOWN, OUTSIDE])


def test_a_view_seeds_only_the_points_it_observed():
    views = ring()
    parts = scene(np.random.default_rng(1))
    xyz = np.concatenate([parts["floor"], parts["ball"]])
    seen_by = observers(xyz, views)
    seen_by[len(parts["floor"]):] = [[n for n in s if n != "v0"] for s in seen_by[len(parts["floor"]):]]
    tracks = tracks_for_views(xyz, seen_by, [v.name for v in views])
    labels = label_points(tracks, track_plane(tracks, views, tolerance=0.02), far=3.0)
    obj, bg = seed_maps(views[0], tracks, tracks.seen[0], labels, radius_px=1)
    assert not obj.any() and bg.any()


def test_without_a_plane_nothing_inside_the_sphere_is_labelled():
    """The ball and the room alone: position cannot tell the object from a floor that is not there."""
    views = ring()
    parts = scene(np.random.default_rng(2))
    xyz = np.concatenate([parts["ball"], parts["room"]])
    tracks = tracks_for_views(xyz, observers(xyz, views), [v.name for v in views])
    labels = label_points(tracks, track_plane(tracks, views, tolerance=0.02), far=3.0)
    assert not (labels == OBJECT).any() and (labels[len(parts["ball"]):] == OUTSIDE).all()


def test_framed_tracks_move_with_the_sphere():
    tracks = tracks_for_views(np.array([[1.0, 2.0, 3.0]]), [["a"]], ["a"])
    np.testing.assert_allclose(tracks.framed(np.array([1.0, 0.0, 1.0]), 2.0).xyz, [[0.0, 1.0, 1.0]])


def test_the_plane_is_the_floor_under_the_object_and_none_when_the_floor_is_out_of_the_sphere():
    views = ring()
    parts = scene(np.random.default_rng(3))
    xyz = np.concatenate([parts["floor"], parts["ball"]])
    tracks = tracks_for_views(xyz, observers(xyz, views), [v.name for v in views])
    plane = track_plane(tracks, views, tolerance=0.02)
    assert plane is not None and plane.thickness > 0
    assert abs(plane.offset - FLOOR_Z) < 1e-6 and plane.normal[2] > 1 - 1e-9
    # a floating object: the floor is below its sphere, and what lies above that floor is not all object
    low = xyz - np.array([0.0, 0.0, 0.6]) * (np.arange(len(xyz)) < len(parts["floor"]))[:, None]
    tracks = tracks_for_views(low, observers(low, views), [v.name for v in views])
    assert track_plane(tracks, views, tolerance=0.02) is None
    assert not (label_points(tracks, None, far=3.0) == OBJECT).any()


def test_the_points_plane_is_the_support_plane_where_the_photos_give_none_or_when_asked():
    from dataclasses import replace

    from pipeline.masking.segment import gather_evidence
    from pipeline.masking.views import SegmentOptions

    views = ring(8, size=(80, 60))
    parts = scene(np.random.default_rng(5))
    xyz = np.concatenate([parts["floor"], parts["ball"]])
    tracks = tracks_for_views(xyz, observers(xyz, views), [v.name for v in views])
    opts = SegmentOptions(sweep=False)

    def plane(source: str, photos: list[View]):
        evidence = gather_evidence(photos, replace(opts, support_plane_from=source), tracks=tracks)
        assert evidence.track_labels["object"] > 0 and evidence.track_labels["floor"] > 0  # whichever plane is used
        return evidence.plane

    def from_points(found) -> bool:
        return found is not None and found.thickness > 0 and abs(found.offset - FLOOR_Z) < 1e-6

    # blank photos: photo-consistency finds a plane (every plane explains them), which stays unless told otherwise
    assert plane("photos", views).thickness == 0 and plane("photos_or_points", views).thickness == 0
    assert from_points(plane("points", views))
    # independent noise in each photo: no plane explains it, so the points' plane stands in
    rng = np.random.default_rng(0)
    noise = [replace(v, image=rng.integers(0, 256, v.image.shape, np.uint8)) for v in views]
    assert plane("photos", noise) is None
    assert from_points(plane("photos_or_points", noise))
