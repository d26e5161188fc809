"""Scenes: procedural builders, mesh files (good and bad), the load normalisation."""

import math

import numpy as np
import pytest

from raplas_hdl.host.meshes import load_mesh
from raplas_hdl.host.scenes import SCENES, get_scene, mesh_scene


@pytest.mark.parametrize("name", sorted(SCENES))
def test_procedural_scene_normalised(name):
    scene = get_scene(name, bound=8.0)
    pts = scene.points_of_interest()
    extent = np.abs(pts).max()
    assert 4.0 < extent <= 8.0
    assert math.log2(scene.scale).is_integer()            # power-of-two scale
    assert scene.n_triangles > 10
    assert np.all((scene.colours >= 0) & (scene.colours <= 1))
    # the scale is exact: normalising again changes nothing
    again = scene.normalised(8.0)
    assert again.scale == scene.scale
    np.testing.assert_array_equal(again.vertices, scene.vertices)
    # the camera and the light went through the same map
    raw = SCENES[name]()
    np.testing.assert_allclose(
        np.asarray(scene.camera.position),
        (np.asarray(raw.camera.position) + scene.translation) * scene.scale)
    np.testing.assert_allclose(scene.light.centre,
                               (raw.light.centre + scene.translation) * scene.scale)


def test_normalisation_maps_vertices_exactly():
    raw = SCENES["terrain"](n=6)
    scene = raw.normalised(2.0)
    t, s = scene.translation, scene.scale
    np.testing.assert_array_equal(scene.vertices, (raw.vertices + t) * s)
    assert np.abs(scene.points_of_interest()).max() <= 2.0


def test_lights_face_the_scene():
    for name in SCENES:
        scene = get_scene(name)
        centre = scene.vertices.mean(axis=0)
        assert (centre - scene.light.centre) @ scene.light.normal > 0, name


def test_unknown_scene():
    with pytest.raises(ValueError, match="unknown scene"):
        get_scene("no-such-scene")


@pytest.mark.parametrize("suffix", ["obj", "ply", "stl"])
def test_mesh_roundtrip(tmp_path, suffix):
    import trimesh

    box = trimesh.creation.box(extents=(1.0, 2.0, 0.5))
    path = tmp_path / f"box.{suffix}"
    box.export(path)
    verts, faces = load_mesh(path)
    assert faces.shape == (12, 3)
    assert np.ptp(verts[faces].reshape(-1, 3), axis=0) == pytest.approx([1.0, 2.0, 0.5])
    scene = get_scene(str(path))
    assert scene.n_triangles == 12 + 8          # the box on a 2x2 floor
    assert np.abs(scene.points_of_interest()).max() <= 8.0


@pytest.mark.parametrize("name, content, message", [
    ("empty.obj", b"", "is empty"),
    ("points.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\n", "no triangles"),
    ("bad.ply", b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nend_header\n1\n",
     "malformed"),
    ("junk.ply", b"this is not a ply file", "malformed"),
    ("junk.stl", b"garbage\x00\x01", "no triangles|malformed"),
    ("mesh.xyz", b"1 2 3", "unsupported type"),
])
def test_bad_mesh_files(tmp_path, name, content, message):
    path = tmp_path / name
    path.write_bytes(content)
    with pytest.raises(ValueError, match=message):
        load_mesh(path)


def test_missing_mesh_file(tmp_path):
    with pytest.raises(FileNotFoundError):
        mesh_scene(tmp_path / "nothing.obj")


def test_bad_scene_arrays():
    from raplas_hdl.host.camera import Camera
    from raplas_hdl.host.scene import AreaLight, Scene

    cam = Camera((0, 0, 5), (0, 0, 0))
    light = AreaLight((0, 3, 0), (1, 0, 0), (0, 0, 1))
    v = np.eye(3)
    with pytest.raises(ValueError, match="no triangles"):
        Scene("x", v, np.zeros((0, 3), int), (1, 1, 1), cam, light)
    with pytest.raises(ValueError, match="does not exist"):
        Scene("x", v, [[0, 1, 3]], (1, 1, 1), cam, light)
    with pytest.raises(ValueError, match="NaN"):
        Scene("x", np.array([[0, 0, 0], [1, 0, 0], [0, np.nan, 0]]), [[0, 1, 2]], (1, 1, 1),
              cam, light)


def test_shipped_meshes_load_by_name():
    """The meshes travel with the package (nothing reads a path outside it) with their
    licence notes, and load by name."""
    import os

    from raplas_hdl.host.meshes import MESH_DIR, MESHES

    assert set(MESHES) == {"stanford-bunny", "teapot", "spot", "suzanne", "stanford-dragon-100k"}
    assert all(os.path.dirname(p) == MESH_DIR for p in MESHES.values())
    notes = open(os.path.join(MESH_DIR, "README.md")).read()
    assert all(os.path.basename(p) in notes for p in MESHES.values())
    assert "Stanford" in notes and "licen" in notes.lower()
    scene = get_scene("teapot")
    assert scene.n_triangles > 6000 and scene.name == "teapot"


def test_scenes_without_materials_keep_one_shared_material():
    """Backward compatibility: a scene built without a materials table has ``(material,)``
    and material ID 0 on every triangle; ``material_at`` gives its constants per triangle."""
    from raplas_hdl.host.scene import Material

    for name in SCENES:
        scene = get_scene(name)
        assert scene.materials == (scene.material,) and scene.material == Material()
        assert scene.material_ids.shape == (scene.n_triangles,)
        assert not scene.material_ids.any()
        per = scene.material_at([0, scene.n_triangles - 1])
        assert per.ambient.tolist() == [Material().ambient] * 2
        assert per.shininess.tolist() == [Material().shininess] * 2


def test_material_ids_are_checked():
    from raplas_hdl.host.camera import Camera
    from raplas_hdl.host.scene import AreaLight, Material, Scene

    cam = Camera((0, 0, 5), (0, 0, 0))
    light = AreaLight((0, 3, 0), (1, 0, 0), (0, 0, 1))
    v, f = np.eye(3), [[0, 1, 2]]
    mats = (Material(), Material(reflectivity=0.5, name="mirror"))
    scene = Scene("x", v, f, (1, 1, 1), cam, light, materials=mats, material_ids=[1])
    assert scene.material_at([0]).reflectivity.tolist() == [0.5]
    assert scene.normalised(8.0).materials == mats
    with pytest.raises(ValueError, match="outside the 2 materials"):
        Scene("x", v, f, (1, 1, 1), cam, light, materials=mats, material_ids=[2])
    with pytest.raises(ValueError, match="material_ids must have shape"):
        Scene("x", v, f, (1, 1, 1), cam, light, materials=mats, material_ids=[0, 1])


def test_mesh_up_axis(tmp_path):
    import trimesh

    trimesh.creation.box(extents=(1.0, 0.5, 4.0)).export(tmp_path / "tall.ply")
    for up, height in (((0, 1, 0), 0.5), ((0, 0, 1), 4.0), ((0, 0, -1), 4.0), ((1, 0, 0), 1.0)):
        scene = mesh_scene(tmp_path / "tall.ply", up=up, floor=False)
        ext = np.ptp(scene.vertices, axis=0)
        assert ext[1] == pytest.approx(2.0 * height / 4.0), up      # largest side scaled to 2
        assert scene.vertices[:, 1].min() == pytest.approx(0.0)      # standing on y = 0


def test_shipped_scene_files_load_by_name():
    import os

    from raplas_hdl.host.scenes import SCENE_DIR, SCENE_FILES

    assert "showcase" in SCENE_FILES
    assert all(os.path.dirname(p) == SCENE_DIR for p in SCENE_FILES.values())
    for name in SCENE_FILES:
        scene = get_scene(name)
        assert scene.name == name and np.abs(scene.points_of_interest()).max() <= 8.0
