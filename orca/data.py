"""Training rays from a set of posed images held in memory (tensors only; files are pipeline/'s job)."""

from __future__ import annotations

from dataclasses import dataclass

import torch

from .model import Batch, DepthBatch
from .rays import camera_rays


@dataclass
class SparseDepth:
    """``P`` pixels of the images whose ray is known to end at a given distance: the sparse points of the
    surroundings that structure from motion triangulated, projected into the photos that see them.

    Attributes:
        image: ``(P,)`` long index into the image stack; uv: ``(P, 2)`` the point's projection (pixels);
        distance: ``(P,)`` from the camera centre to the point along the ray.
    """

    image: torch.Tensor
    uv: torch.Tensor
    distance: torch.Tensor

    def __post_init__(self) -> None:
        p = self.image.shape[0]
        if self.uv.shape != (p, 2) or self.distance.shape != (p,):
            raise ValueError(f"uv {tuple(self.uv.shape)} / distance {tuple(self.distance.shape)} vs {p} points")

    def __len__(self) -> int:
        return int(self.image.shape[0])

    def to(self, device: torch.device | str) -> SparseDepth:
        return SparseDepth(self.image.to(device), self.uv.to(device), self.distance.to(device))


@dataclass
class ImageSet:
    """``N`` posed images of equal size.

    Attributes:
        images: ``(N, H, W, 3)`` linear radiance.
        masks: ``(N, H, W)`` bool object masks.
        valid: ``(N, H, W)`` bool, False where a highlight clipped.
        K: ``(N, 3, 3)`` intrinsics; c2w: ``(N, 4, 4)`` camera-to-world (OpenCV).
        depth: optional sparse depth of the surroundings seen in these images.
    """

    images: torch.Tensor
    masks: torch.Tensor
    valid: torch.Tensor
    K: torch.Tensor
    c2w: torch.Tensor
    depth: SparseDepth | None = None

    def __post_init__(self) -> None:
        n, h, w, _ = self.images.shape
        if self.masks.shape != (n, h, w) or self.valid.shape != (n, h, w):
            raise ValueError(f"masks {tuple(self.masks.shape)} / valid {tuple(self.valid.shape)} vs images {(n, h, w)}")
        if self.K.shape != (n, 3, 3) or self.c2w.shape != (n, 4, 4):
            raise ValueError("K must be (N, 3, 3) and c2w (N, 4, 4)")
        self._object_idx = self.masks.reshape(-1).nonzero().squeeze(-1)
        if self._object_idx.numel() == 0:
            raise ValueError("every mask is empty: there is no object to train on")
        self._background_idx = (~self.masks).reshape(-1).nonzero().squeeze(-1)

    @property
    def shape(self) -> tuple[int, int, int]:
        n, h, w, _ = self.images.shape
        return n, h, w

    def to(self, device: torch.device | str) -> ImageSet:
        return ImageSet(*(t.to(device) for t in (self.images, self.masks, self.valid, self.K, self.c2w)),
                        depth=self.depth.to(device) if self.depth is not None else None)

    def sample(self, n_rays: int, object_fraction: float, generator: torch.Generator | None = None) -> Batch:
        """Random pixels, ``object_fraction`` of them on the object (the rest anywhere), as a :class:`Batch`."""
        n, h, w = self.shape
        n_obj = int(round(n_rays * object_fraction))
        flat_obj = self._pick(self._object_idx, n_obj, generator)
        flat_any = torch.randint(0, n * h * w, (n_rays - n_obj,), generator=generator, device="cpu")
        return self._rays(torch.cat([flat_obj, flat_any.to(self.images.device)]), generator)

    def sample_background(self, n_rays: int, generator: torch.Generator | None = None) -> Batch | None:
        """Random pixels off the object (direct views of the surroundings); None if there are none."""
        if self._background_idx.numel() == 0:
            return None
        return self._rays(self._pick(self._background_idx, n_rays, generator), generator)

    def sample_depth(self, n_rays: int, generator: torch.Generator | None = None) -> DepthBatch | None:
        """Random rays of the sparse depth (through the points' projections); None without any."""
        if self.depth is None or len(self.depth) == 0:
            return None
        pick = torch.randint(0, len(self.depth), (n_rays,), generator=generator, device="cpu").to(self.images.device)
        img = self.depth.image[pick]
        origins, dirs, radii = camera_rays(self.depth.uv[pick], self.K[img], self.c2w[img])
        return DepthBatch(origins, dirs, radii, self.depth.distance[pick])

    def _pick(self, flat_idx: torch.Tensor, count: int, generator: torch.Generator | None) -> torch.Tensor:
        pick = torch.randint(0, flat_idx.numel(), (count,), generator=generator, device="cpu")
        return flat_idx[pick.to(flat_idx.device)]

    def _rays(self, flat: torch.Tensor, generator: torch.Generator | None) -> Batch:
        """Flat pixel indices ``(R,)`` into the image stack -> a :class:`Batch`."""
        n, h, w = self.shape
        device = self.images.device
        img, rem = flat // (h * w), flat % (h * w)
        row, col = rem // w, rem % w
        # a random point inside each pixel (anti-aliasing); pixel (row, col) spans [col, col+1) x [row, row+1)
        jitter = torch.rand(flat.shape[0], 2, generator=generator, device="cpu").to(device, self.images.dtype)
        uv = torch.stack([col, row], dim=-1).to(self.images.dtype) + jitter
        origins, dirs, radii = camera_rays(uv, self.K[img], self.c2w[img])
        return Batch(
            origins=origins, dirs=dirs, radii=radii, rgb=self.images[img, row, col],
            mask=self.masks[img, row, col].to(self.images.dtype), valid=self.valid[img, row, col], photo=img,
        )
