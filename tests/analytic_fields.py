"""Analytic stand-ins for ``orca.fields.EnvironmentField`` in the renderer's and the objective's tests: a subclass
gives ``forward(means, variances, dirs) -> (density, radiance)`` in closed form; the rest of the field's interface
is derived from it here."""

from __future__ import annotations

import torch


class AnalyticEnvironment(torch.nn.Module):
    """A 3D field (not the 2D map ablation) whose density alone is its forward pass's first output."""

    directional = False

    def density(self, means: torch.Tensor, variances: torch.Tensor) -> torch.Tensor:
        return self(means, variances, None)[0]
