"""Virtual cones (orca.cones) against exact optics: plane mirror, brute-force tracing through analytic convex
and concave spheres, the astigmatic foci, and the guards (H≈0, back-facing, grazing, huge footprints,
collimation, float32, gradients, batch shapes).

The brute-force reference traces a few hundred rays across the pixel footprint (an exactly isotropic polar
grid: random sampling breaks the isotropy by ~1/√N and moves the least-squares apex by as much) through the
ANALYTIC surface in float64 — exact ray–sphere intersection, exact normals — reflects them and takes the
least-squares point closest to all reflected rays and the RMS angular spread.
"""

from __future__ import annotations

import math

import pytest
import torch
from helpers import random_rotation

from orca.cones import VirtualCone, astigmatic_vergences, osculating_sphere_center, virtual_cone
from orca.geometry_utils import orthonormal_basis

F64 = torch.float64
METHODS = ["closed_form", "bounding_rays"]


# ------------------------------------------------------------------------------------------------ helpers


def _basis(d: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Independent of orca.geometry_utils on purpose."""
    h = torch.tensor([0.0, 0.0, 1.0], dtype=F64) if abs(d[2]) < 0.9 else torch.tensor([1.0, 0.0, 0.0], dtype=F64)
    e1 = torch.linalg.cross(d, h)
    e1 = e1 / e1.norm()
    return e1, torch.linalg.cross(d, e1)


class Scene:
    """Camera at distance ``s`` from surface point ``p``, at incidence angle ``theta`` to the normal ``n``.

    kind: "convex" (sphere of radius R, H = +1/R), "concave" (inside of a sphere, H = −1/R) or "plane".
    """

    def __init__(self, kind: str, theta_deg: float, s: float, R: float = 0.7, seed: int = 0):
        rot = torch.from_numpy(random_rotation(seed))  # no test in an axis-aligned special position
        th = math.radians(theta_deg)
        self.kind, self.R, self.s = kind, R, s
        self.p = rot @ torch.tensor([0.2, -0.1, 0.3], dtype=F64)
        self.n = rot @ torch.tensor([0.0, 0.0, 1.0], dtype=F64)
        to_cam = rot @ torch.tensor([math.sin(th), 0.0, math.cos(th)], dtype=F64)
        self.o = self.p + s * to_cam
        self.d = -to_cam
        self.H = {"convex": 1 / R, "concave": -1 / R, "plane": 0.0}[kind]
        self.centre = None if kind == "plane" else self.p - self.n / self.H

    def cone(self, r: float, method: str, dtype=F64, **kw) -> VirtualCone:
        args = [self.o, self.d, torch.tensor(r, dtype=F64), self.p, self.n, torch.tensor(self.H, dtype=F64)]
        return virtual_cone(*(a.to(dtype) for a in args), method=method, **kw)

    def trace(self, offsets: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Exact reflection of rays from o in directions d + offsets (``(M, 3)``, ⊥ d): hit points, incoming and
        reflected directions."""
        dj = self.d + offsets
        dj = dj / dj.norm(dim=-1, keepdim=True)
        if self.centre is None:
            t = ((self.p - self.o) @ self.n) / (dj @ self.n)
            x = self.o + t[:, None] * dj
            nj = self.n.expand_as(x)
        else:
            oc = self.o - self.centre
            b = dj @ oc
            disc = b * b - (oc @ oc - self.R**2)
            assert (disc > 0).all(), "brute-force ray missed the analytic sphere"
            roots = torch.stack([-b - disc.sqrt(), -b + disc.sqrt()], -1)
            pick = (roots - self.s).abs().argmin(-1)  # the intersection on the branch through p
            t = roots.gather(-1, pick[:, None])[:, 0]
            x = self.o + t[:, None] * dj
            nj = (x - self.centre) / self.R
            nj = nj * torch.sign(nj @ self.n)[:, None]
        w = dj - 2 * (dj * nj).sum(-1, keepdim=True) * nj
        return x, dj, w


def _footprint_offsets(d: torch.Tensor, r: float, n_rings: int = 12, n_angles: int = 32) -> torch.Tensor:
    """Exactly isotropic, area-uniform polar grid over the pixel disc of angular radius r, plus the chief ray."""
    e1, e2 = _basis(d)
    rad = r * ((torch.arange(n_rings, dtype=F64) + 0.5) / n_rings).sqrt()
    phi = torch.arange(n_angles, dtype=F64) * (2 * math.pi / n_angles) + 0.3
    rad, phi = (t.reshape(-1) for t in torch.meshgrid(rad, phi, indexing="ij"))
    offs = rad[:, None] * (phi.cos()[:, None] * e1 + phi.sin()[:, None] * e2)
    return torch.cat([torch.zeros(1, 3, dtype=F64), offs])


def _ls_apex(x: torch.Tensor, w: torch.Tensor, origin: torch.Tensor) -> torch.Tensor:
    """Point minimizing the summed squared distances to the lines x_i + t w_i (float64).

    Solved as the stacked system e_ik · (v − x_i) = 0 for two unit vectors e_ik ⊥ w_i, by QR: this squares
    neither the small angles between the rays (the normal equations Σ(I − w wᵀ) would) nor anything else.
    """
    h = torch.tensor([0.3, -0.5, 0.8], dtype=F64)
    e1 = torch.linalg.cross(w, h.expand_as(w))
    e1 = e1 / e1.norm(dim=-1, keepdim=True)
    e2 = torch.linalg.cross(w, e1)
    A = torch.cat([e1, e2])
    b = torch.cat([(e1 * (x - origin)).sum(-1), (e2 * (x - origin)).sum(-1)])
    return origin + torch.linalg.lstsq(A, b[:, None]).solution[:, 0]


def brute_force(scene: Scene, r: float) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """(apex, radius growth, axis) of the reflected bundle through the exact surface."""
    x, dj, w = scene.trace(_footprint_offsets(scene.d, r))
    apex = _ls_apex(x, w, scene.p)
    spread = r * (w[1:] - w[0]).square().sum(-1).mean().sqrt() / (dj[1:] - dj[0]).square().sum(-1).mean().sqrt()
    return apex, spread, w[0]


def _rand_unit(n: int, g: torch.Generator) -> torch.Tensor:
    v = torch.randn(n, 3, generator=g, dtype=F64)
    return v / v.norm(dim=-1, keepdim=True)


def random_batch(n: int, seed: int, max_deg: float = 80.0, r: float = 1e-3, curv_scale: float = 3.0):
    """Random camera/surface configurations: (o, d, r, p, n, H), float64, front-facing, p on the ray."""
    g = torch.Generator().manual_seed(seed)
    nrm = _rand_unit(n, g)
    p = 0.5 * torch.randn(n, 3, generator=g, dtype=F64)
    t = _rand_unit(n, g)
    t = t - (t * nrm).sum(-1, keepdim=True) * nrm
    t = t / t.norm(dim=-1, keepdim=True)
    th = torch.rand(n, generator=g, dtype=F64) * math.radians(max_deg)
    to_cam = th.cos()[:, None] * nrm + th.sin()[:, None] * t
    s = 0.5 + 4 * torch.rand(n, generator=g, dtype=F64)
    o = p + s[:, None] * to_cam
    H = curv_scale * torch.randn(n, generator=g, dtype=F64)
    return o, -to_cam, torch.full((n,), r, dtype=F64), p, nrm, H


def _assert_finite(cone: VirtualCone) -> None:
    for name, v in zip(cone._fields, cone):
        assert torch.isfinite(v).all(), f"{name} has non-finite values"


# ------------------------------------------------------------------------------------------------ exact cases


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("theta", [0, 30, 60, 75])
@pytest.mark.parametrize("s", [0.3, 3.0])
def test_plane_mirror_apex_is_the_mirror_image_of_the_camera(method, theta, s):
    sc = Scene("plane", theta, s)
    r = 2e-3
    mirror = sc.o - 2 * ((sc.o - sc.p) @ sc.n) * sc.n
    cone = sc.cone(r, method)
    torch.testing.assert_close(cone.apex, mirror, rtol=0, atol=1e-12)
    torch.testing.assert_close(cone.radius_growth, torch.tensor(r, dtype=F64), rtol=1e-12, atol=0)
    torch.testing.assert_close(cone.t_start, torch.tensor(s, dtype=F64), rtol=1e-12, atol=0)
    # a few ulps of a unit vector: the reflection's rounding differs by CPU (AVX2 against AVX-512)
    torch.testing.assert_close(cone.axis, sc.d - 2 * (sc.d @ sc.n) * sc.n, rtol=0, atol=8 * torch.finfo(F64).eps)
    # float32: same answer to float32 precision
    c32 = sc.cone(r, method, dtype=torch.float32)
    torch.testing.assert_close(c32.apex.double(), mirror, rtol=0, atol=5e-6 * s)
    torch.testing.assert_close(c32.radius_growth.double(), torch.tensor(r, dtype=F64), rtol=1e-5, atol=0)


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("kind", ["convex", "concave"])
@pytest.mark.parametrize("theta", [0, 30, 60, 75])
@pytest.mark.parametrize("s", [0.3, 1.0, 3.0])
def test_matches_brute_force_through_the_analytic_sphere(method, kind, theta, s):
    """Pixel-sized footprint (r = 1e-3, footprint ≤ 0.4 % of R): apex and spread within 1 % of brute force."""
    sc = Scene(kind, theta, s, seed=theta + int(10 * s))
    r = 1e-3
    apex, spread, axis = brute_force(sc, r)
    cone = sc.cone(r, method)
    scale = (apex - sc.p).norm()
    assert (cone.apex - apex).norm() / scale < 1e-2
    assert abs(cone.radius_growth / spread - 1) < 1e-2
    assert (cone.axis - axis).norm() < 1e-12
    # the sign of t_start says which side the apex is on
    assert torch.sign(cone.t_start) == torch.sign((sc.p - apex) @ axis)


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("kind,theta,s", [("convex", 75, 3.0), ("concave", 60, 3.0), ("convex", 30, 1.0)])
def test_converges_to_the_brute_force_bundle_as_the_footprint_shrinks(method, kind, theta, s):
    """The closed form is the small-footprint limit: the error falls like the footprint squared (down to the
    float64 conditioning of the brute-force least squares, ~1e-6 at r = 1e-5)."""
    sc = Scene(kind, theta, s, seed=3)
    errs = []
    for r in [1e-3, 1e-4, 1e-5]:
        apex, spread, _ = brute_force(sc, r)
        cone = sc.cone(r, method)
        errs.append(max(((cone.apex - apex).norm() / (apex - sc.p).norm()).item(),
                        abs(cone.radius_growth / spread - 1).item()))
    assert errs[1] < max(errs[0] / 30, 1e-8)
    assert errs[2] < 2e-6


def test_astigmatic_foci_and_least_squares_apex_at_60_degrees():
    """Distant camera, convex sphere, 60° incidence: the tangential fan focuses R cosθ/2 = 0.25 R behind the
    surface, the sagittal fan R/(2 cosθ) = R; the least-squares apex of the whole bundle is 5R/17 ≈ 0.294 R —
    not their average (0.625 R), not the circle of least confusion (0.4 R), not the mirror equation (0.5 R)."""
    R, s = 1.0, 1e4
    sc = Scene("convex", 60, s, R=R, seed=5)
    r = 1e-8  # footprint 1e-4 R
    e1, e2 = _basis(sc.d)
    # e_t: offset direction in the plane of incidence, e_s: perpendicular to it
    e_s = torch.linalg.cross(sc.d, sc.n)
    e_s = e_s / e_s.norm()
    e_t = torch.linalg.cross(e_s, sc.d)
    lin = torch.linspace(-r, r, 41, dtype=F64)[:, None]

    def depth_behind(apex, axis):
        return ((sc.p - apex) @ axis).item()

    x, _, w = sc.trace(lin * e_t)
    tang = depth_behind(_ls_apex(x, w, sc.p), w[20])
    x, _, w = sc.trace(lin * e_s)
    sag = depth_behind(_ls_apex(x, w, sc.p), w[20])
    apex, _, axis = brute_force(sc, r)
    full = depth_behind(apex, axis)

    u_t, u_s = astigmatic_vergences(torch.tensor(0.5, dtype=F64), torch.tensor(1 / R, dtype=F64),
                                    torch.tensor(s, dtype=F64))
    assert tang == pytest.approx(-1 / u_t.item(), rel=1e-5) and tang == pytest.approx(0.25 * R, rel=2e-4)
    assert sag == pytest.approx(-1 / u_s.item(), rel=1e-5) and sag == pytest.approx(1.0 * R, rel=2e-4)
    assert full == pytest.approx(5 / 17 * R, rel=2e-4)
    assert abs(full - 0.5 * (tang + sag)) > 0.5 * full  # the plain average is far off
    for method in METHODS:
        assert sc.cone(r, method).t_start.item() == pytest.approx(full, rel=1e-4)


def test_concave_mirror_has_a_real_focus_in_front():
    """Object beyond the focal length: converging beam, apex (real image) in front of the surface, t_start < 0;
    mirror equation at normal incidence: 1/s + 1/s' = 2/R."""
    R, s = 1.0, 3.0
    sc = Scene("concave", 0, s, R=R)
    for method in METHODS:
        cone = sc.cone(1e-4, method)
        s_img = 1 / (2 / R - 1 / s)
        assert cone.t_start.item() == pytest.approx(-s_img, rel=1e-6)
        assert ((cone.apex - sc.p) @ sc.n).item() > 0  # in front of the mirror
        # the beam narrows to the focus and widens again: radius |growth · t| over t ∈ [t_start, ∞)
        t = torch.tensor([cone.t_start.item(), 0.0, 1.0], dtype=F64)
        rad = cone.radius_at(t)
        assert rad[0] == pytest.approx(1e-4 * s, rel=1e-6) and rad[1] == 0 and rad[2] > 0


# ------------------------------------------------------------------------------------------------ the two constructions


def test_closed_form_and_bounding_rays_agree_on_random_configurations():
    o, d, r, p, n, H = random_batch(4000, seed=1, max_deg=80.0, r=1e-3)
    a = virtual_cone(o, d, r, p, n, H, method="closed_form")
    b = virtual_cone(o, d, r, p, n, H, method="bounding_rays")
    rho = r * (p - o).norm(dim=-1)
    # valid regime of the first-order picture: footprint ≪ radius of curvature · cos²θ
    x = rho * H.abs() / (d * n).sum(-1).square()
    ok = x < 1e-2
    assert ok.float().mean() > 0.5
    torch.testing.assert_close(a.axis, b.axis, rtol=0, atol=1e-14)
    assert ((a.radius_growth - b.radius_growth).abs() / a.radius_growth)[ok].max() < 1e-3
    assert ((a.radius_at_surface - b.radius_at_surface).abs() / rho)[ok].max() < 1e-3


@pytest.mark.parametrize("K,rot,tol", [(3, 0.0, 2e-3), (4, 0.0, 1e-4), (8, 0.0, 1e-4), (4, 0.7, 1e-4)])
def test_bounding_rays_do_not_depend_on_their_number_or_orientation(K, rot, tol):
    """The least-squares apex and the RMS spread only see second moments of the ring of bounding rays, which
    are isotropic for any K ≥ 3 equally spaced rays at any rotation. (An odd K also lets first-order
    finite-footprint terms through, which an even K cancels by symmetry: hence the looser tolerance.)"""
    sc = Scene("convex", 60, 2.0, seed=9)
    ref = sc.cone(1e-4, "closed_form")
    # rotating the ring about d = rotating the camera frame: emulate by rotating the whole scene about d
    c, s_ = math.cos(rot), math.sin(rot)
    k = sc.d
    Rm = c * torch.eye(3, dtype=F64) + s_ * torch.tensor(
        [[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]], dtype=F64) + (1 - c) * torch.outer(k, k)
    args = [sc.o, sc.d, torch.tensor(1e-4, dtype=F64), sc.p, Rm @ sc.n, torch.tensor(sc.H, dtype=F64)]
    cone = virtual_cone(*args, method="bounding_rays", num_bounding_rays=K)
    ref = virtual_cone(*args, method="closed_form")
    assert cone.t_start.item() == pytest.approx(ref.t_start.item(), rel=tol)
    assert cone.radius_growth.item() == pytest.approx(ref.radius_growth.item(), rel=tol)


def test_too_few_bounding_rays_is_an_error():
    sc = Scene("convex", 30, 1.0)
    with pytest.raises(ValueError):
        sc.cone(1e-3, "bounding_rays", num_bounding_rays=2)
    with pytest.raises(ValueError):
        sc.cone(1e-3, "nonsense")


def test_naive_ablation_restarts_the_pixel_cone_at_the_surface():
    sc = Scene("convex", 45, 2.0)
    cone = sc.cone(1e-3, "naive")
    torch.testing.assert_close(cone.apex, sc.p)
    assert cone.t_start.item() == 0 and cone.radius_growth.item() == pytest.approx(1e-3)
    torch.testing.assert_close(cone.axis, sc.d - 2 * (sc.d @ sc.n) * sc.n)


# ------------------------------------------------------------------------------------------------ guards


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("dtype", [F64, torch.float32])
def test_continuous_through_zero_curvature(method, dtype):
    sc = Scene("plane", 50, 2.0)
    H = torch.cat([torch.linspace(-1e-4, 1e-4, 201, dtype=F64), torch.tensor([1e-30, -1e-30, 1e-38], dtype=F64)])
    n = H.numel()
    args = [sc.o.expand(n, 3), sc.d.expand(n, 3), torch.full((n,), 1e-3, dtype=F64), sc.p.expand(n, 3),
            sc.n.expand(n, 3), H]
    cone = virtual_cone(*(a.to(dtype) for a in args), method=method)
    _assert_finite(cone)
    t = cone.t_start.double()
    g = cone.radius_growth.double()
    tol = 1e-9 if dtype == F64 else 2e-5
    # the sweep is smooth and monotone (more convex -> apex closer to the surface) and passes through the plane
    assert (t[1:201] - t[:200] < tol * 2).all()
    assert torch.diff(t[:201]).abs().max() < 1e-3 * 2.0
    torch.testing.assert_close(t[100], torch.tensor(2.0, dtype=F64), rtol=tol, atol=0)
    torch.testing.assert_close(t[201:], torch.full((3,), 2.0, dtype=F64), rtol=tol, atol=0)
    torch.testing.assert_close(g[201:], torch.full((3,), 1e-3, dtype=F64), rtol=tol, atol=0)


@pytest.mark.parametrize("method", METHODS)
def test_back_facing_normals_give_the_same_cone(method):
    """(n, H) and (−n, −H) describe the same osculating sphere: same cone."""
    o, d, r, p, n, H = random_batch(500, seed=2)
    a = virtual_cone(o, d, r, p, n, H, method=method)
    b = virtual_cone(o, d, r, p, -n, -H, method=method)
    for name, u, v in zip(a._fields, a, b):
        torch.testing.assert_close(u, v, rtol=1e-9, atol=1e-12, msg=name)
    # a convex sphere seen through a back-facing normal with the same H would be a concave one: not the same
    c = virtual_cone(o, d, r, p, -n, H, method=method)
    convex = H > 0.5
    assert (c.t_start[convex] < a.t_start[convex]).all()


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("dtype", [F64, torch.float32])
@pytest.mark.parametrize("kind", ["convex", "concave"])
@pytest.mark.parametrize("theta", [0.0, 60.0, 89.0, 89.999, 90.0])
def test_huge_footprints_and_grazing_incidence_stay_finite_and_capped(method, dtype, kind, theta):
    """Footprint many times the radius of curvature (ρ = 1.5, R = 0.05), and exactly grazing incidence."""
    sc = Scene(kind, theta, 3.0, R=0.05)
    for r in [1e-3, 0.5]:
        cone = sc.cone(r, method, dtype=dtype, max_radius_growth=2.0, max_apex_ratio=1e4)
        _assert_finite(cone)
        assert cone.radius_growth.item() <= 2.0 * (1 + 1e-6)
        assert abs(cone.t_start.item()) <= 1e4 * 3.0 * (1 + 1e-6)
        assert cone.axis.norm().item() == pytest.approx(1.0, abs=1e-5)
        if method == "closed_form":
            assert cone.radius_at_surface.item() <= r * 3.0 * (1 + 1e-5)


@pytest.mark.parametrize("method", METHODS)
def test_collimated_beam_from_a_concave_mirror_becomes_a_cylinder(method):
    """Camera at the focal distance of a concave mirror, normal incidence: the reflected rays are parallel.
    The apex is pushed far away (capped) and the cone keeps the footprint's width."""
    R = 1.0
    sc = Scene("concave", 0, R / 2, R=R)
    r = 1e-3
    cone = sc.cone(r, method)
    _assert_finite(cone)
    assert abs(cone.t_start.item()) > 100 * sc.s
    if method == "closed_form":
        assert cone.radius_at_surface.item() == pytest.approx(r * sc.s, rel=1e-6)
        assert cone.radius_growth.item() == pytest.approx(r * sc.s / (1e4 * sc.s), rel=1e-6)
    # just off the focus both constructions agree and are continuous
    for ds in [1e-3, -1e-3]:
        sc2 = Scene("concave", 0, R / 2 + ds, R=R)
        a, b = sc2.cone(r, "closed_form"), sc2.cone(r, "bounding_rays")
        assert a.t_start.item() == pytest.approx(b.t_start.item(), rel=1e-3)
        assert a.radius_at_surface.item() == pytest.approx(r * sc2.s, rel=1e-3)


@pytest.mark.parametrize("method", METHODS)
def test_float32_matches_float64(method):
    """Pixel-sized footprints (1e-3) over random geometry incl. H ≈ 0: float32 keeps the radius profile
    (radius at the surface relative to the footprint, growth relative to itself) to 1e-4."""
    o, d, r, p, n, H = random_batch(2000, seed=3, max_deg=85.0)
    H[:300] *= 1e-7
    H[300:600] = 0
    a = virtual_cone(o, d, r, p, n, H, method=method)
    b = virtual_cone(*(t.float() for t in (o, d, r, p, n, H)), method=method)
    _assert_finite(b)
    rho = r * (p - o).norm(dim=-1)
    x = rho * H.abs() / (d * n).sum(-1).square()
    ok = x < 0.1  # beyond this the bounding rays straddle the osculating sphere's silhouette
    e0 = (b.radius_at_surface.double() - a.radius_at_surface).abs() / rho
    eg = (b.radius_growth.double() - a.radius_growth).abs() / a.radius_growth
    assert e0[ok].max() < 1e-4 and eg[ok].max() < 1e-4
    assert ((b.axis.double() - a.axis).norm(dim=-1)).max() < 1e-6


@pytest.mark.parametrize("method", METHODS)
def test_gradients_are_correct_and_finite(method):
    """gradcheck (float64) w.r.t. points, normals, curvature, origins and directions; convex, concave and flat,
    normal and oblique incidence."""
    o, d, r, p, n, H = random_batch(4, seed=4, max_deg=70.0, r=1e-2)
    H[0] = 0.0
    H[1] = -0.3
    n = n + 0.01  # not exactly unit: normalization is part of the function
    inputs = [t.clone().requires_grad_(True) for t in (o, d, p, n, H)]

    def f(o_, d_, p_, n_, H_):
        return tuple(virtual_cone(o_, d_, r, p_, n_, H_, method=method)[:4])

    assert torch.autograd.gradcheck(f, inputs, eps=1e-7, atol=1e-6, rtol=1e-5)


@pytest.mark.parametrize("method", METHODS)
def test_gradients_finite_at_the_edge_cases(method):
    cases = [Scene("plane", 0, 1.0), Scene("concave", 0, 0.5, R=1.0), Scene("convex", 90, 2.0, R=0.05),
             Scene("concave", 89.999, 2.0, R=0.05)]
    for sc in cases:
        for r in [1e-3, 0.5]:
            for dtype in [F64, torch.float32]:
                p = sc.p.detach().to(dtype).clone().requires_grad_(True)
                n = sc.n.detach().to(dtype).clone().requires_grad_(True)
                H = torch.tensor(sc.H, dtype=dtype, requires_grad=True)
                cone = virtual_cone(sc.o.to(dtype), sc.d.to(dtype), torch.tensor(r, dtype=dtype), p, n, H,
                                    method=method)
                (cone.apex.sum() + cone.axis.sum() + cone.radius_growth + cone.t_start).backward()
                for t in (p, n, H):
                    assert torch.isfinite(t.grad).all(), (sc.kind, r, dtype)


# ------------------------------------------------------------------------------------------------ shapes, API


@pytest.mark.parametrize("method", ["closed_form", "bounding_rays", "naive"])
def test_batch_shapes_broadcast(method):
    o, d, r, p, n, H = random_batch(10, seed=5)
    # one camera per ray (2, 1, 3), samples along rays (2, 5, 3), per-ray radii (2, 1), per-sample H (2, 5)
    o2 = o[:2, None]
    d2 = d[:2, None].expand(2, 5, 3)
    r2 = r[:2, None]
    p2, n2, H2 = p.reshape(2, 5, 3), n.reshape(2, 5, 3), H.reshape(2, 5)
    cone = virtual_cone(o2, d2, r2, p2, n2, H2, method=method)
    assert cone.apex.shape == (2, 5, 3) and cone.axis.shape == (2, 5, 3)
    assert cone.radius_growth.shape == (2, 5) and cone.t_start.shape == (2, 5)
    assert cone.surface_point.shape == (2, 5, 3)
    flat = virtual_cone(o2.expand(2, 5, 3).reshape(10, 3), d2.reshape(10, 3), r2.expand(2, 5).reshape(10),
                        p2.reshape(10, 3), n2.reshape(10, 3), H2.reshape(10), method=method)
    for u, v in zip(cone, flat):
        torch.testing.assert_close(u.reshape(v.shape), v)
    # a single configuration: (3,) vectors and 0-d scalars
    one = virtual_cone(o[0], d[0], r[0], p[0], n[0], H[0], method=method)
    assert one.apex.shape == (3,) and one.t_start.shape == ()
    # the derived quantities
    t = torch.tensor([[0.0, 1.0]], dtype=F64).expand(2, 5, 2)
    pts = cone.point_at(t + cone.t_start[..., None])
    torch.testing.assert_close(pts[..., 0, :], cone.surface_point)
    torch.testing.assert_close(cone.apex + cone.t_start[..., None] * cone.axis, cone.surface_point)
    assert cone.radius_at(t).shape == (2, 5, 2)


def test_helpers():
    v = _rand_unit(50, torch.Generator().manual_seed(0))
    v[0] = torch.tensor([0.0, 0.0, -1.0], dtype=F64)
    e1, e2 = orthonormal_basis(v)
    torch.testing.assert_close(torch.linalg.cross(e1, e2), v)
    torch.testing.assert_close((e1 * v).sum(-1), torch.zeros(50, dtype=F64), rtol=0, atol=1e-14)
    sc = Scene("convex", 30, 1.0, R=0.7)
    torch.testing.assert_close(osculating_sphere_center(sc.p, sc.n, torch.tensor(sc.H, dtype=F64)), sc.centre)
