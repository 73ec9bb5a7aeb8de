"""Graph-cut seam over a patch's overlap (Kwatra, Schödl, Essa, Turk, Bobick 2003, sec. 3).

Every overlap pixel is a node; 4-neighbours ``s, t`` are joined by an undirected edge of capacity
``M(s, t) = ||A(s) - B(s)|| + ||A(t) - B(t)||`` (eq. 1; ``A`` = the output so far, ``B`` = the new patch,
Euclidean norm over channels). Overlap pixels on the patch's outer border (next to the old output) are tied
to the source (old side) and those next to the patch's non-overlap interior to the sink (new side) by
edges of infinite capacity; the minimum s-t cut (:func:`scipy.sparse.csgraph.maximum_flow`) splits the
overlap into the pixels that keep the old values and those that take the new patch's.

``maximum_flow`` takes integer capacities: the costs are scaled to integers in ``[1, 2^16]`` (the +1 keeps
every edge, so the graph stays connected), and "infinite" is ``2^29``, above any finite cut of a patch
overlap (at most a few thousand edges).

The known region may be any union of border strips (:class:`texsynth.synth.patch.layout.Strips`): a wrapped
patch of a periodic layout is also known along its right and/or bottom border, and those borders are tied to
the source like the top and left ones, so the cut runs through every strip.
"""

from __future__ import annotations

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import breadth_first_order, maximum_flow

__all__ = ["INFINITE", "SCALE", "graph_cut_mask", "overlap_graph"]

SCALE = 2**16
INFINITE = 2**29


def _edge_costs(old: np.ndarray, new: np.ndarray) -> np.ndarray:
    d = np.asarray(old, dtype=np.float64) - np.asarray(new, dtype=np.float64)
    return np.sqrt((d * d).sum(axis=2)) if d.ndim == 3 else np.abs(d)


def overlap_graph(
    old: np.ndarray, new: np.ndarray, overlap_mask: np.ndarray, keep_old: np.ndarray | None = None
) -> tuple[csr_matrix, np.ndarray, int, int]:
    """The s-t graph of an overlap: ``(capacities, node_of_pixel, source, sink)``.

    Parameters
    ----------
    old, new : ndarray, shape (w, w) or (w, w, C)
        The output under the patch and the new patch.
    overlap_mask : ndarray of bool, shape (w, w)
        The overlap (pixels that already hold values).
    keep_old : ndarray of bool, shape (w, w), optional
        More overlap pixels tied to the source (kept old), besides the outer borders of the strips: e.g.
        a strip's end on a patch border where the output beyond it is already written.

    Returns
    -------
    capacities : csr_matrix of int32, shape (n + 2, n + 2)
        Symmetric pixel edges plus source -> old-border and new-border -> sink edges.
    node_of_pixel : ndarray of int, shape (w, w)
        Node index of each overlap pixel, -1 elsewhere.
    source, sink : int
        The two terminal nodes (``n`` and ``n + 1``).
    """
    mask = np.asarray(overlap_mask, dtype=bool)
    h, w = mask.shape
    nodes = np.full((h, w), -1, dtype=np.int64)
    n = int(mask.sum())
    nodes[mask] = np.arange(n)
    source, sink = n, n + 1
    cost = _edge_costs(old, new)
    rows: list[np.ndarray] = []
    cols: list[np.ndarray] = []
    caps: list[np.ndarray] = []
    pair_costs = []
    pairs = []
    for a, b in (
        ((slice(None), slice(0, -1)), (slice(None), slice(1, None))),
        ((slice(0, -1), slice(None)), (slice(1, None), slice(None))),
    ):
        both = mask[a] & mask[b]
        pairs.append((nodes[a][both], nodes[b][both]))
        pair_costs.append(cost[a][both] + cost[b][both])
    allc = np.concatenate(pair_costs) if pair_costs else np.zeros(0)
    top = float(allc.max()) if allc.size else 0.0
    for (u, v), c in zip(pairs, pair_costs, strict=True):
        cap = 1 + (np.floor(c / top * SCALE) if top > 0 else np.zeros_like(c)).astype(np.int64)
        rows += [u, v]
        cols += [v, u]
        caps += [cap, cap]
    # Terminals: the patch's outer border inside the overlap touches the old output; overlap pixels
    # 4-adjacent to the non-overlap interior touch the new patch.
    border = np.zeros((h, w), dtype=bool)
    border[0, :] |= mask[0, :] & _strip_kind(mask, "top")
    border[:, 0] |= mask[:, 0] & _strip_kind(mask, "left")
    border[-1, :] |= mask[-1, :] & _strip_kind(mask, "bottom")
    border[:, -1] |= mask[:, -1] & _strip_kind(mask, "right")
    if keep_old is not None:
        border |= np.asarray(keep_old, dtype=bool) & mask
    interior = ~mask
    near_new = np.zeros((h, w), dtype=bool)
    near_new[:-1, :] |= interior[1:, :]
    near_new[1:, :] |= interior[:-1, :]
    near_new[:, :-1] |= interior[:, 1:]
    near_new[:, 1:] |= interior[:, :-1]
    near_new &= mask
    old_nodes = nodes[border & ~near_new]
    new_nodes = nodes[near_new]
    rows += [np.full(old_nodes.size, source), new_nodes]
    cols += [old_nodes, np.full(new_nodes.size, sink)]
    caps += [np.full(old_nodes.size, INFINITE), np.full(new_nodes.size, INFINITE)]
    graph = csr_matrix(
        (np.concatenate(caps).astype(np.int32), (np.concatenate(rows), np.concatenate(cols))),
        shape=(n + 2, n + 2),
    )
    graph.sum_duplicates()
    return graph, nodes, source, sink


def _strip_kind(mask: np.ndarray, side: str) -> bool:
    """Whether the overlap includes the whole top row / left column / bottom row / right column (a strip
    along that border)."""
    line = {"top": mask[0, :], "left": mask[:, 0], "bottom": mask[-1, :], "right": mask[:, -1]}[side]
    return bool(line.all())


def graph_cut_mask(
    old: np.ndarray, new: np.ndarray, overlap_mask: np.ndarray, keep_old: np.ndarray | None = None
) -> np.ndarray:
    """Where the new patch wins after the graph-cut seam: boolean ``(w, w)``.

    Non-overlap pixels always take the new patch; overlap pixels reachable from the source in the residual
    graph of a maximum flow keep the old values. ``keep_old``: more pixels tied to the source
    (:func:`overlap_graph`).
    """
    mask = np.asarray(overlap_mask, dtype=bool)
    if not mask.any():
        return np.ones(mask.shape, dtype=bool)
    graph, nodes, source, sink = overlap_graph(old, new, mask, keep_old)
    flow = maximum_flow(graph, source, sink).flow
    residual = (graph - flow).tocsr()
    residual.data[residual.data < 0] = 0
    residual.eliminate_zeros()
    reached = breadth_first_order(residual, source, directed=True, return_predecessors=False)
    old_side = np.zeros(graph.shape[0], dtype=bool)
    old_side[reached] = True
    keep_old = np.zeros(mask.shape, dtype=bool)
    keep_old[mask] = old_side[nodes[mask]]
    return ~keep_old
