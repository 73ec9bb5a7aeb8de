"""Laminar structure first: a volume of continuous curved sheets to start a solid synthesis from.

The first of the two stages of Akl et al. (ICIP 2014), carried to 3D (ALGORITHMS.md section 8): before
the texture optimisation, synthesize the *structure*, here a laminar phase field. A smooth Gaussian
random field ``g`` of correlation length ``L`` is cut at its zero level; ``phi`` is the signed Euclidean
distance to that surface, so ``|grad phi| = 1`` away from the medial surfaces, and the volume
``cos(2 pi phi / lambda)`` is a stack of sheets of period ``lambda`` parallel to a curved surface: nested
shells around the field's blobs (onion-like), bent stacks along its saddles, meeting at kinks. Its slices
show fringes of period ``lambda / |n_plane|`` on every plane, with a uniform orientation distribution
(an isotropic material, the case of one exemplar for the three planes).

``lambda`` is the exemplar's dominant period (:func:`dominant_period`: the peak of the radially averaged
power spectrum between :data:`MIN_PERIOD` px and a quarter of the exemplar); ``L`` is given in periods.
The texture stage (the solid methods) then starts from this volume, its grey levels rank-remapped onto
the exemplar's, at the finest pyramid levels where the period is still at least :data:`MIN_PERIOD` px
(a Gaussian pyramid blurs a 6 px period away after two levels; :func:`structure_levels`).

References
----------
A. Akl, C. Yaacoub, M. Donias, J.-P. Da Costa, C. Germain, "Structure tensor based synthesis of
directional textures for virtual material design", ICIP 2014: the structure layer first, then the texture.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence

import numpy as np
from scipy import ndimage as ndi

from synth.analysis.tensor import mean_coherence, structure_tensor
from synth.colour import to_grey

__all__ = [
    "ISOTROPIC_MAX",
    "MIN_PERIOD",
    "PILOT_COHERENCE",
    "START_COHERENCE",
    "dominant_period",
    "laminar_phase",
    "laminar_volume",
    "level_phase",
    "mean_tensor_coherence",
    "sheets",
    "starts_laminar",
    "structure_levels",
]

#: Shortest period (px) a pyramid level must keep to carry fringes (2 px is Nyquist; 3 keeps a profile).
MIN_PERIOD = 3.0
#: An exemplar is isotropic when the coherence of its mean structure tensor is below this (its fringes run
#: every way): onion truth 0.08, turbostratic 0.11, real onion crop 0.15, soot 0.24; bent laminae 0.50,
#: diagonal laminae 0.99. Only an isotropic exemplar fits the isotropic sheets of :func:`laminar_phase`.
ISOTROPIC_MAX = 0.3
#: ... and laminar enough when its mean coherence reaches this (onion truths 0.68-0.82; the real onion crop
#: 0.52 and soot 0.39-0.46 stay below: their fringes are short, the sheets would be too long).
START_COHERENCE = 0.6
#: Between this and :data:`START_COHERENCE` the exemplar is ambiguous (short fringes: soot crops 0.43-0.50,
#: real onion crops 0.47-0.52) and a pilot decides (:func:`starts_laminar`); below it (soot-128 0.39, and
#: no pilot cost) the paper's random start.
PILOT_COHERENCE = 0.45


def mean_tensor_coherence(image: np.ndarray) -> float:
    """Coherence of the mean structure tensor: 0 when the orientations are evenly spread, 1 for one."""
    t = structure_tensor(to_grey(image), 1.0, 3.0).reshape(-1, 3).mean(axis=0, dtype=np.float64)
    a, b, c = (float(v) for v in t)
    return float(np.hypot(a - c, 2.0 * b) / max(a + c, 1e-12))


def dominant_period(image: np.ndarray) -> float:
    """The dominant fringe period of a grey image, in pixels.

    The power of each spectral shell (one frequency step wide: the mean power times the radius, the share
    of the image's variance at that frequency) is searched for its peak among periods from
    :data:`MIN_PERIOD` to a quarter of the shorter side (a low-frequency trend is not a fringe); the peak is
    refined by a parabola through its two neighbours. The mean power alone picked the blotches of a noisy
    onion exemplar (period 22 px for fringes of 6).

    >>> x = np.arange(64)
    >>> round(dominant_period(np.tile(np.cos(2 * np.pi * x / 8.0), (64, 1))), 1)
    8.0
    """
    img = np.asarray(image, dtype=np.float64)
    h, w = img.shape
    power = np.abs(np.fft.fft2(img - img.mean())) ** 2
    radius = np.hypot(np.fft.fftfreq(h)[:, None], np.fft.fftfreq(w)[None, :])
    step = 1.0 / min(h, w)
    shell = np.rint(radius / step).astype(np.int64).ravel()
    n = int(0.5 / step) + 1
    keep = shell < n
    mean = np.bincount(shell[keep], power.ravel()[keep], minlength=n) / np.maximum(
        np.bincount(shell[keep], minlength=n), 1
    )
    lo = max(1, int(np.ceil(4.0)))  # periods up to a quarter of the side: shell 4 and above
    hi = int(np.floor(1.0 / (MIN_PERIOD * step)))
    mean = mean * np.arange(n)
    k = lo + int(np.argmax(mean[lo : hi + 1]))
    if lo < k < min(hi, n - 1):
        a, b, c = mean[k - 1], mean[k], mean[k + 1]
        denom = a - 2 * b + c
        k = k + (0.5 * (a - c) / denom if denom < 0 else 0.0)
    return float(1.0 / (k * step))


def starts_laminar(
    structure: str,
    exemplars: Mapping[str, np.ndarray],
    planes: Sequence[str],
    adapt: bool,
    pilot: Callable[[np.ndarray], bool] | None = None,
) -> bool:
    """Whether a solid synthesis starts from :func:`laminar_volume`.

    ``'laminar'``: always; ``'none'``: never; ``'auto'``: when ``adapt`` (the methods'
    ``adapt_to_structure``) is on and one isotropic (:data:`ISOTROPIC_MAX`) exemplar serves the three
    planes: the isotropic sheets fit it when it is fringed (mean coherence >= :data:`START_COHERENCE`);
    between :data:`PILOT_COHERENCE` and that, ``pilot(exemplar)`` decides (the methods pass
    :func:`synth.methods.solid_kopf.laminar_pilot`: a small volume from each start, the one whose slices
    keep the exemplar's coherence). Per-plane exemplars, two views and one-orientation laminae describe
    anisotropic materials that isotropic sheets do not (docs/solid.md), and a weakly oriented exemplar
    (soot-128) is not laminar: all keep the paper's random start.
    """
    if structure in ("laminar", "none"):
        return structure == "laminar"
    images = [np.asarray(exemplars[p]) for p in planes]
    one = len(images) == 3 and all(im is images[0] or np.array_equal(im, images[0]) for im in images[1:])
    if not (adapt and one) or mean_tensor_coherence(images[0]) >= ISOTROPIC_MAX:
        return False
    fringed = mean_coherence(images[0])
    if fringed >= START_COHERENCE:
        return True
    return fringed >= PILOT_COHERENCE and pilot is not None and pilot(images[0])


def structure_levels(period: float, levels: int) -> int:
    """How many of the finest pyramid levels keep a period of at least :data:`MIN_PERIOD` px (>= 1)."""
    used = 1
    while used < levels and period / 2**used >= MIN_PERIOD:
        used += 1
    return used


def _smooth_field(shape: tuple[int, int, int], sigma: float, rng: np.random.Generator) -> np.ndarray:
    """White noise low-passed by a Gaussian of ``sigma`` voxels, periodic (FFT), unit variance."""
    noise = rng.standard_normal(shape)
    freqs = np.meshgrid(*[np.fft.fftfreq(s) for s in shape[:2]], np.fft.rfftfreq(shape[2]), indexing="ij")
    f2 = sum(f**2 for f in freqs)
    low_pass = np.exp(-2.0 * (np.pi * sigma) ** 2 * f2)
    field = np.fft.irfftn(np.fft.rfftn(noise) * low_pass, s=shape, axes=(0, 1, 2))
    return field / max(float(field.std()), 1e-12)


def laminar_phase(
    shape: tuple[int, int, int], length: float, rng: np.random.Generator, *, periodic: bool = True
) -> np.ndarray:
    """The phase ``phi`` (voxels): signed distance to the zero level of a smooth random field.

    The field (periodic) has Gaussian correlation of ``sigma = length / 2`` voxels; the distance is the
    exact Euclidean distance transform (computed on a wrapped margin of ``length`` voxels so that a
    periodic volume stays periodic) and smoothed by a Gaussian of 1 voxel, which removes the staircase
    of the voxel surface while keeping ``|grad phi|`` about 1.
    """
    field = _smooth_field(shape, max(length, 1.0) / 2.0, rng)
    margin = int(np.ceil(min(length, max(shape))))
    padded = np.pad(field, margin, mode="wrap")
    inside = padded > 0
    phi = ndi.distance_transform_edt(inside) - ndi.distance_transform_edt(~inside)
    phi = phi[margin:-margin, margin:-margin, margin:-margin] if margin else phi
    return ndi.gaussian_filter(phi, 1.0, mode="wrap" if periodic else "reflect")


def laminar_volume(
    shape: tuple[int, int, int],
    period: float,
    length: float,
    values: np.ndarray,
    rng: np.random.Generator,
    *,
    periodic: bool = True,
) -> np.ndarray:
    """Sheets ``cos(2 pi phi / period)`` of :func:`laminar_phase`, grey levels rank-mapped onto ``values``.

    Returns ``(D, H, W)`` float32; its histogram is that of ``values`` (the exemplar's pixels).
    """
    return sheets(laminar_phase(shape, length, rng, periodic=periodic), period, values)


def level_phase(phi: np.ndarray, level: int) -> np.ndarray:
    """The phase at pyramid ``level`` (in that level's voxels): ``phi`` subsampled by ``2**level``, scaled."""
    step = 2**level
    return np.ascontiguousarray(phi[::step, ::step, ::step] / step)


def sheets(phi: np.ndarray, period: float, values: np.ndarray) -> np.ndarray:
    """``cos(2 pi phi / period)`` with its grey levels rank-mapped onto ``values`` (float32)."""
    shape = phi.shape
    wave = np.cos(2.0 * np.pi * phi / period).ravel()
    ranks = np.argsort(wave, kind="stable")
    ref = np.sort(np.asarray(values, dtype=np.float32).ravel())
    out = np.empty(wave.size, dtype=np.float32)
    out[ranks] = ref[(np.arange(wave.size, dtype=np.int64) * ref.size) // wave.size]
    return out.reshape(shape)
