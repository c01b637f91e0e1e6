"""``orca synth``: the synthetic capture and its ground truth, checked against analytic geometry.

Renders are tiny (tens of pixels, tens of samples) and the textures coarse, so the whole file runs in about a
minute on two cores; what is checked (sums, depths, normals, projections) does not depend on image size.
"""

from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
import pytest
from helpers import small

from pipeline.artifacts import read_json
from pipeline.cameras import load_cameras
from pipeline.imageio import read_exr, read_image, srgb_to_linear
from pipeline.synth import SCENES, SynthOptions, geometry, render_capture
from pipeline.synth import render as synth_render
from pipeline.synth.build import rectangle_frame
from pipeline.synth.scenes import AlbedoSpec, SceneSpec, object_mesh, resolve, rotation_xyz
from pipeline.synth.textures import PosterStyle, poster

pytest.importorskip("mitsuba")


SPHERE_OPTIONS = SynthOptions(views=3, width=96, height=72, spp=64, env_size=24, coverage_spp=16, format="both",
                              seed=5)


@pytest.fixture(scope="module")
def sphere_capture(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("synth") / "sphere"
    return render_capture(small(SCENES["sphere"]), out, SPHERE_OPTIONS)


# --------------------------------------------------------------------------------------- analytic tracing


def _pixel_rays(cam, ij: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World-space origins and unit directions of rays through pixel centres ``ij`` (N, 2) = (row, col)."""
    uv1 = np.stack([ij[:, 1] + 0.5, ij[:, 0] + 0.5, np.ones(len(ij))], -1)
    d_cam = uv1 @ np.linalg.inv(cam.K).T
    c2w = cam.c2w
    d = d_cam @ c2w[:3, :3].T
    return np.broadcast_to(c2w[:3, 3], d.shape).copy(), d / np.linalg.norm(d, axis=1, keepdims=True)


def _hit_sphere(o, d, c, r):
    oc = o - c
    b = (oc * d).sum(1)
    disc = b**2 - ((oc * oc).sum(1) - r * r)
    t = -b - np.sqrt(np.where(disc >= 0, disc, np.nan))
    t_far = -b + np.sqrt(np.where(disc >= 0, disc, np.nan))
    t = np.where(t > 1e-6, t, t_far)
    return np.where((disc >= 0) & (t > 1e-6), t, np.inf)


def _hit_box(o, d, centre, half, yaw_deg):
    a = np.deg2rad(yaw_deg)
    rot = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1.0]])
    lo_, ld = (o - centre) @ rot, d @ rot  # into the box frame
    with np.errstate(divide="ignore", invalid="ignore"):
        t1, t2 = (-half - lo_) / ld, (half - lo_) / ld
    tn, tf = np.nanmax(np.minimum(t1, t2), axis=1), np.nanmin(np.maximum(t1, t2), axis=1)
    t = np.where(tn > 1e-6, tn, tf)
    return np.where((tf >= tn) & (t > 1e-6), t, np.inf)


def _hit_cylinder(o, d, centre, radius, height):
    z0, z1 = centre[2] - height / 2, centre[2] + height / 2
    ox, oy, dx, dy = o[:, 0] - centre[0], o[:, 1] - centre[1], d[:, 0], d[:, 1]
    a, b, c = dx * dx + dy * dy, ox * dx + oy * dy, ox * ox + oy * oy - radius * radius
    disc = b * b - a * c
    out = np.full(len(o), np.inf)
    with np.errstate(divide="ignore", invalid="ignore"):
        for sign in (-1, 1):
            t = (-b + sign * np.sqrt(np.where(disc >= 0, disc, np.nan))) / a
            z = o[:, 2] + t * d[:, 2]
            ok = (disc >= 0) & (t > 1e-6) & (z >= z0) & (z <= z1)
            out = np.where(ok, np.minimum(out, t), out)
        for zc in (z0, z1):  # caps
            t = (zc - o[:, 2]) / d[:, 2]
            p = o + t[:, None] * d
            ok = (t > 1e-6) & ((p[:, 0] - centre[0]) ** 2 + (p[:, 1] - centre[1]) ** 2 <= radius * radius)
            out = np.where(ok, np.minimum(out, t), out)
    return out


def _hit_rectangle(o, d, centre, normal, size):
    u, v = rectangle_frame(np.asarray(normal, float))
    n = np.asarray(normal, float) / np.linalg.norm(normal)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = ((np.asarray(centre) - o) @ n) / (d @ n)
    p = o + t[:, None] * d - centre
    ok = (t > 1e-6) & (np.abs(p @ u) <= size[0] / 2) & (np.abs(p @ v) <= size[1] / 2)
    return np.where(ok, t, np.inf)


def _hit_room_inside(o, d, lo, hi):
    with np.errstate(divide="ignore"):
        t = np.where(d > 0, (hi - o) / d, (lo - o) / d)
    return np.min(np.where(np.isfinite(t), t, np.inf), axis=1)


def trace(scene_json: dict, o: np.ndarray, d: np.ndarray, with_object: bool) -> tuple[np.ndarray, np.ndarray]:
    """Analytic first hit (distance along the unit ray, and whether it is the object) for the sphere scene."""
    best = _hit_room_inside(o, d, np.array(scene_json["room"]["min"]), np.array(scene_json["room"]["max"]))
    for p in scene_json["props"]:
        c, s = np.array(p["centre"]), np.array(p["size"])
        if p["kind"] == "sphere":
            t = _hit_sphere(o, d, c, s[0])
        elif p["kind"] == "box":
            t = _hit_box(o, d, c, s, p["yaw_deg"])
        else:
            t = _hit_cylinder(o, d, c, s[0], s[2])
        best = np.minimum(best, t)
    for light in scene_json["lights"]:
        best = np.minimum(best, _hit_rectangle(o, d, np.array(light["centre"]), light["normal"], light["size"]))
    is_object = np.zeros(len(o), bool)
    if with_object:
        obj = scene_json["object"]
        t = _hit_sphere(o, d, np.array(obj["centre"]), obj["radius"])
        is_object = t < best
        best = np.minimum(best, t)
    return best, is_object


def _z_of(cam, o, d, t):
    return ((o + t[:, None] * d - cam.center) @ cam.c2w[:3, 2])


# ------------------------------------------------------------------------------------------------- tests


def test_layout(sphere_capture: Path):
    gt = sphere_capture / "ground_truth"
    names = [f"IMG_{i:04d}" for i in range(1, SPHERE_OPTIONS.views + 1)]
    for n in names:
        assert (sphere_capture / f"{n}.dng").is_file() and (sphere_capture / f"{n}.jpg").is_file()
        for sub, ext in [("linear", "exr"), ("diffuse", "exr"), ("specular", "exr"), ("albedo", "exr"),
                         ("normals", "exr"), ("depth", "exr"), ("masks", "png"), ("coverage", "png")]:
            assert (gt / sub / f"{n}.{ext}").is_file(), (sub, n)
    for f in ("cameras.json", "scene.json", "manifest.json", "object.ply", "object_albedo.png",
              "environment/cameras.json"):
        assert (gt / f).is_file(), f
    env = load_cameras(gt / "environment" / "cameras.json")
    assert len(env) == 6 + len(SCENES["sphere"].env.parallax_offsets)
    for cam in env.cameras:
        assert (gt / "environment" / cam.image).is_file()
        assert (gt / "environment" / "depth" / Path(cam.image).name).is_file()
    # nothing but the photos, capture.yaml and ground_truth/ at the top level, no temporary leftovers beside it
    assert sorted(p.name for p in sphere_capture.iterdir()) == sorted(
        ["ground_truth", "capture.yaml"] + [f"{n}.dng" for n in names] + [f"{n}.jpg" for n in names])
    from pipeline.config import load_config

    assert load_config(sphere_capture / "capture.yaml").train.render.ior == SCENES["sphere"].object.int_ior
    assert not [p for p in sphere_capture.parent.iterdir() if p.name.startswith(".")]
    mask = read_image(gt / "masks" / f"{names[0]}.png")
    assert mask.shape == (SPHERE_OPTIONS.height, SPHERE_OPTIONS.width) and set(np.unique(mask)) <= {0, 255}


def test_cameras_valid_and_centred(sphere_capture: Path):
    gt = sphere_capture / "ground_truth"
    cams = load_cameras(gt / "cameras.json")  # validates the schema (rigid poses, intrinsics)
    scene = read_json(gt / "scene.json")
    assert scene["object"]["centre"] == [0.0, 0.0, 0.0] and scene["object"]["radius"] == 1.0
    for cam in cams.cameras:
        assert (gt / cam.image).resolve() == (sphere_capture / f"{cam.name}.dng").resolve()
        x_cam = np.linalg.inv(cam.c2w) @ np.array([0.0, 0.0, 0.0, 1.0])
        assert x_cam[2] > 0
        u, v = cam.fx * x_cam[0] / x_cam[2] + cam.cx, cam.fy * x_cam[1] / x_cam[2] + cam.cy
        assert abs(u - cam.width / 2) < 0.1 * cam.width and abs(v - cam.height / 2) < 0.1 * cam.height
        # the object takes about a third of the frame width or less
        angular = 2 * np.arcsin(1.0 / np.linalg.norm(cam.center))
        fov = 2 * np.arctan(cam.width / (2 * cam.fx))
        assert 0.2 < angular / fov < 0.4
        # world z up: the image's "up" (-y_cam) points up
        assert (-cam.c2w[:3, 1])[2] > 0.5


def test_sphere_mask_depth_normals_match_analytic(sphere_capture: Path):
    gt = sphere_capture / "ground_truth"
    scene = read_json(gt / "scene.json")
    checked = 0
    for cam in load_cameras(gt / "cameras.json").cameras:
        depth = read_exr(gt / "depth" / f"{cam.name}.exr")
        normals = read_exr(gt / "normals" / f"{cam.name}.exr")
        mask = read_image(gt / "masks" / f"{cam.name}.png") > 0
        ij = np.argwhere(np.ones_like(mask))
        o, d = _pixel_rays(cam, ij)
        t, is_object = trace(scene, o, d, with_object=True)
        is_object = is_object.reshape(mask.shape)
        hit = np.isfinite(depth)
        # The pixel-centre object hits are exactly the analytic ones (occlusion by props included).
        assert np.array_equal(hit, is_object)
        z = _z_of(cam, o, d, t).reshape(mask.shape)
        np.testing.assert_allclose(depth[hit], z[hit], rtol=1e-4)
        # Normals: unit, pointing away from the centre, equal to the analytic ones.
        p = (o + t[:, None] * d).reshape(*mask.shape, 3)
        n_true = p / np.linalg.norm(p, axis=-1, keepdims=True)
        cos = (normals[hit] * n_true[hit]).sum(-1)
        assert cos.min() > 0.9995
        assert np.all(normals[~hit] == 0)
        # The mask (coverage >= 0.5) and the pixel-centre hits differ at most on silhouette pixels.
        differ = mask ^ hit
        edge = _dilate(hit) & _dilate(~hit)
        assert not np.any(differ & ~edge)
        assert differ.sum() <= 0.1 * max(1, hit.sum())
        # Normals at mask pixels point away from the centre (also on silhouette pixels with a hit).
        m = mask & hit
        assert ((normals[m] * p[m]).sum(-1) > 0).all()
        checked += int(hit.sum())
    assert checked > 500


def _dilate(m: np.ndarray) -> np.ndarray:
    out = m.copy()
    out[1:] |= m[:-1]
    out[:-1] |= m[1:]
    out[:, 1:] |= m[:, :-1]
    out[:, :-1] |= m[:, 1:]
    return out


def test_diffuse_plus_specular_is_full_render(sphere_capture: Path):
    """On interior object pixels diffuse + specular = full render, up to Monte Carlo noise (sum over many
    pixels, so the noise averages out); each lobe alone is far from it."""
    gt = sphere_capture / "ground_truth"
    for cam in load_cameras(gt / "cameras.json").cameras:
        full = read_exr(gt / "linear" / f"{cam.name}.exr").astype(np.float64)
        dif = read_exr(gt / "diffuse" / f"{cam.name}.exr").astype(np.float64)
        spec = read_exr(gt / "specular" / f"{cam.name}.exr").astype(np.float64)
        cov = read_image(gt / "coverage" / f"{cam.name}.png")
        m = synth_render.interior_mask(cov / 255.0, SPHERE_OPTIONS.optics_blur_px)
        assert m.sum() > 200  # enough pixels for the mean residual (interior shrunk by the blur footprint)
        scale = full[m].mean()
        residual = abs((full[m] - dif[m] - spec[m]).mean()) / scale
        print(f"{cam.name}: |mean(full - diffuse - specular)| / mean(full) = {residual:.4f} over {m.sum()} px; "
              f"diffuse alone off by {abs((full[m] - dif[m]).mean()) / scale:.2f}, "
              f"specular alone by {abs((full[m] - spec[m]).mean()) / scale:.2f}")
        assert residual < 0.03, residual  # measured 0.2-2.2 % (Monte Carlo noise, same with and without blur)
        # Each lobe's share must dwarf the 3 % tolerance so that a missing lobe fails the sum above (the dark
        # object's diffuse share is ~15 % away from the Fresnel-bright rim).
        assert abs((full[m] - dif[m]).mean()) / scale > 0.1
        assert abs((full[m] - spec[m]).mean()) / scale > 0.1
        # the lobes live on the object, spread only by the optics blur
        r = synth_render.blur_radius(SPHERE_OPTIONS.optics_blur_px)
        near = synth_render.dilate_mask(cov > 0, r)
        assert np.all(dif[~near] == 0) and np.all(spec[~near] == 0)
    summary = read_json(gt / "scene.json")["decomposition_residual"]
    assert summary["relative_mean"]["max"] < 0.03


def test_environment_depth_matches_scene(sphere_capture: Path):
    """Environment views (object removed): every pixel's depth equals the analytic first hit among the
    props, the lights and the room; in particular each prop seen at its projected centre is where scene.json
    says it is."""
    gt = sphere_capture / "ground_truth"
    scene = read_json(gt / "scene.json")
    env = load_cameras(gt / "environment" / "cameras.json")
    props_seen = set()
    for cam in env.cameras:
        depth = read_exr(gt / "environment" / "depth" / Path(cam.image).name)
        rgb = read_exr(gt / "environment" / cam.image)
        assert rgb.shape == (cam.height, cam.width, 3) and np.all(np.isfinite(rgb)) and rgb.mean() > 0
        ij = np.argwhere(np.ones(depth.shape, bool))
        o, d = _pixel_rays(cam, ij)
        t, _ = trace(scene, o, d, with_object=False)
        z = _z_of(cam, o, d, t).reshape(depth.shape)
        bad = np.abs(depth - z) > 1e-3 * z
        # allow a handful of pixels where the centre ray grazes an edge
        assert bad.mean() < 0.01, (cam.name, bad.sum())
        # props: project the centre, read the depth there, compare with the distance to that prop's surface
        w2c = np.linalg.inv(cam.c2w)
        for p in scene["props"]:
            xc = w2c[:3, :3] @ np.array(p["centre"]) + w2c[:3, 3]
            if xc[2] <= 0:
                continue
            u, v = cam.fx * xc[0] / xc[2] + cam.cx, cam.fy * xc[1] / xc[2] + cam.cy
            if not (0 <= u < cam.width and 0 <= v < cam.height):
                continue
            i, j = int(v), int(u)
            o1, d1 = _pixel_rays(cam, np.array([[i, j]]))
            one = dict(scene, props=[p], lights=[])
            t_prop, _ = trace(dict(one, room={"min": [-1e6] * 3, "max": [1e6] * 3}), o1, d1, with_object=False)
            if np.isfinite(t_prop[0]) and abs(t_prop[0] - t.reshape(depth.shape)[i, j]) < 1e-6:
                assert depth[i, j] == pytest.approx(_z_of(cam, o1, d1, t_prop)[0], rel=1e-3)
                props_seen.add(p["name"])
    assert len(props_seen) >= 3, props_seen
    # parallax views share one rotation and differ only by a translation inside the object
    par = [c for c in env.cameras if c.name.startswith("parallax")]
    assert all(np.allclose(c.c2w[:3, :3], par[0].c2w[:3, :3]) for c in par)
    assert all(np.linalg.norm(c.center) < scene["object"]["radius"] for c in par)


def test_photos_exposure_and_radiance_factor(sphere_capture: Path):
    """The photos are real DNGs whose decoded value is scene.json's factor x the linear render, with
    auto-exposure-like EXIF, and only lights clip."""
    rawpy = pytest.importorskip("rawpy")
    gt = sphere_capture / "ground_truth"
    scene = read_json(gt / "scene.json")
    factor = scene["radiance_to_decoded"]["factor"]
    photos = scene["photos"]
    assert photos[0]["exposure"]["shutter_s"] == pytest.approx(1 / 60) and photos[0]["exposure"]["iso"] == 200
    for photo in photos:
        assert photo["clipped_fraction"] < 0.05
    ref = photos[0]
    linear = read_exr(gt / "linear" / "IMG_0001.exr")
    with rawpy.imread(str(sphere_capture / ref["image"])) as raw:
        # adjust_maximum_thr=0: LibRaw would otherwise lower the white level to the image's maximum when
        # nothing clips, brightening the output (the decode stage turns it off too).
        dec = raw.postprocess(gamma=(1, 1), no_auto_bright=True, output_bps=16, use_camera_wb=True,
                              user_flip=0, output_color=rawpy.ColorSpace.sRGB,
                              adjust_maximum_thr=0.0).astype(np.float64) / 65535
    # Compare means over everything but the (dilated) near-clipping regions: demosaicing moves values between
    # neighbours, so a per-pixel selection by value would bias the comparison.
    ok = ~_dilate(_dilate(_dilate((linear * factor).max(-1) > 0.6)))
    ratio = dec[ok].mean(0) / (factor * linear[ok].mean(0))
    np.testing.assert_allclose(ratio, 1.0, atol=0.03)
    # the JPEG of the same view: sRGB of decoded_from_linear @ linear (per-view exposure, not normalized)
    jpg = srgb_to_linear(read_image(sphere_capture / "IMG_0001.jpg") / 255.0).astype(np.float64)
    jratio = jpg[ok].mean(0) / (factor * linear[ok].mean(0))
    print("decoded / (factor x linear): DNG", ratio, "JPEG", jratio)
    np.testing.assert_allclose(jratio, 1.0, atol=0.03)


def _distance_to_surface(spec: SceneSpec, p: np.ndarray) -> np.ndarray:
    """Distance of points to the analytic torus / blob surface the object mesh approximates."""
    obj = spec.object
    q = p @ rotation_xyz(obj.tilt_deg)  # world -> object frame (rows: R^T p)
    if obj.kind == "torus":
        total = obj.torus_major + obj.torus_minor
        ring = np.hypot(np.hypot(q[:, 0], q[:, 1]) - obj.torus_major / total, q[:, 2])
        return np.abs(ring - obj.torus_minor / total)
    raw = geometry.radial_surface(
        lambda d: geometry.bump_radius(d, obj.bump_centres, obj.bump_amplitudes, obj.bump_sharpness),
        *obj.mesh_resolution)
    r = np.linalg.norm(q, axis=1)
    expected = geometry.bump_radius(q / r[:, None], obj.bump_centres, obj.bump_amplitudes, obj.bump_sharpness)
    return np.abs(r - expected / raw.bounding_radius)


def test_mesh_scenes_render(tmp_path: Path):
    """blob and torus: PLY meshes in the world frame, bounding radius 1; depths lie on the surface."""
    trimesh = pytest.importorskip("trimesh")
    for name in ("blob", "torus"):
        out = render_capture(small(SCENES[name]), tmp_path / name,
                             SynthOptions(views=1, width=64, height=48, spp=32, env_size=8, coverage_spp=16))
        gt = out / "ground_truth"
        mesh = trimesh.load(gt / "object.ply", process=False)
        assert np.linalg.norm(mesh.vertices, axis=1).max() == pytest.approx(1.0, rel=1e-5)
        cam = load_cameras(gt / "cameras.json").cameras[0]
        depth = read_exr(gt / "depth" / f"{cam.name}.exr")
        hit = np.isfinite(depth)
        assert hit.sum() > 50
        # depth points lie on the mesh
        ij = np.argwhere(hit)
        o, d = _pixel_rays(cam, ij)
        z_dir = d @ cam.c2w[:3, 2]
        pts = o + (depth[hit] / z_dir)[:, None] * d
        # within the mesh's faceting error (a few 1e-4 at this resolution) of the analytic surface
        assert _distance_to_surface(SCENES[name], pts).max() < 3e-3
        residual = read_json(gt / "scene.json")["decomposition_residual"]["relative_mean"]["max"]
        assert residual < 0.1  # few interior pixels at this size; interreflections add ~1 %


def test_a_gold_ball_is_all_reflection_in_golds_colour_and_its_capture_says_metal(tmp_path: Path):
    """The gold scene (a Mitsuba conductor, no diffuse base): its diffuse truth is black, its specular truth the
    whole photo, redder than the room it reflects (gold reflects ~95 % of red, ~40 % of blue); capture.yaml asks
    training for a tinted reflectance."""
    from pipeline.config import load_config

    out = render_capture(small(SCENES["gold"]), tmp_path / "gold",
                         SynthOptions(views=1, width=64, height=48, spp=32, env_size=8, coverage_spp=16))
    gt = out / "ground_truth"
    assert load_config(out / "capture.yaml").train.sdf.reflectance == "tinted"
    assert read_json(gt / "scene.json")["object"]["material"]["type"] == "conductor"
    name = load_cameras(gt / "cameras.json").cameras[0].name
    # interior: no room in the pixel, nor blurred into it (the photos' optics blur)
    obj = cv2.erode((read_image(gt / "coverage" / f"{name}.png") == 255).astype(np.uint8), np.ones((7, 7))) > 0
    diffuse, specular, linear = (read_exr(gt / sub / f"{name}.exr") for sub in ("diffuse", "specular", "linear"))
    assert obj.sum() > 50
    assert np.abs(diffuse[obj]).max() < 1e-3
    np.testing.assert_allclose(specular[obj].mean(0), linear[obj].mean(0), rtol=0.05)
    object_red_blue = specular[obj][:, 0].mean() / specular[obj][:, 2].mean()
    room = read_image(gt / "coverage" / f"{name}.png") == 0
    room_red_blue = linear[room][:, 0].mean() / linear[room][:, 2].mean()
    assert object_red_blue > 1.5 * room_red_blue, (object_red_blue, room_red_blue)


def test_blob_is_convex_and_concave():
    blob = object_mesh(SCENES["blob"].object)
    assert geometry.convexity(blob) < 0.99  # dents: concave regions next to the bumps
    assert blob.bounding_radius == pytest.approx(1.0)
    # Sign of the mean curvature per vertex from the umbrella operator: the neighbours' mean lies behind
    # the tangent plane on convex patches (dot with the outward normal < 0) and in front of it on concave ones.
    import trimesh

    tm = trimesh.Trimesh(blob.vertices, blob.faces, process=True)  # merges the UV seam duplicates
    edges = np.concatenate([tm.edges_unique, tm.edges_unique[:, ::-1]])
    total, count = np.zeros_like(tm.vertices), np.zeros(len(tm.vertices))
    np.add.at(total, edges[:, 0], tm.vertices[edges[:, 1]])
    np.add.at(count, edges[:, 0], 1)
    umbrella = total / count[:, None] - tm.vertices
    h = (umbrella * tm.vertex_normals).sum(1)
    scale = np.abs(h).max()
    assert (h < -0.05 * scale).mean() > 0.3  # mostly convex
    assert (h > 0.05 * scale).mean() > 0.02  # with real concave regions
    torus = object_mesh(SCENES["torus"].object)
    assert trimesh.Trimesh(torus.vertices, torus.faces, process=False).volume > 0  # outward orientation


def test_posters_are_deterministic_and_in_range():
    style = PosterStyle(reflectance=(0.05, 0.7))
    a, b, c = poster(96, 64, 1, style), poster(96, 64, 1, style), poster(96, 64, 2, style)
    assert a.shape == (64, 96, 3) and a.dtype == np.float32
    np.testing.assert_array_equal(a, b)
    assert np.abs(a - c).mean() > 0.05
    assert a.min() >= 0.05 - 1e-6 and a.max() <= 0.7 + 1e-6
    assert a.std() > 0.1  # strong contrast


def test_scene_json_records_geometry(sphere_capture: Path):
    scene = read_json(sphere_capture / "ground_truth" / "scene.json")
    resolved = resolve(SCENES["sphere"])
    assert [p["name"] for p in scene["props"]] == [p.name for p in resolved.props]
    for p in scene["props"]:
        # props one to three object radii from the object's surface
        gap = np.linalg.norm(np.array(p["centre"][:2])) - scene["object"]["radius"]
        assert 0.9 < gap < 3.0, p["name"]
    assert scene["floor_z"] == pytest.approx(-1.0)
    assert scene["radiance_to_decoded"]["factor"] > 0


def test_cli_and_atomic_failure(tmp_path: Path, monkeypatch):
    from pipeline.errors import InputError
    from pipeline.synth import cli

    parser = argparse.ArgumentParser()
    cli.register(parser.add_subparsers())
    out = tmp_path / "cap"
    args = parser.parse_args(["synth", "sphere", str(out), "--views", "2", "--width", "32", "--height", "24",
                              "--spp", "4", "--env-size", "8", "--format", "jpg", "--seed", "1"])
    args.func(args)
    assert sorted(p.name for p in out.iterdir()) == ["IMG_0001.jpg", "IMG_0002.jpg", "capture.yaml", "ground_truth"]
    assert load_cameras(out / "ground_truth" / "cameras.json").cameras[0].image == "../IMG_0001.jpg"

    with pytest.raises(InputError):  # no silent overwrite
        render_capture("sphere", out, SynthOptions(views=1, width=16, height=12, spp=1, env_size=8))

    calls = {"n": 0}
    original = synth_render._write_view_truth

    def fail_on_second(*a, **k):
        calls["n"] += 1
        if calls["n"] == 2:
            raise RuntimeError("disk full (simulated)")
        return original(*a, **k)

    monkeypatch.setattr(synth_render, "_write_view_truth", fail_on_second)
    spec = small(replace(SCENES["sphere"], object=replace(SCENES["sphere"].object, albedo=AlbedoSpec())))
    fresh = tmp_path / "fresh"
    with pytest.raises(RuntimeError, match="simulated"):
        render_capture(spec, fresh, SynthOptions(views=2, width=16, height=12, spp=1, env_size=8))
    assert not fresh.exists()
    before = sorted(p.name for p in out.rglob("*"))
    calls["n"] = 0
    with pytest.raises(RuntimeError, match="simulated"):
        render_capture(spec, out, SynthOptions(views=2, width=16, height=12, spp=1, env_size=8), overwrite=True)
    assert sorted(p.name for p in out.rglob("*")) == before  # the existing capture is untouched
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cap"]  # no temporary folders left behind


def test_light_pixels_are_found_from_geometry():
    """on_lights must not depend on Mitsuba's shape order (it changes with thread timing between loads)."""
    from pipeline.synth.scenes import LightSpec

    light = LightSpec(centre=(0.0, 0.0, 5.49), size=(2.0, 2.0), normal=(0.0, 0.0, -1.0), radiance=(9.0, 9.0, 9.0))
    position = np.array([[[0.3, -0.4, 5.49], [0.3, -0.4, 5.5], [3.0, 0.0, 5.49], [0.0, 0.0, 0.0]]])
    np.testing.assert_array_equal(synth_render.on_lights(position, [light]), [[True, False, False, False]])
