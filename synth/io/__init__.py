"""Inputs and outputs: load and validate images and volumes, save PNG and TIFF stacks, write files atomically.

:mod:`texsynth.synth.io.images` decodes and encodes; :mod:`texsynth.synth.io.patterns` generates inputs with
known orientation fields (laminae, waves, rings, spirals) for tests, benchmarks and constraints;
:mod:`texsynth.synth.io.laminar` known-answer volumes of HRTEM-like fringes (carbon onions, turbostratic
stacks).
"""

from texsynth.synth.io.atomic import atomic_write_bytes, atomic_write_json
from texsynth.synth.io.depth import InputBits, array_to_unit, used_bits
from texsynth.synth.io.images import (
    FORMAT_FILES,
    PICTURE_PNG_LEVEL,
    SUPPORTED_FORMATS,
    ImageSource,
    LoadMode,
    image_to_png_bytes,
    load_image,
    load_image_bits,
    load_volume,
    sample_bits,
    save_image,
    save_volume,
    sniff_format,
    to_uint,
)
from texsynth.synth.io.limits import (
    DEFAULT_MAX_OUTPUT,
    DEFAULT_MAX_PIXELS,
    DEFAULT_MAX_VOXELS,
    MAX_ASPECT_RATIO,
    MAX_SIDE,
    MIN_SIDE,
)

__all__ = [
    "DEFAULT_MAX_OUTPUT",
    "DEFAULT_MAX_PIXELS",
    "DEFAULT_MAX_VOXELS",
    "FORMAT_FILES",
    "MAX_ASPECT_RATIO",
    "MAX_SIDE",
    "MIN_SIDE",
    "PICTURE_PNG_LEVEL",
    "SUPPORTED_FORMATS",
    "ImageSource",
    "InputBits",
    "LoadMode",
    "array_to_unit",
    "atomic_write_bytes",
    "atomic_write_json",
    "image_to_png_bytes",
    "load_image",
    "load_image_bits",
    "load_volume",
    "sample_bits",
    "save_image",
    "save_volume",
    "sniff_format",
    "to_uint",
    "used_bits",
]
