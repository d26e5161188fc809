"""FPAdd and FPMul as Verilog under cocotb, Icarus and Verilator, against the golden model.

Every output bit and flag is compared. One simulator build per (format, simulator) holds
all roundings of both units (:func:`raplas_hdl.sim.cosim.fp.fp_bundle`) and is reused by the
batch and per-cycle tests (and across pytest-xdist workers). A missing simulator fails these tests
with a message saying what to install; it is never a skip.
"""

import numpy as np
import pytest

from raplas_hdl.sim.build.harness import run_batch, run_percycle
from raplas_hdl.sim.build.runner import require_simulator
from raplas_hdl.sim.cosim.fp import check_bundle, fp_bundle, fp_expected
from tests.support.fp_vectors import fp24_vectors

SIMS = ("icarus", "verilator")

_BUNDLES = {}


def bundle(exp_bits, man_bits, roundings=("rtz", "rne", "chop")):
    key = (exp_bits, man_bits, roundings)
    if key not in _BUNDLES:
        _BUNDLES[key] = fp_bundle(exp_bits, man_bits, roundings)
    return _BUNDLES[key]


def check_batch(simulator, exp_bits, man_bits, a, b, sub, valid_density, stall_density, seed,
                roundings=("rtz", "rne", "chop")):
    require_simulator(simulator)
    spec, verilog, units = bundle(exp_bits, man_bits, roundings)
    out, info = run_batch(simulator, spec, verilog,
                          f"fp_bundle-e{exp_bits}m{man_bits}-{'-'.join(roundings)}",
                          {"a": a, "b": b, "sub": sub}, valid_density, stall_density, seed,
                          timeout_s=600)
    msgs = check_bundle(units, out, a, b, sub)
    assert not msgs, f"{simulator}:\n" + "\n".join(msgs)
    return info


@pytest.mark.parametrize("simulator", SIMS)
def test_fp24_batch_all_roundings(simulator):
    n = 100_000 if simulator == "verilator" else 3_000
    a, b, sub = fp24_vectors(n, seed=24)
    info = check_batch(simulator, 7, 16, a, b, sub, valid_density=0.7, stall_density=0.2,
                       seed=5)
    assert info["cycles"] > a.size   # gaps and stalls happened


@pytest.mark.parametrize("simulator", SIMS)
def test_e4m3_every_pair_batch(simulator):
    """Every operand pair: Verilator in all roundings, add and subtract (131,072 vectors);
    Icarus (about 30x slower) in ``rtz``, add and multiply (65,536)."""
    x = np.arange(256, dtype=np.uint32)
    ga, gb = np.meshgrid(x, x)
    if simulator == "verilator":
        a = np.concatenate([ga.ravel(), ga.ravel()]).astype(np.uint32)
        b = np.concatenate([gb.ravel(), gb.ravel()]).astype(np.uint32)
        sub = np.repeat(np.array([0, 1], dtype=np.uint32), 65536)
        roundings = ("rtz", "rne", "chop")
    else:
        a, b = ga.ravel().astype(np.uint32), gb.ravel().astype(np.uint32)
        sub = np.zeros(a.size, dtype=np.uint32)
        roundings = ("rtz",)
    check_batch(simulator, 4, 3, a, b, sub, valid_density=0.9, stall_density=0.1, seed=7,
                roundings=roundings)


@pytest.mark.parametrize("simulator", SIMS)
def test_fp24_percycle_driver(simulator):
    require_simulator(simulator)
    a, b, sub = fp24_vectors(200, seed=3)
    spec, verilog, units = bundle(7, 16)
    out, info = run_percycle(simulator, spec, verilog, "fp_bundle-e7m16-rtz-rne-chop",
                             {"a": a, "b": b, "sub": sub}, idle=0.3, stall=0.25, seed=11,
                             timeout_s=600)
    msgs = check_bundle(units, out, a, b, sub)
    assert not msgs, f"{simulator}:\n" + "\n".join(msgs)
    assert info["cycles"] > a.size


def test_harness_detects_a_wrong_result():
    """The comparison can fail: a corrupted output beat is reported, naming the unit."""
    spec, verilog, units = bundle(4, 3)
    a = np.arange(64, dtype=np.uint32)
    b = np.full(64, 0x38, dtype=np.uint32)
    sub = np.zeros(64, dtype=np.uint32)
    out = {"valids": np.full(64, (1 << len(units)) - 1)}
    for suffix, (op, fmt) in units.items():
        out[f"o_{suffix}"], out[f"f_{suffix}"] = fp_expected(op, fmt, a, b, sub)
    assert check_bundle(units, out, a, b, sub) == []
    out["o_mul_rne"] = out["o_mul_rne"].copy()
    out["o_mul_rne"][17] ^= 1
    msgs = check_bundle(units, out, a, b, sub)
    assert len(msgs) == 1 and "fp-mul e4m3-rne: 1 of 64" in msgs[0]
