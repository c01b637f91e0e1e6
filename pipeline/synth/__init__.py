"""Synthetic captures with exact ground truth, rendered with Mitsuba 3 (``orca synth``).

``render_capture(scene, out_dir, options)`` writes a capture folder (RAW DNG / JPEG photos) and its
``ground_truth/``; scenes are named presets (:data:`SCENES`). Mitsuba is imported only when rendering.
"""

from .render import ExposureSpec, SynthOptions, render_capture
from .scenes import SCENES, SceneSpec, get_scene

__all__ = ["SCENES", "ExposureSpec", "SceneSpec", "SynthOptions", "get_scene", "render_capture"]
