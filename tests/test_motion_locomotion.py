"""Footstep planner, foot motion and contact labels, locomotion clips measured on the procedural humanoid's mesh."""
import numpy as np
import pytest
import torch

from graspkit import metrics as M
from graspkit.body.markers import foot_vertices
from graspkit.body.skeleton import JOINT_INDEX as J
from graspkit.data import generate_locomotion
from graspkit.data.footsteps import GaitStyle, foot_tracks, plan_footsteps, support_weight
from graspkit.data.locomotion import _segments, locomotion_plan
from graspkit.data.motion import Motion
from graspkit.data.rig import build_rig
from graspkit.data.trajectory import RootPlan, heading_profile, integrate_controls, straight_walk


@pytest.fixture(scope="module")
def rig(bm):
    return build_rig(bm)


@pytest.mark.parametrize("v", [0.6, 1.0, 1.5])
def test_straight_walk_alternates_feet_with_cadence_and_step_length_from_speed(rig, v):
    T, style = 330, GaitStyle()
    xy, speed = straight_walk(T, (0, 0), 0.0, v * (10.0 - 0.9), 0.5, 10.5)   # cruising at v between the ramps
    assert np.isclose(speed[150], v, rtol=1e-3)
    steps = plan_footsteps(RootPlan(xy, np.zeros(T)), rig, style)
    assert all(a.side != b.side for a, b in zip(steps, steps[1:]))                       # alternating
    cruise = [s for s in steps if 3.5 < s.t_land < 7.5]
    f = style.cadence(v, rig.scale)
    assert np.allclose([1 / s.period for s in cruise], f, rtol=0.02)                    # cadence from speed
    lengths = np.diff([s.xy[0] for s in steps if 3.0 < s.t_land < 8.0])
    assert np.allclose(lengths, v / f, rtol=0.1)                                         # step length = v / cadence
    lat = np.array([s.xy[1] for s in cruise]) * np.where([s.side == 0 for s in cruise], 1, -1)
    width = style.half_width * rig.scale * (1 + style.width_gain * (1 - v))          # narrower when faster
    assert np.allclose(lat, width, atol=1e-3)                                           # left at +y, right at -y
    swing = np.array([s.t_land - s.t_lift for s in cruise])
    assert np.allclose(swing, 2 * (1 - style.duty) / f, rtol=0.02) and (swing < 2 / f - swing).all()   # swing < stance


def test_standing_still_takes_no_step_and_turning_in_place_follows_the_heading(rig):
    T = 150
    assert plan_footsteps(RootPlan(np.zeros((T, 2)), np.zeros(T)), rig, GaitStyle()) == []
    h = heading_profile(T, 0.0, np.pi / 2, 0.5, 3.0)
    steps = plan_footsteps(RootPlan(np.zeros((T, 2)), h), rig, GaitStyle())
    assert 2 <= len(steps) <= 8
    style = GaitStyle()
    last = {s.side: s for s in steps}
    for side, s in last.items():
        want = np.pi / 2 + (style.toe_out if side == 0 else -style.toe_out)
        assert abs(s.yaw - want) < style.yaw_threshold + 1e-9


def test_contact_labels_are_honest_on_the_mesh(bm, rig):
    """A labelled heel / toe touches the ground and has a vertex that does not move (the pivot it rolls about);
    an unlabelled one is not below the ground."""
    T = 120
    v_ctrl = np.r_[np.zeros(20), np.full(T - 20, 1.2)]
    plan = integrate_controls(np.convolve(v_ctrl, np.ones(15) / 15, "same"), np.zeros(T), np.full(T, 0.25), fps=30.0)
    style = GaitStyle()
    tracks = foot_tracks(plan_footsteps(plan, rig, style), plan, rig, style)
    from graspkit.data.posing import Style, pose_body
    from graspkit.data.motion import Motion
    aa, root, _ = pose_body(rig, plan, tracks, Style())
    m = Motion(aa, root - rig.joints[0], np.zeros(10), contacts=tracks.contacts)
    v = m.vertices(bm).numpy()
    parts = foot_vertices(bm)
    for k, name in enumerate(("left_heel", "left_toe", "right_heel", "right_toe")):
        on = tracks.contacts[:, k]
        assert on.any() and (~on).any()
        p = v[:, parts[name]]
        assert p[on, :, 2].min(1).max() < 0.01                        # in contact: on the ground (1 cm)
        stay = np.flatnonzero(on[:-1] & on[1:])
        near = (p[stay, :, 2] < 0.01) & (p[stay + 1, :, 2] < 0.01)
        move = np.linalg.norm(p[stay + 1, :, :2] - p[stay, :, :2], axis=-1)
        still = np.where(near, move, np.inf).min(1)
        assert still.max() < 5e-4                                     # a planted point: moves < 0.5 mm per frame
        assert p[~on, :, 2].min() > -0.005                            # never below the ground
    low = M.lowest_vertex_motion(v)[0]
    assert low.max() < M.WANDR_SKATE_THRESHOLD                        # the whole body's lowest vertex never skates


@pytest.mark.parametrize("kind", ["walk", "curve", "turn", "side", "start_stop"])
def test_locomotion_clips_do_not_skate_penetrate_or_break_joints(bm, kind):
    m = generate_locomotion(11, bm, num_frames=110, kind=kind)
    q = M.motion_quality(bm, [m])
    assert q["fs_wandr"] <= 0.05 and q["slide_goal"] <= 0.03
    assert q["penetration_max"] <= 0.01
    assert q["joint_limit_max"] == 0.0
    assert q["max_joint_speed"] < 8.0
    assert m.contacts.any(1).all()                       # something always touches the ground (walking, no flight)


def test_chunked_quality_equals_whole_clip_quality(bm):
    m = generate_locomotion(5, bm, num_frames=60, kind="walk")
    a, b = M.motion_quality(bm, [m], chunk=7), M.motion_quality(bm, [m], chunk=1000)
    for k in ("fs_wandr", "skate_saga", "slide_goal", "penetration_max", "frames"):
        assert a[k] == pytest.approx(b[k])
    v = m.vertices(bm)
    assert a["fs_wandr"] == pytest.approx(M.foot_skating_wandr(v).mean())


def test_motion_quality_reads_a_clip_the_same_at_120_and_30_fps(bm):
    """A standing body glides at 0.25 m/s (0.83 cm per frame at 30 fps, 0.21 cm at 120 fps): WANDR's FS (0.66 cm per
    frame at 30 fps) counts every pair at both rates, GOAL's sliding (1 cm) none; a 0.1 m/s glide skates at neither."""
    from graspkit.data.motion import Motion

    for speed, fs in ((0.25, 1.0), (0.1, 0.0)):
        for fps in (30.0, 120.0):
            T = int(fps // 2)
            trans = np.zeros((T, 3), np.float32)
            trans[:, 0] = speed * np.arange(T) / fps
            m = Motion(np.zeros((T, 55, 3), np.float32), trans, np.zeros(10, np.float32), fps)
            q = M.motion_quality(bm, [m])
            assert q["fs_wandr"] == fs and q["slide_goal"] == 0.0, (speed, fps)


def test_clips_too_short_for_a_metric_add_frames_but_nothing_else(bm):
    m = generate_locomotion(5, bm, num_frames=40, kind="walk")
    alone = M.motion_quality(bm, [m])
    for n in (1, 2, 3):                                  # no frame pair / no jerk (needs 4 frames) in these clips
        q = M.motion_quality(bm, [m.slice(0, n), m], chunk=16)
        assert q["clips"] == 2 and q["frames"] == alone["frames"] + n
        pairs = 39 + n - 1
        assert q["fs_wandr"] == pytest.approx(alone["fs_wandr"] * 39 / pairs)
        assert q["mean_jerk"] == pytest.approx(alone["mean_jerk"]) and alone["mean_jerk"] > 0


def test_saga_canonical_frame_of_a_clip(bm):
    from graspkit.data.motion import canonicalize
    from graspkit.data.ik import axis_angle_matrix
    m = generate_locomotion(2, bm, num_frames=30, kind="walk")
    j = m.joint_positions(bm)
    R, o = canonicalize(j)
    facing = R @ axis_angle_matrix(m.poses[0, 0].astype(np.float64))[:, 2]   # the body's forward axis
    assert facing[1] > 0.9                                     # y forward
    c = (j - o) @ R.T
    assert np.allclose(R @ R.T, np.eye(3), atol=1e-9) and np.allclose(c[0, 0], 0, atol=1e-6)
    s = c[0, 17] - c[0, 16]                                   # left -> right shoulder along +x, horizontal
    assert s[0] > 0.3 and abs(s[1]) < 1e-6
    nose_dir = c[0, 15] - c[0, 12]                            # head above neck: z up
    assert nose_dir[2] > 0


def test_same_seed_same_clip_different_seed_different_clip(bm):
    a, b, c = (generate_locomotion(s, bm, num_frames=45) for s in (3, 3, 4))
    assert np.array_equal(a.poses, b.poses) and np.array_equal(a.trans, b.trans) and np.array_equal(a.betas, b.betas)
    assert not np.array_equal(a.betas, c.betas)


# ------------------------------------------------------------------ headings across +-pi, the gait's size scaling
def test_plan_heading_is_interpolated_the_short_way_across_pi():
    plan = RootPlan(np.zeros((2, 2)), np.array([np.pi - 0.1, -np.pi + 0.1]), fps=30.0)
    _, h = plan.at(0.5 / 30.0)
    assert np.cos(h) < -0.999                                # half-way is pi, not 0


def test_turn_rate_is_steady_when_the_heading_wraps():
    T, fps, w = 300, 30.0, 0.5
    h = np.angle(np.exp(1j * w * np.arange(T) / fps))           # wraps from pi to -pi twice
    np.testing.assert_allclose(RootPlan(np.zeros((T, 2)), h, fps).turn_rate(), w, atol=1e-9)


def test_heading_profile_turns_the_short_way():
    h = heading_profile(90, 3.0, -3.0, 0.5, 2.5)
    assert np.abs(np.diff(h)).sum() < 0.3 + 1e-9                # a 0.28 rad turn through pi, not 6 rad back round
    assert abs(np.angle(np.exp(1j * (h[-1] + 3.0)))) < 1e-9


def test_integrated_controls_follow_a_circle_and_step_left():
    """A constant forward speed v and turn rate w trace the circle of radius v / w; the left of heading h is
    (-sin h, cos h)."""
    T, fps, v, w = 301, 30.0, 1.0, 0.8
    plan = integrate_controls(np.full(T, v), np.zeros(T), np.full(T, w), fps=fps)
    t = np.arange(T) / fps
    np.testing.assert_allclose(plan.xy, np.stack([np.sin(w * t), 1 - np.cos(w * t)], 1) * v / w, atol=2e-3)
    np.testing.assert_allclose(plan.heading, w * t, atol=1e-9)
    side = integrate_controls(np.zeros(T), np.full(T, 0.5), np.zeros(T), heading0=np.pi / 2, fps=fps)
    np.testing.assert_allclose(side.xy[-1], [-0.5 * (T - 1) / fps, 0.0], atol=1e-9)     # facing +y, left is -x


def test_cadence_scales_like_a_pendulum():
    """Dynamic similarity: a body s times the size steps at 1 / sqrt(s) the cadence at s times the speed."""
    g = GaitStyle()
    for s in (0.9, 1.1, 1.21):
        np.testing.assert_allclose(g.cadence(0.0, s), g.cadence(0.0, 1.0) / np.sqrt(s), rtol=1e-12)
        np.testing.assert_allclose(g.cadence(1.2 * s, s), g.cadence(1.2, 1.0) / np.sqrt(s), rtol=1e-12)
    assert g.cadence(1.0, 1.1) < g.cadence(1.0, 1.0)


def test_support_weight_moves_from_the_old_stance_foot_to_the_new_one():
    """Left single support, 5 frames on both feet, right single support: the weight on the left foot falls from 1
    to 0 through the double support, monotonically."""
    T = 30
    c = np.zeros((T, 4), bool)
    c[:15, :2] = True            # left heel and toe on the ground for frames 0..14
    c[10:, 2:] = True            # right foot from frame 10: both feet on frames 10..14
    w = support_weight(c, 30.0)
    np.testing.assert_array_equal(w[:10], 1.0)
    np.testing.assert_array_equal(w[15:], 0.0)
    assert (np.diff(w[9:16]) < 0).all()
    assert w[10] > 0.5 > w[14]


def test_curved_walk_turns_at_curvature_times_speed():
    """A curved walk segment of curvature k at speed v turns at k * v rad/s (steady state)."""
    fps, T, checked = 30.0, 600, 0
    for seed in range(4):
        segs = _segments("curve", np.random.default_rng(seed), T / fps)     # the same draws locomotion_plan makes
        plan, _ = locomotion_plan("curve", np.random.default_rng(seed), T, fps)
        w, speed = plan.turn_rate(), plan.speed()
        t0 = 0.0
        for name, dur, p in segs:
            mid = int(round((t0 + dur / 2) * fps))
            if name == "walk" and dur >= 2.4 and t0 >= 0.5 and t0 + dur <= T / fps:   # steady middle of a segment
                assert abs(speed[mid] - p["v"]) < 0.02 * p["v"] + 0.01
                assert abs(w[mid] - p["k"] * p["v"]) < 0.05 * abs(p["k"] * p["v"]) + 0.02, (seed, p)
                checked += 1
            t0 += int(round(dur * fps)) / fps
    assert checked >= 4


def test_every_locomotion_clip_starts_near_the_origin(bm):
    """Every locomotion clip starts within 0.5 m of the origin in x and y (generate_locomotion) and moves away from it."""
    for seed, kind in ((0, "walk"), (1, "curve"), (2, "backward")):
        m = generate_locomotion(seed, bm, num_frames=90, kind=kind)
        assert np.abs(m.trans[0, :2]).max() <= 0.5 + 1e-9, (seed, kind)
        assert np.linalg.norm(m.trans[-1, :2] - m.trans[0, :2]) > 0.3 or kind == "backward"   # it did move


def test_leg_length_is_thigh_plus_shin_of_the_rest_joints(bm):
    """Rig.leg_length is the hip -> knee -> ankle length (docstring) of the body's rest joints, and arm_length the
    shoulder -> elbow -> wrist one, for a body of another shape (beta_0 = 1.5)."""
    betas = np.zeros(10)
    betas[0] = 1.5
    rig = build_rig(bm, betas)
    with torch.no_grad():
        j = bm(betas=torch.as_tensor(betas[None], dtype=bm.dtype)).joints[0].double().numpy()
    thigh = np.linalg.norm(j[J["left_knee"]] - j[J["left_hip"]])
    shin = np.linalg.norm(j[J["left_ankle"]] - j[J["left_knee"]])
    assert abs(rig.leg_length - (thigh + shin)) < 1e-6
    arm = np.linalg.norm(j[J["right_elbow"]] - j[J["right_shoulder"]]) + np.linalg.norm(j[J["right_wrist"]] - j[J["right_elbow"]])
    assert abs(rig.arm_length - arm) < 1e-6


# In a straight walk the pelvis sways over the stance foot (posing.py: the weight goes to the loaded foot) and the
# arms swing in counter-phase with the legs and with each other (module doc), measured on the mesh joints of the
# generated clip.
@pytest.fixture(scope="module")
def walk(bm):
    m = generate_locomotion(3, bm, num_frames=180, kind="walk")
    p = m.joint_positions(bm)
    v = np.gradient(p[:, 0, :2], axis=0)
    fwd = v / np.linalg.norm(v, axis=1, keepdims=True)
    left = np.stack([-fwd[:, 1], fwd[:, 0]], 1)
    moving = np.linalg.norm(v, axis=1) * m.fps > 0.5
    return m, p, fwd, left, moving


def _along(x, d):
    return (x * d).sum(1)


def test_pelvis_sways_towards_the_stance_foot(walk):
    m, p, fwd, left, moving = walk
    mid = 0.5 * (p[:, J["left_ankle"], :2] + p[:, J["right_ankle"], :2])
    lat = _along(p[:, 0, :2] - mid, left)
    c = m.contacts.astype(bool)
    on_l, on_r = c[:, :2].any(1), c[:, 2:].any(1)
    only_l, only_r = moving & on_l & ~on_r, moving & on_r & ~on_l
    assert only_l.sum() > 10 and only_r.sum() > 10
    assert lat[only_l].mean() > 0.005 and lat[only_r].mean() < -0.005


def test_arms_swing_against_the_legs_and_each_other(walk):
    m, p, fwd, left, moving = walk
    rel = lambda j: _along(p[:, J[j], :2] - p[:, 0, :2], fwd)[moving]        # noqa: E731  ahead of the pelvis
    lw, rw, la, ra = rel("left_wrist"), rel("right_wrist"), rel("left_ankle"), rel("right_ankle")
    corr = lambda a, b: np.corrcoef(a - a.mean(), b - b.mean())[0, 1]       # noqa: E731
    assert corr(lw, rw) < -0.5                                             # the arms alternate
    assert corr(lw, la) < -0.3 and corr(rw, ra) < -0.3                     # each arm against its own leg


def test_duration_from_first_to_last_frame():
    """Motion.duration is the time from the first to the last frame, (T - 1) / fps."""
    m = Motion(np.zeros((31, 55, 3)), np.zeros((31, 3)), np.zeros(10), 30.0)
    assert m.duration == 1.0
    assert Motion(np.zeros((1, 55, 3)), np.zeros((1, 3)), np.zeros(10), 30.0).duration == 0.0


def test_a_curve_plan_does_not_turn_in_place_at_its_start():
    """A 'curve' program walks arcs of curvature |k| <= 0.8 rad/m and starts from rest: over its first quarter
    second the heading turns at most 0.8 rad per metre walked, not in place."""
    for seed in range(10):
        plan, _ = locomotion_plan("curve", np.random.default_rng(seed), 120)
        rest = int(0.25 * plan.fps)
        h = np.unwrap(plan.heading)
        walked = np.linalg.norm(np.diff(plan.xy[:rest + 1], axis=0), axis=1).sum()
        assert abs(h[rest] - h[0]) <= 0.8 * walked, (seed, abs(h[rest] - h[0]), walked)
