"""What the host writes into the intersection unit: configuration, memories, address map.

Shared by the golden model (:mod:`raplas_hdl.model.intersection`), the host backends and
the RTL driver, so that all of them read the same memories the same way. No Amaranth.

The four memories of ``docs/raplas.md`` hold bit patterns of the unit's format
(``uint32`` arrays):

- :class:`SceneMemory` (written once per scene): Triangle Memory (V0, E1, E2, N) and Sphere
  Memory (centre, radius, the IDs of up to ``tris_per_sphere`` triangles);
- :class:`BundleMemory` (written once per bundle, into one of two banks): Plane Memory
  (``rows`` row planes then ``cols`` column planes, unit normal n and offset p) and Ray
  Memory (origin, direction and an enable bit per ray; ray ``(i, j)`` has ID ``i*cols+j``),
  plus the bank's *run list* of sphere IDs when a run names its spheres by list.

Address map of the unit's write port
------------------------------------
One 32-bit word per write; a field narrower than 32 bits takes the low bits of the word::

    addr = region << 28 | bank << 27 | index << 4 | field

==========  ======  =====  =========================  ==============================
region      name    bank   index                      field
==========  ======  =====  =========================  ==============================
0           TRI     0      triangle ID                0-2 V0 xyz, 3-5 E1, 6-8 E2, 9-11 N
1           SPHERE  0      sphere ID                  0-2 centre xyz, 3 radius,
                                                      4 number of triangles
2           TLIST   0      sphere ID * tris_per_sphere  0: triangle ID of list entry
                           + k                        k of the sphere
3           PLANE   0/1    plane ID (rows, then cols)  0-2 n xyz, 3 p
4           RAY     0/1    ray ID (i*cols + j)         0-2 O xyz, 3-5 D xyz, 6 enable (bit 0)
5           RLIST   0/1    position in the run list    0: sphere ID
6           WINDOW  0/1    0                           0: tmin, 1: excluded triangle
                                                      ID + 1 (0: none), 2: any-hit
                                                      (bit 0)
==========  ======  =====  =========================  ==============================

Writes to an index outside the memory's depth, or to an unused field, are ignored.
With the on-chip reduction (``UnitConfig.reduce``), RAY field 7 is the ray's ``tmax`` and
the WINDOW region holds the bank's acceptance window and mode
(:mod:`raplas_hdl.model.reduction`); without it both are ignored.

Runs
----
A *run* (:class:`Run`) is what one command of the unit's ``cmd`` stream (the record
:data:`raplas_hdl.model.records.CMD`) does: a bundle (already in a bank), the spheres to
test against it, and the ``keep_all`` bit (cull nothing). The bit is the command's, so it
is per run: the same bundle in the same bank can be run culled and unculled, and a
keep-all run writes no memory. A host that finds a bundle over the culling budget marks
the bundle instead (:attr:`BundleMemory.keep_all`, not written into the unit): every run
of a marked bundle is sent with the bit set. So a run culls nothing when its own
``keep_all`` or its bundle's is set (:func:`as_run`, and ``run_bundle``). Drivers take runs
as ``Run`` or as plain ``(bundle, sphere_ids)`` and ``(bundle, sphere_ids, keep_all)``
tuples.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from .config import ADDRESS_INDEX_BITS, UnitConfig, check_int
from .modes import MODES
from .reduction import check_window

__all__ = ["SceneMemory", "BundleMemory", "REGIONS", "write_address", "scene_writes",
           "bundle_writes", "run_list_writes", "MODES", "Run", "as_run"]


#: Regions of the write-port address map.
REGIONS = {"tri": 0, "sphere": 1, "tlist": 2, "plane": 3, "ray": 4, "rlist": 5,
           "window": 6}
_REGION_SHIFT = 28
_BANK_SHIFT = 27
_INDEX_SHIFT = 4
_MAX_INDEX = (1 << ADDRESS_INDEX_BITS) - 1
assert _INDEX_SHIFT + ADDRESS_INDEX_BITS == _BANK_SHIFT

def _u32(name, a, shape_tail, fmt=None):
    a = np.asarray(a)
    if a.dtype.kind not in "ui":
        raise ValueError(f"{name} must be an integer array of bit patterns, not {a.dtype}")
    if a.ndim != 1 + len(shape_tail) or tuple(a.shape[1:]) != tuple(shape_tail):
        raise ValueError(f"{name} must have shape (n, {', '.join(map(str, shape_tail))}), "
                         f"not {a.shape}".replace(", )", ")"))
    if a.size and (a.min() < 0 or (fmt is not None and a.max() > fmt.mask)):
        raise ValueError(f"{name} holds patterns wider than the format")
    return np.ascontiguousarray(a, dtype=np.uint32)


@dataclass
class SceneMemory:
    """Triangle Memory and Sphere Memory of one scene, as bit patterns.

    Parameters
    ----------
    v0, e1, e2, n : (T, 3) uint32
        Triangle records (V0, E1 = V1-V0, E2 = V2-V0, N = E1 x E2); triangle ID = row.
    centres : (S, 3) uint32
        Sphere centres; sphere ID = row.
    radii : (S,) uint32
        Sphere radii (already inflated by the host as the culling bound requires).
    tri_lists : (S, L) uint32, L <= tris_per_sphere
        Triangle IDs of each sphere; entries past ``tri_counts[s]`` are ignored.
    tri_counts : (S,) uint32
        Number of triangles of each sphere (0 .. L).
    """

    v0: np.ndarray
    e1: np.ndarray
    e2: np.ndarray
    n: np.ndarray
    centres: np.ndarray
    radii: np.ndarray
    tri_lists: np.ndarray
    tri_counts: np.ndarray

    def __post_init__(self):
        for name in ("v0", "e1", "e2", "n", "centres"):
            setattr(self, name, _u32(name, getattr(self, name), (3,)))
        self.radii = _u32("radii", self.radii, ())
        tl = np.asarray(self.tri_lists)
        if tl.ndim != 2:
            raise ValueError(f"tri_lists must have shape (n_spheres, L), not {tl.shape}")
        self.tri_lists = _u32("tri_lists", tl, (tl.shape[1],))
        self.tri_counts = _u32("tri_counts", self.tri_counts, ())
        t = self.v0.shape[0]
        if not (self.e1.shape[0] == self.e2.shape[0] == self.n.shape[0] == t):
            raise ValueError("v0, e1, e2 and n must have the same number of triangles")
        s = self.centres.shape[0]
        if not (self.radii.shape[0] == self.tri_lists.shape[0] == self.tri_counts.shape[0]
                == s):
            raise ValueError("centres, radii, tri_lists and tri_counts must have the same "
                             "number of spheres")
        if s and self.tri_counts.max() > self.tri_lists.shape[1]:
            raise ValueError("tri_counts exceeds the width of tri_lists")
        used = np.arange(self.tri_lists.shape[1])[None, :] < self.tri_counts[:, None]
        if used.any() and self.tri_lists[used].max() >= t:
            raise ValueError("tri_lists names a triangle ID beyond the triangle records")

    @property
    def n_triangles(self) -> int:
        return self.v0.shape[0]

    @property
    def n_spheres(self) -> int:
        return self.centres.shape[0]

    def check(self, config: UnitConfig):
        """Raise ``ValueError`` if the scene does not fit the unit ``config``."""
        if self.n_triangles > config.max_triangles:
            raise ValueError(f"{self.n_triangles} triangles exceed max_triangles="
                             f"{config.max_triangles}")
        if self.n_spheres > config.max_spheres:
            raise ValueError(f"{self.n_spheres} spheres exceed max_spheres="
                             f"{config.max_spheres}")
        if self.n_spheres and self.tri_counts.max() > config.tris_per_sphere:
            raise ValueError(f"a sphere holds {int(self.tri_counts.max())} triangles, more "
                             f"than tris_per_sphere={config.tris_per_sphere}")
        for name in ("v0", "e1", "e2", "n", "centres", "radii"):
            a = getattr(self, name)
            if a.size and a.max() > config.fmt.mask:
                raise ValueError(f"{name} holds patterns wider than {config.fmt}")


@dataclass
class BundleMemory:
    """Plane Memory and Ray Memory of one bundle, as bit patterns.

    Parameters
    ----------
    plane_n : (rows+cols, 3) uint32
        Unit normals: row planes 0..rows-1, then column planes.
    plane_p : (rows+cols,) uint32
        Plane offsets (plane: n.x + p = 0).
    ray_o, ray_d : (rows*cols, 3) uint32
        Ray origins and unit directions; ray (i, j) is row ``i*cols + j``.
    enable : (rows*cols,) bool, optional
        Enable bit of each ray (default: all enabled).
    keep_all : bool
        The host's mark for a bundle over the culling budget: every run of it is sent with
        the command's ``keep_all`` bit (nothing culled). Not a memory of the unit.
    tmin : int
        Bit pattern of the acceptance window's lower end, finite (default 0: +0.0); used by
        the on-chip reduction only, as ``tmax``, ``exclude`` and ``any_hit``
        (:mod:`raplas_hdl.model.reduction`).
    tmax : (rows*cols,) uint32, optional
        Per ray, the window's upper end: a finite pattern or +infinity (default: +infinity).
    exclude : int
        A triangle ID no answer may be (-1: none), e.g. a shadow bundle's own triangle.
    any_hit : bool
        The bundle's rays want any accepted hit (shadow rays), not the nearest.
    """

    plane_n: np.ndarray
    plane_p: np.ndarray
    ray_o: np.ndarray
    ray_d: np.ndarray
    enable: np.ndarray | None = None
    keep_all: bool = False
    tmin: int = 0
    tmax: np.ndarray | None = None
    exclude: int = -1
    any_hit: bool = False

    def __post_init__(self):
        self.plane_n = _u32("plane_n", self.plane_n, (3,))
        self.plane_p = _u32("plane_p", self.plane_p, ())
        self.ray_o = _u32("ray_o", self.ray_o, (3,))
        self.ray_d = _u32("ray_d", self.ray_d, (3,))
        if self.plane_p.shape[0] != self.plane_n.shape[0]:
            raise ValueError("plane_n and plane_p must have the same number of planes")
        if self.ray_o.shape != self.ray_d.shape:
            raise ValueError("ray_o and ray_d must have the same shape")
        if self.enable is None:
            self.enable = np.ones(self.ray_o.shape[0], dtype=bool)
        else:
            en = np.asarray(self.enable)
            if en.shape != (self.ray_o.shape[0],):
                raise ValueError(f"enable must have shape ({self.ray_o.shape[0]},), "
                                 f"not {en.shape}")
            self.enable = en.astype(bool)
        self.keep_all = bool(self.keep_all)
        check_int("tmin", self.tmin, 0, 0xFFFFFFFF)
        self.tmin = int(self.tmin)
        if self.tmax is not None:
            self.tmax = _u32("tmax", np.asarray(self.tmax).reshape(-1), ())
            if self.tmax.shape[0] != self.ray_o.shape[0]:
                raise ValueError(f"tmax must have one pattern per ray "
                                 f"({self.ray_o.shape[0]}), not {self.tmax.shape[0]}")
        check_int("exclude", self.exclude, -1)
        self.exclude = int(self.exclude)
        self.any_hit = bool(self.any_hit)

    def check(self, config: UnitConfig):
        """Raise ``ValueError`` if the bundle does not fit the unit ``config``."""
        if self.plane_n.shape[0] != config.n_planes:
            raise ValueError(f"the bundle has {self.plane_n.shape[0]} planes; the unit "
                             f"needs rows+cols = {config.n_planes}")
        if self.ray_o.shape[0] != config.n_rays:
            raise ValueError(f"the bundle has {self.ray_o.shape[0]} rays; the unit needs "
                             f"rows*cols = {config.n_rays}")
        for name in ("plane_n", "plane_p", "ray_o", "ray_d"):
            a = getattr(self, name)
            if a.size and a.max() > config.fmt.mask:
                raise ValueError(f"{name} holds patterns wider than {config.fmt}")
        if config.reduce:
            check_window(config, self)

    def window_tmax(self, config: UnitConfig) -> np.ndarray:
        """Per ray, the ``tmax`` pattern the unit holds (+infinity where none was given)."""
        if self.tmax is not None:
            return self.tmax
        inf = ((1 << config.fmt.exp_bits) - 1) << config.fmt.man_bits
        return np.full(self.ray_o.shape[0], inf, np.uint32)


class Run(NamedTuple):
    """One run of the unit: ``bundle`` against ``sphere_ids`` (None: every sphere of the
    scene, in memory order), with the command's ``keep_all`` bit (no culling; see
    :func:`as_run` for the bundle's own mark)."""

    bundle: BundleMemory
    sphere_ids: object = None
    keep_all: bool = False


def as_run(run) -> Run:
    """A :class:`Run` from a ``Run``, ``(bundle, sphere_ids)`` or
    ``(bundle, sphere_ids, keep_all)``; its ``keep_all`` is the command bit the run is sent
    with: the run's own or its bundle's (:attr:`BundleMemory.keep_all`).

    Raises
    ------
    ValueError
        For anything else.
    """
    if isinstance(run, Run):
        out = run
    elif isinstance(run, tuple) and len(run) in (2, 3):
        out = Run(*run)
    else:
        raise ValueError("a run is (bundle, sphere_ids) or (bundle, sphere_ids, keep_all), "
                         f"not {run!r}")
    if not isinstance(out.bundle, BundleMemory):
        raise ValueError(f"a run's bundle must be a BundleMemory, not {out.bundle!r}")
    return out._replace(keep_all=bool(out.keep_all) or bool(out.bundle.keep_all))


# -- address map ----------------------------------------------------------------------------
def write_address(region: str, index, field=0, bank: int = 0):
    """Word address of ``field`` of entry ``index`` in ``region`` (vectorised over index)."""
    if region not in REGIONS:
        raise ValueError(f"region must be one of {', '.join(REGIONS)}, not {region!r}")
    if bank not in (0, 1):
        raise ValueError(f"bank must be 0 or 1, not {bank!r}")
    index = np.asarray(index, dtype=np.uint64)
    if index.size and index.max() > _MAX_INDEX:
        raise ValueError(f"index beyond the address map ({_MAX_INDEX})")
    field = np.asarray(field, dtype=np.uint64)
    if field.size and field.max() > 15:
        raise ValueError("field must be 0 .. 15")
    addr = ((np.uint64(REGIONS[region]) << np.uint64(_REGION_SHIFT))
            | (np.uint64(bank) << np.uint64(_BANK_SHIFT))
            | (index << np.uint64(_INDEX_SHIFT)) | field)
    return addr.astype(np.uint32)


def _record_writes(region, fields: list, bank=0):
    """(addr, data) for records whose field ``f`` of entry ``i`` is ``fields[f][i]``."""
    n = len(fields[0])
    idx = np.repeat(np.arange(n, dtype=np.uint64), len(fields))
    fld = np.tile(np.arange(len(fields), dtype=np.uint64), n)
    data = np.stack([np.asarray(f, dtype=np.uint32) for f in fields], axis=1).reshape(-1)
    return write_address(region, idx, fld, bank), data


def scene_writes(config: UnitConfig, scene: SceneMemory):
    """Writes ``(addr, data)`` (uint32 arrays) that load ``scene`` into the unit."""
    scene.check(config)
    tri_fields = [scene.v0[:, k] for k in range(3)] + [scene.e1[:, k] for k in range(3)] + \
        [scene.e2[:, k] for k in range(3)] + [scene.n[:, k] for k in range(3)]
    a1, d1 = _record_writes("tri", tri_fields)
    sph_fields = [scene.centres[:, k] for k in range(3)] + [scene.radii, scene.tri_counts]
    a2, d2 = _record_writes("sphere", sph_fields)
    s_idx, k_idx = np.nonzero(np.arange(scene.tri_lists.shape[1])[None, :]
                              < scene.tri_counts[:, None])
    a3 = write_address("tlist", s_idx.astype(np.uint64) * config.tris_per_sphere + k_idx)
    d3 = scene.tri_lists[s_idx, k_idx]
    return np.concatenate([a1, a2, a3]), np.concatenate([d1, d2, d3]).astype(np.uint32)


@functools.lru_cache(maxsize=64)
def _bundle_addresses(n_planes: int, n_rays: int, ray_fields: int, bank: int):
    """The addresses :func:`bundle_writes` writes, which depend on the lattice only:
    ``(plane records, ray records, enable bits, window)``, each a read-only uint32 array."""
    out = (_record_writes("plane", [np.zeros(n_planes)] * 4, bank)[0],
           _record_writes("ray", [np.zeros(n_rays)] * ray_fields, bank)[0],
           write_address("ray", np.arange(n_rays), 6, bank),
           write_address("window", np.zeros(3, np.int64), np.arange(3), bank))
    for a in out:
        a.setflags(write=False)
    return out


def bundle_writes(config: UnitConfig, bundle: BundleMemory, bank: int = 0,
                  enable_only: bool = False):
    """Writes that load ``bundle`` into ``bank`` (only the enable bits if ``enable_only``).
    With ``config.reduce`` they also write the rays' ``tmax`` (RAY field 7) and the bank's
    window (WINDOW region). The addresses come from a table per lattice and bank: a run
    costs a few array copies (the rtl backend encodes every run of a render)."""
    bundle.check(config)
    if bank not in (0, 1):
        raise ValueError(f"bank must be 0 or 1, not {bank!r}")
    en = bundle.enable.astype(np.uint32)
    n_p, n_r = bundle.plane_n.shape[0], bundle.ray_o.shape[0]
    a_plane, a_ray, a_en, a_win = _bundle_addresses(n_p, n_r, 8 if config.reduce else 7, bank)
    if enable_only:
        return a_en.copy(), en
    pd = np.empty((n_p, 4), np.uint32)
    pd[:, :3] = bundle.plane_n
    pd[:, 3] = bundle.plane_p
    rd = np.empty((n_r, 8 if config.reduce else 7), np.uint32)
    rd[:, 0:3] = bundle.ray_o
    rd[:, 3:6] = bundle.ray_d
    rd[:, 6] = en
    if not config.reduce:
        return np.concatenate([a_plane, a_ray]), np.concatenate([pd.reshape(-1),
                                                                 rd.reshape(-1)])
    rd[:, 7] = bundle.window_tmax(config)
    d3 = np.array([bundle.tmin, bundle.exclude + 1, int(bundle.any_hit)], np.uint32)
    return (np.concatenate([a_plane, a_ray, a_win]),
            np.concatenate([pd.reshape(-1), rd.reshape(-1), d3]))


def run_list_writes(config: UnitConfig, sphere_ids, bank: int = 0):
    """Writes that put ``sphere_ids`` into the run list of ``bank``."""
    ids = np.asarray(sphere_ids, dtype=np.int64).reshape(-1)
    if ids.size > config.max_spheres:
        raise ValueError(f"a run list holds at most max_spheres={config.max_spheres} IDs")
    if ids.size and (ids.min() < 0 or ids.max() >= config.max_spheres):
        raise ValueError("sphere ID outside Sphere Memory")
    if bank not in (0, 1):
        raise ValueError(f"bank must be 0 or 1, not {bank!r}")
    return _rlist_addresses(config.max_spheres, bank)[:ids.size].copy(), ids.astype(np.uint32)


@functools.lru_cache(maxsize=16)
def _rlist_addresses(max_spheres: int, bank: int) -> np.ndarray:
    """The run list's word addresses of ``bank`` (a table: :func:`run_list_writes`)."""
    out = write_address("rlist", np.arange(max_spheres), 0, bank)
    out.setflags(write=False)
    return out

