"""Footstep planner, foot motion and contact labels, locomotion clips measured on the procedural humanoid's mesh."""
import numpy as np
import pytest
import torch
from scipy.ndimage import gaussian_filter1d

from graspkit import metrics as M
from graspkit.body import BodyModel
from graspkit.body.markers import foot_vertices
from graspkit.body.skeleton import JOINT_INDEX as J
from graspkit.data import generate_locomotion
from graspkit.data.footsteps import GaitStyle, foot_tracks, plan_footsteps, support_weight
from graspkit.data.ik import wrap_angle
from graspkit.data.locomotion import _segments, locomotion_plan
from graspkit.data.motion import Motion
from graspkit.data.posing import Controls, Style, pose_body
from graspkit.data.rig import build_rig
from graspkit.data.trajectory import RootPlan, heading_profile, integrate_controls, straight_walk
from graspkit.paths import REPO_ROOT


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


def test_a_one_or_two_frame_stand_is_the_start_of_a_longer_one(rig):
    """A body standing still is posed the same on every frame, so one- and two-frame plans give the first frames of a
    five-frame plan (they crashed: central differences and the arms' two-frame lag need three frames)."""
    def posed(T):
        plan = RootPlan(np.tile([[0.3, -0.2]], (T, 1)), np.full(T, 0.7))
        assert np.array_equal(plan.speed(), np.zeros(T)) and np.array_equal(plan.turn_rate(), np.zeros(T))
        tracks = foot_tracks(plan_footsteps(plan, rig, GaitStyle()), plan, rig, GaitStyle())
        return pose_body(rig, plan, tracks, Style())[:2]
    local5, root5 = posed(5)
    assert np.allclose(local5, local5[:1]) and np.allclose(root5, root5[:1])
    for T in (1, 2):
        local, root = posed(T)
        assert np.array_equal(local, local5[:T]) and np.array_equal(root, root5[:T])


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


def test_standing_feet_stand_under_the_rest_ankles(bm, rig):
    """A body standing still (facing +x) stands with its ankles where the rest skeleton has them relative to the
    pelvis, along the facing direction: the footprint is under the ankle (FootGeometry.ref), not mirrored about the
    pelvis. Truth: the rest joints of the body model (canonical z forward -> world x)."""
    T = 6
    plan = RootPlan(np.zeros((T, 2)), np.zeros(T))
    tracks = foot_tracks(plan_footsteps(plan, rig, GaitStyle()), plan, rig, GaitStyle())
    _, _, extra = pose_body(rig, plan, tracks, Style())
    pos = extra["joints"]
    with torch.no_grad():
        j = bm(betas=torch.zeros(1, 10, dtype=bm.dtype)).joints[0].double().numpy()
    for side in ("left", "right"):
        want = j[J[f"{side}_ankle"], 2] - j[J["pelvis"], 2]            # rest: ankle ahead (+) / behind (-) the pelvis
        got = pos[:, J[f"{side}_ankle"], 0] - pos[:, J["pelvis"], 0]
        np.testing.assert_allclose(got, want, atol=0.01)


def test_footsteps_do_not_depend_on_how_the_heading_is_wrapped(rig):
    """A turn in place across +-pi: the plan with its heading wrapped to (-pi, pi] (a jump of 2 pi at the seam) is the
    same motion as the unwrapped one, so it takes the same steps at the same times (angles are compared modulo 2 pi)."""
    T = 150
    h = heading_profile(T, 2.6, -2.6, 0.5, 3.0)             # the short way: +1.08 rad through pi
    assert h.max() > np.pi
    a = plan_footsteps(RootPlan(np.zeros((T, 2)), h), rig, GaitStyle())
    b = plan_footsteps(RootPlan(np.zeros((T, 2)), wrap_angle(h)), rig, GaitStyle())
    assert len(a) >= 2
    assert [(s.side, round(s.t_lift, 6)) for s in a] == [(s.side, round(s.t_lift, 6)) for s in b]
    T2 = 90                                                   # standing still facing -x, heading noise across the seam
    h2 = wrap_angle(np.pi + 1e-3 * np.where(np.arange(T2) % 2 == 0, 1.0, -1.0))
    assert plan_footsteps(RootPlan(np.zeros((T2, 2)), h2), rig, GaitStyle()) == []


def test_backward_steps_land_without_a_heel_strike(rig):
    """Walking backwards the foot lands toes first (the heel-strike toes-up angle is for forward travel:
    GaitStyle.strike_gain per m ahead); walking forwards it lands heel first."""
    T = 150
    xb, _ = straight_walk(T, (0, 0), np.pi, 2.0, 0.3, 4.5)      # moving along -x while facing +x
    back = plan_footsteps(RootPlan(xb, np.zeros(T)), rig, GaitStyle())
    xf, _ = straight_walk(T, (0, 0), 0.0, 2.0, 0.3, 4.5)
    fwd = plan_footsteps(RootPlan(xf, np.zeros(T)), rig, GaitStyle())
    assert len(back) >= 4 and all(s.strike == 0.0 for s in back)
    assert max(s.strike for s in fwd) > 0.1


def test_support_weight_moves_from_the_right_foot_to_the_left():
    """The mirror of the suite's left -> right case: right single support, 5 frames on both feet, then left single
    support: the weight on the left foot rises from 0 to 1 through the double support, monotonically (w -> 1 - w)."""
    T = 30
    c = np.zeros((T, 4), bool)
    c[:15, 2:] = True
    c[10:, :2] = True
    w = support_weight(c, 30.0)
    np.testing.assert_array_equal(w[:10], 0.0)
    np.testing.assert_array_equal(w[15:], 1.0)
    assert (np.diff(w[9:16]) > 0).all()
    c2 = c[:, [2, 3, 0, 1]]                                   # the same contacts with the sides swapped
    np.testing.assert_allclose(support_weight(c2, 30.0), 1.0 - w, atol=1e-12)


def test_the_swing_joins_the_stance_without_a_jump_in_vertical_speed(rig):
    """The swing is a Hermite curve matched to the toe-off and heel-strike states (module doc) plus a clearance bump:
    sampled finely (600 fps), the ankle's vertical speed is continuous at lift-off and at landing (a jump < 0.15 m/s;
    a bump with non-zero slope at its ends adds about 0.5 m/s)."""
    fps = 600.0
    T = int(4.0 * fps)
    xy, _ = straight_walk(T, (0, 0), 0.0, 2.5, 0.3, 3.8, fps=fps)
    plan = RootPlan(xy, np.zeros(T), fps)
    steps = plan_footsteps(plan, rig, GaitStyle())
    tr = foot_tracks(steps, plan, rig, GaitStyle())
    assert len(steps) >= 4
    for s in steps[1:-1]:
        z = tr.ankle[s.side, :, 2]
        for t in (s.t_lift, s.t_land):
            k = int(np.ceil(t * fps))
            before, after = (z[k - 1] - z[k - 3]) / 2 * fps, (z[k + 2] - z[k]) / 2 * fps
            assert abs(after - before) < 0.15, (s.side, t, after - before)


def test_swing_clearance_is_in_units_of_a_170_cm_body(bm):
    """GaitStyle: 'lengths in m for a 1.70 m body'. Raising the clearance by dc raises the swing ankle at mid-swing by
    dc x (body height / 1.70 m) (height measured on the shaped mesh), for a body 10 % taller than 1.70 m."""
    betas = np.zeros(10)
    betas[0] = 2.0
    rig = build_rig(bm, betas)
    with torch.no_grad():
        v = bm(betas=torch.as_tensor(betas[None], dtype=bm.dtype)).vertices[0].double().numpy()
    height = v[:, 1].max() - v[:, 1].min()
    assert height > 1.80
    T = 150
    xy, _ = straight_walk(T, (0, 0), 0.0, 3.0, 0.3, 4.5)
    plan = RootPlan(xy, np.zeros(T))
    lo, hi = GaitStyle(clearance=0.06), GaitStyle(clearance=0.09)
    steps = plan_footsteps(plan, rig, lo)
    a = foot_tracks(steps, plan, rig, lo).ankle[..., 2]
    b = foot_tracks(steps, plan, rig, hi).ankle[..., 2]
    assert np.abs(b - a).max() == pytest.approx(0.03 * height / 1.70, rel=0.03)


def test_the_hip_of_the_leading_leg_is_ahead(walk):
    """Pelvic rotation (Inman; posing.py: 'pelvic rotation (yaw) with the stepping leg'): the hip on the side of the
    leading foot is ahead, so the hips' separation along the path follows the ankles'."""
    m, p, _, _, moving = walk
    v = np.gradient(gaussian_filter1d(p[:, 0, :2], 15, axis=0, mode="nearest"), axis=0)   # the path, without the sway
    fwd = v / np.linalg.norm(v, axis=1, keepdims=True)
    hips = _along(p[:, J["left_hip"], :2] - p[:, J["right_hip"], :2], fwd)[moving]
    ankles = _along(p[:, J["left_ankle"], :2] - p[:, J["right_ankle"], :2], fwd)[moving]
    assert np.corrcoef(hips, ankles)[0, 1] > 0.5


def test_the_pelvis_drops_on_the_swing_side(walk):
    """Obliquity (posing.py module doc: 'the swing side drops'): in left single support the left hip is higher than
    the right, in right single support lower."""
    m, p, fwd, _, moving = walk
    c = m.contacts.astype(bool)
    on_l, on_r = c[:, :2].any(1), c[:, 2:].any(1)
    only_l, only_r = moving & on_l & ~on_r, moving & on_r & ~on_l
    dz = p[:, J["left_hip"], 2] - p[:, J["right_hip"], 2]
    assert only_l.sum() > 10 and only_r.sum() > 10
    assert dz[only_l].mean() > 0.002 and dz[only_r].mean() < -0.002


def test_the_arms_lag_the_legs(walk):
    """posing.py: 'arms swing against the legs ... arms lag a little': the left wrist's swing along the path follows
    the right ankle's best a few frames later (a positive lag), not earlier."""
    m, p, fwd, _, moving = walk
    idx = np.flatnonzero(moving)
    sl = slice(idx[0], idx[-1])
    a = _along(p[:, J["left_wrist"], :2] - p[:, 0, :2], fwd)[sl]
    b = _along(p[:, J["right_ankle"], :2] - p[:, 0, :2], fwd)[sl]
    a, b = a - a.mean(), b - b.mean()

    def corr(lag):   # wrist at t + lag against ankle at t
        x, y = (a[lag:], b[:len(b) - lag]) if lag >= 0 else (a[:lag], b[-lag:])
        return np.corrcoef(x, y)[0, 1]

    best = max(range(-6, 7), key=corr)
    assert 1 <= best <= 6, best


@pytest.mark.parametrize("look_yaw", [-0.5, 0.0, 0.7])
def test_the_head_looks_along_the_look_direction(bm, look_yaw):
    """A standing body with the look turned by look_yaw: the head's forward axis (canonical +z) points at that yaw
    from the heading, pitched down by Style.head_pitch (posing.py: 'looks along the path (slightly down)'); the neck
    and head together turn by the whole yaw, not more."""
    rig = build_rig(bm)
    T = 8
    plan = RootPlan(np.zeros((T, 2)), np.full(T, 0.3))
    tracks = foot_tracks([], plan, rig, GaitStyle())
    c = Controls.zeros(T)
    c.look_yaw = np.full(T, look_yaw)
    style = Style()
    _, _, extra = pose_body(rig, plan, tracks, style, c)
    d = extra["global_rot"][:, J["head"]] @ np.array([0.0, 0.0, 1.0])
    yaw = np.arctan2(d[:, 1], d[:, 0])
    pitch_down = -np.arcsin(d[:, 2])
    np.testing.assert_allclose(yaw, 0.3 + look_yaw, atol=0.03)
    np.testing.assert_allclose(pitch_down, style.head_pitch, atol=0.03)


def test_plan_at_a_frame_time_is_that_frame_and_between_frames_linear():
    """RootPlan.at(t) (docstring: linear interpolation, held at the ends): at t = k / fps it is frame k; a quarter of
    the way from frame 1 to frame 2 it is 0.75 xy[1] + 0.25 xy[2]; the heading likewise."""
    xy = np.array([[0.0, 0.0], [1.0, 0.5], [3.0, 0.5], [4.0, 2.0]])
    h = np.array([0.0, 0.2, 0.4, 0.8])
    plan = RootPlan(xy, h, fps=10.0)
    for k in range(4):
        p, hk = plan.at(k / 10.0)
        np.testing.assert_allclose(p, xy[k], atol=1e-12)
        np.testing.assert_allclose(hk, h[k], atol=1e-12)
    p, hk = plan.at(0.125)
    np.testing.assert_allclose(p, 0.75 * xy[1] + 0.25 * xy[2], atol=1e-12)
    np.testing.assert_allclose(hk, 0.75 * h[1] + 0.25 * h[2], atol=1e-12)
    p, _ = plan.at(np.array([-1.0, 5.0]))                     # held at the ends
    np.testing.assert_allclose(p, xy[[0, 3]], atol=1e-12)


def test_side_steps_go_left_for_a_positive_sideways_speed():
    """A 'side' program's segment with sideways speed u (> 0: leftward, integrate_controls' v_side) moves the plan to
    the left of its heading (-sin h, cos h) at about u m/s in the segment's steady middle."""
    fps, T, checked = 30.0, 300, 0
    for seed in range(6):
        segs = _segments("side", np.random.default_rng(seed), T / fps)       # the draws locomotion_plan makes
        plan, _ = locomotion_plan("side", np.random.default_rng(seed), T, fps)
        t0 = 0.0
        for name, dur, p in segs:
            if name == "side" and dur >= 1.2 and t0 + dur <= T / fps:
                a, b = int(round((t0 + 0.4 * dur) * fps)), int(round((t0 + 0.6 * dur) * fps))
                h = plan.heading[a]
                left = np.array([-np.sin(h), np.cos(h)])
                vel = (plan.xy[b] - plan.xy[a]) / ((b - a) / fps)
                assert np.sign(vel @ left) == np.sign(p["u"]), (seed, p)
                assert abs(vel @ left - p["u"]) < 0.35 * abs(p["u"]), (seed, p, vel @ left)
                checked += 1
            t0 += int(round(dur * fps)) / fps
    assert checked >= 2


@pytest.fixture(scope="module")
def shifted_model(tmp_path_factory):
    """The shipped body model with its template translated by (2, 3, 5) cm (the same body; its rest pelvis J0 moves)."""
    a = dict(np.load(REPO_ROOT / "data_stubs" / "body_models" / "smplx" / "SMPLX_NEUTRAL.npz", allow_pickle=False))
    a["v_template"] = a["v_template"] + np.array([0.02, 0.03, 0.05], a["v_template"].dtype)
    root = tmp_path_factory.mktemp("shifted_model")
    (root / "smplx").mkdir()
    np.savez_compressed(root / "smplx" / "SMPLX_NEUTRAL.npz", **a)
    return BodyModel.from_file(root / "smplx" / "SMPLX_NEUTRAL.npz")


@pytest.mark.parametrize("kind", ["walk", "idle"])
def test_a_clip_does_not_depend_on_where_the_template_sits(bm, shifted_model, kind):
    """Translating the model's template translates J0 with it; SMPL-X puts the pelvis at J0 + trans, so a clip that
    sets trans = pelvis - J0 (generate_locomotion) gives the same mesh: the same heights (feet on the floor), and the
    same horizontal motion up to the clip's start offset."""
    m1 = generate_locomotion(1, bm, num_frames=30, kind=kind)
    m2 = generate_locomotion(1, shifted_model, num_frames=30, kind=kind)
    v1, v2 = m1.vertices(bm).numpy(), m2.vertices(shifted_model).numpy()
    np.testing.assert_allclose(v2[..., 2], v1[..., 2], atol=1e-4)
    c1, c2 = v1[0, :, :2].mean(0), v2[0, :, :2].mean(0)
    np.testing.assert_allclose(v2[..., :2] - c2, v1[..., :2] - c1, atol=1e-4)
