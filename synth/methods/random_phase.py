"""Random-phase noise (Galerne, Gousseau & Morel 2011): the exemplar's Fourier modulus, a random phase.

1. The exemplar ``u`` (``M x N``, each channel) is replaced by its periodic component ``p`` (Moisan 2011:
   ``u = p + s`` with ``s`` smooth, ``Laplacian(s) = Laplacian(u) - Laplacian_periodic(u)``, the boundary
   jumps), so that the borders add no cross to the spectrum.
2. Output of the exemplar's size: ``out = m + F^-1( F(p - m) e^{i phi} )`` with ``m`` the mean and ``phi`` the
   phase of the FFT of a Gaussian white-noise image (uniform and Hermitian-symmetric, so ``out`` is real).
3. Larger output ``M' x N'`` (the asymptotic discrete spot noise, sec. 3 of the IPOL paper): the normalised
   spot ``sqrt(M'N' / MN) (p - m)``, zero-padded to ``M' x N'``, takes the place of ``p - m``; its modulus
   keeps the exemplar's variance. A smaller output is the top-left crop of an exemplar-size one.
   Every output at least as large as the exemplar along both axes is periodic (an inverse FFT of its own
   size): it tiles. ``periodic=True`` makes a smaller output tile too: along an axis where the output is
   smaller, the exemplar is cropped to the output's size (top-left) before step 1, so the noise is made at
   the output's size instead of cropped from a larger one; otherwise it changes nothing.
4. Colour: the same random phase is added to the three channels' phases (their cross-spectra are kept).

References
----------
B. Galerne, Y. Gousseau, J.-M. Morel, "Random phase textures: theory and synthesis", IEEE TIP 20(1), 2011,
pp. 257-267; "Micro-texture synthesis by phase randomization", Image Processing On Line 1 (2011),
doi:10.5201/ipol.2011.ggm_rpn. L. Moisan, "Periodic plus smooth image decomposition", J. Math. Imaging
Vis. 39(2), 2011, pp. 161-179.

Departures
----------
- The output is clipped to [0, 1] (``stats['clipped_share']``); the papers display it clipped likewise.
- ``copy_map`` (extras) is computed as for every method here (a random-phase output copies nothing).
"""

from __future__ import annotations

import time

import numpy as np
from pydantic import Field
from scipy import fft as sfft

from texsynth.synth.api import MethodSpec, Progress, Result, register
from texsynth.synth.evaluate.patches import copy_map, copy_share
from texsynth.synth.methods.common import checked_progress
from texsynth.synth.params import MethodParams, ui
from texsynth.synth.threads import current_threads

__all__ = ["RandomPhaseParams", "periodic_component", "random_phase_noise", "run_random_phase"]


class RandomPhaseParams(MethodParams):
    """Random-phase noise: besides the seed and the output size, only whether a smaller output must tile."""

    periodic: bool = Field(
        False,
        description="Make the output tile seamlessly (always so when the output is at least the "
        "exemplar's size).",
        json_schema_extra=ui(
            basic=True,
            details=(
                "Tileable output. Random-phase noise is periodic by construction when the output is at "
                "least as large as the exemplar; with periodic=True a smaller output is made from an "
                "exemplar crop of its size instead of cropped from a larger noise, so it tiles too."
            ),
        ),
    )


def periodic_component(image: np.ndarray) -> np.ndarray:
    """Moisan's periodic component of a grey ``(M, N)`` or colour ``(M, N, C)`` image (float64).

    ``s_hat(q, r) = v_hat(q, r) / (2 cos(2 pi q / M) + 2 cos(2 pi r / N) - 4)``, ``s_hat(0, 0) = 0``, with
    ``v`` the boundary image (``v(0, y) = u(M-1, y) - u(0, y)``, ``v(M-1, y) = -v(0, y)``, and likewise along
    columns); ``p = u - s``. ``p`` keeps ``u``'s mean.
    """
    u = np.asarray(image, dtype=np.float64)
    u3 = u[..., None] if u.ndim == 2 else u
    m, n = u3.shape[:2]
    v = np.zeros_like(u3)
    v[0] += u3[-1] - u3[0]
    v[-1] -= u3[-1] - u3[0]
    v[:, 0] += u3[:, -1] - u3[:, 0]
    v[:, -1] -= u3[:, -1] - u3[:, 0]
    q = np.arange(m)[:, None]
    r = np.arange(n)[None, :]
    denom = 2 * np.cos(2 * np.pi * q / m) + 2 * np.cos(2 * np.pi * r / n) - 4
    denom[0, 0] = 1.0
    s_hat = sfft.fft2(v, axes=(0, 1)) / denom[..., None]
    s_hat[0, 0] = 0.0
    p = u3 - sfft.ifft2(s_hat, axes=(0, 1)).real
    return p[..., 0] if u.ndim == 2 else p


def random_phase_noise(exemplar: np.ndarray, shape: tuple[int, int], rng: np.random.Generator) -> np.ndarray:
    """Random-phase noise of ``shape`` from ``exemplar`` (float64, unclipped).

    Parameters
    ----------
    exemplar : ndarray, shape (M, N) or (M, N, C)
    shape : (int, int)
        Output ``(M', N')``.
    rng : numpy.random.Generator

    Returns
    -------
    ndarray, shape (M', N') or (M', N', C)
        float64 values; the FFTs run in float32 (single precision, about 1e-7 relative).
    """
    p = periodic_component(exemplar)
    p3 = p[..., None] if p.ndim == 2 else p
    m, n = p3.shape[:2]
    mean = p3.mean(axis=(0, 1))
    out_m, out_n = max(m, shape[0]), max(n, shape[1])
    # float32 FFTs (complex64): half the time of float64 at 2048^2, and far below 8-bit output precision.
    spot = np.zeros((out_m, out_n, p3.shape[2]), dtype=np.float32)
    spot[:m, :n] = (p3 - mean) * np.sqrt(out_m * out_n / (m * n))
    # The job's threads share each 2D FFT's independent 1D transforms: the same bytes on any count.
    workers = current_threads()
    phase = sfft.rfft2(rng.standard_normal((out_m, out_n), dtype=np.float32), workers=workers)
    phase /= np.maximum(np.abs(phase), np.finfo(np.float32).tiny)
    spectrum = sfft.rfft2(spot, axes=(0, 1), workers=workers) * phase[..., None]
    out = sfft.irfft2(spectrum, s=(out_m, out_n), axes=(0, 1), workers=workers)[: shape[0], : shape[1]] + mean
    return out[..., 0] if p.ndim == 2 else out


def run_random_phase(
    exemplar: np.ndarray,
    *,
    size: tuple[int, int],
    params: RandomPhaseParams,
    seed: int,
    progress: Progress,
    constraint: np.ndarray | None = None,
) -> Result:
    report = checked_progress(progress)
    start = time.perf_counter()
    shape = (int(size[0]), int(size[1]))
    source = exemplar[: shape[0], : shape[1]] if params.periodic else exemplar
    raw = random_phase_noise(source, shape, np.random.default_rng(seed))
    clipped = float(np.mean((raw < 0) | (raw > 1)))
    image = np.clip(raw, 0.0, 1.0).astype(np.float32)
    t_synth = time.perf_counter() - start
    report("copy map", 0.5)
    cmap = copy_map(image, exemplar)
    report("done", 1.0)
    return Result(
        method="random-phase",
        image=image,
        params=params.model_dump(),
        seed=seed,
        timings={"synthesis": t_synth, "copy_map": time.perf_counter() - start - t_synth},
        extras={"copy_map": cmap},
        stats={"clipped_share": clipped, "copy_share": copy_share(cmap)},
    )


SPEC = register(
    MethodSpec(
        name="random-phase",
        summary="Random-phase noise: the exemplar's Fourier modulus, a random phase (Galerne et al. 2011).",
        params_model=RandomPhaseParams,
        run=run_random_phase,
        paper="Galerne, Gousseau & Morel, IEEE TIP 2011",
    )
)
