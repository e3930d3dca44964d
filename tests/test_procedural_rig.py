"""The procedural body's rig builder (_proc_rig: skinning weights, joint regressor, shape and expression bases) and
pose correctives (_proc_correctives) against independent truths: mirror symmetry, hand-computed blends, the documented
shape fields, scipy rotations, exactly linear data recovered by the fit."""
import functools

import numpy as np
import pytest
from scipy.sparse import coo_matrix
from scipy.spatial.transform import Rotation

from graspkit.body import _proc_correctives as C
from graspkit.body._proc_anatomy import Proportions, body_plan, mirror_joint, rest_joints
from graspkit.body._proc_rig import (_tilt, bone_ends, expression_basis, joint_regressor, shape_basis,
                                     skinning_weights)
from graspkit.body._proc_sdf import Body, Ellipsoid, Floor
from graspkit.body.skeleton import JOINT_INDEX as JI, JOINT_NAMES, NUM_JOINTS, PARENTS
from graspkit.paths import DATA_STUBS

MODEL = DATA_STUBS / "body_models" / "smplx" / "SMPLX_NEUTRAL.npz"
PERM = np.array([mirror_joint(j) for j in range(NUM_JOINTS)])          # left <-> right joint indices
MX = np.array([-1.0, 1.0, 1.0])                                           # the mirror x -> -x


@functools.lru_cache(maxsize=None)
def _shipped():
    """The shipped arrays, seed 0's proportions, its designed rest joints and bone ends."""
    with np.load(MODEL, allow_pickle=False) as z:
        a = {k: z[k] for k in z.files}
    P = Proportions().jittered(0)
    J0 = rest_joints(P)
    return a, P, J0, bone_ends(P, J0)


@functools.lru_cache(maxsize=None)
def _mirrored_half():
    """A mirror-symmetric body from the shipped mesh: its faces wholly on the left (x > 1 mm), their vertices, and the
    mirror image of both; the second half's vertex i is the mirror of the first half's vertex i."""
    a, P, J0, E0 = _shipped()
    v, f = a["v_template"], a["f"]
    keep = f[(v[f, 0] > 1e-3).all(1)]
    ids = np.unique(keep)
    new = -np.ones(len(v), int)
    new[ids] = np.arange(len(ids))
    n = len(ids)
    vs = np.concatenate([v[ids], v[ids] * MX])
    fs = np.concatenate([new[keep], new[keep][:, ::-1] + n])
    return vs, fs, n, ids


def _pure(w: np.ndarray, joints) -> np.ndarray:
    """Mask of the vertices whose whole skinning weight lies on the given joints."""
    return w[:, list(joints)].sum(1) > 1 - 1e-12


# ----------------------------------------------------------------------------- skinning weights
def test_skinning_weights_of_a_mirrored_body_are_the_mirrored_weights():
    """skinning_weights on a mirror-symmetric mesh (the shipped left half and its mirror image, owners from the body's
    own signed-distance field, mirrored for the right half) with seed 0's skeleton (exactly symmetric): away from the
    midline the weight of a right vertex on joint j is its left twin's weight on j's mirror joint, and rows are convex
    (docs: everything is written for the left side and mirrored)."""
    a, P, J0, E0 = _shipped()
    vs, fs, n, _ = _mirrored_half()
    body, _, _ = body_plan(P)
    _, owner = body.evaluate(vs[:n])
    lab = np.array([body.prims[o].joint if o >= 0 else JI["head"] for o in owner])
    labels = np.concatenate([lab, PERM[lab]])
    w = skinning_weights(vs, fs, labels, J0, E0, P, smooth_iters=0)
    assert w.min() >= 0 and np.allclose(w.sum(1), 1.0, atol=1e-12)
    side = vs[:n, 0] > 0.06        # near the midline the left blends (hip, collar) run before the right ones
    assert side.sum() > 3000, side.sum()
    np.testing.assert_allclose(w[n:][side], w[:n][side][:, PERM], atol=1e-9)
    assert np.abs(w[:, [JI["left_eye_smplhf"], JI["right_eye_smplhf"]]]).max() == 0.0   # docs: eyes carry no skin


def _rig_far() -> tuple[np.ndarray, np.ndarray]:
    """Joints and bone ends far from the origin, so that no blend of the rig reaches points near it."""
    joints = np.array([[100.0 + j, 100.0, 100.0] for j in range(55)])
    return joints, joints + np.array([0.0, 0.1, 0.0])


def _strip(n: int) -> np.ndarray:
    """Faces of a triangle strip over n vertices (only for the adjacency; smoothing is off)."""
    return np.array([[k, k + 1, k + 2] for k in range(n - 2)])


def _smoothstep(t):
    """Cubic smoothstep of t clipped to [0, 1]."""
    t = np.clip(t, 0.0, 1.0)
    return t * t * (3 - 2 * t)


def test_a_plane_blend_across_a_bent_joint_uses_the_bisecting_plane():
    """A plane blend at a bent joint (spine1: the parent bone rises along +y, its own bone leans 45 deg towards +x)
    splits across the plane through the joint whose normal bisects the two bone directions (docs, step 5): the child
    weight is the smoothstep of (s + h) / 2h, s the signed distance across that plane, h = 5 cm."""
    joints, ends = _rig_far()
    pel, sp1, sp2, sp3 = (JI[n] for n in ("pelvis", "spine1", "spine2", "spine3"))
    joints[pel] = (0.0, 0.0, 0.0)
    joints[sp1], ends[sp1] = (0.0, 0.1, 0.0), (0.1, 0.2, 0.0)
    joints[sp2], ends[sp2] = (10.0, 10.0, 0.0), (20.0, 20.0, 0.0)
    joints[sp3], ends[sp3] = (20.0, 20.0, 0.0), (30.0, 30.0, 0.0)
    rng = np.random.default_rng(5)
    v = np.array([0.0, 0.1, 0.0]) + rng.uniform(-0.08, 0.08, size=(60, 3))
    nrm = np.array([1.0, 1.0 + np.sqrt(2.0), 0.0])
    nrm /= np.linalg.norm(nrm)                                      # unit((0,1,0) + (1,1,0)/sqrt 2)
    s = (v - joints[sp1]) @ nrm
    labels = np.where(s < 0, pel, sp1)
    w = skinning_weights(v, _strip(len(v)), labels, joints, ends, Proportions(), smooth_iters=0)
    want = _smoothstep((s + 0.05) / 0.1)
    np.testing.assert_allclose(w[:, sp1], want, atol=1e-12)
    np.testing.assert_allclose(w[:, pel], 1 - want, atol=1e-12)


def test_a_cone_blend_follows_the_cone_angle_within_the_lateral_radius():
    """The elbow's cone blend on a straight arm along +x (docs, step 5): within 8 cm of the forearm's axis the elbow's
    weight is t with atan(t / (1 - t)) growing linearly from 0 at alpha = 90 + 55 deg to 90 deg at 90 - 55 deg, alpha
    the angle at the joint between the vertex and the forearm's direction; vertices farther from the axis keep their
    owner."""
    joints, ends = _rig_far()
    col, sh, el = JI["left_collar"], JI["left_shoulder"], JI["left_elbow"]
    joints[col], ends[col] = (0.0, 0.0, 0.0), (0.2, 0.0, 0.0)
    joints[sh], ends[sh] = (0.2, 0.0, 0.0), (0.45, 0.0, 0.0)
    joints[el], ends[el] = (0.45, 0.0, 0.0), (0.7, 0.0, 0.0)
    rng = np.random.default_rng(2)
    x = rng.uniform(0.36, 0.54, 80)
    rho = np.r_[rng.uniform(0.005, 0.06, 60), rng.uniform(0.09, 0.1, 20)]
    ph = rng.uniform(0, 2 * np.pi, 80)
    v = np.stack([x, rho * np.cos(ph), rho * np.sin(ph)], 1)
    labels = np.where(x < 0.45, sh, el)
    w = skinning_weights(v, _strip(len(v)), labels, joints, ends, Proportions(), smooth_iters=0)
    alpha = np.degrees(np.arctan2(rho, x - 0.45))
    psi = np.deg2rad(90.0 * np.clip((90 + 55 - alpha) / 110, 0, 1))
    want = np.where(rho < 0.08, np.sin(psi) / (np.sin(psi) + np.cos(psi)), (labels == el).astype(float))
    np.testing.assert_allclose(w[:, el], want, atol=1e-12)
    np.testing.assert_allclose(w[:, sh], 1 - want, atol=1e-12)


def test_default_smoothing_is_three_laplacian_rounds():
    """skinning_weights' default smoothing is the three rounds of Laplacian averaging w <- (w + mean of the
    neighbours) / 2 that docs/body_model.md states ('Three rounds of mesh-Laplacian smoothing finish'), neighbours from
    trimesh."""
    import trimesh
    mesh = trimesh.creation.icosphere(subdivisions=2)
    v, f = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    labels = np.where(v[:, 0] > 0.2, JI["jaw"], JI["left_eye_smplhf"])
    joints, ends = _rig_far()
    got = skinning_weights(v, f, labels, joints, ends, Proportions())
    w = np.zeros((len(v), 55))
    w[np.arange(len(v)), labels] = 1.0
    for _ in range(3):
        w = 0.5 * w + 0.5 * np.stack([w[n].mean(0) for n in mesh.vertex_neighbors])
    w[w < 1e-6] = 0.0
    np.testing.assert_allclose(got, w / w.sum(1, keepdims=True), atol=1e-12)


def test_bone_ends_run_to_the_single_child_and_through_their_own_part():
    """bone_ends (docs: 'the far end of the bone each joint drives'): a joint with one child drives the bone to that
    child; and for every joint that carries skin, the middle of its bone lies in its own part: the shipped mesh's
    vertex nearest to it is one that joint dominates."""
    a, P, J0, E0 = _shipped()
    v, w = a["v_template"], a["weights"]
    for j in range(1, NUM_JOINTS):
        ch = [c for c in range(NUM_JOINTS) if PARENTS[c] == j]
        if len(ch) == 1:
            np.testing.assert_allclose(E0[j], J0[ch[0]], atol=1e-12, err_msg=JOINT_NAMES[j])
    part = w.argmax(1)
    for j in range(NUM_JOINTS):
        if w[:, j].max() > 0.5:
            mid = 0.5 * (J0[j] + E0[j])
            assert part[np.linalg.norm(v - mid, axis=1).argmin()] == j, JOINT_NAMES[j]


# ----------------------------------------------------------------------------- joint regressor
def test_tilt_is_an_exponential_tilt_of_g_with_the_target_as_mean():
    """_tilt's weights are g_i exp(lam . (x_i - target)) normalised (docs, step 6): log(w / g) is affine in x (least
    squares leaves no residual), they are non-negative, sum to 1, average the points to the target, and the returned
    residual is that average's distance from the target."""
    rng = np.random.default_rng(11)
    x = rng.normal(size=(40, 3))
    g = np.exp(-0.5 * np.sum(x ** 2, 1) / 0.8)
    target = np.array([0.3, -0.2, 0.25])
    w, res = _tilt(x, g, target)
    assert w.min() > 0 and w.sum() == pytest.approx(1.0, abs=1e-12)
    np.testing.assert_allclose(w @ x, target, atol=1e-10)
    assert res == pytest.approx(np.linalg.norm(w @ x - target), abs=1e-12)
    X = np.column_stack([np.ones(len(x)), x])
    y = np.log(w / g)
    coef = np.linalg.lstsq(X, y, rcond=None)[0]
    np.testing.assert_allclose(X @ coef, y, atol=1e-8)


def test_joint_regressor_of_the_shipped_body_averages_its_own_parts_onto_the_designed_joints():
    """joint_regressor on the shipped mesh and weights with seed 0's designed joints (docs, step 6): J_regressor @ v is
    the designed skeleton, rows are non-negative and sum to 1, and each row reads only vertices of the joint's own,
    parent or child parts (head and jaw for the jaw and eyes)."""
    a, P, J0, E0 = _shipped()
    v, w = a["v_template"], a["weights"]
    R = joint_regressor(v, w, J0)
    np.testing.assert_allclose(R @ v, J0, rtol=0, atol=1e-9)
    assert R.min() >= 0 and np.allclose(R.sum(1), 1.0, atol=1e-12)
    for j in range(NUM_JOINTS):
        fam = [j] + [c for c in range(NUM_JOINTS) if PARENTS[c] == j] + ([PARENTS[j]] if PARENTS[j] >= 0 else [])
        if JOINT_NAMES[j] in ("jaw", "left_eye_smplhf", "right_eye_smplhf"):
            fam = [JI["head"], JI["jaw"]]
        sup = R[j] > 0
        assert sup.sum() >= 3 and (w[sup][:, fam].sum(1) > 0).all(), JOINT_NAMES[j]


def test_joint_regressor_refuses_a_joint_outside_the_vertices():
    """A joint that lies outside every vertex of its parts cannot be a convex average of them: joint_regressor raises
    rather than return a row that misses the joint."""
    g = np.linspace(-0.05, 0.05, 5)
    v = np.stack(np.meshgrid(g, g, g, indexing="ij"), -1).reshape(-1, 3)
    weights = np.ones((len(v), NUM_JOINTS))                      # every vertex belongs to every part
    joints = np.zeros((NUM_JOINTS, 3))
    joints[0] = (0.5, 0.5, 0.5)
    with pytest.raises(RuntimeError):
        joint_regressor(v, weights, joints)


# ----------------------------------------------------------------------------- shape and expression bases
@functools.lru_cache(maxsize=None)
def _bases():
    """shape_basis (V, 3, 10) and expression_basis (V, 3, 10) of the shipped mesh and weights, seed 0's skeleton."""
    a, P, J0, E0 = _shipped()
    return shape_basis(a["v_template"], a["weights"], J0, E0), expression_basis(a["v_template"], a["weights"])


def test_shape_and_expression_bases_of_a_mirrored_body_are_mirrored():
    """On a mirror-symmetric body (the shipped left half, its weights, and their mirror images) with seed 0's symmetric
    skeleton, every shape and expression component moves a right vertex as the mirror image (x -> -x) of its left twin
    (all components are described as symmetric: girth, shoulder and hip width, limb lengths, the face bumps)."""
    a, P, J0, E0 = _shipped()
    vs, fs, n, ids = _mirrored_half()
    w = a["weights"][ids]
    ws = np.concatenate([w, w[:, PERM]])
    S = np.concatenate([shape_basis(vs, ws, J0, E0), expression_basis(vs, ws)], 2)
    assert np.abs(S[:n]).max((0, 1)).min() > 0                       # every component moves the left half
    np.testing.assert_allclose(S[n:], S[:n] * MX[None, :, None], atol=1e-12)


def test_girth_grows_inner_thighs_less():
    """beta_1 grows the thigh's cross-section about the hip-knee axis (docs: limbs 6-8 % per unit; 'inner thighs grow
    less'): on vertices (almost) wholly of the left thigh below the belly, the displacement is at most 8 % of the
    offset from the axis, close to it on the outer side, clearly less on the inner side."""
    a, P, J0, E0 = _shipped()
    v, w = a["v_template"], a["weights"]
    S = _bases()[0][:, :, 1]
    hip, knee = JI["left_hip"], JI["left_knee"]
    u = (J0[knee] - J0[hip]) / np.linalg.norm(J0[knee] - J0[hip])
    m = (w[:, hip] > 0.99) & (v[:, 1] < -0.55)                    # (1 % of other bones' fields, no belly)
    rel = v[m] - J0[hip]
    perp = rel - np.outer(rel @ u, u)
    ratio = np.linalg.norm(S[m], axis=1) / (0.08 * np.linalg.norm(perp, axis=1))
    inner, outer = v[m, 0] < J0[hip, 0] - 0.01, v[m, 0] > J0[hip, 0] + 0.03
    assert inner.sum() > 10 and outer.sum() > 10
    assert ratio.max() < 1.02
    assert ratio[outer].min() > 0.95 and ratio[inner].max() < 0.9


@pytest.mark.parametrize("i, a_, bones, hand", [(4, 0.04, ("shoulder", "elbow", "wrist"), ("wrist", "index", "middle",
                                                                                            "ring", "pinky", "thumb")),
                                                (5, 0.045, ("hip", "knee", "ankle"), ("ankle", "foot"))])
def test_limb_length_stretches_each_bone_along_its_axis_and_the_end_follows(i, a_, bones, hand):
    """beta_4 / beta_5 (docs: upper arm and forearm stretch 4 % along their axes, legs 4.5 %; the hand / foot follows):
    on vertices wholly of one bone the field is a translation plus a (u u^T) (x - J), u the bone's axis; the root bone
    is anchored at its joint, the lower bone's translation continues the upper one's at the middle joint, and the
    hand (foot) moves rigidly by the lower bone's field at the distal joint."""
    a, P, J0, E0 = _shipped()
    v, w = a["v_template"], a["weights"]
    S = _bases()[0][:, :, i]
    for side in ("left", "right"):
        r, m, d = (JI[f"{side}_{b}"] for b in bones)
        trans = {}
        for j, k in ((r, m), (m, d)):
            u = (J0[k] - J0[j]) / np.linalg.norm(J0[k] - J0[j])
            sel = _pure(w, [j])
            assert sel.sum() > 20, (side, j)
            t = S[sel] - a_ * (v[sel] - J0[j]) @ np.outer(u, u)
            np.testing.assert_allclose(t, np.broadcast_to(t[0], t.shape), atol=1e-12)
            trans[j] = (t[0], u)
        np.testing.assert_allclose(trans[r][0], 0.0, atol=1e-12)
        t0, u0 = trans[r]
        np.testing.assert_allclose(trans[m][0], t0 + a_ * np.outer(u0, u0) @ (J0[m] - J0[r]), atol=1e-12)
        t1, u1 = trans[m]
        end = t1 + a_ * np.outer(u1, u1) @ (J0[d] - J0[m])
        distal = [j for j, n in enumerate(JOINT_NAMES) if n.startswith(side + "_") and any(h in n for h in hand)]
        sel = _pure(w, distal)
        assert sel.sum() > 20
        np.testing.assert_allclose(S[sel], np.broadcast_to(end, S[sel].shape), atol=1e-12)


def test_torso_length_stretches_the_trunk_and_carries_what_is_above():
    """beta_6 (docs: the trunk between pelvis and neck stretches 5 %; everything above moves up): vertices wholly of the
    spine move up by 0.05 (y - y_pelvis), the pelvis and legs stay, and the arms (with collars and hands) ride rigidly
    on the trunk at the collar joint's height."""
    a, P, J0, E0 = _shipped()
    v, w = a["v_template"], a["weights"]
    S = _bases()[0][:, :, 6]
    y0 = J0[JI["pelvis"], 1]
    spine = _pure(w, [JI[n] for n in ("spine1", "spine2", "spine3")])
    assert spine.sum() > 100
    np.testing.assert_allclose(S[spine, 1], 0.05 * (v[spine, 1] - y0), atol=1e-12)
    legs = [JI[f"{s}_{n}"] for s in ("left", "right") for n in ("hip", "knee", "ankle", "foot")]
    low = _pure(w, [JI["pelvis"]] + legs)
    assert low.sum() > 1000 and np.abs(S[low]).max() < 1e-12
    for side in ("left", "right"):
        arm = _pure(w, [j for j, n in enumerate(JOINT_NAMES) if n.startswith(side + "_") and
                        any(k in n for k in ("collar", "shoulder", "elbow", "wrist", "index", "middle", "ring",
                                             "pinky", "thumb"))])
        assert arm.sum() > 500
        want = (0.0, 0.05 * (J0[JI[f"{side}_collar"], 1] - y0), 0.0)
        np.testing.assert_allclose(S[arm], np.broadcast_to(want, S[arm].shape), atol=1e-12)


def test_expressions_are_compact_face_bumps_of_a_few_millimetres():
    """Expressions (docs: head only, smooth compact bumps of a few millimetres; the jaw drops, fading out at the lip
    line): each component moves some vertex by 1 to 10 mm and nothing beyond; vertices less than 30 % head or jaw stay;
    the jaw component moves nothing above the lip line (y = 0.207) and drops the chin by several millimetres."""
    a, P, J0, E0 = _shipped()
    v, w = a["v_template"], a["weights"]
    X = _bases()[1]
    mag = np.linalg.norm(X, axis=1)                                  # (V, 10)
    assert (mag.max(0) > 1e-3).all() and (mag.max(0) < 1e-2).all(), mag.max(0)
    not_head = w[:, [JI["head"], JI["jaw"]]].sum(1) < 0.3
    assert np.abs(X[not_head]).max() == 0.0
    assert np.abs(X[v[:, 1] >= 0.207, :, 0]).max() == 0.0
    assert X[:, 1, 0].min() < -3e-3


# ----------------------------------------------------------------------------- pose correctives
def test_rodrigues_and_rotvec_agree_with_scipy():
    """rodrigues (axis-angle -> matrix) and _rotvec (matrix -> axis-angle, angles below 180 deg) are scipy's
    Rotation.from_rotvec / as_rotvec, and the zero vector is the identity."""
    rng = np.random.default_rng(8)
    aa = rng.normal(size=(50, 3))
    aa *= (rng.uniform(0.01, 3.0, 50) / np.linalg.norm(aa, axis=1))[:, None]
    for r in aa:
        R = Rotation.from_rotvec(r).as_matrix()
        np.testing.assert_allclose(C.rodrigues(r), R, atol=1e-12)
        np.testing.assert_allclose(C._rotvec(R), r, atol=1e-9)
    np.testing.assert_allclose(C.rodrigues(np.zeros(3)), np.eye(3))


def test_subtree_is_the_joint_and_all_its_descendants():
    """subtree(c) is c and every joint whose chain of parents (PARENTS) reaches c: the shoulder's holds the elbow, the
    wrist and all 15 finger joints of that hand."""
    def ancestors(j):
        """Joints on the chain of parents above j."""
        out = []
        while PARENTS[j] >= 0:
            j = PARENTS[j]
            out.append(j)
        return out
    for c in range(NUM_JOINTS):
        want = {c} | {j for j in range(NUM_JOINTS) if c in ancestors(j)}
        assert set(C.subtree(c)) == want and len(C.subtree(c)) == len(want), JOINT_NAMES[c]
    assert len(C.subtree(JI["left_shoulder"])) == 18


_POSE0 = (np.tile(np.eye(3), (55, 1, 1)), np.zeros((55, 3)))


def test_radial_target_takes_the_nearest_root_within_reach_and_skips_the_axis_and_grazing_rays():
    """radial_target's stated rules, on spheres about the z axis: a ray crossing two surfaces moves a point to the
    crossing nearest to it; a point whose nearest crossing is farther than max_move stays; a point within 5 mm of the
    axis stays; and a point whose ray meets the surface at a grazing angle (near a sphere's pole) stays."""
    r = 0.02
    two = Body([Ellipsoid((0.1, 0.0, 0.0), (r, r, r), joint=0), Ellipsoid((0.2, 0.0, 0.0), (r, r, r), joint=0)],
               Floor(-10.0, 0.0))
    x = np.array([[0.21, 0.0, 0.0], [0.26, 0.0, 0.0], [0.30, 0.0, 0.0], [0.11, 0.0, 0.0]])
    y, ok = C.radial_target(x, np.zeros(3), np.array([0.0, 0.0, 1.0]), two, _POSE0, max_move=0.05)
    assert ok.tolist() == [True, True, False, True]
    np.testing.assert_allclose(y[:, 0], [0.22, 0.22, 0.30, 0.12], atol=1e-5)
    one = Body([Ellipsoid((0.0, 0.0, 0.0), (0.05, 0.05, 0.05), joint=0),
                Ellipsoid((0.0, 0.0, 0.3), (0.008, 0.008, 0.008), joint=0)], Floor(-10.0, 0.0))
    x = np.array([[0.004, 0.0, 0.3], [0.012, 0.0, 0.049], [0.0, 0.04, 0.02]])
    y, ok = C.radial_target(x, np.zeros(3), np.array([0.0, 0.0, 1.0]), one, _POSE0, max_move=0.05)
    assert ok.tolist() == [False, False, True]
    np.testing.assert_allclose(y[:2], x[:2], atol=0)
    assert y[2, 1] == pytest.approx(np.sqrt(0.05 ** 2 - 0.02 ** 2), abs=1e-5)


def test_harmonic_fill_ignores_the_given_values_outside_the_known_rows():
    """harmonic_fill keeps the known rows, solves the unknown region rows from the known ones alone (linear along a
    path) whatever the input holds there, and leaves rows outside the region at zero even where the input is not."""
    n = 8
    i = np.arange(n - 1)
    A = coo_matrix((np.ones(2 * (n - 1)), (np.r_[i, i + 1], np.r_[i + 1, i])), shape=(n, n)).tocsr()
    rng = np.random.default_rng(3)
    delta = rng.normal(size=(n, 3))                                # junk in the unknown and outside rows
    region = np.arange(1, 7)                                       # vertices 0 and 7 lie outside
    known = np.array([True, False, False, False, False, True])     # vertices 1 and 6
    out = C.harmonic_fill(delta, known, region, A)
    s = np.arange(6)[:, None] / 5
    np.testing.assert_allclose(out[1:7], (1 - s) * delta[1] + s * delta[6], atol=1e-12)
    np.testing.assert_allclose(out[[0, 7]], 0.0, atol=0)


def test_fitted_correctives_reproduce_a_linear_offset_field_in_smplx_pose_features(monkeypatch):
    """fit_correctives' least squares on data that is exactly a pose blend shape: with the surface target replaced by
    v_lbs + M_b B (vec(R) - vec(I)) (M_b the vertex's blended rotation, here R itself: the vertices are wholly the
    elbow's), the fitted posedirs give back the rest-space offsets B (vec(R) - vec(I)) at every sampled elbow rotation
    when read as smplx's lbs.py reads them (pose_feature = (R - I) flattened row-major, in joint c's slot 9 (c - 1)),
    on both sides."""
    a, P, J0, E0 = _shipped()
    rng = np.random.default_rng(4)
    G = rng.normal(scale=0.01, size=(3, 3, 9))                     # B(x) = sum_a x_a G_a: a smooth field
    sides = {}
    vs, ws = [], []
    for k, name in enumerate(("left_elbow", "right_elbow")):
        c = JI[name]
        pts = J0[c] + rng.uniform(-0.03, 0.03, size=(25, 3))
        w = np.zeros((25, NUM_JOINTS))
        w[:, c] = 1.0
        vs.append(pts)
        ws.append(w)
        sides[c] = np.arange(25) + 25 * k
    v, w = np.concatenate(vs), np.concatenate(ws)

    def offsets(x_rest, R):
        """The rest-space offsets B(x) (vec(R) - vec(I)) (N, 3)."""
        return np.einsum("na,aki,i->nk", x_rest, G, (R - np.eye(3)).reshape(9))

    def fake_target(x, centre, axis, body, pose, max_move):
        """radial_target's stand-in: v_lbs plus the blended rotation (R: wholly the elbow's) of the offsets."""
        Rs, ts = pose
        c = JI["left_elbow"] if np.allclose(centre, J0[JI["left_elbow"]]) else JI["right_elbow"]
        R, t = Rs[c], ts[c]
        x_rest = (x - t) @ R                                       # x = R x_rest + t
        return x + offsets(x_rest, R) @ R.T, np.ones(len(x), bool)

    body = Body([Ellipsoid(tuple(J0[JI["left_elbow"]]), (0.04, 0.04, 0.04), joint=JI["left_elbow"])], Floor(-10.0, 0.0))
    spec = C.SPECS[0]
    assert spec.joint == "left_elbow"
    monkeypatch.setattr(C, "radial_target", fake_target)
    pd = C.fit_correctives(v, _strip(len(v)), w, J0, body, specs=(spec,), ridge=1e-12)
    for c, rows in sides.items():
        m = np.array([1.0, -1.0, -1.0]) if c == JI["right_elbow"] else np.ones(3)   # pseudo-vector mirror
        for fl in spec.flex_deg:
            for tw in spec.twist_deg:
                R = (Rotation.from_rotvec(np.deg2rad(tw) * np.asarray(spec.twist_axis) * m) *
                     Rotation.from_rotvec(np.deg2rad(fl) * np.asarray(spec.flex_axis) * m)).as_matrix()
                got = pd[rows][:, :, 9 * (c - 1):9 * c] @ (R - np.eye(3)).reshape(9)
                np.testing.assert_allclose(got, offsets(v[rows], R), atol=1e-9, err_msg=(JOINT_NAMES[c], fl, tw))
    others = np.ones(pd.shape[2], bool)
    for c in sides:
        others[9 * (c - 1):9 * c] = False
    assert np.abs(pd[:, :, others]).max() == 0.0


def test_joint_regressor_weights_fall_off_with_distance_for_a_centred_joint():
    """For a joint at the centre of a symmetric cloud of its own vertices the average needs no tilt (lam = 0), so each
    row is the plain Gaussian average the docs describe (step 6): a vertex nearer the joint never weighs less than a
    farther one, and the nearest shell weighs strictly more than the farthest."""
    g = np.array([-0.0375, -0.0125, 0.0125, 0.0375])
    v = np.stack(np.meshgrid(g, g, g, indexing="ij"), -1).reshape(-1, 3)
    weights = np.ones((len(v), NUM_JOINTS))                      # every vertex belongs to every part
    R = joint_regressor(v, weights, np.zeros((NUM_JOINTS, 3)))
    np.testing.assert_allclose(R @ v, 0.0, atol=1e-12)
    d = np.linalg.norm(v, axis=1)
    o = np.argsort(d, kind="stable")
    for row in R:
        sup = row[o] > 0
        assert sup.sum() >= 8
        r, dd = row[o][sup], d[o][sup]
        assert (np.diff(r) <= 1e-12).all()
        assert r[dd < dd.min() + 1e-9].min() > r[dd > dd.max() - 1e-9].max()


def test_mouth_and_brow_expressions_stay_in_their_part_of_the_face():
    """The named expressions move their own features only (docs: smooth compact bumps): smile, pucker, mouth wide and
    mouth corners down move nothing at or above the eyes (y >= 0.29, face landmarks of the procedural face), brows up,
    frown and squint nothing at or below the nostrils (y <= 0.245)."""
    a, P, J0, E0 = _shipped()
    y = a["v_template"][:, 1]
    X = _bases()[1]
    for i in (1, 4, 8, 9):
        assert np.abs(X[y >= 0.29, :, i]).max() == 0.0, i
    for i in (2, 3, 6):
        assert np.abs(X[y <= 0.245, :, i]).max() == 0.0, i
        assert np.abs(X[:, :, i]).max() > 1e-3, i


def _arm_body_and_tube(J0):
    """A left arm of two ellipsoids (upper arm owned by the shoulder, forearm by the elbow) with its mirror image (owned
    by the right joints), and a tube mesh about each elbow (x axis, +-8 cm, each vertex on the arm's rest surface), the
    right one the mirror image of the left; weights: a smoothstep from shoulder to elbow across the elbow."""
    prims, vs, fs, ws = [], [], [], []
    n_s, n_p = 17, 16
    s = np.linspace(-0.08, 0.08, n_s)
    ph = np.linspace(0, 2 * np.pi, n_p, endpoint=False)
    S, P_ = np.meshgrid(s, ph, indexing="ij")
    quads = [(i * n_p + j, (i + 1) * n_p + j, (i + 1) * n_p + (j + 1) % n_p, i * n_p + (j + 1) % n_p)
             for i in range(n_s - 1) for j in range(n_p)]
    f = np.array([(a, b, c) for a, b, c, d in quads] + [(a, c, d) for a, b, c, d in quads])
    t = _smoothstep(S.ravel() / 0.06 + 0.5)
    for k, side in enumerate(("left", "right")):
        sh, el, wr = (JI[f"{side}_{n}"] for n in ("shoulder", "elbow", "wrist"))
        mir = MX if side == "right" else np.ones(3)
        for a_, b_, j, r in ((sh, el, sh, 0.045), (el, wr, el, 0.038)):
            u = (J0[b_] - J0[a_]) / np.linalg.norm(J0[b_] - J0[a_])
            e2 = np.cross(u, (0.0, 0.0, 1.0))
            e2 /= np.linalg.norm(e2)
            R = np.column_stack([u, e2, np.cross(u, e2)])
            prims.append(Ellipsoid(0.5 * (J0[a_] + J0[b_]), (0.5 * np.linalg.norm(J0[b_] - J0[a_]) + 0.03, r, r), R,
                                   joint=j))
        left_el = J0[JI["left_elbow"]]
        v = left_el + np.stack([S.ravel(), 0.04 * np.cos(P_.ravel()), 0.04 * np.sin(P_.ravel())], 1)
        vs.append(v * mir)
        fs.append((f if k == 0 else f[:, ::-1]) + k * n_s * n_p)
        w = np.zeros((len(v), NUM_JOINTS))
        w[:, el], w[:, sh] = t, 1 - t
        ws.append(w)
    body = Body(prims, Floor(-10.0, 0.0))
    v = vs[0]                                     # each tube vertex onto the rest surface, along its ray from the axis
    e = v - left_el
    base = left_el + np.outer(e[:, 0], (1.0, 0.0, 0.0))
    e[:, 0] = 0.0
    e /= np.linalg.norm(e, axis=1, keepdims=True)
    lo, hi = np.full(len(v), 0.001), np.full(len(v), 0.2)
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        inside = body.evaluate(base + mid[:, None] * e)[0] <= 0
        lo, hi = np.where(inside, mid, lo), np.where(inside, hi, mid)
    v = base + (0.5 * (lo + hi))[:, None] * e
    return body, np.concatenate([v, v * MX]), np.concatenate(fs), np.concatenate(ws)


@functools.lru_cache(maxsize=None)
def _arm_fit():
    """The arm pair, its tube meshes and the elbow correctives fit_correctives gives them (SPECS' elbow)."""
    a, P, J0, E0 = _shipped()
    body, v, f, w = _arm_body_and_tube(J0)
    return body, v, f, w, C.fit_correctives(v, f, w, J0, body, specs=(C.SPECS[0],))


def test_right_elbow_correctives_are_the_mirror_image_of_the_left():
    """fit_correctives on a mirror-symmetric arm pair (two ellipsoids per arm, a tube mesh about each elbow): the right
    elbow is sampled with the left's axes mirrored as pseudo-vectors (-M r, docs), so its fitted blend shapes are the
    mirror image of the left's: under M = diag(-1, 1, 1), R -> M R M and offsets -> M offsets, so posedirs entry
    (k, 3a + b) of a right vertex is m_k m_a m_b times its left twin's."""
    body, v, f, w, pd = _arm_fit()
    n = len(v) // 2
    cl, cr = JI["left_elbow"], JI["right_elbow"]
    L, R = pd[:n, :, 9 * (cl - 1):9 * cl], pd[n:, :, 9 * (cr - 1):9 * cr]
    assert np.abs(L).max() > 1e-3
    sign = np.einsum("k,a,b->kab", MX, MX, MX).reshape(3, 9)
    np.testing.assert_allclose(R, L * sign[None], atol=1e-8)


def test_elbow_correctives_bring_the_crease_nearer_the_rigidly_bent_arm():
    """The correctives' target is the body with every primitive carried rigidly by its joint (docs, step 8): on the
    arm pair, the left elbow flexed 45 and 70 deg about its flexion axis and posed by LBS with the fitted correctives
    (smplx's pose feature, pivot at the elbow) leaves the vertices within 7 cm of the elbow at most 80 % as far from
    that rigidly bent surface as plain LBS does."""
    a, P, J0, E0 = _shipped()
    body, v, f, w, pd = _arm_fit()
    c = JI["left_elbow"]
    sub = C.subtree(c)
    t = w[:, sub].sum(1)
    near = np.linalg.norm(v - J0[c], axis=1) < 0.07
    for fl in (45.0, 70.0):
        R = Rotation.from_rotvec(np.deg2rad(fl) * np.asarray(C.SPECS[0].flex_axis, float)).as_matrix()
        Rs, ts = np.tile(np.eye(3), (55, 1, 1)), np.zeros((55, 3))
        Rs[sub], ts[sub] = R, J0[c] - R @ J0[c]

        def lbs(x):
            """Plain LBS of the tube with the elbow's subtree rotated by R about the elbow."""
            return (1 - t)[:, None] * x + t[:, None] * (x @ R.T + ts[c])

        x1 = v + pd[:, :, 9 * (c - 1):9 * c] @ (R - np.eye(3)).reshape(9)
        plain = np.abs(body.evaluate(lbs(v)[near], (Rs, ts))[0]).max()
        fitted = np.abs(body.evaluate(lbs(x1)[near], (Rs, ts))[0]).max()
        assert fitted < 0.8 * plain, (fl, fitted, plain)
