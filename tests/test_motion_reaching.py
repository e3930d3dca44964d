"""The procedural reaching planner (WANDR's time-controlled goal reaching) and CIRCLE-style clips."""
import numpy as np
import pytest
from scipy import stats

from graspkit.checks import GraspkitWarning
from graspkit import metrics as M
from graspkit.body.skeleton import JOINT_INDEX as J
from graspkit.data import Start, evaluation_goals, generate_reach, plan_reach
from graspkit.data.ik import wrap_angle
from graspkit.data.motion import heading_of
from graspkit.data.posing import GAZE_LEVEL, HEAD_YAW_LIMIT, gaze_yaw, hand_pose
from graspkit.data.reaching import (FAR_HEIGHTS, FLOOR_WRIST, LEVELS, REACH_RHO, RELEASE_S, _approach_plan,
                                    _goal_as_reached, _natural_time, choose_posture, plan_reach_chain,
                                    posture_shoulders, sample_reach_task)
from graspkit.data.rig import build_rig


WRIST = 21


@pytest.mark.parametrize("goal", [(0.9, -0.4, 0.05), (1.6, 0.8, 0.9), (-0.3, 1.2, 1.75)])
def test_wrist_is_on_low_middle_and_high_goals_at_the_goal_frame(bm, goal):
    m = plan_reach(Start(0.0, 0.0, 0.3), goal, 100, seed=2, bm=bm, hold_frames=10)
    assert m.num_frames == 111 and m.goal_frame == 100 and m.hand == "right"
    w = m.joint_positions(bm)[:, WRIST]
    want = np.array(goal, float)
    want[2] = max(want[2], FLOOR_WRIST)                      # the hand lies on the floor, the wrist just above
    assert np.linalg.norm(w[100] - want) < 0.01
    assert np.linalg.norm(w[100:] - want, axis=1).max() < 0.01            # held
    assert M.goal_reached(w, goal)
    q = M.motion_quality(bm, [m])
    assert q["fs_wandr"] <= 0.05 and q["penetration_max"] <= 0.01 and q["joint_limit_max"] == 0.0


def test_time_control_the_wrist_arrives_when_asked(bm):
    goal = (1.2, 0.3, 1.1)
    for t_goal in (60, 150):
        m = plan_reach(Start(), goal, t_goal, seed=0, bm=bm, hold_frames=0)
        d = np.linalg.norm(m.joint_positions(bm)[:, WRIST] - goal, axis=1)
        assert d[t_goal] < 0.01
        assert d[: t_goal - 10].min() > 0.02                 # not there early
        assert np.all(np.diff(d[t_goal - 12:]) <= 1e-4)     # slowing down onto the goal


def test_reaching_turns_to_face_a_goal_behind(bm):
    from graspkit.data.motion import heading_of
    m = plan_reach(Start(0, 0, 0), (-2.0, 0.2, 1.0), 150, seed=1, bm=bm, hold_frames=0)
    h = heading_of(m.poses[:, 0])
    assert abs(h[0]) < 0.15
    to_goal = np.arctan2(0.2 - m.trans[-1, 1], -2.0 - m.trans[-1, 0])
    assert abs(np.angle(np.exp(1j * (h[-1] - to_goal)))) < 0.8            # facing the goal (it sits front-right)


def test_circle_style_clips_are_short_mostly_reaching_and_store_their_goal(bm):
    for seed in range(3):
        m = generate_reach(seed, bm)
        assert m.hand == "right" and m.goal is not None and 0 < m.goal_frame < m.num_frames <= 110
        j = m.joint_positions(bm)
        assert np.linalg.norm(j[m.goal_frame, WRIST] - np.maximum(m.goal, [-9, -9, FLOOR_WRIST])) < 0.02
        walked = np.linalg.norm(j[-1, 0, :2] - j[0, 0, :2])
        assert walked < 1.3                                  # a step or two at most
        steps = (np.diff(m.contacts[:, [0, 2]].astype(int), axis=0) == 1).sum()
        assert steps <= 4


def test_room_scale_tasks_cover_wandrs_grid_and_their_clips_reach_the_goal(bm):
    from graspkit.data.reaching import sample_reach_task

    rng = np.random.default_rng(0)
    tasks = [sample_reach_task(rng, far=True) for _ in range(300)]
    d = np.array([np.hypot(t.goal[0] - t.start.x, t.goal[1] - t.start.y) for t in tasks])
    rel = np.array([np.angle(np.exp(1j * (np.arctan2(t.goal[1] - t.start.y, t.goal[0] - t.start.x) - t.start.heading)))
                    for t in tasks])
    tg = np.array([t.goal_frame for t in tasks]) / 30.0
    assert d.min() > 0.2 and d.max() < 5.6 and d.max() > 4.5                 # 0.3-5 m (start jitter: +-0.5 m)
    assert (np.abs(rel) > 2.5).mean() > 0.1                                  # goals behind the start too
    assert tg.max() <= 9.0 and np.all(tg > d / 1.6)                          # reachable at a brisk walk, <= 9 s
    z = np.array([t.goal[2] for t in tasks])                                # heights balanced over the grid's 0-1.8 m
    lo, hi = FAR_HEIGHTS
    assert stats.kstest(z, "uniform", args=(lo, hi - lo)).pvalue > 0.01
    assert FAR_HEIGHTS[0] <= 0.0 and FAR_HEIGHTS[1] >= 1.8 and (z > 1.7).mean() > 0.05
    near = [sample_reach_task(np.random.default_rng(s)) for s in range(50)]
    assert max(np.hypot(t.goal[0] - t.start.x, t.goal[1] - t.start.y) for t in near) < 1.9   # default unchanged
    for seed in range(2):
        m = generate_reach(seed, bm, far=True)
        j = m.joint_positions(bm)
        assert np.linalg.norm(j[m.goal_frame, WRIST] - np.maximum(m.goal, [-9, -9, FLOOR_WRIST])) < 0.02


def test_a_slow_preferred_speed_fills_the_time_with_walking_not_standing(bm):
    # the room-scale clips (generate_reach(far=True)) plan with v_pref = FAR_MIN_SPEED: with 8 s for 3 m the body sets
    # off at once and walks slowly, where a natural pace stands first and then walks fast
    from graspkit.data.reaching import FAR_MIN_SPEED

    out = {}
    for v in (FAR_MIN_SPEED, 1.0):
        m = plan_reach(Start(), (3.0, -0.3, 1.0), 240, seed=0, bm=bm, hold_frames=0, v_pref=v)
        pel = m.joint_positions(bm)[:, 0, :2]
        moved = np.linalg.norm(pel - pel[0], axis=1)
        speed = np.linalg.norm(np.diff(pel, axis=0), axis=1) * 30
        out[v] = (int(np.argmax(moved > 0.1)), float(speed.max()))
        assert np.linalg.norm(m.joint_positions(bm)[240, WRIST] - [3.0, -0.3, 1.0]) < 0.01   # arrives either way
    (start_slow, top_slow), (start_fast, top_fast) = out[FAR_MIN_SPEED], out[1.0]
    assert start_slow < 60 < start_fast            # off within 2 s, against a stand of more than 2 s
    assert top_slow < 0.85 * top_fast


def test_hurried_room_scale_tasks_walk_fast_with_real_steps(bm):
    # a share FAR_HURRY of the room-scale tasks is due at a fast walk: the goal frame comes before the leisurely
    # natural time (walking at ~0.8 m/s), and the planned clip gets there stepping, not sliding
    from graspkit.data.reaching import FAR_HURRY, FAR_HURRY_SPEED, sample_reach_task

    def leisurely(t):    # the earliest goal time of an unhurried task: turn, walk at 0.8 m/s, reach, 0.2 s pause
        d = t.goal[:2] - np.array([t.start.x, t.start.y])
        rel = abs((np.arctan2(d[1], d[0]) - t.start.heading + np.pi) % (2 * np.pi) - np.pi)
        r = float(np.hypot(*d))
        turn = rel / 2.2 + 0.35 if rel > 0.3 else 0.0
        walk = max(r - 0.55, 0.0) / 0.8 + (0.6 if r > 0.55 else 0.0)
        return min(turn + walk + 0.9 + 0.5 * max(0.9 - t.goal[2], 0.0) + 0.2, 9.0), r

    tasks = [sample_reach_task(np.random.default_rng(s), far=True) for s in range(600)]
    hurried = [t for t in tasks if t.goal_frame / 30 < leisurely(t)[0] - 0.1 and leisurely(t)[1] > 1.5]
    far = [t for t in tasks if leisurely(t)[1] > 1.5]
    assert hurried and stats.binomtest(len(hurried), len(far), FAR_HURRY).pvalue > 1e-3
    t = max(hurried, key=lambda t: leisurely(t)[1])              # the longest hurried walk
    m = plan_reach(t.start, t.goal, t.goal_frame, betas=t.betas, seed=0, bm=bm, hold_frames=0, v_pref=0.25)
    pel = m.joint_positions(bm)[:, 0, :2]
    speed = np.linalg.norm(np.diff(pel, axis=0), axis=1) * 30
    assert np.percentile(speed, 90) > 0.9 * FAR_HURRY_SPEED[0]   # walks at a hurried pace for a good part
    v = m.vertices(bm)
    assert float(np.mean(M.foot_skating_wandr(v))) < 0.01       # and steps: the lowest vertex stands still


def test_evaluation_grid_is_wandrs():
    g = evaluation_goals(Start(1.0, 2.0, 0.5))
    assert g.shape == (125, 5)
    assert sorted(set(np.round(g[:, 0]))) == [0, 72, 144, 216, 288]
    assert np.allclose(sorted(set(g[:, 1])), np.linspace(0, 1.8, 5))
    assert np.allclose(np.hypot(g[:, 3] - 1.0, g[:, 4] - 2.0), g[:, 2])


def test_two_reaches_in_a_row_hold_the_first_then_turn_round_for_the_second(bm):
    from graspkit.data.motion import heading_of
    from graspkit.data.reaching import plan_reach_chain

    g1, g2 = np.array([1.0, -0.3, 1.2]), np.array([-1.2, 1.0, 0.6])          # the second behind the first reach
    m, f_rel = plan_reach_chain(Start(0, 0, 0), np.stack([g1, g2]), (90, 240), (15, 10), seed=0, bm=bm)
    assert (m.num_frames, f_rel, m.goal_frame) == (251, 105, 240) and np.allclose(m.goal, g2)
    j = m.joint_positions(bm)
    d1, d2 = (np.linalg.norm(j[:, WRIST] - g, axis=1) for g in (g1, g2))
    assert d1[90:106].max() < 0.01                                       # the first goal reached and held
    assert d1[f_rel + 30] > 0.15 and d2[240:].max() < 0.01              # let go, then the second reached and held
    step = np.linalg.norm(np.diff(j[:, 0], axis=0), axis=1) * 30
    assert step.max() < 2.0                                              # no jump where the legs meet (m/s)
    acc = np.linalg.norm(np.diff(j, 2, axis=0), axis=-1).max(1) * 900
    assert acc[f_rel - 5:f_rel + 40].max() < 1.5 * acc.max(initial=0, where=np.arange(len(acc)) < 90)
    h = heading_of(m.poses[:, 0])
    to_goal = np.arctan2(g2[1] - m.trans[-1, 1], g2[0] - m.trans[-1, 0])
    assert abs(np.angle(np.exp(1j * (h[-1] - to_goal)))) < 0.8                # turned round to face it
    with pytest.raises(ValueError, match="goal_frames"):
        plan_reach_chain(Start(), np.stack([g1, g2]), (90, 100), (15, 10), bm=bm)


def test_chained_room_scale_clips_start_from_a_finished_reach(bm):
    from graspkit.data.reaching import generate_reach_chain, sample_reach_task
    from graspkit.data.wandr_dataset import FOLDERS

    for seed in range(3):
        first = sample_reach_task(np.random.default_rng(seed), far=True)      # the clip's first draw: its first task
        m = generate_reach_chain(seed, bm)
        j = m.joint_positions(bm)
        assert np.linalg.norm(j[0, WRIST] - np.maximum(first.goal, [-9, -9, FLOOR_WRIST])) < 0.01   # on the old goal
        assert np.linalg.norm(j[m.goal_frame, WRIST] - np.maximum(m.goal, [-9, -9, FLOOR_WRIST])) < 0.02
        assert np.linalg.norm(m.goal[:2] - j[0, 0, :2]) > 0.3 and m.goal_frame < m.num_frames
        assert M.motion_quality(bm, [m])["penetration_max"] <= 0.02
    a, b = generate_reach_chain(1, bm), generate_reach_chain(1, bm)
    assert np.array_equal(a.poses, b.poses) and not np.array_equal(a.poses[:50], generate_reach_chain(2, bm).poses[:50])
    assert FOLDERS["reach_chain"] == "reach"                                  # trained on as reaching clips (goal, t_G)


def test_near_tasks_put_the_goal_close_by_at_the_floor_or_overhead_and_their_clips_reach_it(bm):
    from graspkit.data.reaching import NEAR_DISTANCE, NEAR_HEIGHTS, sample_near_task
    from graspkit.data.wandr_dataset import FOLDERS

    tasks = [sample_near_task(np.random.default_rng(s)) for s in range(400)]
    d = np.array([np.hypot(t.goal[0] - t.start.x, t.goal[1] - t.start.y) for t in tasks])
    z = np.array([t.goal[2] for t in tasks])
    rel = np.array([np.angle(np.exp(1j * (np.arctan2(t.goal[1] - t.start.y, t.goal[0] - t.start.x) - t.start.heading)))
                    for t in tasks])
    tg = np.array([t.goal_frame for t in tasks]) / 30.0
    assert d.min() >= NEAR_DISTANCE[0] - 1e-9 and d.max() <= NEAR_DISTANCE[1] + 1e-9
    (lo0, hi0), (lo1, hi1) = NEAR_HEIGHTS
    low, high = (z >= lo0) & (z <= hi0), (z >= lo1) & (z <= hi1)
    assert np.all(low | high) and 0.4 < high.mean() < 0.6 and (z > 1.75).mean() > 0.05    # half each; 1.8 m covered
    assert (np.abs(rel) > 2.5).mean() > 0.1 and tg.max() <= 9.0 and (tg > 5.0).mean() > 0.2   # behind too; long waits
    for seed in range(2):
        m = generate_reach(seed, bm, near=True)
        j = m.joint_positions(bm)
        assert np.linalg.norm(j[m.goal_frame, WRIST] - np.maximum(m.goal, [-9, -9, FLOOR_WRIST])) < 0.02
        assert np.hypot(*(m.goal[:2] - j[0, 0, :2])) < NEAR_DISTANCE[1] + 0.3          # near the start's pelvis
    a, b = generate_reach(1, bm, near=True), generate_reach(1, bm, near=True)
    assert np.array_equal(a.poses, b.poses) and not np.array_equal(a.poses, generate_reach(1, bm, far=True).poses)
    with pytest.raises(ValueError, match="far, near"):
        generate_reach(0, bm, far=True, near=True)
    assert FOLDERS["reach_near"] == "reach"


@pytest.mark.parametrize("bad, match", [
    ({"goal_frames": (90, 120)}, "goal_frames: the second goal frame must come at least 9 frames after"),   # 90 + 10 held + 24 released
    ({"hold_frames": (-1, 5)}, r"hold_frames\[0\]: expected an integer >= 0"),
    ({"hold_frames": (10, -2)}, r"hold_frames\[1\]"),
    ({"goal_frames": (90.5, 200)}, r"goal_frames\[0\]: expected an integer"),
    ({"goals": np.zeros((3, 3))}, r"goals: expected two finite goals \(2, 3\)"),
    ({"goals": np.array([[1.0, 0.0, np.nan], [2.0, 1.0, 1.0]])}, "NaN or Inf"),
    ({"betas": np.zeros(5)}, "betas: expected at least 10 finite shape coefficients"),
    ({"release_s": -0.1}, "release_s"),
])
def test_a_chain_of_reaches_refuses_bad_input_by_name(bm, bad, match):
    from graspkit.data.reaching import plan_reach_chain

    kw = {"goals": np.array([[1.0, 0.0, 1.0], [2.0, 1.0, 1.0]]), "goal_frames": (90, 200), "hold_frames": (10, 5)}
    with pytest.raises(ValueError, match=match):
        plan_reach_chain((0.0, 0.0, 0.0), bm=bm, **{**kw, **bad})


@pytest.mark.parametrize("kind, index", [("reach_near", 11), ("reach_near", 24), ("reach_far", 8)])
def test_the_head_never_snaps_round_when_the_gaze_target_passes_behind_or_under_it(bm, kind, index):
    """Clips of `--seed 0` whose head once turned 82 deg in one frame (a clipped arctan2 wrapping at pi, a blended
    look vector through zero): the neck and head local rotations, read with scipy, turn at most a few deg per frame,
    and the head still faces the goal at the goal frame."""
    from scipy.spatial.transform import Rotation

    from graspkit.data.cli import clip_seed
    from graspkit.data.reaching import generate_reach

    m = generate_reach(clip_seed(0, kind, index), bm, far=kind == "reach_far", near=kind == "reach_near")
    p = m.poses.reshape(len(m.poses), -1, 3).astype(np.float64)
    for j in (12, 15):                                      # neck, head
        r = Rotation.from_rotvec(p[:, j])
        assert np.degrees((r[1:] * r[:-1].inv()).magnitude()).max() < 10.0, j
    k = int(m.goal_frame)
    head = np.eye(3)
    for j in (0, 3, 6, 9, 12, 15):                          # pelvis -> spine1..3 -> neck -> head
        head = head @ Rotation.from_rotvec(p[k, j]).as_matrix()
    to = m.goal - m.slice(k, k + 1).joint_positions(bm)[0, 15]
    cos = head[:, 2] @ to / np.linalg.norm(to)               # SMPL-X's forward is the head's +z
    assert cos > np.cos(np.radians(25.0))


# At the goal frame the goal lies to the RIGHT of the heading as seen from the right shoulder (the stand-off) and
# the right elbow bends out to the body's right (the pole); a second goal frame exactly at the end of the first hold
# plus the release (or fewer than MIN_GOAL_FRAMES after it) is refused ("must come at least ... after").
@pytest.mark.parametrize("goal", [(1.5, 0.4, 1.0), (0.2, -1.6, 1.3)])
def test_the_goal_is_reached_right_of_the_heading_with_the_elbow_out_to_the_right(bm, goal):
    m = plan_reach(Start(0.0, 0.0, 0.3), goal, 90, seed=1, bm=bm, hold_frames=0)
    g = m.goal_frame
    p = m.joint_positions(bm)[g]
    h = float(heading_of(m.poses[g:g + 1, 0])[0])
    fwd, right = np.array([np.cos(h), np.sin(h), 0.0]), np.array([np.sin(h), -np.cos(h), 0.0])
    sh, el, wr = p[J["right_shoulder"]], p[J["right_elbow"]], p[J["right_wrist"]]
    to_goal = np.asarray(goal) - sh                                              # seen from the reaching shoulder
    assert to_goal @ fwd > 0 and to_goal @ right > 0.02                          # ahead, to the right
    line = (wr - sh) / np.linalg.norm(wr - sh)
    out = (el - sh) - ((el - sh) @ line) * line                                  # the elbow off the shoulder-wrist line
    assert out @ right > 0.01                                                    # bent out to the right, not across


def test_a_second_goal_frame_at_the_end_of_the_release_is_refused(bm):
    goals = np.array([[0.8, -0.3, 1.0], [1.6, 0.5, 0.9]])
    r = int(round(RELEASE_S * 30.0))
    with pytest.raises(ValueError, match="goal_frames: the second goal frame must come at least 9 frames after"):
        plan_reach_chain(Start(), goals, (60, 60 + 15 + r), (15, 5), bm=bm)


def test_left_hand_is_the_mirror_of_the_right():
    """The left hand's finger pose mirrors the right's (R_left = M R_right M, M = diag(-1, 1, 1))."""
    curl = np.array([0.0, 0.4, 1.0])
    M = np.diag([-1.0, 1.0, 1.0])
    for spread in (0.0, 0.7):
        r, l = hand_pose("right", curl, spread), hand_pose("left", curl, spread)
        np.testing.assert_allclose(l, M @ r @ M, atol=1e-12)
        assert not np.allclose(l[1:], r[1:])                 # curled fingers do differ between the hands


def test_a_level_gaze_turns_by_its_full_yaw():
    """gaze_yaw turns fully towards a target less than 60 deg up or down (GAZE_LEVEL = cos 60 deg); steeper ones fade."""
    assert GAZE_LEVEL == 0.5
    for yaw in (-0.9, -0.3, 0.2, 0.5, 1.1):
        for elev in (0.0, 0.5, -0.9):                        # up to ~52 deg up or down: cos(elev) > 0.5, no fade
            g = np.array([[np.cos(elev) * np.sin(yaw), np.sin(elev), np.cos(elev) * np.cos(yaw)]])
            np.testing.assert_allclose(gaze_yaw(g), [yaw], atol=1e-12)
    assert abs(HEAD_YAW_LIMIT - 1.2) < 1e-12
    g = np.array([[np.sin(1.1) * np.cos(np.pi / 3 + 0.2), np.sin(np.pi / 3 + 0.2), 0.0]])   # steeper: faded
    assert abs(gaze_yaw(g)[0]) < np.pi / 2


def test_the_wrist_is_on_the_goal_at_the_goal_frame(bm):
    """plan_reach puts the right wrist on the goal at the goal frame (within 1 mm)."""
    goal = (1.2, 0.3, 1.1)
    m = plan_reach(Start(), goal, 60, seed=0, bm=bm, hold_frames=0)
    assert np.linalg.norm(m.joint_positions(bm)[60, WRIST] - goal) < 1e-3


def test_a_hand_on_the_floor_lies_flat_for_short_and_tall_bodies(bm):
    """For a goal on the floor the hand lies flat on it for a short and a tall body alike (lowest vertex 0-8 mm up)."""
    part = bm.lbs_weights.argmax(1).numpy()
    hand = np.isin(part, [WRIST] + list(range(40, 55)))
    for b0 in (-2.5, 2.5):
        betas = np.zeros(10)
        betas[0] = b0
        m = plan_reach(Start(0, 0, 0.3), (0.9, -0.4, 0.0), 100, betas=betas, seed=2, bm=bm, hold_frames=0)
        z = m.vertices(bm, 100, 101)[0].numpy()[hand, 2].min()
        assert 0.0 <= z <= 0.008, (b0, z)


@pytest.mark.parametrize("t_goal", [9, 12, 15])
def test_a_reach_given_little_time_starts_from_rest(bm, t_goal):
    """Step 3 of plan_reach: the reach takes at most 0.8 t_G, so with a goal 0.3-0.6 s away it starts after the
    first fifth of that time and the wrist leaves the standing start at rest (under 0.15 m/s over the first frame;
    a reach begun before frame 0 would start at 1-2 m/s), and is still on the goal at t_G."""
    for goal in ((0.45, -0.1, 1.0), (0.4, -0.2, 1.3), (0.5, -0.1, 0.6)):
        m = plan_reach(Start(), goal, t_goal, seed=0, bm=bm, hold_frames=0)
        w = m.joint_positions(bm)[:, J["right_wrist"]]
        assert np.linalg.norm(w[1] - w[0]) * m.fps < 0.15, goal
        assert np.linalg.norm(w[t_goal] - np.asarray(goal)) < 1e-3


def _shoulders():
    """Synthetic right-shoulder heights: 1.4 m at level 0, 0.6 m lower per unit of b (b > 0 lowers the body)."""
    s = np.zeros((len(LEVELS), 3))
    s[:, 0] = 0.1
    s[:, 2] = 1.4 - 0.6 * LEVELS
    return s


def test_choose_posture_takes_the_smallest_level_that_reaches():
    """choose_posture (docstring): the level with the smallest |b| whose shoulder reaches target_z. A goal just below
    the standing shoulder needs no bend (b = 0, reached at REACH_RHO arm lengths); a low one needs the first level
    whose shoulder is within 0.95 arm lengths above it (here b = 0.55, not the deepest squat)."""
    arm = 0.6
    b, sh, reach = choose_posture(_shoulders(), 1.3, arm)
    assert b == 0.0 and sh[2] == 1.4
    r = REACH_RHO * arm
    assert abs(reach - np.sqrt(r**2 - 0.1**2)) < 1e-9
    b, sh, _ = choose_posture(_shoulders(), 0.52, arm)
    assert abs(b - 0.55) < 1e-9                               # 1.4 - 0.6 b - 0.52 <= 0.57  <=>  b >= 0.5167
    assert 0.52 - sh[2] >= -0.95 * arm


def test_the_final_turn_takes_the_short_way_across_pi():
    """_approach_plan walks along phi = 3.0 rad, then turns to face psi_f = -3.0 rad: the short way is +0.28 rad
    through pi, not -6 rad round (heading_profile's rule: the short way)."""
    T, fps = 150, 30.0
    phi, psi_f = 3.0, -3.0
    P = 2.0 * np.array([np.cos(phi), np.sin(phi)])
    plan = _approach_plan(T, np.zeros(2), phi, P, psi_f, 3.5, 3.8, 1.0, fps)
    h = np.unwrap(plan.heading)
    assert abs(wrap_angle(h[-1] - psi_f)) < 1e-6                         # ends facing psi_f
    assert np.abs(np.diff(h)).sum() < abs(wrap_angle(psi_f - phi)) + 0.05   # and turned no more than the short way


def _rot(a):
    """Rotation (3,3) about world z by a rad."""
    return np.array([[np.cos(a), -np.sin(a), 0.0], [np.sin(a), np.cos(a), 0.0], [0.0, 0.0, 1.0]])


@pytest.mark.parametrize("goal", [(0.0, 0.0, 1.0), (1.3, -0.4, 1.6), (0.9, 0.6, 0.3)])
def test_plan_reach_is_equivariant_under_rotations_and_translations_about_z(bm, goal):
    """Rotating and shifting the start and the goal about the vertical rotates and shifts the whole planned motion
    (the planner has no preferred world direction; the floor is the only fixed reference), even for a goal right
    above the start, where the facing must come from the start's heading."""
    a, tr = 1.1, np.array([0.7, -1.2, 0.0])
    m1 = plan_reach(Start(0.0, 0.0, 0.3), goal, 60, seed=3, bm=bm, hold_frames=5)
    m2 = plan_reach(Start(0.7, -1.2, 0.3 + a), _rot(a) @ np.asarray(goal) + tr, 60, seed=3, bm=bm, hold_frames=5)
    j1, j2 = m1.joint_positions(bm), m2.joint_positions(bm)
    np.testing.assert_allclose(j1 @ _rot(a).T + tr, j2, atol=1e-4)


def test_plan_reach_refuses_bad_frame_counts_and_goals_by_name(bm):
    """plan_reach needs at least one frame before the goal (its docstring: the clip has t_goal_frames + 1 + hold
    frames, the wrist reaching the goal at t_goal_frames): 0, a negative, fractional or boolean goal frame, a negative
    hold and a non-finite goal are refused by name, as plan_reach_chain refuses them."""
    for t in (0, -5, 60.5, True):
        with pytest.raises(ValueError, match="t_goal_frames"):
            plan_reach(Start(), (0.8, -0.3, 1.0), t, bm=bm)
    with pytest.raises(ValueError, match="hold_frames"):          # a negative hold, named (not a Motion error)
        plan_reach(Start(), (0.8, -0.3, 1.0), 40, bm=bm, hold_frames=-5)
    with pytest.raises(ValueError, match="goal: expected a finite point"):
        plan_reach(Start(), (0.8, np.nan, 1.0), 40, bm=bm)


def test_a_chain_without_holds_and_with_an_instant_release_is_valid(bm):
    """plan_reach_chain's docstring and checks: hold frames >= 0 and release_s in [0, 10); holds of 0 frames and a
    release of 0 s are valid, and the wrist is still on each goal at its goal frame (forward kinematics)."""
    goals = np.array([[0.8, -0.3, 1.0], [1.6, 0.5, 0.9]])
    m, f_rel = plan_reach_chain(Start(), goals, (60, 120), (0, 0), bm=bm, release_s=0.0)
    assert f_rel == 60 and m.num_frames == 121
    w = m.joint_positions(bm)[:, WRIST]
    assert np.linalg.norm(w[60] - goals[0]) < 0.01 and np.linalg.norm(w[120] - goals[1]) < 0.01


def test_evaluation_grid_angles_are_measured_from_the_start_heading():
    """WANDR Sec. 4.2: goals at 5 angles 72 deg apart relative to the start's facing; each row's (x, y) lies at the
    row's distance along start.heading + angle (atan2 of the offset, hand-computed)."""
    s = Start(1.0, 2.0, 0.5)
    g = evaluation_goals(s)
    off = g[:, 3:5] - [s.x, s.y]
    ang = np.arctan2(off[:, 1], off[:, 0])
    want = s.heading + np.radians(g[:, 0])
    assert np.abs(np.angle(np.exp(1j * (ang - want)))).max() < 1e-9
    np.testing.assert_allclose(np.hypot(off[:, 0], off[:, 1]), g[:, 2], atol=1e-12)


def test_circle_tasks_keep_their_documented_distance_and_hold_ranges():
    """sample_reach_task's docstring: the goal 0.3-1.2 m from the start, held 0.3-1.0 s (9-30 frames at 30 fps);
    2000 seeded draws stay inside and fill both ranges."""
    rng = np.random.default_rng(5)
    tasks = [sample_reach_task(rng) for _ in range(2000)]
    r = np.array([np.hypot(t.goal[0] - t.start.x, t.goal[1] - t.start.y) for t in tasks])
    hold = np.array([t.hold_frames for t in tasks]) / 30.0
    assert r.min() >= 0.3 - 1e-9 and r.max() <= 1.2 + 1e-9 and r.min() < 0.33 and r.max() > 1.17
    assert hold.min() >= 0.3 - 1e-9 and hold.max() <= 1.0 + 1e-9 and hold.min() < 0.31 and hold.max() > 0.99


def test_the_natural_time_is_longer_for_low_goals_and_not_for_high_ones():
    """_natural_time's docstring: a slower reach for low goals; a floor goal (z = 0) takes longer than one at 1.2 m,
    a goal overhead (1.8 m) no longer than one at 1.2 m, at every distance."""
    for r in (0.3, 0.8, 2.0):
        assert _natural_time(r, 0.0) > _natural_time(r, 1.2) + 0.2
        assert _natural_time(r, 1.8) <= _natural_time(r, 1.2) + 1e-12


def test_choose_posture_puts_goals_above_the_shoulder_at_reach_rho():
    """choose_posture's docstring: a goal level with or above the shoulder is reached at REACH_RHO arm lengths, so the
    returned horizontal reach and the height above the returned shoulder make a hypotenuse of REACH_RHO * arm; a goal
    no level can reach takes the highest shoulder (b = -1, the closest). Synthetic shoulders: 1.4 m at b = 0, 0.6 m
    higher per unit of -b."""
    s = np.zeros((len(LEVELS), 3))
    s[:, 0], s[:, 2] = 0.1, 1.4 - 0.6 * LEVELS
    arm = 0.6
    for z in (1.4, 1.75, 1.9, 2.3):
        b, sh, reach = choose_posture(s, z, arm)
        assert abs(np.hypot(reach, z - sh[2]) - REACH_RHO * arm) < 1e-9, z
        assert b <= 0.0
    b, sh, _ = choose_posture(s, 3.5, arm)                    # out of reach for every level
    assert b == -1.0 and sh[2] == s[:, 2].max()


def test_posture_levels_for_high_goals_raise_the_right_shoulder_and_lean_back(bm):
    """The posture family (module docstring): b < 0 raises the right collar and extends the spine for high goals, so
    by forward kinematics the right shoulder at b = -1 is higher than standing (b = 0) and further back (extension
    leans the thorax backwards, body facing +x), and b > 0 lowers it."""
    rig = build_rig(bm, np.zeros(10))
    sh = posture_shoulders(rig)
    k0, km, kp = int(np.argmin(np.abs(LEVELS))), 0, len(LEVELS) - 1
    assert sh[km, 2] > sh[k0, 2] + 0.01
    assert sh[km, 0] < sh[k0, 0] - 0.01
    assert sh[kp, 2] < sh[k0, 2] - 0.3


def test_an_unreachable_goal_is_stored_where_the_wrist_went_and_a_floor_goal_stays_on_the_floor(bm):
    """_goal_as_reached's docstring: a goal the wrist missed becomes the wrist's position at the goal frame; a floor goal
    the hand reached (wrist FLOOR_WRIST scaled by the body above it) stays on the floor, for a tall and a short body."""
    m = plan_reach(Start(), (0.8, -0.3, 1.0), 60, seed=0, bm=bm, hold_frames=0)
    m.goal = np.array([0.8, -0.3, 1.05])                      # 5 cm above where the wrist went
    w = m.joint_positions(bm)[60, WRIST]
    assert np.linalg.norm(_goal_as_reached(m, bm).goal - w) < 1e-5
    for b0 in (-3.0, 3.0):
        betas = np.zeros(10)
        betas[0] = b0
        goal = np.array([0.9, -0.4, 0.0])
        with pytest.warns(GraspkitWarning, match="outside the ±2"):       # bodies past the checked shapes
            m = plan_reach(Start(0, 0, 0.3), goal, 100, betas=betas, seed=2, bm=bm, hold_frames=0)
        np.testing.assert_allclose(_goal_as_reached(m, bm).goal, goal, atol=1e-9)


@pytest.mark.parametrize("z", [2.0, 1.1, 0.3])
def test_the_reach_with_its_hand_pre_shaping_takes_about_a_second_for_high_middle_and_low_goals(bm, z):
    """Module docstring, step 3-4: with time to spare the reach takes 0.9-1.6 s before the goal frame, the hand opening
    into its pre-shape as the wrist moves in; the right hand's finger pose (read from the clip's axis-angles) starts
    changing 0.8-1.6 s before t_G (the arm's blend spans the last 0.9 of the reach), holds still after it, and is
    open (the fingers less flexed than at the start) at the goal."""
    m = plan_reach(Start(), (0.5, -0.3, z), 120, seed=0, bm=bm, hold_frames=10)
    f = m.poses.reshape(len(m.poses), -1, 3)[:, 40:55].reshape(len(m.poses), -1)
    moving = np.abs(f - f[0]).max(1) > 1e-6
    dur = (120 - int(np.argmax(moving)) + 1) / m.fps
    assert 0.78 <= dur <= 1.6, dur
    assert np.abs(f[120:] - f[120]).max() < 1e-6
    bend = np.linalg.norm(f.reshape(len(f), 15, 3)[:, 3:], axis=-1).sum(1)   # flexion of the four fingers (rad)
    assert bend[120] < 0.7 * bend[0]                       # opened (less curled) at the goal than at the start


def test_evaluate_planner_scores_the_clip_plan_reach_makes_for_a_grid_row(bm):
    """evaluate_planner on one row of WANDR's grid (angle 0, height 0.9 m, distance 0.5 m): the row's height and
    distance come back as given, the goal is (x, y, height), and the scores agree with forward kinematics of the
    same plan_reach clip: the wrist error at the goal frame, DTG (the track's closest approach, so no larger than
    that error) and success (DTG within WANDR's 10 cm)."""
    from graspkit.data.reaching import evaluate_planner

    s = Start(0.5, -0.2, 0.4)
    row = evaluation_goals(s)[10]
    assert tuple(row[:3]) == (0.0, 0.9, 0.5)
    out = evaluate_planner(bm, s, t_goal_frames=60, seed=4, goals=row[None])
    assert len(out) == 1
    r = out[0]
    goal = np.array([row[3], row[4], 0.9])
    assert r["height"] == 0.9 and r["distance"] == 0.5 and np.allclose(r["goal"], goal)
    w = plan_reach(s, goal, 60, seed=4, bm=bm, hold_frames=0).joint_positions(bm)[:, WRIST]
    err = float(np.linalg.norm(w[60] - goal))
    assert abs(r["error_at_goal_frame"] - err) < 1e-6 and err < 0.01
    assert abs(r["dtg"] - np.linalg.norm(w - goal, axis=1).min()) < 1e-6 and r["dtg"] <= err + 1e-9
    assert r["success"]


def test_the_planner_refuses_non_finite_betas_by_name(bm):
    """_betas' docstring: betas must be finite; a NaN or an Inf shape coefficient is refused by name rather than
    turning the whole clip into NaN."""
    for bad in (np.nan, np.inf):
        betas = np.zeros(10)
        betas[3] = bad
        with pytest.raises(ValueError, match="betas"):
            plan_reach(Start(), (0.8, -0.3, 1.0), 30, betas=betas, bm=bm)


def test_generate_reach_uses_the_betas_it_is_given(bm):
    """generate_reach(betas=...) makes the clip for that body: the clip stores those betas, and by forward kinematics
    of that body the wrist is at the stored goal at the goal frame."""
    from graspkit.data.reaching import FLOOR_WRIST, generate_reach

    betas = np.zeros(10)
    betas[0], betas[1] = 2.0, -1.0
    for seed in (0, 1):
        m = generate_reach(seed, bm, betas=betas)
        np.testing.assert_allclose(np.asarray(m.betas, np.float64)[:10], betas, atol=1e-6)
        w = m.joint_positions(bm)[m.goal_frame, WRIST]
        assert np.linalg.norm(w - np.maximum(m.goal, [-9, -9, FLOOR_WRIST])) < 0.02
