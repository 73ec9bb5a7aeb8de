"""Image and volume I/O: load and validate PNG/TIFF/JPEG, save PNG/TIFF, with errors a person can act on.

Every loader returns the engine's one representation (ALGORITHMS.md, "Conventions"): a C-contiguous
``float32`` array in [0, 1], ``(H, W)`` grey or ``(H, W, 3)`` RGB for an image, ``(D, H, W)`` for a
volume. Every failure is one :mod:`texsynth.synth.errors` exception that names the file and the problem:

- :class:`~texsynth.synth.errors.UnsupportedFormat`: the bytes are not a PNG, TIFF or JPEG image (the bytes
  are judged, never the file name's extension);
- :class:`~texsynth.synth.errors.InputTooLarge`: more pixels than allowed, checked from the header before a
  single pixel is decoded; Pillow's decompression-bomb warning counts as this error too;
- :class:`~texsynth.synth.errors.InvalidInput`: missing, empty, truncated or corrupt file, zero-size, tiny or
  absurdly elongated image, NaN/inf in float data, or a shape that is not a 2-D image (or, for
  :func:`load_volume`, not a 3-D stack).

TIFF goes through ``tifffile`` so that 16-bit and floating-point data arrive exactly; TIFFs whose
compression tifffile cannot decode without the optional ``imagecodecs`` package (LZW, PackBits, JPEG)
or whose colour model it does not convert (CMYK, YCbCr) are decoded by Pillow instead. PNG and JPEG
go through Pillow. Savers quantise in one place (:func:`to_uint`) and write atomically (a temporary
file in the destination directory, then :func:`os.replace`), so a reader never sees half a file.
"""

from __future__ import annotations

import io
import os
import struct
import warnings
import zlib
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Literal

import numpy as np
import tifffile
from PIL import Image, UnidentifiedImageError

from texsynth.synth.colour import to_grey
from texsynth.synth.errors import InputTooLarge, InvalidInput, InvalidParameter, SynthError, UnsupportedFormat
from texsynth.synth.io.atomic import atomic_write_bytes, atomic_writer
from texsynth.synth.io.depth import FLOAT_BITS, InputBits, unsigned_to_unit
from texsynth.synth.io.limits import LIMITS, check_image_shape, resolve_limit

__all__ = [
    "FORMAT_FILES",
    "PICTURE_PNG_LEVEL",
    "SUPPORTED_FORMATS",
    "ImageSource",
    "LoadMode",
    "image_to_png_bytes",
    "load_image",
    "load_image_bits",
    "load_volume",
    "sample_bits",
    "save_image",
    "save_volume",
    "to_uint",
]

#: zlib effort of the pictures made for people (tensor images, plots), not of the outputs (Pillow's default
#: 6): at 4096^2 an orientation picture encodes 2.7x faster (4.9 -> 1.8 s), for a file 6-12% larger.
PICTURE_PNG_LEVEL = 3

#: File extension and media type of each format, for storing and serving uploads.
FORMAT_FILES: dict[str, tuple[str, str]] = {
    "PNG": ("png", "image/png"),
    "TIFF": ("tiff", "image/tiff"),
    "JPEG": ("jpg", "image/jpeg"),
}
#: The formats the loaders accept, as Pillow names them (MPO is Pillow's name for a JPEG that
#: carries extra pictures, as some cameras write).
SUPPORTED_FORMATS = ("PNG", "TIFF", "JPEG")

ImageSource = str | os.PathLike[str] | bytes | bytearray | memoryview
LoadMode = Literal["auto", "grey", "rgb"]

_PILLOW_FORMATS = frozenset({"PNG", "JPEG", "MPO", "TIFF"})
_MAGIC = {
    b"\x89PNG\r\n\x1a\n": "PNG",
    b"\xff\xd8\xff": "JPEG",
    b"II*\x00": "TIFF",
    b"MM\x00*": "TIFF",
    b"II+\x00": "TIFF",  # BigTIFF
    b"MM\x00+": "TIFF",
}
_SUPPORTED_TEXT = "PNG, TIFF or JPEG"
# What tifffile or Pillow raise on damaged data (beyond our own SynthError, re-raised untouched).
_DECODE_ERRORS = (
    tifffile.TiffFileError,
    OSError,
    SyntaxError,
    ValueError,
    KeyError,
    IndexError,
    EOFError,
    struct.error,
    zlib.error,
)
_TIFF_DIRECT_PHOTOMETRIC = frozenset(
    {tifffile.PHOTOMETRIC.MINISBLACK, tifffile.PHOTOMETRIC.MINISWHITE, tifffile.PHOTOMETRIC.RGB}
)


# --------------------------------------------------------------------------------------------
# loading


def load_image(
    source: ImageSource,
    *,
    name: str | None = None,
    max_pixels: int | None = None,
    mode: LoadMode = "auto",
) -> np.ndarray:
    """Load a PNG, TIFF or JPEG image as float32 in [0, 1], with a clear error for any bad input.

    Parameters
    ----------
    source : str, os.PathLike or bytes
        A file path, or the file's raw bytes (an upload).
    name : str, optional
        What error messages call the input. Defaults to the path as given, or ``"image"`` for bytes.
    max_pixels : int, optional
        Largest accepted ``width * height``, checked from the header before decoding. Defaults to
        ``TEXSYNTH_MAX_INPUT_PIXELS`` if set (``TEXSYNTH_MAX_PIXELS``, deprecated), else
        :data:`texsynth.synth.io.limits.DEFAULT_MAX_PIXELS`.
    mode : {'auto', 'grey', 'rgb'}
        ``'auto'`` keeps grey as grey and RGB as RGB, except that an RGB image whose three channels
        are identical becomes grey; ``'grey'`` converts colour to luma; ``'rgb'`` repeats a grey
        image into three channels.

    Returns
    -------
    numpy.ndarray
        C-contiguous ``float32`` in [0, 1], shape ``(H, W)`` (grey) or ``(H, W, 3)`` (RGB).

    Raises
    ------
    UnsupportedFormat
        The bytes are not a PNG, TIFF or JPEG image (e.g. BMP, GIF, text).
    InputTooLarge
        More than ``max_pixels`` pixels, or above Pillow's decompression-bomb limit
        (``PIL.Image.MAX_IMAGE_PIXELS``, whose warning range is an error here too).
    InvalidInput
        No such file, empty file, truncated or corrupt data, zero size, a side shorter than
        :data:`MIN_SIDE`, an aspect ratio above :data:`MAX_ASPECT_RATIO`, NaN or inf values, more
        than 4 channels, or several planes (a stack: see :func:`load_volume`).
    InvalidParameter
        ``mode`` or ``max_pixels`` is not valid.

    Notes
    -----
    Conversion to [0, 1]:

    - unsigned integers are divided by their full scale, ``2**bits - 1`` (255 for 8-bit, 65535 for
      16-bit, 4095 for a 12-bit TIFF); 1-bit images give exactly 0 and 1;
    - floating-point TIFFs (and signed-integer TIFFs, which detectors use for counts) must be
      finite. Values already within [0, 1] are kept exactly; otherwise the whole image (all
      channels together) is rescaled linearly from its minimum and maximum to [0, 1], because
      HRTEM data often arrive as float counts. A constant image outside [0, 1] becomes all zeros;
    - an alpha channel is dropped (ignored, not composited over any background): RGBA -> RGB,
      grey+alpha (LA) -> grey; palette images are expanded to their colours; TIFF
      ``MinIsWhite`` is inverted so that 1 is white.

    Grey conversion (``mode='grey'``) uses the ITU-R BT.601 luma ``0.299 R + 0.587 G + 0.114 B``
    (:data:`texsynth.synth.colour.LUMA_WEIGHTS`), the weights of Pillow's ``convert("L")`` and ImageJ's
    weighted conversion, computed in floating point without rounding to 8 bits. (scikit-image's ``rgb2gray``
    uses the BT.709 weights instead; the difference is small for natural images.)

    A 16-bit-per-channel RGB PNG is read at 8 bits per channel (Pillow's limit); 16-bit grey PNG and
    every TIFF keep their full precision.

    Unsigned integers are scaled by the depth their values use (:mod:`texsynth.synth.io.depth`): 12-bit data
    in a 16-bit TIFF (0-4095) by 4095; :func:`load_image_bits` also returns that depth.
    """
    return load_image_bits(source, name=name, max_pixels=max_pixels, mode=mode)[0]


def load_image_bits(
    source: ImageSource,
    *,
    name: str | None = None,
    max_pixels: int | None = None,
    mode: LoadMode = "auto",
) -> tuple[np.ndarray, InputBits]:
    """:func:`load_image`, and the bits per sample of the file: its container's and those it uses."""
    if mode not in ("auto", "grey", "rgb"):
        raise InvalidParameter("mode", mode, "must be one of 'auto', 'grey', 'rgb'")
    limit = resolve_limit("max_pixels", max_pixels, "max_input_pixels")
    data, label = _read_source(source, name, default_name="image")
    if sniff_format(data) == "PNG" and len(data) >= 24 and data[12:16] == b"IHDR":
        # Pillow cannot open a PNG that declares zero width or height ("not an image", 415): it is
        # an image with no pixels, which is the input's problem (422)
        width, height = struct.unpack(">II", data[16:24])
        if width == 0 or height == 0:
            raise InvalidInput(label, f"the image has zero size ({width}x{height} pixels)")
    decoded, fallback_reason = None, None
    if sniff_format(data) == "TIFF":
        decoded, fallback_reason = _decode_tiff_image(data, label, limit)
    if decoded is None:
        decoded = _decode_with_pillow(data, label, limit, tiff_reason=fallback_reason)
    image, depth = decoded
    return _apply_mode(image, mode), depth


def load_volume(source: ImageSource, *, name: str | None = None, max_voxels: int | None = None) -> np.ndarray:
    """Load a grey volume from a multi-page TIFF stack (one page per z-slice) as float32 in [0, 1].

    Parameters
    ----------
    source : str, os.PathLike or bytes
        A file path, or the file's raw bytes.
    name : str, optional
        What error messages call the input. Defaults to the path as given, or ``"volume"`` for bytes.
    max_voxels : int, optional
        Largest accepted ``depth * height * width``, checked from the header before decoding.
        Defaults to the environment variable ``TEXSYNTH_MAX_VOXELS`` if set, else
        :data:`texsynth.synth.io.limits.DEFAULT_MAX_VOXELS`.

    Returns
    -------
    numpy.ndarray
        C-contiguous ``float32`` in [0, 1], shape ``(D, H, W)`` with ``D >= 2``.

    Raises
    ------
    UnsupportedFormat
        The bytes are not a TIFF, or use a compression that needs the optional ``imagecodecs``.
    InputTooLarge
        More than ``max_voxels`` voxels.
    InvalidInput
        No such file, empty, truncated or corrupt; a single 2-D image; a colour stack; a shape that
        is not ``(D, H, W)``; slices smaller than :data:`MIN_SIDE` or more elongated than
        :data:`MAX_ASPECT_RATIO`; NaN or inf values.

    Notes
    -----
    Values are converted to [0, 1] as in :func:`load_image` (integers by their full scale, float
    data rescaled from the whole volume's minimum and maximum only if outside [0, 1]).
    """
    limit = resolve_limit("max_voxels", max_voxels, "max_input_voxels")
    data, label = _read_source(source, name, default_name="volume")
    fmt = sniff_format(data)
    if fmt != "TIFF":
        what = f"a {fmt} image" if fmt else "not a TIFF file"
        raise UnsupportedFormat(label, f"{what}: volumes are read from multi-page TIFF stacks")
    try:
        with tifffile.TiffFile(io.BytesIO(data)) as tif:
            series = tif.series[0]
            page = series.pages[0]
            shape, axes = tuple(series.shape), series.axes
            if 0 in shape:
                raise InvalidInput(label, f"the volume has zero size (shape {shape})")
            if "S" in axes:
                raise InvalidInput(
                    label, f"a colour stack (shape {shape}, axes {axes}); a grey (D, H, W) stack is needed"
                )
            if len(shape) == 2:
                raise InvalidInput(
                    label,
                    f"a single 2-D image ({shape[1]}x{shape[0]} pixels), not a volume: a volume is a "
                    "multi-page TIFF stack (use load_image for 2-D images)",
                )
            if len(shape) != 3:
                raise InvalidInput(
                    label, f"has shape {shape} (axes {axes}); a 3-D grey stack (D, H, W) is needed"
                )
            depth, height, width = shape
            if depth * height * width > limit:
                raise InputTooLarge(
                    label,
                    f"{width}x{height}x{depth} = {depth * height * width} voxels is more than the limit "
                    f"of {limit} (set {LIMITS['max_input_voxels'].env} or max_voxels to change it)",
                )
            check_image_shape(label, height, width, None)
            photometric = page.photometric
            if photometric not in (tifffile.PHOTOMETRIC.MINISBLACK, tifffile.PHOTOMETRIC.MINISWHITE):
                raise InvalidInput(label, f"TIFF photometric {photometric.name}: a grey stack is needed")
            try:
                raw = series.asarray()
            except (KeyError, ValueError, ImportError) as exc:
                if _missing_codec(exc):
                    raise UnsupportedFormat(label, _codec_message(page)) from None
                raise
            bits = page.bitspersample
    except SynthError:
        raise
    except _DECODE_ERRORS as exc:
        raise InvalidInput(label, f"corrupt or truncated TIFF data ({_describe(exc)})") from None
    volume, _ = _to_unit_float(raw, label, bits=bits)
    if photometric == tifffile.PHOTOMETRIC.MINISWHITE:
        volume = 1.0 - volume
    return np.ascontiguousarray(volume, dtype=np.float32)


# --------------------------------------------------------------------------------------------
# saving


def to_uint(image: np.ndarray, bit_depth: int = 8, *, used_bits: int | None = None) -> np.ndarray:
    """Quantise a float image in [0, 1] to unsigned integers: clip, scale, round to nearest.

    The one quantisation used by every saver (and by :func:`image_to_png_bytes`).

    Parameters
    ----------
    image : numpy.ndarray
        Real-valued array of any shape; values outside [0, 1] are clipped.
    bit_depth : {8, 16}
        8 gives ``uint8`` (0-255), 16 gives ``uint16`` (0-65535).
    used_bits : int, optional
        Scale to ``2**used_bits - 1`` within the container instead (12 in a 16-bit container: 0-4095,
        as the 12-bit camera data it came from, :mod:`texsynth.synth.io.depth`); at most ``bit_depth``.

    Returns
    -------
    numpy.ndarray
        ``uint8`` or ``uint16`` array of the same shape; ``round(clip(image, 0, 1) * (2**used_bits - 1))``
        with ties to even.

    Raises
    ------
    InvalidParameter
        ``bit_depth`` is not 8 or 16, or ``image`` is not real-valued or holds NaN/inf.

    Examples
    --------
    >>> to_uint(np.array([0.0, 0.2, 1.0, 1.5]), 8)
    array([  0,  51, 255, 255], dtype=uint8)
    """
    dtype = _uint_dtype(bit_depth)
    arr = np.asarray(image)
    if not (
        np.issubdtype(arr.dtype, np.floating) or np.issubdtype(arr.dtype, np.integer) or arr.dtype == bool
    ):
        raise InvalidParameter("image", f"array of {arr.dtype}", "must hold real numbers")
    work = arr.astype(np.promote_types(arr.dtype, np.float32), copy=False)
    if not np.all(np.isfinite(work)):
        raise InvalidParameter("image", "array with NaN/inf", "must hold finite values to be saved")
    full_scale = np.iinfo(dtype).max
    if used_bits is not None:
        if isinstance(used_bits, bool) or not isinstance(used_bits, int) or not 1 <= used_bits <= bit_depth:
            raise InvalidParameter("used_bits", used_bits, f"must be an integer in [1, {bit_depth}]")
        full_scale = 2**used_bits - 1
    return np.rint(np.clip(work, 0.0, 1.0) * full_scale).astype(dtype)


def image_to_png_bytes(image: np.ndarray, bit_depth: int = 8, *, used_bits: int | None = None) -> bytes:
    """Encode a float image in [0, 1] as PNG bytes (the service's previews and downloads).

    Parameters
    ----------
    image : numpy.ndarray
        ``(H, W)`` grey or ``(H, W, 3)`` RGB, values clipped to [0, 1].
    bit_depth : {8, 16}
        16 is available for grey images only: Pillow neither writes nor reads 16 bits per RGB
        channel, so 16-bit colour is written as TIFF (:func:`save_image` with a ``.tif`` path).
    used_bits : int, optional
        Bits of the container the values use (:func:`to_uint`).

    Returns
    -------
    bytes
        A PNG file.

    Raises
    ------
    InvalidParameter
        Bad bit depth, bad shape, NaN/inf, or 16-bit RGB.
    """
    quantised = to_uint(_savable_image(image), bit_depth, used_bits=used_bits)
    if bit_depth == 16 and quantised.ndim == 3:
        raise InvalidParameter(
            "bit_depth", bit_depth, "16-bit PNG is for grey images only; save 16-bit RGB as .tif"
        )
    buf = io.BytesIO()
    Image.fromarray(quantised).save(buf, format="PNG")
    return buf.getvalue()


def save_image(
    path: str | os.PathLike[str], image: np.ndarray, *, bit_depth: int = 8, used_bits: int | None = None
) -> None:
    """Write a float image in [0, 1] as PNG (``.png``) or TIFF (``.tif``/``.tiff``), atomically.

    Parameters
    ----------
    path : str or os.PathLike
        Destination; its extension picks the format. The file appears complete or not at all.
    image : numpy.ndarray
        ``(H, W)`` grey or ``(H, W, 3)`` RGB; values are clipped to [0, 1] and rounded.
    bit_depth : {8, 16}
        Bits per channel. 16-bit PNG is grey only (see :func:`image_to_png_bytes`); 16-bit TIFF
        takes grey or RGB.
    used_bits : int, optional
        Bits of the container the values use (:func:`to_uint`): 12 writes 12-bit data in 16 bits.

    Raises
    ------
    InvalidParameter
        Unknown extension, bit depth other than 8 or 16, bad image, or the file cannot be written.

    Notes
    -----
    TIFFs are written uncompressed, readable by every TIFF reader (Fiji, Pillow, tifffile).
    """
    target = Path(path)
    suffix = target.suffix.lower()
    _uint_dtype(bit_depth)
    if suffix == ".png":
        data = image_to_png_bytes(image, bit_depth, used_bits=used_bits)
    elif suffix in (".tif", ".tiff"):
        quantised = to_uint(_savable_image(image), bit_depth, used_bits=used_bits)
        buf = io.BytesIO()
        tifffile.imwrite(buf, quantised, photometric="rgb" if quantised.ndim == 3 else "minisblack")
        data = buf.getvalue()
    else:
        raise InvalidParameter("path", str(path), "extension must be .png, .tif or .tiff")
    atomic_write_bytes(target, data)


def save_volume(
    path: str | os.PathLike[str],
    volume: np.ndarray,
    *,
    bit_depth: int = 16,
    voxel_size: float | tuple[float, float, float] | None = None,
    unit: str = "nm",
    used_bits: int | None = None,
    progress: Callable[[str, float], None] | None = None,
) -> None:
    """Write a ``(D, H, W)`` volume as a multi-page TIFF stack that Fiji opens with D slices, atomically.

    Parameters
    ----------
    path : str or os.PathLike
        Destination ending in ``.tif`` or ``.tiff``.
    volume : numpy.ndarray
        ``(D, H, W)`` grey volume in [0, 1]; values are clipped and rounded.
    bit_depth : {8, 16}
        Bits per voxel.
    voxel_size : float or (float, float, float), optional
        The size of a voxel in ``unit``: one value for cubic voxels, or ``(z, y, x)`` in array order.
        Written as ImageJ calibration, so that Fiji shows lengths in ``unit`` and its 3-D viewers keep
        the proportions: ``spacing`` (z) in the ImageJ description, ``XResolution``/``YResolution``
        (pixels per unit, the TIFF tags ImageJ reads) for x and y. ``None`` writes no calibration.
    unit : str
        The length unit of ``voxel_size`` (``'nm'`` by default; ``'um'``, ``'micron'``, ...), stored as
        ImageJ's ``unit``.
    used_bits : int, optional
        Bits of the container the values use (:func:`to_uint`).
    progress : callable ``(stage, fraction)``, optional
        Told the fraction of the slices written.

    Raises
    ------
    InvalidParameter
        Wrong extension or shape, bit depth other than 8 or 16, a voxel size that is not one or three
        positive numbers, an empty unit or one holding a line break, NaN/inf, or the file cannot be
        written.

    Notes
    -----
    One page per z-slice, with ImageJ metadata (``images=D, slices=D``, axes ``ZYX``) so that Fiji
    and ImageJ show a z-stack rather than a time series; uncompressed, as ImageJ writes its own.
    Read the calibration back with :mod:`tifffile`: ``TiffFile.imagej_metadata['spacing']`` and
    ``['unit']``, and ``TiffPage.resolution`` (pixels per unit along x, y).
    """
    target = Path(path)
    if target.suffix.lower() not in (".tif", ".tiff"):
        raise InvalidParameter("path", str(path), "a volume is saved as a TIFF stack: use .tif or .tiff")
    _uint_dtype(bit_depth)
    arr = np.asarray(volume)
    if arr.ndim != 3 or 0 in arr.shape:
        raise InvalidParameter("volume", f"shape {arr.shape}", "must be a non-empty (D, H, W) grey volume")
    metadata: dict[str, object] = {"axes": "ZYX"}
    options: dict[str, object] = {}
    if voxel_size is not None:
        size_z, size_y, size_x = _voxel_size(voxel_size)
        if not isinstance(unit, str) or not unit.strip() or any(c in unit for c in "\r\n="):
            raise InvalidParameter("unit", unit, "must be a non-empty length unit such as 'nm' or 'um'")
        metadata.update(spacing=size_z, unit=unit.strip())
        options["resolution"] = (1.0 / size_x, 1.0 / size_y)
    dtype = _uint_dtype(bit_depth)

    # Quantised and written one page (z-slice) at a time: a 512^3 volume is never copied whole, and
    # an error in any slice (NaN) is raised before the file appears. The bytes are those of one
    # ``tifffile.imwrite`` of the whole quantised stack (tested).
    def pages() -> Iterator[np.ndarray]:
        for z in range(arr.shape[0]):
            yield to_uint(arr[z], bit_depth, used_bits=used_bits)
            if progress is not None and ((z + 1) % 16 == 0 or z + 1 == arr.shape[0]):
                progress("writing output.tiff", (z + 1) / arr.shape[0])

    with atomic_writer(target) as fh, tifffile.TiffWriter(fh, imagej=True) as tif:
        # photometric explicitly: tifffile would store a stack whose last axis is 3 or 4 long as RGB
        tif.write(
            pages(),
            shape=arr.shape,
            dtype=dtype,
            photometric="minisblack",
            metadata=metadata,
            **options,
        )


def sample_bits(source: ImageSource, *, name: str | None = None) -> int:
    """Bits per sample an image file stores (1, 8, 16, 32), read from its header only.

    What a person means by an image's bit depth: an 8-bit PNG says 8, a 16-bit TIFF 16, a float TIFF
    32. Used to refuse per-plane exemplars of different depths, whose grey levels would not compare.
    """
    data, label = _read_source(source, name, default_name="image")
    if sniff_format(data) == "TIFF":
        try:
            with tifffile.TiffFile(io.BytesIO(data)) as tif:
                return int(tif.pages.first.bitspersample)
        except Exception:
            pass
    try:
        with Image.open(io.BytesIO(data)) as im:
            mode = im.mode
    except (UnidentifiedImageError, OSError, SyntaxError, ValueError):
        raise UnsupportedFormat(label, f"not an image format texsynth reads ({_SUPPORTED_TEXT})") from None
    if mode == "1":
        return 1
    if mode.startswith("I;16"):
        return 16
    return 32 if mode in ("I", "F") else 8


def _voxel_size(voxel_size: float | tuple[float, float, float]) -> tuple[float, float, float]:
    """``(z, y, x)`` from one size or three; positive and finite, else :class:`InvalidParameter`."""
    try:
        values = np.broadcast_to(np.asarray(voxel_size, dtype=np.float64), (3,))
    except (TypeError, ValueError):
        values = None
    if values is None or np.ndim(voxel_size) > 1 or not np.all(np.isfinite(values) & (values > 0)):
        raise InvalidParameter(
            "voxel_size", voxel_size, "must be one positive size or three, (z, y, x), in the given unit"
        )
    return float(values[0]), float(values[1]), float(values[2])


# --------------------------------------------------------------------------------------------
# helpers: sources, limits, shapes


def _read_source(source: ImageSource, name: str | None, *, default_name: str) -> tuple[bytes, str]:
    """The bytes of ``source`` and the label that error messages use for it."""
    if isinstance(source, bytes | bytearray | memoryview):
        data, label = bytes(source), name or default_name
    elif isinstance(source, str | os.PathLike):
        label = name or os.fspath(source)
        try:
            data = Path(source).read_bytes()
        except FileNotFoundError:
            raise InvalidInput(label, "no such file") from None
        except IsADirectoryError:
            raise InvalidInput(label, "is a directory, not an image file") from None
        except PermissionError:
            raise InvalidInput(label, "permission denied") from None
        except OSError as exc:
            raise InvalidInput(label, f"cannot be read ({exc.strerror or exc})") from None
    else:
        raise InvalidParameter("source", type(source).__name__, "must be a file path or the file's bytes")
    if not data:
        raise InvalidInput(label, "empty file (0 bytes)")
    return data, label


def sniff_format(data: bytes) -> str | None:
    """The format (``'PNG'``, ``'TIFF'``, ``'JPEG'``) the leading bytes announce, or None.

    Judged from the bytes, never from a file name or a client's content type: the service stores
    and serves uploads by this (issue 14: an ``evil.html`` upload must not come back as a page).
    """
    for magic, fmt in _MAGIC.items():
        if data.startswith(magic):
            return fmt
    return None


def _describe(exc: BaseException) -> str:
    text = str(exc).strip().strip("'\"")
    return text or type(exc).__name__


def _missing_codec(exc: BaseException) -> bool:
    """Whether tifffile failed for want of an optional codec package (not because the data are bad)."""
    return isinstance(exc, ImportError) or "imagecodecs" in str(exc)


def _codec_message(page: tifffile.TiffPage) -> str:
    compression = getattr(page.compression, "name", str(page.compression))
    return (
        f"TIFF compression {compression} cannot be decoded here; save the file uncompressed or with Deflate"
    )


# --------------------------------------------------------------------------------------------
# helpers: decoding


def _decode_tiff_image(
    data: bytes, label: str, max_pixels: int
) -> tuple[tuple[np.ndarray, InputBits] | None, str | None]:
    """Decode a 2-D TIFF with tifffile; ``(None, reason)`` means "let Pillow try" (codec, colour model)."""
    try:
        with tifffile.TiffFile(io.BytesIO(data)) as tif:
            series = tif.series[0]
            page = series.pages[0]
            shape, axes = tuple(series.shape), series.axes
            if 0 in shape:
                raise InvalidInput(label, f"the image has zero size (shape {shape})")
            planar = axes == "SYX"
            if planar:
                shape, axes = (*shape[1:], shape[0]), "YXS"
            if axes not in ("YX", "YXS"):
                hint = " (a stack: use load_volume)" if len(shape) == 3 and "S" not in axes else ""
                raise InvalidInput(
                    label, f"has shape {shape} (axes {axes}); a single 2-D grey or RGB image is needed{hint}"
                )
            height, width = shape[:2]
            channels = shape[2] if axes == "YXS" else 1
            if channels > 4:
                raise InvalidInput(
                    label, f"has {channels} channels; at most 4 (grey, grey+alpha, RGB, RGBA) are supported"
                )
            check_image_shape(label, height, width, max_pixels)
            photometric = page.photometric
            palette = photometric == tifffile.PHOTOMETRIC.PALETTE and channels == 1
            if not palette and photometric not in _TIFF_DIRECT_PHOTOMETRIC:
                return None, f"photometric {getattr(photometric, 'name', photometric)}"
            try:
                raw = series.asarray()
            except (KeyError, ValueError, ImportError) as exc:
                if _missing_codec(exc):
                    return None, _codec_message(page)
                raise
            if planar:
                raw = np.moveaxis(raw, 0, -1)
            colormap = page.colormap if palette else None
            bits = page.bitspersample
    except SynthError:
        raise
    except _DECODE_ERRORS as exc:
        raise InvalidInput(label, f"corrupt or truncated TIFF data ({_describe(exc)})") from None
    if colormap is not None:
        rgb = np.moveaxis(_colormap_to_unit(colormap)[:, raw], 0, -1)
        return (np.ascontiguousarray(rgb), InputBits(8, 8)), None
    if raw.ndim == 3:
        raw = raw[..., :1] if raw.shape[2] <= 2 else raw[..., :3]  # drop alpha / extra samples
        if raw.shape[2] == 1:
            raw = raw[..., 0]
    image, depth = _to_unit_float(raw, label, bits=bits)
    if photometric == tifffile.PHOTOMETRIC.MINISWHITE:
        image = 1.0 - image
    return (image, depth), None


def _colormap_to_unit(colormap: np.ndarray) -> np.ndarray:
    """A TIFF colour map ``(3, 2**bits)`` as float32 in [0, 1].

    The map is 16-bit by the standard, but many writers (Pillow among them) store 8-bit colours as
    ``v * 256``, and some as plain 8-bit values: both are recognised, as libtiff and Pillow do.
    """
    cmap = colormap.astype(np.uint32)
    if not np.any(cmap & 0xFF):
        return (cmap >> 8).astype(np.float32) / np.float32(255)
    if cmap.max() < 256:
        return cmap.astype(np.float32) / np.float32(255)
    return cmap.astype(np.float32) / np.float32(65535)


def _decode_with_pillow(
    data: bytes, label: str, max_pixels: int, *, tiff_reason: str | None
) -> tuple[np.ndarray, InputBits]:
    """Open, check the format and size from the header, verify, reopen, load, convert."""
    fmt = None
    try:
        with warnings.catch_warnings():
            # Pillow only warns between 1x and 2x MAX_IMAGE_PIXELS: make it an error, here only.
            warnings.simplefilter("error", Image.DecompressionBombWarning)
            with Image.open(io.BytesIO(data)) as im:
                fmt = im.format
                if fmt not in _PILLOW_FORMATS:
                    raise UnsupportedFormat(label, f"{fmt} images are not supported (use {_SUPPORTED_TEXT})")
                check_image_shape(label, im.height, im.width, max_pixels)
                im.verify()
            with Image.open(io.BytesIO(data)) as im:
                im.load()
                return _pillow_to_float(im, label)
    except SynthError:
        raise
    except (Image.DecompressionBombError, Image.DecompressionBombWarning) as exc:
        raise InputTooLarge(
            label, f"too many pixels to decode safely, possible decompression bomb ({exc})"
        ) from None
    except UnidentifiedImageError:
        if tiff_reason:
            raise UnsupportedFormat(label, f"cannot decode this TIFF ({tiff_reason})") from None
        announced = sniff_format(data)
        if announced:
            raise InvalidInput(
                label, f"corrupt or truncated {announced} data (the header cannot be read)"
            ) from None
        raise UnsupportedFormat(label, f"not an image in a supported format ({_SUPPORTED_TEXT})") from None
    except _DECODE_ERRORS as exc:
        what = fmt or sniff_format(data) or "image"
        raise InvalidInput(label, f"corrupt or truncated {what} data ({_describe(exc)})") from None


def _pillow_to_float(im: Image.Image, label: str) -> tuple[np.ndarray, InputBits]:
    """A loaded Pillow image as float in [0, 1], ``(H, W)`` or ``(H, W, 3)``, alpha dropped."""
    mode = im.mode
    if mode in ("P", "PA"):
        im, mode = im.convert("RGBA"), "RGBA"
    if mode in ("1", "L", "RGB", "F", "I") or mode.startswith("I;16"):
        arr = np.asarray(im)
    elif mode == "LA":
        arr = np.asarray(im)[..., 0]
    elif mode in ("RGBA", "RGBX"):
        arr = np.asarray(im)[..., :3]
    else:  # CMYK, YCbCr, LAB, HSV, premultiplied alpha, ...
        arr = np.asarray(im.convert("RGB"))
    return _to_unit_float(arr, label)


def _to_unit_float(arr: np.ndarray, label: str, *, bits: int | None = None) -> tuple[np.ndarray, InputBits]:
    """Unsigned integers by the depth they use (:mod:`texsynth.synth.io.depth`); floats and signed counts
    checked and rescaled."""
    if arr.dtype == bool or np.issubdtype(arr.dtype, np.unsignedinteger):
        return unsigned_to_unit(arr, bits=bits)
    if not (np.issubdtype(arr.dtype, np.floating) or np.issubdtype(arr.dtype, np.signedinteger)):
        raise InvalidInput(label, f"unsupported sample type {arr.dtype}")
    if np.issubdtype(arr.dtype, np.floating):
        if np.isnan(arr).any():
            raise InvalidInput(label, "contains NaN values; only finite numbers are accepted")
        if np.isinf(arr).any():
            raise InvalidInput(label, "contains infinite (inf) values; only finite numbers are accepted")
    lo, hi = arr.min(), arr.max()
    if lo >= 0 and hi <= 1:
        return arr.astype(np.float32), FLOAT_BITS
    if hi == lo:
        return np.zeros(arr.shape, np.float32), FLOAT_BITS
    work = arr.astype(np.float64)
    return ((work - float(lo)) / (float(hi) - float(lo))).astype(np.float32), FLOAT_BITS


def _apply_mode(image: np.ndarray, mode: LoadMode) -> np.ndarray:
    """Grey/RGB according to ``mode``; C-contiguous float32 clipped to [0, 1]."""
    if image.ndim == 3:
        if mode == "grey":
            image = to_grey(image)
        elif (
            mode == "auto"
            and np.array_equal(image[..., 0], image[..., 1])
            and np.array_equal(image[..., 1], image[..., 2])
        ):
            image = image[..., 0]
    elif mode == "rgb":
        image = np.repeat(image[..., np.newaxis], 3, axis=2)
    out = np.ascontiguousarray(image, dtype=np.float32)
    np.clip(out, 0.0, 1.0, out=out)
    return out


# --------------------------------------------------------------------------------------------
# helpers: saving


def _uint_dtype(bit_depth: int) -> type[np.unsignedinteger]:
    if isinstance(bit_depth, bool) or bit_depth not in (8, 16):
        raise InvalidParameter("bit_depth", bit_depth, "must be 8 or 16")
    return np.uint8 if bit_depth == 8 else np.uint16


def _savable_image(image: np.ndarray) -> np.ndarray:
    """``image`` as ``(H, W)`` or ``(H, W, 3)`` (a trailing single channel is dropped), else an error."""
    arr = np.asarray(image)
    if arr.ndim == 3 and arr.shape[2] == 1:
        arr = arr[..., 0]
    if not (arr.ndim == 2 or (arr.ndim == 3 and arr.shape[2] == 3)) or 0 in arr.shape:
        raise InvalidParameter(
            "image", f"shape {arr.shape}", "must be a non-empty (H, W) grey or (H, W, 3) RGB image"
        )
    return arr
