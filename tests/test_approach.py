"""The approach clip (graspkit.data.approach): the body slerped into the grasp and held, the pre-shape timing, the
wrist's straight last approach, argument checks; against scipy's Slerp and the body model's own kinematics."""
import numpy as np
import pytest
from scipy.spatial.transform import Rotation, Slerp

from graspkit.body.skeleton import JOINT_INDEX as J
from graspkit.data.approach import _swivel_dirs, approach_motion
from graspkit.data.motion import Motion
from graspkit.data.rig import build_rig


def _mj(u):
    """Minimum-jerk position 10u^3 - 15u^4 + 6u^5, clipped to [0, 1], written out by hand."""
    u = np.clip(u, 0.0, 1.0)
    return 10 * u**3 - 15 * u**4 + 6 * u**5


def _approach_case():
    T, fps, g = 80, 40.0, 60
    poses = np.zeros((T, 55, 3))
    fit = [J[n] for n in ("spine1", "spine2", "spine3", "neck", "head", "right_collar", "right_shoulder",
                          "right_elbow", "right_wrist")]
    poses[:, fit] = [0.0, 0.4, 0.1]
    trans = np.stack([0.02 * np.arange(T), 0.01 * np.arange(T), np.full(T, 0.9)], 1)
    contacts = np.zeros((T, 4), bool)
    contacts[::3, 0] = True
    contacts[1::3, 2] = True
    plan = Motion(poses, trans, np.zeros(10), fps, contacts=contacts)
    grasp = np.zeros((55, 3))
    grasp[fit] = [0.5, -0.1, 0.2]
    grasp[40:55] = [0.0, 0.0, 0.9]
    grasp[J["left_knee"]] = [0.3, 0.0, 0.0]
    open_hand = np.tile([0.0, 0.0, -0.2], (15, 1))
    return plan, g, grasp, open_hand, fit


def test_approach_slerps_the_body_into_the_grasp_and_holds_it():
    """approach_motion without an approach direction (40 fps, grasp frame g): spine, neck, head and right arm are the
    plan's until BLEND_S (20 frames) before g, the geodesic (scipy Slerp) halfway at 10 frames before (min-jerk 0.5),
    the grasp's at g; the fingers are the open pre-shape GRASP_CLOSE_S (10 frames) before g and halfway from the
    plan's to it at 17 frames before; from g on pose, translation and contacts are held."""
    plan, g, grasp, open_hand, fit = _approach_case()
    m = approach_motion(plan, g, grasp, open_hand)
    rp, rg = Rotation.from_rotvec(plan.poses[0, fit[0]]), Rotation.from_rotvec(grasp[fit[0]])
    half = Slerp([0.0, 1.0], Rotation.concatenate([rp, rg]))(0.5)
    for j in fit:
        np.testing.assert_allclose(m.poses[: g - 20, j], plan.poses[: g - 20, j], atol=1e-6)
        got = Rotation.from_rotvec(m.poses[g - 10, j].astype(np.float64))
        assert (got.inv() * half).magnitude() < 1e-5, j
    np.testing.assert_allclose(m.poses[g - 10, 40:55], open_hand, atol=1e-6)
    np.testing.assert_allclose(m.poses[g - 17, 40:55], 0.5 * open_hand, atol=1e-6)
    np.testing.assert_allclose(m.poses[g:], np.broadcast_to(grasp, m.poses[g:].shape), atol=1e-6)
    np.testing.assert_allclose(m.trans[:g + 1], plan.trans[:g + 1], atol=1e-6)
    np.testing.assert_allclose(m.trans[g:], np.broadcast_to(plan.trans[g], m.trans[g:].shape), atol=1e-6)
    assert (m.contacts[:g + 1] == plan.contacts[:g + 1]).all() and (m.contacts[g:] == plan.contacts[g]).all()


def test_approach_rejects_a_bad_grasp_frame_or_start_pose():
    """approach_motion: grasp_frame must be a frame in [0, T) (a negative index is an error, not a frame from the
    end) and start_pose 'idle' or 't_pose' (a typo is an error)."""
    plan, g, grasp, open_hand, _ = _approach_case()
    with pytest.raises(ValueError):
        approach_motion(plan, -1, grasp, open_hand)
    with pytest.raises(ValueError):
        approach_motion(plan, plan.num_frames, grasp, open_hand)
    with pytest.raises(ValueError):
        approach_motion(plan, g, grasp, open_hand, start_pose="tpose")


def test_approach_dir_and_rig_go_together(bm):
    """approach_dir without rig fell back to the plain blend without a word (an independent check): the straight
    approach was lost silently. One without the other is now refused, naming both."""
    plan, g, grasp, open_hand, _ = _approach_case()
    with pytest.raises(ValueError, match="approach_dir, rig: expected both"):
        approach_motion(plan, g, grasp, open_hand, approach_dir=np.array([0.0, 0.0, 1.0]))
    with pytest.raises(ValueError, match="approach_dir, rig: expected both"):
        approach_motion(plan, g, grasp, open_hand, rig=build_rig(bm, np.zeros(10)))
    with pytest.raises(ValueError, match="^betas: expected finite shape coefficients"):
        build_rig(bm, np.full(10, np.nan))


def test_swivel_dirs_carry_over_where_the_arm_is_straight():
    """_swivel_dirs (docstring): the unit part of v perpendicular to the axis, carried over from the previous frame
    where v lies along the axis, and taken from the first good frame when the arm starts straight."""
    axis = np.tile([0.0, 0.0, 1.0], (5, 1))
    v = np.array([[0.0, 0.0, 1.0], [0.0, 0.3, 0.2], [0.005, 0.0, 0.9], [2.0, 0.0, 0.1], [0.0, 0.0, -1.0]])
    want = np.array([[0.0, 1.0, 0.0], [0.0, 1.0, 0.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    np.testing.assert_allclose(_swivel_dirs(v, axis), want, atol=1e-12)


def test_approach_dir_brings_the_wrist_in_on_a_straight_line(bm):
    """approach_motion with approach_dir s and the rig (docstring): over the last APPROACH_S seconds the wrist runs
    along the straight line from APPROACH_DIST out along +s into the grasp's wrist position W, i.e. at W + APPROACH_DIST
    (1 - minimum-jerk(u)) s (u from 0 to 1 over the window, by hand), wrists from the body model's own forward
    kinematics (a bent, reachable arm)."""
    from graspkit.data.approach import APPROACH_DIST, APPROACH_S
    rig = build_rig(bm)
    T, fps, g = 60, 30.0, 50
    poses = np.zeros((T, 55, 3))
    poses[:, J["right_shoulder"]] = [0.0, 0.0, 1.2]                   # the plan: right arm down
    grasp = poses[0].copy()
    grasp[J["right_shoulder"]] = [0.0, 0.9, 0.5]                      # the grasp: arm forward, elbow bent
    grasp[J["right_elbow"]] = [0.0, 1.6, 0.0]
    plan = Motion(poses, np.tile([0.1, 0.9, 0.2], (T, 1)), np.zeros(10), fps)
    s = np.array([0.0, 0.6, 0.8])
    m = approach_motion(plan, g, grasp, np.zeros((15, 3)), approach_dir=s, rig=rig)
    w = m.joint_positions(bm)[:, J["right_wrist"]].astype(np.float64)
    n = int(round(APPROACH_S * fps))
    k = np.arange(g - n, g + 1)
    u = (k - (g - APPROACH_S * fps)) / (APPROACH_S * fps)
    want = w[g] + APPROACH_DIST * (1 - _mj(u))[:, None] * s
    np.testing.assert_allclose(w[k], want, atol=2e-3)
    np.testing.assert_allclose(m.poses[g:], np.broadcast_to(grasp, m.poses[g:].shape), atol=1e-5)
