"""Root plans (trajectory.py), locomotion programs (locomotion.py) and the rig (rig.py) against hand-integrated,
analytic, scipy and body-model truths."""
import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

from graspkit.body.markers import foot_vertices
from graspkit.body.skeleton import JOINT_INDEX as J
from graspkit.data.locomotion import _segments, generate_locomotion, locomotion_plan, sample_betas
from graspkit.data.rig import build_rig
from graspkit.data.trajectory import RootPlan, heading_profile, integrate_controls, smooth_controls, straight_walk


def _mj(u):
    """Minimum-jerk position 10u^3 - 15u^4 + 6u^5, clipped to [0, 1], written out by hand."""
    u = np.clip(u, 0.0, 1.0)
    return 10 * u**3 - 15 * u**4 + 6 * u**5


# ------------------------------------------------------------------------------------------------ trajectory.py
def test_plan_speed_and_turn_rate_of_a_uniform_motion_at_every_frame():
    """A body moving at constant velocity v and turning at constant rate w has speed v and turn rate w on every
    frame, the first and last included (central differences are exact for linear tracks)."""
    T, fps, v, w = 40, 30.0, 1.3, -0.7
    t = np.arange(T) / fps
    plan = RootPlan(np.stack([v * t * np.cos(0.4), v * t * np.sin(0.4)], 1) + [2.0, -1.0], 0.3 + w * t, fps)
    np.testing.assert_allclose(plan.speed(), v, atol=1e-9)
    np.testing.assert_allclose(plan.turn_rate(), w, atol=1e-9)


def test_integrate_controls_is_exact_for_linear_rates_and_starts_at_xy0():
    """Trapezoidal integration is exact for controls linear in time: a yaw rate a*t gives heading h0 + a t^2 / 2,
    a forward speed b*t at fixed heading h0 walks b t^2 / 2 along (cos h0, sin h0); the plan starts at xy0 and
    moving xy0 translates the whole plan (hand integration)."""
    T, fps, a, b, h0 = 61, 30.0, 0.9, 0.6, 0.5
    t = np.arange(T) / fps
    turn = integrate_controls(np.zeros(T), np.zeros(T), a * t, heading0=h0, fps=fps)
    np.testing.assert_allclose(turn.heading, h0 + 0.5 * a * t**2, atol=1e-12)
    xy0 = np.array([2.0, -1.5])
    line = integrate_controls(b * t, np.zeros(T), np.zeros(T), xy0=xy0, heading0=h0, fps=fps)
    want = xy0 + (0.5 * b * t**2)[:, None] * np.array([np.cos(h0), np.sin(h0)])
    np.testing.assert_allclose(line.xy, want, atol=1e-12)
    c = np.full(T, 1.0)
    p0 = integrate_controls(c, 0.3 * c, 0.5 * c, fps=fps)
    p1 = integrate_controls(c, 0.3 * c, 0.5 * c, xy0=xy0, fps=fps)
    np.testing.assert_allclose(p1.xy, p0.xy + xy0, atol=1e-12)


def test_smooth_controls_holds_edges_and_sigma_is_in_seconds():
    """smooth_controls: a constant signal is unchanged up to its edges ('edges held'), and a unit impulse spreads
    into a Gaussian whose standard deviation is sigma_s seconds (its second moment in s^2)."""
    fps = 30.0
    np.testing.assert_allclose(smooth_controls(np.full(50, 1.2), 0.3, fps), 1.2, atol=1e-12)
    x = np.zeros(301)
    x[150] = 1.0
    y = smooth_controls(x, 0.3, fps)
    t = (np.arange(301) - 150) / fps
    assert abs(y.sum() - 1.0) < 1e-9
    assert np.sqrt((y * t**2).sum()) == pytest.approx(0.3, rel=0.02)


def test_heading_profile_is_minimum_jerk_at_any_fps():
    """heading_profile at 60 fps: h0 before t0, h1 after t1 and h0 + (h1 - h0) (10u^3 - 15u^4 + 6u^5) with
    u = (t - t0) / (t1 - t0) in between (the minimum-jerk profile by hand)."""
    T, fps, h0, h1, t0, t1 = 180, 60.0, 0.2, 1.4, 0.5, 2.0
    h = heading_profile(T, h0, h1, t0, t1, fps)
    t = np.arange(T) / fps
    np.testing.assert_allclose(h, h0 + (h1 - h0) * _mj((t - t0) / (t1 - t0)), atol=1e-12)


def test_straight_walk_goes_exactly_distance_along_heading_between_start_and_stop():
    """straight_walk: standing at start_xy before t_start, at start_xy + distance (cos h, sin h) from t_stop on,
    always on that line; between the ramps the speed is distance / (duration - accel_time) (each minimum-jerk ramp
    loses accel_time / 2 of distance), and the speeds returned are the positions' central differences in m/s."""
    T, fps, h, dist, ts, te, acc = 200, 30.0, 2.0, 3.0, 0.5, 5.0, 0.9
    start = np.array([0.5, -1.0])
    xy, speed = straight_walk(T, start, h, dist, ts, te, accel_time=acc, fps=fps)
    t = np.arange(T) / fps
    d = np.array([np.cos(h), np.sin(h)])
    np.testing.assert_allclose(xy[t <= ts], np.broadcast_to(start, xy[t <= ts].shape), atol=1e-12)
    np.testing.assert_allclose(xy[t >= te], np.broadcast_to(start + dist * d, xy[t >= te].shape), atol=1e-9)
    rel = xy - start
    np.testing.assert_allclose(rel[:, 0] * d[1] - rel[:, 1] * d[0], 0.0, atol=1e-12)      # on the line
    cruise = dist / ((te - ts) - acc)
    mid = (t > ts + acc + 0.05) & (t < te - acc - 0.05)
    np.testing.assert_allclose(speed[mid], cruise, rtol=2e-3)
    fd = np.linalg.norm(xy[2:] - xy[:-2], axis=1) / (2 / fps)
    np.testing.assert_allclose(speed[1:-1], fd, atol=1e-9)


# ------------------------------------------------------------------------------------------------ locomotion.py
def test_sample_betas_are_a_clipped_normal():
    """sample_betas: N(0, scale^2) (std 0.3 over 4000 draws within 5 %), clipped to +-2 (a wide scale 5 puts some
    draws exactly on the bounds and none beyond)."""
    rng = np.random.default_rng(0)
    b = np.concatenate([sample_betas(rng, 0.3) for _ in range(400)])
    assert b.shape == (4000,) and b.std() == pytest.approx(0.3, rel=0.05)
    w = np.concatenate([sample_betas(rng, 5.0) for _ in range(20)])
    assert np.abs(w).max() == 2.0 and (np.abs(w) == 2.0).sum() > 50


def test_locomotion_plan_length_and_a_slow_start():
    """locomotion_plan: num_frames + preroll + postroll frames (docstring), and every plan starts from rest
    (comment: the feet stand at their footprints): on the first frame the planned speed is under half its peak."""
    for seed in range(3):
        plan, v = locomotion_plan("walk", np.random.default_rng(seed), 90, 30.0, preroll=2.5, postroll=1.0)
        assert plan.num_frames == len(v) == 90 + 75 + 30
        assert v[0] < 0.5 * v.max() and plan.speed()[0] < 0.5 * v.max()


def _segment_frames(segs, fps, T):
    k, out = 0, []
    for name, dur, p in segs:
        n = int(round(dur * fps))
        if k + n <= T:
            out.append((name, k, k + n, p))
        k += n
    return out


def test_turn_side_and_backward_programs_move_as_drawn():
    """Programs against their own draws (same seed, _segments): a turn in place changes the heading by w * duration
    (sign included, smoothing only spreads it); a side step moves to the body's left (-sin h, cos h) at u m/s and
    not forwards; a backward walk moves against the heading at |v| m/s."""
    fps, T, seen = 30.0, 450, set()
    for seed in range(6):
        for kind in ("turn", "side", "backward"):
            segs = _segments(kind, np.random.default_rng(seed), T / fps)
            plan, _ = locomotion_plan(kind, np.random.default_rng(seed), T, fps)
            h = np.unwrap(plan.heading)
            vel = np.gradient(plan.xy, axis=0) * fps
            fwd = np.stack([np.cos(plan.heading), np.sin(plan.heading)], 1)
            left = np.stack([-np.sin(plan.heading), np.cos(plan.heading)], 1)
            for name, a, b, p in _segment_frames(segs, fps, T):
                pad = 12
                if a < 10 or b + pad >= T:
                    continue
                if name == "turn":
                    turned = h[b + pad] - h[max(a - pad, 0)]
                    assert turned == pytest.approx(p["w"] * (b - a) / fps, rel=0.15, abs=0.05), (seed, p)
                    seen.add("turn")
                elif name == "side" and b - a >= 36:
                    m = (a + b) // 2
                    assert abs((vel[m] * left[m]).sum() - p["u"]) < 0.2 * abs(p["u"]), (seed, p)
                    assert abs((vel[m] * fwd[m]).sum()) < 0.02
                    seen.add("side")
                elif name == "walk" and kind == "backward" and b - a >= 45:
                    m = (a + b) // 2
                    assert (vel[m] * fwd[m]).sum() == pytest.approx(p["v"], rel=0.1), (seed, p)
                    assert p["v"] < 0
                    seen.add("backward")
    assert seen == {"turn", "side", "backward"}


def test_generate_locomotion_rejects_an_unknown_kind(bm):
    """generate_locomotion: kind must be one of PROGRAMS (docstring); a typo is an error, not an idle clip."""
    with pytest.raises(ValueError):
        generate_locomotion(0, bm, num_frames=20, kind="run")


# ------------------------------------------------------------------------------------------------ rig.py
def test_rig_heights_ground_points_and_toe_tip_from_the_mesh(bm):
    """build_rig for beta_0 = 1.5 against the body model's own rest mesh: sole = lowest vertex, height = mesh
    extent along y, scale = height / 1.70, pelvis height = pelvis joint above the sole; per foot the ground point
    lies under the ankle at sole height, and the toe tip is the foot's most forward sole vertex, ahead of the ball."""
    betas = np.zeros(10)
    betas[0] = 1.5
    rig = build_rig(bm, betas)
    with torch.no_grad():
        out = bm(betas=torch.as_tensor(betas[None], dtype=bm.dtype))
    v, j = out.vertices[0].double().numpy(), out.joints[0].double().numpy()
    lo, height = v[:, 1].min(), v[:, 1].max() - v[:, 1].min()
    assert rig.sole_y == pytest.approx(lo, abs=1e-6) and rig.height == pytest.approx(height, abs=1e-6)
    assert rig.scale == pytest.approx(height / 1.70, rel=1e-9)
    assert rig.pelvis_height == pytest.approx(j[0, 1] - lo, abs=1e-6)
    soles = foot_vertices(bm)
    for side in ("left", "right"):
        f = rig.feet[side]
        ank = j[J[f"{side}_ankle"]]
        np.testing.assert_allclose(f.ref, [ank[0], lo, ank[2]], atol=1e-6)
        ids = np.concatenate([soles[f"{side}_heel"], soles[f"{side}_toe"]])
        assert f.toe_tip[2] == pytest.approx(v[ids, 2].max(), abs=1e-6)
        assert f.toe_tip[2] > j[J[f"{side}_foot"], 2]


def test_heel_pivot_is_the_rear_point_lowest_with_the_toes_raised(bm):
    """The heel pivot (rig.py: 'the rear vertex that is lowest when the toes are raised by strike_angle'): rotating
    the ankle segment's vertices behind and below the ankle about the ankle with scipy, by the rotation that lifts
    the toe tip, the heel is the lowest of them; with a steeper strike it moves no further forward."""
    rig0 = build_rig(bm, strike_angle=0.0)
    weights = bm.lbs_weights.double().numpy()
    with torch.no_grad():
        v = bm(betas=torch.zeros(1, 10, dtype=bm.dtype)).vertices[0].double().numpy()
    zs = []
    for a in (0.3, 0.6):
        rig = build_rig(bm, strike_angle=a)
        for side in ("left", "right"):
            f = rig.feet[side]
            ank = f.ankle
            rear = (weights.argmax(1) == J[f"{side}_ankle"]) & (v[:, 2] < ank[2]) & (v[:, 1] < ank[1])
            rot = Rotation.from_rotvec([a, 0.0, 0.0])
            if rot.apply(f.toe_tip - ank)[1] <= f.toe_tip[1] - ank[1]:
                rot = rot.inv()                                   # the rotation that raises the toes
            y = rot.apply(v[rear] - ank)[:, 1]
            assert rot.apply(f.heel - ank)[1] <= y.min() + 1e-9, (a, side)
            if side == "left":
                zs.append(f.heel[2])
    assert zs[1] <= zs[0] + 1e-9 and zs[0] <= rig0.feet["left"].heel[2] + 1e-9

def test_a_rig_for_fewer_betas_than_the_model_has_is_the_rig_for_them_zero_padded(bm):
    """build_rig pads short betas with zeros as BodyModel does (it crashed: the shape coefficients had the wrong
    width), so two betas give the rig of those two followed by eight zeros."""
    a, b = build_rig(bm, np.array([1.0, 0.5])), build_rig(bm, np.r_[1.0, 0.5, np.zeros(8)])
    assert a.scale == b.scale and a.pelvis_height == b.pelvis_height
    np.testing.assert_array_equal(a.feet["left"].heel, b.feet["left"].heel)
