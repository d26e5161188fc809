"""The benchmark's plan: which points a sweep runs.


Axes: formats (FP16, FP20, FP24, FP32 and any extra), roundings (rtz, rne, chop), ray-triangle
modes (paper, conservative), scenes (the procedural ones, and the meshes shipped with the
package, :data:`raplas_hdl.host.meshes.MESH_DIR`), bundle sizes, backends (``float64``,
``model``; ``rtl`` on one tiny point on request). The full product is too large for one
machine, so the points form three grids:

``main``     every format x rounding x mode on every procedural scene at the main bundle
             size (the grid of the Pareto fronts);
``meshes``   every format x mode on every mesh file, first rounding, main bundle size (the
             conservative mode at FP16 and FP20 on a 70k-triangle mesh issues nearly the
             brute-force pairs: such points come out *capped*, below);
``bundles``  every format on every procedural scene at the other bundle sizes, first rounding,
             first mode;

plus a ``float64`` reference point per scene, bundle size and bound, an ``rtl`` point when
asked (a 24-triangle soup at 16x16, no shadows, against the model: slow), and with
``probe_cap`` a ``cap`` point (the first main point under a tiny cap, which must come out
capped: ``--quick`` has one).

Each scene is normalised into its format's domain (:func:`domain_bound`: the largest power
of two inside :func:`raplas_hdl.model.conservative.domain`, at most :data:`BOUND_CAP`); the
float64 reference is rendered at the same bound. The model backend of the sweep loads every
triangle the record builder accepts, also those outside the domain (the host's
``check_domain`` drop would hide the error the format makes there); such triangles are
counted and every pair with one of them is an *out-of-domain pair*, left out of the t errors.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

from ..fp import ROUNDINGS, FPFormat, parse_format
from ..host.meshes import MESH_DIR, MESH_SUFFIXES
from ..host.scenes import SCENES
from ..model.conservative import domain
from ..model.modes import MODES

__all__ = ["BOUND_CAP", "DEFAULT_MESH_DIR", "DEFAULT_MAX_PAIRS", "DEFAULT_PAIR_SAMPLE",
           "PREPASS_DIVISOR", "BenchSpec", "quick_spec", "full_spec", "domain_bound",
           "find_meshes", "plan", "point_format", "format_label", "scene_label"]

#: Largest normalisation bound used (beyond it only the host's float64 shading changes).
BOUND_CAP = 256.0
#: The meshes shipped with the package.
DEFAULT_MESH_DIR = Path(MESH_DIR)
#: Pairs a point may issue (2 % of the brute-force pairs of a 70k-triangle mesh at 256x256
#: with 3x3 shadows; 1-15 minutes of the model on one core, by format and mode).
DEFAULT_MAX_PAIRS = 500_000_000
#: Pairs of the per-pair error sample of a point.
DEFAULT_PAIR_SAMPLE = 200_000
#: The pre-pass renders 1/PREPASS_DIVISOR of the image side.
PREPASS_DIVISOR = 4


@dataclass
class BenchSpec:
    """What one ``raplas-hdl bench`` run sweeps.

    Attributes
    ----------
    formats : list of str
        Format names without rounding (``FP16``, ``e6m17``...).
    roundings, modes : list of str
    scenes : list of str
        Procedural scene names.
    mesh_dir : str or None
        Directory of mesh files (None: no meshes).
    bundles : list of (int, int)
        Bundle sizes; the first is the main one.
    size, mesh_size : (int, int)
        Image size of procedural and mesh scenes.
    shadow : (int, int)
        Light lattice of shadow bundles (0, 0: no shadows).
    rtl : str or None
        Simulator for the tiny rtl point (None: none).
    per_family, seed : int
        Stress families for the R metrics.
    repeats : int
        Renders per point; the timings are the fastest run's.
    max_pairs : int
        Pairs a point may issue (the cap, module docstring).
    probe_cap : int or None
        Add a ``cap`` point: the first main point under this cap (it must come out capped).
    pair_sample : int
        Pairs of the per-pair error sample of a point.
    threads : int
        Threads of the compiled passes (1: the timings are per core).
    quick : bool
    """

    formats: list = field(default_factory=lambda: ["FP16", "FP20", "FP24", "FP32"])
    roundings: list = field(default_factory=lambda: list(ROUNDINGS))
    modes: list = field(default_factory=lambda: list(MODES))
    scenes: list = field(default_factory=lambda: list(SCENES))
    mesh_dir: str | None = str(DEFAULT_MESH_DIR)
    bundles: list = field(default_factory=lambda: [(8, 8), (4, 4), (16, 16)])
    size: tuple = (128, 128)
    mesh_size: tuple = (256, 256)
    shadow: tuple = (3, 3)
    rtl: str | None = None
    per_family: int = 2000
    seed: int = 0
    repeats: int = 1
    max_pairs: int = DEFAULT_MAX_PAIRS
    probe_cap: int | None = None
    pair_sample: int = DEFAULT_PAIR_SAMPLE
    threads: int = 1
    quick: bool = False

    def __post_init__(self):
        for f in self.formats:
            parse_format(f)
        for r in self.roundings:
            if r not in ROUNDINGS:
                raise ValueError(f"unknown rounding {r!r}: use {', '.join(ROUNDINGS)}")
        for m in self.modes:
            if m not in MODES:
                raise ValueError(f"unknown mode {m!r}: use {', '.join(MODES)}")
        for s in self.scenes:
            if s not in SCENES:
                raise ValueError(f"unknown procedural scene {s!r}: use {', '.join(SCENES)}")
        if not (self.formats and self.roundings and self.modes and self.bundles):
            raise ValueError("formats, roundings, modes and bundles must not be empty")
        if self.repeats < 1 or self.per_family < 1:
            raise ValueError("repeats and per_family must be at least 1")
        if self.max_pairs < 1 or self.pair_sample < 1 or self.threads < 1:
            raise ValueError("max_pairs, pair_sample and threads must be at least 1")
        if self.probe_cap is not None and self.probe_cap < 1:
            raise ValueError("probe_cap must be at least 1")


def quick_spec(**overrides) -> BenchSpec:
    """``--quick``: FP16, FP24, FP32; rtz; paper; cornell and spheres; 8x8; 32x32 with 2x2
    shadows; no meshes; a ``cap`` point under a cap of 1000 pairs."""
    kw = dict(formats=["FP16", "FP24", "FP32"], roundings=["rtz"], modes=["paper"],
              scenes=["cornell", "spheres"], mesh_dir=None, bundles=[(8, 8)], size=(32, 32),
              mesh_size=(32, 32), shadow=(2, 2), per_family=300, probe_cap=1000,
              quick=True)
    kw.update(overrides)
    return BenchSpec(**kw)


def full_spec(**overrides) -> BenchSpec:
    """The default campaign (see :class:`BenchSpec` defaults)."""
    return BenchSpec(**overrides)


def domain_bound(fmt: FPFormat) -> float:
    """Normalisation bound of a scene for ``fmt``: ``min(2**P, BOUND_CAP)``."""
    return float(min(domain(fmt).max_coord, BOUND_CAP))


def find_meshes(mesh_dir) -> tuple[list[str], str | None]:
    """Mesh files of ``mesh_dir`` (sorted) and a note when there are none."""
    if mesh_dir is None:
        return [], "meshes not requested"
    p = Path(mesh_dir)
    if not p.is_dir():
        return [], f"mesh directory {p} not found: mesh scenes skipped"
    files = sorted(str(f) for f in p.iterdir() if f.suffix.lower() in MESH_SUFFIXES)
    return files, (None if files else f"no mesh files in {p}: mesh scenes skipped")


def plan(spec: BenchSpec, meshes) -> list[dict]:
    """The model points of the grids (see the module docstring), in run order."""
    main = spec.bundles[0]
    pts = []

    def add(grid, f, r, m, scene, b, cap=spec.max_pairs):
        pts.append({"grid": grid, "format": f, "rounding": r, "mode": m, "scene": scene,
                    "bundle": b, "max_pairs": int(cap)})

    for f in spec.formats:
        for r in spec.roundings:
            for m in spec.modes:
                for s in spec.scenes:
                    add("main", f, r, m, s, main)
    for f in spec.formats:
        for m in spec.modes:
            for s in meshes:
                add("meshes", f, spec.roundings[0], m, s, main)
    for b in spec.bundles[1:]:
        for f in spec.formats:
            for s in spec.scenes:
                add("bundles", f, spec.roundings[0], spec.modes[0], s, b)
    if spec.probe_cap is not None:
        first = spec.scenes[0] if spec.scenes else (meshes[0] if meshes else None)
        if first is not None:
            add("cap", spec.formats[0], spec.roundings[0], spec.modes[0], first, main,
                spec.probe_cap)
    return pts


def point_format(name: str, rounding: str) -> FPFormat:
    """The format of a point: ``name`` with ``rounding`` unless it names its own."""
    return parse_format(name, rounding) if "/" not in name else parse_format(name)


def format_label(fmt: FPFormat) -> str:
    """A format's name without its rounding (``FP24``)."""
    return str(fmt).split("/")[0]


def scene_label(spec: str) -> str:
    """A scene's name in the results: a procedural scene's, or a mesh file's stem."""
    return os.path.splitext(os.path.basename(spec))[0] if spec not in SCENES else spec
