"""Stimulus and results of the plane-sphere array's tests (``rtl/test_plane_sphere.py``,
``rtl/test_dsp48_target.py``): bundles, sphere patterns near their planes, the model's masks,
the PS_RESULT beats and their comparison, and the stimulus file of
``raplas_hdl/sim/tb/plane_sphere.py``."""

from __future__ import annotations

import numpy as np

from raplas_hdl.fp import model as fpm
from raplas_hdl.host.culling import CullingBudget, encode_spheres
from raplas_hdl.model.bundles import RayBundle
from raplas_hdl.model.plane_sphere import sphere_masks
from raplas_hdl.model.records import PLANE, PS_RESULT, SPHERE

ID_BITS = 16


def _bundle(rng, rows, cols):
    origin = rng.uniform(-2, 2, 3)
    centre = origin + rng.normal(size=3) * 1.5 + 0.1
    a = rng.normal(size=3) * rng.uniform(0.05, 1.0)
    b = np.cross(centre - origin, a)
    b = b / np.linalg.norm(b) * rng.uniform(0.05, 1.0)
    return RayBundle(origin, centre, a, b, rows, cols)


def _spheres(rng, bundle, fmt, n, first_id):
    """Sphere patterns: geometric ones near the bundle's planes (inflated radii), spheres
    at distance r(1 +- 2^-M) from a plane, and raw bit patterns (NaN, inf, negative and
    denormal patterns included) to exercise the comparator."""
    budget = CullingBudget(fmt, 8.0)
    k_geo = n // 2
    pts = bundle.points.reshape(-1, 3)
    t = rng.uniform(0.2, 3.0, k_geo)
    sel = pts[rng.integers(0, len(pts), k_geo)]
    centres = bundle.origin + t[:, None] * (sel - bundle.origin) + rng.normal(size=(k_geo, 3)) * 0.3
    radii = 10 ** rng.uniform(-3, 0, k_geo)
    c_geo, _, r_geo, _ = encode_spheres(centres, radii, budget)
    k_edge = n // 4
    planes = rng.integers(0, bundle.n_planes, k_edge)
    r_edge = 10 ** rng.uniform(-2, 0, k_edge)
    side = rng.choice([-1.0, 1.0], k_edge) * (1 + rng.choice([-2, 2], k_edge) * fmt.ulp)
    foot = bundle.origin + rng.normal(size=(k_edge, 3))
    n_pl = bundle.plane_n[planes]
    foot = foot - (np.sum(n_pl * foot, 1) + bundle.plane_p[planes])[:, None] * n_pl
    c_edge = fpm.encode(foot + (side * r_edge)[:, None] * n_pl, fmt)
    r_edge = fpm.encode(r_edge, fmt, direction="up")
    k_raw = n - k_geo - k_edge
    c_raw = rng.integers(0, 1 << fmt.width, (k_raw, 3), dtype=np.uint64).astype(np.uint32)
    r_raw = rng.integers(0, 1 << fmt.width, k_raw, dtype=np.uint64).astype(np.uint32)
    specials = [fmt.inf, fmt.nan, fmt.sign_bit, 0, 1, fmt.max_finite, fmt.sign_bit | fmt.one]
    r_raw[:len(specials)] = specials[:k_raw]
    c = np.concatenate([c_geo, c_edge, c_raw])
    r = np.concatenate([r_geo, r_edge, r_raw])
    order = rng.permutation(n)
    ids = (first_id + np.arange(n)) % (1 << ID_BITS)
    return ids, c[order], r[order]


def make_cases(rows, cols, fmt, n_bundles=2, n_spheres=40, seed=0):
    """Plane words, spheres and the model's masks for ``n_bundles`` bundles."""
    rng = np.random.default_rng(seed)
    cases = []
    for b in range(n_bundles):
        bundle = _bundle(rng, rows, cols)
        n, p = bundle.encode_planes(fmt)
        ids, c, r = _spheres(rng, bundle, fmt, n_spheres, b * n_spheres)
        row_mask, col_mask = sphere_masks(n, p, c, r, rows, cols, fmt)
        planes = PLANE.bind(fmt).pack({"nx": n[:, 0], "ny": n[:, 1], "nz": n[:, 2], "p": p})
        cases.append({"planes": planes, "ids": ids, "c": c, "r": r,
                      "row_mask": row_mask, "col_mask": col_mask})
    return cases


def sphere_payloads(fmt, case):
    """The case's spheres as input payloads (Python ints) of the record SPHERE."""
    return SPHERE.bind(fmt, id_bits=ID_BITS).pack({"id": case["ids"], "c": case["c"],
                                                   "r": case["r"]})


def mask_bits(mask):
    """(n, k) bool -> (n,) integers, bit j = column j."""
    mask = np.asarray(mask, bool)
    return (mask.astype(np.uint64) << np.arange(mask.shape[1], dtype=np.uint64)).sum(axis=1)


def result_layout(rows, cols):
    return PS_RESULT.bind(id_bits=ID_BITS, rows=rows, cols=cols)


def expected_beats(cases, rows, cols):
    """The model's results, in order, as a structured array of the record PS_RESULT."""
    out = result_layout(rows, cols).zeros(sum(len(c["ids"]) for c in cases))
    out["id"] = np.concatenate([c["ids"] for c in cases])
    out["row_mask"] = np.concatenate([mask_bits(c["row_mask"]) for c in cases])
    out["col_mask"] = np.concatenate([mask_bits(c["col_mask"]) for c in cases])
    return out


def unpack_beat(v, rows, cols):
    """One result payload -> ``(id, row_mask, col_mask)``."""
    return tuple(int(x) for x in result_layout(rows, cols).unpack(v).item())


def check_beats(got, want):
    """``want``: :func:`expected_beats`; ``got``: the same, or ``(id, row_mask, col_mask)``
    tuples."""
    if not isinstance(got, np.ndarray):
        got = np.array([tuple(g) for g in got], want.dtype)
    assert len(got) == len(want), f"{len(got)} results for {len(want)} spheres"
    bad = np.nonzero(got != want)[0]
    assert not bad.size, (f"{bad.size} of {len(want)} results differ; first (index, got (id, "
                          f"row, col), model): "
                          f"{[(int(k), got[k].item(), want[k].item()) for k in bad[:3]]}")


def write_stimulus(path, cases, fmt, idle=0.3, stall=0.3, seed=7):
    """The stimulus file of ``raplas_hdl/sim/tb/plane_sphere.py``: planes and spheres as hex
    words, and the testbench's random idle and stall rates."""
    np.savez(path,
             planes=np.array([[f"{w:x}" for w in c["planes"]] for c in cases]),
             spheres=np.array([[f"{v:x}" for v in sphere_payloads(fmt, c)] for c in cases]),
             idle=idle, stall=stall, seed=seed)

