"""Objects of one's own (graspkit.objects.user): a trimesh or a mesh file checked and moved to the object frame, its
collision grid against trimesh's exact signed distance, the errors a bad mesh gets, and SAGA end to end on it."""
import warnings
from pathlib import Path

import numpy as np
import pytest
import torch
import trimesh

from graspkit.data import grasp_io
from graspkit.data.formats import write_npz_atomic
from graspkit.data.grasp_io import COLLISION_CELL, cached_sdf_grid, collision_sdf_grid
from graspkit.objects import make_object
from graspkit.objects.sdf import SDFGrid
from graspkit.paths import DATA_STUBS
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


def test_a_nan_vertex_in_a_file_is_named_not_dropped(tmp_path):
    path = tmp_path / "corrupt.obj"
    _box().export(path)
    lines = path.read_text().splitlines()
    k = next(i for i, line in enumerate(lines) if line.startswith("v "))
    lines[k] = "v nan 0 0"                       # trimesh's processing would drop it and its faces: "not closed"
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(ValueError, match="corrupt.obj.*NaN or infinite"):
        as_object(path)


def test_a_catalogue_name_may_come_as_a_path():
    name, m = as_object(Path("mug"))
    assert name == "mug" and np.array_equal(m.vertices, make_object("mug").vertices)


def test_a_catalogue_name_is_not_hidden_by_a_file_of_that_name(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    _box().export(tmp_path / "mug", file_type="stl")      # a file called "mug" in the working folder
    name, m = as_object("mug")                             # the name: the catalogue's mug
    assert name == "mug" and np.array_equal(m.vertices, make_object("mug").vertices)
    with pytest.raises(ValueError, match="could not read a mesh from mug"):
        as_object(Path("mug"))                             # a Path: the file (trimesh needs a suffix to read it)


def test_a_glb_file_is_read_y_up_as_gltf_specifies_and_round_trips_graspkits_export(tmp_path):
    from scipy.spatial import cKDTree

    from graspkit.viz.export import export_scene
    mug = make_object("mug")                            # z up, handle along +x
    path = export_scene({"mug": mug}, tmp_path / "mug_export.glb")        # written y up
    raw = trimesh.load(path, force="mesh", process=False)
    np.testing.assert_allclose(raw.extents, mug.extents[[0, 2, 1]], atol=1e-6)   # the file: the mug's height along y
    name, m = as_object(path)
    assert name == "mug_export"
    np.testing.assert_allclose(m.extents, mug.extents, atol=1e-6)
    d, _ = cKDTree(mug.vertices).query(m.vertices)
    assert d.max() < 1e-6                              # the same mug, upright, not mirrored
    assert m.volume == pytest.approx(mug.volume, rel=1e-5)


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


def test_a_grid_cached_by_another_grid_version_is_not_read(tmp_path, monkeypatch):
    """A cache file written by another SDF_VERSION (a stale algorithm) is neither found nor overwritten: the grid is
    built again, under its own name."""
    _, m = as_object(_box())
    grid = cached_sdf_grid(m, 16, tmp_path)
    (old,) = tmp_path.glob("mesh_r16_*.npz")
    with np.load(old) as z:                                                      # poison the cached values
        write_npz_atomic(old, {"values": z["values"] + 1.0, "lower": z["lower"], "upper": z["upper"]})
    assert float(cached_sdf_grid(m, 16, tmp_path).values.min()) == pytest.approx(float(grid.values.min()) + 1.0)
    monkeypatch.setattr(grasp_io, "SDF_VERSION", grasp_io.SDF_VERSION + 1)
    fresh = cached_sdf_grid(m, 16, tmp_path)
    torch.testing.assert_close(fresh.values, SDFGrid.from_mesh(m, 16, grasp_io.SDF_PADDING).values)
    assert len(list(tmp_path.glob("mesh_r16_*.npz"))) == 2


def test_the_shipped_grids_are_what_this_grid_version_builds():
    """Each grid in data_stubs/sdf has the current file name of its object and resolution (a stale shipped grid would
    otherwise be read in place of a rebuild), and the smallest one (a few seconds to rebuild) its values within
    0.05 mm. (The r64 grids are float32 as the cache stores them, mug_r84 float16 from ship_sdf_grid; an independent
    rebuild of mug_r84 on 2026-12-06 found 0.031 mm.)"""
    files = sorted((DATA_STUBS / "sdf").glob("*.npz"))
    assert files
    for f in files:
        name, res, _ = f.name.rsplit("_", 2)
        assert f.name == grasp_io._grid_filename(name, int(res[1:]))
    f = min(files, key=lambda f: f.stat().st_size)                             # one rebuilt: seconds
    name, res, _ = f.name.rsplit("_", 2)
    built = SDFGrid.from_mesh(make_object(name), int(res[1:]), grasp_io.SDF_PADDING)
    with np.load(f, allow_pickle=False) as z:
        assert np.abs(z["values"].astype(np.float64) - built.values.numpy()).max() < 5e-5


def _box_with_sliver() -> trimesh.Trimesh:
    """The box with one face split at the midpoint m of its edge a-b and the T-junction closed by the zero-area face
    (a, b, m), as CAD exports make them: trimesh calls it watertight, consistently wound and of positive volume."""
    m = _box()
    v, f = np.array(m.vertices), [list(x) for x in m.faces]
    a, b, c = f[0]
    v = np.vstack([v, (v[a] + v[b]) / 2])
    mid = len(v) - 1
    f[0:1] = [[a, mid, c], [mid, b, c], [a, b, mid]]
    return trimesh.Trimesh(v, np.array(f), process=False)


def _overlapping_bars() -> trimesh.Trimesh:
    """Two crossing bars, one mesh of two closed parts that overlap (a plus sign, not a union)."""
    return trimesh.util.concatenate([trimesh.creation.box((0.12, 0.03, 0.03)), trimesh.creation.box((0.03, 0.12, 0.03))])


def _one_part_inverted() -> trimesh.Trimesh:
    """A ball and, beside it, a smaller ball turned inside out: the total volume is still positive."""
    big, small = trimesh.creation.icosphere(3, 0.04), trimesh.creation.icosphere(3, 0.02)
    small.apply_translation((0.1, 0, 0))
    small.invert()
    return trimesh.util.concatenate([big, small])


def _touching_boxes() -> trimesh.Trimesh:
    """Two 5 cm cubes side by side, each closed, sharing the face x = 0 (a body and its lid glued face to face): the
    10 x 5 x 5 cm box, with an inner wall along which the distance to the surface is 0 at 2.5 cm depth."""
    a, b = trimesh.creation.box((0.05, 0.05, 0.05)), trimesh.creation.box((0.05, 0.05, 0.05))
    a.apply_translation((-0.025, 0, 0))
    b.apply_translation((0.025, 0, 0))
    return trimesh.util.concatenate([a, b])


def _repeated_corner() -> trimesh.Trimesh:
    """A closed box plus one face that repeats a corner (zero area): it also fails trimesh's watertight test."""
    m = _box()
    return trimesh.Trimesh(m.vertices, np.vstack([m.faces, [[0, 0, 1]]]), process=False)


def _nan_vertex() -> trimesh.Trimesh:
    m = _box()
    v = np.array(m.vertices)
    v[0, 0] = np.nan
    return trimesh.Trimesh(v, m.faces, process=False)


def _unmerged() -> trimesh.Trimesh:
    m = _box()
    return trimesh.Trimesh(m.vertices[m.faces].reshape(-1, 3), np.arange(3 * len(m.faces)).reshape(-1, 3), process=False)


@pytest.mark.parametrize("make, message", [
    (_box_with_sliver, "1 faces have zero area"), (_overlapping_bars, "overlap"), (_one_part_inverted, "inside out"),
    (_nan_vertex, "NaN"), (_unmerged, "merge_vertices"), (_touching_boxes, "touch along shared faces"),
    (_repeated_corner, "1 faces have zero area"),
])
def test_meshes_that_pass_trimesh_checks_but_give_wrong_signs_are_refused(make, message):
    mesh = make()
    if make in (_box_with_sliver, _overlapping_bars, _one_part_inverted, _touching_boxes):   # what trimesh passes
        assert mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0
    with pytest.raises(ValueError, match=f"obj: .*{message}"):
        as_object(mesh)


@pytest.mark.parametrize("make", [_box_with_sliver, _repeated_corner])
def test_a_zero_area_face_is_refused_by_the_signed_distance_too(make):
    from graspkit.objects.sdf import signed_distance

    with pytest.raises(ValueError, match="mesh: 1 faces have zero area"):
        signed_distance(np.zeros((1, 3)), make())


def test_touching_parts_would_give_signs_against_trimeshs_box():
    """Why the touching boxes are refused: the winding number is 1 inside (volumes are right), but the inner wall
    is surface to a distance query, so points deep inside read as on or outside it (trimesh's box is the truth)."""
    from graspkit.objects.sdf import signed_distance

    box = trimesh.creation.box((0.1, 0.05, 0.05))
    p = np.array([[0.0, 0, 0], [-0.001, 0, 0], [0.001, 0.01, 0]])
    truth = -trimesh.proximity.signed_distance(box, p)
    assert (truth < -0.015).all()
    assert (signed_distance(p, _touching_boxes()).numpy() > -0.002).all()


def test_a_cavity_is_one_solid_and_its_signs_match_trimesh():
    outer, inner = trimesh.creation.icosphere(3, 0.04), trimesh.creation.icosphere(3, 0.02)
    inner.invert()                                         # the cavity's wall faces into the cavity
    _, m = as_object(trimesh.util.concatenate([outer, inner]))
    from graspkit.objects.sdf import signed_distance

    p = np.random.default_rng(1).uniform(-0.05, 0.05, (3000, 3))
    truth = -trimesh.proximity.signed_distance(m, p)
    got = signed_distance(p, m).numpy()
    far = np.abs(truth) > 1e-4
    assert far.sum() > 2500 and (np.sign(got[far]) == np.sign(truth[far])).all()
    assert got[np.linalg.norm(p, axis=1) < 0.015].min() > 0                     # the cavity is outside the solid


def test_vertices_no_face_uses_do_not_stretch_the_collision_grid(tmp_path):
    m = _box()
    stray = trimesh.Trimesh(np.vstack([m.vertices, [[5.0, 5.0, 5.0]]]), m.faces, process=False)
    _, checked = as_object(stray)
    assert len(checked.vertices) == len(m.vertices)
    assert float(collision_sdf_grid(checked, tmp_path).cell.max()) <= COLLISION_CELL + 1e-9
    from graspkit.objects.sdf import SDFGrid

    grid = SDFGrid.from_mesh(stray, resolution=16, padding=0.01)               # the library's grid alone, too
    np.testing.assert_allclose(grid.lower.numpy(), stray.bounds[0] - 0.01, atol=1e-6)


def test_an_object_outside_the_trained_sizes_is_taken_with_a_warning(tmp_path):
    """The catalogue's largest sides (trimesh's bounds) are the range the methods are trained and evaluated on; a
    4 cm ball and a 50 cm box are taken with a UserWarning saying so, a 12 cm box and the catalogue objects without
    one."""
    import warnings

    from graspkit.objects.catalogue import list_objects
    from graspkit.objects.user import CATALOGUE_SIDES

    sides = [float(np.ptp(make_object(n).bounds, axis=0).max()) for n in list_objects()]
    assert CATALOGUE_SIDES == (round(min(sides), 2), round(max(sides), 2))
    with pytest.warns(UserWarning, match=r"the mesh: its largest side is 4.0 cm, below the 8-41 cm"):
        as_object(trimesh.creation.icosphere(radius=0.02))
    trimesh.creation.box((0.5, 0.1, 0.1)).export(tmp_path / "long.stl")
    with pytest.warns(UserWarning, match=r"long.stl: its largest side is 50.0 cm, above the 8-41 cm"):
        as_object(tmp_path / "long.stl")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        as_object(trimesh.creation.box((0.12, 0.05, 0.05)))
        as_object("frying_pan")


def test_the_command_shows_the_size_warning_once_as_a_note(tmp_path, capsys, monkeypatch):
    """`graspkit goal --object small.ply`: the mesh is checked before the run and again inside it; the warning
    shows once, as a `graspkit: note:` line (the run itself is stopped at the first place a body is built)."""
    import graspkit.eval_goal
    from graspkit.cli import main

    trimesh.creation.icosphere(radius=0.02).export(tmp_path / "small.ply")

    def stop(*a, **k):
        raise ValueError("stopped here")

    monkeypatch.setattr(graspkit.eval_goal, "_body", stop)   # synthesize has checked the mesh again by then
    assert main(["goal", "--object", str(tmp_path / "small.ply"), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.count("graspkit: note: ") == 1 and "small.ply: its largest side is 4.0 cm, below" in err, err


def test_user_object_names_sizes_and_upper_case_glb(tmp_path):
    """A mesh's metadata name is its name; a 5 mm box is refused as not metres (the documented 0.01-0.6 m); a glTF file
    named .GLB is y up like .glb (the specification does not depend on the suffix's case): the mug comes back z up."""
    from graspkit.objects import make_object
    from graspkit.objects.user import as_object
    from graspkit.viz.export import export_scene

    box = trimesh.creation.box((0.05, 0.07, 0.10))
    box.metadata["name"] = "kettle"
    assert as_object(box)[0] == "kettle"
    with pytest.raises(ValueError, match="obj: expected a hand-held object in metres"):
        as_object(trimesh.creation.box((0.005, 0.004, 0.003)))
    mug = make_object("mug")
    path = export_scene({"mug": mug}, tmp_path / "mug.glb")
    upper = path.rename(tmp_path / "MUG.GLB")
    name, m = as_object(upper)
    assert name == "MUG"
    np.testing.assert_allclose(m.extents, mug.extents, atol=1e-6)


@pytest.mark.parametrize("offset", [3e4, 1e5, 3e5])
def test_a_mesh_far_from_the_origin_is_taken_and_centred(offset):
    """A closed, outward box still in map coordinates (tens of km out) was refused as inside out: the volume's
    triple products about the world origin cancelled to noise. It is taken, centred, with trimesh's volume."""
    box = trimesh.creation.box((0.10, 0.06, 0.04))
    far = box.copy()
    far.apply_translation((offset, -2 * offset, offset / 2))
    _, m = as_object(far)
    np.testing.assert_allclose(m.bounds, box.bounds, atol=1e-9 * offset)
    assert m.volume == pytest.approx(box.volume, rel=1e-6)
    from graspkit.objects.sdf import signed_distance
    assert float(signed_distance(np.array(far.centroid)[None], far)[0]) == pytest.approx(-0.02, abs=1e-6)


@pytest.mark.parametrize("side", [0.004, 0.002])
def test_a_small_part_sunk_into_another_is_seen(side):
    """A knob of 2-4 mm sunk half into a 12 cm ball is under 0.5 % of the surface, so area-uniform samples missed it;
    each connected part now gets samples of its own. The same knob set apart from the ball is fine."""
    ball = trimesh.creation.icosphere(4, 0.06)
    knob = trimesh.creation.box((side,) * 3)
    with pytest.raises(ValueError, match="overlap"):
        as_object(trimesh.util.concatenate([ball, knob.copy().apply_translation((0.06, 0, 0))]))
    as_object(trimesh.util.concatenate([ball, knob.copy().apply_translation((0.07, 0, 0))]))


def test_the_solid_check_reads_each_part_only_near_its_box_with_the_whole_meshs_winding_number():
    """solid_problem sums each connected part's winding number at the points near that part's box only (a scan of
    250 fragments took minutes against every face): the sum is the whole mesh's winding number at any point, also
    where two parts overlap (2 inside both)."""
    import trimesh

    from graspkit.objects.sdf import winding_number
    from graspkit.objects.user import _winding_by_part

    a, b, c = (trimesh.creation.icosphere(2, r) for r in (0.05, 0.03, 0.02))
    b.apply_translation([0.06, 0.0, 0.0])                  # overlaps a
    c.apply_translation([0.0, 0.2, 0.0])                   # apart
    mesh = trimesh.util.concatenate([a, b, c])
    labels = trimesh.graph.connected_component_labels(mesh.face_adjacency, node_count=len(mesh.faces))
    assert len(np.unique(labels)) == 3
    q = np.random.default_rng(0).uniform([-0.1, -0.1, -0.1], [0.15, 0.3, 0.1], (4000, 3))
    q = np.concatenate([q, [[0.04, 0.0, 0.0], [0.0, 0.2, 0.0], [0.5, 0.5, 0.5]]])
    by_part = _winding_by_part(q, mesh, labels, 1e-4)
    np.testing.assert_allclose(by_part, winding_number(q, mesh).numpy(), atol=1e-9)
    assert by_part[-3] == pytest.approx(2.0) and by_part[-2] == pytest.approx(1.0) and by_part[-1] == 0.0


def test_a_mesh_of_many_faces_gets_a_note_on_what_will_be_slow(monkeypatch):
    """A scan of 82k faces ran `graspkit saga` for over 3 minutes without a word (its 2 mm collision grid): above
    MANY_FACES faces as_object says what grows with them and what to do."""
    import trimesh

    import graspkit.objects.user as U

    ball = trimesh.creation.icosphere(3, 0.06)                 # 1,280 faces
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        U.as_object(ball)                                      # no note below the limit
    monkeypatch.setattr(U, "MANY_FACES", 1000)
    with pytest.warns(UserWarning, match="the mesh: 1,280 faces: the exact distances and the 2 mm collision grid"):
        U.as_object(ball)


def test_solids_that_touch_along_a_face_are_told_to_be_joined(tmp_path):
    """Two boxes touching face to face, concatenated and saved: the file's error said "not closed" with a hint to fill
    holes it does not have (edges shared by four faces); it names those edges and the union that mends them."""
    a = trimesh.creation.box((0.06, 0.04, 0.04))
    b = trimesh.creation.box((0.04, 0.04, 0.04))
    b.apply_translation([0.05, 0.0, 0.0])
    trimesh.util.concatenate([a, b]).export(tmp_path / "L.stl")
    with pytest.raises(ValueError, match=r"4 edges are used by more than two faces: .*boolean union"):
        as_object(tmp_path / "L.stl", "--object")
