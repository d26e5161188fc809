"""Seeded hard-case (ray, triangle) families in float64 and bit-pattern vectors drawn from them.

:func:`generate` makes (ray, triangle) pairs in float64 scene coordinates, family by
family (same arguments, same cases); :func:`vectors` encodes pairs of all families for a
format (the triangles through :func:`raplas_hdl.model.triangles.make_triangles`) and mixes
in special and random bit patterns, the stimulus that checks an implementation against the
golden model. The stress campaign (:mod:`raplas_hdl.verify.stress`) judges the pairs by the
exact reference R.

Families (``FAMILIES``): ``random``; ``shared_edge`` (two triangles of a quad, ray aimed
at a point of the diagonal); ``shared_vertex`` (a fan of six triangles, ray aimed at the
centre); ``near_parallel`` (det near 0); ``grazing`` (target at a relative distance
``2**-k`` from an edge, either side); ``tiny`` (edges near the domain's minimum,
geometry at that scale);
``huge`` (edges near the domain's maximum); ``far`` (geometry near the domain's
bound, far from the origin); ``thin`` (aspect ratios ``2**6`` to ``2**16``, targets near
the long edges); ``on_start`` (ray origin on the triangle, or just behind or in front);
``flush`` (edges near ``2**(emin/2)``, so that N, det and t' are near the format's flush
level and some of their products flush to zero: the certified bounds' flush terms).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..fp.format import FPFormat
from ..fp.model import encode
from .conservative import domain
from .triangles import make_triangles

__all__ = ["FAMILIES", "StressCases", "generate", "vectors"]

FAMILIES = ("random", "shared_edge", "shared_vertex", "near_parallel", "grazing", "tiny",
            "huge", "far", "thin", "on_start", "flush")


@dataclass
class StressCases:
    """Pairs of one or more families (float64 scene coordinates).

    Attributes
    ----------
    family : ndarray of int
        Index into ``FAMILIES`` per pair.
    group : ndarray of int
        Ray group for the leak count (pairs of one ray against the triangles around a
        shared edge or vertex share a group), -1 elsewhere.
    o, d, v0, v1, v2 : ndarray of float64, shape (n, 3)
    seed : int
    """

    family: np.ndarray
    group: np.ndarray
    o: np.ndarray
    d: np.ndarray
    v0: np.ndarray
    v1: np.ndarray
    v2: np.ndarray
    seed: int

    def __len__(self):
        return len(self.family)


# -- geometry helpers ----------------------------------------------------------------------
def _rotations(rng, n):
    q, r = np.linalg.qr(rng.normal(size=(n, 3, 3)))
    return q * np.sign(np.diagonal(r, axis1=1, axis2=2))[:, None, :]


def _place(local, rot, scale, centre):
    """``centre + scale * rot @ local`` for (n, k, 3) local points."""
    return centre[:, None, :] + scale[:, None, None] * np.einsum("nij,nkj->nki", rot, local)


def _dirs(rng, n, rot, min_z=0.2):
    """Unit directions in world space with ``|local z| >= min_z`` and a random sign."""
    v = rng.normal(size=(n, 3))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    z = np.abs(v[:, 2])
    v[:, 2] = np.where(z < min_z, min_z, z) * rng.choice([-1.0, 1.0], size=n)
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    return np.einsum("nij,nj->ni", rot, v)


def _tri_local(rng, n):
    a = rng.uniform(-0.5, 1.5, n)
    b = rng.uniform(0.2, 1.5, n)
    z = np.zeros(n)
    return np.stack([np.stack([z, z, z], 1), np.stack([z + 1, z, z], 1),
                     np.stack([a, b, z], 1)], axis=1)


def _bary_point(tri, beta, gamma):
    return tri[:, 0] + beta[:, None] * (tri[:, 1] - tri[:, 0]) \
        + gamma[:, None] * (tri[:, 2] - tri[:, 0])


def _cycle(rng, tri):
    """Random cyclic vertex order (which vertex is V0 changes E1, E2 and N)."""
    k = rng.integers(0, 3, len(tri))
    idx = (np.arange(3)[None, :] + k[:, None]) % 3
    return np.take_along_axis(tri, idx[:, :, None], axis=1)


def _single(rng, n, scale, centre, target_local, rot=None, dirs=None, dist=None):
    """One triangle per ray, both given in local coordinates then placed."""
    rot = _rotations(rng, n) if rot is None else rot
    tri_local = target_local[1]
    tri = _place(tri_local, rot, scale, centre)
    p = _place(target_local[0][:, None, :], rot, scale, centre)[:, 0]
    d = _dirs(rng, n, rot) if dirs is None else dirs
    dist = scale * 2.0 ** rng.uniform(0, 6, n) if dist is None else dist
    o = p - dist[:, None] * d
    return o, d, _cycle(rng, tri)


# -- families ------------------------------------------------------------------------------
def _fam_random(rng, n, fmt):
    tri = _tri_local(rng, n)
    p = _bary_point(tri, rng.uniform(-0.3, 1.3, n), rng.uniform(-0.3, 1.3, n))
    return _single(rng, n, 2.0 ** rng.uniform(-4, 4, n), rng.uniform(-8, 8, (n, 3)), (p, tri))


def _edge_target(rng, tri, rel):
    """A point on a random edge of each triangle, moved in-plane by ``rel`` (signed)."""
    n = len(tri)
    k = rng.integers(0, 3, n)
    a = tri[np.arange(n), k]
    b = tri[np.arange(n), (k + 1) % 3]
    lam = rng.uniform(0.05, 0.95, n)
    e = b - a
    perp = np.stack([-e[:, 1], e[:, 0], np.zeros(n)], 1)
    perp /= np.linalg.norm(perp, axis=1, keepdims=True)
    return a + lam[:, None] * e + rel[:, None] * perp


def _fam_grazing(rng, n, fmt):
    tri = _tri_local(rng, n)
    rel = rng.choice([-1.0, 1.0], n) * 2.0 ** -rng.uniform(4, fmt.man_bits + 8, n)
    p = _edge_target(rng, tri, rel)
    return _single(rng, n, 2.0 ** rng.uniform(-3, 3, n), rng.uniform(-4, 4, (n, 3)), (p, tri))


def _fam_near_parallel(rng, n, fmt):
    tri = _tri_local(rng, n)
    p = _bary_point(tri, rng.uniform(-0.2, 1.2, n), rng.uniform(-0.2, 1.2, n))
    rot = _rotations(rng, n)
    ang = rng.uniform(0, 2 * np.pi, n)
    dz = rng.choice([-1.0, 1.0], n) * 2.0 ** -rng.uniform(1, fmt.man_bits + 6, n)
    dl = np.stack([np.cos(ang), np.sin(ang), dz], 1)
    dl /= np.linalg.norm(dl, axis=1, keepdims=True)
    d = np.einsum("nij,nj->ni", rot, dl)
    scale = 2.0 ** rng.uniform(-3, 3, n)
    return _single(rng, n, scale, rng.uniform(-4, 4, (n, 3)), (p, tri), rot=rot, dirs=d,
                   dist=scale * 2.0 ** rng.uniform(0, 3, n))


def _fam_tiny(rng, n, fmt):
    dom = domain(fmt)
    tri = _tri_local(rng, n)
    p = _bary_point(tri, rng.uniform(-0.2, 1.2, n), rng.uniform(-0.2, 1.2, n))
    scale = 2.0 ** -(dom.min_edge_exp - rng.uniform(0, 6, n))
    centre = rng.uniform(-1, 1, (n, 3)) * (scale * 2.0 ** rng.uniform(0, 10, n))[:, None]
    return _single(rng, n, scale, centre, (p, tri),
                   dist=scale * 2.0 ** rng.uniform(0, 8, n))


def _fam_huge(rng, n, fmt):
    dom = domain(fmt)
    tri = _tri_local(rng, n)
    p = _bary_point(tri, rng.uniform(-0.2, 1.2, n), rng.uniform(-0.2, 1.2, n))
    scale = 2.0 ** (dom.pos_exp - 2 - rng.uniform(0, 3, n))
    centre = rng.uniform(-1, 1, (n, 3)) * 2.0 ** (dom.pos_exp - 3)
    return _single(rng, n, scale, centre, (p, tri), dist=scale * rng.uniform(0.1, 0.5, n))


def _fam_far(rng, n, fmt):
    dom = domain(fmt)
    tri = _tri_local(rng, n)
    rel = rng.choice([-1.0, 1.0], n) * 2.0 ** -rng.uniform(2, fmt.man_bits + 4, n)
    p = _edge_target(rng, tri, rel)
    centre = (rng.choice([-1.0, 1.0], (n, 3)) * rng.uniform(0.5, 0.9, (n, 3))
              * 2.0 ** dom.pos_exp)
    scale = 2.0 ** rng.uniform(-2, 4, n)
    return _single(rng, n, scale, centre, (p, tri), dist=scale * 2.0 ** rng.uniform(0, 4, n))


def _fam_thin(rng, n, fmt):
    h = 2.0 ** -rng.uniform(6, 16, n)
    a = rng.uniform(0, 1, n)
    z = np.zeros(n)
    tri = np.stack([np.stack([z, z, z], 1), np.stack([z + 1, z, z], 1),
                    np.stack([a, h, z], 1)], axis=1)
    rel = rng.choice([-1.0, 1.0], n) * h * 2.0 ** -rng.uniform(0, fmt.man_bits, n)
    lam = rng.uniform(0.05, 0.95, n)
    p = np.stack([lam, rel, z], 1)
    return _single(rng, n, 2.0 ** rng.uniform(-2, 4, n), rng.uniform(-4, 4, (n, 3)), (p, tri))


def _fam_on_start(rng, n, fmt):
    tri = _tri_local(rng, n)
    p = _bary_point(tri, rng.uniform(-0.1, 1.1, n), rng.uniform(-0.1, 1.1, n))
    scale = 2.0 ** rng.uniform(-3, 3, n)
    off = rng.choice([-1.0, 0.0, 1.0], n) * 2.0 ** -rng.uniform(2, fmt.man_bits + 6, n)
    return _single(rng, n, scale, rng.uniform(-4, 4, (n, 3)), (p, tri), dist=scale * off)


def _fam_flush(rng, n, fmt):
    tri = _tri_local(rng, n)
    p = _bary_point(tri, rng.uniform(-0.2, 1.2, n), rng.uniform(-0.2, 1.2, n))
    scale = 2.0 ** (fmt.emin / 2 + rng.uniform(-1, 4, n))
    centre = rng.uniform(-1, 1, (n, 3)) * (scale * 2.0 ** rng.uniform(0, 6, n))[:, None]
    return _single(rng, n, scale, centre, (p, tri), dist=scale * 2.0 ** rng.uniform(0, 6, n))


def _fam_shared_edge(rng, n, fmt):
    """Quads split along a diagonal: rays aimed at the diagonal hit (in R) one or both."""
    z = np.zeros(n)
    v1 = np.stack([z, z, z], 1)
    v2 = np.stack([z + 1, z, z], 1)
    va = np.stack([rng.uniform(-0.5, 1.5, n), rng.uniform(0.2, 1.5, n), z], 1)
    vb = np.stack([rng.uniform(-0.5, 1.5, n), -rng.uniform(0.2, 1.5, n), z], 1)
    rot = _rotations(rng, n)
    scale = 2.0 ** rng.uniform(-3, 3, n)
    centre = rng.uniform(-4, 4, (n, 3))
    pts = _place(np.stack([v1, v2, va, vb], 1), rot, scale, centre)
    lam = rng.uniform(0.02, 0.98, n)
    target = pts[:, 0] + lam[:, None] * (pts[:, 1] - pts[:, 0])
    d = _dirs(rng, n, rot)
    o = target - (scale * 2.0 ** rng.uniform(0, 6, n))[:, None] * d
    ta = _cycle(rng, np.stack([pts[:, 2], pts[:, 0], pts[:, 1]], 1))
    tb = _cycle(rng, np.stack([pts[:, 3], pts[:, 1], pts[:, 0]], 1))
    grp = np.arange(n)
    return (np.concatenate([o, o]), np.concatenate([d, d]), np.concatenate([ta, tb]),
            np.concatenate([grp, grp]))


def _fam_shared_vertex(rng, n, fmt, k=6):
    ang = 2 * np.pi * (np.arange(k)[None, :] + rng.uniform(-0.2, 0.2, (n, k))) / k
    rad = rng.uniform(0.7, 1.3, (n, k))
    ring = np.stack([rad * np.cos(ang), rad * np.sin(ang), np.zeros((n, k))], 2)
    rot = _rotations(rng, n)
    scale = 2.0 ** rng.uniform(-3, 3, n)
    centre = rng.uniform(-4, 4, (n, 3))
    pts = _place(np.concatenate([np.zeros((n, 1, 3)), ring], 1), rot, scale, centre)
    d = _dirs(rng, n, rot)
    o = pts[:, 0] - (scale * 2.0 ** rng.uniform(0, 6, n))[:, None] * d
    tris = [_cycle(rng, np.stack([pts[:, 0], pts[:, 1 + j], pts[:, 1 + (j + 1) % k]], 1))
            for j in range(k)]
    grp = np.arange(n)
    return (np.tile(o, (k, 1)), np.tile(d, (k, 1)), np.concatenate(tris), np.tile(grp, k))


_GEN = {"random": _fam_random, "grazing": _fam_grazing, "near_parallel": _fam_near_parallel,
        "tiny": _fam_tiny, "huge": _fam_huge, "far": _fam_far, "thin": _fam_thin,
        "on_start": _fam_on_start, "shared_edge": _fam_shared_edge, "flush": _fam_flush,
        "shared_vertex": _fam_shared_vertex}


def generate(fmt: FPFormat, per_family: int = 1000, seed: int = 0,
             families=FAMILIES) -> StressCases:
    """Generate ``per_family`` rays of each family (the edge and vertex families give 2 and
    6 pairs per ray). Same arguments, same cases.

    Raises
    ------
    ValueError
        For an unknown family or a non-positive count.
    """
    if per_family < 1:
        raise ValueError(f"per_family must be at least 1, not {per_family}")
    fam, grp, o, d, tri = [], [], [], [], []
    gbase = 0
    for name in families:
        if name not in _GEN:
            raise ValueError(f"unknown stress family {name!r}; known: {', '.join(FAMILIES)}")
        rng = np.random.default_rng([seed, FAMILIES.index(name)])
        out = _GEN[name](rng, per_family, fmt)
        if len(out) == 4:
            oo, dd, tt, gg = out
            gg = gg + gbase
            gbase = gg.max() + 1
        else:
            oo, dd, tt = out
            gg = np.full(len(oo), -1)
        fam.append(np.full(len(oo), FAMILIES.index(name)))
        grp.append(gg)
        o.append(oo)
        d.append(dd)
        tri.append(tt)
    tri = np.concatenate(tri)
    return StressCases(np.concatenate(fam), np.concatenate(grp), np.concatenate(o),
                       np.concatenate(d), tri[:, 0].copy(), tri[:, 1].copy(), tri[:, 2].copy(),
                       seed)


def vectors(fmt: FPFormat, count: int, seed: int = 0, special_rate: float = 0.02,
            random_rate: float = 0.1) -> dict:
    """Bit-pattern vectors for checking an implementation against the golden model.

    Pairs of all families (the ray encoded with the format's rounding, the triangle
    through :func:`~raplas_hdl.model.triangles.make_triangles`), where a fraction
    ``special_rate`` of the components is replaced by a special pattern (signed zeros,
    infinities, the canonical and other NaNs, denormal patterns, max finite, min normal)
    and a fraction ``random_rate`` of the pairs by uniformly random patterns.

    Returns
    -------
    dict
        ``o``, ``d``, ``v0``, ``e1``, ``e2``, ``n``: uint32 arrays of shape (count, 3).
    """
    per = max(1, -(-count // len(FAMILIES)))
    cases = generate(fmt, per, seed)
    recs = make_triangles(np.stack([cases.v0, cases.v1, cases.v2], 1), fmt, on_bad="skip")
    k = recs.ids
    rng = np.random.default_rng([seed, 99])
    pick = rng.permutation(len(k))[:count]
    if len(pick) < count:
        pick = rng.choice(len(k), count)
    out = {"o": encode(cases.o[k], fmt)[pick], "d": encode(cases.d[k], fmt)[pick],
           "v0": recs.v0_bits[pick], "e1": recs.e1_bits[pick], "e2": recs.e2_bits[pick],
           "n": recs.n_bits[pick]}
    m = fmt.man_bits
    specials = np.array([0, fmt.sign_bit, fmt.inf, fmt.inf | fmt.sign_bit, fmt.nan,
                         fmt.inf | 1, fmt.nan | fmt.sign_bit, 1, fmt.man_mask | fmt.sign_bit,
                         fmt.max_finite, fmt.max_finite | fmt.sign_bit, fmt.min_normal,
                         fmt.min_normal | fmt.sign_bit, fmt.one, fmt.one | fmt.sign_bit,
                         1 << m], dtype=np.uint32)
    rand_pair = rng.random(count) < random_rate
    for name in out:
        a = out[name].copy()
        a[rand_pair] = rng.integers(0, fmt.mask + 1, (int(rand_pair.sum()), 3), dtype=np.uint32)
        sp = rng.random(a.shape) < special_rate
        a[sp] = rng.choice(specials, int(sp.sum()))
        out[name] = a
    return out
