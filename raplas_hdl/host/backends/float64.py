"""The ``float64`` backend: the reference with no quantisation."""

from __future__ import annotations

import numpy as np

from ...engine.kernels import F64_SLACK, cull_f64, trace_f64
from ...engine.passes import Arithmetic, BundleBatch
from ...model.bundles import bundle_geometry
from ...model.intersection import enumerate_pairs
from ..exact import float64_intersect
from .base import COUNTERS, Backend, RunResult


class Float64Backend(Backend):
    """Reference backend: float64 culling and float64 Moller-Trumbore, no quantisation."""

    name = "float64"

    def load(self, tris, tree, bound):
        rep = super().load(tris, tree, bound)
        r = tree.radii * (1.0 + F64_SLACK)
        t = self.tris
        v0 = t[:, 0]
        e1, e2 = t[:, 1] - v0, t[:, 2] - v0
        nn = np.stack([e1[:, 1] * e2[:, 2] - e1[:, 2] * e2[:, 1],
                       e1[:, 2] * e2[:, 0] - e1[:, 0] * e2[:, 2],
                       e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]], axis=1)
        leaf = tree.leaf_node
        self.scene = self._scene_tree(tree, tree.centres, r, tree.centres[leaf], r[leaf], v0,
                                      e1, e2, nn)
        return rep

    def arithmetic(self):
        return Arithmetic("float64", cull_f64, trace_f64, ())

    def batch(self, origins, centres, col_axes, row_axes, rows, cols, enable=None):
        g = bundle_geometry(origins, centres, col_axes, row_axes, rows, cols)
        B = len(g["plane_p"])
        o = np.ascontiguousarray(origins, np.float64).reshape(B, 3)
        return BundleBatch(rows, cols, np.ascontiguousarray(g["plane_n"].reshape(-1, 3)),
                           np.ascontiguousarray(g["plane_p"].reshape(-1)), o,
                           np.ascontiguousarray(g["directions"].reshape(-1, 3)),
                           self._enable_array(enable, B, rows * cols), np.zeros(B, bool), o,
                           g["directions"], g)

    def _masks(self, batch, b, ids):
        """The float64 plane test of leaf spheres ``ids`` against bundle ``b``'s planes
        (S, P), the arithmetic of :func:`raplas_hdl.engine.kernels.cull_f64`."""
        P = batch.n_planes
        if batch.keep_all[b]:
            return np.ones((ids.size, P), bool)
        pn = batch.pn[b * P:(b + 1) * P]
        pp = batch.pp[b * P:(b + 1) * P]
        a = self.scene.sc[ids][:, None, :] * pn[None, :, :]
        d = a[..., 0] + a[..., 1] + a[..., 2] + pp
        slack = F64_SLACK * (np.abs(a[..., 0]) + np.abs(a[..., 1]) + np.abs(a[..., 2])
                             + np.abs(pp))
        return np.abs(d) <= self.scene.sr[ids][:, None] + slack

    def stream(self, batch, runs):
        out = []
        sc = self.scene
        for b, ids in runs:
            ids = np.asarray(ids, dtype=np.int64)
            counters = dict.fromkeys(COUNTERS, 0)
            counters["spheres"] = int(ids.size)
            counters["plane_tests"] = int(ids.size) * batch.n_planes
            if ids.size == 0:
                out.append(RunResult.empty(counters))
                continue
            keep = self._masks(batch, b, ids)
            rm, cm = keep[:, :batch.rows], keep[:, batch.rows:]
            ray, tri, skipped = enumerate_pairs(batch, rm, cm, sc.tcount[ids], sc.tlist[ids],
                                                batch.enable[b])
            counters["pairs_skipped"] = skipped
            counters["pairs_issued"] = int(ray.size)
            tv = self.tris[tri]
            r = float64_intersect(np.broadcast_to(batch.origin[b], (ray.size, 3)),
                                  batch.directions[b][ray], tv[:, 0], tv[:, 1], tv[:, 2])
            hit = np.asarray(r["hit"], bool)
            t, u, v = (np.where(hit, r[k], np.nan) for k in ("t", "u", "v"))
            counters["hits"] = int(hit.sum())
            out.append(RunResult(ray, tri, hit, t, u, v, np.zeros(ray.size, np.uint8),
                                 counters))
        return out
