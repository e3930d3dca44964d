"""Grasp fitting internals: partial skinning, the analytic arm, hand shapes, closing fingers until contact."""
import numpy as np
import pytest
import torch
import trimesh

from graspkit.body.hand_poses import _FINGER_TEMPLATES, _SPREAD, _THUMB_TEMPLATES, hand_axes, template_pose
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


def test_hand_shapes_use_the_hand_pose_conventions(bm):
    """hand_pose_from_angles with a template's angles reproduces graspkit.body.hand_poses.template_pose."""
    axes = hand_axes(build_rig(bm).joints, "right")
    for kind in ("power", "pinch", "hook"):
        fingers = np.array([_FINGER_TEMPLATES[kind][f] for f in FINGERS[:4]], float)
        spread = np.array([_SPREAD[f] * 0.3 for f in FINGERS[:4]])
        out = go.hand_pose_from_angles(axes, fingers, np.array(_THUMB_TEMPLATES[kind], float), spread)
        assert np.allclose(out.reshape(45), template_pose(kind, axes), atol=1e-12)


def test_fingers_close_until_they_touch_a_box(bm, hm):
    """An open right hand above a box (rest pose, palm facing -y): every digit stops within a few mm of the analytic
    box surface and no deeper than the stop depth plus the grid's error, or closes fully without touching."""
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
    lo, hi = box.bounds
    def box_sdf(p):
        q = np.abs(p - box.centroid) - (hi - lo) / 2                                # analytic box SDF
        return np.linalg.norm(np.maximum(q, 0), axis=1) + np.minimum(q.max(1), 0)

    open_rot = torch.eye(3).repeat(1, 55, 1, 1)
    open_rot[0, 40:55] = axis_angle_to_matrix(torch.as_tensor(path(np.zeros((1, 5)))[0], dtype=torch.float32))
    v_open = bm.forward_rotmats(open_rot).vertices[0].detach().numpy()
    for k, f in enumerate(FINGERS):
        d = box_sdf(v[hm.finger_ids[f]])
        if f != "thumb":
            assert 0 < curls[0, k] < 1, f"{f} never touched or started inside"
        if curls[0, k] == 0:       # a digit that is already inside when open stays open
            assert box_sdf(v_open[hm.finger_ids[f]]).min() < -go.PENETRATION_STOP
        else:
            assert -0.0025 < d.min() < 0.004, f"{f}: closest {d.min() * 1000:.1f} mm from the surface"


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
