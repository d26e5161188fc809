"""The modes of the ray-triangle unit, defined once for the model, the RTL, the host, the
campaigns and the CLI.

- ``paper``: the paper's exact inequalities on the unit's arithmetic;
- ``conservative``: every test widened by a certified margin
  (:mod:`raplas_hdl.model.conservative`), so no pair the exact test hits is missed;
- ``certified``: a three-valued outcome per pair, hit / miss / uncertain, each hit and miss
  guaranteed against the exact test by running error bounds
  (:mod:`raplas_hdl.model.certified`); the host resolves the uncertain pairs.
"""

from __future__ import annotations

__all__ = ["MODES", "check_mode"]

MODES = ("paper", "conservative", "certified")


def check_mode(mode) -> str:
    """``mode`` if it is one of :data:`MODES`.

    Raises
    ------
    ValueError
        Naming the mode and the choices.
    """
    if mode not in MODES:
        raise ValueError(f"mode must be one of {', '.join(MODES)}, not {mode!r}")
    return mode
