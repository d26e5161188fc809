"""Plane-sphere tester and the tester array with its decoder (paper fig. 6, left half).

:class:`PlaneSphereTester` computes ``d = n . C + p`` for one sphere per clock and flags
whether the sphere may touch the plane: ``flag = NOT(|d| > r')`` (a NaN keeps the
sphere). Its stages, numbered for the paper's FP units (multiplier 3, adder 4 stages: 12 in
all); this project's FP24 ``rtz`` defaults are cut by placed-and-routed delays (multiplier 4,
adder 6 stages: 17 in all, one more with ``multiplier="virtex4"``), and the stage numbers
below shift accordingly:

1. stages 1-3, three :class:`~.fp_mul.FPMul`: ``mx = n.x*C.x``, ``my = n.y*C.y``,
   ``mz = n.z*C.z``; the plane comes from the tester's plane registers (slot ``sel``);
   ``r'`` and ``sel`` ride along in shift registers.
2. stages 4-7, two :class:`~.fp_add.FPAdd`: ``s1 = mx + my``, ``s2 = mz + p`` (``p`` of
   the slot that ``sel`` named, read when the products arrive).
3. stages 8-11, one :class:`~.fp_add.FPAdd`: ``d = s1 + s2``.
4. stage 12, the comparator: ``flag = NOT lt(r', |d|)`` (ordered: NaN gives "keep";
   denormal patterns are zero), registered with ``o_valid``.

:class:`PlaneSphereArray` broadcasts each sphere of its input stream to ``testers``
testers. A bundle of ``P = rows + cols`` planes (IDs: rows first, then columns) needs
``G = ceil(P / testers)`` passes: in pass ``g`` tester ``k`` tests plane ``g*testers + k``
(each tester holds ``G`` planes and ``sel = g`` picks one). The array's stages:

1. issue register: the accepted sphere, held for ``G`` cycles (pass ``0 .. G-1``; it loads
   whenever it may take one, and is used only once accepted); the input is ready when the
   last pass is being issued (or nothing is) *and* there is room in the output FIFO for
   every sphere in flight;
2. ``latency`` of the testers (12), with the sphere ID and pass number in a shift register;
3. decoder: passes ``0 .. G-2`` are collected in a mask register; the last pass writes
   (ID, row mask, column mask) into the output FIFO;
4. output FIFO (``SyncFIFO``, first word falls through), depth ``latency + 2``.

Back-pressure: the pipeline never stalls (``en`` = 1). A counter ``occupied`` holds the
spheres accepted and not yet read from the FIFO; ``i.ready`` needs
``occupied < fifo_depth``, so the FIFO can always take whatever is in flight, and
``o.ready`` reaches ``i.ready`` only through registers (the FIFO's level, the read
registered as ``took``, and the comparisons of ``occupied`` formed a cycle ahead): no
combinational path from ``o.ready`` into the pipeline.

Plane writes: ``pw_en`` writes ``pw_data`` to plane ``pw_addr`` at the clock edge. The
**drain rule**: write planes only while ``idle`` is 1 (no sphere accepted and not yet in
the FIFO); stop offering spheres, wait for ``idle``, write all ``rows + cols`` planes,
then offer the next bundle's spheres. Results already in the FIFO are not affected. A
write while not idle is not blocked, but the spheres in flight then see a mix of planes.
"""

from __future__ import annotations

import math

from amaranth.hdl import Cat, Module, Mux, Signal
from amaranth.lib import data, stream, wiring
from amaranth.lib.fifo import SyncFIFO
from amaranth.lib.wiring import In, Out

from ..fp import FP24
from ..model.records import PLANE, PS_RESULT, SPHERE
from .fp_add import FPAdd, check_adder, default_add_stages, fp_add_latency
from .fp_common import check_format
from .fp_mul import FPMul, check_multiplier, default_mul_stages, fp_mul_latency
from .pipeline import delay
from .records import struct_layout

__all__ = ["PlaneSphereTester", "PlaneSphereArray", "build_plane_sphere", "plane_layout",
           "sphere_layout", "result_layout"]


def vec3_layout(width: int) -> data.StructLayout:
    """``x | y << W | z << 2W``."""
    return data.StructLayout({"x": width, "y": width, "z": width})


def plane_layout(fmt) -> data.StructLayout:
    """Plane word, the record :data:`~raplas_hdl.model.records.PLANE`:
    ``n.x | n.y << W | n.z << 2W | p << 3W`` (``4W`` bits)."""
    return struct_layout(PLANE, fmt)


def sphere_layout(fmt, id_bits: int) -> data.StructLayout:
    """Sphere payload, the record :data:`~raplas_hdl.model.records.SPHERE`: ``id``
    (``id_bits``), ``c`` (x, y, z, ``3W``), ``r`` (``r'``, ``W``), packed LSB first in that
    order."""
    return struct_layout(SPHERE, fmt, id_bits=id_bits)


def result_layout(rows: int, cols: int, id_bits: int) -> data.StructLayout:
    """Result payload, the record :data:`~raplas_hdl.model.records.PS_RESULT`: ``id``,
    ``row_mask`` (bit k = row plane k), ``col_mask`` (bit k = column plane ``rows + k``),
    packed LSB first in that order."""
    return struct_layout(PS_RESULT, id_bits=id_bits, rows=rows, cols=cols)


def _stages(fmt, mul_stages, add_stages):
    """The FP units' stage counts, ``None`` meaning the format's default."""
    return (default_mul_stages(fmt) if mul_stages is None else mul_stages,
            default_add_stages(fmt) if add_stages is None else add_stages)


def _check_int(name, value, low):
    if not isinstance(value, int) or isinstance(value, bool) or value < low:
        raise ValueError(f"{name} must be an integer >= {low}, not {value!r}")


def radius_terms(m: Module, r, fmt):
    """What :func:`abs_gt` needs of the radius ``r``: ``Cat(mag, nan, neg)``, its magnitude
    (denormal patterns as zero), whether it is a NaN and whether it is below zero; a
    combinational value, formed where ``r`` enters so that it travels the delay line
    already decoded."""
    w, mb = fmt.width, fmt.man_bits
    exp, frac = r[mb:w - 1], r[:mb]
    mag = Signal(w - 1, name="r_mag")
    m.d.comb += mag.eq((exp != 0).replicate(w - 1) & r[:w - 1])
    nan = (exp == fmt.exp_max_field) & (frac != 0)
    return Cat(mag, nan, r[w - 1] & (mag != 0))


def abs_gt(m: Module, d, r_terms, fmt):
    """``|d| > r`` as an ordered comparison of the contract (NaN: False; denormal
    patterns compare as zero), ``r`` given by :func:`radius_terms`; a combinational value.

    ``d``'s bits meet the comparison's carry chain straight from its register: a denormal
    ``d`` (exponent field 0) is below every nonzero magnitude, so ``d``'s exponent is tested
    beside the chain instead of masking ``d``'s bits in front of it (placed and routed, the
    decoding of both operands in front of the chain made the tester's comparison the
    certified whole unit's path, 12.1 ns at ECP5 speed 6)."""
    w, mb = fmt.width, fmt.man_bits
    r_mag, r_nan, r_neg = r_terms[:w - 1], r_terms[w - 1], r_terms[w]
    exp, frac = d[mb:w - 1], d[:mb]
    d_nan = (exp == fmt.exp_max_field) & (frac != 0)
    gt = Signal(name="abs_gt")
    m.d.comb += gt.eq(~d_nan & ~r_nan & (r_neg | ((exp != 0) & (d[:w - 1] > r_mag))))
    return gt


class PlaneSphereTester(wiring.Component):
    """One plane-sphere tester: a sphere per clock in, a keep flag out.

    Parameters
    ----------
    fmt : FPFormat
        Format and rounding of all six operations.
    planes : int
        Plane slots in the tester's registers (1 for the paper's tester; the array uses
        one per pass when it time-shares).
    mul_stages, add_stages : int
        Depths of the FP units (default: the format's, 4 and 6 in rtz: latency 17).
    multiplier : {"generic", "virtex4"}
        Significand multiplier of the three :class:`~.fp_mul.FPMul` (``virtex4``: DSP48
        primitives, one cycle more at FP24).
    adder : {"generic", "virtex4"}
        Target of the three :class:`~.fp_add.FPAdd` (``virtex4``: two DSP48 each, latency
        7 whatever ``add_stages``).

    Attributes
    ----------
    pw_en : In(1)
        Write ``pw_data`` into slot ``pw_addr`` at the clock edge.
    pw_addr : In(range(planes))
    pw_data : In(plane_layout(fmt))
        ``n.x | n.y << W | n.z << 2W | p << 3W``.
    c : In(vec3_layout(W))
        Sphere centre.
    r : In(W)
        Inflated radius ``r'``.
    sel : In(range(planes))
        Plane slot to test this sphere against.
    i_valid : In(1)
    en : In(1)
        Clock enable of the whole pipeline (hold when 0).
    flag : Out(1)
        ``NOT(|d| > r')``: 1 keeps the sphere; meaningful only with ``o_valid``.
    o_valid : Out(1)
    latency : int
        ``Lm + 2*La + 1`` with ``Lm``, ``La`` the multiplier's and the adder's latencies
        (12 by default, 13 with ``multiplier="virtex4"`` at FP24, 19 with both targets
        ``virtex4``).

    Raises
    ------
    ValueError
        For a bad format, a slot count below 1 or an unknown multiplier or adder.
    """

    def __init__(self, fmt=FP24, planes: int = 1, mul_stages: int | None = None,
                 add_stages: int | None = None, multiplier: str = "generic",
                 adder: str = "generic"):
        self._fmt = check_format(fmt)
        mul_stages, add_stages = _stages(fmt, mul_stages, add_stages)
        _check_int("planes", planes, 1)
        self._planes = planes
        _check_int("mul_stages", mul_stages, 1)
        _check_int("add_stages", add_stages, 1)
        self._mul_stages = mul_stages
        self._add_stages = add_stages
        self._multiplier = check_multiplier(multiplier)
        self._mul_latency = fp_mul_latency(fmt, mul_stages, multiplier)
        self._adder = check_adder(adder)
        self._add_latency = fp_add_latency(fmt, add_stages, adder)
        w = fmt.width
        super().__init__({
            "pw_en": In(1), "pw_addr": In(range(planes)), "pw_data": In(plane_layout(fmt)),
            "c": In(vec3_layout(w)), "r": In(w), "sel": In(range(planes)),
            "i_valid": In(1), "en": In(1),
            "flag": Out(1), "o_valid": Out(1),
        })

    @property
    def fmt(self):
        return self._fmt

    @property
    def planes(self) -> int:
        return self._planes

    @property
    def multiplier(self) -> str:
        return self._multiplier

    @property
    def adder(self) -> str:
        return self._adder

    @property
    def latency(self) -> int:
        """Enabled clock edges from a sphere to its flag."""
        return self._mul_latency + 2 * self._add_latency + 1

    def elaborate(self, platform):
        m = Module()
        fmt = self._fmt
        mul_x, mul_y, mul_z = muls = [FPMul(fmt, self._mul_stages, self._multiplier)
                                      for _ in range(3)]
        add_s1, add_s2, add_d = [FPAdd(fmt, self._add_stages, self._adder) for _ in range(3)]
        for i, u in enumerate(muls):
            m.submodules[f"mul_{'xyz'[i]}"] = u
        m.submodules.add_s1 = add_s1
        m.submodules.add_s2 = add_s2
        m.submodules.add_d = add_d

        # Plane registers (slots), written through the write port.
        slots = [Signal(plane_layout(fmt), name=f"plane_{g}") for g in range(self._planes)]
        with m.If(self.pw_en):
            with m.Switch(self.pw_addr):
                for g, slot in enumerate(slots):
                    with m.Case(g):
                        m.d.sync += slot.eq(self.pw_data)

        def pick(sel, field):
            if self._planes == 1:
                return getattr(slots[0], field)
            value = Signal(fmt.width, name=f"sel_{field}")
            with m.Switch(sel):
                for g, slot in enumerate(slots):
                    with m.Case(g):
                        m.d.comb += value.eq(getattr(slot, field))
            return value

        en = self.en
        # Stages 1-3: products.
        for u, nf, cf in ((mul_x, "nx", "x"), (mul_y, "ny", "y"), (mul_z, "nz", "z")):
            m.d.comb += [u.a.eq(pick(self.sel, nf)), u.b.eq(getattr(self.c, cf)),
                         u.i_valid.eq(self.i_valid), u.en.eq(en)]
        lat_m, lat_a = mul_x.latency, add_s1.latency
        sel_m = delay(m, self.sel, lat_m, en=en, name="sel_dly")
        # r' rides along to the comparator; the line's last stage is the tester's own: it
        # takes the plane's bits on a cycle without a sphere (its flag is then not read), so
        # that synthesis cannot merge it with the other testers' (their lines are the same
        # signal, and one merged register fanned out to every tester's comparator was one of
        # the certified whole unit's paths, 11.2 ns at ECP5 speed 6, 9.2 of it routing)
        lat_r = lat_m + 2 * lat_a
        r_line = delay(m, radius_terms(m, self.r, fmt), lat_r - 1, en=en, name="r_dly")
        v_line = delay(m, self.i_valid, lat_r - 1, en=en, name="rv_dly")
        r_d = Signal(len(r_line), name="r_own", reset_less=True)
        with m.If(en):
            m.d.sync += r_d.eq(Mux(v_line, r_line, Cat(slots[0].p, slots[0].nx)))
        # Stages 4-7: s1 = mx + my, s2 = mz + p.
        m.d.comb += [
            add_s1.a.eq(mul_x.o), add_s1.b.eq(mul_y.o), add_s1.sub.eq(0),
            add_s1.i_valid.eq(mul_x.o_valid), add_s1.en.eq(en),
            add_s2.a.eq(mul_z.o), add_s2.b.eq(pick(sel_m, "p")), add_s2.sub.eq(0),
            add_s2.i_valid.eq(mul_z.o_valid), add_s2.en.eq(en),
        ]
        # Stages 8-11: d = s1 + s2.
        m.d.comb += [add_d.a.eq(add_s1.o), add_d.b.eq(add_s2.o), add_d.sub.eq(0),
                     add_d.i_valid.eq(add_s1.o_valid), add_d.en.eq(en)]
        # Stage 12: the comparator.
        gt = abs_gt(m, add_d.o, r_d, fmt)
        with m.If(en):
            m.d.sync += [self.flag.eq(~gt), self.o_valid.eq(add_d.o_valid)]
        return m


class PlaneSphereArray(wiring.Component):
    """``testers`` plane-sphere testers with the decoder and an output FIFO.

    Parameters
    ----------
    fmt : FPFormat
    rows, cols : int
        Bundle lattice (each at least 1).
    testers : int or None
        Testers in the array (default ``rows + cols``: one pass per sphere). Fewer testers
        time-share: ``ceil((rows+cols)/testers)`` clocks per sphere. More than
        ``rows + cols`` are not built.
    sphere_id_bits : int
        Width of the sphere ID carried through (default 16).
    mul_stages, add_stages : int
        Depths of the FP units in each tester.
    multiplier : {"generic", "virtex4"}
        Significand multiplier of the testers' :class:`~.fp_mul.FPMul`.
    adder : {"generic", "virtex4"}
        Target of the testers' :class:`~.fp_add.FPAdd`.

    Attributes
    ----------
    pw_en : In(1)
    pw_addr : In(range(rows+cols))
        Plane ID: rows ``0 .. rows-1``, then columns.
    pw_data : In(plane_layout(fmt))
        ``n.x | n.y << W | n.z << 2W | p << 3W``.
    i : In(stream.Signature(sphere_layout(fmt, sphere_id_bits)))
        Spheres: ``id``, ``c`` (x, y, z), ``r`` (the inflated radius ``r'``).
    o : Out(stream.Signature(result_layout(rows, cols, sphere_id_bits)))
        One result per sphere, in order: ``id``, ``row_mask``, ``col_mask``.
    idle : Out(1)
        No sphere in flight: planes may be written (the drain rule, module docstring).
    latency : int
        Cycles from an input handshake to ``o.valid`` (empty FIFO): the issue register,
        ``passes - 1`` more issue cycles, the testers and the FIFO write:
        ``passes + tester latency + 1`` (14 for 4x4 at FP24).
    passes : int
        Clocks per sphere.
    fifo_depth : int
        ``latency + 2``.

    Raises
    ------
    ValueError
        Naming a bad parameter.
    """

    def __init__(self, fmt=FP24, *, rows: int, cols: int, testers: int | None = None,
                 sphere_id_bits: int = 16, mul_stages: int | None = None,
                 add_stages: int | None = None, multiplier: str = "generic",
                 adder: str = "generic"):
        self._fmt = check_format(fmt)
        mul_stages, add_stages = _stages(fmt, mul_stages, add_stages)
        _check_int("rows", rows, 1)
        _check_int("cols", cols, 1)
        if testers is None:
            testers = rows + cols
        _check_int("testers", testers, 1)
        _check_int("sphere_id_bits", sphere_id_bits, 1)
        self._rows, self._cols = rows, cols
        self._n_planes = rows + cols
        self._passes = math.ceil(self._n_planes / testers)
        self._testers = min(testers, self._n_planes)
        self._id_bits = sphere_id_bits
        # The testers' parameters: the array builds its testers in elaborate, so that an
        # array that is never elaborated leaves no unused elaboratables behind.
        self._tester_args = (fmt, self._passes, mul_stages, add_stages, multiplier, adder)
        _check_int("mul_stages", mul_stages, 1)
        _check_int("add_stages", add_stages, 1)
        self._multiplier = check_multiplier(multiplier)
        self._adder = check_adder(adder)
        self._tester_latency = (fp_mul_latency(fmt, mul_stages, multiplier)
                                + 2 * fp_add_latency(fmt, add_stages, adder) + 1)
        self._fifo_depth = self.latency + 2
        super().__init__({
            "pw_en": In(1), "pw_addr": In(range(self._n_planes)),
            "pw_data": In(plane_layout(fmt)),
            "i": In(stream.Signature(sphere_layout(fmt, sphere_id_bits))),
            "o": Out(stream.Signature(result_layout(rows, cols, sphere_id_bits))),
            "idle": Out(1),
        })

    @property
    def fmt(self):
        return self._fmt

    @property
    def rows(self) -> int:
        return self._rows

    @property
    def cols(self) -> int:
        return self._cols

    @property
    def testers(self) -> int:
        """Testers actually built (at most ``rows + cols``)."""
        return self._testers

    @property
    def passes(self) -> int:
        return self._passes

    @property
    def tester_latency(self) -> int:
        return self._tester_latency

    @property
    def multiplier(self) -> str:
        return self._multiplier

    @property
    def adder(self) -> str:
        return self._adder

    @property
    def latency(self) -> int:
        return self._passes + self._tester_latency + 1

    @property
    def fifo_depth(self) -> int:
        return self._fifo_depth

    def elaborate(self, platform):
        m = Module()
        T, G, P = self._testers, self._passes, self._n_planes
        units = [PlaneSphereTester(*self._tester_args) for _ in range(T)]
        for k, t in enumerate(units):
            m.submodules[f"tester_{k}"] = t
        fifo = m.submodules.fifo = SyncFIFO(width=self.o.payload.shape().size,
                                            depth=self._fifo_depth)

        # Plane writes: plane a goes to tester a % T, slot a // T.
        for k, t in enumerate(units):
            m.d.comb += t.pw_data.eq(self.pw_data)
            with m.Switch(self.pw_addr):
                for g in range(G):
                    a = g * T + k
                    if a < P:
                        with m.Case(a):
                            m.d.comb += [t.pw_en.eq(self.pw_en), t.pw_addr.eq(g)]

        # Issue register and credit counter.
        cur = Signal(self.i.payload.shape(), name="cur")
        busy = Signal(name="busy")
        pass_ = Signal(range(G), name="pass_no")
        # the credit count, kept as ``occupied = in use + took``: ``took`` is the last
        # cycle's read from the FIFO, registered, so that ``o.ready`` (the selector's side,
        # through the sphere slice) reaches one flip-flop, not the count's carry chain (that
        # route was 6.8 ns of the certified whole unit's 12.5 ns path, ECP5 speed 6); the two
        # comparisons ``i.ready`` picks from are registers formed from the count's next
        # value, so every handshake happens on the same cycle as with the true count
        depth = self._fifo_depth
        occupied = Signal(range(depth + 2), name="occupied")
        took = Signal(name="took")
        occupied_next = Signal(range(depth + 2), name="occupied_next")
        below = Signal(init=1, name="occupied_below")        # occupied < depth
        at_most = Signal(init=1, name="occupied_at_most")    # occupied <= depth
        in_flight = Signal(range(self._fifo_depth + 1), name="in_flight")
        last_issue = Signal()
        m.d.comb += last_issue.eq(pass_ == G - 1)
        can_take = ~busy | last_issue
        m.d.comb += self.i.ready.eq(can_take & Mux(took, at_most, below))
        accept = self.i.valid & self.i.ready
        # The issue register loads whenever it may take a sphere, accepted or not: when
        # nothing is accepted ``busy`` falls and ``cur`` is not used, and its ~100 enables
        # stay off the credit counter's path (``occupied`` -> ``ready`` -> ``occupied``).
        with m.If(can_take):
            m.d.sync += cur.eq(self.i.payload)
        with m.If(accept):
            m.d.sync += [busy.eq(1), pass_.eq(0)]
        with m.Elif(busy):
            with m.If(last_issue):
                m.d.sync += busy.eq(0)
            with m.Else():
                m.d.sync += pass_.eq(pass_ + 1)

        for t in units:
            m.d.comb += [t.c.eq(cur.c), t.r.eq(cur.r), t.sel.eq(pass_),
                         t.i_valid.eq(busy), t.en.eq(1)]
        lat = self._tester_latency
        id_out = delay(m, cur.id, lat, name="id_dly")
        pass_out = delay(m, pass_, lat, name="pass_dly")
        valid_out = units[0].o_valid
        flags = Cat(*(t.flag for t in units))

        # Decoder: collect passes 0 .. G-2, write the last one with the mask to the FIFO.
        acc = Signal(max(1, (G - 1) * T), name="mask_acc")
        if G > 1:
            with m.If(valid_out):
                with m.Switch(pass_out):
                    for g in range(G - 1):
                        with m.Case(g):
                            m.d.sync += acc[g * T:(g + 1) * T].eq(flags)
            mask = Cat(acc[:(G - 1) * T], flags)[:P]
        else:
            mask = flags[:P]
        write = Signal(name="fifo_write")
        m.d.comb += write.eq(valid_out & (pass_out == G - 1))
        result = Signal(self.o.payload.shape(), name="result")
        m.d.comb += [result.id.eq(id_out), result.row_mask.eq(mask[:self._rows]),
                     result.col_mask.eq(mask[self._rows:])]
        m.d.comb += [fifo.w_en.eq(write), fifo.w_data.eq(result)]

        # Output stream straight from the FIFO.
        read = Signal(name="fifo_read")
        m.d.comb += [self.o.valid.eq(fifo.r_rdy), self.o.payload.eq(fifo.r_data),
                     fifo.r_en.eq(self.o.ready), read.eq(fifo.r_rdy & self.o.ready)]
        m.d.comb += occupied_next.eq(occupied + accept - took)
        m.d.sync += [occupied.eq(occupied_next), took.eq(read),
                     below.eq(occupied_next < depth), at_most.eq(occupied_next <= depth),
                     in_flight.eq(in_flight + accept - write)]
        m.d.comb += self.idle.eq((in_flight == 0) & ~busy)
        return m


def build_plane_sphere(fmt=FP24, rows: int = 4, cols: int = 4, testers: int | None = None,
                       **options) -> PlaneSphereArray:
    """The ``raplas-hdl verilog plane-sphere`` unit: a :class:`PlaneSphereArray`."""
    return PlaneSphereArray(fmt, rows=rows, cols=cols, testers=testers, **options)
