"""The ray-triangle unit: division-free Moller-Trumbore, fully pipelined, one pair per clock.

The datapath is the golden model's (:mod:`raplas_hdl.model.ray_triangle`) operation for
operation: 33 operations (18 :class:`FPMul`, 15 :class:`FPAdd`), 34 in the conservative
mode, which adds ``w = det - s``. With adder latency ``La`` and multiplier latency ``Lm``
(6 and 4 by default at FP24 ``rtz``, :mod:`.step_delays`) the schedule, in cycles after a
pair is accepted, is:

1. cycle 0: ``T = V0 - O`` (3 subs) and the products ``N*D`` of ``det`` (3 muls) start;
   the margin exponents of the conservative mode are formed from the input exponent
   fields and registered into a delay line.
2. ``La``: ``T`` ready; the products ``N*T`` (t') and ``D*T`` (Q) start.
3. ``Lm .. Lm+2La``: ``det`` summed, ``(n0 d0 + n1 d1) + n2 d2``.
4. ``La+Lm .. 2La+Lm``: ``Q = D x T`` (3 subs); ``t'`` summed by ``3La+Lm``.
5. ``2La+Lm``: the products ``Q*E2`` and ``Q*E1`` start (E1, E2 delayed to meet Q).
6. ``4La+2Lm``: ``u' = neg(Q.E2)`` (a sign flip), ``v' = Q.E1``; ``s = u' + v'`` starts.
7. ``5La+2Lm``: ``s`` ready. Conservative mode: ``w = det - s`` ready at ``6La+2Lm``.
8. decision cycle ``D`` (``5La+2Lm``, ``6La+2Lm``; certified ``6La+2Lm+3``): the
   contract comparisons, each on a register of its own (a comparison and the logic that
   combines them do not fit one 100 MHz cycle on an ECP5 at speed 6: 11.3 ns placed and
   routed).
9. ``D+1``: the hit decision from the registered comparisons, the per-event operation
   counts (summed along the pipeline as the operations finish: one adder per event per
   finishing time) and their OR, the event flags; the IDs from their delay line: all
   registered into the output register at ``D+2``.
10. the output register is written into the output FIFO; ``o`` shows the FIFO's head.

``latency`` (``D + 3``: 41 for the FP24 ``rtz`` defaults (``La`` 6, ``Lm`` 4) in paper
mode, 47 in conservative mode, 50 in certified mode, whose decision waits three cycles
after ``w`` for the last bound, :mod:`.certified_bound`; the paper's unit has 29 stages;
with ``adder="virtex4"`` ``La`` is 7, with ``multiplier="virtex4"`` ``Lm`` is 5 at FP24; one
more with the output FIFO in block RAM, below) is the number of clock edges from the one
that accepts a pair on
``i`` to the one that can take its result from ``o``, with an empty FIFO.

Back-pressure: the pipeline never stalls (its clock enable is tied high). Every accepted
pair will land in the output FIFO, whose depth is ``latency + 1``; a credit counter counts the
pairs accepted and not yet taken from ``o``, and ``i.ready`` is high while it is below the
FIFO depth, so the FIFO can never overflow, and the FIFO's write is not gated by its level
(:class:`~.ram.CreditSyncFIFO`). ``i.ready`` is a function of registers only:
there is no combinational path from ``o.ready`` into the pipeline, to ``i.ready`` or into the
counter's adder (a take from ``o`` is registered and subtracted a cycle later, and
``i.ready`` allows for it, so the handshakes are those of the plain counter). With
``o.ready`` held high the unit takes one pair per clock indefinitely. Results leave in the
order the pairs came in.

**Delay lines in SRL16E.** With ``adder="virtex4"`` the schedule is 45 cycles deep and the
operand, ID and count delay lines hold most of the unit's flip-flops (about 7,200 of 11,200
in Yosys's xc4v count), so the unit is bound by its flip-flops. There (``srl``, by default
16 with the DSP48 adders, else 0) every reset-less delay line of at least 17 stages puts
each run of 16 stages into one Virtex-4 ``SRL16E`` per bit
(:func:`~raplas_hdl.rtl.pipeline.delay`): 16 flip-flops become one LUT site, the last stage
stays a flip-flop. Shorter pieces stay flip-flops: each further ``SRL16E`` trades fewer
flip-flops for one more LUT in a unit whose whole-unit count is already balanced between
the two. The valid bit (reset) always stays in flip-flops. ``srl=0`` gives the
flip-flop-only Verilog of the generic target.

**Output FIFO in block RAM.** The output FIFO of ``D + 4`` words of about 140 bits is, as
Amaranth's ``SyncFIFO`` (cycle for cycle), distributed RAM with an asynchronous read: about
450 ``RAM16X1D`` (900 LUT sites) on Virtex-4. With ``bram_fifo`` (by default with
``adder="virtex4"``) it is a :class:`~.ram.BlockRAMFIFO` instead: a synchronous-read
memory marked for block RAM (four ``RAMB16`` at FP24) whose read register holds the head
word. A result then reaches ``o`` one clock later, so ``latency`` is ``D + 4`` and the
FIFO ``D + 5`` words deep (the credit scheme is unchanged: it still can never overflow, and
one pair a clock still never runs out of credits). The generic target's Verilog is unchanged.
"""

from __future__ import annotations

from amaranth.hdl import Cat, Const, Module, Mux, Signal, signed
from amaranth.lib import data, stream, wiring
from amaranth.lib.wiring import In, Out

from ..fp.format import FLAG_OVERFLOW, FPFormat, check_format
from ..model.modes import MODES, check_rtl_mode
from ..model.conservative import MARGIN_NAMES, margin_constants
from ..model.certified import certified_constants, check_certified_format
from ..model.ordering import tight_bits
from ..model.records import EVENT_COUNT_BITS, PAIR, RT_RESULT, RT_RESULT_CERTIFIED
from .certified_bound import RTL_VARIANTS, BoundOps
from .credit_count import credit_count
from .fp_add import FPAdd, check_adder, default_add_stages, fp_add_latency
from .fp_compare import is_nan, le as fp_le, lt as fp_lt, neg as fp_neg
from .fp_mul import FPMul, check_multiplier, default_mul_stages, fp_mul_latency
from .pipeline import SRL_STAGES, check_srl, delay
from .ram import BlockRAMFIFO, CreditSyncFIFO
from .records import struct_layout

__all__ = ["RayTriangleUnit", "vec3_layout", "input_layout", "output_layout", "MODES",
           "EVENTS", "EVENT_COUNT_BITS"]

#: The events counted per pair (``n_overflow``, ``n_underflow``, ``n_invalid``).
EVENTS = ("overflow", "underflow", "invalid")
EVENT_COUNT_MAX = (1 << EVENT_COUNT_BITS) - 1


def vec3_layout(width: int) -> data.StructLayout:
    """``x``, ``y``, ``z``: three bit patterns, ``x`` in the low bits."""
    return data.StructLayout({"x": width, "y": width, "z": width})


def input_layout(fmt: FPFormat, ray_id_bits: int = 16, tri_id_bits: int = 16):
    """Payload of the unit's input stream: the record :data:`~raplas_hdl.model.records.PAIR`
    (fields from the low bits up)."""
    return struct_layout(PAIR, fmt, ray_id_bits=ray_id_bits, tri_id_bits=tri_id_bits)


def output_layout(fmt: FPFormat, ray_id_bits: int = 16, tri_id_bits: int = 16,
                  outcome: bool = False):
    """Payload of the unit's output stream: the record
    :data:`~raplas_hdl.model.records.RT_RESULT` (fields from the low bits up).

    ``flags`` is the OR of the event flags of the pair's operations; ``n_overflow``,
    ``n_underflow``, ``n_invalid`` count the operations that raised each event. With
    ``outcome`` (the certified mode) the record
    :data:`~raplas_hdl.model.records.RT_RESULT_CERTIFIED`: a 2-bit ``outcome`` field (0 miss,
    1 hit, 2 uncertain) above the record's bits, ``hit`` then ``outcome == 1``, and above it
    ``tight`` (:mod:`raplas_hdl.model.ordering`)."""
    return struct_layout(RT_RESULT_CERTIFIED if outcome else RT_RESULT, fmt,
                         ray_id_bits=ray_id_bits, tri_id_bits=tri_id_bits)


class _Timed:
    """A value and the cycle (after acceptance) at which it is valid."""

    def __init__(self, value, time, start=None, parts=()):
        self.value = value
        self.time = time
        self.start = time if start is None else start    # the operation's start cycle
        self.parts = parts                               # a dot product's p0, p1, p2, p0+p1
        self._delayed = {}


class RayTriangleUnit(wiring.Component):
    """Fully pipelined ray-triangle test, one (ray, triangle) pair per clock.

    Parameters
    ----------
    fmt : FPFormat
        Format and rounding of every operation.
    mode : {"paper", "conservative", "certified"}
        The paper's exact inequalities, the conservative mode's widened tests
        (:mod:`raplas_hdl.model.conservative`; needs ``man_bits >= 8``), or the certified
        hit / miss / uncertain outcome (:mod:`raplas_hdl.model.certified`: 34 operations,
        each with its running error bound in a bound float beside the FP datapath,
        :mod:`.certified_bound`; ``exp_bits <= 9``).
    margin_scale : float
        ``s``, the factor on the derived conservative margin (1 = the derivation); the
        certified mode takes 1 only (the guarantee).
    bound_variant : str
        Certified mode only: the bound variant (``"exp"``, the one with gateware).
    ray_id_bits, tri_id_bits : int
        Widths of the IDs carried with each pair.
    add_stages, mul_stages : int
        Depths of the FP adders and multipliers (default: the format's, 5 and 3 in rtz).
    multiplier : {"generic", "virtex4"}
        Significand multiplier of the 18 :class:`~.fp_mul.FPMul` (``virtex4``: one DSP48
        each at FP24 and one cycle more, so ``latency`` grows by 2).
    adder : {"generic", "virtex4"}
        Target of the 15 (16) :class:`~.fp_add.FPAdd` (``virtex4``: two DSP48 each,
        latency 7 whatever ``add_stages``; the schedule follows, see the module docstring).
    srl : int or None
        Fewest stages of a delay-line piece put into an ``SRL16E`` (0: flip-flops only; 1 to
        16, see :func:`~raplas_hdl.rtl.pipeline.srl_split`); ``None`` (the default): 16
        with ``adder="virtex4"``, else 0 (see the module docstring).
    bram_fifo : bool or None
        Build the output FIFO in block RAM (:class:`~.ram.BlockRAMFIFO`: a synchronous read,
        so ``latency`` and ``fifo_depth`` grow by 1) instead of LUT RAM; ``None`` (the
        default): with ``adder="virtex4"`` (see the module docstring).

    Attributes
    ----------
    i : In(stream.Signature(input_layout(...)))
        Pairs: ``ray_id``, ``tri_id``, ``o``, ``d``, ``v0``, ``e1``, ``e2``, ``n``.
    o : Out(stream.Signature(output_layout(...)))
        Results: ``ray_id``, ``tri_id``, ``hit``, ``t``, ``u``, ``v``, ``det`` (t', u', v',
        det as bit patterns), ``flags`` (OR of the event flags of the pair's operations) and
        ``n_overflow``, ``n_underflow``, ``n_invalid`` (how many of the pair's operations
        raised each event, :data:`EVENT_COUNT_BITS` bits each); certified mode: also
        ``outcome`` (0 miss, 1 hit, 2 uncertain; ``hit = outcome == 1``) and ``tight`` (a hit
        whose t' and det are each at least ``2**tight_bits`` times their bounds:
        :mod:`raplas_hdl.model.ordering`).

    Raises
    ------
    ValueError
        For a bad format, mode, scale, ID width, multiplier, adder or ``srl``.
    """

    def __init__(self, fmt, *, mode: str = "paper", margin_scale: float = 1,
                 ray_id_bits: int = 16, tri_id_bits: int = 16,
                 add_stages: int | None = None, mul_stages: int | None = None,
                 multiplier: str = "generic",
                 adder: str = "generic", bound_variant: str = "exp", srl=None,
                 bram_fifo=None):
        check_format(fmt)
        check_rtl_mode(mode)
        self._bound_k = None
        if mode == "certified":
            check_certified_format(fmt)
            if bound_variant not in RTL_VARIANTS:
                raise ValueError(f"the RTL's bound variants are {', '.join(RTL_VARIANTS)}, "
                                 f"not {bound_variant!r}")
            if margin_scale != 1:
                raise ValueError(f"the certified RTL takes margin_scale 1 only, "
                                 f"not {margin_scale!r}")
            self._bound_k = int(certified_constants(fmt, 1.0, bound_variant)[2])
        self._bound_variant = bound_variant if mode == "certified" else None
        self._dec = None
        for name, bits in (("ray_id_bits", ray_id_bits), ("tri_id_bits", tri_id_bits)):
            if not isinstance(bits, int) or isinstance(bits, bool) or not 1 <= bits <= 64:
                raise ValueError(f"{name} must be an integer from 1 to 64, not {bits!r}")
        self._fmt = fmt
        self._mode = mode
        self._consts = margin_constants(fmt, margin_scale) if mode == "conservative" else None
        self._margin_scale = float(margin_scale)
        self._ray_id_bits = ray_id_bits
        self._tri_id_bits = tri_id_bits
        if add_stages is None:
            add_stages = default_add_stages(fmt)
        if mul_stages is None:
            mul_stages = default_mul_stages(fmt)
        for name, st in (("add_stages", add_stages), ("mul_stages", mul_stages)):
            if not isinstance(st, int) or isinstance(st, bool) or st < 1:
                raise ValueError(f"{name} must be a positive integer, not {st!r}")
        self._add_stages = add_stages
        self._mul_stages = mul_stages
        self._multiplier = check_multiplier(multiplier)
        self._adder = check_adder(adder)
        if srl is None:
            srl = SRL_STAGES if self._adder == "virtex4" else 0
        self._srl = check_srl(srl)
        if bram_fifo is None:
            bram_fifo = self._adder == "virtex4"
        if not isinstance(bram_fifo, bool):
            raise ValueError(f"bram_fifo must be True, False or None, not {bram_fifo!r}")
        self._bram_fifo = bram_fifo
        # the FP units' latencies (checked against the built units in elaborate)
        self._la = fp_add_latency(fmt, add_stages, adder)
        self._lm = fp_mul_latency(fmt, mul_stages, multiplier)
        super().__init__({
            "i": In(stream.Signature(input_layout(fmt, ray_id_bits, tri_id_bits))),
            "o": Out(stream.Signature(output_layout(fmt, ray_id_bits, tri_id_bits,
                                                    outcome=mode == "certified"))),
        })

    @property
    def fmt(self) -> FPFormat:
        return self._fmt

    @property
    def mode(self) -> str:
        return self._mode

    @property
    def margin_scale(self) -> float:
        return self._margin_scale

    @property
    def multiplier(self) -> str:
        return self._multiplier

    @property
    def adder(self) -> str:
        return self._adder

    @property
    def srl(self) -> int:
        """Fewest stages of a delay-line piece in an ``SRL16E`` (0: flip-flops only)."""
        return self._srl

    @property
    def bram_fifo(self) -> bool:
        """The output FIFO is in block RAM (one more cycle of latency and depth)."""
        return self._bram_fifo

    @property
    def bound_variant(self):
        return self._bound_variant

    @property
    def decision_cycle(self) -> int:
        """Cycle (after acceptance) of the combinational hit decision (certified mode: when
        the last bound is ready, from a trial build of the schedule)."""
        d = 5 * self._la + 2 * self._lm
        if self._mode == "certified":
            if self._dec is None:
                self._dec = self._schedule_end()
            return self._dec
        return d + self._la if self._mode == "conservative" else d

    @property
    def fifo_depth(self) -> int:
        """Words of the output FIFO: ``latency + 1``, so that one pair a clock never runs
        out of credits."""
        return self.latency + 1

    @property
    def latency(self) -> int:
        """Clock edges from accepting a pair on ``i`` to taking its result from ``o``
        (FIFO empty, ``o.ready`` high)."""
        return self.decision_cycle + 3 + self._bram_fifo

    # -- helpers -------------------------------------------------------------------------
    def _at(self, m, tv: _Timed, time: int):
        if time < tv.time:
            raise AssertionError("schedule error: value used before it is ready")
        if time == tv.time:
            return tv.value
        if time not in tv._delayed:
            self._n_delay += 1
            tv._delayed[time] = delay(m, tv.value, time - tv.time,
                                      name=f"dl{self._n_delay}", srl=self._srl)
        return tv._delayed[time]

    def _new_op(self, kind):
        """The unit of one operation (``mul`` or ``add``): the proofs by composition
        (:mod:`raplas_hdl.formal.composition`) put a stand-in of the same ports and latency
        in its place."""
        if kind == "mul":
            return FPMul(self._fmt, self._mul_stages, self._multiplier)
        return FPAdd(self._fmt, self._add_stages, self._adder)

    def _op(self, m, kind, a: _Timed, b: _Timed, sub=False):
        t = max(a.time, b.time)
        unit = self._new_op(kind)
        self._n_ops += 1
        m.submodules[f"{kind}{self._n_ops}"] = unit
        m.d.comb += [unit.a.eq(self._at(m, a, t)), unit.b.eq(self._at(m, b, t)),
                     unit.i_valid.eq(1), unit.en.eq(1)]
        if kind != "mul":
            m.d.comb += unit.sub.eq(int(sub))
        if unit.latency != (self._lm if kind == "mul" else self._la):
            raise AssertionError(f"{kind} latency {unit.latency} differs from the schedule's")
        if self._trial:
            unit._MustUse__silence = True        # a trial build is never elaborated
        out = _Timed(unit.o, t + unit.latency, start=t)
        self._flag_taps.append((unit.flags, out.time))
        return out

    def _dot(self, m, a, b):
        p = [self._op(m, "mul", x, y) for x, y in zip(a, b)]
        s01 = self._op(m, "add", p[0], p[1])
        out = self._op(m, "add", s01, p[2])
        out.parts = (*p, s01)
        return out

    # -- the certified mode's bounds (model.certified, operand order as there) -----------
    def _breg(self, m, value, time, layout=None):
        """Register a bound value (or, given its ``layout``, a half-way record) computed at
        ``time``."""
        self._n_bound += 1
        r = Signal(self._bo.width if layout is None else layout, name=f"bound{self._n_bound}")
        m.d.sync += r.eq(value)
        return _Timed(r, time + 1)

    def _bv(self, m, tv, time):
        return self._bo.view(self._at(m, tv, time))

    def _bop(self, m, kind, a, b):
        """``a + b`` or ``a * b`` of two registered bounds, in two stages: each half of the
        operator (:mod:`.certified_bound`) into a register of its own."""
        ops = self._bo
        t = max(a.time, b.time)
        av, bv = self._bv(m, a, t), self._bv(m, b, t)
        if kind == "add":
            first, layout, second = ops.align(m, av, bv), ops.align_layout, ops.add_sum
        else:
            first, layout, second = (ops.mul_product(m, av, bv), ops.product_layout,
                                     ops.mul_round)
        mid = self._breg(m, first, t, layout)
        return self._breg(m, second(m, mid.value), t + 1)

    def _upper(self, m, x):
        """``U(x)`` of a pattern, registered."""
        return self._breg(m, self._bo.upper(m, x.value), x.time)

    def _bound_mul(self, m, x, bx, y, by, p):
        """Bound of ``p = x*y``: ``U(x) B_y + (U(y) + B_y) B_x + rnd`` (``by`` None: y
        exact, then ``U(y) B_x + rnd``)."""
        ops = self._bo
        if by is None:
            acc = self._bop(m, "mul", self._upper(m, y), bx)
        else:
            t1 = self._bop(m, "mul", self._upper(m, x), by)
            t2 = self._bop(m, "mul", self._bop(m, "add", self._upper(m, y), by), bx)
            acc = self._bop(m, "add", t1, t2)
        return self._bop(m, "add", acc, self._breg(m, ops.rnd_mul(m, p.value), p.time))

    def _bound_add(self, m, a, ba, b, bb, s):
        """Bound of ``s = a + b`` (or ``a - b``): ``B_a + B_b + rnd`` (``bb`` None: b
        exact)."""
        ops = self._bo
        acc = ba if bb is None else self._bop(m, "add", ba, bb)
        opnd = ops.rnd_add_operands(m, self._at(m, a, s.start), self._at(m, b, s.start))
        opnd = _Timed(opnd.as_value(), s.start)
        top = ops.rnd_add_top(m, data.View(ops.operand_layout, self._at(m, opnd, s.time)),
                              s.value)
        tf = s.time
        if ops.rnd_add_stages == 2:
            top = self._breg(m, top, tf, ops.top_layout).value
            tf += 1
        return self._bop(m, "add", acc, self._breg(m, ops.rnd_add_finish(m, top), tf))

    def _bound_dot(self, m, x, bx, y, by, dot):
        """Bound of the dot product ``dot`` of ``x`` and ``y`` (``by`` None: y exact)."""
        p0, p1, p2, s01 = dot.parts
        q = [self._bound_mul(m, x[c], bx[c], y[c], None if by is None else by[c], pc)
             for c, pc in enumerate((p0, p1, p2))]
        g01 = self._bound_add(m, p0, q[0], p1, q[1], s01)
        return self._bound_add(m, s01, g01, p2, q[2], dot)

    def _neg(self, m, x: _Timed):
        r = Signal(self._fmt.width, name=f"neg{self._n_ops}")
        m.d.comb += r.eq(fp_neg(x.value, self._fmt))
        return _Timed(r, x.time)

    def _margin_fields(self, m, p):
        """Exponent fields of the five margins (plus an infinity bit), from the inputs."""
        f = self._fmt
        c = self._consts
        ys = signed(f.exp_bits + 5)

        def maxfield(vec):
            fields = [vec[k][f.man_bits:f.width - 1] for k in ("x", "y", "z")]
            a = Mux(fields[0] > fields[1], fields[0], fields[1])
            r = Signal(f.exp_bits)
            m.d.comb += r.eq(Mux(a > fields[2], a, fields[2]))
            return r

        def smax(a, b):
            r = Signal(ys)
            m.d.comb += r.eq(Mux(a > b, a, b))
            return r

        lv = {}
        for name in ("o", "d", "v0", "e1", "e2", "n"):
            sig = Signal(ys, name=f"L_{name}")
            m.d.comb += sig.eq(maxfield(getattr(p, name)) - f.bias + 1)
            lv[name] = sig
        lvo = smax(lv["v0"], lv["o"])
        le12 = smax(lv["e1"], lv["e2"])
        y = {"det": lv["n"] + lv["d"], "t": lv["n"] + lvo, "u": lv["d"] + lvo + lv["e2"],
             "v": lv["d"] + lvo + lv["e1"], "w": lv["d"] + smax(lv["n"], le12 + lvo)}
        out = {}
        for name in MARGIN_NAMES:
            yy = Signal(ys, name=f"Y_{name}")
            m.d.comb += yy.eq(y[name])
            field = Signal(signed(f.exp_bits + 6), name=f"mfield_{name}")
            m.d.comb += field.eq(c.k_field[name] + Mux(yy > c.floor[name], yy, c.floor[name]))
            bits = Signal(f.width, name=f"margin_{name}")
            m.d.comb += bits.eq(Mux(field >= f.exp_max_field, f.inf,
                                    Mux(field < 1, Const(1 << f.man_bits, f.width)
                                        | c.k_frac[name],
                                        (field[:f.exp_bits] << f.man_bits) | c.k_frac[name])))
            out[name] = bits
        return out

    # -- elaboration ---------------------------------------------------------------------
    def _datapath(self, m, p):
        """The operations (and, in certified mode, their bounds) on the payload ``p``;
        returns ``{name: _Timed}`` of det, t', u', v', s (and w), bounds as ``g_<name>``."""
        self._n_ops = 0
        self._n_delay = 0
        self._n_bound = 0
        self._flag_taps = []
        vec = {name: [_Timed(getattr(p, name)[k], 0) for k in ("x", "y", "z")]
               for name in ("o", "d", "v0", "e1", "e2", "n")}
        o, d, v0 = vec["o"], vec["d"], vec["v0"]
        e1, e2, n = vec["e1"], vec["e2"], vec["n"]

        # 1-3: T = V0 - O
        t = [self._op(m, "add", v0[k], o[k], sub=True) for k in range(3)]
        # 4-8: det = N.D; 9-13: t' = N.T
        det = self._dot(m, n, d)
        tp = self._dot(m, n, t)
        # 14-22: Q = D x T, q_c = p_c - r_c
        prods = [(self._op(m, "mul", d[a], t[b]), self._op(m, "mul", d[b], t[a]))
                 for a, b in ((1, 2), (2, 0), (0, 1))]
        q = [self._op(m, "add", pc, rc, sub=True) for pc, rc in prods]
        # 23-27: u' = neg(Q.E2); 28-32: v' = Q.E1; 33: s = u' + v'
        qe2 = self._dot(m, q, e2)
        up = self._neg(m, qe2)
        vp = self._dot(m, q, e1)
        s = self._op(m, "add", up, vp)
        res = {"det": det, "t": tp, "u": up, "v": vp, "s": s}
        if self._mode != "paper":
            res["w"] = self._op(m, "add", det, s, sub=True)      # 34: w = det - s
        if self._mode != "certified":
            return res

        ops = self._bo = BoundOps(self._fmt, self._bound_k)
        w = res["w"]

        def inputs(vals, slack):
            return [self._breg(m, ops.input_bound(m, x.value, slack), 0) for x in vals]

        bv, b1, b2, bn = inputs(v0, False), inputs(e1, True), inputs(e2, True), inputs(n, True)
        gt_ = [self._bound_add(m, v0[c], bv[c], o[c], None, t[c]) for c in range(3)]
        g = {"det": self._bound_dot(m, n, bn, d, None, det),
             "t": self._bound_dot(m, n, bn, t, gt_, tp)}
        gq = []
        for (a, b), (pc, rc), qc in zip(((1, 2), (2, 0), (0, 1)), prods, q):
            gp = self._bound_mul(m, t[b], gt_[b], d[a], None, pc)
            gr = self._bound_mul(m, t[a], gt_[a], d[b], None, rc)
            gq.append(self._bound_add(m, pc, gp, rc, gr, qc))
        g["u"] = self._bound_dot(m, e2, b2, q, gq, qe2)
        g["v"] = self._bound_dot(m, e1, b1, q, gq, vp)
        gs = self._bound_add(m, up, g["u"], vp, g["v"], s)
        g["w"] = self._bound_add(m, det, g["det"], s, gs, w)
        res.update({f"g_{k}": v for k, v in g.items()})
        return res

    def _schedule_end(self) -> int:
        """The certified mode's decision cycle: when the last result and bound are ready
        (a trial build of the datapath into a module that is thrown away)."""
        self._trial = True
        try:
            p = Signal(input_layout(self._fmt, self._ray_id_bits, self._tri_id_bits))
            trial = Module()
            trial._MustUse__silence = True
            res = self._datapath(trial, p)
        finally:
            self._trial = False
        return max(tv.time for tv in res.values())

    _trial = False

    def elaborate(self, platform):
        m = Module()
        f = self._fmt
        dec = self.decision_cycle
        p = self.i.payload
        res = self._datapath(m, p)
        det, tp, up, vp, s = (res[k] for k in ("det", "t", "u", "v", "s"))
        assert max(tv.time for tv in res.values()) <= dec

        # the FIFO's writer holds a credit for every word (below), so its write enable is
        # the output register's valid bit alone, not gated by the FIFO's level
        width = len(self.o.payload.as_value())
        fifo = m.submodules.fifo = (
            BlockRAMFIFO(width=width, depth=self.fifo_depth, credits=True) if self._bram_fifo
            else CreditSyncFIFO(width=width, depth=self.fifo_depth))
        # a credit for every accepted pair until it is taken from ``o`` (:mod:`.credit_count`)
        accept = credit_count(m, valid=self.i.valid, ready=self.i.ready,
                              take=fifo.r_rdy & self.o.ready, depth=self.fifo_depth)
        m.d.comb += [
            self.o.valid.eq(fifo.r_rdy),
            fifo.r_en.eq(self.o.ready),
            self.o.payload.eq(fifo.r_data),
        ]
        # event counts: per event, the number of the pair's operations that raised it,
        # summed along the pipeline as the operations finish (each running sum only as
        # wide as the operations finished so far need); the OR flags follow from them
        counts, acc_t, done = None, 0, 0
        for time in sorted({tm for _, tm in self._flag_taps}):
            here = [fl for fl, tm in self._flag_taps if tm == time]
            done += len(here)
            new_counts = []
            for b, ev in enumerate(EVENTS):
                prev = (Const(0, 1) if counts is None
                        else delay(m, counts[b], time - acc_t, name=f"n{ev[:3]}{time}",
                                   srl=self._srl))
                c = Signal(range(done + 1), name=f"n_{ev}_at_{time}")
                m.d.comb += c.eq(sum((fl[b] for fl in here), prev))
                new_counts.append(c)
            counts, acc_t = new_counts, time
        if done > EVENT_COUNT_MAX:
            raise AssertionError(f"{done} operations do not fit the event counts")
        dec1 = dec + 1
        counts = [delay(m, c, dec1 - acc_t, name=f"n{ev[:3]}dec", srl=self._srl)
                  for c, ev in zip(counts, EVENTS)]
        flags = Signal(3, name="flags")
        m.d.comb += flags.eq(Cat(*(c != 0 for c in counts)))

        # the decision in two cycles: every comparison at cycle `dec`, on a register of its
        # own (`reg`); their combination at `dec + 1`, into the output register
        def reg(value, name):
            r = Signal(name=name)
            m.d.sync += r.eq(value)
            return r

        zero = Const(0, f.width)
        det_d, tp_d = self._at(m, det, dec), self._at(m, tp, dec)
        up_d, vp_d, s_d = self._at(m, up, dec), self._at(m, vp, dec), self._at(m, s, dec)
        hit = Signal()
        outcome = Signal(2)
        tight = Signal()
        if self._mode == "certified":
            ops = self._bo
            emf = f.exp_max_field
            vals = {k: self._at(m, res[k], dec) for k in ("det", "t", "u", "v", "w")}
            special = reg(Cat(*(v[f.man_bits:f.width - 1] == emf
                                for v in vals.values())).any(), "special")
            cl = {k: ops.classify(v, self._bv(m, res[f"g_{k}"], dec)) for k, v in vals.items()}
            ge, gt, le, lt = ({k: reg(c[i], f"{('ge', 'gt', 'le', 'lt')[i]}_{k}")
                               for k, c in cl.items()} for i in range(4))
            names = ("u", "v", "w", "t")
            chit = ((gt["det"] & Cat(*(ge[k] for k in names)).all())
                    | (lt["det"] & Cat(*(le[k] for k in names)).all()))
            cmiss = ((le["det"] | Cat(*(lt[k] for k in names)).any())
                     & (ge["det"] | Cat(*(gt[k] for k in names)).any()))
            # tight: t' and det each known to 2**-q (the reducer orders only those hits)
            q = tight_bits(f)
            tight_k = {k: reg(ops.tight(vals[k], self._bv(m, res[f"g_{k}"], dec), q),
                              f"tight_{k}") for k in ("t", "det")}
            m.d.comb += [
                outcome.eq(Mux(special | (flags & FLAG_OVERFLOW).any(), 2,
                               Mux(chit, 1, Mux(cmiss, 0, 2)))),
                hit.eq(outcome == 1),
                tight.eq(hit & tight_k["t"] & tight_k["det"]),
            ]
        elif self._mode == "paper":
            le, lt = (lambda a, b, n: reg(fp_le(m, a, b, f), n),
                      lambda a, b, n: reg(fp_lt(m, a, b, f), n))
            pos = (le(zero, up_d, "pos_u") & le(zero, vp_d, "pos_v") & le(s_d, det_d, "pos_s")
                   & le(zero, tp_d, "pos_t"))
            neg = (le(up_d, zero, "neg_u") & le(vp_d, zero, "neg_v") & le(det_d, s_d, "neg_s")
                   & le(tp_d, zero, "neg_t"))
            m.d.comb += hit.eq((lt(zero, det_d, "pos_det") & pos)
                               | (lt(det_d, zero, "neg_det") & neg))
        else:
            mg = self._margin_fields(m, p)
            mg = {k: delay(m, v, dec, name=f"mg_{k}", srl=self._srl) for k, v in mg.items()}
            w_d = self._at(m, res["w"], dec)
            sign = f.sign_bit

            def le(a, b, n):
                return reg(fp_le(m, a, b, f), n)

            bad = (reg(is_nan(det_d, f) | is_nan(tp_d, f) | is_nan(up_d, f) | is_nan(vp_d, f)
                       | is_nan(w_d, f), "nan") | (flags & FLAG_OVERFLOW).any())
            pos = (le(mg["u"] ^ sign, up_d, "pos_u") & le(mg["v"] ^ sign, vp_d, "pos_v")
                   & le(mg["w"] ^ sign, w_d, "pos_w") & le(mg["t"] ^ sign, tp_d, "pos_t"))
            neg = (le(up_d, mg["u"], "neg_u") & le(vp_d, mg["v"], "neg_v")
                   & le(w_d, mg["w"], "neg_w") & le(tp_d, mg["t"], "neg_t"))
            m.d.comb += hit.eq(bad | (le(mg["det"] ^ sign, det_d, "pos_det") & pos)
                               | (le(det_d, mg["det"], "neg_det") & neg))

        valid_d = delay(m, accept, dec1, name="valid", reset_less=False)
        ids_d = delay(m, p.ray_id, dec1, name="ray_id", srl=self._srl)
        tid_d = delay(m, p.tri_id, dec1, name="tri_id", srl=self._srl)
        det_d, tp_d, up_d, vp_d = (delay(m, v, 1, name=f"{n}_dec1") for v, n in
                                   ((det_d, "det"), (tp_d, "t"), (up_d, "u"), (vp_d, "v")))

        # output register (cycle dec + 2), then the FIFO
        out = Signal(output_layout(f, self._ray_id_bits, self._tri_id_bits,
                                   outcome=self._mode == "certified"))
        out_valid = Signal()
        m.d.sync += [
            out.ray_id.eq(ids_d), out.tri_id.eq(tid_d), out.hit.eq(hit),
            out.t.eq(tp_d), out.u.eq(up_d), out.v.eq(vp_d), out.det.eq(det_d),
            out.flags.eq(flags), out.n_overflow.eq(counts[0]),
            out.n_underflow.eq(counts[1]), out.n_invalid.eq(counts[2]), out_valid.eq(valid_d),
        ]
        if self._mode == "certified":
            m.d.sync += [out.outcome.eq(outcome), out.tight.eq(tight)]
        m.d.comb += [fifo.w_data.eq(out.as_value()), fifo.w_en.eq(out_valid)]
        return m
