"""Grasp-data I/O (graspkit.data.grasp_io: SDF grid resolution, digests, the grid cache and shipped grids) and the
`graspkit data make` command (graspkit.data.cli: limits, default folders, grasp-only flags, resume), against hand
counts, round trips and grids built separately."""
import argparse
from pathlib import Path

import numpy as np
import pytest
import trimesh

from graspkit.data import cli as data_cli
from graspkit.data import grasp_io
from graspkit.data.grasp_io import SDF_PADDING, cached_sdf_grid, mesh_digest, resolution_for, ship_sdf_grid


def _box():
    return trimesh.creation.box(extents=(0.10, 0.06, 0.04))


@pytest.mark.parametrize("cell", [0.001, 0.0015, 0.0007])
def test_resolution_for_matches_hand_count(cell):
    """Nodes for cells <= `cell` on a 10 cm box padded 3 cm each side (16 cm): the smallest n with 0.16/(n-1) <= cell,
    counted by hand (an exact multiple takes no extra node)."""
    want = {0.001: 161, 0.0015: 108, 0.0007: 230}[cell]       # 0.16/0.001=160 -> 161; 106.7 -> 108; 228.6 -> 230
    n = resolution_for(_box(), cell)
    assert n == want
    longest = 0.10 + 2 * SDF_PADDING
    assert longest / (n - 1) <= cell * (1 + 1e-9) and longest / (n - 2) > cell


def test_mesh_digest_tracks_faces_and_padding(monkeypatch):
    """The digest names a cached grid, so it must change when the faces (reversed winding: another solid's signs) or
    the padding change, as its docstring says; the same mesh gives the same digest."""
    a = _box()
    b = trimesh.Trimesh(a.vertices.copy(), a.faces[:, ::-1].copy(), process=False)
    assert mesh_digest(a) == mesh_digest(_box())
    assert mesh_digest(a) != mesh_digest(b)
    before = mesh_digest(a)
    monkeypatch.setattr(grasp_io, "SDF_PADDING", 0.05)
    assert mesh_digest(a) != before


def test_two_resolutions_of_one_mesh_are_cached_apart(tmp_path):
    """Round trip: grids of one mesh at 12 and 16 nodes go to two files and each read gives back its own resolution
    (nodes on the longest side)."""
    mesh = _box()
    g12 = cached_sdf_grid(mesh, 12, tmp_path)
    g16 = cached_sdf_grid(mesh, 16, tmp_path)
    assert len(list(tmp_path.glob("*.npz"))) == 2
    assert max(g12.values.shape) == 12 and max(g16.values.shape) == 16
    assert max(cached_sdf_grid(mesh, 12, tmp_path).values.shape) == 12
    assert max(cached_sdf_grid(mesh, 16, tmp_path).values.shape) == 16


def test_ship_writes_float16_grid_close_to_built(tmp_path, monkeypatch):
    """ship_sdf_grid's documented contract: float16 values within 0.03 mm of the float32 grid SDFGrid.from_mesh builds,
    box corners as built, in the folder given (the cache elsewhere)."""
    from graspkit.objects.catalogue import make_object
    from graspkit.objects.sdf import SDFGrid

    monkeypatch.setenv("GRASPKIT_CACHE", str(tmp_path / "cache"))
    path = ship_sdf_grid("apple", 16, tmp_path / "ship")
    assert path.parent == tmp_path / "ship" and path.is_file()
    ref = SDFGrid.from_mesh(make_object("apple"), 16, SDF_PADDING)
    with np.load(path) as z:
        assert z["values"].dtype == np.float16
        np.testing.assert_allclose(z["values"].astype(np.float32), ref.values.numpy(), atol=3e-5)
        np.testing.assert_allclose(z["lower"], ref.lower.numpy(), atol=1e-7)
        np.testing.assert_allclose(z["upper"], ref.upper.numpy(), atol=1e-7)


def test_make_dataset_limits(tmp_path):
    """n >= 0 (none asked: none written, no error) and workers >= 1 (ValueError naming workers, before any folder is
    made), the limits make_dataset states."""
    assert data_cli.make_dataset("reach", 0, 1, tmp_path / "zero", workers=1, progress=False) == []
    assert not list((tmp_path / "zero").glob("*.npz"))
    with pytest.raises(ValueError, match="workers"):
        data_cli.make_dataset("reach", 0, 1, tmp_path / "w0", workers=0, progress=False)
    assert not (tmp_path / "w0").exists()


def _parse(*argv):
    p = argparse.ArgumentParser()
    data_cli.add_data_commands(p.add_subparsers(dest="command"))
    return p.parse_args(["data", "make", *argv])


@pytest.fixture
def calls(monkeypatch, tmp_path):
    """Record what `graspkit data make` hands to the generators (none runs)."""
    from graspkit.data import grasp_make

    got = []
    monkeypatch.setenv("GRASPKIT_CACHE", str(tmp_path))
    monkeypatch.setattr(data_cli, "make_dataset", lambda kind, n, seed, out, *a, **k: got.append((kind, n, Path(out))))
    monkeypatch.setattr(grasp_make, "make_grasp_dataset",
                        lambda kind, n, seed, out, *a, **k: got.append((kind, n, Path(out), k.get("objects"))))
    return got


def test_cli_n_zero_and_default_folder(calls, tmp_path):
    """--n 0 is taken as given (not the default), and the default --out is <cache>/motion/<kind> for clips and
    <cache>/grasps/<kind> for grasps, as the --out help says."""
    a = _parse("--kind", "reach", "--n", "0")
    assert a.func(a) == 0
    assert calls[-1] == ("reach", 0, tmp_path / "motion" / "reach")
    a = _parse("--kind", "grasp", "--n", "3")
    assert a.func(a) == 0
    assert calls[-1][:3] == ("grasp", 3, tmp_path / "grasps" / "grasp")


@pytest.mark.parametrize("argv, flag", [(("--kind", "reach", "--objects", "mug"), "--objects"),
                                        (("--kind", "locomotion", "--chunk", "0"), "--chunk"),
                                        (("--kind", "reach", "--chunk", "8"), "--chunk")])
def test_cli_grasp_only_flags_are_refused_for_motion(calls, tmp_path, argv, flag):
    """--chunk and --objects are grasp/approach options: given (even 0) with a motion kind the command fails with a
    ValueError naming the flag, before any generator runs."""
    a = _parse(*argv, "--out", str(tmp_path / "o"))
    with pytest.raises(ValueError, match=flag):
        a.func(a)
    assert calls == []


def test_cli_objects_list_is_checked_before_work(calls, tmp_path):
    """--objects must name catalogue objects: an empty list or an unknown name is a ValueError naming --objects before
    any work; spaces and empty items around names are dropped."""
    from graspkit.data.grasp_make import OBJECT_ORDER

    for bad in (",", " ", f"{OBJECT_ORDER[0]},nope"):
        a = _parse("--kind", "grasp", "--objects", bad, "--out", str(tmp_path / "o"))
        with pytest.raises(ValueError, match="--objects"):
            a.func(a)
    assert calls == []
    a = _parse("--kind", "approach", "--objects", f" {OBJECT_ORDER[0]} ,", "--out", str(tmp_path / "o"))
    assert a.func(a) == 0
    assert calls[-1][3] == (OBJECT_ORDER[0],)


def test_object_collision_grid_of_a_file_path_string_is_the_meshs(tmp_path, monkeypatch):
    """A user object given as a file path (a str, not a catalogue name) gets its mesh's own collision grid, the same
    grid collision_sdf_grid builds for that mesh (docstring: only a catalogue name keeps its name's grid)."""
    from graspkit.data.grasp_io import collision_sdf_grid, object_collision_grid

    monkeypatch.setenv("GRASPKIT_CACHE", str(tmp_path))
    mesh = trimesh.creation.box(extents=(0.03, 0.02, 0.01))
    got = object_collision_grid(str(tmp_path / "thing.obj"), mesh)
    want = collision_sdf_grid(mesh)
    np.testing.assert_array_equal(got.values.numpy(), want.values.numpy())
    np.testing.assert_array_equal(got.lower.numpy(), want.lower.numpy())


def test_resume_remakes_a_damaged_last_clip(tmp_path):
    """Resume drops every damaged clip, the last one included: a cut-short last clip is made again to the same bytes
    (a clip's bytes depend only on (seed, kind, index))."""
    a = data_cli.make_dataset("reach", 2, 5, tmp_path, workers=1, progress=False)
    whole = a[1].read_bytes()
    a[1].write_bytes(whole[: len(whole) // 2])
    data_cli.make_dataset("reach", 2, 5, tmp_path, workers=1, progress=False)
    assert a[1].read_bytes() == whole


def test_resolution_for_honours_a_smaller_minimum():
    """With minimum=8, 1 cm cells on the 16 cm padded box need 0.16/0.01 + 1 = 17 nodes (hand count), not 64."""
    assert resolution_for(_box(), 0.01, minimum=8) == 17
    assert resolution_for(_box(), 0.05, minimum=8) == 8          # 0.16/0.05 -> 4 + 1 = 5 < 8: the minimum
