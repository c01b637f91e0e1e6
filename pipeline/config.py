"""The pipeline's configuration: one validated model, presets by name, YAML files and CLI overrides.

Unknown keys and bad values are errors (pydantic ``extra="forbid"``), never silence. A config is built as
``defaults <- preset <- capture.yaml <- --config FILE <- --set key=value``, later layers winning. A preset is
a YAML file of ``pipeline/presets/`` (its name the file's stem). The train section is nested per component
of the model (``train.sdf``, ``train.environment``, ``train.render``, ...); its earlier flat keys
(:data:`MOVED`) still work, with a warning naming the new key.
"""

from __future__ import annotations

import copy
import difflib
import hashlib
import json
import logging
from pathlib import Path
from typing import Any, Literal, TypeVar

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from .errors import ConfigError, validation_problem

log = logging.getLogger("orca.config")


class StrictModel(BaseModel):
    model_config = ConfigDict(extra="forbid", validate_assignment=True)


SectionT = TypeVar("SectionT", bound=StrictModel)


MAX_DOWNSCALE = 16  # decode.downscale's bound, and that of the factor decode.max_size chooses


class DecodeConfig(StrictModel):
    """How photos become linear, exposure-normalized radiance (``orca decode``; see pipeline/stages/decode.py)."""

    white_balance: Literal["reference"] | tuple[float, float, float] = Field(
        "reference",
        description="'reference': the as-shot white balance of the reference image, applied to every RAW image; "
        "or explicit (R, G, B) multipliers on camera RGB, normalized so G = 1. JPEG/PNG/TIFF are already balanced.",
    )
    reference_image: str | None = Field(
        None, description="file name (or stem) of the reference image (white balance, exposure); default: the first."
    )
    normalize_exposure: bool = Field(
        True,
        description="scale each image by its EXIF exposure (shutter x ISO / f-number^2) relative to the reference.",
    )
    min_images: int = Field(3, ge=1, description="fewer usable photos than this is an error.")
    downscale: int | None = Field(
        None, ge=1, le=MAX_DOWNSCALE, description="integer downscale factor (area averaging) after decoding; default: "
        "the smallest that brings the longest side to max_size or below."
    )
    max_size: int = Field(
        1600, ge=0, description="without a downscale, photos whose longest side is larger are downscaled by the "
        "smallest integer factor that fits (a 24 MP photo: 4x, 1500x1000): SfM, masks and training gain little "
        "from more pixels and the decoded float images would fill memory; 0: full size."
    )
    clip_fraction: float = Field(
        0.98,
        gt=0,
        le=1,
        description="raw values at or above black + clip_fraction x (white - black) count as clipped "
        "(8/16-bit files: at or above this fraction of the maximum code value).",
    )
    clip_dilate_raw: int = Field(
        0, ge=0, le=4, description="RAW: the clipped mask grown by this many raw pixels. Training takes a clipped "
        "pixel as a lower bound, so every pixel flagged beyond the saturated photosites lets a reflected light "
        "bloom: their decoded values are measurements (on the demo within a few percent of the truth in the "
        "median at 2 px, colour-skewed next to a saturated photosite) and 0 fits the lights' edges best "
        "(docs/method.md)",
    )
    demosaic: Literal["AHD", "DHT", "VNG", "PPG", "DCB", "AAHD", "LINEAR"] = Field(
        "AHD", description="LibRaw demosaicing algorithm for RAW files."
    )
    color_space: Literal["srgb", "camera"] = Field(
        "srgb",
        description="'srgb': linear sRGB primaries via the camera's colour matrix; 'camera': white-balanced "
        "camera RGB (no matrix; for diagnostics).",
    )
    black_level: int | None = Field(
        None, ge=0, description="override the RAW files' black level (raw units); default: from each file."
    )
    white_level: int | None = Field(
        None, gt=0, description="override the RAW files' white (saturation) level (raw units); default: from each file."
    )

    @field_validator("white_balance")
    @classmethod
    def _positive_multipliers(cls, v: Any) -> Any:
        if isinstance(v, tuple) and not all(x > 0 for x in v):
            raise ValueError(f"white balance multipliers must be positive, got {v}")
        return v


class PosesConfig(StrictModel):
    """Camera poses and intrinsics (``orca poses``; see pipeline/stages/poses.py)."""

    known_poses: Literal["auto", "ignore"] = Field(
        "auto",
        description="'auto': a capture folder's own cameras.json, transforms.json or poses_bounds.npy (LLFF) "
        "(turntable, phone AR, another SfM run) is used and SfM is skipped; 'ignore': always run SfM.",
    )
    triangulate_known: bool = Field(
        True, description="with known cameras that bring no 3D points (cameras.json, transforms.json, LLFF), match "
        "SIFT features and triangulate sparse points with the cameras held as given: the masks stage seeds the "
        "object and the floor with them, and training's sparse depth holds the room with them (a COLMAP model's "
        "own points are used as they are)",
    )
    known_pairs: int = Field(
        0, ge=0, description="with known cameras, match each photo only with the photos whose views are this many "
        "nearest its own (optical axis and centre), not every pair. 0: match as SfM does (matcher). Faster, but "
        "the points' tracks are shorter and the masks seeded with them worse: on the blowtorch's 67 photos 12 "
        "matched 464 pairs instead of 2211 (triangulation 258 s instead of 491 s, cores shared) and the masks "
        "scored 0.915 / 0.849 instead of 0.933 / 0.855 (bench/results/known_pairs.json).",
    )
    camera_model: Literal["auto", "SIMPLE_PINHOLE", "PINHOLE", "SIMPLE_RADIAL", "RADIAL", "OPENCV"] = Field(
        "auto",
        description="COLMAP camera model. 'auto': the calibration's OPENCV model (held fixed) when the capture has "
        "calibration/calibration.json, else SIMPLE_RADIAL (one focal length, one radial term).",
    )
    refine_calibration: bool = Field(
        False, description="let bundle adjustment refine calibrated intrinsics (normally they are held fixed)."
    )
    exif_focal: Literal["start", "prior"] = Field(
        "start", description="what the EXIF 35 mm focal length is to COLMAP. 'start': the lens's focal length "
        "starts there and is estimated like an unknown one (two-view geometries as fundamental matrices); 'prior': "
        "COLMAP takes it as known (essential matrices with it). EXIF gives the 35 mm focal length in whole "
        "millimetres, a few per cent off: as a prior that costs accuracy. Measured (bench/results/"
        "poses_exif_focal.json): the blowtorch 0.30 -> 0.19 degrees median from the photographers' cameras (max 2.4 "
        "-> 1.5), the synthetic family's 7 registered scenes 0.077 -> 0.053 median of medians (6 of 7 better). A "
        "calibration is always a prior.",
    )
    matcher: Literal["auto", "exhaustive", "sequential"] = Field(
        "auto",
        description="'exhaustive': every pair; 'sequential': each photo with its neighbours in file-name order "
        "(wrapping around, as a capture circles the object); 'auto': exhaustive up to exhaustive_max_images.",
    )
    exhaustive_max_images: int = Field(
        100, ge=2, description="'auto' matches exhaustively up to this many photos (a walk-around in rings is not in "
        "name order across rings: on 67 real photos in four rings, sequential matching verified 128 pairs, exhaustive "
        "205, the second model registering twice the photos)."
    )
    mapper: Literal["auto", "incremental", "global"] = Field(
        "auto",
        description="'incremental': COLMAP's incremental mapper; 'global': GLOMAP's global mapper (every photo placed "
        "at once: one model where weak overlap splits the incremental one); 'auto': incremental, and when it leaves "
        "photos out (a split, photos not registered), the global mapper on the same matches, continued by the "
        "incremental one, kept if it registers more (both then go through the pose checks).",
    )
    object_points: Literal["drop", "keep"] = Field(
        "keep", description="'keep': the cameras as SfM adjusted them, on every point; 'drop': after SfM, the "
        "sparse points inside the object's sphere are left out and the cameras bundle-adjusted again on the "
        "surroundings alone (not done when object masks hid the object from SfM already). A real object's own "
        "texture holds its photos together where reflections pull them apart: on the blowtorch, 'drop' moved the "
        "cameras 0.53 -> 0.80 degrees from the photographers' (bench/results/poses_object_points.json); on an "
        "untextured glossy object it gains up to 0.03 degrees."
    )
    object_points_max_share: float = Field(
        0.3, gt=0, le=1, description="...unless the sphere holds more than this share of the points (then it is not "
        "trusted)."
    )
    global_min_observations: int = Field(
        30, ge=0, description="the global mapper's photos supported by fewer of its 3D points than this get no "
        "camera (the incremental mapper's own bar for registering a photo)."
    )
    sequential_overlap: int = Field(
        12, ge=1, description="'sequential': neighbours on each side, plus photos 2^k apart (loop closure)."
    )
    relaxed_min_inliers: int = Field(
        15, ge=0, description="photos still without a camera after mapping are registered again with the absolute "
        "pose needing this many inlier 2D-3D matches (COLMAP's bar: 30): in a sparse walk-around a photo verified "
        "with its neighbours may see too few of the model's 3D points for it (the blowtorch: 50 -> 55 of 67 photos, "
        "the 5 new ones 0.5-2.5 degrees from the photographers' poses). The pose checks judge them like any other; "
        "0: no second pass."
    )
    relaxed_min_inlier_ratio: float = Field(
        0.1, gt=0, le=1, description="...and this share of its 2D-3D matches as inliers (COLMAP's bar: 0.25)."
    )
    relaxed_min_model: int = Field(
        10, ge=2, description="the relaxed pass extends only a model of at least this many photos (or half the "
        "photos, when fewer): a model of a few photos has few, poorly triangulated points and a lens fitted to "
        "them, and photos registered against it on 15 matches follow it wherever it is wrong (a 2-photo model of a "
        "plain room grew to 9 photos 5.7 degrees off the truth, its focal length 20 times the EXIF one). COLMAP "
        "itself keeps no model under 10 photos by default."
    )
    max_image_size: int = Field(
        1600, ge=0, description="SIFT runs on images downscaled to this longest side (0: full size)."
    )
    sift_brightness: float = Field(
        0.0, ge=0, lt=1, description="SIFT sees each photo in grey, brightened so that its median is at least this "
        "(0..1, e.g. 0.45): photos exposure normalization made darker by stops keep their features. 0: the decoded "
        "photos as they are (the default: 0.45 helped the blowtorch slightly and was mixed on the synthetic suite; "
        "bench/results/front_end.jsonl, blowtorch.jsonl)."
    )
    max_num_features: int = Field(8192, ge=64, description="SIFT features kept per image.")
    sift_affine_shape: bool = Field(
        True, description="SfM's SIFT estimates each feature's affine shape (COLMAP's estimate_affine_shape): "
        "features that survive the viewpoint changes of a sparse walk-around (the blowtorch: 55 -> 59 of 67 photos "
        "registered, 0.54 -> 0.30 degrees from the photographers' cameras). Known cameras' points keep plain SIFT: "
        "the masks seeded with them were better on the synthetic family (bench/results/sift_affine_shape.json). CPU "
        "SIFT only."
    )
    sift_domain_size_pooling: bool = Field(
        False, description="DSP-SIFT: descriptors pooled over several scales (COLMAP's domain_size_pooling). CPU "
        "SIFT only; about twice the extraction time."
    )
    sift_peak_threshold: float = Field(
        0.02 / 3, gt=0, description="SIFT's contrast threshold on difference-of-Gaussian peaks (COLMAP's default "
        "0.02 / octave_resolution): lower finds features in fainter texture, a plain wall's or floor's."
    )
    min_features: int = Field(
        50, ge=1, description="an image with fewer SIFT features than this counts as featureless."
    )
    min_registered: int = Field(3, ge=2, description="fewer registered photos than this is an error.")
    min_registered_fraction: float = Field(
        0.5, gt=0, le=1, description="registering a smaller fraction of the photos than this is an error; above "
        "it the photos left out are named with the reason (poses_report.json not_registered_why) and the run goes "
        "on without them (a real walk-around often loses a few: the blowtorch's 67 photos register 50)."
    )
    use_masks: bool = Field(
        True,
        description="with object masks (CAPTURE/masks/<name>.png or --masks; white = object), ignore features on "
        "the glossy object (reflections move with the viewpoint) and take the object's sphere from the masks.",
    )
    mask_dilate_px: int = Field(4, ge=0, description="grow the object masks by this much before ignoring features.")
    object_window: float = Field(
        0.6,
        gt=0,
        le=1,
        description="the object is assumed to lie inside this central fraction of every photo (width and height); "
        "sparse points seen there from nearly all cameras are the object's (for its radius).",
    )
    radius_margin: float = Field(1.1, ge=1, description="the object's radius estimate is enlarged by this factor.")
    undistort_threshold_px: float = Field(
        0.5,
        ge=0,
        description="images are resampled to a pinhole camera only if the lens distortion moves some pixel by more "
        "than this; below it, cameras.json points at the decoded images with the model's pinhole part (SIMPLE_RADIAL "
        "fitted to a distortion-free synthetic capture moves corners by 0.1-0.4 px: noise of the fit).",
    )
    num_threads: int = Field(0, ge=0, description="CPU threads for pycolmap (0: all cores).")
    seed: int = Field(0, ge=0, description="random seed of RANSAC and the mapper.")
    keep_database: bool = Field(False, description="keep COLMAP's database.db (features, matches) in the output.")
    on_suspect: Literal["warn", "drop", "error"] = Field(
        "drop",
        description="photos the pose checks doubt (pipeline/pose_checks.py: path jumps, axes that miss the object) "
        "after the retry: 'drop' gives them no camera (a few photos fewer cost little; one wrong pose corrupts the "
        "object and the environment field trained on it), 'warn' keeps them, 'error' stops the stage.",
    )
    jump_ratio: float = Field(
        4.0, gt=1, description="a step between consecutive photos (capture order) longer than this times the median "
        "step is a jump when the two share many matches (hand-held spacing varies up to ~3x; wrong poses on "
        "repetitive textures jumped 9-16x)."
    )
    jump_min_match_share: float = Field(
        0.3, ge=0, le=1, description="two consecutive photos look alike (a long step between them is a jump, not "
        "photos missing from the capture) when they share at least this share of the median verified matches of "
        "consecutive photos."
    )
    axis_miss_mads: float = Field(
        5.0, gt=0, description="a camera's axis misses the others' convergence point suspiciously when it is more "
        "than this many MADs (as standard deviations) above the median miss, and outside object_window."
    )
    distance_ratio: float = Field(
        4.0, gt=1, description="a camera farther from the object than this times the cameras' median distance is "
        "doubted (a walk-around keeps its distance within ~2x; a weak view graph lets the global mapper put a "
        "camera far behind the others along its line of sight)."
    )
    min_support_points: int = Field(
        15, ge=0, description="a registered photo in which fewer of the final model's 3D points are seen is doubted: "
        "its camera rests on too little (the relaxed pass's own bar for registering one; 0: no check)."
    )
    focal_warn_ratio: float = Field(
        1.25, gt=1, description="warn when a camera's fitted focal length differs from its EXIF (or calibration) prior "
        "by more than this factor either way: the right models measured stay within 1.07 (the blowtorch's lens "
        "against its EXIF), partial models of plain rooms were 1.4-1.6 off and a degenerate one 20x. A warning, not "
        "a doubt: photos cropped after they were taken keep their EXIF and are as far off with a right model (a 3:2 "
        "photo cropped square: 1.5; a crop to the object a third as wide: 3)."
    )
    up_max_deg: float = Field(
        10.0, gt=0, le=90, description="warn when the plane under the object (RANSAC on the sparse points) is tilted "
        "by more than this from the cameras' mean up (the masks stage searches the support plane within 10 degrees "
        "of it)."
    )
    mapping_runs: int = Field(
        3, ge=1, le=5, description="map the matches up to this many times (seeds seed, seed+1, ...): a second run "
        "always, each further one only while every run so far has cameras turned by more than mapping_max_deg against "
        "all the others. The run with the most cameras not so turned is kept, and its turned ones are doubted. Where "
        "a part of the capture hangs on a few weak or look-alike pairs the mapper places it differently from run to "
        "run (on the blowtorch 2 of 46 runs turned its lowest ring 16-38 degrees round the object, unseen by the other "
        "checks). 1: one run, no such check. A run costs the mapping time again, not features or matching (the "
        "blowtorch's 67 photos: 33 s on 2 cores)."
    )
    mapping_max_deg: float = Field(
        10.0, gt=0, description="a camera turned by more than this between the kept mapper run and every other run "
        "is doubted (the blowtorch's 31 runs that agree differ by 5.1 degrees at most on its weakest photos, 0.0-0.3 "
        "median; the wrong placements measured were 16-38 off)."
    )
    retry_matching: bool = Field(
        True, description="when photos are doubted, run SfM again matching only neighbours in capture order with a "
        "stricter two-view verification, and keep the run with more undoubted photos."
    )
    retry_overlap: int = Field(5, ge=1, description="retry: neighbours on each side in capture order matched.")
    retry_min_inliers: int = Field(
        30, ge=15, description="retry: verified matches a pair of photos needs (COLMAP's default is 15)."
    )
    retry_max_error_px: float = Field(
        2.0, gt=0, description="retry: RANSAC's largest epipolar error in pixels (COLMAP's default is 4)."
    )


class MasksConfig(StrictModel):
    """Object masks (``orca masks``; see pipeline/stages/masks.py, the method in pipeline/masking/)."""

    user_masks: Literal["auto", "ignore"] = Field(
        "auto",
        description="'auto': masks in CAPTURE/masks (or --user-masks) replace the automatic ones for the views they "
        "cover (all views, or corrections for a few); 'ignore': always automatic.",
    )
    user_mask_min_fraction: float = Field(
        0.001, ge=0, lt=1, description="a user mask covering less of its image than this (empty, or a stray brush "
        "stroke) stops the stage naming the file: one empty view cuts the object out of the visual hull; 0: accept "
        "empty masks (the object is really out of those photos; masks that are all empty are always refused)"
    )
    work_size: int = Field(
        480, ge=64, description="segmentation runs on images reduced to this longest side (masks are written at "
        "full size, their outline snapped to the photo's edges)"
    )
    workers: int = Field(
        0, ge=0, description="processes that segment views side by side (0: one per core this process may use; 1: "
        "no worker processes). The masks are the same for any count; each worker holds a few views in memory"
    )
    rounds: int = Field(3, ge=1, description="rounds of visual-hull carving <-> per-view GrabCut")
    grabcut_iterations: int = Field(4, ge=1, description="GrabCut's own iterations per view and round")
    hull_resolution: int = Field(128, ge=16, le=512, description="voxels along each side of the unit sphere's cube")
    carve_share: float = Field(
        0.2, ge=0, le=1, description="a voxel leaves the visual hull when this share of the views see it off the "
        "object (robust to a few wrong masks; a smaller share: tighter around thin parts, less robust)"
    )
    carve_votes: int = Field(3, ge=1, description="...and at least this many views (1: the classic visual hull)")
    core_carve_share: float | None = Field(
        0.15, ge=0, le=1, description="GrabCut's certain object (the hull's core) is cut from a tighter hull, where "
        "this share of the views is enough to cut a voxel; what the hull keeps beyond it is "
        "probable object, for colour to decide. A wedge of floor or wall that only a few views see past (between a "
        "handle and a tank) is then not forced as object (the blowtorch 0.902/0.839 -> 0.935/0.853, median/worst "
        "view), but a glossy rim that colour loses in the views that see it edge-on is forced less often (the "
        "synthetic family's worst views -0.02..+0.00, docs/masks.md). None: the hull's own core"
    )
    core_carve_votes: int = Field(
        6, ge=1, description="...and at least this many views: a glossy rim is lost by colour in the handful of "
        "views that see it edge-on, and those must not cut it from the core (a capture of up to 32 views keeps its "
        "hull's core)"
    )
    contact_height: float | None = Field(
        0.05, gt=0, lt=1, description="in the last round, the hull's pixels whose ray enters it at most this far "
        "above the support plane (sphere radii), unless dark, are certain object up to the hull's outline: a glossy "
        "object's bottom rim mirrors the floor beside it and colour gives it to the floor (the blowtorch's tank: "
        "after our SfM 0.896/0.817 -> 0.899/0.819 median/worst view, with the reference cameras 0.935/0.853 -> "
        "0.935/0.863; docs/masks.md); a dark contact shadow the hull still holds is left to colour. None: off"
    )
    stand_height: float = Field(
        0.0, ge=0, lt=1, description="every round's hull stands on the support plane where it comes this close to "
        "it (sphere radii; at least a voxel, which is the default): each voxel below that height takes the fewest "
        "background votes of its column up to it, and the hull is cut at the plane itself. Carved alone, the hull "
        "stopped at its lowest voxel centres, short of the plane by a band along every view's bottom outline "
        "(docs/masks.md). Higher (0.03) also stands a glossy rim that mirrors the floor on it, but gives rounded "
        "bottoms a skirt"
    )
    core_fraction: float = Field(
        0.4, ge=0, lt=1, description="in every round but the last, GrabCut takes as certain object only the part of "
        "the hull's reprojection farther from its outline than this share of its deepest pixel's distance; the "
        "rest is probable object, for colour to decide. Forced, a hull fattened by loose first masks keeps its "
        "wedges of floor and wall in every round (the blowtorch: median IoU 0.795 at 0, 0.850 at 0.2, 0.887 at "
        "0.4, 0.922 at 0.6, where a glossy rim that mirrors the room is lost in the synthetic family). The last "
        "round's share is final_core_fraction; 0: every round forces the whole core"
    )
    final_core_fraction: float = Field(
        0.0, ge=0, lt=1, description="core_fraction in the last round (0: the whole core but a 3 px rim is forced, "
        "so a glossy rim that mirrors the room stays; higher: colour trims more of a hull that a ring of low "
        "views leaves fat beside the object)"
    )
    core_colour_log_odds: float | None = Field(
        3.0, gt=0, description="a pixel GrabCut would take as certain object (the hull's core, sparse points, "
        "highlights) is only probable background where its colour is this much likelier (natural log of the odds, "
        "averaged over a disc of colour_open_px) among the certain background within colour_ring_px of the object "
        "than in the hull's deep core (deeper than core_fraction): a wedge of floor or wall that few views see past "
        "is coloured like the room beside it, a mirror's rim mostly like the rest of the mirror "
        "(pipeline.masking.colour; the blowtorch 0.897/0.818 -> 0.902/0.839, the random family's worst views the "
        "same or better but one, docs/masks.md). None: off"
    )
    colour_bins: int = Field(8, ge=2, le=64, description="...colour histograms with this many bins per channel")
    colour_ring_px: int = Field(20, ge=1, description="...the background sample's reach around the object (work px)")
    colour_min_pixels: int = Field(50, ge=1, description="...no release where either sample is smaller than this")
    colour_open_px: int = Field(
        2, ge=0, description="...only released pieces wider than a disc of this radius: a glossy rim shows the room "
        "beside it in a thin band (without: the blowtorch 0.915/0.862, but a floating torus's rim lost, worst view "
        "0.873 -> 0.838)"
    )
    trim_colour_log_odds: float | None = Field(
        1.5, gt=0, description="the final masks lose the pieces (wider than a disc of colour_open_px) that some view "
        "sees past along the whole of their ray's way through the hull (trim_seen_through_votes) and whose colour "
        "is this much likelier (natural log of the odds, trim_colour_bins per channel) in the room right around "
        "this view's mask than in every view's mask core: a gap between the object's parts that too few views see "
        "through to carve shows what this view shows beside the object (pipeline.masking.colour.trim_room_colours; "
        "docs/masks.md). Not in the sphere prior's probes. None: off"
    )
    trim_capture_log_odds: float = Field(
        0.0, description="...and only where the colour is also this much likelier in the room around every view's "
        "mask than in their cores: a part coloured like the room behind it in one photo (a dark burner against dark "
        "wood) has the object's colours over the capture. 0: at least as common in the room as on the object"
    )
    trim_colour_bins: int = Field(16, ge=2, le=64, description="...colour histograms with this many bins per channel")
    restore_colour_log_odds: float | None = Field(
        0.0, description="then the final masks get back the pieces of the hull they left out (wider than a disc of "
        "restore_piece_px, not certain background) whose ray crosses a voxel that fewer than "
        "restore_seen_through_votes see past, where their colour is not this much likelier (natural log of the "
        "odds, trim_colour_bins per channel) in the room around this view's mask than in every view's mask core: "
        "a view's colours lose a white mug's shadowed side on its dark shadow, while hardly any other view sees "
        "past it (pipeline.masking.colour.restore_object_colours; docs/masks.md). None: off"
    )
    restore_seen_through_votes: float = Field(
        3.25, gt=0, description="...a piece is restored where its ray crosses a voxel with fewer background votes "
        "than this (3.25: at most three views'). Higher: more of the hull comes back, the room in gaps few views "
        "see through as well"
    )
    restore_piece_px: int = Field(
        1, ge=0, description="...only pieces wider than a disc of this radius: the band along the outline is the "
        "view's colours' to decide (final_reach_px)"
    )
    outline_reach_px: int = Field(
        2, ge=0, description="last, each pixel on either side of a mask's outline goes to the side that covers most "
        "of it: its colour read as a mix (in linear light) of the sure object's and the sure background's within "
        "this many pixels (pipeline.masking.outline; GrabCut's cut falls on either side of a mixed pixel, most of a "
        "small object's error at 320x240). 0: off"
    )
    outline_contrast: float = Field(
        0.1, ge=0, description="...only where the two colours differ by at least this (linear, RMS over the channels)"
    )
    outline_margin: float = Field(
        0.1, ge=0, lt=0.5, description="...and the pixel's share of the object's colour is beyond one half by this"
    )
    outline_residual: float = Field(
        0.5, gt=0, description="...and the pixel's colour lies within this share of the two colours' difference of "
        "the line between them (a highlight, texture or a shaded rim is no mix of the two)"
    )
    trim_seen_through_votes: float = Field(
        0.75, gt=0, description="...a pixel may be trimmed where every voxel its ray crosses in the hull has at "
        "least this many background votes (0.75: one view's, not a dark pixel's doubtful half vote). Higher: "
        "fewer pixels; unrestricted, a dark glossy blob's rims, which mirror the room, went (worst view 0.962 -> "
        "0.874)"
    )
    snap_band_px: float = Field(
        2.0, ge=0, description="photos larger than the working size: the mask's outline, brought up to the photo's "
        "size, is moved onto the photo's edges within this many working pixels of it (GrabCut at full size in that "
        "band; pipeline.masking.scale.snap_to_edges). The blowtorch's 1060x707 photos through the stage: IoU 0.924 / "
        "0.848 -> 0.947 / 0.866 (median / worst view; docs/masks.md). 0: off"
    )
    snap_iterations: int = Field(2, ge=1, description="...GrabCut's own iterations there")
    snap_min_edge_gain: float = Field(
        1.5, ge=0, description="...kept only where the snapped outline's median image gradient is at least this "
        "many times the outline's before (a glossy rim mirroring the room has its strongest edge inside the object)"
    )
    snap_min_core: float = Field(
        0.8, ge=0, le=1, description="...and only where at least this share of the mask lies farther than the band "
        "from its outline (a small or thin object's colour model would be mostly band)"
    )
    seed_radius: float = Field(
        0.3, ge=0, lt=1, description="before any hull, the central part of the unit sphere's image (this fraction of "
        "its radius) is taken as object: the cameras converge on it (of the first sphere's radius when the "
        "sphere prior grows)"
    )
    unexplained_vote: float = Field(
        1.0, ge=0, le=1, description="a background vote counts this much where no background explains the pixel (the "
        "support plane clearly does not, no surface outside the sphere does): something in the sphere is seen "
        "there, like a mirror-like neck that reflects the room and that colour loses in every view. 1: off (the "
        "default; 0 keeps such parts, but also a prop, a table or a contact shadow the support plane does not "
        "explain)"
    )
    unexplained_retry_share: float = Field(
        0.4, ge=0, description="when the masks leave out, in the median view, unexplained pixels touching them (see "
        "unexplained_vote) amounting to more than this share of the mask's area, the rounds run again with "
        "unexplained_vote 0 and the report says so: a part lost alike in every view (a mirror-like neck, paint "
        "coloured like the room) leaves such pixels beside every mask. 0: never"
    )
    unexplained_max_rate: float = Field(
        0.4, ge=0, le=1, description="unexplained pixels count (unexplained_vote) only in a capture whose likely "
        "background (the sphere's image outside the first masks) is unexplained in at most this share of its "
        "pixels, median view: elsewhere (a real carpet's weave matches no plane by colour) they mean nothing"
    )
    doubtful_vote: float = Field(
        0.5, ge=0, le=1, description="a background vote counts this much where the view's pixel is dark (see "
        "dark_level) and no evidence (outside the sphere, floor, depth sweep) confirms it: a dark object bottom on "
        "its dark contact shadow is lost by colour in the views from above; the views that see it against a lit "
        "background keep it (1: every vote counts fully)"
    )
    confirmed_vote: float = Field(
        3.0, ge=1, description="a background vote counts this much where the depth sweep explains the pixel by a "
        "surface behind the sphere (the ray passes the object empty): a gap between the object's parts that a few "
        "views see the room through is carved by fewer views than carve_share (see docs/masks.md)"
    )
    colour_vote_odds: float | None = Field(
        1.0, gt=0, description="in the rounds' carves, a background vote from a thin piece a view's GrabCut cut off "
        "the hull (see colour_vote_thin_px) counts its colour's log odds of background over object (GrabCut's own "
        "colour models) over this, clipped to [0, 1]: GrabCut's smoothness joins a thin part coloured like the "
        "object (a vase's neck, a wire stand) to the background, and carved in every round the hull loses it "
        "(null: every vote counts)"
    )
    colour_vote_thin_px: int = Field(
        3, ge=0, description="colour_vote_odds weighs only the pieces GrabCut cut off the hull that a disc of this "
        "radius does not fit in: a wide piece is a gap of room the hull kept (between a handle and a tank), whose "
        "colour the object's model, learned from that hull, also holds (0: every piece)"
    )
    dark_level: int = Field(
        48, ge=0, le=255, description="pixels whose brightest sRGB channel is at most this are dark (doubtful_vote)"
    )
    final_reach_px: int = Field(
        1, ge=-1, description="a view's final mask is the visual hull's reprojection within this many pixels of the "
        "view's own GrabCut mask (the hull keeps what one view's colours lose inside, the view's colours trim the "
        "hull's overhang at the outline); -1: the hull's reprojection less certain background and the pieces "
        "GrabCut gave to a prop in front"
    )
    final_max_core_lost: float = Field(
        0.15, ge=0, le=1, description="a view whose last GrabCut mask gave more than this share of the hull's core "
        "(its reprojection eroded by core_erode_px) to the background gets the hull's reprojection less certain "
        "background: its colours failed (a shadowed side lost to a dark floor), the views agree on the hull; "
        "1: never"
    )
    neighbours: int = Field(6, ge=1, description="views compared with each view (support-plane test)")
    neighbour_max_deg: float = Field(60.0, gt=0, le=180, description="...at most this far around the object")
    consistency_rank: int = Field(
        3, ge=1, description="a pixel is explained by a surface when this many neighbours agree (occlusion-robust)"
    )
    floor: bool = Field(True, description="find the support plane and take the floor around the object as background")
    match_exposure: bool = Field(
        False, description="before comparing two photos for photo-consistency (support plane, depth sweeps), bring "
        "one to the other's exposure and white balance by per-channel gains (the ratio of their medians where they "
        "overlap): photos of one capture often differ by stops and in tint. Off by default: on the blowtorch's fine "
        "carpet it finds a support plane at the wrong height (docs/masks.md)"
    )
    floor_threshold: float = Field(
        0.03, gt=0, lt=1, description="mean absolute sRGB difference (0..1, 5x5 box) under which the plane explains "
        "a pixel"
    )
    floor_shift: float = Field(
        0.3, ge=0, description="a floor pixel must match at the support plane's height only: the plane moved this "
        "far down (sphere radii) must explain it worse (flat patches, on the object or the floor, match at any "
        "height and are no evidence); 0: no such test"
    )
    floor_margin: float = Field(
        0.03, ge=0, lt=1, description="by at least this much (as floor_threshold)"
    )
    floor_measure: Literal["sad", "zncc", "both"] = Field(
        "sad", description="how the support plane's photo-consistency is measured: 'sad', the mean absolute sRGB "
        "difference (floor_threshold, floor_margin); 'zncc', one minus the normalized cross-correlation of the grey "
        "images (zncc_*): blind to exposure and white balance, and it tells a fine texture's match from a near miss "
        "(a carpet's weave), but a plain floor or a shadow gives it no evidence; 'both': floor where either finds it"
    )
    zncc_window: int = Field(7, ge=3, description="'zncc': the window's side in pixels at work_size")
    zncc_min_std: float = Field(
        2.0, ge=0, description="'zncc': windows flatter than this (grey levels, 0..255) are no evidence"
    )
    zncc_floor_threshold: float = Field(0.5, gt=0, lt=2, description="'zncc': as floor_threshold (0..2)")
    zncc_floor_margin: float = Field(0.3, ge=0, lt=2, description="'zncc': as floor_margin")
    zncc_not_floor_threshold: float = Field(
        0.8, gt=0, lt=2, description="'zncc': a textured pixel costing more is not the floor (seeds the first masks)"
    )
    sweep: bool = Field(
        True, description="sweep depths outside the unit sphere: props in front of the object and the room behind it "
        "that match across views are background"
    )
    sweep_neighbours: int = Field(3, ge=1, description="nearest views compared in the depth sweep")
    sweep_rank: int = Field(2, ge=1, description="how many of them must agree")
    sweep_threshold: float = Field(0.04, gt=0, lt=1, description="as floor_threshold, for the depth sweep")
    sweep_step_px: float = Field(
        1.0, gt=0, le=8, description="the depth sweep's planes are this far apart in disparity (pixels) in the "
        "farthest neighbour: the sweep's time goes as its inverse"
    )
    sweep_near: float = Field(
        0.25, gt=0, lt=1, description="the depth sweep starts this far from the camera (a share of its distance "
        "from the object's centre): a prop nearer the camera gives no evidence there. From 0.25, half the planes lie "
        "nearer than half the distance and change at most 4 of 15,000-74,000 swept pixels per capture, but starting "
        "at 0.5 moves the other planes a fraction of a pixel and lowered the synthetic suite's figures a little "
        "(bench/results/masks_sweep_near.json)"
    )
    texture_threshold: float = Field(
        0.05, ge=0, description="the depth sweep counts only patches with at least this sRGB standard deviation "
        "(flat patches match at any depth)"
    )
    front_sweep: bool = Field(
        True, description="from the second round, sweep planes parallel to the floor between each camera and the "
        "visual hull: the top of a prop standing in front of the object inside the unit sphere (which the hull "
        "covers), and its side under it, are background (~1 s per view and round at 320x240 on a CPU core)"
    )
    through_floor: bool = Field(
        True, description="from the second round, pixels inside the visual hull's image that the support plane "
        "explains in any other view are certain background: the floor seen through a hole or under an overhang, "
        "which the hull fills when few views see through it"
    )
    through_reach_px: int = Field(
        20, ge=0, description="...and the hull is not forced as object within this many pixels (at work_size) of "
        "them: GrabCut decides the rest of the hole by colour"
    )
    through_views: int = Field(
        40, ge=1, description="...compared with at most this many other views, spread around the object (the test "
        "costs this many image warps per view and round; with more photos, a subset on every side)"
    )
    prior_growth: float = Field(
        1.5, gt=1, description="when the probe's masks reach the poses stage's sphere's outline in many views (the "
        "object is larger than that sphere and cut by it), the sphere is re-centred on the probe's hull and grown by "
        "this, and probed again (pipeline.masking.prior)"
    )
    prior_max_growth: float = Field(
        3.0, ge=1, description="...up to this many times the poses stage's radius (1: the poses stage's sphere as is)"
    )
    prior_touch_share: float = Field(
        0.1, ge=0, le=1, description="...'many views': more than this share of them (low: a part leaving the sphere "
        "towards or away from a camera ends inside the sphere's image, so only the views that see it leave at the "
        "outline count)"
    )
    tracks: bool = Field(
        True, description="seed the masks with the poses stage's sparse points: in each photo that observed a point, "
        "one on the plane fitted to them or far outside the object's sphere is certain background and one clearly "
        "above that plane inside the sphere certain object (pipeline.masking.tracks)"
    )
    track_plane_tolerance: float = Field(
        0.02, gt=0, lt=1, description="...points this close to the plane fitted to them (share of their median "
        "distance from the object's centre) are on it"
    )
    track_seed_px: int = Field(1, ge=0, description="...each point seeds a square of 2n+1 pixels at work_size")
    track_far: float = Field(
        3.0, gt=1, description="...points farther than this many radii of the object's sphere are the room (closer "
        "ones outside it may be the object reaching past a sphere still to grow: no evidence)"
    )
    support_plane_from: Literal["photos", "photos_or_points", "points"] = Field(
        "photos_or_points", description="the floor cue's support plane: the photo-consistency search's ('photos'), "
        "the plane fitted to the sparse points where that search finds none ('photos_or_points': the real "
        "blowtorch's carpet, whose weave matches too little across views, IoU median/worst 0.887/0.808 -> "
        "0.897/0.818; no scene of the random family lacks a photo plane and has a points plane), or always the "
        "points' ('points': mixed on the family, the textured vase -0.12; docs/masks.md)"
    )
    sphere_margin: float = Field(1.05, ge=1, description="the object's refined bounding sphere is enlarged by this")
    renormalize: bool = Field(
        True, description="write cameras.json in the frame where the refined sphere is the unit sphere (tight "
        "training bounds); otherwise a copy of the poses frame"
    )
    agreement_warning: float = Field(
        0.85, ge=0, le=1, description="warn about views whose mask and the hull's reprojection agree less (IoU)"
    )
    overlay_size: int = Field(640, ge=64, description="longest side of the QA overlays")


class LossConfig(StrictModel):
    """Weights of the training losses (see orca/model.py)."""

    photometric: float = Field(1.0, ge=0)
    mask: float = Field(0.1, ge=0)
    eikonal: float = Field(0.1, ge=0)
    orientation: float = Field(1e-3, ge=0)
    distortion: float = Field(1e-3, ge=0)
    background: float = Field(
        0.1, ge=0, description="background pixels supervise the environment field (beyond the paper); weighed low "
        "so the reflections, the only view of the props' inner sides, are not drowned out (docs/method.md)"
    )
    free_space: float = Field(
        0.0, ge=0, description="the environment's opacity between each camera and the object along object rays, "
        "where a mask says nothing occludes the object (beyond the paper; docs/method.md)"
    )
    clipped_excess: float = Field(
        0.1, ge=0, le=1, description="clipped (saturated) pixels bound the prediction from below; above, this weak "
        "pull toward the recorded value keeps a light of unrecorded brightness from blooming past its edges"
    )
    sparse_depth: float = Field(
        0.1, ge=0, description="rays through the poses stage's sparse points of the surroundings end there "
        "(only with `orca train --points`, which the Snakefile passes; beyond the paper; docs/method.md)"
    )
    sparse_depth_band: float = Field(0.03, gt=0, lt=1, description="... within this share of the point's distance")
    smoothness: float = Field(0.1, ge=0, description="normals at the surface vs a small random step away")
    smoothness_step: float = Field(0.01, gt=0, description="that step's standard deviation (object radii)")
    appearance: float = Field(
        0.01, ge=0, description="each photo's learned exposure and white balance (train.appearance) pulled toward "
        "the photos' average: keeps the gains of photos that show little from drifting"
    )


class HashGridConfig(StrictModel):
    """A multiresolution hash grid (``orca.encoding.HashGridSpec``); these defaults are the SDF's."""

    levels: int = Field(12, ge=1)
    log2_table_size: int = Field(16, ge=8, le=24)
    max_resolution: int = Field(1024, ge=16)


class TextureGridConfig(HashGridConfig):
    """The diffuse head's own hash grid: texture detail that need not come from the SDF's grid."""

    levels: int = Field(12, ge=0, description="0: none (the diffuse colour from the SDF's features, as the paper)")
    log2_table_size: int = Field(17, ge=8, le=24)
    max_resolution: int = Field(2048, ge=16)


class EnvironmentGridConfig(HashGridConfig):
    """The environment field's hash grid (over the contracted space)."""

    log2_table_size: int = Field(17, ge=8, le=24)


class SDFConfig(StrictModel):
    """The object's SDF field (``orca.fields.SDFFieldSpec``) and the schedules of its grid and its density's β
    (``orca.model.ModelSpec``)."""

    encoding: Literal["hashgrid", "frequency"] = "hashgrid"
    hidden: int = Field(64, ge=8)
    layers: int = Field(2, ge=1)
    init_radius: float = Field(0.7, gt=0, description="the SDF starts as a sphere of this radius (init: sphere)")
    init: Literal["sphere", "hull"] = Field(
        "hull", description="the SDF's start: the masks' visual hull (the photos' silhouettes carved into a voxel "
        "grid, its signed distance fitted by the SDF before the first step), which has the holes, handles and "
        "necks a sphere lacks (bench/shapes.py: normals better on all four of the family's shapes), or a sphere "
        "of init_radius"
    )
    hull_resolution: int = Field(64, ge=8, le=256, description="voxels per side of the visual hull's grid")
    hull_carve_share: float = Field(
        0.1, gt=0, le=1, description="a voxel leaves the visual hull when this share of the photos that see it (and "
        "at least 2) see it off the object's mask: a few wrong masks (a prop in front, a rim missed) do not cut "
        "the object (docs/method.md)"
    )
    hull_smoothing: float = Field(
        1.0, ge=0, description="the hull's signed distance is blurred by this many voxels (its facets and steps "
        "would become bumps)"
    )
    hull_floor_clearance: float = Field(
        0.02, ge=0, description="the hull is cut this far (in the object sphere's radii) below the support plane the "
        "masks stage found (masks_report.json): no photo sees under an object standing on it, so the masks keep "
        "that space; the clearance is the plane's uncertainty (the blowtorch's carpet: +-0.02 of the masks' sphere)"
    )
    hull_fit_steps: int = Field(300, ge=1, description="steps of fitting the SDF to the visual hull")
    hull_fit_batch: int = Field(8192, ge=64, description="points per step of that fit")
    hash_grid: HashGridConfig = Field(default_factory=HashGridConfig)
    texture_grid: TextureGridConfig = Field(default_factory=TextureGridConfig)
    reflectance: Literal["dielectric", "tinted"] = Field(
        "dielectric", description="the surface's reflections: dielectric, a clear coat's (glazed ceramic, plastic, "
        "paint, glass: a few percent of the light, colourless; Fresnel at render.ior), or tinted, a colour learned "
        "per surface point (metals: brass, copper, gold, steel, chrome reflect most of the light in their own "
        "colour; Schlick's Fresnel starting from render.ior's)"
    )
    levels_start: int = Field(4, ge=1, description="coarse-to-fine: hash-grid levels active at the start")
    levels_full: float = Field(0.3, ge=0, le=1, description="fraction of training after which all levels are active")
    beta_init: float = Field(0.05, gt=0, description="VolSDF's β (the density's sharpness) at the start")
    beta_final: float = Field(0.005, gt=0, description="β is capped by a schedule from beta_init to this")
    beta_anneal: float = Field(0.5, ge=0, le=1, description="fraction of training at which the cap reaches beta_final")


class EnvironmentConfig(StrictModel):
    """The 5D environment field (``orca.fields.EnvironmentFieldSpec``)."""

    encoding: Literal["hashgrid", "ipe", "direction"] = Field(
        "hashgrid", description="'direction': the 2D environment map ablation (radiance from direction only)"
    )
    hidden: int = Field(64, ge=8)
    layers: int = Field(2, ge=1)
    hash_grid: EnvironmentGridConfig = Field(default_factory=EnvironmentGridConfig)
    dir_freqs: int = Field(
        2, ge=0, le=8, description="frequencies of the view direction in the environment's radiance (0: none)"
    )
    contract_radius: float = Field(
        3.0, gt=0, description="the environment's contraction is the identity inside this radius (object radii)"
    )
    density_bias: float = Field(
        -3.0, description="added to the environment field's density before softplus: how empty it starts"
    )


class RenderConfig(StrictModel):
    """Samples along primary rays and virtual cones (``orca.render.RenderSpec``)."""

    object_radius: float = Field(
        1.2, gt=0, description="primary rays are sampled inside this sphere, which the SDF's grid covers (the object "
        "is in the unit sphere)"
    )
    n_coarse: int = Field(48, ge=4)
    n_fine: int = Field(32, ge=0)
    upsample_steps: int = Field(4, ge=1, description="rounds of coarse-to-fine search for the surface")
    band_samples: int = Field(
        32, ge=0, description="rendered samples in a band around the surface; 0: render every coarse and fine sample"
    )
    cone_samples: int = Field(2, ge=1, description="top-weight primary samples that cast virtual cones")
    cone_method: Literal["closed_form", "bounding_rays", "naive"] = "closed_form"
    env_samples: int = Field(48, ge=4, description="coarse samples along each virtual cone (log-spaced)")
    env_fine: int = Field(32, ge=0, description="more samples from the coarse pass's weights (0: one pass)")
    env_fine_render: int = Field(
        128, ge=0, description="env_fine when a trained model renders the environment's views and depth (evaluate, "
        "export, render): one fixed set of samples per view, where training draws new ones every step, and too few "
        "step through thin props to the wall behind. The object's colour and the background of a photo's render "
        "use env_fine, the estimate the model was fitted to"
    )
    depth_quantile: float = Field(
        0.3, gt=0, lt=1, description="an environment ray's depth (export, evaluate, render): where its accumulated "
        "weight reaches this share of the total (0.5: the median); lower reads the first surface that takes a good "
        "part of it, where a prop left semi-transparent sits (docs/method.md)"
    )
    env_near: float = Field(0.05, gt=0, description="first environment sample past a cone's start (object radii)")
    env_far: float = Field(
        100.0, gt=0, description="last environment sample (object radii; the contraction keeps it finite)"
    )
    env_far_from_points: float = Field(
        1.25, ge=0, description="with sparse points (`--points`), env_far becomes this times the farthest a photo "
        "saw a point (0: keep env_far)"
    )
    ior: float = Field(1.5, gt=1, description="index of refraction of the glossy coating (Fresnel)")

    @model_validator(mode="after")
    def _environment_range(self) -> RenderConfig:
        if self.env_far <= self.env_near:
            raise ValueError(f"env_far ({self.env_far}) must exceed env_near ({self.env_near})")
        return self


class SamplerConfig(StrictModel):
    """The rays each iteration draws besides ``batch_rays`` (``orca.data.ImageSet``)."""

    object_fraction: float = Field(0.5, ge=0, le=1, description="share of the batch's rays drawn from object pixels")
    background_rays: int = Field(
        2048, ge=0, description="extra off-object rays per iteration for the environment field (cheap: no SDF)"
    )
    background_near: float = Field(
        0.0, ge=0, lt=1, description="background rays start this fraction of the way from their camera to the "
        "object's centre (no samples right before the lens, where floaters explain a photo's background); off "
        "by default: it helped an environment-only fit but not joint training (docs/method.md)"
    )
    depth_rays: int = Field(512, ge=0, description="rays through sparse points per iteration (losses.sparse_depth)")
    depth_object_margin_px: int = Field(
        4, ge=0, description="a sparse point seen this close to the object's mask in any photo is not used"
    )


class LoggingConfig(StrictModel):
    """What a run writes as it goes into its checkpoint folder."""

    log_every: int = Field(50, ge=1, description="metrics.jsonl and tensorboard, every this many iterations")
    preview_every: int = Field(1000, ge=1)
    preview_downscale: int = Field(4, ge=1)
    checkpoint_every: int = Field(500, ge=1)
    keep_checkpoints: int = Field(3, ge=1)


class TrainConfig(StrictModel):
    """Training the ORCa model (``orca train``): the optimizer loop here, the model and its sampling in the
    groups. Sizes default to the ``standard`` preset."""

    iterations: int = Field(20000, ge=1)
    batch_rays: int = Field(2048, ge=8)
    mask_warmup: int = Field(1000, ge=0, description="iterations of silhouette-only training first")
    lr: float = Field(5e-3, gt=0)
    appearance_lr: float = Field(
        0.05, gt=0, description="learning rate of the per-photo gains (train.appearance; decays as train.lr does): "
        "ten times the fields', or a gain's log moves at most ~lr a step and a stop's difference takes most of a "
        "short training"
    )
    lr_final_ratio: float = Field(0.05, gt=0, le=1, description="exponential decay to lr x ratio at the end")
    environment_lr: float | None = Field(
        None, gt=0, description="learning rate of the environment field (decays as train.lr does; none: train.lr)"
    )
    adam_beta2: float = Field(
        0.999, gt=0, lt=1, description="Adam's second-moment decay (hash grids' rarely touched rows adapt faster "
        "with a lower one)"
    )
    grad_clip: float = Field(1.0, gt=0)
    device: Literal["auto", "cpu", "cuda"] = "auto"
    seed: int = 0
    holdout_every: int = Field(
        0, ge=0, description="hold every k-th photo (name order, from the first: LLFF's convention) out of training, "
        "for `orca evaluate --held-out` to compare the model's renders with photos it never saw; 0: train on all"
    )
    appearance: Literal["auto"] | bool = Field(
        "auto", description="learn each photo's exposure and white balance (a gain per colour channel; "
        "orca/appearance.py), so the fields are not painted with each photo's tint: true / false, or auto: true "
        "unless every photo is RAW (decoded with one white balance and its EXIF exposure)"
    )
    sdf: SDFConfig = Field(default_factory=SDFConfig)
    environment: EnvironmentConfig = Field(default_factory=EnvironmentConfig)
    render: RenderConfig = Field(default_factory=RenderConfig)
    sampler: SamplerConfig = Field(default_factory=SamplerConfig)
    losses: LossConfig = Field(default_factory=LossConfig)
    logging: LoggingConfig = Field(default_factory=LoggingConfig)

    @model_validator(mode="before")
    @classmethod
    def _moved_keys(cls, values: Any) -> Any:
        # model files and checkpoints of earlier versions hold the flat keys (load_config warns about them in
        # what a user writes; these are read silently)
        return move_keys("train", values)[0] if isinstance(values, dict) else values


class MeshConfig(StrictModel):
    """Marching cubes of the trained SDF (``orca mesh``; see pipeline/stages/mesh.py)."""

    resolution: int = Field(256, ge=16, le=2048, description="voxels along each side of the meshed cube")
    extent: float | None = Field(
        None, gt=0, description="half side of the meshed cube (object radii); default: the SDF's own bound"
    )
    block_resolution: int = Field(8, ge=2, le=32, description="voxels per side of open3d's voxel blocks")
    sparse: bool = Field(
        True, description="evaluate the SDF only in blocks near the surface (found on a coarse pass of one sample "
        "per block): several times fewer network evaluations at the same mesh"
    )
    min_component_fraction: float = Field(
        0.01, ge=0, le=1,
        description="drop connected pieces with fewer triangles than this fraction of the largest (floaters)",
    )
    colors: bool = Field(True, description="vertex colours from the diffuse head (tone-mapped sRGB)")
    chunk: int = Field(65536, ge=1024, description="points per network evaluation")


class ExportConfig(StrictModel):
    """Environment views, panoramas, videos, point cloud and object renders (``orca export``)."""

    view_size: int = Field(128, ge=8, description="side of the square environment views (pixels)")
    view_fov_deg: float = Field(90.0, gt=0, lt=180, description="their field of view")
    translated_offsets: list[float] = Field(
        [-0.5, 0.5], description="translated views: sideways shifts from the object centre (object radii)"
    )
    rotated_yaw_deg: list[float] = Field(
        [45.0, 135.0], description="rotated views from the centre: yaws between the cube faces (degrees)"
    )
    panorama_width: int = Field(512, ge=8, description="equirectangular panorama width (height: half of it)")
    point_cloud_max_depth: float = Field(
        30.0, gt=0, description="panorama points farther than this (object radii) are left out of the point cloud"
    )
    video_frames: int = Field(48, ge=2, description="frames per video")
    video_width: int = Field(160, ge=8, description="video width (pixels, even)")
    video_height: int = Field(120, ge=8, description="video height (pixels, even)")
    video_fps: int = Field(12, ge=1)
    video_fov_deg: float | None = Field(
        None, gt=0, lt=180, description="orbit video's vertical field of view; default: the training cameras'"
    )
    flythrough_radius: float = Field(
        0.5, ge=0, description="the environment video's camera circles the centre at this radius (object radii)"
    )
    object_views: int = Field(8, ge=0, description="object renders from this many evenly spaced training cameras")
    object_downscale: int = Field(2, ge=1, description="object renders at 1/k of the training size")
    background: bool = Field(True, description="composite the orbit video's object over the environment field")

    @field_validator("video_width", "video_height")
    @classmethod
    def _even(cls, v: int) -> int:
        if v % 2:
            raise ValueError(f"video sizes must be even (H.264 with 4:2:0 chroma), got {v}")
        return v


class PipelineConfig(StrictModel):
    preset: str = "standard"
    decode: DecodeConfig = Field(default_factory=DecodeConfig)
    poses: PosesConfig = Field(default_factory=PosesConfig)
    masks: MasksConfig = Field(default_factory=MasksConfig)
    train: TrainConfig = Field(default_factory=TrainConfig)
    mesh: MeshConfig = Field(default_factory=MeshConfig)
    export: ExportConfig = Field(default_factory=ExportConfig)


# The train section's flat keys of earlier versions -> their place in it now.
MOVED: dict[str, dict[str, str]] = {"train": {
    "object_fraction": "sampler.object_fraction",
    "background_rays": "sampler.background_rays",
    "background_near": "sampler.background_near",
    "depth_rays": "sampler.depth_rays",
    "depth_object_margin_px": "sampler.depth_object_margin_px",
    "checkpoint_every": "logging.checkpoint_every",
    "preview_every": "logging.preview_every",
    "preview_downscale": "logging.preview_downscale",
    "log_every": "logging.log_every",
    "keep_checkpoints": "logging.keep_checkpoints",
    "sdf_encoding": "sdf.encoding",
    "sdf_hidden": "sdf.hidden",
    "sdf_layers": "sdf.layers",
    "sdf_init_radius": "sdf.init_radius",
    "grid_levels": "sdf.hash_grid.levels",
    "grid_log2_table": "sdf.hash_grid.log2_table_size",
    "grid_max_resolution": "sdf.hash_grid.max_resolution",
    "texture_levels": "sdf.texture_grid.levels",
    "texture_log2_table": "sdf.texture_grid.log2_table_size",
    "texture_max_resolution": "sdf.texture_grid.max_resolution",
    "sdf_levels_start": "sdf.levels_start",
    "sdf_levels_full": "sdf.levels_full",
    "beta_init": "sdf.beta_init",
    "beta_final": "sdf.beta_final",
    "beta_anneal": "sdf.beta_anneal",
    "env_encoding": "environment.encoding",
    "env_hidden": "environment.hidden",
    "env_layers": "environment.layers",
    "env_grid_log2_table": "environment.hash_grid.log2_table_size",
    "env_view_freqs": "environment.dir_freqs",
    "env_contract_radius": "environment.contract_radius",
    "env_density_bias": "environment.density_bias",
    "scene_radius": "render.object_radius",
    "n_coarse": "render.n_coarse",
    "n_fine": "render.n_fine",
    "upsample_steps": "render.upsample_steps",
    "band_samples": "render.band_samples",
    "cone_samples": "render.cone_samples",
    "cone_method": "render.cone_method",
    "env_samples": "render.env_samples",
    "env_fine": "render.env_fine",
    "env_fine_render": "render.env_fine_render",
    "env_depth_quantile": "render.depth_quantile",
    "env_near": "render.env_near",
    "env_far": "render.env_far",
    "env_far_from_points": "render.env_far_from_points",
    "ior": "render.ior",
}}


def move_keys(section: str, values: dict[str, Any]) -> tuple[dict[str, Any], list[tuple[str, str]]]:
    """``values`` of ``section`` with each of its :data:`MOVED` keys at its new place (a copy), and the
    ``(old, new)`` keys moved.

    Raises:
        ValueError: an old key and its new one are both given, or the new one's group is not a mapping.
    """
    moved = MOVED.get(section, {})
    moves = [(k, moved[k]) for k in values if k in moved]
    if not moves:
        return values, []
    out = copy.deepcopy({k: v for k, v in values.items() if k not in moved})
    for old, new in moves:
        *groups, key = new.split(".")
        node = out
        for group in groups:
            node = node.setdefault(group, {})
            if not isinstance(node, dict):
                raise ValueError(f"{section}.{old} moved to {section}.{new}, but {section}.{group} is not a mapping")
        if key in node:
            raise ValueError(f"{section}.{old} and {section}.{new} are both given (the first is the second's "
                             "earlier name)")
        node[key] = copy.deepcopy(values[old])
    return out, moves


def _moved_in_layer(where: str, layer: dict[str, Any]) -> dict[str, Any]:
    """A layer with the :data:`MOVED` keys at their new places, each move a warning naming the new key."""
    for section in MOVED:
        if not isinstance(layer.get(section), dict):
            continue
        try:
            values, moves = move_keys(section, layer[section])
        except ValueError as e:
            raise ConfigError(f"{where}: {e}", fix="keep only the new key") from e
        for old, new in moves:
            log.warning("%s: %s.%s is deprecated; write %s.%s", where, section, old, section, new)
        layer = {**layer, section: values}
    return layer


def dotted(values: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    """Nested mappings as one level of dotted keys: ``{"sdf": {"hidden": 64}}`` -> ``{"sdf.hidden": 64}``."""
    out: dict[str, Any] = {}
    for k, v in values.items():
        if isinstance(v, dict) and v:
            out.update(dotted(v, f"{prefix}{k}."))
        else:
            out[f"{prefix}{k}"] = v
    return out


def deep_merge(base: dict[str, Any], update: dict[str, Any]) -> dict[str, Any]:
    """Recursive dict merge; ``update`` wins. Inputs are not modified."""
    out = copy.deepcopy(base)
    for k, v in update.items():
        if isinstance(v, dict) and isinstance(out.get(k), dict):
            out[k] = deep_merge(out[k], v)
        else:
            out[k] = copy.deepcopy(v)
    return out


def parse_override(item: str) -> dict[str, Any]:
    """``"decode.downscale=2"`` -> ``{"decode": {"downscale": 2}}``; the value is parsed as YAML."""
    if "=" not in item:
        raise ConfigError(f"--set {item}: not of the form key.sub=value", fix="write it as --set decode.downscale=2")
    key, value = item.split("=", 1)
    try:
        parsed: Any = yaml.safe_load(value)
    except yaml.YAMLError as e:
        raise ConfigError(f"--set {item}: the value {value!r} is not valid YAML ({_yaml_problem(e)})",
                          fix="write the value as YAML, e.g. --set 'decode.white_balance=[2.1, 1, 1.6]' "
                          "(quoted for the shell)") from e
    for part in reversed(key.strip().split(".")):
        parsed = {part: parsed}
    return parsed


def _read_yaml(path: Path) -> dict[str, Any]:
    if not path.is_file():
        raise ConfigError("config file not found" if not path.exists() else "not a file", path,
                          fix="check the path given to --config (or leave the option out)")
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8")) or {}
    except (OSError, UnicodeDecodeError) as e:
        raise ConfigError(f"cannot read the config file ({e})", path, fix="save it as UTF-8 text you can read") from e
    except yaml.YAMLError as e:
        raise ConfigError(f"not valid YAML: {_yaml_problem(e)}", path, fix="correct the YAML syntax there") from e
    if not isinstance(data, dict):
        raise ConfigError(f"expected a mapping at the top level, got {type(data).__name__}", path,
                          fix="write sections of keys, e.g. `decode:` then `  downscale: 2` on the next line")
    return data


def _yaml_problem(e: yaml.YAMLError) -> str:
    """What the YAML parser objects to and where, without its echo of the text."""
    problem = getattr(e, "problem", None) or " ".join(str(e).split())
    mark = getattr(e, "problem_mark", None)
    return f"{problem} at line {mark.line + 1}, column {mark.column + 1}" if mark is not None else problem


PRESET_DIR = Path(__file__).parent / "presets"
PRESETS: dict[str, dict[str, Any]] = {p.stem: _read_yaml(p) for p in sorted(PRESET_DIR.glob("*.yaml"))}


Layers = list[tuple[str, dict[str, Any]]]  # (where it came from: a file, "--set key=value"; its values)


def load_config(
    *files: str | Path | None,
    preset: str | None = None,
    overrides: list[str] | tuple[str, ...] = (),
) -> PipelineConfig:
    """Build and validate the config from a preset, YAML files (missing ``None`` entries skipped), overrides."""
    layers = [(str(f), _read_yaml(Path(f))) for f in files if f is not None]
    layers += [(f"--set {o}", parse_override(o)) for o in overrides]
    layers = [(where, _moved_in_layer(where, layer)) for where, layer in layers]
    chosen = _preset(preset, layers)
    merged: dict[str, Any] = deep_merge({}, PRESETS[chosen])
    for _, layer in layers:
        merged = deep_merge(merged, layer)
    merged["preset"] = chosen
    try:
        return PipelineConfig.model_validate(merged)
    except ValidationError as e:
        raise _invalid(e, layers, f"preset {chosen!r}") from e


def _preset(given: str | None, layers: Layers) -> str:
    """The preset: ``given`` (``--preset``) wins over the last layer's ``preset:``; 'standard' by default."""
    chosen, source = given, f"--preset {given}"
    if given is None:
        for where, layer in layers:
            if "preset" in layer:
                chosen, source = layer["preset"], where
    chosen = chosen or "standard"
    if not isinstance(chosen, str) or chosen not in PRESETS:
        raise ConfigError(f"{source}: unknown preset {chosen!r}{_did_you_mean(str(chosen), {p: [p] for p in PRESETS})}",
                          fix=f"choose one of {', '.join(PRESETS)}")
    return chosen


def _invalid(error: ValidationError, layers: Layers, default: str) -> ConfigError:
    """One line per problem: where the value came from (the last layer that sets it), its key, what is wrong
    and, for an unknown key, the closest valid one."""
    problems: dict[tuple[str, str], list[str]] = {}
    for item in error.errors():
        # pydantic names the member of a union a value failed (``literal['reference']``) as if it were a key
        loc = tuple(part for part in item["loc"] if not (isinstance(part, str) and "[" in part))
        what = validation_problem(item)
        if item["type"] == "extra_forbidden":
            what += _did_you_mean(str(loc[-1]), _keys_beside(loc))
        found = problems.setdefault((_source(loc, layers) or default, ".".join(map(str, loc))), [])
        if what not in found:
            found.append(what)
    lines = [f"{where}: {key}: {'; or '.join(whats)}" for (where, key), whats in problems.items()]
    fix = "correct the values named above (every key, its default and its meaning: pipeline/config.py)"
    if len(lines) == 1:
        return ConfigError(f"invalid configuration: {lines[0]}", fix=fix)
    return ConfigError("invalid configuration:\n" + "\n".join(f"  {line}" for line in lines), fix=fix)


def _source(loc: tuple[Any, ...], layers: Layers) -> str | None:
    """The last layer setting ``loc``, or the longest part of it that some layer sets (a model's own check
    reports the section only)."""
    for n in range(len(loc), 0, -1):
        for where, layer in reversed(layers):
            node: Any = layer
            for part in loc[:n]:
                if isinstance(node, dict) and part in node:
                    node = node[part]
                elif isinstance(node, list) and isinstance(part, int) and 0 <= part < len(node):
                    node = node[part]
                else:
                    break
            else:
                return where
    return None


def _keys_beside(loc: tuple[Any, ...]) -> dict[str, list[str]]:
    """The valid keys where ``loc``'s last key was given, each with how to write it. A key may belong one
    level or more further in (``iteratons`` -> ``train.iterations``, ``train.hiden`` -> ``train.sdf.hidden``):
    those are candidates there too, written in full."""
    model: type[BaseModel] = PipelineConfig
    for part in loc[:-1]:
        inner = _group(model, part)
        if inner is None:
            return {}
        model = inner
    keys = {k: [k] for k in model.model_fields}
    for path in _paths(model):
        if len(path) > 1:
            keys.setdefault(path[-1], []).append(".".join(map(str, (*loc[:-1], *path))))
    return keys


def _group(model: type[BaseModel], key: Any) -> type[BaseModel] | None:
    """The model of ``model``'s field ``key`` when that field is a group of keys."""
    field = model.model_fields.get(key) if isinstance(key, str) else None
    inner = field.annotation if field is not None else None
    return inner if isinstance(inner, type) and issubclass(inner, BaseModel) else None


def _paths(model: type[BaseModel], prefix: tuple[str, ...] = ()) -> list[tuple[str, ...]]:
    """Every key of ``model``, groups' keys included, as paths."""
    paths = []
    for key in model.model_fields:
        paths.append((*prefix, key))
        inner = _group(model, key)
        if inner is not None:
            paths += _paths(inner, (*prefix, key))
    return paths


def _did_you_mean(key: str, valid: dict[str, list[str]]) -> str:
    """'; did you mean ...?' naming the valid key closest to ``key`` (each way to write it), or ''."""
    close = difflib.get_close_matches(key, list(valid), n=1)
    return f"; did you mean {' or '.join(repr(k) for k in valid[close[0]])}?" if close else ""


def with_values(section: SectionT, option: str, **values: Any) -> SectionT:
    """A config section with ``values`` set by a stage's own CLI option (``mesh --resolution``), validated: a bad
    value is a :class:`ConfigError` naming ``option``, like a bad ``--set``."""
    try:
        return type(section).model_validate({**section.model_dump(), **values})
    except ValidationError as e:
        raise _invalid(e, [(option, values)], option) from e


def add_config_arguments(parser: Any) -> None:
    """The config options every stage's CLI shares: ``--preset``, ``--config``, ``--set``."""
    parser.add_argument("--preset", default=None, help=f"config preset ({', '.join(PRESETS)})")
    parser.add_argument("--config", type=Path, default=None, help="YAML config file")
    parser.add_argument(
        "--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
        help="override a config value, e.g. train.iterations=500 (repeatable; the stage's section may be omitted)",
    )


def config_from_arguments(args: Any, section: str, capture_yaml: Path | None = None) -> PipelineConfig:
    """Load the config from parsed ``add_config_arguments`` options; bare keys belong to ``section``."""
    return stage_config(section, args.preset, args.config, args.overrides, capture_yaml)


def stage_config(
    section: str,
    preset: str | None = None,
    config_file: Path | None = None,
    overrides: list[str] | tuple[str, ...] = (),
    capture_yaml: Path | None = None,
) -> PipelineConfig:
    """The config a stage's CLI resolves: the capture's ``capture.yaml`` (when it exists), ``config_file``,
    then ``overrides``, whose bare keys (``iterations=500``) belong to ``section``."""
    fields = {*type(getattr(PipelineConfig(), section)).model_fields, *MOVED.get(section, {})}

    def qualify(item: str) -> str:
        # "iterations=500" and "losses.background=0.1" belong to the stage's section; "masks.x=1" does not
        head = item.split("=", 1)[0].strip().split(".", 1)[0]
        own = head in fields and head not in PipelineConfig.model_fields
        return f"{section}.{item.strip()}" if own else item

    return load_config(
        capture_yaml if capture_yaml is not None and capture_yaml.is_file() else None,
        config_file,
        preset=preset,
        overrides=[qualify(o) for o in overrides],
    )


# Keys that change how a stage runs, never what it makes: out of its digest, so a machine with other cores
# does not rerun it.
HOW_NOT_WHAT = {"masks": {"workers"}}


def stage_config_digest(
    section: str,
    preset: str | None = None,
    overrides: list[str] | tuple[str, ...] = (),
    capture_yaml: Path | None = None,
) -> str:
    """A short hash of the stage's section of :func:`stage_config`, every default filled in.

    The Snakefile records it as each rule's ``params``: Snakemake reruns a rule whose params changed, so a
    stage reruns when the values it runs with change, even when no file or command line did (a default
    changed by an upgrade of this package, a preset edited).
    """
    values = getattr(stage_config(section, preset, None, overrides, capture_yaml), section)
    text = json.dumps(values.model_dump(mode="json", exclude=HOW_NOT_WHAT.get(section, set())), sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()[:16]
