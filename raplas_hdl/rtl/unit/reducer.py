"""The on-chip reduction: a run's result beats in, one answer per ray out.

The golden model is :func:`raplas_hdl.model.reduction.reduce_run` (the record
:data:`~raplas_hdl.model.records.ANSWER`); the stage sits between the result framing and
the output FIFO of an intersection unit built with ``UnitConfig(reduce=True)``.

Stages (a pipeline that moves as a whole, ``en``, while no run's answers are being sent):

1. **take** a beat of ``RESULT`` (its run's bank from the run-bank FIFO, filled by the top
   when it accepts a command); read the ray's ``tmax`` (a RAM of ``2 * rows * cols``
   patterns, written by snooping the host's writes to RAY field 7).
2. **qualify**: the beat is a *candidate* when ``hit``, ``t'`` finite, ``det`` finite and
   not zero, ``tmin * |det| <= t' * sign(det) <= tmax * |det|`` and ``tri_id + 1 !=
   exclude`` (``tmin``, ``exclude`` and the any-hit bit per bank, snooped from the WINDOW
   region). The products are exact: :func:`product_key` multiplies the significands (an
   integer multiply, one DSP48 per 17-bit significand pair at FP24) and give the sign and a
   magnitude key (exponent sum above the normalised product) that orders as the product's
   value (:func:`key_lt`). Read the ray's current answer (a RAM of ``rows * cols``
   answers).
3. **fold**: the ray's answer (the RAM's word, or the one written in the cycle the read was
   made) and a *valid* bit per ray (registers). A candidate replaces the answer when the
   ray has none or, in a nearest-hit bundle, ``t'_n * |det_a| < t'_a * |det_n|`` (signs of
   ``det`` on the numerators), equal ratios going to the lower triangle ID. On the run's
   ``last`` (or ``empty``) beat the unit stops taking beats and
4. **sends** the answers: the lowest ray with an answer each cycle (a tree of priority
   encoders on the valid bits, :func:`lowest_set_tree`; the answer RAM read a cycle ahead),
   the last marked ``last``, or one ``empty`` beat; then clears the valid bits and counts
   the run (``seq``).

Early-out: in an any-hit bundle a ray with an answer is *blocked*; ``blocked`` is the
valid-bit vector of the run being reduced while that run is any-hit (else 0) and ``seq``
its number (runs finished since reset, modulo ``2**seq_bits``); the pair selector drops the
jobs of blocked rays of the run with that number. Pairs a blocked ray would have issued
later cannot change its answer (the first candidate of the stream), so the answers do not
depend on when the bit arrives; only ``pairs_issued`` does.

Certified mode (``config.mode == "certified"``, :data:`~raplas_hdl.model.records.ANSWER_CERTIFIED`):
only a certain hit (``outcome`` 1) can be a candidate. An uncertain pair (``outcome`` 2) of
another triangle than the excluded one is qualified as *passed on* in stage 2 and, in stage
3, unless its ray is blocked (an any-hit bundle whose ray already has an answer), loaded
into the output register as its own beat (``outcome`` 2, the fields of the pair, not
``last``) instead of being folded; while the output register holds a beat not yet taken,
a passed-on pair waits in stage 3 and the pipeline stalls (``en``). So a run's uncertain
pairs leave in stream order before its answers (``outcome`` 1); a run without answers ends
with the ``empty`` beat (``outcome`` 0) after them.
"""

from __future__ import annotations

from amaranth.hdl import Cat, Const, Module, Mux, Signal
from amaranth.lib import data, stream, wiring
from amaranth.lib.fifo import SyncFIFOBuffered
from amaranth.lib.wiring import In, Out

from ...model.memory_image import REGIONS, UnitConfig
from ...model.records import OUTCOME_HIT, OUTCOME_UNCERTAIN, answer_record
from ..ram import SyncRAM
from ..records import struct_layout
from .selector import lowest_set
from .streams import result_layout

__all__ = ["Reducer", "answer_layout", "product_key", "key_lt", "key_eq", "lowest_set_tree",
           "RUN_FIFO_DEPTH", "SEQ_BITS"]

#: Runs accepted but not yet reduced that the run-bank FIFO holds (the top stalls ``cmd``
#: when it is full).
RUN_FIFO_DEPTH = 8
#: Default width of the run number ``seq``.
SEQ_BITS = 8


def answer_layout(cfg: UnitConfig) -> data.StructLayout:
    return struct_layout(answer_record(cfg), cfg)


def product_key(m: Module, x, y, sign, fmt, name: str):
    """``(s, mag)``: the sign and the magnitude key of ``(-1)**sign * |x| * |y|`` (``x``,
    ``y`` finite patterns of ``fmt``): ``mag`` is the exponent sum above the normalised
    significand product (it orders as ``|x| * |y|``), 0 when either is zero, and ``s`` is 0
    for a zero. :func:`key_lt` and :func:`key_eq` compare two keys."""
    M, E = fmt.man_bits, fmt.exp_bits
    ex, ey = x[M:M + E], y[M:M + E]
    p = Signal(2 * M + 2, name=f"{name}_p")
    m.d.comb += p.eq(Cat(x[:M], 1) * Cat(y[:M], 1))
    top = p[2 * M + 1]
    sig = Signal(2 * M + 1, name=f"{name}_sig")      # the product without its leading one
    m.d.comb += sig.eq(Mux(top, p[:2 * M + 1], Cat(0, p[:2 * M])))
    mag = Signal(2 * M + 1 + E + 2, name=f"{name}_mag")
    s = Signal(name=f"{name}_s")
    zero = (ex == 0) | (ey == 0)
    m.d.comb += [mag.eq(Mux(zero, 0, Cat(sig, ex + ey + top))), s.eq(sign & ~zero)]
    return s, mag


def key_lt(a, b):
    """``a < b`` for two :func:`product_key` keys (two magnitude compares side by side, no
    negation in series)."""
    (sa, ma), (sb, mb) = a, b
    return (sa & ~sb) | (~sa & ~sb & (ma < mb)) | (sa & sb & (mb < ma))


def key_eq(a, b):
    return (a[0] == b[0]) & (a[1] == b[1])


def lowest_set_tree(m: Module, mask, n: int, name: str):
    """(index, only) of the lowest set bit of ``mask`` (``n`` bits): ``only`` when it is the
    only one. Above 16 bits a tree of 8-bit priority encoders (the group, then the bit in
    it), so no carry chain is longer than 16."""
    if n <= 16:
        index, hot = lowest_set(m, mask, n, name)
        return index, (mask & ~hot) == 0
    g = 8
    ng = -(-n // g)
    padded = Cat(mask, Const(0, ng * g - n))
    groups = Signal(ng, name=f"{name}_groups")
    m.d.comb += groups.eq(Cat(*[padded[k * g:(k + 1) * g].any() for k in range(ng)]))
    gi, g_only = lowest_set_tree(m, groups, ng, f"{name}_g")
    sub = Signal(g, name=f"{name}_sub")
    m.d.comb += sub.eq(padded.word_select(gi, g))
    si, s_hot = lowest_set(m, sub, g, f"{name}_s")
    index = Signal(max(1, (n - 1).bit_length()), name=f"{name}_index")
    m.d.comb += index.eq(Cat(si, gi))
    return index, g_only & ((sub & ~s_hot) == 0)


class Reducer(wiring.Component):
    """Result beats of runs in, each run's answers out (see the module docstring).

    Parameters
    ----------
    config : UnitConfig
        ``reduce`` need not be set (the standalone tests build it alone).
    ram : {"memory", "verilog"}
        Implementation of its two RAMs (:class:`~raplas_hdl.rtl.ram.SyncRAM`).
    seq_bits : int
        Width of ``seq``: more than the runs that can be between the pair selector's output
        and this stage.

    Members
    -------
    i : In(stream.Signature(result_layout))
        The result framing's beats (``RESULT``).
    o : Out(stream.Signature(answer_layout))
        Answers (``ANSWER``).
    wr_en, wr_addr, wr_data : In(1), In(32), In(32)
        The host's write port (snooped: RAY field 7, WINDOW region).
    run_bank : In(stream.Signature(1))
        The bank of each accepted run, in command order.
    blocked : Out(rows * cols)
        Rays of run ``seq`` that have an answer, when that run is any-hit.
    seq : Out(seq_bits)
        The number of the run being reduced.
    """

    def __init__(self, config: UnitConfig, ram: str = "memory", seq_bits: int = SEQ_BITS):
        from ...model.reduction import check_reduce_format

        check_reduce_format(config.fmt)
        self._cfg = config
        self._ram = ram
        self._seq_bits = int(seq_bits)
        super().__init__({
            "i": In(stream.Signature(result_layout(config))),
            "o": Out(stream.Signature(answer_layout(config))),
            "wr_en": In(1), "wr_addr": In(32), "wr_data": In(32),
            "run_bank": In(stream.Signature(1)),
            "blocked": Out(config.n_rays),
            "seq": Out(self._seq_bits),
        })

    def elaborate(self, platform):
        cfg = self._cfg
        fmt = cfg.fmt
        M, E, W = fmt.man_bits, fmt.exp_bits, fmt.width
        R = cfg.n_rays
        tb = cfg.tri_id_bits
        e_max = (1 << E) - 1
        m = Module()

        # -- the host's writes: tmax per ray (RAY field 7), tmin / exclude / any per bank
        region, bank_w = self.wr_addr[28:32], self.wr_addr[27]
        index, fld = self.wr_addr[4:27], self.wr_addr[0:4]
        tmax_ram = SyncRAM(W, 2 * R, impl=self._ram, name="tmax_mem")
        tw = tmax_ram.write_port()
        m.d.comb += [tw.addr.eq(index + Mux(bank_w, R, 0)), tw.data.eq(self.wr_data[:W]),
                     tw.en.eq(self.wr_en & (region == REGIONS["ray"]) & (fld == 7)
                              & (index < R))]
        tmin = Signal(data.ArrayLayout(W, 2))
        excl = Signal(data.ArrayLayout(tb + 1, 2))
        anyh = Signal(2)
        with m.If(self.wr_en & (region == REGIONS["window"]) & (index == 0)):
            with m.Switch(fld):
                with m.Case(0):
                    m.d.sync += tmin[bank_w].eq(self.wr_data[:W])
                with m.Case(1):
                    m.d.sync += excl[bank_w].eq(self.wr_data[:tb + 1])
                with m.Case(2):
                    m.d.sync += anyh.bit_select(bank_w, 1).eq(self.wr_data[0])

        # -- run banks, in command order (popped when a run's last beat is taken)
        m.submodules.runs = runs = SyncFIFOBuffered(width=1, depth=RUN_FIFO_DEPTH)
        wiring.connect(m, wiring.flipped(self.run_bank), runs.w_stream)

        ans_fields = {"tri_id": tb, "t": W, "u": W, "v": W, "det": W, "flags": 3}
        ans = data.StructLayout(ans_fields)
        certified = cfg.mode == "certified"
        beat_l = data.StructLayout({**ans_fields, "ray": cfg.ray_id_bits, "hit": 1,
                                    "last": 1, "empty": 1, "bank": 1,
                                    **({"uncertain": 1} if certified else {})})
        en = Signal()            # the take / qualify / fold pipeline moves
        scanning = Signal()
        if not certified:
            m.d.comb += en.eq(~scanning)

        # -- 1. take
        a_v = Signal()
        a = Signal(beat_l)
        r = self.i.payload
        m.d.comb += [self.i.ready.eq(en & runs.r_stream.valid),
                     runs.r_stream.ready.eq(self.i.valid & self.i.ready & r.last)]
        tr = tmax_ram.read_port()
        m.d.comb += [tr.addr.eq(r.ray_id + Mux(runs.r_stream.payload, R, 0)), tr.en.eq(en)]
        with m.If(en):
            m.d.sync += a_v.eq(self.i.valid & self.i.ready)
            m.d.sync += [a.ray.eq(r.ray_id), a.hit.eq(r.hit), a.last.eq(r.last),
                         a.empty.eq(r.empty), a.bank.eq(runs.r_stream.payload)]
            if certified:
                m.d.sync += a.uncertain.eq(r.outcome == OUTCOME_UNCERTAIN)
            m.d.sync += [a[k].eq(r[k]) for k in ans_fields]

        # -- 2. qualify
        def exp_of(x):
            return x[M:M + E]

        def sign_of(x):
            return x[W - 1]

        one = Const(((1 << (E - 1)) - 1) << M, W)
        tmax = tr.data
        s_num = sign_of(a.t) ^ sign_of(a.det)
        k_num = product_key(m, a.t, one, s_num, fmt, "k_num")
        k_lo = product_key(m, tmin[a.bank], a.det, sign_of(tmin[a.bank]), fmt, "k_lo")
        k_hi = product_key(m, tmax, a.det, sign_of(tmax), fmt, "k_hi")
        tmax_inf = (exp_of(tmax) == e_max) & ~sign_of(tmax)
        ok = Signal()
        m.d.comb += ok.eq(a.hit & ~a.empty & (exp_of(a.t) != e_max)
                          & (exp_of(a.det) != e_max) & (exp_of(a.det) != 0)
                          & ~key_lt(k_num, k_lo) & (tmax_inf | ~key_lt(k_hi, k_num))
                          & (excl[a.bank] != a.tri_id + 1))
        ans_ram = SyncRAM(ans.size, R, impl=self._ram, name="answer_mem")
        aw = ans_ram.write_port()
        ar = ans_ram.read_port()
        b_v = Signal()
        b = Signal(beat_l)
        b_ok = Signal()
        b_any = Signal()
        with m.If(en):
            m.d.sync += [b_v.eq(a_v), b.eq(a), b_ok.eq(ok), b_any.eq(anyh.bit_select(a.bank, 1))]
        if certified:
            # an uncertain pair of another triangle than the excluded one is passed on
            b_pass = Signal()
            with m.If(en):
                m.d.sync += b_pass.eq(a.uncertain & ~a.empty & (excl[a.bank] != a.tri_id + 1))

        # -- 3. fold
        valid = Signal(R)
        cur_any = Signal()
        fwd_v = Signal()
        fwd = Signal(ans)
        cur = Signal(ans)
        m.d.comb += cur.eq(Mux(fwd_v, fwd, ar.data))
        new = Signal(ans)
        m.d.comb += new.eq(Cat(*[b[k] for k in ans_fields]))
        has = valid.bit_select(b.ray, 1)
        k_new = product_key(m, b.t, cur.det, sign_of(b.t) ^ sign_of(b.det), fmt, "k_new")
        k_cur = product_key(m, cur.t, b.det, sign_of(cur.t) ^ sign_of(cur.det), fmt, "k_cur")
        better = Signal()
        m.d.comb += better.eq(~has | (~b_any & (key_lt(k_new, k_cur)
                                                | (key_eq(k_new, k_cur)
                                                   & (b.tri_id < cur.tri_id)))))
        write = Signal()
        m.d.comb += [write.eq(en & b_v & b_ok & better),
                     aw.addr.eq(b.ray), aw.data.eq(new), aw.en.eq(write)]
        with m.If(en):
            m.d.sync += [fwd_v.eq(write & (b.ray == a.ray)), fwd.eq(new)]
        with m.If(write):
            m.d.sync += valid.bit_select(b.ray, 1).eq(1)
        with m.If(en & b_v):
            m.d.sync += cur_any.eq(b_any)
            with m.If(b.last):
                m.d.sync += scanning.eq(1)
        m.d.comb += self.blocked.eq(Mux(cur_any, valid, 0))

        # -- 4. send
        o_v = Signal()
        o_last = Signal()
        o_empty = Signal()
        o_ray = Signal(cfg.ray_id_bits)
        if certified:
            # passed-on uncertain pairs leave from stage 3 through the output register
            o_unc = Signal()
            u_word = Signal(ans)
            emit = Signal()
            m.d.comb += [emit.eq(b_v & b_pass & ~(b_any & has)),
                         en.eq(~scanning & ~(emit & o_v))]
            with m.If(~scanning):
                with m.If(o_v & self.o.ready):
                    m.d.sync += o_v.eq(0)
                with m.If(en & emit):
                    m.d.sync += [o_v.eq(1), o_unc.eq(1), o_last.eq(0), o_empty.eq(0),
                                 o_ray.eq(b.ray), u_word.eq(new)]
        idx, only = lowest_set_tree(m, valid, R, "next")
        step = scanning & (~o_v | self.o.ready)
        m.d.comb += [ar.addr.eq(Mux(scanning, idx, a.ray)),
                     ar.en.eq(Mux(scanning, step & (valid != 0), en))]
        with m.If(step):
            with m.If(o_v & o_last):
                m.d.sync += [scanning.eq(0), o_v.eq(0), cur_any.eq(0),
                             self.seq.eq(self.seq + 1)]
            with m.Elif(valid != 0):
                m.d.sync += [o_v.eq(1), o_ray.eq(idx), o_empty.eq(0), o_last.eq(only),
                             valid.bit_select(idx, 1).eq(0)]
            with m.Else():
                m.d.sync += [o_v.eq(1), o_empty.eq(1), o_last.eq(1)]
            if certified:
                m.d.sync += o_unc.eq(0)
        out = self.o.payload
        word = Signal(ans)
        if certified:
            m.d.comb += [word.eq(Mux(o_unc, u_word, ar.data)),
                         out.outcome.eq(Mux(o_empty, 0, Mux(o_unc, OUTCOME_UNCERTAIN,
                                                             OUTCOME_HIT)))]
        else:
            m.d.comb += word.eq(ar.data)
        m.d.comb += [self.o.valid.eq(o_v), out.last.eq(o_last), out.empty.eq(o_empty)]
        with m.If(~o_empty):
            m.d.comb += [out.ray_id.eq(o_ray)] + [out[k].eq(word[k]) for k in ans_fields]

        tmax_ram.add_to(m)
        ans_ram.add_to(m)
        return m
