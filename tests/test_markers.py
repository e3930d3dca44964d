"""Marker and vertex sets on the procedural humanoid: counts, uniqueness and anatomy checked geometrically."""
import numpy as np
import pytest
import smplx
import torch
import trimesh

from graspkit.body import BodyModel
from graspkit.body.markers import (_Rest, farthest_point_sampling, foot_vertices, goal_vertices, palm_vertices,
                                   saga_markers, saga_sparse_markers, sole_rest_heights, vertex_normals)
from graspkit.body.skeleton import JOINT_INDEX
from graspkit.paths import default_model_path


@pytest.fixture(scope="module")
def bm():
    return BodyModel.from_file(default_model_path(), dtype=torch.float64)


@pytest.fixture(scope="module")
def rest(bm):
    out = bm()
    return out.vertices[0].numpy(), out.joints[0].numpy()


def test_saga_marker_counts_and_groups(bm):
    m = saga_markers(bm)
    sizes = {g: b - a for g, (a, b) in m.groups.items()}
    assert sizes == {"body": 49, "face": 14, "hand": 6, "finger": 30, "palm": 44} and len(m) == 143
    assert len(set(m.vertex_ids.tolist())) == 143 and len(set(m.names)) == 143
    s = saga_sparse_markers(bm)
    assert len(s) == 79 and s.groups["fingertip"] == (69, 79)
    np.testing.assert_array_equal(s.vertex_ids[:69], m.vertex_ids[:69])


def test_markers_sit_on_their_side_and_height(bm, rest):
    v, j = rest
    m = saga_markers(bm)
    p = v[m.vertex_ids]
    for name, x in zip(m.names, p):
        if name[0] in "LR" and name not in ("LIPU", "LIPD") and not name.startswith("LIP"):
            assert (x[0] > 0) == (name[0] == "L"), name  # the body's left is +x in the canonical frame
    a, b = m.groups["face"]
    assert (p[a:b, 1] > j[JOINT_INDEX["neck"], 1]).all() and (p[a:b, 2] > j[JOINT_INDEX["head"], 2]).all()
    knee_y = j[JOINT_INDEX["left_knee"], 1]
    for n in ("LHEE", "RHEE", "LTOE", "RTOE", "LANK", "RANK"):
        assert p[m.names.index(n), 1] < knee_y, n


def test_palm_markers_face_the_palm_and_finger_markers_the_back(bm, rest):
    v, _ = rest
    n = vertex_normals(torch.as_tensor(v)[None], bm.faces)[0].numpy()
    m = saga_markers(bm)
    a, b = m.groups["palm"]
    assert np.mean(n[m.vertex_ids[a:b], 1] < 0) >= 0.9   # palms face down (-y) in the rest pose
    a, b = m.groups["finger"]
    assert np.mean(n[m.vertex_ids[a:b], 1] > 0) >= 0.9   # finger markers on the back of the fingers


def test_goal_vertices(bm, rest):
    v, j = rest
    g = goal_vertices(bm)
    assert g.vertex_ids.shape == (400,) and len(set(g.vertex_ids.tolist())) == 400
    hand = v[g.vertex_ids[g.right_hand]]
    assert g.right_hand.shape == (99,) and (hand[:, 0] < j[JOINT_INDEX["right_wrist"], 0] + 0.03).all()
    q = g.head_direction(torch.as_tensor(v)[None])[0].numpy()
    assert q[2] > 0.9  # the head looks forward (+z) at rest


def test_foot_and_palm_vertex_sets(bm, rest):
    v, _ = rest
    f = foot_vertices(bm)
    for s in ("left", "right"):
        assert v[f[f"{s}_heel"], 2].mean() < v[f[f"{s}_toe"], 2].mean()      # heels behind toes
        assert v[np.concatenate([f[f"{s}_heel"], f[f"{s}_toe"]]), 1].max() < v[:, 1].min() + 0.021
    p = palm_vertices(bm)
    assert (v[p["left"], 0] > 0).all() and (v[p["right"], 0] < 0).all() and len(p["left"]) > 20


def test_farthest_point_sampling_against_brute_force():
    pts = np.random.default_rng(0).random((200, 3))
    idx = farthest_point_sampling(pts, 10)
    d = np.linalg.norm(pts[:, None] - pts[idx[:5]][None], axis=2).min(1)
    assert idx[5] == np.argmax(d)
    assert farthest_point_sampling(pts, 3, start=7)[0] == 7
    for kw, name in ((dict(n=0), "n"), (dict(n=2.0), "n"), (dict(n=201), "n"), (dict(n=3, start=-1), "start"),
                     (dict(n=3, start=200), "start")):
        with pytest.raises(ValueError, match=f"^{name}:"):
            farthest_point_sampling(pts, **kw)
    with pytest.raises(ValueError, match="^points: contain NaN"):
        farthest_point_sampling(np.r_[pts, [[np.nan, 0, 0]]], 3)
    grid = np.arange(30).reshape(10, 3)                       # integer coordinates are points too
    for dtype in (np.int64, np.uint8):                        # (unsigned differences wrapped)
        assert farthest_point_sampling(grid.astype(dtype), 3).tolist() == farthest_point_sampling(grid * 1.0, 3).tolist()


def test_vertex_normals_point_outwards_on_a_sphere_and_up_on_a_plane():
    import trimesh
    sph = trimesh.creation.icosphere(subdivisions=3)
    n = vertex_normals(torch.as_tensor(sph.vertices)[None], torch.as_tensor(sph.faces))[0].numpy()
    radial = sph.vertices / np.linalg.norm(sph.vertices, axis=1, keepdims=True)
    assert (np.sum(n * radial, axis=1) > 1 - 1e-4).all()
    quad = torch.tensor([[[0.0, 0, 0], [2, 0, 0], [2, 1, 0], [0, 1, 0]]], dtype=torch.float64)
    nq = vertex_normals(quad, torch.tensor([[0, 1, 2], [0, 2, 3]]))[0].numpy()
    np.testing.assert_allclose(nq, np.tile([0.0, 0, 1], (4, 1)), atol=1e-15)


def test_layouts_depend_on_the_file_not_the_model_options(bm):
    """One file, one layout: flat_hand_mean, use_pca and dtype do not move a marker (they used to: a flat-hand model
    placed 32 SAGA markers and 132 GOAL vertices elsewhere), and GOAL's layout is the one placed on flat hands."""
    others = [BodyModel.from_file(default_model_path(), flat_hand_mean=True),
              BodyModel.from_file(default_model_path(), use_pca=True, num_pca_comps=12, dtype=torch.float32)]
    for o in others:
        for f in (saga_markers, saga_sparse_markers):
            np.testing.assert_array_equal(f(o).vertex_ids, f(bm).vertex_ids)
        g, h = goal_vertices(o), goal_vertices(bm)
        np.testing.assert_array_equal(g.vertex_ids, h.vertex_ids)
        assert (g.head_back, g.head_front) == (h.head_back, h.head_front)
        for k, ids in palm_vertices(o).items():
            np.testing.assert_array_equal(ids, palm_vertices(bm)[k])
        for k, ids in foot_vertices(o).items():
            np.testing.assert_array_equal(ids, foot_vertices(bm)[k])
    # the rules see the hands they are documented to see: SAGA's markers the mean hand, GOAL's vertices flat hands
    flat_rest = others[0]().vertices[0].double()
    mean_rest = bm().vertices[0]
    hand = saga_markers(bm).vertex_ids[saga_markers(bm).groups["finger"][0]:]
    assert (flat_rest[hand] - mean_rest[hand]).norm(dim=-1).max() > 0.01   # the two rests differ at the fingers


def test_the_marker_cache_does_not_keep_a_model_alive():
    import gc
    import weakref
    m = BodyModel.from_file(default_model_path())
    ids = saga_markers(m).vertex_ids
    assert saga_markers(m) is saga_markers(m)                      # cached while the model lives
    ref = weakref.ref(m)
    del m
    gc.collect()
    assert ref() is None and len(ids) == 143


def test_sole_heights_are_above_each_foots_lowest_vertex(bm, rest):
    """sole_rest_heights: each sole vertex's height above its own foot's lowest vertex at rest (the rest mesh's y)."""
    v = rest[0]
    feet, h, start = foot_vertices(bm), sole_rest_heights(bm), 0
    for side in ("left", "right"):
        ids = np.concatenate([feet[k] for k in feet if k.startswith(side)])
        want = v[ids, 1] - v[ids, 1].min()
        got = h[start:start + len(ids)]
        np.testing.assert_allclose(got, want, atol=1e-9, err_msg=side)
        assert got.min() == 0.0
        start += len(ids)
    assert start == len(h)


def test_palm_vertices_face_the_palm(bm, rest):
    """palm_vertices are on the palm side: trimesh's vertex normals of the rest mesh point down (-y) there."""
    n = trimesh.Trimesh(rest[0], bm.faces.numpy(), process=False).vertex_normals
    for side, ids in palm_vertices(bm).items():
        assert len(ids) > 20, side
        assert np.mean(n[ids, 1] < -0.5) > 0.95, side


def test_palm_grid_runs_from_wrist_to_knuckles(bm, rest):
    """A marker's anchor is (1 - t) a + t b: the palm grid's four markers along each finger's wrist -> knuckle line
    come in order from the wrist (t = 0.2) to the knuckles (t = 0.95); the thigh's front marker (t = 0.4) is nearer
    the hip than the knee."""
    v, j = rest
    m = saga_markers(bm)
    p = dict(zip(m.names, v[m.vertex_ids]))
    for s, S in (("left", "L"), ("right", "R")):
        w = j[JOINT_INDEX[f"{s}_wrist"]]
        for f in ("index", "middle", "ring", "pinky"):
            k = j[JOINT_INDEX[f"{s}_{f}1"]]
            axis = (k - w) / np.linalg.norm(k - w)
            along = [(p[f"{S}PALM_{f}{i}"] - w) @ axis for i in range(4)]
            assert np.all(np.diff(along) > 0), (S, f, along)
            assert along[0] < 0.5 * np.linalg.norm(k - w) < along[3], (S, f, along)
        hip, knee = j[JOINT_INDEX[f"{s}_hip"]], j[JOINT_INDEX[f"{s}_knee"]]
        thf = p[f"{S}THF"]
        assert np.linalg.norm(thf - hip) < np.linalg.norm(thf - knee), S


def test_front_markers_are_in_front_and_back_markers_behind(bm, rest):
    """SAGA's front/back marker pairs (GRAB layout) on the rest body, which faces +z: the F-markers lie in front of their
    B or anchor counterparts."""
    v, j = rest
    m = saga_markers(bm)
    z = {n: v[i, 2] for n, i in zip(m.names, m.vertex_ids)}
    for front, back in (("LFHD", "LBHD"), ("RFHD", "RBHD"), ("STRN", "T10"), ("CLAV", "C7"),
                        ("LFWT", "LBWT"), ("RFWT", "RBWT"), ("LELBIN", "LELB"), ("RELBIN", "RELB")):
        assert z[front] > z[back], (front, back)
    for s, S in (("left", "L"), ("right", "R")):
        # thigh front (THF) is placed from 0.4 of the hip->knee segment along +z: in front of that segment
        anchor = 0.6 * j[JOINT_INDEX[f"{s}_hip"]] + 0.4 * j[JOINT_INDEX[f"{s}_knee"]]
        assert z[f"{S}THF"] > anchor[2], S
        # shin (SHN) is placed forward from the knee->ankle midpoint
        anchor = 0.5 * j[JOINT_INDEX[f"{s}_knee"]] + 0.5 * j[JOINT_INDEX[f"{s}_ankle"]]
        assert z[f"{S}SHN"] > anchor[2], S


def test_rest_bodies_carry_the_documented_hands():
    """Module doc: SAGA's markers are placed on the rest body with the file's mean hands, GOAL's vertices on the rest
    body with flat hands -- whatever the BodyModel's flat_hand_mean. Truth: the smplx package's zero-pose body with
    flat_hand_mean=False (mean hands) and =True (flat hands) of the same file."""
    bm = BodyModel.from_file(default_model_path(), dtype=torch.float64)
    root = str(default_model_path().parents[1])
    for hands, flat in (("mean", False), ("flat", True)):
        ref = smplx.create(root, model_type="smplx", gender="neutral", ext="npz", use_pca=False,
                           flat_hand_mean=flat, dtype=torch.float64)
        with torch.no_grad():
            want = ref().vertices[0].numpy()
        got = _Rest(bm, hands).v
        np.testing.assert_allclose(got, want, atol=1e-6, err_msg=hands)
    assert np.abs(_Rest(bm, "mean").v - _Rest(bm, "flat").v).max() > 0.01     # the two rests differ (fingers)


def test_fin_markers_sit_on_the_back_of_the_hand():
    """SAGA's hand markers (App. A.1): LFIN/RFIN on the back of the hand between wrist and knuckles. At rest the palms
    face -y (down), so the back of the hand faces +y. Truth: trimesh's vertex normals of the rest mesh (mean hands)."""
    bm = BodyModel.from_file(default_model_path(), dtype=torch.float64)
    out = bm()                                              # zero pose + the file's mean hands (flat_hand_mean=False)
    v, j = out.vertices[0].numpy(), out.joints[0].numpy()
    normals = trimesh.Trimesh(v, bm.faces.numpy(), process=False).vertex_normals
    m = saga_markers(bm)
    for S, s in (("L", "left"), ("R", "right")):
        i = m.vertex_ids[m.names.index(f"{S}FIN")]
        assert normals[i, 1] > 0.7, (S, normals[i])
        assert v[i, 1] > j[JOINT_INDEX[f"{s}_wrist"], 1], S   # above the wrist joint: the back, not the palm
