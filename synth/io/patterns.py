"""Generated test patterns: fringes with known orientation fields, and two-phase media with known statistics.

Exemplars with long-range orientation variation (the case where Wei-Levoy comes out too regular,
Akl 2014) and constraint images (waves, concentric rings, spirals) for arbitrary-shape synthesis.
Each returns a float32 image in [0, 1] of laminae of period ``period`` pixels, whose *fringe*
direction is known in closed form, so tests and benchmarks can vary them freely.

:func:`gaussian_random_field` makes an anisotropic two-phase image or volume whose two-point
correlation along each axis is known in closed form
(:func:`texsynth.synth.evaluate.correlation.level_cut_s2`): a known answer for the whole solid-synthesis path.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from texsynth.synth.errors import InvalidParameter

__all__ = [
    "concentric_rings",
    "gaussian_random_field",
    "grating",
    "laminae_volume",
    "spiral",
    "undulating_laminae",
    "voronoi_cells",
    "waves",
    "wood_grain",
]


def _coords(shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Pixel coordinates with ``x`` to the right and ``y`` up (ALGORITHMS.md)."""
    rows, cols = np.mgrid[0 : shape[0], 0 : shape[1]].astype(np.float64)
    return cols, -rows


def _finish(phase: np.ndarray, noise: float, seed: int) -> np.ndarray:
    img = 0.5 + 0.5 * np.cos(phase)
    if noise > 0:
        img = img + np.random.default_rng(seed).normal(0.0, noise, img.shape)
    img = (img - img.min()) / max(img.max() - img.min(), 1e-12)
    return img.astype(np.float32)


def grating(
    shape: tuple[int, int], angle: float, period: float = 8.0, *, noise: float = 0.0, seed: int = 0
) -> np.ndarray:
    """Straight fringes whose *gradient* points at ``angle`` (radians, counter-clockwise from +x)."""
    x, y = _coords(shape)
    return _finish(2 * np.pi * (x * np.cos(angle) + y * np.sin(angle)) / period, noise, seed)


def undulating_laminae(
    shape: tuple[int, int],
    period: float = 8.0,
    amplitude: float = 10.0,
    wavelength: float = 64.0,
    *,
    noise: float = 0.15,
    seed: int = 0,
) -> np.ndarray:
    """Horizontal laminae bent by a sine of ``amplitude`` px over ``wavelength`` px (curved fringes)."""
    x, y = _coords(shape)
    return _finish(2 * np.pi * (y + amplitude * np.sin(2 * np.pi * x / wavelength)) / period, noise, seed)


def laminae_volume(
    shape: tuple[int, int, int],
    normal: Sequence[float] = (1.0, 0.0, 0.0),
    period: float = 8.0,
    amplitude: float = 6.0,
    wavelength: float = 64.0,
    *,
    noise: float = 0.15,
    seed: int = 0,
) -> np.ndarray:
    """Bent sheets in a volume ``(D, H, W) = (z, y, x)``: the 3D laminae whose slices are laminae.

    The phase is ``2 pi (n . r + a sin(2 pi u / lambda) + a sin(2 pi v / lambda)) / period`` with ``r =
    (z, y, x)`` in voxels, ``n`` the unit ``normal`` of the sheets and ``u``, ``v`` two coordinates
    across them (orthonormal to ``n``), so the sheets undulate both ways by ``amplitude`` voxels over
    ``wavelength``; grey ``0.5 + 0.5 cos(phase)`` plus Gaussian ``noise``, rescaled to [0, 1].

    Every slice of such a volume is a laminae image, and its three orthogonal mid-slices are mutually
    consistent per-plane exemplars (a material that exists): with ``normal=(1, 0, 0)`` the xz and yz
    slices show bent horizontal laminae and the xy slices cut the sheets into contour bands. With
    ``normal=(1, 1, 1)`` the three planes show the same laminae running diagonally: the one uniaxial
    layout that a single laminae exemplar can describe on all three planes (docs/solid.md).
    """
    dims = tuple(int(s) for s in shape)
    if len(dims) != 3 or any(s < 2 for s in dims):
        raise InvalidParameter("shape", tuple(shape), "must be (D, H, W) with every side at least 2")
    n = np.asarray(normal, dtype=np.float64)
    if n.shape != (3,) or not np.all(np.isfinite(n)) or np.linalg.norm(n) == 0:
        raise InvalidParameter("normal", tuple(normal), "must be three finite numbers, not all zero")
    n = n / np.linalg.norm(n)
    helper = np.eye(3)[int(np.argmin(np.abs(n)))]
    u = np.cross(n, helper)
    u /= np.linalg.norm(u)
    v = np.cross(n, u)
    z, y, x = np.meshgrid(*(np.arange(s, dtype=np.float64) for s in dims), indexing="ij")
    along = n[0] * z + n[1] * y + n[2] * x
    cu = u[0] * z + u[1] * y + u[2] * x
    cv = v[0] * z + v[1] * y + v[2] * x
    bend = amplitude * (np.sin(2 * np.pi * cu / wavelength) + np.sin(2 * np.pi * cv / wavelength))
    return _finish(2 * np.pi * (along + bend) / period, noise, seed)


def wood_grain(
    shape: tuple[int, int],
    fibre_width: float = 5.0,
    amplitude: float = 4.0,
    wavelength: float = 96.0,
    *,
    noise: float = 0.03,
    seed: int = 0,
) -> np.ndarray:
    """Long, nearly vertical fibres with their own grey levels (a wood-grain or fibre-bundle texture).

    Fibre ``k`` occupies ``k w <= u < (k + 1) w`` with ``u = x + amplitude sin(2 pi y / wavelength)``
    (gently wavy fibres across the whole image); each fibre has a random grey level in [0.3, 0.7] and a
    slow variation along its length, the boundaries between fibres are dark lines one or two pixels
    wide, plus Gaussian ``noise``; rescaled to [0, 1]. The strands run the image's full height: the
    exemplar for measuring whether a method keeps long fibres continuous (issue 13).
    """
    rng = np.random.default_rng(seed)
    rows, cols = np.mgrid[0 : shape[0], 0 : shape[1]].astype(np.float64)
    u = cols + amplitude * np.sin(2 * np.pi * rows / wavelength) + amplitude
    fibre = np.floor(u / fibre_width).astype(np.int64)
    levels = rng.uniform(0.3, 0.7, int(fibre.max()) + 1)
    phases = rng.uniform(0, 2 * np.pi, int(fibre.max()) + 1)
    along = 0.08 * np.sin(2 * np.pi * rows / (2.5 * wavelength) + phases[fibre])
    frac = u / fibre_width - fibre
    boundary = np.exp(-0.5 * (np.minimum(frac, 1 - frac) * fibre_width / 0.7) ** 2)
    img = levels[fibre] + along - 0.25 * boundary + rng.normal(0.0, noise, shape)
    img = (img - img.min()) / max(img.max() - img.min(), 1e-12)
    return img.astype(np.float32)


def waves(
    shape: tuple[int, int],
    period: float = 8.0,
    amplitude: float = 16.0,
    wavelength: float = 128.0,
    *,
    noise: float = 0.0,
    seed: int = 0,
) -> np.ndarray:
    """A wave constraint: the same bent laminae, larger and without noise by default."""
    return undulating_laminae(shape, period, amplitude, wavelength, noise=noise, seed=seed)


def concentric_rings(
    shape: tuple[int, int],
    period: float = 8.0,
    centre: tuple[float, float] | None = None,
    *,
    noise: float = 0.0,
    seed: int = 0,
) -> np.ndarray:
    """Rings around ``centre`` (row, col; default the middle): fringes run tangentially."""
    rows, cols = np.mgrid[0 : shape[0], 0 : shape[1]].astype(np.float64)
    cy, cx = centre if centre is not None else ((shape[0] - 1) / 2, (shape[1] - 1) / 2)
    return _finish(2 * np.pi * np.hypot(rows - cy, cols - cx) / period, noise, seed)


def spiral(
    shape: tuple[int, int], period: float = 8.0, arms: int = 1, *, noise: float = 0.0, seed: int = 0
) -> np.ndarray:
    """An Archimedean spiral of ``arms`` arms and radial period ``period``."""
    rows, cols = np.mgrid[0 : shape[0], 0 : shape[1]].astype(np.float64)
    dy, dx = rows - (shape[0] - 1) / 2, cols - (shape[1] - 1) / 2
    return _finish(2 * np.pi * np.hypot(dy, dx) / period + arms * np.arctan2(-dy, dx), noise, seed)


def gaussian_random_field(
    shape: Sequence[int],
    correlation_lengths: float | Sequence[float],
    volume_fraction: float = 0.5,
    *,
    seed: int = 0,
) -> np.ndarray:
    """A two-phase image or volume: a level cut of an anisotropic Gaussian random field.

    White noise is filtered in Fourier space by a Gaussian of standard deviation ``l_k / 2`` along
    axis ``k`` (periodic boundaries), which gives a stationary Gaussian field whose correlation is
    ``rho(r) = exp(-sum_k (r_k / l_k)^2)``: along axis ``k`` alone, ``exp(-(r / l_k)^2)``. The field is
    cut so that exactly ``round(volume_fraction * size)`` voxels, its largest values, form phase 1.

    Parameters
    ----------
    shape : sequence of int
        ``(H, W)`` or ``(D, H, W)``; each side at least 2.
    correlation_lengths : float or sequence of float
        ``l_k`` per axis in voxels (one value: isotropic). Keep them well below the sides: the field
        is periodic, and a length near the side correlates the sample with itself.
    volume_fraction : float
        ``phi``, the share of phase 1, in (0, 1).
    seed : int
        Seed of the white noise (:func:`numpy.random.default_rng`): same arguments, same bytes.

    Returns
    -------
    ndarray of float32
        1.0 in phase 1, 0.0 elsewhere; shape ``shape``.

    Notes
    -----
    The two-point correlation of phase 1 along axis ``k`` is then that of a level-cut Gaussian field
    (Berk 1987; Teubner 1991; Torquato 2002, section 2.5.4),
    :func:`texsynth.synth.evaluate.correlation.level_cut_s2` with ``correlation_length = l_k``, up to the
    sampling error of a finite sample: the correlation lengths of ``S2`` per axis are in the ratios
    of ``l_k``.

    References
    ----------
    S. Torquato, *Random Heterogeneous Materials: Microstructure and Macroscopic Properties*,
    Springer, New York, 2002, section 2.5.4.
    M. Teubner, "Level surfaces of Gaussian random fields and microemulsions", Europhysics Letters
    14(5), 1991, 403-408.

    Examples
    --------
    >>> vol = gaussian_random_field((16, 16, 32), (2.0, 2.0, 6.0), 0.3, seed=1)
    >>> vol.shape, float(vol.mean())
    ((16, 16, 32), 0.300048828125)
    """
    dims = tuple(int(s) for s in shape)
    if len(dims) not in (2, 3) or any(s < 2 for s in dims):
        raise InvalidParameter(
            "shape", tuple(shape), "must be (H, W) or (D, H, W) with every side at least 2"
        )
    given = np.asarray(correlation_lengths, dtype=np.float64)
    if given.ndim > 1 or (given.ndim == 1 and given.size != len(dims)):
        raise InvalidParameter(
            "correlation_lengths", correlation_lengths, f"needs one value or {len(dims)} (one per axis)"
        )
    lengths = np.broadcast_to(given, (len(dims),))
    if not np.all(np.isfinite(lengths) & (lengths > 0)):
        raise InvalidParameter(
            "correlation_lengths", correlation_lengths, "must be positive lengths in voxels"
        )
    if not (isinstance(volume_fraction, int | float) and 0 < volume_fraction < 1):
        raise InvalidParameter("volume_fraction", volume_fraction, "must lie strictly between 0 and 1")
    noise = np.random.default_rng(seed).standard_normal(dims)
    spectrum = np.fft.rfftn(noise)
    # the transfer function of a Gaussian of standard deviation sigma = l / 2: exp(-2 pi^2 sigma^2 k^2)
    transfer = np.ones(spectrum.shape)
    for k, (n, length) in enumerate(zip(dims, lengths, strict=True)):
        freq = np.fft.rfftfreq(n) if k == len(dims) - 1 else np.fft.fftfreq(n)
        gauss = np.exp(-2.0 * math.pi**2 * (length / 2.0) ** 2 * freq**2)
        transfer = transfer * gauss.reshape([-1 if j == k else 1 for j in range(len(dims))])
    field = np.fft.irfftn(spectrum * transfer, s=dims, axes=tuple(range(len(dims))))
    n_phase = round(volume_fraction * field.size)
    out = np.zeros(field.size, dtype=np.float32)
    if n_phase > 0:
        out[np.argsort(field, axis=None, kind="stable")[field.size - n_phase :]] = 1.0
    return out.reshape(dims)


def voronoi_cells(
    shape: tuple[int, int],
    cell_size: float = 16.0,
    wall: float = 1.5,
    *,
    noise: float = 0.05,
    seed: int = 0,
) -> np.ndarray:
    """A cell-like texture with known curvilinear features: dark walls on the edges of a Voronoi diagram.

    The cell centres lie on a square grid of spacing ``cell_size`` px, each moved uniformly by up to
    0.4 of the spacing (a jittered grid, so that cells have similar sizes); the grid covers one cell
    beyond the image so that border cells are whole. A pixel at distances ``d1 <= d2`` from its two
    nearest centres lies ``(d2 - d1) / 2`` px (to first order) from the wall between them; the wall is
    a Gaussian dip of standard deviation ``wall`` px in that distance, and each cell's interior a
    slightly different grey. The walls form a closed network with no free ends (every feature
    endpoint in a synthesized image of it is a break), the features that
    :func:`texsynth.synth.evaluate.breaks.broken_features` counts.

    Returns a float32 image in [0, 1] (walls dark).

    Examples
    --------
    >>> img = voronoi_cells((64, 64), seed=1)
    >>> img.shape, img.dtype.name, float(img.min()) >= 0.0, float(img.max()) <= 1.0
    ((64, 64), 'float32', True, True)
    """
    from scipy.spatial import cKDTree

    if len(tuple(shape)) != 2 or min(int(s) for s in shape) < 2:
        raise InvalidParameter("shape", tuple(shape), "must be (H, W) with every side at least 2")
    for name, value in (("cell_size", cell_size), ("wall", wall)):
        if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
            raise InvalidParameter(name, value, "must be a positive number of pixels")
    if not (isinstance(noise, int | float) and math.isfinite(noise) and noise >= 0):
        raise InvalidParameter("noise", noise, "must be a number >= 0")
    h, w = int(shape[0]), int(shape[1])
    rng = np.random.default_rng(seed)
    gy, gx = np.mgrid[-1 : h / cell_size + 1, -1 : w / cell_size + 1]
    centres = (np.stack([gy.ravel(), gx.ravel()], axis=1) + 0.5) * cell_size
    centres += rng.uniform(-0.4, 0.4, centres.shape) * cell_size
    rows, cols = np.mgrid[0:h, 0:w].astype(np.float64)
    dist, idx = cKDTree(centres).query(np.stack([rows.ravel(), cols.ravel()], axis=1), k=2)
    to_wall = (dist[:, 1] - dist[:, 0]) / 2.0
    shade = rng.uniform(0.75, 0.95, len(centres))[idx[:, 0]]
    img = shade - 0.6 * np.exp(-0.5 * (to_wall / wall) ** 2)
    if noise > 0:
        img = img + rng.normal(0.0, noise, img.shape)
    img = (img - img.min()) / max(img.max() - img.min(), 1e-12)
    return img.reshape(h, w).astype(np.float32)
