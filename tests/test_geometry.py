"""The geometry layer against independent truths: trimesh, scipy, brute force and analytic formulas."""
from __future__ import annotations

import numpy as np
import pytest
import torch
import trimesh
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from graspkit.objects import (IAA_WEIGHT, SDFGrid, TEST_OBJECTS, apply_pose, body_object_attention, bps_basis,
                              bps_encode, interaction_attention, interpenetration, intersection_volume,
                              list_objects, make_object, marker_contact, nearest_neighbours, object_contact,
                              object_sdf_grid, penetration_depth, point_mesh_distance, sample_object_pose, sample_surface,
                              signed_distance, signed_distance_to_points, winding_number)
from graspkit.objects import distance as D
from graspkit.objects.contact import distance_to

ALL = list_objects()


def _box_points(mesh: trimesh.Trimesh, n: int, seed: int, pad: float = 0.02) -> np.ndarray:
    """n uniform random points in the mesh's bounding box padded by `pad` metres."""
    lo, hi = mesh.bounds
    return np.random.default_rng(seed).uniform(lo - pad, hi + pad, size=(n, 3))


def _brute_force_distance(mesh: trimesh.Trimesh, pts: np.ndarray) -> np.ndarray:
    """Exact point-mesh distance by trimesh's point-triangle routine over ALL (point, face) pairs."""
    tri = mesh.triangles
    cp = trimesh.triangles.closest_point(np.tile(tri, (len(pts), 1, 1)), np.repeat(pts, len(tri), 0))
    return np.linalg.norm(np.repeat(pts, len(tri), 0) - cp, axis=1).reshape(len(pts), len(tri)).min(1)


def _sphere(radius: float, centre=(0.0, 0.0, 0.0), subdivisions: int = 4) -> trimesh.Trimesh:
    s = trimesh.creation.icosphere(subdivisions, radius)
    s.apply_translation(centre)
    return s


def _open_mesh() -> trimesh.Trimesh:
    s = _sphere(0.05, subdivisions=2)
    return trimesh.Trimesh(s.vertices, s.faces[1:], process=False)


# ---------------------------------------------------------------------------------------------- sampling

@pytest.mark.parametrize("name", ["mug", "wine_glass", "banana", "cracker_box"])
def test_sampled_points_on_surface_with_outward_unit_normals(name):
    mesh = make_object(name)
    pts, nrm = sample_surface(mesh, 2048, seed=0)
    assert pts.shape == (2048, 3) and nrm.shape == (2048, 3)
    np.testing.assert_allclose(np.linalg.norm(nrm, axis=1), 1.0, atol=1e-9)
    assert _brute_force_distance(mesh, pts[:200]).max() <= 1e-5
    # the normal agrees with trimesh's normal of the face the point lies on, and points outward
    _, _, face = trimesh.proximity.closest_point(mesh, pts)
    assert (np.einsum("nd,nd->n", nrm, mesh.face_normals[face]) > 0.999).mean() > 0.99
    out, inn = mesh.contains(pts + 5e-4 * nrm), mesh.contains(pts - 5e-4 * nrm)
    assert (~out).mean() > 0.99 and inn.mean() > 0.99


def test_sampling_is_deterministic_and_area_weighted():
    mesh = make_object("cracker_box")
    a, b, c = sample_surface(mesh, 4000, seed=1), sample_surface(mesh, 4000, seed=1), sample_surface(mesh, 4000, 2)
    np.testing.assert_array_equal(a[0], b[0])
    assert not np.allclose(a[0], c[0])
    # fraction of points on the two large (x-z) faces equals their share of the area (binomial 5 sigma)
    on_large = np.abs(np.abs(a[1][:, 1]) - 1.0) < 1e-9
    share = 2 * 0.16 * 0.21 / mesh.area
    assert abs(on_large.mean() - share) < 5 * np.sqrt(share * (1 - share) / 4000)
    with pytest.raises(ValueError, match="n"):
        sample_surface(mesh, 0)
    for seed in (-1, 1.5, "0"):
        with pytest.raises(ValueError, match="seed: expected a non-negative integer"):
            sample_surface(mesh, 10, seed=seed)
    g1, g2 = np.random.default_rng(7), np.random.default_rng(7)                 # a Generator is used as given
    np.testing.assert_array_equal(sample_surface(mesh, 10, seed=g1)[0], sample_surface(mesh, 10, seed=g2)[0])


# ---------------------------------------------------------------------------------------------- BPS

def test_bps_basis_uniform_in_ball_and_deterministic():
    basis = bps_basis(1024, 0.15, seed=0)
    assert basis.shape == (1024, 3) and basis.dtype == torch.float32
    torch.testing.assert_close(basis, bps_basis(1024, 0.15, seed=0), rtol=0, atol=0)
    assert not torch.allclose(basis, bps_basis(1024, 0.15, seed=1))
    r = basis.double().norm(dim=1)
    assert r.max() <= 0.15 + 1e-7
    # uniform in volume: half of the points within R / 2^(1/3); octants equally filled
    inner = (r < 0.15 / 2 ** (1 / 3)).double().mean().item()
    assert abs(inner - 0.5) < 5 * np.sqrt(0.25 / 1024)
    assert abs((basis[:, 2] > 0).double().mean().item() - 0.5) < 5 * np.sqrt(0.25 / 1024)


def test_bps_encode_matches_kdtree_and_deltas_reach_cloud():
    basis = bps_basis(1024, 0.15, seed=0).double()
    clouds = np.stack([sample_surface(make_object(n), 2048, seed=0)[0] for n in ("mug", "camera")])
    dist, delta = bps_encode(torch.tensor(clouds), basis, return_deltas=True)
    assert dist.shape == (2, 1024) and delta.shape == (2, 1024, 3)
    for b in range(2):
        ref, idx = cKDTree(clouds[b]).query(basis.numpy())
        np.testing.assert_allclose(dist[b].numpy(), ref, atol=1e-12)
        np.testing.assert_allclose((basis + delta[b]).numpy(), clouds[b][idx], atol=1e-12)
    torch.testing.assert_close(delta.norm(dim=-1), dist)
    single = bps_encode(torch.tensor(clouds[0]), basis)
    assert single.shape == (1024,)
    torch.testing.assert_close(single, dist[0])


# ---------------------------------------------------------------------------------------------- distances

def test_nearest_neighbours_matches_kdtree_batched():
    rng = np.random.default_rng(0)
    q, t = rng.normal(size=(3, 500, 3)), rng.normal(size=(3, 800, 3))
    d, i = nearest_neighbours(torch.tensor(q), torch.tensor(t))
    d2, _ = nearest_neighbours(torch.tensor(q), torch.tensor(t), squared=True)
    for b in range(3):
        ref, ridx = cKDTree(t[b]).query(q[b])
        np.testing.assert_allclose(d[b].numpy(), ref, atol=1e-12)
        np.testing.assert_array_equal(i[b].numpy(), ridx)
        np.testing.assert_allclose(d2[b].numpy(), ref ** 2, atol=1e-12)
    d_single, _ = nearest_neighbours(torch.tensor(q[1]), torch.tensor(t[1]))
    torch.testing.assert_close(d_single, d[1])


@pytest.mark.parametrize("kd_pairs", [1, 10 ** 12], ids=["kd-tree", "brute-force"])
def test_nearest_neighbours_both_paths_match_a_full_distance_matrix(monkeypatch, kd_pairs):
    """From KD_PAIRS pairs a cloud the indices come from scipy's KD-tree (brute force took 131 s for 200,000 points
    against 100,000, an independent check): both paths give numpy's full-matrix nearest, batched (one target cloud
    broadcast), squared, in float32, and gradients through the distances."""
    from graspkit.objects import distance

    monkeypatch.setattr(distance, "KD_PAIRS", kd_pairs)
    rng = np.random.default_rng(3)
    q, t = rng.normal(size=(2, 700, 3)) + 5.0, rng.normal(size=(900, 3)) + 5.0
    full = np.linalg.norm(q[:, :, None] - t[None, None], axis=-1)                    # (2, 700, 900)
    qt = torch.tensor(q, requires_grad=True)
    d, i = nearest_neighbours(qt, torch.tensor(t)[None].expand(2, -1, -1))
    np.testing.assert_array_equal(i.numpy(), full.argmin(-1))
    np.testing.assert_allclose(d.detach().numpy(), full.min(-1), atol=1e-12)
    d.sum().backward()
    want = (q - t[full.argmin(-1)]) / full.min(-1)[..., None]                      # d|q - t|/dq
    np.testing.assert_allclose(qt.grad.numpy(), want, atol=1e-9)
    q32, t32 = q[0].astype(np.float32), t.astype(np.float32)                       # the truth on the rounded points
    full32 = np.linalg.norm(q32.astype(np.float64)[:, None] - t32.astype(np.float64)[None], axis=-1)
    d2, i2 = nearest_neighbours(torch.tensor(q32), torch.tensor(t32), squared=True)
    assert d2.dtype == torch.float32 and d2.shape == (700,)
    np.testing.assert_array_equal(i2.numpy(), full32.argmin(-1))
    np.testing.assert_allclose(d2.numpy(), full32.min(-1) ** 2, rtol=1e-5, atol=1e-9)


def test_nearest_neighbours_of_a_large_call_take_the_tree_not_the_distance_matrix(monkeypatch):
    """At the default threshold a call of 12,000 x 12,000 points (above KD_PAIRS) makes no distance matrix; its
    answers on 300 of the queries are numpy's full-matrix nearest."""
    from graspkit.objects import distance

    assert 12_000 ** 2 >= distance.KD_PAIRS
    rng = np.random.default_rng(4)
    q, t = rng.uniform(size=(12_000, 3)), rng.uniform(size=(12_000, 3))

    def no_cdist(*a, **k):
        raise AssertionError("a distance matrix was built")

    monkeypatch.setattr(torch, "cdist", no_cdist)
    d, i = nearest_neighbours(torch.tensor(q), torch.tensor(t))
    some = rng.choice(len(q), 300, replace=False)
    full = np.linalg.norm(q[some, None] - t[None], axis=-1)
    np.testing.assert_array_equal(i.numpy()[some], full.argmin(-1))
    np.testing.assert_allclose(d.numpy()[some], full.min(-1), atol=1e-12)


def test_nearest_neighbours_and_bps_far_from_the_origin_match_kdtree():
    """Basis points 1 km from the origin (world coordinates), each with two candidate points 1 mm away that differ
    by 0.2 µm: the nearer one is found, as by a k-d tree (cdist's |a|² + |b|² - 2ab rounds at ~1e-9 m² there)."""
    rng = np.random.default_rng(0)
    basis = rng.normal(size=(200, 3)) * 0.01 + np.array([1000.0, -700.0, 20.0])
    u, w = (x / np.linalg.norm(x, axis=1, keepdims=True) for x in rng.normal(size=(2, 200, 3)))
    cloud = np.concatenate([basis + 1e-3 * u, basis + (1e-3 - 2e-7) * w])
    dist, delta = bps_encode(torch.tensor(cloud), torch.tensor(basis), return_deltas=True)
    ref, idx = cKDTree(cloud).query(basis)
    assert (idx >= 200).all()                                   # the k-d tree's answer: always the nearer point
    np.testing.assert_allclose(dist.numpy(), ref, rtol=0, atol=1e-12)
    np.testing.assert_allclose((torch.tensor(basis) + delta).numpy(), cloud[idx], rtol=0, atol=1e-12)
    with pytest.raises(ValueError, match=r"query: expected points of shape"):
        nearest_neighbours(torch.zeros(2, 2, 5, 3), torch.zeros(4, 3))
    mug = make_object("mug")
    with pytest.raises(ValueError, match="mesh: face indices must be integers"):
        signed_distance(np.zeros((1, 3)), (mug.vertices, mug.faces + 0.5))


@pytest.mark.parametrize("name", TEST_OBJECTS)
def test_point_mesh_distance_is_exact(name):
    mesh = make_object(name)
    pts = _box_points(mesh, 150, seed=1, pad=0.05)
    res = point_mesh_distance(pts, mesh)
    np.testing.assert_allclose(res.distance.numpy(), _brute_force_distance(mesh, pts), atol=1e-12)
    # the closest point lies on the reported face (trimesh's projection is only ~1e-6 m precise on slivers)
    tri = mesh.triangles[res.face.numpy()]
    on = trimesh.triangles.closest_point(tri, res.closest.numpy())
    np.testing.assert_allclose(on, res.closest.numpy(), atol=1e-5)
    torch.testing.assert_close(res.distance, torch.linalg.vector_norm(torch.tensor(pts) - res.closest, dim=-1))


def test_point_mesh_distance_ignores_vertices_no_face_uses():
    """A mesh given as all of a body's vertices and only some of its faces (the faces near an object): the vertices
    no face uses lie nearer the points than any kept face, and must not bound the search (they once emptied it)."""
    mesh = make_object("mug")
    stray = _box_points(mesh, 400, seed=3, pad=0.0)                     # unused vertices amid the points
    verts = np.concatenate([mesh.vertices, stray])
    keep = np.asarray(mesh.faces)[: len(mesh.faces) // 3]               # a third of the faces
    pts = _box_points(mesh, 120, seed=4, pad=0.03)
    res = point_mesh_distance(pts, (torch.tensor(verts), torch.tensor(keep)))
    want = _brute_force_distance(trimesh.Trimesh(verts, keep, process=False), pts)
    np.testing.assert_allclose(res.distance.numpy(), want, atol=1e-12)


def test_point_mesh_distance_grouped_in_cells_is_exact_on_a_grid():
    """An SDF-style lattice around a mesh (several cells of the search): every node's distance equals the brute force
    over all (point, face) pairs, and the reported face is the nearest."""
    from graspkit.objects.distance import _cells

    mesh = make_object("mug")
    lo, hi = mesh.bounds
    axes = [np.linspace(a - 0.04, b + 0.04, 13) for a, b in zip(lo, hi)]
    pts = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
    assert len(_cells(pts)[1]) - 1 >= 4
    res = point_mesh_distance(pts, mesh)
    want = _brute_force_distance(mesh, pts)
    np.testing.assert_allclose(res.distance.numpy(), want, atol=1e-12)
    on_face = trimesh.triangles.closest_point(mesh.triangles[res.face.numpy()], pts)
    np.testing.assert_allclose(np.linalg.norm(pts - on_face, axis=1), want, atol=1e-9)


def test_search_cells_stay_few_for_points_on_a_plane_or_a_line():
    """A figure's slice (points on a plane) or a line would make thousands of near-empty cells from the box volume; the
    cells grow until there are at most 2N/512, and the slice's distances stay the brute force's."""
    from graspkit.objects.distance import CELL_POINTS, _cells

    x, y = np.meshgrid(np.linspace(-0.2, 0.2, 150), np.linspace(-0.2, 0.2, 150))
    plane = np.stack([x.ravel(), y.ravel(), np.full(x.size, 0.05)], 1)
    line = np.repeat(np.linspace(-1.0, 1.0, 4000)[:, None], 3, 1)
    for pts in (plane, line, plane[:1]):
        order, starts = _cells(pts)
        assert 1 <= len(starts) - 1 <= max(1, 2 * len(pts) // CELL_POINTS)
        assert np.array_equal(np.sort(order), np.arange(len(pts))) and starts[0] == 0 and starts[-1] == len(pts)
    mesh = make_object("camera")
    lo, hi = mesh.bounds
    a, b = np.meshgrid(np.linspace(lo[0] - 0.03, hi[0] + 0.03, 40), np.linspace(lo[1] - 0.03, hi[1] + 0.03, 40))
    cut = np.stack([a.ravel(), b.ravel(), np.full(a.size, (lo[2] + hi[2]) / 2)], 1)   # a slice through the middle
    np.testing.assert_allclose(point_mesh_distance(cut, mesh).distance.numpy(), _brute_force_distance(mesh, cut),
                               atol=1e-12)


def test_point_mesh_distance_batched_vertices_and_points():
    mesh = make_object("can")
    poses = [sample_object_pose(s) for s in range(3)]
    verts = torch.tensor(np.stack([apply_pose(p, mesh.vertices) for p in poses]))
    pts = torch.tensor(np.stack([apply_pose(p, _box_points(mesh, 200, seed=s)) for s, p in enumerate(poses)]))
    batched = point_mesh_distance(pts, (verts, mesh.faces))
    for b in range(3):
        single = point_mesh_distance(pts[b], (verts[b], mesh.faces))
        torch.testing.assert_close(batched.distance[b], single.distance)
        # rigid motion of both leaves distances unchanged
        local = point_mesh_distance(apply_pose(poses[b].inverse(), pts[b]), mesh).distance
        torch.testing.assert_close(single.distance, local, atol=1e-12, rtol=0)


# ---------------------------------------------------------------------------------------------- signed distance

@pytest.mark.parametrize("name", ALL)
def test_signed_distance_agrees_with_trimesh(name):
    mesh = make_object(name)
    pts = _box_points(mesh, 5000, seed=0)
    sd = signed_distance(pts, mesh).numpy()
    inside = mesh.contains(pts)
    assert ((sd < 0) == inside).mean() >= 0.995
    # trimesh's closest-point search is approximate from above: ours is never larger and within 1 mm
    unsigned = trimesh.proximity.closest_point(mesh, pts)[1]
    assert np.all(np.abs(sd) <= unsigned + 1e-9)
    assert np.abs(np.abs(sd) - unsigned).max() <= 1e-3


@pytest.mark.parametrize("name", ["mug", "pitcher", "binoculars"])
def test_winding_number_agrees_with_signed_distance(name):
    mesh = make_object(name)
    pts = _box_points(mesh, 1500, seed=3)
    w = winding_number(pts, mesh).numpy()
    sd = signed_distance(pts, mesh).numpy()
    assert np.all(np.abs(w - np.round(w)) < 1e-6) or np.abs(sd).min() < 1e-6  # integer away from the surface
    np.testing.assert_array_equal(w > 0.5, sd < 0)


def _fanned_spike(k: int = 20) -> trimesh.Trimesh:
    """A closed 10 cm spike (apex at the origin, base triangle at x = 0.1 m) whose one side face is split into a fan
    of k thin triangles at the apex: the apex's incident faces are mostly that one plane."""
    tip, b1, b2, b3 = np.zeros(3), np.array([1, .1, 0.]), np.array([1, -.1, 0.]), np.array([1, 0, .05])
    fan = [b1 + (b3 - b1) * i / k for i in range(k + 1)]
    v = np.array([tip, b2] + fan) * 0.1
    f = [[0, 1, 2], [0, 2 + k, 1]] + [[0, 3 + i, 2 + i] for i in range(k)] + [[1, 2 + i, 3 + i] for i in range(k)]
    m = trimesh.Trimesh(v, f, process=False)
    m.fix_normals()
    return m


def test_signed_distance_sign_near_a_vertex_with_a_fanned_face():
    """The sign of a point closest to a vertex comes from the angle-weighted pseudo-normal (Baerentzen & Aanaes): a
    face split into 20 slivers must weigh as one. Points behind the apex and off to the side are outside by
    trimesh's containment and the winding number, so their signed distance is positive."""
    m = _fanned_spike()
    assert m.is_watertight and m.is_winding_consistent and m.volume > 0
    pts = np.array([-0.002, -0.005, 0.0]) + np.random.default_rng(0).normal(scale=5e-4, size=(200, 3))
    assert not m.contains(pts).any()
    assert (winding_number(pts, m).numpy() < 0.5).all()
    sd = signed_distance(pts, m).numpy()
    assert (sd > 0).all()
    np.testing.assert_allclose(np.abs(sd), trimesh.proximity.closest_point(m, pts)[1], atol=1e-9)


def test_signed_distance_of_sphere_is_analytic():
    r = 0.05
    sphere = _sphere(r, subdivisions=5)
    pts = np.random.default_rng(0).uniform(-0.08, 0.08, size=(3000, 3))
    sd = signed_distance(pts, sphere).numpy()
    # the icosphere lies inside the true sphere by at most the sagitta of its faces (< 0.1 mm here)
    np.testing.assert_allclose(sd, np.linalg.norm(pts, axis=1) - r, atol=1e-4)


@pytest.mark.parametrize("name", ["mug", "camera", "wine_glass"])
def test_sdf_grid_matches_exact_away_from_surface(name):
    mesh = make_object(name)
    grid = SDFGrid.from_mesh(mesh, resolution=48)
    cell = grid.cell.max().item()
    pts = _box_points(mesh, 5000, seed=2)
    exact = signed_distance(pts, mesh).numpy()
    approx = grid(torch.tensor(pts)).numpy()
    far = np.abs(exact) > cell
    assert far.mean() > 0.5
    assert ((approx < 0) == (exact < 0))[far].mean() >= 0.995
    assert np.abs(approx - exact)[far].max() < cell
    assert np.median(np.abs(approx - exact)) < 0.1 * cell
    # outside the grid box the lookup is an upper bound of the true distance
    outer = mesh.bounds[1] + np.array([[0.1, 0.0, 0.0], [0.2, 0.1, 0.3]])
    assert np.all(grid(torch.tensor(outer)).numpy() >= signed_distance(outer, mesh).numpy() - 1e-6)


def test_object_sdf_grid_is_cached_and_movable():
    grid = object_sdf_grid("can", 16)
    assert object_sdf_grid("can", 16) is grid
    torch.testing.assert_close(grid.values, SDFGrid.from_mesh(make_object("can"), 16).values)
    g64 = grid.to(dtype=torch.float64)
    assert g64.values.dtype == torch.float64 and grid.values.dtype == torch.float32
    x = torch.tensor([[0.0, 0.0, 0.0], [0.0, 0.0, 0.2]], dtype=torch.float64)
    torch.testing.assert_close(g64(x), grid(x.float()).double(), atol=1e-6, rtol=0)
    # numpy and list queries of any (..., 3) shape, one point included, as tensors are taken
    assert float(g64(np.array([0.0, 0.0, 0.2]))) == float(g64(x)[1])
    torch.testing.assert_close(g64([[0.0, 0.0, 0.0], [0.0, 0.0, 0.2]]), g64(x))
    with pytest.raises(ValueError, match="points: expected finite"):
        g64(np.array([0.0, np.nan, 0.0]))


def test_sdf_grid_gradient_is_unit_and_points_away_from_surface():
    mesh = make_object("can")
    grid = SDFGrid.from_mesh(mesh, resolution=48, dtype=torch.float64)
    pts = _box_points(mesh, 2000, seed=4)
    res = point_mesh_distance(pts, mesh)
    keep = (res.distance > 3 * grid.cell.max()).numpy()
    x = torch.tensor(pts[keep], requires_grad=True)
    grid(x).sum().backward()
    sd = signed_distance(pts[keep], mesh)
    direction = (x.detach() - res.closest[keep]) / res.distance[keep, None] * torch.sign(sd)[:, None]
    cos = (x.grad * direction).sum(-1) / x.grad.norm(dim=-1)
    assert (cos > 0.95).float().mean() > 0.95
    assert ((x.grad.norm(dim=-1) - 1).abs() < 0.1).float().mean() > 0.95


# ---------------------------------------------------------------------------------------------- gradients

def _generic_points(mesh: trimesh.Trimesh, n: int, seed: int) -> torch.Tensor:
    return torch.tensor(_box_points(mesh, n, seed, pad=0.01), dtype=torch.float64)


def test_gradcheck_point_mesh_and_signed_distance():
    mesh = make_object("toothpaste")
    pts = _generic_points(mesh, 12, 0).requires_grad_(True)
    assert torch.autograd.gradcheck(lambda p: point_mesh_distance(p, mesh).distance, (pts,))
    assert torch.autograd.gradcheck(lambda p: signed_distance(p, mesh), (pts,))
    verts = torch.tensor(mesh.vertices, requires_grad=True)
    assert torch.autograd.gradcheck(lambda v: point_mesh_distance(pts.detach(), (v, mesh.faces)).distance, (verts,))


def test_gradcheck_nearest_neighbours_and_bps():
    rng = np.random.default_rng(0)
    q = torch.tensor(rng.normal(size=(2, 10, 3)), requires_grad=True)
    t = torch.tensor(rng.normal(size=(2, 15, 3)), requires_grad=True)
    assert torch.autograd.gradcheck(lambda a, b: nearest_neighbours(a, b)[0], (q, t))
    assert torch.autograd.gradcheck(lambda a, b: nearest_neighbours(a, b, squared=True)[0], (q, t))
    basis = bps_basis(32, 1.0, seed=0).double()
    assert torch.autograd.gradcheck(lambda p: bps_encode(p, basis, return_deltas=True), (t,))


def test_gradcheck_sdf_grid():
    grid = SDFGrid.from_mesh(make_object("apple"), resolution=24, dtype=torch.float64)
    pts = _generic_points(make_object("apple"), 10, 5)
    pts = torch.cat([pts, pts[:2] + 0.2]).requires_grad_(True)  # two queries outside the grid box
    assert torch.autograd.gradcheck(grid, (pts,))


def test_distance_gradient_is_unit_direction_to_closest_point():
    mesh = make_object("mug")
    x = _generic_points(mesh, 300, 6).requires_grad_(True)
    res = point_mesh_distance(x, mesh)
    res.distance.sum().backward()
    expected = (x.detach() - res.closest.detach()) / res.distance.detach()[:, None]
    torch.testing.assert_close(x.grad, expected, atol=1e-9, rtol=0)


# ---------------------------------------------------------------------------------------------- contact, attention

def test_object_contact_measures_to_the_body_surface_not_its_vertices():
    """SAGA's C_O: an object point within 1 cm of the body's surface; on a coarse body (a 20 cm box, its 8 vertices
    14-17 cm from these points) the nearest vertex would miss every contact trimesh finds."""
    box = trimesh.creation.box(extents=(0.2, 0.2, 0.2))
    pts = np.array([[0.0, 0.0, 0.105], [0.0, 0.0, 0.115], [0.105, 0.02, -0.03], [0.02, -0.108, 0.0]])
    truth = trimesh.proximity.closest_point(box, pts)[1] <= 0.01          # 5, 15, 5 and 8 mm from a face
    assert truth.tolist() == [True, False, True, True]
    body = (torch.as_tensor(box.vertices), torch.as_tensor(box.faces))
    assert object_contact(torch.as_tensor(pts), body).bool().tolist() == truth.tolist()
    assert object_contact(torch.as_tensor(pts), box).bool().tolist() == truth.tolist()


def test_surface_points_are_uniform_in_a_triangle():
    """Area-uniform sampling (Osada's square-root warp): on the right triangle (0,0)-(1,0)-(0,1) x has the density
    2 (1 - x) (Kolmogorov-Smirnov against its CDF) and the points' mean is the centroid (1/3, 1/3)."""
    from scipy import stats

    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0.0, 0.0, 1e-6]], float)       # closed by three tiny faces
    mesh = trimesh.Trimesh(v, [[0, 2, 1], [0, 1, 3], [1, 2, 3], [2, 0, 3]], process=False)
    p, _ = sample_surface(mesh, 20000, seed=0)
    assert stats.kstest(p[:, 0], lambda s: 1 - (1 - np.clip(s, 0, 1)) ** 2).pvalue > 1e-3
    np.testing.assert_allclose(p[:, :2].mean(0), [1 / 3, 1 / 3], atol=0.01)


def test_marker_and_object_contact_thresholds():
    box = make_object("cracker_box")  # faces at y = +-0.03
    offsets = np.array([0.0, 0.005, 0.019, 0.021, 0.05])
    markers = torch.tensor([[0.0, 0.03 + o, 0.0] for o in offsets])
    np.testing.assert_array_equal(marker_contact(markers, box).numpy(), [1, 1, 1, 0, 0])
    np.testing.assert_array_equal(marker_contact(markers, box, threshold=0.004).numpy(), [1, 0, 0, 0, 0])
    # object points against a body surface (a sphere of radius 5 cm) and against its vertices only
    body = _sphere(0.05, subdivisions=4)
    pts = torch.tensor([[0.0, 0.0, 0.05 + o] for o in offsets])
    np.testing.assert_array_equal(object_contact(pts, body).numpy(), [1, 1, 0, 0, 0])
    np.testing.assert_array_equal(object_contact(pts, torch.tensor(body.vertices)).numpy(), [1, 1, 0, 0, 0])
    batched = object_contact(pts[None].expand(2, -1, -1), torch.tensor(body.vertices)[None].expand(2, -1, -1))
    assert batched.shape == (2, 5)
    for bad in (float("nan"), -0.01, float("inf"), "1cm"):
        with pytest.raises(ValueError, match="threshold: expected a finite distance"):
            marker_contact(markers, box, threshold=bad)
        with pytest.raises(ValueError, match="threshold: expected a finite distance"):
            object_contact(pts, body, threshold=bad)


def test_interaction_attention_is_goal_eq1():
    d = torch.tensor([0.0, 0.1, 0.2, 1.0], dtype=torch.float64)
    assert IAA_WEIGHT == 5.0
    np.testing.assert_allclose(interaction_attention(d).numpy(), np.exp(-5.0 * d.numpy()))
    box = make_object("cracker_box")
    verts = torch.tensor([[0.0, 0.03, 0.0], [0.0, 0.23, 0.0], [0.0, 0.0, 0.0]], dtype=torch.float64)
    att = body_object_attention(verts, box)
    np.testing.assert_allclose(att.numpy(), [1.0, np.exp(-1.0), np.exp(-5 * 0.03)], atol=1e-9)
    for w in (0.0, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="w: GOAL's weight"):
            interaction_attention(d, w=w)
    with pytest.raises(ValueError, match="distance: expected distances >= 0"):       # a signed distance inside
        interaction_attention(torch.tensor([0.1, -0.01]))
    with pytest.raises(TypeError, match="distance: expected a torch tensor"):
        interaction_attention(d.numpy())


# ---------------------------------------------------------------------------------------------- interpenetration

def _lens_volume(r1: float, r2: float, d: float) -> float:
    """Volume of the intersection of two balls (radii r1, r2, centres d apart), |r1 - r2| < d < r1 + r2."""
    return np.pi * (r1 + r2 - d) ** 2 * (d * d + 2 * d * (r1 + r2) - 3 * (r1 - r2) ** 2) / (12 * d)


@pytest.mark.parametrize("r1, r2, d", [(0.05, 0.05, 0.07), (0.06, 0.03, 0.075), (0.04, 0.05, 0.06),
                                       (0.05, 0.04, 0.03)])
def test_sphere_lens_volume_and_depth(r1, r2, d):
    body = _sphere(r1)
    # put the object along a vertex direction of the body, so a body vertex sits at the deepest point
    v = body.vertices[np.argmax(body.vertices @ np.array([0.3, 0.5, 0.8]))]
    obj = _sphere(r2, centre=v / np.linalg.norm(v) * d)
    pen = interpenetration(body, obj)
    assert abs(pen.volume_cm3 - _lens_volume(r1, r2, d) * 1e6) <= 0.05 * _lens_volume(r1, r2, d) * 1e6
    depth = r2 - abs(d - r1)  # deepest body point: on the axis, |d - r1| from the object's centre
    assert abs(pen.depth_cm - depth * 100) <= 0.1  # 1 mm
    # against the mesh-exact intersection (manifold3d boolean), the ray casting is within 0.2 %
    exact = body.intersection(obj, engine="manifold").volume
    assert abs(intersection_volume(body, obj) - exact) <= 2e-3 * exact


@pytest.mark.parametrize("yaw_deg, slab_mm, one_ray_off, refined_tol", [(45, 3.0, 0.05, 0.01), (0, 1.4, 0.2, 1e-9),
                                                                         (0, 0.8, 0.2, 1e-9)])
def test_shallow_sideways_overlap_is_refined_along_vertical_walls(yaw_deg, slab_mm, one_ray_off, refined_tol):
    """Two 10 cm cubes overlapping by a slab through their vertical faces (exact volume 100 t cm^3 for t cm):
    one ray per 1 mm column rounds the slab to whole columns, the refined cells resolve it."""
    box = trimesh.creation.box((0.1, 0.1, 0.1))
    R = trimesh.transformations.rotation_matrix(np.radians(yaw_deg), [0, 0, 1])[:3, :3]
    a, b = box.vertices @ R.T, (box.vertices + [0.1 - slab_mm / 1000, 0.0, 0.0]) @ R.T
    exact = 100 * slab_mm / 10
    one = interpenetration((a, box.faces), (b, box.faces), refine=1).volume_cm3
    refined = interpenetration((a, box.faces), (b, box.faces)).volume_cm3
    assert abs(one / exact - 1) > one_ray_off
    assert abs(refined / exact - 1) < refined_tol
    with pytest.raises(ValueError, match="refine"):
        interpenetration((a, box.faces), (b, box.faces), refine=0)


def test_penetration_edge_cases_and_inputs():
    body = _sphere(0.05)
    far = _sphere(0.05, centre=(0.2, 0.0, 0.0))
    assert interpenetration(body, far).volume_cm3 == 0.0 and interpenetration(body, far).depth_cm == 0.0
    small = _sphere(0.02, centre=(0.01, 0.0, 0.0))  # wholly inside: the volume is the small one's
    assert abs(intersection_volume(body, small) - small.volume) <= 2e-3 * small.volume
    assert abs(intersection_volume(small, body) - small.volume) <= 2e-3 * small.volume
    # (vertices, faces) arrays and torch tensors work like a Trimesh
    mug = apply_pose(sample_object_pose(0, height_range=(0.0, 0.0), distance_range=(0.0, 0.0)), make_object("mug"))
    hand = _sphere(0.03, centre=mug.vertices[np.argmax(mug.vertices[:, 0])])
    a = interpenetration(hand, mug)
    b = interpenetration((torch.tensor(hand.vertices), torch.tensor(hand.faces)), (mug.vertices, mug.faces))
    assert a == b and a.volume_cm3 > 0 and a.depth_cm > 0
    assert abs(penetration_depth(hand, mug) * 100 - a.depth_cm) < 1e-12


def _box(size, centre) -> trimesh.Trimesh:
    b = trimesh.creation.box(size)
    b.apply_translation(centre)
    return b


def test_a_self_overlapping_body_counts_its_overlap_once():
    """Two boxes 10 cm wide, overlapping by 5 cm in x, as one mesh (a body pressed into itself): a 4 cm box in the
    overlap lies inside the body, all 64 cm³ of it (the parity rule would see it outside: two surfaces crossed)."""
    two = trimesh.util.concatenate([_box((0.1, 0.1, 0.1), (0, 0, 0)), _box((0.1, 0.1, 0.1), (0.05, 0, 0))])
    inner = _box((0.04, 0.04, 0.04), (0.025, 0, 0))
    assert interpenetration(two, inner).volume_cm3 == pytest.approx(64.0, rel=1e-6)
    edge = _box((0.04, 0.04, 0.04), (0.11, 0, 0))            # x 9-13 cm: 1 cm of it inside the second box
    assert interpenetration(two, edge).volume_cm3 == pytest.approx(16.0, rel=1e-6)


def test_a_body_with_holes_is_measured_away_from_them():
    """A body box missing its top face (a hole over every column) measures nothing; missing a side face (no vertical
    ray passes through it) it measures what the closed box does. The object must stay closed."""
    closed = _box((0.1, 0.1, 0.1), (0, 0, 0))
    obj = _box((0.04, 0.04, 0.04), (0.05, 0.0, -0.03))       # 2 x 4 x 4 cm inside the body: 32 cm³
    side = closed.faces[~np.isclose(closed.triangles_center[:, 0], 0.05)]      # the +x wall removed
    top = closed.faces[~np.isclose(closed.triangles_center[:, 2], 0.05)]       # the lid removed
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")                        # a closed body: no warning
        assert interpenetration(closed, obj).volume_cm3 == pytest.approx(32.0, rel=1e-6)
    with pytest.warns(UserWarning, match=r"body mesh is not closed \(4 edges border only one face\)"):
        assert interpenetration((closed.vertices, side), obj).volume_cm3 == pytest.approx(32.0, rel=1e-6)
    with pytest.warns(UserWarning, match="can be under-counted"):   # the user is told the 32 cm³ read as 0
        assert interpenetration((closed.vertices, top), obj).volume_cm3 == 0.0
    corner = _box((0.04, 0.04, 0.04), (0.05, 0.05, -0.05))  # around the body's corner vertex: 8 cm³, 2 cm deep
    for faces in (closed.faces, side):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")                   # the open one's warning, checked above
            pen = interpenetration((closed.vertices, faces), corner)
        assert pen.volume_cm3 == pytest.approx(8.0, rel=1e-6) and pen.depth_cm == pytest.approx(2.0, abs=1e-9)


# ---------------------------------------------------------------------------------------------- errors

def test_non_watertight_or_inverted_mesh_is_rejected():
    bad = _open_mesh()
    with pytest.raises(ValueError, match="mesh: .*watertight"):
        signed_distance(np.zeros((1, 3)), bad)
    flipped = trimesh.Trimesh(bad.vertices, np.vstack([bad.faces[:1, ::-1], bad.faces[1:]]), process=False)
    with pytest.raises(ValueError, match="body: .*inconsistent winding"):
        interpenetration(flipped, _sphere(0.05))            # a body may have holes, never inconsistent winding
    with pytest.raises(ValueError, match="obj: .*watertight"):
        interpenetration(_sphere(0.05), bad)
    with pytest.raises(ValueError, match="mesh: .*watertight"):
        SDFGrid.from_mesh(bad)
    s = _sphere(0.05)
    inverted = trimesh.Trimesh(s.vertices, s.faces[:, ::-1], process=False)
    with pytest.raises(ValueError, match="mesh: .*inwards"):
        signed_distance(np.zeros((1, 3)), inverted)


def test_bad_point_sets_are_rejected_with_the_argument_name():
    mesh = make_object("can")
    with pytest.raises(ValueError, match="points: empty"):
        signed_distance(np.zeros((0, 3)), mesh)
    with pytest.raises(ValueError, match="points: contains NaN"):
        point_mesh_distance(np.array([[0.0, np.nan, 0.0]]), mesh)
    with pytest.raises(ValueError, match="query: .*shape"):
        nearest_neighbours(np.zeros((4, 2)), np.zeros((4, 3)))
    with pytest.raises(ValueError, match="target: empty"):
        nearest_neighbours(np.zeros((4, 3)), np.zeros((0, 3)))
    with pytest.raises(ValueError, match="markers: contains NaN"):
        marker_contact(torch.tensor([[np.inf, 0.0, 0.0]]), mesh)
    with pytest.raises(ValueError, match="points: contains NaN"):
        bps_encode(torch.full((5, 3), float("nan")), bps_basis(8))
    with pytest.raises(ValueError, match="mesh: face indices"):
        point_mesh_distance(np.zeros((1, 3)), (mesh.vertices, mesh.faces + 10_000))


def test_meshes_in_millimetres_and_non_numeric_inputs_are_refused_by_name():
    box = _box((0.1, 0.1, 0.1), (0, 0, 0))
    mm = box.copy()
    mm.apply_scale(1000.0)                                    # the same box in millimetres: 1000 cm^3 of "overlap"
    assert interpenetration(box, box.copy()).volume_cm3 == pytest.approx(1000.0, rel=1e-6)
    with pytest.raises(ValueError, match=r"obj: largest side 100, expected .* metres.*apply_scale\(0.001\)"):
        interpenetration(box, mm)
    with pytest.raises(ValueError, match="body: largest side 100"):
        interpenetration(mm, box)
    with pytest.raises(ValueError, match="mesh: largest side 100"):
        SDFGrid.from_mesh(mm)
    with pytest.raises(ValueError, match="points: expected points of numbers"):
        signed_distance("abc", box)
    with pytest.raises(ValueError, match="points: expected an array of numbers"):
        SDFGrid.from_mesh(box, resolution=8)("abc")
    with pytest.raises(ValueError, match="spacing: expected a positive grid spacing"):
        interpenetration(box, box.copy(), spacing="1mm")


def test_signed_distance_to_point_cloud_saga_eq7():
    r = 0.05
    sphere = _sphere(r, subdivisions=5)
    cloud = torch.tensor(sphere.vertices)
    normals = cloud / cloud.norm(dim=1, keepdim=True)
    pts = np.random.default_rng(1).uniform(-0.08, 0.08, size=(3000, 3))
    truth = np.linalg.norm(pts, axis=1) - r
    sd = signed_distance_to_points(torch.tensor(pts), cloud, normals).numpy()
    clear = np.abs(truth) > 1e-3
    np.testing.assert_array_equal(np.sign(sd[clear]), np.sign(truth[clear]))
    # nearest-vertex distance overestimates the surface distance by at most the vertex spacing (~2 mm)
    gap = np.abs(sd) - np.abs(truth)
    assert gap.min() > -1e-4 and gap.max() < 2.5e-3
    batched = signed_distance_to_points(torch.tensor(pts)[None].expand(2, -1, -1), cloud, normals)
    torch.testing.assert_close(batched[1], torch.tensor(sd))


@pytest.mark.parametrize("tri", [
    [[0, 0, 0], [0, 0, 0], [1, 0, 0]], [[1, 0, 0], [0, 0, 0], [0, 0, 0]], [[0, 0, 0], [0.3, 0, 0], [1, 0, 0]],
    [[0.2, 0.1, 0], [0.2, 0.1, 0], [0.2, 0.1, 0]],
])
def test_closest_point_on_a_triangle_without_area_is_on_its_nearest_edge(tri):
    from graspkit.objects.distance import closest_point_on_triangle

    a, b, c = torch.tensor(tri, dtype=torch.float64)
    p = torch.as_tensor(np.random.default_rng(3).normal(size=(500, 3)))
    got, _ = closest_point_on_triangle(p, a, b, c)
    s = torch.linspace(0, 1, 20001, dtype=torch.float64)[:, None]                # dense points along the three edges
    edge_pts = torch.cat([u + (v - u) * s for u, v in ((a, b), (b, c), (c, a))])
    truth = torch.cdist(p, edge_pts).min(1).values
    torch.testing.assert_close((p - got).norm(dim=-1), truth, atol=1e-4, rtol=0)


def test_closest_point_on_sliver_triangles_in_float32_matches_float64():
    """Triangles a few micro- to nanometres wide per metre (near-collinear corners): float32 gives the float64
    distance of the same float32 inputs to 1e-5 m (the regions' products lost the area to rounding: 1.29 m for 0.63)."""
    from graspkit.objects.distance import closest_point_on_triangle

    g = torch.Generator().manual_seed(0)
    N = 5000
    a, b, p = (torch.randn(N, 3, generator=g, dtype=torch.float64) for _ in range(3))
    t = torch.rand(N, 1, generator=g, dtype=torch.float64)
    width = 10 ** (-4 - 5 * torch.rand(N, 1, generator=g, dtype=torch.float64))
    c = a + t * (b - a) + torch.randn(N, 3, generator=g, dtype=torch.float64) * width
    a, b, c, p = (x.float() for x in (a, b, c, p))
    q32, _ = closest_point_on_triangle(p, a, b, c)
    q64, _ = closest_point_on_triangle(*(x.double() for x in (p, a, b, c)))
    d32, d64 = (q32.double() - p.double()).norm(dim=-1), (q64 - p.double()).norm(dim=-1)
    assert float((d32 - d64).abs().max()) < 1e-5


def test_walls_on_both_sides_of_the_overlap_box_are_exact():
    """Two 10 cm cubes offset by (9.57, 1.37, 2.1) cm overlap in a 4.3 x 86.3 x 79 mm box (analytic volume) bounded
    by faces of the cubes on both sides: the refined cells tile the box, so its far walls lie on cell borders as its
    near ones do (the first rule, square 1 mm cells from the near corner, read 1.2 % low)."""
    box = trimesh.creation.box((0.1, 0.1, 0.1))
    a, b = box.vertices, box.vertices + [0.0957, 0.0137, 0.021]
    exact = 4.3 * 86.3 * 79.0 / 1000                                       # cm^3
    assert abs(interpenetration((a, box.faces), (b, box.faces)).volume_cm3 / exact - 1) < 1e-9


def test_refined_slabs_through_yawed_walls_over_a_sweep():
    """Slabs 0.5-3 mm thick through the faces of two 10 cm cubes (offset 3 mm sideways) yawed 10-77 degrees (42 cases,
    analytic volumes): the refined cells average 0.15 % off, 1.6 % at worst (square cells from the near corner:
    0.79 and 10 %; one ray per column: 3.4 and 42 %); a 45-degree wall against the 0.25 mm rays can alias
    (docs/objects.md)."""
    box = trimesh.creation.box((0.1, 0.1, 0.1))
    errs, ones = [], []
    for yaw in (10, 22.5, 30, 45, 60, 77):
        R = trimesh.transformations.rotation_matrix(np.radians(yaw), [0, 0, 1])[:3, :3]
        for slab in (0.5, 0.8, 1.0, 1.4, 2.0, 3.0, 4.0):
            a, b = box.vertices @ R.T, (box.vertices + [0.1 - slab / 1000, 0.003, 0.0]) @ R.T
            exact = slab * 9.7                                           # cm^3: slab (cm) x 9.7 x 10 cm
            errs.append(interpenetration((a, box.faces), (b, box.faces)).volume_cm3 / exact - 1)
            ones.append(interpenetration((a, box.faces), (b, box.faces), refine=1).volume_cm3 / exact - 1)
    errs, ones = np.abs(errs), np.abs(ones)
    assert errs.mean() < 0.003 and errs.max() < 0.02
    assert ones.mean() > 5 * errs.mean()


def test_point_mesh_distance_is_exact_far_from_the_mesh():
    """Points 1.2-2.5 m from a 10 cm sphere (a body 1-1.5 m from an object at GOAL's start): trimesh's
    point-triangle distance over every (point, face) pair."""
    mesh = trimesh.creation.icosphere(2, 0.1)
    rng = np.random.default_rng(0)
    d = rng.normal(size=(40, 3))
    pts = d / np.linalg.norm(d, axis=1, keepdims=True) * rng.uniform(1.2, 2.5, (40, 1))
    tri = mesh.triangles
    cp = trimesh.triangles.closest_point(np.tile(tri, (len(pts), 1, 1)), np.repeat(pts, len(tri), 0))
    want = np.linalg.norm(np.repeat(pts, len(tri), 0) - cp, axis=1).reshape(len(pts), len(tri)).min(1)
    np.testing.assert_allclose(point_mesh_distance(pts, mesh).distance.numpy(), want, atol=1e-9)


def test_grid_has_resolution_nodes_on_the_longest_side_and_covers_the_padded_box():
    """SDFGrid.from_mesh puts `resolution` nodes along the longest side of the padded box (docstring), with cubic
    cells, and its box covers the mesh's bounds plus the padding."""
    mesh = trimesh.creation.box((0.10, 0.16, 0.30))
    res, pad = 16, 0.02
    grid = SDFGrid.from_mesh(mesh, resolution=res, padding=pad, dtype=torch.float64)
    nz, ny, nx = grid.values.shape
    assert nz == res                                               # z is the longest side: 0.34 m padded
    h = (0.30 + 2 * pad) / (res - 1)
    np.testing.assert_allclose(grid.cell.numpy(), h, rtol=1e-9)    # cubic cells of the longest side's spacing
    lo, hi = mesh.bounds[0] - pad, mesh.bounds[1] + pad
    np.testing.assert_allclose(grid.lower.numpy(), lo, atol=1e-12)
    assert (grid.upper.numpy() >= hi - 1e-9).all()                 # every padded bound inside the grid
    assert (grid.upper.numpy() < hi + h).all()                     # and less than one extra cell beyond it
    for n, ext in ((nx, (hi - lo)[0]), (ny, (hi - lo)[1])):          # the fewest whole cells that span each side
        assert (n - 1) * h >= ext - 1e-9 and (n - 2) * h < ext


def test_a_long_thin_box_inside_a_big_box_has_its_own_volume():
    """A 6 x 1 x 2 cm box wholly inside a 10 cm cube: the intersection is the small box, 12 cm^3 (its overlap box is
    not square, so the ray grid's cells are not square either)."""
    big = trimesh.creation.box(extents=(0.1, 0.1, 0.1))
    small = trimesh.creation.box(extents=(0.06, 0.01, 0.02))
    small.apply_translation((0.01, -0.02, 0.005))
    pen = interpenetration(small, big)
    assert pen.volume_cm3 == pytest.approx(12.0, rel=2e-3)
    assert interpenetration(big, small).volume_cm3 == pytest.approx(12.0, rel=2e-3)


def test_a_turned_cube_inside_a_big_box_has_its_own_volume():
    """A 3 cm cube turned about an oblique axis (no face horizontal or vertical) wholly inside a 12 cm cube: 27 cm^3,
    trimesh's volume of the turned cube."""
    big = trimesh.creation.box(extents=(0.12, 0.12, 0.12))
    cube = trimesh.creation.box(extents=(0.03, 0.03, 0.03))
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec([0.4, -0.7, 0.3]).as_matrix()
    T[:3, 3] = (0.005, 0.01, -0.01)
    cube.apply_transform(T)
    assert cube.volume * 1e6 == pytest.approx(27.0, rel=1e-9)
    assert interpenetration(cube, big).volume_cm3 == pytest.approx(27.0, rel=3e-3)


def test_depth_is_the_deepest_body_vertex_not_an_average():
    """A body tetrahedron poking into a 10 cm cube from above: its vertices 3 cm, 0.5 cm, 0.5 cm inside the top face
    and one 1 cm above it. The depth is the deepest, 3 cm (trimesh's signed distance, positive inside)."""
    obj = trimesh.creation.box(extents=(0.1, 0.1, 0.1))
    pts = np.array([[0.0, 0.0, 0.02], [0.01, 0.0, 0.045], [0.0, 0.01, 0.045], [0.0, 0.0, 0.06]])
    body = trimesh.convex.convex_hull(pts)
    sd = trimesh.proximity.signed_distance(obj, body.vertices)
    assert sd.max() == pytest.approx(0.03, abs=1e-9)
    assert interpenetration(body, obj).depth_cm == pytest.approx(100 * sd.max(), abs=1e-6)


def test_an_ellipsoid_inside_a_big_box_has_its_own_volume_on_a_grid_of_oblong_cells():
    """A flat ellipsoid mesh (semi-axes 3.125, 0.565, 1 cm; its overlap box 62.5 x 11.3 mm does not divide into whole
    1-mm cells, so the cells that tile it are oblong) wholly inside a 10 cm cube: the intersection is the ellipsoid,
    trimesh's volume of the mesh."""
    big = trimesh.creation.box(extents=(0.1, 0.1, 0.1))
    ell = trimesh.creation.icosphere(subdivisions=3)
    ell.apply_scale((0.03125, 0.00565, 0.01))
    ell.apply_translation((0.004, -0.003, 0.002))
    assert interpenetration(ell, big).volume_cm3 == pytest.approx(ell.volume * 1e6, rel=3e-3)


@pytest.mark.parametrize("overlap_mm, tol", [(1.0, 0.02), (3.0, 0.01)])
def test_a_thin_lens_on_the_overlap_boxs_border_is_refined(overlap_mm, tol):
    """Two 3 cm spheres (meshes) overlapping by 1 or 3 mm along x: the lens's bounding-box overlap is 1-3 mm wide, so
    its cells all lie on the overlap box's border, where a column's length changes steeply within a cell (the lens
    thins to nothing at its rim and its tip). Those cells are refined: the volume is within 1-2 % of manifold3d's exact
    intersection (unrefined border cells read 2.5-10 % high)."""
    a = _sphere(0.03)
    b = _sphere(0.03, centre=(0.06 - overlap_mm / 1000, 0.0, 0.0))
    exact = a.intersection(b, engine="manifold").volume
    assert exact > 0
    assert abs(intersection_volume(a, b) / exact - 1) < tol


def test_distance_to_a_point_set_is_the_euclidean_distance_to_the_nearest_point():
    rng = np.random.default_rng(0)
    pts, cloud = rng.uniform(-0.2, 0.2, (50, 3)), rng.uniform(-0.2, 0.2, (200, 3))
    want, _ = cKDTree(cloud).query(pts)
    got = distance_to(torch.tensor(pts), torch.tensor(cloud)).numpy()
    np.testing.assert_allclose(got, want, atol=1e-9)


def test_object_contact_against_a_vertex_cloud_uses_metres_not_squared_metres():
    # one point 5 mm from the nearest cloud point (in contact at 1 cm), one 5 cm away (not: 0.05^2 < 0.01 would say so)
    cloud = torch.tensor([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]], dtype=torch.float64)
    pts = torch.tensor([[0.005, 0.0, 0.0], [0.0, 0.05, 0.0]], dtype=torch.float64)
    assert object_contact(pts, cloud).tolist() == [1.0, 0.0]


@pytest.mark.parametrize("w", [1.0, 2.0, 20.0])
def test_body_object_attention_uses_the_given_weight(w):
    """GOAL Eq. 1, I_w(d) = exp(-w d), with d the exact distance to the mesh (trimesh) and the weight w asked for."""
    box = trimesh.creation.box((0.1, 0.1, 0.1))
    verts = np.array([[0.0, 0.0, 0.15], [0.2, 0.0, 0.0], [0.08, 0.09, 0.0]])
    _, d, _ = trimesh.proximity.closest_point(box, verts)
    got = body_object_attention(torch.tensor(verts), box, w=w).numpy()
    np.testing.assert_allclose(got, np.exp(-w * d), rtol=1e-6)


def test_marker_contact_uses_the_given_threshold():
    box = trimesh.creation.box((0.1, 0.1, 0.1))
    markers = torch.tensor([[0.0, 0.0, 0.08], [0.0, 0.0, 0.09], [0.0, 0.0, 0.1]], dtype=torch.float64)  # 3, 4, 5 cm
    assert marker_contact(markers, box, threshold=0.035).tolist() == [1.0, 0.0, 0.0]
    assert marker_contact(markers, box, threshold=0.045).tolist() == [1.0, 1.0, 0.0]
    assert marker_contact(markers, box).tolist() == [0.0, 0.0, 0.0]     # the 2 cm default


CORNER = {D.VERT_A: 0, D.VERT_B: 1, D.VERT_C: 2}  # region code -> the corner it names
EDGE = {D.EDGE_AB: (0, 1), D.EDGE_BC: (1, 2), D.EDGE_CA: (2, 0)}


def _check_codes(tri: np.ndarray, p: np.ndarray, q: np.ndarray, code: np.ndarray, tol: float = 1e-9) -> None:
    """Each region code names the feature the closest point q lies on: a vertex code -> q is that corner; an edge code
    -> q on that edge's segment; FACE -> q strictly inside the triangle (barycentrics)."""
    for k in range(len(p)):
        c = int(code[k])
        if c in CORNER:
            assert np.linalg.norm(q[k] - tri[CORNER[c]]) < tol, (k, c, p[k], q[k])
        elif c in EDGE:
            u, v = tri[EDGE[c][0]], tri[EDGE[c][1]]
            s = np.clip(np.dot(q[k] - u, v - u) / np.dot(v - u, v - u), 0, 1)
            assert np.linalg.norm(u + s * (v - u) - q[k]) < tol, (k, c, p[k], q[k])
        else:
            assert c == D.FACE
            bary = trimesh.triangles.points_to_barycentric(tri[None], q[k][None])[0]
            assert bary.min() > -tol, (k, bary)


def test_region_codes_name_the_closest_feature_and_points_match_trimesh():
    """closest_point_on_triangle: the closest point equals trimesh's and the region code names the vertex / edge / face
    it lies on (the code picks the pseudo-normal of signed_distance's sign), for points around a triangle in all
    seven Voronoi regions."""
    tri = np.array([[0.0, 0.0, 0.0], [1.0, 0.1, 0.0], [0.3, 0.8, 0.1]])
    rng = np.random.default_rng(0)
    p = rng.uniform(-1.0, 2.0, (4000, 3)) * [1, 1, 0.5]
    q, code = D.closest_point_on_triangle(torch.as_tensor(p), *torch.as_tensor(tri))
    q, code = q.numpy(), code.numpy()
    truth = trimesh.triangles.closest_point(np.repeat(tri[None], len(p), 0), p)
    np.testing.assert_allclose(q, truth, atol=1e-9, rtol=0)
    assert set(code.tolist()) == set(range(7))
    _check_codes(tri, p, q, code)


def test_region_codes_of_a_triangle_without_area_name_the_closest_feature():
    """On a triangle whose corners lie on a line, a point beyond an end gets the code of that end's corner and one
    beside the segment an edge code whose segment holds the closest point (checked geometrically)."""
    tri = np.array([[0.0, 0.0, 0.0], [0.3, 0.0, 0.0], [1.0, 0.0, 0.0]])
    rng = np.random.default_rng(1)
    p = np.concatenate([rng.normal(size=(300, 3)), [[1.5, 0.2, 0.0], [-0.4, 0.1, 0.3], [0.6, 0.5, 0.0]]])
    q, code = D.closest_point_on_triangle(torch.as_tensor(p), *torch.as_tensor(tri))
    q, code = q.numpy(), code.numpy()
    np.testing.assert_allclose(np.linalg.norm(p - q, axis=1),
                               np.linalg.norm(p - np.clip(p[:, :1], 0, 1) * [1, 0, 0], axis=1), atol=1e-12)
    _check_codes(tri, p, q, code)
    assert code[-3] == D.VERT_C and code[-2] == D.VERT_A


def test_zero_area_faces_is_scale_invariant():
    """Whether a face has area (to rounding) is a property of its shape: the same triangles scaled by 1e-6 .. 10 give
    the same answer (a sound 1-unit triangle has area, a sliver 1e-12 wide per unit has none)."""
    tri = torch.tensor([[[0.0, 0, 0], [1, 0, 0], [0, 1, 0]],              # sound
                        [[0.0, 0, 0], [1, 0, 0], [0.5, 1e-12, 0]],        # sliver
                        [[0.0, 0, 0], [0.5, 0, 0], [1, 0, 0]]], dtype=torch.float64)   # corners on a line
    for k in (1e-6, 1e-3, 1.0, 10.0):
        assert D.zero_area_faces(tri * k).tolist() == [False, True, True], k


def test_require_closed_refuses_a_flat_two_sided_sheet_and_flipped_faces_even_with_holes_allowed():
    """A triangle and its reverse form a closed, consistently wound surface enclosing zero volume (refused: degenerate);
    a box with one face flipped is inconsistently wound, which allow_holes (boundary edges only) does not excuse."""
    v = torch.tensor([[0.0, 0, 0], [0.1, 0, 0], [0, 0.1, 0]], dtype=torch.float64)
    f = torch.tensor([[0, 1, 2], [0, 2, 1]])
    with pytest.raises(ValueError, match="volume"):
        D.require_closed(v, f, "sheet")
    box = trimesh.creation.box((0.1, 0.1, 0.1))
    faces = np.array(box.faces)
    faces[3] = faces[3, ::-1]
    vb, fb = torch.as_tensor(np.array(box.vertices)), torch.as_tensor(faces)
    for allow in (False, True):
        with pytest.raises(ValueError, match="winding"):
            D.require_closed(vb, fb, "box", allow_holes=allow)


def test_nearest_neighbours_broadcasts_a_single_batch_against_many():
    """Query (1,N,3) against targets (B,M,3) broadcasts like torch and equals scipy cKDTree per batch entry."""
    rng = np.random.default_rng(2)
    q = rng.normal(size=(1, 50, 3))
    t = rng.normal(size=(3, 80, 3))
    dist, idx = D.nearest_neighbours(q, t)
    assert dist.shape == (3, 50)
    for b in range(3):
        d, i = cKDTree(t[b]).query(q[0])
        np.testing.assert_allclose(dist[b].numpy(), d, atol=1e-12)
        assert idx[b].tolist() == i.tolist()
    dist2, _ = D.nearest_neighbours(t, q)
    for b in range(3):
        np.testing.assert_allclose(dist2[b].numpy(), cKDTree(q[0]).query(t[b])[0], atol=1e-12)


def test_point_mesh_distance_promotes_float32_points_against_a_float64_mesh():
    """float32 points against a float64 mesh are measured in float64 (torch type promotion), matching trimesh on the
    same (float32-exact) points to 1e-10 m; rounding the mesh to float32 would be off by ~1e-8."""
    mesh = trimesh.creation.icosphere(subdivisions=2, radius=0.37)
    rng = np.random.default_rng(3)
    p32 = torch.as_tensor(rng.normal(scale=0.5, size=(200, 3)), dtype=torch.float32)
    res = D.point_mesh_distance(p32, mesh)
    assert res.distance.dtype == torch.float64
    _, truth, _ = trimesh.proximity.closest_point(mesh, p32.double().numpy())
    np.testing.assert_allclose(res.distance.numpy(), truth, atol=1e-10, rtol=0)


def test_point_mesh_distance_batch_mismatch_is_a_value_error():
    """Points (2,N,3) against vertices (3,V,3) cannot broadcast: a ValueError naming the batch sizes."""
    box = trimesh.creation.box((0.1, 0.1, 0.1))
    v = torch.as_tensor(np.array(box.vertices))[None].repeat(3, 1, 1)
    with pytest.raises(ValueError, match="batch"):
        D.point_mesh_distance(torch.zeros(2, 4, 3, dtype=torch.float64), (v, torch.as_tensor(box.faces)))


def test_a_point_without_its_n_axis_is_refused_by_name():
    """as_points' contract is (..., N, 3): a bare (3,) vector is not a point set and is refused naming the argument,
    as are the distance functions given one."""
    with pytest.raises(ValueError, match="q"):
        D.as_points(np.zeros(3), "q")
    with pytest.raises(ValueError, match="query"):
        D.nearest_neighbours(np.zeros(3), np.zeros((4, 3)))


def test_a_face_index_equal_to_the_vertex_count_is_refused():
    """Face indices index the vertices: with V vertices, index V is out of range and is refused by name (ValueError),
    not left to fail later as an IndexError."""
    box = trimesh.creation.box((0.1, 0.1, 0.1))
    faces = np.array(box.faces)
    faces[0, 0] = len(box.vertices)
    with pytest.raises(ValueError, match="face indices"):
        D.mesh_arrays((np.array(box.vertices), faces), "m")


def test_the_metres_check_measures_the_span_and_ignores_where_the_mesh_is():
    """require_metres refuses a mesh by its span (largest side of its box), which moving it does not change: a 0.5 m
    box is accepted at the origin and 20 m away, the same box in millimetres is refused wherever it is."""
    box = trimesh.creation.box((0.5, 0.3, 0.2))
    f = torch.as_tensor(box.faces)
    for shift in ([0.0, 0, 0], [20.0, -5.0, 3.0]):
        v = torch.as_tensor(np.array(box.vertices) + shift)
        D.require_metres(v, f, "box")
        with pytest.raises(ValueError, match="box: largest side"):
            D.require_metres(v * 1000.0, f, "box")


def test_boxes_touching_along_a_face_or_an_edge_do_not_interpenetrate():
    """Two closed boxes that only share a face (or an edge) have an intersection of zero volume and no body vertex
    strictly inside the other: analytic, the interiors are disjoint."""
    a = _box((0.1, 0.1, 0.1), (0.0, 0.0, 0.0))
    for centre in [(0.1, 0.0, 0.0), (0.0, 0.0, 0.1), (0.1, 0.1, 0.0), (0.0, 0.1, 0.0)]:
        b = _box((0.1, 0.1, 0.1), centre)
        pen = interpenetration(a, b)
        assert pen.volume_cm3 == 0.0 and pen.depth_cm == 0.0
        assert intersection_volume(b, a) == 0.0


def test_grid_spacing_and_refine_refuse_booleans():
    """`refine` is a number of rays per cell side and `spacing` a length in metres: True/False are neither, and are
    refused by name like other non-numbers (a bool is not a count, per the documented 'positive integer')."""
    a, b = _box((0.1, 0.1, 0.1), (0, 0, 0)), _box((0.1, 0.1, 0.1), (0.05, 0, 0))
    with pytest.raises(ValueError, match="refine"):
        interpenetration(a, b, refine=True)
    with pytest.raises(ValueError, match="spacing"):
        interpenetration(a, b, spacing=True)
    assert interpenetration(a, b, refine=np.int64(2)).volume_cm3 == pytest.approx(500.0, rel=1e-6)   # 5 x 10 x 10 cm


def test_sdf_grid_nodes_hold_the_exact_sdf_and_padding_zero_is_the_surface_box():
    """SDFGrid.from_mesh with padding 0 spans the surface's own box (vertices no face uses do not count, docstring);
    node (ix, iy, iz) sits at lower + cell * (ix, iy, iz) and stores the exact signed distance there, and the lookup
    there returns it (trilinear interpolation is exact at a node)."""
    box = trimesh.creation.box(extents=(0.06, 0.1, 0.16))
    far = np.vstack([box.vertices, [[-1.0, -1.0, -1.0]]])             # an unused vertex far away
    grid = SDFGrid.from_mesh((far, box.faces), resolution=9, padding=0.0, dtype=torch.float64)
    np.testing.assert_allclose(grid.lower.numpy(), box.bounds[0], atol=1e-12)
    assert (grid.upper.numpy() >= box.bounds[1] - 1e-12).all()
    nz, ny, nx = grid.values.shape
    rng = np.random.default_rng(0)
    idx = np.stack([rng.integers(0, n, 40) for n in (nx, ny, nz)], 1)
    nodes = grid.lower.numpy() + grid.cell.numpy() * idx
    want = signed_distance(nodes, box).numpy()
    np.testing.assert_allclose(grid.values.numpy()[idx[:, 2], idx[:, 1], idx[:, 0]], want, atol=1e-12)
    np.testing.assert_allclose(grid(torch.tensor(nodes)).numpy(), want, atol=1e-9)


def test_sdf_grid_built_in_slabs_with_a_bar_holds_the_same_values(monkeypatch, capsys):
    """from_mesh(progress=True) (a user mesh's collision grid, minutes for a scan, was built without a word) evaluates
    the nodes a few z layers at a time under a bar: the values are those of the one call, bit for bit."""
    import graspkit.objects.sdf as S

    ico = trimesh.creation.icosphere(2, 0.05)
    whole = SDFGrid.from_mesh(ico, resolution=12)
    monkeypatch.setattr(S, "SLAB_NODES", 300)                        # 12 x 12 nodes a layer: 2 layers a slab
    slabs = SDFGrid.from_mesh(ico, resolution=12, progress=True)
    assert torch.equal(whole.values, slabs.values) and torch.equal(whole.lower, slabs.lower)
    assert "SDF grid (320 faces)" in capsys.readouterr().err


def test_sdf_grid_far_outside_reads_about_the_true_distance_and_resolution_one_is_refused():
    """Outside its box the grid continues as sdf(clamped) + |p - clamped| (docstring), so a point 0.5 m off a 6 cm
    cube reads its exact distance to within a cell; a grid of one node has no spacing and is refused by name."""
    box = trimesh.creation.box(extents=(0.06, 0.06, 0.06))
    grid = SDFGrid.from_mesh(box, resolution=16, padding=0.01, dtype=torch.float64)
    p = np.array([[0.53, 0.0, 0.0], [0.0, -0.4, 0.1], [0.2, 0.2, 0.2]])
    np.testing.assert_allclose(grid(torch.tensor(p)).numpy(), signed_distance(p, box).numpy(),
                               atol=float(grid.cell.max()))
    with pytest.raises(ValueError, match="resolution"):
        SDFGrid.from_mesh(box, resolution=1)


def test_contact_at_exactly_the_threshold_counts_and_threshold_zero_is_allowed():
    """'within threshold' includes the threshold (dyadic distances, exact in floating point): a point 1/16 m off a
    box face is in contact at threshold 1/16 m; threshold 0 (documented '>= 0') marks only points on the surface."""
    box = trimesh.creation.box(extents=(0.25, 0.25, 0.25))            # faces at +-0.125
    pts = torch.tensor([[0.1875, 0.0, 0.0], [0.125, 0.0, 0.0], [0.25, 0.0, 0.0]], dtype=torch.float64)
    np.testing.assert_array_equal(marker_contact(pts, box, threshold=0.0625).numpy(), [1, 1, 0])
    np.testing.assert_array_equal(object_contact(pts, box, threshold=0.0625).numpy(), [1, 1, 0])
    np.testing.assert_array_equal(marker_contact(pts, box, threshold=0.0).numpy(), [0, 1, 0])
    cloud = torch.tensor(box.vertices)
    np.testing.assert_array_equal(object_contact(cloud[:3], cloud, threshold=0).numpy(), [1, 1, 1])


def test_columns_through_two_stacked_open_boxes_count_as_empty():
    """Two lidless boxes stacked one above the other: each vertical ray enters both bottoms and leaves through
    neither (two crossings, both entering), so its counts do not close and the column counts as empty (module
    docstring), even though the count is even: the object inside the lower box measures 0 cm^3, with the warning."""
    lower, upper = _box((0.1, 0.1, 0.1), (0, 0, 0)), _box((0.1, 0.1, 0.1), (0, 0, 0.2))
    keep = lambda b: b.faces[~np.isclose(b.triangles_center[:, 2], b.bounds[1, 2])]   # noqa: E731  lid removed
    verts = np.vstack([lower.vertices, upper.vertices])
    faces = np.vstack([keep(lower), keep(upper) + len(lower.vertices)])
    obj = _box((0.04, 0.04, 0.04), (0.0, 0.0, -0.01))
    with pytest.warns(UserWarning, match="not closed"):
        assert interpenetration((verts, faces), obj).volume_cm3 == 0.0


def test_a_column_length_linear_in_y_is_integrated_exactly_on_oblong_cells():
    """A 100 x 10.05 x 60 mm box cut by a 45-degree plane z = -y (a big cube turned about x): each column's length is
    30 mm - y, linear, so the midpoint rule is exact on any grid of cells centred on their rays; on 5 mm spacing the
    overlap box's 10.05 mm side splits into three 3.35 mm cells (oblong), and the volume is 100 * 10.05 * 30 mm^3
    (the linear term integrates to zero): analytic."""
    a = _box((0.1, 0.01005, 0.06), (0.0, 0.0, 0.0))
    b = trimesh.creation.box(extents=(0.3, 0.3, 0.3))
    b.apply_translation((0.0, 0.0, -0.15))                              # top face z = 0
    b.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 4, [1, 0, 0]))   # top face now z = y ... turned
    n = b.face_normals[np.argmax(b.face_normals[:, 2])]
    assert np.allclose(np.abs(n), [0, np.sqrt(0.5), np.sqrt(0.5)])
    exact = 100 * 10.05 * 30 / 1000                                     # cm^3
    for spacing in (0.005, 0.003):
        assert intersection_volume(a, b, spacing=spacing) * 1e6 == pytest.approx(exact, rel=1e-4)
        assert intersection_volume(b, a, spacing=spacing) * 1e6 == pytest.approx(exact, rel=1e-4)


def test_a_grid_too_big_to_build_is_refused_naming_resolution():
    """resolution 5,000 failed in torch's allocator (or ran out of memory) without naming the argument."""
    with pytest.raises(ValueError, match="^resolution: 5000 gives .* grid nodes, more than 100,000,000"):
        SDFGrid.from_mesh(trimesh.creation.icosphere(1, 0.05), resolution=5000)


@pytest.mark.parametrize("budget", [10_000_000, 1300, 60])     # one call; two clouds a call; one cloud in row chunks
def test_nearest_neighbours_in_chunks_of_clouds_or_rows_matches_a_kd_tree(monkeypatch, budget):
    """A big batch was cut into chunks of a few rows of every cloud (64 clouds of 20,000 points: 200 s against 9 s one
    by one): now whole clouds a call while one fits in PAIR_BUDGET, else one cloud at a time; same indices either way,
    and those of scipy's k-d tree."""
    from scipy.spatial import cKDTree

    import graspkit.objects.distance as D

    g = torch.Generator().manual_seed(3)
    q = torch.randn(7, 30, 3, generator=g, dtype=torch.float64)
    t = torch.randn(7, 20, 3, generator=g, dtype=torch.float64)
    monkeypatch.setattr(D, "PAIR_BUDGET", budget)
    d, i = D.nearest_neighbours(q, t)
    for b in range(7):
        kd_d, kd_i = cKDTree(t[b].numpy()).query(q[b].numpy())
        np.testing.assert_array_equal(i[b].numpy(), kd_i)
        np.testing.assert_allclose(d[b].numpy(), kd_d, atol=1e-12)
    d1, i1 = D.nearest_neighbours(q, t[0])                     # one target for every cloud
    assert torch.equal(i1, torch.stack([D.nearest_neighbours(q[b], t[0])[1] for b in range(7)]))


def test_float32_distance_next_to_a_thin_face_is_that_of_float64():
    """A closed box with one face split around a sliver 0.2 mm or 0.2 µm high: float32 points and vertices measured up
    to 1 cm off beside the thinner when the closest point was computed in float32 (the region test's products lose
    the sliver's area); the truth is trimesh's closest point on every triangle in float64, on the very same rounded
    inputs (trimesh.proximity.closest_point searches candidates only and is up to 5 µm longer here)."""
    box = trimesh.creation.box((0.2, 0.2, 0.2))
    rng = np.random.default_rng(0)
    worst = 0.0
    for height in (2e-4, 2e-7):
        for fi in range(12):
            V, F = box.vertices.copy(), box.faces.copy()
            a, b, c = F[fi]
            foot = V[a] + 0.4 * (V[b] - V[a])
            V = np.vstack([V, foot + height * (V[c] - foot) / np.linalg.norm(V[c] - foot)])
            d = len(V) - 1
            F = np.vstack([np.delete(F, fi, 0), [[b, c, d], [c, a, d], [a, b, d]]])     # (a, b, d): the sliver
            assert trimesh.Trimesh(V, F, process=False).is_watertight
            P = torch.tensor(foot + rng.standard_normal((200, 3)) * 0.01, dtype=torch.float32)
            Vt = torch.tensor(V, dtype=torch.float32)
            got = point_mesh_distance(P, (Vt, F)).distance.double()
            tris, p = Vt.double().numpy()[F], P.double().numpy()      # every triangle against every point
            near = trimesh.triangles.closest_point(np.tile(tris, (len(p), 1, 1)), np.repeat(p, len(tris), 0))
            want = torch.as_tensor(np.linalg.norm(near - np.repeat(p, len(tris), 0), axis=1).reshape(len(p), -1).min(1))
            worst = max(worst, float((got - want).abs().max()))
    assert worst < 1e-7
