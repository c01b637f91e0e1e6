"""The randomized scene family of ``orca synth`` (:mod:`pipeline.synth.family`): deterministic per seed, every
kind covered, geometrically valid (checked with the ground-truth cameras and the props as ``scene.json`` writes
them), and tiny front-end renders of a random and a tiled scene give masks; plus the new meshes, the camera
path and the tile texture."""

from __future__ import annotations

import argparse
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from helpers import small

from pipeline.artifacts import read_json
from pipeline.cameras import load_cameras
from pipeline.errors import InputError
from pipeline.ground_truth import GroundTruth
from pipeline.imageio import read_image
from pipeline.props import Prop
from pipeline.synth import SynthOptions, geometry, get_scene, render_capture
from pipeline.synth.family import (
    FRONT_END_SUITE,
    PLACEMENTS,
    ROOMS,
    SHAPES,
    TABLE,
    distance_for_fraction,
    fraction_for_distance,
    kelvin_rgb,
    random_scene,
    tiles_scene,
    traits,
)
from pipeline.synth.rig import capture_views, planned_path
from pipeline.synth.scenes import SCENES, ObjectSpec, RigSpec, object_mesh, resolve
from pipeline.synth.textures import tile

# The first N_COVER seeds hold every shape, placement and room kind (and small and large objects).
N_COVER = 20
VIEWS, WIDTH, HEIGHT = 40, 320, 240  # the front-end benchmark's captures


def test_family_is_deterministic_per_seed():
    assert random_scene(5) == random_scene(5)
    specs = [random_scene(s) for s in range(N_COVER)]
    assert len({repr(s) for s in specs}) == N_COVER  # every seed its own scene
    assert [s.name for s in specs[:2]] == ["random-0", "random-1"]
    # the tiled variant changes the room's finish and the name, nothing else
    t = tiles_scene(5)
    assert traits(t)["room"] == "tiles" and traits(t)["floor"] == "tiles" and t.name == "tiles-5"
    assert replace(t, name="random-5", room=random_scene(5).room) == random_scene(5)
    with pytest.raises(ValueError):
        random_scene(-1)


def test_family_covers_every_kind():
    seen = [traits(random_scene(s)) for s in range(N_COVER)]
    for key, kinds in (("shape", SHAPES), ("placement", PLACEMENTS), ("room", ROOMS)):
        assert {t[key] for t in seen} == set(kinds), key
    fractions = [t["size_fraction"] for t in seen]
    assert min(fractions) < 0.3 and max(fractions) > 0.55
    assert {t["rings"] for t in seen} == {1, 2, 3}
    assert {t["ring_order"] for t in seen} == {"interleaved", "sequential"}
    assert any(t["room"] == "plain" and t["floor"] == "plain" for t in seen)
    # the benchmark suite covers every kind too
    suite = [traits(random_scene(s)) for s in FRONT_END_SUITE]
    assert len(suite) >= 8
    for key, kinds in (("shape", SHAPES), ("placement", PLACEMENTS), ("room", ROOMS)):
        assert {t[key] for t in suite} == set(kinds), key
    assert any(t["room"] == "plain" and t["props"] <= 2 for t in suite)
    assert max(t["size_fraction"] for t in suite) > 0.6


def _points_in_box(prop: Prop, n: int = 12) -> np.ndarray:
    """A grid of points filling a prop (its bounding box, kept where the prop contains them)."""
    half = np.array([math.hypot(prop.size[0], prop.size[1])] * 2 + [prop.size[2]])
    if prop.kind == "cylinder":
        half[2] = prop.size[2] / 2
    g = np.linspace(-1, 1, n)
    pts = np.stack(np.meshgrid(g, g, g, indexing="ij"), -1).reshape(-1, 3) * half + prop.centre
    return pts[prop.contains(pts)]


@pytest.mark.parametrize("seed", sorted(set(range(N_COVER)) | set(FRONT_END_SUITE)))
def test_family_scene_is_valid(seed: int):
    spec = random_scene(seed)
    scene = resolve(spec)
    mesh = scene.mesh.vertices
    assert np.linalg.norm(mesh, axis=1).max() == pytest.approx(spec.object.radius)
    lowest = mesh[:, 2].min()
    assert lowest - scene.floor_z == pytest.approx(spec.lift)  # on the floor, the table, or floating above it
    props = {p.name: Prop.from_json(p.to_json()) for p in scene.props}
    room_lo, room_hi = scene.room_min, scene.room_max
    for name, prop in props.items():
        if name == TABLE:  # the object rests on the table's top, centred
            assert prop.centre[2] + prop.size[2] == pytest.approx(lowest)
            assert not prop.contains(mesh, margin=-1e-6).any()
            assert prop.contains(mesh[mesh[:, 2] < lowest + 1e-6], margin=1e-6).all()
        else:
            assert not prop.contains(mesh, margin=0.1).any(), name
        inside = _points_in_box(prop)
        assert len(inside) > 0
        assert (inside >= room_lo - 1e-9).all() and (inside <= room_hi + 1e-9).all(), name
        bottom = prop.centre[2] - (prop.size[2] / 2 if prop.kind == "cylinder" else prop.size[2])
        assert bottom == pytest.approx(scene.floor_z)  # standing on the floor
        for other_name, other in props.items():
            if other_name != name:
                assert not other.contains(inside).any(), (name, other_name)

    views = capture_views(spec.rig, VIEWS, WIDTH, HEIGHT, np.random.default_rng([0, 1]),
                          [f"v{i}" for i in range(VIEWS)])
    fraction = fraction_for_distance(sum(spec.rig.distance) / 2, spec.rig.fov_x_deg)
    assert 0.2 - 1e-9 <= fraction <= 2 / 3 + 1e-9
    extents = []
    for v in views:
        c = v.c2w[:3, 3]
        assert (c > room_lo + 0.5).all() and (c < room_hi - 0.5).all()
        assert np.linalg.norm(c) > 2 * spec.object.radius
        line = c[None] + np.linspace(0, 1, 50)[:, None] * (-c)[None]  # camera -> object centre
        line = line[np.linalg.norm(line, axis=1) > spec.object.radius]
        for name, prop in props.items():
            assert not prop.contains(c[None], margin=0.1).any(), (v.name, name)
            assert not prop.contains(line).any(), (v.name, name)
        # the object is in front, near the centre of the frame, wholly inside it, at its intended size
        x = (mesh - c) @ v.c2w[:3, :3]
        assert (x[:, 2] > 0).all()
        u, w = v.fx * x[:, 0] / x[:, 2] + WIDTH / 2, v.fx * x[:, 1] / x[:, 2] + HEIGHT / 2
        assert u.min() > 0 and u.max() < WIDTH and w.min() > 0 and w.max() < HEIGHT, v.name
        centre = v.fx * (-c @ v.c2w[:3, :3])[:2] / (-c @ v.c2w[:3, :3])[2]
        assert np.abs(centre).max() < 0.15 * HEIGHT
        extents.append(max(u.max() - u.min(), w.max() - w.min()) / HEIGHT)
    # a fifth to two thirds of the frame: the widest projection is the bounding sphere's (at most) and no
    # less than 3/4 of it (objects are about as wide as their bounding sphere in some direction)
    print(f"seed {seed}: {traits(spec)}; projected extent / height {min(extents):.2f}-{max(extents):.2f}")
    assert 0.75 * fraction < max(extents) < 1.1 * fraction


def test_get_scene_names_and_cli(tmp_path: Path):
    assert get_scene("random-3") == random_scene(3)
    assert get_scene("Tiles-3") == tiles_scene(3)
    assert get_scene("sphere") is SCENES["sphere"]
    for bad in ("random-x", "random-", "tiles3", "cube"):
        with pytest.raises(InputError, match="random-<seed>"):
            get_scene(bad)
    from pipeline.synth import cli

    parser = argparse.ArgumentParser()
    cli.register(parser.add_subparsers())
    args = parser.parse_args(["synth", "random-3", str(tmp_path / "x"), "--truth", "front_end", "--coverage-spp",
                              "9"])
    assert args.scene == "random-3" and args.truth == "front_end" and args.coverage_spp == 9
    with pytest.raises(InputError):
        args.func(parser.parse_args(["synth", "random-three", str(tmp_path / "y")]))
    assert not (tmp_path / "y").exists()


FRONT_END = SynthOptions(views=4, width=48, height=36, spp=4, coverage_spp=4, truth="front_end", format="jpg")


@pytest.mark.parametrize("name", ["random-3", "tiles-21"])
def test_tiny_front_end_render(tmp_path: Path, name: str):
    """A random scene and a tiled one render in front-end mode: photos, cameras, scene.json, mesh, masks and
    coverage only, every mask non-empty, and the ground-truth reader copes with what is missing."""
    spec = small(get_scene(name))
    out = render_capture(spec, tmp_path / name, FRONT_END)
    gt = out / "ground_truth"
    assert sorted(p.name for p in gt.iterdir() if p.is_dir()) == ["coverage", "masks"]
    for f in ("cameras.json", "scene.json", "object.ply", "manifest.json"):
        assert (gt / f).is_file()
    scene = read_json(gt / "scene.json")
    assert scene["truth"] == "front_end" and scene["environment"] is None and scene["decomposition_residual"] is None
    assert scene["room"]["finish"]["walls"]["kind"] == traits(spec)["room"]
    cams = load_cameras(gt / "cameras.json")
    assert len(cams) == FRONT_END.views
    reader = GroundTruth(gt)
    assert not reader.has_environment and reader.factor > 0
    for cam in cams.cameras:
        assert (out / f"{cam.name}.jpg").is_file()
        mask = read_image(gt / "masks" / f"{cam.name}.png")
        assert mask.shape == (FRONT_END.height, FRONT_END.width)
        assert (mask > 0).sum() >= 4, cam.name
        assert np.array_equal(reader.mask(cam.name), mask > 0)
        photo = read_image(out / f"{cam.name}.jpg")
        assert photo.mean() > 10  # lit, not black


def test_a_scene_renders_the_same_photos_every_time(tmp_path: Path):
    """Mitsuba keeps the scene dictionary's shape order, so the lights' order and with it every random number of
    the path tracer are the same on every load: a scene with three lights rendered twice gives the same photos
    to the byte (an optimizing load shuffled the lights from load to load, and the noise with them)."""
    from pipeline.synth import build, geometry
    from pipeline.synth.render import resolve

    spec = small(get_scene("tiles-2"))
    resolved = resolve(spec)
    ply = geometry.write_ply(tmp_path / "object.ply", resolved.mesh)
    assets = build.make_assets(resolved, None if spec.object.kind == "sphere" else ply)
    orders = [list(build.load_scene(resolved, assets, "full")[1]) for _ in range(4)]
    assert all(order == orders[0] for order in orders) and len(orders[0]) > 10
    first, second = (render_capture(spec, tmp_path / k, FRONT_END) for k in ("a", "b"))
    photos = sorted(p.name for p in first.glob("*.jpg"))
    assert len(photos) == FRONT_END.views
    assert all((first / n).read_bytes() == (second / n).read_bytes() for n in photos)


def test_default_camera_path_is_unchanged():
    """The presets' path (interleaved rings, no gaps) draws exactly as before the family's options existed."""
    rig = RigSpec()
    views = capture_views(rig, 7, 64, 48, np.random.default_rng(3), [str(i) for i in range(7)])
    rng = np.random.default_rng(3)
    for i, v in enumerate(views):
        az = np.deg2rad(360.0 * i / 7 + rng.uniform(-1, 1) * rig.azimuth_jitter_deg)
        el = np.deg2rad(rig.elevations_deg[i % 3] + rng.uniform(-1, 1) * rig.elevation_jitter_deg)
        eye = rng.uniform(*rig.distance) * np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
        rng.uniform(-1, 1, 3), rng.uniform(-1, 1)  # aim and roll
        np.testing.assert_array_equal(v.c2w[:3, 3], eye)


def test_planned_path_rings_gaps_and_drops():
    rig = RigSpec(elevations_deg=(10.0, 30.0, 45.0), ring_order="sequential", spacing_jitter=0.5, dropped=4)
    az, el = planned_path(rig, 32, np.random.default_rng(0))
    assert len(az) == len(el) == 32
    assert [int((el == e).sum()) for e in rig.elevations_deg] == [11, 11, 10]  # one ring after the other
    assert np.all(np.diff(np.flatnonzero(np.diff(el))) > 0) and len(np.flatnonzero(np.diff(el))) == 2
    steps = np.concatenate([np.diff(az[el == e]) for e in rig.elevations_deg])
    assert steps.min() > 0 and steps.max() > 2 * steps.min()  # uneven steps; gaps where photos were dropped
    interleaved = replace(rig, ring_order="interleaved", spacing_jitter=0.0, dropped=0)
    az, el = planned_path(interleaved, 6, np.random.default_rng(0))
    np.testing.assert_array_equal(az, 360.0 * np.arange(6) / 6)
    np.testing.assert_array_equal(el, [10, 30, 45, 10, 30, 45])


def test_size_fraction_is_the_sphere_projection():
    for fraction, fov in ((0.2, 55.0), (0.5, 70.0), (2 / 3, 75.0)):
        d = distance_for_fraction(fraction, fov)
        assert fraction_for_distance(d, fov) == pytest.approx(fraction)
        # the silhouette of the unit sphere seen from d on the axis: tangent rays at asin(1 / d)
        height = 240
        f = height * 4 / 3 / (2 * math.tan(math.radians(fov) / 2))
        assert 2 * f * math.tan(math.asin(1 / d)) / height == pytest.approx(fraction)


def test_vase_and_mug_meshes():
    trimesh = pytest.importorskip("trimesh")
    vase = object_mesh(ObjectSpec("vase", profile_radii=(0.45, 0.7, 0.25, 0.45), profile_height=2.4,
                                  mesh_resolution=(96, 96)))
    tm = trimesh.Trimesh(vase.vertices, vase.faces, process=True)
    assert tm.is_watertight and tm.volume > 0  # closed, normals outward
    assert geometry.convexity(vase) < 0.95  # the waist
    assert vase.bounding_radius == pytest.approx(1.0)
    outward = (vase.normals[:, :2] * vase.vertices[:, :2]).sum(1)
    assert (outward > -1e-6).mean() > 0.9  # smooth vertex normals point away from the axis on the side wall
    mug = object_mesh(ObjectSpec("mug", profile_radii=(0.5, 0.5, 0.55), profile_height=1.2, mesh_resolution=(96, 64)))
    assert mug.bounding_radius == pytest.approx(1.0)
    lo, hi = mug.vertices.min(0), mug.vertices.max(0)
    np.testing.assert_allclose((lo + hi) / 2, 0.0, atol=1e-9)  # centred
    assert (hi - lo)[0] > 1.3 * (hi - lo)[1]  # the handle sticks out along x
    assert geometry.convexity(mug) < 0.9
    assert mug.uv.min() >= 0 and mug.uv.max() <= 1


def test_tile_texture_grid():
    t = tile(20, 2.0, (0.8, 0.8, 0.8), (0.2, 0.2, 0.2))
    assert t.shape == (20, 20, 3) and t.dtype == np.float32
    grout = np.isclose(t[..., 0], 0.2)
    # one grout texel on each border: repeated, lines two texels wide every 20 texels
    assert grout[0].all() and grout[-1].all() and grout[:, 0].all() and grout[:, -1].all()
    assert not grout[1:-1, 1:-1].any()
    np.testing.assert_allclose(np.tile(t, (2, 2, 1))[19:21, :, 0], 0.2)


def test_kelvin_colours():
    warm, cool = kelvin_rgb(2700), kelvin_rgb(9000)
    assert warm[0] > warm[2] and cool[2] > cool[0]
    for c in (warm, cool, kelvin_rgb(6500)):
        assert np.dot(c, (0.2126, 0.7152, 0.0722)) == pytest.approx(1.0)
