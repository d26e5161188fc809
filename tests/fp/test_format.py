"""The format object: derived constants and the parameter checks of the contract."""

import pytest

from raplas_hdl.fp import FP16, FP24, FP32, FPFormat, parse_format


def test_fp24_constants():
    assert (FP24.width, FP24.bias, FP24.emin, FP24.emax) == (24, 63, -62, 63)
    assert FP24.nan == 0x7F8000
    assert FP24.inf == 0x7F0000
    assert FP24.max_finite == 0x7EFFFF
    assert FP24.max_value == (2 - 2**-16) * 2.0**63
    assert FP24.min_value == 2.0**-62
    assert FP24.one == 63 << 16


@pytest.mark.parametrize("fmt,width", [(FP16, 16), (FP32, 32), (FPFormat(4, 3), 8)])
def test_widths(fmt, width):
    assert fmt.width == width


@pytest.mark.parametrize("args,name", [
    ((1, 3), "exp_bits"), ((12, 3), "exp_bits"), ((4, 0), "man_bits"),
    ((11, 21), "man_bits"), ((8, 24), "man_bits"), ((4.0, 3), "exp_bits"),
    ((4, 3, "rnd"), "rounding"),
])
def test_out_of_range_names_parameter(args, name):
    with pytest.raises(ValueError, match=name):
        FPFormat(*args)


def test_edges_valid():
    assert FPFormat(2, 1).width == 4
    assert FPFormat(11, 20).width == 32
    assert FPFormat(8, 23, "chop").rounding == "chop"


@pytest.mark.parametrize("text,expect", [
    ("FP24", FP24), ("fp24/rne", FP24.with_rounding("rne")),
    ("e4m3-chop", FPFormat(4, 3, "chop")), ("E8M23", FP32),
])
def test_parse_format(text, expect):
    assert parse_format(text) == expect


@pytest.mark.parametrize("text", ["fp23", "e4", "float", "e12m3"])
def test_parse_format_rejects(text):
    with pytest.raises(ValueError):
        parse_format(text)
