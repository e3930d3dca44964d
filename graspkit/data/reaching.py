"""Goal reaching: the procedural planner `plan_reach` and CIRCLE-style reaching clips (WANDR Sec. 3.1-3.2, 4.2).

The planner walks to a stand-off point, turns to face the goal, slows down and reaches with the right
hand so that the wrist is on the goal exactly at frame t_G (WANDR's time control, Sec. 3.2 and Sup. C.1):

1. posture   a one-parameter family of whole-body postures, level b in [-1, 1]: b > 0 lowers the pelvis
             (knee bend, then squat), pitches the pelvis and bends the spine for low goals; b < 0 raises the
             right collar and extends the spine for high goals. For each level the right shoulder's position
             is measured once (forward kinematics of a standing body) and the smallest |b| from which the
             wrist target lies within REACH_RHO arm lengths of the shoulder is chosen.
2. stand-off the root point from which that shoulder sees the goal at a comfortable reach, on the line from
             the start to the goal, facing so that the goal is ahead and to the right.
3. schedule  backwards from t_G: the reach takes 0.9-1.7 s (longer for lower goals), at most 0.8 t_G (a reach
             given little time starts after its first fifth, from rest, not before frame 0), and starts while the
             last step lands; walking (turn towards the stand-off, straight walk, final turn) is timed to
             stop then; if there is time to spare the person waits first, if not they walk faster.
4. motion    footsteps and whole-body posing as for locomotion, plus controls blending into the posture,
             the gaze on the goal, the right wrist moved by IK along a minimum-jerk blend onto the target,
             and the hand opened into a pre-shape.

CIRCLE-style training clips (`generate_reach`) are short: a standing start near a goal (a step or two at
most), right-hand targets, goal heights concentrated where people usually reach (not uniform over
WANDR's evaluation volume).
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from graspkit.data.footsteps import GaitStyle, foot_tracks, plan_footsteps
from graspkit.data.ik import smoothstep, wrap_angle
from graspkit.data.locomotion import sample_betas, sample_gait_style, sample_style
from graspkit.data.motion import Motion
from graspkit.data.posing import Controls, Style, pose_body
from graspkit.data.rig import Rig, build_rig
from graspkit.data.trajectory import RootPlan, heading_profile, ramp, straight_walk
from graspkit.body.skeleton import JOINT_INDEX
from graspkit.checks import check_betas, seeded_rng

if TYPE_CHECKING:
    from graspkit.body import BodyModel

REACH_RHO = 0.86           # shoulder-to-wrist distance at the goal, as a fraction of the arm length
MIN_GOAL_FRAMES = 9       # plan_reach: the shortest time to the goal (0.3 s, when a shuffle arrives at the earliest)
MAX_WALK_SPEED = 1.6      # m/s: the planner's fastest walk when it has the time (and the largest v_pref taken)
FAR_MIN_SPEED = 0.25      # m/s: the slowest walk of a room-scale clip (it fills the time to its goal frame)
FAR_HEIGHTS = (0.0, 1.9)   # room-scale goal heights (m), uniform: the grid's 0-1.8 m evenly, a little above
FAR_HURRY = 0.4            # share of room-scale tasks due at a fast walk (FAR_HURRY_SPEED) rather than at leisure
FAR_HURRY_SPEED = (1.0, 1.5)   # m/s: their walking speed (WANDR's late rollouts skate when |I^w| is above 0.7 m/s)
RELEASE_S = 0.8           # s: a chained clip lowers the arm of its first reach over this time, walking off
NEAR_DISTANCE = (0.3, 1.0)    # m: a near clip's goal from the start (reach_near)
NEAR_HEIGHTS = ((0.0, 0.35), (1.45, 1.9))   # m: its goal height, at the floor or overhead (half each)
FLOOR_WRIST = 0.07         # the wrist stays this high (m) above the floor: the hand lies flat below it
LEVELS = np.linspace(-1.0, 1.0, 41)
EVAL_ANGLES_DEG = (0.0, 72.0, 144.0, 216.0, 288.0)        # WANDR Sec. 4.2: 5 angles 72 deg apart
EVAL_HEIGHTS = tuple(np.linspace(0.0, 1.8, 5))             # 0 .. 1.8 m
EVAL_DISTANCES = tuple(np.linspace(0.5, 5.0, 5))           # 0.5 .. 5 m
EVAL_FRAMES = 240                                          # 8 s at 30 fps


@dataclass(frozen=True)
class Start:
    """Where a planned motion starts: ground position (x, y) and facing (rad from world +x)."""

    x: float = 0.0
    y: float = 0.0
    heading: float = 0.0

    def __post_init__(self) -> None:
        for k in ("x", "y", "heading"):
            v = getattr(self, k)
            if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, float, np.integer, np.floating)) \
                    or not np.isfinite(v):
                raise ValueError(f"Start.{k}: expected a finite number, got {v!r}")


def posture_controls(b: np.ndarray | float, scale: float = 1.0) -> dict[str, np.ndarray]:
    """Control values (each shaped like b) of posture level b: > 0 bend and squat for low goals, < 0 stretch for high."""
    b = np.asarray(b, np.float64)
    lo, hi = np.clip(b, 0, 1), np.clip(-b, 0, 1)
    return {"pelvis_drop": scale * 0.38 * lo**1.5, "pelvis_back": scale * 0.16 * lo,
            "hip_flex": 0.97 * np.minimum(lo / 0.7, 1.0), "spine_flex": 1.45 * lo**1.3 - 0.15 * hi,
            "spine_side": 0.6 * lo, "spine_twist": -0.2 * lo - 0.1 * hi,
            "collar_raise": 0.3 * hi - 0.35 * lo**2, "arm_flex": 1.4 * lo}


def _static_plan(K: int) -> RootPlan:
    """K frames of standing still at the origin facing +x."""
    return RootPlan(np.zeros((K, 2)), np.zeros(K))


def posture_shoulders(rig: Rig, style: Style | None = None) -> np.ndarray:
    """Right-shoulder positions (len(LEVELS), 3) for each posture level, body at the origin facing +x (z up)."""
    style = style or Style()
    K = len(LEVELS)
    plan, gait = _static_plan(K), GaitStyle()
    tracks = foot_tracks([], plan, rig, gait)
    c = Controls.zeros(K)
    for k, v in posture_controls(LEVELS, rig.scale).items():
        setattr(c, k, v)
    _, _, extra = pose_body(rig, plan, tracks, style, c)
    return extra["joints"][:, JOINT_INDEX["right_shoulder"]]


def choose_posture(shoulders: np.ndarray, target_z: float, arm: float) -> tuple[float, np.ndarray, float]:
    """The posture level with the smallest |b| whose shoulder reaches target_z; returns (b, shoulder (3,), horizontal reach).

    Goals level with or above the shoulder are reached at REACH_RHO arm lengths; goals far below it with the arm
    hanging almost straight (up to 0.97 arm lengths, as people reach for the floor).
    """
    r = REACH_RHO * arm
    dz = target_z - shoulders[:, 2]
    ok = (dz >= -0.95 * arm) & (dz <= 0.93 * r)
    if ok.any():
        k = int(np.flatnonzero(ok)[np.argmin(np.abs(LEVELS[ok]))])
    else:
        k = int(np.argmin(np.abs(np.clip(dz, -0.95 * arm, 0.93 * r) - dz)))
    dzk = float(np.clip(dz[k], -0.95 * arm, 0.93 * r))
    r_eff = float(np.clip(-dzk / 0.9, r, 0.97 * arm)) if dzk < 0 else r
    return float(LEVELS[k]), shoulders[k], float(np.sqrt(r_eff**2 - dzk**2))


def _default_model():
    """The default body model (float32): the file default_model_path() names now (`shared_body`)."""
    from graspkit.body import shared_body

    return shared_body()


def _betas(betas, bm) -> np.ndarray:
    """betas (k,) as float64, checked: finite, at least bm.num_betas of them (None: zeros (10,))."""
    if betas is None:
        return np.zeros(10)
    return check_betas(betas, bm.num_betas)


def _frame(name: str, value, least: int) -> int:
    """An integer frame count >= least (numpy integers too; floats and bools refused)."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)) or value < least:
        raise ValueError(f"{name}: expected an integer >= {least}, got {value!r}")
    return int(value)


def _start(start) -> Start:
    """A Start, or one from (x, y, heading) (metres, radians), checked."""
    if isinstance(start, Start):
        return start
    try:
        values = [float(v) for v in start]
    except (TypeError, ValueError):
        values = []
    if len(values) != 3:
        raise ValueError(f"start: expected a Start or (x, y, heading) in metres and radians, got {start!r}")
    return Start(*values)


def _person(seed: int, bm, betas, style: Style | None, gait: GaitStyle | None, v_pref: float | None):
    """The body model (default if None), a generator seeded with `seed`, checked betas, their rig, and the person's
    style, gait and preferred speed (drawn in that order unless given): the planners' common start."""
    bm = bm if bm is not None else _default_model()
    rng = seeded_rng(seed)
    betas = _betas(betas, bm)
    rig = build_rig(bm, betas)
    style = style or _mild(sample_style(rng), Style())
    gait = gait or _mild(sample_gait_style(rng), GaitStyle())
    v_pref = v_pref if v_pref is not None else float(rng.uniform(1.0, 1.35))
    if isinstance(v_pref, bool) or not isinstance(v_pref, (int, float, np.floating, np.integer)) \
            or not 0 < v_pref <= MAX_WALK_SPEED:
        raise ValueError(f"v_pref: expected a walking speed in (0, {MAX_WALK_SPEED}] m/s, got {v_pref!r}")
    return bm, rng, betas, rig, style, gait, float(v_pref)


def _pose(rig: Rig, plan: RootPlan, gait: GaitStyle, style: Style, c: Controls, betas: np.ndarray, goal: np.ndarray,
          goal_frame: int) -> Motion:
    """Footsteps, foot tracks and the whole-body pose for a root plan and controls: a reaching Motion (right hand)."""
    tracks = foot_tracks(plan_footsteps(plan, rig, gait), plan, rig, gait)
    aa, root, _ = pose_body(rig, plan, tracks, style, c)
    return Motion(aa, root - rig.joints[0], betas, plan.fps, contacts=tracks.contacts, goal=goal,
                  goal_frame=goal_frame, hand="right")


def plan_reach(start: Start | tuple[float, float, float], goal: np.ndarray | Sequence[float], t_goal_frames: int,
               betas: np.ndarray | None = None, seed: int = 0, bm: BodyModel | None = None, hold_frames: int = 15,
               style: Style | None = None, gait: GaitStyle | None = None, v_pref: float | None = None) -> Motion:
    """The procedural planner: walk, turn, slow down and reach so the right wrist is on `goal` (3,) (world, z up)
    at frame t_goal_frames; the clip has t_goal_frames + 1 + hold_frames frames. start: Start or (x, y, heading).

    seed draws the small person-to-person variations (style, gait, preferred speed) unless given. A goal out of the
    body's reach is kept as given and the arm stops at full stretch (`generate_reach` relabels such a goal to where
    the wrist is).
    """
    t_goal_frames = _frame("t_goal_frames", t_goal_frames, MIN_GOAL_FRAMES)
    hold_frames = _frame("hold_frames", hold_frames, 0)
    start = _start(start)
    goal = np.asarray(goal, np.float64)
    if goal.shape != (3,) or not np.isfinite(goal).all():
        raise ValueError(f"goal: expected a finite point (3,) in metres, got {goal.tolist()}")
    bm, rng, betas, rig, style, gait, v_pref = _person(seed, bm, betas, style, gait, v_pref)
    fps, T = 30.0, t_goal_frames + 1 + hold_frames
    plan, c = _reach_leg(rig, style, start, goal, t_goal_frames, T, rng, v_pref, fps)
    return _pose(rig, plan, gait, style, c, betas, goal, t_goal_frames)


def _stand_off(rig: Rig, style: Style, start: Start, goal: np.ndarray) -> tuple[np.ndarray, float, np.ndarray,
                                                                               np.ndarray, float]:
    """Steps 1-2 of `plan_reach`: the wrist target (3,), posture level b, right shoulder (3,) at that level (body
    frame), the root's stand-off point P (2,) and its heading psi_f (rad) there."""
    target = goal.copy()
    target[2] = max(target[2], FLOOR_WRIST * rig.scale)
    b, shoulder, d_h = choose_posture(posture_shoulders(rig, style), float(target[2]), rig.arm_length)
    beta = 0.3 + 0.2 * max(b, 0.0)                 # the goal a little to the right of straight ahead
    q = shoulder[:2] + d_h * np.array([np.cos(beta), -np.sin(beta)])   # goal seen from the root (body frame)
    xy0 = np.array([start.x, start.y])
    to_goal = target[:2] - xy0
    theta = float(np.arctan2(to_goal[1], to_goal[0])) if np.linalg.norm(to_goal) > 1e-6 else start.heading
    psi_f = theta - float(np.arctan2(q[1], q[0]))
    return target, b, shoulder, target[:2] - _rot2(psi_f) @ q, psi_f


def _reach_leg(rig: Rig, style: Style, start: Start, goal: np.ndarray, t_goal_frames: int, T: int,
               rng: np.random.Generator, v_pref: float, fps: float = 30.0) -> tuple[RootPlan, Controls]:
    """One walk-and-reach of `plan_reach` over T frames: the root plan and the controls."""
    t_G = t_goal_frames / fps

    # 1-2: posture and stand-off
    target, b, shoulder, P, psi_f = _stand_off(rig, style, start, goal)
    xy0 = np.array([start.x, start.y])

    # 3: schedule, backwards from t_G
    D = float(np.linalg.norm(P - xy0))
    walk_min = 0.9 if D < 0.4 else D / 1.5 + 0.9          # the quickest approach (a shuffle, or a brisk walk)
    T_r = float(np.clip(0.9 + 0.7 * abs(b) + 0.1 * rng.random(), min(0.6, 0.8 * t_G), max(t_G - 0.3 - 0.7 * walk_min, 0.6)))
    T_r = min(T_r, 0.8 * t_G)
    t_rs = t_G - T_r
    t_stop = t_rs + 0.3 * T_r
    plan = _approach_plan(T, xy0, start.heading, P, psi_f, t_rs, t_stop, v_pref, fps)

    # 4: controls
    t = np.arange(T) / fps
    s = smoothstep((t - t_rs) / T_r)
    s_arm = smoothstep((t - t_rs - 0.1 * T_r) / (0.9 * T_r))
    c = Controls.zeros(T)
    for k, v in posture_controls(b, rig.scale).items():
        setattr(c, k, float(v) * s)
    right = np.array([np.sin(psi_f), -np.cos(psi_f), 0.0])
    fwd = np.array([np.cos(psi_f), np.sin(psi_f), 0.0])
    up = np.array([0.0, 0.0, 1.0])
    lo, hi = max(b, 0.0), max(-b, 0.0)
    pole = 0.7 * right - (0.8 - 0.5 * hi) * up - 0.5 * lo * fwd
    c.reach_target = np.broadcast_to(target, (T, 3)).copy()
    c.reach_weight = s_arm
    c.reach_pole = np.broadcast_to(pole / np.linalg.norm(pole), (T, 3)).copy()
    c.hand_open = s_arm
    c.support_weight = smoothstep((lo - 0.35) / 0.25) * (1 - smoothstep((lo - 0.7) / 0.2)) * s   # hand on knee in a crouch
    # fingers continue the shoulder->goal line (levelled out for low goals), palm down for low goals, inwards else
    sh = _rot3(psi_f) @ shoulder + np.array([P[0], P[1], 0.0])      # the shoulder in the world at the goal
    along = target - sh
    along = along / np.linalg.norm(along)
    fingers = (1 - lo) * along + lo * (0.8 * fwd + 0.2 * right - 0.1 * up)
    palm = (1 - lo) * (-(0.7 * right) - 0.5 * up + 0.4 * hi * fwd) + lo * (-up)
    c.finger_dir = np.broadcast_to(fingers / np.linalg.norm(fingers), (T, 3)).copy()
    c.palm_dir = np.broadcast_to(palm / np.linalg.norm(palm), (T, 3)).copy()
    c.gaze = np.broadcast_to(goal, (T, 3)).copy()
    c.gaze_weight = smoothstep(t / max(min(1.0, t_rs), 0.3)) * 0.85 + 0.15 * s
    return plan, c


def _blend_unit(a: np.ndarray, wa: np.ndarray, b: np.ndarray, wb: np.ndarray) -> np.ndarray:
    """Per-frame unit directions (T,3) between a and b (T,3), weighted by wa and wb (T,) (a where both are zero)."""
    v = wa[:, None] * a + wb[:, None] * b
    v = np.where((wa + wb)[:, None] > 1e-9, v, a)
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-9)


def plan_reach_chain(start: Start | tuple[float, float, float], goals: np.ndarray, goal_frames: tuple[int, int],
                     hold_frames: tuple[int, int], betas: np.ndarray | None = None, seed: int = 0,
                     bm: BodyModel | None = None, style: Style | None = None,
                     gait: GaitStyle | None = None, v_pref: float | None = None, release_s: float = RELEASE_S
                     ) -> tuple[Motion, int]:
    """Two reaches in a row: `plan_reach` to goals[0] (2,3) at goal_frames[0], held hold_frames[0] frames, then the arm
    released over release_s seconds while the second walk starts, and a reach of goals[1] at goal_frames[1] (frames
    from the clip's start), held hold_frames[1]. Returns the motion and the first frame of the second leg.

    The second leg starts from where the first one stands, so the body sets off from a finished reach (WANDR's goals in
    a row, Sup. C.2, ask for exactly that state; CIRCLE's subjects reach targets one after another).
    """
    start = _start(start)
    if len(goal_frames) != 2 or len(hold_frames) != 2:
        raise ValueError(f"goal_frames, hold_frames: expected two each, got {goal_frames!r}, {hold_frames!r}")
    g1, g2 = _frame("goal_frames[0]", goal_frames[0], MIN_GOAL_FRAMES), _frame("goal_frames[1]", goal_frames[1], 1)
    h1, h2 = _frame("hold_frames[0]", hold_frames[0], 0), _frame("hold_frames[1]", hold_frames[1], 0)
    if not 0.0 <= release_s < 10.0:
        raise ValueError(f"release_s: expected seconds in [0, 10), got {release_s}")
    fps, r = 30.0, int(round(release_s * 30.0))
    if g2 < g1 + h1 + r + MIN_GOAL_FRAMES:
        raise ValueError(f"goal_frames: the second goal frame must come at least {MIN_GOAL_FRAMES} frames after the "
                         f"first one's hold and the arm's release ({g1} + {h1} + {r} frames), got {g2}")
    goals = np.asarray(goals, np.float64)
    if goals.shape != (2, 3) or not np.isfinite(goals).all():
        raise ValueError(f"goals: expected two finite goals (2, 3) in metres, got shape {goals.shape}"
                         + ("" if goals.shape != (2, 3) else " with NaN or Inf"))
    bm, rng, betas, rig, style, gait, v_pref = _person(seed, bm, betas, style, gait, v_pref)
    T, f_rel = g2 + 1 + h2, g1 + h1
    plan1, c1 = _reach_leg(rig, style, start, goals[0], g1, T, rng, v_pref, fps)
    mid = Start(float(plan1.xy[f_rel, 0]), float(plan1.xy[f_rel, 1]), float(plan1.heading[f_rel]))
    plan2, c2 = _reach_leg(rig, style, mid, goals[1], g2 - f_rel, T - f_rel, rng, v_pref, fps)
    plan = RootPlan(np.concatenate([plan1.xy[:f_rel], plan2.xy]),
                    np.concatenate([plan1.heading[:f_rel], plan2.heading]), fps)
    keep = 1.0 - ramp(T, f_rel / fps, f_rel / fps + release_s, fps)      # leg 1's controls, released after its hold
    late = lambda x: np.concatenate([np.zeros((f_rel,) + x.shape[1:]), x])   # noqa: E731 - leg 2 on the clip's clock
    c = Controls.zeros(T)
    for k in ("pelvis_drop", "pelvis_back", "hip_flex", "spine_flex", "spine_twist", "spine_side", "collar_raise",
              "hand_open", "support_weight", "arm_flex"):
        setattr(c, k, keep * getattr(c1, k) + late(getattr(c2, k)))
    w1, w2 = keep * c1.reach_weight, late(c2.reach_weight)
    c.reach_weight = np.minimum(w1 + w2, 1.0)
    wsum = np.maximum(w1 + w2, 1e-9)[:, None]
    c.reach_target = np.where((w1 + w2)[:, None] > 1e-9, (w1[:, None] * c1.reach_target
                                                          + w2[:, None] * late(c2.reach_target)) / wsum, c1.reach_target)
    for k in ("reach_pole", "finger_dir", "palm_dir"):
        setattr(c, k, _blend_unit(getattr(c1, k), w1, late(getattr(c2, k)), w2))
    # the gaze lets go of the first goal with the arm, then takes up the second (a moving point would whip the head)
    c.gaze = np.where((np.arange(T) < f_rel + r)[:, None], goals[0], goals[1])
    w2 = np.concatenate([np.zeros(r), c2.gaze_weight])[:T - f_rel]
    c.gaze_weight = np.concatenate([c1.gaze_weight[:f_rel], keep[f_rel:] * c1.gaze_weight[f_rel] + w2])
    return _pose(rig, plan, gait, style, c, betas, goals[1], g2), f_rel


def _mild(sampled, default):
    """Halfway between a sampled style and the default one (the planner varies less than the training data)."""
    from dataclasses import fields, replace

    return replace(default, **{f.name: 0.5 * (getattr(sampled, f.name) + getattr(default, f.name)) for f in fields(default)})


def _rot3(a: float) -> np.ndarray:
    """Rotation (3,3) about the world z axis."""
    return np.array([[np.cos(a), -np.sin(a), 0.0], [np.sin(a), np.cos(a), 0.0], [0.0, 0.0, 1.0]])


def _rot2(a: float) -> np.ndarray:
    """2D rotation matrix (2,2)."""
    return np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])


def _approach_plan(T: int, xy0: np.ndarray, h0: float, P: np.ndarray, psi_f: float, t_rs: float, t_stop: float,
                   v_pref: float, fps: float) -> RootPlan:
    """Root plan from (xy0, h0) to (P, psi_f), arriving at t_stop: turn, straight walk, final turn (or a shuffle if P is near)."""
    d = P - xy0
    D = float(np.linalg.norm(d))
    if D < 0.4:   # a step or two: shift and turn together
        t1 = max(t_stop, 0.3)
        t0 = max(0.15, min(t1 - 1.0, t_rs - 0.8))
        a = ramp(T, t0, t1, fps)[:, None]
        return RootPlan(xy0 + a * d, heading_profile(T, h0, psi_f, t0 - 0.1, t1, fps), fps)
    phi = float(np.arctan2(d[1], d[0]))
    turn1 = abs(wrap_angle(phi - h0))
    T_turn = 0.35 + turn1 / 2.2 if turn1 > 0.3 else 0.0
    overlap = 0.55 if turn1 < 1.2 else 0.85
    accel = 0.9
    walk_pref = D / v_pref + accel
    avail = t_stop - 0.2 - overlap * T_turn
    walk = (min(max(walk_pref, D / MAX_WALK_SPEED + accel), avail) if avail > D / MAX_WALK_SPEED + accel
            else max(avail, 0.6))     # too little time: squeezed in, faster than MAX_WALK_SPEED (docs/data.md)
    t_ws = t_stop - walk
    t_turn0 = max(0.1, t_ws - overlap * T_turn)
    xy, _ = straight_walk(T, xy0, phi, D, t_ws, t_stop, accel, fps)
    h = heading_profile(T, h0, phi, t_turn0, t_turn0 + T_turn, fps) if T_turn > 0 else np.full(T, h0)
    h = h + wrap_angle(psi_f - phi) * ramp(T, t_stop - 0.7, t_stop + 0.3, fps)
    return RootPlan(xy, h, fps)


@dataclass(frozen=True)
class ReachTask:
    """A CIRCLE-style task: start, goal (3,), the goal frame, frames held after it, and the person's betas (10,)."""

    start: Start
    goal: np.ndarray
    goal_frame: int
    hold_frames: int
    betas: np.ndarray


def sample_reach_task(rng: np.random.Generator, far: bool = False) -> ReachTask:
    """Draw a CIRCLE-style task: a right-hand goal 0.3-1.2 m from a standing start, mostly ahead, heights mostly
    0.7-1.5 m (25 % at 0.25-0.7, 10 % at 1.5-1.8, 5 % below 0.25), reached when a person would (a step closer if
    needed, a slower reach for low goals, a short pause first: about 1.1-3.2 s) and held 0.3-1.0 s.

    far=True draws a room-scale task (CIRCLE's subjects walk about a room to their targets): the goal 0.3-5 m away
    in any direction (a turn first when it is behind), heights uniform over FAR_HEIGHTS (0-1.9 m: WANDR's Fig. 5 finds
    reaching weakest where data are scarce, at the floor and overhead), and the goal frame drawn uniformly between
    the natural time (turn, walk at ~0.8 m/s, reach, a short pause first: 0.2-0.8 s; at most 9 s) and 9 s; the
    clip (generate_reach) walks slower, down to FAR_MIN_SPEED (0.25 m/s), to arrive then. A share FAR_HURRY of them
    is due sooner instead: turn, walk at FAR_HURRY_SPEED (1.0-1.5 m/s), reach, 0.2 s of slack."""
    betas = sample_betas(rng)
    h0 = rng.uniform(-np.pi, np.pi)
    if far:
        return _far_task(rng, betas, h0, float(rng.uniform(*FAR_HEIGHTS)))
    u = rng.random()
    z = (rng.uniform(0.7, 1.5) if u < 0.6 else rng.uniform(0.25, 0.7) if u < 0.85
         else rng.uniform(1.5, 1.8) if u < 0.95 else rng.uniform(0.0, 0.25))
    r = rng.uniform(0.3, 1.2)
    ang = h0 + np.clip(rng.normal(-0.2, 0.6), -1.8, 1.6)
    xy0 = rng.uniform(-0.5, 0.5, 2)
    goal = np.array([xy0[0] + r * np.cos(ang), xy0[1] + r * np.sin(ang), z])
    t_goal = int(round((_natural_time(r, z) + rng.uniform(0.2, 0.8)) * 30))      # plus a pause first
    return ReachTask(Start(float(xy0[0]), float(xy0[1]), float(h0)), goal, t_goal, int(rng.integers(9, 31)), betas)


def _natural_time(r: float, z: float) -> float:
    """Seconds to step or walk to within reach of a goal r m away (~0.8 m/s) and to reach it at height z m (slower for
    low goals); no pause, no turn."""
    walk = max(r - 0.55, 0.0) / 0.8 + (0.6 if r > 0.55 else 0.0)
    reach = 0.9 + 0.5 * max(0.9 - z, 0.0)
    return walk + reach


def _far_task(rng: np.random.Generator, betas: np.ndarray, h0: float, z: float,
              distance: tuple[float, float] = (0.3, 5.0)) -> ReachTask:
    """The room-scale task of sample_reach_task(far=True), given the person, start heading, goal height and the range
    of the goal's distance from the start (m)."""
    r = rng.uniform(*distance)
    rel = rng.uniform(-np.pi, np.pi)                     # goal direction relative to the start heading
    xy0 = rng.uniform(-0.5, 0.5, 2)
    goal = np.array([xy0[0] + r * np.cos(h0 + rel), xy0[1] + r * np.sin(h0 + rel), z])
    turn = abs(rel) / 2.2 + 0.35 if abs(rel) > 0.3 else 0.0
    t_nat = min(turn + _natural_time(r, z) + rng.uniform(0.2, 0.8), 9.0)
    t_goal = rng.uniform(t_nat, 9.0)            # the slack goes into a slower walk (generate_reach), not a longer pause
    hurry, v = rng.random(), rng.uniform(*FAR_HURRY_SPEED)
    if hurry < FAR_HURRY:                       # a hurried walk: the data's high wrist intentions, with real steps
        walk = max(r - 0.55, 0.0) / v + (0.6 if r > 0.55 else 0.0)
        t_goal = min(t_nat, turn + walk + 0.9 + 0.5 * max(0.9 - z, 0.0) + 0.2)
    return ReachTask(Start(float(xy0[0]), float(xy0[1]), float(h0)), goal, int(round(t_goal * 30)),
                     int(rng.integers(9, 31)), betas)


def sample_near_task(rng: np.random.Generator) -> ReachTask:
    """Draw a room-scale task whose goal is near (NEAR_DISTANCE, 0.3-1 m, in any direction) and at the floor or
    overhead (NEAR_HEIGHTS): the grid's weakest cells (docs/wandr.md), scarce among the room-scale tasks (1.5 % of
    them put a goal above 1.6 m within 0.8 m). Timed as those: due between the natural time and 9 s (a wait, then the
    reach) or, for a share FAR_HURRY, at once."""
    betas = sample_betas(rng)
    h0 = rng.uniform(-np.pi, np.pi)
    band = NEAR_HEIGHTS[int(rng.integers(len(NEAR_HEIGHTS)))]
    return _far_task(rng, betas, h0, float(rng.uniform(*band)), distance=NEAR_DISTANCE)


def generate_reach(seed: int, bm: BodyModel, betas: np.ndarray | None = None, far: bool = False,
                   near: bool = False) -> Motion:
    """One CIRCLE-style clip (a step or two at most, then a right-hand reach; far=True: a room-scale task, see
    `sample_reach_task`; near=True: a near goal at the floor or overhead, `sample_near_task`) for the task drawn."""
    if far and near:
        raise ValueError("far, near: expected at most one of them True")
    rng = seeded_rng(seed)
    task = sample_near_task(rng) if near else sample_reach_task(rng, far=far)
    room_scale = far or near                           # a near task is a room-scale task: walked as slowly
    style, gait = sample_style(rng), sample_gait_style(rng)
    plan_seed, v_pref = int(rng.integers(2**31)), float(rng.uniform(0.7, 1.1))  # this order: the default clips as before
    # room-scale: walk as slowly as FAR_MIN_SPEED to arrive at the goal frame (plan_reach walks at v_pref when it can and
    # stands first with the time left over; a long stand at full intention teaches a per-frame model to stand)
    m = plan_reach(task.start, task.goal, task.goal_frame, betas=task.betas if betas is None else betas,
                   seed=plan_seed, bm=bm, hold_frames=task.hold_frames, style=style, gait=gait,
                   v_pref=FAR_MIN_SPEED if room_scale else v_pref)
    return _goal_as_reached(m, bm)


def _goal_as_reached(m: Motion, bm) -> Motion:
    """A goal this body cannot reach (too high for a short person, too low for a stiff one) becomes the point the
    wrist did reach: the stored goal is where the hand is at the goal frame (a floor goal stays on the floor, the
    wrist FLOOR_WRIST, scaled, above it). Changes m in place and returns it."""
    wrist = m.joint_positions(bm)[m.goal_frame, JOINT_INDEX["right_wrist"]]
    target = np.array([m.goal[0], m.goal[1], max(m.goal[2], FLOOR_WRIST * build_rig(bm, m.betas).scale)])
    if np.linalg.norm(wrist - target) > 0.01:
        m.goal = wrist.astype(np.float32)
    return m


def generate_reach_chain(seed: int, bm: BodyModel, betas: np.ndarray | None = None) -> Motion:
    """One room-scale clip that starts from a finished reach: two `sample_reach_task(far=True)` tasks in a row
    (`plan_reach_chain`, the second drawn relative to where the first one stands), cut to start at the first goal's
    frame or during its hold; the clip's goal is the second one. WANDR's goals in a row (Sup. C.2) set off from
    exactly this state, which the one-goal clips never show."""
    rng = seeded_rng(seed)
    first = sample_reach_task(rng, far=True)
    nxt = _far_task(rng, first.betas, 0.0, float(rng.uniform(*FAR_HEIGHTS)))   # body frame: root at the origin, +x
    style, gait = sample_style(rng), sample_gait_style(rng)
    plan_seed, cut = int(rng.integers(2**31)), int(rng.integers(0, first.hold_frames + 1))
    betas = first.betas if betas is None else _betas(betas, bm)
    _, _, _, P, psi = _stand_off(build_rig(bm, betas), style, first.start, first.goal)
    rel = nxt.goal - np.array([nxt.start.x, nxt.start.y, 0.0])
    goal2 = np.array([*(P + _rot2(psi) @ rel[:2]), rel[2]])
    g1 = first.goal_frame
    g2 = g1 + first.hold_frames + int(round(RELEASE_S * 30)) + nxt.goal_frame
    m, _ = plan_reach_chain(first.start, np.stack([first.goal, goal2]), (g1, g2), (first.hold_frames, nxt.hold_frames),
                            betas=betas, seed=plan_seed, bm=bm, style=style, gait=gait, v_pref=FAR_MIN_SPEED)
    f0 = g1 + cut
    m = Motion(m.poses[f0:], m.trans[f0:], m.betas, m.fps, contacts=m.contacts[f0:], goal=m.goal,
               goal_frame=g2 - f0, hand="right")
    return _goal_as_reached(m, bm)


def evaluation_goals(start: Start = Start()) -> np.ndarray:
    """WANDR's evaluation grid (Sec. 4.2): (125, 5) rows (angle deg, height m, distance m, goal x, goal y) around `start`."""
    rows = []
    for a in EVAL_ANGLES_DEG:
        for hgt in EVAL_HEIGHTS:
            for d in EVAL_DISTANCES:
                th = start.heading + np.deg2rad(a)
                rows.append((a, hgt, d, start.x + d * np.cos(th), start.y + d * np.sin(th)))
    return np.array(rows)


def evaluate_planner(bm: BodyModel, start: Start = Start(), t_goal_frames: int = EVAL_FRAMES - 1,
                     betas: np.ndarray | None = None, seed: int = 0,
                     goals: np.ndarray | None = None, hold_frames: int = 0) -> list[dict]:
    """Run plan_reach on WANDR's grid (or `goals` rows as evaluation_goals gives) and score each motion on its mesh:
    success (wrist within 10 cm, WANDR Sec. 4.3), DTG (m), wrist error at the goal frame, FS (WANDR), GOAL sliding."""
    from graspkit import metrics as M

    rows = []
    for k, (a, h, d, x, y) in enumerate(evaluation_goals(start) if goals is None else goals):
        goal = np.array([x, y, h])
        m = plan_reach(start, goal, t_goal_frames, betas=betas, seed=seed + k, bm=bm, hold_frames=hold_frames)
        w = m.joint_positions(bm)[:, JOINT_INDEX["right_wrist"]]
        q = M.motion_quality(bm, [m])
        rows.append({"angle": float(a), "height": float(h), "distance": float(d), "goal": goal,
                     "dtg": M.distance_to_goal(w, goal), "success": M.goal_reached(w, goal),
                     "error_at_goal_frame": float(np.linalg.norm(w[t_goal_frames] - goal)),
                     "fs_wandr": q["fs_wandr"], "slide_goal": q["slide_goal"], "penetration": q["penetration_max"],
                     "joint_limit": q["joint_limit_max"]})
    return rows
