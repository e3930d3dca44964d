"""The procedural body's mesh builders (_proc_mesh: marching cubes, components, topology checks, splits,
self-intersections; _proc_remesh: Delaunay flips, relaxation) against trimesh, analytic spheres, hand-built meshes and
the definitions in their docstrings."""
import numpy as np
import trimesh
from scipy.spatial import Delaunay

from graspkit.body import _proc_mesh as M
from graspkit.body._proc_remesh import SurfaceProjector, delaunay_flips, relax

from conftest import jittered_plane


def _within(seconds, fn, *args):
    """fn(*args), failing the test instead of hanging if it runs longer than seconds (SIGALRM, main thread)."""
    import signal

    def boom(*_):
        raise TimeoutError(f"{fn.__name__} ran past {seconds} s")
    old = signal.signal(signal.SIGALRM, boom)
    signal.alarm(seconds)
    try:
        return fn(*args)
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)


def _tm(v, f):
    return trimesh.Trimesh(np.asarray(v), np.asarray(f), process=False)


def test_marching_cubes_of_a_sphere_sdf_is_the_sphere_outward():
    """The zero set of the exact signed distance of a sphere, sampled on a shifted grid, lies on that sphere (in the
    grid's world frame, origin u0) and encloses its volume 4/3 pi r^3 with outward (positive-volume) faces."""
    c, r, h, n = np.array([0.2, -0.1, 0.3]), 0.8, 0.1, 30
    u0 = c - 1.45
    idx = np.stack(np.meshgrid(*[np.arange(n)] * 3, indexing="ij"), -1)
    field = np.linalg.norm(u0 + h * idx - c, axis=-1) - r
    v, f = M.marching_cubes(field, h, u0)
    assert np.abs(np.linalg.norm(v - c, axis=1) - r).max() < 0.02
    vol = M.signed_volume(v, f)
    assert abs(vol - 4 / 3 * np.pi * r ** 3) / (4 / 3 * np.pi * r ** 3) < 0.03
    mesh = _tm(v, f)
    assert mesh.volume > 0 and mesh.is_winding_consistent


def test_largest_component_keeps_the_bigger_sphere_and_drops_its_unused_vertices():
    """Of two disjoint icospheres (320 and 80 faces) plus a stray vertex, the one with the most faces is kept, whole
    and closed, with no unreferenced vertex."""
    a, b = trimesh.creation.icosphere(2), trimesh.creation.icosphere(1)
    b.apply_translation([5.0, 0, 0])
    both = trimesh.util.concatenate([b, a])
    v = np.vstack([both.vertices, [[9.0, 9, 9]]])
    v2, f2 = M.largest_component(v, np.asarray(both.faces))
    assert len(f2) == 320 and len(v2) == 162
    assert np.abs(np.linalg.norm(v2, axis=1) - 1).max() < 1e-9
    assert _tm(v2, f2).is_watertight


def test_drop_doubled_faces_removes_both_copies_of_a_doubled_face():
    """A face whose vertex set occurs twice (in either winding) goes, both copies; faces occurring once stay in order."""
    tet = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    f = np.vstack([tet, [[1, 2, 0]]])
    np.testing.assert_array_equal(M.drop_doubled_faces(f), tet[1:])
    np.testing.assert_array_equal(M.drop_doubled_faces(tet), tet)


def test_topology_report_matches_trimesh_on_known_meshes():
    """Volume, winding, Euler characteristic and genus of a unit box, a torus, a box with one face reversed, with an
    unused vertex and with a degenerate face agree with trimesh and with the definitions (genus = (2 - chi) / 2)."""
    box = trimesh.creation.box()
    r = M.topology_report(box.vertices, box.faces)
    assert r["volume"] == pytest_approx(1.0) and r["watertight"] and r["winding_consistent"]
    assert r["euler"] == 2 == box.euler_number and r["genus"] == 0 and r["degenerate_faces"] == 0
    tor = trimesh.creation.torus(major_radius=1.0, minor_radius=0.3)
    r = M.topology_report(tor.vertices, tor.faces)
    assert r["euler"] == tor.euler_number == 0 and r["genus"] == 1
    assert r["volume"] == pytest_approx(tor.volume) and r["volume"] > 0
    f = np.array(box.faces)
    f[0] = f[0, ::-1]
    assert not _tm(box.vertices, f).is_winding_consistent
    assert not M.topology_report(box.vertices, f)["winding_consistent"]
    v = np.vstack([box.vertices, [[5.0, 5, 5]]])
    r = M.topology_report(v, box.faces)
    assert r["unused_vertices"] == 1 and r["vertices"] == 9 and r["euler"] == 2 and r["genus"] == 0
    r = M.topology_report(box.vertices, np.vstack([box.faces, [[0, 0, 1]]]))
    assert r["degenerate_faces"] == 1


def pytest_approx(x):
    import pytest
    return pytest.approx(x, rel=1e-9, abs=1e-12)


def test_pinched_vertices_counts_a_bowtie_vertex_and_none_on_a_sphere():
    """Two closed tetrahedra sharing only one vertex make that vertex pinched (two fans of faces); an icosphere and a
    lone tetrahedron have none."""
    s = trimesh.creation.icosphere(2)
    assert M.pinched_vertices(np.asarray(s.faces), len(s.vertices)) == 0
    tet = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    assert M.pinched_vertices(tet, 4) == 0
    other = np.array([[0, 5, 4], [0, 4, 6], [0, 6, 5], [4, 5, 6]])    # vertices 0, 4, 5, 6: shares only vertex 0
    assert M.pinched_vertices(np.vstack([tet, other]), 7) == 1


def test_split_longest_edges_hits_the_target_and_keeps_a_closed_surface():
    """Splitting an icosphere from 42 to 60 vertices gives exactly 60 vertices and 2(V-2) faces, a closed oriented genus-0
    mesh (trimesh) of unchanged volume, each new vertex the midpoint of an original edge."""
    s = trimesh.creation.icosphere(1)
    v, f = np.asarray(s.vertices), np.asarray(s.faces)
    v2, f2 = _within(10, M.split_longest_edges, v, f, 60)   # a face rewritten twice in one round would loop forever
    assert len(v2) == 60 and len(f2) == 2 * (60 - 2)
    np.testing.assert_array_equal(v2[:42], v)
    mesh = _tm(v2, f2)
    assert mesh.is_watertight and mesh.is_winding_consistent and mesh.euler_number == 2
    assert mesh.volume == pytest_approx(s.volume)
    mids = 0.5 * (v[s.edges_unique[:, 0]] + v[s.edges_unique[:, 1]])
    d = np.linalg.norm(v2[42:, None] - mids[None], axis=2).min(1)
    assert d.max() < 1e-12


def test_self_intersections_subset_returns_global_face_ids():
    """With a subset of faces, an intersecting pair is reported by its ids in the whole mesh, as for the whole mesh."""
    far = np.array([[10.0, 10, 10], [11, 10, 10], [10, 11, 10]])
    big = np.array([[-1.0, -1, 0], [1, -1, 0], [0, 1, 0]])
    small = np.array([[0, -0.1, -0.2], [0.1, 0.1, 0.3], [-0.1, 0.1, 0.3]])
    v = np.concatenate([far, big, small])
    f = np.array([[0, 1, 2], [3, 4, 5], [6, 7, 8]])
    assert sorted(map(tuple, M.self_intersections(v, f).tolist())) == [(1, 2)]
    assert sorted(map(tuple, M.self_intersections(v, f, subset=np.array([1, 2])).tolist())) == [(1, 2)]
    assert len(M.self_intersections(v, f, subset=np.array([0, 1]))) == 0


def _normals(v, f):
    n = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    return n / np.linalg.norm(n, axis=1, keepdims=True)


def _non_delaunay(v, f):
    """Number of interior edges whose two opposite angles sum to more than pi (trimesh face adjacency)."""
    m = _tm(v, f)
    adj, edges = m.face_adjacency, m.face_adjacency_edges
    tot = 0
    for (f1, f2), e in zip(adj, edges):
        s = 0.0
        for fi in (f1, f2):
            o = [x for x in f[fi] if x not in e][0]
            u, w = v[e[0]] - v[o], v[e[1]] - v[o]
            s += np.arccos(np.clip(u @ w / np.linalg.norm(u) / np.linalg.norm(w), -1, 1))
        tot += s > np.pi + 1e-6
    return tot


def test_delaunay_flips_on_a_stretched_sphere_keep_it_closed_convex_and_flip_only_flat_pairs():
    """On a convex stretched icosphere (obtuse, non-Delaunay triangles), the flips leave a closed, oriented, genus-0 mesh
    (trimesh) whose faces all face outward, no vertex below valence 4, fewer non-Delaunay edges, and every new edge
    between two faces within max_dihedral_deg of coplanar, whose old faces were too (the docstring's conditions)."""
    s = trimesh.creation.icosphere(3)
    v = np.asarray(s.vertices) * [2.5, 1.0, 0.7]
    f = np.asarray(s.faces)
    out = delaunay_flips(v, f, max_dihedral_deg=12.0)
    key = lambda ff: {tuple(sorted(t)) for t in ff.tolist()}  # noqa: E731
    assert key(out) != key(f)
    mesh = _tm(v, out)
    assert mesh.is_watertight and mesh.is_winding_consistent and mesh.euler_number == 2
    assert ((_normals(v, out) * v[out].mean(1)).sum(1) > 0).all()
    assert np.bincount(out.ravel()).min() >= 4
    assert _non_delaunay(v, out) < _non_delaunay(v, f)
    cos_max = np.cos(np.deg2rad(12.0))
    old = _tm(v, f)
    old_e = {tuple(e) for e in old.edges_unique.tolist()}
    on = _normals(v, out)
    for (f1, f2), e in zip(mesh.face_adjacency, mesh.face_adjacency_edges):
        if tuple(sorted(e)) not in old_e:
            assert on[f1] @ on[f2] >= cos_max - 1e-12
    oldn = _normals(v, f)
    new_e = {tuple(e) for e in mesh.edges_unique.tolist()}
    for (f1, f2), e in zip(old.face_adjacency, old.face_adjacency_edges):
        if tuple(sorted(e)) not in new_e:
            assert oldn[f1] @ oldn[f2] >= cos_max - 1e-12


def test_relax_on_a_plane_is_one_uniform_laplacian_step():
    """On a flat jittered grid projected onto its own plane, each relaxation step moves every vertex by step times the
    offset to the mean of its edge neighbours (uniform Laplacian, hand-computed), and stays in the plane."""
    v, tri = jittered_plane(6, seed=3)
    gp = np.stack(np.meshgrid(np.linspace(-20, 20, 9), np.linspace(-20, 20, 9)), -1).reshape(-1, 2)
    ref = trimesh.Trimesh(np.column_stack([gp, np.zeros(len(gp))]), Delaunay(gp).simplices, process=False)
    proj = SurfaceProjector(np.asarray(ref.vertices), np.asarray(ref.faces))
    nb = [set() for _ in range(len(v))]
    for t in tri.tolist():
        for i in range(3):
            nb[t[i]] |= {t[(i + 1) % 3], t[(i + 2) % 3]}

    def step(x, s):
        return np.array([x[i] + s * (x[sorted(nb[i])].mean(0) - x[i]) for i in range(len(x))])

    np.testing.assert_allclose(relax(v, tri, proj, iters=1, step=0.5), step(v, 0.5), atol=1e-9)
    np.testing.assert_allclose(relax(v, tri, proj, iters=2, step=0.3), step(step(v, 0.3), 0.3), atol=1e-9)


def _quad_with_fans(h, pad_a, pad_b):
    """Quad a b c d (faces abc, bad, counter-clockwise from +z) split along its long diagonal a-b, non-Delaunay (the
    angles at c and d are about 145 degrees each); c and d at height h. Each of a, b also gets pad_* extra faces with
    far-away vertices (no shared edges), so that its valence (face count) is 2 + pad."""
    v = [[-1.0, 0, 0], [1.0, 0, 0], [0, 0.3, h], [0, -0.3, h]]
    f = [[0, 1, 2], [1, 0, 3]]
    for k, (who, pad) in enumerate(((0, pad_a), (1, pad_b))):
        for i in range(pad):
            n = len(v)
            v += [[5.0 * (k + 1), 3.0 * i, 10.0], [5.0 * (k + 1) + 1, 3.0 * i, 10.0]]
            f.append([who, n, n + 1])
    return np.array(v), np.array(f)


def _quad_flipped(v, f, **kw):
    out = delaunay_flips(v, f, **kw)
    key = {tuple(sorted(t)) for t in out[:2].tolist()}
    assert key in ({(0, 1, 2), (0, 1, 3)}, {(0, 2, 3), (1, 2, 3)})
    return key == {(0, 2, 3), (1, 2, 3)}


def test_delaunay_flips_respect_the_valence_and_dihedral_limits():
    """A flat non-Delaunay quad is flipped to its short diagonal when both ends of the long one keep valence >= 4, and not
    when one would drop to 3; a folded one (old faces 37 degrees apart, new ones 11) is flipped only when
    max_dihedral_deg admits the old pair (the docstring's conditions, with the angles computed by hand)."""
    assert _quad_flipped(*_quad_with_fans(0.0, 3, 3))
    assert not _quad_flipped(*_quad_with_fans(0.0, 2, 3))
    assert not _quad_flipped(*_quad_with_fans(0.0, 3, 2))
    v, f = _quad_with_fans(0.1, 3, 3)
    assert not _quad_flipped(v, f, max_dihedral_deg=12.0)
    assert _quad_flipped(v, f, max_dihedral_deg=40.0)
