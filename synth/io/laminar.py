"""Known-answer laminar volumes whose slices look like HRTEM lattice fringes (issue 24).

Two families of dense-carbon nanostructure, each a volume ``(D, H, W) = (z, y, x)`` of float32 grey in
[0, 1] drawn from a seed, of any size:

- :func:`onion_volume`: carbon onions, nested spherical shells around random centres, each voxel on the
  shells of its nearest centre: grey ``cos(2 pi d / lambda)`` with ``d`` the distance to that centre.
- :func:`turbostratic_volume`: a stack of crumpled sheets, grey ``cos(2 pi phi / lambda)`` with the phase
  ``phi = n . r + u(r)``: ``n`` the stack's unit normal and ``u`` a smooth random displacement field
  (Gaussian-filtered white noise) scaled so that ``|grad phi|`` stays near 1 (rms of ``|grad u|`` =
  ``crumple``): sheets ``lambda`` apart everywhere, bent over ``correlation`` voxels.

Both are then blurred (a Gaussian of ``blur`` voxels: the microscope's transfer) and given Gaussian
``noise`` (relative to the fringe amplitude 1), and mapped to grey by a fixed affine map (not the
sample's extremes, so that two sizes of one material have the same grey scale). The fringe period is
``period`` voxels (HRTEM of graphitic carbon: 0.34 nm at ~18 px/nm, about 6 px).

Their mid-slices (:func:`texsynth.synth.output.volume.mid_slices`) are exemplars for which a consistent volume
exists by construction, and the truth's own slices give the targets a solid synthesis must reach
(benchmarks/bench_laminar.py). Onions are isotropic: one exemplar serves the three planes. A stack is
isotropic across the planes only for ``normal = (1, 1, 1)`` (the default: each plane cuts the sheets at
the same angle; docs/solid.md, "Laminae and one exemplar for three planes"); ``normal = (1, 0, 0)`` is
the anisotropic pyrocarbon-like case, given per plane.

Reference: R. D. Urs, J.-P. Da Costa, J.-M. Leyssale, G. Vignoles, C. Germain, "Non-parametric synthesis
of laminar volumetric textures from a 2D sample", BMVC 2012 (the evaluation these volumes serve).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from scipy import ndimage

from texsynth.synth.errors import InvalidParameter

__all__ = ["onion_volume", "turbostratic_volume"]

#: Largest side accepted (a 512^3 float32 volume is 0.5 GiB; the generators hold a few such arrays).
MAX_SIDE = 512
#: The grey map: fringe amplitude 1 plus this many noise standard deviations fill [0, 1].
_NOISE_SPAN = 3.0


def _check_shape(shape: Sequence[int]) -> tuple[int, int, int]:
    try:
        dims = tuple(int(s) for s in shape)
    except (TypeError, ValueError):
        raise InvalidParameter("shape", shape, "must be (D, H, W), three integers") from None
    if len(dims) != 3 or any(not 8 <= s <= MAX_SIDE for s in dims):
        raise InvalidParameter("shape", tuple(shape), f"must be (D, H, W) with every side in [8, {MAX_SIDE}]")
    return dims  # type: ignore[return-value]


def _check_number(
    name: str, value: float, low: float, *, strict: bool = True, high: float = math.inf
) -> float:
    ok = isinstance(value, int | float | np.integer | np.floating) and not isinstance(value, bool)
    if ok:
        value = float(value)
        ok = math.isfinite(value) and (value > low if strict else value >= low) and value <= high
    if not ok:
        bound = f"> {low:g}" if strict else f">= {low:g}"
        span = f" and <= {high:g}" if math.isfinite(high) else ""
        raise InvalidParameter(name, value, f"must be a number {bound}{span}")
    return float(value)


def _finish(fringes: np.ndarray, blur: float, noise: float, rng: np.random.Generator) -> np.ndarray:
    """Blur, noise and the fixed grey map ``0.5 + v / (2 (1 + 3 noise))``, clipped to [0, 1]; float32."""
    vol = ndimage.gaussian_filter(fringes, blur, mode="nearest") if blur > 0 else fringes
    if noise > 0:
        vol += rng.standard_normal(vol.shape, dtype=np.float32) * np.float32(noise)
    vol *= np.float32(0.5 / (1.0 + _NOISE_SPAN * noise))
    vol += np.float32(0.5)
    np.clip(vol, 0.0, 1.0, out=vol)
    return vol.astype(np.float32, copy=False)


def onion_volume(
    shape: Sequence[int],
    period: float = 6.0,
    centres: int | None = None,
    *,
    blur: float = 0.8,
    noise: float = 0.3,
    seed: int = 0,
) -> np.ndarray:
    """Carbon onions: nested spherical shells ``period`` voxels apart around random centres.

    Parameters
    ----------
    shape : (D, H, W)
        Every side in [8, 512].
    period : float
        Distance between shells, voxels (> 2.5: a fringe needs more than two samples); HRTEM 5-8.
    centres : int, optional
        Number of onions, their centres uniform in the volume; by default 80 per 128^3 (at least 1): about
        ten per 64^3, so that a 64^3 sample's slice statistics are those of the material (an independent
        64^3 sample scores orientation KL <= 0.06 and fringe KS <= 0.13 against a 128^3 one's slices).
    blur : float
        Standard deviation of the Gaussian blur, voxels (0: none).
    noise : float
        Standard deviation of the Gaussian noise relative to the fringe amplitude (0: none).
    seed : int
        Seed of the centres and the noise: same arguments, same bytes.

    Returns
    -------
    ndarray of float32, shape ``shape``
        Grey in [0, 1]; every voxel on the shells of its nearest centre, ``cos(2 pi d / period)``.

    Examples
    --------
    >>> vol = onion_volume((16, 16, 16), seed=1)
    >>> vol.shape, vol.dtype.name
    ((16, 16, 16), 'float32')
    """
    dims = _check_shape(shape)
    period = _check_number("period", period, 2.5)
    blur = _check_number("blur", blur, 0.0, strict=False, high=16.0)
    noise = _check_number("noise", noise, 0.0, strict=False, high=10.0)
    if centres is None:
        centres = max(1, round(80 * math.prod(dims) / 128**3))
    if isinstance(centres, bool) or not isinstance(centres, int | np.integer) or not 1 <= centres <= 1000:
        raise InvalidParameter("centres", centres, "must be an integer in [1, 1000]")
    rng = np.random.default_rng(seed)
    where = rng.uniform(0.0, 1.0, (int(centres), 3)) * (np.array(dims, dtype=np.float64) - 1.0)
    z, y, x = (np.arange(n, dtype=np.float32) for n in dims)
    nearest = np.full(dims, np.inf, dtype=np.float32)
    for cz, cy, cx in where.astype(np.float32):
        d2 = (z[:, None, None] - cz) ** 2 + ((y[None, :, None] - cy) ** 2 + (x[None, None, :] - cx) ** 2)
        np.minimum(nearest, d2, out=nearest)
    np.sqrt(nearest, out=nearest)
    nearest *= np.float32(2.0 * math.pi / period)
    fringes = np.cos(nearest, out=nearest)
    return _finish(fringes, blur, noise, rng)


def turbostratic_volume(
    shape: Sequence[int],
    period: float = 6.0,
    normal: Sequence[float] = (1.0, 1.0, 1.0),
    *,
    crumple: float = 0.2,
    correlation: float = 8.0,
    blur: float = 0.8,
    noise: float = 0.3,
    seed: int = 0,
) -> np.ndarray:
    """A turbostratic stack of crumpled sheets: ``cos(2 pi phi / period)``, ``phi = n . r + u(r)``.

    Parameters
    ----------
    shape : (D, H, W)
        Every side in [8, 512].
    period : float
        Distance between sheets, voxels (> 2.5); HRTEM 5-8.
    normal : (n_z, n_y, n_x)
        Mean normal of the sheets (normalised here). ``(1, 1, 1)``: every plane cuts the sheets at the
        same angle (one exemplar fits the three planes); ``(1, 0, 0)``: sheets normal to z.
    crumple : float
        Root mean square of ``|grad u|`` over the volume, in [0, 0.6]: how far the local sheet normal
        and spacing wander (``|grad phi|`` stays within about ``1 +- crumple``); 0 gives flat sheets.
    correlation : float
        Standard deviation, voxels, of the Gaussian that smooths the displacement's white noise (the
        size of the crumples), in [1, 64]. With 12 a 64^3 sample held too few crumples for its fringe
        tortuosity to be the material's (KS up to 0.17 against a 128^3 sample's slices; 8: 0.13).
    blur, noise, seed
        As :func:`onion_volume`.

    Returns
    -------
    ndarray of float32, shape ``shape``
        Grey in [0, 1].

    Notes
    -----
    ``u`` is white noise filtered by a Gaussian of ``correlation`` voxels (periodic), then scaled so
    that the mean of ``|grad u|^2`` (central differences) is ``crumple^2``. The local period across
    the sheets is ``period / |n + grad u|``.

    Examples
    --------
    >>> vol = turbostratic_volume((16, 16, 16), seed=1)
    >>> vol.shape, vol.dtype.name
    ((16, 16, 16), 'float32')
    """
    dims = _check_shape(shape)
    period = _check_number("period", period, 2.5)
    crumple = _check_number("crumple", crumple, 0.0, strict=False, high=0.6)
    correlation = _check_number("correlation", correlation, 1.0, strict=False, high=64.0)
    blur = _check_number("blur", blur, 0.0, strict=False, high=16.0)
    noise = _check_number("noise", noise, 0.0, strict=False, high=10.0)
    try:
        n = np.asarray(normal, dtype=np.float64)
    except (TypeError, ValueError):
        raise InvalidParameter("normal", normal, "must be three finite numbers, not all zero") from None
    if n.shape != (3,) or not np.all(np.isfinite(n)) or np.linalg.norm(n) == 0:
        raise InvalidParameter("normal", normal, "must be three finite numbers, not all zero")
    n = n / np.linalg.norm(n)
    rng = np.random.default_rng(seed)
    phase = np.zeros(dims, dtype=np.float32)
    if crumple > 0:
        u = ndimage.gaussian_filter(rng.standard_normal(dims, dtype=np.float32), correlation, mode="wrap")
        grad_sq = np.zeros(dims, dtype=np.float32)
        for g in np.gradient(u):
            grad_sq += g * g
        u *= np.float32(crumple / max(math.sqrt(float(grad_sq.mean(dtype=np.float64))), 1e-12))
        del grad_sq
        phase += u
    for axis, component in enumerate(n):
        if component != 0:
            ramp = np.arange(dims[axis], dtype=np.float32) * np.float32(component)
            phase += ramp.reshape([-1 if k == axis else 1 for k in range(3)])
    phase *= np.float32(2.0 * math.pi / period)
    fringes = np.cos(phase, out=phase)
    return _finish(fringes, blur, noise, rng)
