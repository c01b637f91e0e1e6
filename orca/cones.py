r"""Virtual cones (ORCa, section 3.3): the cone a pixel's reflected beam sweeps into the environment.

A pixel cone (apex ``o``, unit axis ``d``, mip-NeRF radius growth ``r``: radius ``r t`` at distance ``t``)
hits a glossy surface at ``p`` with unit normal ``n`` and mean curvature ``H``. Near ``p`` the surface is
replaced by its **osculating sphere** (radius ``1/|H|``, centre ``p − n/H``), and the reflected beam is
replaced by a **virtual cone**: axis ``ω_r = d − 2(d·n)n``, an apex (virtual centre of projection) on the
line through ``p`` along ``ω_r``, and a radius growth. The environment field then integrates conical
frustums along that cone from the surface point outwards (mip-NeRF style).

Conventions
-----------
* Curvature: ``H = ½ div n`` with ``n`` the outward normal (as in :mod:`orca.differential`): a convex
  sphere of radius ``R`` has ``H = +1/R``, a plane ``0``, a concave mirror ``H < 0``. The osculating
  sphere's centre is ``p − n/H`` (inside a convex object, in front of a concave one). The paper writes
  ``R = 2/K`` and ``o_S = p + R n``; with ``K = ½ div n`` that is a typo/sign slip; we use ``R = 1/H``.
* Back-facing normals (``d·n > 0``, e.g. samples behind the surface during volume rendering): the
  osculating sphere ``{x : H|x−p|² + 2 n·(x−p) = 0}`` does not change under ``(n, H) → (−n, −H)``, and
  neither does ``ω_r``, so we flip both to the side facing the camera and reflect off that side. The
  bounding-ray construction does the same implicitly; both constructions agree for either sign.
* ``radii`` is mip-NeRF's pixel-cone radius growth per unit distance along the (normalized) ray,
  ``pixel width · 2/√12 / focal``. The virtual cone's ``radius_growth`` is in the same units, so a
  plane mirror returns exactly the incoming value.
* Inputs ``dirs`` and ``normals`` are normalized here; they need not be exactly unit.
* Shapes: every ``(..., 3)`` / ``(...)`` input broadcasts against the others over the leading dims
  (e.g. origins ``(R, 1, 3)`` with points ``(R, S, 3)``); outputs have the broadcast leading shape.

Representation (see :class:`VirtualCone`)
-----------------------------------------
Points on the cone are ``apex + t · axis`` with the radius ``radius_growth · |t|``. ``t_start`` is the
signed axial coordinate of the surface point, so the environment segment is ``t ∈ [t_start, ∞)``:

* ``t_start > 0`` — diverging beam, virtual apex *behind* the surface (convex, flat: the camera's mirror
  image, ``t_start = |p − o|``);
* ``t_start < 0`` — converging beam (concave, object beyond the focal length): a real focus at distance
  ``|t_start|`` *in front of* the surface; the beam narrows to the apex and widens again. mip-NeRF's frustum
  moments depend on ``t`` only through the cone's ``t²`` weight, so they stay valid for signed
  ``t0 < t1`` (a frustum straddling ``t = 0`` is a double cone);
* near collimation (concave, object near the focal length) ``|t_start|`` is capped at
  ``max_apex_ratio · |p − o|`` while keeping the radius at the surface, so the cone tends to a cylinder.

``radius_at_surface = radius_growth · |t_start|`` is always bounded by the incoming footprint radius
``r |p − o|``. Downstream code should place samples as ``surface_point + (t − t_start) axis`` rather than
``apex + t axis`` (no cancellation when the apex is far away).

Constructions (``method=``)
---------------------------
``"bounding_rays"`` (the paper): ``K`` (default 4) rays on the pixel cone's boundary at angles
``2πj/K``, intersected with the osculating sphere, reflected about the sphere's normals there; the apex is
the least-squares point closest to these ``K`` reflected rays and the central one (projected onto the axis
through ``p``), and the radius growth is ``r · rms|ω_j − ω_r| / rms|d_j − d|`` (RMS rather than the mean:
invariant to how the ``K`` rays are rotated about ``d``, exact for a plane).

``"closed_form"`` (default): the small-footprint limit of the same least-squares apex and spread, from the
Coddington equations of the osculating sphere (derivation: ``docs/virtual_cones.md``). With
``s = |p − o|``, ``c = cos θ = −d·n`` and the reflected bundle's tangential / sagittal vergences
(inverse focal distances, positive = real focus in front of the surface)

    u_t = −2H / c − 1/s,        u_s = −2H c − 1/s,

a reflected ray through the footprint point ``ρ(cos φ, sin φ)`` (``ρ = r s``) has transverse position
``ρ(cos φ (1 − z u_t), sin φ (1 − z u_s))`` at distance ``z`` along the axis. The least-squares apex minimizes
the mean squared distance to all rays, i.e. it is the waist of the RMS beam radius
``ρ²[(1 − z u_t)² + (1 − z u_s)²]/2``:

    z* = (u_t + u_s) / (u_t² + u_s²),     t_start = −z*,     radius_growth = ρ √((u_t² + u_s²)/2).

This is neither focal line, nor their average, nor the circle of least confusion ``2/(u_t+u_s)``. For a
convex sphere viewed from afar at 60°: tangential focus 0.25 R, sagittal 1.0 R, their average 0.625 R,
circle of least confusion 0.4 R, mean-curvature mirror equation 0.5 R, least-squares apex 5R/17 ≈ 0.294 R
behind the surface. The code evaluates these in a dimensionless form that is polynomial in ``H`` (no
``1/H``; continuous through ``H = 0``) and never divides by ``c`` except in the spread.

``"naive"`` (the paper's ablation, sec. 4.4): mip-NeRF's cone re-emitted at the surface point: apex ``p``,
axis ``ω_r``, radius growth ``r``, ``t_start = 0``.

Guards: grazing incidence and huge footprints (footprint larger than the radius of curvature) can make the
first-order spread explode; ``radius_growth`` is capped at ``max_radius_growth`` (the apex moves back so
the radius at the surface is kept). Bounding rays that miss the osculating sphere use the point of closest
approach. All outputs stay finite in float32 and float64.
"""

from __future__ import annotations

import math
from typing import Literal, NamedTuple

import torch
from torch import Tensor

from orca.geometry_utils import dot, orthonormal_basis, reflect, safe_norm, safe_normalize

Method = Literal["closed_form", "bounding_rays", "naive"]
# vergences within this many machine epsilons of zero are a collimated beam: rounding, not curvature (a beam
# that near collimation has its apex far past the max_apex_ratio cap anyway)
COLLIMATED_ULPS = 16

__all__ = [
    "VirtualCone",
    "virtual_cone",
    "closed_form_cone",
    "bounding_ray_cone",
    "naive_cone",
    "astigmatic_vergences",
    "osculating_sphere_center",
]


class VirtualCone(NamedTuple):
    """A virtual cone, all fields with the broadcast leading shape ``(...)``.

    Attributes:
        apex: ``(..., 3)`` virtual centre of projection ``surface_point − t_start · axis``.
        axis: ``(..., 3)`` unit reflected direction ``ω_r = d − 2(d·n)n``.
        radius_growth: ``(...)`` cone radius per unit axial distance from the apex, ``≥ 0``.
        t_start: ``(...)`` signed axial coordinate of the surface point measured from the apex:
            ``> 0`` virtual apex behind the surface (diverging), ``< 0`` real focus in front (converging).
        surface_point: ``(..., 3)`` the surface point ``p`` where environment integration starts.
    """

    apex: Tensor
    axis: Tensor
    radius_growth: Tensor
    t_start: Tensor
    surface_point: Tensor

    @property
    def radius_at_surface(self) -> Tensor:
        """``(...)`` cone radius at the surface point, ``radius_growth · |t_start|``."""
        return self.radius_growth * self.t_start.abs()

    def radius_at(self, t: Tensor) -> Tensor:
        """Cone radius ``radius_growth · |t|`` at axial coordinates ``t`` of shape ``(..., S)``."""
        return self.radius_growth[..., None] * t.abs()

    def point_at(self, t: Tensor) -> Tensor:
        """Points on the axis at axial coordinates ``t`` ``(..., S)`` → ``(..., S, 3)``, measured from the
        apex but computed from the surface point (stable when the apex is far away)."""
        return self.surface_point[..., None, :] + (t - self.t_start[..., None])[..., None] * self.axis[..., None, :]


# ----------------------------------------------------------------------------------------------------------
# Shared preparation and finishing
# ----------------------------------------------------------------------------------------------------------


class _Prepared(NamedTuple):
    o: Tensor  # (..., 3) camera centres
    d: Tensor  # (..., 3) unit primary directions
    r: Tensor  # (...) incoming radius growth
    p: Tensor  # (..., 3) surface points
    n: Tensor  # (..., 3) unit normals, flipped to face the camera
    H: Tensor  # (...) mean curvature w.r.t. the flipped normal
    c: Tensor  # (...) cos of the incidence angle, = −d·n ≥ 0
    s: Tensor  # (...) object distance |p − o|
    axis: Tensor  # (..., 3) reflected chief direction


def _prepare(origins, dirs, radii, points, normals, curvature) -> _Prepared:
    lead = torch.broadcast_shapes(
        origins.shape[:-1], dirs.shape[:-1], points.shape[:-1], normals.shape[:-1], radii.shape, curvature.shape
    )
    o = origins.expand(*lead, 3)
    p = points.expand(*lead, 3)
    d = safe_normalize(dirs).expand(*lead, 3)
    n = safe_normalize(normals).expand(*lead, 3)
    r = radii.expand(lead)
    H = curvature.expand(lead)
    dn = dot(d, n)
    # Back-facing: the osculating sphere is invariant under (n, H) -> (-n, -H); use the camera-facing side.
    sign = torch.where(dn > 0, -torch.ones_like(dn), torch.ones_like(dn))
    n = n * sign[..., None]
    H = H * sign
    c = dn.abs()
    s = safe_norm(p - o)
    axis = reflect(d, n)
    return _Prepared(o, d, r, p, n, H, c, s, axis)


def _finish(
    prep: _Prepared,
    t0: Tensor,
    g_hat: Tensor,
    r0_hat: Tensor,
    max_radius_growth: float,
    max_apex_ratio: float,
) -> VirtualCone:
    """Apply the guards and assemble the cone.

    Args:
        t0: ``(...)`` raw signed apex distance ``t_start`` (may be huge near collimation).
        g_hat: ``(...)`` radius growth per unit incoming ``r`` (``radius_growth = r · g_hat``).
        r0_hat: ``(...)`` signed radius at the surface per unit ``r`` (``|r0_hat| ≤ s``), used when the apex
            distance is capped so that the cone keeps the beam's width at the surface.
    """
    r = prep.r
    # Cap the spread: shrink the growth by lam >= 1 and move the apex back by lam (radius at p is kept).
    lam = (r * g_hat / max_radius_growth).clamp_min(1.0)
    t_cap = max_apex_ratio * prep.s
    t_start = torch.maximum(torch.minimum(lam * t0, t_cap), -t_cap)
    # When the apex distance was capped, the growth that keeps the surface radius is |r0| / t_cap.
    growth = torch.maximum(r * g_hat / lam, r * r0_hat.abs() / t_cap)
    apex = prep.p - t_start[..., None] * prep.axis
    return VirtualCone(apex, prep.axis, growth, t_start, prep.p)


# ----------------------------------------------------------------------------------------------------------
# Optics of the osculating sphere
# ----------------------------------------------------------------------------------------------------------


def osculating_sphere_center(points: Tensor, normals: Tensor, curvature: Tensor) -> Tensor:
    """Centre ``p − n/H`` of the osculating sphere, ``(..., 3)`` (infinite for ``H = 0``; for display only —
    the constructions below never form it)."""
    return points - safe_normalize(normals) / curvature[..., None]


def astigmatic_vergences(cos_theta: Tensor, curvature: Tensor, distance: Tensor) -> tuple[Tensor, Tensor]:
    """Coddington equations for a spherical mirror, in this module's sign conventions.

    A point source at ``distance`` ``s`` in front of a mirror of mean curvature ``H`` (``> 0`` convex), hit at
    incidence angle ``θ``, images to two focal lines along the reflected axis, at signed distances ``1/u_t``
    (tangential, in the plane of incidence) and ``1/u_s`` (sagittal) from the surface point (``> 0``: real,
    in front; ``< 0``: virtual, behind):

        u_t = −2H / cos θ − 1/s,     u_s = −2H cos θ − 1/s

    (the optics-textbook form ``1/s + 1/s' = 2/(R cos θ)`` and ``2 cos θ / R`` with ``R = −1/H``).

    Args:
        cos_theta, curvature, distance: ``(...)``.
    Returns:
        ``(u_t, u_s)``, each ``(...)``, in inverse length units.
    """
    u_t = -2 * curvature / cos_theta - 1 / distance
    u_s = -2 * curvature * cos_theta - 1 / distance
    return u_t, u_s


# ----------------------------------------------------------------------------------------------------------
# The three constructions
# ----------------------------------------------------------------------------------------------------------


def closed_form_cone(
    origins: Tensor,
    dirs: Tensor,
    radii: Tensor,
    points: Tensor,
    normals: Tensor,
    curvature: Tensor,
    *,
    max_radius_growth: float = 2.0,
    max_apex_ratio: float = 1e4,
    cos_min: float = 1e-4,
) -> VirtualCone:
    """Virtual cone from the small-footprint limit of the least-squares apex (see the module docstring).

    Args:
        origins: ``(..., 3)`` camera centres ``o``.
        dirs: ``(..., 3)`` primary ray directions ``d``.
        radii: ``(...)`` incoming radius growth ``r`` (mip-NeRF radii).
        points: ``(..., 3)`` surface points ``p``.
        normals: ``(..., 3)`` outward surface normals ``n``.
        curvature: ``(...)`` mean curvature ``H = ½ div n``.
        max_radius_growth: cap on the virtual cone's radius growth (grazing incidence, huge footprints).
        max_apex_ratio: cap on ``|t_start| / |p − o|`` (near-collimated beams).
        cos_min: floor on ``cos θ`` where the spread divides by it.
    Returns:
        :class:`VirtualCone`.
    """
    prep = _prepare(origins, dirs, radii, points, normals, curvature)
    c, s = prep.c, prep.s
    kappa = prep.H * s  # dimensionless curvature: the only place H enters, polynomially (no 1/H)
    # a = c·s·u_t, b = c·s·u_s: the vergences scaled by c·s, finite at H = 0 and at grazing incidence.
    a = -(2 * kappa + c)
    b = -(2 * kappa * c * c + c)
    Q = 0.5 * (a * a + b * b)  # = (c s)² (u_t² + u_s²)/2
    eps = torch.finfo(Q.dtype).eps
    tiny = eps**2
    # both vergences vanish (concave, normal incidence, s = focal length) to within the rounding of computing
    # them: at the exact focus one of a, b can come out 0 and the other a few ulps, by CPU (AVX2 against AVX-512)
    collimated = Q <= (COLLIMATED_ULPS * eps) ** 2
    Q_safe = Q.clamp_min(tiny)
    sqrt_Q = Q_safe.sqrt()
    # t_start = −z* = −(u_t + u_s)/(u_t² + u_s²)
    t_cap = max_apex_ratio * s
    t0 = torch.where(collimated, 2 * t_cap, -c * s * (a + b) / (2 * Q_safe))
    # radius growth = r s √((u_t² + u_s²)/2) = r √Q / c
    g_hat = sqrt_Q / c.clamp_min(cos_min)
    # signed radius at the surface = g · t_start = −r s (a + b) / (2 √Q), |.| ≤ r s (Cauchy–Schwarz);
    # in the collimated limit the beam is a cylinder of the footprint's radius.
    r0_hat = torch.where(collimated, s, -s * (a + b) / (2 * sqrt_Q))
    return _finish(prep, t0, g_hat, r0_hat, max_radius_growth, max_apex_ratio)


def bounding_ray_cone(
    origins: Tensor,
    dirs: Tensor,
    radii: Tensor,
    points: Tensor,
    normals: Tensor,
    curvature: Tensor,
    *,
    num_bounding_rays: int = 4,
    max_radius_growth: float = 2.0,
    max_apex_ratio: float = 1e4,
    cos_min: float = 1e-4,
) -> VirtualCone:
    """The paper's construction: bounding rays, osculating sphere, reflection, least-squares apex.

    Arguments as :func:`closed_form_cone`, plus ``num_bounding_rays`` (``K ≥ 3``; the paper uses 4), the
    rays at angles ``2πj/K`` around ``d`` at the cone boundary (offset ``r`` per unit distance).

    Numerics: the sphere is written relative to ``p`` as ``H|y|² + 2 n·y = 0`` (no centre, no ``1/H``) and
    each ray is intersected starting from where it crosses the tangent plane, taking the small root in the
    cancellation-free form, so ``H → 0`` gives the plane continuously. The least-squares system is solved in
    the frame ``(ω_r, e1, e2)`` with its small axial entries built from ``ω_j − ω_r`` directly (not as
    ``1 − cos²``), which keeps float32 accurate for pixel-sized footprints.
    """
    if num_bounding_rays < 3:
        raise ValueError("num_bounding_rays must be >= 3 (fewer rays do not constrain the apex isotropically)")
    prep = _prepare(origins, dirs, radii, points, normals, curvature)
    d, n, H, r, axis = prep.d, prep.n, prep.H, prep.r, prep.axis
    dtype, device = d.dtype, d.device
    K = num_bounding_rays

    # Bounding rays d_j = d + Δ_j with d_j = normalize(d + r (cos φ_j e_u + sin φ_j e_v)). Everything below is
    # written in small differences (Δ_j, y_j, Δn_j, δ_j) formed without subtracting nearly equal numbers,
    # which is what keeps float32 accurate when the footprint is 1e-3 of the distances involved.
    e_u, e_v = orthonormal_basis(d)
    phi = torch.arange(K, dtype=dtype, device=device) * (2 * math.pi / K)
    offs = phi.cos()[:, None] * e_u[..., None, :] + phi.sin()[:, None] * e_v[..., None, :]  # (..., K, 3)
    rk = r[..., None, None]
    root = (1 + rk * rk).sqrt()
    Delta = rk * offs / root - d[..., None, :] * (rk * rk / (root * (1 + root)))  # d_j − d, exactly
    d_j = d[..., None, :] + Delta

    # The camera enters only through s = |p − o| (as in the closed form): the pixel cone is taken around the
    # chief ray through p, apex at p − s d. Bounding ray j crosses the tangent plane n·y = 0 (y = x − p) at
    #   y0_j = (t_j − s) d + t_j Δ_j,  t_j = s (n·d)/(n·d_j),  t_j − s = −s (n·Δ_j)/(n·d_j).
    nk = n[..., None, :]
    sk = prep.s[..., None]
    nd = dot(nk, d_j).clamp(max=-cos_min)  # front-facing after the flip; guard rays grazing the plane
    t_j = sk * dot(n, d)[..., None] / nd
    y0 = (-sk * dot(nk, Delta) / nd)[..., None] * d[..., None, :] + t_j[..., None] * Delta
    # Osculating sphere H|y|² + 2 n·y = 0 along y = y0 + τ d_j:  H τ² + 2 B τ + H|y0|² = 0. Take the root
    # continuous with the tangent plane in the cancellation-free form (no 1/H: H → 0 gives the plane).
    Hk = H[..., None]
    y0_sq = y0.square().sum(-1)
    B = Hk * dot(y0, d_j) + nd
    disc = (B * B - Hk * Hk * y0_sq).clamp_min(0.0)  # a miss -> point of closest approach
    den = (B - disc.sqrt()).clamp(max=-cos_min)  # B < 0
    tau = -Hk * y0_sq / den
    y_j = y0 + tau[..., None] * d_j  # hit points relative to p
    # Sphere normal at p + y is n + H y (unit on the sphere); Δn_j = n_j − n formed without cancellation:
    # |n + Hy|² = 1 + q with q = 2H n·y + H²|y|² (0 on the sphere), 1 − |m| = −q / (1 + |m|).
    Hy = Hk[..., None] * y_j
    q = 2 * dot(nk, Hy) + Hy.square().sum(-1)
    m_len = (1 + q).clamp_min(torch.finfo(dtype).eps).sqrt()
    Dn = (Hy - nk * (q / (1 + m_len))[..., None]) / m_len[..., None]
    n_j = nk + Dn
    # δ_j = ω_j − ω_r = Δ_j − 2[(k_j − k) n_j + k Δn_j], k = d·n, k_j − k = Δ_j·n_j + d·Δn_j.
    k = dot(d, n)[..., None]
    dk = dot(Delta, n_j) + dot(d[..., None, :], Dn)
    delta = Delta - 2 * (dk[..., None] * n_j + k[..., None] * Dn)
    w_j = axis[..., None, :] + delta  # reflected bounding directions

    # Least squares: min_v Σ_j |P_j (v − p − y_j)|² over the K rays and the central one (y = 0, ω_r),
    # with P_j = I − ω_j ω_jᵀ. Unknowns v − p = z ω_r + ξ1 e1 + ξ2 e2.
    e1, e2 = orthonormal_basis(axis)
    E = torch.stack([e1, e2], dim=-2)  # (..., 2, 3)
    # P_j ω_r = −δ_j + ω_j (ω_j·δ_j) and ω_j·δ_j = |δ_j|²/2 for unit vectors.
    Pa = -delta + w_j * (0.5 * delta.square().sum(-1))[..., None]  # (..., K, 3)
    M_aa = Pa.square().sum((-1, -2))  # Σ ω_rᵀ P_j ω_r
    M_at = torch.einsum("...jc,...kc->...k", Pa, E)  # Σ e_kᵀ P_j ω_r
    we = torch.einsum("...jc,...kc->...jk", w_j, E)  # ω_j·e_k
    eye2 = torch.eye(2, dtype=dtype, device=device)
    M_tt = (K + 1) * eye2 - torch.einsum("...jk,...jl->...kl", we, we)  # +1: the central ray
    Py = y_j - w_j * dot(w_j, y_j)[..., None]  # P_j y_j
    b_a = (Pa * y_j).sum((-1, -2))
    b_t = torch.einsum("...jc,...kc->...k", Py, E)
    # Schur complement on the axial unknown (M_tt ≈ (K+1) I is well conditioned).
    det = M_tt[..., 0, 0] * M_tt[..., 1, 1] - M_tt[..., 0, 1] * M_tt[..., 1, 0]
    inv = torch.stack(
        [torch.stack([M_tt[..., 1, 1], -M_tt[..., 0, 1]], -1), torch.stack([-M_tt[..., 1, 0], M_tt[..., 0, 0]], -1)],
        -2,
    ) / det[..., None, None]
    inv_at = torch.einsum("...kl,...l->...k", inv, M_at)
    S = M_aa - (M_at * inv_at).sum(-1)
    num = b_a - (inv_at * b_t).sum(-1)
    t_cap2 = 2 * max_apex_ratio * prep.s
    tiny = torch.finfo(dtype).tiny ** 0.5
    z = num / torch.maximum(S, num.abs() / t_cap2).clamp_min(tiny)  # |z| ≤ 2 t_cap: parallel rays
    t0 = -z  # the transverse offset ξ (second order in the footprint) is dropped: apex on the axis

    # Spread: r · rms|ω_j − ω_r| / rms|d_j − d| (exact for a plane, rotation-invariant in the limit).
    rms_out = delta.square().sum(-1).mean(-1).sqrt()
    rms_in = Delta.square().sum(-1).mean(-1).clamp_min(tiny * tiny).sqrt()
    g_hat = rms_out / rms_in
    # Radius at the surface for the capped-apex case; bounded by the footprint like the closed form's (it only
    # matters when the footprint straddles the osculating sphere's silhouette or the rays are parallel).
    r0_hat = torch.maximum(torch.minimum(g_hat * t0, prep.s), -prep.s)
    return _finish(prep, t0, g_hat, r0_hat, max_radius_growth, max_apex_ratio)


def naive_cone(
    origins: Tensor,
    dirs: Tensor,
    radii: Tensor,
    points: Tensor,
    normals: Tensor,
    curvature: Tensor | None = None,
) -> VirtualCone:
    """The paper's ablation (sec. 4.4): mip-NeRF's cone restarted at the surface point.

    Apex ``p``, axis ``ω_r``, radius growth ``r`` (the incoming one), ``t_start = 0``. ``curvature`` is
    ignored (accepted for a uniform signature).
    """
    H = torch.zeros_like(radii) if curvature is None else curvature
    prep = _prepare(origins, dirs, radii, points, normals, H)
    zero = torch.zeros_like(prep.r)
    return VirtualCone(prep.p, prep.axis, prep.r, zero, prep.p)


def virtual_cone(
    origins: Tensor,
    dirs: Tensor,
    radii: Tensor,
    points: Tensor,
    normals: Tensor,
    curvature: Tensor,
    method: Method = "closed_form",
    **kwargs,
) -> VirtualCone:
    """The virtual cone of a pixel cone reflected at a surface point — the one entry point.

    Args:
        origins: ``(..., 3)`` camera centres ``o``.
        dirs: ``(..., 3)`` primary ray directions ``d`` (normalized here).
        radii: ``(...)`` incoming radius growth ``r`` (mip-NeRF radii, per unit distance).
        points: ``(..., 3)`` surface points ``p``.
        normals: ``(..., 3)`` outward normals ``n`` (normalized here; back-facing ones are handled).
        curvature: ``(...)`` mean curvature ``H = ½ div n`` (``+1/R`` on a convex sphere).
        method: ``"closed_form"`` (default), ``"bounding_rays"`` (the paper's) or ``"naive"`` (ablation).
        **kwargs: options of the chosen construction (``max_radius_growth``, ``max_apex_ratio``,
            ``cos_min``; ``num_bounding_rays`` for ``"bounding_rays"``).
    Returns:
        :class:`VirtualCone` with the broadcast leading shape of the inputs.
    """
    if method == "closed_form":
        return closed_form_cone(origins, dirs, radii, points, normals, curvature, **kwargs)
    if method == "bounding_rays":
        return bounding_ray_cone(origins, dirs, radii, points, normals, curvature, **kwargs)
    if method == "naive":
        if kwargs:
            raise TypeError(f"naive cones take no options, got {sorted(kwargs)}")
        return naive_cone(origins, dirs, radii, points, normals, curvature)
    raise ValueError(f"unknown virtual cone method {method!r}; use 'closed_form', 'bounding_rays' or 'naive'")
