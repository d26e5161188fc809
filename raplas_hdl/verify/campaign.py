"""The stress campaign at scale (issue 6, point 2): sharded, seeded, resumable.

Two tasks, over every format and rounding asked for (default FP16, FP20, FP24, FP32 in
``rtz``, ``rne`` and ``chop``):

``raytri``
    The ray-triangle stress families of :mod:`raplas_hdl.model.stress_cases` judged by the
    exact reference R (:mod:`raplas_hdl.verify.stress`, :mod:`raplas_hdl.host.exact`), each
    pair evaluated in every mode of the unit (``paper``, ``conservative`` at margin scale 1,
    and ``certified`` with its bounds times ``certified_scale``: 1 for the guarantee, below 1
    for the negative control). R does not depend on the mode, so one shard computes it once
    and evaluates every mode.
``culling``
    The plane-culling proof of ``tests/model/test_plane_culling.py`` at scale: seeded random
    bundles (1 to 8 rows and columns, origin within ``|O| <= O_MAX``) against spheres of
    one *kind*, ``random`` (centres near the origin, along the bundle, behind it; radii
    over four decades) or ``adversarial`` (at distance ``r (1 +- k 2**-M)`` from a ray or a
    plane). The spheres are encoded with the inflated radius ``r'``
    (:func:`raplas_hdl.host.culling.encode_spheres`) and tested by the golden model of the
    tester (:func:`raplas_hdl.model.plane_sphere.tester_flags`). A **false rejection** is a
    (ray, sphere) pair whose *line* meets the sphere exactly (the encoded ray against the
    encoded sphere; float64 with a safety band, then exact rationals inside the band) while
    one of the ray's two planes culls the sphere. It must never happen *in domain* (sphere
    inside the domain and bundle within the slack budget).

Shards
------
The work is cut into shards ``(task, format/rounding, family or kind, index)``; each has
its own seed, derived (BLAKE2b) from the campaign seed, the task, the format *without* its
rounding (so the three roundings of a format see the same geometry), the family and the
index. A shard's result is written atomically (temporary file, then ``os.replace``) as
``<out_dir>/<task>_<format>_<family>_<index>_<digest>.json``, where the digest covers the
whole key: :data:`VERSION`, the sizes, the seed. A shard file whose key matches is reused;
a change of version or parameters gives other names, so stale files are ignored.
:func:`run_campaign` runs the missing shards on an executor of :mod:`raplas_hdl.cluster`
(a local process pool by default, or a Dask cluster) and writes each shard's file in the
calling process as its result comes back; :func:`merge` sums the shard files (in key order:
the result does not depend on the order shards finished, nor on where they ran).

Merged JSON (``docs/results/stress_campaign.json``)
--------------------------------------------------
Top level:

``schema``          1.
``version``         :data:`VERSION` of the code that made the shards.
``params``          the campaign's parameters (:class:`CampaignParams` as a dict).
``command``, ``machine`` (``node``, ``cpus``, ``python``, ``platform``), ``date`` (UTC ISO
                    time of the merge), ``run`` (``wall_s`` of the invocation that merged,
                    ``shards_run``, ``shards_reused``): what differs between two runs that
                    produce the same results. Everything else is a pure function of the
                    shard files.
``cpu_s``           CPU seconds summed over the shards (as measured when each ran).
``shard_wall_s``    wall seconds summed over the shards.
``totals``          ``shards``, ``raytri_pairs`` (ray-triangle pairs generated),
                    ``raytri_evaluations`` (pairs x modes), ``sphere_tests`` ((ray, sphere)
                    pairs of the culling proof), ``plane_tests`` ((plane, sphere) pairs),
                    ``cases`` (``raytri_pairs + sphere_tests``).
``ray_triangle``    list of rows, one per (format, mode), in format order then mode:
                    ``format`` ("FP24/rtz"), ``mode``, ``cases`` (pairs), ``in_domain``
                    (pairs with a triangle record inside the format's domain), ``skipped``
                    (no valid triangle record), ``unguaranteed`` (outside the domain),
                    ``r_hits``, ``unit_hits``, ``false_hits``, ``false_misses``,
                    ``uncertain``, ``edge_rays``, ``leaks`` (all in domain, as
                    :func:`raplas_hdl.verify.stress.evaluate`), ``t_rel_median``,
                    ``t_rel_p99``, ``t_rel_max`` (relative error of ``t`` over in-domain pairs
                    both hit; median and p99 are the upper edge of a histogram bin of width
                    ``2**(1/16)``, so within 4.4 % above the empirical quantile; max exact),
                    ``t_rel_count`` (pairs in that statistic), and ``families``: the same
                    keys per family.
``culling``         list of rows, one per format: ``format``, ``bundles``,
                    ``bundles_out_of_budget`` (unguaranteed bundles), ``spheres``,
                    ``spheres_out_of_domain``, ``plane_tests`` ((plane, sphere) pairs),
                    ``plane_rejected``, ``culled_fraction`` (= plane_rejected / plane_tests),
                    ``sphere_tests`` ((ray, sphere) pairs), ``sphere_tests_culled``
                    (pairs where one of the ray's planes culls the sphere),
                    ``line_hits`` (pairs whose line meets the sphere), ``exact_checks``
                    (pairs decided with exact rationals), ``false_rejections`` (in domain;
                    must be 0), ``false_rejections_unguaranteed`` (bundle over budget or
                    sphere outside the domain), ``false_rejections_raw`` (the same spheres
                    *without* inflation: shows that the check can fail), and ``kinds``: the
                    same keys per sphere kind (``random``, ``adversarial``).
``guarantees``      ``culling_false_rejections`` and ``conservative_false_misses``,
                    ``conservative_leaks``, ``certified_mis_certified`` (certified hits R
                    misses plus certified misses R hits), ``certified_leaks`` (in domain,
                    summed over everything; all must be 0) and ``ok`` (bool).

Nothing here imports Amaranth.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import platform
import time
from dataclasses import asdict, dataclass
from datetime import datetime, timezone
from fractions import Fraction
from pathlib import Path

import numpy as np

from ..cluster import SerialExecutor, make_executor, versions
from ..fp.format import ROUNDINGS, FPFormat, parse_format
from ..model.modes import MODES

__all__ = ["VERSION", "worker_versions", "RUN_KEYS", "MODES", "KINDS", "CampaignParams",
           "Shard", "plan", "shard_path", "compute_shard", "write_shard", "run_shard",
           "run_campaign", "merge", "markdown", "culling_shard", "raytri_shard",
           "random_bundle", "random_spheres", "adversarial_spheres", "exact_line_hit",
           "line_gap", "quantile_from_hist", "results_of", "write_outputs"]

#: Keys of the merged document that describe a run rather than its results
#: (:func:`results_of` drops them).
RUN_KEYS = ("command", "machine", "date", "run", "cpu_s", "shard_wall_s")
#: Version of the shard computations: bump it when a change alters any shard's result.
VERSION = 2


def worker_versions() -> dict:
    """What a Dask worker must share with the client to compute the same shards: the
    package versions (:func:`raplas_hdl.cluster.versions`) and :data:`VERSION`."""
    return {**versions(), "campaign_version": VERSION}
#: Sphere kinds of the culling proof.
KINDS = ("random", "adversarial")
#: Bound on ``|O|`` of the culling proof's bundles (scene units), as in the test.
O_MAX = 8.0
#: Histogram of the relative error of t: bins of 2**(1/_SUB) from 2**_LO up.
_SUB = 16
_LO = -80
_HI = 24


@dataclass(frozen=True)
class CampaignParams:
    """What a campaign runs.

    Attributes
    ----------
    formats : tuple of str
        Formats without rounding ("FP16", ...) or with one ("FP24/rne").
    roundings : tuple of str
        Roundings applied to formats given without one.
    families : tuple of str
        Ray-triangle stress families.
    rays_per_family : int
        Rays per (format, rounding, family); edge and vertex families give 2 and 6 pairs
        per ray.
    shard_rays : int
        Rays per ray-triangle shard.
    bundles : int
        Bundles per (format, rounding, sphere kind) of the culling proof.
    shard_bundles : int
        Bundles per culling shard.
    spheres_per_bundle : int
    seed : int
    certified_scale : float
        Factor on every bound of the certified mode (1: the guarantee; the negative control
        runs below the factor :func:`raplas_hdl.verify.stress.bisect_certified` finds and
        must fail).
    """

    formats: tuple = ("FP16", "FP20", "FP24", "FP32")
    roundings: tuple = ROUNDINGS
    families: tuple = ()
    rays_per_family: int = 20000
    shard_rays: int = 2500
    bundles: int = 4000
    shard_bundles: int = 500
    spheres_per_bundle: int = 16
    seed: int = 2026
    certified_scale: float = 1.0

    def __post_init__(self):
        # lazy: model.stress_cases loads numba; importing the campaign (CLI, merge) needs none
        from ..model.stress_cases import FAMILIES
        if not self.families:
            object.__setattr__(self, "families", FAMILIES)
        for name in ("rays_per_family", "bundles"):
            if getattr(self, name) < 0:
                raise ValueError(f"{name} must be non-negative, not {getattr(self, name)}")
        for name in ("shard_rays", "shard_bundles", "spheres_per_bundle"):
            if getattr(self, name) < 1:
                raise ValueError(f"{name} must be at least 1, not {getattr(self, name)}")
        if not (self.certified_scale > 0 and math.isfinite(self.certified_scale)):
            raise ValueError(f"certified_scale must be a positive finite number, not "
                             f"{self.certified_scale!r}")
        for r in self.roundings:
            if r not in ROUNDINGS:
                raise ValueError(f"unknown rounding {r!r}; known: {', '.join(ROUNDINGS)}")
        for f in self.families:
            if f not in FAMILIES:
                raise ValueError(f"unknown stress family {f!r}; known: {', '.join(FAMILIES)}")
        self.format_list()

    def format_list(self) -> list[FPFormat]:
        """The formats with their roundings, in campaign order."""
        out = []
        for f in self.formats:
            if "/" in f:
                out.append(parse_format(f))
            else:
                base = parse_format(f)
                out.extend(base.with_rounding(r) for r in self.roundings)
        return out


@dataclass(frozen=True)
class Shard:
    """One unit of work. ``fmt`` is ``str(FPFormat)`` ("FP24/rtz"); ``group`` the family
    (``raytri``) or sphere kind (``culling``); ``count`` rays or bundles."""

    task: str
    fmt: str
    group: str
    index: int
    count: int
    seed: int
    spheres: int = 0
    version: int = VERSION
    scale: float = 1.0

    def key(self) -> dict:
        return asdict(self)

    def digest(self) -> str:
        text = json.dumps(self.key(), sort_keys=True)
        return hashlib.blake2b(text.encode(), digest_size=6).hexdigest()

    def derived_seed(self) -> int:
        """The shard's seed: the campaign seed, task, format without rounding, group, index."""
        fmt = parse_format(self.fmt)
        text = f"{self.seed}/{self.task}/e{fmt.exp_bits}m{fmt.man_bits}/{self.group}/{self.index}"
        return int.from_bytes(hashlib.blake2b(text.encode(), digest_size=8).digest(), "little") \
            >> 1


def plan(params: CampaignParams) -> list[Shard]:
    """Every shard of a campaign, in a fixed order (cheap first within each format)."""
    shards = []
    for fmt in params.format_list():
        name = str(fmt)
        for kind in KINDS:
            for i in range(math.ceil(params.bundles / params.shard_bundles)):
                n = min(params.shard_bundles, params.bundles - i * params.shard_bundles)
                shards.append(Shard("culling", name, kind, i, n, params.seed,
                                    params.spheres_per_bundle))
        for fam in params.families:
            for i in range(math.ceil(params.rays_per_family / params.shard_rays)):
                n = min(params.shard_rays, params.rays_per_family - i * params.shard_rays)
                shards.append(Shard("raytri", name, fam, i, n, params.seed,
                                    scale=params.certified_scale))
    return shards


def shard_path(out_dir, shard: Shard) -> Path:
    fmt = parse_format(shard.fmt)
    return Path(out_dir) / (f"{shard.task}_{fmt.name}_{shard.group}_{shard.index:05d}_"
                            f"{shard.digest()}.json")


# -- the ray-triangle task ---------------------------------------------------------------------
def _hist(rel) -> dict:
    """Sparse histogram of relative errors: ``"zero"``, bin index ``k`` for
    ``2**((k-1)/16) < x <= 2**(k/16)`` (as strings), ``"over"`` above ``2**_HI``."""
    rel = np.asarray(rel, np.float64)
    out = {}
    z = int(np.sum(rel == 0))
    if z:
        out["zero"] = z
    pos = rel[rel > 0]
    over = pos > 2.0 ** _HI
    if over.any():
        out["over"] = int(over.sum())
    pos = pos[~over]
    k = np.ceil(np.log2(np.maximum(pos, 2.0 ** _LO)) * _SUB).astype(np.int64)
    vals, counts = np.unique(k, return_counts=True)
    for v, c in zip(vals, counts):
        out[str(int(v))] = int(c)
    return out


def _hist_add(a: dict, b: dict) -> dict:
    out = dict(a)
    for k, v in b.items():
        out[k] = out.get(k, 0) + v
    return out


def quantile_from_hist(hist: dict, q: float, vmax: float = math.inf) -> float:
    """The upper edge of the bin holding rank ``ceil(q n)`` (0 for an empty histogram);
    ``vmax`` (the exact maximum) caps it."""
    n = sum(hist.values())
    if n == 0:
        return 0.0
    rank = max(1, math.ceil(q * n))
    keys = (["zero"] if "zero" in hist else []) + sorted(
        (k for k in hist if k not in ("zero", "over")), key=int) + (
        ["over"] if "over" in hist else [])
    acc = 0
    for k in keys:
        acc += hist[k]
        if acc >= rank:
            if k == "zero":
                return 0.0
            value = vmax if k == "over" else 2.0 ** (int(k) / _SUB)
            return float(min(value, vmax))
    return float(vmax)


_RT_COUNTS = ("cases", "in_domain", "skipped", "unguaranteed", "r_hits", "unit_hits",
              "false_hits", "false_misses", "uncertain", "edge_rays", "leaks")


def raytri_shard(shard: Shard) -> dict:
    """Generate the shard's pairs, compute R once, evaluate every mode.

    Returns
    -------
    dict
        mode -> counts (``_RT_COUNTS``), ``t_rel_max``, ``t_rel_hist``.
    """
    # lazy: verify.stress loads numba; importing the campaign (CLI, merge) needs none
    from ..model import stress_cases
    from . import stress

    fmt = parse_format(shard.fmt)
    cases = stress_cases.generate(fmt, shard.count, shard.derived_seed(), (shard.group,))
    enc = stress.reference(cases, fmt)
    out = {}
    for mode in MODES:
        scale = shard.scale if mode == "certified" else 1.0
        row = stress.evaluate(cases, enc, mode, scale)[shard.group]
        hit, t = stress.unit_hits(enc, mode, scale)
        ok = enc.cert_in_domain if mode == "certified" else enc.in_domain
        both = (ok & hit & enc.r_hit & np.isfinite(t) & np.isfinite(enc.r_t)
                & (enc.r_t != 0))
        rel = np.abs(t[both] - enc.r_t[both]) / np.abs(enc.r_t[both])
        tmax = float(rel.max()) if rel.size else 0.0
        if tmax != row["t_rel_max"]:
            raise AssertionError("relative errors disagree with stress.evaluate")
        res = {k: int(row[k]) for k in _RT_COUNTS if k in row}
        res["cases"] = int(row["pairs"])
        res["in_domain"] = int(row["pairs"] - row["skipped"] - row["unguaranteed"])
        res["t_rel_max"] = tmax
        res["t_rel_hist"] = _hist(rel)
        out[mode] = res
    return out


# -- the culling task --------------------------------------------------------------------------
def random_bundle(rng):
    """A random bundle: 1..8 rows and columns, ``|O|`` from 1e-3 to 0.95 ``O_MAX``, screen at
    1e-2..10, axes 45..90 degrees apart, half extents 1e-3..1 of the distance (as the
    test of the culling proof)."""
    # lazy: the model loads numba; importing the campaign (CLI, merge) needs none
    from ..model.bundles import RayBundle
    rows, cols = (int(x) for x in rng.integers(1, 9, 2))
    o_norm = 10 ** rng.uniform(-3, math.log10(O_MAX * 0.95))
    origin = rng.normal(size=3)
    origin *= o_norm / np.linalg.norm(origin)
    dist = 10 ** rng.uniform(-2, 1)
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    a = np.cross(axis, rng.normal(size=3))
    a /= np.linalg.norm(a)
    b = np.cross(axis, a)
    ang = rng.uniform(0.5, 1.0) * math.pi / 2
    b = math.cos(ang) * a + math.sin(ang) * b
    half = dist * 10 ** rng.uniform(-3, 0, 2)
    return RayBundle(origin, origin + dist * axis, a * half[0], b * half[1], rows, cols)


def _perp(rng, d):
    e = np.cross(d, rng.normal(size=np.shape(d)))
    return e / np.linalg.norm(e, axis=-1, keepdims=True)


def random_spheres(rng, bundle, n):
    """Centres near O, along the bundle (far) and behind O; radii over 4 decades."""
    dirs = bundle.directions[rng.integers(0, bundle.n_rays, n)]
    t = 10 ** rng.uniform(-3, 2, n) * rng.choice([1, 1, 1, -1], n)
    r = 10 ** rng.uniform(-4, 0, n) * np.maximum(np.abs(t), 1e-2)
    off = _perp(rng, dirs) * (r * rng.uniform(0, 3, n))[:, None]
    return bundle.origin + t[:, None] * dirs + off, r


def adversarial_spheres(rng, bundle, n, fmt):
    """Spheres at distance ``r (1 +- k 2**-M)`` from a ray (half) or from a plane (half)."""
    ks = np.array([0.25, 0.5, 1, 2, 4, 8, 16])
    k = rng.choice(ks, n) * rng.choice([-1, 1], n)
    r = 10 ** rng.uniform(-4, 0, n)
    scale = 1 + k * fmt.ulp
    t = 10 ** rng.uniform(-1, 3, n) * r * rng.choice([1, 1, -1], n)
    rays = rng.integers(0, bundle.n_rays, n)
    d = bundle.directions[rays]
    c_ray = bundle.origin + t[:, None] * d + _perp(rng, d) * (r * scale)[:, None]
    plane = np.where(rng.random(n) < 0.5, rays // bundle.cols, bundle.rows + rays % bundle.cols)
    nrm = bundle.plane_n[plane]
    inplane = np.cross(nrm, _perp(rng, nrm))
    x = bundle.origin + t[:, None] * (d + rng.uniform(-1, 1, n)[:, None] * inplane)
    c_plane = x + nrm * (r * scale * rng.choice([-1, 1], n))[:, None]
    centres = np.where((np.arange(n) % 2 == 0)[:, None], c_ray, c_plane)
    return centres, r


def exact_line_hit(o, d, c, r) -> bool:
    """Does the line ``O + tD`` meet the ball ``|X - C| <= r``? Exact (rationals)."""
    o, d, c = ([Fraction(float(x)) for x in v] for v in (o, d, c))
    w = [c[i] - o[i] for i in range(3)]
    cx = [w[1] * d[2] - w[2] * d[1], w[2] * d[0] - w[0] * d[2], w[0] * d[1] - w[1] * d[0]]
    dd = sum(x * x for x in d)
    return sum(x * x for x in cx) <= Fraction(float(r)) ** 2 * dd


def line_gap(o, d, c, r):
    """float64 ``|w x D|^2 - r^2 |D|^2`` per (ray, sphere) and a scale of its error."""
    w = c[None, :, :] - o[None, None, :]
    dd = np.sum(d * d, axis=1)[:, None]
    cross = np.cross(w, d[:, None, :])
    gap = np.sum(cross * cross, axis=2) - (r * r)[None, :] * dd
    scale = (np.sum(w * w, axis=2) + (r * r)[None, :]) * dd
    return gap, scale


_CULL_COUNTS = ("bundles", "bundles_out_of_budget", "spheres", "spheres_out_of_domain",
                "plane_tests", "plane_rejected", "sphere_tests", "sphere_tests_culled",
                "line_hits", "exact_checks", "false_rejections",
                "false_rejections_unguaranteed", "false_rejections_raw")


def culling_shard(shard: Shard) -> dict:
    """The culling proof over the shard's bundles and spheres of its kind: counts
    (``_CULL_COUNTS``)."""
    # lazy: the model loads numba; importing the campaign (CLI, merge) needs none
    from ..fp import model as fpm
    from ..model import plane_sphere as ps_model
    from ..model.bundles import encode_bundles
    from ..host.culling import CullingBudget, bundle_slacks, encode_spheres

    fmt = parse_format(shard.fmt)
    rng = np.random.default_rng(shard.derived_seed())
    budget = CullingBudget(fmt, O_MAX)
    n_s = shard.spheres
    st = dict.fromkeys(_CULL_COUNTS, 0)
    bundles = [random_bundle(rng) for _ in range(shard.count)]
    if shard.group == "random":
        spheres = [random_spheres(rng, b, n_s) for b in bundles]
    elif shard.group == "adversarial":
        spheres = [adversarial_spheres(rng, b, n_s, fmt) for b in bundles]
    else:
        raise ValueError(f"unknown sphere kind {shard.group!r}; known: {', '.join(KINDS)}")
    if not bundles:
        return st
    centres = np.concatenate([c for c, _ in spheres])
    radii = np.concatenate([r for _, r in spheres])
    c_all, r_all, rinf_all, ok_all = encode_spheres(centres, radii, budget)
    c_dec_all, r_dec_all = fpm.decode(c_all, fmt), fpm.decode(r_all, fmt)
    enc = encode_bundles(bundles, fmt)
    slacks = bundle_slacks([(n, p, o, d, b.rows, b.cols) for (n, p, o, d), b
                            in zip(enc, bundles)], fmt)
    admitted = [budget.admits(x) for x in slacks]
    o_all = fpm.decode(np.array([e[2] for e in enc]), fmt)
    d_all = fpm.decode(np.concatenate([e[3] for e in enc]), fmt)
    d_at = 0
    for k, (bundle, (n_enc, p_enc, _, _)) in enumerate(zip(bundles, enc)):
        sl = slice(k * n_s, (k + 1) * n_s)
        c_enc, r_enc, r_inf, ok = c_all[sl], r_all[sl], rinf_all[sl], ok_all[sl]
        c_dec, r_dec = c_dec_all[sl], r_dec_all[sl]
        o_dec, d_dec = o_all[k], d_all[d_at:d_at + bundle.n_rays]
        d_at += bundle.n_rays
        keep = ps_model.tester_flags(n_enc, p_enc, c_enc, r_inf, fmt)          # (S, P)
        keep_raw = ps_model.tester_flags(n_enc, p_enc, c_enc, r_enc, fmt)
        row, col = bundle.ray_planes()
        both = keep[:, row] & keep[:, col]                                     # (S, rays)
        both_raw = keep_raw[:, row] & keep_raw[:, col]
        # the float64 line test is only sound for finite encoded spheres
        fin = np.isfinite(c_dec).all(1) & np.isfinite(r_dec)
        gap, scale = line_gap(o_dec, d_dec, np.where(fin[:, None], c_dec, 0.0),
                               np.where(fin, r_dec, 0.0))                       # (rays, S)
        sure = (gap < -1e-9 * scale) & fin[None, :]
        maybe = (np.abs(gap) <= 1e-9 * scale) & fin[None, :]
        guaranteed = ok[None, :] & admitted[k]                                 # (1, S)
        st["bundles"] += 1
        st["bundles_out_of_budget"] += int(not admitted[k])
        st["spheres"] += n_s
        st["spheres_out_of_domain"] += int(np.sum(~ok))
        st["plane_tests"] += keep.size
        st["plane_rejected"] += int(np.sum(~keep))
        st["sphere_tests"] += both.size
        st["sphere_tests_culled"] += int(np.sum(~both))
        # decide every pair in the float64 band exactly, once
        line = sure.copy()
        for i, s in zip(*np.nonzero(maybe)):
            line[i, s] = exact_line_hit(o_dec, d_dec[i], c_dec[s], r_dec[s])
        st["exact_checks"] += int(np.sum(maybe))
        st["line_hits"] += int(np.sum(line))
        lost = line & ~both.T                                                 # (rays, S)
        st["false_rejections"] += int(np.sum(lost & guaranteed))
        st["false_rejections_unguaranteed"] += int(np.sum(lost & ~guaranteed))
        st["false_rejections_raw"] += int(np.sum(line & ~both_raw.T))
    return st


# -- running -----------------------------------------------------------------------------------
def compute_shard(shard: Shard) -> dict:
    """Compute one shard: the content of its file (``key``, ``result``, ``wall_s``,
    ``cpu_s``). Runs wherever the executor puts it; writes nothing."""
    t0, c0 = time.perf_counter(), time.process_time()
    if shard.task == "raytri":
        result = raytri_shard(shard)
    elif shard.task == "culling":
        result = culling_shard(shard)
    else:
        raise ValueError(f"unknown campaign task {shard.task!r}")
    return {"key": shard.key(), "result": result,
            "wall_s": time.perf_counter() - t0, "cpu_s": time.process_time() - c0}


def write_shard(out_dir, shard: Shard, doc: dict) -> Path:
    """Write a shard's file atomically (a temporary file, then ``os.replace``)."""
    path = shard_path(out_dir, shard)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    tmp.write_text(json.dumps(doc, sort_keys=True))
    os.replace(tmp, path)
    return path


def run_shard(shard: Shard, out_dir) -> dict:
    """Compute one shard and write its file atomically. Returns the file's content."""
    doc = compute_shard(shard)
    write_shard(out_dir, shard, doc)
    return doc


def _load(out_dir, shard: Shard):
    path = shard_path(out_dir, shard)
    try:
        doc = json.loads(path.read_text())
    except (FileNotFoundError, json.JSONDecodeError):
        return None
    return doc if doc.get("key") == shard.key() else None


def run_campaign(params: CampaignParams, out_dir="build/campaign", jobs=None,
                 max_shards=None, progress=True, executor=None) -> dict:
    """Run the shards of ``params`` that ``out_dir`` lacks.

    The shards run on ``executor`` (:mod:`raplas_hdl.cluster`: this process, the local
    process pool or a Dask cluster) and come back to this process, which writes each one's
    file as it arrives: an interrupted run keeps every shard that came back, and the workers
    of a cluster need no file system in common with this one.

    Parameters
    ----------
    jobs : int, optional
        Worker processes of the default executor (default ``os.cpu_count()``); 1 runs in
        this process. Not with ``executor``.
    max_shards : int, optional
        Stop after this many new shards (an interrupted campaign, on purpose).
    progress : bool
        Show a tqdm progress bar.
    executor : raplas_hdl.cluster.Executor, optional
        Where the shards run (the caller closes it); default a process pool of ``jobs``.

    Returns
    -------
    dict
        ``shards`` (total), ``reused``, ``run`` (computed now), ``pending`` (still
        missing), ``wall_s``, ``executor`` (where they ran).
    """
    if executor is not None and jobs is not None:
        raise ValueError("give jobs or an executor, not both")
    own = executor is None
    if own:
        executor = make_executor(jobs, worker_versions=worker_versions)
    t0 = time.perf_counter()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    for stale in out.glob(".*.tmp"):
        stale.unlink(missing_ok=True)
    shards = plan(params)
    todo = [s for s in shards if _load(out, s) is None]
    reused = len(shards) - len(todo)
    if max_shards is not None:
        todo = todo[:max(0, int(max_shards))]
    if own and len(todo) <= 1:
        executor = SerialExecutor()
    bar = None
    if progress and todo:
        # lazy: tqdm costs tens of ms, only for a progress bar
        from tqdm import tqdm
        bar = tqdm(total=len(todo), unit="shard", desc="stress campaign", smoothing=0.05)
    done = 0
    try:
        if todo and executor.kind != "serial" and executor.local:
            # compile the kernels the shards use once, here, so that the workers only load
            # numba's disk cache (each would otherwise compile them again)
            # lazy: host.warm loads the model and the renderer (numba)
            from ..host.warm import default_lock, warm

            warm(engine=False, lock=default_lock())
        for shard, doc in executor.run(compute_shard, todo):
            write_shard(out, shard, doc)
            done += 1
            if bar:
                bar.update(1)
    finally:
        if bar:
            bar.close()
        if own:
            executor.close()
    pending = sum(1 for s in shards if _load(out, s) is None)
    return {"shards": len(shards), "reused": reused, "run": done, "pending": pending,
            "wall_s": time.perf_counter() - t0, "executor": executor.describe()}


# -- merging -----------------------------------------------------------------------------------
def _finish_rt(acc: dict) -> dict:
    row = {k: acc[k] for k in _RT_COUNTS}
    hist = acc["t_rel_hist"]
    row["t_rel_median"] = quantile_from_hist(hist, 0.5, acc["t_rel_max"])
    row["t_rel_p99"] = quantile_from_hist(hist, 0.99, acc["t_rel_max"])
    row["t_rel_max"] = acc["t_rel_max"]
    row["t_rel_count"] = sum(hist.values())
    return row


def _add_rt(acc, res):
    if acc is None:
        acc = dict.fromkeys(_RT_COUNTS, 0)
        acc["t_rel_hist"] = {}
        acc["t_rel_max"] = 0.0
    for k in _RT_COUNTS:
        acc[k] += res[k]
    acc["t_rel_hist"] = _hist_add(acc["t_rel_hist"], res["t_rel_hist"])
    acc["t_rel_max"] = max(acc["t_rel_max"], res["t_rel_max"])
    return acc


def _finish_cull(acc: dict) -> dict:
    row = dict(acc)
    row["culled_fraction"] = acc["plane_rejected"] / acc["plane_tests"] if acc[
        "plane_tests"] else 0.0
    return row


def merge(params: CampaignParams, out_dir="build/campaign", command="", run_info=None) -> dict:
    """Sum the shard files of a finished campaign into the merged document (module
    docstring).

    Raises
    ------
    ValueError
        When a shard of the plan has no valid file.
    """
    shards = plan(params)
    docs = []
    missing = 0
    for s in shards:
        d = _load(out_dir, s)
        if d is None:
            missing += 1
        docs.append(d)
    if missing:
        raise ValueError(f"{missing} of {len(shards)} shards are missing in {out_dir}: run "
                         "the campaign to the end first")
    rt, cull = {}, {}
    cpu = wall = 0.0
    for s, d in zip(shards, docs):
        cpu += d["cpu_s"]
        wall += d["wall_s"]
        if s.task == "raytri":
            for mode in MODES:
                fam = rt.setdefault((s.fmt, mode), {})
                fam[s.group] = _add_rt(fam.get(s.group), d["result"][mode])
        else:
            kinds = cull.setdefault(s.fmt, {})
            acc = kinds.setdefault(s.group, dict.fromkeys(_CULL_COUNTS, 0))
            for k in _CULL_COUNTS:
                acc[k] += d["result"][k]
    rt_rows = []
    for (fmt, mode), fams in rt.items():
        tot = None
        for acc in fams.values():
            tot = _add_rt(tot, acc)
        row = {"format": fmt, "mode": mode, **_finish_rt(tot),
               "families": {f: _finish_rt(a) for f, a in fams.items()}}
        rt_rows.append(row)
    cull_rows = []
    for fmt, kinds in cull.items():
        tot = dict.fromkeys(_CULL_COUNTS, 0)
        for acc in kinds.values():
            for k in _CULL_COUNTS:
                tot[k] += acc[k]
        cull_rows.append({"format": fmt, **_finish_cull(tot),
                          "kinds": {k: _finish_cull(a) for k, a in kinds.items()}})
    pairs = sum(r["cases"] for r in rt_rows if r["mode"] == MODES[0])
    sphere_tests = sum(r["sphere_tests"] for r in cull_rows)
    guar = {"culling_false_rejections": sum(r["false_rejections"] for r in cull_rows),
            "conservative_false_misses": sum(r["false_misses"] for r in rt_rows
                                             if r["mode"] == "conservative"),
            "conservative_leaks": sum(r["leaks"] for r in rt_rows
                                      if r["mode"] == "conservative"),
            "certified_mis_certified": sum(r["false_hits"] + r["false_misses"]
                                           for r in rt_rows if r["mode"] == "certified"),
            "certified_leaks": sum(r["leaks"] for r in rt_rows if r["mode"] == "certified")}
    guar["ok"] = not any(guar.values())
    return {
        "schema": 1, "version": VERSION, "params": asdict(params),
        "command": command,
        "machine": {"node": platform.node(), "cpus": os.cpu_count(),
                    "python": platform.python_version(), "platform": platform.platform()},
        "date": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "run": run_info or {},
        "cpu_s": cpu, "shard_wall_s": wall,
        "totals": {"shards": len(shards), "raytri_pairs": pairs,
                   "raytri_evaluations": pairs * len(MODES), "sphere_tests": sphere_tests,
                   "plane_tests": sum(r["plane_tests"] for r in cull_rows),
                   "cases": pairs + sphere_tests},
        "ray_triangle": rt_rows, "culling": cull_rows, "guarantees": guar,
    }


def results_of(doc: dict) -> dict:
    """The merged document without :data:`RUN_KEYS`: equal for equal shard results."""
    return {k: v for k, v in doc.items() if k not in RUN_KEYS}


def _domain_text(name: str) -> str:
    # lazy: the model loads numba; importing the campaign (CLI, merge) needs none
    from ..model.conservative import domain
    d = domain(parse_format(name))
    return f"{name}: P = {d.pos_exp}, Lmin = {d.min_edge_exp}"


def _e(x):
    return f"{x:.2e}"


def markdown(doc: dict) -> str:
    """The markdown report of a merged document."""
    tot = doc["totals"]
    p = doc["params"]
    run = doc.get("run", {})
    m = doc["machine"]
    lines = [
        "# Stress campaign",
        "",
        "The ray-triangle stress families against the exact reference R and the plane-culling "
        "proof, at scale, over every format, rounding and ray-triangle mode "
        "(`raplas_hdl/verify/campaign.py`, the families of `raplas_hdl/model/stress_cases.py`; "
        "the data: `docs/results/stress_campaign.json`).",
        "",
        f"- command: `{doc['command']}`",
        f"- machine: {m['node']}, {m['cpus']} CPUs, Python {m['python']}, {m['platform']}",
        f"- date (merge): {doc['date']}",
        f"- wall time of the run that merged: {run.get('wall_s', 0):.0f} s "
        f"({run.get('shards_run', 0)} shards run"
        + (f" on a {run['executor']}" if run.get("executor", "").startswith(("process", "Dask"))
           else "") + f", {run.get('shards_reused', 0)} reused); "
        f"CPU time summed over the shards: {doc['cpu_s']:.0f} s",
        f"- {tot['shards']} shards; seed {p['seed']}; {p['rays_per_family']} rays per family "
        f"and format ({p['shard_rays']} per shard); {p['bundles']} bundles per sphere kind "
        f"and format ({p['shard_bundles']} per shard, {p['spheres_per_bundle']} spheres each)",
        f"- cases: **{tot['cases']:,}** = {tot['raytri_pairs']:,} ray-triangle pairs (each "
        f"in {len(MODES)} modes: {tot['raytri_evaluations']:,} evaluations) + "
        f"{tot['sphere_tests']:,} "
        f"(ray, sphere) tests of the culling proof ({tot['plane_tests']:,} plane tests)",
        "",
        "Reproduce (resumable: an interrupted run keeps its finished shards in `--out-dir`, and "
        "the same command continues; shards are seeded, so the result is the same):",
        "",
        "```",
        doc["command"],
        "```",
        "",
        "## Guarantees",
        "",
        f"- in-domain false rejections of plane culling: "
        f"**{doc['guarantees']['culling_false_rejections']}**",
        f"- conservative mode, in domain: false misses "
        f"**{doc['guarantees']['conservative_false_misses']}**, leaks "
        f"**{doc['guarantees']['conservative_leaks']}**",
        f"- certified mode (bounds x{p.get('certified_scale', 1.0):g}), in its domain: "
        f"mis-certified pairs **{doc['guarantees'].get('certified_mis_certified', 0)}** "
        f"(a certified hit that R misses or a certified miss that R hits), leaks "
        f"**{doc['guarantees'].get('certified_leaks', 0)}**",
        "",
        "## Ray-triangle unit against R",
        "",
        "Counts over in-domain pairs (false hits: the unit hits, R misses; false misses: R "
        "hits, the unit misses; leaks: rays aimed at a shared edge or vertex that R hits "
        "and the unit misses on every side). `t` error: relative error of `t'/det` against "
        "R's `t` over pairs both hit (median and p99 from a histogram with bins of 2^(1/16): "
        "upper bounds within 4.4 %). Unguaranteed: pairs outside the format's domain "
        "(not counted in the other columns). Certified mode: false hits / false misses are "
        "*mis-certified* pairs (certified hit, R misses / certified miss, R hits); uncertain: "
        "pairs left to the host; its domain is "
        "`raplas_hdl.model.certified.certified_domain` (every vertex coordinate within "
        "2^P, P = floor((emax - 3)/2)).",
        "",
        "Domains of the ray-triangle guarantee (`raplas_hdl.model.conservative.domain`): "
        "every coordinate at most 2^P in magnitude, every edge at least 2^-Lmin long: "
        + "; ".join(_domain_text(f) for f in dict.fromkeys(
            r["format"].split("/")[0] for r in doc["ray_triangle"])) + ". The families "
        "spread geometry over several binades around these limits, so a narrow format "
        "(FP16) has most of its pairs outside its domain.",
        "",
        "| format | mode | cases | in domain | R hits | false hits | false misses | uncertain "
        "| leaks / edge rays | t rel. err. median | p99 | max | unguaranteed |",
        "|---|---|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|",
    ]
    for r in doc["ray_triangle"]:
        lines.append(
            f"| {r['format']} | {r['mode']} | {r['cases']:,} | {r['in_domain']:,} | "
            f"{r['r_hits']:,} | {r['false_hits']:,} | {r['false_misses']:,} | "
            f"{r.get('uncertain', 0):,} | {r['leaks']:,} / {r['edge_rays']:,} | "
            f"{_e(r['t_rel_median'])} | "
            f"{_e(r['t_rel_p99'])} | {_e(r['t_rel_max'])} | {r['unguaranteed']:,} |")
    fams = list(doc["ray_triangle"][0]["families"]) if doc["ray_triangle"] else []
    for mode in MODES:
        lines += ["", f"### Per family, {mode} mode: false hits / false misses (in domain)",
                  "", "| format | " + " | ".join(fams) + " |",
                  "|---|" + "--:|" * len(fams)]
        for r in doc["ray_triangle"]:
            if r["mode"] != mode:
                continue
            cells = [f"{r['families'][f]['false_hits']} / {r['families'][f]['false_misses']}"
                     for f in fams]
            lines.append(f"| {r['format']} | " + " | ".join(cells) + " |")
    lines += ["", "### Per family, certified mode: uncertain fraction (in domain)", "",
              "| format | " + " | ".join(fams) + " |", "|---|" + "--:|" * len(fams)]
    for r in doc["ray_triangle"]:
        if r["mode"] != "certified":
            continue
        cells = [f"{c['uncertain'] / max(c['in_domain'], 1):.3f}"
                 for c in (r["families"][f] for f in fams)]
        lines.append(f"| {r['format']} | " + " | ".join(cells) + " |")
    lines += [
        "", "## Plane culling: the proof at scale", "",
        f"Random bundles (1-8 rows and columns, |O| <= {O_MAX:g}) against random and "
        "adversarial spheres, encoded with the inflated radius r'. Sphere tests: (ray, "
        "sphere) pairs; line hits: pairs whose ray's line meets the sphere exactly; a false "
        "rejection is a line hit that one of the ray's planes culls. *In domain*: sphere in "
        "the domain and bundle within the slack budget. Without inflation: the same spheres "
        "with their plain radius (the check has teeth). Culled fraction: (plane, sphere) "
        "pairs rejected.",
        "",
        "| format | bundles (over budget) | sphere tests | line hits | exact checks | false "
        "rejections in domain | unguaranteed | without inflation | culled fraction | (ray, "
        "sphere) pairs culled |",
        "|---|--:|--:|--:|--:|--:|--:|--:|--:|--:|",
    ]
    for r in doc["culling"]:
        lines.append(
            f"| {r['format']} | {r['bundles']:,} ({r['bundles_out_of_budget']}) | "
            f"{r['sphere_tests']:,} | {r['line_hits']:,} | {r['exact_checks']:,} | "
            f"**{r['false_rejections']}** | {r['false_rejections_unguaranteed']} | "
            f"{r['false_rejections_raw']:,} | {r['culled_fraction']:.3f} | "
            f"{r['sphere_tests_culled'] / max(r['sphere_tests'], 1):.3f} |")
    lines.append("")
    return "\n".join(lines)


def write_outputs(doc: dict, json_path, md_path) -> None:
    """Write the merged JSON and the markdown report (atomically each)."""
    for path, text in ((json_path, json.dumps(doc, indent=1) + "\n"),
                       (md_path, markdown(doc))):
        if path is None:
            continue
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(f".{path.name}.tmp")
        tmp.write_text(text)
        os.replace(tmp, path)

