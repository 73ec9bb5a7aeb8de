"""Per-pixel neighbourhood search and copy: the hot loop of every pixel-based method.

For each position in a chunk of a scan order, compare the output's neighbourhood with exemplar
neighbourhoods and copy the best match's features (and remember its source position). A distance is
the weighted sum of up to three blocks: ``cur`` (the image being synthesized, same level), ``par``
(the parent level at ``(y // 2, x // 2)``, full square) and ``gui`` (a fixed guidance field: the
tensor field of Akl 2014, eq 13), each with its metric: ``SSD`` (also ED on tensors stored as
``(S_xx, sqrt(2) S_xy, S_yy)``), ``NORM`` (its square root: FN, and LE on log-tensors) or ``SO``
(channels ``(sin O, cos O, C, 1 / C)``, eqs 7-9). Output positions wrap; candidates lie in the
rectangle ``valid`` (every neighbourhood inside the exemplar) and where ``mask`` is non-zero (one
canvas may hold several images, e.g. rotated copies of the exemplar).

Search: ``exact`` visits every valid position (partial distances stop once above the best, which
keeps the argmin); otherwise candidates are k-coherent (Tong et al. 2002): each neighbour ``q``'s
source and its ``k`` most similar exemplar positions shifted by ``p - q``, the same from an optional
``hint`` map, and ``n_random`` seeded random positions. In the first pass unsynthesized pixels
(``done == 0``) are left out of ``cur``. Options: histogram matching (a candidate's distance times
``1 + weight * max(0, count / target - 1)`` for its label, Kopf et al. 2007 eq 4); a class window (a
candidate counts only when its class, e.g. its rotated copy, is within ``span`` of the wanted one,
cyclically; with a *transfer* a proposal of another class moves to the same point of the wanted class).

Parallel, same bytes on any thread count: a pass is units (positions run in order by one thread) in levels
whose units never read what another of the level writes (Lefebvre & Hoppe 2005's sub-passes):
:func:`tile_schedule` for a raster pass (parallelogram tiles), :func:`schedule_levels` for any other order
(a position a unit); :func:`synthesize_levels` runs each level's units on numba's threads, the histogram
counts changing between levels. The inputs come in named groups (:class:`SearchState`), numba
named tuples built once per level; :func:`synthesize_levels_reference` and
:func:`synthesize_chunk_reference` are the plain NumPy versions the tests compare the kernel with. The
speed-ups that keep every bit (no array-taking helper in the candidate loop) are in docs/pixel.md.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numba import prange

from texsynth.synth.kernels.common import histogram_factor, splitmix
from texsynth.synth.kernels.options import kernel

__all__ = [
    "METRIC_NORM",
    "METRIC_SO",
    "METRIC_SSD",
    "Candidates",
    "ClassWindow",
    "Histogram",
    "Part",
    "Pass",
    "Schedule",
    "SearchState",
    "candidate_capacity",
    "conflict_offsets",
    "position_distance",
    "schedule_levels",
    "schedule_levels_reference",
    "synthesize_chunk",
    "synthesize_chunk_reference",
    "synthesize_levels",
    "synthesize_levels_reference",
    "tile_schedule",
    "tile_shape",
    "tile_units",
]

METRIC_SSD = 0
METRIC_NORM = 1
METRIC_SO = 2


class Part(NamedTuple):
    """One part of a neighbourhood distance: the output's features against the exemplar's.

    Three parts make a distance (Akl 2014, eq 13): the level's own pixels (``cur``), the parent
    level's square neighbourhood at half the position (``par``, Wei & Levoy 2000), and the guidance
    field (``gui``: tensors). A part with ``weight == 0`` is skipped.
    """

    out: np.ndarray  # (H, W, C) float32: the output's features (NaN where not yet synthesized)
    ex: np.ndarray  # (h, w, C) float32: the exemplar's features
    offsets: np.ndarray  # (K, 2) int32: (dy, dx) of the neighbourhood's entries
    metric: int  # METRIC_SSD | METRIC_NORM | METRIC_SO
    weight: float  # the part's weight, already divided by its typical distance and size
    #: (K,) float64 weights of the ``offsets`` entries (a Gaussian falloff, Efros & Leung 1999); empty: all 1
    entry_weights: np.ndarray = np.ones(0, dtype=np.float64)


class Candidates(NamedTuple):
    """Where the search looks: exhaustive, or k-coherent candidates (Tong et al. 2002)."""

    src: np.ndarray  # (H, W, 2) int64: the exemplar position each output pixel copies (updated)
    hint: np.ndarray  # (H, W, 2) int64: a second source map proposing candidates (used if use_hint)
    use_hint: bool
    valid: np.ndarray  # (4,) y0, y1, x0, x1: exemplar positions whose neighbourhoods fit
    mask: np.ndarray  # (h, w) uint8: exemplar positions that may be copied
    kset: np.ndarray  # (h, w, k, 2) int64: each exemplar position's k most similar positions (-1: none)
    cand_offs: np.ndarray  # (M, 2) int32: neighbours whose sources propose candidates
    exact: bool  # compare every valid position (the definition) instead
    n_random: int  # random positions added per pixel
    capacity: int  # size of the candidate buffer (candidate_capacity)


class Histogram(NamedTuple):
    """Histogram matching in the search: a label per exemplar position and the output's count per
    label; a candidate whose label is over-represented has its distance multiplied by
    ``1 + weight * excess`` (Chen & Wang 2010's position histogram when the labels are positions)."""

    labels: np.ndarray  # (h * w,) int64
    count: np.ndarray  # (n_labels,) int64: the output's use of each label (updated)
    target: np.ndarray  # (n_labels,) float64: the wanted count
    weight: float  # 0 switches it off


class ClassWindow(NamedTuple):
    """Per-position candidate window: exemplar positions carry a class (e.g. the rotation of their
    copy), output positions a wanted class; only classes within ``span`` (cyclic, ``period``) count."""

    cls: np.ndarray  # (h * w,) int64: class of each exemplar position (-1: none)
    want: np.ndarray  # (H, W) int64: wanted class per output position
    period: int
    span: int  # -1 switches the window off
    #: (n_classes, 2, 3) float64 affine maps, class positions (row, col, 1) -> shared frame, and back;
    #: (0, 2, 3): no transfer (out-of-window proposals are dropped).
    to_common: np.ndarray = np.zeros((0, 2, 3))
    from_common: np.ndarray = np.zeros((0, 2, 3))


class Pass(NamedTuple):
    """One pass over the output: its scan order and the state it updates."""

    order: np.ndarray  # (H * W,) int64: flat output positions in scan order
    first_pass: bool  # unsynthesized pixels (done == 0) are left out of the neighbourhoods
    done: np.ndarray  # (H, W) uint8: synthesized in this level (updated)
    seed_key: np.uint64  # the pass's random key (candidates' random positions)
    stamp: np.ndarray  # (h * w,) int64: scratch, de-duplicates candidates
    counter: np.ndarray  # (1,) int64: scratch, the stamp's current value
    best_out: np.ndarray  # (H, W) float32: each pixel's best distance (updated)


@dataclass
class SearchState:
    """Everything the search kernel reads and updates for one pyramid level, in named groups.

    The driver (:func:`texsynth.synth.pixel.synthesis.synthesize_source_map`) builds one per level and a new
    :class:`Pass` per pass; :func:`synthesize_chunk` and :func:`synthesize_chunk_reference` take it.
    """

    cur: Part
    par: Part
    gui: Part
    alpha: float  # SO metric exponent (Akl 2014, eq 8)
    cands: Candidates
    hist: Histogram
    win: ClassWindow
    run: Pass
    #: The parts' exemplar features in one flat buffer (:func:`_concat_features`), built by the first
    #: :func:`synthesize_chunk` of the level and kept with the exemplar arrays it was built from: a
    #: level's exemplar features do not change between chunks and passes, and rebuilding the buffer at
    #: every chunk copied the whole exemplar 64 times a pass (arbitrary-shape's rotated dictionary, about
    #: 40 MB: its texture stage 1.4 -> 4.0 s).
    flat: tuple | None = None


@kernel(inline="always")
def _so_half(s1, c1, k1, s2, c2, k2):
    """Akl 2014's SO dissimilarity (eq 8) at ``alpha = 0.5`` of features ``(sin O, cos O, C, ...)``:
    ``M_or M_coh = |sin| min(C1, C2) max(C1, C2) / min(C1, C2) = |sin| max(C1, C2)``, square-rooted."""
    return math.sqrt(abs(s1 * c2 - c1 * s2) * max(k1, k2))


@kernel(inline="always")
def _so_term(s1, c1, k1, r1, s2, c2, k2, r2, alpha):
    """Akl 2014's SO dissimilarity (eq 8) of features ``(sin O, cos O, C, 1 / C)``, any ``alpha``."""
    sin_d = abs(s1 * c2 - c1 * s2)
    m_or = sin_d * min(k1, k2)
    m_coh = max(k1 * r2, k2 * r1)  # channel 3 holds 1 / C: no division here
    return m_or**alpha * m_coh ** (1.0 - alpha)


@kernel
def _gather_query(img, oy, ox, offs, ex_width, channels, part_start, done, use_mask, q, lin, first, ew, wq):
    """Copy the (wrapped) output neighbourhood of ``(oy, ox)`` into ``q[first:]``; return its length.

    With ``use_mask`` the unsynthesized positions are skipped. ``lin`` receives, for every kept
    entry, its element offset in the flat feature buffer (see :func:`_concat_features`): the part's
    start plus the entry's linear offset in the exemplar times its channels; ``wq`` its weight
    (``ew[i]``, or 1 when ``ew`` is empty: the same bytes as no weight).
    """
    H = img.shape[0]
    W = img.shape[1]
    n = first
    for i in range(offs.shape[0]):
        qy = (oy + offs[i, 0]) % H
        qx = (ox + offs[i, 1]) % W
        if use_mask and done[qy, qx] == 0:
            continue
        for c in range(channels):
            q[n, c] = img[qy, qx, c]
        lin[n] = part_start + (offs[i, 0] * ex_width + offs[i, 1]) * channels
        wq[n] = ew[i] if ew.shape[0] > 0 else 1.0
        n += 1
    return n - first


@kernel
def _concat_features(ex, par_ex, gui_ex):
    """The three parts' exemplar features in one flat buffer, and where each part starts in it.

    The candidate loop then reads every part from one array with scalar offsets: passing arrays to
    a helper per candidate costs numba two atomic reference-count updates per array and call, which
    took half of the search's time.
    """
    starts = np.zeros(3, dtype=np.int64)
    starts[1] = ex.size
    starts[2] = ex.size + par_ex.size
    feats = np.empty(ex.size + par_ex.size + gui_ex.size, dtype=np.float32)
    feats[: starts[1]] = ex.ravel()
    feats[starts[1] : starts[2]] = par_ex.ravel()
    feats[starts[2] :] = gui_ex.ravel()
    return feats, starts


def candidate_capacity(n_cand_offsets: int, k: int, has_hint: bool, n_random: int) -> int:
    """Largest number of candidates one position can have (the kernel's scratch size)."""
    return n_cand_offsets * (k + 1) * (2 if has_hint else 1) + n_random + 1


@kernel(inline="always")
def _class_allowed(cls, key, want, period, span):
    """Whether exemplar position ``key``'s class lies within ``span`` of ``want`` (cyclic, ``period``);
    always true when ``span < 0`` (no window)."""
    if span < 0:
        return True
    k = cls[key]
    if k < 0:
        return False
    d = (k - want) % period
    return min(d, period - d) <= span


@kernel(inline="always")
def _transfer_class(c, want, period, n_classes):
    """The class a proposal of class ``c`` moves to: among ``want + j period`` (cyclic, ``n_classes``),
    the one nearest ``c`` (a rotated copy's half-turn twin is nearer when ``c`` is)."""
    d = (c - want) % n_classes
    j = (2 * d + period) // (2 * period)
    return (want + j * period) % n_classes


@kernel
def _gather_candidates(cand, oy, ox, cands, win, want, key, stamp, tag, w):
    """The position's candidates into ``cand``, in proposal order, each once; return their number.

    ``cands`` (:class:`Candidates`) and ``win`` (:class:`ClassWindow`) as in :class:`SearchState`;
    ``want`` the position's wanted class, ``key`` its random key, ``w`` the exemplar's width.
    Proposals first (the sources of the neighbours in ``cand_offs`` shifted by ``p - q``, each with
    its ``k`` similar positions (Tong et al.), from ``src`` and then ``hint``; then ``n_random``
    seeded random positions), then one pass keeps those inside ``valid`` and ``mask``, not seen yet
    at this position (``stamp == tag``) and inside the class window, in place and in order; with a
    transfer (``to_c``, ``from_c`` not empty) a proposal of another class is first moved to the same
    point of the wanted class and then checked the same way.
    """
    src, hint, use_hint, valid, mask, kset, cand_offs, _, n_random, _ = cands
    cls, _, period, span, to_c, from_c = win
    H = src.shape[0]
    W = src.shape[1]
    k = kset.shape[2]
    m = 0
    for sel in range(2 if use_hint else 1):
        for i in range(cand_offs.shape[0]):
            dy = cand_offs[i, 0]
            dx = cand_offs[i, 1]
            qy = (oy + dy) % H
            qx = (ox + dx) % W
            if sel == 0:
                ay = src[qy, qx, 0]
                ax = src[qy, qx, 1]
            else:
                ay = hint[qy, qx, 0]
                ax = hint[qy, qx, 1]
            cand[m, 0] = ay - dy
            cand[m, 1] = ax - dx
            m += 1
            for j in range(k):  # Tong et al.: the k positions similar to q's source, shifted by p - q
                ky = kset[ay, ax, j, 0]
                if ky >= 0:
                    cand[m, 0] = ky - dy
                    cand[m, 1] = kset[ay, ax, j, 1] - dx
                    m += 1
    span_y = np.uint64(valid[1] - valid[0])
    span_x = np.uint64(valid[3] - valid[2])
    for j in range(n_random):
        r = splitmix(key + np.uint64(j))
        cand[m, 0] = valid[0] + np.int64(r % span_y)
        cand[m, 1] = valid[2] + np.int64((r >> np.uint64(32)) % span_x)
        m += 1
    n = 0
    for j in range(m):
        cy = cand[j, 0]
        cx = cand[j, 1]
        if cy < valid[0] or cy >= valid[1] or cx < valid[2] or cx >= valid[3]:
            continue
        if mask[cy, cx] == 0:
            continue
        key_j = cy * w + cx
        if stamp[key_j] == tag:
            continue
        if span >= 0 and not _class_allowed(cls, key_j, want, period, span):
            c = cls[key_j]
            if to_c.shape[0] == 0 or c < 0:
                continue
            t = _transfer_class(c, want, period, to_c.shape[0])
            ey = to_c[c, 0, 0] * cy + to_c[c, 0, 1] * cx + to_c[c, 0, 2]
            ex = to_c[c, 1, 0] * cy + to_c[c, 1, 1] * cx + to_c[c, 1, 2]
            cy = np.int64(math.floor(from_c[t, 0, 0] * ey + from_c[t, 0, 1] * ex + from_c[t, 0, 2] + 0.5))
            cx = np.int64(math.floor(from_c[t, 1, 0] * ey + from_c[t, 1, 1] * ex + from_c[t, 1, 2] + 0.5))
            if cy < valid[0] or cy >= valid[1] or cx < valid[2] or cx >= valid[3]:
                continue
            if mask[cy, cx] == 0:
                continue
            key_j = cy * w + cx
            if stamp[key_j] == tag or not _class_allowed(cls, key_j, want, period, span):
                continue
        stamp[key_j] = tag
        cand[n, 0] = cy
        cand[n, 1] = cx
        n += 1
    return n


@kernel
def _valid_positions(valid, mask):
    """Every exemplar position of the ``valid`` rectangle that ``mask`` allows, in raster order."""
    n = 0
    for cy in range(valid[0], valid[1]):
        for cx in range(valid[2], valid[3]):
            if mask[cy, cx] != 0:
                n += 1
    out = np.empty((n, 2), dtype=np.int64)
    n = 0
    for cy in range(valid[0], valid[1]):
        for cx in range(valid[2], valid[3]):
            if mask[cy, cx] != 0:
                out[n, 0] = cy
                out[n, 1] = cx
                n += 1
    return out


@kernel
def _search_block(
    sched,
    units,
    u_lo,
    u_hi,
    cur,
    par,
    gui,
    alpha,
    cands,
    hist,
    win,
    run,
    feats,
    part_start,
    all_cand,
    stamp,
    tag0,
    labs,
    delta,
):
    """Search and copy the units ``u_lo:u_hi`` (unit ``u``: the positions ``sched[units[u]:units[u + 1]]``),
    one position after the other, in place.

    A position reads the histogram counts as they were when its level began plus its own unit's changes
    so far (``delta``, this block's scratch, zero between units), its own current label less one;
    ``labs[0, i]`` and ``labs[1, i]`` receive the old and the new label of ``sched[i]`` (-1: unchanged),
    which :func:`_levels_body` adds to the counts after the level. ``stamp`` is this block's
    de-duplication scratch; ``tag0 + i + 1`` the tag of ``sched[i]``.
    """
    # Unpacked once, so the loop below reads as the algorithm (see SearchState for each name).
    out, ex, offs, metric, w_cur, ew_cur = cur
    par_out, par_ex, par_offs, par_metric, w_par, ew_par = par
    gui_out, gui_ex, gui_offs, gui_metric, w_gui, ew_gui = gui
    src, _, _, _, _, _, _, exact, _, capacity = cands  # the rest: _gather_candidates
    labels, label_count, label_target, hist_weight = hist
    cls, want_cls, cls_period, cls_span, _, _ = win
    _, first_pass, done, seed_key, _, _, best_out = run
    W = out.shape[1]
    w = ex.shape[1]
    C = out.shape[2]
    par_width = par_ex.shape[1]
    # The parts of a distance (0 = cur, 1 = par, 2 = gui), read in this order by one loop: their
    # weights, metrics and channels, the exemplar features in one flat buffer, and the gathered
    # query entries of the current position (part b holds entries bounds[b]:bounds[b + 1]).
    part_w = np.array([w_cur, w_par, w_gui], dtype=np.float64)
    part_metric = np.array([metric, par_metric, gui_metric], dtype=np.int64)
    part_c = np.array([C, par_ex.shape[2], gui_ex.shape[2]], dtype=np.int64)
    n_entries = offs.shape[0] + par_offs.shape[0] + gui_offs.shape[0]
    q = np.empty((n_entries, max(C, par_out.shape[2], gui_out.shape[2])), dtype=np.float32)
    lin = np.empty(n_entries, dtype=np.int64)
    wq = np.empty(n_entries, dtype=np.float64)  # each gathered entry's weight (1 without a falloff)
    qf = q.reshape(q.size)  # the same entries, read with unsigned flat indices below
    cq = np.uint64(q.shape[1])
    one, two, three = np.uint64(1), np.uint64(2), np.uint64(3)
    bounds = np.zeros(4, dtype=np.int64)
    cand = np.empty((capacity, 2), dtype=np.int64)
    for u in range(u_lo, u_hi):
        for idx in range(units[u], units[u + 1]):
            p = sched[idx]
            labs[0, idx] = -1
            oy = p // W
            ox = p % W
            n_cur = _gather_query(
                out, oy, ox, offs, w, C, part_start[0], done, first_pass, q, lin, 0, ew_cur, wq
            )
            n_par = 0
            if w_par > 0.0:
                c_par, s_par = part_c[1], part_start[1]
                n_par = _gather_query(
                    par_out,
                    oy // 2,
                    ox // 2,
                    par_offs,
                    par_width,
                    c_par,
                    s_par,
                    done,
                    False,
                    q,
                    lin,
                    n_cur,
                    ew_par,
                    wq,
                )
            n_gui = 0
            if w_gui > 0.0:
                n_gui = _gather_query(
                    gui_out,
                    oy,
                    ox,
                    gui_offs,
                    w,
                    part_c[2],
                    part_start[2],
                    done,
                    False,
                    q,
                    lin,
                    n_cur + n_par,
                    ew_gui,
                    wq,
                )
            bounds[1] = n_cur
            bounds[2] = n_cur + n_par
            bounds[3] = n_cur + n_par + n_gui
            if n_cur == 0 and n_par == 0 and n_gui == 0:  # nothing to compare yet: keep the initial source
                sy = src[oy, ox, 0]
                sx = src[oy, ox, 1]
                for c in range(C):
                    out[oy, ox, c] = ex[sy, sx, c]
                done[oy, ox] = 1
                best_out[oy, ox] = 0.0
                continue
            # This pixel's current source leaves the histogram while it looks for a new one.
            old_lab = labels[src[oy, ox, 0] * w + src[oy, ox, 1]] if hist_weight > 0.0 else -1
            best = np.inf
            best_raw = np.inf
            by = -1
            bx = -1
            want = want_cls[oy, ox] if cls_span >= 0 else 0
            if exact:  # the definition: every valid exemplar position
                n = all_cand.shape[0]
            else:
                key = splitmix(seed_key ^ np.uint64(p))
                n = _gather_candidates(cand, oy, ox, cands, win, want, key, stamp, tag0 + idx + 1, w)
                if n == 0:  # every proposal fell outside the class window: keep the current source
                    cand[0, 0] = src[oy, ox, 0]
                    cand[0, 1] = src[oy, ox, 1]
                    n = 1
            for j in range(n):
                if exact:
                    cy = all_cand[j, 0]
                    cx = all_cand[j, 1]
                    if cls_span >= 0 and not _class_allowed(cls, cy * w + cx, want, cls_period, cls_span):
                        continue
                else:
                    cy = cand[j, 0]
                    cx = cand[j, 1]
                f = 1.0
                if hist_weight > 0.0:
                    lab = labels[cy * w + cx]
                    count = label_count[lab] + delta[lab] - (1 if lab == old_lab else 0)
                    f = histogram_factor(count, label_target[lab], hist_weight)
                # The distance, part by part, cheapest first (plain SSD over pixels), each part's sum
                # stopping once it exceeds what is left below the best so far (the argmin is unchanged).
                bound = best / f
                d = 0.0
                for b in range(3):
                    wb = part_w[b]
                    if not wb > 0.0:
                        continue
                    mb = part_metric[b]
                    cb = part_c[b]
                    # The candidate's element offset (each entry's ``lin`` holds its part's start); the
                    # parent part is read at half the position.
                    e_base = ((cy // 2) * par_width + cx // 2) * cb if b == 1 else (cy * w + cx) * cb
                    limit = (bound - d) / wb
                    s = 0.0
                    # Unsigned indices (all are >= 0 here): numba then emits no negative-index
                    # wrap-around per load, a quarter of the loop's time.
                    lo = np.uint64(bounds[b])
                    hi = np.uint64(bounds[b + 1])
                    if mb == METRIC_SO and alpha == 0.5:  # channel 3 (1 / C) is not read
                        for i in range(lo, hi):
                            e = np.uint64(lin[i] + e_base)
                            r = i * cq
                            qs, qc, qk = qf[r], qf[r + one], qf[r + two]
                            s += wq[i] * _so_half(qs, qc, qk, feats[e], feats[e + one], feats[e + two])
                            if s > limit:
                                break
                    elif mb == METRIC_SO:
                        for i in range(lo, hi):
                            e = np.uint64(lin[i] + e_base)
                            r = i * cq
                            qs, qc, qk, qr = qf[r], qf[r + one], qf[r + two], qf[r + three]
                            es, ec, ek, er = feats[e], feats[e + one], feats[e + two], feats[e + three]
                            s += wq[i] * _so_term(qs, qc, qk, qr, es, ec, ek, er, alpha)
                            if s > limit:
                                break
                    elif mb == METRIC_SSD and cb == 1:  # one channel: the channel loop's sum is its one term
                        for i in range(lo, hi):
                            t = qf[i * cq] - feats[np.uint64(lin[i] + e_base)]
                            s += wq[i] * (t * t)
                            if s > limit:
                                break
                    else:
                        for i in range(lo, hi):
                            e = np.uint64(lin[i] + e_base)
                            r = i * cq
                            t = 0.0
                            for c in range(np.uint64(cb)):
                                dc = qf[r + c] - feats[e + c]
                                t += dc * dc
                            s += wq[i] * (math.sqrt(t) if mb == METRIC_NORM else t)
                            if s > limit:
                                break
                    d += wb * s
                    if d >= bound:
                        break
                d = f * d
                if d < best:
                    best = d
                    best_raw = d / f
                    by = cy
                    bx = cx
            if by < 0:  # an exact search with an empty class window: keep the source and its distance
                by = src[oy, ox, 0]
                bx = src[oy, ox, 1]
                best_raw = best_out[oy, ox]
            src[oy, ox, 0] = by
            src[oy, ox, 1] = bx
            if hist_weight > 0.0:
                new_lab = labels[by * w + bx]
                labs[0, idx] = old_lab
                labs[1, idx] = new_lab
                delta[old_lab] -= 1
                delta[new_lab] += 1
            for c in range(C):
                out[oy, ox, c] = ex[by, bx, c]
            done[oy, ox] = 1
            best_out[oy, ox] = best_raw
        if hist_weight > 0.0:  # the unit's changes leave the scratch: the next unit starts from the level's
            for idx in range(units[u], units[u + 1]):
                if labs[0, idx] >= 0:
                    delta[labs[0, idx]] = 0
                    delta[labs[1, idx]] = 0


@kernel(inline="always")
def _block_edge(units, a, z, target):
    """The unit boundary of ``a:z`` (an index ``i`` of ``units``) whose position count is nearest to
    ``target``, the later one on a tie: blocks split there hold as nearly equal shares of a level's
    positions as whole units allow (with 2 blocks, the best split). Non-decreasing in ``target``, so
    consecutive edges never cross; which block runs a unit does not change the bytes."""
    i = a + np.searchsorted(units[a : z + 1], target)
    if i > a and target - units[i - 1] < units[i] - target:
        i -= 1
    return i


def _levels_body(
    level_lo,
    level_hi,
    schedule,
    blocks,
    cur,
    par,
    gui,
    alpha,
    cands,
    hist,
    win,
    run,
    feats,
    part_start,
    all_cand,
    stamps,
    labs,
    deltas,
):
    """Levels ``level_lo:level_hi`` of ``schedule``: each level's units in ``blocks`` blocks of whole units,
    of about as many positions each (on the thread pool when compiled parallel), then the level's
    histogram changes, in schedule order."""
    sched, units, starts, tag0 = schedule
    _, label_count, _, hist_weight = hist
    for level in range(level_lo, level_hi):
        a = starts[level]
        z = starts[level + 1]
        nb = max(1, min(blocks, z - a))
        first = units[a]
        total = units[z] - first
        for b in prange(nb):  # blocks of whole units holding about as many positions each
            lo = _block_edge(units, a, z, first + (b * total) // nb)
            hi = _block_edge(units, a, z, first + ((b + 1) * total) // nb)
            if lo < hi:
                _search_block(
                    sched,
                    units,
                    lo,
                    hi,
                    cur,
                    par,
                    gui,
                    alpha,
                    cands,
                    hist,
                    win,
                    run,
                    feats,
                    part_start,
                    all_cand,
                    stamps[b],
                    tag0,
                    labs,
                    deltas[b],
                )
        if hist_weight > 0.0:
            for idx in range(units[a], units[z]):
                if labs[0, idx] >= 0:
                    label_count[labs[0, idx]] -= 1
                    label_count[labs[1, idx]] += 1


# One body, compiled twice: on the calling thread, and with the levels' blocks on numba's pool.
# Units of one level never read what another writes, so both give the same bytes. The serial one lets
# Python's lock go: the seam pass runs it while another thread makes the next pass's schedule.
_levels_serial = kernel(nogil=True)(_levels_body)
_levels_parallel = kernel(parallel=True)(_levels_body)

#: Below this many positions per level on average, a pass runs on the calling thread: waking the pool
#: for every level costs more than it saves (about 20 us a level, a position 2-10 us).
PARALLEL_MIN_LEVEL = 16

#: Rows and width of the tiles of a raster pass (:func:`tile_schedule`; docs/pixel.md, "Parallel passes"),
#: smaller on small outputs (:func:`tile_shape`).
TILE = (4, 24)


def tile_shape(shape: tuple[int, int]) -> tuple[int, int]:
    """The tiles of a raster pass over ``shape``: :data:`TILE`, down to one row by 8 on small outputs, so
    that a pass has dozens of levels (a progress report comes between levels)."""
    return max(1, min(TILE[0], int(shape[0]) // 32)), max(8, min(TILE[1], int(shape[1]) // 8))


class Schedule(NamedTuple):
    """A pass's positions in units run one after the other by one thread, the units grouped in levels
    (:func:`schedule_levels`, :func:`tile_schedule`): no position of a unit reads or writes what a
    position of another unit of the same level writes."""

    sched: np.ndarray  # (n,) int64: flat output positions, unit by unit, each unit in pass order
    units: np.ndarray  # (units + 1,) int64: unit u is sched[units[u]:units[u + 1]]
    starts: np.ndarray  # (levels + 1,) int64: level l is the units starts[l]:starts[l + 1]
    tag0: int  # the de-duplication tags of this pass are tag0 + 1 ... tag0 + n

    def positions(self, level: int) -> np.ndarray:
        """The positions of level ``level``, unit by unit."""
        return self.sched[self.units[self.starts[level]] : self.units[self.starts[level + 1]]]


@kernel(nogil=True)
def _schedule_kernel(order, H, W, offs):
    n = order.shape[0]
    # A position's level once placed; -1 before (and for positions the order leaves out), so that the
    # positions after it in the order count as level -1 + 1 = 0: no rank to look up.
    placed = np.full(H * W, -1, dtype=np.int64)
    level = np.zeros(n, dtype=np.int64)  # by rank
    top = 0
    for i in range(n):
        p = order[i]
        y = p // W
        x = p % W
        lv = 0
        for j in range(offs.shape[0]):
            qy = y + offs[j, 0]
            qx = x + offs[j, 1]
            while qy < 0:
                qy += H
            while qy >= H:
                qy -= H
            while qx < 0:
                qx += W
            while qx >= W:
                qx -= W
            lq = placed[qy * W + qx] + 1
            if lq > lv:
                lv = lq
        placed[p] = lv
        level[i] = lv
        top = max(top, lv)
    starts = np.zeros(top + 2, dtype=np.int64)
    for i in range(n):
        starts[level[i] + 1] += 1
    for lv in range(top + 1):
        starts[lv + 1] += starts[lv]
    fill = starts[:-1].copy()
    sched = np.empty(n, dtype=np.int64)
    for i in range(n):
        sched[fill[level[i]]] = order[i]
        fill[level[i]] += 1
    return sched, starts


def conflict_offsets(*offsets: np.ndarray) -> np.ndarray:
    """The offsets ``o`` such that positions ``p`` and ``p + o`` may touch the same data in a pass whose
    positions read at ``p + offsets`` (each ``(K, 2)``): their union and its mirror, ``(0, 0)`` left out."""
    both = np.vstack([np.asarray(o, dtype=np.int64).reshape(-1, 2) for o in offsets])
    both = np.unique(np.vstack([both, -both]), axis=0)
    return np.ascontiguousarray(both[np.any(both != 0, axis=1)], dtype=np.int64)


def schedule_levels(
    order: np.ndarray, shape: tuple[int, int], offsets: np.ndarray, tag0: int = 0
) -> Schedule:
    """Group a pass's ``order`` in levels that can run in parallel and give the sequential pass's result.

    A position's level is one more than the highest level among the positions before it in ``order``
    within ``offsets`` (:func:`conflict_offsets`, wrapped on ``shape``) of it, so any two positions that
    read or write each other's data keep their order, and the positions of one level are independent
    (Lefebvre & Hoppe 2005 split a pass so; here the split follows the pass's own order). Every unit is
    one position. The levels depend only on the order and the neighbourhood, never on the thread count.
    """
    sched, starts = _schedule_kernel(
        np.ascontiguousarray(order, dtype=np.int64),
        int(shape[0]),
        int(shape[1]),
        np.ascontiguousarray(offsets, dtype=np.int64),
    )
    return Schedule(sched, np.arange(len(sched) + 1, dtype=np.int64), starts, int(tag0))


def schedule_levels_reference(
    order: np.ndarray, shape: tuple[int, int], offsets: np.ndarray, tag0: int = 0
) -> Schedule:
    """Plain Python version of :func:`schedule_levels`."""
    H, W = shape
    rank = {int(p): i for i, p in enumerate(order)}
    level: dict[int, int] = {}
    for i, p in enumerate(int(v) for v in order):
        y, x = divmod(p, W)
        near = {((y + dy) % H) * W + (x + dx) % W for dy, dx in offsets}
        level[p] = max([level[q] + 1 for q in near if q != p and rank.get(q, len(order)) < i] or [0])
    top = max(level.values(), default=-1)
    groups = [[p for p in (int(v) for v in order) if level[p] == lv] for lv in range(top + 1)]
    starts = np.cumsum([0] + [len(g) for g in groups]).astype(np.int64)
    sched = np.array([p for g in groups for p in g], dtype=np.int64)
    return Schedule(sched, np.arange(len(sched) + 1, dtype=np.int64), starts, int(tag0))


def _offset_runs(offsets: np.ndarray) -> np.ndarray:
    """``offsets`` as runs of consecutive columns per row: ``(n, 3)`` int64 ``(dy, dx_first, dx_last)``."""
    runs = []
    offs = np.asarray(offsets, dtype=np.int64).reshape(-1, 2)
    for dy in np.unique(offs[:, 0]):
        dx = np.unique(offs[offs[:, 0] == dy, 1])
        cut = np.flatnonzero(np.diff(dx) > 1) + 1
        runs += [(int(dy), int(r[0]), int(r[-1])) for r in np.split(dx, cut)]
    return np.array(runs, dtype=np.int64).reshape(-1, 3)


@kernel
def _unit_levels_kernel(unit_of, H, W, runs, n_units):
    """Each unit's level: one more than the highest among the earlier units (lower ids) it touches.

    A unit touches the units of its positions shifted by the offsets; here by rows, without visiting
    every position and offset: each row's positions fall in segments of one unit (at most a few per
    tile), and a segment ``[x0, x1)`` of row ``y`` shifted by the offsets' run ``(dy, a, b)`` (consecutive
    columns, :func:`_offset_runs`) covers the columns ``[x0 + a, x1 - 1 + b]`` of row ``y + dy`` (wrapped),
    whose segments it touches. Units in increasing order, so an earlier unit's level is final when read.
    """
    # Segments of equal unit along each row: row y holds the segments row_seg[y]:row_seg[y + 1].
    n_seg = 0
    for y in range(H):
        for x in range(W):
            if x == 0 or unit_of[y * W + x] != unit_of[y * W + x - 1]:
                n_seg += 1
    seg_y = np.empty(n_seg, dtype=np.int64)
    seg_x0 = np.empty(n_seg, dtype=np.int64)
    seg_x1 = np.empty(n_seg, dtype=np.int64)
    seg_u = np.empty(n_seg, dtype=np.int64)
    row_seg = np.zeros(H + 1, dtype=np.int64)
    k = 0
    for y in range(H):
        row_seg[y] = k
        for x in range(W):
            u = unit_of[y * W + x]
            if x == 0 or u != unit_of[y * W + x - 1]:
                seg_y[k] = y
                seg_x0[k] = x
                seg_u[k] = u
                k += 1
            seg_x1[k - 1] = x + 1
    row_seg[H] = k
    level = np.zeros(n_units, dtype=np.int64)
    for i in np.argsort(seg_u, kind="mergesort"):
        u = seg_u[i]
        for r in range(runs.shape[0]):
            yy = (seg_y[i] + runs[r, 0]) % H
            lo = seg_x0[i] + runs[r, 1]
            hi = seg_x1[i] + runs[r, 2]  # exclusive
            if hi - lo >= W:
                lo = 0
                hi = W
            lo_w = lo % W
            hi_w = lo_w + (hi - lo)
            for piece in range(2):  # the covered columns, split where they cross the border
                a = lo_w if piece == 0 else 0
                z = min(hi_w, W) if piece == 0 else hi_w - W
                if z <= a:
                    continue
                j = row_seg[yy] + np.searchsorted(seg_x0[row_seg[yy] : row_seg[yy + 1]], a, side="right") - 1
                while j < row_seg[yy + 1] and seg_x0[j] < z:
                    v = seg_u[j]
                    if v < u and level[v] + 1 > level[u]:
                        level[u] = level[v] + 1
                    j += 1
    return level


def _unit_levels_reference(unit_of: np.ndarray, shape: tuple[int, int], offsets: np.ndarray) -> np.ndarray:
    """Plain Python version of :func:`_unit_levels_kernel` (positions ``unit_of``, flat)."""
    H, W = shape
    n_units = int(unit_of.max()) + 1
    touches: list[set[int]] = [set() for _ in range(n_units)]
    for p in range(H * W):
        y, x = divmod(p, W)
        for dy, dx in offsets:
            touches[int(unit_of[p])].add(int(unit_of[((y + dy) % H) * W + (x + dx) % W]))
    level = [0] * n_units
    for u in range(n_units):
        level[u] = max([level[v] + 1 for v in touches[u] if v < u] or [0])
    return np.array(level, dtype=np.int64)


def tile_units(shape: tuple[int, int], offsets: np.ndarray, tile: tuple[int, int] = TILE) -> np.ndarray:
    """Each position's tile (flat ``(H * W,)``), tiles numbered in the order a raster pass takes them.

    The tiles are parallelograms ``tile = (rows, width)``: row band ``i = y // rows`` and ``j = (x + s y) //
    width``, ``s`` the steepest column reach of an entry above the position among ``offsets``, so every
    such entry lies in the position's tile or an earlier one; numbered by wave ``i + j``, then ``i``.
    """
    H, W = (int(v) for v in shape)
    offs = np.asarray(offsets, dtype=np.int64).reshape(-1, 2)
    above = offs[offs[:, 0] < 0]
    skew = max(0, int(np.max(np.ceil(above[:, 1] / -above[:, 0])))) if len(above) else 0
    yy, xx = np.mgrid[0:H, 0:W]
    ti = yy // int(tile[0])
    tj = (xx + skew * yy) // int(tile[1])
    key = (ti + tj) * (int(ti.max()) + 1) + ti
    return np.unique(key.ravel(), return_inverse=True)[1].astype(np.int64)


def tile_schedule(
    shape: tuple[int, int], offsets: np.ndarray, tile: tuple[int, int] | None = None, tag0: int = 0
) -> Schedule:
    """A raster pass in parallel: parallelogram tiles (:func:`tile_units`; ``tile``: :func:`tile_shape`),
    each in raster order inside.

    Every tile is a unit; its level is one more than the highest among the earlier tiles it touches within
    the conflict ``offsets`` (:func:`conflict_offsets`, wrapped), so touching tiles keep their order and
    the tiles of a level are independent. Every entry above a position and to its left, short of the
    output's border, is synthesized before it, as in a raster scan; a position of the first columns no
    longer sees the end of the row above across the wrap (it comes later).
    """
    offs = np.ascontiguousarray(offsets, dtype=np.int64).reshape(-1, 2)
    tile = tile_shape(shape) if tile is None else tile
    key = (int(shape[0]), int(shape[1]), offs.tobytes(), int(tile[0]), int(tile[1]))
    return _tile_schedule(key)._replace(tag0=int(tag0))


@functools.lru_cache(maxsize=4)
def _tile_schedule(key: tuple[int, int, bytes, int, int]) -> Schedule:
    """:func:`tile_schedule`'s arrays, computed once per shape, offsets and tile (the passes of a level
    share them; nothing writes them)."""
    H, W, raw, rows, width = key
    offs = np.frombuffer(raw, dtype=np.int64).reshape(-1, 2)
    unit_of = tile_units((H, W), offs, (rows, width))
    n_units = int(unit_of.max()) + 1
    flat = np.arange(H * W, dtype=np.int64)
    level = _unit_levels_kernel(unit_of, H, W, _offset_runs(offs), n_units)
    by_level = np.lexsort((np.arange(n_units), level))
    rank = np.empty(n_units, dtype=np.int64)
    rank[by_level] = np.arange(n_units)
    sched = np.lexsort((flat, rank[unit_of])).astype(np.int64)
    units = np.concatenate([[0], np.cumsum(np.bincount(unit_of, minlength=n_units)[by_level])])
    starts = np.searchsorted(level[by_level], np.arange(int(level.max()) + 2), side="left")
    return Schedule(sched, units.astype(np.int64), starts.astype(np.int64), 0)


def _prepared(state: SearchState) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    s = state
    arrays = (s.cur.ex, s.par.ex, s.gui.ex)
    if s.flat is None or any(a is not b for a, b in zip(s.flat[0], arrays, strict=True)):
        s.flat = (arrays, *_concat_features(*arrays))
    _, feats, part_start = s.flat
    all_cand = (
        _valid_positions(s.cands.valid, s.cands.mask) if s.cands.exact else np.empty((0, 2), dtype=np.int64)
    )
    return feats, part_start, all_cand


def _run_levels(state: SearchState, schedule: Schedule, level_lo: int, level_hi: int, parallel: bool) -> None:
    import numba

    s = state
    feats, part_start, all_cand = _prepared(s)
    stamps = s.run.stamp.reshape(-1, s.run.stamp.shape[-1])
    blocks = max(1, min(numba.get_num_threads(), stamps.shape[0])) if parallel else 1
    levels = int(level_hi) - int(level_lo)
    units = schedule.units
    span = int(units[schedule.starts[level_hi]] - units[schedule.starts[level_lo]])
    run = _levels_serial if blocks == 1 or span < PARALLEL_MIN_LEVEL * max(1, levels) else _levels_parallel
    labs = np.empty((2, len(schedule.sched)), dtype=np.int64)
    deltas = np.zeros((blocks, len(s.hist.count) if s.hist.weight > 0.0 else 1), dtype=np.int64)
    run(
        int(level_lo),
        int(level_hi),
        schedule,
        blocks,
        s.cur,
        s.par,
        s.gui,
        float(s.alpha),
        s.cands,
        s.hist,
        s.win,
        s.run,
        feats,
        part_start,
        all_cand,
        stamps,
        labs,
        deltas,
    )


def synthesize_levels(state: SearchState, schedule: Schedule, level_lo: int, level_hi: int) -> None:
    """Run the kernel on the levels ``level_lo:level_hi`` of ``schedule``: search, copy, update, in place.

    Each level's units run on numba's threads (:func:`texsynth.synth.threads.use_threads`), split in as
    many blocks of whole units as threads; the histogram counts change between levels (and within a unit).
    Every array must be C-contiguous, features float32, maps int64 (the caller,
    :mod:`texsynth.synth.pixel.synthesis`, prepares them once per level and pass); ``state.run.stamp`` is
    ``(blocks, h * w)`` (or ``(h * w,)``: one block). The bytes do not depend on the thread count.
    """
    _run_levels(state, schedule, level_lo, level_hi, parallel=True)


def synthesize_chunk(state: SearchState, start: int, stop: int) -> None:
    """Run the kernel on ``state.run.order[start:stop]``, one position after the other, in place.

    Every array must be C-contiguous, features float32, maps int64 (see :func:`synthesize_levels`, the
    parallel form the driver uses).
    """
    order = np.ascontiguousarray(state.run.order[start:stop], dtype=np.int64)
    tag0 = int(state.run.counter[0])
    state.run.counter[0] += len(order) + 1
    steps = np.arange(len(order) + 1, dtype=np.int64)
    _run_levels(state, Schedule(order, steps, steps, tag0), 0, len(order), parallel=False)


def position_distance(a: np.ndarray, b: np.ndarray, metric: int, alpha: float) -> np.ndarray:
    """Position distances between feature vectors ``a`` and ``b`` of shape ``(..., C)`` (NumPy, float64).

    The metric the kernel sums over a neighbourhood, in the kernel's feature encoding: squared
    difference (``METRIC_SSD``), its root (``METRIC_NORM``) or Akl 2014's SO (eq 8) on
    ``(sin, cos, C, 1/C)`` features (``METRIC_SO``). The driver uses it to normalise distances; the
    plain reference below uses it for every block.
    """
    a64 = a.astype(np.float64)
    b64 = b.astype(np.float64)
    if metric == METRIC_SO:
        m_or = np.abs(a64[..., 0] * b64[..., 1] - a64[..., 1] * b64[..., 0]) * np.minimum(
            a64[..., 2], b64[..., 2]
        )
        m_coh = np.maximum(a64[..., 2] * b64[..., 3], b64[..., 2] * a64[..., 3])
        if alpha == 0.5:  # the kernel's exact identity M_or M_coh = |sin| max(C1, C2)
            sin_d = np.abs(a64[..., 0] * b64[..., 1] - a64[..., 1] * b64[..., 0])
            return np.sqrt(sin_d * np.maximum(a64[..., 2], b64[..., 2]))
        return m_or**alpha * m_coh ** (1.0 - alpha)
    ssd = ((a64 - b64) ** 2).sum(axis=-1)
    return np.sqrt(ssd) if metric == METRIC_NORM else ssd


# ----------------------------------------------------------------------------------------------
# Plain reference: the same algorithm, one position at a time, with NumPy and no early stopping.


def _block_reference(out, oy, ox, ex, cands, offs, metric, alpha, keep, entry_weights=None):
    H, W = out.shape[:2]
    wts = np.ones(len(offs)) if entry_weights is None or len(entry_weights) == 0 else entry_weights
    offs, wts = offs[keep], wts[keep]
    q = out[(oy + offs[:, 0]) % H, (ox + offs[:, 1]) % W]  # (K, C)
    e = ex[cands[:, None, 0] + offs[None, :, 0], cands[:, None, 1] + offs[None, :, 1]]  # (N, K, C)
    return (position_distance(q[None], e, metric, alpha) * wts).sum(axis=1)


def _in_class_window(state: SearchState, cands: np.ndarray, oy: int, ox: int) -> np.ndarray:
    """Which candidates ``(N, 2)`` the class window of output position ``(oy, ox)`` allows."""
    s = state
    if s.win.span < 0:
        return np.ones(len(cands), dtype=bool)
    k = s.win.cls[cands[:, 0] * s.cur.ex.shape[1] + cands[:, 1]]
    d = (k - s.win.want[oy, ox]) % s.win.period
    return (k >= 0) & (np.minimum(d, s.win.period - d) <= s.win.span)


def _candidates_reference(state: SearchState, oy: int, ox: int, key: int) -> np.ndarray:
    s = state
    y0, y1, x0, x1 = (int(v) for v in s.cands.valid)
    H, W = s.cands.src.shape[:2]
    seen: list[tuple[int, int]] = []

    def fits(cy: int, cx: int) -> bool:
        return y0 <= cy < y1 and x0 <= cx < x1 and bool(s.cands.mask[cy, cx]) and (cy, cx) not in seen

    def add(cy: int, cx: int) -> None:
        if not fits(cy, cx):
            return
        if not _in_class_window(s, np.array([[cy, cx]]), oy, ox)[0]:
            c = int(s.win.cls[cy * s.cur.ex.shape[1] + cx])
            if len(s.win.to_common) == 0 or c < 0:
                return
            # moved to the same point of the wanted class nearest its own (want + j period)
            n_cls, period, want = len(s.win.to_common), int(s.win.period), int(s.win.want[oy, ox])
            t = (want + int(np.floor(((c - want) % n_cls) / period + 0.5)) * period) % n_cls
            a, b = s.win.to_common[c], s.win.from_common[t]
            ey, ex = (a[i, 0] * cy + a[i, 1] * cx + a[i, 2] for i in (0, 1))
            cy, cx = (int(np.floor(b[i, 0] * ey + b[i, 1] * ex + b[i, 2] + 0.5)) for i in (0, 1))
            if not fits(cy, cx) or not _in_class_window(s, np.array([[cy, cx]]), oy, ox)[0]:
                return
        seen.append((cy, cx))

    maps = [s.cands.src, s.cands.hint] if s.cands.use_hint else [s.cands.src]
    for smap in maps:
        for dy, dx in s.cands.cand_offs:
            ay, ax = (int(v) for v in smap[(oy + dy) % H, (ox + dx) % W])
            add(ay - dy, ax - dx)
            for ky, kx in s.cands.kset[ay, ax]:
                if ky >= 0:
                    add(int(ky) - dy, int(kx) - dx)
    mask = (1 << 64) - 1
    for j in range(s.cands.n_random):
        r = int(splitmix(np.uint64((key + j) & mask)))
        add(y0 + r % (y1 - y0), x0 + (r >> 32) % (x1 - x0))
    if not seen:  # every proposal fell outside the class window: the current source
        seen.append((int(s.cands.src[oy, ox, 0]), int(s.cands.src[oy, ox, 1])))
    return np.array(seen, dtype=np.int64).reshape(-1, 2)


def synthesize_chunk_reference(state: SearchState, start: int, stop: int) -> None:
    """Slow, obvious NumPy version of :func:`synthesize_chunk` (same arguments, same results)."""
    for p in state.run.order[start:stop]:
        _positions_reference(state, [[int(p)]])


def synthesize_levels_reference(state: SearchState, schedule: Schedule, level_lo: int, level_hi: int) -> None:
    """Slow, obvious NumPy version of :func:`synthesize_levels` (same arguments, same results): the
    levels one after the other, each level's units one after the other."""
    sched, units, starts = schedule.sched, schedule.units, schedule.starts
    for level in range(level_lo, level_hi):
        steps = range(int(starts[level]), int(starts[level + 1]))
        _positions_reference(state, [[int(p) for p in sched[units[u] : units[u + 1]]] for u in steps])


def _positions_reference(state: SearchState, units: list[list[int]]) -> None:
    """Search and copy the positions of ``units`` in turn, the histogram counts as they were before the
    first one plus the changes of the position's own unit (each position's own label less one), changed
    after the last."""
    s = state
    out, ex, src, done = s.cur.out, s.cur.ex, s.cands.src, s.run.done
    H, W = out.shape[:2]
    y0, y1, x0, x1 = (int(v) for v in s.cands.valid)
    labels, count, ew = s.hist.labels, s.hist.count, ex.shape[1]
    frozen = count.copy()
    changes: list[tuple[int, int]] = []
    for unit in units:
        unit_count = frozen.copy()  # the level's counts, with this unit's own changes
        for p in unit:
            oy, ox = divmod(int(p), W)
            keep = np.ones(len(s.cur.offsets), dtype=bool)
            if s.run.first_pass:
                keep = done[(oy + s.cur.offsets[:, 0]) % H, (ox + s.cur.offsets[:, 1]) % W] != 0
                if s.par.weight == 0.0 and s.gui.weight == 0.0 and not keep.any():  # nothing to compare yet
                    out[oy, ox] = ex[src[oy, ox, 0], src[oy, ox, 1]]
                    done[oy, ox] = 1
                    s.run.best_out[oy, ox] = 0.0
                    continue
            if s.cands.exact:
                gy, gx = np.mgrid[y0:y1, x0:x1]
                cands = np.stack([gy.ravel(), gx.ravel()], axis=1)
                cands = cands[s.cands.mask[cands[:, 0], cands[:, 1]] != 0]
                cands = cands[_in_class_window(s, cands, oy, ox)]
                if len(cands) == 0:  # an empty class window: keep the source and its distance
                    out[oy, ox] = ex[src[oy, ox, 0], src[oy, ox, 1]]
                    done[oy, ox] = 1
                    continue
            else:
                key = int(splitmix(np.uint64(s.run.seed_key) ^ np.uint64(p)))
                cands = _candidates_reference(s, oy, ox, key)
            d = np.zeros(len(cands))
            if s.cur.weight > 0:
                d += s.cur.weight * _block_reference(
                    out, oy, ox, ex, cands, s.cur.offsets, s.cur.metric, s.alpha, keep, s.cur.entry_weights
                )
            if s.par.weight > 0:
                full = np.ones(len(s.par.offsets), dtype=bool)
                d += s.par.weight * _block_reference(
                    s.par.out,
                    oy // 2,
                    ox // 2,
                    s.par.ex,
                    cands // 2,
                    s.par.offsets,
                    s.par.metric,
                    s.alpha,
                    full,
                    s.par.entry_weights,
                )
            if s.gui.weight > 0:
                full = np.ones(len(s.gui.offsets), dtype=bool)
                d += s.gui.weight * _block_reference(
                    s.gui.out,
                    oy,
                    ox,
                    s.gui.ex,
                    cands,
                    s.gui.offsets,
                    s.gui.metric,
                    s.alpha,
                    full,
                    s.gui.entry_weights,
                )
            factor = np.ones(len(cands))
            if s.hist.weight > 0:  # counts are kept only while they matter
                old = int(labels[src[oy, ox, 0] * ew + src[oy, ox, 1]])
                lab = labels[cands[:, 0] * ew + cands[:, 1]]
                have = unit_count[lab] - (lab == old)
                factor = 1.0 + s.hist.weight * np.maximum(have / s.hist.target[lab] - 1.0, 0.0)
            best = int(np.argmin(d * factor))
            by, bx = cands[best]
            src[oy, ox] = (by, bx)
            if s.hist.weight > 0:
                changes.append((old, int(labels[by * ew + bx])))
                unit_count[old] -= 1  # the unit's own changes count at once
                unit_count[labels[by * ew + bx]] += 1
            out[oy, ox] = ex[by, bx]
            done[oy, ox] = 1
            s.run.best_out[oy, ox] = d[best]
    for old, new in changes:
        count[old] -= 1
        count[new] += 1
