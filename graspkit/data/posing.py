"""Whole-body poses from a root plan, foot tracks and a few per-frame controls (all frames at once).

    pelvis   follows the root plan with lateral sway towards the stance foot, pelvic rotation (yaw)
             with the stepping leg, obliquity (the swing side drops), a forward lean growing with speed;
             its height is the standing height minus knee bend, lowered wherever a leg could not reach
             its foot (the vertical bob of walking comes out of this: lowest in double support)
    legs     analytic two-bone IK (hip, knee) onto the planned ankle, knee pole over the toes; the ankle
             and toe joints take the foot's planned rotations exactly
    spine    counter-rotates the thorax against the pelvis, keeps the trunk upright against obliquity,
             and carries the reach posture's bend and twist
    head     looks along the path or at a target
    arms     swing in counter-phase with the legs (elbows flex on the forward swing); the right arm
             blends into two-bone IK onto a wrist target when reaching
    hands    relaxed curl, opened into a pre-shape when reaching

Canonical frame of each joint: y up, z forward, x left (SMPL-X). Rotations in graspkit/body/poses.py's
conventions: hip flexion about -x, knee flexion +x, spine forward bend +x, left arm down about -z.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.ndimage import gaussian_filter1d

from graspkit.body.skeleton import JOINT_INDEX, NUM_JOINTS, PARENTS
from graspkit.data.footsteps import FootTracks
from graspkit.data.ik import axis_angle_matrix, frame, matrix_axis_angle, normalize, rot_x, rot_y, rot_z, two_bone_ik
from graspkit.data.rig import R_BASE, SIDES, Rig
from graspkit.data.trajectory import RootPlan

J = JOINT_INDEX
FINGERS = ("index", "middle", "pinky", "ring", "thumb")


@dataclass
class Style:
    """Per-person upper-body and pelvis style (sampled per clip); angles in radians."""

    arm_lower: float = 1.42        # shoulders lowered from the T-pose
    arm_abduct: float = 0.0        # extra abduction (arms further from the body)
    arm_swing: float = 0.3         # shoulder swing amplitude at a 0.7 m step (scales with step length)
    elbow_bend: float = 0.3        # elbow flexion at rest
    sway: float = 0.38             # fraction of the half stance width the pelvis shifts towards the stance foot
    pelvic_rotation: float = 0.14  # pelvis yaw (rad) per metre of foot separation along the path
    obliquity: float = 0.05        # pelvis roll (rad) in single support
    lean: float = 0.05             # forward lean (rad) per m/s of speed
    knee_bend: float = 0.015       # pelvis lowered this much (m) while walking
    head_pitch: float = 0.12       # looking slightly down while walking
    finger_curl: float = 1.0       # scale of the relaxed finger curl


@dataclass
class Controls:
    """Per-frame extra controls on top of walking (T,...); zeros / None mean plain locomotion."""

    pelvis_drop: np.ndarray          # (T,) extra lowering of the pelvis (m)
    pelvis_back: np.ndarray          # (T,) pelvis moved backwards along the facing direction (m)
    hip_flex: np.ndarray             # (T,) forward pitch of the pelvis (rad)
    spine_flex: np.ndarray           # (T,) forward bend of the spine, total over 3 joints (rad)
    spine_twist: np.ndarray          # (T,) thorax yaw (left +), total (rad)
    spine_side: np.ndarray           # (T,) lateral bend (towards the left +), total (rad)
    collar_raise: np.ndarray         # (T,) right collar elevation (rad; < 0 depresses and protracts the shoulder)
    gaze: np.ndarray | None = None   # (T,3) world point to look at; None: along the path
    gaze_weight: np.ndarray | None = None  # (T,) 0 path, 1 gaze point
    reach_target: np.ndarray | None = None  # (T,3) right wrist target
    reach_weight: np.ndarray | None = None  # (T,) 0 natural wrist and elbow (IK sets the arm's twist), 1 wrist on target
    reach_pole: np.ndarray | None = None    # (T,3) direction the right elbow points when reaching
    hand_open: np.ndarray | None = None     # (T,) 0 relaxed, 1 pre-shaped (right hand)
    finger_dir: np.ndarray | None = None    # (T,3) wanted world direction of the right fingers when reaching
    palm_dir: np.ndarray | None = None      # (T,3) wanted world direction the right palm faces when reaching
    support_weight: np.ndarray | None = None  # (T,) left hand onto the left knee (with a reach; at 0 the soft reach
    #                                             limit can still pull a near-straight arm in a little)
    weight_shift: np.ndarray | None = None  # (T,) added to the weight on the left foot while both feet stand
    look_yaw: np.ndarray | None = None      # (T,) head turned left (+) from the path direction (rad)
    arm_flex: np.ndarray | None = None      # (T,) shoulders flexed forward, elbows bent (arms stay off the floor when the trunk bends)

    @staticmethod
    def zeros(T: int) -> "Controls":
        z = lambda: np.zeros(T)  # noqa: E731
        return Controls(z(), z(), z(), z(), z(), z(), z())


def forward_kinematics(rig: Rig, local: np.ndarray, root: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Global rotations (T,55,3,3) and joint positions (T,55,3) from local rotations (T,55,3,3) and pelvis positions (T,3)."""
    T = local.shape[0]
    Rg, pos = np.zeros_like(local), np.zeros((T, NUM_JOINTS, 3))
    Rg[:, 0], pos[:, 0] = local[:, 0], root
    for j in range(1, NUM_JOINTS):
        p = PARENTS[j]
        Rg[:, j] = Rg[:, p] @ local[:, j]
        pos[:, j] = pos[:, p] + Rg[:, p] @ (rig.joints[j] - rig.joints[p])
    return Rg, pos


def hand_pose(side: str, curl: np.ndarray, spread: np.ndarray | float = 0.0) -> np.ndarray:
    """Finger rotations (T,15,3,3) of one hand: curl (T,) scales a relaxed flexion, spread (T,) abducts the thumb."""
    curl = np.asarray(curl, np.float64)
    sgn = 1.0 if side == "right" else -1.0      # flexion towards the palm: left about -z, right about +z
    out = np.zeros(curl.shape + (15, 3, 3))
    base = {"index": 0.18, "middle": 0.24, "ring": 0.30, "pinky": 0.36}
    for f, name in enumerate(FINGERS):
        for k in range(3):
            if name == "thumb":
                R = rot_x(curl * (0.15 + 0.12 * k)) @ rot_y(sgn * (0.35 * np.asarray(spread) - 0.15) * (k == 0))
            else:
                R = rot_z(sgn * curl * base[name] * (1.0, 1.5, 1.1)[k])
            out[..., 3 * f + k, :, :] = R
    return out


HEAD_YAW_LIMIT = 1.2    # rad: the most the neck and head together turn towards a gaze target (about 69 deg)
GAZE_LEVEL = 0.5        # cos of the gaze's elevation below which the head turn fades (a target > 60 deg up or down)
GAZE_NEAR = 0.25        # m: a gaze target nearer the head than this pulls the look less, in proportion
SUPPORT_SOFT = 0.15     # the support arm's soft reach limit (`two_bone_ik`), a share of the arm's length


def gaze_yaw(g: np.ndarray, limit: float = HEAD_YAW_LIMIT) -> np.ndarray:
    """The head-turn yaw (T,) towards gaze directions g (T,3) in the thorax frame (x left, y up, z forward): the
    target's yaw up to +-limit, back to 0 as it goes round behind (linearly in the angle), and faded to 0 as it
    goes straight up or down, where its yaw is ill-defined. A plain clip of arctan2 jumped from +limit to -limit in
    one frame when a target crossed behind the chest (it wraps at pi), and swung 35 deg in one frame when one passed
    under the head: head snaps of 82 deg in 6 % of the reaching clips (an independent check, 2026-12-03). This is
    continuous in g."""
    yaw, level = np.arctan2(g[:, 0], g[:, 2]), np.hypot(g[:, 0], g[:, 2]) / np.linalg.norm(g, axis=1)
    a = np.abs(yaw)
    turn = np.where(a <= limit, a, limit * (np.pi - a) / (np.pi - limit))
    return np.sign(yaw) * turn * np.minimum(level / GAZE_LEVEL, 1.0)


def head_turn(R_thorax: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Yaw and pitch (T,), (T,) of the neck and head together that look along world directions d (T,3), given the
    thorax's world rotations (T,3,3): `gaze_yaw`, and the elevation clipped to [-0.6, 0.9] rad (down positive)."""
    g = np.einsum("tji,tj->ti", R_thorax, d)                       # the direction in the thorax frame
    return gaze_yaw(g), np.clip(np.arctan2(-g[:, 1], np.hypot(g[:, 0], g[:, 2])), -0.6, 0.9)


def _heading_vectors(h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Forward and left unit vectors (T,3) for headings (T,)."""
    z = np.zeros_like(h)
    return np.stack([np.cos(h), np.sin(h), z], -1), np.stack([-np.sin(h), np.cos(h), z], -1)


def _lower_envelope(h_nom: np.ndarray, h_max: np.ndarray, fps: float, sigma_s: float = 0.1) -> np.ndarray:
    """A smooth height <= h_max that equals h_nom where there is room: the deficit is blurred and added
    back until (almost) nothing is left, then clamped (a dip shaped like a bell, not a notch)."""
    drop = np.zeros_like(h_nom)
    for _ in range(6):
        rem = np.maximum(h_nom - drop - h_max, 0.0)
        if rem.max() < 1e-4:
            break
        drop += gaussian_filter1d(1.6 * rem, sigma_s * fps, mode="nearest")
    return np.minimum(h_nom - drop, h_max)


def pose_body(rig: Rig, plan: RootPlan, tracks: FootTracks, style: Style, controls: Controls | None = None
              ) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
    """Local rotations as axis-angle (T,55,3), pelvis positions (T,3) and extras (joint positions (T,55,3), ...)."""
    T, fps = plan.num_frames, plan.fps
    c = controls or Controls.zeros(T)
    heading = np.unwrap(plan.heading)
    fwd, left = _heading_vectors(heading)
    speed = gaussian_filter1d(plan.speed(), 0.2 * fps, mode="nearest")
    walking = np.clip(speed / 0.4, 0, 1)
    # signed separation of the feet along the path: > 0 when the left foot is ahead
    sep = gaussian_filter1d(((tracks.xy[0] - tracks.xy[1]) * fwd[:, :2]).sum(-1), 0.05 * fps, mode="nearest")
    w = tracks.weight_left.copy()
    if c.weight_shift is not None:
        both = tracks.contacts[:, :2].any(1) & tracks.contacts[:, 2:].any(1)
        w = np.clip(w + c.weight_shift * gaussian_filter1d(both.astype(float), 0.15 * fps, mode="nearest"), 0, 1)
    w = gaussian_filter1d(w, 0.08 * fps, mode="nearest")

    R_pelvis, root, roll, tilt = _pelvis(rig, plan, tracks, style, c, heading, speed, walking, sep, w)
    local = np.broadcast_to(np.eye(3), (T, NUM_JOINTS, 3, 3)).copy()
    local[:, 0] = R_pelvis
    _spine(local, style, c, sep, roll, tilt)
    _legs(rig, local, root, R_pelvis, tracks, fwd, left)
    _arms(local, style, c, walking, sep, rig.scale)
    _head(rig, local, root, heading, style, c)
    # ---- hands
    open_ = c.hand_open if c.hand_open is not None else np.zeros(T)
    local[:, 25:40] = hand_pose("left", np.full(T, style.finger_curl))
    local[:, 40:55] = hand_pose("right", style.finger_curl * (1 - 0.75 * open_), spread=open_)

    Rg, pos = forward_kinematics(rig, local, root)
    # ---- right arm: blend into IK onto the reach target
    if c.reach_target is not None and c.reach_weight is not None and np.any(c.reach_weight > 0):
        _reach_arm(rig, local, Rg, pos, c)
        if c.support_weight is not None and np.any(c.support_weight > 0):
            _support_arm(rig, local, Rg, pos, c.support_weight)
        Rg, pos = forward_kinematics(rig, local, root)
    aa = matrix_axis_angle(local)
    return aa, root, {"joints": pos, "global_rot": Rg}


def _pelvis(rig: Rig, plan: RootPlan, tracks: FootTracks, style: Style, c: Controls, heading: np.ndarray,
            speed: np.ndarray, walking: np.ndarray, sep: np.ndarray, w: np.ndarray
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The pelvis's world rotation (T,3,3) and position (T,3), and its roll and tilt (T,): sway towards the loaded
    foot (weight w), pelvic rotation with the stride (sep), lean with the speed, knees bent while walking, and no
    higher than both legs reach their ankles."""
    T, fps, sc = plan.num_frames, plan.fps, rig.scale
    fwd, left = _heading_vectors(heading)
    lat = ((tracks.xy[0] - tracks.xy[1]) * left[:, :2]).sum(-1)                  # stance width
    lat = np.clip(lat, 0.0, 0.3 * sc)                                            # (wide side steps sway no further)
    sway = style.sway * (w - 0.5) * lat
    yaw = heading - style.pelvic_rotation * sep
    roll = style.obliquity * (2 * w - 1)
    tilt = 0.03 + style.lean * speed + c.hip_flex
    R_pelvis = rot_z(yaw) @ R_BASE @ rot_z(roll) @ rot_x(tilt)
    xy = plan.xy + sway[:, None] * left[:, :2] - c.pelvis_back[:, None] * fwd[:, :2]
    h_nom = rig.pelvis_height - style.knee_bend * sc * walking - c.pelvis_drop
    # highest pelvis from which both legs still reach their ankles with the knee bent >= 8 degrees
    l1 = np.linalg.norm(rig.bone("left_hip", "left_knee"))
    l2 = np.linalg.norm(rig.bone("left_knee", "left_ankle"))
    reach = np.sqrt(l1**2 + l2**2 + 2 * l1 * l2 * np.cos(np.deg2rad(8.0)))
    h_max = np.full(T, np.inf)
    for s, side in enumerate(SIDES):
        off = R_pelvis @ (rig.joints[J[f"{side}_hip"]] - rig.joints[0])
        d_h = np.linalg.norm(xy + off[:, :2] - tracks.ankle[s, :, :2], axis=-1)
        h_max = np.minimum(h_max, tracks.ankle[s, :, 2] + np.sqrt(np.maximum(reach**2 - d_h**2, 0.0)) - off[:, 2])
    # (a foot out of reach even with the pelvis at half height is left to the IK to stretch towards)
    height = np.maximum(_lower_envelope(h_nom, h_max, fps), np.minimum(h_nom, 0.5 * rig.pelvis_height))
    root = np.concatenate([xy, height[:, None]], 1)

    return R_pelvis, root, roll, tilt


def _spine(local: np.ndarray, style: Style, c: Controls, sep: np.ndarray, roll: np.ndarray, tilt: np.ndarray) -> None:
    """Into local (T,55,3,3): the spine's counter-rotation, upright against obliquity and lean, plus the reach
    posture."""
    counter = (style.pelvic_rotation * 1.6) * sep
    spine_yaw = counter + c.spine_twist
    spine_roll = -0.8 * roll - c.spine_side
    spine_pitch = -0.5 * (tilt - c.hip_flex) + c.spine_flex
    for j, k in (("spine1", 0.35), ("spine2", 0.35), ("spine3", 0.3)):
        local[:, J[j]] = rot_y(k * spine_yaw) @ rot_z(k * spine_roll) @ rot_x(k * spine_pitch)


def _legs(rig: Rig, local: np.ndarray, root: np.ndarray, R_pelvis: np.ndarray, tracks: FootTracks, fwd: np.ndarray,
          left: np.ndarray) -> None:
    """Into local (T,55,3,3): hips, knees, ankles and toes by two-bone IK from the pelvis onto the foot tracks."""
    Rg_pelvis = R_pelvis
    for s, side in enumerate(SIDES):
        hip = root + (R_pelvis @ (rig.joints[J[f"{side}_hip"]] - rig.joints[0]))
        foot_fwd = tracks.R_foot[s] @ np.array([0.0, 0.0, 1.0])
        pole = normalize(foot_fwd * [1, 1, 0] + 0.4 * fwd + (0.15 if s == 0 else -0.15) * left)
        R_thigh, R_shin, _ = two_bone_ik(hip, tracks.ankle[s], pole, rig.bone(f"{side}_hip", f"{side}_knee"),
                                         rig.bone(f"{side}_knee", f"{side}_ankle"), np.array([0.0, 0.0, 1.0]))
        tr = lambda R: np.swapaxes(R, -1, -2)  # noqa: E731
        local[:, J[f"{side}_hip"]] = tr(Rg_pelvis) @ R_thigh
        local[:, J[f"{side}_knee"]] = tr(R_thigh) @ R_shin
        local[:, J[f"{side}_ankle"]] = tr(R_shin) @ tracks.R_foot[s]
        local[:, J[f"{side}_foot"]] = tr(tracks.R_foot[s]) @ tracks.R_toe[s]


def _arms(local: np.ndarray, style: Style, c: Controls, walking: np.ndarray, sep: np.ndarray, sc: float) -> None:
    """Into local (T,55,3,3): the arms swing against the legs (the left arm forward when the right foot is ahead),
    lagging two frames; the right collar's raise."""
    T = len(local)
    amp = style.arm_swing * np.clip(walking, 0.15, 1.0)
    raw = np.clip(-sep / (0.7 * sc), -1.15, 1.15)
    sig = np.concatenate([np.full(min(2, T), raw[0]), raw[:max(T - 2, 0)]])   # the arms lag two frames
    for side, sgn in (("left", 1.0), ("right", -1.0)):
        swing = sgn * amp * sig + 0.06
        extra = c.arm_flex if c.arm_flex is not None else np.zeros(T)
        local[:, J[f"{side}_shoulder"]] = rot_x(-(swing + extra)) @ rot_z(-sgn * (style.arm_lower - style.arm_abduct))
        local[:, J[f"{side}_elbow"]] = rot_y(-sgn * (style.elbow_bend + 0.5 * np.maximum(swing, 0.0) + 1.1 * extra))
        local[:, J[f"{side}_wrist"]] = rot_z(-sgn * 0.1)
    # right collar: elevation lifts the shoulder (about -z for the right side); depression also protracts it
    local[:, J["right_collar"]] = rot_y(0.8 * np.maximum(-c.collar_raise, 0.0)) @ rot_z(-c.collar_raise)


def _head(rig: Rig, local: np.ndarray, root: np.ndarray, heading: np.ndarray, style: Style, c: Controls) -> None:
    """Into local (T,55,3,3): neck and head look along the path (slightly down), or at a gaze point."""
    T = len(local)
    Rg, pos = forward_kinematics(rig, local, root)
    look_h = heading + (c.look_yaw if c.look_yaw is not None else 0.0)
    look = _heading_vectors(look_h)[0] * np.cos(style.head_pitch) - np.array([0, 0, 1.0]) * np.sin(style.head_pitch)
    gyaw, gpitch = head_turn(Rg[:, J["spine3"]], look)
    if c.gaze is not None:
        # blend the head turns, not the directions: a target behind the body made the blended vector pass through
        # zero and flip; a target passing the head flips its own direction, so a near one weighs less
        to = c.gaze - pos[:, J["head"]]
        near = np.minimum(np.linalg.norm(to, axis=1) / GAZE_NEAR, 1.0)
        gw = (c.gaze_weight if c.gaze_weight is not None else np.ones(T)) * near
        tyaw, tpitch = head_turn(Rg[:, J["spine3"]], to)
        gyaw, gpitch = (1 - gw) * gyaw + gw * tyaw, (1 - gw) * gpitch + gw * tpitch
    local[:, J["neck"]] = rot_y(0.4 * gyaw) @ rot_x(0.4 * gpitch)
    local[:, J["head"]] = rot_y(0.6 * gyaw) @ rot_x(0.6 * gpitch)


def _arm_ik(rig: Rig, local: np.ndarray, Rg: np.ndarray, pos: np.ndarray, side: str, target: np.ndarray,
            weight: np.ndarray, pole: np.ndarray, soft: float = 0.0) -> np.ndarray:
    """Blend one arm from its current pose into two-bone IK onto target (T,3) with weight (T,) and elbow pole (T,3),
    overwriting the shoulder and elbow rotations in place (soft: `two_bone_ik`'s soft reach limit); returns the
    forearm's global rotation (T,3,3)."""
    s, e, wr = J[f"{side}_shoulder"], J[f"{side}_elbow"], J[f"{side}_wrist"]
    wgt = weight[:, None]
    goal = (1 - wgt) * pos[:, wr] + wgt * target
    line = normalize(pos[:, wr] - pos[:, s])
    nat = pos[:, e] - pos[:, s]
    nat_pole = normalize(nat - (nat * line).sum(-1, keepdims=True) * line)
    pole = normalize((1 - wgt) * nat_pole + wgt * normalize(pole))
    bend = np.array([0.0, 0.0, -1.0])            # the elbow moves backwards when the arm flexes
    R_up, R_fore, _ = two_bone_ik(pos[:, s], goal, pole, rig.bone(f"{side}_shoulder", f"{side}_elbow"),
                                  rig.bone(f"{side}_elbow", f"{side}_wrist"), bend, soft=soft)
    tr = lambda R: np.swapaxes(R, -1, -2)  # noqa: E731
    local[:, s] = tr(Rg[:, J[f"{side}_collar"]]) @ R_up
    local[:, e] = tr(R_up) @ R_fore
    return R_fore


def _reach_arm(rig: Rig, local: np.ndarray, Rg: np.ndarray, pos: np.ndarray, c: Controls) -> None:
    """Right arm by IK onto the blended wrist target, hand turned to the wanted orientation (in place)."""
    R_fore = _arm_ik(rig, local, Rg, pos, "right", c.reach_target, c.reach_weight, c.reach_pole)
    if c.finger_dir is not None and c.palm_dir is not None:
        # canonical right hand: fingers along -x, palm facing -y; blend the wrist towards that world orientation
        R_hand = frame(c.finger_dir, c.palm_dir) @ frame(np.array([-1.0, 0, 0]), np.array([0, -1.0, 0])).T
        wr = J["right_wrist"]
        desired = np.swapaxes(R_fore, -1, -2) @ R_hand
        rel = matrix_axis_angle(np.swapaxes(local[:, wr], -1, -2) @ desired)
        local[:, wr] = local[:, wr] @ axis_angle_matrix(rel * c.reach_weight[:, None])


def _support_arm(rig: Rig, local: np.ndarray, Rg: np.ndarray, pos: np.ndarray, weight: np.ndarray) -> None:
    """Left hand onto the left knee (a support when squatting or bending), blended by weight (T,) (in place)."""
    knee = pos[:, J["left_knee"]]
    out = normalize(knee - pos[:, J["right_knee"]]) * [1, 1, 0]
    target = knee + 0.09 * np.array([0.0, 0.0, 1.0]) + 0.03 * out
    pole = normalize(out - 0.6 * np.array([0.0, 0.0, 1.0]))
    # a soft reach limit: the knee comes within reach quickly as the body crouches, and a straight arm bending at
    # once read as an elbow snap (42 deg in one frame)
    _arm_ik(rig, local, Rg, pos, "left", target, weight, pole, soft=SUPPORT_SOFT)
