"""Checks of what SfM returns, before anything trusts it: a registered photo is not a right photo.

Repetitive textures (plain tiles, brick, a patterned floor) fool the matcher: a photo can register at the
spot of another that looks the same, with a small reprojection error, and nothing in COLMAP's own figures
says so. The checks below look at the cameras themselves; each returns the photos it doubts with the measured
figure and a reason a person can read:

1. **Path jumps** (:func:`path_jumps`): in capture order (EXIF capture time when every photo has one, else
   file name: :func:`capture_order`) the camera moves in small steps. A step far above the median step
   between two photos that look alike (they share many verified matches: they were taken one after the
   other) means one side's pose is wrong. The photos dropped are the fewest that leave a path without such
   jumps (:func:`consistent_path`). Two photos that share few matches may be far apart for real (a stretch
   of the orbit was not photographed) and are never flagged.
2. **Axes that miss the object** (:func:`axes_misses`): people aim at the object; a camera whose optical axis
   misses the point where the other cameras' axes converge (:func:`pipeline.object_frame.axes_convergence`)
   by much more than the others' (median + a multiple of the MAD), and by more than the central window where
   the object is assumed to lie (``poses.object_window``), or which looks away from it, is doubted.
3. **Cameras far out** (:func:`far_cameras`): a walk-around keeps its distance from the object within a small
   factor (hand-held: ~2x between the nearest and farthest photo); a camera more than ``poses.distance_ratio``
   times the cameras' median distance from the point their axes converge on is doubted. A weak view graph
   leaves the global mapper's translation averaging free to put a camera along its viewing ray far behind the
   others -- its axis still meets the object, so check 2 cannot see it.
4. **Up** (:func:`up_check`): the normalized frame's z is the cameras' mean up
   (:func:`pipeline.object_frame.camera_up`). The floor or table under the object, fitted to the sparse points
   by RANSAC (:func:`pipeline.object_frame.support_plane`), should be perpendicular to it; a clearly supported
   plane tilted by more than ``poses.up_max_deg`` is reported (a frame-wide warning, not a photo's).
5. **Weak support** (:func:`weak_support`): a camera the final model's 3D points support with fewer observations
   than ``poses.min_support_points`` rests on too little to trust, however well those few reproject. The mapper's
   last bundle adjustments and filtering can strip a photo of what registered it and leave the camera where it
   was: on the blowtorch walk-around a photo ended with 10 observations and 37 degrees off the photographers'
   camera while its axis still met the object (check 2 cannot see that); every right camera measured had 16 or
   more.
6. **Focal length** (:func:`focal_checks`): a model can be consistent and wrong as a whole, its lens fitted to
   make it so. Its focal length drifts from what EXIF (or a calibration) says: on a plain room the mapper's
   2-photo model, extended by the relaxed pass, fitted a focal length 20 times the EXIF one and placed 9
   photos 5.7 degrees off; partial models of other plain rooms were 1.4-1.6 off, every right model measured
   within 1.07 (the blowtorch's lens against its EXIF; the synthetic captures' within 0.01). Beyond
   ``poses.focal_warn_ratio`` either way it warns about the model as a whole, and doubts no photo: photos
   cropped after they were taken keep their EXIF and are as far off with a right model (1.5 for a 3:2 photo
   cropped square, 3 for a crop to an object a third as wide), and the models measured that far off were
   partial ones, which ``poses.min_registered_fraction`` stops.
7. **Runs that disagree** (:func:`ambiguous`): the mapper is randomized (RANSAC, the order it adds photos in),
   and where the view graph holds a part of the capture by a few weak or look-alike pairs it can place that
   part differently from run to run, each placement consistent in itself. On the blowtorch walk-around one of
   32 runs measured on the same matches put its lowest ring's 7 photos 23-38 degrees round the object from the
   photographers' cameras, with as many observations and as small a reprojection error as the right
   placement, their axes still on the object: none of the checks above can see that. So the matches are mapped
   again with other seeds (``poses.mapping_runs``), and a camera whose orientation differs by more than
   ``poses.mapping_max_deg`` from every other run's (:func:`rotation_disagreement`, after the rotation that
   best aligns the runs' other cameras) is doubted: the photos cannot tell where it was taken. Between the
   other 31 runs the blowtorch's cameras differ by 5.1 degrees at most (its weakest photos; 0.0-0.3 median).

:func:`check_poses` runs them all (the up check on the cameras it is given) and returns a :class:`PoseChecks`
for ``poses_report.json``. Arrays only; no files, no pycolmap.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from datetime import datetime
from typing import Any

import numpy as np

from .alignment import mean_rotation, rotation_angle_deg
from .config import PosesConfig
from .object_frame import axes_convergence, camera_up, plane_normal, support_plane, window_fraction

EXIF_TIME = "%Y:%m:%d %H:%M:%S"  # EXIF DateTimeOriginal
MAD_TO_SIGMA = 1.4826  # the MAD of a normal distribution times this is its standard deviation
PARALLEL_AXES = 0.01  # conditioning under which the axes do not converge (the test object_frame.find_object uses)
MIN_PATH = 3  # fewer cameras have no median step worth the name
MIN_AXES = 4  # the convergence of the others' axes needs at least three lines
# The up check's plane search: up to this tilt from the cameras' up (object_frame's own search stops at 30
# degrees, which would hide the disagreements this check is for); planes of fewer points are not "clear".
PLANE_SEARCH_DEG = 45.0
MIN_PLANE_POINTS = 30
PLANE_TOLERANCE = 0.02  # inlier distance, as a share of the points' median distance from the centre (as find_object)


@dataclass(frozen=True)
class Suspect:
    """One photo whose pose a check doubts."""

    name: str
    check: str  # "path_jump" | "axis_miss" | "looks_away" | "far_out" | "weak_support" | "ambiguous"
    value: float  # the measured figure: step / median step (path_jump), degrees off the axis (axis_miss,
    # looks_away), distance / median distance (far_out), observations (weak_support), degrees to the nearest
    # other run's orientation (ambiguous)
    limit: float  # the threshold it exceeded, same unit
    reason: str


@dataclass(frozen=True)
class UpCheck:
    """The cameras' up against the plane under the object."""

    angle_deg: float | None  # between up and the plane's normal; None when no plane is clearly supported
    plane_points: int  # sparse points on the plane
    points: int  # sparse points considered (central in half of the photos, as object_frame's)
    limit_deg: float
    normal: list[float] | None = None  # the plane's normal, pointing up

    @property
    def disagrees(self) -> bool:
        return self.angle_deg is not None and self.angle_deg > self.limit_deg

    def warning(self) -> str | None:
        if not self.disagrees:
            return None
        return (f"the up direction (the cameras' mean up) is {self.angle_deg:.1f} degrees off the normal of the "
                f"plane under the object ({self.plane_points} of {self.points} sparse points lie on it; more than "
                f"poses.up_max_deg={self.limit_deg:g}): the normalized frame is tilted, or some poses are wrong")


@dataclass(frozen=True)
class FocalCheck:
    """One lens's fitted focal length against its prior (EXIF or calibration)."""

    photos: int
    fitted_px: float
    prior_px: float
    warn_ratio: float

    @property
    def ratio(self) -> float:
        """The factor between fitted and prior, either way (>= 1)."""
        return max(self.fitted_px / self.prior_px, self.prior_px / self.fitted_px)

    def warning(self) -> str | None:
        if self.ratio <= self.warn_ratio:
            return None
        return (f"the focal length fitted to {self.photos} photo(s) is {self.fitted_px:.0f} px, {self.ratio:.2f} "
                f"times off the {self.prior_px:.0f} px their EXIF (or calibration) gives (more than "
                f"poses.focal_warn_ratio={self.warn_ratio:g}): unless the photos were cropped after they were taken, "
                "the model is wrong as a whole (too few photos overlap); check poses.png")


@dataclass
class PoseChecks:
    """What :func:`check_poses` found: the doubted photos and the up check."""

    order: str  # what set the capture order: "capture time" | "file name"
    suspects: list[Suspect] = field(default_factory=list)
    median_step: float | None = None  # between consecutive cameras, in the cameras' frame
    median_matches: float | None = None  # verified matches between consecutive photos
    axis_median_deg: float | None = None  # how far the axes miss the others' convergence, median over cameras
    median_distance: float | None = None  # of the cameras from the axes' convergence, in the cameras' frame
    up: UpCheck | None = None
    focal: list[FocalCheck] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    @property
    def flagged(self) -> list[str]:
        """The doubted photos' names, each once, in the order the checks found them."""
        return list(dict.fromkeys(s.name for s in self.suspects))

    def photo_warnings(self) -> list[str]:
        """One line per doubted photo, its reasons joined."""
        return [f"{n}: " + "; ".join(s.reason for s in self.suspects if s.name == n) for n in self.flagged]

    def frame_warnings(self) -> list[str]:
        """The up check's and the focal checks' warnings: about the model as a whole."""
        frame = [self.up.warning() if self.up is not None else None] + [f.warning() for f in self.focal]
        return [w for w in frame if w]

    def warnings(self) -> list[str]:
        return self.photo_warnings() + self.frame_warnings()

    def to_json(self) -> dict[str, Any]:
        out = asdict(self)
        out["flagged"] = self.flagged
        if self.up is not None:
            out["up"]["disagrees"] = self.up.disagrees
        for f, check in zip(out["focal"], self.focal):
            f["ratio"] = check.ratio
        return out


# ------------------------------------------------------------------------------------------ capture order


def capture_order(names: Sequence[str], times: Sequence[str | None]) -> tuple[np.ndarray, str]:
    """``(N,)`` indices of ``names`` in the order the photos were taken, and what set it.

    EXIF capture time (``YYYY:MM:DD HH:MM:SS``) when every photo has a readable one and they are not all equal
    (ties keep name order: EXIF counts whole seconds, a burst shares one); else file-name order (cameras and
    phones number photos as they take them; frames of a video are numbered in time).
    """
    parsed = []
    for t in times:
        try:
            parsed.append(datetime.strptime(t.strip(), EXIF_TIME) if t else None)
        except ValueError:
            parsed.append(None)
    by_name = sorted(range(len(names)), key=lambda i: names[i])
    if not names or any(t is None for t in parsed) or len(set(parsed)) == 1:
        return np.array(by_name, int), "file name"
    return np.array(sorted(by_name, key=lambda i: parsed[i]), int), "capture time"


# --------------------------------------------------------------------------------------------- path jumps


def consistent_path(centers: np.ndarray, alike: np.ndarray, max_step: float, step: float) -> np.ndarray:
    """``(N,)`` bool: the longest sub-path of the cameras (in capture order) without a jump; False = dropped.

    A link between kept cameras ``a < b`` is a jump when the photos between them are all alike (each pair of
    consecutive ones, ``alike[a:b]``) and the cameras lie more than ``max_step + step * (b - a - 1)`` apart:
    one step's allowance plus a typical step for each photo left out (a chord is never longer than the path
    it cuts). Dynamic programming over the cameras, O(N^2).

    Args:
        centers: ``(N, 3)`` camera centres in capture order.
        alike: ``(N - 1,)`` bool, photo ``i`` and ``i + 1`` look alike.
        max_step: the longest step between alike neighbours that is not a jump.
        step: the typical step (the median).
    """
    n = len(centers)
    dist = np.linalg.norm(centers[:, None] - centers[None], axis=-1)
    breaks = np.concatenate([[0], np.cumsum(~alike)])  # non-alike pairs before each camera
    length = np.ones(n, int)
    prev = np.full(n, -1)
    for b in range(1, n):
        a = np.arange(b)
        ok = (dist[a, b] <= max_step + step * (b - a - 1)) | (breaks[b] > breaks[a])
        if ok.any():
            best = int(a[ok][np.argmax(length[a[ok]])])
            length[b], prev[b] = length[best] + 1, best
    keep = np.zeros(n, bool)
    i = int(np.argmax(length))
    while i >= 0:
        keep[i] = True
        i = int(prev[i])
    return keep


def path_jumps(names: Sequence[str], centers: np.ndarray, matches: np.ndarray, ratio: float,
               min_match_share: float) -> tuple[list[Suspect], float | None, float | None]:
    """Photos whose camera jumps away from its neighbours in capture order (see the module doc).

    Args:
        names: ``N`` photo names in capture order.
        centers: ``(N, 3)`` camera centres, same order.
        matches: ``(N - 1,)`` verified matches between photo ``i`` and ``i + 1`` (how alike they look).
        ratio: a step longer than this times the median step is a jump, when the two photos look alike ...
        min_match_share: ... that is, they share at least this share of the median of ``matches``.

    Returns:
        (suspects, median step, median matches); no suspects under :data:`MIN_PATH` cameras.
    """
    n = len(names)
    if n < MIN_PATH:
        return [], None, None
    steps = np.linalg.norm(np.diff(centers, axis=0), axis=1)
    median_step, median_matches = float(np.median(steps)), float(np.median(matches))
    alike = (matches > 0) & (matches >= min_match_share * median_matches)
    limit = ratio * median_step
    if median_step <= 0 or not np.any(alike & (steps > limit)):
        return [], median_step, median_matches
    dropped = np.flatnonzero(~consistent_path(centers, alike, limit, median_step))
    suspects = []
    for run in np.split(dropped, np.flatnonzero(np.diff(dropped) > 1) + 1) if len(dropped) else []:
        first, last = int(run[0]), int(run[-1])
        edges = [(i, i + 1) for i in (first - 1, last) if 0 <= i < n - 1]
        jumps = [(i, j) for i, j in edges if alike[i] and steps[i] > limit] or edges
        value = max(float(steps[i]) / median_step for i, _ in jumps)
        what = ", ".join(f"{steps[i] / median_step:.1f}x from {names[i]} to {names[j]} ({int(matches[i])} shared "
                         f"matches)" for i, j in jumps)
        who = (f"the pose of {names[first]} disagrees" if first == last else
               f"the poses of {names[first]}..{names[last]} ({last - first + 1} photos) disagree")
        reason = (f"the camera path jumps {what}: more than poses.jump_ratio={ratio:g} times the median step "
                  f"between photos taken one after the other (median {median_matches:.0f} shared matches), so "
                  f"{who} with the neighbours'")
        suspects += [Suspect(names[k], "path_jump", value, ratio, reason) for k in range(first, last + 1)]
    return suspects, median_step, median_matches


# --------------------------------------------------------------------------------------------------- axes


def axes_misses(names: Sequence[str], c2w: np.ndarray, K: np.ndarray, sizes: np.ndarray, window: float,
                mads: float) -> tuple[list[Suspect], float | None, str | None]:
    """Cameras whose optical axis misses the point the other cameras' axes converge on (see the module doc).

    Each camera against the convergence of the others' (leave-one-out: a wrong camera does not pull its own
    reference). The angle between its axis and the direction to that point is doubted when it exceeds both
    ``median + mads * MAD`` over the cameras (much more than the others) and the half-angle of the camera's
    central ``window`` (the object is assumed to lie there: ``poses.object_window``); at 90 degrees and more
    the camera looks away from it.

    Args:
        names: ``N`` photo names; c2w ``(N, 4, 4)`` OpenCV camera-to-world; K ``(N, 3, 3)``; sizes ``(N, 2)``
        (width, height).

    Returns:
        (suspects, median angle in degrees, a note when the check could not run).
    """
    n = len(names)
    centers, dirs = c2w[:, :3, 3], c2w[:, :3, 2] / np.linalg.norm(c2w[:, :3, 2], axis=1, keepdims=True)
    if n < MIN_AXES:
        return [], None, f"axes not checked: {n} cameras (at least {MIN_AXES} needed)"
    if axes_convergence(centers, dirs)[2] < PARALLEL_AXES:
        return [], None, "axes not checked: they are nearly parallel (not an orbit around the object)"
    angles = np.empty(n)
    for i in range(n):
        others = np.arange(n) != i
        point = axes_convergence(centers[others], dirs[others])[0]
        to_point = point - centers[i]
        cos = float(to_point @ dirs[i]) / max(float(np.linalg.norm(to_point)), 1e-12)
        angles[i] = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
    median = float(np.median(angles))
    spread = median + mads * MAD_TO_SIGMA * float(np.median(np.abs(angles - median)))
    half = np.degrees(np.arctan(window * np.minimum(sizes[:, 0] / K[:, 0, 0], sizes[:, 1] / K[:, 1, 1]) / 2))
    suspects = []
    for i in range(n):
        limit = max(spread, float(half[i]))
        if angles[i] >= 90.0:
            suspects.append(Suspect(names[i], "looks_away", float(angles[i]), 90.0,
                                    f"the camera looks away from the object: the point the other cameras' axes "
                                    f"converge on is {angles[i]:.0f} degrees off its axis, behind it"))
        elif angles[i] > limit:
            suspects.append(Suspect(names[i], "axis_miss", float(angles[i]), limit,
                                    f"its optical axis misses the point the other cameras' axes converge on by "
                                    f"{angles[i]:.1f} degrees (median over the cameras {median:.1f}; limit "
                                    f"{limit:.1f}: median + poses.axis_miss_mads={mads:g} MADs, and at least the "
                                    f"central poses.object_window={window:g} of the photo)"))
    return suspects, median, None


def far_cameras(names: Sequence[str], centers: np.ndarray, point: np.ndarray,
                ratio: float) -> tuple[list[Suspect], float]:
    """Cameras (``centers`` ``(N, 3)``) more than ``ratio`` times the median distance from ``point`` ``(3,)``,
    where the axes converge (see the module doc). Returns (suspects, median distance)."""
    distance = np.linalg.norm(centers - point, axis=1)
    median = float(np.median(distance))
    suspects = [Suspect(names[i], "far_out", float(distance[i] / median), ratio,
                        f"the camera is {distance[i] / median:.1f} times as far from the object as the median camera "
                        f"(more than poses.distance_ratio={ratio:g}): SfM placed it along its line of sight, far "
                        f"behind the others") for i in np.flatnonzero(distance > ratio * median)]
    return suspects, median


def weak_support(names: Sequence[str], support: np.ndarray, min_points: int) -> list[Suspect]:
    """Cameras whose pose fewer than ``min_points`` of the model's 3D points support (``support`` ``(N,)``: the
    observations of 3D points in each photo; see the module doc)."""
    return [Suspect(names[i], "weak_support", float(support[i]), float(min_points),
                    f"only {int(support[i])} of the model's 3D points are seen in it (fewer than "
                    f"poses.min_support_points={min_points}): its camera rests on too little to trust")
            for i in np.flatnonzero(np.asarray(support) < min_points)]


def focal_checks(focal: np.ndarray, prior: np.ndarray, warn_ratio: float) -> list[FocalCheck]:
    """One :class:`FocalCheck` per lens: per distinct (fitted, prior) pair of ``focal`` ``(N,)`` (fitted focal
    lengths in pixels) and ``prior`` ``(N,)`` (NaN where there is none: not checked). See the module doc."""
    focal, prior = np.asarray(focal, float), np.asarray(prior, float)
    known = np.isfinite(prior)
    pairs = np.unique(np.stack([focal[known], prior[known]], axis=1), axis=0)
    return [FocalCheck(int(np.sum(known & (focal == f) & (prior == p))), float(f), float(p), warn_ratio)
            for f, p in pairs]


# ------------------------------------------------------------------------------------ runs that disagree


def rotation_disagreement(c2w: np.ndarray, other: np.ndarray, max_deg: float, rounds: int = 3) -> np.ndarray:
    """``(N,)`` degrees between each camera's orientation in ``c2w`` ``(N, 4, 4)`` and in ``other`` ``(N, 4, 4)``
    (the same cameras from another SfM run, any similarity apart; NaN rows: not in that run, NaN out).

    The runs are aligned by the rotation that best maps ``other``'s orientations onto ``c2w``'s (the chordal
    mean of the cameras' relative rotations), refitted ``rounds`` times on the cameras within ``max_deg``:
    a block of cameras placed elsewhere must not tilt the alignment of the rest (7 of 59 cameras 25 degrees
    off bias a plain mean by 3).
    """
    found = ~np.isnan(other[:, 0, 0])
    out = np.full(len(c2w), np.nan)
    if found.sum() < 2:
        return out
    relative = c2w[found, :3, :3] @ np.swapaxes(other[found, :3, :3], -1, -2)  # other's world -> ours, per camera
    used = np.ones(int(found.sum()), bool)
    for _ in range(rounds):
        align = mean_rotation(relative[used])
        angles = rotation_angle_deg(np.swapaxes(align, -1, -2) @ relative)
        if (angles <= max_deg).sum() < 2:
            break
        used = angles <= max_deg
    out[found] = angles
    return out


def ambiguous(names: Sequence[str], disagreement: np.ndarray, max_deg: float) -> list[Suspect]:
    """Cameras whose orientation differs by more than ``max_deg`` from every other run's that placed them
    (``disagreement`` ``(N, R)``: :func:`rotation_disagreement` against each of R other runs; NaN: not placed
    there). See the module doc."""
    runs = disagreement.shape[1]
    if not runs:
        return []
    nearest = np.where(np.isnan(disagreement), np.inf, disagreement).min(axis=1)
    return [Suspect(names[i], "ambiguous", float(nearest[i]), max_deg,
                    f"another run of the mapper on the same matches turned this camera by {nearest[i]:.0f} degrees "
                    f"(more than poses.mapping_max_deg={max_deg:g}; {runs} other run(s), each aligned on the rest): "
                    f"its photo is held to the others by too few or look-alike matches to say where it was taken")
            for i in np.flatnonzero(np.isfinite(nearest) & (nearest > max_deg))]


# ----------------------------------------------------------------------------------------------------- up


def up_check(points: np.ndarray, up: np.ndarray, center: np.ndarray, limit_deg: float, seed: int = 0) -> UpCheck:
    """``up`` ``(3,)`` against the dominant plane of ``points`` ``(M, 3)`` (the sparse points around and under
    the object) within :data:`PLANE_SEARCH_DEG` of it, in the lower half of the points. A plane of fewer than
    :data:`MIN_PLANE_POINTS` points (or 20 % of them) gives no angle: nothing clear to compare with."""
    m = len(points)
    if m < MIN_PLANE_POINTS:
        return UpCheck(None, 0, m, limit_deg)
    tolerance = PLANE_TOLERANCE * float(np.median(np.linalg.norm(points - center, axis=1)))
    on = support_plane(points, up, tolerance, np.random.default_rng(seed), max_tilt_deg=PLANE_SEARCH_DEG)
    if on.sum() < MIN_PLANE_POINTS:
        return UpCheck(None, int(on.sum()), m, limit_deg)
    plane = points[on]
    normal = plane_normal(plane, up)
    angle = float(np.degrees(np.arccos(np.clip(normal @ up / np.linalg.norm(up), -1.0, 1.0))))
    return UpCheck(angle, int(on.sum()), m, limit_deg, [float(v) for v in normal])


def object_points(points: np.ndarray, c2w: np.ndarray, K: np.ndarray, sizes: np.ndarray,
                  window: float) -> np.ndarray:
    """The sparse points ``(M, 3)`` central (inside ``window``) in at least half of the photos: the object and
    what it stands on, as :func:`pipeline.object_frame.find_object` takes them."""
    return points[window_fraction(points, c2w, K, sizes, window) >= 0.5] if len(points) else points


# -------------------------------------------------------------------------------------------- entry point


def check_poses(names: Sequence[str], c2w: np.ndarray, K: np.ndarray, sizes: np.ndarray, matches: np.ndarray,
                order: np.ndarray, order_by: str, points: np.ndarray | None, config: PosesConfig,
                support: np.ndarray | None = None, focal_prior: np.ndarray | None = None,
                disagreement: np.ndarray | None = None) -> PoseChecks:
    """All the checks on one set of cameras.

    Args:
        names: ``N`` photo names; c2w ``(N, 4, 4)``; K ``(N, 3, 3)``; sizes ``(N, 2)``: any order.
        matches: ``(N - 1,)`` verified matches between consecutive photos in capture order.
        order: ``(N,)`` indices into ``names`` in capture order (:func:`capture_order`), ``order_by`` what set it.
        points: ``(M, 3)`` sparse points, or None (no up check).
        config: the thresholds (``jump_ratio``, ``jump_min_match_share``, ``axis_miss_mads``, ``object_window``,
            ``distance_ratio``, ``min_support_points``, ``focal_warn_ratio``, ``up_max_deg``, ``mapping_max_deg``,
            ``seed``).
        support: ``(N,)`` observations of 3D points in each photo, or None (no support check: cameras not from SfM).
        focal_prior: ``(N,)`` each photo's prior focal length in pixels (NaN: none), or None (no focal check).
        disagreement: ``(N, R)`` degrees between each camera and its orientation in R other mapper runs
            (:func:`rotation_disagreement`; NaN: not placed there), or None (no such runs).
    """
    checks = PoseChecks(order_by)
    ordered = [names[i] for i in order]
    jumps, checks.median_step, checks.median_matches = path_jumps(
        ordered, c2w[order, :3, 3], np.asarray(matches, float), config.jump_ratio, config.jump_min_match_share)
    misses, checks.axis_median_deg, note = axes_misses(names, c2w, K, sizes, config.object_window,
                                                       config.axis_miss_mads)
    center, _, conditioning = axes_convergence(c2w[:, :3, 3], c2w[:, :3, 2])
    far = []
    if len(names) >= MIN_AXES and conditioning >= PARALLEL_AXES:  # else no point to measure distances from
        far, checks.median_distance = far_cameras(names, c2w[:, :3, 3], center, config.distance_ratio)
    weak = [] if support is None else weak_support(names, support, config.min_support_points)
    unsure = [] if disagreement is None else ambiguous(names, disagreement, config.mapping_max_deg)
    checks.suspects = jumps + misses + far + weak + unsure
    if focal_prior is not None:
        checks.focal = focal_checks(K[:, 0, 0], focal_prior, config.focal_warn_ratio)
    checks.notes += [note] if note else []
    if points is not None:
        checks.up = frame_up_check(points, c2w, K, sizes, camera_up(c2w), center, config)
    return checks


def frame_up_check(points: np.ndarray, c2w: np.ndarray, K: np.ndarray, sizes: np.ndarray, up: np.ndarray,
                   center: np.ndarray, config: PosesConfig) -> UpCheck:
    """:func:`up_check` of a frame's ``up`` ``(3,)`` and object ``center`` ``(3,)`` on the sparse points
    ``(M, 3)`` :func:`object_points` keeps (c2w ``(N, 4, 4)``, K ``(N, 3, 3)``, sizes ``(N, 2)``)."""
    near = object_points(points, c2w, K, sizes, config.object_window)
    return up_check(near, up, center, config.up_max_deg, config.seed)
