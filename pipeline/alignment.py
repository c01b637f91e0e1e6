"""Similarity alignment of point sets and camera poses (Umeyama), and the errors measured after it.

Used by the poses stage (to report how well known or refined cameras agree) and by ``orca evaluate``
(a model's frame against the ground truth's: poses, and the frame its renders are moved by). A similarity
``(s, R, t)`` maps a point ``x`` to ``s * R @ x + t``; as a 4x4 matrix it is ``[[s R, t], [0, 1]]``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from .errors import InputError

if TYPE_CHECKING:
    from .cameras import CameraSet


@dataclass(frozen=True)
class Similarity:
    """``x -> scale * rotation @ x + translation``."""

    scale: float
    rotation: np.ndarray  # (3, 3), det +1
    translation: np.ndarray  # (3,)

    @property
    def matrix(self) -> np.ndarray:
        """``(4, 4)`` homogeneous form."""
        m = np.eye(4)
        m[:3, :3] = self.scale * self.rotation
        m[:3, 3] = self.translation
        return m

    @classmethod
    def identity(cls) -> Similarity:
        return cls(1.0, np.eye(3), np.zeros(3))

    @classmethod
    def from_matrix(cls, m: np.ndarray) -> Similarity:
        """The similarity of a ``(4, 4)`` matrix; an InputError when it is not one (not finite, last row not
        0 0 0 1, a reflection, or a 3x3 part that is not a scaled rotation)."""
        m = np.asarray(m, dtype=np.float64)
        if m.shape != (4, 4) or not np.isfinite(m).all() or not np.allclose(m[3], [0, 0, 0, 1]):
            raise InputError(f"expected a finite 4x4 similarity with last row 0 0 0 1, got {m.shape}")
        det = np.linalg.det(m[:3, :3])
        if det <= 0:
            raise InputError("the 4x4 similarity is a reflection or degenerate (det <= 0)")
        scale = float(np.cbrt(det))
        rotation = m[:3, :3] / scale
        if not np.allclose(rotation.T @ rotation, np.eye(3), atol=1e-5):
            raise InputError("not a similarity: the 3x3 part of the 4x4 matrix is not a scaled rotation")
        return cls(scale, rotation, m[:3, 3].copy())

    def inverse(self) -> Similarity:
        r_inv = self.rotation.T
        return Similarity(1.0 / self.scale, r_inv, -(r_inv @ self.translation) / self.scale)

    def apply(self, points: np.ndarray) -> np.ndarray:
        """``(..., 3)`` points -> ``(..., 3)`` transformed points."""
        return self.scale * np.asarray(points) @ self.rotation.T + self.translation

    def apply_c2w(self, c2w: np.ndarray) -> np.ndarray:
        """``(..., 4, 4)`` rigid camera-to-world matrices -> the same cameras in the target frame (still rigid:
        the rotation is composed, the centre transformed; the scale only moves the centre)."""
        c2w = np.asarray(c2w, dtype=np.float64)
        out = c2w.copy()
        out[..., :3, :3] = self.rotation @ c2w[..., :3, :3]
        out[..., :3, 3] = self.apply(c2w[..., :3, 3])
        return out

    def apply_inverse_c2w(self, c2w: np.ndarray) -> np.ndarray:
        """A ``(4, 4)`` rigid camera-to-world matrix of the target frame -> the same camera in the source frame
        (rotation ``R^T R_c``, centre ``R^T (c - t) / s``)."""
        out = np.eye(4)
        out[:3, :3] = self.rotation.T @ c2w[:3, :3]
        out[:3, 3] = self.rotation.T @ (c2w[:3, 3] - self.translation) / self.scale
        return out

    def rotate(self, vectors: np.ndarray) -> np.ndarray:
        """``(..., 3)`` directions (normals) -> the target frame's: the rotation alone."""
        return vectors @ self.rotation.T


def fit_similarity(src: np.ndarray, dst: np.ndarray, *, with_scale: bool = True) -> Similarity:
    """Least-squares similarity with ``dst ~ s R src + t`` (Umeyama 1991).

    Args:
        src, dst: ``(N, 3)`` corresponding points, ``N >= 3`` not all collinear.
        with_scale: ``False`` fits a rigid transform (``s = 1``).
    """
    src = np.asarray(src, dtype=np.float64)
    dst = np.asarray(dst, dtype=np.float64)
    if src.shape != dst.shape or src.ndim != 2 or src.shape[1] != 3:
        raise ValueError(f"expected two (N, 3) arrays of the same shape, got {src.shape} and {dst.shape}")
    if len(src) < 3:
        raise ValueError(f"a similarity needs at least 3 point pairs, got {len(src)}")
    mu_s, mu_d = src.mean(0), dst.mean(0)
    xs, xd = src - mu_s, dst - mu_d
    var_s = float((xs**2).sum() / len(src))
    if var_s < 1e-300:
        raise ValueError("source points all coincide")
    cov = xd.T @ xs / len(src)
    u, d, vt = np.linalg.svd(cov)
    if d[1] < 1e-12 * max(d[0], 1e-300):
        raise ValueError("points are collinear: the rotation about their line is undetermined")
    sign = np.ones(3)
    if np.linalg.det(u) * np.linalg.det(vt) < 0:  # a reflection fits better; take the best rotation instead
        sign[2] = -1
    r = u @ np.diag(sign) @ vt
    s = float((d * sign).sum() / var_s) if with_scale else 1.0
    t = mu_d - s * r @ mu_s
    return Similarity(s, r, t)


def rotation_angle_deg(r: np.ndarray) -> np.ndarray:
    """``(..., 3, 3)`` rotations -> ``(...)`` their angles in degrees (numerically safe near 0 and 180)."""
    r = np.asarray(r, dtype=np.float64)
    cos = (np.trace(r, axis1=-2, axis2=-1) - 1) / 2
    # arccos loses precision near 0; the skew part gives sin directly.
    skew = np.stack([r[..., 2, 1] - r[..., 1, 2], r[..., 0, 2] - r[..., 2, 0], r[..., 1, 0] - r[..., 0, 1]], -1)
    sin = np.linalg.norm(skew, axis=-1) / 2
    return np.rad2deg(np.arctan2(sin, cos))


@dataclass(frozen=True)
class PoseErrors:
    """Camera poses compared after aligning camera centres with a similarity."""

    similarity: Similarity  # estimated frame -> reference frame
    rotation_deg: np.ndarray  # (N,) angle between aligned and reference camera rotations
    center: np.ndarray  # (N,) centre distance after alignment, reference units

    def summary(self, scale: float = 1.0) -> dict[str, float]:
        """Median/mean/max of both errors; centre errors also as a fraction of ``scale`` (e.g. orbit radius)."""
        return {
            "rotation_deg_median": float(np.median(self.rotation_deg)),
            "rotation_deg_mean": float(self.rotation_deg.mean()),
            "rotation_deg_max": float(self.rotation_deg.max()),
            "center_median": float(np.median(self.center)),
            "center_mean": float(self.center.mean()),
            "center_max": float(self.center.max()),
            "center_median_fraction": float(np.median(self.center) / scale),
            "center_max_fraction": float(self.center.max() / scale),
        }


def mean_rotation(rotations: np.ndarray) -> np.ndarray:
    """``(N, 3, 3)`` rotations -> ``(3, 3)`` their chordal L2 mean (the rotation nearest to their sum)."""
    u, _, vt = np.linalg.svd(np.asarray(rotations, dtype=np.float64).sum(0))
    return u @ np.diag([1.0, 1.0, np.linalg.det(u @ vt)]) @ vt


def compare_poses(c2w_est: np.ndarray, c2w_ref: np.ndarray, *, rotation_from: str = "centers") -> PoseErrors:
    """Align estimated cameras to reference ones with a similarity and measure what is left.

    Args:
        c2w_est, c2w_ref: ``(N, 4, 4)`` camera-to-world matrices of the same N cameras, OpenCV convention.
        rotation_from: ``"centers"``: the whole similarity from the camera centres (Umeyama); the usual
            choice, but its rotation inherits the centres' noise (0.3 % centre noise on a ring of cameras
            tilts it by ~0.15 degrees, which then shows up in every camera's rotation error).
            ``"orientations"``: the rotation is the mean of the cameras' relative rotations, then scale and
            translation come from the centres; the rotation errors are then the cameras' own.
    """
    c2w_est = np.asarray(c2w_est, dtype=np.float64)
    c2w_ref = np.asarray(c2w_ref, dtype=np.float64)
    sim = fit_similarity(c2w_est[:, :3, 3], c2w_ref[:, :3, 3])
    if rotation_from == "orientations":
        r = mean_rotation(c2w_ref[:, :3, :3] @ np.swapaxes(c2w_est[:, :3, :3], -1, -2))
        src, dst = c2w_est[:, :3, 3] @ r.T, c2w_ref[:, :3, 3]
        xs, xd = src - src.mean(0), dst - dst.mean(0)
        scale = float((xs * xd).sum() / (xs**2).sum())
        sim = Similarity(scale, r, dst.mean(0) - scale * src.mean(0))
    elif rotation_from != "centers":
        raise ValueError(f"rotation_from must be 'centers' or 'orientations', got {rotation_from!r}")
    aligned = sim.apply_c2w(c2w_est)
    rel = np.swapaxes(aligned[:, :3, :3], -1, -2) @ c2w_ref[:, :3, :3]
    return PoseErrors(sim, rotation_angle_deg(rel), np.linalg.norm(aligned[:, :3, 3] - c2w_ref[:, :3, 3], axis=-1))


def align_cameras(result: CameraSet, truth: CameraSet, centre: np.ndarray | None = None,
                  result_path: Path | None = None) -> tuple[Similarity, dict[str, Any]]:
    """The similarity result frame -> reference frame fitted on the centres of the cameras both hold (matched
    by name; Umeyama), and the pose errors left after it.

    Args:
        centre: the object centre in the reference frame (the orbit radius is measured from it);
            default: the mean of the reference camera centres.
        result_path: the result's cameras.json, named in errors.
    Returns:
        the similarity and a JSON-ready report: ``summary`` (medians, means, maxima; centre errors also in %
        of the orbit radius: the reference cameras' median distance from ``centre``), ``per_camera``,
        ``missing`` (reference cameras the result lacks, e.g. photos SfM did not register: not counted).
    """
    ours, theirs = result.by_name(), truth.by_name()
    common = [n for n in theirs if n in ours]
    missing = [n for n in theirs if n not in ours]
    if len(common) < 3:
        raise InputError(f"only {len(common)} camera name(s) in common with the ground truth; aligning the frames "
                         "needs 3 or more", result_path,
                         "pass the cameras.json the model was trained with (the poses stage's), whose names are the "
                         "photos' names")
    est = np.stack([ours[n].c2w for n in common])
    ref = np.stack([theirs[n].c2w for n in common])
    try:
        errors = compare_poses(est, ref)
    except ValueError as e:
        raise InputError(f"cannot align the cameras to the ground truth: {e}", result_path) from e
    centres = np.stack([c.center for c in truth.cameras])
    centre = centres.mean(0) if centre is None else np.asarray(centre, np.float64)
    orbit = float(np.median(np.linalg.norm(centres - centre, axis=1)))
    summary = errors.summary(scale=orbit)
    summary = {k: v for k, v in summary.items() if not k.endswith("_fraction")}
    summary.update(center_median_percent=100 * float(np.median(errors.center)) / orbit,
                   center_max_percent=100 * float(errors.center.max()) / orbit, orbit_radius=orbit,
                   cameras=len(common), missing=len(missing), scale=errors.similarity.scale)
    report = {
        "summary": summary,
        "per_camera": {n: {"rotation_deg": float(r), "center": float(c), "center_percent": 100 * float(c) / orbit}
                       for n, r, c in zip(common, errors.rotation_deg, errors.center, strict=True)},
        "missing": missing, "to_ground_truth": errors.similarity.matrix.tolist(),
        "method": "Umeyama similarity on camera centres (result -> ground truth), then per-camera errors",
    }
    return errors.similarity, report
