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
``error='normalised'``, docs/patch.md).
"""

from __future__ import annotations

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view
from scipy import fft as sfft

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
            ssd = self.ssd(template, m)
        energy, first = self._mask_sums(m)
        n = float(m.sum())
        var_e = np.maximum(energy / n - (first / n) ** 2, 0.0)
        t = np.asarray(template, dtype=np.float64)
        t = t[..., None] if t.ndim == 2 else t
        mean_t = float(np.sum(m * t)) / n
        var_t = max(float(np.sum(m * t * t)) / n - mean_t**2, 0.0)
        eps = 1e-3 * float(self.exemplar.var()) + 1e-12
        return ssd / (n * (var_t + var_e + eps))

    def ssd(self, template: np.ndarray, mask: np.ndarray) -> np.ndarray:
        """Masked SSD of ``template`` against every exemplar patch.

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
