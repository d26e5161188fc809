"""Scene files (TOML): the shipped showcase, every error, transforms, lights, materials, the
render command's view overrides, and a small render of the showcase."""

import math
import re
import shutil
from pathlib import Path

import numpy as np
import pytest

from raplas_hdl.cli import build_parser, main
from raplas_hdl.host.scene_file import (
    SceneFileError,
    check_scene_file,
    load_scene_file,
    mesh_transform,
    override_scene,
    parse_axis,
)
from raplas_hdl.host.meshes import MESHES, load_mesh
from raplas_hdl.host.scene import Material
from raplas_hdl.host.scenes import SCENE_FILES, get_scene

SHOWCASE = SCENE_FILES["showcase"]

SMALL = """\
name = "small"

[camera]
position = [0.0, 1.0, 6.0]
look_at = [0.0, 0.5, 0.0]
fov = 45

[[light]]
type = "area"
corner = [-0.5, 4.0, -0.5]
edge_u = [1.0, 0.0, 0.0]
edge_v = [0.0, 0.0, 1.0]
intensity = 0.5

[materials.shiny]
colour = [0.2, 0.4, 0.6]
specular = 0.7
shininess = 80
reflectivity = 0.5

[[mesh]]
primitive = "quad"
size = [4.0, 3.0]
subdiv = 2

[[mesh]]
file = "box.obj"
material = "shiny"
scale = [1.0, 2.0, 0.5]
rotate = [30.0, 45.0, 60.0]
translate = [0.5, 1.0, -0.25]
"""


@pytest.fixture
def small(tmp_path):
    """A scene file beside a mesh it names by a relative path."""
    import trimesh

    trimesh.creation.box(extents=(1.0, 1.0, 1.0)).export(tmp_path / "box.obj")
    path = tmp_path / "small.toml"
    path.write_text(SMALL)
    return path


def _write(tmp_path, text, name="scene.toml"):
    p = tmp_path / name
    p.write_text(text)
    return p


# -- the showcase ------------------------------------------------------------------------

def test_showcase_loads_by_name_with_its_materials():
    scene = get_scene("showcase", bound=None)
    assert scene.name == "showcase" and 1000 < scene.n_triangles < 20000
    mats = {m.name: m for m in scene.materials}
    assert {"white", "red", "green", "floor", "mirror", "glass"} <= set(mats)
    assert mats["mirror"].reflectivity == 0.9
    assert (mats["glass"].transparency, mats["glass"].ior) == (0.85, 1.5)
    assert mats["floor"].gloss_angle == 6.0 and mats["floor"].reflectivity == 0.3
    assert scene.material == Material()            # the default the renderer uses today
    # every triangle has a material; the glass Suzanne has all of hers
    ids = scene.material_ids
    glass = [m.name for m in scene.materials].index("glass")
    assert np.count_nonzero(ids == glass) == len(load_mesh(MESHES["suzanne"])[1])
    # the walls lie exactly on the box's planes (quarter turns are exact)
    floor = [m.name for m in scene.materials].index("floor")
    assert np.all(scene.triangles[ids == floor][..., 1] == 0.0)
    assert scene.vertices.min(axis=0).tolist() == [0.0, 0.0, 0.0]
    assert scene.vertices.max(axis=0).tolist() == [555.0, 548.8, 559.2]
    assert scene.light.kind == "area" and scene.light.normal[1] == -1.0
    np.testing.assert_allclose(scene.light.centre, (278.0, 548.0, 279.5))
    assert scene.camera.fov == 39.3
    # the same file from another directory gives the same scene
    norm = get_scene("showcase")
    assert np.abs(norm.points_of_interest()).max() <= 8.0
    np.testing.assert_array_equal(norm.material_ids, ids)


def test_showcase_copy_loads_the_same(tmp_path):
    shutil.copy(SHOWCASE, tmp_path / "copy.toml")
    a, b = get_scene("showcase", bound=None), get_scene(str(tmp_path / "copy.toml"), bound=None)
    np.testing.assert_array_equal(a.vertices, b.vertices)
    np.testing.assert_array_equal(a.colours, b.colours)
    assert a.materials == b.materials and a.camera == b.camera and a.light == b.light


# -- transforms, primitives, lights --------------------------------------------------------

def test_transform_order_and_values(small):
    import trimesh

    scene = load_scene_file(small)
    box_v, box_f = load_mesh(small.parent / "box.obj")
    mine = scene.vertices[scene.faces[scene.material_ids == 1]].reshape(-1, 3)
    # reference: trimesh's static-axes x, y, z Euler rotation of the scaled box, translated
    r = trimesh.transformations.euler_matrix(*np.radians([30.0, 45.0, 60.0]), "sxyz")[:3, :3]
    ref = (box_v * [1.0, 2.0, 0.5]) @ r.T + [0.5, 1.0, -0.25]
    np.testing.assert_allclose(mine, ref[box_f].reshape(-1, 3), atol=1e-12)
    np.testing.assert_allclose(mesh_transform(box_v, box_f, None, (1.0, 2.0, 0.5),
                                              (30.0, 45.0, 60.0), (0.5, 1.0, -0.25)), ref,
                               atol=1e-12)


def test_fit_centres_and_scales():
    v = np.array([[1.0, 2.0, 3.0], [5.0, 4.0, 3.5], [1.0, 3.0, 4.0]])
    out = mesh_transform(v, [[0, 1, 2]], fit=2.0, translate=(0.0, 10.0, 0.0))
    np.testing.assert_allclose(out.min(axis=0) + out.max(axis=0), [0.0, 20.0, 0.0])
    assert np.ptp(out, axis=0).max() == pytest.approx(2.0)
    np.testing.assert_allclose(out, (v - [3.0, 3.0, 3.5]) * 0.5 + [0.0, 10.0, 0.0])


def test_quad_primitive_faces_up_and_materials_default(small):
    from raplas_hdl.host.shading import face_normals

    scene = load_scene_file(small)
    quad = scene.material_ids == 0
    assert np.count_nonzero(quad) == 8                      # 2x2 cells, 2 triangles each
    np.testing.assert_allclose(face_normals(scene.triangles[quad]), [[0.0, 1.0, 0.0]] * 8)
    assert np.ptp(scene.triangles[quad].reshape(-1, 3), axis=0).tolist() == [4.0, 0.0, 3.0]
    np.testing.assert_allclose(scene.colours[quad], 0.73)
    np.testing.assert_allclose(scene.colours[~quad], [[0.2, 0.4, 0.6]] * 12)
    np.testing.assert_allclose(scene.light.colour, (0.5, 0.5, 0.5))     # intensity


def test_point_light_is_a_small_square_facing_its_direction(tmp_path, small):
    text = SMALL.replace('type = "area"\ncorner = [-0.5, 4.0, -0.5]\nedge_u = [1.0, 0.0, 0.0]\n'
                         'edge_v = [0.0, 0.0, 1.0]',
                         'type = "point"\nposition = [1.0, 3.0, 2.0]\ndirection = [0, -1, -1]')
    scene = load_scene_file(_write(small.parent, text))
    lt = scene.light
    assert lt.kind == "point"
    np.testing.assert_allclose(lt.centre, (1.0, 3.0, 2.0))
    np.testing.assert_allclose(lt.normal, np.array([0.0, -1.0, -1.0]) / math.sqrt(2))
    side = 0.01 * np.ptp(scene.vertices[np.unique(scene.faces)], axis=0).max()
    assert np.linalg.norm(lt.edge_u) == pytest.approx(side)
    assert np.linalg.norm(lt.edge_v) == pytest.approx(side)
    # default direction: against the camera's up
    text = text.replace("direction = [0, -1, -1]", "size = 0.25")
    lt = load_scene_file(_write(small.parent, text)).light
    np.testing.assert_allclose(lt.normal, (0.0, -1.0, 0.0))
    assert np.linalg.norm(lt.edge_u) == pytest.approx(0.25)
    assert lt.transformed((1.0, 0.0, 0.0), 2.0).kind == "point"       # survives the load map


def test_gltf_mesh_and_sphere_primitive(tmp_path):
    import trimesh

    trimesh.creation.box(extents=(2.0, 1.0, 1.0)).export(tmp_path / "box.glb")
    text = SMALL.replace('file = "box.obj"', 'file = "box.glb"').replace(
        'scale = [1.0, 2.0, 0.5]\nrotate = [30.0, 45.0, 60.0]\n', "").replace(
        'primitive = "quad"\nsize = [4.0, 3.0]\nsubdiv = 2',
        'primitive = "sphere"\nradius = 0.5\nsubdiv = 1')
    scene = load_scene_file(_write(tmp_path, text))
    ball = scene.vertices[np.unique(scene.faces[scene.material_ids == 0])]
    np.testing.assert_allclose(np.linalg.norm(ball, axis=1), 0.5)
    assert np.count_nonzero(scene.material_ids == 0) == 80
    box = scene.vertices[np.unique(scene.faces[scene.material_ids == 1])]
    assert np.ptp(box, axis=0) == pytest.approx([2.0, 1.0, 1.0])


def test_per_triangle_phong_constants(small):
    from raplas_hdl.host.shading import phong

    scene = load_scene_file(small)
    rng = np.random.default_rng(3)
    tri = rng.integers(0, scene.n_triangles, 40)
    pts = scene.triangles[tri].mean(axis=1)
    nrm = np.tile([0.0, 1.0, 0.0], (40, 1))
    vis = rng.uniform(0, 1, 40)
    eye = np.asarray(scene.camera.position)
    got = phong(pts, nrm, scene.colours[tri], eye, scene.light, scene.material_at(tri), vis)
    for k, m in enumerate(scene.materials):
        sel = scene.material_ids[tri] == k
        want = phong(pts[sel], nrm[sel], scene.colours[tri][sel], eye, scene.light, m, vis[sel])
        np.testing.assert_allclose(got[sel], want, rtol=1e-14)
    assert np.any(scene.material_ids[tri] == 1) and np.any(scene.material_ids[tri] == 0)


# -- errors: one line naming the file, the line and the key ---------------------------------

BASE = Path(SHOWCASE).read_text()


def _line(text, needle):
    return text[:text.index(needle)].count("\n") + 1


@pytest.mark.parametrize("old, new, message", [
    ("fov = 39.3", "fov = 39.3.1", r"line {n}, column \d+: TOML syntax error: "),
    ("rotate = [0.0, 180.0, 0.0]", "rotation = [0.0, 180.0, 0.0]",
     r"line {n}: \[\[mesh\]\] #8 rotation: unknown key"),
    ("rotate = [0.0, 180.0, 0.0]", "rotate = [0.0, 180.0]",
     r"line {n}: \[\[mesh\]\] #8 rotate: must be 3 angles"),
    ('material = "glass"', 'material = "glas"',
     r"line {n}: \[\[mesh\]\] #8 material: unknown material 'glas'"),
    ('shipped = "suzanne"', 'file = "nope.obj"',
     r"line {n}: .*file: mesh file .*nope.obj' does not exist"),
    ('shipped = "suzanne"', 'shipped = "bunny"', r"line {n}: .*shipped: unknown value 'bunny'"),
    ('shipped = "suzanne"', 'file = "mesh.xyz"', r"line {n}: .*unsupported type"),
    ('up = "y"', "up = [0, 0, 1]", r"line {n}: \[camera\] up: up is parallel"),
    ('up = "y"', 'up = "w"', r"line {n}: \[camera\] up: 'w' is not an axis"),
    ("look_at = [278.0, 273.0, 0.0]", "look_at = [278.0, 273.0, -800.0]",
     r"line {n}: \[camera\] look_at: look_at equals position"),
    ("fov = 39.3", "fov = 190", r"line {n}: \[camera\] fov: must be above 0 and below 180"),
    ("fov = 39.3", 'fov = "wide"', r"line {n}: \[camera\] fov: must be a number, not a string"),
    ("position = [278.0, 273.0, -800.0]\n", "", r"line {camera}: camera: missing key 'position'"),
    ("[camera]", "[kamera]", r"line {n}: kamera: unknown key"),
    ("[[light]]", "[light]", r"line {n}: light: must be an array of tables: write \[\[light\]\]"),
    ("edge_v = [0.0, 0.0, 105.0]", "edge_v = [260.0, 0.0, 0.0]",
     r"line {n}: \[\[light\]\] #1 edge_v: .*not parallel"),
    ('type = "area"', 'type = "spot"', r"line {n}: \[\[light\]\] #1 type: unknown value 'spot'"),
    ('type = "area"', 'type = "point"',
     r"line {n1}: \[\[light\]\] #1 corner: unknown key \(expected one of type, position, size"),
    ("ior = 1.5", "ior = 0.5", r"line {n}: \[materials.glass\] ior: must be from 1 to 4"),
    ("transparency = 0.85", "transparency = 0.95",
     r"line {n}: \[materials.glass\] transparency: reflectivity \+ transparency must be at most 1"),
    ("colour = [0.65, 0.06, 0.05]", "colour = [1.65, 0.06, 0.05]",
     r"line {n}: \[materials.red\] colour: must be 3 numbers .*from 0 to 1"),
    ('primitive = "sphere"', 'primitive = "cube"',
     r"line {n}: \[\[mesh\]\] #7 primitive: unknown value 'cube'"),
    ("radius = 100.0", "size = [1.0, 2.0, 3.0]", r"line {n}: \[\[mesh\]\] #7 size: unknown key"),
    ("fit = 200.0", "scale = -1", r"line {n}: .*#8 scale: must be above 0"),
    ("fit = 200.0", "scale = [1, 0, 1]",
     r"line {n}: \[\[mesh\]\] #8 scale: must be 3 positive numbers"),
    ('shipped = "suzanne"', 'shipped = "suzanne"\nprimitive = "box"',
     (r"line {mesh8}: \[\[mesh\]\] #8: needs exactly one of file, shipped, primitive "
     r"\(has shipped and primitive\)")),
    ("subdiv = 3", "subdiv = true",
     r"line {n}: \[\[mesh\]\] #7 subdiv: must be an integer, not a boolean"),
    ("subdiv = 3", "subdiv = 9", r"line {n}: \[\[mesh\]\] #7 subdiv: must be from 0 to 5"),
    ('name = "showcase"', 'nme = "x"', r"line {n}: nme: unknown key"),
])
def test_errors_name_file_line_and_key(tmp_path, old, new, message):
    assert old in BASE
    text = BASE.replace(old, new, 1)
    n = _line(text, new) if new else _line(BASE, old)
    path = _write(tmp_path, text, "bad.toml")
    mesh8 = text.rindex("[[mesh]]")
    message = message.format(n=n, n1=n + 1, camera=_line(BASE, "[camera]"),
                             mesh8=text[:mesh8].count("\n") + 1)
    with pytest.raises(SceneFileError, match=re.escape(str(path)) + ": " + message):
        check_scene_file(path)


def test_errors_of_whole_tables(tmp_path):
    cases = [
        (BASE + '\n[[light]]\ntype = "point"\nposition = [1, 2, 3]\n', r"2 lights"),
        (BASE.split("[[mesh]]")[0], r"missing \[\[mesh\]\]"),
        (BASE.replace("[camera]", "[[camera]]"), r"write \[camera\], not \[\[camera\]\]"),
        ('mesh = "box"\n' + BASE.split("[[mesh]]")[0],
         r"mesh: must be an array of tables \(\[\[mesh\]\]\), not a string"),
        ("", r"missing table \[camera\]"),
    ]
    for text, message in cases:
        with pytest.raises(SceneFileError, match=message):
            check_scene_file(_write(tmp_path, text))
    with pytest.raises(SceneFileError, match="does not exist"):
        check_scene_file(tmp_path / "none.toml")
    (tmp_path / "bin.toml").write_bytes(b"\xff\xfe name")
    with pytest.raises(SceneFileError, match="not UTF-8"):
        check_scene_file(tmp_path / "bin.toml")


def test_malformed_mesh_file_named_with_the_scene_file(tmp_path, small):
    (small.parent / "box.obj").write_text("v 0 0 0\nv 1 0 0\n")
    with pytest.raises(SceneFileError, match=r"small.toml: line \d+: \[\[mesh\]\] #2 file: "
                                             r"mesh file .* no triangles"):
        load_scene_file(small)


# -- the command line ---------------------------------------------------------------------

def _args(*argv):
    args = build_parser().parse_args(["render", *argv, "-o", "/tmp/unused.png"])
    args._check(args)
    return args


def test_cli_overrides_change_camera_and_light():
    from raplas_hdl.cli.render import scene_from_args

    args = _args("--scene", "showcase", "--camera", "100,200,-700", "--look-at", "300,250,10",
                 "--up=-x", "--fov", "60", "--light", "278,500,300")
    scene = scene_from_args(args)
    cam = scene.camera
    assert (cam.position, cam.look_at, cam.up, cam.fov) == ((100.0, 200.0, -700.0),
                                                            (300.0, 250.0, 10.0),
                                                            (-1.0, 0.0, 0.0), 60.0)
    np.testing.assert_allclose(scene.light.centre, (278.0, 500.0, 300.0))
    np.testing.assert_allclose(scene.light.edge_u, (130.0, 0.0, 0.0))
    # a procedural scene: the same options through override_scene
    scene = scene_from_args(_args("--scene", "spheres", "--fov", "20"))
    assert scene.camera.fov == 20.0 and scene.camera.position == (0.5, 3.2, 7.0)


def test_cli_up_turns_a_mesh_file(tmp_path):
    import trimesh

    from raplas_hdl.cli.render import scene_from_args

    trimesh.creation.box(extents=(1.0, 1.0, 4.0)).export(tmp_path / "tall.stl")
    scene = scene_from_args(_args("--scene", str(tmp_path / "tall.stl"), "--up", "z"))
    box = scene.vertices[np.unique(scene.faces[-12:])]
    assert np.ptp(box, axis=0) == pytest.approx([0.5, 2.0, 0.5])      # tallest side now y
    assert scene.camera.up == (0.0, 1.0, 0.0)


def test_cli_errors_are_one_line(tmp_path, capsys):
    bad = _write(tmp_path, BASE.replace("ior = 1.5", "ior = 9"), "bad.toml")
    cases = [
        (["--scene", str(bad)], r"bad.toml: line \d+: \[materials.glass\] ior"),
        (["--scene", "showcase", "--up", "0,0,1"], r"up is parallel .*overridden up"),
        (["--scene", "showcase", "--camera", "1,2"], r"--camera: '1,2' is not a point"),
        (["--scene", "showcase", "--fov", "180"], r"--fov: must be in \(0, 180\)"),
        (["--scene", "showcase", "--up", "q"], r"--up: 'q' is not an axis"),
        (["--scene", str(tmp_path / "none.toml")], r"scene file .*none.toml.* does not exist"),
    ]
    out = tmp_path / "out.png"
    for argv, message in cases:
        assert main(["render", *argv, "-o", str(out), "--backend", "float64"]) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and re.search(message, err), err
        assert err.startswith("raplas-hdl render: error: ")
    assert not out.exists()


def test_mode_choices_come_from_modes():
    from raplas_hdl.model.modes import MODES

    for mode in MODES:
        assert _args("--mode", mode).mode == mode
    action = next(a for a in build_parser()._subparsers._group_actions[0].choices["render"]
                  ._actions if a.dest == "mode")
    assert action.metavar == "{" + ",".join(MODES) + "}"


def test_parse_axis():
    assert parse_axis("z") == (0.0, 0.0, 1.0) and parse_axis("-Y") == (0.0, -1.0, 0.0)
    assert parse_axis("1, 2, 3") == (1.0, 2.0, 3.0)
    for bad in ("", "w", "0,0,0", "1,2", "nan,1,1", "xy"):
        with pytest.raises(ValueError):
            parse_axis(bad)


def test_override_scene_checks_the_camera():
    scene = get_scene("cornell", bound=None)
    with pytest.raises(ValueError, match="overridden look_at: look_at equals position"):
        override_scene(scene, look_at=scene.camera.position)
    moved = override_scene(scene, light=(0.0, 0.0, 0.0))
    np.testing.assert_allclose(moved.light.centre, 0.0)
    assert moved.camera == scene.camera


# -- a render of the showcase -------------------------------------------------------------

def test_showcase_renders_through_float64_and_the_model(tmp_path):
    from raplas_hdl.host.backends import make_backend
    from raplas_hdl.host.output import compare
    from raplas_hdl.host.render import RenderSettings, render

    scene = get_scene("showcase")
    s = RenderSettings(width=16, height=16, rows=8, cols=8, shadow_rows=2, shadow_cols=2,
                       progress=False)
    ref = render(scene, make_backend("float64"), s)
    res = render(scene, make_backend("model", mode="paper"), s)
    cmp = compare(res, ref)
    assert cmp["psnr"] > 40.0
    assert np.all(np.isfinite(ref.image))
    # the picture shows the box, the mirror sphere and the glass Suzanne
    names = [m.name for m in scene.materials]
    seen = {names[k] for k in scene.material_ids[ref.tri_id[ref.tri_id >= 0]]}
    assert {"floor", "mirror", "glass", "red", "green", "white"} <= seen
    assert np.mean(ref.tri_id == res.tri_id) > 0.97


def test_the_example_of_the_docs_loads(tmp_path):
    """docs/scenes.md's full example is a valid scene file (beside a mesh it names)."""
    import trimesh

    doc = (Path(__file__).resolve().parents[2] / "docs" / "scenes.md").read_text()
    text = re.search(r"## A full example\s+```toml\n(.*?)```", doc, re.DOTALL).group(1)
    (tmp_path / "meshes").mkdir()
    trimesh.creation.box(extents=(1.0, 1.0, 3.0)).export(tmp_path / "meshes" / "vase.obj")
    scene = load_scene_file(_write(tmp_path, text, "example.toml"))
    assert scene.name == "example" and [m.name for m in scene.materials] == \
        ["default", "floor", "glass", "mirror"]
    vase = scene.vertices[np.unique(scene.faces[scene.material_ids == 2])]
    assert np.ptp(vase, axis=0) == pytest.approx([0.5, 1.5, 0.5])      # fit, then z up
    np.testing.assert_allclose(vase.min(axis=0) + vase.max(axis=0), [-2.0, 1.5, 0.0],
                               atol=1e-12)


def test_inline_table_errors_name_its_line(tmp_path):
    text = BASE.replace('[camera]\nposition = [278.0, 273.0, -800.0]\nlook_at = [278.0, 273.0, '
                        '0.0]\nup = "y"\nfov = 39.3\n',
                        'camera = {position = [278.0, 273.0, -800.0], look_at = [0, 0, 0], '
                        'fov = 200}\n')
    assert text != BASE
    with pytest.raises(SceneFileError, match=rf"line {_line(text, 'camera = ')}: \[camera\] "
                                             r"fov: must be above 0 and below 180"):
        check_scene_file(_write(tmp_path, text))
