"""The ray-triangle unit's checks shared by the model and RTL tests: the six operand names,
the PAIR / RT_RESULT payloads, the golden model's expected fields and their comparison
(``rtl/test_ray_triangle_amaranth.py``, ``rtl/test_ray_triangle_cocotb.py``,
``rtl/test_dsp48_target.py``), and pairs with known event counts
(``model/test_ray_triangle.py``, ``rtl/test_ray_triangle_amaranth.py``,
``rtl/test_ray_triangle_certified.py``)."""

import numpy as np

from raplas_hdl.fp import model as fpm
from raplas_hdl.model.ray_triangle import EVENTS, intersect
from raplas_hdl.model.records import PAIR, RT_RESULT

NAMES = ("o", "d", "v0", "e1", "e2", "n")


def pack_inputs(fmt, vec, ray_ids, tri_ids, ray_id_bits=16, tri_id_bits=16):
    """Input payloads (Python ints) of the record PAIR."""
    layout = PAIR.bind(fmt, ray_id_bits=ray_id_bits, tri_id_bits=tri_id_bits)
    return layout.pack({"ray_id": ray_ids, "tri_id": tri_ids, **{k: vec[k] for k in NAMES}})


def unpack_outputs(fmt, values, ray_id_bits=16, tri_id_bits=16):
    """Output payloads -> {field: uint64 array} of the record RT_RESULT."""
    out = RT_RESULT.bind(fmt, ray_id_bits=ray_id_bits, tri_id_bits=tri_id_bits).unpack(values)
    return {k: out[k].astype(np.uint64) for k in RT_RESULT.names}


def expected(fmt, vec, ray_ids, tri_ids, mode, margin_scale=1.0):
    ref = intersect(*(vec[k] for k in NAMES), fmt, mode=mode, margin_scale=margin_scale)
    return {"ray_id": np.asarray(ray_ids, np.uint64), "tri_id": np.asarray(tri_ids, np.uint64),
            "hit": ref["hit"].astype(np.uint64), "t": ref["t"].astype(np.uint64),
            "u": ref["u"].astype(np.uint64), "v": ref["v"].astype(np.uint64),
            "det": ref["det"].astype(np.uint64), "flags": ref["flags"].astype(np.uint64),
            **{f"n_{ev}": ref["event_counts"][:, k].astype(np.uint64)
               for k, ev in enumerate(EVENTS)}}


def compare(got, exp):
    n = len(exp["hit"])
    assert all(len(got[k]) == n for k in exp), "results lost or doubled"
    bad = {k: int((got[k] != exp[k]).sum()) for k in exp}
    assert not any(bad.values()), f"mismatching fields (count per field): {bad}"



def event_pairs(fmt):
    """Pairs with known operation event counts ``(overflow, underflow, invalid)``.

    With ``O = V0 = 0`` and ``E1 = E2 = 0`` only ``det = N.D`` and the cross products
    ``Q = D x T`` can raise events (``T = 0``):

    - ``N = D = (b, b, b)``, ``b = 2**(emax // 2 + 2)``: the three products of det
      overflow; with ``rtz`` and ``chop`` they saturate to the largest finite value and
      both sums overflow again (5), with ``rne`` they are infinities that add without an
      event (3);
    - ``N = D = (s, s, s)``, ``s = 2**((emin - 2) // 2)``: the three products of det
      underflow (flushed to zero); their sums are exact zeros: 3;
    - ``D = (inf, inf, 1)``, ``N = (0, 0, 1)``: ``0 * inf`` twice in det, and ``inf * 0``
      in 4 of the 6 products of ``D x T``; the NaNs they make raise nothing further: 6;
    - an ordinary hit: nothing.

    Returns the six operand arrays (``o, d, v0, e1, e2, n``) and the expected counts.
    """
    big = 2.0 ** (fmt.emax // 2 + 2)
    small = 2.0 ** ((fmt.emin - 2) // 2)
    inf = np.inf
    rows = [  # o, d, v0, e1, e2, n
        ([0, 0, 0], [big] * 3, [0, 0, 0], [0, 0, 0], [0, 0, 0], [big] * 3),
        ([0, 0, 0], [small] * 3, [0, 0, 0], [0, 0, 0], [0, 0, 0], [small] * 3),
        ([0, 0, 0], [inf, inf, 1], [0, 0, 0], [0, 0, 0], [0, 0, 0], [0, 0, 1]),
        ([0.25, 0.25, 1], [0, 0, -1], [0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]),
    ]
    ops = [fpm.encode(np.array([r[k] for r in rows], float), fmt) for k in range(6)]
    counts = np.array([[3 if fmt.rounding == "rne" else 5, 0, 0], [0, 3, 0], [0, 0, 6],
                       [0, 0, 0]], np.uint8)
    return ops, counts

