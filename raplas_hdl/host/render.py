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

Writing a result (PNG, ids), comparing two and the printed summary:
:mod:`raplas_hdl.host.output`.

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

import time
from contextlib import contextmanager
from dataclasses import dataclass, field

import numba
import numpy as np

from .backends import Backend
from .scene_file import MAX_DEPTH, MAX_SECONDARY_LATTICE
from .scene import Scene
from .secondary import Tracer, whitted
from .shading import face_normals, light_hits, phong, shadow_bundles
from .spheres import build_sphere_tree
from .tracing import Tally, nearest_pass

__all__ = ["RenderResult", "RenderSettings", "render"]


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
    depth : int
        Generations of reflection and refraction rays (0: none; docs/secondary-rays.md).
    glossy_rows, glossy_cols : int
        Glossy bundle of a point whose material has ``gloss_angle > 0`` (0: such materials
        use the single mirror ray).
    ao_rows, ao_cols : int
        Ambient-occlusion bundle of every primary point (0: no ambient occlusion).
    ao_angle : float
        Half-angle in degrees of the ambient-occlusion cone, above 0 and below 90.
    ao_distance : float
        Reach of an ambient-occlusion ray as a fraction of the normalised scene's extent
        (``tmax = ao_distance * 2 * bound``), above 0 and at most 1.
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
    depth: int = 0
    glossy_rows: int = 0
    glossy_cols: int = 0
    ao_rows: int = 0
    ao_cols: int = 0
    ao_angle: float = 60.0
    ao_distance: float = 0.25

    def __post_init__(self):
        for name in ("width", "height", "rows", "cols", "tris_per_sphere", "batch_spheres",
                     "chunk"):
            if int(getattr(self, name)) < 1:
                raise ValueError(f"{name} must be at least 1, not {getattr(self, name)}")
        if (self.shadow_rows == 0) != (self.shadow_cols == 0) or min(
                self.shadow_rows, self.shadow_cols) < 0:
            raise ValueError("shadow_rows and shadow_cols must both be positive (or both 0 "
                             "for no shadows)")
        for name in ("depth", "glossy_rows", "glossy_cols", "ao_rows", "ao_cols"):
            v = getattr(self, name)
            if not isinstance(v, (int, np.integer)) or isinstance(v, bool) or v < 0:
                raise ValueError(f"{name} must be a non-negative integer, not {v!r}")
        if self.depth > MAX_DEPTH:
            raise ValueError(f"depth must be at most {MAX_DEPTH}, not {self.depth}")
        for kind in ("glossy", "ao"):
            r, c = getattr(self, f"{kind}_rows"), getattr(self, f"{kind}_cols")
            if (r == 0) != (c == 0) or max(r, c) > MAX_SECONDARY_LATTICE:
                raise ValueError(f"{kind}_rows and {kind}_cols must both be 1 to "
                                 f"{MAX_SECONDARY_LATTICE} (or both 0 for none), not {r}x{c}")
        if not 0.0 < float(self.ao_angle) < 90.0:
            raise ValueError(f"ao_angle must be above 0 and below 90 degrees, not "
                             f"{self.ao_angle}")
        if not 0.0 < float(self.ao_distance) <= 1.0:
            raise ValueError(f"ao_distance must be above 0 and at most 1 (a fraction of the "
                             f"scene's extent), not {self.ao_distance}")

    @property
    def shadows(self) -> bool:
        return self.shadow_rows > 0

    @classmethod
    def for_scene(cls, scene: Scene, **settings) -> RenderSettings:
        """Settings with the scene's defaults (a scene file's ``[render]`` table,
        :attr:`Scene.render_defaults`) under ``settings``."""
        return cls(**{**getattr(scene, "render_defaults", {}), **settings})


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
        ``loaded``: the IDs of the triangles the backend loaded. Only the shadow rays of
        primary points are recorded here (not those of secondary hits). ``passes``: every
        pass of every ray type (primary, shadow, reflection, refraction, glossy, ambient
        occlusion), chunk by chunk, with its rays, window and answers
        (:meth:`raplas_hdl.host.tracing.Tally.record`;
        :func:`raplas_hdl.host.reference.check_passes` checks them).
    layers : dict
        Per-pixel (H, W) arrays of the first secondary bounce (empty when no secondary ray
        ran): ``reflection_tri``, ``refraction_tri`` (nearest triangle of the pixel's
        depth-1 mirror or refracted ray; -1 miss; -2 no such ray), ``glossy_hit`` (fraction
        of the pixel's glossy rays that hit, NaN for none), ``ao`` (unoccluded fraction,
        NaN for none).
    """

    image: np.ndarray
    tri_id: np.ndarray
    t: np.ndarray
    visibility: np.ndarray
    stats: dict = field(default_factory=dict)
    timings: dict = field(default_factory=dict)
    rays: dict | None = None
    layers: dict = field(default_factory=dict)


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


def _shadow_eps(backend: Backend, bound: float) -> float:
    """Lift of shadow origins and their ``tmin``: ``bound * max(2**-11, 2**(4-M))``."""
    m = backend.fmt.man_bits if backend.fmt is not None else 52
    return bound * max(2.0 ** -11, 2.0 ** (4 - m))


@contextmanager
def _numba_threads(n: int | None):
    """Run the compiled passes on ``n`` threads (None: leave numba's setting)."""
    if n is None:
        yield
        return
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
    from tqdm import tqdm       # lazy: the progress bar loads only when a render runs

    s = settings
    backend.check_settings(s)
    timer = _Timer()
    stats: dict = {"backend": backend.describe(), "scene": scene.name,
                   "triangles": scene.n_triangles, "size": f"{s.width}x{s.height}"}
    with timer("spheres"):
        tris, usable, tree = _spheres(scene, backend, s, stats)
    with timer("load"):
        stats.update(backend.load(tris, tree, s.bound) or {})
    normals_all = face_normals(tris)
    tally = Tally(scene.n_triangles, tree.levels, s.hierarchy, record=s.record_rays)
    tiles = _Tiles.of(scene, s)
    rec = {k: [] for k in ("primary_o", "primary_d", "primary_yx", "shadow_o", "shadow_d",
                           "shadow_tmax", "shadow_own", "shadow_point")}
    layers: dict = {}
    bar = tqdm(total=tiles.n, unit="bundle", disable=not s.progress,
               desc=f"render {scene.name} [{backend.name}]", leave=False)
    eps = _shadow_eps(backend, s.bound)
    tracer = Tracer(backend, scene, s, tally, normals_all, eps, timer, bar)
    try:
        with timer("compile"):
            _compile(backend, tiles, s, bar, f"render {scene.name} [{backend.name}]")
        prim = _primary(backend, tiles, s, tally, timer, bar, rec)
        with timer("shading"):
            pt = _Points.of(prim, normals_all)
        vis = _shadows(tracer, scene, s, pt, stats, timer, rec, eps)
        ao = tracer.occlusion(pt.pts, pt.nrm, pt.tri) if s.ao_rows else None
        with timer("image"):
            img, vis_img, sees = _compose(scene, prim, pt, vis, ao, layers)
        if s.depth > 0:
            _secondary(tracer, prim, pt, sees, img, layers)
    finally:
        bar.close()
    _summarise(stats, tally, prim)
    backend.report(stats)       # the render mode's figures, the on-chip reduction's beats
    rays = None
    if s.record_rays:
        rays = {k: np.concatenate(v) if v else np.zeros((0,)) for k, v in rec.items()}
        rays["shadow_tmin"] = eps
        rays["loaded"] = usable
        rays["passes"] = tally.passes
    return RenderResult(img, prim.tri, prim.t, vis_img, stats, dict(timer.times), rays,
                        layers)


# -- the stages, in the order _render runs them ----------------------------------------------
def _spheres(scene: Scene, backend: Backend, s: RenderSettings, stats: dict):
    """The usable triangles (the others counted) and their sphere hierarchy, with the
    unit's conservative margin when that mode is on: ``(tris, usable, tree)``."""
    tris = scene.triangles
    ok, skipped = backend.usable(tris)
    usable = np.flatnonzero(ok)
    stats["skipped_triangles"] = skipped
    stats["degenerate_triangles"] = int(scene.n_triangles - usable.size)
    if usable.size == 0:
        raise ValueError(f"scene {scene.name!r} has no usable triangle ({skipped})")
    o_max = 2.0 * s.bound
    margin = backend.sphere_margin(tris[usable], o_max)
    tree = build_sphere_tree(tris[usable], s.tris_per_sphere, s.fanout, margin)
    tree.leaf_tris = np.where(tree.leaf_tris >= 0, usable[tree.leaf_tris.clip(0)], -1)
    stats.update(spheres=tree.n_leaves, sphere_nodes=tree.n_nodes, levels=tree.levels,
                 sphere_margin_median=float(np.median(margin)))
    return tris, usable, tree


@dataclass
class _Tiles:
    """The camera's tiles as arrays, one row per primary bundle."""

    org: np.ndarray
    cen: np.ndarray
    col: np.ndarray
    row: np.ndarray
    valid: np.ndarray       # (bundles, rows * cols): lattice points inside the image
    y0: np.ndarray
    x0: np.ndarray

    @property
    def n(self) -> int:
        return len(self.org)

    @classmethod
    def of(cls, scene: Scene, s: RenderSettings) -> _Tiles:
        tiles = scene.camera.tiles(s.width, s.height, s.rows, s.cols)
        return cls(np.array([t.origin for t in tiles]), np.array([t.centre for t in tiles]),
                   np.array([0.5 * t.cols * t.step_col for t in tiles]),
                   np.array([0.5 * t.rows * t.step_row for t in tiles]),
                   np.array([t.valid.reshape(-1) for t in tiles]),
                   np.array([t.y0 for t in tiles], np.int64),
                   np.array([t.x0 for t in tiles], np.int64))


def _compile(backend: Backend, tiles: _Tiles, s: RenderSettings, bar, desc: str) -> None:
    """Compile (or load from numba's cache) the kernels with a pass of one bundle: its own
    phase, not a rate."""
    bar.set_description_str(f"{desc}: compiling kernels (once per machine)")
    backend.warm_pass(tiles.org[:1], tiles.cen[:1], tiles.col[:1], tiles.row[:1], s.rows,
                      s.cols)
    bar.set_description_str(desc)
    bar.reset(total=tiles.n)


@dataclass
class _Primary:
    """The primary pass's per-pixel images: nearest triangle (-1 none), its distance (inf
    none), the ray's direction, and the camera's origin."""

    tri: np.ndarray
    t: np.ndarray
    dirs: np.ndarray
    origin: np.ndarray


def _primary(backend: Backend, tiles: _Tiles, s: RenderSettings, tally: Tally, timer, bar,
             rec: dict) -> _Primary:
    """The primary stage: all tiles, a pass of ``chunk`` bundles at a time, into the
    per-pixel images."""
    W, H = s.width, s.height
    ii, jj = np.divmod(np.arange(s.rows * s.cols), s.cols)
    out = _Primary(np.full((H, W), -1, np.int64), np.full((H, W), np.inf), np.zeros((H, W, 3)),
                   np.zeros(3))

    def primary_chunk(lo, hi, batch, best_t, best_tri):
        v = tiles.valid[lo:hi]
        y = (tiles.y0[lo:hi, None] + ii[None, :])[v]
        x = (tiles.x0[lo:hi, None] + jj[None, :])[v]
        out.tri[y, x] = best_tri[v]
        out.t[y, x] = best_t[v]
        out.dirs[y, x] = batch.directions[v]
        out.origin = batch.origin[-1]
        if s.record_rays:
            rec["primary_o"].append(np.repeat(batch.origin, v.sum(axis=1), axis=0))
            rec["primary_d"].append(batch.directions[v])
            rec["primary_yx"].append(np.stack([y, x], 1))

    nearest_pass(backend, tiles.org, tiles.cen, tiles.col, tiles.row, s.rows, s.cols,
                 tally=tally, kind="primary", chunk=s.chunk, enable=tiles.valid, timer=timer,
                 progress=bar.update, on_chunk=primary_chunk)
    return out


@dataclass
class _Points:
    """The primary hits: pixel rows and columns, triangle, point, normal facing the
    camera."""

    ys: np.ndarray
    xs: np.ndarray
    tri: np.ndarray
    pts: np.ndarray
    nrm: np.ndarray

    @classmethod
    def of(cls, prim: _Primary, normals_all: np.ndarray) -> _Points:
        ys, xs = np.nonzero(prim.tri >= 0)
        tri_h = prim.tri[ys, xs]
        pts = prim.origin + prim.t[ys, xs, None] * prim.dirs[ys, xs]
        nrm = normals_all[tri_h]
        flip = np.einsum("ij,ij->i", nrm, prim.dirs[ys, xs]) > 0
        nrm[flip] *= -1.0
        return cls(ys, xs, tri_h, pts, nrm)


def _shadows(tracer: Tracer, scene: Scene, s: RenderSettings, pt: _Points, stats: dict, timer,
             rec: dict, eps: float) -> np.ndarray:
    """The shadow stage: shadow bundles in passes of ``chunk``, early-out rounds within
    each: the fraction of the light each point sees."""
    plan = None
    if s.shadows:
        with timer("shading"):
            plan = shadow_bundles(pt.pts, pt.nrm, scene.light, s.shadow_rows, s.shadow_cols,
                                  eps)
        stats["points_behind_light"] = plan.behind_light
        stats["points_facing_away"] = plan.facing_away

    def shadow_chunk(lo, hi, batch, blocked):
        rec["shadow_o"].append(batch.origin)
        rec["shadow_d"].append(batch.directions)
        rec["shadow_tmax"].append(plan.tmax[lo:hi])
        rec["shadow_own"].append(pt.tri[plan.point[lo:hi]])
        rec["shadow_point"].append(plan.point[lo:hi])

    vis, _ = tracer.shadows(pt.pts, pt.nrm, pt.tri, shadow_chunk if s.record_rays else None,
                            plan)
    return vis


def _compose(scene: Scene, prim: _Primary, pt: _Points, vis, ao, layers: dict):
    """The direct image (Phong terms of the hits, the light where a primary ray sees
    it, the background elsewhere): ``(image, visibility image, sees-the-light mask)``;
    the ambient-occlusion layer into ``layers``."""
    H, W = prim.tri.shape
    img = np.empty((H, W, 3))
    img[:] = np.asarray(scene.background, float)
    eye = np.asarray(scene.camera.position, float)
    img[pt.ys, pt.xs] = phong(pt.pts, pt.nrm, scene.colours[pt.tri], eye, scene.light,
                              scene.material_at(pt.tri), vis, ao)
    sees = light_hits(eye, prim.dirs.reshape(-1, 3), scene.light,
                      prim.t.reshape(-1)).reshape(H, W)
    img[sees] = np.asarray(scene.light.colour, float)
    vis_img = np.full((H, W), np.nan)
    vis_img[pt.ys, pt.xs] = vis
    if ao is not None:
        layers["ao"] = np.full((H, W), np.nan)
        layers["ao"][pt.ys, pt.xs] = ao
    return img, vis_img, sees


def _secondary(tracer: Tracer, prim: _Primary, pt: _Points, sees, img, layers: dict) -> None:
    """Secondary rays: reflection, refraction and glossy rays, a generation at a time,
    added to ``img``; their first bounce's layers into ``layers``."""
    H, W = prim.tri.shape
    pix = pt.ys * W + pt.xs
    add, sec = whitted(tracer, pix, pt.pts, pt.nrm, pt.tri, prim.dirs[pt.ys, pt.xs],
                       (~sees[pt.ys, pt.xs]).astype(float), H * W)
    img += add.reshape(H, W, 3)
    layers.update({k: v.reshape(H, W) for k, v in sec.items()})


def _summarise(stats: dict, tally: Tally, prim: _Primary) -> None:
    """The run's figures from the tally (rays, bundles, plane tests, pairs, hits, events,
    the hierarchy's skips) into ``stats``."""
    unit = tally.unit_total()
    types = tally.ray_types()
    kinds = tally.kinds
    for kind in ("primary", "shadow"):
        stats[f"{kind}_bundles"] = kinds.get(kind, {}).get("bundles", 0)
        stats[f"{kind}_rays"] = kinds.get(kind, {}).get("rays", 0)
    stats["host_plane_tests"] = sum(k["host_plane_tests"] for k in kinds.values())
    stats["brute_force_pairs"] = sum(k["brute_force_pairs"] for k in kinds.values())
    stats["shadow_spheres_skipped"] = kinds.get("shadow", {}).get("spheres_skipped", 0)
    stats["early_out_pairs_skipped"] = sum(k["early_out_pairs_skipped"]
                                           for k in kinds.values())
    stats["unguaranteed_bundles"] = tally.unguaranteed_bundles
    stats["rays"] = sum(k["rays"] for k in kinds.values())
    stats["bundles"] = sum(k["bundles"] for k in kinds.values())
    stats["unit"] = unit
    stats["pairs_issued"] = unit.get("pairs_issued", 0)
    stats["plane_tests"] = stats["host_plane_tests"] + unit.get("plane_tests", 0)
    bf = stats["brute_force_pairs"]
    stats["pair_fraction"] = stats["pairs_issued"] / bf if bf else 0.0
    stats["hits"] = unit.get("hits", 0)
    stats["ray_types"] = types
    stats["events"] = {k: unit.get(k, 0) for k in ("overflow", "underflow", "invalid")}
    hier = tally.hier
    stats["hierarchy"] = {"tested": hier["tested"].tolist(), "dropped": hier["dropped"].tolist(),
                          "triangles_dropped": hier["tris_dropped"].tolist(),
                          "leaves_to_unit": hier["leaves"]}
    stats["pixels_hit"] = int((prim.tri >= 0).sum())
