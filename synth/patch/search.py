"""Masked SSD of a template against every exemplar patch, by FFT correlation.

For a template ``T`` (``w x w x C``) and per-pixel weights ``M`` (the overlap mask, 0/1), the masked sum of
squared differences at every exemplar position ``q`` is expanded as

    SSD(q) = sum_u M(u) E(q + u)^2  -  2 sum_u M(u) T(u) E(q + u)  +  sum_u M(u) T(u)^2,

three correlations of which the first depends on the mask only (computed once per mask kind and cached) and
the second is one real FFT product per channel. A circular correlation on the exemplar's own grid is exact
at every valid position (``q + u`` never wraps), so no padding is needed. Sums are in float64 and the result
is clipped at 0 (the expansion can round to tiny negatives).

:meth:`PatchSearcher.normalised_ssd` divides it by ``n (var_T + var_E(q))``, the template's and each
candidate's own variance on the mask (two more cached correlations of the mask: ``sum M E`` beside
``sum M E^2``), so that an uncorrelated candidate scores about 1 whatever its contrast (quilting's
``error='normalised'``, docs/patch.md). :meth:`PatchSearcher.errors` gives both, times the usage factors,
with the arithmetic around the FFTs in ``nogil`` numba kernels (:mod:`texsynth.synth.kernels.patch_search`):
the patches of a wave search at once on the job's threads. :meth:`PatchSearcher.ssd_reference` and
:meth:`PatchSearcher.normalised_ssd` are the NumPy versions the tests compare it with (the same bytes).
"""

from __future__ import annotations

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view
from scipy import fft as sfft

from texsynth.synth.kernels import patch_search as kernels
from texsynth.synth.threads import thread_map

__all__ = ["PatchSearcher", "candidates_within", "k_nearest"]


class PatchSearcher:
    """Every ``w x w`` patch of an exemplar, searchable by masked SSD.

    Parameters
    ----------
    exemplar : ndarray, shape (h, w) or (h, w, C)
        The exemplar (float, any number of channels: colour, or colour plus guide channels).
    w : int
        Patch side; ``w <= min(h, w)``.

    Examples
    --------
    >>> ex = np.arange(36.0).reshape(6, 6) / 36
    >>> s = PatchSearcher(ex, 3)
    >>> d = s.ssd(ex[2:5, 1:4], np.ones((3, 3)))
    >>> np.unravel_index(np.argmin(d), d.shape)
    (np.int64(2), np.int64(1))
    """

    def __init__(self, exemplar: np.ndarray, w: int) -> None:
        ex = np.asarray(exemplar, dtype=np.float64)
        self.exemplar = ex[..., None] if ex.ndim == 2 else ex
        self.w = int(w)
        h, wd, _ = self.exemplar.shape
        self.grid = (h, wd)
        self.positions_shape = (h - self.w + 1, wd - self.w + 1)
        self._spectra = sfft.rfft2(self.exemplar, axes=(0, 1))
        self._square_spectra = sfft.rfft2(self.exemplar**2, axes=(0, 1))
        self._energy: dict[bytes, np.ndarray] = {}
        self._first: dict[bytes, np.ndarray] = {}
        self._masks: dict[tuple, tuple[np.ndarray, bytes, float]] = {}
        self._stacks: dict[tuple, tuple[np.ndarray, np.ndarray]] = {}
        self._eps = 1e-3 * float(self.exemplar.var()) + 1e-12
        self.windows = sliding_window_view(self.exemplar, (self.w, self.w), axis=(0, 1))

    @property
    def channels(self) -> int:
        return self.exemplar.shape[2]

    def _correlate(self, spectra: np.ndarray, kernel: np.ndarray) -> np.ndarray:
        """``sum_c sum_u kernel[u, c] X_c(q + u)`` at every valid ``q`` (``spectra`` = rfft2 of X)."""
        k = sfft.rfft2(kernel, s=self.grid, axes=(0, 1))
        prod = (spectra * np.conj(k)).sum(axis=2)
        full = sfft.irfft2(prod, s=self.grid)
        return full[: self.positions_shape[0], : self.positions_shape[1]]

    def _weights(self, mask: np.ndarray) -> np.ndarray:
        m = np.asarray(mask, dtype=np.float64)
        if m.ndim == 2:
            m = np.repeat(m[..., None], self.channels, axis=2)
        return m

    @staticmethod
    def _key(m: np.ndarray) -> bytes:
        if not np.all((m == 0) | (m == 1)):
            return m.tobytes()
        return np.packbits(m > 0).tobytes() + m.shape[2].to_bytes(2, "little")

    def _prepared(self, mask: np.ndarray) -> tuple[np.ndarray, bytes, float]:
        """A mask's per-channel weights (contiguous float64), cache key and weight sum, made once per mask
        (the patch loops pass the same few masks at every patch)."""
        mask = np.asarray(mask)
        index = (mask.shape, mask.dtype.str, mask.tobytes())
        got = self._masks.get(index)
        if got is None:
            m = np.ascontiguousarray(self._weights(mask))
            got = self._masks[index] = (m, self._key(m), float(m.sum()))
        return got

    def search_many(
        self,
        templates: np.ndarray,
        masks: list[np.ndarray],
        normalised: bool,
        factors: np.ndarray | None,
        tolerance: float,
        threads: int = 1,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`errors` and the candidates within ``(1 + tolerance)`` of the best of ``k`` templates at
        once: the FFTs of all of them in one SciPy call (``workers=threads``), the rest in numba's threads.

        Parameters
        ----------
        templates : ndarray, shape (k, w, w, C)
        masks : list of k ndarray, shape (w, w)
        normalised, factors
            As :meth:`errors`.
        tolerance : float
            As :func:`candidates_within`.
        threads : int
            Threads of the FFTs, the per-template products and the kernel; 1: all on the calling thread
            (a chunk of a wave, several chunks searched at once on Python threads).

        Returns
        -------
        err, ssd : ndarray, shape (k, P, Q)
        pools : ndarray, shape (k, P Q)
            Row ``b``'s first ``counts[b]`` entries are template ``b``'s candidates (flat, ascending).
        counts : ndarray, shape (k,)

        The same bytes as :meth:`errors` and :func:`candidates_within` one template at a time (SciPy's
        transforms of a stack are those of each array; the spectral product stays NumPy's per template).
        """
        prepared = [self._prepared(m) for m in masks]
        index: dict[bytes, int] = {}
        uniq: list[tuple[np.ndarray, bytes]] = []
        which = np.empty(len(prepared), dtype=np.int64)
        for b, (m, key, _) in enumerate(prepared):
            if key not in index:
                index[key] = len(uniq)
                uniq.append((m, key))
            which[b] = index[key]
        stack_key = (tuple(k for _, k in uniq), bool(normalised))
        stacked = self._stacks.get(stack_key)
        if stacked is None:
            energy = np.stack([self._energy_of(m, key) for m, key in uniq])
            first = np.stack([self._mask_sums(m)[1] for m, _ in uniq]) if normalised else energy
            stacked = self._stacks[stack_key] = (energy, first)
        energy, first = stacked
        weights = np.stack([p[0] for p in prepared])
        n = np.array([p[2] for p in prepared])
        t = np.ascontiguousarray(templates, dtype=np.float64)
        mt, sum_t, sum_tt = kernels.template_terms_many(weights, t)
        spectra = sfft.rfft2(mt, s=self.grid, axes=(1, 2), workers=threads)
        products = np.empty(spectra.shape[:3], dtype=spectra.dtype)

        def product(b: int) -> None:  # NumPy's, template by template: the bytes of errors()
            np.sum(self._spectra * np.conj(spectra[b]), axis=2, out=products[b])

        thread_map(product, range(len(t)), threads)
        cross = sfft.irfft2(products, s=self.grid, axes=(1, 2), workers=threads)
        weighted = factors is not None
        f = np.ascontiguousarray(factors, dtype=np.float64) if weighted else np.ones((1, 1))
        per_template = (which, cross, sum_t, sum_tt, n)
        flags = (bool(normalised), weighted)
        finish = kernels.search_many if threads > 1 else kernels.search_many_serial
        return finish((energy, first), per_template, f, (self._eps, float(tolerance)), flags)

    def mask_weight(self, mask: np.ndarray) -> float:
        """``sum M`` over every channel: the number of known values of a 0/1 mask."""
        return self._prepared(mask)[2]

    def _energy_of(self, m: np.ndarray, key: bytes) -> np.ndarray:
        energy = self._energy.get(key)
        if energy is None:
            energy = self._energy[key] = self._correlate(self._square_spectra, m)
        return energy

    def errors(
        self,
        template: np.ndarray,
        mask: np.ndarray,
        normalised: bool = False,
        factors: np.ndarray | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """The search error of every candidate position and its plain masked SSD (numba kernels).

        The error is :meth:`ssd`, or with ``normalised`` :meth:`normalised_ssd`, times ``factors`` (the
        usage penalty, :class:`texsynth.synth.patch.usage.UsagePenalty`) when given: the same bytes as
        those NumPy methods, with one FFT product per template.

        Returns
        -------
        (ndarray, ndarray), each ``(h - w + 1, w_ex - w + 1)`` float64
            The error, and the SSD (``>= 0``).
        """
        m, key, n = self._prepared(mask)
        t = np.asarray(template, dtype=np.float64)
        t = np.ascontiguousarray(t[..., None] if t.ndim == 2 else t)
        energy = self._energy_of(m, key)
        first = self._mask_sums(m)[1] if normalised else energy
        mt, sum_t, sum_tt = kernels.template_terms(m, t)
        cross = self._correlate(self._spectra, mt)
        weighted = factors is not None
        f = np.ascontiguousarray(factors, dtype=np.float64) if weighted else np.ones((1, 1))
        terms = (float(sum_t), float(sum_tt), float(n), float(self._eps))
        return kernels.finish_errors((energy, cross, first, f), terms, (bool(normalised), weighted))

    def _mask_sums(self, m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``sum_u M(u) E(q + u)^2`` and ``sum_u M(u) E(q + u)`` at every ``q`` (cached per mask)."""
        key = self._key(m)
        energy = self._energy.get(key)
        if energy is None:
            energy = self._correlate(self._square_spectra, m)
            self._energy[key] = energy
        first = self._first.get(key)
        if first is None:
            first = self._correlate(self._spectra, m)
            self._first[key] = first
        return energy, first

    def normalised_ssd(
        self, template: np.ndarray, mask: np.ndarray, ssd: np.ndarray | None = None
    ) -> np.ndarray:
        """Masked SSD over the sum of the template's and each candidate's own variance on the mask.

        ``SSD(q) / (n (var_T + var_E(q)) + eps)``, with ``n = sum M``, the variances taken over the masked
        values (all channels pooled) and ``eps`` a thousandth of the exemplar's variance times ``n``. An
        uncorrelated candidate scores about 1 whatever its own contrast, a matching one about 0: unlike
        the plain SSD (about ``n (var_T + var_E)`` for an uncorrelated candidate), a flat candidate is not
        preferred for being flat. Same shapes as :meth:`ssd`; ``ssd``: :meth:`ssd` of the same template
        and mask when already computed.
        """
        m = self._weights(mask)
        if ssd is None:
            ssd = self.ssd_reference(template, m)
        energy, first = self._mask_sums(m)
        n = float(m.sum())
        var_e = np.maximum(energy / n - (first / n) ** 2, 0.0)
        t = np.asarray(template, dtype=np.float64)
        t = t[..., None] if t.ndim == 2 else t
        mean_t = float(np.sum(m * t)) / n
        var_t = max(float(np.sum(m * t * t)) / n - mean_t**2, 0.0)
        return ssd / (n * (var_t + var_e + self._eps))

    def ssd(self, template: np.ndarray, mask: np.ndarray) -> np.ndarray:
        """Masked SSD of ``template`` against every exemplar patch (:meth:`errors`'s second array).

        Parameters
        ----------
        template : ndarray, shape (w, w) or (w, w, C)
            Values outside the mask are ignored.
        mask : ndarray, shape (w, w) or (w, w, C)
            Weights (0/1 for an overlap mask); a 2-D mask applies to every channel.

        Returns
        -------
        ndarray, shape (h - w + 1, w_ex - w + 1)
            The SSD at every top-left exemplar position, float64, >= 0.
        """
        return self.errors(template, mask)[1]

    def ssd_reference(self, template: np.ndarray, mask: np.ndarray) -> np.ndarray:
        """:meth:`ssd` in plain NumPy (same arguments and result): the reference its tests compare with."""
        m = self._weights(mask)
        t = np.asarray(template, dtype=np.float64)
        t = t[..., None] if t.ndim == 2 else t
        key = self._key(m)
        energy = self._energy.get(key)
        if energy is None:
            energy = self._correlate(self._square_spectra, m)
            self._energy[key] = energy
        mt = m * t
        cross = self._correlate(self._spectra, mt)
        out = energy - 2.0 * cross + float(np.sum(mt * t))
        return np.maximum(out, 0.0)

    def patch(self, y: int, x: int) -> np.ndarray:
        """The exemplar patch with top-left corner ``(y, x)``, ``(w, w, C)``."""
        return self.exemplar[y : y + self.w, x : x + self.w]

    def patches(self, flat_indices: np.ndarray) -> np.ndarray:
        """Patches at flat positions (into :attr:`positions_shape`), ``(n, w, w, C)``."""
        ys, xs = np.unravel_index(np.asarray(flat_indices), self.positions_shape)
        return np.moveaxis(self.windows[ys, xs], 1, -1)


def k_nearest(ssd: np.ndarray, k: int) -> np.ndarray:
    """Flat indices of the ``k`` smallest values of ``ssd``, nearest first (ties by index: deterministic)."""
    flat = ssd.ravel()
    k = min(int(k), flat.size)
    part = np.argpartition(flat, k - 1)[:k] if k < flat.size else np.arange(flat.size)
    return part[np.lexsort((part, flat[part]))]


def candidates_within(ssd: np.ndarray, tolerance: float) -> np.ndarray:
    """Flat indices whose SSD is within ``(1 + tolerance)`` of the best (Efros & Freeman 2001, sec. 2.1).

    When the best error is 0 (an exact match) every exact match qualifies.
    """
    flat = ssd.ravel()
    best = float(flat.min())
    bound = best * (1.0 + tolerance)
    return np.flatnonzero(flat <= bound + 1e-12 * max(1.0, best))
