"""What every unit's co-simulation shares: :class:`UnitCosim`, the comparison of
every output field, the units' Verilog (cached on disk by the RTL sources) and the batch
harness run."""

from __future__ import annotations

import hashlib
import os

import numpy as np

from raplas_hdl.rtl.emit import emit_verilog
from raplas_hdl.rtl.units import build_unit

from ..build.runner import BUILD_ROOT
from ..build.sources import rtl_sources_digest
from .vectors import read_lines, write_lines

#: Sphere IDs of the plane-sphere array (its default).
SPHERE_ID_BITS = 16
#: Ray and triangle IDs of the ray-triangle unit (its defaults).
RT_ID_BITS = 16


def as_u64(x) -> np.ndarray:
    return np.asarray(x).astype(np.uint64)


def compare(expected: dict, got: dict, names) -> np.ndarray:
    """Indices of the cases where any field of ``names`` differs."""
    n = len(expected[names[0]])
    bad = np.zeros(n, bool)
    for k in names:
        g = as_u64(got[k])
        if g.shape[0] != n:
            raise AssertionError(f"{g.shape[0]} results of {k} for {n} cases")
        bad |= g != as_u64(expected[k])
    return np.flatnonzero(bad)


# -- Verilog text, cached per source version ---------------------------------------------------
def unit_verilog(unit: str, fmt, options: dict, module: str) -> tuple[str, int]:
    """``(verilog, latency)`` of a registered unit (:func:`raplas_hdl.rtl.units.build_unit`)
    with ``options``; cached on disk by the parameters and the RTL sources. With
    ``target="virtex4"`` Yosys's DSP48 model is appended."""
    opts = {k: v for k, v in options.items() if v is not None}
    key = hashlib.sha256(repr((unit, fmt.name, sorted(opts.items()), rtl_sources_digest()))
                         .encode()).hexdigest()[:16]
    path = BUILD_ROOT / "verilog" / f"cosim-{module}-{key}.v"
    meta = path.with_suffix(".latency")
    if path.exists() and meta.exists():
        text, latency = path.read_text(), int(meta.read_text())
    else:
        _, comp, used = build_unit(unit, fmt, **opts)
        params = {"exp_bits": fmt.exp_bits, "man_bits": fmt.man_bits,
                  "rounding": fmt.rounding, **used}
        text, _ = emit_verilog(comp, module, params)
        latency = int(comp.latency)
        path.parent.mkdir(parents=True, exist_ok=True)
        for p, content in ((path, text), (meta, str(latency))):
            tmp = p.with_suffix(p.suffix + f".{os.getpid()}.tmp")
            tmp.write_text(content)
            os.replace(tmp, p)
    if "virtex4" in (opts.get("target"), opts.get("adder")):
        # lazy: rtl.dsp48 loads Amaranth; importing raplas_hdl.sim.cosim needs none
        from raplas_hdl.rtl.dsp48 import dsp48_sim_model

        text += "\n" + dsp48_sim_model()
    return text, latency


# -- the units ---------------------------------------------------------------------------------
class UnitCosim:
    """A unit under co-simulation.

    Parameters
    ----------
    fmt : FPFormat
    options : dict
        The unit's options as ``raplas-hdl verilog`` takes them (None: the default).

    Attributes
    ----------
    kinds : tuple of LineKind
        The line kinds of its vectors file.
    outputs : tuple of str
        The output fields compared with the model.
    header_params : dict
        Build parameters a vectors file's header must agree with.
    """

    name = ""
    kinds: tuple = ()
    outputs: tuple = ()
    percycle_only = False

    def __init__(self, fmt, options: dict):
        self.fmt = fmt
        self.options = {k: v for k, v in options.items() if v is not None}
        self.target = self.options.get("target", "generic")
        self.adder = self.options.get("adder", "generic")
        # build-cache tag of the DSP48 choices (the adder only when not generic)
        self.targets = self.target + ("" if self.adder == "generic" else f"-add-{self.adder}")
        self.header_params = {}

    # the interface
    def random(self, n: int, seed: int) -> dict:
        raise NotImplementedError

    def expected(self, cases: dict) -> dict:
        raise NotImplementedError

    def from_items(self, items) -> tuple[dict, dict]:
        raise NotImplementedError

    def blocks(self, cases: dict, expected: dict):
        raise NotImplementedError

    def simulate(self, cases, simulator, *, valid_density, stall_density, seed,
                 timeout_s=None) -> tuple[dict, dict]:
        raise NotImplementedError

    def n_cases(self, cases: dict) -> int:
        return len(cases[self.kinds[-1].fields[0][0]])

    def describe(self, cases: dict, i: int) -> str:
        """The inputs of case ``i``, one line."""
        names = [n for n, _ in self.kinds[-1].fields if n not in self.outputs]
        return " ".join(f"{n}={int(cases[n][i]):x}" for n in names if n in cases)

    # shared
    def read(self, path) -> tuple[dict, dict]:
        """``(cases, expected)`` of a vectors file, checked whole."""
        items = read_lines(path, self.name, self.kinds, self.fmt, self.header_params)
        return self.from_items(path, items)

    def write(self, path, cases: dict, expected: dict) -> None:
        write_lines(path, self.name, self.fmt, self.header_params, self.kinds,
                    self.blocks(cases, expected))

    def show(self, cases, expected, got, i: int) -> list[str]:
        """Case ``i`` field by field (inputs, then each output expected/got)."""
        lines = [f"  case {i}: {self.describe(cases, i)}"]
        for k in self.outputs:
            e, g = int(as_u64(expected[k])[i]), int(as_u64(got[k])[i])
            mark = "   <- differs" if e != g else ""
            lines.append(f"    {k:12s} expected {e:x}, got {g:x}{mark}")
        return lines


def cosim_key(*parts) -> str:
    return "cosim-" + "-".join(str(p) for p in parts if p is not None)
