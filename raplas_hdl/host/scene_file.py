"""Scene files: a camera, a light, materials and meshes with transforms, in TOML.

The format is documented with a full example in ``docs/scenes.md``; in short::

    name = "example"                 # optional (default: the file's stem)
    background = [0.0, 0.0, 0.0]     # optional

    [camera]                         # position, look_at; up (default [0, 1, 0] or "y")
    position = [0, 1, 5]             # and fov (vertical, degrees, default 40)
    look_at = [0, 1, 0]

    [[light]]                        # exactly one: type "area" (corner, edge_u, edge_v)
    type = "point"                   # or "point" (position; size, direction)
    position = [0, 4, 0]             # colour (default white), intensity (default 1)

    [materials.glass]                # colour, ambient, diffuse, specular, shininess,
    colour = [0.9, 0.95, 1.0]        # reflectivity, transparency, ior, gloss_angle
    transparency = 0.9
    ior = 1.5

    [[mesh]]                         # one of: file (relative to this file), shipped (a
    shipped = "suzanne"              # mesh of the package) or primitive (box, sphere,
    material = "glass"               # quad); fit, scale, rotate (degrees about x, then
    fit = 1.5                        # y, then z), translate
    rotate = [0, 180, 0]
    translate = [0, 1, 0]

    [render]                         # optional: the scene's default render settings
    depth = 3                        # (the render command's options override them):
    glossy = "3x3"                   # depth, glossy ("RxC" or "0"), ao ("RxC" or "0"),
    ao = "3x3"                       # ao_angle (degrees), ao_distance (fraction of the
    ao_angle = 60                    # normalised scene's extent)
    ao_distance = 0.25

Everything is checked before any mesh is read (:func:`check_scene_file`): unknown or
missing keys, wrong types, values out of range, mesh files that do not exist, unknown
materials, a camera that cannot look (``up`` parallel to the view, ``look_at`` on the
eye, ``fov`` outside 0-180 degrees), a light with parallel edges. An error is one line
naming the file, the line (tomllib's own for a syntax error; found in the text for a key)
and the key: ``scene.toml: line 12: [[mesh]] #2 rotate: must be 3 numbers, not [0, 90]``.

A point light is a small square area light (:class:`~raplas_hdl.host.scene.AreaLight`
with ``kind="point"``) centred on the point and facing ``direction`` (default: against
the camera's up vector, i.e. down): the renderer shades and shadows with a light's
lattice, so the square's side (``size``, default 1/100 of the meshes' bounding box) sets
how soft its shadows are.

:func:`override_scene` replaces the camera position, look-at point, up vector, field of
view or the light's centre of any scene (the ``render`` command's ``--camera``,
``--look-at``, ``--up``, ``--fov``, ``--light``).
"""

from __future__ import annotations

import math
import os
import re
import tomllib
from dataclasses import dataclass, replace

import numpy as np

from .camera import Camera
from .meshes import MESH_SUFFIXES, MESHES, MeshBuilder, box_mesh, load_mesh, quad_grid
from .scene import AreaLight, Material, Scene

__all__ = ["MAX_DEPTH", "MAX_SECONDARY_LATTICE", "PRIMITIVES", "SceneFileError",
           "check_scene_file", "load_scene_file", "mesh_transform", "override_scene",
           "parse_axis"]

#: Procedural meshes of ``[[mesh]] primitive = ...``: their own keys and defaults.
PRIMITIVES = {
    "box": {"size": [1.0, 1.0, 1.0], "subdiv": 0},      # centred cube of sides ``size``
    "sphere": {"radius": 1.0, "subdiv": 3},              # icosphere centred on the origin
    "quad": {"size": [1.0, 1.0], "subdiv": 1},           # x-z square at y = 0, facing +y
}
_SUBDIV_MAX = {"box": 4, "sphere": 5, "quad": 64}

_TOP_KEYS = ("name", "background", "camera", "light", "materials", "mesh", "render")
_RENDER_KEYS = ("depth", "glossy", "ao", "ao_angle", "ao_distance")
#: Largest depth of reflection and refraction rays (``RenderSettings.depth``).
MAX_DEPTH = 16
#: Largest side of a glossy or ambient-occlusion bundle.
MAX_SECONDARY_LATTICE = 64
_CAMERA_KEYS = ("position", "look_at", "up", "fov")
_LIGHT_KEYS = {"area": ("type", "corner", "edge_u", "edge_v", "colour", "intensity"),
               "point": ("type", "position", "size", "direction", "colour", "intensity")}
_MATERIAL_KEYS = ("colour", "ambient", "diffuse", "specular", "shininess", "reflectivity",
                  "transparency", "ior", "gloss_angle")
_MESH_SOURCES = ("file", "shipped", "primitive")
_MESH_KEYS = ("material", "fit", "scale", "rotate", "translate")
#: The colour of the built-in ``default`` material (a file may redefine it).
DEFAULT_COLOUR = (0.73, 0.73, 0.73)
_AXES = {"x": (1.0, 0.0, 0.0), "y": (0.0, 1.0, 0.0), "z": (0.0, 0.0, 1.0)}


class SceneFileError(ValueError):
    """A malformed scene file: one line naming the file, the line and the key."""


def parse_axis(text) -> tuple:
    """An up axis: ``x``, ``y``, ``z`` (optionally signed: ``-z``) or ``X,Y,Z``.

    Raises
    ------
    ValueError
        For anything else, or a zero or non-finite vector.
    """
    t = str(text).strip().lower().replace(" ", "")
    sign = -1.0 if t.startswith("-") else 1.0
    if t.lstrip("+-") in _AXES and len(t) <= 2:
        return tuple(sign * c for c in _AXES[t.lstrip("+-")])
    try:
        v = tuple(float(x) for x in t.split(","))
    except ValueError:
        v = ()
    if len(v) != 3:
        raise ValueError(f"{text!r} is not an axis: use x, y, z, -x, -y, -z or X,Y,Z")
    if not all(math.isfinite(c) for c in v) or not any(v):
        raise ValueError(f"{text!r} is not an axis: it must be finite and not zero")
    return v


# -- where an error is ------------------------------------------------------------------

_HEADER = re.compile(r"""^\s*(\[\[?)\s*([A-Za-z0-9_\-."' ]+?)\s*\]\]?\s*(#.*)?$""")
_KEY = re.compile(r"""^\s*(?:"([^"]+)"|'([^']+)'|([A-Za-z0-9_-]+))\s*=""")


class _Where:
    """Names a key of the file in errors, with its line when it can be found."""

    def __init__(self, label: str, text: str):
        self.label = label
        self.lines: dict = {}
        table: tuple = ()
        counts: dict = {}
        for n, line in enumerate(text.splitlines(), 1):
            h = _HEADER.match(line)
            if h:
                parts = tuple(p.strip().strip("\"'") for p in h.group(2).split("."))
                if h.group(1) == "[[":
                    counts[parts] = counts.get(parts, -1) + 1
                    parts = parts + (counts[parts],)
                table = parts
                self.lines.setdefault(table, n)
                continue
            k = _KEY.match(line)
            if k:
                self.lines.setdefault(table + (next(g for g in k.groups() if g),), n)

    @staticmethod
    def name(path) -> str:
        """``[camera] fov``, ``[[mesh]] #2 rotate``, ``[materials.glass] ior``."""
        out, i = [], 0
        while i < len(path):
            if i + 1 < len(path) and isinstance(path[i + 1], int):
                out.append(f"[[{path[i]}]] #{path[i + 1] + 1}")
                i += 2
            elif path[i] == "materials" and i + 1 < len(path):
                out.append(f"[materials.{path[i + 1]}]")
                i += 2
            elif i == 0 and len(path) > 1:
                out.append(f"[{path[i]}]")
                i += 1
            else:
                out.append(str(path[i]))
                i += 1
        return " ".join(out)

    def error(self, path, message: str) -> SceneFileError:
        line = next((self.lines[path[:k]] for k in range(len(path), 0, -1)
                     if path[:k] in self.lines), None)
        at = f"line {line}: " if line else ""
        what = f"{self.name(path)}: " if path else ""
        return SceneFileError(f"{self.label}: {at}{what}{message}")


# -- values ---------------------------------------------------------------------------

def _is_number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


class _Table:
    """One TOML table being checked: its keys, its values by type."""

    def __init__(self, where: _Where, path: tuple, value, allowed, required=()):
        self.w, self.path = where, path
        if not isinstance(value, dict):
            raise where.error(path, f"must be a table, not {_kind(value)}")
        self.d = value
        for k in value:
            if k not in allowed:
                raise self.error(k, f"unknown key (expected one of {', '.join(allowed)})")
        for k in required:
            if k not in value:
                raise where.error(path, f"missing key {k!r}")

    def error(self, key, message: str) -> SceneFileError:
        return self.w.error(self.path + (key,), message)

    def number(self, key, default=None, lo=-math.inf, hi=math.inf, lo_open=False,
               hi_open=False, integer=False):
        v = self.d.get(key, default)
        if v is None:
            return None
        if not _is_number(v) or (integer and not isinstance(v, int)):
            raise self.error(key, f"must be {'an integer' if integer else 'a number'}, "
                                  f"not {_kind(v)}")
        if not math.isfinite(v) or v < lo or v > hi or (lo_open and v == lo) or \
                (hi_open and v == hi):
            raise self.error(key, f"must be {_range(lo, hi, lo_open, hi_open)}, not {v}")
        return v

    def vector(self, key, default=None, n=3, lo=-math.inf, hi=math.inf, what="numbers"):
        v = self.d.get(key, default)
        if v is None:
            return None
        if not isinstance(v, list) or len(v) != n or not all(_is_number(x) for x in v):
            raise self.error(key, f"must be {n} {what}, not {_show(v)}")
        if not all(math.isfinite(x) and lo <= x <= hi for x in v):
            raise self.error(key, f"must be {n} {what} {_range(lo, hi)}, not {_show(v)}")
        return tuple(float(x) for x in v)

    def colour(self, key, default=None, hi=1.0):
        return self.vector(key, default, 3, 0.0, hi, "numbers (red, green, blue)")

    def string(self, key, default=None, choices=None):
        v = self.d.get(key, default)
        if v is None:
            return None
        if not isinstance(v, str):
            raise self.error(key, f"must be a string, not {_kind(v)}")
        if choices is not None and v not in choices:
            raise self.error(key, f"unknown value {v!r} (expected one of "
                                  f"{', '.join(choices)})")
        return v

    def axis(self, key, default=None):
        v = self.d.get(key, default)
        if isinstance(v, str):
            try:
                return parse_axis(v)
            except ValueError as exc:
                raise self.error(key, str(exc)) from None
        out = self.vector(key, default)
        if out is not None and not any(out):
            raise self.error(key, "must not be the zero vector")
        return out


def _kind(v) -> str:
    if isinstance(v, bool):
        return f"a boolean ({str(v).lower()})"
    if isinstance(v, dict):
        return "a table"
    if isinstance(v, list):
        return f"an array ({_show(v)})"
    if isinstance(v, str):
        return f"a string ({v!r})"
    return f"{type(v).__name__} {v!r}"


def _show(v) -> str:
    s = repr(v).replace("True", "true").replace("False", "false")
    return s if len(s) <= 60 else s[:57] + "..."


def _range(lo, hi, lo_open=False, hi_open=False) -> str:
    if hi == math.inf:
        return f"{'above' if lo_open else 'at least'} {lo:g}" if lo > -math.inf else "finite"
    if lo == -math.inf:
        return f"{'below' if hi_open else 'at most'} {hi:g}"
    return f"{'above' if lo_open else 'from'} {lo:g} {'and below' if hi_open else 'to'} {hi:g}"


# -- the parsed file -------------------------------------------------------------------

@dataclass
class _MeshSpec:
    path: tuple                 # where it is in the file
    source: str                 # "file", "shipped" or "primitive"
    value: str                  # the file path (resolved), the mesh name or the primitive
    params: dict                # primitive parameters
    material: int
    fit: float | None
    scale: tuple
    rotate: tuple
    translate: tuple


@dataclass
class _SceneSpec:
    """A checked scene file: everything but the meshes' triangles."""

    where: _Where
    name: str
    background: tuple
    camera: Camera
    light: dict
    materials: tuple
    colours: tuple
    meshes: list
    render: dict


def _read(path) -> tuple[str, dict]:
    label = os.fspath(path)
    if not os.path.exists(label):
        raise SceneFileError(f"scene file {label!r} does not exist")
    if os.path.isdir(label):
        raise SceneFileError(f"scene file {label!r} is a directory, not a file")
    try:
        with open(label, "rb") as fh:
            raw = fh.read()
    except OSError as exc:
        raise SceneFileError(f"scene file {label!r} cannot be read "
                             f"({exc.strerror or exc})") from None
    try:
        text = raw.decode("utf-8")
        return text, tomllib.loads(text)
    except UnicodeDecodeError as exc:
        raise SceneFileError(f"{label}: not UTF-8 text ({exc.reason} at byte "
                             f"{exc.start})") from None
    except tomllib.TOMLDecodeError as exc:
        msg = str(exc)       # "Invalid value (at line 3, column 7)"
        m = re.search(r"\(at line (\d+), column (\d+)\)$", msg)
        at = f"line {m.group(1)}, column {m.group(2)}: " if m else ""
        msg = msg[:m.start()].strip() if m else msg
        raise SceneFileError(f"{label}: {at}TOML syntax error: {msg}") from None


def _camera(w: _Where, doc: dict, overrides: dict) -> Camera:
    if "camera" not in doc:
        raise w.error((), "missing table [camera] (position, look_at, up, fov)")
    if isinstance(doc["camera"], list):
        raise w.error(("camera",), "must be one table: write [camera], not [[camera]]")
    t = _Table(w, ("camera",), doc["camera"], _CAMERA_KEYS, ("position", "look_at"))
    values = {"position": t.vector("position"), "look_at": t.vector("look_at"),
              "up": t.axis("up", [0.0, 1.0, 0.0]),
              "fov": t.number("fov", 40.0, 0.0, 180.0, True, True)}
    given = {k: v for k, v in overrides.items() if v is not None}
    values.update(given)
    try:
        return Camera(**values)
    except ValueError as exc:
        key = next((k for k in ("up", "fov") if k in str(exc)), "look_at")
        extra = f" (with the overridden {', '.join(given)})" if given else ""
        raise t.error(key, f"{exc}{extra}") from None


def _light(w: _Where, doc: dict, camera_up) -> dict:
    lights = doc.get("light")
    if lights is None:
        raise w.error((), "missing [[light]] (an area or a point light)")
    if isinstance(lights, dict):
        raise w.error(("light",), "must be an array of tables: write [[light]], not [light]")
    if not isinstance(lights, list) or not all(isinstance(x, dict) for x in lights):
        raise w.error(("light",), f"must be an array of tables ([[light]]), not "
                                  f"{_kind(lights)}")
    if len(lights) != 1:
        raise w.error(("light", 1), f"{len(lights)} lights: the renderer shades and shadows "
                                    "with one light; give one [[light]]")
    path = ("light", 0)
    kind = _Table(w, path, lights[0], tuple(lights[0]), ("type",)).string(   # type first
        "type", choices=tuple(_LIGHT_KEYS))
    t = _Table(w, path, lights[0], _LIGHT_KEYS[kind],
               ("corner", "edge_u", "edge_v") if kind == "area" else ("position",))
    colour = np.asarray(t.colour("colour", [1.0, 1.0, 1.0]))
    colour = tuple(float(c) for c in colour * t.number("intensity", 1.0, 0.0, lo_open=True))
    if kind == "area":
        try:
            AreaLight(t.vector("corner"), t.vector("edge_u"), t.vector("edge_v"))
        except ValueError as exc:
            raise t.error("edge_v", str(exc)) from None
        return {"kind": kind, "corner": t.vector("corner"), "edge_u": t.vector("edge_u"),
                "edge_v": t.vector("edge_v"), "colour": colour}
    return {"kind": kind, "position": t.vector("position"), "colour": colour,
            "size": t.number("size", None, 0.0, lo_open=True),
            "direction": t.axis("direction", [-c for c in camera_up])}


def _materials(w: _Where, doc: dict) -> tuple[dict, list, list]:
    mats = doc.get("materials", {})
    if not isinstance(mats, dict):
        raise w.error(("materials",), f"must be a table of [materials.NAME] tables, not "
                                      f"{_kind(mats)}")
    names, table, colours = {"default": 0}, [Material()], [DEFAULT_COLOUR]
    for name, value in mats.items():
        path = ("materials", name)
        if not isinstance(value, dict):
            raise w.error(path, f"must be a table [materials.{name}], not {_kind(value)}")
        t = _Table(w, path, value, _MATERIAL_KEYS)
        d = Material()
        m = Material(ambient=t.number("ambient", d.ambient, 0.0),
                     diffuse=t.number("diffuse", d.diffuse, 0.0),
                     specular=t.number("specular", d.specular, 0.0),
                     shininess=t.number("shininess", d.shininess, 0.0),
                     reflectivity=t.number("reflectivity", 0.0, 0.0, 1.0),
                     transparency=t.number("transparency", 0.0, 0.0, 1.0),
                     ior=t.number("ior", 1.0, 1.0, 4.0),
                     gloss_angle=t.number("gloss_angle", 0.0, 0.0, 90.0, hi_open=True),
                     name=name)
        if m.reflectivity + m.transparency > 1.0:
            raise t.error("transparency", f"reflectivity + transparency must be at most 1, "
                                          f"not {m.reflectivity + m.transparency:g}")
        colour = t.colour("colour", list(DEFAULT_COLOUR))
        if name in names:
            table[names[name]], colours[names[name]] = m, colour
        else:
            names[name] = len(table)
            table.append(m)
            colours.append(colour)
    return names, table, colours


def _lattice(t: _Table, key: str) -> tuple:
    v = t.d.get(key, "0")
    if v == 0:
        return 0, 0
    if not isinstance(v, str):
        raise t.error(key, f'must be a string "RxC" (for example "3x3") or "0", not {_kind(v)}')
    text = v.strip().lower()
    if text in ("0", "off", "none", "0x0"):
        return 0, 0
    m = re.fullmatch(r"(\d+)x(\d+)", text)
    if not m or not all(1 <= int(x) <= MAX_SECONDARY_LATTICE for x in m.groups()):
        raise t.error(key, f'must be "RxC" with rows and cols 1 to {MAX_SECONDARY_LATTICE}, '
                           f'or "0", not {v!r}')
    return int(m.group(1)), int(m.group(2))


def _render(w: _Where, doc: dict) -> dict:
    """The optional ``[render]`` table as ``RenderSettings`` field values."""
    if "render" not in doc:
        return {}
    if isinstance(doc["render"], list):
        raise w.error(("render",), "must be one table: write [render], not [[render]]")
    t = _Table(w, ("render",), doc["render"], _RENDER_KEYS)
    out = {}
    if "depth" in t.d:
        out["depth"] = t.number("depth", lo=0, hi=MAX_DEPTH, integer=True)
    for kind in ("glossy", "ao"):
        if kind in t.d:
            out[f"{kind}_rows"], out[f"{kind}_cols"] = _lattice(t, kind)
    if "ao_angle" in t.d:
        out["ao_angle"] = float(t.number("ao_angle", lo=0.0, hi=90.0, lo_open=True,
                                         hi_open=True))
    if "ao_distance" in t.d:
        out["ao_distance"] = float(t.number("ao_distance", lo=0.0, hi=1.0, lo_open=True))
    return out


def _mesh(w: _Where, path: tuple, value, base: str, materials: dict) -> _MeshSpec:
    if not isinstance(value, dict):
        raise w.error(path, f"must be a table, not {_kind(value)}")
    sources = [k for k in _MESH_SOURCES if k in value]
    if len(sources) != 1:
        why = "none" if not sources else " and ".join(sources)
        raise w.error(path, f"needs exactly one of file, shipped, primitive (has {why})")
    source = sources[0]
    allowed = (source, *_MESH_KEYS)
    if source == "primitive":      # its value first: it says which keys are allowed
        kind = _Table(w, path, value, tuple(value)).string("primitive",
                                                           choices=tuple(PRIMITIVES))
        allowed = (source, *(k for k in _MESH_KEYS if k != "fit"), *PRIMITIVES[kind])
    t = _Table(w, path, value, allowed)
    params = {}
    if source == "file":
        name = t.string("file")
        full = name if os.path.isabs(name) else os.path.join(base, name)
        if os.path.splitext(full)[1].lower() not in MESH_SUFFIXES:
            raise t.error("file", f"{name!r}: unsupported type (use "
                                  f"{', '.join(MESH_SUFFIXES)})")
        if not os.path.isfile(full):
            why = "is a directory" if os.path.isdir(full) else "does not exist"
            raise t.error("file", f"mesh file {full!r} {why}")
        if not os.access(full, os.R_OK):
            raise t.error("file", f"mesh file {full!r} cannot be read (permission denied)")
        value_ = full
    elif source == "shipped":
        value_ = t.string("shipped", choices=tuple(MESHES))
    else:
        value_ = t.string("primitive", choices=tuple(PRIMITIVES))
        defaults = PRIMITIVES[value_]
        if value_ == "sphere":
            params["radius"] = t.number("radius", defaults["radius"], 0.0, lo_open=True)
        else:
            n = len(defaults["size"])
            size = t.vector("size", defaults["size"], n, 0.0, what="positive numbers")
            if min(size) <= 0.0:
                raise t.error("size", f"must be {n} positive numbers, not {list(size)}")
            params["size"] = size
        params["subdiv"] = t.number("subdiv", defaults["subdiv"], 1 if value_ == "quad" else 0,
                                    _SUBDIV_MAX[value_], integer=True)
    material = t.string("material", "default")
    if material not in materials:
        raise t.error("material", f"unknown material {material!r} (defined: "
                                  f"{', '.join(materials)})")
    if isinstance(value.get("scale"), list):
        scale = t.vector("scale", what="positive numbers")
        if min(scale) <= 0.0:
            raise t.error("scale", f"must be 3 positive numbers, not {_show(value['scale'])}")
    else:
        scale = (t.number("scale", 1.0, 0.0, lo_open=True),) * 3
    return _MeshSpec(path, source, value_, params, materials[material],
                     t.number("fit", None, 0.0, lo_open=True), scale,
                     t.vector("rotate", [0.0, 0.0, 0.0], what="angles in degrees"),
                     t.vector("translate", [0.0, 0.0, 0.0]))


def check_scene_file(path, camera=None, look_at=None, up=None, fov=None,
                     light=None) -> _SceneSpec:
    """Read and check a scene file, with the overrides (``None``: the file's), without
    reading any mesh.

    Raises
    ------
    SceneFileError
        (a ``ValueError``) One line naming the file, the line and the key.
    """
    text, doc = _read(path)
    label = os.fspath(path)
    w = _Where(label, text)
    for k in doc:
        if k not in _TOP_KEYS:
            raise w.error((k,), f"unknown key (expected one of {', '.join(_TOP_KEYS)})")
    top = _Table(w, (), doc, _TOP_KEYS)
    name = top.string("name", os.path.splitext(os.path.basename(label))[0])
    background = top.colour("background", [0.0, 0.0, 0.0])
    cam = _camera(w, doc, {"position": camera, "look_at": look_at, "up": up, "fov": fov})
    file_up = cam.up if up is None else _camera(w, doc, {}).up
    lt = _light(w, doc, file_up)
    if light is not None:
        lt["moved_to"] = tuple(float(c) for c in light)
    names, table, colours = _materials(w, doc)
    meshes = doc.get("mesh")
    if meshes is None:
        raise w.error((), "missing [[mesh]] (at least one)")
    if isinstance(meshes, dict):
        raise w.error(("mesh",), "must be an array of tables: write [[mesh]], not [mesh]")
    if not isinstance(meshes, list):
        raise w.error(("mesh",), f"must be an array of tables ([[mesh]]), not {_kind(meshes)}")
    if not meshes:
        raise w.error(("mesh",), "is empty: give at least one [[mesh]]")
    base = os.path.dirname(os.path.abspath(label))
    specs = [_mesh(w, ("mesh", i), m, base, names) for i, m in enumerate(meshes)]
    return _SceneSpec(w, name, background, cam, lt, tuple(table), tuple(colours), specs,
                      _render(w, doc))


# -- building -------------------------------------------------------------------------

def _rotation(degrees) -> np.ndarray:
    """``Rz @ Ry @ Rx``: about x first, then y, then z (fixed axes)."""
    out = np.eye(3)
    for axis, deg in enumerate(degrees):
        if deg % 90 == 0:         # quarter turns exactly: walls stay on their planes
            c, s = [(1.0, 0.0), (0.0, 1.0), (-1.0, 0.0), (0.0, -1.0)][int(deg // 90) % 4]
        else:
            c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
        i, j = [(1, 2), (2, 0), (0, 1)][axis]
        r = np.eye(3)
        r[i, i], r[i, j], r[j, i], r[j, j] = c, -s, s, c
        out = r @ out
    return out


def mesh_transform(vertices, faces=None, fit=None, scale=(1.0, 1.0, 1.0),
                   rotate=(0.0, 0.0, 0.0), translate=(0.0, 0.0, 0.0)) -> np.ndarray:
    """The vertices of a ``[[mesh]]`` placed in the scene: ``fit`` (centre the bounding box
    of the used vertices on the origin, largest side ``fit``), then ``scale`` (per axis),
    ``rotate`` (degrees about x, then y, then z) and ``translate``."""
    v = np.asarray(vertices, np.float64)
    if fit is not None:
        used = v[np.unique(faces)] if faces is not None else v
        lo, hi = used.min(axis=0), used.max(axis=0)
        size = float(np.max(hi - lo))
        if size == 0.0:
            raise ValueError("the mesh has zero extent: fit cannot scale it")
        v = (v - 0.5 * (lo + hi)) * (fit / size)
    v = (v * np.asarray(scale, float)) @ _rotation(rotate).T
    return v + np.asarray(translate, float)


def _primitive(kind: str, params: dict):
    import trimesh     # lazy: trimesh loads only to read a mesh file

    if kind == "box":
        m = box_mesh(params["size"], None, params["subdiv"])
        return m.vertices, m.faces
    if kind == "sphere":
        m = trimesh.creation.icosphere(subdivisions=params["subdiv"], radius=params["radius"])
        return m.vertices, m.faces
    sx, sz = params["size"]
    return quad_grid((-sx / 2, 0.0, -sz / 2), (0.0, 0.0, sz), (sx, 0.0, 0.0), params["subdiv"])


def _point_light(spec: dict, size: float) -> AreaLight:
    d = np.asarray(spec["direction"], float)
    d /= np.linalg.norm(d)
    a = np.eye(3)[int(np.argmin(np.abs(d)))]
    eu = np.cross(a, d)
    eu *= size / np.linalg.norm(eu)
    ev = np.cross(d, eu)          # eu x ev = size^2 d: it faces d
    corner = np.asarray(spec["position"], float) - 0.5 * (eu + ev)
    return AreaLight(tuple(corner), tuple(eu), tuple(ev), spec["colour"], "point")


def _build(spec: _SceneSpec) -> Scene:
    b, ids = MeshBuilder(), []
    for m in spec.meshes:
        if m.source == "primitive":
            verts, faces = _primitive(m.value, m.params)
        else:
            try:
                verts, faces = load_mesh(MESHES[m.value] if m.source == "shipped" else m.value)
            except (OSError, ValueError) as exc:
                raise spec.where.error(m.path + (m.source,), str(exc)) from None
        try:
            verts = mesh_transform(verts, faces, m.fit, m.scale, m.rotate, m.translate)
        except ValueError as exc:
            raise spec.where.error(m.path + ("fit",), str(exc)) from None
        b.add(verts, faces, spec.colours[m.material])
        ids.append(np.full(len(faces), m.material, np.int64))
    v, f, c = b.arrays()
    lt = spec.light
    if lt["kind"] == "area":
        light = AreaLight(lt["corner"], lt["edge_u"], lt["edge_v"], lt["colour"])
    else:
        used = v[np.unique(f)]
        size = lt["size"] or 0.01 * float(np.max(np.ptp(used, axis=0)))
        light = _point_light(lt, size)
    if "moved_to" in lt:
        light = light.moved(lt["moved_to"])
    return Scene(spec.name, v, f, c, spec.camera, light, spec.materials[0],
                 spec.background, materials=spec.materials, material_ids=np.concatenate(ids),
                 render_defaults=dict(spec.render))


def load_scene_file(path, camera=None, look_at=None, up=None, fov=None, light=None) -> Scene:
    """The scene of a TOML scene file (in its own units: not normalised).

    Parameters
    ----------
    path : str or path-like
    camera, look_at : 3 numbers, optional
        Replace the camera's position, the point it looks at.
    up : 3 numbers, optional
        Replace the camera's up vector.
    fov : float, optional
        Replace the vertical field of view (degrees).
    light : 3 numbers, optional
        Move the light's centre there.

    Raises
    ------
    SceneFileError
        (a ``ValueError``) for anything malformed, before any mesh is read; for a mesh
        file trimesh cannot read, naming the scene file, the line and the mesh.
    """
    return _build(check_scene_file(path, camera, look_at, up, fov, light))


def override_scene(scene: Scene, camera=None, look_at=None, up=None, fov=None,
                   light=None) -> Scene:
    """``scene`` with the camera position, look-at point, up vector, field of view or the
    light's centre replaced (``None``: kept), in the scene's own units.

    Raises
    ------
    ValueError
        When the camera they make cannot look (up parallel to the view, look-at on the eye).
    """
    c = scene.camera
    values = {"position": camera, "look_at": look_at, "up": up, "fov": fov}
    given = [k for k, v in values.items() if v is not None]
    try:
        cam = Camera(**{k: getattr(c, k) if v is None else v for k, v in values.items()})
    except ValueError as exc:
        raise ValueError(f"scene {scene.name!r} with the overridden {', '.join(given)}: "
                         f"{exc}") from None
    lt = scene.light if light is None else scene.light.moved(light)
    return replace(scene, camera=cam, light=lt)
