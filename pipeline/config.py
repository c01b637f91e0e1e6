"""The pipeline's configuration: one validated model, presets by name, YAML files and CLI overrides.

Unknown keys and bad values are errors (pydantic ``extra="forbid"``), never silence. A config is built as
``defaults <- preset <- capture.yaml <- --config FILE <- --set key=value``, later layers winning.
"""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Any, Literal

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator

from .errors import ConfigError


class StrictModel(BaseModel):
    model_config = ConfigDict(extra="forbid", validate_assignment=True)


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
        True, description="scale each image by its EXIF exposure (shutter x ISO / f-number^2) relative to the reference."
    )
    min_images: int = Field(3, ge=1, description="fewer usable photos than this is an error.")
    downscale: int = Field(1, ge=1, le=16, description="integer downscale factor (area averaging) after decoding.")
    clip_fraction: float = Field(
        0.98,
        gt=0,
        le=1,
        description="raw values at or above black + clip_fraction x (white - black) count as clipped "
        "(8/16-bit files: at or above this fraction of the maximum code value).",
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


class PipelineConfig(StrictModel):
    preset: str = "standard"
    decode: DecodeConfig = Field(default_factory=DecodeConfig)


PRESETS: dict[str, dict[str, Any]] = {
    # CPU, the demo capture, tests: small images, small networks.
    "fast": {"decode": {"downscale": 1}},
    # A GPU and a real capture.
    "standard": {},
    # The paper's network sizes and sample counts.
    "paper": {},
}


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
        raise ConfigError(f"override {item!r} is not of the form key.sub=value")
    key, value = item.split("=", 1)
    parsed: Any = yaml.safe_load(value)
    for part in reversed(key.strip().split(".")):
        parsed = {part: parsed}
    return parsed


def _read_yaml(path: Path) -> dict[str, Any]:
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8")) or {}
    except yaml.YAMLError as e:
        raise ConfigError(f"{path}: not valid YAML: {e}") from e
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: expected a mapping at the top level, got {type(data).__name__}")
    return data


def load_config(
    *files: str | Path | None,
    preset: str | None = None,
    overrides: list[str] | tuple[str, ...] = (),
) -> PipelineConfig:
    """Build and validate the config from a preset, YAML files (missing ``None`` entries skipped), overrides."""
    layers = [_read_yaml(Path(f)) for f in files if f is not None]
    layers += [parse_override(o) for o in overrides]
    chosen = preset
    for layer in layers:
        chosen = layer.get("preset", chosen) if preset is None else preset
    chosen = chosen or "standard"
    if chosen not in PRESETS:
        raise ConfigError(f"unknown preset {chosen!r}; choose one of {', '.join(PRESETS)}")
    merged: dict[str, Any] = deep_merge({}, PRESETS[chosen])
    for layer in layers:
        merged = deep_merge(merged, layer)
    merged["preset"] = chosen
    try:
        return PipelineConfig.model_validate(merged)
    except ValidationError as e:
        where = ", ".join(str(f) for f in files if f is not None) or "config"
        raise ConfigError(f"{where}: invalid configuration:\n{e}") from e
