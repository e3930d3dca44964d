"""Footsteps (graspkit.data.footsteps): placement against the module doc worked out by hand, invariance under moving
the plan, the step-length cap, stance width and toe-out, swing clearance, support weights and rate continuity."""
import numpy as np
import pytest
import torch

from graspkit.body.skeleton import JOINT_INDEX as J
from graspkit.data.footsteps import GaitStyle, foot_tracks, plan_footsteps, support_weight
from graspkit.data.ik import rot_z, smoothstep, wrap_angle
from graspkit.data.rig import build_rig
from graspkit.data.trajectory import RootPlan, heading_profile, integrate_controls, straight_walk


@pytest.fixture(scope="module")
def rig(bm):
    return build_rig(bm)


@pytest.fixture(scope="module")
def tall(bm):
    """A body about 10 % taller than 1.70 m (scale ~1.1), so that lengths 'for a 1.70 m body' must be scaled."""
    betas = np.zeros(10)
    betas[0] = 2.0
    r = build_rig(bm, betas)
    assert r.scale > 1.08
    return r


def _rest_ankle_ahead(bm, side):
    """Rest ankle ahead (+) / behind (-) the pelvis along the facing direction (canonical z), from the body model."""
    with torch.no_grad():
        j = bm(betas=torch.zeros(1, 10, dtype=bm.dtype)).joints[0].double().numpy()
    return j[J[f"{side}_ankle"], 2] - j[J["pelvis"], 2]


def _heading_vec(h):
    return np.array([np.cos(h), np.sin(h)]), np.array([-np.sin(h), np.cos(h)])


def test_cruise_footprints_lie_lead_periods_ahead_of_the_root_at_landing(bm, rig):
    """Module doc: a footprint is where the root will be `lead` step periods after landing, offset sideways by half the
    stance width, with the ankle's rest offset along the facing direction. At constant speed along a heading of 0.6
    rad this is hand-computable: root(t_land + lead P) + f_off fwd +- hw left, hw = half_width scale (1 + gain (1 - v))."""
    T, v, h = 330, 1.1, 0.6
    st = GaitStyle()
    xy, speed = straight_walk(T, (0.3, -0.2), h, v * (10.0 - 0.9), 0.5, 10.5)
    plan = RootPlan(xy, np.full(T, h))
    steps = plan_footsteps(plan, rig, st)
    fwd, left = _heading_vec(h)
    cruise = [s for s in steps if 3.0 < s.t_land < 8.0]
    assert len(cruise) >= 6
    hw = st.half_width * rig.scale * (1 + st.width_gain * (1 - v))
    t = np.arange(T) / plan.fps
    for s in cruise:
        tau = s.t_land + st.lead * s.period
        root = np.array([np.interp(tau, t, xy[:, 0]), np.interp(tau, t, xy[:, 1])])
        sgn = 1.0 if s.side == 0 else -1.0
        want = root + _rest_ankle_ahead(bm, ("left", "right")[s.side]) * fwd + sgn * hw * left
        np.testing.assert_allclose(s.xy, want, atol=2e-3)
        assert wrap_angle(s.yaw - (h + sgn * st.toe_out)) == pytest.approx(0.0, abs=1e-9)


def _rotate_plan(plan, ang, shift):
    c, s = np.cos(ang), np.sin(ang)
    Rm = np.array([[c, -s], [s, c]])
    return RootPlan(plan.xy @ Rm.T + shift, plan.heading + ang, plan.fps), Rm


def test_steps_and_feet_rotate_and_translate_with_the_plan(rig):
    """Invariance: rotating the whole plan by 2 rad about z and translating it moves every footstep and foot pose
    rigidly (same sides, times and pitch angles; footprints, ankles and foot rotations transformed), since gait does
    not depend on where the walk happens or which way the world's x axis points. The plan starts from rest, curves
    (early enough that the outer foot is clearly the first to step: no tie) and side-steps."""
    T = 150
    st = GaitStyle()
    t = np.arange(T) / 30.0
    v = 1.3 * smoothstep((t - 0.3) / 0.8)
    side = 0.25 * smoothstep((t - 2.5) / 0.5)
    plan = integrate_controls(v, side, 0.6 * smoothstep((t - 0.6) / 0.6), heading0=0.2)
    ang, shift = 2.0, np.array([3.0, -1.5])
    plan2, Rm = _rotate_plan(plan, ang, shift)
    a, b = plan_footsteps(plan, rig, st), plan_footsteps(plan2, rig, st)
    assert len(a) >= 5 and max(s.strike for s in a) > 0.1
    assert [(s.side, round(s.t_lift, 9), round(s.t_land, 9)) for s in a] == \
        [(s.side, round(s.t_lift, 9), round(s.t_land, 9)) for s in b]
    for s, r in zip(a, b):
        np.testing.assert_allclose(r.xy, Rm @ s.xy + shift, atol=1e-9)
        assert wrap_angle(r.yaw - s.yaw - ang) == pytest.approx(0.0, abs=1e-9)
        assert (r.strike, r.toeoff) == pytest.approx((s.strike, s.toeoff), abs=1e-9)
    ta, tb = foot_tracks(a, plan, rig, st), foot_tracks(b, plan2, rig, st)
    np.testing.assert_array_equal(ta.contacts, tb.contacts)
    np.testing.assert_allclose(tb.ankle[..., :2], ta.ankle[..., :2] @ Rm.T + shift, atol=1e-8)
    np.testing.assert_allclose(tb.ankle[..., 2], ta.ankle[..., 2], atol=1e-8)
    np.testing.assert_allclose(tb.R_foot, rot_z(ang) @ ta.R_foot, atol=1e-8)


def test_first_step_waits_to_shift_the_weight_only_when_starting_from_rest(rig):
    """GaitStyle.first_step: starting from rest the first lift-off is no earlier than first_step (0.4 s) after the
    start; a body already walking at 1.2 m/s at t=0 (feet at their footprints, the root moving away) steps at once."""
    T, st = 120, GaitStyle()
    xy, _ = straight_walk(T, (0, 0), 0.0, 3.0, 0.0, 3.5, accel_time=0.5)     # from rest at t=0
    rest = plan_footsteps(RootPlan(xy, np.zeros(T)), rig, st)
    assert rest and rest[0].t_lift >= st.first_step - 1e-9
    t = np.arange(T) / 30.0
    moving = plan_footsteps(RootPlan(np.stack([1.2 * t, np.zeros(T)], 1), np.zeros(T)), rig, st)
    assert moving and moving[0].t_lift < 0.5 * st.first_step


@pytest.mark.parametrize("direction", [0.0, np.pi])
def test_fast_steps_are_capped_at_max_step_of_a_scaled_body(tall, direction):
    """GaitStyle.max_step: a footprint lands at most max_step (0.95 m for a 1.70 m body, times the body's scale) ahead
    of or behind the stance foot. Walking at 4.2 m/s (forwards, then backwards while facing +x) the step length
    v / cadence (~1.4 m) exceeds it, so the longest steps are exactly the cap."""
    T, st = 150, GaitStyle()
    xy, _ = straight_walk(T, (0, 0), direction, 12.0, 0.3, 4.7, accel_time=0.6)
    steps = plan_footsteps(RootPlan(xy, np.zeros(T)), tall, st)
    cap = st.max_step * tall.scale
    where = {}
    along = []
    for s in steps:
        if 1 - s.side in where:
            along.append((s.xy - where[1 - s.side])[0])
        where[s.side] = s.xy
    along = np.array(along) * (1 if direction == 0.0 else -1)
    assert len(along) >= 5 and (along >= -1e-9).all()
    assert along.max() == pytest.approx(cap, abs=1e-9)
    assert (along <= cap + 1e-9).all()


def test_a_foot_on_its_heel_or_its_toes_alone_carries_the_weight():
    """support_weight: a foot touching the ground with only its heel (heel strike) or only its toes (heel rise) is a
    supporting foot, so with the other foot in the air all the weight is on it (1 on the left, 0 on the right)."""
    c = np.zeros((8, 4), bool)
    c[:2, 0] = True       # left heel only
    c[2:4, 1] = True      # left toes only
    c[4:6, 2] = True      # right heel only
    c[6:, 3] = True       # right toes only
    np.testing.assert_array_equal(support_weight(c, 30.0), [1, 1, 1, 1, 0, 0, 0, 0])


def test_a_long_double_support_rests_at_half_weight_between_two_shifts():
    """support_weight docstring: a long double support (standing, 2 s > 2 x shift_time) hands the weight from the foot
    that carried it (left, 1) to the one that carries it after (right, 0) by resting at 0.5 in between, with weight
    shifts of shift_time s at its ends: near 1 at its start, exactly 0.5 once shift_time has passed and until
    shift_time before its end, near 0 at its end, never rising."""
    fps, sh = 30.0, 0.35
    c = np.zeros((90, 4), bool)
    c[:70, :2] = True            # left foot down for frames 0..69
    c[10:, 2:] = True            # right foot down from frame 10: double support 10..69 (2 s)
    w = support_weight(c, fps, sh)
    np.testing.assert_array_equal(w[:10], 1.0)
    np.testing.assert_array_equal(w[70:], 0.0)
    d = w[10:70]
    tt = (np.arange(60) + 0.5) / fps
    assert d[0] > 0.97 and d[-1] < 0.03
    np.testing.assert_allclose(d[(tt >= sh) & (tt <= 2.0 - sh)], 0.5, atol=1e-12)
    assert (np.diff(w) <= 1e-12).all()


def test_standing_feet_are_a_widened_stance_apart_and_turned_outwards(tall):
    """GaitStyle: each footprint sits half_width (1.70 m body, times the scale) x (1 + width_gain (1 - v)) to its side
    of the path, i.e. x (1 + width_gain) when standing (v = 0), and each foot is turned outwards by toe_out (the left
    foot's toes to the left of the heading, the right's to the right). A body of scale ~1.1 stands still facing 0.7
    rad; the ankles and the feet's forward axes (canonical +z through R_foot) are measured."""
    T, st, h = 10, GaitStyle(), 0.7
    plan = RootPlan(np.tile([1.0, 2.0], (T, 1)), np.full(T, h))
    steps = plan_footsteps(plan, tall, st)
    assert steps == []
    tr = foot_tracks(steps, plan, tall, st)
    fwd, left = _heading_vec(h)
    hw = st.half_width * tall.scale * (1 + st.width_gain)
    for s, sgn in ((0, 1.0), (1, -1.0)):
        lat = (tr.ankle[s, :, :2] - [1.0, 2.0]) @ left
        np.testing.assert_allclose(lat, sgn * hw, atol=1e-6)
        f = tr.R_foot[s] @ np.array([0.0, 0.0, 1.0])
        np.testing.assert_allclose(np.arctan2(f[:, 1], f[:, 0]), h + sgn * st.toe_out, atol=1e-9)
        np.testing.assert_allclose(f[:, 2], 0.0, atol=1e-9)                       # standing flat
    assert tr.contacts.all()


def test_mid_swing_soles_keep_the_promised_clearance_even_without_a_bump(rig):
    """Module doc / foot_tracks: the swing is raised if a sole point would come closer to the ground than 1.5 cm x bump
    (bump = 16 u^2 (1-u)^2, u the swing phase) in the middle of the swing (0.2 < u < 0.8). With the ankle's clearance
    bump switched off (clearance 0), the soles' world points (R_foot and the ankle) must still keep that clearance."""
    T, st = 120, GaitStyle(clearance=0.0, clearance_gain=0.0)
    xy, _ = straight_walk(T, (0, 0), 0.0, 4.0, 0.3, 3.8)
    plan = RootPlan(xy, np.zeros(T))
    steps = plan_footsteps(plan, rig, st)
    tr = foot_tracks(steps, plan, rig, st)
    t = np.arange(T) / plan.fps
    checked = 0
    for s in steps:
        foot = rig.feet[("left", "right")[s.side]]
        u = (t - s.t_lift) / (s.t_land - s.t_lift)
        for k in np.flatnonzero((u > 0.2) & (u < 0.8)):
            pts = (tr.R_foot[s.side, k] @ (foot.sole - foot.ankle).T).T + tr.ankle[s.side, k]
            assert pts[:, 2].min() >= 0.015 * 16 * u[k] ** 2 * (1 - u[k]) ** 2 - 1e-9, (s.side, t[k])
            checked += 1
    assert checked >= 20


def _pitch_yaw(R):
    """Pitch (heel up > 0) and yaw of feet R (...,3,3): the canonical forward axis +z maps to (cos p, 0, -sin p) about z."""
    f = R @ np.array([0.0, 0.0, 1.0])
    return -np.arcsin(np.clip(f[..., 2], -1, 1)), np.unwrap(np.arctan2(f[..., 1], f[..., 0]))


def test_foot_pitch_and_yaw_rates_are_continuous_at_lift_off_and_landing(rig):
    """The swing joins the stance (Hermite curves matched to the toe-off and heel-strike states, module doc): sampled
    at 600 fps along a curving walk, the foot's pitch rate (heel rise: pitch toeoff x u^2) and its yaw rate (zero in
    stance) have no jump at lift-off or landing (< 0.5 rad/s and < 0.3 rad/s; the rates themselves reach several rad/s)."""
    fps = 600.0
    T = int(4.0 * fps)
    t = np.arange(T) / fps
    plan = integrate_controls(1.5 * smoothstep((t - 0.3) / 0.8), np.zeros(T), 0.6 * smoothstep((t - 0.5) / 0.5),
                              fps=fps)
    st = GaitStyle()
    steps = plan_footsteps(plan, rig, st)
    tr = foot_tracks(steps, plan, rig, st)
    assert len(steps) >= 5
    big_yaw = 0.0
    for s in steps[1:-1]:
        pitch, yaw = _pitch_yaw(tr.R_foot[s.side])
        for tc in (s.t_lift, s.t_land):
            k = int(np.ceil(tc * fps))
            for x, tol in ((pitch, 0.5), (yaw, 0.3)):
                before, after = (x[k - 1] - x[k - 3]) / 2 * fps, (x[k + 2] - x[k]) / 2 * fps
                assert abs(after - before) < tol, (s.side, tc, after - before)
        big_yaw = max(big_yaw, np.abs(np.gradient(yaw) * fps).max())
    assert big_yaw > 1.0


def test_a_turn_across_the_heading_seam_turns_the_feet_the_short_way(rig):
    """A turn in place from 2.6 to -2.6 rad the short way (+1.08 rad through pi) with the heading wrapped to (-pi, pi]:
    each foot yaws about 1.08 rad in all, never swinging a near full turn the long way round (frame-to-frame rotation
    angles of R_foot stay small)."""
    T = 150
    h = wrap_angle(heading_profile(T, 2.6, -2.6, 0.5, 3.0))
    plan = RootPlan(np.zeros((T, 2)), h)
    st = GaitStyle()
    steps = plan_footsteps(plan, rig, st)
    tr = foot_tracks(steps, plan, rig, st)
    turn = 2 * np.pi - 5.2
    for s in (0, 1):
        R = tr.R_foot[s]
        rel = np.einsum("tji,tjk->tik", R[:-1], R[1:])
        ang = np.arccos(np.clip((np.trace(rel, axis1=1, axis2=2) - 1) / 2, -1, 1))
        assert ang.max() < 0.3
        _, yaw = _pitch_yaw(R)
        assert np.abs(np.diff(yaw)).sum() < turn + 0.5
        assert abs(yaw[-1] - yaw[0] - turn) < st.yaw_threshold + 1e-9


@pytest.mark.parametrize("direction", [-np.pi / 2, np.pi / 2])
def test_side_steps_never_cross_the_feet(rig, direction):
    """GaitStyle.min_separation: footprints are never closer sideways than 9 cm (x scale) and each stays on its own side
    of the other (no crossing). Side-stepping 1 m/s to the right, then to the left, while facing +x: at every landing
    (starting from the standing footprints) the left footprint is at least that far to the left (+y) of the right one."""
    T, st = 120, GaitStyle()
    xy, _ = straight_walk(T, (0, 0), direction, 2.5, 0.3, 3.6)
    steps = plan_footsteps(RootPlan(xy, np.zeros(T)), rig, st)
    assert len(steps) >= 4
    hw0 = st.half_width * rig.scale * (1 + st.width_gain)         # standing footprints at +-hw0 (v = 0)
    where = {0: np.array([0.0, hw0]), 1: np.array([0.0, -hw0])}
    for s in steps:
        where[s.side] = s.xy
        assert where[0][1] - where[1][1] >= st.min_separation * rig.scale - 1e-9, (s.side, s.t_land)
