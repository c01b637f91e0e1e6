"""The neural fields: the object's SDF with its diffuse-radiance head, and the environment radiance field.

``SDFField``: points in the object's unit-sphere frame -> signed distance (positive outside) and features;
the diffuse head maps features to view-independent linear radiance. It starts as a sphere: f(x) = |x| − r0
plus a network whose output begins near zero, so normals and curvature are sensible from step one.

``EnvironmentField``: conical frustums (Gaussians) in contracted space -> density and linear radiance,
f_E(cone) of the paper; the 5D field queried along virtual cones from the object's surface.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal

import torch
from torch import nn
from torch.nn import functional as F

from .encoding import HashGrid, HashGridSpec, integrated_positional_encoding, positional_encoding
from .frustum import contract_gaussian

Encoding = Literal["hashgrid", "frequency"]

# Radius of the contracted space (mip-NeRF 360 maps all of R^3 into a ball of radius 2).
_CONTRACTED_RADIUS = 2.0
_MIN_VARIANCE = 1e-12  # floor of a frustum's variance under a square root


def mlp(in_dim: int, hidden: int, layers: int, out_dim: int, smooth: bool = True) -> nn.Sequential:
    """``layers`` hidden layers of width ``hidden``; Softplus if ``smooth`` (the SDF is differentiated
    twice), else the cheaper ReLU."""
    mods: list[nn.Module] = []
    dim = in_dim
    for _ in range(layers):
        mods += [nn.Linear(dim, hidden), nn.Softplus(beta=100) if smooth else nn.ReLU()]
        dim = hidden
    mods.append(nn.Linear(dim, out_dim))
    return nn.Sequential(*mods)


@dataclass(frozen=True)
class SDFFieldSpec:
    encoding: Encoding = "hashgrid"
    hash_grid: HashGridSpec = field(default_factory=HashGridSpec)
    num_freqs: int = 6  # frequency encoding (the paper's MLP)
    hidden: int = 64
    layers: int = 2
    feature_dim: int = 15
    diffuse_hidden: int = 64
    diffuse_layers: int = 2
    # A hash grid of its own for the diffuse head (None: SDF features only, as the paper). Texture detail
    # then need not come from the SDF's grid, whose fine levels would turn it into bumpy normals.
    texture_grid: HashGridSpec | None = None
    init_radius: float = 0.5  # the initial sphere, in the unit-sphere frame of the object
    # Initial diffuse radiance (linear). Softplus of a zero output is 0.69, far above most objects; the
    # photometric loss then drives the head deep into softplus' flat tail, where it stops learning.
    diffuse_init: float = 0.05
    bound: float = 1.0  # the SDF is modelled inside [-bound, bound]^3
    # "tinted": the diffuse head also predicts each point's RGB reflectance at normal incidence (Schlick's F0):
    # a metal's reflections take its colour and most of the light, which a clear coat's Fresnel (about 4 %,
    # colourless) cannot give. "dielectric": no reflectance head; the renderer's exact Fresnel at its IOR.
    reflectance: Literal["dielectric", "tinted"] = "dielectric"
    reflectance_init: float = 0.04  # F0 at the start (a clear coat's at IOR 1.5: the dielectric's reflections)


class SDFField(nn.Module):
    def __init__(self, spec: SDFFieldSpec = SDFFieldSpec()):
        super().__init__()
        self.spec = spec
        if spec.encoding == "hashgrid":
            self.grid: HashGrid | None = HashGrid(spec.hash_grid)
            enc_dim = 3 + self.grid.out_dim
        else:
            self.grid = None
            enc_dim = 3 * (2 * spec.num_freqs + 1)
        self.net = mlp(enc_dim, spec.hidden, spec.layers, 1 + spec.feature_dim)
        # The network starts as a near-zero correction to the analytic sphere.
        with torch.no_grad():
            self.net[-1].weight.mul_(1e-3)
            self.net[-1].bias.zero_()
        self.texture_grid = HashGrid(spec.texture_grid) if spec.texture_grid is not None else None
        texture_dim = self.texture_grid.out_dim if self.texture_grid is not None else 0
        outputs = 6 if spec.reflectance == "tinted" else 3  # diffuse radiance, then F0's logits
        self.diffuse_net = mlp(spec.feature_dim + 3 + texture_dim, spec.diffuse_hidden, spec.diffuse_layers, outputs)
        with torch.no_grad():
            self.diffuse_net[-1].weight.mul_(0.1)
            self.diffuse_net[-1].bias[:3].fill_(math.log(math.expm1(spec.diffuse_init)))  # softplus⁻¹
            self.diffuse_net[-1].bias[3:].fill_(math.log(spec.reflectance_init / (1 - spec.reflectance_init)))

    def _unit(self, x: torch.Tensor) -> torch.Tensor:
        return (x / self.spec.bound + 1) * 0.5

    def encode(self, x: torch.Tensor) -> torch.Tensor:
        """``(N, 3)`` -> ``(N, enc_dim)``."""
        if self.grid is not None:
            return torch.cat([x, self.grid(self._unit(x))], dim=-1)
        return positional_encoding(x, self.spec.num_freqs)

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """SDF and geometry features.

        Args:
            x: ``(N, 3)`` points.
        Returns:
            ``(N,)`` signed distances and ``(N, feature_dim)`` features.
        """
        out = self.net(self.encode(x))
        sdf = x.norm(dim=-1) - self.spec.init_radius + out[:, 0]
        return sdf, out[:, 1:]

    def sdf(self, x: torch.Tensor) -> torch.Tensor:
        """``(N, 3)`` -> ``(N,)``."""
        return self.forward(x)[0]

    def surface(self, x: torch.Tensor, features: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor | None]:
        """The surface's view-independent properties at ``(N, 3)`` points with their ``(N, feature_dim)`` features.

        The SDF's features are layer-normalized first: the geometry terms alone (mask warm-up) let their
        scale drift, and an unnormalized drift can push the head into softplus' flat tail for good.

        Returns:
            linear diffuse radiance ``(N, 3)`` (non-negative, may exceed 1), and the RGB reflectance at normal
            incidence ``(N, 3)`` in (0, 1) when ``spec.reflectance`` is "tinted" (else None).
        """
        parts = [x, F.layer_norm(features, features.shape[-1:])]
        if self.texture_grid is not None:
            parts.append(self.texture_grid(self._unit(x)))
        out = self.diffuse_net(torch.cat(parts, dim=-1))
        reflectance = torch.sigmoid(out[:, 3:]) if self.spec.reflectance == "tinted" else None
        return F.softplus(out[:, :3]), reflectance

    def diffuse(self, x: torch.Tensor, features: torch.Tensor) -> torch.Tensor:
        """View-independent linear diffuse radiance ``(N, 3)`` (:meth:`surface`'s first part)."""
        return self.surface(x, features)[0]


@dataclass(frozen=True)
class EnvironmentFieldSpec:
    # "direction": the ablation of the paper's Fig. 8: a 2D environment map, radiance from the cone's axis
    # alone (position dropped), hash-grid encoded on the unit sphere of directions.
    encoding: Literal["hashgrid", "ipe", "direction"] = "hashgrid"
    hash_grid: HashGridSpec = field(
        default_factory=lambda: HashGridSpec(levels=12, log2_table_size=17, base_resolution=16, max_resolution=1024)
    )
    ipe_max_deg: int = 12  # mip-NeRF's IPE (the paper's setting)
    hidden: int = 64
    layers: int = 2
    dir_freqs: int = 2  # view dependence of the environment's radiance (0: none)
    # The contraction is the identity inside this radius (object radii) and squeezes what lies beyond: the
    # room's near props keep most of the grid's cells, the far walls still fit.
    contract_radius: float = 1.0
    color_hidden: int = 64
    density_bias: float = -1.0  # starts mostly empty so early cones see through to the walls


class EnvironmentField(nn.Module):
    """f_E: conical frustums -> (density, linear radiance), in the contracted space of the surroundings."""

    def __init__(self, spec: EnvironmentFieldSpec = EnvironmentFieldSpec()):
        super().__init__()
        self.spec = spec
        if spec.encoding in ("hashgrid", "direction"):
            self.grid: HashGrid | None = HashGrid(spec.hash_grid, first_order=True)
            enc_dim = self.grid.out_dim
        else:
            self.grid = None
            enc_dim = 2 * 3 * spec.ipe_max_deg
        self.trunk = mlp(enc_dim, spec.hidden, spec.layers, 1 + spec.hidden, smooth=False)
        dir_dim = 3 * (2 * spec.dir_freqs + 1) if spec.dir_freqs > 0 else 0
        self.color = mlp(spec.hidden + dir_dim, spec.color_hidden, 1, 3, smooth=False)

    def forward(
        self, means: torch.Tensor, variances: torch.Tensor, dirs: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Density and radiance of frustum Gaussians.

        Args:
            means: ``(N, S, 3)`` world-space frustum means; variances: ``(N, S, 3)``.
            dirs: ``(N, 3)`` unit cone axes (viewing direction for view-dependent radiance).
        Returns:
            density ``(N, S)`` (in world units⁻¹ of the contracted space) and radiance ``(N, S, 3)``.
        """
        n, s, _ = means.shape
        h = self.trunk(self._encode(means, variances))
        density = F.softplus(h[..., 0] + self.spec.density_bias)
        feat = h[..., 1:]
        if self.spec.dir_freqs > 0:
            d = positional_encoding(dirs, self.spec.dir_freqs)[:, None, :].expand(n, s, -1)
            feat = torch.cat([feat, d], dim=-1)
        radiance = F.softplus(self.color(feat))
        return density, radiance

    def density(self, means: torch.Tensor, variances: torch.Tensor) -> torch.Tensor:
        """:meth:`forward`'s density alone, ``(N, S)``, for ``(N, S, 3)`` means and variances: the trunk's first
        output without its features or the colour head (a coarse pass that only places samples needs no more)."""
        hidden = self.trunk[:-1](self._encode(means, variances))
        last = self.trunk[-1]
        return F.softplus(F.linear(hidden, last.weight[:1], last.bias[:1])[..., 0] + self.spec.density_bias)

    def _encode(self, means: torch.Tensor, variances: torch.Tensor) -> torch.Tensor:
        """``(N, S, 3)`` frustum means and variances -> ``(N, S, enc_dim)``, in the contracted space."""
        n, s, _ = means.shape
        r0 = self.spec.contract_radius
        c_mean, c_var = contract_gaussian(means / r0, variances / r0**2)
        if self.grid is None:
            return integrated_positional_encoding(c_mean, c_var, 0, self.spec.ipe_max_deg)
        unit = (c_mean / _CONTRACTED_RADIUS + 1) * 0.5
        # footprint std in [0, 1] grid units: mean per-axis std of the contracted Gaussian. A zero-length
        # frustum at a cone's apex (coarse and fine edges coincide there) has zero variance, where
        # sqrt's gradient is infinite: the floor keeps it finite (and zero below the floor).
        scale = c_var.clamp_min(0).mean(-1).clamp_min(_MIN_VARIANCE).sqrt() / (2 * _CONTRACTED_RADIUS)
        return self.grid(unit.reshape(-1, 3), scale.reshape(-1)).reshape(n, s, -1)

    @property
    def directional(self) -> bool:
        """True for the 2D environment map ablation (no position, no depth)."""
        return self.spec.encoding == "direction"

    def radiance_at_infinity(self, dirs: torch.Tensor, spread: torch.Tensor) -> torch.Tensor:
        """Radiance of the 2D environment map: ``(N, 3)`` unit directions and ``(N,)`` angular radius of
        the cone (radians) -> ``(N, 3)``; the footprint blurs the map as the cone widens."""
        enc = self.grid((dirs + 1) * 0.5, spread * 0.5)  # the unit sphere spans half the grid's cube
        feat = self.trunk(enc)[:, 1:]
        if self.spec.dir_freqs > 0:
            feat = torch.cat([feat, positional_encoding(dirs, self.spec.dir_freqs)], dim=-1)
        return F.softplus(self.color(feat))
