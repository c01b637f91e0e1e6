"""Per-photo appearance: each training photo's exposure and white balance as a gain per colour channel.

Phones and cameras on auto expose and white-balance every photo differently (and decode's EXIF-based exposure
normalization leaves what EXIF does not record). In linear radiance both are a gain per channel, so a photo's
pixels are modelled as ``gain[photo] * radiance``. The gains are learned with the fields, relative to their
geometric mean over the photos (which fixes the scale the fields are in: an average photo's) and pulled
toward 1 by :func:`appearance_prior`. A render without a photo (a held-out or a novel view) is that average
photo's appearance.
"""

from __future__ import annotations

import torch


def photo_gains(log_gains: torch.Tensor) -> torch.Tensor:
    """``(P, 3)`` free log gains -> ``(P, 3)`` gains whose geometric mean over the photos is 1 per channel."""
    return torch.exp(log_gains - log_gains.mean(dim=0, keepdim=True))


def apply_gains(rgb: torch.Tensor, gains: torch.Tensor, photo: torch.Tensor) -> torch.Tensor:
    """Radiance ``(R, 3)`` as photo ``photo`` ``(R,)`` (long, into ``gains`` ``(P, 3)``) records it."""
    return rgb * gains[photo]


def appearance_prior(log_gains: torch.Tensor) -> torch.Tensor:
    """Mean squared log gain ``(P, 3)`` about the photos' geometric mean: 0 when every photo looks alike."""
    centred = log_gains - log_gains.mean(dim=0, keepdim=True)
    return centred.square().mean()

