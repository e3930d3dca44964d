"""WANDR's pose / delta / state representation and intention features (§3.2-3.3) on hand-made cases."""
import math

import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

from graspkit import intention as I
from graspkit.data import load_motion
from graspkit.data.rig import R_BASE
from graspkit.paths import DATA_STUBS
from graspkit.rotations import axis_angle_to_matrix, rotation_about_z

ROOT = "data_stubs/motion"


def _standing(heading: float = 0.0, xy=(0.0, 0.0), z: float = 0.9) -> torch.Tensor:
    """p (135,) of a rest-pose body facing `heading` (rad from world +x) with its root at (x, y, z)."""
    R = torch.zeros(22, 3, 3, dtype=torch.float64)
    R[:] = torch.eye(3, dtype=torch.float64)
    R[0] = rotation_about_z(torch.tensor(heading, dtype=torch.float64)) @ torch.as_tensor(R_BASE)
    return I.pose_from_rotmats(torch.tensor([xy[0], xy[1], z], dtype=torch.float64), R)


def _clip(name="locomotion/locomotion_000003.npz"):
    """(p (T,135) float64, rest joints (22,3)) of a sample clip on the shipped body."""
    from graspkit.body import BodyModel
    from graspkit.data import load_motion
    from graspkit.paths import default_model_path

    bm = BodyModel.from_file(default_model_path(), dtype=torch.float64)
    m = load_motion(f"{ROOT}/{name}")
    coeffs = torch.zeros(1, bm.num_betas + bm.num_expression, dtype=torch.float64)
    coeffs[0, :10] = torch.as_tensor(m.betas, dtype=torch.float64)
    rest = bm.shaped(coeffs)[1][0, :22]
    p = I.pose_from_axis_angle(torch.as_tensor(m.trans, dtype=torch.float64), torch.as_tensor(m.poses, dtype=torch.float64))
    return p, rest, m, bm


def test_sizes_are_the_papers():
    assert (I.POSE_DIM, I.DELTA_DIM, I.STATE_DIM, I.INTENTION_DIM) == (135, 135, 268, 7)


def test_heading_of_a_turned_body():
    for a in (0.0, 0.7, -2.5, 3.0):
        assert I.heading_of_pose(_standing(a)).item() == pytest.approx(a, abs=1e-12)


def test_six_d_is_the_first_two_columns_as_scipy_says():
    rng = np.random.default_rng(0)
    aa = rng.normal(size=(5, 22, 3))
    p = I.pose_from_axis_angle(torch.zeros(5, 3, dtype=torch.float64), torch.as_tensor(aa))
    M = Rotation.from_rotvec(aa.reshape(-1, 3)).as_matrix().reshape(5, 22, 3, 3)
    six = np.concatenate([M[..., :, 0], M[..., :, 1]], -1).reshape(5, -1)
    assert np.allclose(p[:, 3:].numpy(), six, atol=1e-12)


def test_delta_of_a_straight_walk_is_forward_in_the_heading_frame():
    """A body facing +y walking 1 m/s along +y: d^t = (1/30, 0, 0) (forward), rotations unchanged (zero deltas)."""
    p = torch.stack([_standing(math.pi / 2, (0.0, k / 30.0)) for k in range(5)])
    d = I.poses_to_deltas(p)
    assert torch.allclose(d[:, :3], torch.tensor([1 / 30, 0.0, 0.0], dtype=torch.float64).expand(4, 3), atol=1e-12)
    assert torch.allclose(d[:, 3:], torch.zeros(4, 132, dtype=torch.float64), atol=1e-12)


def test_delta_of_a_turn_in_place_is_the_same_whatever_the_heading():
    """Turning 2 degrees per frame gives the same root delta from any starting heading (the yaw is removed)."""
    ds = []
    for h0 in (0.0, 1.3, -2.9):
        p = torch.stack([_standing(h0 + math.radians(2 * k)) for k in range(3)])
        ds.append(I.poses_to_deltas(p))
    for d in ds[1:]:
        assert torch.allclose(d, ds[0], atol=1e-12)
    assert ds[0][:, 3:9].abs().max() > 1e-3          # the turn is in the root delta


def test_integrating_deltas_gives_the_clip_back():
    p, rest, _, _ = _clip()
    d = I.poses_to_deltas(p)
    q, out = p[0], [p[0]]
    for k in range(len(d)):
        q = I.integrate_delta(q, d[k])
        out.append(q)
    assert torch.allclose(torch.stack(out), p, atol=1e-9)


def test_forward_kinematics_matches_the_body_model():
    p, rest, m, bm = _clip()
    J = torch.as_tensor(m.joint_positions(bm))[:, :22]
    assert torch.allclose(I.body_joints(p, rest), J, atol=1e-9)


def test_state_features_layout():
    p = _standing(1.0, (3.0, -2.0), z=0.93)
    d = torch.arange(135, dtype=torch.float64)
    s = I.state_features(p, d)
    assert s.shape == (268,)
    assert s[0] == pytest.approx(0.93)                                        # height only, not x, y
    assert torch.allclose(s[1:7], I.pose_from_rotmats(torch.zeros(3, dtype=torch.float64),
                                                      torch.as_tensor(R_BASE)[None].expand(22, 3, 3))[3:9])  # yaw removed
    assert torch.equal(s[133:], d)


def _I(wrist, pelvis, psi, goal, t, goal_heading=None):
    f = lambda x: torch.as_tensor(x, dtype=torch.float64)  # noqa: E731
    return I.intention(f(wrist), f(pelvis), f(psi), f(goal), f(t), None if goal_heading is None else f(goal_heading))


def test_goal_ahead():
    out = _I([0.2, -0.2, 1.0], [0.0, 0.0, 0.9], 0.0, [2.0, 0.0, 1.0], 2.0)
    assert torch.allclose(out[0:3], torch.tensor([0.9, 0.1, 0.0], dtype=torch.float64))            # (G - W) / 2 s
    assert torch.allclose(out[3:5], torch.zeros(2, dtype=torch.float64))                             # already facing it
    assert torch.allclose(out[5:7], torch.tensor([2 * (1 - math.exp(-2)), 0.0], dtype=torch.float64))


def test_goal_behind_and_to_the_left_of_a_turned_body():
    """Facing +y (psi = 90 deg); the goal 3 m behind (-y): in the heading frame it is at -x."""
    out = _I([0.0, 0.0, 1.0], [0.0, 0.0, 0.9], math.pi / 2, [0.0, -3.0, 0.5], 1.0)
    assert torch.allclose(out[0:3], torch.tensor([-3.0, 0.0, -0.5], dtype=torch.float64), atol=1e-12)
    assert torch.allclose(out[3:5], torch.tensor([-2.0, 0.0], dtype=torch.float64), atol=1e-12)   # turn around
    assert torch.allclose(out[5:7], torch.tensor([-2 * (1 - math.exp(-3)), 0.0], dtype=torch.float64), atol=1e-12)
    left = _I([0.0, 0.0, 1.0], [0.0, 0.0, 0.9], math.pi / 2, [-1.0, 0.0, 0.9], 1.0)               # -x is its left
    assert torch.allclose(left[3:5], torch.tensor([-1.0, 1.0], dtype=torch.float64), atol=1e-12)


def test_heading_and_time_left_may_be_plain_numbers():
    """A number for psi or time_left is the same for every body: the result is the tensor call's, and
    rotation_about_z takes a number as scipy's rotation about z."""
    t = lambda x: torch.tensor(x, dtype=torch.float64)  # noqa: E731
    w, p, g = t([[0.2, -0.2, 1.0], [0.0, 0.3, 1.1]]), t([[0.0, 0.0, 0.9], [0.1, 0.0, 0.9]]), t([2.0, 0.5, 1.0])
    want = I.intention(w, p, t([0.5, 0.5]), g, t([1.5, 1.5]))
    assert torch.equal(I.intention(w, p, 0.5, g, 1.5), want)
    np.testing.assert_allclose(rotation_about_z(0.5).numpy(), Rotation.from_euler("z", 0.5).as_matrix(), atol=1e-7)


def test_goal_straight_above_the_pelvis():
    out = _I([0.1, 0.0, 1.0], [0.0, 0.0, 0.9], 0.4, [0.0, 0.0, 1.8], 0.5)
    assert torch.isfinite(out).all()
    assert torch.allclose(out[3:7], torch.zeros(4, dtype=torch.float64))
    assert out[2] == pytest.approx((1.8 - 1.0) / 0.5)
    near = _I([0.1, 0.0, 1.0], [0.0, 0.0, 0.9], 0.0, [1e-4, 0.0, 1.8], 0.5)     # continuous into the limit
    assert torch.allclose(near[5:7], torch.zeros(2, dtype=torch.float64), atol=3e-4)


def test_at_and_past_the_goal_time_the_intention_is_zero():
    for t in (0.0, -0.5):
        out = _I([0.0, 0.0, 1.0], [0.0, 0.0, 0.9], 0.0, [2.0, 1.0, 1.0], t)
        assert torch.equal(out, torch.zeros(7, dtype=torch.float64))


def test_wrist_intention_is_a_velocity_in_metres_per_second():
    """1 m to go with 30 frames (1 s) left: |I^w| = 1 m/s; halving the time doubles it; I^p and I^r have no time."""
    a = _I([0.0, 0.0, 1.0], [0.0, 0.0, 0.9], 0.0, [0.0, 1.0, 1.0], 30 / I.FPS)
    b = _I([0.0, 0.0, 1.0], [0.0, 0.0, 0.9], 0.0, [0.0, 1.0, 1.0], 15 / I.FPS)
    assert a[:3].norm() == pytest.approx(1.0) and torch.allclose(b[:3], 2 * a[:3])
    assert torch.equal(a[3:], b[3:])


def test_pelvis_intention_saturates_at_two():
    out = _I([0.0, 0.0, 1.0], [0.0, 0.0, 0.9], 0.0, [60.0, 80.0, 1.0], 8.0)
    assert out[5:7].norm() == pytest.approx(2.0, abs=1e-12)
    assert torch.allclose(out[5:7] / 2, torch.tensor([0.6, 0.8], dtype=torch.float64))


def test_training_orientation_uses_the_heading_at_the_goal_frame():
    """Goal straight ahead but the body at t_G faces 90 deg left: I^r = (0, 1) - (1, 0)."""
    out = _I([0.0, 0.0, 1.0], [0.0, 0.0, 0.9], 0.3, [5.0, 0.0, 1.0], 1.0, goal_heading=0.3 + math.pi / 2)
    assert torch.allclose(out[3:5], torch.tensor([-1.0, 1.0], dtype=torch.float64), atol=1e-12)


def test_condition_is_invariant_to_rotating_and_moving_start_and_goal_about_z():
    p, rest, _, _ = _clip()
    goal = torch.tensor([1.5, -2.0, 0.6], dtype=torch.float64)
    J0 = rest[0]
    for phi, shift in ((0.9, (3.0, -1.0, 0.0)), (-2.4, (-7.0, 4.0, 0.0))):
        Rz = rotation_about_z(torch.tensor(phi, dtype=torch.float64))
        t, R = I.pose_rotmats(p)
        t2 = (Rz @ (t + J0).unsqueeze(-1)).squeeze(-1) + torch.tensor(shift, dtype=torch.float64) - J0
        R2 = R.clone()
        R2[:, 0] = Rz @ R[:, 0]
        p2 = I.pose_from_rotmats(t2, R2)
        g2 = Rz @ goal + torch.tensor(shift, dtype=torch.float64)
        k = 40
        c1 = I.condition(p[k], I.pose_to_delta(p[k - 1], p[k]), rest, goal, torch.tensor(2.0, dtype=torch.float64))
        c2 = I.condition(p2[k], I.pose_to_delta(p2[k - 1], p2[k]), rest, g2, torch.tensor(2.0, dtype=torch.float64))
        assert torch.allclose(c1, c2, atol=1e-9)
        assert torch.allclose(I.poses_to_deltas(p), I.poses_to_deltas(p2), atol=1e-9)
        assert not torch.allclose(p, p2, atol=1e-3)                    # the poses themselves did change
    # and a goal moved relative to the body does change the condition
    c3 = I.condition(p[40], I.pose_to_delta(p[39], p[40]), rest, goal + 0.5, torch.tensor(2.0, dtype=torch.float64))
    assert not torch.allclose(c1, c3)


def test_intention_from_pose_uses_the_right_wrist_and_pelvis():
    p, rest, m, bm = _clip()
    J = torch.as_tensor(m.joint_positions(bm))
    goal = torch.tensor([0.3, 0.2, 1.1], dtype=torch.float64)
    out = I.intention_from_pose(p[10], rest, goal, torch.tensor(1.0, dtype=torch.float64))
    psi = torch.as_tensor(np.arctan2(*axis_angle_to_matrix(torch.as_tensor(m.poses[10, 0], dtype=torch.float64))[[1, 0], 2].numpy()))
    ref = I.intention(J[10, 21], J[10, 0], psi, goal, torch.tensor(1.0, dtype=torch.float64))
    assert torch.allclose(out, ref, atol=1e-9)


def test_errors_name_the_argument():
    with pytest.raises(ValueError, match="p:"):
        I.state_features(torch.zeros(134), torch.zeros(135))
    with pytest.raises(ValueError, match="d_prev"):
        I.state_features(torch.zeros(135), torch.zeros(3))
    with pytest.raises(ValueError, match="goal"):
        I.intention(torch.zeros(3), torch.zeros(3), torch.tensor(0.0), torch.zeros(2), torch.tensor(1.0))
    with pytest.raises(ValueError, match="rest"):
        I.body_joints(torch.zeros(135), torch.zeros(21, 3))
    with pytest.raises(ValueError, match="wrist, pelvis, psi, goal, time_left: expected shapes that broadcast"):
        I.intention(torch.zeros(2, 3), torch.zeros(2, 3), torch.zeros(5), torch.zeros(2, 3), 1.0)
    out = I.intention(torch.zeros(2, 3), torch.zeros(2, 3), torch.zeros(1), torch.ones(2, 3), torch.tensor([1.0, 0.0]))
    assert out.shape == (2, 7) and (out[1] == 0).all() and (out[0] != 0).any()      # broadcast; past t_G zero


def test_a_nan_time_left_goal_or_body_is_refused_not_read_as_goal_time_passed():
    with pytest.raises(ValueError, match="time_left: contains NaN"):
        _I([0.0, 0.0, 1.0], [0.0, 0.0, 0.9], 0.0, [2.0, 1.0, 1.0], float("nan"))
    with pytest.raises(ValueError, match="goal: contains NaN"):     # I^r would read a NaN goal as "straight above"
        _I([0.0, 0.0, 1.0], [0.0, 0.0, 0.9], 0.0, [float("nan"), 1.0, 1.0], 1.0)
    for time_left in (1.0, -1.0):       # past t_G the intention is zero: a NaN body must not pass unseen there
        with pytest.raises(ValueError, match="wrist: contains NaN"):
            _I([float("nan"), 0.0, 1.0], [0.0, 0.0, 0.9], 0.0, [2.0, 1.0, 1.0], time_left)
        with pytest.raises(ValueError, match="pelvis: contains NaN"):
            _I([0.0, 0.0, 1.0], [0.0, float("inf"), 0.9], 0.0, [2.0, 1.0, 1.0], time_left)
        with pytest.raises(ValueError, match="psi: contains NaN"):
            _I([0.0, 0.0, 1.0], [0.0, 0.0, 0.9], float("nan"), [2.0, 1.0, 1.0], time_left)
        with pytest.raises(ValueError, match="goal_heading: contains NaN"):      # past t_G it gave zeros silently
            _I([0.0, 0.0, 1.0], [0.0, 0.0, 0.9], 0.0, [2.0, 1.0, 1.0], time_left, float("nan"))


def test_a_nan_pose_is_named_as_the_pose_not_as_the_wrist_derived_from_it():
    """intention_from_pose / condition named a NaN in p (or rest) "wrist", an argument the caller did not pass."""
    p, rest = torch.zeros(1, 135, dtype=torch.float64), torch.zeros(1, 22, 3, dtype=torch.float64)
    p[0, 3], p[0, 7] = 1.0, 1.0                                   # the identity root in 6D
    goal, t = torch.tensor([[1.0, 0.0, 1.0]], dtype=torch.float64), torch.tensor([1.0], dtype=torch.float64)
    assert torch.isfinite(I.intention_from_pose(p, rest, goal, t)).all()
    bad = p.clone()
    bad[0, 22] = float("nan")
    with pytest.raises(ValueError, match="^p: contains NaN or Inf"):
        I.intention_from_pose(bad, rest, goal, t)
    with pytest.raises(ValueError, match="^p: contains NaN or Inf"):
        I.condition(bad, torch.zeros(1, 135, dtype=torch.float64), rest, goal, t)
    with pytest.raises(ValueError, match="^rest: contains NaN or Inf"):
        I.intention_from_pose(p, rest * float("nan"), goal, t)


def _start(bm, frame=5):
    f = sorted((DATA_STUBS / "motion" / "locomotion").glob("*.npz"))[0]
    m = load_motion(f)
    return m, I.StartPose.from_motion(m, frame, bm)


def test_from_motion_full_pose_is_the_start_frames(bm):
    m, s = _start(bm, 5)
    np.testing.assert_allclose(s.full_pose.numpy(), m.poses[5], atol=1e-6)
    _, body = I.pose_to_axis_angle(s.p)                      # p's 22 body rotations, as scipy reads them
    np.testing.assert_allclose(Rotation.from_rotvec(body[:22].double().numpy()).as_matrix(),
                               Rotation.from_rotvec(np.asarray(s.full_pose[:22], np.float64)).as_matrix(), atol=1e-5)


def test_from_motion_rest_joints_give_the_motions_joints(bm):
    """FK of the start pose with its rest joints = the body model's joints of that frame (Motion.joint_positions)."""
    m, s = _start(bm, 5)
    J = I.body_joints(s.p, s.rest).double().numpy()
    np.testing.assert_allclose(J, m.joint_positions(bm)[5, :22], atol=1e-4)


def test_a_start_on_another_body_stands_where_it_stood(bm, tmp_path):
    """StartPose.on_body: a start made on graspkit's body moved onto one 8 % larger keeps its pose, the larger body's
    rest joints, its first frame's pelvis x, y and lowest vertex (on the floor), and its delta p_prev -> p; on the same
    body it is the start itself. The truth: the locomotion clip's own frames on the small body, and the larger body's
    vertices of the start rebuilt as a Motion. (A `restand` of the whole clip keeps every frame's shift the same.)"""
    from conftest import PROCEDURAL_MODEL, npz_copy

    from graspkit.body import BodyModel
    from graspkit.data.motion import Motion, restand

    m, s = _start(bm, 5)
    with np.load(PROCEDURAL_MODEL, allow_pickle=False) as z:
        big = BodyModel.from_file(npz_copy(PROCEDURAL_MODEL, tmp_path / "big.npz", v_template=z["v_template"] * 1.08,
                                           shapedirs=z["shapedirs"] * 1.08))
    assert s.on_body(bm, BodyModel.from_file(PROCEDURAL_MODEL)) is s
    o = s.on_body(bm, big)
    k = big.num_betas
    coeffs = torch.zeros(1, k + big.num_expression)
    coeffs[0, :k] = s.betas[:k]
    torch.testing.assert_close(o.rest, big.shaped(coeffs)[1][0, :22].float())
    torch.testing.assert_close(I.pose_to_delta(o.p_prev, o.p), I.pose_to_delta(s.p_prev, s.p), atol=1e-5, rtol=0)
    trans, aa = I.pose_to_axis_angle(torch.stack([o.p_prev, o.p]), o.full_pose)
    mine = Motion(aa.double().numpy(), trans.double().numpy(), s.betas.double().numpy(), 30.0)
    first = m.slice(4, 5)                                                      # p_prev: frame 4 of the clip
    assert float(mine.vertices(big)[0, :, 2].min()) == pytest.approx(float(first.vertices(bm)[0, :, 2].min()), abs=1e-4)
    np.testing.assert_allclose(mine.joint_positions(big)[0, 0, :2], first.joint_positions(bm)[0, 0, :2], atol=1e-4)
    kept = Motion(first.poses, first.trans, first.betas, 30.0)
    assert abs(float(kept.vertices(big)[0, :, 2].min()) - float(first.vertices(bm)[0, :, 2].min())) > 0.03
    whole = restand(m, bm, big)
    np.testing.assert_allclose(whole.trans - m.trans, np.broadcast_to(whole.trans[0] - m.trans[0], m.trans.shape),
                               atol=1e-6)                                      # float32 translations
    assert float(whole.vertices(big, 0, 1)[0, :, 2].min()) == pytest.approx(float(m.vertices(bm, 0, 1)[0, :, 2].min()),
                                                                            abs=1e-5)
    np.testing.assert_array_equal(restand(m, bm, BodyModel.from_file(PROCEDURAL_MODEL)).trans, m.trans)



def test_a_body_of_other_skinning_weights_is_not_the_same_body(bm, tmp_path):
    """StartPose.on_body gives the start back as it is only on the same body: a body with graspkit's template, shape
    space and joint regressor but other skinning weights (every vertex on the pelvis) has the same rest joints (made_on
    holds) yet stands the posed start at another height, so the start is restood on it (its lowest vertex where it was
    on graspkit's body). Until 2026-12-07 template, shapes and regressor alone were compared and such a body got the
    start unmoved."""
    from conftest import PROCEDURAL_MODEL, npz_copy

    from graspkit.body import BodyModel
    from graspkit.data.motion import Motion

    m, s = _start(bm, 5)
    with np.load(PROCEDURAL_MODEL, allow_pickle=False) as z:
        w = np.zeros_like(z["weights"])
        w[:, 0] = 1.0
        flat = BodyModel.from_file(npz_copy(PROCEDURAL_MODEL, tmp_path / "flat.npz", weights=w))
    assert s.made_on(flat)
    first = m.slice(4, 5)                                                      # p_prev: frame 4 of the clip
    low = float(first.vertices(bm)[0, :, 2].min())
    assert abs(float(first.vertices(flat)[0, :, 2].min()) - low) > 1e-3       # kept as it is, it would not stand
    o = s.on_body(bm, flat)
    trans, aa = I.pose_to_axis_angle(torch.stack([o.p_prev, o.p]), o.full_pose)
    mine = Motion(aa.double().numpy(), trans.double().numpy(), s.betas.double().numpy(), 30.0)
    assert float(mine.vertices(flat)[0, :, 2].min()) == pytest.approx(low, abs=1e-4)
    assert s.on_body(bm, BodyModel.from_file(PROCEDURAL_MODEL)) is s

def test_canonical_puts_the_pelvis_joint_over_the_origin_facing_plus_x(bm):
    _, s = _start(bm, 5)
    c = s.canonical()
    J0, Jc = I.body_joints(s.p, s.rest), I.body_joints(c.p, c.rest)
    assert Jc[0, :2].abs().max() < 1e-5                      # the pelvis joint (not the root translation)
    assert abs(Jc[0, 2] - J0[0, 2]) < 1e-5                    # height kept
    assert abs(I.heading_of_pose(c.p).item()) < 1e-5
    torch.testing.assert_close(I.pose_to_delta(c.p_prev, c.p), I.pose_to_delta(s.p_prev, s.p), atol=1e-5, rtol=0)
    # the whole body moved rigidly: pairwise joint distances unchanged, and the rest joint J_0 is not at the origin
    assert s.rest[0].norm() > 0.05
    torch.testing.assert_close(torch.cdist(Jc, Jc), torch.cdist(J0, J0), atol=1e-5, rtol=0)


def test_pose_to_axis_angle_takes_joints_22_to_54_from_rest_unchanged():
    """The docstring: joints 22-54 (jaw, eyes, hands) are taken from `rest` (a full (55, 3) pose)."""
    g = torch.Generator().manual_seed(0)
    rest = 0.3 * torch.randn(55, 3, generator=g, dtype=torch.float64)
    p = I.pose_from_axis_angle(torch.zeros(3, dtype=torch.float64), rest)
    _, aa = I.pose_to_axis_angle(p, rest)
    torch.testing.assert_close(aa[22:], rest[22:], rtol=0, atol=0)
    torch.testing.assert_close(aa[:22], rest[:22], rtol=0, atol=1e-9)     # the body round-trips through p
