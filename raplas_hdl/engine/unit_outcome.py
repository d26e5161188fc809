"""The ray-triangle unit's three-valued outcome per pair, as the certified pass calls it.

``unit_outcome(o, oi, d, di, v0, e1, e2, nn, ti, e, m, r, cc) -> (outcome, counts)``:
0 miss, 1 hit, 2 uncertain, and the pair's packed event counts. Until the model's
certified mode exists, the stand-in is rigorous and useless: the conservative mode never
misses a pair that R hits, so its miss is certain and its hit is *uncertain*.
"""

from __future__ import annotations

from numba import njit

from ..fp.numba_cache import drop_stale_cache
from ..model.ray_triangle import pair_exact

drop_stale_cache(__file__)

__all__ = ["unit_outcome", "outcome_constants"]


@njit(cache=True)
def unit_outcome(o, oi, d, di, v0, e1, e2, nn, ti, e, m, r, cc):
    h, _, _, _, _, cnt = pair_exact(o, oi, d, di, v0, e1, e2, nn, ti, e, m, r, True, cc)
    return (2 if h else 0), cnt


def outcome_constants(fmt):
    """The constants table ``cc`` :func:`unit_outcome` takes for ``fmt``."""
    from ..model.conservative import margin_constants, margin_table

    return margin_table(margin_constants(fmt, 1))
