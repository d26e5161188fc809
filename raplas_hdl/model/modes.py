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

__all__ = ["MODES", "RTL_MODES", "check_mode", "check_rtl_mode"]

MODES = ("paper", "conservative", "certified")
#: The modes the RTL implements (the ray-triangle unit, and the intersection unit: in
#: certified mode its result records carry the pair's ``outcome``).
RTL_MODES = ("paper", "conservative", "certified")


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


def check_rtl_mode(mode) -> str:
    """``mode`` if the RTL implements it (:data:`RTL_MODES`).

    Raises
    ------
    ValueError
        For an unknown mode, or one the RTL does not have yet, naming it.
    """
    check_mode(mode)
    if mode not in RTL_MODES:
        raise ValueError(f"the RTL has no {mode} mode yet (RTL modes: {', '.join(RTL_MODES)}); "
                         f"it exists in the golden model only")
    return mode
