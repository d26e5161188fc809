"""Does a synthesised design fit a device? Checked before nextpnr spends minutes finding out.

:data:`DEVICE_CELLS` is what nextpnr-ecp5 reports as ``available`` for each cell type of the
devices here, package CABGA381 (``--report``'s ``utilization``). :func:`cells_needed` turns
``synth_ecp5``'s resource columns into a lower bound of the cells nextpnr will place: a
``CCU2C`` carry is two ``TRELLIS_COMB``, a ``TRELLIS_DPR16X4`` distributed RAM two
``TRELLIS_COMB`` and one ``TRELLIS_RAMW``; nextpnr may add a few LUTs of its own (route-
through), never fewer. :func:`check_fit` refuses, in one line, a design whose lower bound
already exceeds the device, so a design that fits is never refused.
"""

from __future__ import annotations

__all__ = ["DEVICE_CELLS", "cells_needed", "check_fit"]

#: device -> cell type -> available (nextpnr-ecp5 0.11, CABGA381).
DEVICE_CELLS = {
    "LFE5U-25F": {"TRELLIS_COMB": 24288, "TRELLIS_FF": 24288, "TRELLIS_RAMW": 3036,
                  "MULT18X18D": 28, "ALU54B": 14, "DP16KD": 56, "TRELLIS_IO": 197},
    "LFE5U-45F": {"TRELLIS_COMB": 43848, "TRELLIS_FF": 43848, "TRELLIS_RAMW": 5481,
                  "MULT18X18D": 72, "ALU54B": 36, "DP16KD": 108, "TRELLIS_IO": 245},
    "LFE5U-85F": {"TRELLIS_COMB": 83640, "TRELLIS_FF": 83640, "TRELLIS_RAMW": 10455,
                  "MULT18X18D": 156, "ALU54B": 78, "DP16KD": 208, "TRELLIS_IO": 365},
}

#: The names the refusal uses for nextpnr's cell types.
_NAMES = {"TRELLIS_COMB": "LUT4", "TRELLIS_FF": "FF", "TRELLIS_RAMW": "distributed RAM "
          "write ports", "MULT18X18D": "MULT18X18D", "ALU54B": "ALU54B",
          "DP16KD": "EBR (DP16KD)", "TRELLIS_IO": "I/O pins"}


def cells_needed(counts: dict, io: int = 0) -> dict:
    """nextpnr cells (lower bound) of ``synth_ecp5`` resource columns
    (:func:`.report.synth_counts`) and ``io`` placed I/O pins."""
    return {"TRELLIS_COMB": counts["lut4"] + 2 * counts["carry"] + 2 * counts["dram"],
            "TRELLIS_FF": counts["ff"], "TRELLIS_RAMW": counts["dram"],
            "MULT18X18D": counts["mult18"], "ALU54B": counts["alu54"],
            "DP16KD": counts["ebr"], "TRELLIS_IO": io}


def check_fit(counts: dict, device: str, what: str, io: int = 0) -> dict:
    """The cells needed; ``ValueError`` naming every resource that does not fit."""
    need = cells_needed(counts, io)
    have = DEVICE_CELLS[device]
    over = [f"{need[k]:,} {_NAMES[k]} (the {device} has {have[k]:,})"
            for k in need if need[k] > have[k]]
    if over:
        raise ValueError(f"{what} does not fit: it needs at least " + ", ".join(over))
    return need
