# amaranth: UnusedElaboratable=no
"""FPAdd and FPMul in Amaranth's simulator against the golden model, every bit and flag.

Large runs go through :class:`StreamHarness`: the stimulus (operands, ``sub``, ``i_valid``
and ``en`` for every clock) sits in a ROM that the harness reads one word per clock, and
every result the unit retires (``o_valid`` at an enabled edge) is written to a RAM with
the number of enabled edges seen so far. The testbench only runs the clock and reads the
RAM at the end, so Python stays out of the per-cycle loop. From the RAM the checks
assert that the unit retired exactly one result per accepted operation (``i_valid`` at an
enabled edge), in order, each ``latency`` enabled edges after its operation, with the
model's bits and flags. One smaller test drives the ports directly from the testbench
(``ctx.set`` / ``await ctx.tick()``) to cross-check the harness.
"""

import numpy as np
import pytest
from amaranth.back import rtlil, verilog
from amaranth.hdl import Cat, Elaboratable, Module, Signal
from amaranth.lib.memory import Memory
from amaranth.sim import Simulator

from raplas_hdl.fp import FP24, FPFormat, model
from raplas_hdl.rtl.fp_add import FPAdd
from raplas_hdl.rtl.fp_mul import FPMul
from raplas_hdl.rtl.pipeline import Delay, place_registers

E4M3 = FPFormat(4, 3)
EDGE_BITS = 32


# -- harness ------------------------------------------------------------------------------
class StreamHarness(Elaboratable):
    """One stimulus word per clock into ``dut``, every retired result into a RAM.

    Stimulus word, LSB first: ``a``, ``b``, ``sub``, ``i_valid``, ``en``. Result word:
    ``o``, ``flags``, enabled edges before the retiring edge.
    """

    def __init__(self, dut, words, capacity):
        self.dut = dut
        self.width = len(dut.a)
        self.stim = Memory(shape=2 * self.width + 3, depth=len(words), init=words)
        self.capacity = capacity
        self.results = Memory(shape=self.width + 3 + EDGE_BITS, depth=capacity, init=[])
        self.count = Signal(EDGE_BITS)

    def elaborate(self, platform):
        m = Module()
        dut, w = self.dut, self.width
        m.submodules.dut = dut
        m.submodules.stim = self.stim
        m.submodules.results = self.results
        addr = Signal(range(self.stim.depth))
        with m.If(addr != self.stim.depth - 1):
            m.d.sync += addr.eq(addr + 1)
        rd = self.stim.read_port(domain="comb")
        word = rd.data
        m.d.comb += [rd.addr.eq(addr), dut.a.eq(word[:w]), dut.b.eq(word[w:2 * w]),
                     dut.i_valid.eq(word[2 * w + 1]), dut.en.eq(word[2 * w + 2])]
        if hasattr(dut, "sub"):
            m.d.comb += dut.sub.eq(word[2 * w])
        edges = Signal(EDGE_BITS)
        with m.If(dut.en):
            m.d.sync += edges.eq(edges + 1)
        retire = dut.o_valid & dut.en
        wr = self.results.write_port()
        m.d.comb += [wr.addr.eq(self.count), wr.data.eq(Cat(dut.o, dut.flags, edges)),
                     wr.en.eq(retire & (self.count < self.capacity))]
        with m.If(retire):
            m.d.sync += self.count.eq(self.count + 1)
        return m


def simulate(dut, a, b, sub, valid, en):
    """Run per-cycle stimulus arrays through ``dut``; return the retired results.

    Returns
    -------
    (o, flags, edge) : numpy arrays, one element per retired result, in order.
    """
    w = len(dut.a)
    cols = [np.asarray(x, dtype=object) for x in (a, b, sub, valid, en)]
    words = (cols[0] | cols[1] << w | cols[2] << (2 * w) | cols[3] << (2 * w + 1)
             | cols[4] << (2 * w + 2))
    # Flush: enough enabled empty cycles to drain the pipeline.
    words = [int(x) for x in words] + [1 << (2 * w + 2)] * (dut.latency + 2)
    capacity = int(np.count_nonzero(np.asarray(valid) & np.asarray(en))) + 8
    h = StreamHarness(dut, words, capacity)
    got = {}

    async def testbench(ctx):
        await ctx.tick().repeat(len(words))
        n = ctx.get(h.count)
        got["count"] = n
        got["words"] = [ctx.get(h.results.data[i]) for i in range(min(n, capacity))]

    sim = Simulator(h)
    sim.add_clock(1e-6)
    sim.add_testbench(testbench)
    sim.run()
    r = np.array(got["words"], dtype=object)
    mask = (1 << w) - 1
    o = np.array([int(x) & mask for x in r], dtype=np.uint32)
    fl = np.array([(int(x) >> w) & 7 for x in r], dtype=np.uint8)
    edge = np.array([int(x) >> (w + 3) for x in r], dtype=np.int64)
    assert got["count"] == len(r), f"{got['count']} results retired, room for {capacity}"
    return o, fl, edge


def expected(op, a, b, sub, fmt):
    if op == "mul":
        return model.mul(a, b, fmt, flags=True)
    add_bits, add_fl = model.add(a, b, fmt, flags=True)
    sub_bits, sub_fl = model.sub(a, b, fmt, flags=True)
    sub = np.asarray(sub, dtype=bool)
    return np.where(sub, sub_bits, add_bits), np.where(sub, sub_fl, add_fl)


def schedule(rng, n_cycles, gap=0.0, stall=0.0):
    """Per-cycle ``i_valid`` and ``en`` with random gaps and stalls."""
    valid = (rng.random(n_cycles) >= gap).astype(np.int64)
    en = (rng.random(n_cycles) >= stall).astype(np.int64)
    return valid, en


def check_stream(dut, a, b, sub=None, *, rng=None, gap=0.0, stall=0.0):
    """Stream operand pairs through ``dut`` (one per accepted cycle) and check everything.

    Cycles that accept nothing (a gap or a stall) carry random operands, which must not
    reach the output.
    """
    fmt, op = dut.fmt, "mul" if isinstance(dut, FPMul) else "add"
    a = np.asarray(a, dtype=np.uint32)
    b = np.asarray(b, dtype=np.uint32)
    sub = np.zeros(len(a), dtype=np.uint32) if sub is None else np.asarray(sub, np.uint32)
    rng = rng or np.random.default_rng(0)
    # Enough cycles that every operation finds an accepting cycle.
    n_cycles = len(a)
    while True:
        valid, en = schedule(rng, n_cycles, gap, stall)
        accept = (valid & en).astype(bool)
        if accept.sum() >= len(a):
            break
        n_cycles += len(a) - int(accept.sum()) + 16
    last = np.nonzero(accept)[0][len(a) - 1]
    valid, en, accept = valid[:last + 1], en[:last + 1], accept[:last + 1]
    junk = rng.integers(0, 1 << fmt.width, size=(3, last + 1), dtype=np.uint32)
    ca, cb, cs = junk[0], junk[1], junk[2] & 1
    ca[accept], cb[accept], cs[accept] = a, b, sub
    o, fl, edge = simulate(dut, ca, cb, cs, valid, en)

    assert len(o) == len(a), f"{len(a)} operations accepted, {len(o)} results retired"
    accept_edge = (np.cumsum(en) - en)[accept]
    late = np.nonzero(edge != accept_edge + dut.latency)[0]
    assert not late.size, (f"result {late[0]} retired at enabled edge {edge[late[0]]}, "
                           f"expected {accept_edge[late[0]] + dut.latency}")
    want, want_fl = expected(op, a, b, sub, fmt)
    bad = np.nonzero((o != want) | (fl != want_fl))[0]
    if bad.size:
        lines = [f"  {op}{'-sub' if sub[i] else ''} a={a[i]:#x} b={b[i]:#x}: rtl "
                 f"{o[i]:#x}/{fl[i]} model {want[i]:#x}/{want_fl[i]}" for i in bad[:8]]
        pytest.fail(f"{fmt} stages={dut.stages}: {bad.size} of {len(a)} differ\n"
                    + "\n".join(lines))
    return want_fl


# -- case generators ----------------------------------------------------------------------
def special_values(fmt):
    """Signed zeros, denormal patterns, infinities, NaNs, range ends, significand patterns."""
    m, bias, top = fmt.man_bits, fmt.bias, fmt.exp_max_field
    fracs = sorted({0, 1, fmt.man_mask, fmt.man_mask - 1 if m > 1 else 0, 1 << (m - 1),
                    (1 << (m - 1)) - 1, 0x5555_5555 & fmt.man_mask, 0x3333_3333 & fmt.man_mask})
    exps = sorted({0, 1, 2, bias - 1, bias, bias + 1, top - 2, top - 1, top})
    vals = [(s << (fmt.width - 1)) | (e << m) | f for s in (0, 1) for e in exps for f in fracs]
    return np.array(vals, dtype=np.uint32)


def random_values(rng, fmt, n, spread):
    """Random patterns: half uniform bits, half with exponents within ``spread`` of 1.0."""
    u = rng.integers(0, 1 << fmt.width, size=n, dtype=np.uint64)
    e = rng.integers(max(1, fmt.bias - spread), min(fmt.exp_max_field - 1, fmt.bias + spread)
                     + 1, size=n, dtype=np.uint64)
    near = (u & np.uint64(fmt.sign_bit | fmt.man_mask)) | (e << np.uint64(fmt.man_bits))
    return np.where(rng.random(n) < 0.5, u, near).astype(np.uint32)


def stress_pairs(rng, fmt, op, n_random):
    """Pairs for one op: specials x specials, cancellation, alignment shifts, range ends."""
    m = fmt.man_bits
    sv = special_values(fmt)
    pa, pb = np.repeat(sv, sv.size), np.tile(sv, sv.size)
    keep = rng.random(pa.size) < min(1.0, 3000 / pa.size)
    # Every pair of the corner values: signed zeros, a denormal pattern, infinities, NaNs,
    # one, the largest finite and the smallest normal values.
    corners = np.array([v | s for v in (0, 1, fmt.inf, fmt.nan, fmt.inf | 1, fmt.one,
                                        fmt.max_finite, fmt.min_normal)
                        for s in (0, fmt.sign_bit)], dtype=np.uint32)
    parts_a = [pa[keep], np.repeat(corners, corners.size)]
    parts_b = [pb[keep], np.tile(corners, corners.size)]
    base = random_values(rng, fmt, n_random, 2 ** (fmt.exp_bits - 2))
    parts_a.append(base)
    parts_b.append(random_values(rng, fmt, n_random, 2 ** (fmt.exp_bits - 2)))
    if op == "add":
        x = random_values(rng, fmt, 600, 4)
        x = x & np.uint32(fmt.mask ^ (fmt.exp_max_field << m)) | np.uint32(fmt.bias << m)
        # Cancellation: the same magnitude +- a few ulps, opposite sign.
        delta = rng.integers(-3, 4, size=x.size).astype(np.int64)
        y = (x.astype(np.int64) + delta) ^ fmt.sign_bit
        parts_a.append(x)
        parts_b.append(y.astype(np.uint32))
        # Alignment: exponent differences 0 .. M+5 (just below, at and beyond guard bits).
        d = rng.integers(0, m + 6, size=x.size).astype(np.uint32)
        y = (x - (d << np.uint32(m))) ^ np.where(rng.random(x.size) < 0.5, fmt.sign_bit, 0)
        parts_a.append(x)
        parts_b.append(y.astype(np.uint32))
        # Near overflow and underflow: large same-sign sums, differences near min normal.
        big = (np.uint32(fmt.exp_max_field - 1) << np.uint32(m)) | rng.integers(
            0, fmt.man_mask + 1, size=300, dtype=np.uint32)
        small = (np.uint32(1 + rng.integers(0, 3, size=300, dtype=np.uint32)) << np.uint32(m)
                 ) | rng.integers(0, fmt.man_mask + 1, size=300, dtype=np.uint32)
        parts_a += [big, small]
        parts_b += [big[::-1], (small[::-1] ^ np.uint32(fmt.sign_bit))]
    else:
        # Products whose exponents land near the top and the bottom of the range.
        for target in (fmt.exp_max_field - 1, fmt.exp_max_field, 0, 1):
            ea = rng.integers(1, fmt.exp_max_field, size=300).astype(np.int64)
            eb = np.clip(target + fmt.bias - ea + rng.integers(-1, 2, size=300), 1,
                         fmt.exp_max_field - 1)
            fr = rng.integers(0, fmt.man_mask + 1, size=(2, 300), dtype=np.int64)
            sg = rng.integers(0, 2, size=(2, 300), dtype=np.int64) << (fmt.width - 1)
            parts_a.append((sg[0] | ea << m | fr[0]).astype(np.uint32))
            parts_b.append((sg[1] | eb << m | fr[1]).astype(np.uint32))
    a = np.concatenate(parts_a) & np.uint32(fmt.mask)
    b = np.concatenate(parts_b) & np.uint32(fmt.mask)
    order = rng.permutation(a.size)
    return a[order], b[order]


def all_pairs(fmt):
    values = np.arange(1 << fmt.width, dtype=np.uint32)
    return np.repeat(values, values.size), np.tile(values, values.size)


def make(op, fmt, stages=None):
    cls = FPAdd if op == "add" else FPMul
    return cls(fmt) if stages is None else cls(fmt, stages=stages)


# -- tests: every pair of E=4/M=3 ----------------------------------------------------------
@pytest.mark.parametrize("op,rounding", [("add", "rne"), ("add", "chop"), ("mul", "rne")])
def test_e4m3_every_pair(op, rounding):
    """All 65,536 pairs in one simulation run (``sub`` random for the adder), light
    gaps and stalls on top."""
    fmt = E4M3.with_rounding(rounding)
    rng = np.random.default_rng(1)
    a, b = all_pairs(fmt)
    sub = rng.integers(0, 2, size=a.size) if op == "add" else None
    flags = check_stream(make(op, fmt), a, b, sub, rng=rng, gap=0.02, stall=0.02)
    # The run must have exercised every event.
    assert {1, 2, 4} <= set(np.unique(flags).tolist())


@pytest.mark.parametrize("op,rounding", [("add", "rtz"), ("mul", "rtz"), ("mul", "chop")])
def test_e4m3_random(op, rounding):
    fmt = E4M3.with_rounding(rounding)
    rng = np.random.default_rng(2)
    a, b = all_pairs(fmt)
    pick = rng.choice(a.size, size=6000, replace=False)
    sub = rng.integers(0, 2, size=pick.size) if op == "add" else None
    check_stream(make(op, fmt), a[pick], b[pick], sub, rng=rng, gap=0.1, stall=0.1)


# -- tests: FP24 --------------------------------------------------------------------------
@pytest.mark.parametrize("rounding", ["rtz", "rne", "chop"])
@pytest.mark.parametrize("op", ["add", "mul"])
def test_fp24_stress(op, rounding):
    """Specials, cancellation, alignment, range ends and random, with gaps and stalls."""
    fmt = FP24.with_rounding(rounding)
    rng = np.random.default_rng(3)
    a, b = stress_pairs(rng, fmt, op, 2500)
    sub = rng.integers(0, 2, size=a.size) if op == "add" else None
    flags = check_stream(make(op, fmt), a, b, sub, rng=rng, gap=0.2, stall=0.2)
    assert {1, 2, 4} <= set(np.unique(flags).tolist())


@pytest.mark.parametrize("op,stages", [("add", 1), ("add", 2), ("add", 4), ("add", 9),
                                       ("mul", 1), ("mul", 2), ("mul", 4), ("mul", 5)])
def test_fp24_depths(op, stages):
    """Other depths give the same results, with ``latency`` equal to ``stages``."""
    fmt = FP24.with_rounding("rne")
    rng = np.random.default_rng(4)
    a, b = stress_pairs(rng, fmt, op, 300)
    a, b = a[:1500], b[:1500]
    sub = rng.integers(0, 2, size=a.size) if op == "add" else None
    dut = make(op, fmt, stages)
    assert dut.latency == stages
    check_stream(dut, a, b, sub, rng=rng, gap=0.3, stall=0.3)


@pytest.mark.parametrize("exp_bits,man_bits,rounding", [
    (2, 1, "rne"), (2, 29, "chop"), (3, 2, "rtz"), (5, 10, "rne"), (8, 23, "rne"),
    (11, 20, "chop"), (6, 13, "rtz")])
@pytest.mark.parametrize("op", ["add", "mul"])
def test_other_formats(op, exp_bits, man_bits, rounding):
    fmt = FPFormat(exp_bits, man_bits, rounding)
    rng = np.random.default_rng(5)
    a, b = stress_pairs(rng, fmt, op, 200)
    a, b = a[:700], b[:700]
    sub = rng.integers(0, 2, size=a.size) if op == "add" else None
    check_stream(make(op, fmt), a, b, sub, rng=rng, gap=0.1, stall=0.1)


def test_direct_drive():
    """Ports driven from the testbench, cycle by cycle, with gaps and stalls: results
    come out in order, once each, ``latency`` enabled edges after their inputs."""
    fmt = FP24.with_rounding("rne")
    rng = np.random.default_rng(6)
    dut = FPAdd(fmt)
    a, b = stress_pairs(rng, fmt, "add", 100)
    a, b = a[:400], b[:400]
    sub = rng.integers(0, 2, size=a.size)
    want, want_fl = expected("add", a, b, sub, fmt)
    got, sent = [], []

    async def testbench(ctx):
        i, edge = 0, 0
        while len(got) < len(a):
            en, valid = int(rng.random() > 0.25), int(rng.random() > 0.25 and i < len(a))
            j = min(i, len(a) - 1)
            ctx.set(dut.en, en)
            ctx.set(dut.i_valid, valid)
            ctx.set(dut.a, int(a[j]) if valid else int(rng.integers(1 << fmt.width)))
            ctx.set(dut.b, int(b[j]))
            ctx.set(dut.sub, int(sub[j]))
            if en and ctx.get(dut.o_valid):
                got.append((ctx.get(dut.o), ctx.get(dut.flags), edge))
            if en and valid:
                sent.append(edge)
                i += 1
            edge += en
            await ctx.tick()

    sim = Simulator(dut)
    sim.add_clock(1e-6)
    sim.add_testbench(testbench)
    sim.run()
    assert [(int(x), int(f)) for x, f in zip(want, want_fl)] == [g[:2] for g in got]
    assert [e + dut.latency for e in sent] == [g[2] for g in got]


def test_stall_holds_outputs():
    """With ``en`` low the outputs do not change and nothing is taken in."""
    fmt = FP24
    dut = FPMul(fmt)
    one, two = fmt.one, fmt.one + (1 << fmt.man_bits)
    trace = []

    async def testbench(ctx):
        ctx.set(dut.en, 1)
        ctx.set(dut.i_valid, 1)
        ctx.set(dut.a, two)
        ctx.set(dut.b, two)
        await ctx.tick()
        ctx.set(dut.i_valid, 0)
        for _ in range(dut.latency - 1):
            await ctx.tick()
        ctx.set(dut.en, 0)
        ctx.set(dut.i_valid, 1)
        ctx.set(dut.a, one)
        ctx.set(dut.b, one)
        for _ in range(5):
            trace.append((ctx.get(dut.o_valid), ctx.get(dut.o)))
            await ctx.tick()
        ctx.set(dut.en, 1)
        ctx.set(dut.i_valid, 0)
        await ctx.tick()
        trace.append((ctx.get(dut.o_valid), ctx.get(dut.o)))

    sim = Simulator(dut)
    sim.add_clock(1e-6)
    sim.add_testbench(testbench)
    sim.run()
    four = fmt.one + (2 << fmt.man_bits)
    assert trace == [(1, four)] * 5 + [(0, four)]


# -- tests: structure, parameters, emission -----------------------------------------------
def test_default_stage_lists():
    """The stages the measured step delays give (raplas_hdl.rtl.step_delays)."""
    assert FPAdd(FP24).stage_steps == (("classify",), ("order", "align"), ("shift", "add"),
                                       ("lzc",), ("normalise", "round"), ("pack",))
    assert FPMul(FP24).stage_steps == (("unpack",), ("multiply",), ("normalise", "round"),
                                       ("pack",))
    assert FPAdd(FP24).latency == 6 and FPMul(FP24).latency == 4
    rne = FP24.with_rounding("rne")
    assert FPAdd(rne).latency == 7 and FPMul(rne).latency == 5
    assert FPMul(rne).stage_steps == (("unpack",), ("multiply",), ("normalise",), ("round",),
                                      ("pack",))
    assert FPAdd(FP24, stages=9).stage_steps == tuple((n,) for n in
                                                      ("classify", "order", "align", "shift",
                                                       "add", "lzc", "normalise", "round",
                                                       "pack"))
    assert len(FPMul(FP24, stages=1).stage_steps) == 1


def test_default_stages_meet_the_target():
    """Every default stage count is the fewest whose predicted slowest stage meets
    TARGET_NS, by the measured step delays."""
    from raplas_hdl.rtl.step_delays import (DEFAULT_STAGES, STEP_NS, TARGET_NS,
                                            stage_delays)

    for unit, cls in (("fp_add", FPAdd), ("fp_mul", FPMul)):
        for rounding in STEP_NS[unit]:
            fmt = FP24.with_rounding(rounding)
            n = DEFAULT_STAGES[unit][rounding]
            assert cls(fmt).stages == n
            assert max(stage_delays(unit, rounding, cls(fmt).stage_steps)) <= TARGET_NS
            if n > 1:
                fewer = cls(fmt, stages=n - 1).stage_steps
                assert max(stage_delays(unit, rounding, fewer)) > TARGET_NS


@pytest.mark.parametrize("cls,bad", [(FPAdd, 0), (FPAdd, 10), (FPMul, 0), (FPMul, 6),
                                     (FPAdd, "4"), (FPMul, True), (FPMul, 2.0)])
def test_bad_stages(cls, bad):
    with pytest.raises(ValueError, match="stages"):
        cls(FP24, stages=bad)


@pytest.mark.parametrize("cls", [FPAdd, FPMul])
def test_bad_format(cls):
    with pytest.raises(ValueError, match="fmt"):
        cls((7, 16))


def test_place_registers():
    assert place_registers([1, 1, 1, 1], 2) == (1, 3)
    assert place_registers([5, 1, 1, 1, 1, 1], 2) == (0, 5)
    assert place_registers([2, 2], 1) == (1,)
    with pytest.raises(ValueError, match="stages"):
        place_registers([1, 2, 3], 4)


def test_delay():
    d = Delay(8, 3)
    assert d.latency == 3
    seen = []

    async def testbench(ctx):
        for i, en in enumerate([1, 1, 0, 1, 1, 0, 0, 1, 1, 1]):
            ctx.set(d.i, i + 1)
            ctx.set(d.en, en)
            await ctx.tick()
            seen.append(ctx.get(d.o))

    sim = Simulator(d)
    sim.add_clock(1e-6)
    sim.add_testbench(testbench)
    sim.run()
    # Inputs taken at enabled edges: 1, 2, 4, 5, 8, 9, 10; each leaves 3 enabled edges later.
    assert seen == [0, 0, 0, 1, 2, 2, 2, 4, 5, 8]
    with pytest.raises(ValueError, match="cycles"):
        Delay(8, -1)


def test_one_multiplier():
    """The multiplier has exactly one multiply (the significand product), the adder none."""
    mul_text = rtlil.convert(FPMul(FP24))
    add_text = rtlil.convert(FPAdd(FP24))
    assert mul_text.count("cell $mul ") == 1
    assert add_text.count("cell $mul ") == 0


@pytest.mark.parametrize("cls,name", [(FPAdd, "fp_add"), (FPMul, "fp_mul")])
def test_verilog(cls, name):
    text = verilog.convert(cls(FP24), name=name)
    assert f"module {name}" in text
    for port in ("a", "b", "i_valid", "en", "o", "flags", "o_valid", "clk", "rst"):
        assert f" {port};" in text or f" {port}," in text or f"{port}\n" in text, port
