"""Inputs and outputs: load and validate images and volumes, save PNG and TIFF stacks, write files atomically.

:mod:`synth.io.images` decodes and encodes; :mod:`synth.io.patterns` generates inputs with known orientation
fields (laminae, waves, rings, spirals) for tests, benchmarks and constraints.
"""

from synth.io.images import (
    DEFAULT_MAX_PIXELS,
    DEFAULT_MAX_VOXELS,
    LUMA_WEIGHTS,
    MAX_ASPECT_RATIO,
    MIN_SIDE,
    SUPPORTED_FORMATS,
    ImageSource,
    LoadMode,
    atomic_write_bytes,
    image_to_png_bytes,
    load_image,
    load_volume,
    save_image,
    save_volume,
    to_uint,
)

__all__ = [
    "DEFAULT_MAX_PIXELS",
    "DEFAULT_MAX_VOXELS",
    "LUMA_WEIGHTS",
    "MAX_ASPECT_RATIO",
    "MIN_SIDE",
    "SUPPORTED_FORMATS",
    "ImageSource",
    "LoadMode",
    "atomic_write_bytes",
    "image_to_png_bytes",
    "load_image",
    "load_volume",
    "save_image",
    "save_volume",
    "to_uint",
]
