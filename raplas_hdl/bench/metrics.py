"""What the sweep measures at a point, and which metrics a point must have.

Per point (see :data:`MODEL_METRICS`): wall and CPU time of the render and per stage,
throughput (rays per second over the whole render, pairs per second over the unit's stages),
the device figures (:mod:`.cost`: the cycles of the device unit for the frame from the unit's
counters, the units that fit on one XC4VSX35, the frame time at the board clock, the result
link's traffic: one ``RESULT`` beat per issued pair), and errors:

- against float64, per pair: the sweep's backend records a uniform sample of the unit's runs
  as the render traces them (whole runs, at most ``pair_sample`` pairs: the sampling rate
  halves whenever the sample outgrows it); after the render (outside the timings) it streams
  those runs' pairs (:meth:`~raplas_hdl.host.backends.Backend.stream`) and evaluates each in
  float64 on the original geometry (:func:`raplas_hdl.host.exact.float64_intersect`);
  median and 99th percentile of ``|t - t64| / |t64|`` over the in-domain pairs both hit, and
  the in-domain pairs whose hit bit differs (counts scaled from the sample to the issued
  pairs);
- against float64, per pixel: PSNR of the 8-bit images, fraction of pixels whose nearest
  triangle differs (all pixels, and pixels whose triangles are all in the domain);
- against R (:mod:`raplas_hdl.verify.stress`): false hits, false misses, edge leaks and the
  relative error of t on the seeded stress families, computed once per format, rounding and
  mode (R is exact and slow) and attached to every point of that configuration.
"""

from __future__ import annotations

import math
import time

import numpy as np

from ..fp import FPFormat
from ..fp.model import decode
from ..host.exact import float64_intersect
from ..host.output import compare
from ..model import stress_cases
from ..model.ray_triangle import intersect
from ..model.records import RESULT
from ..verify import stress
from . import cost as dev
from .instrumented import SweepBackend

__all__ = ["STAGES", "DEVICE_METRICS", "MODEL_METRICS", "CAPPED_METRICS", "REFERENCE_METRICS",
           "pair_errors", "pixel_errors", "run_figures", "device_counts", "device_figures",
           "stress_metrics", "missing_metrics"]

STAGES = ("spheres", "load", "compile", "primary cull", "primary unit", "shading",
          "shadow cull", "shadow unit", "image")

#: Device and link figures of a point.
DEVICE_METRICS = ("device_cycles", "device_cycles_overlap", "device_units", "device_frame_s",
                  "device_fps", "link_beat_bits", "link_bits", "link_bits_per_s")
#: Metrics every model (or rtl) point must have (none may be None or NaN).
MODEL_METRICS = (
    "t_total", "cpu_total", *(f"t_{s.replace(' ', '_')}" for s in STAGES), "rays",
    "pairs_issued", "rays_per_s", "pairs_per_s",
    "psnr", "tri_differs", "tri_differs_in_domain", "hit_differs",
    "t_rel_median", "t_rel_p99", "t_pairs", "pair_hit_differs", "pairs_out_of_domain",
    "pairs_out_of_domain_frac", "pairs_sampled", "tris_out_of_domain", "unguaranteed_bundles",
    "overflow", "underflow", "invalid",
    "r_pairs", "r_in_domain", "r_false_hits", "r_false_misses", "r_edge_rays", "r_leaks",
    "r_t_rel_median", "r_t_rel_p99",
    "hw_dsp48", "hw_luts", "hw_ffs", "hw_slices", "hw_cost",
    *DEVICE_METRICS, "max_pairs", "capped",
)
#: Metrics a capped point must have (it was not rendered to the end).
CAPPED_METRICS = ("t_total", "cpu_total", "pairs_issued", "max_pairs", "capped",
                  "capped_reason", "r_pairs", "r_false_hits", "r_false_misses", "r_leaks",
                  "hw_dsp48", "hw_slices", "hw_cost", *DEVICE_METRICS)
#: Metrics of a float64 reference point.
REFERENCE_METRICS = ("t_total", "cpu_total", *(f"t_{s.replace(' ', '_')}" for s in STAGES),
                     "rays", "pairs_issued", "rays_per_s", "pairs_per_s")


def _quantiles(rel: np.ndarray) -> tuple[float, float]:
    if rel.size == 0:
        return math.nan, math.nan
    return float(np.median(rel)), float(np.quantile(rel, 0.99))


def pair_errors(backend: SweepBackend, tris: np.ndarray) -> dict:
    """Errors of the sampled runs' pairs against float64 on the same pairs (original
    geometry); counts scaled from the sample to the pairs the backend issued."""
    ood = backend.out_of_domain
    total = int(backend.pairs_issued)
    ray, tri, hit, t, o, d = [], [], [], [], [], []
    mismatch = 0
    for sub, k, n, r in backend.sampler.streams(backend):
        mismatch += int(r.ray_id.size != n)
        if not r.ray_id.size:
            continue
        ray.append(r.ray_id)
        tri.append(r.tri_id)
        hit.append(r.hit)
        t.append(r.t)
        o.append(np.broadcast_to(sub.geometry["origins"][k], (r.ray_id.size, 3)))
        d.append(sub.geometry["directions"][k][r.ray_id])
    out = {"pairs_total": total, "pairs_sampled": 0, "pair_sample_frac": 0.0,
           "sample_stream_mismatch": mismatch}
    if not ray:
        out.update(t_rel_median=math.nan, t_rel_p99=math.nan, t_pairs=0, pair_hit_differs=0,
                   pairs_out_of_domain=0, in_domain_pairs=0, pairs_out_of_domain_frac=0.0)
        return out
    tri, hit, t = np.concatenate(tri), np.concatenate(hit), np.concatenate(t)
    o, d = np.concatenate(o), np.concatenate(d)
    tv = tris[tri]
    ref = float64_intersect(o, d, tv[:, 0], tv[:, 1], tv[:, 2])
    ind = ~ood[tri]
    t64 = ref["t"]
    both = ind & hit & ref["hit"] & np.isfinite(t) & np.isfinite(t64) & (t64 != 0)
    rel = np.abs(t[both] - t64[both]) / np.abs(t64[both])
    med, p99 = _quantiles(rel)
    n = int(tri.size)
    scale = total / n if total else 1.0
    out.update(t_rel_median=med, t_rel_p99=p99, t_pairs=int(both.sum()),
               pair_hit_differs=int(round((ind & (hit != ref["hit"])).sum() * scale)),
               pairs_out_of_domain=int(round((~ind).sum() * scale)),
               in_domain_pairs=int(round(ind.sum() * scale)),
               pairs_out_of_domain_frac=float((~ind).mean()),
               pairs_sampled=n, pair_sample_frac=n / total if total else 0.0)
    return out


def pixel_errors(res, ref, ood) -> dict:
    c = compare(res, ref)
    a, b = res.tri_id, ref.tri_id
    ok_a = (a < 0) | ~ood[a.clip(0)]
    ok_b = (b < 0) | ~ood[b.clip(0)]
    sel = ok_a & ok_b
    return {"psnr": c["psnr"], "max_abs": c["max_abs"], "tri_differs": c["tri_differs"],
            "hit_differs": c["hit_differs"],
            "tri_differs_in_domain": float(np.mean(a[sel] != b[sel])) if sel.any() else math.nan,
            "pixels_in_domain": float(np.mean(sel))}


def run_figures(res, wall, cpu) -> dict:
    st, tm = res.stats, res.timings
    out = {"t_total": wall, "cpu_total": cpu}
    for s in STAGES:
        out[f"t_{s.replace(' ', '_')}"] = float(tm.get(s, 0.0))
    unit_t = tm.get("primary unit", 0.0) + tm.get("shadow unit", 0.0)
    out.update(rays=int(st["rays"]), bundles=int(st["bundles"]),
               pairs_issued=int(st["pairs_issued"]),
               brute_force_pairs=int(st["brute_force_pairs"]),
               pair_fraction=float(st["pair_fraction"]),
               rays_per_s=st["rays"] / wall if wall > 0 else math.nan,
               pairs_per_s=st["pairs_issued"] / unit_t if unit_t > 0 else math.nan,
               hits=int(st["hits"]), triangles=int(st["triangles"]),
               unit_spheres=int(st["unit"].get("spheres", 0)),
               unit_plane_tests=int(st["unit"].get("plane_tests", 0)),
               host_plane_tests=int(st["host_plane_tests"]),
               unguaranteed_bundles=int(st["unguaranteed_bundles"]),
               **{k: int(v) for k, v in st["events"].items()})
    return out


def _link_layout(backend: SweepBackend):
    """The result record bound to the unit configuration of the point's largest bundle."""
    rows, cols = max(backend.passes, key=lambda rc: (rc[0] * rc[1], rc)) if backend.passes \
        else (1, 1)
    return RESULT.bind(backend.config(rows, cols))


def device_counts(backend: SweepBackend, mode: str, scale: float = 1.0) -> dict:
    """The device figures that do not need the resources: cycles and link bits."""
    passes = backend.device_passes(scale)
    pairs = sum(p["pairs"] for p in passes)
    lay = _link_layout(backend)
    return {"device_passes": passes, "device_runs": sum(p["runs"] for p in passes),
            "device_cycles": dev.device_cycles(passes, mode),
            "device_cycles_overlap": dev.device_cycles(passes, mode, overlap=True),
            "device_pairs": pairs, "link_beat_bits": int(lay.size),
            "link_params": dict(lay.params), "link_bits": int(pairs * lay.size),
            "link_empty_beats": sum(p["empty_runs"] for p in passes)}


def device_figures(point: dict, unit: dict | None, clock_mhz: float) -> dict:
    """Frame time and link rate of a point from its cycles and the device unit (``unit``:
    :func:`raplas_hdl.bench.cost.device_unit`; None or an error: NaN figures)."""
    if not unit or "error" in unit or point.get("device_cycles") is None:
        return {"device_units": math.nan, "device_basis": None, "device_frame_s": math.nan,
                "device_fps": math.nan, "link_bits_per_s": math.nan,
                "device_clock_mhz": clock_mhz}
    units = int(unit["units"])
    hz = clock_mhz * 1e6
    frame = point["device_cycles"] / units / hz if units else math.inf
    fps = 1.0 / frame if frame > 0 and math.isfinite(frame) else 0.0
    return {"device_units": units, "device_basis": unit["basis"], "device_frame_s": frame,
            "device_frame_s_overlap": (point["device_cycles_overlap"] / units / hz
                                       if units else math.inf),
            "device_unit_s": point["device_cycles"] / hz, "device_fps": fps,
            "link_bits_per_s": point["link_bits"] * fps, "device_clock_mhz": clock_mhz}


# -- R: the stress families ----------------------------------------------------------------

def stress_metrics(fmt: FPFormat, modes, per_family: int, seed: int) -> dict:
    """Pooled counts of the model against R on the seeded stress families, per mode.

    Returns
    -------
    dict
        mode -> ``r_pairs``, ``r_in_domain``, ``r_hits``, ``r_false_hits``,
        ``r_false_misses``, ``r_edge_rays``, ``r_leaks``, ``r_t_rel_median``,
        ``r_t_rel_p99`` (in-domain pairs both hit), ``r_seconds``.
    """
    t0 = time.perf_counter()
    cases = stress_cases.generate(fmt, per_family, seed)
    enc = stress.reference(cases, fmt)
    t_ref = time.perf_counter() - t0
    out = {}
    for mode in modes:
        t1 = time.perf_counter()
        pooled = stress.pooled(stress.evaluate(cases, enc, mode))
        k = enc.kept
        res = intersect(enc.o_bits[k], enc.d_bits[k], enc.v0_bits, enc.e1_bits, enc.e2_bits,
                        enc.n_bits, fmt, mode=mode)
        hit = np.zeros(len(cases), bool)
        hit[k] = res["hit"]
        t = np.full(len(cases), np.nan)
        with np.errstate(divide="ignore", invalid="ignore"):
            t[k] = decode(res["t"], fmt) / decode(res["det"], fmt)
        both = (enc.in_domain & hit & enc.r_hit & np.isfinite(t) & np.isfinite(enc.r_t)
                & (enc.r_t != 0))
        med, p99 = _quantiles(np.abs(t[both] - enc.r_t[both]) / np.abs(enc.r_t[both]))
        out[mode] = {"r_pairs": pooled["pairs"], "r_in_domain": int(enc.in_domain.sum()),
                     "r_hits": pooled["r_hits"], "r_false_hits": pooled["false_hits"],
                     "r_false_misses": pooled["false_misses"],
                     "r_edge_rays": pooled["edge_rays"], "r_leaks": pooled["leaks"],
                     "r_t_rel_median": med, "r_t_rel_p99": p99, "r_t_pairs": int(both.sum()),
                     "r_seconds": t_ref + time.perf_counter() - t1}
    return out


def missing_metrics(point: dict) -> list[str]:
    """The required metrics of ``point`` that are absent, None or NaN."""
    if point.get("backend") == "float64":
        need = REFERENCE_METRICS
    elif point.get("capped"):
        need = CAPPED_METRICS
    else:
        need = MODEL_METRICS
    bad = []
    for k in need:
        v = point.get(k)
        if v is None or (isinstance(v, float) and math.isnan(v)) or v == "nan":
            bad.append(k)
    return bad
