"""Motion metrics on hand-made cases with known answers (a still body, a foot dragged at a known speed, ...)."""
import numpy as np
import pytest
import trimesh

from graspkit import metrics as M


def _cloud(T, motion=(0.0, 0.0, 0.0), lift=0.0):
    """A 'body' of 50 points above the ground plus one lowest 'sole' point that moves by `motion` per frame."""
    rng = np.random.default_rng(0)
    body = rng.uniform([-0.2, -0.2, 0.3], [0.2, 0.2, 1.7], (50, 3))
    v = np.repeat(np.concatenate([body, [[0.0, 0.0, 0.0]]])[None], T, 0).astype(np.float32)
    v[:, -1] += np.arange(T)[:, None] * np.asarray(motion, np.float32)
    v[:, :, 2] += lift
    return v


def test_thresholds_are_the_papers():
    assert M.WANDR_SKATE_THRESHOLD == 0.0066 and M.GOAL_SLIDE_THRESHOLD == 0.01 and M.WANDR_SUCCESS_RADIUS == 0.10
    assert M.SAGA_SKATE_HEEL_HEIGHT == 0.05 and M.SAGA_SKATE_HEEL_SPEED == 0.075


def test_still_body_has_no_skating_sliding_penetration_speed_or_jerk():
    v = _cloud(20)
    assert not M.foot_skating_wandr(v).any() and not M.foot_sliding_goal(v).any()
    assert not M.foot_skating_saga(v[:, [-1, 0]]).any()
    assert M.ground_penetration(v).max() == 0
    assert M.joint_speed(v).max() == 0 and M.joint_jerk(v).max() == 0


@pytest.mark.parametrize("per_frame,wandr,goal", [(0.005, False, False), (0.008, True, False), (0.012, True, True)])
def test_a_foot_dragged_at_known_speed(per_frame, wandr, goal):
    v = _cloud(30, motion=(per_frame, 0.0, 0.0))
    assert M.foot_skating_wandr(v).all() == wandr and M.foot_skating_wandr(v).any() == wandr
    assert M.foot_sliding_goal(v).all() == goal and M.foot_sliding_goal(v).any() == goal
    h, d3 = M.lowest_vertex_motion(v)
    assert np.allclose(h, per_frame, atol=1e-6) and np.allclose(d3, per_frame, atol=1e-6)


@pytest.mark.parametrize("speed,wandr,goal", [(0.15, False, False), (0.25, True, False), (0.35, True, True)])
def test_per_frame_thresholds_are_a_speed_at_other_frame_rates(speed, wandr, goal):
    """The papers' per-frame thresholds hold at 30 fps: 0.66 cm and 1 cm per frame are 0.198 and 0.30 m/s. A sole
    dragged at `speed` m/s reads the same at 30, 60 and 120 fps (at 120 fps it moves a quarter as far per frame)."""
    for fps in (30, 60, 120):
        v = _cloud(int(fps), motion=(speed / fps, 0.0, 0.0))
        assert M.foot_skating_wandr(v, fps=fps).all() == wandr and M.foot_skating_wandr(v, fps=fps).any() == wandr
        assert M.foot_sliding_goal(v, fps=fps).all() == goal and M.foot_sliding_goal(v, fps=fps).any() == goal
    assert M.per_frame_threshold(M.WANDR_SKATE_THRESHOLD, 120) == pytest.approx(0.0066 / 4)


def test_wandr_counts_horizontal_motion_goal_counts_all_motion():
    v = _cloud(10, motion=(0.0, 0.0, -0.012), lift=0.2)   # the lowest point sinks 1.2 cm per frame, straight down
    assert not M.foot_skating_wandr(v).any() and M.foot_sliding_goal(v).all()


def test_saga_needs_both_heels_low_and_fast():
    T = 12
    t = np.arange(T)[:, None] * 0.003                       # 3 mm per frame = 90 mm/s at 30 fps
    moving = np.concatenate([t, 0 * t, 0 * t + 0.02], 1)   # heel 2 cm above the ground
    still = np.tile([0.3, 0.1, 0.02], (T, 1))
    both = np.stack([moving, moving + [0, 0.2, 0]], 1)
    assert M.foot_skating_saga(both, fps=30).all()
    assert not M.foot_skating_saga(np.stack([moving, still], 1), fps=30).any()        # one foot planted
    assert not M.foot_skating_saga(both + [0, 0, 0.1], fps=30).any()                   # both feet in the air
    assert not M.foot_skating_saga(both, fps=20).any()                                 # 60 mm/s is slow enough
    rising = both.copy()                                  # 4 cm high at frame t, 6 cm at t + 1: the height read is t's
    rising[1::2, :, 2] = 0.06
    rising[0::2, :, 2] = 0.04
    assert M.foot_skating_saga(rising, fps=30)[0::2].all() and not M.foot_skating_saga(rising, fps=30)[1::2].any()


def test_penetration_speed_and_jerk_known_values():
    v = _cloud(5, lift=-0.02)
    assert np.allclose(M.ground_penetration(v), 0.02, atol=1e-6)
    on = _cloud(5, lift=0.0)
    on[:, :, 2] -= on[:, :, 2].min()                                     # lowest vertex exactly on the ground: +0, not -0
    assert not np.signbit(M.ground_penetration(on)).any()
    fps = 30.0
    t = np.arange(40) / fps
    acc = np.stack([0.5 * 2.0 * t**2, 0 * t, 0 * t], 1)[:, None]       # constant acceleration: no jerk
    assert np.allclose(M.joint_jerk(acc, fps), 0, atol=1e-6)
    cub = np.stack([t**3, 0 * t, 0 * t], 1)[:, None]                      # x = t^3: jerk 6 m/s^3
    assert np.allclose(M.joint_jerk(cub, fps), 6.0, atol=1e-6)
    lin = np.stack([1.5 * t, 0 * t, 0 * t], 1)[:, None]
    assert np.allclose(M.joint_speed(lin, fps), 1.5)


def test_joint_limits_flag_a_hyperextended_knee_and_a_broken_neck_only():
    poses = np.zeros((3, 55, 3))
    poses[1, 4] = [np.deg2rad(90), 0, 0]         # left knee flexed 90 deg: fine
    poses[2, 4] = [np.deg2rad(-30), 0, 0]        # left knee hyperextended 30 deg: 20 beyond -10
    poses[2, 12] = [0, np.deg2rad(100), 0]       # neck turned 100 deg: 40 beyond 60
    lim = M.joint_limit_violation(poses)
    assert lim[:2].max() == 0
    assert np.isclose(lim[2, 4], 20, atol=1e-6) and np.isclose(lim[2, 12], 40, atol=1e-6)


@pytest.mark.parametrize("side", ["left", "right"])
def test_elbow_flexion_is_the_forearm_swinging_forward(bm, side):
    """Each elbow's hinge axis, checked on the body: 90 deg of flexion about it swings the forearm from the side to
    the front (+z, the canonical facing direction) within the range; 30 deg the other way (hyperextension) reads 20
    deg beyond its -10 deg limit."""
    import torch

    from graspkit.body.skeleton import JOINT_INDEX

    j, w = JOINT_INDEX[f"{side}_elbow"], JOINT_INDEX[f"{side}_wrist"]
    axis = np.array(M.HINGES[f"{side}_elbow"][0], float)
    for deg, excess in ((90, 0.0), (-30, 20.0)):
        body_pose = torch.zeros(1, 21, 3, dtype=bm.dtype)
        body_pose[0, j - 1] = torch.as_tensor(axis * np.deg2rad(deg))
        joints = bm(body_pose=body_pose.reshape(1, -1)).joints[0].double().numpy()
        forearm = joints[w] - joints[j]
        if deg == 90:
            assert forearm[2] > 0.95 * np.linalg.norm(forearm)
        else:
            assert forearm[2] < -0.4 * np.linalg.norm(forearm)
        poses = np.zeros((1, 55, 3))
        poses[0, j] = axis * np.deg2rad(deg)
        assert np.isclose(M.joint_limit_violation(poses)[0, j], excess, atol=1e-6)


def test_joint_limit_excess_is_the_metric_with_a_gradient_along_the_turn():
    """The differentiable form (GraspPose-Opt's limits term) gives the metric's degrees, and d(excess)/d(axis-angle)
    of a wrist turned 120 deg about u is (180/pi) u: one degree of excess per degree of turn."""
    import torch

    u = torch.tensor([0.6, 0.0, 0.8], dtype=torch.float64)
    poses = torch.zeros(2, 55, 3, dtype=torch.float64)
    poses[1, 21] = np.deg2rad(120.0) * u                     # right wrist: 30 deg past its 90
    poses[1, 12] = torch.tensor([0.0, np.deg2rad(100.0), 0.0])
    poses.requires_grad_(True)
    ex = M.joint_limit_excess(poses)
    np.testing.assert_allclose(ex.detach().numpy(), M.joint_limit_violation(poses.detach().numpy()), atol=1e-9)
    assert np.isclose(float(ex[1, 21].detach()), 30.0)
    ex[1, 21].backward()
    np.testing.assert_allclose(poses.grad[1, 21].numpy(), np.rad2deg(1.0) * u.numpy(), rtol=1e-9)
    assert float(poses.grad.abs().sum() - poses.grad[1, 21].abs().sum()) == 0.0


def test_joint_limits_read_the_rotation_not_its_axis_angle_writing():
    """An angle above 180 deg is the same rotation as a shorter one (scipy's as_rotvec gives it): the limits read the
    rotation, so 240 deg at the hip (120 deg the other way), 2 pi at the wrist (none) and -200 deg at the knee (160 deg
    of flexion, 5 past its 155) read as their short forms do; optimisers can write any of them."""
    import torch
    from scipy.spatial.transform import Rotation

    cases = {1: [np.deg2rad(240.0), 0, 0], 4: [np.deg2rad(-200.0), 0, 0], 20: [0, 2 * np.pi, 0],
             0: [np.deg2rad(400.0), 0, 0], 21: 5.5 * np.pi * np.array([0.6, 0.0, 0.8])}
    long, short = np.zeros((1, 55, 3)), np.zeros((1, 55, 3))
    for j, aa in cases.items():
        long[0, j], short[0, j] = aa, Rotation.from_rotvec(aa).as_rotvec()
    np.testing.assert_allclose(M.joint_limit_violation(long), M.joint_limit_violation(short), atol=1e-9)
    assert np.isclose(M.joint_limit_violation(long)[0, 4], 5.0) and M.joint_limit_violation(long)[0, 20] < 1e-9
    p = torch.tensor(long, requires_grad=True)                  # still differentiable, finite gradients
    M.joint_limit_excess(p).sum().backward()
    assert torch.isfinite(p.grad).all()


def test_distance_to_goal_and_success():
    w = np.stack([np.linspace(0, 1, 11), np.zeros(11), np.ones(11)], 1)
    assert np.isclose(M.distance_to_goal(w, [1.0, 0.05, 1.0]), 0.05)
    assert M.goal_reached(w, [1.0, 0.09, 1.0]) and not M.goal_reached(w, [1.0, 0.11, 1.0])
    assert M.distance_to_goal(w, [[1.0, 0.05, 1.0]]) == M.distance_to_goal(w, [1.0, 0.05, 1.0])   # a (1, 3) goal
    with pytest.raises(ValueError, match="goal"):
        M.distance_to_goal(w, [[1.0, 0.05, 1.0], [0.0, 0.0, 0.0]])


def test_distance_to_goal_is_the_closest_approach_not_the_last_frame():
    """A wrist that passes the goal and goes on: DTG is the perpendicular distance at mid-track (5 cm), not the last
    frame's 50 cm; on a random track it is scipy's smallest pairwise distance."""
    from scipy.spatial.distance import cdist

    w = np.stack([np.linspace(0, 1, 11), np.zeros(11), np.ones(11)], 1)
    assert np.isclose(M.distance_to_goal(w, [0.5, 0.05, 1.0]), 0.05)
    assert M.goal_reached(w, [0.5, 0.05, 1.0])
    track, goal = np.random.default_rng(0).normal(size=(40, 3)), np.array([0.2, -0.1, 0.3])
    assert np.isclose(M.distance_to_goal(track, goal), cdist(track, goal[None]).min())


def test_non_collision_score_counts_vertices_above_the_ground():
    v = _cloud(4)                                   # 50 points well above the ground, the sole point at z = 0
    assert np.allclose(M.non_collision_score(v), 1.0)
    sunk = _cloud(4, lift=-0.5)                     # points below z = 0 now: count them by hand
    expected = (sunk[..., 2] >= 0).mean(-1)
    assert np.allclose(M.non_collision_score(sunk), expected) and 0 < expected[0] < 1
    assert np.allclose(M.non_collision_score(v, floor=2.0), 0.0)     # a floor above everything


@pytest.mark.parametrize("call, message", [
    (lambda: M.foot_skating_saga(np.zeros((5, 3))), r"heels: expected shape \(T,2,3\)"),
    (lambda: M.foot_skating_saga(np.zeros((1, 2, 3))), r"heels: .*T >= 2"),
    (lambda: M.foot_skating_wandr(np.zeros((4, 10, 2))), r"vertices: expected shape \(T,V,3\)"),
    (lambda: M.distance_to_goal(np.zeros((3, 2)), [0, 0, 1]), r"wrist: expected shape \(T,3\)"),
    (lambda: M.distance_to_goal(np.zeros((3, 3)), [0, 1]), r"goal: expected shape \(3\)"),
    (lambda: M.joint_jerk(np.zeros((3, 22, 3))), r"joints: .*T >= 4"),
    (lambda: M.apd(np.zeros((0, 3))), r"samples: expected"),
    (lambda: M.apd([[0.0, 1.0], [1.0]]), r"samples: expected an array of numbers"),
    (lambda: M.distance_to_goal(np.zeros((3, 3)), None), r"goal: expected an array of numbers"),
    (lambda: M.distance_to_goal(np.zeros((3, 3)), "abc"), r"goal: expected an array of numbers"),
    (lambda: M.apd(np.array([[0.0, np.nan], [1.0, 1.0]])), r"samples: contains NaN"),
    (lambda: M.ground_penetration(np.full((2, 4, 3), np.nan)), r"vertices: contains NaN"),
    (lambda: M.distance_to_goal(np.zeros((3, 3)), [0, np.inf, 1]), r"goal: contains NaN or Inf"),
    (lambda: M.foot_skating_wandr(np.zeros((4, 0, 3))), r"vertices: expected shape \(T,V,3\).*no size zero"),
    (lambda: M.joint_speed(np.zeros((3, 22, 3)), fps=0), r"fps: expected a positive number"),
    (lambda: M.contact_ratio([np.nan, 0.0]), r"min_distances: contains NaN"),
    (lambda: M.contact_ratio([]), r"min_distances: expected at least one grasp"),
    (lambda: M.contact_ratio([0.0], threshold=np.nan), r"threshold: expected a finite"),
    (lambda: M.contact_ratio([0.0], threshold="x"), r"threshold: expected a finite"),
    (lambda: M.foot_skating_wandr(np.zeros((4, 10, 3)), fps=0), r"fps: expected a positive"),
    (lambda: M.grasp_quality_table([{"contact": 1.0, "volume_cm3": np.nan, "depth_cm": 0.0}]), r"rows: 'volume_cm3'"),
    (lambda: M.grasp_quality_table([{"contact": 1.0, "depth_cm": 0.0}]), r"rows: every row needs 'volume_cm3'"),
    (lambda: M.foot_skating_wandr(np.zeros((4, 10, 3)), threshold=np.nan), r"threshold: expected a positive"),
    (lambda: M.foot_sliding_goal(np.zeros((4, 10, 3)), threshold=-1.0), r"threshold: expected a positive"),
    (lambda: M.joint_limit_violation(np.zeros((3, 22, 3))), r"poses: expected shape \(T,55,3\)"),
    (lambda: M.joint_limit_violation(np.full((3, 55, 3), np.nan)), r"poses: contains NaN"),
    (lambda: M.non_collision_score(np.zeros((2, 4, 3)), floor=np.nan), r"floor: expected a finite distance"),
    (lambda: M.foot_skating_saga(np.zeros((3, 2, 3)), height=None), r"height: expected a positive number"),
    (lambda: M.foot_skating_saga(np.zeros((3, 2, 3)), speed=-1.0), r"speed: expected a positive number"),
])
def test_bad_shapes_name_the_argument(call, message):
    with pytest.raises(ValueError, match=message):
        call()


def test_tensors_that_require_grad_and_integer_arrays_are_measured_as_plain_numbers():
    """smplx returns vertices that require grad, and a user may pass integer grids: the metrics measure them as the
    same float values (a detached copy), never raising."""
    import torch

    rng = np.random.default_rng(0)
    v = rng.normal(size=(6, 20, 3))
    t = torch.tensor(v, requires_grad=True)
    for f in (M.foot_skating_wandr, M.foot_sliding_goal, M.ground_penetration, M.non_collision_score,
              M.joint_speed, M.joint_jerk):
        assert np.array_equal(f(t), f(v))
    step = np.zeros((3, 1, 3), np.int64)
    step[1:, 0, 0] = 1                                           # the one vertex moves 1 m in the first pair only
    assert M.foot_skating_wandr(step).tolist() == [True, False]
    assert M.distance_to_goal(np.array([[0, 0, 0], [3, 4, 0]]), [3, 4, 0]) == 0.0
    d = torch.tensor([0.001, 0.003], requires_grad=True)
    assert M.contact_ratio(d) == M.contact_ratio([0.001, 0.003]) == 0.5


def test_contact_ratio_with_volumes_counts_an_object_poking_between_vertices_as_grasp_metrics_does():
    """A 10 cm box body and a 1 cm rod pushed 5 mm into the middle of its top face: no body vertex comes within 6 cm
    of the rod, yet they overlap by 0.5 cm³ (manifold3d's exact intersection): in contact for grasp_metrics, and for
    contact_ratio once it is given the volumes."""
    body = trimesh.creation.box(extents=(0.1, 0.1, 0.1))
    rod = trimesh.creation.box(extents=(0.01, 0.01, 0.1))
    rod.apply_translation((0.0, 0.0, 0.095))
    truth = trimesh.boolean.intersection([body, rod], engine="manifold").volume * 1e6
    assert truth == pytest.approx(0.5, rel=1e-6)
    g = M.grasp_metrics(body.vertices, body.faces, rod)
    assert g["min_distance"] > 0.06 and g["contact"] == 1.0 and g["volume_cm3"] == pytest.approx(truth, rel=1e-6)
    assert M.contact_ratio([g["min_distance"], 0.0]) == 0.5                                # the distances alone miss it
    assert M.contact_ratio([g["min_distance"], 0.0], volumes_cm3=[g["volume_cm3"], 0.0]) == 1.0
    table = M.grasp_quality_table([g])["contact_ratio"]
    assert M.contact_ratio([g["min_distance"]], volumes_cm3=[g["volume_cm3"]]) == table == 1.0
    with pytest.raises(ValueError, match=r"volumes_cm3: expected one volume per grasp \(2\)"):
        M.contact_ratio([0.0, 0.1], volumes_cm3=[0.0])
    with pytest.raises(ValueError, match=r"min_distances: expected one number per grasp, shape \(N,\)"):
        M.contact_ratio([[0.0, 0.1]])


def test_apd_of_equal_samples_is_zero_and_matches_scipy():
    """APD is the mean distance over ordered pairs i != j (a plain broadcast here); equal samples (K > 25, where a
    matrix-product shortcut |a|²+|b|²-2ab would round) give exactly 0."""
    assert M.apd(np.full((30, 67, 3), 1.3)) == 0.0
    x = np.random.default_rng(1).normal(size=(31, 12, 3)) + 500.0
    f = x.reshape(31, -1)
    d = np.sqrt(((f[:, None] - f[None]) ** 2).sum(-1))                  # (31, 31), zero diagonal
    assert M.apd(x) == pytest.approx(d.sum() / (31 * 30), rel=1e-12)
    assert M.apd(x[::-1]) == pytest.approx(M.apd(x), rel=1e-12)          # a view with negative strides
    j = x[:, :4]
    assert np.allclose(M.joint_speed(j[::-1])[::-1], M.joint_speed(j))


def test_floor_figures_of_a_body_that_sinks_then_rises():
    """Three frames of a two-vertex body whose lowest vertex is at +1, -2.5 and -0.4 cm: deepest 2.5 cm, end -0.4 cm."""
    v = np.zeros((3, 2, 3))
    v[:, 0, 2], v[:, 1, 2] = [0.01, -0.025, -0.004], 0.5
    f = M.floor_figures(v)
    assert f["floor_deepest_cm"] == pytest.approx(2.5) and f["end_floor_cm"] == pytest.approx(-0.4)
    assert M.floor_figures(v[:1])["floor_deepest_cm"] == 0.0                   # never below: 0
    assert f["floating_share"] == 0.0                                      # +1 cm is not more than 1 cm above


def test_floating_share_counts_the_frames_whose_lowest_vertex_is_above_the_floor_plus_height():
    """Four frames of a two-vertex body, lowest at 0, 1.5, 0.9 and 3 cm: two of four more than 1 cm above z = 0;
    with the floor at 1 cm one (3 cm); with height 0.5 cm three."""
    v = np.zeros((4, 2, 3))
    v[:, 0, 2], v[:, 1, 2] = [0.0, 0.015, 0.009, 0.03], 1.0
    assert M.floating_share(v) == pytest.approx(0.5)
    assert M.floating_share(v, floor=0.01) == pytest.approx(0.25)
    assert M.floating_share(v, height=0.005) == pytest.approx(0.75)
    assert M.floor_figures(v)["floating_share"] == pytest.approx(0.5)
    with pytest.raises(ValueError, match="height"):
        M.floating_share(v, height=-0.01)


def test_joint_turn_speed_is_the_angular_speed_of_a_joint_turning_about_any_axis():
    from scipy.spatial.transform import Rotation

    fps, w = 30.0, 90.0                                               # deg/s about a tilted axis, from a tilted start
    axis = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    start = Rotation.from_rotvec([0.4, 0.2, -0.7])
    R = [start * Rotation.from_rotvec(np.radians(w) * k / fps * axis) for k in range(20)]
    poses = np.stack([r.as_rotvec() for r in R])[:, None]            # (T, 1, 3)
    np.testing.assert_allclose(M.joint_turn_speed(poses, fps), w, rtol=1e-6)
    snap = np.zeros((6, 55, 3))
    snap[3:, 15, 1] = np.radians(82.5)                                 # a head turned 82.5 deg in one frame
    turn = M.joint_turn_speed(snap[:, M.TURN_JOINTS], fps)
    assert turn.max() == pytest.approx(82.5 * fps) and np.unravel_index(turn.argmax(), turn.shape) == (2, 15)


def test_motion_quality_reports_the_fastest_turning_joint_of_a_clip(bm):
    """On a shipped reach clip: motion_quality's max_joint_turn is scipy's largest frame-to-frame rotation angle of
    the local rotations of joints 0-24, times the frame rate, at the joint and frame it names."""
    from scipy.spatial.transform import Rotation

    from graspkit.body.skeleton import JOINT_NAMES

    m = _reach()
    p = m.poses.reshape(len(m.poses), -1, 3)[:, :25]
    r = [Rotation.from_rotvec(p[:, j]) for j in range(25)]
    deg = np.stack([np.degrees((x[:-1].inv() * x[1:]).magnitude()) for x in r], 1) * m.fps
    q = M.motion_quality(bm, [m])
    t, j = np.unravel_index(deg.argmax(), deg.shape)
    assert q["max_joint_turn"] == pytest.approx(deg.max(), rel=1e-4)
    assert q["max_joint_turn_at"] == f"clip 0 frame {t} {JOINT_NAMES[j]}"


def test_motion_quality_of_one_frame_clips_has_no_rates_rather_than_zero(bm):
    """One frame has no frame pairs: its skating rates were reported as 0 %, which reads as "no skating"."""
    m = _reach()
    one = M.motion_quality(bm, [m.slice(0, 1)])
    assert one["pairs"] == 0 and one["frames"] == 1
    assert all(np.isnan(one[k]) for k in ("fs_wandr", "skate_saga", "slide_goal", "mean_jerk"))
    both = M.motion_quality(bm, [m.slice(0, 1), m])              # the one-frame clip adds nothing to the rates
    alone = M.motion_quality(bm, [m])
    assert both["pairs"] == alone["pairs"] == m.num_frames - 1
    assert both["fs_wandr"] == alone["fs_wandr"] and both["skate_saga"] == alone["skate_saga"]


def test_motion_quality_averages_wandrs_fs_per_motion_and_pools_goals_sliding(bm):
    """Two motions of different lengths: 3 frames gliding 5 cm a frame (both pairs skate and slide) and 21 frames
    standing still. WANDR's FS is per motion, averaged: (1 + 0) / 2; GOAL's sliding is the share of all frames:
    2 of 22 pairs; pooling FS as well would read 2 / 22."""
    from graspkit.data.motion import Motion

    poses = np.zeros((21, 165))
    glide = Motion(poses[:3], np.array([[0.05 * t, 0.0, 0.0] for t in range(3)]), np.zeros(10), 30.0)
    still = Motion(poses, np.zeros((21, 3)), np.zeros(10), 30.0)
    q = M.motion_quality(bm, [glide, still])
    assert q["pairs"] == 22 and q["fs_wandr"] == pytest.approx(0.5) and q["slide_goal"] == pytest.approx(2 / 22)
    one = [M.foot_skating_wandr(m.vertices(bm)).mean() for m in (glide, still)]        # each motion on its own
    assert one == [1.0, 0.0]
    assert M.motion_quality(bm, [still, glide], chunk=2)["fs_wandr"] == pytest.approx(0.5)  # any order, any chunk


def test_skating_follows_the_vertex_lowest_at_t_not_the_one_lowest_at_t_plus_1():
    """metrics' docstring: "the lowest vertex moves" is measured on the same vertex from t to t+1, the vertex that is
    lowest at t. Vertex A is lowest at t and lifts straight up; vertex B comes down 5 cm sideways and is lowest at
    t+1. Followed from t, A moves 0 horizontally (no skating) and 2 cm in 3D."""
    v = np.array([[[0.0, 0.0, 0.0], [0.0, 0.0, 0.05], [0.0, 0.0, 1.0]],
                  [[0.0, 0.0, 0.02], [0.05, 0.0, 0.0], [0.0, 0.0, 1.0]]], np.float32)
    h, d3 = M.lowest_vertex_motion(v)
    assert h[0] == pytest.approx(0.0, abs=1e-7) and d3[0] == pytest.approx(0.02, abs=1e-6)
    assert not M.foot_skating_wandr(v).any()
    assert M.foot_sliding_goal(v).all()                   # 2 cm per frame in 3D: above GOAL's 1 cm


def test_motion_quality_counts_each_frame_once_across_chunks(bm):
    """A clip of 10 frames sinking 1 cm a frame, read in chunks of 3 (chunks share one frame): motion_quality's
    frames and mean penetration are those of the 10 frames, each once (the depth of the lowest vertex below z = 0,
    measured here on the whole clip's vertices with numpy)."""
    from graspkit.data.motion import Motion

    T = 10
    m = Motion(np.zeros((T, 165)), np.array([[0.0, 0.0, -0.01 * t] for t in range(T)]), np.zeros(10), 30.0)
    v = np.asarray(m.vertices(bm))
    depth = np.maximum(-v[:, :, 2].min(1), 0.0)
    q = M.motion_quality(bm, [m], chunk=3)
    assert q["frames"] == T
    assert q["penetration_mean"] == pytest.approx(depth.mean(), rel=1e-5)
    assert q["penetration_max"] == pytest.approx(depth.max(), rel=1e-5)


def _step(move: float) -> np.ndarray:
    """One vertex on the ground that moves `move` m along x in the first frame pair and then stands: (3, 1, 3)."""
    v = np.zeros((3, 1, 3))
    v[1:, 0, 0] = move
    return v


def test_more_than_thresholds_are_strict_and_within_radii_inclusive():
    """The docstrings' words on exactly representable numbers: a move exactly at the threshold is not "more than" it
    (WANDR FS, GOAL sliding, SAGA's heel speed); a distance exactly at the radius/threshold is "within" it (WANDR's
    success, contact_ratio's <= threshold, the feet share's "within 1 cm")."""
    for f in (M.foot_skating_wandr, M.foot_sliding_goal):
        assert f(_step(0.5), threshold=0.5).tolist() == [False, False]      # 0.5 * 30 / 30 is exactly 0.5
        assert f(_step(0.5), threshold=0.25).tolist() == [True, False]
    heels = np.zeros((3, 2, 3))
    heels[1:, :, 0] = 1.0                                   # both heels on the floor, 1 m in the first pair: 1 m/s at 1 fps
    assert M.foot_skating_saga(heels, fps=1.0, speed=1.0).tolist() == [False, False]
    assert M.foot_skating_saga(heels, fps=1.0, speed=0.5).tolist() == [True, False]
    wrist = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.25]])
    assert M.goal_reached(wrist, [0.5, 0.0, 0.0], radius=0.5) and not M.goal_reached(wrist, [0.5, 0.0, 0.0], radius=0.25)
    t = M.GRASP_CONTACT_THRESHOLD
    assert M.contact_ratio([t, t + 1e-4]) == 0.5 and M.contact_ratio([0.5, 0.75], threshold=0.5) == 0.5
    rows = [{"contact": 1.0, "volume_cm3": 0.0, "depth_cm": 0.0, "feet_cm": f} for f in (1.0, 1.5)]
    assert M.grasp_quality_table(rows)["feet_within_1cm"] == 0.5


def test_saga_skating_defaults_to_30_fps_like_the_other_metrics():
    """Heels on the floor gliding 2.8 mm a frame: 84 mm/s at the default 30 fps (the metrics' default rate, as
    joint_speed's and WANDR's), above SAGA's 75 mm/s; the default reads exactly as fps=30."""
    T = 10
    heels = np.zeros((T, 2, 3))
    heels[:, :, 0] = np.arange(T)[:, None] * 0.0028
    heels[:, 1, 1] = 0.2
    assert M.foot_skating_saga(heels).all()
    np.testing.assert_array_equal(M.foot_skating_saga(heels), M.foot_skating_saga(heels, fps=30.0))
    assert not M.foot_skating_saga(heels, fps=20.0).any()   # 56 mm/s


def test_joint_limits_flag_a_twisted_knee_and_an_overbent_finger_everywhere_on_the_hand():
    """A knee does not twist: 60 deg about the hinge's perpendicular is off-axis rotation beyond the table's off-axis
    limit (HINGES), by 60 - that limit; a finger curled 170 deg is beyond any human range (first and last finger joints,
    both hands), one curled 30 deg is not."""
    from graspkit.body.skeleton import JOINT_INDEX

    poses = np.zeros((3, 55, 3))
    knee = JOINT_INDEX["left_knee"]
    poses[0, knee] = [0.0, np.deg2rad(60.0), 0.0]
    lim = M.joint_limit_violation(poses)
    assert lim[0, knee] == pytest.approx(60.0 - M.HINGES["left_knee"][3], abs=1e-6)
    for j in (25, 39, 40, 54):
        poses[1, j] = [0.0, 0.0, np.deg2rad(170.0)]
        poses[2, j] = [0.0, 0.0, np.deg2rad(30.0)]
    lim = M.joint_limit_violation(poses)
    assert (lim[1, [25, 39, 40, 54]] > 0).all() and lim[2].max() == 0.0


def test_measures_over_pairs_refuse_inputs_without_a_pair():
    """APD averages over pairs i != j and WANDR's FS / GOAL's sliding over frame pairs t, t+1: one sample or one frame
    has no pair, so it is an error (as SAGA's skating gives), not NaN or an empty answer."""
    with pytest.raises(ValueError, match="at least 2 samples"):
        M.apd(np.zeros((1, 4, 3)))
    for f in (M.foot_skating_wandr, M.foot_sliding_goal, M.lowest_vertex_motion):
        with pytest.raises(ValueError, match=r"vertices: .*T >= 2"):
            f(np.zeros((1, 4, 3)))


def _reach():
    """A shipped reaching clip (graspkit.data.Motion)."""
    from graspkit.data import load_motion
    from graspkit.paths import DATA_STUBS
    return load_motion(DATA_STUBS / "motion" / "reach" / "reach_000003.npz")


def test_motion_quality_speed_jerk_and_fs_match_numpy_on_a_reach_clip(bm):
    """On a shipped reach clip read in chunks of 16: the largest body-joint speed (joints 0..21, pelvis to right wrist)
    and where, the mean jerk over every frame and body joint, and WANDR's FS are numpy's finite differences of the
    clip's own joints and vertices; a 4-frame clip has one jerk frame (not NaN)."""
    from graspkit.body.skeleton import JOINT_NAMES

    m = _reach()
    j = np.asarray(m.joint_positions(bm), np.float64)[:, :22]
    sp = np.linalg.norm(np.diff(j, axis=0), axis=-1) * m.fps
    jerk = np.linalg.norm(np.diff(j, 3, axis=0), axis=-1) * m.fps ** 3
    v = np.asarray(m.vertices(bm), np.float64)
    low = v[:-1, :, 2].argmin(1)
    ar = np.arange(len(low))
    h = np.linalg.norm(v[1:][ar, low, :2] - v[:-1][ar, low, :2], axis=-1)
    q = M.motion_quality(bm, [m], chunk=16)
    t, k = np.unravel_index(sp.argmax(), sp.shape)
    assert q["max_joint_speed"] == pytest.approx(sp.max(), rel=1e-4)
    assert q["max_joint_speed_at"] == f"clip 0 frame {t} {JOINT_NAMES[k]}"
    assert q["mean_jerk"] == pytest.approx(jerk.mean(), rel=1e-3)
    assert q["pairs"] == m.num_frames - 1 and q["fs_wandr"] == pytest.approx(np.mean(h > 0.0066), abs=1e-9)
    q4 = M.motion_quality(bm, [m.slice(0, 4)])
    assert q4["mean_jerk"] == pytest.approx(jerk[:1].mean(), rel=1e-3)


def test_motion_quality_reads_sagas_heel_speed_at_the_clips_own_rate(bm):
    """A standing body gliding at 10 cm/s with both heels 1 cm above the floor, captured at 60 fps: both heels low
    and faster than SAGA's 75 mm/s in every pair (skate_saga 1), whatever the rate it is stored at."""
    from graspkit.data.motion import Motion

    T, fps = 10, 60.0
    hl, hr = M.heel_vertex_ids()
    trans = np.array([[0.1 * t / fps, 0.0, 0.0] for t in range(T)])
    m0 = Motion(np.zeros((T, 165)), trans, np.zeros(10), fps)
    heel_z = np.asarray(m0.vertices(bm, 0, 1))[0, [hl, hr], 2]
    trans[:, 2] = 0.01 - heel_z.max()
    m = Motion(np.zeros((T, 165)), trans, np.zeros(10), fps)
    heels = np.asarray(m.vertices(bm))[:, [hl, hr]]
    assert (heels[:, :, 2] < 0.05).all() and (heels[:, :, 2] > -0.01).all()
    assert M.motion_quality(bm, [m])["skate_saga"] == 1.0
