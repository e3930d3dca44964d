"""Whole-body posing (graspkit.data.posing): poses checked by the body model's own forward kinematics against what the
controls, foot tracks and docstrings ask for."""
import numpy as np
import pytest
import torch

from graspkit.body.skeleton import JOINT_INDEX as J
from graspkit.data.footsteps import GaitStyle, foot_tracks, plan_footsteps
from graspkit.data.motion import Motion
from graspkit.data.posing import Controls, Style, forward_kinematics, hand_pose, pose_body
from graspkit.data.rig import build_rig
from graspkit.data.trajectory import RootPlan, straight_walk


@pytest.fixture(scope="module")
def rig(bm):
    return build_rig(bm)


def _stand(rig, T=6, heading=0.0, xy=(0.0, 0.0)):
    plan = RootPlan(np.tile(np.asarray(xy, float), (T, 1)), np.full(T, heading))
    return plan, foot_tracks(plan_footsteps(plan, rig, GaitStyle()), plan, rig, GaitStyle())


def _walk(rig, T=150, heading=0.0):
    xy, _ = straight_walk(T, (0, 0), heading, 3.0, 0.3, 4.5)
    plan = RootPlan(xy, np.full(T, heading))
    st = GaitStyle()
    return plan, foot_tracks(plan_footsteps(plan, rig, st), plan, rig, st)


def _pose(rig, plan, tracks, style=None, **ctrl):
    c = Controls.zeros(plan.num_frames)
    for k, v in ctrl.items():
        setattr(c, k, v)
    return pose_body(rig, plan, tracks, style or Style(), c)


def test_walking_legs_put_the_ankles_and_feet_exactly_on_their_tracks_with_knees_forward(rig):
    """Legs are analytic two-bone IK onto the planned ankle and the ankle/toe joints take the planned rotations
    (module doc): the body's forward kinematics puts each ankle on the track (< 0.1 mm), the foot and toe global
    rotations equal the tracks', each knee bends forward (ahead of its hip-ankle line along the foot) and by at least
the 8 degrees the pelvis height is chosen for ('highest pelvis from which both legs still reach their ankles with
the knee bent >= 8 degrees')."""
    plan, tr = _walk(rig)
    _, root, ex = _pose(rig, plan, tr)
    p, Rg = ex["joints"], ex["global_rot"]
    for s, side in enumerate(("left", "right")):
        np.testing.assert_allclose(p[:, J[f"{side}_ankle"]], tr.ankle[s], atol=1e-4)
        np.testing.assert_allclose(Rg[:, J[f"{side}_ankle"]], tr.R_foot[s], atol=1e-6)
        np.testing.assert_allclose(Rg[:, J[f"{side}_foot"]], tr.R_toe[s], atol=1e-6)
        hip, knee, ank = p[:, J[f"{side}_hip"]], p[:, J[f"{side}_knee"]], p[:, J[f"{side}_ankle"]]
        u = (ank - hip) / np.linalg.norm(ank - hip, axis=1, keepdims=True)
        off = (knee - hip) - ((knee - hip) * u).sum(1, keepdims=True) * u     # knee's offset from the hip-ankle line
        foot_fwd = tr.R_foot[s] @ np.array([0.0, 0.0, 1.0])
        assert ((off * foot_fwd).sum(1) > 0).all()
        a, b = hip - knee, ank - knee
        flex = np.pi - np.arccos(np.clip((a * b).sum(1) / np.linalg.norm(a, axis=1) / np.linalg.norm(b, axis=1), -1, 1))
        assert np.degrees(flex).min() > 8.0 - 0.05


def test_the_pelvis_bobs_smoothly_and_a_weight_shift_acts_only_while_both_feet_stand(rig):
    """Module doc: the pelvis is lowered where a leg could not reach its foot, in a smooth dip ('a bell, not a
    notch'): walking, its vertical acceleration stays within 0.3 g (the range of the body's vertical acceleration in
    human walking). Controls.weight_shift is 'added to the weight on the left foot while both feet stand': a shift to
    the left moves the pelvis left in double support more than in right single support (where the left foot is up)."""
    plan, tr = _walk(rig)
    _, root, _ = _pose(rig, plan, tr)
    acc = np.diff(root[:, 2], 2) * plan.fps**2
    assert np.abs(acc).max() < 0.3 * 9.81
    T = plan.num_frames
    _, r2, _ = _pose(rig, plan, tr, weight_shift=np.full(T, 0.5))
    d = r2[:, 1] - root[:, 1]                                          # heading 0: left is +y
    on_l, on_r = tr.contacts[:, :2].any(1), tr.contacts[:, 2:].any(1)
    both, only_r = on_l & on_r, on_r & ~on_l
    assert both.sum() > 20 and only_r.sum() > 10
    assert d[both].mean() > 0.005 and d[only_r].mean() < d[both].mean()


def test_a_foot_out_of_reach_does_not_pull_the_pelvis_to_the_floor(rig):
    """posing.py: 'a foot out of reach even with the pelvis at half height is left to the IK to stretch towards':
    with the left ankle's track 1.5 m to the side, the pelvis stays at least at half the standing pelvis height
    and the left leg points (hip -> ankle) straight at the far track."""
    from dataclasses import replace
    T = 4
    plan, tr = _stand(rig, T)
    ankle = tr.ankle.copy()
    ankle[0, :, 1] += 1.5
    tr2 = replace(tr, ankle=ankle)
    _, root, e = _pose(rig, plan, tr2)
    assert (root[:, 2] >= 0.5 * rig.pelvis_height - 1e-9).all()
    p = e["joints"]
    leg = p[:, J["left_ankle"]] - p[:, J["left_hip"]]
    want = ankle[0] - p[:, J["left_hip"]]
    cos = (leg * want).sum(1) / np.linalg.norm(leg, axis=1) / np.linalg.norm(want, axis=1)
    assert (cos > 0.999).all()


def test_pose_body_joints_are_the_body_models_forward_kinematics(bm, rig):
    """The joints pose_body returns are those of its own rotations and pelvis: SMPL-X forward kinematics of the
    returned (axis-angle, root - J0) on the body model gives the same joints (< 0.1 mm), also after a reach with a
    support arm (which re-poses the arms after the first pass)."""
    T = 12
    plan, tr = _stand(rig, T)
    w = np.linspace(0.0, 1.0, T)
    aa, root, ex = _pose(rig, plan, tr, pelvis_drop=np.full(T, 0.25), spine_flex=np.full(T, 0.5),
                         reach_target=np.tile([0.45, -0.25, 0.55], (T, 1)), reach_weight=w,
                         reach_pole=np.tile([0.0, -1.0, -0.3], (T, 1)), support_weight=w)
    jp = Motion(aa, root - rig.joints[0], np.zeros(10)).joint_positions(bm)
    np.testing.assert_allclose(jp, ex["joints"], atol=1e-4)


def test_a_standing_body_stands_at_its_rest_pelvis_height_and_drop_and_back_move_the_pelvis(rig):
    """Standing still (speed 0: no knee bend), the pelvis is at the rest pelvis height above the soles (the legs are
    nearly straight, within 3 mm); pelvis_drop d puts it exactly d below that height and pelvis_back b moves it b backwards along
    the heading (Controls' docs), wherever the plan stands and faces."""
    h = 0.7
    plan, tr = _stand(rig, heading=h, xy=(1.0, -2.0))
    _, root, _ = _pose(rig, plan, tr)
    np.testing.assert_allclose(root[:, 2], rig.pelvis_height, atol=3e-3)
    np.testing.assert_allclose(root[:, :2], plan.xy, atol=1e-9)
    _, root2, _ = _pose(rig, plan, tr, pelvis_drop=np.full(6, 0.1), pelvis_back=np.full(6, 0.08))
    np.testing.assert_allclose(root2[:, 2], rig.pelvis_height - 0.1, atol=1e-6)     # legs bent: no reach limit
    np.testing.assert_allclose(root2[:, :2], plan.xy - 0.08 * np.array([np.cos(h), np.sin(h)]), atol=1e-9)


def test_a_weight_shift_to_the_left_moves_the_pelvis_over_the_left_foot_and_drops_the_right_hip(rig):
    """Controls.weight_shift > 0 adds weight on the left foot while both feet stand: the pelvis sways towards the
    (more) loaded left foot and the unloaded right side drops (obliquity), mirrored for a shift to the right."""
    T = 30
    plan, tr = _stand(rig, T)
    _, r0, e0 = _pose(rig, plan, tr)
    for s in (1.0, -1.0):
        _, r, e = _pose(rig, plan, tr, weight_shift=np.full(T, 0.4 * s))
        p = e["joints"]
        assert s * (r[T // 2, 1] - r0[T // 2, 1]) > 0.005                     # heading 0: left is +y
        dz = p[T // 2, J["left_hip"], 2] - p[T // 2, J["right_hip"], 2]
        assert s * dz > 0.001


def _fwd_yaw_pitch(R):
    """World yaw (about z) and forward pitch-down of a joint's canonical forward axis (+z) under global rotations R."""
    d = R @ np.array([0.0, 0.0, 1.0])
    return np.arctan2(d[:, 1], d[:, 0]), -np.arcsin(np.clip(d[:, 2], -1, 1))


def test_trunk_controls_bend_and_turn_the_way_their_docs_say(rig):
    """Controls' docs, standing facing +x (left = +y): spine_twist turns the thorax left by its total (relative to the
    pelvis); spine_flex bends it forward (the head
    moves forward and down); hip_flex pitches the pelvis forward by its amount and carries the trunk with it, not
    changing the spine's own bend; collar_raise lifts the right shoulder."""
    T = 4
    plan, tr = _stand(rig, T)
    _, _, e0 = _pose(rig, plan, tr)
    p0, R0 = e0["joints"], e0["global_rot"]
    # twist: thorax yaw relative to the pelvis equals the total twist
    _, _, e = _pose(rig, plan, tr, spine_twist=np.full(T, 0.8))
    dyaw = _fwd_yaw_pitch(e["global_rot"][:, J["spine3"]])[0] - _fwd_yaw_pitch(e["global_rot"][:, 0])[0]
    dyaw0 = _fwd_yaw_pitch(R0[:, J["spine3"]])[0] - _fwd_yaw_pitch(R0[:, 0])[0]
    np.testing.assert_allclose(dyaw - dyaw0, 0.8, atol=0.01)
    # forward bend
    _, _, e = _pose(rig, plan, tr, spine_flex=np.full(T, 0.5))
    d = e["joints"][:, J["head"]] - p0[:, J["head"]]
    assert (d[:, 0] > 0.1).all() and (d[:, 2] < -0.02).all()
    # hip flexion: the pelvis pitches forward by hip_flex, the thorax with it (the spine's bend unchanged)
    _, _, e = _pose(rig, plan, tr, hip_flex=np.full(T, 0.3))
    up = lambda R: R @ np.array([0.0, 1.0, 0.0])                      # noqa: E731  canonical up axis, world
    pitch = lambda R: np.arctan2(up(R)[:, 0], up(R)[:, 2])             # noqa: E731  leaning forward (+x) > 0
    np.testing.assert_allclose(pitch(e["global_rot"][:, 0]) - pitch(R0[:, 0]), 0.3, atol=1e-6)
    np.testing.assert_allclose(pitch(e["global_rot"][:, J["spine3"]]) - pitch(R0[:, J["spine3"]]), 0.3, atol=1e-3)
    # right collar elevation
    _, _, e = _pose(rig, plan, tr, collar_raise=np.full(T, 0.3))
    assert (e["joints"][:, J["right_shoulder"], 2] - p0[:, J["right_shoulder"], 2] > 0.01).all()
    np.testing.assert_allclose(e["joints"][:, J["left_shoulder"]], p0[:, J["left_shoulder"]], atol=1e-9)


def test_arm_style_and_arm_flex_move_the_wrists_the_way_their_docs_say(rig):
    """Style and Controls docs, standing facing +x: more arm_abduct takes both wrists further from the body's midline;
    arm_flex flexes the shoulders forward (both wrists move forward and up); more elbow_bend flexes the elbows
    forward (the wrists move forward: an elbow never bends backwards)."""
    T = 4
    plan, tr = _stand(rig, T)
    _, _, e0 = _pose(rig, plan, tr)
    p0 = e0["joints"]
    wr = [J["left_wrist"], J["right_wrist"]]
    lat = lambda p: np.abs(p[:, wr, 1] - p[:, [0], 1])                  # noqa: E731  distance from the midline
    _, _, e = _pose(rig, plan, tr, Style(arm_abduct=0.3))
    assert (lat(e["joints"]) - lat(p0) > 0.05).all()
    _, _, e = _pose(rig, plan, tr, arm_flex=np.full(T, 0.5))
    d = e["joints"][:, wr] - p0[:, wr]
    assert (d[..., 0] > 0.05).all() and (d[..., 2] > 0.01).all()
    _, _, e = _pose(rig, plan, tr, Style(elbow_bend=0.9))
    d = e["joints"][:, wr] - p0[:, wr]
    assert (d[..., 0] > 0.05).all()
    np.testing.assert_allclose(e["joints"][:, [J["left_elbow"], J["right_elbow"]]],
                               p0[:, [J["left_elbow"], J["right_elbow"]]], atol=1e-9)


def test_a_faster_walk_leans_the_pelvis_forward(rig):
    """Style.lean: forward lean (rad) per m/s of speed; walking at about 0.7 m/s the pelvis is pitched forward by
    about lean x speed more than standing (both facing +x)."""
    plan, tr = _walk(rig)
    _, _, e = _pose(rig, plan, tr, Style(lean=0.2))
    up = e["global_rot"][:, 0] @ np.array([0.0, 1.0, 0.0])
    pitch = np.arctan2(up[:, 0], up[:, 2])
    v = np.linalg.norm(np.gradient(plan.xy, axis=0), axis=1) * plan.fps
    cruise = (v > 0.9 * v.max())
    assert cruise.sum() > 20
    np.testing.assert_allclose((pitch[cruise] - pitch[0]).mean(), 0.2 * v[cruise].mean(), rtol=0.25)


def test_a_gaze_point_turns_the_head_onto_it_and_weight_zero_keeps_the_path_look(rig):
    """Controls.gaze (a world point to look at; gaze_weight 1 when not given): a standing body facing +x turns its
    head's forward axis (canonical +z) towards a point 2 m away, 0.6 rad to its left at head height (yaw 0.6,
    pitch 0 seen from the head); with gaze_weight 0 it looks along the path, pitched down by Style.head_pitch."""
    T = 4
    plan, tr = _stand(rig, T)
    _, _, e0 = _pose(rig, plan, tr)
    head = e0["joints"][0, J["head"]]
    target = head + 2.0 * np.array([np.cos(0.6), np.sin(0.6), 0.0])
    _, _, e = _pose(rig, plan, tr, gaze=np.tile(target, (T, 1)))
    d = e["global_rot"][:, J["head"]] @ np.array([0.0, 0.0, 1.0])
    to = target - e["joints"][:, J["head"]]
    to /= np.linalg.norm(to, axis=1, keepdims=True)
    assert (np.arccos(np.clip((d * to).sum(1), -1, 1)) < 0.04).all()
    _, _, e = _pose(rig, plan, tr, gaze=np.tile(target, (T, 1)), gaze_weight=np.zeros(T))
    yaw, pitch = _fwd_yaw_pitch(e["global_rot"][:, J["head"]])
    np.testing.assert_allclose(yaw, 0.0, atol=0.03)
    np.testing.assert_allclose(pitch, Style().head_pitch, atol=0.03)


def _reach_case(rig, T=10, **extra):
    plan, tr = _stand(rig, T)
    _, _, e0 = _pose(rig, plan, tr, **extra)
    sh = e0["joints"][0, J["right_shoulder"]]
    target = sh + 0.8 * rig.arm_length * np.array([1.0, -0.3, -0.6]) / np.linalg.norm([1.0, -0.3, -0.6])
    reach = dict(reach_target=np.tile(target, (T, 1)), reach_weight=np.linspace(0.0, 1.0, T),
                 reach_pole=np.tile([0.0, -1.0, -0.5], (T, 1)), finger_dir=np.tile([1.0, 0.0, -0.3], (T, 1)),
                 palm_dir=np.tile([0.0, 1.0, 0.0], (T, 1)))
    return plan, tr, e0, target, reach


def test_a_reach_blends_from_the_natural_arm_onto_the_target_with_the_hand_turned_as_asked(rig):
    """Controls: reach_weight 0 is the natural arm, 1 the wrist on the target. With the right collar raised, a reach
    whose weight ramps 0 -> 1 leaves the weight-0 frame as without a reach (the body and the arm's joints exactly, the right
fingers within 1 cm: the IK arm sets the upper arm's and forearm's twist itself);
    at weight 1 the right wrist is on the target (< 1 mm; it is within reach), the fingers (canonical -x of the right
    hand) point along finger_dir and the palm (canonical -y) faces palm_dir (as far as they are perpendicular), and
    the elbow flexes as a hinge in the same sense as the natural arm's elbow (canonical +y for the right arm)."""
    from graspkit.data.ik import normalize
    T = 10
    cr = dict(collar_raise=np.full(T, 0.25))
    plan, tr, e0, target, reach = _reach_case(rig, T, **cr)
    aa0, _, _ = _pose(rig, plan, tr, **cr)
    aa, _, e = _pose(rig, plan, tr, **cr, **reach)
    np.testing.assert_allclose(e["joints"][0, :40], e0["joints"][0, :40], atol=1e-9)
    np.testing.assert_allclose(e["global_rot"][0, :17], e0["global_rot"][0, :17], atol=1e-9)
    np.testing.assert_allclose(e["joints"][0, 40:], e0["joints"][0, 40:], atol=0.01)   # (the IK arm's own twist)
    np.testing.assert_allclose(e["joints"][-1, J["right_wrist"]], target, atol=1e-3)
    R = e["global_rot"][-1, J["right_wrist"]]
    f = normalize(np.array([1.0, 0.0, -0.3]))
    np.testing.assert_allclose(R @ np.array([-1.0, 0.0, 0.0]), f, atol=1e-6)
    palm = np.array([0.0, 1.0, 0.0])
    np.testing.assert_allclose(R @ np.array([0.0, -1.0, 0.0]), normalize(palm - (palm @ f) * f), atol=1e-6)
    v0, v = aa0[-1, J["right_elbow"]], aa[-1, J["right_elbow"]]
    assert v0[1] > 0.1 and v[1] > 0.1 and abs(v[1]) > 0.9 * np.linalg.norm(v)


def test_the_support_hand_rests_on_top_of_the_left_knee_in_a_crouch(bm, rig):
    """Controls.support_weight: the left hand onto the left knee (a support when squatting or bending): crouched and
    bent forward with a right-hand reach, at support weight 1 the left wrist is close to the left knee (< 12 cm,
    the soft reach limit may keep it a little short) and above it by most of the knee's half thickness (measured on the
rest mesh: the hand lies on top of the knee, not beside or below it), and the right wrist stays on its target."""
    T = 6
    crouch = dict(pelvis_drop=np.full(T, 0.3), hip_flex=np.full(T, 0.6), spine_flex=np.full(T, 0.8))
    plan, tr, e0, target, reach = _reach_case(rig, T, **crouch)
    sw = np.linspace(0.0, 1.0, T)
    _, _, e = _pose(rig, plan, tr, **crouch, **reach, support_weight=sw)
    p = e["joints"]
    knee, wrist = p[-1, J["left_knee"]], p[-1, J["left_wrist"]]
    with torch.no_grad():
        v = bm(betas=torch.zeros(1, 10, dtype=bm.dtype)).vertices[0].double().numpy()
    k = rig.joints[J["left_knee"]]
    ring = v[(np.abs(v[:, 1] - k[1]) < 0.01) & (v[:, 0] > 0.02)]        # the left leg's rest cross-section at the knee
    half_depth = 0.5 * (ring[:, 2].max() - ring[:, 2].min())
    assert np.linalg.norm(wrist - knee) < 0.12 and wrist[2] - knee[2] > 0.8 * half_depth
    np.testing.assert_allclose(p[-1, J["right_wrist"]], target, atol=1e-3)


def test_fingers_curl_towards_the_palm_on_both_hands(rig):
    """hand_pose: a curl flexes the fingers towards the palm (SMPL-X canonical: palms face -y in the T-pose), on
    both hands; the thumb's spread abducts the thumb at its base (carpometacarpal) joint, so the whole thumb swings
    (its second joint moves); and in pose_body both relaxed hands curl towards the palm, seen in each wrist's frame."""
    T = 1
    local = np.broadcast_to(np.eye(3), (T, 55, 3, 3)).copy()
    _, rest = forward_kinematics(rig, local, np.zeros((T, 3)))
    local[:, 25:40] = hand_pose("left", np.ones(T))
    local[:, 40:55] = hand_pose("right", np.ones(T))
    _, p = forward_kinematics(rig, local, np.zeros((T, 3)))
    for side in ("left", "right"):
        for f in ("index", "middle", "ring", "pinky"):
            a, b = J[f"{side}_{f}1"], J[f"{side}_{f}3"]
            assert (p[0, b] - p[0, a])[1] < (rest[0, b] - rest[0, a])[1] - 0.005, (side, f)
    for side in ("left", "right"):                                    # the thumb abducts about its base joint
        local = np.broadcast_to(np.eye(3), (2, 55, 3, 3)).copy()
        local[:, 25:40] = hand_pose("left", np.zeros(2), np.array([0.0, 1.0]))
        local[:, 40:55] = hand_pose("right", np.zeros(2), np.array([0.0, 1.0]))
        _, q = forward_kinematics(rig, local, np.zeros((2, 3)))
        t1, t2 = J[f"{side}_thumb1"], J[f"{side}_thumb2"]
        np.testing.assert_allclose(q[1, t1], q[0, t1], atol=1e-12)
        assert np.linalg.norm(q[1, t2] - q[0, t2]) > 0.005
    plan, tr = _stand(rig, 3)
    _, _, e = _pose(rig, plan, tr)
    for side in ("left", "right"):
        Rw = e["global_rot"][0, J[f"{side}_wrist"]]
        for f in ("index", "middle", "ring", "pinky"):
            a, b = J[f"{side}_{f}1"], J[f"{side}_{f}3"]
            local_d = Rw.T @ (e["joints"][0, b] - e["joints"][0, a])
            assert local_d[1] < (rest[0, b] - rest[0, a])[1] - 0.005, (side, f)
