"""The procedural humanoid (data_stubs/.../SMPLX_NEUTRAL.npz) against independent truths: trimesh for
topology and inside/outside, the smplx package for posing, analytic facts for shapes and hands."""
from pathlib import Path

import numpy as np
import pytest
import scipy.linalg
import smplx
import torch
import trimesh

from graspkit.body import BodyModel
from graspkit.body import _proc_mesh as M
from graspkit.body._proc_anatomy import Proportions
from graspkit.body._proc_remesh import closest_point_on_triangles
from graspkit.body._proc_rig import skinning_weights
from graspkit.body.hand_poses import HAND_KINDS, hand_axes, hand_pca, sample_hand_poses, template_pose
from graspkit.body.procedural import build_procedural_smplx, part_of_vertex
from graspkit.body.skeleton import FINGERS, JOINT_INDEX, NUM_VERTICES, PARENTS, SMPLX_LANDMARK_VERTEX_IDS as LMK
from graspkit.checks import seeded_rng

ROOT = Path(__file__).resolve().parents[1]
MODEL_DIR = ROOT / "data_stubs" / "body_models"
MODEL = MODEL_DIR / "smplx" / "SMPLX_NEUTRAL.npz"


@pytest.fixture(scope="module")
def shipped() -> dict[str, np.ndarray]:
    with np.load(MODEL, allow_pickle=False) as npz:
        return {k: npz[k] for k in npz.files}


@pytest.fixture(scope="module")
def fresh() -> dict[str, np.ndarray]:
    return build_procedural_smplx(seed=0, progress=False)


def _smplx(**kw):
    kw = {"use_pca": False, "flat_hand_mean": True, "dtype": torch.float64, **kw}
    return smplx.create(str(MODEL_DIR), model_type="smplx", gender="neutral", ext="npz", **kw)


def _pose(**joints: tuple[float, float, float]) -> torch.Tensor:
    """body_pose (1, 63) with the given joints' axis-angles."""
    p = torch.zeros(1, 63, dtype=torch.float64)
    for name, aa in joints.items():
        j = JOINT_INDEX[name]
        p[0, 3 * (j - 1):3 * j] = torch.tensor(aa, dtype=torch.float64)
    return p


# ----------------------------------------------------------------------------- the file
def test_shipped_file_is_the_fresh_build_of_seed_0(shipped, fresh):
    """Same keys, dtypes and shapes; byte-identical where the machine computes as the one that built the file (the
    hand components within 1e-12: their LAPACK sums change with the thread count).

    The quadric decimation follows floating-point ties, which differ between CPUs (numpy picks SIMD kernels at run
    time), so on another machine the rebuild may triangulate differently: then the body must still be the same
    body: joints, stature, volume and area equal, every landmark id at the same anatomy."""
    assert sorted(shipped) == sorted(fresh)
    for k in fresh:
        assert shipped[k].dtype == fresh[k].dtype and shipped[k].shape == fresh[k].shape, k
    if np.array_equal(shipped["f"], fresh["f"]):
        for k in fresh:      # the hand PCA's LAPACK sums depend on the thread count: 1e-16 apart on one thread
            if fresh[k].dtype.kind == "f" and k.startswith("hands_components"):
                np.testing.assert_allclose(shipped[k], fresh[k], rtol=0, atol=1e-12, err_msg=k)
            else:
                assert np.array_equal(shipped[k], fresh[k]), f"{k} differs from a fresh build"
        return
    js, jf = (d["J_regressor"] @ d["v_template"] for d in (shipped, fresh))
    np.testing.assert_allclose(js, jf, atol=1e-4)
    ms, mf = (trimesh.Trimesh(d["v_template"], d["f"], process=False) for d in (shipped, fresh))
    assert mf.is_watertight and mf.is_winding_consistent
    assert abs(mf.volume / ms.volume - 1) < 1e-3 and abs(mf.area / ms.area - 1) < 2e-3
    assert abs(np.ptp(mf.vertices[:, 1]) - np.ptp(ms.vertices[:, 1])) < 1e-3
    ids = list(LMK.values())
    assert np.linalg.norm(shipped["v_template"][ids] - fresh["v_template"][ids], axis=1).max() < 0.025


def test_file_loads_without_pickle_and_says_it_is_procedural(shipped):
    assert all(a.dtype != object for a in shipped.values())
    text = str(shipped["procedural"])
    assert "procedural" in text and "seed=0" in text
    assert BodyModel.from_file(MODEL).is_procedural
    assert MODEL.stat().st_size < 8e6


# ----------------------------------------------------------------------------- the mesh
def test_mesh_is_closed_oriented_genus0_and_free_of_self_intersection(shipped):
    v, f = shipped["v_template"], shipped["f"]
    assert v.shape == (NUM_VERTICES, 3) and f.shape == (2 * (NUM_VERTICES - 2), 3)
    mesh = trimesh.Trimesh(v, f, process=False)
    assert mesh.is_watertight and mesh.is_winding_consistent
    assert mesh.euler_number == 2 and mesh.volume > 0
    assert 0.05 < mesh.volume < 0.09                       # m^3: an adult of 1.70 m
    assert len(M.self_intersections(v, f)) == 0


def test_self_intersection_check_against_known_cases():
    a, b = trimesh.creation.box(), trimesh.creation.box()
    b.apply_translation([0.5, 0.3, 0.2])
    both = trimesh.util.concatenate([a, b])
    assert len(M.self_intersections(both.vertices, both.faces)) > 0
    b.apply_translation([2.0, 0, 0])
    apart = trimesh.util.concatenate([a, b])
    assert len(M.self_intersections(apart.vertices, apart.faces)) == 0
    # the spatial hash finds every bounding-box overlap that brute force finds
    s = trimesh.creation.icosphere(2)
    v = s.vertices + np.random.default_rng(0).normal(scale=0.05, size=s.vertices.shape)
    lo, hi = v[s.faces].min(1), v[s.faces].max(1)
    i, j = np.triu_indices(len(s.faces), 1)
    over = np.all((lo[i] <= hi[j]) & (lo[j] <= hi[i]), axis=1)
    share = (s.faces[i][:, :, None] == s.faces[j][:, None, :]).any((1, 2))
    brute = {(x, y) for x, y in zip(i[over & ~share], j[over & ~share])}
    assert {tuple(p) for p in M.candidate_pairs(v, s.faces).tolist()} == brute


def test_stature_and_height_component(shipped):
    bm = _smplx()
    stature = {}
    for b in (-2.0, 0.0, 2.0):
        betas = torch.zeros(1, 10, dtype=torch.float64)
        betas[0, 0] = b
        y = bm(betas=betas).vertices[0, :, 1].detach().numpy()
        stature[b] = float(y.max() - y.min())
    assert 1.65 <= stature[0.0] <= 1.75
    assert 1.50 <= stature[-2.0] <= 1.60 and 1.82 <= stature[2.0] <= 1.92, stature
    v = shipped["v_template"]
    assert abs(v[:, 1].min() + 1.30) < 0.01 and abs(v[:, 1].max() - 0.40) < 0.01   # soles and head top as SMPL-X
    assert abs((shipped["J_regressor"] @ v)[0, 1] + 0.35) < 0.01                     # pelvis joint height


def test_shape_and_expression_components_keep_the_mesh_free_of_self_intersection(shipped):
    v, f, S = shipped["v_template"], shipped["f"], shipped["shapedirs"]
    for i in range(10):
        for b in (-2.0, 2.0):
            assert len(M.self_intersections(v + b * S[:, :, i], f)) == 0, (i, b)
    moved = np.abs(S[:, :, 10:]).max((1, 2)) > 0
    head = shipped["weights"][:, [JOINT_INDEX["head"], JOINT_INDEX["jaw"]]].sum(1)
    assert moved.any() and head[moved].min() > 0.3                 # expressions move the head only ...
    upper = np.nonzero((v[f, 1] > v[moved, 1].min() - 0.05).any(1))[0]
    for i in range(10, 20):                                         # ... so only faces near it can collide
        for b in (-2.0, 2.0):
            assert len(M.self_intersections(v + b * S[:, :, i], f, subset=upper)) == 0, (i, b)


def test_every_joint_is_inside_the_mesh_at_rest_and_at_betas_pm2(shipped):
    v, f, S, R = shipped["v_template"], shipped["f"], shipped["shapedirs"], shipped["J_regressor"]
    shapes = [v] + [v + b * S[:, :, i] for i in range(10) for b in (-2.0, 2.0)]
    for vs in shapes:
        inside = trimesh.Trimesh(vs, f, process=False).contains(R @ vs)
        assert inside.all(), np.nonzero(~inside)[0]


# ----------------------------------------------------------------------------- landmarks and parts
def test_landmark_vertices_sit_on_their_anatomy(shipped):
    v = shipped["v_template"]
    J = shipped["J_regressor"] @ v
    head = v[:, 1] > J[JOINT_INDEX["neck"], 1]
    nose, leye, reye = v[LMK["nose"]], v[LMK["leye"]], v[LMK["reye"]]
    assert nose[2] == v[head, 2].max()                                   # the most forward point of the head
    assert leye[1] > nose[1] and reye[1] > nose[1] and leye[0] > 0 > reye[0]
    assert v[LMK["lear"], 0] > 0.07 and v[LMK["rear"], 0] < -0.07
    part = part_of_vertex(shipped)
    for side, prefix in (("l", "left_"), ("r", "right_")):
        for finger in ("thumb", "index", "middle", "ring", "pinky"):
            j3 = JOINT_INDEX[f"{prefix}{finger}3"]
            d = J[j3] - J[j3 - 1]
            d /= np.linalg.norm(d)
            tip = LMK[side + finger]
            assert part[tip] == j3
            along = (v[part == j3] - J[j3]) @ d
            assert (v[tip] - J[j3]) @ d == pytest.approx(along.max())    # the farthest point along the finger
    for side, prefix in (("L", "left_"), ("R", "right_")):
        heel, big, small = v[LMK[f"{side}Heel"]], v[LMK[f"{side}BigToe"]], v[LMK[f"{side}SmallToe"]]
        ankle = J[JOINT_INDEX[prefix + "ankle"]]
        assert big[2] > small[2] > ankle[2] > heel[2]                   # toes ahead, heel at the back
        assert heel[1] < v[:, 1].min() + 0.01                            # heel on the ground
        assert abs(big[0]) < abs(small[0])                               # big toe on the inner side


def test_weights_and_regressor_are_convex_combinations(shipped):
    w, R = shipped["weights"], shipped["J_regressor"]
    assert np.allclose(w.sum(1), 1.0) and w.min() >= 0
    assert np.allclose(R.sum(1), 1.0) and R.min() >= 0
    assert np.array_equal(shipped["kintree_table"][1], np.arange(55))
    assert shipped["kintree_table"][0, 0] == 4294967295 and list(shipped["kintree_table"][0, 1:]) == list(PARENTS[1:])


# ----------------------------------------------------------------------------- posing
def _rodrigues(aa: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) of axis-angles (..., 3)."""
    th = np.linalg.norm(aa, axis=-1, keepdims=True)[..., None]
    k = aa / np.maximum(np.linalg.norm(aa, axis=-1, keepdims=True), 1e-12)
    K = np.zeros(aa.shape[:-1] + (3, 3))
    K[..., 0, 1], K[..., 0, 2], K[..., 1, 2] = -k[..., 2], k[..., 1], -k[..., 0]
    K = K - np.swapaxes(K, -1, -2)
    return np.eye(3) + np.sin(th) * K + (1 - np.cos(th)) * K @ K


def _numpy_lbs(a: dict, betas: np.ndarray, expr: np.ndarray, full_pose: np.ndarray) -> np.ndarray:
    """Plain SMPL-X LBS (SMPL Eq. 1-10) of one body: betas (10,), expression (10,), full pose (55, 3) -> (V, 3)."""
    v = a["v_template"] + a["shapedirs"] @ np.concatenate([betas, expr])
    J = a["J_regressor"] @ v
    R = _rodrigues(full_pose)
    v = v + a["posedirs"] @ (R[1:] - np.eye(3)).reshape(-1)
    parents = a["kintree_table"][0].astype(np.int64)
    G = np.zeros((55, 4, 4))
    for j in range(55):
        local = np.eye(4)
        local[:3, :3] = R[j]
        local[:3, 3] = J[j] - (J[parents[j]] if j else 0)
        G[j] = local if j == 0 else G[parents[j]] @ local
    G[:, :3, 3] -= np.einsum("jab,jb->ja", G[:, :3, :3], J)
    T = np.einsum("vj,jab->vab", a["weights"], G)
    return np.einsum("vab,vb->va", T[:, :3, :3], v) + T[:, :3, 3]


def test_smplx_poses_the_file_like_a_plain_numpy_lbs(shipped):
    rng = np.random.default_rng(3)
    betas, expr = rng.normal(size=10), rng.normal(size=10)
    pose = rng.normal(scale=0.4, size=(55, 3))
    bm = _smplx(flat_hand_mean=False)
    t = lambda x: torch.tensor(x[None], dtype=torch.float64)  # noqa: E731
    out = bm(betas=t(betas), expression=t(expr), global_orient=t(pose[0]), body_pose=t(pose[1:22].ravel()),
             jaw_pose=t(pose[22]), leye_pose=t(pose[23]), reye_pose=t(pose[24]),
             left_hand_pose=t(pose[25:40].ravel()), right_hand_pose=t(pose[40:55].ravel()))
    full = pose.copy()
    full[25:40] += shipped["hands_meanl"].reshape(15, 3)
    full[40:55] += shipped["hands_meanr"].reshape(15, 3)
    ours = _numpy_lbs(shipped, betas, expr, full)
    assert np.abs(out.vertices[0].detach().numpy() - ours).max() < 1e-5


def _contour(model, yaw_deg: float) -> np.ndarray:
    """smplx's 17 jaw-contour landmarks (17, 3) with the head turned by yaw_deg about the vertical (canonical y)."""
    return model(body_pose=_pose(head=(0, np.deg2rad(yaw_deg), 0))).joints[0, -17:].detach().numpy()


def test_smplx_face_contour_reads_the_yaw_bins_in_smplx_order():
    """smplx (lbs.find_dynamic_lmk_idx_and_bcoords) reads the 79 contour bins as yaw 0, +1..+39, -1..-39: at rest it
    must pick a jaw line symmetric about the face (right ear -> chin -> left ear mirrors onto itself, x -> -x), and
    a head turned left and right by the same angle must give mirror images."""
    model = _smplx(use_face_contour=True)
    mirror = lambda c: c[::-1] * np.array([-1.0, 1.0, 1.0])  # noqa: E731
    rest = _contour(model, 0)
    assert abs(rest[8, 0]) < 3e-3                              # the chin on the midline
    assert np.abs(rest - mirror(rest)).max() < 4e-3
    for yaw in (10, 25):
        assert np.abs(_contour(model, yaw) - mirror(_contour(model, -yaw))).max() < 4e-3


@pytest.mark.parametrize("joint, aa", [("left_elbow", (0, -np.pi / 2, 0)), ("right_elbow", (0, np.pi / 2, 0)),
                                       ("left_knee", (np.pi / 2, 0, 0)), ("right_knee", (np.pi / 2, 0, 0))])
def test_90_degree_elbow_and_knee_keep_volume_without_folding(shipped, joint, aa):
    """Local volume (cones from the joint to the faces within 12 cm / 15 cm of it) changes by < 10 %;
    no face pair near the joint intersects (nothing passes through the other limb); almost no face
    turns over against the rotation its weights give it (a crease apex may pinch a few)."""
    bm = _smplx()
    rest, bent = bm(), bm(body_pose=_pose(**{joint: aa}))
    v0, J0 = rest.vertices[0].detach().numpy(), rest.joints[0].detach().numpy()
    v1, J1 = bent.vertices[0].detach().numpy(), bent.joints[0].detach().numpy()
    f, w = shipped["f"], shipped["weights"]
    c = JOINT_INDEX[joint]
    radius = 0.12 if "elbow" in joint else 0.15
    near = (np.linalg.norm(v0 - J0[c], axis=1) < radius)[f].all(1)

    def cone_volume(v, centre):
        t = v[f[near]] - centre
        return np.einsum("ij,ij->i", t[:, 0], np.cross(t[:, 1], t[:, 2])).sum() / 6

    change = cone_volume(v1, J1[c]) / cone_volume(v0, J0[c]) - 1
    assert abs(change) < 0.10
    region = np.nonzero(np.linalg.norm(v0[f].mean(1) - J0[c], axis=1) < 0.2)[0]
    assert len(M.self_intersections(v1, f, subset=region)) == 0
    child = [c]
    for j in range(c + 1, 55):
        if PARENTS[j] in child:
            child.append(j)
    t = w[:, child].sum(1)[f].mean(1)                                 # share of the bent part, per face
    axis = np.asarray(aa) / np.linalg.norm(aa)
    R = _rodrigues(t[:, None] * (np.pi / 2) * axis)                   # the rotation the face's weights give it
    n0 = np.cross(v0[f[:, 1]] - v0[f[:, 0]], v0[f[:, 2]] - v0[f[:, 0]])
    n1 = np.cross(v1[f[:, 1]] - v1[f[:, 0]], v1[f[:, 2]] - v1[f[:, 0]])
    turned = (np.einsum("fab,fb,fa->f", R, n0, n1) < 0) & near
    print(f"{joint}: local volume change {100 * change:+.1f} %, faces turned over {turned.sum()} of {near.sum()}")
    assert turned.sum() <= 0.005 * near.sum()


def test_everyday_poses_do_not_intersect_themselves(shipped):
    """Arms lowered (A-pose), a walking stride and an arm raised: no face pair intersects."""
    bm = _smplx()
    poses = [
        _pose(left_shoulder=(0, 0, -1.1), right_shoulder=(0, 0, 1.1)),
        _pose(left_hip=(-0.45, 0, 0), right_hip=(0.3, 0, 0), left_knee=(0.25, 0, 0), right_knee=(0.5, 0, 0),
              left_shoulder=(0.3, 0, -1.25), right_shoulder=(-0.3, 0, 1.25), left_elbow=(0, -0.3, 0),
              right_elbow=(0, 0.3, 0)),
        _pose(right_shoulder=(0, 0, -1.1), right_elbow=(0, 0.15, 0), left_shoulder=(0, 0, -1.2)),
    ]
    for p in poses:
        v = bm(body_pose=p).vertices[0].detach().numpy()
        assert len(M.self_intersections(v, shipped["f"])) == 0


# ----------------------------------------------------------------------------- hands
def test_hand_pca_is_orthonormal_and_45_components_reproduce_the_full_pose(shipped):
    for s in "lr":
        C = shipped[f"hands_components{s}"]
        assert np.allclose(C @ C.T, np.eye(45), atol=1e-10)
    rng = np.random.default_rng(1)
    lh = sample_hand_poses(1, "power", rng, "left")
    rh = sample_hand_poses(1, "pinch", rng, "right")
    t = lambda x: torch.tensor(x, dtype=torch.float64)  # noqa: E731
    full = _smplx(flat_hand_mean=False)(left_hand_pose=t(lh), right_hand_pose=t(rh)).vertices
    pca = _smplx(flat_hand_mean=False, use_pca=True, num_pca_comps=45)(
        left_hand_pose=t(lh @ shipped["hands_componentsl"].T), right_hand_pose=t(rh @ shipped["hands_componentsr"].T))
    assert (full - pca.vertices).abs().max().item() < 1e-8


def test_hand_poses_curl_towards_the_palm_and_mirror(shipped):
    J0 = shipped["J_regressor"] @ shipped["v_template"]
    bm = _smplx()
    for kind in HAND_KINDS:
        lh = sample_hand_poses(1, kind, 0, "left", joints=J0, noise_deg=0.0)
        rh = sample_hand_poses(1, kind, 0, "right", joints=J0, noise_deg=0.0)
        t = lambda x: torch.tensor(x, dtype=torch.float64)  # noqa: E731
        J = bm(left_hand_pose=t(lh), right_hand_pose=t(rh)).joints[0, :55].detach().numpy()
        assert np.allclose(J[25:40] * (-1, 1, 1), J[40:55], atol=1e-9), kind      # left = mirrored right
        if kind in ("power", "fist", "hook"):
            for finger in ("index", "middle", "ring", "pinky"):
                j = JOINT_INDEX[f"left_{finger}3"]
                assert J[j, 1] < J0[j, 1] - 0.01, (kind, finger)                  # towards the palm (-y)
    mean = shipped["hands_meanl"].reshape(15, 3)
    assert 0.1 < np.linalg.norm(mean, axis=1).mean() < 0.6              # a relaxed, slightly curled hand


def test_hand_pca_components_are_the_principal_axes_about_the_returned_mean(shipped):
    """hand_pca's components are the principal axes of the seeded hand poses about the returned mean (the relaxed
    template), by variance, each with its largest entry positive: scipy's eigh of the scatter about that mean."""
    J0 = shipped["J_regressor"] @ shipped["v_template"]
    comps, mean = hand_pca(J0, "right", n_per_kind=60, seed=3)
    rng = seeded_rng(3)                                          # the same draws, in the same order
    X = np.concatenate([sample_hand_poses(60, k, rng, "right", J0) for k in HAND_KINDS])
    _, U = scipy.linalg.eigh((X - mean).T @ (X - mean))          # ascending eigenvalues
    for i in range(6):                                            # the leading axes, up to sign
        assert abs(comps[i] @ U[:, -1 - i]) > 1 - 1e-6, i
    np.testing.assert_allclose(comps @ comps.T, np.eye(45), atol=1e-10)
    left, _ = hand_pca(J0, "left", n_per_kind=20, seed=0)
    assert (left[np.arange(45), np.abs(left).argmax(1)] > 0).all()


def test_hand_templates_flex_by_their_angles(shipped):
    """A template's finger flexions are its angles about the flexion axes (only hyperextension past -10 deg is
    clipped): the flat hand's fingers are straight, the pointing hand's index 5 deg at MCP and PIP, straight at DIP."""
    J0 = shipped["J_regressor"] @ shipped["v_template"]
    for side in ("left", "right"):
        axes = hand_axes(J0, side)
        flat = template_pose("flat", axes).reshape(15, 3)
        for fi, f in enumerate(FINGERS[:4]):
            np.testing.assert_allclose(flat[3 * fi + 1:3 * fi + 3], 0.0, atol=1e-12, err_msg=f"{side} {f}")
        point = template_pose("point", axes).reshape(15, 3)
        i = FINGERS.index("index")
        np.testing.assert_allclose(np.linalg.norm(point[3 * i + 1]), np.deg2rad(5.0), atol=1e-12)
        np.testing.assert_allclose(point[3 * i + 1] @ axes["flex"][3 * i + 1], np.deg2rad(5.0), atol=1e-12)
        np.testing.assert_allclose(point[3 * i + 2], 0.0, atol=1e-12)


def test_closest_point_on_triangles_matches_trimesh():
    """The build's closest_point_on_triangles (Ericson 5.1.5) agrees with trimesh in every Voronoi region of a triangle."""
    rng = np.random.default_rng(0)
    tri = rng.normal(size=(4000, 3, 3))
    p = tri.mean(1) + 2.0 * rng.normal(size=(4000, 3))            # far and near: every region gets points
    got = closest_point_on_triangles(p, tri)
    want = trimesh.triangles.closest_point(tri, p)
    np.testing.assert_allclose(got, want, atol=1e-9)
    # the edge-ab region on its own: a point beside the middle of ab, off the triangle
    t = np.array([[[0.0, 0, 0], [2.0, 0, 0], [0, 2.0, 0]]])
    np.testing.assert_allclose(closest_point_on_triangles(np.array([[0.5, -1.0, 0.3]]), t), [[0.5, 0, 0]], atol=1e-12)


def _far_joints() -> tuple[np.ndarray, np.ndarray]:
    """Joints and bone ends far from a small mesh at the origin, so that no blend of the rig reaches it."""
    joints = np.array([[100.0 + j, 100.0, 100.0] for j in range(55)])
    return joints, joints + np.array([0.0, 0.1, 0.0])


def test_smoothing_is_laplacian_averaging_with_the_neighbours():
    """skinning_weights' smoothing is Laplacian averaging w <- (w + mean of the neighbours) / 2, neighbours from
    trimesh, on a small sphere (the full build's test checks the weights only where this machine triangulates alike)."""
    mesh = trimesh.creation.icosphere(subdivisions=2)
    v, f = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    labels = np.where(v[:, 0] > 0.2, JOINT_INDEX["jaw"], JOINT_INDEX["left_eye_smplhf"])     # owners no blend touches
    joints, ends = _far_joints()
    got = skinning_weights(v, f, labels, joints, ends, Proportions(), smooth_iters=3)
    w = np.zeros((len(v), 55))
    w[np.arange(len(v)), labels] = 1.0
    nb = mesh.vertex_neighbors
    for _ in range(3):
        w = 0.5 * w + 0.5 * np.stack([w[n].mean(0) for n in nb])
    w[w < 1e-6] = 0.0
    w /= w.sum(1, keepdims=True)
    np.testing.assert_allclose(got, w, atol=1e-12)


def test_a_plane_blend_is_the_smoothstep_across_the_plane():
    """A plane blend's child weight is the smoothstep of (s + size) / (2 size) clipped to [0, 1], s the signed distance
    across the plane."""
    size = 0.05                                                       # spine1's plane blend half-width
    joints, ends = _far_joints()
    joints[JOINT_INDEX["pelvis"]] = (0.0, 0.0, 0.0)
    joints[JOINT_INDEX["spine1"]], ends[JOINT_INDEX["spine1"]] = (0.0, 0.1, 0.0), (0.0, 10.0, 0.0)
    joints[JOINT_INDEX["spine2"]], ends[JOINT_INDEX["spine2"]] = (0.0, 10.0, 0.0), (0.0, 20.0, 0.0)
    joints[JOINT_INDEX["spine3"]], ends[JOINT_INDEX["spine3"]] = (0.0, 20.0, 0.0), (0.0, 30.0, 0.0)
    y = np.linspace(0.02, 0.18, 33)
    v = np.stack([0.01 * np.cos(7 * y), y, 0.01 * np.sin(7 * y)], 1)
    f = np.array([[k, k + 1, k + 2] for k in range(len(v) - 2)])
    labels = np.where(y < 0.1, JOINT_INDEX["pelvis"], JOINT_INDEX["spine1"])
    w = skinning_weights(v, f, labels, joints, ends, Proportions(), smooth_iters=0)
    t = np.clip((y - 0.1 + size) / (2 * size), 0.0, 1.0)
    want = t * t * (3 - 2 * t)
    np.testing.assert_allclose(w[:, JOINT_INDEX["spine1"]], want, atol=1e-12)
    np.testing.assert_allclose(w[:, JOINT_INDEX["pelvis"]], 1 - want, atol=1e-12)
