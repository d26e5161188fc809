"""The render pipeline: scene -> spheres -> memories -> primary bundles -> shading ->
shadow bundles -> image, with every skip counted and every stage timed.

Stages (each timed in :attr:`RenderResult.timings`):

1. ``spheres``: drop degenerate triangles (counted), build the sphere hierarchy
   (:mod:`raplas_hdl.host.spheres`) with the unit's conservative margin when that mode is
   on;
2. ``load``: write Triangle Memory and Sphere Memory (:meth:`Backend.load`);
3. ``compile``: a throw-away pass of one bundle, so that the compiled kernels are built
   (first run on a machine) or loaded from numba's cache before the real passes (the
   progress bar says so instead of showing a bundle rate);
4. ``primary``: the camera's ``rows`` x ``cols`` tiles as bundles (lattice points outside
   the image are disabled rays), handed to the backend as whole passes of ``chunk``
   bundles: the hierarchy cull of the pass (``primary cull``), then the unit's runs of the
   surviving leaf spheres reduced to each ray's nearest hit (``primary unit``; ties to the
   lowest triangle ID);
5. ``shading``: hit points, normals, Phong terms; shadow bundles for the points that need
   one (the others counted), built as arrays;
6. ``shadows``: passes of ``chunk`` shadow bundles: the hierarchy cull (``shadow cull``),
   then early-out rounds (``shadow unit``): round ``k`` runs every bundle's ``k``-th batch
   of ``batch_spheres`` leaves; between rounds the rays already blocked are disabled, and a
   bundle whose rays are all blocked runs no further batch;
7. ``image``: compose and tone-map.

A bundle whose quantisation slack is over the culling budget carries the keep-all bit: it
is not culled, on the host or in the unit (counted as ``unguaranteed_bundles``). The
results do not depend on ``chunk`` or on the thread count.

The summary counts rays, bundles, spheres, plane tests (host hierarchy and unit), pairs
issued against brute force (every ray against every triangle), pairs skipped by
early-out, hits, the unit's arithmetic events (the ray-triangle operations that raised
overflow, underflow, invalid, summed over the issued pairs), and the hierarchy's skips per
level.
"""

from __future__ import annotations

import math
import time
from contextlib import contextmanager
from dataclasses import dataclass, field

import numpy as np

from ..engine.passes import round_runs, select_runs
from .backends import COUNTERS, Backend
from .scenes import Scene
from .shading import face_normals, phong, shadow_bundles
from .spheres import build_sphere_tree, unit_margin

__all__ = [
    "RenderResult",
    "RenderSettings",
    "compare",
    "difference_image",
    "format_summary",
    "render",
    "save_ids",
    "save_png",
    "to_uint8",
]


@dataclass
class RenderSettings:
    """Parameters of a render.

    Attributes
    ----------
    width, height : int
        Image size.
    rows, cols : int
        Primary bundle (tile) size.
    shadow_rows, shadow_cols : int
        Light lattice of a shadow bundle; 0 turns shadows off (every point lit).
    tris_per_sphere, fanout : int
        Sphere hierarchy shape.
    hierarchy : bool
        Cull the hierarchy on the host (False: every leaf goes to the unit).
    early_out : bool
        Disable blocked shadow rays between sphere batches.
    batch_spheres : int
        Leaf spheres per shadow run.
    chunk : int
        Bundles per pass handed to the backend at once (the RTL backend runs one simulation
        per pass and early-out round); the results do not depend on it.
    bound : float
        The scene's normalisation bound (coordinates in ``[-bound, bound]``).
    progress : bool
        Show a tqdm progress bar.
    threads : int or None
        Threads of the compiled passes (default None: numba's setting, every core); the
        results do not depend on it.
    record_rays : bool
        Keep every issued ray in :attr:`RenderResult.rays` (for the exact reference).
    """

    width: int = 128
    height: int = 128
    rows: int = 8
    cols: int = 8
    shadow_rows: int = 4
    shadow_cols: int = 4
    tris_per_sphere: int = 8
    fanout: int = 8
    hierarchy: bool = True
    early_out: bool = True
    batch_spheres: int = 32
    chunk: int = 4096
    bound: float = 8.0
    progress: bool = True
    threads: int | None = None
    record_rays: bool = False

    def __post_init__(self):
        for name in ("width", "height", "rows", "cols", "tris_per_sphere", "batch_spheres",
                     "chunk"):
            if int(getattr(self, name)) < 1:
                raise ValueError(f"{name} must be at least 1, not {getattr(self, name)}")
        if (self.shadow_rows == 0) != (self.shadow_cols == 0) or min(
                self.shadow_rows, self.shadow_cols) < 0:
            raise ValueError("shadow_rows and shadow_cols must both be positive (or both 0 "
                             "for no shadows)")

    @property
    def shadows(self) -> bool:
        return self.shadow_rows > 0


@dataclass
class RenderResult:
    """A rendered image with its per-pixel data and the run's figures.

    Attributes
    ----------
    image : ndarray (H, W, 3) float64
        Linear colour.
    tri_id : ndarray (H, W) int64
        Nearest triangle of each pixel's primary ray, -1 for none.
    t : ndarray (H, W) float64
        Its distance (inf for none).
    visibility : ndarray (H, W) float64
        Fraction of the light each pixel's point sees (NaN where there is no point).
    stats : dict
    timings : dict
        Seconds per stage.
    rays : dict or None
        With ``RenderSettings.record_rays``: every ray the render issued, as the unit saw
        it (:func:`raplas_hdl.host.reference.exact_reference` checks them): ``primary_o``,
        ``primary_d`` (N, 3) and ``primary_yx`` (N, 2); ``shadow_o`` (S, 3), ``shadow_d``
        (S, r, 3), ``shadow_tmax`` (S, r), ``shadow_own`` (S,), ``shadow_point`` (S,) (the
        index of the shaded point, in ``np.nonzero(tri_id >= 0)`` order), ``shadow_tmin``;
        ``loaded``: the IDs of the triangles the backend loaded.
    """

    image: np.ndarray
    tri_id: np.ndarray
    t: np.ndarray
    visibility: np.ndarray
    stats: dict = field(default_factory=dict)
    timings: dict = field(default_factory=dict)
    rays: dict | None = None


class _Timer:
    def __init__(self):
        self.times = {}

    @contextmanager
    def __call__(self, name):
        t0 = time.perf_counter()
        try:
            yield
        finally:
            self.times[name] = self.times.get(name, 0.0) + time.perf_counter() - t0


def _add_counters(total: dict, counters: dict):
    for k, v in counters.items():
        total[k] = total.get(k, 0) + int(v)


def _shadow_eps(backend: Backend, bound: float) -> float:
    """Lift of shadow origins and their ``tmin``: ``bound * max(2**-11, 2**(4-M))``."""
    m = backend.fmt.man_bits if backend.fmt is not None else 52
    return bound * max(2.0 ** -11, 2.0 ** (4 - m))


def _light_hits(origin, dirs, light, t_hit):
    """Rays that see the area light before their hit (host-only, float64)."""
    n = light.normal
    c = np.asarray(light.corner, float)
    u, v = np.asarray(light.edge_u, float), np.asarray(light.edge_v, float)
    dn = dirs @ n
    with np.errstate(divide="ignore", invalid="ignore"):
        t = ((c - origin) @ n) / dn
    p = origin + t[:, None] * dirs - c
    a = (p @ u) / (u @ u)
    b = (p @ v) / (v @ v)
    return (dn < 0) & (t > 0) & (t < t_hit) & (a >= 0) & (a <= 1) & (b >= 0) & (b <= 1)


@contextmanager
def _numba_threads(n: int | None):
    """Run the compiled passes on ``n`` threads (None: leave numba's setting)."""
    if n is None:
        yield
        return
    import numba

    old = numba.get_num_threads()
    numba.set_num_threads(max(1, min(n, numba.config.NUMBA_NUM_THREADS)))
    try:
        yield
    finally:
        numba.set_num_threads(old)


def render(scene: Scene, backend: Backend, settings: RenderSettings | None = None):
    """Render ``scene`` (normalised into ``settings.bound``) through ``backend``.

    Returns
    -------
    RenderResult

    Raises
    ------
    ValueError
        When the scene has no usable triangle, or a parameter is out of range.
    """
    s = settings or RenderSettings()
    with _numba_threads(s.threads):
        return _render(scene, backend, s)


def _render(scene: Scene, backend: Backend, settings: RenderSettings):
    from tqdm import tqdm

    s = settings
    timer = _Timer()
    stats: dict = {"backend": backend.describe(), "scene": scene.name,
                   "triangles": scene.n_triangles, "size": f"{s.width}x{s.height}"}
    W, H = s.width, s.height

    # 1. spheres ---------------------------------------------------------------------
    with timer("spheres"):
        tris = scene.triangles
        ok, skipped = backend.usable(tris)
        usable = np.flatnonzero(ok)
        stats["skipped_triangles"] = skipped
        stats["degenerate_triangles"] = int(scene.n_triangles - usable.size)
        if usable.size == 0:
            raise ValueError(f"scene {scene.name!r} has no usable triangle ({skipped})")
        o_max = 2.0 * s.bound
        margin = (np.zeros(usable.size) if backend.fmt is None else
                  unit_margin(tris[usable], backend.fmt, o_max, backend.mode))
        tree = build_sphere_tree(tris[usable], s.tris_per_sphere, s.fanout, margin)
        tree.leaf_tris = np.where(tree.leaf_tris >= 0, usable[tree.leaf_tris.clip(0)], -1)
        stats.update(spheres=tree.n_leaves, sphere_nodes=tree.n_nodes, levels=tree.levels,
                     sphere_margin_median=float(np.median(margin)))
    # 2. load ------------------------------------------------------------------------
    with timer("load"):
        stats.update(backend.load(tris, tree, s.bound) or {})
    normals_all = face_normals(tris)

    unit = np.zeros(len(COUNTERS), np.int64)
    L = tree.levels
    hier = {"tested": np.zeros(L, np.int64), "dropped": np.zeros(L, np.int64),
            "tris_dropped": np.zeros(L, np.int64), "leaves": 0}
    counts = {"primary_bundles": 0, "primary_rays": 0, "shadow_bundles": 0,
              "shadow_rays": 0, "host_plane_tests": 0, "brute_force_pairs": 0,
              "shadow_spheres_skipped": 0, "early_out_pairs_skipped": 0,
              "unguaranteed_bundles": 0}
    F = scene.n_triangles

    def cull(batch):
        cr = backend.cull(batch, s.hierarchy)
        for k in ("tested", "dropped", "tris_dropped"):
            hier[k] += getattr(cr, k)
        hier["leaves"] += int(cr.leaves.size)
        counts["host_plane_tests"] += cr.plane_tests
        counts["unguaranteed_bundles"] += int(np.count_nonzero(batch.keep_all))
        return cr

    tiles = scene.camera.tiles(W, H, s.rows, s.cols)
    t_org = np.array([t.origin for t in tiles])
    t_cen = np.array([t.centre for t in tiles])
    t_col = np.array([0.5 * t.cols * t.step_col for t in tiles])
    t_row = np.array([0.5 * t.rows * t.step_row for t in tiles])
    t_valid = np.array([t.valid.reshape(-1) for t in tiles])
    t_y0 = np.array([t.y0 for t in tiles], np.int64)
    t_x0 = np.array([t.x0 for t in tiles], np.int64)
    R = s.rows * s.cols
    ii, jj = np.divmod(np.arange(R), s.cols)
    tri_img = np.full((H, W), -1, np.int64)
    t_img = np.full((H, W), np.inf)
    dir_img = np.zeros((H, W, 3))
    org = np.zeros(3)

    rec = {k: [] for k in ("primary_o", "primary_d", "primary_yx", "shadow_o", "shadow_d",
                           "shadow_tmax", "shadow_own", "shadow_point")}
    n_shadow_est = W * H if s.shadows else 0
    bar = tqdm(total=len(tiles) + n_shadow_est, unit="bundle", disable=not s.progress,
               desc=f"render {scene.name} [{backend.name}]", leave=False)
    try:
        # compile (or load from numba's cache) the kernels: its own phase, not a rate
        with timer("compile"):
            bar.set_description_str(f"render {scene.name} [{backend.name}]: compiling "
                                    "kernels (once per machine)")
            backend.warm_pass(t_org[:1], t_cen[:1], t_col[:1], t_row[:1], s.rows, s.cols)
            bar.set_description_str(f"render {scene.name} [{backend.name}]")
            bar.reset(total=len(tiles) + n_shadow_est)

        # 3. primary: all tiles, a pass of ``chunk`` bundles at a time -------------------
        for lo in range(0, len(tiles), s.chunk):
            hi = min(lo + s.chunk, len(tiles))
            with timer("primary cull"):
                batch = backend.batch(t_org[lo:hi], t_cen[lo:hi], t_col[lo:hi], t_row[lo:hi],
                                      s.rows, s.cols, t_valid[lo:hi])
                n_en = int(batch.enable.sum())
                counts["primary_bundles"] += hi - lo
                counts["primary_rays"] += n_en
                counts["brute_force_pairs"] += n_en * F
                cr = cull(batch)
            with timer("primary unit"):
                best_t = np.full((hi - lo, R), np.inf)
                best_tri = np.full((hi - lo, R), -1, np.int64)
                unit += backend.trace(batch, *round_runs(cr.start, cr.leaves, None, 0),
                                      best_t, best_tri, 0.0).sum(axis=0)
            with timer("primary cull"):
                v = t_valid[lo:hi]
                y = (t_y0[lo:hi, None] + ii[None, :])[v]
                x = (t_x0[lo:hi, None] + jj[None, :])[v]
                tri_img[y, x] = best_tri[v]
                t_img[y, x] = best_t[v]
                dir_img[y, x] = batch.directions[v]
                org = batch.origin[-1]
                if s.record_rays:
                    rec["primary_o"].append(np.repeat(batch.origin, v.sum(axis=1), axis=0))
                    rec["primary_d"].append(batch.directions[v])
                    rec["primary_yx"].append(np.stack([y, x], 1))
            bar.update(hi - lo)

        # 4. shading ---------------------------------------------------------------------
        with timer("shading"):
            hit_px = tri_img >= 0
            ys, xs = np.nonzero(hit_px)
            tri_h = tri_img[ys, xs]
            pts = org + t_img[ys, xs, None] * dir_img[ys, xs]
            nrm = normals_all[tri_h]
            flip = np.einsum("ij,ij->i", nrm, dir_img[ys, xs]) > 0
            nrm[flip] *= -1.0
            vis = np.ones(len(ys))
            eps = _shadow_eps(backend, s.bound)
            if s.shadows:
                plan = shadow_bundles(pts, nrm, scene.light, s.shadow_rows, s.shadow_cols, eps)
                no_bundle = np.ones(len(ys), bool)
                no_bundle[plan.point] = False
                vis[no_bundle] = 0.0      # behind the light or facing away: unlit
                stats["points_behind_light"] = plan.behind_light
                stats["points_facing_away"] = plan.facing_away
                bar.total = len(tiles) + len(plan)
                bar.refresh()

        # 5. shadows: passes of ``chunk`` bundles, early-out rounds within each ------------
        if s.shadows:
            nr = s.shadow_rows * s.shadow_cols
            step = s.batch_spheres if s.early_out else None
            for lo in range(0, len(plan), s.chunk):
                hi = min(lo + s.chunk, len(plan))
                k = hi - lo
                with timer("shadow cull"):
                    batch = backend.batch(plan.origins[lo:hi], np.broadcast_to(plan.centre, (k, 3)),
                                          np.broadcast_to(plan.col_axis, (k, 3)),
                                          np.broadcast_to(plan.row_axis, (k, 3)),
                                          s.shadow_rows, s.shadow_cols)
                    counts["shadow_bundles"] += k
                    counts["shadow_rays"] += k * nr
                    counts["brute_force_pairs"] += k * nr * F
                    cr = cull(batch)
                    own = tri_h[plan.point[lo:hi]]
                    best_t = np.full((k, nr), np.inf)
                    best_tri = np.full((k, nr), -1, np.int64)
                rnd = 0
                while True:
                    with timer("shadow cull"):
                        run_b, run_start, run_sph = round_runs(cr.start, cr.leaves, step, rnd)
                        if not run_b.size:
                            break
                        live = batch.enable[run_b].any(axis=1)
                        counts["shadow_spheres_skipped"] += int(
                            np.diff(run_start)[~live].sum())
                        run_b, run_start, run_sph = select_runs(run_b, run_start, run_sph,
                                                                live)
                    with timer("shadow unit"):
                        ctr = backend.trace(batch, run_b, run_start, run_sph, best_t, best_tri,
                                            eps, plan.tmax[lo:hi], own, any_hit=True)
                        unit += ctr.sum(axis=0)
                        counts["early_out_pairs_skipped"] += int(ctr[:, 3].sum())
                    if s.early_out:
                        batch.enable &= ~(best_tri >= 0)
                    rnd += 1
                vis[plan.point[lo:hi]] = 1.0 - (best_tri >= 0).mean(axis=1)
                if s.record_rays:
                    rec["shadow_o"].append(batch.origin)
                    rec["shadow_d"].append(batch.directions)
                    rec["shadow_tmax"].append(plan.tmax[lo:hi])
                    rec["shadow_own"].append(own)
                    rec["shadow_point"].append(plan.point[lo:hi])
                bar.update(k)

        # 6. image -----------------------------------------------------------------------
        with timer("image"):
            img = np.empty((H, W, 3))
            img[:] = np.asarray(scene.background, float)
            col = phong(pts, nrm, scene.colours[tri_h], np.asarray(scene.camera.position, float),
                        scene.light, scene.material_at(tri_h), vis)
            img[ys, xs] = col
            d = dir_img.reshape(-1, 3)
            sees = _light_hits(np.asarray(scene.camera.position, float), d, scene.light,
                               t_img.reshape(-1)).reshape(H, W)
            img[sees] = np.asarray(scene.light.colour, float)
            vis_img = np.full((H, W), np.nan)
            vis_img[ys, xs] = vis
    finally:
        bar.close()

    unit = {name: int(v) for name, v in zip(COUNTERS, unit)}
    stats.update(counts)
    stats["rays"] = counts["primary_rays"] + counts["shadow_rays"]
    stats["bundles"] = counts["primary_bundles"] + counts["shadow_bundles"]
    stats["unit"] = unit
    stats["pairs_issued"] = unit.get("pairs_issued", 0)
    stats["plane_tests"] = counts["host_plane_tests"] + unit.get("plane_tests", 0)
    bf = counts["brute_force_pairs"]
    stats["pair_fraction"] = stats["pairs_issued"] / bf if bf else 0.0
    stats["hits"] = unit.get("hits", 0)
    stats["events"] = {k: unit.get(k, 0) for k in ("overflow", "underflow", "invalid")}
    stats["hierarchy"] = {"tested": hier["tested"].tolist(), "dropped": hier["dropped"].tolist(),
                          "triangles_dropped": hier["tris_dropped"].tolist(),
                          "leaves_to_unit": hier["leaves"]}
    stats["pixels_hit"] = int(hit_px.sum())
    if backend.mode == "certified":
        cert = dict(getattr(backend, "certified", {}))
        cert["uncertain_fraction"] = (cert.get("uncertain", 0) / stats["pairs_issued"]
                                      if stats["pairs_issued"] else 0.0)
        stats["certified"] = cert
    rays = None
    if s.record_rays:
        rays = {k: np.concatenate(v) if v else np.zeros((0,)) for k, v in rec.items()}
        rays["shadow_tmin"] = eps
        rays["loaded"] = usable
    return RenderResult(img, tri_img, t_img, vis_img, stats, dict(timer.times), rays)


# -- output ------------------------------------------------------------------------------

def to_uint8(image: np.ndarray, gamma: float = 2.2) -> np.ndarray:
    """Linear colour to 8-bit sRGB-ish (clip, gamma)."""
    return np.round(255.0 * np.clip(image, 0.0, 1.0) ** (1.0 / gamma)).astype(np.uint8)


def save_png(image: np.ndarray, path, linear: bool = True):
    """Write an image (float linear colour, or uint8) as PNG with Pillow."""
    from PIL import Image

    arr = to_uint8(image) if linear and image.dtype != np.uint8 else image
    Image.fromarray(arr).save(path)


def save_ids(result: RenderResult, path):
    """Per-pixel nearest triangle IDs (-1: none), distances and visibility as ``.npz``."""
    np.savez_compressed(path, tri_id=result.tri_id, t=result.t, visibility=result.visibility)


def difference_image(a: RenderResult, b: RenderResult, gain: float = 4.0) -> np.ndarray:
    """``|a - b|`` of the 8-bit images times ``gain``, with pixels whose nearest triangle
    differs marked magenta (uint8)."""
    d = np.abs(to_uint8(a.image).astype(np.int16) - to_uint8(b.image).astype(np.int16))
    out = np.clip(d * gain, 0, 255).astype(np.uint8)
    out[a.tri_id != b.tri_id] = (255, 0, 255)
    return out


def compare(result: RenderResult, reference: RenderResult) -> dict:
    """Image error of ``result`` against ``reference`` (same size).

    Returns
    -------
    dict
        ``psnr`` (dB, on 8-bit images; ``inf`` when equal), ``max_abs`` (8-bit levels),
        ``tri_differs`` (fraction of pixels whose nearest triangle differs),
        ``hit_differs`` (fraction where one hits and the other does not).
    """
    if result.image.shape != reference.image.shape:
        raise ValueError(f"image sizes differ: {result.image.shape} and "
                         f"{reference.image.shape}")
    a = to_uint8(result.image).astype(np.float64)
    b = to_uint8(reference.image).astype(np.float64)
    mse = float(np.mean((a - b) ** 2))
    psnr = math.inf if mse == 0 else 10.0 * math.log10(255.0 ** 2 / mse)
    return {"psnr": psnr, "max_abs": float(np.max(np.abs(a - b))),
            "tri_differs": float(np.mean(result.tri_id != reference.tri_id)),
            "hit_differs": float(np.mean((result.tri_id >= 0) != (reference.tri_id >= 0)))}


def format_summary(result: RenderResult, comparison: dict | None = None) -> str:
    """A human-readable summary of a render."""
    st, tm = result.stats, result.timings
    bf = st["brute_force_pairs"]
    skipped = ", ".join(f"{k} {v}" for k, v in st["skipped_triangles"].items() if v) or "none"
    lines = [
        (f"scene {st['scene']} ({st['triangles']} triangles, skipped: {skipped}), "
        f"{st['size']}, backend {st['backend']}"),
        (f"  rays      {st['rays']:>12,}  (primary {st['primary_rays']:,}, shadow "
        f"{st['shadow_rays']:,})"),
        (f"  bundles   {st['bundles']:>12,}  (primary {st['primary_bundles']:,}, shadow "
        f"{st['shadow_bundles']:,}; unguaranteed {st['unguaranteed_bundles']:,})"),
        (f"  spheres   {st['spheres']:>12,}  leaf spheres of <= tris/sphere, {st['levels']} "
        f"levels; runs tested {st['unit'].get('spheres', 0):,} leaf spheres"),
        (f"  plane tests {st['plane_tests']:>10,}  (host hierarchy {st['host_plane_tests']:,}, "
        f"unit {st['unit'].get('plane_tests', 0):,})"),
        (f"  pairs     {st['pairs_issued']:>12,}  of {bf:,} brute force "
        f"({100.0 * st['pair_fraction']:.3f} %); early-out skipped "
        f"{st['early_out_pairs_skipped']:,} pairs and {st['shadow_spheres_skipped']:,} "
        f"sphere runs"),
        f"  hits      {st['hits']:>12,}  pixels hit {st['pixels_hit']:,}",
        (f"  events    overflow {st['events']['overflow']:,}, underflow "
        f"{st['events']['underflow']:,}, invalid {st['events']['invalid']:,} (operations)"),
    ]
    if "certified" in st:
        c = st["certified"]
        lines.append(f"  certified uncertain {c['uncertain']:,} pairs "
                     f"({100.0 * c['uncertain_fraction']:.3f} % of issued), certified hits "
                     f"{c['certified_hits']:,}; float64 filter {c['filtered']:,} pairs, "
                     f"exact {c['exact']:,} pairs in {c['exact_s']:.3f}s")
    if "points_behind_light" in st:
        lines.append(f"  shading points without a shadow bundle: behind the light "
                     f"{st['points_behind_light']:,}, facing away {st['points_facing_away']:,}")
    h = st["hierarchy"]
    lvl = ", ".join(f"L{k}: {d}/{t} nodes ({tr:,} tris)" for k, (t, d, tr) in
                    enumerate(zip(h["tested"], h["dropped"], h["triangles_dropped"])) if t)
    lines.append(f"  hierarchy dropped {lvl}")
    lines.append("  time      " + ", ".join(f"{k} {v:.2f}s" for k, v in tm.items())
                 + f"; total {sum(tm.values()):.2f}s")
    if comparison:
        lines.append(f"  vs float64: PSNR {comparison['psnr']:.2f} dB, max diff "
                     f"{comparison['max_abs']:.0f}/255, nearest triangle differs on "
                     f"{100 * comparison['tri_differs']:.3f} % of pixels, hit/miss differs on "
                     f"{100 * comparison['hit_differs']:.3f} %")
    return "\n".join(lines)
