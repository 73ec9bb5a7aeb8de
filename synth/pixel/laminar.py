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

Anisotropic laminae (a stack seen at an angle, per-plane exemplars, two views) get an *oriented* start
instead (:func:`oriented_phase`): a stack ``n . r + c u(r)`` whose mean normal ``n`` is fitted to the planes'
fringe orientations (:func:`sheet_normal`), crumpled as much as their fringes spread. :func:`start_kind`
chooses between them. Both lengths can be fitted to the exemplars: ``L`` to their coherence at the period's
scale and their fringes' curvature (:func:`fitted_structure_length`), the crumples' to how far their fringes
keep an orientation (:func:`fitted_oriented_length`); the field scales with its length, so tables measured
once on the starts' own slices hold at every period. Shells around centres (``solid-chen-wang``): do the
fringes curve around points, how far apart (:func:`curvature_centres`), or round one (:func:`concentric_fit`)?
Or straight stacks in random cells of a few periods, turbostratic crystallites (:func:`domain_phase`).

Reference: A. Akl, C. Yaacoub, M. Donias, J.-P. Da Costa, C. Germain, "Structure tensor based synthesis
of directional textures for virtual material design", ICIP 2014: the structure layer first, then the texture.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np
from scipy import ndimage as ndi
from scipy.spatial import cKDTree

from texsynth.synth.analysis.tensor import coherence, mean_coherence, structure_tensor
from texsynth.synth.colour import to_grey
from texsynth.synth.errors import InvalidInput
from texsynth.synth.threads import current_threads

__all__ = [
    "BEND_PER_LENGTH",
    "CENTRED_MIN_CONCENTRATION",
    "CENTRE_CONCENTRATION",
    "CENTRE_DENSITY",
    "CENTRE_RADIUS",
    "CENTRE_SPACINGS",
    "CENTRE_VOTE_SIGMA",
    "CONCENTRIC_MIN_EXPLAINED",
    "DOMAIN_MAX_BEND",
    "DOMAIN_SPACING",
    "DOMAIN_SPACING_BENDS",
    "DOMAIN_SPACING_RANGE",
    "ISOTROPIC_MAX",
    "MIN_PERIOD",
    "MIN_PERIOD_SIDE",
    "ORIENTED_MAX_BEND",
    "PILOT_COHERENCE",
    "SHEET_COHERENCE",
    "SHEET_LENGTHS",
    "SHEET_RADIUS",
    "START_COHERENCE",
    "ConcentricFit",
    "CurvatureCentres",
    "Shells",
    "bend_length",
    "centre_phase",
    "centre_phase_reference",
    "choose_shells",
    "concentric_fit",
    "curvature_centres",
    "domain_phase",
    "dominant_period",
    "exemplar_bend",
    "fitted_oriented_length",
    "fitted_structure_length",
    "fringe_centres",
    "fringe_concentricity",
    "fringe_radius",
    "laminar_phase",
    "laminar_volume",
    "level_phase",
    "mean_tensor_coherence",
    "oriented_phase",
    "period_coherence",
    "plane_orientation",
    "resolved_length",
    "sheet_normal",
    "sheets",
    "stack_period",
    "start_kind",
    "starts_laminar",
    "structure_levels",
]

#: Shortest period (px) a pyramid level must keep to carry fringes (2 px is Nyquist; 3 keeps a profile).
MIN_PERIOD = 3.0
#: :func:`dominant_period` searches periods from :data:`MIN_PERIOD` to a quarter of the shorter side.
MIN_PERIOD_SIDE = 12
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
    if min(h, w) < MIN_PERIOD_SIDE:
        raise InvalidInput(
            "exemplar",
            f"{h} x {w} px is too small to measure its fringe period (a structured start needs at least "
            f"{MIN_PERIOD_SIDE} px on each side: four periods of {MIN_PERIOD:g} px); use structure='none'",
        )
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
    :func:`texsynth.synth.methods.solid_kopf.laminar_pilot`: a small volume from each start, the one whose
    slices keep the exemplar's coherence). Per-plane exemplars, two views and one-orientation laminae describe
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


def start_kind(
    structure: str,
    exemplars: Mapping[str, np.ndarray],
    planes: Sequence[str],
    adapt: bool,
    pilot: Callable[[np.ndarray], bool] | None = None,
    max_bend: float | None = None,
) -> str:
    """Which structured start a solid synthesis takes: ``'laminar'``, ``'oriented'`` or ``'none'``.

    ``'laminar'``, ``'oriented'``, ``'none'``: as asked. ``'auto'``: :func:`starts_laminar`'s rule first
    (one isotropic exemplar, fringed or chosen by the pilot: ``'laminar'``); otherwise, with ``adapt`` on
    and every constrained exemplar fringed (mean coherence >= :data:`START_COHERENCE`): ``'laminar'``
    when they are all isotropic (per-plane onions), else ``'oriented'`` (stacks, per-plane laminae, two
    views: :func:`oriented_phase`). Weakly oriented exemplars (soot) keep the paper's random start.
    With ``max_bend`` (periods), an anisotropic set whose fringes keep their orientation farther than that
    (:func:`exemplar_bend`: bent laminae, not a crumpled stack) keeps the random start too.
    """
    if structure in ("laminar", "oriented", "none"):
        return structure
    if starts_laminar(structure, exemplars, planes, adapt, pilot):
        return "laminar"
    images = [np.asarray(exemplars[p]) for p in planes]
    if not adapt or min(mean_coherence(im) for im in images) < START_COHERENCE:
        return "none"
    if all(mean_tensor_coherence(im) < ISOTROPIC_MAX for im in images):
        return "laminar"
    if max_bend is not None and exemplar_bend({p: exemplars[p] for p in planes}) > max_bend:
        return "none"
    return "oriented"


def structure_levels(period: float, levels: int) -> int:
    """How many of the finest pyramid levels keep a period of at least :data:`MIN_PERIOD` px (>= 1)."""
    used = 1
    while used < levels and period / 2**used >= MIN_PERIOD:
        used += 1
    return used


def _smooth_field(
    shape: tuple[int, int, int], sigma: float, rng: np.random.Generator, *, centred: bool = False
) -> np.ndarray:
    """White noise low-passed by a Gaussian of ``sigma`` voxels, periodic (FFT), unit variance.

    ``centred`` removes the field's mean (its zero-frequency term): when ``sigma`` nears the side, the mean
    outweighs the few waves left and the zero level misses most of the volume (docs/solid.md).
    """
    spectrum = np.fft.rfftn(rng.standard_normal(shape))
    if centred:
        spectrum[0, 0, 0] = 0.0
    fz, fy, fx = np.fft.fftfreq(shape[0]), np.fft.fftfreq(shape[1]), np.fft.rfftfreq(shape[2])
    # the same sums and products as on whole meshgrids, broadcast and in place (memory: issue 25)
    low_pass = fz[:, None, None] ** 2 + fy[None, :, None] ** 2 + fx[None, None, :] ** 2
    low_pass *= -2.0 * (np.pi * sigma) ** 2
    spectrum *= np.exp(low_pass, out=low_pass)
    del low_pass
    field = np.fft.irfftn(spectrum, s=shape, axes=(0, 1, 2))
    del spectrum
    field /= max(float(field.std()), 1e-12)
    return field


def laminar_phase(
    shape: tuple[int, int, int],
    length: float,
    rng: np.random.Generator,
    *,
    periodic: bool = True,
    centred: bool = False,
) -> np.ndarray:
    """The phase ``phi`` (voxels): signed distance to the zero level of a smooth random field.

    The field (periodic) has Gaussian correlation of ``sigma = length / 2`` voxels; the distance is the
    exact Euclidean distance transform (computed on a wrapped margin of ``length`` voxels so that a
    periodic volume stays periodic) and smoothed by a Gaussian of 1 voxel, which removes the staircase
    of the voxel surface while keeping ``|grad phi|`` about 1. ``centred``: the field's mean removed
    (:func:`_smooth_field`), so that the zero level cuts the volume however long the sheets.
    """
    field = _smooth_field(shape, max(length, 1.0) / 2.0, rng, centred=centred)
    margin = int(np.ceil(min(length, max(shape))))
    padded = np.pad(field, margin, mode="wrap")
    inside = padded > 0
    del padded
    phi = _signed_distance(inside)
    phi = phi[margin:-margin, margin:-margin, margin:-margin] if margin else phi
    return ndi.gaussian_filter(phi, 1.0, mode="wrap" if periodic else "reflect")


#: Slabs (along the first axis) in which :func:`_edt` turns the feature transform into distances.
EDT_SLAB = 16


def _edt(mask: np.ndarray) -> np.ndarray:
    """``scipy.ndimage.distance_transform_edt(mask)`` with a fraction of its memory: SciPy's feature
    transform, then the distances slab by slab (SciPy holds three int32 and three float64 volumes at once,
    1.5 GB for a padded 256^3 start). The squared distances are sums of squared integers, exact in float64,
    so the result is the same bytes."""
    ft = ndi.distance_transform_edt(mask, return_distances=False, return_indices=True)
    out = np.empty(mask.shape, dtype=np.float64)
    grids = [
        np.arange(n, dtype=np.int32).reshape([-1 if a == i else 1 for a in range(mask.ndim)])
        for i, n in enumerate(mask.shape)
    ]
    for z in range(0, mask.shape[0], EDT_SLAB):
        sl = slice(z, z + EDT_SLAB)
        total = np.zeros(out[sl].shape, dtype=np.float64)
        for axis in range(mask.ndim):
            d = (ft[axis, sl] - (grids[axis][sl] if axis == 0 else grids[axis])).astype(np.float64)
            total += d * d
        np.sqrt(total, out=out[sl])
    return out


#: Above this many voxels (128^3) the two distance transforms run one after the other: each holds 20 bytes
#: per padded voxel, and two at once made the start the peak of a whole solid run (issue 25).
PARALLEL_EDT_VOXELS = 2**21


def _signed_distance(inside: np.ndarray) -> np.ndarray:
    """``edt(inside) - edt(~inside)`` (float64), the two transforms on two threads when the work has
    them (SciPy's transform releases the GIL; each is exact, so the bytes do not depend on the threads)
    and the volume is below :data:`PARALLEL_EDT_VOXELS` (each transform holds 20 bytes per voxel)."""
    if current_threads() < 2 or inside.size > PARALLEL_EDT_VOXELS:
        return _edt(inside) - _edt(~inside)
    with ThreadPoolExecutor(max_workers=2) as pool:
        outside = pool.submit(_edt, ~inside)
        phi = _edt(inside)
        phi -= outside.result()
    return phi


def laminar_volume(
    shape: tuple[int, int, int],
    period: float,
    length: float,
    values: np.ndarray,
    rng: np.random.Generator,
    *,
    periodic: bool = True,
    centred: bool = False,
) -> np.ndarray:
    """Sheets ``cos(2 pi phi / period)`` of :func:`laminar_phase`, grey levels rank-mapped onto ``values``.

    Returns ``(D, H, W)`` float32; its histogram is that of ``values`` (the exemplar's pixels).
    ``centred``: as :func:`laminar_phase` (off: the bytes before it existed).
    """
    return sheets(laminar_phase(shape, length, rng, periodic=periodic, centred=centred), period, values)


def level_phase(phi: np.ndarray, level: int) -> np.ndarray:
    """The phase at pyramid ``level`` (in that level's voxels): ``phi`` subsampled by ``2**level``, scaled."""
    step = 2**level
    return np.ascontiguousarray(phi[::step, ::step, ::step] / step)


def centre_phase(
    shape: tuple[int, int, int], spacing: float, rng: np.random.Generator, *, periodic: bool = True
) -> np.ndarray:
    """The phase of nested spherical shells (voxels): the distance to the nearest of random centres.

    One centre per ``spacing**3`` voxels (at least one), uniform in the volume; with ``periodic`` the
    distance wraps at the volume's sides (a k-d tree with the volume as its box).
    Returns ``(D, H, W)`` float64.
    """
    tree, _ = _centres(shape, spacing, rng, periodic)
    phase = np.empty(shape, dtype=np.float64)
    for slab, _, distance, _ in _nearest(tree, shape):
        phase[slab] = distance.reshape(phase[slab].shape)
    return phase


def _centres(
    shape: tuple[int, int, int], spacing: float, rng: np.random.Generator, periodic: bool
) -> tuple[cKDTree, int]:
    """Random centres, one per ``spacing**3`` voxels (at least one), uniform in the volume, in a k-d tree
    (with ``periodic``, the volume is its box: distances wrap at the sides), and their number. The centres
    are the only draws from ``rng``."""
    dims = np.asarray(shape, dtype=np.float64)
    n = max(1, round(float(np.prod(dims)) / max(spacing, 1.0) ** 3))
    centres = rng.uniform(0.0, 1.0, (n, 3)) * dims
    if periodic:  # the box is half-open: a centre drawn at the far side exactly wraps to 0
        centres = np.where(centres >= dims, 0.0, centres)
    return cKDTree(centres, boxsize=dims if periodic else None), n


#: Voxels per slab of the nearest-centre queries (:func:`_nearest`): the coordinates and answers of one slab
#: at a time (a 256^3 start held 1.2 GB of them at once).
NEAREST_SLAB = 2**20


def _nearest(
    tree: cKDTree, shape: tuple[int, int, int]
) -> Iterator[tuple[slice, np.ndarray, np.ndarray, np.ndarray]]:
    """The volume in slabs of whole first-axis planes, about :data:`NEAREST_SLAB` voxels each: each slab's
    slice, its voxels' coordinates ``(N, 3)`` (float64, raster order) and their nearest centre in ``tree``
    (distance, index). The tree is queried on the job's threads: each voxel's nearest centre is its own
    answer, the same on any count."""
    plane = shape[1] * shape[2]
    rows, cols = (
        a.ravel() for a in np.meshgrid(*(np.arange(n, dtype=np.float64) for n in shape[1:]), indexing="ij")
    )
    step = max(1, NEAREST_SLAB // max(plane, 1))
    for z0 in range(0, shape[0], step):
        z1 = min(shape[0], z0 + step)
        depth = np.repeat(np.arange(z0, z1, dtype=np.float64), plane)
        points = np.column_stack([depth, np.tile(rows, z1 - z0), np.tile(cols, z1 - z0)])
        distance, index = tree.query(points, workers=current_threads())
        yield slice(z0, z1), points, distance, index


#: The domains' spacing (periods) when none is given (:func:`domain_phase`): on the real crops whose
#: fringes are short and straight (the onion core, soot-256, the particle's edge, the onion's top),
#: 2.5 periods gave `solid-kopf` fringe lengths and tortuosity closer to the exemplars' than 2 or 3
#: (docs/solid.md, "Straight stacks in domains, chosen").
DOMAIN_SPACING = 2.5
#: ``shells='sheets'`` and ``'auto'``: the domains' spacing follows how far the exemplar's fringes keep
#: their orientation (:func:`bend_length`, periods): :data:`DOMAIN_SPACING_RANGE` at these bends, linear
#: between (soot-256 and the particle's edge, 1.64-1.67, measured better 2 periods apart; the onion core
#: and top, 1.95-2.15, 2.5: docs/solid.md).
DOMAIN_SPACING_BENDS = (1.7, 1.9)
DOMAIN_SPACING_RANGE = (2.0, DOMAIN_SPACING)
#: ``shells='sheets'``: exemplars whose fringes keep their orientation less than this (periods,
#: :func:`bend_length`) without gathering their centres of curvature are short straight pieces, started
#: from domains; real crops measured 1.6-2.15 (domains better, but one shift of the onion crop at 2.10)
#: against the onion crop's 2.42 (surfaces better; docs/solid.md).
DOMAIN_MAX_BEND = 2.2


def domain_phase(
    shape: tuple[int, int, int], spacing: float, rng: np.random.Generator, *, periodic: bool = True
) -> np.ndarray:
    """The phase (voxels) of straight stacks in random domains: turbostratic crystallites.

    One domain per ``spacing**3`` voxels (at least one): the Voronoi cell of a centre drawn uniformly in
    the volume (with ``periodic``, distances wrap at its sides), whose phase is ``n . r + c`` with a
    random unit normal ``n`` and a random offset ``c`` in ``[0, spacing)``: ``|grad phi| = 1`` inside
    each cell, so ``cos(2 pi phi / period)`` stacks straight sheets there, each cell its own way.
    Returns ``(D, H, W)`` float64.
    """
    tree, n = _centres(shape, spacing, rng, periodic)
    normals = rng.standard_normal((n, 3))  # each cell's normal and offset, drawn after the centres
    normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-12)
    offsets = rng.uniform(0.0, max(spacing, 1.0), n)
    phase = np.empty(shape, dtype=np.float64)
    for slab, points, _, cell in _nearest(tree, shape):
        phi = np.einsum("ij,ij->i", points, normals[cell]) + offsets[cell]
        phase[slab] = phi.reshape(phase[slab].shape)
    return phase


def centre_phase_reference(
    shape: tuple[int, int, int], spacing: float, rng: np.random.Generator, *, periodic: bool = True
) -> np.ndarray:
    """:func:`centre_phase` by brute force over the centres (the plain reference of the tests)."""
    dims = np.asarray(shape, dtype=np.float64)
    n = max(1, round(float(np.prod(dims)) / max(spacing, 1.0) ** 3))
    centres = rng.uniform(0.0, 1.0, (n, 3)) * dims
    axes = [np.arange(n_, dtype=np.float64) for n_ in shape]
    best = np.full(shape, np.inf)
    for centre in centres:
        d = [np.abs(axes[i] - centre[i]) for i in range(3)]
        if periodic:
            d = [np.minimum(d[i], dims[i] - d[i]) for i in range(3)]
        np.minimum(
            best, d[0][:, None, None] ** 2 + d[1][None, :, None] ** 2 + d[2][None, None, :] ** 2, out=best
        )
    return np.sqrt(best)


def sheets(phi: np.ndarray, period: float, values: np.ndarray) -> np.ndarray:
    """``cos(2 pi phi / period)`` with its grey levels rank-mapped onto ``values`` (float32)."""
    shape = phi.shape
    wave = np.cos(2.0 * np.pi * phi / period).ravel()
    ranks = np.argsort(wave, kind="stable")
    ref = np.sort(np.asarray(values, dtype=np.float32).ravel())
    out = np.empty(wave.size, dtype=np.float32)
    out[ranks] = ref[(np.arange(wave.size, dtype=np.int64) * ref.size) // wave.size]
    return out.reshape(shape)


#: Crumple amplitudes (rms of ``|grad u|``) among which :func:`oriented_phase` fits the exemplars' spread.
CRUMPLES = tuple(np.round(np.arange(0.0, 0.62, 0.05), 2))
#: Side of the probe volume on which the crumple is fitted (the fit costs a few FFTs of this size).
CRUMPLE_PROBE = 48


def plane_orientation(image: np.ndarray) -> tuple[np.ndarray, float]:
    """The dominant fringe normal of a grey image in its (row, column) axes, and how dominant it is.

    Returns the unit principal eigenvector ``(d_row, d_col)`` of the mean gradient outer product
    (Gaussian derivatives of 1 px) and its anisotropy ``(l1 - l2) / (l1 + l2)`` (0: every orientation
    equally, 1: one); the sign of the vector is arbitrary (a fringe normal is an orientation).
    """
    img = np.asarray(to_grey(image), dtype=np.float64)
    gr = ndi.gaussian_filter(img, 1.0, order=(1, 0), mode="reflect")
    gc = ndi.gaussian_filter(img, 1.0, order=(0, 1), mode="reflect")
    j = np.array([[np.mean(gr * gr), np.mean(gr * gc)], [np.mean(gr * gc), np.mean(gc * gc)]])
    evals, evecs = np.linalg.eigh(j)
    return evecs[:, 1], float((evals[1] - evals[0]) / max(evals[1] + evals[0], 1e-12))


def sheet_normal(orientations: Mapping[str, tuple[np.ndarray, float]]) -> np.ndarray:
    """The unit 3D sheet normal ``(n_z, n_y, n_x)`` whose traces best fit the planes' fringe normals.

    Sheets of normal ``n`` show, in a plane of volume axes ``(a, b)``
    (:data:`texsynth.synth.pixel.solid.PLANE_AXES`), fringes whose normal is ``(n_a, n_b)``; a plane whose
    fringe normal is ``d`` asks
    ``n_a d_b - n_b d_a = 0``. Each plane's equation is weighted by its anisotropy and ``n`` is the
    least-squares solution of unit length (the smallest right singular vector), its largest component
    made positive. ``orientations`` maps plane names to :func:`plane_orientation` answers.
    """
    axes = {"xy": (1, 2), "xz": (0, 2), "yz": (0, 1)}
    rows = []
    for plane, (d, weight) in orientations.items():
        a, b = axes[plane]
        row = np.zeros(3)
        row[a], row[b] = d[1], -d[0]
        rows.append(weight * row)
    _, _, vt = np.linalg.svd(np.array(rows))
    n = vt[-1]
    return n if n[np.argmax(np.abs(n))] > 0 else -n


def _crumple_field(shape: tuple[int, ...], sigma: float, rng: np.random.Generator) -> np.ndarray:
    """A periodic smooth displacement (white noise low-passed by a Gaussian of ``sigma``), rms gradient 1."""
    u = _smooth_field(shape, sigma, rng)  # type: ignore[arg-type]
    grad = np.sqrt(sum(g**2 for g in np.gradient(u)).mean())
    return u / max(float(grad), 1e-12)


def _wave_vector(normal: np.ndarray, period: float, shape: tuple[int, ...], periodic: bool) -> np.ndarray:
    """``normal / period``, each component rounded to a whole number of periods across a periodic volume."""
    k = normal / period
    if periodic:
        k = np.array([np.round(ki * s) / s for ki, s in zip(k, shape, strict=True)])
    return k


def stack_period(exemplars: Mapping[str, np.ndarray], normal: np.ndarray) -> float:
    """The sheets' spacing (px) behind the planes' apparent periods: a plane of axes ``(a, b)`` cuts sheets of
    spacing ``lambda`` and normal ``n`` into fringes ``lambda / |(n_a, n_b)|`` apart; each plane's
    :func:`dominant_period` times ``|(n_a, n_b)|``, weighted by ``|(n_a, n_b)|^2`` (a plane nearly parallel
    to the sheets sees few, long fringes)."""
    axes = {"xy": (1, 2), "xz": (0, 2), "yz": (0, 1)}
    num = den = 0.0
    for plane, image in exemplars.items():
        a, b = axes[plane]
        trace = float(np.hypot(normal[a], normal[b]))
        num += trace**2 * dominant_period(image) * trace
        den += trace**2
    return num / max(den, 1e-12)


def oriented_phase(
    shape: tuple[int, int, int],
    exemplars: Mapping[str, np.ndarray],
    period: float,
    length: float,
    rng: np.random.Generator,
    *,
    periodic: bool = True,
) -> np.ndarray:
    """The phase (voxels) of a crumpled stack whose slices keep the planes' fringe orientations.

    The oriented start (the structure first, for an anisotropic laminar material: Akl 2014's two stages
    carried to 3D): the mean sheet normal ``n`` is fitted to the exemplars' dominant fringe normals
    (:func:`sheet_normal`), ``period`` is the sheets' spacing (:func:`stack_period`); the phase is
    ``phi = period k . r + c u(r)``, ``k = n / period`` (rounded to whole periods across a periodic
    volume: it stays tileable), ``u`` a smooth displacement of correlation ``length / 2`` voxels and unit
    rms gradient, and ``c`` the crumple among :data:`CRUMPLES` whose probe volume's slices best match the
    exemplars' anisotropy (:func:`plane_orientation`): the local normals spread as the fringes do.
    """
    fits = {p: plane_orientation(image) for p, image in exemplars.items()}
    normal = sheet_normal(fits)
    sigma = max(length, 1.0) / 2.0
    probe = (CRUMPLE_PROBE,) * 3
    u_probe = _crumple_field(probe, sigma, rng)
    ramp_probe = _ramp(_wave_vector(normal, period, probe, True), probe)
    normal_axis = {"xy": 0, "xz": 1, "yz": 2}
    best, best_err = 0.0, np.inf
    for c in CRUMPLES:
        wave = np.cos(2.0 * np.pi * (ramp_probe + c * u_probe / period))
        err = 0.0
        for plane, (_, target) in fits.items():
            axis = normal_axis[plane]
            got = np.mean(
                [plane_orientation(np.take(wave, i, axis=axis))[1] for i in range(0, CRUMPLE_PROBE, 8)]
            )
            err += (got - target) ** 2
        if err < best_err - 1e-12:
            best, best_err = float(c), err
    u = _crumple_field(shape, sigma, rng)
    return period * _ramp(_wave_vector(normal, period, shape, periodic), shape) + best * u


def _ramp(k: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    """``k . r`` over a volume of ``shape`` (float64)."""
    return sum(k[i] * np.arange(shape[i]).reshape([-1 if j == i else 1 for j in range(3)]) for i in range(3))


# ------------------------------------------------------------------ lengths fitted to the exemplars


#: The laminar start's sheet lengths (periods), and the mean :func:`period_coherence` of their slices:
#: ``python -m benchmarks.bench_laminar --calibrate`` (sheets of period 6 px, 128^3, two draws, every 8th
#: slice of each axis; the measure is in periods, so the table holds at every period). Short sheets bend
#: within a period or two and cross at many kinks; long ones are large gently curved shells.
SHEET_LENGTHS = (1.5, 2.0, 2.5, 3.0, 3.5, 4.0, 5.0, 6.0, 8.0)
SHEET_COHERENCE = (0.257, 0.345, 0.416, 0.481, 0.542, 0.592, 0.695, 0.755, 0.8)
#: ... and the mean :func:`fringe_radius` of their slices (periods of the slices).
SHEET_RADIUS = (3.77, 4.13, 4.5, 5.01, 5.49, 6.01, 8.24, 10.89, 13.46)
#: The oriented start's slices keep their orientation :func:`bend_length` periods for every this many
#: periods of crumple length (``python -m benchmarks.bench_laminar --calibrate``: 0.50-0.56 between 2 and
#: 4 periods; the crumple field scales with its length, so the ratio is a constant).
BEND_PER_LENGTH = 0.52
#: Bounds of the fitted crumple length (periods).
ORIENTED_LENGTH_RANGE = (1.0, 16.0)
#: :func:`start_kind`'s ``max_bend`` for ``solid-kopf``: fringes that keep their orientation farther than
#: this many periods (:func:`exemplar_bend`; turbostratic stack 1.3, per-plane bent sheets 2.5, bent laminae
#: 4.8) are bent laminae, better served by the random start (docs/solid.md: orientation KL 0.08-0.10
#: against 0.09-0.31 from crumples of 2 periods and 1.0-2.0 from fitted ones).
ORIENTED_MAX_BEND = 2.0


def period_coherence(image: np.ndarray, period: float | None = None) -> float:
    """Mean structure-tensor coherence at the fringes' own scale: how far they run unbroken and unbent.

    Gaussian derivatives of a quarter period (they average much of the pixel noise out: the laminar
    truth's onion exemplar 0.36 against 0.38 without its noise, where 1 px derivatives give 0.67 against
    0.74) and an integration window of one period, over which a ring of radius ``r`` turns by ``1 / r``
    radians; a border of two periods is left out. ``period`` defaults to :func:`dominant_period`.
    """
    img = np.asarray(to_grey(image), dtype=np.float64)
    p = dominant_period(img) if period is None else float(period)
    c = coherence(structure_tensor(img, p / 4.0, p))
    m = min(int(np.ceil(2.0 * p)), (min(c.shape) - 1) // 4)
    return float(c[m : c.shape[0] - m, m : c.shape[1] - m].mean())


def _fringe_turn(img: np.ndarray, p: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """The fringes' signed turn ``d theta / d s`` (radians per px), their normal angle ``theta`` in ``(x,
    y) = (column, -row)`` axes, the tensor coherence, and the border (two periods) the measures leave out.

    The orientation field of the structure tensor (Gaussian derivatives of 1 px, integration of half a
    period: the pixel noise averages out, a ring of two periods keeps its turn) is differentiated along
    the fringe tangent ``t = (-sin theta, cos theta)``: ``d theta / d s = (u x (t . grad) u) / 2`` with
    ``u`` the doubled-angle unit field. Flipping ``theta`` by ``pi`` flips ``t`` and the turn's sign
    together, so the centre of curvature ``x - n / turn`` (``n`` the normal) is well defined.
    """
    t = structure_tensor(img, 1.0, p / 2.0).astype(np.float64)
    a, b, c = t[..., 0], t[..., 1], t[..., 2]
    z = (a - c) + 2j * b  # doubled angle of the gradient in (x, y) = (column, -row) axes
    mag = np.abs(z)
    u = z / np.maximum(mag, 1e-12)
    theta = 0.5 * np.angle(u)  # gradient (fringe normal) angle; the tangent is perpendicular
    tx, ty = -np.sin(theta), np.cos(theta)
    d_row = [np.gradient(f, axis=0) for f in (u.real, u.imag)]
    d_col = [np.gradient(f, axis=1) for f in (u.real, u.imag)]
    # along t = (tx, ty) in (x, y): d/ds = tx d/dcol - ty d/drow
    dr, di = (tx * dc - ty * dr_ for dc, dr_ in zip(d_col, d_row, strict=True))
    turn = 0.5 * (u.real * di - u.imag * dr)
    coh = mag / np.maximum(a + c, 1e-12)
    m = min(int(np.ceil(2.0 * p)), (min(img.shape) - 1) // 4)
    return turn, theta, coh, m


def fringe_radius(image: np.ndarray, period: float | None = None) -> float:
    """The median radius of curvature (periods) of the fringes where they are the more coherent half.

    ``kappa = |d theta / d s|`` of :func:`_fringe_turn`; the median over the pixels of above-median
    coherence (the fringes, not the gaps between onions) is inverted. A border of two periods is left out.
    """
    img = np.asarray(to_grey(image), dtype=np.float64)
    p = dominant_period(img) if period is None else float(period)
    turn, _, coh, m = _fringe_turn(img, p)
    kappa = np.abs(turn)
    kappa, coh = (
        kappa[m : img.shape[0] - m, m : img.shape[1] - m],
        coh[m : img.shape[0] - m, m : img.shape[1] - m],
    )
    k = float(np.median(kappa[coh >= np.median(coh)]))
    return 1.0 / max(k, 1e-6) / p


def _fringe_pixels(
    image: np.ndarray, period: float | None
) -> tuple[float, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The period, :func:`_fringe_turn`'s turn, normal angle and coherence, and the fringe pixels that
    :func:`curvature_centres` and :func:`concentric_fit` read: above-median coherence, a border of two
    periods left out."""
    img = np.asarray(to_grey(image), dtype=np.float64)
    p = dominant_period(img) if period is None else float(period)
    turn, theta, coh, m = _fringe_turn(img, p)
    h, w = img.shape
    inner = np.zeros((h, w), dtype=bool)
    inner[m : h - m, m : w - m] = True
    return p, turn, theta, coh, inner & (coh >= np.median(coh[inner]))


#: :func:`curvature_centres`: the votes are smoothed by a Gaussian of this many periods, and a vote is
#: gathered where their density reaches :data:`CENTRE_DENSITY` times the density of as many votes spread
#: evenly over the image (docs/solid.md, session cw8: onion truth's top 21-23, real crops 7, soot 5-6).
CENTRE_VOTE_SIGMA = 0.5
CENTRE_DENSITY = 8.0


@dataclass(frozen=True)
class CurvatureCentres:
    """Where the fringes' centres of curvature fall (:func:`curvature_centres`)."""

    #: The exemplar's dominant period (px).
    period: float
    #: Share of the fringe pixels whose centre of curvature lands where the votes gather (0-1).
    concentration: float
    #: The median radius of curvature of the fringe pixels (periods): the onions' size.
    radius: float
    #: The vote peaks (row, column; px), strongest first: the onions' centres seen in the image.
    centres: np.ndarray
    #: The densest vote over the evenly spread density.
    peak: float


def curvature_centres(image: np.ndarray, period: float | None = None) -> CurvatureCentres:
    """The fringes' centres of curvature, voted into the image: do the fringes curve around points?

    Each pixel of above-median coherence (the fringes; a border of two periods left out) votes for its
    centre of curvature ``x - n / (d theta / d s)`` (:func:`_fringe_turn`). Rings around a point put
    every vote at that point; straight fringes vote at infinity (outside the image); bent sheets and
    kinked fringes scatter their votes. The votes inside the image are smoothed
    (:data:`CENTRE_VOTE_SIGMA` periods) and divided by the density of as many votes spread evenly;
    ``concentration`` is the share of all voters whose vote lands at :data:`CENTRE_DENSITY` or more,
    ``centres`` the local maxima (within a period) above it. ``radius`` is the voters' median ``|1 /
    turn|``, in periods (the same quantity as :func:`fringe_radius`, over the same pixels).
    """
    p, turn, theta, _, voters = _fringe_pixels(image, period)
    h, w = voters.shape
    k = turn[voters]
    k = np.where(np.abs(k) < 1e-9, 1e-9, k)
    rows, cols = np.nonzero(voters)
    # (x, y) = (column, -row): the centre x - n / k, n = (cos theta, sin theta)
    c_col = cols - np.cos(theta[voters]) / k
    c_row = rows + np.sin(theta[voters]) / k
    inside = (c_row >= 0) & (c_row < h) & (c_col >= 0) & (c_col < w)
    vr, vc = c_row[inside].astype(np.int64), c_col[inside].astype(np.int64)
    votes = np.bincount(vr * w + vc, minlength=h * w).astype(np.float64).reshape(h, w)
    density = ndi.gaussian_filter(votes, CENTRE_VOTE_SIGMA * p, mode="constant")
    density /= max(rows.size / (h * w), 1e-12)
    concentration = float(np.sum(density[vr, vc] >= CENTRE_DENSITY)) / max(rows.size, 1)
    peaks = (density == ndi.maximum_filter(density, size=2 * int(p) + 1, mode="constant")) & (
        density >= CENTRE_DENSITY
    )
    centres = np.argwhere(peaks)
    centres = centres[np.argsort(-density[peaks], kind="stable")]
    radius = float(np.median(1.0 / np.abs(k))) / p if k.size else float("inf")
    return CurvatureCentres(p, concentration, radius, centres, float(density.max()))


#: ``solid-chen-wang``'s shells around centres: centre spacings (periods; one centre per cube of that side)
#: and the mean :func:`curvature_centres` radius and concentration of their slices (``python -m
#: benchmarks.bench_laminar --calibrate``: ``cos(2 pi d / period)`` of the distance ``d`` to the nearest
#: centre plus noise 0.3, period 6 px, 128^3, two draws, every 16th slice of each axis).
CENTRE_SPACINGS = (3.0, 4.0, 4.5, 5.0, 6.0, 8.0, 12.0, 16.0, 24.0)
CENTRE_RADIUS = (2.3, 2.48, 2.62, 2.78, 3.12, 3.83, 5.27, 7.64, 8.93)
CENTRE_CONCENTRATION = (0.148, 0.344, 0.434, 0.503, 0.591, 0.698, 0.659, 0.433, 0.365)
#: ... and the concentration of the surfaces' slices (:func:`laminar_phase`, the same draws) at sheet lengths
#: 2, 3, 4 and 6 periods: 0.015, 0.055, 0.102, 0.081. Exemplars whose fringes gather their centres of
#: curvature at least this much curve around points (halfway between the surfaces' 0.10 and the centres'
#: 0.34 at 4 periods; the onion truth 0.29-0.43, the real onion crops, soot and the stack 0.00).
CENTRED_MIN_CONCENTRATION = 0.2


@dataclass(frozen=True)
class ConcentricFit:
    """How well one centre explains the fringes' orientations (:func:`concentric_fit`)."""

    #: The exemplar's dominant period (px).
    period: float
    #: Agreement with straight parallel fringes: the mean resultant of the doubled orientation (0-1).
    straight: float
    #: Agreement with rings around the best centre: the mean of ``cos 2 (theta - phi)`` (-1 to 1).
    rings: float
    #: The share of the straight model's misfit that the rings explain, ``(rings - straight) / (1 -
    #: straight)`` within [-1, 1]: about 1 for concentric fringes, 0 or less for many centres, -1 for
    #: straight stripes (no misfit to explain).
    explained: float
    #: The best centre (row, column; px), possibly outside the image (up to half its size beyond).
    centre: tuple[float, float]


def concentric_fit(image: np.ndarray, period: float | None = None) -> ConcentricFit:
    """Do the fringes curve around one point: a crop of one large particle (an onion seen whole)?

    :func:`curvature_centres` finds many small onions, where every fringe's centre of curvature falls
    near one of them. A crop of one particle whose fringes bend and break gathers no such votes, but its
    orientation field is still that of rings around one centre. Over the same pixels (above-median
    coherence, a border of two periods left out, every half period), weighted by their coherence, the
    fringe normal ``theta`` (:func:`_fringe_turn`) is compared with the direction ``phi`` from a centre:
    ``rings`` is the best mean ``cos 2 (theta - phi)`` over centres up to half the image beyond its sides
    (a grid of 1/16 of the image, then refined twice by quarters); ``straight`` is what one orientation
    explains, so that far centres, whose rings are straight, gain nothing. ``explained`` compares them.
    """
    p, _, theta, coh, voters = _fringe_pixels(image, period)
    h, w = voters.shape
    step = max(1, round(p / 2.0))
    every = np.zeros((h, w), dtype=bool)
    every[::step, ::step] = True
    voters &= every
    rows, cols = np.nonzero(voters)
    weight = coh[voters] / max(float(np.sum(coh[voters])), 1e-12)
    doubled = np.exp(2j * theta[voters])  # in (x, y) = (column, -row) axes
    straight = float(abs(np.sum(weight * doubled)))

    def agreement(centres: np.ndarray) -> np.ndarray:
        radial = (cols[None, :] - centres[:, 1:2]) - 1j * (rows[None, :] - centres[:, 0:1])
        radial2 = radial * radial / np.maximum(np.abs(radial) ** 2, 1e-12)
        return np.real(doubled[None, :] * np.conj(radial2)) @ weight

    grid_step = max(h, w) / 16.0
    axes = (np.arange(-h / 2, 1.5 * h + 1e-9, grid_step), np.arange(-w / 2, 1.5 * w + 1e-9, grid_step))
    centres = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 2)
    scores = agreement(centres)
    best = centres[int(np.argmax(scores))]
    for _ in range(2):
        grid_step /= 4.0
        offsets = np.arange(-4, 5) * grid_step
        centres = best + np.stack(np.meshgrid(offsets, offsets, indexing="ij"), axis=-1).reshape(-1, 2)
        scores = agreement(centres)
        best = centres[int(np.argmax(scores))]
    rings = float(np.max(scores))
    explained = float(np.clip((rings - straight) / max(1.0 - straight, 1e-6), -1.0, 1.0))
    return ConcentricFit(p, straight, rings, explained, (float(best[0]), float(best[1])))


#: Exemplars whose orientations one centre explains at least this much (:func:`concentric_fit`, the mean
#: over the planes) are a particle seen whole: more than any slice of the surfaces' start at the sheet
#: lengths ``solid-chen-wang`` takes, 3-4 periods (96 slices: max 0.43 and 0.61; ``python -m
#: benchmarks.bench_laminar --calibrate``). The real onion crops 0.76-0.85; soot, the onion truth -0.1-0.1.
CONCENTRIC_MIN_EXPLAINED = 0.65


def fringe_concentricity(images: Sequence[np.ndarray]) -> float:
    """The exemplars' mean :func:`concentric_fit` ``explained``: how much one centre per image explains."""
    return float(np.mean([concentric_fit(im).explained for im in images]))


def fringe_centres(images: Sequence[np.ndarray]) -> tuple[float, float]:
    """The exemplars' mean :func:`curvature_centres` concentration, and the centre spacing (periods) whose
    shells' slices curve as much as theirs (their mean radius looked up in :data:`CENTRE_RADIUS`, linear
    between the table's spacings, clipped to its ends: the onion truth's 2.6-2.9 gives 4.9-5.1 periods,
    its own centres are 5.0 apart; the real onion crops' 6.8-7.5 give 14-16)."""
    found = [curvature_centres(im) for im in images]
    concentration = float(np.mean([f.concentration for f in found]))
    radius = float(np.mean([f.radius for f in found]))
    return concentration, float(np.interp(radius, CENTRE_RADIUS, CENTRE_SPACINGS))


@dataclass(frozen=True)
class Shells:
    """The laminar start's sheets (:func:`choose_shells`) and the measures that chose them (None: not
    needed, so not measured)."""

    #: 'surfaces' (around the zero level of a random field), 'centres' (around random centres) or
    #: 'domains' (straight stacks in random cells).
    kind: str
    #: :func:`fringe_centres`' concentration and the centres' spacing (periods: given, else fitted; the
    #: domains': given, else by the bend, :data:`DOMAIN_SPACING_BENDS`, or :data:`DOMAIN_SPACING` alone).
    concentration: float | None
    spacing: float | None
    #: :func:`fringe_concentricity`: how much one centre explains the exemplars' orientations.
    concentric: float | None
    #: The exemplars' mean :func:`bend_length` (periods): how far their fringes keep their orientation.
    bend: float | None = None


def choose_shells(shells: str, spacing: float | None, images: Sequence[np.ndarray]) -> Shells:
    """``shells`` ('auto', 'sheets', 'surfaces', 'centres' or 'domains') resolved for ``images``.

    'sheets': 'domains' when the fringes are short straight pieces in every orientation (they keep it
    less than :data:`DOMAIN_MAX_BEND` periods, :func:`bend_length`; their centres of curvature do not
    gather, :data:`CENTRED_MIN_CONCENTRATION`; the exemplars are isotropic, :data:`ISOTROPIC_MAX`: the
    bend of one orientation is measured about its mean, which says nothing of straight laminae), else
    'surfaces'. 'auto': 'centres' where the centres of curvature gather (many small onions), else
    'domains' as 'sheets', else 'centres' where one centre explains the orientations
    (:data:`CONCENTRIC_MIN_EXPLAINED`: a particle seen whole, its fringes long), else 'surfaces'. The
    centres' ``spacing`` (periods) is the given one, else fitted (:func:`fringe_centres`); the domains',
    the given one, else by the bend (:data:`DOMAIN_SPACING_BENDS`), or :data:`DOMAIN_SPACING` for
    'domains' asked alone. Only what the choice needs is measured: 'surfaces' and 'domains' nothing,
    'centres' the spacing when none is given, 'sheets' no centre's share.
    """
    if shells == "surfaces":
        return Shells("surfaces", None, None, None)
    if shells == "domains":
        return Shells("domains", None, DOMAIN_SPACING if spacing is None else float(spacing), None)
    concentration = fitted = concentric = None
    if shells in ("auto", "sheets") or spacing is None:
        concentration, fitted = fringe_centres(images)
    if shells == "centres":
        return Shells("centres", concentration, fitted if spacing is None else float(spacing), None)
    assert concentration is not None and fitted is not None
    given = fitted if spacing is None else float(spacing)
    gathered = concentration >= CENTRED_MIN_CONCENTRATION
    if shells == "auto" and gathered:
        return Shells("centres", concentration, given, None)
    bend = float(np.mean([bend_length(im) for im in images]))
    isotropic = float(np.mean([mean_tensor_coherence(im) for im in images])) < ISOTROPIC_MAX
    if not gathered and bend < DOMAIN_MAX_BEND and isotropic:
        fitted_domains = float(np.interp(bend, DOMAIN_SPACING_BENDS, DOMAIN_SPACING_RANGE))
        domains = fitted_domains if spacing is None else float(spacing)
        return Shells("domains", concentration, domains, None, bend)
    if shells == "auto":
        concentric = fringe_concentricity(images)
        if concentric >= CONCENTRIC_MIN_EXPLAINED:
            return Shells("centres", concentration, given, concentric, bend)
    return Shells("surfaces", concentration, given, concentric, bend)


def fitted_structure_length(images: Sequence[np.ndarray]) -> float:
    """The laminar start's sheet length (periods): the shortest whose slices are at least as coherent at
    the period's scale (:func:`period_coherence`) and at most as curved (:func:`fringe_radius`) as the
    exemplars.

    Each of the exemplars' means is looked up in its table (:data:`SHEET_COHERENCE`,
    :data:`SHEET_RADIUS`: linear between the table's lengths, clipped to its ends) and the longer length
    is kept. The random sheets' kinks and curvature both fall as they lengthen; an exemplar may need
    them long for either reason: large shells (the tests' three onions in 64 px: 3.3 periods, by the
    coherence), or straight but short fringes (the real onion crops: 4-5 periods, by the curvature;
    their breaks lower the coherence). Small onions get short sheets (the laminar truth's: 2.1 periods).
    A fit from the 1 px coherence chose 1.5 periods for every noisy exemplar.
    """
    coherent = float(np.mean([period_coherence(im) for im in images]))
    radius = float(np.mean([fringe_radius(im) for im in images]))
    return max(
        float(np.interp(coherent, SHEET_COHERENCE, SHEET_LENGTHS)),
        float(np.interp(radius, SHEET_RADIUS, SHEET_LENGTHS)),
    )


def bend_length(image: np.ndarray) -> float:
    """How far (periods) the fringes keep their orientation, the pixel noise's share left out.

    The structure tensor's doubled-angle orientation (unit complex, 1 px derivatives, integration 2 px),
    less its mean, is autocorrelated (periodic FFT) and radially averaged; noise decorrelates within the
    integration window only, so the profile is normalised by its value at 4 px (not at 0) and the
    answer is the first radius beyond 4 px where it falls below half of that, divided by
    :func:`dominant_period`. Crumpled stacks about 1.3, bent laminae bending once over 18 periods 4.8.
    """
    img = np.asarray(to_grey(image), dtype=np.float64)
    t = structure_tensor(img, 1.0, 2.0).astype(np.float64)
    z = (t[..., 0] - t[..., 2]) + 2j * t[..., 1]
    z = z / np.maximum(np.abs(z), 1e-12)
    z = z - z.mean()
    spectrum = np.fft.fft2(z)
    ac = np.fft.ifft2(spectrum * np.conj(spectrum)).real
    h, w = ac.shape
    rows, cols = np.meshgrid(np.fft.fftfreq(h) * h, np.fft.fftfreq(w) * w, indexing="ij")
    radius = np.rint(np.hypot(rows, cols)).astype(np.int64).ravel()
    profile = np.bincount(radius, ac.ravel()) / np.maximum(np.bincount(radius), 1)
    start = 4
    below = np.flatnonzero(profile[start:] < 0.5 * profile[start])
    lag = start + int(below[0]) if below.size else len(profile)
    return lag / max(dominant_period(img), 1e-6)


def exemplar_bend(exemplars: Mapping[str, np.ndarray]) -> float:
    """The planes' :func:`bend_length` (periods), weighted by their anisotropy (:func:`plane_orientation`: a
    plane nearly parallel to the sheets shows contour bands, not fringes)."""
    weights, lengths = [], []
    for image in exemplars.values():
        weights.append(max(plane_orientation(image)[1], 1e-3))
        lengths.append(bend_length(image))
    return float(np.average(lengths, weights=weights))


def fitted_oriented_length(exemplars: Mapping[str, np.ndarray]) -> float:
    """The oriented start's crumple length (periods) whose slices bend as the exemplars' fringes do.

    :func:`exemplar_bend` divided by :data:`BEND_PER_LENGTH`, kept within :data:`ORIENTED_LENGTH_RANGE`:
    the turbostratic truth's stack (bends of 1.3 periods) gets 2.5 periods, per-plane bent sheets 4.8 and
    bent laminae that bend once over 18 periods 9.3. Measured no better than 2 periods (docs/solid.md: the
    stack's tortuosity KS worst 0.24 against 0.12; at 64^3 long crumples flatten or tilt whole slabs of
    bent laminae), so ``solid-kopf`` keeps 2 unless asked, and bent laminae keep the random start
    (:data:`ORIENTED_MAX_BEND`).
    """
    return float(np.clip(exemplar_bend(exemplars) / BEND_PER_LENGTH, *ORIENTED_LENGTH_RANGE))


def resolved_length(length: float | str | None, fit: Callable[[], float]) -> float:
    """``length`` (periods) as given, or ``fit()`` when it is ``None`` or ``'auto'``; other words: refused."""
    if length is None or length == "auto":
        return float(fit())
    if isinstance(length, str):
        raise ValueError(f"length must be a number of periods or 'auto', not {length!r}")
    return float(length)
