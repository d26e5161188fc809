"""What every unit's co-simulation shares: :class:`UnitCosim`, the comparison of
every output field (:func:`compare`; a run's result beats, :func:`beat_lines`) and the units'
Verilog (cached on disk by the RTL sources)."""

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
    driver : str
        One of :attr:`drivers`: ``"batch"`` (the harness at full clock rate) or, for the
        units that have one, ``"percycle"`` (the cocotb driver).

    Attributes
    ----------
    kinds : tuple of LineKind
        The line kinds of its vectors file.
    outputs : tuple of str
        The output fields shown, field by field, for a case that differs.
    compared : tuple of str
        The fields compared with the model (default :attr:`outputs`; a field the expected
        results leave at None is not compared).
    header_params : dict
        Build parameters a vectors file's header must agree with.
    harness : str
        How the run is named in ``raplas-hdl cosim``'s first line.
    case_name : str
        What a case is, plural (``"cases"``, or ``"runs"`` for the units fed runs).

    Raises
    ------
    ValueError
        A driver the unit does not have.
    """

    name = ""
    kinds: tuple = ()
    outputs: tuple = ()
    drivers = ("batch",)
    harness = "batch harness"
    case_name = "cases"

    def __init__(self, fmt, options: dict, driver: str = "batch"):
        if driver not in self.drivers:
            raise ValueError(f"{self.name} runs under the driver {' or '.join(self.drivers)}, "
                             f"not {driver!r}")
        self.fmt = fmt
        self.driver = driver
        self.options = {k: v for k, v in options.items() if v is not None}
        self.compared = self.outputs
        self.target = self.options.get("target", "generic")
        self.adder = self.options.get("adder", "generic")
        # build-cache tag of the DSP48 choices (the adder only when not generic)
        self.targets = self.target + ("" if self.adder == "generic" else f"-add-{self.adder}")
        self.header_params = {}

    # the interface
    def check(self) -> None:
        """Check the build parameters by building the unit (no elaboration); ValueError
        names the parameter."""
        _, comp, _ = build_unit(self.name, self.fmt, **self.options)
        comp._MustUse__silence = True             # built only to check the parameters

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
    def label(self) -> str:
        """The unit's options as ``raplas-hdl cosim``'s first line gives them."""
        return " ".join(f"{k}={v}" for k, v in self.options.items())

    def report(self, cases, expected, got, limit: int) -> tuple[int, list[str]]:
        """``(cases that differ, the lines that show the first limit of them)``."""
        bad = compare(expected, got, [k for k in self.compared if expected.get(k) is not None])
        return len(bad), [line for i in bad[:limit]
                          for line in self.show(cases, expected, got, int(i))]

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


def beat_lines(expected, got) -> list[str]:
    """The lines that show how a run's result beats (structured arrays) differ: the counts,
    then the first differing beat field by field (empty when they are equal)."""
    lines = []
    if len(expected) != len(got):
        lines.append(f"    beats        expected {len(expected)}, got {len(got)}   <- differs")
    m = min(len(expected), len(got))
    diff = [j for j in range(m) if expected[j].tobytes() != got[j].tobytes()]
    if diff:
        j = diff[0]
        lines.append(f"    {len(diff)} beats differ; the first, beat {j}:")
        for name in expected.dtype.names:
            e, g = int(expected[name][j]), int(got[name][j])
            mark = "   <- differs" if e != g else ""
            lines.append(f"      {name:12s} expected {e:x}, got {g:x}{mark}")
    return lines


def report_runs(unit: UnitCosim, cases, diffs, limit: int) -> tuple[int, list[str]]:
    """:meth:`UnitCosim.report` of a unit fed runs: ``diffs`` holds, per run, the lines that
    show its differences (empty or None when it agrees)."""
    bad = [k for k, lines in enumerate(diffs) if lines]
    return len(bad), [line for i in bad[:limit]
                      for line in (f"  {unit.describe(cases, i)}", *diffs[i])]


def cosim_key(*parts) -> str:
    return "cosim-" + "-".join(str(p) for p in parts if p is not None)
