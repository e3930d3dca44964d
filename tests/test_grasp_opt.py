"""Grasp fitting internals: partial skinning, the analytic arm, hand shapes, closing fingers until contact."""
import numpy as np
import pytest
import torch
import trimesh

from graspkit.body.hand_poses import _FINGER_TEMPLATES, _SPREAD, _THUMB_TEMPLATES, hand_axes, template_pose
from graspkit.body.markers import goal_vertices
from graspkit.body.skeleton import FINGERS, JOINT_INDEX as J
from graspkit.data import grasp_opt as go
from graspkit.data.ik import axis_angle_matrix
from graspkit.data.posing import forward_kinematics
from graspkit.data.rig import R_BASE, build_rig
from graspkit.objects.sdf import SDFGrid
from graspkit.rotations import axis_angle_to_matrix


@pytest.fixture(scope="module")
def hm(bm):
    return go.HandModel(bm)


def test_partial_body_equals_the_full_model(bm):
    g = torch.Generator().manual_seed(0)
    rot = axis_angle_to_matrix(0.4 * torch.randn(3, 55, 3, generator=g))
    betas = torch.randn(3, 10, generator=g)
    transl = torch.randn(3, 3, generator=g)
    ids = np.array([0, 17, 5000, 8079, 10474, 7669])
    v, j = go.PartialBody(bm, ids)(rot, go.coeffs_of(bm, betas.numpy()), transl)
    ref = bm.forward_rotmats(rot, betas=betas, transl=transl)
    assert torch.allclose(v, ref.vertices[:, ids], atol=2e-6) and torch.allclose(j, ref.joints, atol=2e-6)


def test_solve_arm_puts_the_wrist_on_target_with_the_hand_rotation(bm):
    rig = build_rig(bm)
    local = np.broadcast_to(np.eye(3), (1, 55, 3, 3)).copy()
    Rg, pos = forward_kinematics(rig, local, rig.joints[:1])
    rng = np.random.default_rng(1)
    arm = rig.arm_length
    targets = pos[0, J["right_shoulder"]] + np.array([[-0.7, -0.3, 0.3], [-0.5, -0.5, 0.2], [-0.6, 0.2, 0.4]]) * arm
    hands = axis_angle_matrix(rng.normal(scale=0.5, size=(3, 3)))
    sh, el, wr, resid = go.solve_arm(Rg[0, J["right_collar"]], pos[0, J["right_shoulder"]], rig.joints, targets, hands)
    for k in range(3):
        loc = local.copy()
        loc[0, J["right_shoulder"]], loc[0, J["right_elbow"]], loc[0, J["right_wrist"]] = sh[k], el[k], wr[k]
        Rk, pk = forward_kinematics(rig, loc, rig.joints[:1])
        assert np.allclose(pk[0, J["right_wrist"]], targets[k], atol=1e-6)           # exact IK
        assert np.allclose(Rk[0, J["right_wrist"]], hands[k], atol=1e-6)             # the hand turned as asked
        angle = np.arccos(np.clip((np.trace(wr[k]) - 1) / 2, -1, 1))
        assert abs(angle - resid[k]) < 1e-6 and resid[k] < np.pi


def test_solve_arm_solves_a_wrist_straight_below_the_shoulder(bm):
    """Its swivel poles came from world-down, all zero for an arm hanging straight down: two_bone_ik refused them
    (and before that returned determinant-0 matrices). Now the wrist lands there with proper rotations, in a batch
    with an ordinary reach."""
    rig = build_rig(bm)
    local = np.broadcast_to(np.eye(3), (1, 55, 3, 3)).copy()
    Rg, pos = forward_kinematics(rig, local, rig.joints[:1])
    sh0 = pos[0, J["right_shoulder"]]
    targets = sh0 + np.array([[0.0, 0.0, -0.8], [-0.6, 0.2, 0.4]]) * rig.arm_length
    hands = np.broadcast_to(np.eye(3), (2, 3, 3))
    sh, el, wr, resid = go.solve_arm(Rg[0, J["right_collar"]], sh0, rig.joints, targets, hands)
    for k in range(2):
        for R in (sh[k], el[k], wr[k]):
            assert np.allclose(R @ R.T, np.eye(3), atol=1e-9) and abs(np.linalg.det(R) - 1) < 1e-9
        loc = local.copy()
        loc[0, J["right_shoulder"]], loc[0, J["right_elbow"]], loc[0, J["right_wrist"]] = sh[k], el[k], wr[k]
        _, pk = forward_kinematics(rig, loc, rig.joints[:1])
        assert np.allclose(pk[0, J["right_wrist"]], targets[k], atol=1e-6)


def test_hand_shapes_use_the_hand_pose_conventions(bm):
    """hand_pose_from_angles with a template's angles reproduces graspkit.body.hand_poses.template_pose."""
    axes = hand_axes(build_rig(bm).joints, "right")
    for kind in ("power", "pinch", "hook"):
        fingers = np.array([_FINGER_TEMPLATES[kind][f] for f in FINGERS[:4]], float)
        spread = np.array([_SPREAD[f] * 0.3 for f in FINGERS[:4]])
        out = go.hand_pose_from_angles(axes, fingers, np.array(_THUMB_TEMPLATES[kind], float), spread)
        assert np.allclose(out.reshape(45), template_pose(kind, axes), atol=1e-12)


def _box_sdf(p: np.ndarray, box: trimesh.Trimesh) -> np.ndarray:
    """The analytic signed distance (negative inside) of an axis-aligned box mesh."""
    lo, hi = box.bounds
    q = np.abs(p - (lo + hi) / 2) - (hi - lo) / 2
    return np.linalg.norm(np.maximum(q, 0), axis=1) + np.minimum(q.max(1), 0)


def test_fingers_close_until_they_touch_a_box(bm, hm):
    """An open right hand above a box (rest pose, palm facing -y): every digit stops within a few mm of the analytic
    box surface and no deeper than the stop depth (PENETRATION_STOP, 1 mm) plus 0.2 mm of the grid's error, or closes
    fully without touching."""
    rest_v = bm().vertices[0].detach().numpy()
    palm = rest_v[hm.palm_ids]
    top = palm[:, 1].min() - 0.012
    box = trimesh.creation.box(extents=(0.30, 0.10, 0.30))
    box.apply_translation([palm[:, 0].mean(), top - 0.05, palm[:, 2].mean()])
    grid = SDFGrid.from_mesh(box, resolution=16)   # trilinear interpolation is exact near a face
    sdf = go.PosedSDF(grid, np.eye(3)[None], np.zeros((1, 3)))
    axes = hm.axes(np.zeros(10))
    path = lambda c: go.hand_path(go.HAND_SHAPES["power"], axes, c)  # noqa: E731
    rot = torch.eye(3).repeat(1, 55, 1, 1)
    pb = go.PartialBody(bm, hm.fit_ids)
    curls, hands = go.close_fingers(pb, hm, rot, go.coeffs_of(bm, np.zeros((1, 10))), torch.zeros(1, 3), sdf, [path])
    rot[0, 40:55] = axis_angle_to_matrix(torch.as_tensor(hands[0], dtype=torch.float32))
    v = bm.forward_rotmats(rot).vertices[0].detach().numpy()
    open_rot = torch.eye(3).repeat(1, 55, 1, 1)
    open_rot[0, 40:55] = axis_angle_to_matrix(torch.as_tensor(path(np.zeros((1, 5)))[0], dtype=torch.float32))
    v_open = bm.forward_rotmats(open_rot).vertices[0].detach().numpy()
    for k, f in enumerate(FINGERS):
        d = _box_sdf(v[hm.finger_ids[f]], box)
        if f != "thumb":
            assert 0 < curls[0, k] < 1, f"{f} never touched or started inside"
        if curls[0, k] == 0:       # a digit that is already inside when open stays open
            assert _box_sdf(v_open[hm.finger_ids[f]], box).min() < -go.PENETRATION_STOP
        else:
            assert -go.PENETRATION_STOP - 2e-4 < d.min() < 0.004, f"{f}: {d.min() * 1000:.1f} mm from the surface"


def test_profile_sdf_is_the_sdf_of_the_revolved_solid():
    """The fit's cavity fill: profile_sdf of a (r, z) polygon equals trimesh's signed distance to the revolved mesh."""
    prof = np.array([(0, 0), (0.06, 0), (0.07, 0.05), (0.072, 0.12), (0.062, 0.19), (0, 0.19)])
    solid = trimesh.creation.revolve(prof, sections=256)
    P = np.random.default_rng(0).uniform([-0.1, -0.1, -0.03], [0.1, 0.1, 0.22], (2000, 3))
    rz = torch.as_tensor(np.stack([np.linalg.norm(P[:, :2], axis=1), P[:, 2]], 1))
    d = go.profile_sdf(rz, torch.as_tensor(prof)).numpy()
    assert np.abs(d + trimesh.proximity.signed_distance(solid, P)).max() < 1e-4       # trimesh: > 0 inside


# The fitter's hand geometry and arm against independent references: trimesh's normals (finger pads on the palm
# side), the thumb joint (the frame's thumb side) and world height (the elbow below the shoulder).
def test_finger_pads_are_on_the_palm_side_of_the_distal_segments(bm, hm):
    with torch.no_grad():
        v = bm().vertices[0].double().numpy()
    n = trimesh.Trimesh(v, bm.faces.numpy(), process=False).vertex_normals      # rest pose: the palm faces -y
    part = bm.lbs_weights.argmax(1).numpy()
    for f, js in go.FINGER_JOINTS.items():
        pads, distal = hm.pad_ids[f], np.flatnonzero(part == js[2])
        assert set(pads) <= set(distal)
        assert n[pads, 1].mean() < -0.3 and n[pads, 1].mean() < n[distal, 1].mean() - 0.2, f


def test_hand_frame_thumb_points_to_the_thumb_side(bm, hm):
    hf = hm.frame(np.zeros(10))
    _, j = hm.rest(np.zeros(10))
    side = j[J["right_thumb1"]] - j[J["right_middle1"]]
    assert hf.thumb @ side > 0.5 * np.linalg.norm(side - (side @ hf.finger) * hf.finger - (side @ hf.normal) * hf.normal)
    assert abs(hf.thumb @ hf.finger) < 1e-9 and abs(hf.thumb @ hf.normal) < 1e-9


def test_solve_arm_keeps_the_elbow_below_the_shoulder_in_the_z_up_world(bm):
    rig = build_rig(bm)
    local = np.broadcast_to(np.eye(3), (1, 55, 3, 3)).copy()
    local[0, 0] = R_BASE                                       # the z-up world, facing +x
    Rg, pos = forward_kinematics(rig, local, rig.joints[:1])
    sh0, arm = pos[0, J["right_shoulder"]], rig.arm_length
    targets = sh0 + np.array([[0.7, -0.1, -0.2], [0.6, 0.1, -0.4], [0.7, -0.3, 0.0]]) * arm
    hands = Rg[0, J["right_wrist"]] @ axis_angle_matrix(np.array([[0.0, 0.3, 0.0], [0.2, 0.0, 0.0], [0.0, 0.0, 0.3]]))
    sh, el, wr, _ = go.solve_arm(Rg[0, J["right_collar"]], sh0, rig.joints, targets, hands)
    for k in range(3):
        loc = local.copy()
        loc[0, J["right_shoulder"]], loc[0, J["right_elbow"]], loc[0, J["right_wrist"]] = sh[k], el[k], wr[k]
        _, pk = forward_kinematics(rig, loc, rig.joints[:1])
        assert np.allclose(pk[0, J["right_wrist"]], targets[k], atol=1e-6)
        assert pk[0, J["right_elbow"], 2] < sh0[2] - 0.03, k                       # the elbow hangs, not raised


def test_hand_frame_normal_is_the_palms_outward_normal(bm, hm):
    """HandFrame.normal is the palm's outward normal: along trimesh's mean vertex normal of the palm vertices (rest
    pose: the palm faces -y)."""
    hf = hm.frame(np.zeros(10))
    with torch.no_grad():
        v = bm().vertices[0].double().numpy()
    n = trimesh.Trimesh(v, bm.faces.numpy(), process=False).vertex_normals[hm.palm_ids].mean(0)
    assert hf.normal @ n / np.linalg.norm(n) > 0.99 and hf.normal[1] < -0.8


def test_hand_frame_finger_is_wrist_to_middle_knuckle_in_the_palm_plane(bm, hm):
    """HandFrame.finger (docstring: wrist -> middle knuckle) is that direction with its normal component removed: a
    unit vector perpendicular to the palm normal, in the plane of the normal and the wrist -> right_middle1 bone (the
    body model's rest joints), and the frame is a rotation."""
    hf = hm.frame(np.zeros(10))
    with torch.no_grad():
        j = bm().joints[0].double().numpy()
    u = j[J["right_middle1"]] - j[J["right_wrist"]]
    u = u / np.linalg.norm(u)
    assert abs(np.linalg.norm(hf.finger) - 1) < 1e-9 and abs(hf.finger @ hf.normal) < 1e-9
    assert abs(np.cross(u, hf.normal) @ hf.finger) < 1e-6                  # in the plane of u and the normal
    assert hf.finger @ u == pytest.approx(np.sqrt(1 - (u @ hf.normal) ** 2), abs=1e-6)
    R = hf.rot
    assert np.allclose(R.T @ R, np.eye(3), atol=1e-9) and np.linalg.det(R) == pytest.approx(1.0)


def test_hand_path_closes_each_digit_with_its_own_curl(hm):
    """hand_path (docstring: digit d at curl curls[k, d], order FINGERS = index, middle, pinky, ring, thumb): the
    thumb alone closed is the open fingers with the closed thumb, and the fingers alone closed the reverse."""
    axes = hm.axes(np.zeros(10))
    s = go.HAND_SHAPES["power"]
    of, cf = np.array(s.open_fingers, float), np.array(s.closed_fingers, float)
    ot, ct = np.array(s.open_thumb, float), np.array(s.closed_thumb, float)
    sp = np.array(s.spread, float)
    out = go.hand_path(s, axes, np.array([[0, 0, 0, 0, 1.0], [1.0, 1, 1, 1, 0]]))
    assert np.allclose(out[0], go.hand_pose_from_angles(axes, of, ct, sp), atol=1e-12)
    assert np.allclose(out[1], go.hand_pose_from_angles(axes, cf, ot, sp), atol=1e-12)


def test_solve_arm_moves_a_forearm_twist_into_the_elbow(bm):
    """solve_arm's docstring: forearm twist up to max_twist (85 deg) goes into the elbow. A hand rotation made by an
    arm pose whose forearm is twisted 0.9 rad about its bone (wrist unturned) is met with the wrist nearly unturned:
    the residual is at most the swivel grid's spacing (15 deg), not the half twist (26 deg) a split would leave."""
    rig = build_rig(bm)
    local = np.broadcast_to(np.eye(3), (1, 55, 3, 3)).copy()
    b2 = rig.joints[J["right_wrist"]] - rig.joints[J["right_elbow"]]
    d = b2 / np.linalg.norm(b2)
    local[0, J["right_shoulder"]] = axis_angle_matrix(np.array([0.0, 0.0, 1.0]))
    local[0, J["right_elbow"]] = axis_angle_matrix(np.array([0.0, 1.2, 0.0])) @ axis_angle_matrix(0.9 * d)
    Rg, pos = forward_kinematics(rig, local, rig.joints[:1])
    W, H = pos[0, J["right_wrist"]][None], Rg[0, J["right_wrist"]][None]
    sh, el, wr, resid = go.solve_arm(Rg[0, J["right_collar"]], pos[0, J["right_shoulder"]], rig.joints, W, H)
    loc = local.copy()
    loc[0, J["right_shoulder"]], loc[0, J["right_elbow"]], loc[0, J["right_wrist"]] = sh[0], el[0], wr[0]
    Rk, pk = forward_kinematics(rig, loc, rig.joints[:1])
    assert np.allclose(pk[0, J["right_wrist"]], W[0], atol=1e-6) and np.allclose(Rk[0, J["right_wrist"]], H[0], atol=1e-6)
    assert resid[0] < np.deg2rad(15.0), np.rad2deg(resid[0])


def test_posed_sdf_reads_the_grid_through_the_object_pose():
    """PosedSDF (x_obj = R^T (x - t)): the grid of a 20 x 10 x 6 cm box seen through a turned and moved pose gives
    trimesh's signed distance to the box mesh moved by the same pose (opposite sign), away from its edges."""
    box = trimesh.creation.box(extents=(0.20, 0.10, 0.06))
    grid = SDFGrid.from_mesh(box, resolution=40)
    R = axis_angle_matrix(np.array([0.3, -0.5, 1.1]))
    t = np.array([0.4, -0.2, 0.9])
    sdf = go.PosedSDF(grid, R[None], t[None])
    rng = np.random.default_rng(0)
    local = rng.uniform([-0.14, -0.09, -0.07], [0.14, 0.09, 0.07], (3000, 3))
    q = np.abs(local) - np.array([0.10, 0.05, 0.03])
    keep = (np.sort(q, 1)[:, 1] < -0.015) | (q.max(1) < -0.005)         # near one face only, or well inside
    world = local[keep] @ R.T + t
    posed = box.copy()
    posed.apply_transform(np.block([[R, t[:, None]], [np.zeros((1, 3)), np.ones((1, 1))]]))
    want = -trimesh.proximity.signed_distance(posed, world)
    got = sdf(torch.as_tensor(world, dtype=torch.float32)[None])[0].numpy()
    assert keep.sum() > 500 and np.abs(got - want).max() < 2.5e-3


@pytest.fixture(scope="module")
def scene(bm, hm):
    """The rest body (B = 1; the palm faces -y) above a 30 x 10 x 30 cm box whose top face is 12 mm below the lowest
    palm vertex, its SDF grid (exact near a face) and the partial bodies the fitter uses."""
    with torch.no_grad():
        rest = bm().vertices[0].numpy()
    palm = rest[hm.palm_ids]
    top = palm[:, 1].min() - 0.012
    box = trimesh.creation.box(extents=(0.30, 0.10, 0.30))
    box.apply_translation([palm[:, 0].mean(), top - 0.05, palm[:, 2].mean()])
    sdf = go.PosedSDF(SDFGrid.from_mesh(box, resolution=16), np.eye(3)[None], np.zeros((1, 3)))
    gv = goal_vertices(bm)
    return dict(box=box, sdf=sdf, rest=rest, pb=go.PartialBody(bm, hm.fit_ids),
                head_pb=go.PartialBody(bm, np.array([gv.head_back, gv.head_front])), gv=gv)


def _energies(bm, hm, scene, rot=None, regions=(1, 1, 1, 1, 1, 1), normal=(0.0, 1.0, 0.0), centre=None, pts=None):
    """The polish's energy terms (history) at the start pose: polish with steps=0 evaluates them once."""
    rot = torch.eye(3).repeat(1, 55, 1, 1) if rot is None else rot
    palm = scene["rest"][hm.palm_ids].mean(0)
    centre = scene["box"].centroid if centre is None else centre
    targets = go.PolishTargets(palm[None], np.array([normal]), np.array(centre, float)[None],
                               np.array([regions], float))
    if pts is None:
        pts = torch.as_tensor(trimesh.sample.sample_surface_even(scene["box"], 1000, seed=0)[0]).float()[None]
    hist: list = []
    go.polish(scene["pb"], hm, scene["head_pb"], (0, 1), rot, go.coeffs_of(bm, np.zeros((1, 10))), torch.zeros(1, 3),
              scene["sdf"], targets, pts, steps=0, history=hist)
    return hist[0]


def test_polish_contact_term_is_the_squared_gap_of_a_region_within_25_mm(bm, hm, scene):
    """E_cont (SAGA Eq. 6, mm): with only the palm asked to touch, a box 12 mm below the lowest palm vertex costs about
    (12 mm)^2 (a smooth minimum: a little less); the same box 30 mm below is beyond the 25 mm reach: 0."""
    e = _energies(bm, hm, scene, regions=(1, 0, 0, 0, 0, 0))["contact"]
    assert 0.6 * 144 < e <= 144 * 1.02, e
    far = dict(scene, sdf=go.PosedSDF(scene["sdf"].grid, np.eye(3)[None], np.array([[0.0, -0.018, 0.0]])),
               box=scene["box"].copy().apply_translation([0.0, -0.018, 0.0]))
    assert _energies(bm, hm, far, regions=(1, 0, 0, 0, 0, 0))["contact"] == 0.0


def test_polish_facing_term_is_zero_for_a_palm_facing_the_surface(bm, hm, scene):
    """E_facing = 1 + n . s (palm normal n against the surface's outward normal s): the rest palm (facing -y) over a
    box top (s = +y) costs about 0, under a ceiling (s = -y) about 2."""
    assert _energies(bm, hm, scene, normal=(0.0, 1.0, 0.0))["facing"] < 0.1
    assert _energies(bm, hm, scene, normal=(0.0, -1.0, 0.0))["facing"] > 1.9


def test_polish_gaze_term_is_zero_for_an_object_straight_ahead(bm, hm, scene):
    """E_gaze = 1 - cos(q, object - head) with GOAL's head direction q (back of the head -> nose): an object 1 m
    ahead along q costs 0, one 1 m behind the head 2."""
    with torch.no_grad():
        v = bm().vertices
    q = scene["gv"].head_direction(v)[0].numpy()
    nose = v[0, scene["gv"].head_front].numpy()
    assert _energies(bm, hm, scene, centre=nose + q)["gaze"] < 1e-4
    assert _energies(bm, hm, scene, centre=nose - q)["gaze"] > 1.99


def test_polish_wrist_limit_is_in_degrees(bm, hm, scene):
    """The wrist range penalty (relu(angle - 80 deg))^2 in rad^2: a wrist turned 90 deg costs (10 deg)^2 in rad^2,
    one turned 60 deg nothing."""
    for deg, want in ((90.0, np.deg2rad(10.0) ** 2), (60.0, 0.0)):
        rot = torch.eye(3).repeat(1, 55, 1, 1)
        rot[0, J["right_wrist"]] = axis_angle_to_matrix(torch.tensor([0.0, 0.0, np.deg2rad(deg)], dtype=torch.float32))
        assert _energies(bm, hm, scene, rot=rot)["limits"] == pytest.approx(want, abs=1e-5)


def test_polish_object_in_hand_term_counts_points_inside_the_palm_only(bm, hm, scene):
    """Eq. 7's object-in-hand sum (mm^2): object points 4 mm inside the palm (along trimesh's outward vertex normals),
    among 300 far points, cost about (4 mm)^2 each (the nearest hand vertex's normal decides); the same points 4 mm
    outside cost nothing."""
    with torch.no_grad():
        v = bm().vertices[0].double().numpy()
    n = trimesh.Trimesh(v, bm.faces.numpy(), process=False).vertex_normals
    ids = hm.palm_ids[::4]
    far = torch.as_tensor(np.random.default_rng(0).uniform(-0.2, 0.2, (300, 3)) + np.array([0.0, 1.5, 0.0])).float()

    def e(sign: float) -> float:
        pts = torch.cat([torch.as_tensor(v[ids] + sign * 0.004 * n[ids]).float(), far])[None]
        return _energies(bm, hm, scene, pts=pts)["colli_obj"]

    inside = e(-1.0)
    assert 0.5 * 16 * len(ids) < inside < 1.5 * 16 * len(ids), (inside, len(ids))
    assert e(+1.0) == 0.0


def test_polish_learning_rate_decays_linearly_to_a_tenth(bm, hm, scene, monkeypatch):
    """polish's docstring: Adam with the learning rate decaying linearly to a tenth: step k of 10 runs at
    lr (1 - 0.9 k / 10)."""
    seen = []

    class Recording(torch.optim.Adam):
        def step(self, *a, **k):
            seen.append(self.param_groups[0]["lr"])
            return super().step(*a, **k)

    monkeypatch.setattr(torch.optim, "Adam", Recording)
    targets = go.PolishTargets(scene["rest"][hm.palm_ids].mean(0)[None], np.array([[0.0, 1.0, 0.0]]),
                               np.array(scene["box"].centroid)[None], np.ones((1, 6)))
    pts = torch.as_tensor(trimesh.sample.sample_surface_even(scene["box"], 500, seed=0)[0]).float()[None]
    go.polish(scene["pb"], hm, scene["head_pb"], (0, 1), torch.eye(3).repeat(1, 55, 1, 1),
              go.coeffs_of(bm, np.zeros((1, 10))), torch.zeros(1, 3), scene["sdf"], targets, pts, steps=10, lr=0.005)
    assert seen == pytest.approx([0.005 * (1 - 0.9 * k / 10) for k in range(10)], rel=1e-9)


def test_fit_arm_vertices_are_on_the_right_arm(bm, hm):
    """HandModel.arm_ids (the polish's forearm and upper arm): in the rest pose every one lies on the body's right
    (SMPL-X: -x) between the right shoulder and wrist joints (the body model's rest joints)."""
    with torch.no_grad():
        out = bm()
    v, j = out.vertices[0].numpy(), out.joints[0].numpy()
    x = v[hm.arm_ids, 0]
    assert len(x) > 100 and (x < 0).all()
    assert j[J["right_wrist"], 0] - 0.02 < np.median(x) < j[J["right_shoulder"], 0] + 0.02


def test_the_pads_depend_on_the_model_file_not_on_flat_hand_mean(bm):
    """HandModel chose the fingertip pads on bm()'s rest body, whose hands are curled or flat by flat_hand_mean: the
    two models of one file shared 2-8 of 4-11 pad vertices per digit, and the same task fitted to an accepted grasp
    with one and a rejected, 5 mm deep one with the other (an independent check). Now one file, one set of pads
    (the mean hands' rest body, as the marker layouts)."""
    from graspkit.body import BodyModel
    from graspkit.paths import default_model_path

    flat = go.HandModel(BodyModel.from_file(default_model_path(), flat_hand_mean=True))
    mean = go.HandModel(bm)
    assert set(flat.pad_ids) == set(mean.pad_ids) == set(go.FINGER_JOINTS)
    for f in go.FINGER_JOINTS:
        np.testing.assert_array_equal(flat.pad_ids[f], mean.pad_ids[f])
