"""Approach-and-grasp sequences: walk to the object, reach, close the hand into the fitted grasp and hold it.

The reach plan that a grasp was fitted on (graspkit.data.grasp: plan_reach from a start 0.05-1.5 m away, facing
the object within +-10 deg, SAGA Sec. 4.3 / GOAL Sec. 3) already walks and reaches; the approach clip adds:

- the grasp: the spine, neck and head rotate smoothly into the fitted pose over the last half second; the right arm
  turns from the plan's configuration into the grasp's (local rotations slerped over ARM_BLEND_S) and the wrist's last
  APPROACH_S seconds are a straight line in along the grasp's approach direction (IK per frame, the grasp's elbow pole);
  the fingers go from the plan's opening hand to the grasp type's open pre-shape, then close into the grasp in the
  last GRASP_CLOSE_S seconds; from the grasp frame on, the whole pose is held (GOAL's goal frame = this frame);
- a GRAB-like start: half of the clips start in a T-pose (GRAB's start pose), whose arms lower into the plan's
  over the first TPOSE_S seconds; the others start from the planner's idle stance.

The lower body is the planner's, so feet, foot contacts and skating are those of the motion data (docs/data.md).
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from graspkit.body.skeleton import JOINT_INDEX
from graspkit.data.ik import axis_angle_matrix, matrix_axis_angle, smoothstep
from graspkit.data.motion import Motion

if TYPE_CHECKING:
    from graspkit.data.rig import Rig

J = JOINT_INDEX
BLEND_S = 0.5          # s before the grasp frame in which the body turns into the fitted pose
PRESHAPE_S = 0.6       # s before the grasp frame the fingers start taking the pre-shape
GRASP_CLOSE_S = 0.25   # s before the grasp frame the fingers start closing
TPOSE_S = 1.2          # s over which a T-pose start lowers its arms
ARM_JOINTS = tuple(J[n] for n in ("left_collar", "right_collar", "left_shoulder", "right_shoulder", "left_elbow",
                                  "right_elbow", "left_wrist", "right_wrist")) + tuple(range(25, 55))
FIT_JOINTS = tuple(J[n] for n in ("spine1", "spine2", "spine3", "neck", "head", "right_collar", "right_shoulder",
                                  "right_elbow", "right_wrist"))


def _continuous(aa: np.ndarray) -> np.ndarray:
    """Axis-angle tracks (T,...,3) made continuous in time: where a rotation near pi flips its axis from one frame
    to the next, the equivalent vector (2 pi - angle about the opposite axis) is used instead."""
    aa = aa.copy()
    for k in range(1, len(aa)):
        ang = np.linalg.norm(aa[k], axis=-1, keepdims=True)
        alt = aa[k] - 2 * np.pi * aa[k] / np.maximum(ang, 1e-12)
        flip = (np.linalg.norm(alt - aa[k - 1], axis=-1) < np.linalg.norm(aa[k] - aa[k - 1], axis=-1))[..., None]
        aa[k] = np.where(flip & (ang > np.pi / 2), alt, aa[k])
    return aa


def _slerp_from(R0: np.ndarray, R1: np.ndarray, w: np.ndarray) -> np.ndarray:
    """R0 (…,3,3) rotated a fraction w (…) of the way to R1: R0 exp(w log(R0^T R1))."""
    rel = matrix_axis_angle(np.swapaxes(R0, -1, -2) @ R1)
    return R0 @ axis_angle_matrix(rel * np.asarray(w)[..., None])


def approach_motion(plan: Motion, grasp_frame: int, grasp_pose: np.ndarray, open_hand: np.ndarray,
                    start_pose: str = "idle", approach_dir: np.ndarray | None = None,
                    rig: Rig | None = None) -> Motion:
    """The approach-and-grasp clip: the plan (T frames) with the fitted grasp pose (55,3) reached at grasp_frame and
    held to the end; open_hand (15,3): the right hand's pre-shape; start_pose 'idle' or 't_pose'.

    approach_dir (3,) (with rig = graspkit.data.rig.build_rig(bm, betas)): the hand's last APPROACH_S seconds are a
    straight line in along -approach_dir from APPROACH_DIST away (the right arm re-solved by IK each frame with the
    grasp's elbow pole), so the open hand reaches the object from outside rather than sweeping through it."""
    if start_pose not in ("idle", "t_pose"):
        raise ValueError(f"start_pose: expected 'idle' or 't_pose', got {start_pose!r}")
    if (approach_dir is None) != (rig is None):
        raise ValueError("approach_dir, rig: expected both (the straight approach needs rig = build_rig(bm, betas)) or "
                         f"neither, got approach_dir={'None' if approach_dir is None else 'given'}, "
                         f"rig={'None' if rig is None else 'given'}")
    T, fps, g = plan.num_frames, plan.fps, int(grasp_frame)
    if not 0 <= g < T:
        raise ValueError(f"grasp_frame: expected a frame in [0, {T}), got {grasp_frame}")
    R = axis_angle_matrix(plan.poses.astype(np.float64))                     # (T,55,3,3)
    Rg = axis_angle_matrix(np.asarray(grasp_pose, np.float64))               # (55,3,3)
    t = np.arange(T) / fps
    tg = g / fps
    # spine, neck, head: the change at the grasp frame, phased in over BLEND_S
    w = smoothstep((t - (tg - BLEND_S)) / BLEND_S)
    for j in FIT_JOINTS[:5]:
        delta = matrix_axis_angle(R[g, j].T @ Rg[j])
        R[:, j] = R[:, j] @ axis_angle_matrix(w[:, None] * delta)
    arm = [J[n] for n in ("right_collar", "right_shoulder", "right_elbow", "right_wrist")]
    if approach_dir is not None and rig is not None:
        _approach_arm(R, Rg, plan.trans.astype(np.float64), g, fps, np.asarray(approach_dir, np.float64), rig)
    else:
        for j in arm:
            delta = matrix_axis_angle(R[g, j].T @ Rg[j])
            R[:, j] = R[:, j] @ axis_angle_matrix(w[:, None] * delta)
    # fingers: plan -> open pre-shape -> grasp
    Ro = axis_angle_matrix(np.asarray(open_hand, np.float64))                # (15,3,3)
    w1 = smoothstep((t - (tg - PRESHAPE_S)) / (PRESHAPE_S - GRASP_CLOSE_S))
    w2 = smoothstep((t - (tg - GRASP_CLOSE_S)) / GRASP_CLOSE_S)
    hand = _slerp_from(R[:, 40:55], np.broadcast_to(Ro, (T, 15, 3, 3)), np.broadcast_to(w1[:, None], (T, 15)))
    R[:, 40:55] = _slerp_from(hand, np.broadcast_to(Rg[40:55], (T, 15, 3, 3)), np.broadcast_to(w2[:, None], (T, 15)))
    # hold the grasp from the grasp frame on
    R[g:] = Rg
    trans = plan.trans.astype(np.float64).copy()
    trans[g:] = trans[g]
    contacts = plan.contacts.copy() if plan.contacts is not None else None
    if contacts is not None:
        contacts[g:] = contacts[g]
    if start_pose == "t_pose":
        wt = smoothstep(t / TPOSE_S)
        ids = list(ARM_JOINTS)
        aa = _continuous(matrix_axis_angle(R[:, ids]))                      # from the T-pose (identity) to the plan
        R[:, ids] = axis_angle_matrix(wt[:, None, None] * aa)
    poses = matrix_axis_angle(R)
    return Motion(poses, trans, plan.betas, fps, contacts=contacts, goal=None, goal_frame=None, hand=None)


APPROACH_S = 0.45      # s: the hand's straight final approach
APPROACH_DIST = 0.10   # m: from this far out along the approach direction
ARM_BLEND_S = 0.7      # s before the straight approach in which the arm turns from the plan's into the grasp's
MAX_SWIVEL_DEG = 8.0   # deg per frame the elbow may swivel about the shoulder-wrist line
REACH_MAX = 0.95       # fraction of the arm's length the approach path may ask for
MAX_TWIST = np.deg2rad(85.0)   # forearm twist moved from the wrist into the elbow at most (as grasp_opt.solve_arm)


def _rate_limited(dirs: np.ndarray, axis: np.ndarray, max_step: float) -> np.ndarray:
    """Unit directions (T,3) perpendicular to axis (T,3) following `dirs` but turning at most max_step rad per frame
    about the axis (the elbow's swivel speed stays bounded when the wanted side changes quickly)."""
    out = np.zeros_like(dirs)
    cur = dirs[0]
    for k in range(len(dirs)):
        cur = cur - (cur @ axis[k]) * axis[k]
        cur = cur / max(np.linalg.norm(cur), 1e-12)
        ang = np.arctan2(np.cross(cur, dirs[k]) @ axis[k], cur @ dirs[k])
        step = np.clip(ang, -max_step, max_step)
        cur = np.cos(step) * cur + np.sin(step) * np.cross(axis[k], cur)
        out[k] = cur
    return out


def _swivel_dirs(v: np.ndarray, axis: np.ndarray, min_len: float = 0.02) -> np.ndarray:
    """Unit components (T,3) of v (T,3) perpendicular to axis (T,3), carried over from the previous frame where the
    component is shorter than min_len (a straight arm has no swivel direction of its own)."""
    out = np.zeros_like(v)
    prev = None
    for k in range(len(v)):
        c = v[k] - (v[k] @ axis[k]) * axis[k]
        if np.linalg.norm(c) < min_len and prev is not None:
            c = prev - (prev @ axis[k]) * axis[k]
        out[k] = c / max(np.linalg.norm(c), 1e-12)
        prev = out[k]
    if np.linalg.norm(v[0] - (v[0] @ axis[0]) * axis[0]) < min_len:    # straight at the start: use the first good one
        good = [k for k in range(len(v)) if np.linalg.norm(v[k] - (v[k] @ axis[k]) * axis[k]) >= min_len]
        if good:
            c = out[good[0]]
            for k in range(good[0]):
                d = c - (c @ axis[k]) * axis[k]
                out[k] = d / max(np.linalg.norm(d), 1e-12)
    return out


def _approach_arm(R: np.ndarray, Rg: np.ndarray, trans: np.ndarray, g: int, fps: float, s: np.ndarray, rig) -> None:
    """Right collar, shoulder, elbow, wrist (in place in R (T,55,3,3)) for the final approach (see approach_motion)."""
    from graspkit.data.ik import normalize, two_bone_ik
    from graspkit.data.posing import forward_kinematics

    t0 = max(0, g - int(round((APPROACH_S + ARM_BLEND_S) * fps)))
    win = np.arange(t0, g + 1)
    tt = (win - g) / fps                                                     # <= 0
    cs, sh, el, wr = (J[n] for n in ("right_collar", "right_shoulder", "right_elbow", "right_wrist"))
    # the grasp's arm (with the final body) and the plan's arm, in the world
    root = trans + rig.joints[0]
    Rg_full = R[g].copy()
    Rg_full[[cs, sh, el, wr]] = Rg[[cs, sh, el, wr]]
    G, P = forward_kinematics(rig, Rg_full[None], root[g][None])
    W, H = P[0, wr], G[0, wr]
    pole = P[0, el] - P[0, sh]
    Rw, Pw = forward_kinematics(rig, R[win], root[win])                      # plan (with the spine already blended)
    u = np.clip((tt + APPROACH_S) / APPROACH_S, 0, 1)
    A = W + APPROACH_DIST * (1 - smoothstep(u))[:, None] * s                 # the straight approach path
    b = smoothstep((tt + APPROACH_S + ARM_BLEND_S) / ARM_BLEND_S)[:, None]   # leave the plan's path
    target = (1 - b) * Pw[:, wr] + b * A
    reach = REACH_MAX * (np.linalg.norm(rig.bone("right_shoulder", "right_elbow"))
                         + np.linalg.norm(rig.bone("right_elbow", "right_wrist")))
    hand = _slerp_from(Rw[:, wr], np.broadcast_to(H, Rw[:, wr].shape), b[:, 0])
    # collar from the grasp, phased in with b; then two-bone IK and the twist split
    Rc = _slerp_from(R[win, cs], np.broadcast_to(Rg[cs], R[win, cs].shape), b[:, 0])
    R[win, cs] = Rc
    Rw, Pw = forward_kinematics(rig, R[win], root[win])
    off = target - Pw[:, sh]                  # a path point out of comfortable reach is pulled in (the elbow would
    dist = np.linalg.norm(off, axis=1, keepdims=True)        # whip round near full extension)
    target = Pw[:, sh] + off * np.minimum(1.0, reach / np.maximum(dist, 1e-9))
    b1, b2 = rig.bone("right_shoulder", "right_elbow"), rig.bone("right_elbow", "right_wrist")
    # the elbow swivels about the shoulder -> target line from the plan's side to the grasp's (angle blended by b),
    # so the wrist stays on its path while the arm changes configuration
    axis = normalize(target - Pw[:, sh])
    p1 = _swivel_dirs(np.broadcast_to(pole, target.shape), axis)                       # the grasp's elbow side
    p0 = _swivel_dirs(Pw[:, el] - Pw[:, sh], axis)                                       # the plan's
    ang = np.unwrap(np.arctan2((np.cross(p0, p1) * axis).sum(-1), (p0 * p1).sum(-1)))   # no flip at +-pi
    th = (b[:, 0] * ang)[:, None]
    pole_t = _rate_limited(np.cos(th) * p0 + np.sin(th) * np.cross(axis, p0), axis, np.deg2rad(MAX_SWIVEL_DEG))
    R_up, R_fore, _ = two_bone_ik(Pw[:, sh], target, pole_t, b1, b2, np.array([0.0, 0.0, -1.0]))
    d = normalize(b2)
    wrist = np.swapaxes(R_fore, -1, -2) @ hand
    aa = matrix_axis_angle(wrist)
    twist = np.clip(aa @ d, -MAX_TWIST, MAX_TWIST)[:, None] * d              # forearm twist into the elbow (limited)
    R_fore = R_fore @ axis_angle_matrix(twist)
    ik = np.stack([np.swapaxes(Rw[:, cs], -1, -2) @ R_up, np.swapaxes(R_up, -1, -2) @ R_fore,
                   np.swapaxes(R_fore, -1, -2) @ hand], 1)                   # local shoulder, elbow, wrist
    c = smoothstep((tt - tt[0]) / 0.2)[:, None]                              # the plan's twist split -> ours
    R[win[:, None], [sh, el, wr]] = _slerp_from(R[win][:, [sh, el, wr]], ik, np.broadcast_to(c, (len(win), 3)))
    # land exactly on the fitted arm at the grasp frame (a small correction, phased in over the straight approach)
    for j in (sh, el, wr):
        delta = matrix_axis_angle(R[g, j].T @ Rg[j])
        R[win, j] = R[win, j] @ axis_angle_matrix(smoothstep(u)[:, None] * delta)
