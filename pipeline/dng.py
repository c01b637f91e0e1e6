"""A simulated camera: scene-linear RGB in, a real DNG (Bayer mosaic, noise, EXIF) out.

The synthetic renderer calls :func:`write_dng` so that its captures go through exactly the same
``decode`` stage as a real camera's RAW files.

The signal chain, per pixel (``C`` = :attr:`SensorModel.camera_from_srgb`, ``x`` = ``linear_rgb``)::

    k      = gain * exposure.value / sensor.full_scale_exposure        # "raw_scale" in the returned dict
    s      = k * C @ x                          # camera RGB, in units of the full scale (white - black)
    s_cfa  = s sampled on the Bayer pattern     # one channel per photosite
    e      = Poisson(s_cfa * full_well_e * 100 / iso) + Normal(0, read_noise_e)   # electrons (noise on)
    DN     = round(black + e * (white - black) / (full_well_e * 100 / iso) + Normal(0, read_noise_dn))
    DN     = clip(DN, 0, white)

**How EXIF exposure enters.** :attr:`Exposure.value` is ``shutter_s * (iso / 100) / f_number**2``,
the photometric exposure relative to 1 s at ISO 100 and f/1. Raw values (above black) are proportional to
it: two photos of the same scene at different EXIF settings differ by exactly
``value_a / value_b``, which is what ``orca decode`` divides out (``exposure_scale = value_ref / value_i``).
``gain`` is the part of the brightness EXIF does not know (scene illumination, the renderer's units); it is
not undone by decoding. ISO is an amplification, so higher ISO means fewer electrons for the same DN and
relatively more shot noise, as in a real camera.

**What decoding gives back.** The camera matrix is normalized so that its green row sums to 1, so a white
(1, 1, 1) input gives camera RGB ``(n_R, 1, n_B)`` = ``AsShotNeutral`` (for the default illuminant), and
``orca decode`` (white balance with G = 1, camera -> sRGB matrix from ``ColorMatrix1``) returns, for the
reference image ``r`` of a capture, and every other image after exposure normalization::

    decoded = gain * exposure_r.value / sensor.full_scale_exposure * linear_rgb  =  decoded_scale(...) * x

(up to noise, demosaicing and clipping at the white level). With a non-white ``white_balance_illuminant``
the map is the 3x3 matrix ``decoded_from_linear`` in the returned dict instead of a scalar (for the image
whose as-shot white balance decode uses: the capture's reference image; decode applies that one to all).
"""

from __future__ import annotations

import datetime as _dt
import struct
from collections.abc import Sequence
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path
from typing import Any

import numpy as np

from .artifacts import atomic_path

# sRGB (D65) -> XYZ, the constants LibRaw/dcraw use (``xyz_rgb``), so that the ColorMatrix1 we write and the
# camera -> sRGB matrix LibRaw derives from it are exact inverses of each other.
XYZ_FROM_SRGB = np.array(
    [[0.412453, 0.357580, 0.180423], [0.212671, 0.715160, 0.072169], [0.019334, 0.119193, 0.950227]]
)
SRGB_FROM_XYZ = np.linalg.inv(XYZ_FROM_SRGB)

# A plausible XYZ(D65) -> camera matrix: the D65 ColorMatrix Adobe publishes for a full-frame Canon DSLR
# (dcraw's adobe_coeff "Canon EOS 5D Mark II"). Its white point is (0.39, 1, 0.72): red and blue multipliers
# about 2.6 and 1.4, and real cross-talk between channels, so the colour path is actually exercised.
_DEFAULT_XYZ_TO_CAMERA = (
    (0.4716, 0.0603, -0.0830),
    (-0.7798, 1.5474, 0.2480),
    (-0.1496, 0.1937, 0.6651),
)

# DNG CalibrationIlluminant codes (EXIF LightSource).
ILLUMINANT_D65 = 21

# A private tag number with no other tag we write between it and 34665 (ExifIFD), so IFD order stays sorted.
_EXIF_PLACEHOLDER = 34666

_CFA_CODES = {"R": 0, "G": 1, "B": 2}


@dataclass(frozen=True)
class Exposure:
    """The exposure settings a camera writes to EXIF."""

    shutter_s: float  # ExposureTime, seconds
    iso: float  # ISOSpeedRatings
    f_number: float  # FNumber

    def __post_init__(self) -> None:
        for name in ("shutter_s", "iso", "f_number"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise ValueError(f"Exposure.{name} must be a positive number, got {v!r}")

    @property
    def value(self) -> float:
        """Relative photometric exposure ``shutter_s * (iso / 100) / f_number**2``.

        Base: 1 s at ISO 100 and f/1 is 1.0. Raw signal is proportional to it.
        """
        return self.shutter_s * (self.iso / 100.0) / self.f_number**2


@dataclass(frozen=True)
class SensorModel:
    """A plausible 14-bit Bayer camera. All defaults are fixed (tests and ground truth depend on them)."""

    make: str = "ORCa"
    model: str = "SimCam 14"
    bits: int = 14  # white level = 2**bits - 1
    black_level: int = 512
    cfa_pattern: str = "RGGB"  # top-left 2x2 block, row-major
    # XYZ (D65) -> camera native RGB; normalized on use (see camera_from_srgb).
    xyz_to_camera: tuple[tuple[float, float, float], ...] = _DEFAULT_XYZ_TO_CAMERA
    # Exposure.value at which a white (1, 1, 1) input at gain 1 fills the green channel to the white level.
    # Default: 1/100 s, ISO 100, f/4.
    full_scale_exposure: float = (1 / 100) * 1.0 / 4.0**2
    # Noise: electrons filling the full scale at ISO 100 (scaled by 100/ISO at other ISOs), read noise
    # before the ISO amplifier (electrons) and after it (DN).
    full_well_e: float = 25000.0
    read_noise_e: float = 3.0
    read_noise_dn: float = 1.0

    def __post_init__(self) -> None:
        if len(self.cfa_pattern) != 4 or sorted(self.cfa_pattern) != sorted("RGGB"):
            raise ValueError(f"cfa_pattern must be a 2x2 Bayer pattern like 'RGGB', got {self.cfa_pattern!r}")
        if not 8 <= self.bits <= 16:
            raise ValueError(f"bits must be in 8..16, got {self.bits}")
        if not 0 <= self.black_level < self.white_level // 2:
            raise ValueError(f"black_level {self.black_level} out of range for {self.bits} bits")

    @property
    def white_level(self) -> int:
        return (1 << self.bits) - 1

    @property
    def camera_from_srgb(self) -> np.ndarray:
        """Linear sRGB -> camera RGB (3x3), scaled so the green row sums to 1."""
        m = np.asarray(self.xyz_to_camera, dtype=np.float64) @ XYZ_FROM_SRGB
        return m / m[1].sum()

    @property
    def color_matrix1(self) -> np.ndarray:
        """DNG ColorMatrix1: XYZ (D65) -> camera RGB, consistent with :attr:`camera_from_srgb`."""
        return self.camera_from_srgb @ SRGB_FROM_XYZ

    def cfa_indices(self) -> np.ndarray:
        """2x2 array of channel indices (0=R, 1=G, 2=B) of the CFA's top-left block."""
        return np.array([_CFA_CODES[c] for c in self.cfa_pattern.upper()], dtype=np.uint8).reshape(2, 2)


def as_shot_neutral(sensor: SensorModel, illuminant: Sequence[float] = (1.0, 1.0, 1.0)) -> np.ndarray:
    """Camera RGB of the illuminant (its linear sRGB colour), normalized to G = 1 (DNG ``AsShotNeutral``)."""
    n = sensor.camera_from_srgb @ np.asarray(illuminant, dtype=np.float64)
    if not np.all(n > 0):
        raise ValueError(f"white_balance_illuminant {tuple(illuminant)} gives a non-positive camera neutral {n}")
    return n / n[1]


def decoded_from_linear(sensor: SensorModel, illuminant: Sequence[float] = (1.0, 1.0, 1.0)) -> np.ndarray:
    """3x3 map from ``linear_rgb * raw_scale`` to what decode returns with this image's as-shot white balance.

    decode: camera -> white balance (multipliers 1/neutral, G = 1) -> camera-to-sRGB matrix LibRaw derives
    from ColorMatrix1 (``inv(C / rowsum(C))``). Identity for a white illuminant.
    """
    c = sensor.camera_from_srgb
    rowsum = c.sum(axis=1)
    rgb_from_cam = np.linalg.inv(c / rowsum[:, None])
    wb = 1.0 / as_shot_neutral(sensor, illuminant)
    return rgb_from_cam @ np.diag(wb) @ c


def decoded_scale(gain: float, reference: Exposure, sensor: SensorModel = SensorModel()) -> float:
    """Factor from ``linear_rgb`` to the decode stage's output, for a capture whose reference image has
    exposure ``reference`` (white illuminant): ``decoded = decoded_scale * linear_rgb`` for every image."""
    return float(gain * reference.value / sensor.full_scale_exposure)


def mosaic(camera_rgb: np.ndarray, sensor: SensorModel) -> np.ndarray:
    """(H, W, 3) -> (H, W): each photosite keeps the channel its CFA filter passes."""
    h, w, _ = camera_rgb.shape
    idx = sensor.cfa_indices()
    chan = np.tile(idx, ((h + 1) // 2, (w + 1) // 2))[:h, :w]
    return np.take_along_axis(camera_rgb, chan[..., None].astype(np.intp), axis=2)[..., 0]


def simulate_raw(
    linear_rgb: np.ndarray,
    *,
    exposure: Exposure,
    gain: float = 1.0,
    sensor: SensorModel = SensorModel(),
    rng: np.random.Generator | None = None,
    noise: bool = True,
) -> np.ndarray:
    """The sensor simulation alone: (H, W, 3) linear sRGB -> (H, W) uint16 raw mosaic (see module doc)."""
    x = np.asarray(linear_rgb, dtype=np.float64)
    if x.ndim != 3 or x.shape[2] != 3:
        raise ValueError(f"linear_rgb must be (H, W, 3), got {x.shape}")
    if not np.all(np.isfinite(x)):
        raise ValueError("linear_rgb contains NaN or inf")
    k = gain * exposure.value / sensor.full_scale_exposure
    cam = np.einsum("ij,hwj->hwi", sensor.camera_from_srgb, x) * k
    s = mosaic(cam, sensor)  # fraction of full scale
    span = float(sensor.white_level - sensor.black_level)
    if noise:
        rng = rng if rng is not None else np.random.default_rng()
        e_full = sensor.full_well_e * 100.0 / exposure.iso  # electrons at full scale for this ISO
        lam = s * e_full
        pos = np.clip(lam, 0.0, None)
        # Poisson shot noise (the mean stays exact, also for the rare negative camera values that out-of-gamut
        # colours give), read noise before the amplifier in electrons, after it in DN.
        e = rng.poisson(np.minimum(pos, 1e12)).astype(np.float64) + (lam - pos)
        e += rng.normal(0.0, sensor.read_noise_e, size=e.shape)
        dn = sensor.black_level + e * (span / e_full) + rng.normal(0.0, sensor.read_noise_dn, size=e.shape)
    else:
        dn = sensor.black_level + s * span
    return np.clip(np.round(dn), 0, sensor.white_level).astype(np.uint16)


def write_dng(
    path: str | Path,
    linear_rgb: np.ndarray,
    *,
    exposure: Exposure,
    gain: float = 1.0,
    sensor: SensorModel = SensorModel(),
    white_balance_illuminant: Sequence[float] = (1.0, 1.0, 1.0),
    rng: np.random.Generator | None = None,
    noise: bool = True,
    focal_length_mm: float | None = None,
    focal_length_35mm: float | None = None,
    datetime: _dt.datetime | None = None,
    orientation: int = 1,
) -> dict[str, Any]:
    """Simulate ``sensor`` photographing ``linear_rgb`` and write the raw mosaic as a DNG 1.4 (atomically).

    Args:
        linear_rgb: (H, W, 3) scene-linear radiance, linear sRGB primaries (float).
        exposure: the EXIF exposure; raw values scale with ``exposure.value`` (see module doc).
        gain: brightness factor not recorded in EXIF (illumination / units); not undone by decoding.
        white_balance_illuminant: linear sRGB colour the camera's as-shot white balance neutralizes
            (written as ``AsShotNeutral``). (1, 1, 1) = D65 white: decoding then returns ``linear_rgb``
            times a scalar.
        rng: random generator for the noise; pass a seeded one for reproducible files.
        noise: shot + read noise on/off (quantization always).
        focal_length_mm, focal_length_35mm: optional EXIF FocalLength / FocalLengthIn35mmFilm (SfM uses them).
        datetime: EXIF DateTime / DateTimeOriginal; default now.
        orientation: EXIF/TIFF Orientation (1 = as stored; 6 = the camera was turned 90 degrees clockwise,
            viewers rotate the stored image 90 degrees clockwise). The mosaic is stored as given either way.

    Returns a dict (JSON-serializable) with what a ground-truth writer needs, notably ``raw_scale``
    (``(raw - black) / (white - black) = raw_scale * C @ linear_rgb``), ``decoded_from_linear`` (3x3: the
    decode stage's output for this image, before exposure normalization, is ``decoded_from_linear @ x``), the
    exposure, the neutral, the levels and the fraction of clipped photosites.
    """
    path = Path(path)
    if orientation not in range(1, 9):
        raise ValueError(f"orientation must be an EXIF orientation 1..8, got {orientation}")
    x = np.asarray(linear_rgb)
    raw = simulate_raw(x, exposure=exposure, gain=gain, sensor=sensor, rng=rng, noise=noise)
    neutral = as_shot_neutral(sensor, white_balance_illuminant)
    when = datetime or _dt.datetime.now().replace(microsecond=0)
    _write_dng_file(
        path,
        raw,
        sensor=sensor,
        exposure=exposure,
        neutral=neutral,
        when=when,
        orientation=orientation,
        focal_length_mm=focal_length_mm,
        focal_length_35mm=focal_length_35mm,
    )
    raw_scale = gain * exposure.value / sensor.full_scale_exposure
    return {
        "path": str(path),
        "width": int(raw.shape[1]),
        "height": int(raw.shape[0]),
        "make": sensor.make,
        "model": sensor.model,
        "exposure": {
            "shutter_s": exposure.shutter_s,
            "iso": exposure.iso,
            "f_number": exposure.f_number,
            "value": exposure.value,
        },
        "gain": float(gain),
        "raw_scale": float(raw_scale),
        "camera_from_srgb": sensor.camera_from_srgb.tolist(),
        "as_shot_neutral": neutral.tolist(),
        "white_balance_multipliers": (1.0 / neutral).tolist(),
        "decoded_from_linear": (raw_scale * decoded_from_linear(sensor, white_balance_illuminant)).tolist(),
        "black_level": sensor.black_level,
        "white_level": sensor.white_level,
        "cfa_pattern": sensor.cfa_pattern,
        "noise": bool(noise),
        "clipped_fraction": float(np.mean(raw >= sensor.white_level)),
    }


# ----------------------------------------------------------------------------------------------- TIFF details


def _rational(v: float, denominator: int = 10000) -> tuple[int, int]:
    f = Fraction(float(v)).limit_denominator(denominator)
    return f.numerator, f.denominator


def _rationals(values: Sequence[float], denominator: int = 10000) -> tuple[int, ...]:
    out: list[int] = []
    for v in values:
        out.extend(_rational(v, denominator))
    return tuple(out)


def _ifd_bytes(entries: list[tuple[int, int, int, bytes]], offset: int) -> bytes:
    """A little-endian TIFF IFD at file ``offset``: entries (tag, type, count, packed value)."""
    entries = sorted(entries)
    head = struct.pack("<H", len(entries))
    data_start = offset + 2 + 12 * len(entries) + 4
    body, data = b"", b""
    for tag, typ, count, value in entries:
        if len(value) <= 4:
            body += struct.pack("<HHI", tag, typ, count) + value.ljust(4, b"\0")
        else:
            body += struct.pack("<HHII", tag, typ, count, data_start + len(data))
            data += value + (b"\0" if len(value) % 2 else b"")
    return head + body + struct.pack("<I", 0) + data


def _exif_entries(
    exposure: Exposure, when: _dt.datetime, focal_length_mm: float | None, focal_length_35mm: float | None
) -> list[tuple[int, int, int, bytes]]:
    stamp = when.strftime("%Y:%m:%d %H:%M:%S").encode() + b"\0"
    num, den = _shutter_fraction(exposure.shutter_s)
    fn = _rational(exposure.f_number, 100)
    iso = int(round(min(exposure.iso, 65535)))
    entries = [
        (33434, 5, 1, struct.pack("<II", num, den)),  # ExposureTime
        (33437, 5, 1, struct.pack("<II", *fn)),  # FNumber
        (34855, 3, 1, struct.pack("<H", iso)),  # ISOSpeedRatings (PhotographicSensitivity)
        (36864, 7, 4, b"0231"),  # ExifVersion
        (36867, 2, len(stamp), stamp),  # DateTimeOriginal
        (36868, 2, len(stamp), stamp),  # DateTimeDigitized
    ]
    if focal_length_mm is not None:
        entries.append((37386, 5, 1, struct.pack("<II", *_rational(focal_length_mm, 1000))))
    if focal_length_35mm is not None:
        entries.append((41989, 3, 1, struct.pack("<H", int(round(focal_length_35mm)))))
    return entries


def _shutter_fraction(seconds: float) -> tuple[int, int]:
    inv = 1.0 / seconds
    if seconds < 1 and abs(inv - round(inv)) < 1e-6 * inv:
        return 1, int(round(inv))
    return _rational(seconds, 1_000_000)


def _write_dng_file(
    path: Path,
    raw: np.ndarray,
    *,
    sensor: SensorModel,
    exposure: Exposure,
    neutral: np.ndarray,
    when: _dt.datetime,
    orientation: int,
    focal_length_mm: float | None,
    focal_length_35mm: float | None,
) -> None:
    import tifffile

    cfa = bytes(int(v) for v in sensor.cfa_indices().ravel())
    stamp = when.strftime("%Y:%m:%d %H:%M:%S")
    cm = sensor.color_matrix1.ravel()
    extratags = [
        (271, "s", 0, sensor.make, True),  # Make
        (272, "s", 0, sensor.model, True),  # Model
        (274, "H", 1, orientation, True),  # Orientation (1: top-left)
        (33421, "H", 2, (2, 2), True),  # CFARepeatPatternDim
        (33422, "B", 4, cfa, True),  # CFAPattern
        (_EXIF_PLACEHOLDER, "I", 1, 0, True),  # becomes ExifIFD (34665) below
        (37398, "B", 4, b"\x01\x00\x00\x00", True),  # TIFF/EPStandardID
        (50706, "B", 4, b"\x01\x04\x00\x00", True),  # DNGVersion 1.4
        (50707, "B", 4, b"\x01\x01\x00\x00", True),  # DNGBackwardVersion 1.1
        (50708, "s", 0, f"{sensor.make} {sensor.model}", True),  # UniqueCameraModel
        (50710, "B", 3, b"\x00\x01\x02", True),  # CFAPlaneColor R, G, B
        (50711, "H", 1, 1, True),  # CFALayout rectangular
        (50713, "H", 2, (1, 1), True),  # BlackLevelRepeatDim
        (50714, "I", 1, sensor.black_level, True),  # BlackLevel
        (50717, "I", 1, sensor.white_level, True),  # WhiteLevel
        (50721, "2i", 9, _rationals(cm), True),  # ColorMatrix1 (SRATIONAL)
        (50728, "2I", 3, _rationals(neutral, 1_000_000), True),  # AsShotNeutral
        (50730, "2i", 1, (0, 1), True),  # BaselineExposure
        (50778, "H", 1, ILLUMINANT_D65, True),  # CalibrationIlluminant1
    ]
    with atomic_path(path) as tmp:
        tifffile.imwrite(
            tmp,
            raw,
            byteorder="<",
            bigtiff=False,
            photometric=32803,
            compression=None,
            subfiletype=0,
            software="ORCa pipeline (pipeline.dng)",
            datetime=stamp,
            metadata=None,
            extratags=extratags,
        )
        # tifffile refuses to write tag 34665 (ExifIFD) and writes no EXIF sub-IFD, so it wrote a placeholder tag
        # that sorts at the same place; append the EXIF IFD and turn the placeholder into a pointer to it.
        with tifffile.TiffFile(tmp) as tf:
            slot = tf.pages.first.tags[_EXIF_PLACEHOLDER].valueoffset
        with open(tmp, "r+b") as f:
            f.seek(0, 2)
            end = f.tell()
            if end % 2:
                f.write(b"\0")
                end += 1
            f.write(_ifd_bytes(_exif_entries(exposure, when, focal_length_mm, focal_length_35mm), end))
            f.seek(slot - 8)  # the 12-byte entry: tag, type, count, value
            f.write(struct.pack("<HHII", 34665, 4, 1, end))
