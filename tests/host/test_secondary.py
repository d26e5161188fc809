"""Secondary rays (issue 14): reflection, refraction with total internal reflection, glossy
and ambient-occlusion bundles, their counters per ray type, the ``[render]`` table of a
scene file and the render command's options. Each geometric check recomputes what the
renderer should find in float64 with a brute-force tracer over every triangle."""

import math
import re
from pathlib import Path

import numpy as np
import pytest

from raplas_hdl.cli import main
from raplas_hdl.host.backends import make_backend
from raplas_hdl.host.camera import Camera
from raplas_hdl.host.exact import float64_intersect
from raplas_hdl.host.output import compare, format_summary
from raplas_hdl.host.render import RenderSettings, render
from raplas_hdl.host.scene_file import SceneFileError, check_scene_file, load_scene_file
from raplas_hdl.host.meshes import MeshBuilder, box_mesh, quad_grid
from raplas_hdl.host.scene import AreaLight, Material, Scene
from raplas_hdl.host.scenes import SCENE_FILES
from raplas_hdl.host.secondary import perpendicular_axes, reflect, refract
from raplas_hdl.host.shading import face_normals, phong
from raplas_hdl.host.tracing import RAY_TYPES

#: The lift of secondary origins for the float64 backend: ``bound * 2**-11``.
EPS64 = 8.0 * 2.0 ** -11
MIRROR = Material(diffuse=0.1, specular=0.5, shininess=80.0, reflectivity=0.8)
GLASS = Material(diffuse=0.05, specular=0.5, shininess=80.0, transparency=0.9, ior=1.5)
WALL = Material()


def _scene(parts, camera, light, name="test"):
    """A normalised scene of ``(vertices, faces, colour, material)`` parts."""
    b, mats, ids = MeshBuilder(), [Material()], []
    for v, f, colour, mat in parts:
        b.add(v, f, colour)
        mats.append(mat)
        ids.append(np.full(len(f), len(mats) - 1))
    v, f, c = b.arrays()
    return Scene(name, v, f, c, camera, light, materials=tuple(mats),
                 material_ids=np.concatenate(ids)).normalised()


def _down_light(y, half=1.0, z=0.0):
    """A square light at height ``y`` facing down."""
    return AreaLight((-half, y, z - half), (2 * half, 0.0, 0.0), (0.0, 0.0, 2 * half))


def _nearest(o, d, tris, exclude, tmin=EPS64):
    """Brute-force float64 nearest hit of rays ``o + t d`` (``exclude`` a triangle per ray)."""
    n, F = len(o), len(tris)
    r = float64_intersect(np.repeat(o, F, 0), np.repeat(d, F, 0), np.tile(tris[:, 0], (n, 1)),
                          np.tile(tris[:, 1], (n, 1)), np.tile(tris[:, 2], (n, 1)))
    t = np.where(r["hit"], r["t"], np.inf).reshape(n, F)
    t[np.arange(n), exclude] = np.inf
    t[t < tmin] = np.inf
    best = np.argmin(t, axis=1)
    return np.where(np.isfinite(t.min(axis=1)), best, -1), t.min(axis=1)


def _settings(**kw):
    base = {"width": 20, "height": 20, "rows": 4, "cols": 4, "shadow_rows": 0, "shadow_cols": 0,
            "progress": False}
    return RenderSettings(**{**base, **kw})


# -- a mirror facing a red wall -----------------------------------------------------------

@pytest.fixture(scope="module")
def mirror_scene():
    # mirror through the origin facing (1, 0, 1): rays along -z reflect towards +x
    s2 = math.sqrt(2.0)
    eu, ev = np.array([0.0, 2.0, 0.0]), np.array([-s2, 0.0, s2])
    mirror = quad_grid(-(eu + ev) / 2, eu, ev, 1)
    wall = quad_grid((3.0, -3.0, -3.0), (0.0, 0.0, 6.0), (0.0, 6.0, 0.0), 4)   # faces -x
    return _scene([(*mirror, (0.9, 0.9, 0.9), MIRROR), (*wall, (0.8, 0.1, 0.1), WALL)],
                  Camera((0.0, 0.0, 5.0), (0.0, 0.0, 0.0), fov=30.0), _down_light(4.0, z=2.0))


@pytest.fixture(scope="module")
def mirror_renders(mirror_scene):
    be = make_backend("float64")
    return (render(mirror_scene, be, _settings(record_rays=True)),
            render(mirror_scene, be, _settings(depth=1, record_rays=True)))


def test_mirror_reflects_the_wall(mirror_scene, mirror_renders):
    flat, deep = mirror_renders
    sc = mirror_scene
    tris = sc.triangles
    rays = deep.rays
    yx = rays["primary_yx"]
    tri = deep.tri_id[yx[:, 0], yx[:, 1]]
    on = sc.material_ids[tri.clip(0)] == 1
    on &= tri >= 0
    assert on.sum() > 100
    y, x = yx[on, 0], yx[on, 1]
    d = rays["primary_d"][on]
    p = rays["primary_o"][on] + deep.t[y, x, None] * d
    n = face_normals(tris[tri[on]])
    n[np.einsum("ij,ij->i", n, d) > 0] *= -1
    o = p + EPS64 * n
    r = d - 2.0 * np.einsum("ij,ij->i", n, d)[:, None] * n
    want, s = _nearest(o, r, tris, tri[on])
    assert (want >= 0).all() and (sc.material_ids[want] == 2).all()
    np.testing.assert_array_equal(deep.layers["reflection_tri"][y, x], want)
    assert len(np.unique(want)) > 4                 # the wall's triangles tell rays apart
    # pixels without a mirror ray are -2, and depth 0 leaves no layer
    assert (deep.layers["reflection_tri"][~np.isin(np.arange(400), y * 20 + x)
                                          .reshape(20, 20)] == -2).all()
    assert flat.layers == {}
    # the pixel gains reflectivity x the wall's Phong colour seen from the mirror
    q = o + s[:, None] * r
    nw = face_normals(tris[want])
    nw[np.einsum("ij,ij->i", nw, r) > 0] *= -1
    wall = phong(q, nw, sc.colours[want], o, sc.light, sc.material_at(want), np.ones(len(q)))
    np.testing.assert_allclose(deep.image[y, x] - flat.image[y, x], 0.8 * wall, atol=1e-9)
    off = ~np.isin(np.arange(400), y * 20 + x).reshape(20, 20)
    np.testing.assert_array_equal(deep.image[off], flat.image[off])


def test_counters_per_ray_type_sum_to_the_totals(mirror_scene, mirror_renders):
    _, deep = mirror_renders
    st = deep.stats
    types = st["ray_types"]
    assert set(types) == {"primary", "reflection"}
    for key in ("rays", "bundles", "pairs_issued", "brute_force_pairs"):
        assert sum(t[key] for t in types.values()) == st[key], key
    assert st["pair_fraction"] == st["pairs_issued"] / st["brute_force_pairs"]
    refl = types["reflection"]
    assert refl["rays"] == refl["bundles"] == (deep.layers["reflection_tri"] != -2).sum()
    assert refl["brute_force_pairs"] == refl["rays"] * mirror_scene.n_triangles
    assert 0 < refl["pair_fraction"] < 1 and refl["plane_tests"] > 0
    assert sum(t["hits"] for t in types.values()) == st["hits"]
    text = format_summary(deep)
    assert re.search(r"reflection\s+[\d,]+ rays in [\d,]+ bundles", text)


def test_glossy_with_a_tiny_cone_is_the_mirror(mirror_scene, mirror_renders):
    _, mirror = mirror_renders
    mats = list(mirror_scene.materials)
    mats[1] = Material(**{**MIRROR.__dict__, "gloss_angle": 1e-4})
    from dataclasses import replace

    glossy_scene = replace(mirror_scene, materials=tuple(mats))
    res = render(glossy_scene, make_backend("float64"),
                 _settings(depth=1, glossy_rows=2, glossy_cols=3))
    assert "reflection" not in res.stats["ray_types"]
    g = res.stats["ray_types"]["glossy"]
    has = mirror.layers["reflection_tri"] != -2
    assert g["bundles"] == has.sum() and g["rays"] == 6 * has.sum()
    np.testing.assert_array_equal(res.layers["glossy_hit"][has],
                                  (mirror.layers["reflection_tri"][has] >= 0).astype(float))
    assert np.isnan(res.layers["glossy_hit"][~has]).all()
    np.testing.assert_allclose(res.image, mirror.image, atol=1e-5)


# -- refraction: a glass slab, and total internal reflection from inside a glass box --------

def _snell(d, n_geo, ior):
    """Refracted directions built from the angles (sin t = sin i / eta_ratio)."""
    c = np.einsum("ij,ij->i", n_geo, d)
    inward = np.where((c < 0)[:, None], -n_geo, n_geo)        # along the transmitted side
    ratio = np.where(c < 0, 1.0 / ior, ior)
    tangent = d - np.einsum("ij,ij->i", d, inward)[:, None] * inward
    sin_i = np.linalg.norm(tangent, axis=1)
    sin_t = ratio * sin_i
    tangent /= np.where(sin_i > 0, sin_i, 1.0)[:, None]
    cos_t = np.sqrt(np.clip(1.0 - sin_t ** 2, 0.0, None))
    return cos_t[:, None] * inward + sin_t[:, None] * tangent, sin_t > 1.0


def test_refract_obeys_snell_and_reflect_the_mirror_law():
    rng = np.random.default_rng(4)
    d = rng.normal(size=(500, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    n = rng.normal(size=(500, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    ior = rng.uniform(1.0, 2.5, 500)
    t, tir, entering = refract(d, n, ior)
    want, want_tir = _snell(d, n, ior)
    np.testing.assert_array_equal(tir, want_tir)
    np.testing.assert_array_equal(entering, np.einsum("ij,ij->i", n, d) < 0)
    np.testing.assert_allclose(t[~tir], want[~tir], atol=1e-12)
    assert tir.any() and (~tir).any() and entering.any() and (~entering).any()
    r = reflect(d, n)
    np.testing.assert_allclose(np.einsum("ij,ij->i", r, n), -np.einsum("ij,ij->i", d, n))
    a, b = perpendicular_axes(d)
    np.testing.assert_allclose(np.cross(a, b), d, atol=1e-12)


def test_refraction_through_a_slab_hits_the_predicted_back_face():
    slab = box_mesh((4.0, 4.0, 1.0), None, 2)               # z from -0.5 to 0.5, outward normals
    floor = quad_grid((-4.0, -3.0, -4.0), (0.0, 0.0, 8.0), (8.0, 0.0, 0.0), 2)
    sc = _scene([(slab.vertices, slab.faces, (0.9, 0.95, 1.0), GLASS),
                 (*floor, (0.6, 0.6, 0.6), WALL)],
                Camera((2.0, 1.0, 5.0), (0.0, 0.0, 0.0), fov=25.0), _down_light(5.0))
    res = render(sc, make_backend("float64"), _settings(depth=1, record_rays=True))
    rays = res.rays
    yx = rays["primary_yx"]
    tri = res.tri_id[yx[:, 0], yx[:, 1]]
    on = (tri >= 0) & (sc.material_ids[tri.clip(0)] == 1)
    assert on.sum() > 100
    d = rays["primary_d"][on]
    p = rays["primary_o"][on] + res.t[yx[on, 0], yx[on, 1], None] * d
    n_geo = face_normals(sc.triangles[tri[on]])
    t_dir, tir = _snell(d, n_geo, np.full(len(d), 1.5))
    assert not tir.any()
    facing = np.where((np.einsum("ij,ij->i", n_geo, d) > 0)[:, None], -n_geo, n_geo)
    want, _ = _nearest(p - EPS64 * facing, t_dir, sc.triangles, tri[on])
    got = res.layers["refraction_tri"][yx[on, 0], yx[on, 1]]
    assert (sc.material_ids[want] == 1).all()           # the slab's back (or side) faces
    assert np.mean(got == want) >= 0.99 and len(np.unique(want)) > 4
    assert (res.layers["reflection_tri"] == -2).all()   # no reflectivity, no TIR


def test_total_internal_reflection_sends_the_weight_to_the_reflection():
    box = box_mesh((4.0, 4.0, 4.0), None, 1)
    sc = _scene([(box.vertices, box.faces, (0.9, 0.95, 1.0), GLASS)],
                Camera((0.0, 0.0, 0.0), (0.0, 0.0, -1.0), fov=110.0),
                _down_light(1.5, half=0.3))
    res = render(sc, make_backend("float64"), _settings(depth=1, record_rays=True))
    yx = res.rays["primary_yx"]
    d = res.rays["primary_d"]
    tri = res.tri_id[yx[:, 0], yx[:, 1]]
    assert (tri >= 0).all()
    n_geo = face_normals(sc.triangles[tri])
    c = np.abs(np.einsum("ij,ij->i", n_geo, d))
    k = 1.0 - 1.5 ** 2 * (1.0 - c ** 2)              # leaving the glass: eta = 1.5
    clear = np.abs(k) > 1e-6
    refl = res.layers["reflection_tri"][yx[:, 0], yx[:, 1]]
    refr = res.layers["refraction_tri"][yx[:, 0], yx[:, 1]]
    tir = k < 0
    assert tir[clear].any() and (~tir[clear]).any()
    np.testing.assert_array_equal((refr == -2)[clear], tir[clear])
    np.testing.assert_array_equal((refl != -2)[clear], tir[clear])
    assert (refr[~tir & clear] == -1).all()          # out into nothing
    # the reflected ray stays inside (points on the box's edges may leave it at once)
    sel = np.flatnonzero(tir & clear)
    p = res.rays["primary_o"][sel] + res.t[yx[sel, 0], yx[sel, 1], None] * d[sel]
    n = -np.sign(np.einsum("ij,ij->i", n_geo[sel], d[sel]))[:, None] * n_geo[sel]
    want, _ = _nearest(p + EPS64 * n, reflect(d[sel], n), sc.triangles, tri[sel])
    assert np.mean(refl[sel] == want) >= 0.99 and np.mean(want >= 0) > 0.9


# -- ambient occlusion -------------------------------------------------------------------

def test_ambient_occlusion_in_a_corner_and_on_open_floor():
    floor = quad_grid((-4.0, 0.0, -4.0), (0.0, 0.0, 8.0), (8.0, 0.0, 0.0), 4)     # faces +y
    wall = quad_grid((-4.0, 0.0, -1.0), (8.0, 0.0, 0.0), (0.0, 3.0, 0.0), 2)      # faces +z
    sc = _scene([(*floor, (0.7, 0.7, 0.7), WALL), (*wall, (0.7, 0.7, 0.7), WALL)],
                Camera((0.0, 3.0, 4.0), (0.0, 0.0, 0.0), fov=50.0), _down_light(3.5, z=1.0))
    s = _settings(ao_rows=3, ao_cols=3, ao_angle=50.0, ao_distance=0.2, record_rays=True,
                  batch_spheres=2)
    res = render(sc, make_backend("float64"), s)
    assert set(res.stats["ray_types"]) == {"primary", "ao"}
    yx = res.rays["primary_yx"]
    tri = res.tri_id[yx[:, 0], yx[:, 1]]
    keep = tri >= 0
    yx, tri = yx[keep], tri[keep]
    d = res.rays["primary_d"][keep]
    p = res.rays["primary_o"][keep] + res.t[yx[:, 0], yx[:, 1], None] * d
    n = face_normals(sc.triangles[tri])
    n[np.einsum("ij,ij->i", n, d) > 0] *= -1
    o = p + EPS64 * n
    a, b = perpendicular_axes(n)
    h = math.tan(math.radians(50.0))
    lattice = [(i, j) for i in (-2 / 3, 0, 2 / 3) for j in (-2 / 3, 0, 2 / 3)]
    free = np.zeros(len(o))
    for yi, xj in lattice:
        r = n + h * (xj * a + yi * b)
        r /= np.linalg.norm(r, axis=1, keepdims=True)
        hit, t = _nearest(o, r, sc.triangles, tri)
        free += ~((hit >= 0) & (t <= 0.2 * 2 * 8.0))
    want = free / 9
    got = res.layers["ao"][yx[:, 0], yx[:, 1]]
    assert np.mean(np.abs(got - want) < 1e-12) >= 0.99
    on_floor = sc.material_ids[tri] == 1
    wall_z = sc.vertices[sc.faces[sc.material_ids == 2]][..., 2].min()
    corner = on_floor & (p[:, 2] < wall_z + 1.5)          # floor just in front of the wall
    open_ = on_floor & (p[:, 2] > wall_z + 5.0)           # floor far from it
    assert corner.sum() > 3 and open_.sum() > 3
    assert (got[open_] == 1.0).all() and got[corner].max() < 1.0
    assert np.isnan(res.layers["ao"][res.tri_id < 0]).all()
    # the ambient term is scaled: an occluded point is darker than without AO
    plain = render(sc, make_backend("float64"), _settings())
    y, x = yx[corner].T
    assert (res.image[y, x] < plain.image[y, x]).all()
    assert res.stats["ray_types"]["ao"]["early_out_pairs_skipped"] > 0


# -- every backend ------------------------------------------------------------------------

def test_model_agrees_with_float64_on_every_layer(mirror_scene):
    slab = box_mesh((1.0, 1.0, 0.5), None, 0)
    sc = mirror_scene
    mats = list(sc.materials) + [Material(**{**MIRROR.__dict__, "gloss_angle": 5.0}), GLASS]
    glass_v = slab.vertices * sc.scale + np.array([-2.0, 0.0, 3.0])
    verts = np.vstack([sc.vertices, glass_v])
    faces = np.vstack([sc.faces, slab.faces + len(sc.vertices)])
    ids = np.concatenate([sc.material_ids, np.full(len(slab.faces), 4)])
    ids[:1] = 3                                                   # half the mirror glossy
    both = Scene("layers", verts, faces, np.vstack([sc.colours, np.full((12, 3), 0.9)]),
                 sc.camera, sc.light, materials=tuple(mats), material_ids=ids).normalised()
    s = _settings(width=16, height=16, depth=2, glossy_rows=2, glossy_cols=2, ao_rows=2,
                  ao_cols=2, shadow_rows=2, shadow_cols=2)
    ref = render(both, make_backend("float64"), s)
    model = render(both, make_backend("model", mode="paper"), s)
    cert = render(both, make_backend("model", mode="certified"), s)
    assert set(ref.stats["ray_types"]) == set(RAY_TYPES)
    for key in ("reflection_tri", "refraction_tri"):
        assert (ref.layers[key] >= 0).sum() > 10, key
    assert (ref.layers["glossy_hit"] > 0).sum() > 10
    for res in (model, cert):
        assert set(res.layers) == {"reflection_tri", "refraction_tri", "glossy_hit", "ao"}
        for key in ("reflection_tri", "refraction_tri"):
            assert np.mean(res.layers[key] == ref.layers[key]) >= 0.97, key
            np.testing.assert_array_equal(res.layers[key] == -2, ref.layers[key] == -2)
        for key in ("glossy_hit", "ao"):
            a, b = res.layers[key], ref.layers[key]
            np.testing.assert_array_equal(np.isnan(a), np.isnan(b))
            assert np.nanmean(np.abs(a - b)) <= 0.05, key
        assert np.abs(res.image - ref.image).mean() < 0.01
    cmp = compare(model, ref)["layers"]
    assert set(cmp) == {"reflection_tri", "refraction_tri", "glossy_hit", "ao"}
    some = ref.layers["reflection_tri"] != -2
    assert cmp["reflection_tri"] == {"pixels": some.sum(), "differs": np.mean(
        model.layers["reflection_tri"][some] != ref.layers["reflection_tri"][some])}
    assert "refraction_tri: nearest triangle differs" in format_summary(model, compare(model,
                                                                                       ref))


# -- defaults, scene files, the command ---------------------------------------------------

def test_defaults_issue_no_secondary_ray(mirror_scene):
    be = make_backend("float64")
    a = render(mirror_scene, be, _settings(shadow_rows=2, shadow_cols=2))
    b = render(mirror_scene, be, _settings(shadow_rows=2, shadow_cols=2, depth=0, ao_rows=0,
                                           ao_cols=0, glossy_rows=3, glossy_cols=3))
    np.testing.assert_array_equal(a.image, b.image)
    assert a.layers == b.layers == {}
    assert set(a.stats["ray_types"]) == {"primary", "shadow"}


@pytest.mark.parametrize("kw, message", [
    ({"depth": -1}, "depth must be a non-negative integer"),
    ({"depth": 17}, "depth must be at most 16"),
    ({"glossy_rows": 3}, "glossy_rows and glossy_cols must both be"),
    ({"ao_rows": 65, "ao_cols": 2}, "ao_rows and ao_cols must both be 1 to 64"),
    ({"ao_angle": 90.0}, "ao_angle must be above 0 and below 90"),
    ({"ao_distance": 0.0}, "ao_distance must be above 0 and at most 1"),
])
def test_settings_are_checked(kw, message):
    with pytest.raises(ValueError, match=message):
        RenderSettings(**kw)


def test_showcase_render_table_and_overrides():
    scene = load_scene_file(SCENE_FILES["showcase"])
    assert scene.render_defaults == {"depth": 3, "glossy_rows": 3, "glossy_cols": 3,
                                     "ao_rows": 3, "ao_cols": 3, "ao_angle": 60.0,
                                     "ao_distance": 0.25}
    s = RenderSettings.for_scene(scene, depth=1, progress=False)
    assert (s.depth, s.glossy_rows, s.ao_cols) == (1, 3, 3)
    from raplas_hdl.cli import build_parser
    from raplas_hdl.cli.render import settings_from_args

    args = build_parser().parse_args(["render", "--depth", "2", "--ao", "0", "--glossy", "2x4",
                                      "--ao-angle", "30", "-o", "/tmp/unused.png"])
    s = settings_from_args(args, (8, 8), scene.render_defaults)
    assert (s.depth, s.ao_rows, s.glossy_rows, s.glossy_cols, s.ao_angle, s.ao_distance) == \
        (2, 0, 2, 4, 30.0, 0.25)


@pytest.mark.parametrize("table, message", [
    ("depth = 2\nbounces = 3", r"line 3: \[render\] bounces: unknown key"),
    ('glossy = "3"', r"line 2: \[render\] glossy: must be \"RxC\""),
    ("ao = 4", r"line 2: \[render\] ao: must be a string"),
    ("depth = 99", r"line 2: \[render\] depth: must be from 0 to 16"),
    ("ao_angle = 90", r"line 2: \[render\] ao_angle: must be above 0 and below 90"),
])
def test_render_table_errors_name_file_line_and_key(tmp_path, table, message):
    text = Path(SCENE_FILES["showcase"]).read_text().split("[render]")[0]
    head = text.count("\n")
    p = tmp_path / "s.toml"
    p.write_text(text + "[render]\n" + table + "\n")
    msg = message.replace("line 2", f"line {head + 2}").replace("line 3", f"line {head + 3}")
    with pytest.raises(SceneFileError, match=r"s\.toml: " + msg):
        check_scene_file(p)


def test_cli_secondary_options_are_one_line_errors(tmp_path, capsys):
    out = tmp_path / "o.png"
    for argv, message in [(["--depth", "17"], r"--depth: must be 0 to 16"),
                          (["--glossy", "3"], r"--glossy: '3' is not RxC"),
                          (["--ao", "0x2"], r"--ao: '0x2': rows and cols"),
                          (["--ao-angle", "95"], r"--ao-angle: must be in \(0, 90\)"),
                          (["--ao-distance", "2"], r"--ao-distance: must be in \(0, 1\]")]:
        assert main(["render", "--scene", "showcase", *argv, "-o", str(out)]) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and re.search(message, err), err
        assert err.startswith("raplas-hdl render: error: ")
    assert not out.exists()
