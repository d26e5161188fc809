"""The on-chip reduction: a run's result beats in, one answer per ray out.

The golden model is :func:`raplas_hdl.model.reduction.reduce_run` (the record
:data:`~raplas_hdl.model.records.ANSWER`); the stage sits between the result framing and
the output FIFO of an intersection unit built with ``UnitConfig(reduce=True)``.

Stages (a pipeline that moves as a whole, ``en``, while no run's answers are being sent):

1. **take** a beat of ``RESULT`` (its run's bank from the run-bank FIFO, filled by the top
   when it accepts a command); read the ray's ``tmax`` (a RAM of ``2 * rows * cols``
   patterns, written by snooping the host's writes to RAY field 7).
2. **qualify**, in two stages (``a2``: the products, from ``tmax`` registered as it leaves
   the RAM and the bank's ``tmin`` registered beside it, into registers; ``b``: their
   comparisons). The beat is a *candidate* when
   ``hit``, ``t'`` finite, ``det`` finite and not zero, ``tmin * |det| <= t' * sign(det)
   <= tmax * |det|`` and ``tri_id + 1 != exclude`` (``tmin``, ``exclude`` and the any-hit
   bit per bank, snooped from the WINDOW region). The products are exact:
   :func:`product_raw` multiplies the significands (an integer multiply, one DSP48 per
   17-bit significand pair at FP24) and :func:`key_of` gives the sign and a magnitude key
   (exponent sum above the normalised product) that orders as the product's value
   (:func:`key_lt`). The
   ray's current answer is read from a RAM of ``rows * cols`` answers as the beat leaves
   ``a2``.
3. **fold**, in three stages (``p``, ``q``, ``r``). A candidate replaces the ray's answer
   when the ray has none (a *valid* bit per ray, registers) or, in a nearest-hit bundle,
   ``t'_n * |det_a| < t'_a * |det_n|`` (signs of ``det`` on the numerators), equal ratios
   going to the lower triangle ID. The answer it must beat is the word of the last beat
   before it that wrote the ray: one of the three beats ahead of it in the fold (the
   third has just left it), or else the RAM's word or the word written in the cycle of
   that read (a write history of three entries). ``p`` multiplies the candidate against
   all four, from registers into registers, ``q`` compares, and ``r``, by then knowing
   which beat wrote last, takes that comparison, writes the answer and sets the valid bit:
   the loop through the answer has neither a multiply nor a compare in it, and a beat a
   cycle costs no stall. On the run's ``last`` (or ``empty``) beat, in ``r``, the unit
   stops taking beats and
4. **sends** the answers: the lowest ray with an answer each cycle (a tree of priority
   encoders on the valid bits, :func:`lowest_set_tree`, into registers a cycle ahead of the
   answer RAM's read, so a scan starts with a cycle that only primes them), the last marked
   ``last``, or one ``empty`` beat; then clears the valid bits and counts the run
   (``seq``). The next run's beats wait in the stages where they are; a write
   history or a read of the previous run cannot matter to them, as the valid bits are
   clear.

Early-out: in an any-hit bundle a ray with an answer is *blocked*; ``blocked`` is the
valid-bit vector of the run being reduced while that run is any-hit (else 0) and ``seq``
its number (runs finished since reset, modulo ``2**seq_bits``); the pair selector drops the
jobs of blocked rays of the run with that number. Pairs a blocked ray would have issued
later cannot change its answer (the first candidate of the stream), so the answers do not
depend on when the bit arrives; only ``pairs_issued`` does.

Certified mode (``config.mode == "certified"``, :data:`~raplas_hdl.model.records.ANSWER_CERTIFIED`;
:mod:`raplas_hdl.model.ordering`): only a *tight* certain hit (``outcome`` 1 and ``tight``) can
be a candidate, and only when its ``t'/det`` is not *near* ``tmin`` or ``tmax``
(:func:`key_near` on the window's keys, in stage ``b``). Passed on, as *uncertain*, in stage 2:
an uncertain pair or a certain hit that is not tight, of another triangle than the excluded
one, and a tight hit near the window. In a nearest-hit bundle a candidate near the ray's
answer (``near``, four bits beside ``better``, the one of the last writer taken in stage
``r``) is passed on in stage ``r`` instead of replacing the answer or being dropped. A beat
passed on is, unless its ray is blocked (an any-hit bundle whose ray already has an answer),
loaded in stage ``r`` into the output register as its own beat (``outcome`` 2, the fields of
the pair, not ``last``) instead of being folded, or into a skid register behind it while the
output register holds a beat not yet taken; while the skid register is full the pipeline
stalls (``en``, a function of registers only), and a scan waits for it to drain. So a run's
passed-on pairs leave in stream order before its answers (``outcome`` 1); a run without
answers ends with the ``empty`` beat (``outcome`` 0) after them. Every certain hit either
leaves the unit or was dropped behind an answer certainly nearer in R (or is certainly
outside the window), so R's nearest hit reaches the host.
"""

from __future__ import annotations

from amaranth.hdl import Cat, Const, Module, Mux, Signal
from amaranth.lib import data, stream, wiring
from amaranth.lib.fifo import SyncFIFOBuffered
from amaranth.lib.wiring import In, Out

from ...model.config import UnitConfig
from ...model.memory_image import REGIONS
from ...model.ordering import near_shift
from ...model.records import OUTCOME_HIT, OUTCOME_UNCERTAIN, answer_record
from ...model.reduction import check_reduce_format
from ..ram import SyncRAM
from ..records import struct_layout
from .selector import lowest_set
from .streams import result_layout

__all__ = ["Reducer", "answer_layout", "product_raw", "key_of", "key_lt", "key_eq",
           "key_near", "lowest_set_tree", "RUN_FIFO_DEPTH", "SEQ_BITS"]

#: Runs accepted but not yet reduced that the run-bank FIFO holds (the top stalls ``cmd``
#: when it is full).
RUN_FIFO_DEPTH = 8
#: Default width of the run number ``seq``.
SEQ_BITS = 8


def answer_layout(cfg: UnitConfig) -> data.StructLayout:
    return struct_layout(answer_record(cfg), cfg)


def raw_layout(fmt) -> data.StructLayout:
    """What :func:`product_raw` gives: the significand product ``p``, the exponent sum
    ``e`` and ``e + 1`` (``e1``), a zero bit and the sign."""
    M, E = fmt.man_bits, fmt.exp_bits
    return data.StructLayout({"p": 2 * M + 2, "e": E + 2, "e1": E + 2, "zero": 1, "s": 1})


def product_raw(m: Module, x, y, sign, fmt, name: str):
    """The multiply of ``(-1)**sign * |x| * |y|`` (``x``, ``y`` finite patterns of ``fmt``)
    and, beside it, the exponent sums: the first half of a product's key, to be
    registered before :func:`key_of`."""
    M, E = fmt.man_bits, fmt.exp_bits
    ex, ey = x[M:M + E], y[M:M + E]
    r = Signal(raw_layout(fmt), name=f"{name}_raw")
    zero = (ex == 0) | (ey == 0)
    m.d.comb += [r.p.eq(Cat(x[:M], 1) * Cat(y[:M], 1)), r.e.eq(ex + ey), r.e1.eq(ex + ey + 1),
                 r.zero.eq(zero), r.s.eq(sign & ~zero)]
    return r


def key_of(m: Module, raw, fmt, name: str):
    """``(s, mag)``: the sign and the magnitude key of a product, from :func:`product_raw`'s
    record: ``mag`` is the exponent sum above the normalised significand product (it
    orders as ``|x| * |y|``), 0 when either is zero, and ``s`` is 0 for a zero.
    :func:`key_lt` and :func:`key_eq` compare two keys."""
    M = fmt.man_bits
    p = raw.p
    top = p[2 * M + 1]
    sig = Signal(2 * M + 1, name=f"{name}_sig")      # the product without its leading one
    m.d.comb += sig.eq(Mux(top, p[:2 * M + 1], Cat(0, p[:2 * M])))
    mag = Signal(2 * M + 1 + fmt.exp_bits + 2, name=f"{name}_mag")
    m.d.comb += mag.eq(Mux(raw.zero, 0, Cat(sig, Mux(top, raw.e1, raw.e))))
    return raw.s, mag


def key_lt(a, b):
    """``a < b`` for two :func:`key_of` keys (two magnitude compares side by side, no
    negation in series)."""
    (sa, ma), (sb, mb) = a, b
    return (sa & ~sb) | (~sa & ~sb & (ma < mb)) | (sa & sb & (mb < ma))


def key_eq(a, b):
    return (a[0] == b[0]) & (a[1] == b[1])


def key_near(a, b, fmt):
    """Whether two :func:`key_of` keys are *near* (:func:`raplas_hdl.model.ordering.near`):
    equal signs and magnitudes whose bits from ``near_shift(fmt)`` up differ by at most 1."""
    (sa, ma), (sb, mb) = a, b
    s = near_shift(fmt)
    ha, hb = ma[s:], mb[s:]
    return (sa == sb) & ((ha == hb) | (ha == hb + 1) | (hb == ha + 1))


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
        a = Signal(beat_l, reset_less=True)
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
                # only a tight certain hit can be folded; a certain hit that is not tight
                # goes to the host like an uncertain pair (model/ordering.py)
                m.d.sync += [a.hit.eq(r.hit & r.tight),
                             a.uncertain.eq((r.outcome == OUTCOME_UNCERTAIN)
                                            | ((r.outcome == OUTCOME_HIT) & ~r.tight))]
            m.d.sync += [a[k].eq(r[k]) for k in ans_fields]

        # -- 2. qualify: the bounds' products (tmax from its RAM's read register), then
        # their comparisons; the ray's answer is read on the way
        def exp_of(x):
            return x[M:M + E]

        def sign_of(x):
            return x[W - 1]

        def stage(src_v, src, name, extra=None):
            """The next pipeline register of a beat: its valid bit, and a record of the
            beat's fields and ``extra`` ones, where those ``src`` has are copied (without a
            reset: only the valid bit needs one)."""
            layout = data.StructLayout({**beat_l.members, **(extra or {})})
            v = Signal(name=f"{name}_v")
            r = Signal(layout, name=name, reset_less=True)
            have = src.shape().members
            with m.If(en):
                m.d.sync += [v.eq(src_v)] + [r[k].eq(src[k]) for k in layout.members
                                             if k in have]
            return v, r

        raw_l = raw_layout(fmt)

        def raw_reg(x, y, sign, name):
            """A product's first half (:func:`product_raw`) on a register; its key. The
            register and the operands' stage registers have no reset, so that place and
            route can move them into the multiplier block
            (:mod:`raplas_hdl.pnr.dsp_registers`)."""
            r = Signal(raw_l, name=f"{name}_r", reset_less=True)
            with m.If(en):
                m.d.sync += r.eq(product_raw(m, x, y, sign, fmt, name))
            return key_of(m, r, fmt, name)

        one = Const(((1 << (E - 1)) - 1) << M, W)
        # the bank's tmin is selected as the beat enters a2, so no multiplexer stands before
        # k_lo's multiply (a bank's window is written only before its run is accepted)
        a2_v, a2 = stage(a_v, a, "a2", {"tmax": W, "tmin": W})
        with m.If(en):
            m.d.sync += [a2.tmax.eq(tr.data), a2.tmin.eq(tmin[a.bank])]
        s_num = sign_of(a2.t) ^ sign_of(a2.det)
        k_num = raw_reg(a2.t, one, s_num, "k_num")
        k_lo = raw_reg(a2.tmin, a2.det, sign_of(a2.tmin), "k_lo")
        k_hi = raw_reg(a2.tmax, a2.det, sign_of(a2.tmax), "k_hi")
        b_v, b = stage(a2_v, a2, "b", {"tmax_inf": 1})
        with m.If(en):
            m.d.sync += b.tmax_inf.eq((exp_of(a2.tmax) == e_max) & ~sign_of(a2.tmax))
        ok = Signal()
        if certified:
            # a tight hit near tmin or tmax goes to the host: its side of the window is not
            # certain (model/ordering.py)
            base = Signal()
            near_w = Signal()
            m.d.comb += [base.eq(b.hit & ~b.empty & (exp_of(b.t) != e_max)
                                 & (exp_of(b.det) != e_max) & (exp_of(b.det) != 0)
                                 & (excl[b.bank] != b.tri_id + 1)),
                         near_w.eq(key_near(k_num, k_lo, fmt)
                                   | (~b.tmax_inf & key_near(k_hi, k_num, fmt))),
                         ok.eq(base & ~key_lt(k_num, k_lo) & (b.tmax_inf | ~key_lt(k_hi, k_num))
                               & ~near_w)]
        else:
            m.d.comb += ok.eq(b.hit & ~b.empty & (exp_of(b.t) != e_max)
                              & (exp_of(b.det) != e_max) & (exp_of(b.det) != 0)
                              & ~key_lt(k_num, k_lo) & (b.tmax_inf | ~key_lt(k_hi, k_num))
                              & (excl[b.bank] != b.tri_id + 1))
        ans_ram = SyncRAM(ans.size, R, impl=self._ram, name="answer_mem")
        aw = ans_ram.write_port()
        ar = ans_ram.read_port()

        # -- 3. fold, in three stages. A candidate replaces the ray's answer when it is
        # better than the answer left by the beats before it: the word of the last of them
        # that wrote the ray. That is one of the three beats ahead of it (``q``, ``r`` and
        # the one that has just left ``r``: its word is the write history's first entry),
        # or else the answer read from the RAM as the beat entered ``b`` (or written by
        # the beat that wrote in the cycle of that read, the history's first entry then),
        # ``p.cur``. Stage p multiplies the candidate's fields against all four, each a
        # register, q compares, and r, knowing by then which beat wrote last (the history,
        # three deep), takes that comparison and writes: no multiply or compare in the loop
        # through the answer.
        cmp_l = data.StructLayout({"t": W, "det": W, "tri_id": tb})
        hist_l = data.StructLayout({"v": 1, "ray": cfg.ray_id_bits, "w": cmp_l})
        hist = [Signal(hist_l, name=f"hist{k}") for k in (1, 2, 3)]  # last en-cycle first
        tags = {"ok": 1, "any": 1, **({"pass_": 1} if certified else {})}
        p_v, p = stage(b_v, b, "p", {**tags, "cur": cmp_l})
        read = data.View(ans, ar.data)
        with m.If(en):
            m.d.sync += [p.ok.eq(ok), p.any.eq(anyh.bit_select(b.bank, 1)),
                         p.cur.eq(Mux(hist[0].v & (hist[0].ray == b.ray), hist[0].w,
                                      Cat(*[read[k] for k in cmp_l.members])))]
            if certified:
                # an uncertain pair of another triangle than the excluded one is passed on,
                # and so is a tight hit near the window
                m.d.sync += p.pass_.eq((b.uncertain & ~b.empty
                                        & (excl[b.bank] != b.tri_id + 1))
                                       | (base & near_w))
        q_v, q = stage(p_v, p, "q", tags)
        r_v, r3 = stage(q_v, q, "r", {**tags, "better": 4,
                                      **({"near": 4} if certified else {})})
        s_new = sign_of(p.t) ^ sign_of(p.det)
        better, near = [], []
        for n, x in enumerate((p.cur, q, r3, hist[0].w)):
            k_new = raw_reg(p.t, x.det, s_new, f"k_new{n}")
            k_cur = raw_reg(x.t, p.det, sign_of(x.t) ^ sign_of(x.det), f"k_cur{n}")
            lower = Signal(name=f"lower{n}")
            with m.If(en):
                m.d.sync += lower.eq(p.tri_id < x.tri_id)
            better.append(key_lt(k_new, k_cur) | (key_eq(k_new, k_cur) & lower))
            if certified:
                near.append(key_near(k_new, k_cur, fmt))
        with m.If(en):
            m.d.sync += r3.better.eq(Cat(*better))
            if certified:
                m.d.sync += r3.near.eq(Cat(*near))

        valid = Signal(R)
        cur_any = Signal()
        new = Signal(ans)
        m.d.comb += new.eq(Cat(*[r3[k] for k in ans_fields]))
        has = valid.bit_select(r3.ray, 1)

        def last_writer(bits):
            """The bit of ``bits`` (one per answer compared in stage p) of the answer the
            beat in r must beat: the last beat before it that wrote its ray's."""
            return Mux(hist[0].v & (hist[0].ray == r3.ray), bits[1],
                       Mux(hist[1].v & (hist[1].ray == r3.ray), bits[2],
                           Mux(hist[2].v & (hist[2].ray == r3.ray), bits[3], bits[0])))

        wins = Signal()
        m.d.comb += wins.eq(last_writer(r3.better))
        write = Signal()
        if certified:
            # a candidate near the ray's answer goes to the host (model/ordering.py)
            near_cur = Signal()
            fold_pass = Signal()
            m.d.comb += [near_cur.eq(last_writer(r3.near)),
                         fold_pass.eq(r3.ok & has & ~r3.any & near_cur),
                         write.eq(en & r_v & r3.ok & (~has | (~r3.any & wins & ~near_cur))),
                         aw.addr.eq(r3.ray), aw.data.eq(new), aw.en.eq(write)]
        else:
            m.d.comb += [write.eq(en & r_v & r3.ok & (~has | (~r3.any & wins))),
                         aw.addr.eq(r3.ray), aw.data.eq(new), aw.en.eq(write)]
        with m.If(en):
            m.d.sync += [hist[0].v.eq(write), hist[0].ray.eq(r3.ray),
                         hist[0].w.eq(Cat(*[r3[k] for k in cmp_l.members])),
                         hist[1].eq(hist[0]), hist[2].eq(hist[1])]
        with m.If(write):
            m.d.sync += valid.bit_select(r3.ray, 1).eq(1)
        with m.If(en & r_v):
            m.d.sync += cur_any.eq(r3.any)
            with m.If(r3.last):
                m.d.sync += scanning.eq(1)
        m.d.comb += self.blocked.eq(Mux(cur_any, valid, 0))

        # -- 4. send
        o_v = Signal()
        o_last = Signal()
        o_empty = Signal()
        o_ray = Signal(cfg.ray_id_bits)
        if certified:
            # passed-on uncertain pairs leave from stage r through the output register, or,
            # when that holds a beat not taken, through a skid register behind it; the
            # pipeline stops while the skid register is full, so ``en`` is two registers'
            # function (a stop computed from this cycle's beat in r drove the enables of
            # every stage through the valid bits' multiplexer: the board's critical path)
            o_unc = Signal()
            u_word = Signal(ans)
            emit = Signal()
            sk_v = Signal()
            sk_ray = Signal(cfg.ray_id_bits)
            sk_word = Signal(ans)
            o_free = Signal()
            m.d.comb += [emit.eq(r_v & (r3.pass_ | fold_pass) & ~(r3.any & has)),
                         en.eq(~scanning & ~sk_v), o_free.eq(~o_v | self.o.ready)]
            with m.If(o_v & self.o.ready):
                m.d.sync += o_v.eq(0)
            # the skid register drains into the output register (never while ``en``)
            with m.If(sk_v & o_free):
                m.d.sync += [sk_v.eq(0), o_v.eq(1), o_unc.eq(1), o_last.eq(0),
                             o_empty.eq(0), o_ray.eq(sk_ray), u_word.eq(sk_word)]
            with m.If(en & emit):
                with m.If(o_free):
                    m.d.sync += [o_v.eq(1), o_unc.eq(1), o_last.eq(0), o_empty.eq(0),
                                 o_ray.eq(r3.ray), u_word.eq(new)]
                with m.Else():
                    m.d.sync += [sk_v.eq(1), sk_ray.eq(r3.ray), sk_word.eq(new)]
        # The ray to send is registered a cycle ahead (``s_*``, from the valid bits without
        # the one being sent), so the encoder tree ends in registers, not in the RAM's
        # address; the first cycle of a scan only primes them.
        primed = Signal()
        s_idx = Signal(max(1, (R - 1).bit_length()))
        s_only = Signal()
        s_any = Signal()
        sending = Signal(R)
        m.d.comb += sending.eq(Mux(primed & s_any,
                                   Cat(*[s_idx == k for k in range(R)]), 0))
        rest = Signal(R)
        m.d.comb += rest.eq(valid & ~sending)
        idx, only = lowest_set_tree(m, rest, R, "next")
        step = scanning & primed & (~o_v | self.o.ready)
        if certified:
            step = step & ~sk_v          # the run's passed-on pairs leave before its answers
        with m.If(scanning & (step | ~primed)):
            m.d.sync += [primed.eq(1), s_idx.eq(idx), s_only.eq(only), s_any.eq(rest != 0)]
        m.d.comb += [ar.addr.eq(Mux(scanning, s_idx, a2.ray)),
                     ar.en.eq(Mux(scanning, step & s_any, en))]
        with m.If(step):
            with m.If(o_v & o_last):
                m.d.sync += [scanning.eq(0), primed.eq(0), o_v.eq(0), cur_any.eq(0),
                             self.seq.eq(self.seq + 1)]
            with m.Elif(s_any):
                m.d.sync += [o_v.eq(1), o_ray.eq(s_idx), o_empty.eq(0), o_last.eq(s_only),
                             valid.bit_select(s_idx, 1).eq(0)]
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
