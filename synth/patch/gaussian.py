"""Locally Gaussian patch models (Raad, Desolneux & Morel 2015, sec. 2): LG, CLG and RCLG.

A patch ``p`` (all pixels and channels stacked, length ``D = w^2 C``) splits into its overlap part
``Mp`` (``k`` values, known: ``y0``) and the rest ``Sp`` (eq. 2). Its model is learnt from the ``N``
exemplar patches nearest on the overlap (eq. 1): ``mu = mean(p_i)``, ``Sigma = A A^T`` with
``A = (P - mu) / sqrt(N)``, and ``G = Sigma + sigma^2 I``.

- **LG** (Raad et al. 2014): a draw ``mu + A z``, ``z ~ N(0, I_N)``; the overlap is ignored.
- **CLG** (eq. 4): ``x1 = mu1 + G12 G22^-1 (y0 - mu2)``, ``x2 = y0``.
- **RCLG** (eq. 7): ``p = (theta^2 G^-1 + M^T M)^-1 (M^T y0 + theta^2 G^-1 mu)``, the minimiser of eq. 5.

Everything is solved in the ``N``-dimensional span of the neighbours: by the matrix inversion lemma and
the push-through identity, with ``lam = sigma^2 + theta^2`` and ``c = (A2^T A2 + lam I_N)^-1 A2^T (y0 - mu2)``
(one ``N x N`` Cholesky),

    x1 = mu1 + A1 c,       x2 = y0 - (theta^2 / lam) (y0 - mu2 - A2 c);

``theta = 0`` gives CLG exactly, ``theta -> inf`` gives ``mu``. A patch costs ``O(N^2 k + N D)``.

Beyond the paper (derivations and reasons: docs/design.md, "locally Gaussian patch models"):
- :func:`rclg_draw`: a draw from the conditional law by Matheron's rule (its sec. 3.1 suggests it);
- :func:`rclg_neighbour`: Matheron's rule on one neighbour drawn uniformly (an ensemble Kalman filter's
  analysis, Evensen 1994), tapered away from the overlap (:func:`localisation_taper`, Houtekamer &
  Mitchell 2001);
- :func:`mend_inner_edges`: a two-sided patch's new part re-solved to meet its known part (a discrete
  Poisson equation, Pérez, Gangnet & Blake 2003).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import cho_factor, cho_solve
from scipy.ndimage import distance_transform_edt
from scipy.sparse import coo_matrix
from scipy.sparse.linalg import spsolve

__all__ = [
    "GaussianPatchModel",
    "clg_patch",
    "lg_patch",
    "localisation_taper",
    "mend_inner_edges",
    "rclg_draw",
    "rclg_neighbour",
    "rclg_patch",
    "restore_contrast",
]


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


def localisation_taper(known: np.ndarray, length: float) -> np.ndarray:
    """``exp(-d^2 / (2 length^2))``, ``d`` the Euclidean distance (pixels) to the nearest known pixel.

    ``known`` is a ``(h, w)`` mask: 1 on it, falling off away from it (the taper of
    :func:`rclg_neighbour`'s correction).

    Examples
    --------
    >>> known = np.zeros((1, 4), dtype=bool); known[0, 0] = True
    >>> np.round(localisation_taper(known, 1.0), 3)
    array([[1.   , 0.607, 0.135, 0.011]])
    """
    known = np.asarray(known, dtype=bool)
    if not known.any():
        return np.zeros(known.shape)
    d = distance_transform_edt(~known)
    return np.exp(-0.5 * (d / float(length)) ** 2)


def rclg_neighbour(
    model: GaussianPatchModel,
    known: np.ndarray,
    y0: np.ndarray,
    sigma: float,
    theta: float,
    rng: np.random.Generator,
    taper: np.ndarray | None = None,
    member: int | None = None,
) -> np.ndarray:
    """A neighbour drawn uniformly, corrected toward the overlap by the RCLG gain (a departure).

    Same parameters as :func:`rclg_patch`, plus ``rng`` and ``taper``. The neighbour ``p_j`` (one of the
    ``N`` patches the model is learnt from, ``mu + sqrt(N) A[:, j]``) is corrected as the prior draw of
    :func:`rclg_draw` is: ``p = p_j + A c`` with ``c = (A2^T A2 + lam I)^-1 A2^T (y0 - p_j2)``, its overlap
    part as in :func:`rclg_patch`. ``taper`` (shape ``(D,)``, 1 on the overlap; :func:`localisation_taper`)
    multiplies the correction ``A c`` pixel by pixel: the patch keeps the neighbour's own structure where
    the overlap says little about it. ``taper=None``: no taper (then the average over ``j`` is
    :func:`rclg_patch`, since the correction is linear). ``member``: the neighbour's index, already drawn
    (then ``rng`` is not used).
    """
    known = np.asarray(known, dtype=bool)
    n = model.A.shape[1]
    j = int(rng.integers(n)) if member is None else int(member)
    prior = model.mu + np.sqrt(n) * model.A[:, j]
    if not known.any():
        return prior
    d = np.asarray(y0, dtype=np.float64) - prior[known]
    corrected = _corrected(model, known, prior, d, sigma, theta)
    if taper is None:
        return corrected
    return prior + np.asarray(taper, dtype=np.float64) * (corrected - prior)


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


def mend_inner_edges(patch: np.ndarray, known: np.ndarray) -> np.ndarray:
    """A patch whose new part meets its known part without a jump (a departure, for two-sided patches).

    A conditional patch's known part is (close to) the output's values, its new part the model's
    continuation; where they meet (the inner edge of each strip) they differ by the part of the overlap
    the rank-``N`` model does not fit. A patch known along two opposite borders (the wrapped patches of a
    periodic layout) has to fit twice as many values with the same ``N`` neighbours: measured on HRTEM
    soot (128^2, seeds 1-3), its inner edges carry 1.2-2.9 times the mean gradient energy, against 1.1-2.0
    for the one-sided patches' (``docs/quality.md``, tileable outputs). Here the new part ``f`` minimises

        sum over 4-neighbour pairs (a, b), a new:  (f_a - f_b - t_ab)^2,   f_b = patch_b for b known,

    with ``t_ab = patch_a - patch_b`` between two new pixels (the patch's own gradients) and, across an
    inner edge ``b = a + d``, the gradient one step back inside the new part, ``patch_{a-d} - patch_a``
    (else one step on inside the known part, ``patch_b - patch_{b+d}``): a discrete Poisson equation with
    the known part as Dirichlet values and the patch's free borders as Neumann ones (Pérez, Gangnet &
    Blake 2003). Between new pixels nothing changes but the offset the jumps spread over the new part.

    Parameters
    ----------
    patch : ndarray, shape (w, w) or (w, w, C)
    known : ndarray of bool, shape (w, w)
        The known strips.

    Returns
    -------
    ndarray, float64, the shape of ``patch``
        The known part unchanged, the new part re-solved.

    Examples
    --------
    >>> ramp = np.tile(np.arange(6.0), (4, 1))
    >>> jumpy = ramp.copy(); jumpy[:, 2:4] += 5.0  # the new part (columns 2-3) off by 5
    >>> known = np.zeros((4, 6), dtype=bool); known[:, :2] = known[:, 4:] = True
    >>> np.allclose(mend_inner_edges(jumpy, known), ramp)
    True
    """
    p = np.asarray(patch, dtype=np.float64)
    p3 = p[..., None] if p.ndim == 2 else p
    h, w, channels = p3.shape
    new = ~np.asarray(known, dtype=bool)
    n = int(new.sum())
    if n == 0 or n == new.size:
        return p.copy()
    node = np.full((h, w), -1, dtype=np.int64)
    node[new] = np.arange(n)
    ys, xs = np.nonzero(new)
    degree = np.zeros(n)
    rhs = np.zeros((n, channels))
    rows: list[np.ndarray] = []
    cols: list[np.ndarray] = []
    crossings = 0

    def inside(r: np.ndarray, c: np.ndarray) -> np.ndarray:
        return (r >= 0) & (r < h) & (c >= 0) & (c < w)

    for dy, dx in ((0, 1), (0, -1), (1, 0), (-1, 0)):
        ok = inside(ys + dy, xs + dx)
        ay, ax, by, bx = ys[ok], xs[ok], ys[ok] + dy, xs[ok] + dx
        a = node[ay, ax]
        np.add.at(degree, a, 1.0)
        both = new[by, bx]
        np.add.at(rhs, a[both], p3[ay[both], ax[both]] - p3[by[both], bx[both]])
        rows.append(a[both])
        cols.append(node[by[both], bx[both]])
        # across an inner edge: a smooth estimate of the gradient instead of the jump
        cross = ~both
        crossings += int(cross.sum())
        ay, ax, by, bx, a = ay[cross], ax[cross], by[cross], bx[cross], a[cross]
        qy, qx = ay - dy, ax - dx
        back = inside(qy, qx)
        back[back] = new[qy[back], qx[back]]
        ry, rx = by + dy, bx + dx
        on = inside(ry, rx) & ~back
        on[on] = ~new[ry[on], rx[on]]
        grad = np.zeros((len(a), channels))
        grad[back] = p3[qy[back], qx[back]] - p3[ay[back], ax[back]]
        grad[on] = p3[by[on], bx[on]] - p3[ry[on], rx[on]]
        np.add.at(rhs, a, grad + p3[by, bx])
    if crossings == 0:
        return p.copy()
    off_r, off_c = np.concatenate(rows), np.concatenate(cols)
    matrix = coo_matrix(
        (
            np.concatenate([degree, -np.ones(off_r.size)]),
            (np.concatenate([np.arange(n), off_r]), np.concatenate([np.arange(n), off_c])),
        ),
        shape=(n, n),
    ).tocsc()
    solved = spsolve(matrix, rhs)
    out = p3.copy()
    out[new] = solved.reshape(n, channels)
    return out[..., 0] if p.ndim == 2 else out
