"""The ORCa model: SDF + diffuse head, environment radiance field, learnable VolSDF β; and its objective.

``OrcaModel`` renders object rays (diffuse + specular through virtual cones) and environment rays (virtual
cameras anywhere, or background pixels that see the room directly). ``objective`` turns a batch into the
weighted sum of the paper's losses, with a mask-only warm-up phase.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal, NamedTuple

import torch
from torch import nn

from .appearance import appearance_prior, apply_gains, photo_gains
from .differential import gradient
from .fields import EnvironmentField, EnvironmentFieldSpec, SDFField, SDFFieldSpec
from .geometry_utils import safe_normalize
from .losses import (
    cone_distortion_loss,
    eikonal_loss,
    mask_loss,
    normal_orientation_loss,
    normal_smoothness_loss,
    photometric_loss,
    sparse_depth_loss,
)
from .render import (
    RayOutputs,
    RenderSpec,
    environment_weights,
    free_space_opacity,
    render_environment_along,
    render_rays,
)


@dataclass(frozen=True)
class ModelSpec:
    sdf: SDFFieldSpec = field(default_factory=SDFFieldSpec)
    env: EnvironmentFieldSpec = field(default_factory=EnvironmentFieldSpec)
    render: RenderSpec = field(default_factory=RenderSpec)
    beta_init: float = 0.05
    beta_min: float = 1e-4  # keeps the density finite however sharp the surface gets
    # Schedules over training progress p in [0, 1] (see OrcaModel.apply_schedule).
    beta_final: float = 0.005  # β may not exceed beta_init -> beta_final (geometric) ...
    beta_anneal: float = 0.5  # ... reached at this p; the learned β can always go lower
    sdf_levels_start: int = 4  # coarse-to-fine: SDF hash-grid levels active at p = 0 ...
    sdf_levels_full: float = 0.3  # ... all levels active from this p on
    # Background rays (camera pixels off the object) may start this fraction of the way from their camera to
    # the object's centre: with samples right in front of the lens, the field can explain a photo's background
    # with a floater before its own camera (invisible to the others) instead of learning the room.
    background_near: float = 0.0
    # Training photos with a learned exposure and white balance (orca.appearance); 0: none (one appearance).
    photos: int = 0


class OrcaModel(nn.Module):
    def __init__(self, spec: ModelSpec = ModelSpec()):
        super().__init__()
        self.spec = spec
        self.sdf_field = SDFField(spec.sdf)
        self.env_field = EnvironmentField(spec.env)
        self.log_beta = nn.Parameter(torch.tensor(math.log(spec.beta_init - spec.beta_min)))
        self.log_gains = nn.Parameter(torch.zeros(spec.photos, 3)) if spec.photos else None

    @property
    def beta(self) -> torch.Tensor:
        return self.spec.beta_min + self.log_beta.exp()

    def photo_gains(self) -> torch.Tensor | None:
        """``(photos, 3)`` each training photo's gain per channel (:func:`orca.appearance.photo_gains`), or None."""
        return photo_gains(self.log_gains) if self.log_gains is not None else None

    @torch.no_grad()
    def apply_schedule(self, progress: float) -> None:
        """Set the coarse-to-fine state for training progress ``progress`` in [0, 1]: the SDF's active
        hash-grid levels (fine levels first fit noise, which becomes bumpy normals and a noisy reflection)
        and the cap on β (a learned β alone shrinks slowly: the mask and photometric terms barely feel the
        surface's sharpness, but the reflection needs a sharp, well-placed surface)."""
        s = self.spec
        grid = self.sdf_field.grid
        if grid is not None:
            ramp = min(progress / s.sdf_levels_full, 1.0) if s.sdf_levels_full > 0 else 1.0
            grid.set_active_levels(s.sdf_levels_start + ramp * (grid.spec.levels - s.sdf_levels_start))
        fraction = min(progress / s.beta_anneal, 1.0) if s.beta_anneal > 0 else 1.0
        cap = s.beta_init * (s.beta_final / s.beta_init) ** fraction
        self.log_beta.clamp_(max=math.log(max(cap - s.beta_min, 1e-12)))

    def forward(
        self, origins: torch.Tensor, dirs: torch.Tensor, radii: torch.Tensor, specular: bool | torch.Tensor = True
    ) -> RayOutputs:
        """Object rays ``(N, 3), (N, 3), (N,)`` -> :class:`RayOutputs` (``specular``: every ray's virtual cones,
        none, or those of the rays a ``(N,)`` bool tensor marks; see :func:`~orca.render.render_rays`)."""
        return render_rays(
            self.sdf_field, self.env_field, self.beta, origins, dirs, radii, self.spec.render, specular
        )

    def environment(
        self, origins: torch.Tensor, dirs: torch.Tensor, radii: torch.Tensor, near: torch.Tensor | None = None,
        render: RenderSpec | None = None,
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Radiance ``(N, 3)`` and ray depth ``(N,)`` (at ``spec.render.depth_quantile``) of the environment
        field alone (object absent), seen by ordinary camera cones from ``origins``, empty before ``near``
        ``(N,)`` (default 0), traced as ``render`` says (default: ``spec.render``; a depth wants
        :meth:`RenderSpec.for_depth`). The object's inside is empty (see ``solid``)."""
        near = torch.zeros_like(radii) if near is None else near
        rgb, depth, _, _ = render_environment_along(
            self.env_field, origins, dirs, radii, near, render or self.spec.render, self.solid
        )
        depth = near + depth
        return rgb, depth

    @torch.no_grad()
    def solid(self, x: torch.Tensor) -> torch.Tensor:
        """``(P, 3)`` -> ``(P,)`` bool: inside the object (SDF < 0; only the bounding sphere is checked)."""
        inside = torch.zeros(x.shape[0], dtype=torch.bool, device=x.device)
        near = (x.norm(dim=-1) < self.spec.render.object_radius).nonzero().squeeze(-1)
        if near.numel():
            inside[near] = self.sdf_field.sdf(x[near]) < 0
        return inside


@dataclass(frozen=True)
class LossWeights:
    photometric: float = 1.0
    mask: float = 0.1
    eikonal: float = 0.1
    orientation: float = 1e-3
    distortion: float = 1e-3
    background: float = 0.1  # background pixels supervise the environment field directly (beyond the paper)
    free_space: float = 0.0  # no environment density between a camera and the object (beyond the paper)
    sparse_depth: float = 0.0  # rays through sparse points of the surroundings end there (beyond the paper)
    sparse_depth_band: float = 0.03  # ... within this share of the point's distance
    clipped_excess: float = 0.1  # clipped pixels: weight of a prediction's excess over the recorded value
    smoothness: float = 0.0  # normals at the surface vs a small random step away (beyond the paper)
    smoothness_step: float = 0.01  # the step's standard deviation, in object radii
    appearance: float = 0.01  # per-photo gains pulled toward their geometric mean (orca.appearance)


class Batch(NamedTuple):
    """``N`` rays with their targets."""

    origins: torch.Tensor  # (N, 3)
    dirs: torch.Tensor  # (N, 3)
    radii: torch.Tensor  # (N,)
    rgb: torch.Tensor  # (N, 3) linear target
    mask: torch.Tensor  # (N,) object mask in {0, 1}
    valid: torch.Tensor  # (N,) not clipped
    photo: torch.Tensor | None = None  # (N,) long: the training photo of each ray (for its appearance)


class DepthBatch(NamedTuple):
    """``N`` rays with the distance at which each should end (sparse points of the surroundings)."""

    origins: torch.Tensor  # (N, 3)
    dirs: torch.Tensor  # (N, 3)
    radii: torch.Tensor  # (N,)
    distance: torch.Tensor  # (N,)


Phase = Literal["mask", "joint"]

_OPACITY_EPS = 1e-6


def objective(
    model: OrcaModel, batch: Batch, weights: LossWeights, phase: Phase, background: Batch | None = None,
    depth: DepthBatch | None = None,
) -> tuple[torch.Tensor, dict[str, torch.Tensor], RayOutputs]:
    """Weighted loss of a batch; ``phase="mask"`` trains geometry from silhouettes only (warm-up).

    The background term (environment field vs. the batch's off-object pixels, plus the optional
    ``background`` batch of off-object pixels) runs in both phases: it does not touch the object, and
    off-object rays are cheap (no SDF), so the room can be learned from more of them than object rays.
    So does the sparse-depth term (``depth``: rays through known points of the surroundings).

    Returns:
        total loss, the unweighted terms (detached, for logging), and the render.
    """
    obj = batch.mask > 0.5
    # Virtual cones (the environment along each) only where the photometric term reads the colour: object
    # pixels, after the warm-up, which uses geometry alone.
    out = model(batch.origins, batch.dirs, batch.radii, specular=obj if phase == "joint" else False)
    gains = model.photo_gains() if batch.photo is not None else None
    terms: dict[str, torch.Tensor] = {
        "mask": mask_loss(out.opacity, batch.mask),
        "eikonal": eikonal_loss(out.sdf_grad),
    }
    if phase == "joint":
        normals = safe_normalize(out.sdf_grad)
        # The surface's colour (radiance per unit opacity): otherwise the quickest way to darken a too-bright
        # start is to thin the surface, and the photometric term fights the silhouettes the mask term learns.
        surface_rgb = out.rgb / out.opacity.clamp_min(_OPACITY_EPS)[:, None]
        if gains is not None:
            surface_rgb = apply_gains(surface_rgb, gains, batch.photo)
        terms["photometric"] = photometric_loss(
            surface_rgb, batch.rgb, obj & batch.valid, obj & ~batch.valid, weights.clipped_excess
        )
        terms["orientation"] = normal_orientation_loss(out.weights, normals, batch.dirs)
        if obj.any():
            terms["distortion"] = cone_distortion_loss(out.env_weights, out.env_s)
        if weights.smoothness > 0:
            terms["smoothness"] = smoothness_term(model, batch, out, weights.smoothness_step)
    if weights.free_space > 0 and obj.any():
        opacity = free_space_opacity(
            model.env_field, batch.origins[obj], batch.dirs[obj], batch.radii[obj], model.spec.render
        )
        terms["free_space"] = opacity.mean()
    terms.update(environment_terms(model, batch, obj, weights, gains, background, depth))
    if gains is not None:
        terms["appearance"] = appearance_prior(model.log_gains)
    total = sum(getattr(weights, k) * v for k, v in terms.items())
    return total, {k: v.detach() for k, v in terms.items()}, out


def environment_terms(
    model: OrcaModel, batch: Batch, obj: torch.Tensor, weights: LossWeights, gains: torch.Tensor | None,
    background: Batch | None, depth: DepthBatch | None,
) -> dict[str, torch.Tensor]:
    """The background term (the environment field against the off-object pixels of ``batch``, whose ``(N,)``
    bool ``obj`` marks the object's, and of ``background``) and the sparse-depth term (its weights along
    ``depth``'s rays against their points' distances), as :func:`objective` weighs them.

    Both sets of rays go through the field in one pass: a training step on a GPU costs its number of kernel
    launches more than their work, and each pass of the field is a few hundred of them. The object's inside is
    empty for both (``OrcaModel.solid``); background rays start ``spec.background_near`` of the way to the
    object's centre, depth rays at their camera."""
    terms: dict[str, torch.Tensor] = {}
    rays = []
    if weights.background > 0:
        rays.append(tuple(t[~obj] for t in _background_parts(batch, gains)))
        if background is not None:
            rays.append(_background_parts(background, gains))
    origins, dirs, radii, rgb, valid, photo = (torch.cat(parts) for parts in zip(*rays)) if rays else [None] * 6
    n = 0 if origins is None else origins.shape[0]
    use_depth = weights.sparse_depth > 0 and depth is not None and not model.env_field.directional
    if model.env_field.directional:  # a 2D map: colour alone
        env_rgb = model.environment(origins, dirs, radii)[0] if n else None
    elif n or use_depth:
        starts = [model.spec.background_near * origins.norm(dim=-1)] if n else []  # the object's centre is 0
        cones = [(origins, dirs, radii)] if n else []
        if use_depth:
            starts.append(torch.zeros_like(depth.radii))
            cones.append((depth.origins, depth.dirs, depth.radii))
        apex, axis, growth = (torch.cat(parts) for parts in zip(*cones))
        w, edges, radiance = environment_weights(model.env_field, apex, axis, growth, torch.cat(starts),
                                                 model.spec.render, model.solid)
        env_rgb = (w[:n, :, None] * radiance[:n]).sum(-2)
        if use_depth:
            terms["sparse_depth"] = sparse_depth_loss(w[n:], edges[n:], depth.distance,
                                                      weights.sparse_depth_band * depth.distance)
    if n:
        if gains is not None:
            env_rgb = apply_gains(env_rgb, gains, photo)
        terms["background"] = photometric_loss(env_rgb, rgb, valid, ~valid, weights.clipped_excess)
    return terms


def _background_parts(batch: Batch, gains: torch.Tensor | None) -> tuple[torch.Tensor, ...]:
    """What the background term reads of a batch: its rays, targets and (with gains) photo indices."""
    photo = batch.photo if gains is not None else torch.zeros_like(batch.radii, dtype=torch.long)
    return batch.origins, batch.dirs, batch.radii, batch.rgb, batch.valid, photo


def smoothness_term(model: OrcaModel, batch: Batch, out: RayOutputs, step: float) -> torch.Tensor:
    """:func:`normal_smoothness_loss` at each ray's expected surface point and a random step from it."""
    surface = batch.origins + (out.depth / out.opacity.clamp_min(_OPACITY_EPS))[:, None] * batch.dirs
    surface = surface.detach()
    nearby = surface + step * torch.randn_like(surface)
    _, g = gradient(model.sdf_field.sdf, torch.cat([surface, nearby]), create_graph=True)
    n_surface, n_nearby = safe_normalize(g).chunk(2)
    return normal_smoothness_loss(n_surface, n_nearby, out.opacity.detach())
