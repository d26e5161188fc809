"""``ray-triangle``: the batch harness around the unit's pair and result streams."""

from __future__ import annotations

import numpy as np

from ..build.harness import HarnessSpec, run_unit_batch, words32, words64
from .base import RT_ID_BITS, UnitCosim, as_u64, cosim_key, unit_verilog
from .vectors import LineKind, columns_of


class RayTriangleCosim(UnitCosim):
    """``ray-triangle``: one untagged line per pair, inputs then the expected result (the
    certified mode: the record ``RT_RESULT_CERTIFIED``, with ``outcome`` and ``tight``,
    compared with the model's ``bound_variant="exp"``, the variant the RTL has)."""

    name = "ray-triangle"

    def __init__(self, fmt, options, driver="batch"):
        super().__init__(fmt, options, driver)
        # lazy: the model loads numba; importing raplas_hdl.sim.cosim needs none
        from raplas_hdl.model.records import PAIR, RT_RESULT, RT_RESULT_CERTIFIED

        self.mode = self.options.get("mode", "paper")
        self.header_params = {"mode": self.mode}
        ids = {"ray_id_bits": RT_ID_BITS, "tri_id_bits": RT_ID_BITS}
        self.certified = self.mode == "certified"
        self.pair = PAIR.bind(fmt, **ids)
        self.res = (RT_RESULT_CERTIFIED if self.certified else RT_RESULT).bind(fmt, **ids)
        ins = [(n, w) for n, (_, w) in self.pair.offsets().items()]
        outs = [(n, w) for n, (_, w) in self.res.offsets().items()
                if n not in ("ray_id", "tri_id")]
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
        # lazy: the model loads numba; importing raplas_hdl.sim.cosim needs none
        from raplas_hdl.model.stress_cases import vectors

        vec = vectors(self.fmt, n, seed)
        rng = np.random.default_rng([seed, 7])
        cases = {"ray_id": rng.integers(0, 1 << RT_ID_BITS, n).astype(np.uint64),
                 "tri_id": rng.integers(0, 1 << RT_ID_BITS, n).astype(np.uint64)}
        for k, v in vec.items():
            for j, p in enumerate("xyz"):
                cases[f"{k}.{p}"] = v[:, j].astype(np.uint64)
        return cases

    def expected(self, cases):
        # lazy: the model loads numba; importing raplas_hdl.sim.cosim needs none
        from raplas_hdl.model.ray_triangle import intersect

        f = self._split(cases, self.pair)
        arrs = [np.ascontiguousarray(f[k], np.uint32) for k in ("o", "d", "v0", "e1", "e2", "n")]
        ref = intersect(*arrs, self.fmt, mode=self.mode,
                        bound_variant="exp" if self.certified else None)
        out = {"ray_id": as_u64(cases["ray_id"]), "tri_id": as_u64(cases["tri_id"])}
        for k in ("hit", "t", "u", "v", "det", "flags") + ("outcome",) * self.certified:
            out[k] = as_u64(ref[k])
        if self.certified:
            from raplas_hdl.model.ordering import tight_flags

            out["tight"] = as_u64(tight_flags(arrs, ref["outcome"], self.fmt, 1.0, "exp"))
        for j, ev in enumerate(("overflow", "underflow", "invalid")):
            out[f"n_{ev}"] = as_u64(ref["event_counts"][:, j])
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
        text, latency = unit_verilog(self.name, self.fmt, self.options, "ray_triangle")
        out_bits = self.res.size
        spec = HarnessSpec(dut="ray_triangle", inputs=[("i__payload", self.pair.size)],
                           outputs=[("o__payload", out_bits)], i_valid="i__valid",
                           o_valid="o__valid", i_ready="i__ready", o_ready="o__ready")
        words = self.pair.pack_words(self._split(cases, self.pair))
        out, info = run_unit_batch(simulator, spec, text,
                          cosim_key("ray_triangle", self.fmt.name, self.mode, self.targets),
                          {"i__payload": words32(words, self.pair.size)}, valid_density,
                          stall_density, seed, timeout_s=timeout_s)
        words = words64(out["o__payload"], out_bits)
        rec = self.res.unpack_words(words)
        got = {s.name: rec[s.name] for s in self.res.fields}
        info["latency"] = latency
        return got, info
