"""Objects of one's own (graspkit.objects.user): a trimesh or a mesh file checked and moved to the object frame, its
collision grid against trimesh's exact signed distance, the errors a bad mesh gets, and SAGA end to end on it."""
import numpy as np
import pytest
import torch
import trimesh

from graspkit.data.grasp_io import COLLISION_CELL, collision_sdf_grid
from graspkit.objects import make_object
from graspkit.objects.user import as_object


def _box(centre=(0.4, -0.2, 0.9)) -> trimesh.Trimesh:
    """A 5 x 7 x 10 cm box (no catalogue object is a plain box) away from the origin."""
    m = trimesh.creation.box((0.05, 0.07, 0.10))
    m.apply_translation(centre)
    return m


def test_a_catalogue_name_gives_the_catalogue_mesh():
    name, m = as_object("mug")
    ref = make_object("mug")
    assert name == "mug"
    np.testing.assert_array_equal(m.vertices, ref.vertices)
    np.testing.assert_array_equal(m.faces, ref.faces)


def test_a_mesh_is_copied_into_its_bounding_box_frame():
    src = _box()
    before = np.array(src.vertices)
    name, m = as_object(src)
    assert name == "object"
    np.testing.assert_array_equal(src.vertices, before)                       # the caller's mesh is not moved
    np.testing.assert_allclose(m.bounds, [[-0.025, -0.035, -0.05], [0.025, 0.035, 0.05]], atol=1e-12)
    np.testing.assert_allclose(m.vertices, before - [0.4, -0.2, 0.9], atol=1e-12)
    assert np.isclose(m.volume, 0.05 * 0.07 * 0.10)


@pytest.mark.parametrize("suffix", [".obj", ".ply", ".stl"])
def test_a_mesh_file_loads_with_its_stem_as_the_name(tmp_path, suffix):
    path = tmp_path / f"my_kettle{suffix}"
    _box().export(path)
    name, m = as_object(path)
    assert name == "my_kettle"
    assert m.is_watertight and np.isclose(m.volume, 0.05 * 0.07 * 0.10, rtol=1e-6)
    np.testing.assert_allclose(m.bounds[1], [0.025, 0.035, 0.05], atol=1e-6)
    assert as_object(str(path))[0] == "my_kettle"


def _open() -> trimesh.Trimesh:
    m = _box()
    return trimesh.Trimesh(m.vertices, m.faces[:-1], process=False)


def _inverted() -> trimesh.Trimesh:
    m = _box()
    m.invert()
    return m


def _millimetres() -> trimesh.Trimesh:
    m = _box()
    m.apply_scale(1000.0)
    return m


@pytest.mark.parametrize("make, message", [
    (_open, "not closed"), (_inverted, "inside out"), (_millimetres, "in metres"),
    (lambda: "teapot", "unknown object 'teapot'"), (lambda: 3.5, "got float"),
])
def test_a_bad_object_names_the_argument_and_what_was_expected(make, message):
    with pytest.raises(ValueError, match=f"obj: .*{message}"):
        as_object(make())


def test_an_unreadable_file_is_named(tmp_path):
    bad = tmp_path / "broken.obj"
    bad.write_text("this is not a mesh\n")
    with pytest.raises(ValueError, match="broken.obj"):
        as_object(bad)


def test_the_collision_grid_of_a_mesh_matches_trimesh_and_is_cached(tmp_path):
    _, m = as_object(_box())
    grid = collision_sdf_grid(m, tmp_path)
    assert float(grid.cell.max()) <= COLLISION_CELL + 1e-9
    files = list(tmp_path.glob("mesh_r*.npz"))
    assert len(files) == 1
    p = np.random.default_rng(0).uniform(-0.06, 0.06, (2000, 3))
    truth = -trimesh.proximity.signed_distance(m, p)                           # trimesh: positive inside
    got = grid(torch.as_tensor(p)).numpy()
    assert np.abs(got - truth).max() < COLLISION_CELL                            # trilinear within one cell
    again = collision_sdf_grid(m, tmp_path)                                      # read back, not rebuilt
    torch.testing.assert_close(again.values, grid.values)
    assert list(tmp_path.glob("mesh_r*.npz")) == files
