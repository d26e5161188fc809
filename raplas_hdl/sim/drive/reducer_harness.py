"""Co-simulation of the reducer alone (:class:`raplas_hdl.rtl.unit.reducer.Reducer`) in the
batch harness (:mod:`raplas_hdl.sim.build.harness`), Icarus or Verilator, against
:func:`raplas_hdl.model.reduction.reduce_run`.

The harness has one input stream; :class:`ReducerTop` makes it the reducer's three inputs:
each input word is a ``kind`` and a payload, ``kind`` 0 a ``RESULT`` beat (to ``i``), 1 a
host write (``addr``, ``data``: the window of a bank), 2 a run's bank (to ``run_bank``).
:func:`stimulus` orders them as the intersection unit would: per run, the bank's window
writes, the bank, then the beats; runs alternate banks.
"""

from __future__ import annotations

import numpy as np
from amaranth.hdl import Module
from amaranth.lib import data, stream, wiring
from amaranth.lib.wiring import In, Out

from raplas_hdl.model.config import UnitConfig
from raplas_hdl.model.memory_image import REGIONS, bundle_writes
from raplas_hdl.model.records import answer_record, result_record
from raplas_hdl.model.reduction import reduce_run
from raplas_hdl.rtl.emit import emit_verilog
from raplas_hdl.rtl.unit.reducer import Reducer, answer_layout
from raplas_hdl.sim.build.harness import HarnessSpec, run_unit_batch, words64

__all__ = ["ReducerTop", "stimulus", "expected", "cosim_reducer"]

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
