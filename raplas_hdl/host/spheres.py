"""Bounding spheres: a BVH-style split into spheres of at most ``tris_per_sphere``
triangles, a sphere hierarchy above them, and the top-down cull of that hierarchy.

Build (:func:`build_sphere_tree`): the triangles are split recursively by the median of
their centroids along the longest axis of the centroids' bounding box. A node with at
most ``tris_per_sphere`` triangles is a leaf; a larger one is bisected ``log2(fanout)``
times, giving up to ``fanout`` children (parts that are already small enough stop
bisecting early). Split points are rounded to multiples of ``tris_per_sphere`` so leaves
are full. Each node's sphere is centred on the bounding-box centre of its triangles'
vertices and reaches the farthest vertex plus the triangles' ``margin``: the distance by
which the ray-triangle unit's conservative mode may accept a ray outside the triangle.
So a node's sphere encloses every triangle below it as the unit sees it, and every
child's region. The leaves, in depth-first order, are the Sphere Memory (leaf ``k`` is
sphere ID ``k``), which keeps spatially close spheres close in memory.

Cull (:func:`cull_tree`): for one bundle, the host tests the internal nodes level by
level with the same plane test as the unit (the caller passes it), starting at the root.
A node that no (row plane, column plane) pair touches (its row mask or its column mask
is empty) drops out with its whole subtree; the children of a surviving node are
tested at the next level, and surviving leaves go to the unit, which tests them again
with the bundle's planes. Each level's count of tested and dropped nodes and of the
triangles they held is returned, so the skipped work can be reported.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..fp import model as fpm
from ..model.conservative import margins

__all__ = [
    "CullStats",
    "SphereTree",
    "build_sphere_tree",
    "cull_tree",
    "enclosing_spheres",
    "unit_margin",
]


@dataclass
class SphereTree:
    """A sphere hierarchy over a triangle list.

    Attributes
    ----------
    centres : ndarray (nodes, 3) float64
    radii : ndarray (nodes,) float64
        Node spheres; node 0 is the root.
    child_start : ndarray (nodes + 1,) int64
        Children of node ``k`` are ``child_index[child_start[k]:child_start[k+1]]``.
    child_index : ndarray int64
    depth : ndarray (nodes,) int64
        Root at depth 0.
    node_leaf : ndarray (nodes,) int64
        Leaf sphere ID of a leaf node, -1 for an internal node.
    node_tris : ndarray (nodes,) int64
        Triangles below each node.
    leaf_node : ndarray (leaves,) int64
        Node of each leaf sphere.
    leaf_tris : ndarray (leaves, tris_per_sphere) int64
        Triangle IDs of each leaf sphere, padded with -1.
    tris_per_sphere, fanout : int
    """

    centres: np.ndarray
    radii: np.ndarray
    child_start: np.ndarray
    child_index: np.ndarray
    depth: np.ndarray
    node_leaf: np.ndarray
    node_tris: np.ndarray
    leaf_node: np.ndarray
    leaf_tris: np.ndarray
    tris_per_sphere: int
    fanout: int

    @property
    def n_nodes(self) -> int:
        return len(self.radii)

    @property
    def n_leaves(self) -> int:
        return len(self.leaf_node)

    @property
    def levels(self) -> int:
        return int(self.depth.max()) + 1

    @property
    def leaf_centres(self) -> np.ndarray:
        return self.centres[self.leaf_node]

    @property
    def leaf_radii(self) -> np.ndarray:
        return self.radii[self.leaf_node]

    @property
    def leaf_counts(self) -> np.ndarray:
        """Triangles in each leaf sphere."""
        return (self.leaf_tris >= 0).sum(axis=1)

    def children(self, nodes: np.ndarray) -> np.ndarray:
        """All children of ``nodes``, concatenated in node order."""
        nodes = np.asarray(nodes, dtype=np.int64)
        if len(nodes) == 0:
            return nodes
        starts, ends = self.child_start[nodes], self.child_start[nodes + 1]
        lens = ends - starts
        offs = np.repeat(starts - np.cumsum(lens) + lens, lens)
        return self.child_index[offs + np.arange(lens.sum())]


def enclosing_spheres(tris: np.ndarray, groups, margin) -> tuple[np.ndarray, np.ndarray]:
    """Spheres around groups of triangles.

    Parameters
    ----------
    tris : ndarray (F, 3, 3)
    groups : list of int arrays
        Triangle IDs of each group.
    margin : ndarray (F,)
        Per-triangle distance added to the radius.

    Returns
    -------
    centres (G, 3), radii (G,)
        Centre: the bounding-box centre of the group's vertices; radius: the largest
        distance to a vertex plus the largest margin of the group.
    """
    centres = np.empty((len(groups), 3))
    radii = np.empty(len(groups))
    for k, g in enumerate(groups):
        v = tris[g].reshape(-1, 3)
        c = 0.5 * (v.min(axis=0) + v.max(axis=0))
        centres[k] = c
        radii[k] = np.sqrt(((v - c) ** 2).sum(axis=1).max()) + margin[g].max()
    return centres, radii


def build_sphere_tree(tris, tris_per_sphere: int = 8, fanout: int = 8,
                      margin=0.0) -> SphereTree:
    """Group triangles into a sphere hierarchy.

    Parameters
    ----------
    tris : array_like (F, 3, 3)
        Triangle vertices in scene coordinates.
    tris_per_sphere : int
        Most triangles per leaf sphere (the unit's ``tris_per_sphere``).
    fanout : int
        Most children per internal node, a power of two >= 2.
    margin : float or array_like (F,)
        The ray-triangle unit's conservative margin as a distance, per triangle.

    Raises
    ------
    ValueError
        For an empty or malformed triangle array, or bad parameters.
    """
    tris = np.asarray(tris, dtype=np.float64)
    if tris.ndim != 3 or tris.shape[1:] != (3, 3):
        raise ValueError(f"triangles must have shape (F, 3, 3), not {tris.shape}")
    if len(tris) == 0:
        raise ValueError("cannot build spheres around zero triangles")
    if not np.all(np.isfinite(tris)):
        raise ValueError("a triangle has a NaN or infinite vertex")
    if int(tris_per_sphere) < 1:
        raise ValueError(f"tris_per_sphere must be at least 1, not {tris_per_sphere}")
    if fanout < 2 or fanout & (fanout - 1):
        raise ValueError(f"fanout must be a power of two >= 2, not {fanout}")
    margin = np.broadcast_to(np.asarray(margin, dtype=np.float64), (len(tris),))
    if np.any(margin < 0) or not np.all(np.isfinite(margin)):
        raise ValueError("margin must be finite and non-negative")
    T = int(tris_per_sphere)
    cent = tris.mean(axis=1)
    bisections = fanout.bit_length() - 1

    def bisect(ids):
        if len(ids) <= T:
            return [ids]
        c = cent[ids]
        axis = int(np.argmax(c.max(axis=0) - c.min(axis=0)))
        nleaf = -(-len(ids) // T)
        k = T * (-(-nleaf // 2))
        order = np.argpartition(c[:, axis], k - 1) if k < len(ids) else np.arange(len(ids))
        return [ids[order[:k]], ids[order[k:]]]

    # Iterative build: nodes in depth-first order.
    groups, depth, parent, children = [], [], [], []
    stack = [(np.arange(len(tris)), 0, -1)]
    while stack:
        ids, d, par = stack.pop()
        node = len(groups)
        groups.append(ids)
        depth.append(d)
        parent.append(par)
        children.append([])
        if par >= 0:
            children[par].append(node)
        if len(ids) > T:
            parts = [ids]
            for _ in range(bisections):
                parts = [q for p in parts for q in bisect(p)]
            for p in reversed(parts):
                stack.append((p, d + 1, node))

    n = len(groups)
    centres, radii = enclosing_spheres(tris, groups, margin)
    counts = np.array([len(c) for c in children], dtype=np.int64)
    child_start = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    child_index = np.array([c for cs in children for c in cs], dtype=np.int64)
    is_leaf = counts == 0
    leaf_node = np.flatnonzero(is_leaf).astype(np.int64)
    node_leaf = np.full(n, -1, dtype=np.int64)
    node_leaf[leaf_node] = np.arange(len(leaf_node))
    leaf_tris = np.full((len(leaf_node), T), -1, dtype=np.int64)
    for k, node in enumerate(leaf_node):
        g = np.sort(groups[node])
        leaf_tris[k, :len(g)] = g
    return SphereTree(centres, radii, child_start, child_index, np.array(depth, np.int64),
                      node_leaf, np.array([len(g) for g in groups], np.int64), leaf_node,
                      leaf_tris, T, fanout)


@dataclass
class CullStats:
    """What the hierarchy cull did for one bundle.

    Attributes
    ----------
    tested : ndarray (levels,) int64
        Internal nodes tested at each level on the host.
    dropped : ndarray (levels,) int64
        Of those, the ones no plane pair touches.
    tris_dropped : ndarray (levels,) int64
        Triangles below the dropped nodes (each is a skipped pair for every ray).
    leaves : int
        Leaf spheres handed to the unit.
    """

    tested: np.ndarray
    dropped: np.ndarray
    tris_dropped: np.ndarray
    leaves: int

    def __iadd__(self, other: CullStats):
        n = max(len(self.tested), len(other.tested))
        for name in ("tested", "dropped", "tris_dropped"):
            a = np.zeros(n, np.int64)
            a[:len(getattr(self, name))] += getattr(self, name)
            a[:len(getattr(other, name))] += getattr(other, name)
            setattr(self, name, a)
        self.leaves += other.leaves
        return self

    @classmethod
    def zero(cls, levels: int = 0) -> CullStats:
        z = np.zeros(levels, np.int64)
        return cls(z.copy(), z.copy(), z.copy(), 0)


def cull_tree(tree: SphereTree, touched, hierarchy: bool = True):
    """Cull the hierarchy top-down for one bundle.

    Parameters
    ----------
    tree : SphereTree
    touched : callable
        ``touched(node_ids) -> bool array``: True where some row plane and some column
        plane of the bundle touch the node's sphere (the same plane test as the unit,
        with the same radius inflation).
    hierarchy : bool
        False sends every leaf to the unit (no host test at all).

    Returns
    -------
    leaves : ndarray int64
        Leaf sphere IDs to run on the unit, ascending (Sphere Memory order).
    stats : CullStats
    """
    L = tree.levels
    stats = CullStats.zero(L)
    if not hierarchy:
        stats.leaves = tree.n_leaves
        return np.arange(tree.n_leaves, dtype=np.int64), stats
    active = np.array([0], dtype=np.int64)
    out = []
    while len(active):
        leaf = tree.node_leaf[active] >= 0
        out.append(tree.node_leaf[active[leaf]])
        inner = active[~leaf]
        if len(inner) == 0:
            break
        keep = np.asarray(touched(inner), dtype=bool)
        lvl = tree.depth[inner]
        np.add.at(stats.tested, lvl, 1)
        np.add.at(stats.dropped, lvl[~keep], 1)
        np.add.at(stats.tris_dropped, lvl[~keep], tree.node_tris[inner[~keep]])
        active = tree.children(inner[keep])
    leaves = np.sort(np.concatenate(out)) if out else np.zeros(0, np.int64)
    stats.leaves = len(leaves)
    return leaves, stats


def unit_margin(tris, fmt, o_max: float, mode: str = "conservative",
                margin_scale: float = 1.0) -> np.ndarray:
    """The distance by which the ray-triangle unit may accept a ray outside a triangle.

    In ``paper`` mode the unit never accepts a point outside the (quantised) triangle
    beyond rounding, and the culling bound already covers quantisation: 0. The same holds
    in ``certified`` mode, whose answer is the exact reference's. In
    ``conservative`` mode the barycentric tests are widened by the margins of
    :mod:`raplas_hdl.model.conservative`; for a ray at perpendicular incidence from an
    origin as far as ``o_max`` they allow ``u, v >= -m/|det|`` and ``u + v <= 1 + m_w/|det|``,
    which moves the accepted boundary out by at most that slack times the longest edge.
    (At grazing incidence the slack grows as ``1/cos``; such accepts are false hits by
    construction and may be culled: culling must only keep what the exact reference hits.)

    Returns
    -------
    ndarray (F,) float64
    """
    if mode in ("paper", "certified"):
        return np.zeros(len(tris))
    tris = np.asarray(tris, dtype=np.float64)
    v0 = tris[:, 0]
    e1, e2 = tris[:, 1] - v0, tris[:, 2] - v0
    n = np.cross(e1, e2)
    nn = np.linalg.norm(n, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        d = n / nn[:, None]
    d = np.where(np.isfinite(d), d, 0.0)
    o = np.full_like(v0, o_max)
    enc = [fpm.encode(x, fmt) for x in (o, d, v0, e1, e2, n)]
    m = margins(*enc, fmt, margin_scale=margin_scale)
    slack = np.maximum(np.maximum(fpm.decode(m["u"], fmt), fpm.decode(m["v"], fmt)),
                       fpm.decode(m["w"], fmt))
    longest = np.max(np.linalg.norm(np.stack([e1, e2, tris[:, 2] - tris[:, 1]], 1), axis=2),
                     axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        out = slack / nn * longest
    return np.where(np.isfinite(out), out, 0.0)
