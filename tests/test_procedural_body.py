"""The procedural humanoid (data_stubs/.../SMPLX_NEUTRAL.npz) against independent truths: trimesh for
topology and inside/outside, the smplx package for posing, analytic facts for shapes and hands."""
from pathlib import Path

import numpy as np
import pytest
import scipy.linalg
import smplx
import torch
import trimesh
from scipy.sparse import coo_matrix
from scipy.spatial.transform import Rotation

from graspkit.body import BodyModel
from graspkit.body import _proc_mesh as M
from graspkit.body._proc_anatomy import Proportions, rest_joints
from graspkit.body._proc_correctives import harmonic_fill, radial_target
from graspkit.body._proc_remesh import SurfaceProjector, closest_point_on_triangles, delaunay_flips, relax
from graspkit.body._proc_rig import skinning_weights
from graspkit.body._proc_sdf import Body, Ellipsoid, Floor, Lens, Loft, Sweep
from graspkit.body.hand_poses import HAND_KINDS, hand_axes, hand_pca, sample_hand_poses, template_pose
from graspkit.body.procedural import build_procedural_smplx, part_of_vertex
from graspkit.body.skeleton import FINGERS, JOINT_INDEX, NUM_VERTICES, PARENTS, SMPLX_LANDMARK_VERTEX_IDS as LMK
from graspkit.checks import seeded_rng

from conftest import jittered_plane

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


@pytest.fixture(scope="module")
def fresh_dir(fresh, tmp_path_factory) -> Path:
    """The fresh build written as `<tmp>/smplx/SMPLX_NEUTRAL.npz`, for the smplx package."""
    root = tmp_path_factory.mktemp("fresh_body_model")
    (root / "smplx").mkdir()
    np.savez(root / "smplx" / "SMPLX_NEUTRAL.npz", **fresh)
    return root


def _smplx(root: Path = MODEL_DIR, **kw):
    """The smplx package's model of the body file under root (float64, full hand pose, flat hand mean unless
    overridden)."""
    kw = {"use_pca": False, "flat_hand_mean": True, "dtype": torch.float64, **kw}
    return smplx.create(str(root), model_type="smplx", gender="neutral", ext="npz", **kw)


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
@pytest.mark.parametrize("which", ["shipped", "fresh"])
def test_landmark_vertices_sit_on_their_anatomy(which, request):
    """SMPL-X's landmark vertex ids on the shipped file and on a fresh build of seed 0: the nose the head's most
    forward point, eyes above it, ears outside, each fingertip its finger's farthest vertex along the last bone, toes
    ahead of the ankle and the heel behind it on the ground, the big toe inside the small one."""
    body = request.getfixturevalue(which)
    v = body["v_template"]
    J = body["J_regressor"] @ v
    head = v[:, 1] > J[JOINT_INDEX["neck"], 1]
    nose, leye, reye = v[LMK["nose"]], v[LMK["leye"]], v[LMK["reye"]]
    assert nose[2] == v[head, 2].max()                                   # the most forward point of the head
    assert leye[1] > nose[1] and reye[1] > nose[1] and leye[0] > 0 > reye[0]
    assert v[LMK["lear"], 0] > 0.07 and v[LMK["rear"], 0] < -0.07
    part = part_of_vertex(body)
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


def _contour(model, yaw_deg: float) -> tuple[np.ndarray, np.ndarray]:
    """smplx's 17 jaw-contour landmarks (17, 3) and the head joint (3,) with the NECK turned by yaw_deg about the
    vertical (canonical y): smplx picks the yaw bin from the neck chain (joints 12, 9, 6, 3, 0), not the head."""
    o = model(body_pose=_pose(neck=(0, np.deg2rad(yaw_deg), 0)))
    return o.joints[0, -17:].detach().numpy(), o.joints[0, JOINT_INDEX["head"]].detach().numpy()


@pytest.mark.parametrize("which", ["shipped", "fresh"])
def test_smplx_face_contour_reads_the_yaw_bins_in_smplx_order(which, fresh_dir):
    """smplx (lbs.find_dynamic_lmk_idx_and_bcoords) reads the 79 contour bins as yaw 0, +1..+39, -1..-39, the jaw
    line seen from the front (+z): at rest it must be symmetric about the face (right ear -> chin -> left ear mirrors
    onto itself, x -> -x); with the neck turned by +-25 deg the chin point turns the same way by less than the turn,
    every point stays on the camera-facing half (< 90 deg round from +z about the head joint), and the two turns are
    mirror images. On the shipped file and on a fresh build of seed 0."""
    model = _smplx(MODEL_DIR if which == "shipped" else fresh_dir, use_face_contour=True)
    mirror = lambda c: c[::-1] * np.array([-1.0, 1.0, 1.0])  # noqa: E731
    rest = _contour(model, 0)[0]
    assert abs(rest[8, 0]) < 3e-3                              # the chin on the midline
    assert np.abs(rest - mirror(rest)).max() < 4e-3
    for yaw in (10.0, 25.0):
        assert np.abs(_contour(model, yaw)[0] - mirror(_contour(model, -yaw)[0])).max() < 4e-3
    for yaw in (-25.0, 25.0):
        c, head = _contour(model, yaw)
        angle = np.degrees(np.arctan2(c[:, 0] - head[0], c[:, 2] - head[2]))
        assert 0 < angle[8] * np.sign(yaw) < abs(yaw), (yaw, angle)
        assert np.abs(angle).max() < 90.0, (yaw, angle)


def _cone_volume(v: np.ndarray, faces: np.ndarray, centre: np.ndarray) -> float:
    """Signed volume of the cones from centre (3,) to the faces (F, 3) of vertices v (V, 3)."""
    t = v[faces] - centre
    return float(np.einsum("ij,ij->i", t[:, 0], np.cross(t[:, 1], t[:, 2])).sum() / 6)


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

    change = _cone_volume(v1, f[near], J1[c]) / _cone_volume(v0, f[near], J0[c]) - 1
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


# pseudo-vector mirror of a hand pose (45,): each joint's axis-angle r -> -M r, M = diag(-1, 1, 1)
_MIRROR45 = np.tile([1.0, -1.0, -1.0], 15)


# ----------------------------------------------------------------------------- regressor and weights
def test_fresh_regressor_hits_the_designed_rest_joints(fresh):
    """J_regressor @ v_template is the designed rest skeleton (rest_joints of seed 0's proportions) to 1e-8 m, each
    row a convex combination."""
    R, v = fresh["J_regressor"], fresh["v_template"]
    np.testing.assert_allclose(R @ v, rest_joints(Proportions().jittered(0)), rtol=0, atol=1e-8)
    assert R.min() >= 0 and np.allclose(R.sum(1), 1.0)


def _mid_segment(v: np.ndarray, a: np.ndarray, b: np.ndarray, radius: float) -> np.ndarray:
    """Mask of vertices within `radius` of the segment a-b's axis whose projection falls in its middle third."""
    u = (b - a) / np.linalg.norm(b - a)
    s = (v - a) @ u / np.linalg.norm(b - a)
    lateral = np.linalg.norm((v - a) - np.outer((v - a) @ u, u), axis=1)
    return (s > 1 / 3) & (s < 2 / 3) & (lateral < radius)


def test_fresh_weights_give_each_limb_segment_to_its_bone(fresh):
    """The dominant skinning joint of the middle third of each limb segment is the joint driving that bone (upper arm:
    shoulder, forearm: elbow, thigh: hip, shank: knee, both sides), and each fingertip, toe and heel landmark vertex
    belongs to its finger's last joint, its foot and ankle."""
    v, J0 = fresh["v_template"], fresh["J_regressor"] @ fresh["v_template"]
    part = part_of_vertex(fresh)
    for side in ("left", "right"):
        for a, b, r in (("shoulder", "elbow", 0.07), ("elbow", "wrist", 0.06), ("hip", "knee", 0.10),
                        ("knee", "ankle", 0.07)):
            ja, jb = JOINT_INDEX[f"{side}_{a}"], JOINT_INDEX[f"{side}_{b}"]
            mid = _mid_segment(v, J0[ja], J0[jb], r)
            assert mid.sum() > 20, (side, a)
            assert (part[mid] == ja).mean() > 0.95, (side, a, np.bincount(part[mid]))
        s = side[0]
        for finger in FINGERS:
            assert part[LMK[s + finger]] == JOINT_INDEX[f"{side}_{finger}3"], (side, finger)
        S = s.upper()
        assert part[LMK[f"{S}Heel"]] == JOINT_INDEX[f"{side}_ankle"]
        assert part[LMK[f"{S}BigToe"]] == JOINT_INDEX[f"{side}_foot"]


def test_cone_weight_turns_a_vertex_linearly_with_its_cone_angle():
    """_cone_weight (private: skinning_weights applies it to the fresh mesh only) gives the child weight t whose turn
    angle psi = atan(t / (1 - t)) for a 90 deg bend grows linearly from 0 at alpha = 90 + beta to 90 deg at 90 - beta
    (docs/body_model.md, step 5): t = 0 beyond, 1/2 on the joint plane (alpha = 90), 1 past 90 - beta."""
    from graspkit.body._proc_rig import _cone_weight
    beta = 55.0
    alpha = np.linspace(90 - beta, 90 + beta, 23)
    t = _cone_weight(alpha, beta)
    psi = np.degrees(np.arctan2(t, 1 - t))
    np.testing.assert_allclose(psi, 90 * (90 + beta - alpha) / (2 * beta), atol=1e-9)
    np.testing.assert_allclose(_cone_weight(np.array([0.0, 20.0, 90.0, 160.0, 180.0]), beta), [1, 1, 0.5, 0, 0],
                               atol=1e-12)


# ----------------------------------------------------------------------------- shape space
def _dJ(a: dict, i: int) -> np.ndarray:
    """Joint displacement (55, 3) per unit of shape component i."""
    return a["J_regressor"] @ a["shapedirs"][:, :, i]


def test_fresh_height_component_scales_about_the_pelvis_joint(fresh):
    """beta_0 is a uniform 5 % scale about the pelvis joint (docs/body_model.md): the pelvis stays, every joint moves
    by 0.05 (J - J_pelvis), and the stature at beta_0 = -2 / +2 is 0.9 / 1.1 times the rest stature."""
    v, J0 = fresh["v_template"], fresh["J_regressor"] @ fresh["v_template"]
    np.testing.assert_allclose(_dJ(fresh, 0), 0.05 * (J0 - J0[0]), rtol=0, atol=1e-9)
    h = np.ptp(v[:, 1])
    for b in (-2.0, 2.0):
        assert np.ptp((v + b * fresh["shapedirs"][:, :, 0])[:, 1]) == pytest.approx((1 + 0.05 * b) * h, rel=1e-9)


def test_fresh_girth_grows_cross_sections_not_lengths(fresh):
    """beta_1 grows cross-sections about the bone axes: limb joints stay within 1 mm, trunk vertices do not move
    vertically, and the belly front moves forward at least 2 cm per unit (docs: 'belly forward 2 cm')."""
    dJ = _dJ(fresh, 1)
    for n in ("elbow", "wrist", "knee", "ankle"):
        for side in ("left", "right"):
            assert np.linalg.norm(dJ[JOINT_INDEX[f"{side}_{n}"]]) < 1e-3, (side, n, dJ[JOINT_INDEX[f"{side}_{n}"]])
    v, w, S = fresh["v_template"], fresh["weights"], fresh["shapedirs"][:, :, 1]
    trunk = w[:, [JOINT_INDEX[n] for n in ("pelvis", "spine1", "spine2", "spine3")]].sum(1) > 0.999
    assert np.abs(S[trunk, 1]).max() < 1e-4
    belly = trunk & (np.abs(v[:, 0]) < 0.03) & (np.abs(v[:, 1] + 0.20) < 0.03)
    front = np.nonzero(belly)[0][v[belly, 2].argmax()]
    assert S[front, 2] > 0.02, S[front]


def test_fresh_shoulder_width_moves_each_arm_outwards(fresh):
    """beta_2 moves each arm out by 2.2 cm per unit (docs): left arm joints +x, right arm joints -x, nothing else."""
    dJ = _dJ(fresh, 2)
    for side, sign in (("left", 1.0), ("right", -1.0)):
        for n in ["elbow", "wrist"] + [f"{f}{k}" for f in FINGERS for k in (1, 2, 3)]:
            np.testing.assert_allclose(dJ[JOINT_INDEX[f"{side}_{n}"]], (0.022 * sign, 0, 0), atol=1e-6,
                                       err_msg=f"{side}_{n}")


def test_fresh_hip_width_moves_vertices_sideways_and_outwards_only(fresh):
    """beta_3 stretches the pelvis sideways (docs: '10 % per unit, the legs follow by 0.5 cm'): every vertex moves
    along x only, away from the midline, and the hip joints by 0.5 cm."""
    S, v = fresh["shapedirs"][:, :, 3], fresh["v_template"]
    assert np.abs(S[:, 1:]).max() < 1e-12
    off = np.abs(v[:, 0]) > 0.03                          # (a crotch vertex of the other leg may cross the midline)
    assert (S[off, 0] * np.sign(v[off, 0]) >= -1e-12).all()
    dJ = _dJ(fresh, 3)
    assert dJ[JOINT_INDEX["left_hip"], 0] == pytest.approx(0.005, abs=1e-3)
    assert dJ[JOINT_INDEX["right_hip"], 0] == pytest.approx(-0.005, abs=1e-3)


@pytest.mark.parametrize("i, a, bones", [(4, 0.04, ("shoulder", "elbow", "wrist")), (5, 0.045, ("hip", "knee", "ankle"))])
def test_fresh_limb_length_components_stretch_both_bones(fresh, i, a, bones):
    """beta_4 / beta_5 stretch the upper and lower bone of each limb by 4 % / 4.5 % along the bone (docs), so the distal
    joint moves by a times the (straight) limb's whole length and the hand or foot follows."""
    J0 = fresh["J_regressor"] @ fresh["v_template"]
    dJ = _dJ(fresh, i)
    for side in ("left", "right"):
        r, m, d = (JOINT_INDEX[f"{side}_{b}"] for b in bones)
        for j, L0 in ((m, J0[m] - J0[r]), (d, J0[d] - J0[m])):
            u = L0 / np.linalg.norm(L0)
            base = dJ[r] if j == m else dJ[m]
            assert (dJ[j] - base) @ u == pytest.approx(a * np.linalg.norm(L0), rel=0.1), (side, j)
        assert np.linalg.norm(dJ[d] - dJ[r]) == pytest.approx(a * np.linalg.norm(J0[d] - J0[r]), rel=0.1)


def test_fresh_torso_length_is_vertical_and_the_head_follows_the_neck(fresh):
    """beta_6 stretches the trunk between pelvis and neck by 5 % (docs): every vertex moves vertically only, and the
    head, jaw and eyes ride on the stretched trunk's top: dy = 0.05 (y_neck - y_pelvis)."""
    S = fresh["shapedirs"][:, :, 6]
    assert np.abs(S[:, [0, 2]]).max() < 1e-12
    J0 = fresh["J_regressor"] @ fresh["v_template"]
    dJ = _dJ(fresh, 6)
    want = 0.05 * (J0[JOINT_INDEX["neck"], 1] - J0[0, 1])
    for n in ("head", "jaw", "left_eye_smplhf", "right_eye_smplhf"):
        assert dJ[JOINT_INDEX[n], 1] == pytest.approx(want, abs=5e-4), n


def test_fresh_head_size_scales_about_the_head_joint(fresh):
    """beta_7 scales head, jaw and eyes 4 % about the head joint (docs): vertices wholly of the head move by
    0.04 (v - J_head), so the head joint itself stays within 1.5 mm (its regressor also reads neck vertices)."""
    v, w, S = fresh["v_template"], fresh["weights"], fresh["shapedirs"][:, :, 7]
    J0 = fresh["J_regressor"] @ v
    head = w[:, [JOINT_INDEX[n] for n in ("head", "jaw")]].sum(1) > 1 - 1e-12
    np.testing.assert_allclose(S[head], 0.04 * (v[head] - J0[JOINT_INDEX["head"]]), atol=1e-9)
    assert np.linalg.norm(_dJ(fresh, 7)[JOINT_INDEX["head"]]) < 1.5e-3


def test_fresh_chest_depth_moves_the_front_and_keeps_the_back(fresh):
    """beta_8: the chest moves forward, the back stays (docs): the front of the upper chest moves > 1 cm per unit along
    +z, the back of the chest not at all, and nothing moves sideways or vertically."""
    v, w, S = fresh["v_template"], fresh["weights"], fresh["shapedirs"][:, :, 8]
    chest = w[:, [JOINT_INDEX["spine2"], JOINT_INDEX["spine3"]]].sum(1) > 0.9
    front = np.nonzero(chest)[0][v[chest, 2].argmax()]
    back = chest & (v[:, 2] < -0.10)
    assert S[front, 2] > 0.01
    assert back.sum() > 10 and np.abs(S[back]).max() < 1e-12
    assert np.abs(S[:, :2]).max() < 1e-12


def test_fresh_muscularity_slims_the_waist(fresh):
    """beta_9: 'waist a little slimmer' (docs): vertices of the lower spine (spine1 part) move towards the vertical
    axis through spine1."""
    v, w, S = fresh["v_template"], fresh["weights"], fresh["shapedirs"][:, :, 9]
    J0 = fresh["J_regressor"] @ v
    waist = w[:, JOINT_INDEX["spine1"]] > 0.9
    radial = v[waist] - J0[JOINT_INDEX["spine1"]]
    radial[:, 1] = 0.0
    assert waist.sum() > 20 and ((S[waist] * radial).sum(1) < 0).mean() > 0.95


# ----------------------------------------------------------------------------- expressions
def test_fresh_expressions_are_left_right_symmetric(fresh):
    """Every expression is symmetric about the face's midline: the summed sideways displacements of the left (x > 0) and
    right (x < 0) halves are opposite to within 25 % of their size (the face mesh is mirror-symmetric only up to its
    triangulation, a few mm), and the vertex the mouth-open component moves most moves down."""
    S, x = fresh["shapedirs"][:, :, 10:], fresh["v_template"][:, 0]
    for i in range(10):
        left, right = S[x > 0, 0, i].sum(), S[x < 0, 0, i].sum()
        assert abs(left + right) <= 0.25 * (abs(left) + abs(right)), (i, left, right)
    jaw = S[:, :, 0]
    k = np.linalg.norm(jaw, axis=1).argmax()
    assert jaw[k, 1] < 0, jaw[k]


# ----------------------------------------------------------------------------- face landmarks
def _static_landmarks(a: dict) -> np.ndarray:
    """The 51 static face landmarks (51, 3) of arrays a at rest (barycentric points of lmk_faces_idx)."""
    tri = a["v_template"][a["f"][a["lmk_faces_idx"]]]
    return np.einsum("lk,lkd->ld", a["lmk_bary_coords"], tri)


def test_fresh_face_landmarks_run_from_the_subjects_right_to_left(fresh):
    """iBUG-68 order (points 17..67 stored as 0..50): brows and nostrils run from -x to +x, and so do the eye corners
    (36 outer -> 39 inner on the right eye, 42 inner -> 45 outer on the left); the outer lip contour starts at the
    right mouth corner, runs over the upper lip to the left corner, and its 51 (upper lip) is above its 57 (lower)."""
    p = _static_landmarks(fresh)
    for lo, hi in ((17, 21), (22, 26), (31, 35)):
        assert (np.diff(p[lo - 17:hi - 16, 0]) > 0).all(), (lo, hi)
    assert p[36 - 17, 0] < p[39 - 17, 0] < p[42 - 17, 0] < p[45 - 17, 0]
    outer = p[48 - 17:60 - 17]
    assert outer[0, 0] == outer[:, 0].min() and outer[6, 0] == outer[:, 0].max()      # corners 48 and 54
    assert (np.diff(outer[0:7, 0]) > 0).all() and outer[3, 1] > outer[9, 1]           # 51 above 57


# ----------------------------------------------------------------------------- pose correctives
def test_fresh_correctives_sit_only_in_the_elbow_knee_and_hip_slots(fresh):
    """posedirs (V, 3, 486) has nine columns per joint 1..54 ((j - 1) 9 .. j 9, SMPL-X's layout); the fitted
    correctives fill exactly the slots of the elbows, knees and hips, and each of the six is non-zero."""
    P = fresh["posedirs"].reshape(len(fresh["v_template"]), 3, 54, 9)
    used = {j + 1 for j in range(54) if np.abs(P[:, :, j]).max() > 0}
    want = {JOINT_INDEX[f"{s}_{n}"] for s in ("left", "right") for n in ("elbow", "knee", "hip")}
    assert used == want


@pytest.mark.parametrize("joint, aa, radius", [("left_elbow", (0, -np.pi / 2, 0), 0.12),
                                               ("right_elbow", (0, np.pi / 2, 0), 0.12),
                                               ("left_knee", (np.pi / 2, 0, 0), 0.15),
                                               ("right_knee", (np.pi / 2, 0, 0), 0.15)])
def test_fresh_correctives_keep_the_volume_of_a_90_degree_bend(fresh, fresh_dir, joint, aa, radius):
    """smplx posing the fresh build: the local volume near a 90 deg elbow or knee (cones from the joint to the faces
    within 12 / 15 cm) changes by < 10 % with the correctives and by at least 5 points less than with plain LBS
    (posedirs zeroed; docs: about -5 % against about -20 %)."""
    bm = _smplx(fresh_dir)
    f = fresh["f"]
    c = JOINT_INDEX[joint]
    pose = _pose(**{joint: aa})
    rest = bm()
    v0, J0 = rest.vertices[0].detach().numpy(), rest.joints[0].detach().numpy()
    near = (np.linalg.norm(v0 - J0[c], axis=1) < radius)[f].all(1)

    def change(model):
        o = model(body_pose=pose)
        v1, J1 = o.vertices[0].detach().numpy(), o.joints[0].detach().numpy()
        return _cone_volume(v1, f[near], J1[c]) / _cone_volume(v0, f[near], J0[c]) - 1

    with_correctives = change(bm)
    bm.posedirs.zero_()
    plain = change(bm)
    assert abs(with_correctives) < 0.10 and abs(with_correctives) < abs(plain) - 0.05, (with_correctives, plain)


def test_harmonic_fill_interpolates_linearly_along_a_path():
    """harmonic_fill on a path graph: the known ends are kept, the unknown interior is the discrete harmonic (linear)
    interpolation between them, and rows outside the region are zero."""
    n = 7
    i = np.arange(n - 1)
    A = coo_matrix((np.ones(2 * (n - 1)), (np.r_[i, i + 1], np.r_[i + 1, i])), shape=(n, n)).tocsr()
    delta = np.zeros((n, 3))
    delta[0], delta[5] = (1.0, 2.0, -1.0), (6.0, -3.0, 4.0)
    region = np.arange(6)                                     # vertex 6 lies outside
    known = np.array([True, False, False, False, False, True])
    out = harmonic_fill(delta, known, region, A)
    want = np.outer(1 - np.arange(6) / 5, delta[0]) + np.outer(np.arange(6) / 5, delta[5])
    np.testing.assert_allclose(out[:6], want, atol=1e-12)
    np.testing.assert_allclose(out[6], 0.0)


def test_radial_target_moves_points_onto_a_sphere_along_rays_from_the_axis():
    """radial_target on a sphere of radius 0.05 about the z axis through its centre: points inside and outside the
    surface move along their ray from the axis onto the sphere (height along the axis kept)."""
    r = 0.05
    body = Body([Ellipsoid((0.0, 0.0, 0.0), (r, r, r), joint=0)], Floor(-10.0, 0.0))
    pose = (np.tile(np.eye(3), (55, 1, 1)), np.zeros((55, 3)))
    ang = np.linspace(0, 2 * np.pi, 9)[:-1]
    rho = np.array([0.035, 0.040, 0.043, 0.050, 0.055, 0.038, 0.048, 0.060])    # the surface is at 0.0458
    x = np.stack([rho * np.cos(ang), rho * np.sin(ang), np.full(8, 0.02)], 1)
    y, ok = radial_target(x, np.zeros(3), np.array([0.0, 0.0, 1.0]), body, pose, max_move=0.05)
    assert ok.all()
    want_rho = np.sqrt(r ** 2 - 0.02 ** 2)
    np.testing.assert_allclose(np.linalg.norm(y[:, :2], axis=1), want_rho, atol=1e-5)
    np.testing.assert_allclose(np.arctan2(y[:, 1], y[:, 0]), np.arctan2(x[:, 1], x[:, 0]), atol=1e-9)
    np.testing.assert_allclose(y[:, 2], 0.02, atol=1e-12)


def test_posed_body_carries_each_primitive_rigidly_with_its_joint():
    """Body.evaluate with a pose (R, t) per joint: the distance at R x + t equals the rest distance at x (x_posed =
    R x_rest + t), for a rotation that is not its own inverse."""
    e = Ellipsoid((0.3, 0.1, 0.0), (0.08, 0.03, 0.05), joint=5)
    body = Body([e], Floor(-10.0, 0.0))
    R = Rotation.from_rotvec([0.3, -0.7, 0.5]).as_matrix()
    Rs, ts = np.tile(np.eye(3), (55, 1, 1)), np.zeros((55, 3))
    Rs[5], ts[5] = R, (0.05, -0.02, 0.1)
    x = e.c + np.random.default_rng(0).normal(scale=0.05, size=(200, 3))
    rest, _ = body.evaluate(x)
    posed, _ = body.evaluate(x @ R.T + ts[5], (Rs, ts))
    np.testing.assert_allclose(posed, rest, atol=1e-12)


# ----------------------------------------------------------------------------- signed distances and lenses
def test_sweep_and_loft_caps_reach_as_far_as_stated():
    """A Sweep's rounded ends reach caps[0] before a and caps[1] beyond b, and its first semi-axis runs from sa[0] at a
    to sb[0] at b; a Loft's caps reach caps[0] below its first section and caps[1] above its last."""
    s = Sweep((0.0, 0.0, 0.0), (0.2, 0.0, 0.0), (0.02, 0.03), (0.04, 0.05), up=(0.0, 1.0, 0.0), caps=(0.01, 0.03))
    pts = np.array([[-0.01, 0, 0], [0.23, 0, 0], [0, 0.02, 0], [0.2, 0.04, 0], [0.1, 0.03, 0]])
    np.testing.assert_allclose(s.sdf(pts), 0.0, atol=1e-12)
    loft = Loft(np.array([[-0.1, 0.10, 0.08, 0.0], [0.1, 0.12, 0.09, 0.0]]), caps=(0.04, 0.02))
    np.testing.assert_allclose(loft.sdf(np.array([[0, -0.14, 0], [0, 0.12, 0]])), 0.0, atol=1e-12)


def test_lens_is_a_c1_round_trip_with_the_stated_magnification():
    """A bubble lens maps the u-ball of radius r0 onto the world ball r0 / m (magnification m), is the identity beyond
    r1, has a continuous radial derivative at r0 and r1 (C1: 1 / m inside r0, 1 outside r1), and
    inverse(forward(u)) = u."""
    lens = Lens((0.1, 0.2, 0.3), 0.2875, 0.60, 2.5)
    r0, r1, m = lens.r0, lens.r1, lens.m
    e = 1e-7
    for r, slope in ((r0, 1 / m), (r1, 1.0)):
        d_lo = (lens.rho(np.array([r])) - lens.rho(np.array([r - e])))[0] / e
        d_hi = (lens.rho(np.array([r + e])) - lens.rho(np.array([r])))[0] / e
        assert d_lo == pytest.approx(d_hi, rel=1e-4) and d_lo == pytest.approx(slope, rel=1e-4), r
    assert lens.rho(np.array([0.1, r0]))[0:2] == pytest.approx([0.1 / m, r0 / m])
    assert lens.rho(np.array([r1 + 0.01, r1 + 0.3])) == pytest.approx([r1 + 0.01, r1 + 0.3])
    u = np.asarray(lens.c) + np.random.default_rng(0).normal(scale=0.3, size=(500, 3))
    np.testing.assert_allclose(lens.inverse(lens.forward(u)), u, atol=1e-9)


# ----------------------------------------------------------------------------- mesh checks and remeshing
def test_topology_report_flags_an_edge_shared_by_four_faces():
    """Two tetrahedra sharing one edge: each is closed, together they are not an edge-manifold surface (an edge in four
    faces), as trimesh says too."""
    tet = trimesh.Trimesh([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    assert M.topology_report(tet.vertices, tet.faces)["watertight"] and tet.is_watertight
    other = trimesh.Trimesh([[0, 0, 0], [1, 0, 0], [0, -1, 0], [0, 0, -1]], [[0, 1, 2], [0, 3, 1], [0, 2, 3], [1, 3, 2]])
    both = trimesh.util.concatenate([tet, other])
    both.merge_vertices()
    assert not both.is_watertight
    assert not M.topology_report(np.asarray(both.vertices), np.asarray(both.faces))["watertight"]


def test_split_longest_edges_splits_the_longest_edge_at_its_midpoint():
    """One split of a closed tetrahedron adds the midpoint of its longest edge, keeps the surface (same volume) and the
    mesh closed and oriented."""
    v = np.array([[0.0, 0, 0], [3.0, 0, 0], [0, 1.0, 0], [0, 0, 2.0]])
    f = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    assert M.signed_volume(v, f) > 0
    v2, f2 = M.split_longest_edges(v, f, 5)
    np.testing.assert_allclose(v2[4], (1.5, 0.0, 1.0))                 # edge (3,0,0)-(0,0,2) is the longest
    assert M.signed_volume(v2, f2) == pytest.approx(M.signed_volume(v, f))
    mesh = trimesh.Trimesh(v2, f2, process=False)
    assert mesh.is_watertight and mesh.is_winding_consistent


@pytest.mark.parametrize("flip_a", [False, True])
@pytest.mark.parametrize("flip_b", [False, True])
@pytest.mark.parametrize("swap", [False, True])
def test_self_intersections_find_piercing_and_interlocking_triangles(flip_a, flip_b, swap):
    """Two triangles that cross are one intersecting pair, whatever the winding of either and the order of the two
    faces: a small triangle piercing a large one (only the small one's edges cross the other) and two interlocking
    triangles (one edge of each crosses the other); moved apart, none."""
    big = np.array([[-1.0, -1, 0], [1, -1, 0], [0, 1, 0]])
    cases = [
        (big, np.array([[0, -0.1, -0.2], [0.1, 0.1, 0.3], [-0.1, 0.1, 0.3]])),              # piercing
        (np.array([[0.0, 0, 0], [2, 0, 0], [1, 2, 0]]), np.array([[1.0, 1, -1], [1, 1, 1], [3, 1, 0.1]])),  # interlocking
    ]
    for a, b in cases:
        a, b = (a[::-1] if flip_a else a), (b[::-1] if flip_b else b)
        v = np.concatenate([a, b])
        f = np.array([[3, 4, 5], [0, 1, 2]] if swap else [[0, 1, 2], [3, 4, 5]])
        assert len(M.self_intersections(v, f)) == 1
        v[3:, 2] += 5.0
        assert len(M.self_intersections(v, f)) == 0


def test_delaunay_flips_restore_a_planar_delaunay_triangulation():
    """On a jittered planar grid, scipy's Delaunay triangulation with one interior edge flipped the wrong way comes back
    to the Delaunay triangulation after delaunay_flips, and an already Delaunay one is left as it is."""
    v, tri = jittered_plane(7, seed=4)                                   # counter-clockwise, seen from +z
    p = v[:, :2]
    key = lambda f: {tuple(sorted(t)) for t in f.tolist()}  # noqa: E731
    assert key(delaunay_flips(v, tri)) == key(tri)
    centre = np.argmin(np.linalg.norm(p - p.mean(0), axis=1))           # an interior vertex
    f1 = next(i for i in range(len(tri)) if centre in tri[i])
    a = tri[f1][(list(tri[f1]).index(centre) + 1) % 3]
    f2 = next(i for i in range(len(tri)) if i != f1 and centre in tri[i] and a in tri[i])
    c = next(x for x in tri[f1] if x not in (centre, a))
    d = next(x for x in tri[f2] if x not in (centre, a))
    bad = tri.copy()
    # the wrong diagonal c-d of the quad (centre, a, c, d), both faces counter-clockwise
    for i, (x, y, z) in ((f1, (c, d, centre)), (f2, (d, c, a))):
        t = np.array([x, y, z])
        nz = np.cross(v[t[1]] - v[t[0]], v[t[2]] - v[t[0]])[2]
        bad[i] = t if nz > 0 else t[::-1]
    assert key(bad) != key(tri)
    assert key(delaunay_flips(v, bad)) == key(tri)


def test_relax_keeps_the_vertices_on_the_reference_surface():
    """Tangential relaxation of a jittered sphere mesh, projected onto a fine sphere of radius 1, leaves every vertex on
    that sphere (within the fine mesh's chordal error)."""
    fine = trimesh.creation.icosphere(subdivisions=5)
    coarse = trimesh.creation.icosphere(subdivisions=2)
    rng = np.random.default_rng(2)
    v = coarse.vertices + rng.normal(scale=0.04, size=coarse.vertices.shape)
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    out = relax(v, np.asarray(coarse.faces), SurfaceProjector(np.asarray(fine.vertices), np.asarray(fine.faces)),
                iters=3)
    r = np.linalg.norm(out, axis=1)
    assert np.abs(r - 1).max() < 2e-3
    assert np.linalg.norm(out - v, axis=1).max() > 1e-3                 # it did move


# ----------------------------------------------------------------------------- hands
def _rot_about(axis: np.ndarray, deg: float) -> np.ndarray:
    """Rotation matrix (3, 3) by deg degrees about the unit axis (scipy)."""
    return Rotation.from_rotvec(np.deg2rad(deg) * axis).as_matrix()


@pytest.mark.parametrize("side", ["left", "right"])
def test_hand_axes_bend_towards_the_palm_and_spread_towards_the_thumb(side):
    """With the procedural humanoid's rest joints: a positive rotation about a finger joint's flexion axis moves the next joint
    towards the palm (-y in the rest pose, both hands), about the MCP's spread axis moves the finger tip towards the
    thumb side, and about the thumb's abduction axis moves the thumb tip out of the palm plane to the palm side."""
    J0 = rest_joints(Proportions().jittered(0))
    ax = hand_axes(J0, side)
    j = lambda n: J0[JOINT_INDEX[f"{side}_{n}"]]  # noqa: E731
    thumb_side = j("index1") - j("pinky1")
    for fi, f in enumerate(FINGERS[:4]):
        for k in (1, 2):
            base, nxt = j(f"{f}{k}"), j(f"{f}{k + 1}")
            moved = base + _rot_about(ax["flex"][3 * fi + k - 1], 20) @ (nxt - base)
            assert moved[1] < nxt[1] - 1e-3, (f, k)
        base, tip = j(f"{f}1"), j(f"{f}3")
        moved = base + _rot_about(ax["spread"][3 * fi], 10) @ (tip - base)
        assert (moved - tip) @ thumb_side > 0, f
    base, tip = j("thumb1"), j("thumb3")
    moved = base + _rot_about(ax["abduct"], 20) @ (tip - base)
    assert moved[1] < tip[1] - 1e-3


def test_thumb_template_flexions_are_about_the_thumb_flexion_axes():
    """As for the fingers (test_hand_templates_flex_by_their_angles): a template's thumb MCP and IP flexions are its
    angles about those joints' own flexion axes (the pointing hand: 30 and 30 deg)."""
    J0 = rest_joints(Proportions().jittered(0))
    for side in ("left", "right"):
        axes = hand_axes(J0, side)
        point = template_pose("point", axes).reshape(15, 3)
        np.testing.assert_allclose(point[13], np.deg2rad(30.0) * axes["flex"][13], atol=1e-12)
        np.testing.assert_allclose(point[14], np.deg2rad(30.0) * axes["flex"][14], atol=1e-12)


def test_hand_pca_mean_is_the_relaxed_template_and_the_sides_mirror():
    """hand_pca's mean is the relaxed template of that side's axes (docs: 'as SMPL-X's hands_mean'), and the left hand's
    components are the right hand's mirrored as pseudo-vectors (-M r per joint), up to sign, as the draws are equal."""
    J0 = rest_joints(Proportions().jittered(0))
    cl, ml = hand_pca(J0, "left", n_per_kind=40, seed=5)
    cr, mr = hand_pca(J0, "right", n_per_kind=40, seed=5)
    np.testing.assert_allclose(ml, template_pose("relaxed", hand_axes(J0, "left")), atol=1e-12)
    np.testing.assert_allclose(mr, template_pose("relaxed", hand_axes(J0, "right")), atol=1e-12)
    for i in range(6):
        assert abs(cl[i] @ (cr[i] * _MIRROR45)) > 1 - 1e-8, i


def test_fresh_hand_pca_arrays_belong_to_their_side(fresh):
    """The fresh file's hands_mean{l,r} and hands_components{l,r} are the left and right hands' own: the means mirror
    each other as pseudo-vectors and are each side's relaxed template; component i of the left hand is the mirror of
    component i of the right, up to sign."""
    J0 = fresh["J_regressor"] @ fresh["v_template"]
    np.testing.assert_allclose(fresh["hands_meanl"], template_pose("relaxed", hand_axes(J0, "left")), atol=1e-12)
    np.testing.assert_allclose(fresh["hands_meanr"], template_pose("relaxed", hand_axes(J0, "right")), atol=1e-12)
    np.testing.assert_allclose(fresh["hands_meanl"], fresh["hands_meanr"] * _MIRROR45, atol=1e-9)
    cl, cr = fresh["hands_componentsl"], fresh["hands_componentsr"]
    for i in range(6):
        assert abs(cl[i] @ (cr[i] * _MIRROR45)) > 1 - 1e-6, i
