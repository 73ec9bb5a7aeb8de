"""Hints laid along the constraint's strands: each output strand proposes one exemplar fibre along its length.

Why: arbitrary-shape synthesis (:mod:`texsynth.synth.methods.arbitrary_shape`) offers every output position a
*hint*, an exemplar point in the rotated copy at the local angle. The paper's route takes it from an
exemplar-like texture synthesized in the exemplar's own frame (section 2.1: "synthesize a texture of
the constraint's size first"), so along a constraint strand that runs across the exemplar's fibres
the hints jump from fibre to fibre; a fibrous exemplar whose fibres each have their own grey level
(wood grain) then comes out as a patchwork of grey along each strand (docs/arbitrary-shape.md,
"Continuous strands"). This module lays them along the constraint's flow (``hint_layout='strands'``).
How (a piecewise parametrisation of the output by the constraint's strands):

1. **Fibre table** (:func:`fibre_table`): in the exemplar, the streamlines of its own structure
   direction from points on the line through its centre across its dominant fibre direction, one per
   pixel: entry ``(a, s)`` is the point ``s`` pixels along fibre ``a``. Only points at least
   ``margin`` pixels inside the exemplar count (a rotated copy can hold their neighbourhood); each
   fibre keeps its run through the centre, and ``s`` wraps within that run (the same fibre again).
2. **Cuts**: seeds on a jittered grid ``spacing`` pixels apart; through each, a curve across the
   strands (the streamline of the normal field), ``1.2 spacing`` long, rasterised 2 pixels thick, each
   of its pixels knowing its distance ``u`` along the cut; each cut gets a random fibre ``a0`` and
   offset ``s0``.
3. **Parameters of every pixel** (:func:`texsynth.synth.kernels.streamline_hits.first_hits`): its strand is
   followed both ways until it meets a cut (the nearer one wins); the pixel's across coordinate is the
   ``u`` where it met the cut (constant along the strand), its along coordinate the signed number of
   steps. Its hint is the table's entry ``(a0 + u, s0 + s)``: along a strand the fibre stays the same
   until the strand is nearer the next cut (runs of about ``spacing`` pixels), and neighbouring strands
   get neighbouring fibres, so the hints show an undistorted strip of exemplar along the strand.
4. **Copy**: the copy whose turn carries the fibre's direction at the hint (signed) onto the strand's
   (signed) direction at the pixel, so that the strip keeps its handedness. A pixel whose strand
   meets no cut within ``2 spacing`` steps (near a spiral's centre) takes a random fibre.
"""

from __future__ import annotations

import heapq
from dataclasses import dataclass

import numpy as np

from texsynth.synth.analysis.streamlines import doubled_angle, trace
from texsynth.synth.kernels.streamline_hits import first_hits

__all__ = ["FibreTable", "StrandHints", "fibre_table", "strand_hints"]


@dataclass(frozen=True)
class FibreTable:
    """``positions[a, s]`` (row, col) = the point ``s - centre`` pixels along fibre ``a`` (float64);
    fibre ``a`` is valid for ``lo[a] <= s <= hi[a]`` (``lo <= centre <= hi``)."""

    positions: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    centre: int

    @property
    def n_fibres(self) -> int:
        return len(self.lo)


def _rot90(d: np.ndarray) -> np.ndarray:
    """A (row, col) direction turned a quarter counter-clockwise (y up)."""
    return np.stack([-d[..., 1], d[..., 0]], axis=-1)


def _plus(angle: float) -> np.ndarray:
    """The (row, col) unit direction of a strand angle, rightwards (down when vertical)."""
    d = np.array([-np.sin(angle), np.cos(angle)])
    return -d if d[1] < 0 or (d[1] == 0 and d[0] < 0) else d


def fibre_table(direction: np.ndarray, dominant: float, margin: int) -> FibreTable:
    """The exemplar's fibres (streamlines of its structure ``direction``, radians, (h, w)) from the line
    through its centre across its ``dominant`` structure direction (radians); points at least
    ``margin`` pixels inside the exemplar."""
    h, w = direction.shape
    reach = int(np.ceil(np.hypot(h, w) / 2)) + 1
    t_dom = _plus(dominant)
    centre = np.array([(h - 1) / 2, (w - 1) / 2])
    offsets = np.arange(-reach, reach + 1, dtype=np.float64)
    starts = centre + offsets[:, None] * _rot90(t_dom)[None, :]

    def inside(p: np.ndarray) -> np.ndarray:
        rows_in = (p[..., 0] >= margin) & (p[..., 0] <= h - 1 - margin)
        return rows_in & (p[..., 1] >= margin) & (p[..., 1] <= w - 1 - margin)

    starts = starts[inside(starts)]
    fwd = np.broadcast_to(t_dom, starts.shape)
    ahead = trace(direction, starts, 2 * reach, forward=fwd)
    behind = trace(direction, starts, 2 * reach, forward=-fwd)
    pos = np.concatenate([behind[:0:-1], ahead], axis=0).transpose(1, 0, 2)  # (n_a, 4 reach + 1, 2)
    c = 2 * reach
    ok = inside(pos)
    run_ahead = np.cumprod(ok[:, c:], axis=1).sum(axis=1)
    run_behind = np.cumprod(ok[:, c::-1], axis=1).sum(axis=1)
    return FibreTable(np.ascontiguousarray(pos), c - run_behind + 1, c + run_ahead - 1, c)


@dataclass(frozen=True)
class StrandHints:
    """``source`` (H, W, 2) int64 exemplar positions; ``copy_angle`` (H, W) the turn (radians,
    modulo 2 pi) that carries the fibre's signed direction at the source onto the strand's at the
    pixel; ``missed`` the share of pixels whose strand met no cut."""

    source: np.ndarray
    copy_angle: np.ndarray
    missed: float


def _cuts(strand_angle, spacing, rng, periodic):
    """Rasterised cuts: label (H, W) int64 (-1: none), and per pixel u, the cut point and its normal."""
    h, w = strand_angle.shape
    # cuts every ``spacing`` px from half a spacing in; a side shorter than a spacing gets one, at its middle
    rows = np.arange(min(spacing, h) / 2, h, spacing)
    cols = np.arange(min(spacing, w) / 2, w, spacing)
    seeds = np.stack(np.meshgrid(rows, cols, indexing="ij"), axis=-1).reshape(-1, 2)
    seeds = seeds + rng.uniform(-spacing / 4, spacing / 4, seeds.shape)
    n_steps = round(1.2 * spacing)
    normal = strand_angle + np.pi / 2
    ahead = trace(normal, seeds, n_steps, step=0.5, periodic=periodic)
    behind = trace(normal, seeds, n_steps, step=0.5, forward=-(ahead[1] - ahead[0]), periodic=periodic)
    pts = np.concatenate([behind[:0:-1], ahead], axis=0)  # (2 n + 1, K, 2)
    u = np.arange(-n_steps, n_steps + 1) * 0.5
    travel = np.gradient(pts, axis=0)
    travel /= np.maximum(np.linalg.norm(travel, axis=-1, keepdims=True), 1e-12)
    ids = np.broadcast_to(np.arange(len(seeds)), pts.shape[:2])
    uu = np.broadcast_to(u[:, None], pts.shape[:2])
    # sample order: cut by cut (later cuts overwrite earlier ones where they cross)
    pts, travel = pts.transpose(1, 0, 2).reshape(-1, 2), travel.transpose(1, 0, 2).reshape(-1, 2)
    ids, uu = ids.T.reshape(-1), uu.T.reshape(-1)
    label = np.full((h, w), -1, np.int64)
    data = np.zeros((h, w, 5))
    for dr in (0, 1):
        for dc in (0, 1):
            r = np.floor(pts[:, 0]).astype(np.int64) + dr
            c = np.floor(pts[:, 1]).astype(np.int64) + dc
            if periodic:
                r, c, keep = r % h, c % w, np.ones(len(r), bool)
            else:
                keep = (r >= 0) & (r < h) & (c >= 0) & (c < w)
            label[r[keep], c[keep]] = ids[keep]
            data[r[keep], c[keep]] = np.column_stack([uu, pts, travel])[keep]
    return label, data, pts.reshape(len(seeds), -1, 2), uu.reshape(len(seeds), -1)


def _link_cuts(strand_angle, label, data, cut_pts, cut_u, spacing, fibre_of, s0, periodic):
    """Each cut's fibre index along it (``fibre_of`` (cuts, samples), over its samples' ``u``), along
    offset ``s0`` and orientation (+-1), such that a strand crossing from one cut's reach into the next
    keeps its fibre: from points of every cut (every 2 px) the strands are followed both ways to the
    next cut; cuts are joined along a maximum spanning tree of the number of strands linking them (Prim,
    from cut 0), each new cut taking, at the points its parent's strands reach, the parent's fibre
    there (interpolated between them, the least-squares line beyond: strands may be closer together
    on one cut than on the other, e.g. where the waves are steep), the median along offset and the
    slope's sign as orientation. Loops (rings) close with at most one seam per loop."""
    h, w = label.shape
    n_cuts, n_samples = cut_u.shape
    sub = np.arange(0, n_samples, 4)
    pts = cut_pts[:, sub].reshape(-1, 2)
    own = np.repeat(np.arange(n_cuts), len(sub))
    u_own = cut_u[:, sub].reshape(-1)
    ir, ic = np.floor(pts[:, 0] + 0.5).astype(np.int64), np.floor(pts[:, 1] + 0.5).astype(np.int64)
    if periodic:
        ir, ic, keep = ir % h, ic % w, np.ones(len(ir), bool)
    else:
        keep = (ir >= 0) & (ir < h) & (ic >= 0) & (ic < w)
    keep &= label[np.clip(ir, 0, h - 1), np.clip(ic, 0, w - 1)] == own
    pts, own, u_own = pts[keep], own[keep], u_own[keep]
    n_own = data[np.clip(ir[keep], 0, h - 1), np.clip(ic[keep], 0, w - 1), 3:5]
    t_own = np.stack([n_own[:, 1], -n_own[:, 0]], axis=-1)
    links: dict[tuple[int, int], list[tuple[float, float, float, float]]] = {}
    for direction in (1.0, -1.0):
        curve = trace(strand_angle, pts, 2 * spacing, forward=direction * t_own, periodic=periodic)
        cr = np.floor(curve[..., 0] + 0.5).astype(np.int64)
        cc = np.floor(curve[..., 1] + 0.5).astype(np.int64)
        if periodic:
            cr, cc, inside = cr % h, cc % w, np.ones(cr.shape, bool)
        else:
            inside = np.cumprod((cr >= 0) & (cr < h) & (cc >= 0) & (cc < w), axis=0).astype(bool)
        lab = np.where(inside, label[np.clip(cr, 0, h - 1), np.clip(cc, 0, w - 1)], -1)
        other = (lab >= 0) & (lab != own[None, :])
        other[:3] = False
        hit_any = other.any(axis=0)
        step = other.argmax(axis=0)
        for i in np.flatnonzero(hit_any):
            k, j = int(own[i]), int(lab[step[i], i])
            d = data[cr[step[i], i], cc[step[i], i]]
            u_j = d[0] + float(((curve[step[i], i] - d[1:3]) * d[3:5]).sum())
            travel = curve[step[i], i] - curve[step[i] - 1, i]
            t_j = np.array([d[4], -d[3]])
            rel = 1.0 if direction * float(travel @ t_j) > 0 else -1.0
            links.setdefault((k, j), []).append((u_own[i], u_j, rel, direction * step[i]))
    counts = {}
    for (k, j), rec in links.items():
        counts[(k, j)] = counts.get((k, j), 0) + len(rec)
    fibre_of, s0, flip = fibre_of.copy(), s0.copy(), np.ones(n_cuts)
    grid = cut_u[0]
    done = np.zeros(n_cuts, bool)

    for root in range(n_cuts):
        if done[root]:
            continue
        done[root] = True
        heap = [(-c, k, j) for (k, j), c in counts.items() if k == root]
        heapq.heapify(heap)
        while heap:
            _, k, j = heapq.heappop(heap)
            if done[j]:
                continue
            rec = np.array(links[(k, j)])
            rel = 1.0 if rec[:, 2].sum() >= 0 else -1.0
            y = np.interp(rec[:, 0], grid, fibre_of[k])
            slope = _fit_slope(rec[:, 1], y, flip[k] * rel)
            flip[j] = 1.0 if slope > 0 else -1.0
            order = np.argsort(rec[:, 1], kind="stable")
            xs, ys = rec[order, 1], y[order]
            row = np.interp(grid, xs, ys)
            row = np.where(grid < xs[0], ys[0] + slope * (grid - xs[0]), row)
            fibre_of[j] = np.where(grid > xs[-1], ys[-1] + slope * (grid - xs[-1]), row)
            s0[j] = s0[k] + float(np.median(flip[k] * rec[:, 3]))
            done[j] = True
            for (k2, j2), c in counts.items():
                if k2 == j and not done[j2]:
                    heapq.heappush(heap, (-c, k2, j2))
    return fibre_of, s0, flip


def _fit_slope(x: np.ndarray, y: np.ndarray, sign: float) -> float:
    """Slope of ``y`` on ``x`` (least squares), its size kept within [1/2, 2]; ``sign`` (the
    strands' orientation) with fewer than 3 points or a slope near 0."""
    if len(x) < 3 or np.ptp(x) < 1.0:
        return sign
    xc = x - x.mean()
    b = float((xc * (y - y.mean())).sum() / (xc * xc).sum())
    if abs(b) < 0.25:
        return sign
    return float(np.sign(b) * np.clip(abs(b), 0.5, 2.0))


def strand_hints(
    strand_angle: np.ndarray,
    table: FibreTable,
    spacing: int,
    rng: np.random.Generator,
    *,
    periodic: bool = False,
    linked: bool = True,
) -> StrandHints:
    """Hints along the strands of ``strand_angle`` (the constraint's strand direction, radians, (H, W))
    from the exemplar fibres of ``table``; cuts ``spacing`` pixels apart (see the module's docstring)."""
    h, w = strand_angle.shape
    label, data, cut_pts, cut_u = _cuts(strand_angle, spacing, rng, periodic)
    n_cuts = len(cut_pts)
    fibre_of = rng.uniform(0, table.n_fibres, n_cuts)[:, None] + cut_u
    s0 = rng.integers(0, 1 << 16, n_cuts).astype(np.float64)
    flip = np.ones(n_cuts)
    if linked:
        fibre_of, s0, flip = _link_cuts(
            strand_angle, label, data, cut_pts, cut_u, spacing, fibre_of, s0, periodic
        )
    c2, s2 = doubled_angle(strand_angle)
    steps, hit, end, first = first_hits(c2, s2, label, 2 * spacing, 1.0, periodic)
    found = steps >= 0
    hr = np.floor(hit[..., 0] + 0.5).astype(np.int64)
    hc = np.floor(hit[..., 1] + 0.5).astype(np.int64)
    hr, hc = (hr % h, hc % w) if periodic else (np.clip(hr, 0, h - 1), np.clip(hc, 0, w - 1))
    lab = np.where(found, label[hr, hc], 0)
    d = data[hr, hc]
    n_q = d[..., 3:5]
    u = d[..., 0] + ((hit - d[..., 1:3]) * n_q).sum(axis=-1)  # along the cut as traced
    n_q = n_q * flip[lab][..., None]  # the side the cut's fibre index grows to
    t_q = np.stack([n_q[..., 1], -n_q[..., 0]], axis=-1)  # a quarter clockwise: the strand's direction
    behind = (end * t_q).sum(axis=-1) > 0
    s = np.where(behind, -steps, steps)
    t_p = np.where(behind[..., None], first, -first)
    grid = cut_u[0]
    at = np.clip((u - grid[0]) / (grid[1] - grid[0]), 0, len(grid) - 1)
    i0 = np.minimum(np.floor(at).astype(np.int64), len(grid) - 2)
    frac = at - i0
    a_val = fibre_of[lab, i0] * (1 - frac) + fibre_of[lab, i0 + 1] * frac
    a = np.mod(np.rint(a_val).astype(np.int64), table.n_fibres)
    a = np.where(found, a, rng.integers(0, table.n_fibres, (h, w)))
    lo, hi = table.lo[a], table.hi[a]
    span = hi - lo + 1
    along = np.where(found, np.rint(s0[lab]).astype(np.int64) + s, rng.integers(0, 1 << 16, (h, w)))
    idx = lo + np.mod(along, span)
    pos = table.positions[a, idx]
    nxt = table.positions[a, np.minimum(idx + 1, hi)]
    prv = table.positions[a, np.maximum(idx - 1, lo)]
    f = nxt - prv
    # direction angles (y up): the turn carrying the fibre's direction f onto the strand's t_p
    turn = np.arctan2(-t_p[..., 0], t_p[..., 1]) - np.arctan2(-f[..., 0], f[..., 1])
    return StrandHints(
        source=np.rint(pos).astype(np.int64),
        copy_angle=np.mod(turn, 2 * np.pi),
        missed=float(1.0 - found.mean()),
    )
