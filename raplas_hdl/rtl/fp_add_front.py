"""The front of the FP adder that both its targets share: its ports, and the ``classify`` and
``order`` steps (:mod:`.fp_add`, the fabric adder; :mod:`.fp_add_dsp48`, the Virtex-4 one,
which runs the two as one step).

Below both adders, so that neither imports the other's module for them: :mod:`.fp_add`
builds the DSP48 adder for ``target="virtex4"``, and the DSP48 adder takes its ports and its
first step from here.
"""

from __future__ import annotations

from amaranth.hdl import Mux
from amaranth.lib.wiring import In, Out

from .fp_common import unpack
from .pipeline import wire

__all__ = ["adder_ports", "SPECIALS", "keep", "classify", "order", "classify_and_order"]

#: The special-case bits every step after ``classify`` carries along.
SPECIALS = ("nan", "invalid", "inf")


def adder_ports(width: int) -> dict:
    """The ports of the FP adder (both targets) for ``width``-bit patterns."""
    return {"a": In(width), "b": In(width), "sub": In(1), "i_valid": In(1), "en": In(1),
            "o": Out(width), "flags": Out(3), "o_valid": Out(1)}


def keep(v, *names):
    """The entries ``names`` of a step's values ``v``, passed on unchanged."""
    return {name: v[name] for name in names}


def classify(fmt, m, v):
    """Step ``classify``: unpack both operands (``b``'s sign flipped by ``sub``), their
    magnitude order and both exponent differences, the effective operation and the special
    cases."""
    ua, ub = unpack(fmt, v["a"]), unpack(fmt, v["b"])
    sign_b = ub.sign ^ v["sub"]
    both_inf = ua.is_inf & ub.is_inf
    eff_sub = ua.sign ^ sign_b
    any_nan = ua.is_nan | ub.is_nan
    return {
        "sign_a": ua.sign, "sign_b": sign_b, "exp_a": ua.exp, "exp_b": ub.exp,
        "sig_a": ua.sig, "sig_b": ub.sig,
        # the magnitude order and both exponent differences side by side: ``order``
        # picks one difference, so no subtraction waits for the comparison. The raw
        # patterns are compared (no zeroing of a denormal's fraction in front of the
        # carry chain): they order as the magnitudes do except between two zero-valued
        # patterns, where either order gives the same sum
        "swap": v["b"][:fmt.width - 1] > v["a"][:fmt.width - 1],
        "diff_ab": (ua.exp - ub.exp)[:fmt.exp_bits],
        "diff_ba": (ub.exp - ua.exp)[:fmt.exp_bits],
        "zero_sign": ua.sign & sign_b,
        "eff_sub": eff_sub,
        "nan": any_nan | (both_inf & eff_sub),
        "invalid": ~any_nan & both_inf & eff_sub,
        "inf": ua.is_inf | ub.is_inf,
    }


def order(m, v):
    """Step ``order``: the larger operand ``x`` and the smaller ``y``, and their exponent
    difference."""
    swap = wire(m, v["swap"], "swap")
    return {"sign_x": Mux(swap, v["sign_b"], v["sign_a"]),
            **keep(v, "zero_sign", "eff_sub"),
            "exp_x": Mux(swap, v["exp_b"], v["exp_a"]),
            "sig_x": Mux(swap, v["sig_b"], v["sig_a"]),
            "sig_y": Mux(swap, v["sig_a"], v["sig_b"]),
            "diff": Mux(swap, v["diff_ba"], v["diff_ab"]),
            **keep(v, *SPECIALS)}


def classify_and_order(fmt, m, v):
    """``classify`` then ``order`` in one step (the DSP48 adder's first step)."""
    return order(m, classify(fmt, m, v))
