"""Co-simulation of the reducer alone (:class:`raplas_hdl.rtl.unit.reducer.Reducer`) in the
batch harness (:mod:`raplas_hdl.sim.build.harness`), Icarus or Verilator, against
:func:`raplas_hdl.model.reduction.reduce_run`.

The harness has one input stream; :class:`ReducerTop` makes it the reducer's three inputs:
each input word is a ``kind`` and a payload, ``kind`` 0 a ``RESULT`` beat (to ``i``), 1 a
host write (``addr``, ``data``: the window of a bank), 2 a run's bank (to ``run_bank``).
:func:`stimulus` orders them as the intersection unit would: per run, the bank's window
writes, the bank, then the beats; runs alternate banks. :func:`random_runs` makes
adversarial runs for it (and for the reduction's model tests).
"""

from __future__ import annotations

import numpy as np
from amaranth.hdl import Module
from amaranth.lib import data, stream, wiring
from amaranth.lib.wiring import In, Out

from raplas_hdl.fp import model as fpm
from raplas_hdl.model.config import UnitConfig
from raplas_hdl.model.intersection import RESULT_DTYPE
from raplas_hdl.model.memory_image import REGIONS, BundleMemory, bundle_writes
from raplas_hdl.model.records import answer_record, result_record
from raplas_hdl.model.reduction import inf_pattern, reduce_run
from raplas_hdl.rtl.emit import emit_verilog
from raplas_hdl.rtl.unit.reducer import Reducer, answer_layout
from raplas_hdl.sim.build.harness import HarnessSpec, run_unit_batch, words64

__all__ = ["ReducerTop", "stimulus", "expected", "cosim_reducer", "random_runs",
           "random_beats", "window_bundle"]

KIND_BEAT, KIND_WRITE, KIND_RUN = range(3)


def _word_layout(cfg: UnitConfig) -> data.StructLayout:
    return data.StructLayout({"kind": 2, "body": max(result_record(cfg).bind(cfg).size, 64)})


class ReducerTop(wiring.Component):
    """The reducer behind one input stream (see the module docstring)."""

    def __init__(self, config: UnitConfig, ram: str = "memory"):
        self._cfg, self._ram = config, ram
        super().__init__({"i": In(stream.Signature(_word_layout(config))),
                          "o": Out(stream.Signature(answer_layout(config)))})

    def elaborate(self, platform):
        m = Module()
        m.submodules.red = red = Reducer(self._cfg, ram=self._ram)
        w = self.i.payload
        kind = w.kind
        m.d.comb += [red.i.payload.eq(w.body), red.i.valid.eq(self.i.valid & (kind == 0)),
                     red.run_bank.payload.eq(w.body[0]),
                     red.run_bank.valid.eq(self.i.valid & (kind == KIND_RUN)),
                     red.wr_en.eq(self.i.valid & (kind == KIND_WRITE)),
                     red.wr_addr.eq(w.body[:32]), red.wr_data.eq(w.body[32:64])]
        with m.Switch(kind):
            with m.Case(KIND_BEAT):
                m.d.comb += self.i.ready.eq(red.i.ready)
            with m.Case(KIND_RUN):
                m.d.comb += self.i.ready.eq(red.run_bank.ready)
            with m.Default():
                m.d.comb += self.i.ready.eq(1)
        wiring.connect(m, red.o, wiring.flipped(self.o))
        return m


def _window_writes(cfg, bundle, bank):
    addr, dat = bundle_writes(cfg, bundle, bank)
    region = addr >> 28
    fld = addr & 15
    keep = (region == REGIONS["window"]) | ((region == REGIONS["ray"]) & (fld == 7))
    return addr[keep], dat[keep]


def stimulus(cfg: UnitConfig, runs) -> np.ndarray:
    """Input words (Python ints) for ``runs``: a list of ``(beats, bundle)``."""
    res = result_record(cfg).bind(cfg)
    words = []
    for k, (beats, bundle) in enumerate(runs):
        bank = k % 2
        addr, dat = _window_writes(cfg, bundle, bank)
        words += [KIND_WRITE | (int(a) | int(d) << 32) << 2 for a, d in zip(addr, dat)]
        words.append(KIND_RUN | bank << 2)
        words += [KIND_BEAT | x << 2 for x in res.pack(beats)]
    return words


def expected(cfg: UnitConfig, runs) -> np.ndarray:
    """The model's answers of ``runs``, concatenated."""
    return np.concatenate([reduce_run(cfg, beats, bundle) for beats, bundle in runs])


def cosim_reducer(simulator: str, cfg: UnitConfig, runs, *, seed: int = 1,
                  valid_density: float = 0.8, stall_density: float = 0.3,
                  build_key: str = "reducer"):
    """Run ``runs`` through the reducer's Verilog; return ``(got, want, info)``: the answers
    (structured arrays of ``ANSWER``, ``ANSWER_CERTIFIED`` in certified mode) of the RTL and
    of the model."""
    top = ReducerTop(cfg)
    text, _ = emit_verilog(top, "reducer_top", cfg.params())
    width = _word_layout(cfg).size
    ans = answer_record(cfg).bind(cfg)
    spec = HarnessSpec(dut="reducer_top", inputs=[("i__payload", width)],
                       outputs=[("o__payload", ans.size)], i_valid="i__valid",
                       o_valid="o__valid", i_ready="i__ready", o_ready="o__ready")
    want = expected(cfg, runs)
    ints = stimulus(cfg, runs)
    n32 = (width + 31) // 32
    col = np.array([[(x >> (32 * k)) & 0xFFFFFFFF for k in range(n32)] for x in ints],
                   np.uint32)
    out, info = run_unit_batch(simulator, spec, text, build_key, {"i__payload": col},
                               valid_density, stall_density, seed, n_out=want.size)
    got = ans.unpack_words(words64(out["o__payload"], ans.size))
    return got, want, info


# -- random runs ------------------------------------------------------------------------------
def window_bundle(cfg: UnitConfig, **window) -> BundleMemory:
    """A bundle of zero planes and rays with the window ``window`` (tmin, tmax, exclude,
    any_hit)."""
    z3 = np.zeros((cfg.n_rays, 3), np.uint32)
    return BundleMemory(np.zeros((cfg.n_planes, 3), np.uint32),
                        np.zeros(cfg.n_planes, np.uint32), z3, z3.copy(), **window)


def random_beats(rng, n: int, cfg: UnitConfig) -> np.ndarray:
    """Result beats with random and deliberately tied ratios t'/det (3/6 = 1/2, scaled by
    powers of two), some a few ulps off a tie, signs, zeros, infinities and NaNs, tri IDs
    with repeats."""
    fmt = cfg.fmt
    b = np.zeros(n, RESULT_DTYPE)
    b["ray_id"] = rng.integers(0, cfg.n_rays, n)
    b["tri_id"] = rng.integers(0, 12, n)
    b["hit"] = rng.random(n) < 0.8
    t = rng.uniform(-0.5, 4.0, n)
    det = rng.choice([-1.0, 1.0], n) * rng.uniform(0.01, 2.0, n)
    # ties: t'/det = a/b for small a, b, times a power of two
    k = rng.random(n) < 0.4
    num, den = rng.integers(1, 6, n), rng.integers(1, 4, n)
    mult = rng.integers(1, 4, n) * 2.0 ** rng.integers(-3, 3, n)
    sgn = rng.choice([-1.0, 1.0], n)
    t = np.where(k, sgn * num * mult, t)
    det = np.where(k, sgn * den * mult, det)
    bits_t = fpm.encode(t, fmt)
    bits_d = fpm.encode(det, fmt)
    # near ties: a few ulps off a tie (the certified reduction passes such hits on)
    off = (rng.random(n) < 0.15) & k
    frac = bits_t & fmt.man_mask
    bits_t = np.where(off & (frac > 8) & (frac < fmt.man_mask - 8),
                      bits_t.astype(np.int64) + rng.integers(-3, 4, n), bits_t).astype(np.uint32)
    special = rng.random(n)
    inf = inf_pattern(fmt)
    bits_t = np.where(special < 0.02, inf, bits_t)
    bits_d = np.where((special > 0.02) & (special < 0.04), 0, bits_d)
    bits_t = np.where((special > 0.04) & (special < 0.05), inf | 1, bits_t)
    bits_t = np.where((special > 0.05) & (special < 0.06), 0, bits_t)
    b["t"], b["det"] = bits_t, bits_d
    b["u"], b["v"] = rng.integers(0, fmt.mask, n), rng.integers(0, fmt.mask, n)
    b["flags"] = rng.integers(0, 8, n)
    b["last"][-1] = 1
    return b


def random_runs(cfg: UnitConfig, n_runs: int, seed: int, beats_per_run: int = 40) -> list:
    """``n_runs`` (beats, bundle) runs for the reducer: random beats (:func:`random_beats`),
    a run that issued no pair and one without a hit every seven, random windows, nearest-hit
    and any-hit runs alternating."""
    fmt = cfg.fmt
    rng = np.random.default_rng(seed)
    runs = []
    for k in range(n_runs):
        kind = k % 7
        if kind == 5:                       # a run that issued no pair
            beats = np.zeros(1, RESULT_DTYPE)
            beats["last"] = beats["empty"] = 1
        else:
            beats = random_beats(rng, int(rng.integers(1, beats_per_run)), cfg)
            if kind == 6:                   # pairs, but no hit
                beats["hit"] = 0
        tmax = fpm.encode(rng.uniform(0.5, 6.0, cfg.n_rays), fmt)
        tmax[rng.random(cfg.n_rays) < 0.3] = inf_pattern(fmt)
        tmin = int(fpm.encode(np.array([rng.choice([0.0, -1.0, 0.3])]), fmt)[0])
        bundle = window_bundle(cfg, tmin=tmin, tmax=tmax, exclude=int(rng.integers(-1, 12)),
                               any_hit=bool(k % 2))
        runs.append((beats, bundle))
    return runs
