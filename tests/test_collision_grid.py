"""GraspPose-Opt's collision grids (graspkit.data.grasp_io.collision_sdf_grid): cells of at most 2 mm, so that points
just inside a thin wall read as inside, against the exact signed distance (a 64-node grid misses most of them)."""
import numpy as np
import pytest
import torch
import trimesh

from graspkit.data.grasp_io import COLLISION_CELL, collision_sdf_grid, resolution_for
from graspkit.objects import make_object
from graspkit.objects.sdf import SDFGrid, signed_distance


def _inside_share(grid: SDFGrid, mesh: trimesh.Trimesh, depth: float) -> float:
    """Share of points `depth` m inside the surface (along the inward normal) that the grid reads as inside."""
    pts, fi = trimesh.sample.sample_surface(mesh, 2000, seed=0)
    q = pts - depth * mesh.face_normals[fi]
    inside = signed_distance(torch.as_tensor(q), mesh).numpy() < 0          # exact: the truth
    return float((grid(torch.as_tensor(q, dtype=torch.float32)[None])[0].numpy() < 0)[inside].mean())


def test_collision_grid_sees_inside_the_wine_glass_walls():
    mesh = make_object("wine_glass")
    fine = collision_sdf_grid("wine_glass")
    assert float(fine.cell.max()) <= COLLISION_CELL + 1e-9
    coarse = SDFGrid.from_mesh(mesh, 64, 0.03)
    for depth in (0.001, 0.002):
        assert _inside_share(fine, mesh, depth) >= 0.95
        assert _inside_share(coarse, mesh, depth) < 0.6              # the old grid: blind in the thin walls


def test_resolution_for_small_objects_keeps_the_minimum_and_rejects_bad_cells():
    assert resolution_for("apple", 0.01) == 64                       # a coarse request never goes below 64 nodes
    n = resolution_for("frying_pan", COLLISION_CELL)
    ext = make_object("frying_pan").bounds
    assert (float(np.max(ext[1] - ext[0])) + 0.06) / (n - 1) <= COLLISION_CELL
    with pytest.raises(ValueError, match="cell"):
        resolution_for("apple", 0.0)
