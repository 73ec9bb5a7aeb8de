"""Locally Gaussian patch models (Raad, Desolneux & Morel 2015, sec. 2): LG, CLG and RCLG.

A patch ``p`` (all pixels and channels stacked in one vector of length ``D = w^2 C``) splits into its
overlap part ``Mp`` (``k`` values, known: ``y0``) and the rest ``Sp`` (eq. 2). Its model is learnt from the
``N`` exemplar patches nearest on the overlap (eq. 1): ``mu = mean(p_i)``, ``Sigma = A A^T`` with
``A = (P - mu) / sqrt(N)`` the ``D x N`` centred patch matrix, and ``G = Sigma + sigma^2 I``.

- **LG** (Raad et al. 2014): a draw ``mu + A z``, ``z ~ N(0, I_N)``, exactly ``N(mu, Sigma)``; the overlap is
  ignored (the method stitches it afterwards).
- **CLG** (eq. 4): ``x1 = mu1 + G12 G22^-1 (y0 - mu2)``, ``x2 = y0``.
- **RCLG** (eq. 7): ``p = (theta^2 G^-1 + M^T M)^-1 (M^T y0 + theta^2 G^-1 mu)``, the minimiser of eq. 5.

Everything is solved in the ``N``-dimensional span of the neighbours. Eq. 7 is the posterior mean of ``p``
observed through ``y0 = Mp + n``, ``n ~ N(0, theta^2 I_k)``, so by the matrix inversion lemma
``p = mu + G M^T (M G M^T + theta^2 I)^-1 (y0 - mu2)``; with ``G22 = A2 A2^T + sigma^2 I`` and Woodbury /
the push-through identity ``A2^T (A2 A2^T + lam I)^-1 = (A2^T A2 + lam I_N)^-1 A2^T``,
``lam = sigma^2 + theta^2``, ``c = (A2^T A2 + lam I_N)^-1 A2^T (y0 - mu2)`` (one ``N x N`` Cholesky):

    x1 = mu1 + A1 c,       x2 = y0 - (theta^2 / lam) (y0 - mu2 - A2 c).

``theta = 0`` gives CLG exactly (``x2 = y0``; eq. 4 with ``lam = sigma^2``); ``theta -> inf`` gives
``p -> mu``. A patch costs ``O(N^2 k + N D)``, never ``O(D^3)``, and no matrix is inverted explicitly.

Beyond the paper (its sec. 3.1 suggests it: "sample a patch from [the RCLG law] instead of taking the
most probable one"), :func:`rclg_draw` draws from the conditional law by Matheron's rule: a prior draw
``p' = mu + A z`` and observation noise ``theta n`` are corrected by the same linear map as the mean,
``p = p' + G M^T (M G M^T + theta^2 I)^-1 (y0 - M p' - theta n)``. The ``sigma^2 I`` part of the prior is not
drawn (it would only add white pixel noise of standard deviation ``sigma``), so the draw lies in the
neighbours' span; it is exact for the model ``N(mu, Sigma)`` observed with the regularised gain.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import cho_factor, cho_solve

__all__ = ["GaussianPatchModel", "clg_patch", "lg_patch", "rclg_draw", "rclg_patch", "restore_contrast"]


@dataclass(frozen=True)
class GaussianPatchModel:
    """``mu`` (``D``) and the centred, scaled patch matrix ``A`` (``D x N``): ``Sigma = A A^T`` (eq. 1)."""

    mu: np.ndarray
    A: np.ndarray

    @classmethod
    def from_patches(cls, patches: np.ndarray) -> GaussianPatchModel:
        """The model of eq. 1 from ``patches`` of shape ``(N, ...)`` (each flattened to a vector)."""
        P = np.asarray(patches, dtype=np.float64).reshape(len(patches), -1)
        mu = P.mean(axis=0)
        return cls(mu=mu, A=((P - mu) / np.sqrt(len(P))).T)

    def covariance(self, sigma: float = 0.0) -> np.ndarray:
        """The dense ``D x D`` matrix ``Sigma + sigma^2 I`` (for tests and small cases only)."""
        return self.A @ self.A.T + sigma**2 * np.eye(self.A.shape[0])


def lg_patch(model: GaussianPatchModel, rng: np.random.Generator) -> np.ndarray:
    """LG: one draw from ``N(mu, Sigma)`` (``mu + A z``)."""
    return model.mu + model.A @ rng.standard_normal(model.A.shape[1])


def rclg_patch(
    model: GaussianPatchModel, known: np.ndarray, y0: np.ndarray, sigma: float, theta: float
) -> np.ndarray:
    """RCLG (eq. 7), solved in the span of the neighbours; ``theta = 0`` is CLG (eq. 4).

    Parameters
    ----------
    model : GaussianPatchModel
        ``mu`` and ``A`` (``D x N``).
    known : ndarray of bool, shape (D,)
        The overlap ``M`` as a mask over the patch vector.
    y0 : ndarray, shape (k,)
        The output's values on the overlap, in ``known``'s order.
    sigma : float
        ``G = Sigma + sigma^2 I``; must be > 0 when ``theta = 0``.
    theta : float
        Relaxation of the overlap (eq. 5); 0 = CLG.

    Returns
    -------
    ndarray, shape (D,)
        The most probable patch.
    """
    mu, A = model.mu, model.A
    known = np.asarray(known, dtype=bool)
    if not known.any():
        return mu.copy()
    lam = sigma**2 + theta**2
    A2 = A[known]
    d = np.asarray(y0, dtype=np.float64) - mu[known]
    gram = A2.T @ A2
    gram[np.diag_indices_from(gram)] += lam
    c = cho_solve(cho_factor(gram, lower=True), A2.T @ d)
    p = mu + A @ c
    p[known] = y0 - (theta**2 / lam) * (d - A2 @ c)
    return p


def _corrected(
    model: GaussianPatchModel, known: np.ndarray, prior: np.ndarray, d: np.ndarray, sigma: float, theta: float
) -> np.ndarray:
    """``prior + G M^T (G22 + theta^2 I)^-1 d`` in the span of the neighbours (module docstring)."""
    A = model.A
    lam = sigma**2 + theta**2
    A2 = A[known]
    gram = A2.T @ A2
    gram[np.diag_indices_from(gram)] += lam
    c = cho_solve(cho_factor(gram, lower=True), A2.T @ d)
    p = prior + A @ c
    p[known] = prior[known] + d - (theta**2 / lam) * (d - A2 @ c)
    return p


def rclg_draw(
    model: GaussianPatchModel,
    known: np.ndarray,
    y0: np.ndarray,
    sigma: float,
    theta: float,
    rng: np.random.Generator,
) -> np.ndarray:
    """A draw from the RCLG (``theta > 0``) or CLG (``theta = 0``) conditional law, by Matheron's rule.

    Same parameters as :func:`rclg_patch`, plus ``rng``. The mean of the draws is :func:`rclg_patch`.
    """
    known = np.asarray(known, dtype=bool)
    prior = lg_patch(model, rng)
    if not known.any():
        return prior
    noise = theta * rng.standard_normal(int(known.sum()))
    d = np.asarray(y0, dtype=np.float64) - prior[known] - noise
    return _corrected(model, known, prior, d, sigma, theta)


def clg_patch(model: GaussianPatchModel, known: np.ndarray, y0: np.ndarray, sigma: float) -> np.ndarray:
    """CLG (eq. 4): conditional mean of the unknown part given ``Mp = y0``, with ``G = Sigma + sigma^2 I``."""
    return rclg_patch(model, known, y0, sigma, 0.0)


def restore_contrast(model: GaussianPatchModel, known: np.ndarray, patch: np.ndarray) -> np.ndarray:
    """The new part of a conditional patch with its spread set to the neighbours' (a departure).

    The conditional mean is ``mu1 + A1 c``: the average of ``N`` neighbours' new parts plus a correction
    in their span. Where the neighbours agree on the overlap but not beyond it (any stochastic texture),
    the average is a blur, and the next patch, conditioned on that blur, finds flatter neighbours: the
    contrast decays patch after patch (docs/patch.md: soot's grey-level std falls from 0.16 to 0.07).
    Here the new part's deviations from its own mean are scaled so that its standard deviation is the
    neighbours' mean standard deviation over the same pixels; the overlap is left as it is.

    Parameters
    ----------
    model : GaussianPatchModel
        The neighbours' model (``mu``, ``A``): the neighbours are ``mu + sqrt(N) A[:, i]``.
    known : ndarray of bool, shape (D,)
        The overlap mask.
    patch : ndarray, shape (D,)
        The conditional estimate.
    """
    new = ~known
    if not new.any():
        return patch
    n = model.A.shape[1]
    neighbours = model.mu[new][None, :] + np.sqrt(n) * model.A[new].T  # (N, D_new)
    target = float(neighbours.std(axis=1).mean())
    values = patch[new]
    spread = float(values.std())
    if spread <= 1e-12:
        return patch
    out = patch.copy()
    centre = float(values.mean())
    out[new] = centre + (values - centre) * (target / spread)
    return out
