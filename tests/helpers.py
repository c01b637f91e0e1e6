"""Helpers shared by several test modules."""

from __future__ import annotations

from dataclasses import replace

from pipeline.synth.scenes import SceneSpec


def small(spec: SceneSpec) -> SceneSpec:
    """The same scene with coarse textures (texture generation dominates tiny renders otherwise)."""
    room = replace(spec.room, texels_per_unit=12.0, prop_texels_per_unit=32.0)
    albedo = replace(spec.object.albedo, texture_size=(128, 64))
    return replace(spec, room=room, object=replace(spec.object, albedo=albedo))
