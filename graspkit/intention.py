"""WANDR's motion representation and intention features (Diomataris et al., CVPR 2024, §3.2-3.3).

Pose (§3.2)   p_i = (t_i, r_i, θ_i) ∈ R^135: root translation t (3, z-up world, m), root orientation r (6D, Zhou et
              al.) and the 21 body joints θ (21 × 6D), all SMPL-X local rotations (the hands are not modelled).
Delta (§3.3)  d_i = (d^{t-z}, d^{r-z}, d^θ) ∈ R^135 between p_{i-1} and p_i, with the global z rotation (yaw ψ_{i-1} of
              r_{i-1}) removed: d^{t-z} = R_z(-ψ_{i-1}) (t_i - t_{i-1}); d^{r-z} = 6D(R_z(-ψ_{i-1}) R_i) - 6D(R_z(-ψ_{i-1})
              R_{i-1}); d^θ = θ_i - θ_{i-1} (differences of 6D vectors). `integrate_delta` inverts it exactly.
State (§3.3)  p^dyn_i = (t_i^z, 6D(R_z(-ψ_i) R_i), θ_i, d_i) ∈ R^268: the pose without its position on the ground and
              its heading, and the last delta (the dynamics).
Intention (§3.2; its three unnumbered formulas), each expressed in the body's heading frame (rotated by R_z(-ψ_i)):
              I^w = (G - W_i) / (t_G - i)           wrist: the average velocity that puts the wrist on the goal in time,
                                                    in m/s (t_G - i in seconds); the only time-dependent feature;
              I^r = Ĥ_goal^xy - H_i^xy               orientation: unit forward direction wanted at the goal minus the
                                                    current one (training: the body's heading at t_G; inference: the
                                                    direction from the pelvis to the goal); no time term;
              I^p = 2 (1 - e^{-|Δ|}) Δ / |Δ|,  Δ = (G - P_i)^xy    pelvis: ground-plane offset saturating at norm 2.
              Degenerate cases: a goal straight above/below the pelvis (|Δ| < 1e-6) gives I^p = 0 (its limit) and,
              in the inference form, I^r = 0 (no direction to turn to; the training form's I^r is the turn to the
              heading at t_G wherever G is); at or past t_G (no time left) the whole intention is zero.

World conventions as graspkit's (z up, metres, 30 fps); the body's canonical frame is SMPL-X's (y up, facing +z), so the
heading ψ is the angle of the root's canonical +z axis projected on the ground, from world +x.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import torch
from torch import Tensor

from graspkit.body.skeleton import JOINT_INDEX, PARENTS
from graspkit.rotations import (axis_angle_to_matrix, matrix_to_axis_angle, matrix_to_rot6d, rot6d_to_matrix,
                                rotation_about_z)

if TYPE_CHECKING:
    from graspkit.body import BodyModel
    from graspkit.data.motion import Motion

FPS = 30.0
NUM_BODY = 22                                   # pelvis + 21 body joints: the joints of p and of the joint loss
POSE_DIM = 3 + 6 + 21 * 6                       # 135
DELTA_DIM = POSE_DIM                            # 135
STATE_DIM = 1 + 6 + 21 * 6 + DELTA_DIM          # 268
INTENTION_DIM = 7
INTENTION_PARTS: dict[str, slice] = {"wrist": slice(0, 3), "orientation": slice(3, 5), "pelvis": slice(5, 7)}
WRIST, PELVIS = JOINT_INDEX["right_wrist"], JOINT_INDEX["pelvis"]
_EPS = 1e-6


def _check(x: Tensor, last: int, name: str) -> None:
    """Raise a ValueError naming `name` unless x is a tensor with trailing size `last`."""
    if not isinstance(x, Tensor):
        raise TypeError(f"{name}: expected a torch.Tensor, got {type(x).__name__}")
    if x.dim() < 1 or x.shape[-1] != last:
        raise ValueError(f"{name}: expected shape (..., {last}), got {tuple(x.shape)}")


# ----------------------------------------------------------------------------------------------------- poses
def yaw_of(R: Tensor) -> Tensor:
    """Heading ψ (...) in radians from world +x of root rotations R (..., 3, 3): canonical +z projected on the ground."""
    return torch.atan2(R[..., 1, 2], R[..., 0, 2])


def pose_from_rotmats(trans: Tensor, rotmats: Tensor) -> Tensor:
    """p (..., 135) from translations (..., 3) and local rotation matrices (..., >=22, 3, 3) (the first 22 are used)."""
    _check(trans, 3, "trans")
    if rotmats.dim() < 3 or rotmats.shape[-3] < NUM_BODY or tuple(rotmats.shape[-2:]) != (3, 3):
        raise ValueError(f"rotmats: expected shape (..., >=22, 3, 3), got {tuple(rotmats.shape)}")
    r6 = matrix_to_rot6d(rotmats[..., :NUM_BODY, :, :])
    return torch.cat([trans, r6.flatten(-2)], dim=-1)


def pose_from_axis_angle(trans: Tensor, poses: Tensor) -> Tensor:
    """p (..., 135) from translations (..., 3) and axis-angle local rotations (..., >=22, 3) (e.g. Motion.poses)."""
    return pose_from_rotmats(trans, axis_angle_to_matrix(poses[..., :NUM_BODY, :]))


def split_pose(p: Tensor) -> tuple[Tensor, Tensor, Tensor]:
    """p (..., 135) -> translation (..., 3), root 6D (..., 6), body 6D (..., 21, 6)."""
    _check(p, POSE_DIM, "p")
    return p[..., :3], p[..., 3:9], p[..., 9:].unflatten(-1, (21, 6))


def pose_rotmats(p: Tensor) -> tuple[Tensor, Tensor]:
    """p (..., 135) -> translation (..., 3) and local rotation matrices (..., 22, 3, 3) (Gram-Schmidt of the 6D)."""
    _check(p, POSE_DIM, "p")
    return p[..., :3], rot6d_to_matrix(p[..., 3:].unflatten(-1, (NUM_BODY, 6)))


def pose_to_axis_angle(p: Tensor, rest: Tensor | None = None) -> tuple[Tensor, Tensor]:
    """p (..., 135) -> translation (..., 3) and axis-angle poses (..., 55, 3); joints 22-54 (jaw, eyes, hands) taken
    from `rest` (..., 55, 3) or (55, 3) when given, else zeros (flat hands)."""
    t, R = pose_rotmats(p)
    body = matrix_to_axis_angle(R)
    other = (torch.zeros(body.shape[:-2] + (33, 3), dtype=p.dtype) if rest is None
             else rest[..., NUM_BODY:, :].to(p.dtype).expand(body.shape[:-2] + (33, 3)))
    return t, torch.cat([body, other], dim=-2)


def pose_to_delta(p_prev: Tensor, p: Tensor) -> Tensor:
    """WANDR §3.3 delta d (..., 135) from p_prev to p (both (..., 135)), the yaw of p_prev's root removed."""
    t0, r0, th0 = split_pose(p_prev)
    t1, r1, th1 = split_pose(p)
    psi = yaw_of(rot6d_to_matrix(r0))
    Rz_inv = rotation_about_z(-psi)
    dt = (Rz_inv @ (t1 - t0).unsqueeze(-1)).squeeze(-1)
    dr = matrix_to_rot6d(Rz_inv @ rot6d_to_matrix(r1)) - matrix_to_rot6d(Rz_inv @ rot6d_to_matrix(r0))
    return torch.cat([dt, dr, (th1 - th0).flatten(-2)], dim=-1)


def integrate_rotmats(t0: Tensor, R0: Tensor, d: Tensor) -> tuple[Tensor, Tensor]:
    """integrate_delta on translation (..., 3) and local rotation matrices (..., 22, 3, 3): the new (t, R)."""
    _check(d, DELTA_DIM, "d")
    psi = yaw_of(R0[..., 0, :, :])
    Rz = rotation_about_z(psi)
    t1 = t0 + (Rz @ d[..., :3].unsqueeze(-1)).squeeze(-1)
    root = Rz @ rot6d_to_matrix(matrix_to_rot6d(Rz.transpose(-1, -2) @ R0[..., 0, :, :]) + d[..., 3:9])
    body = rot6d_to_matrix(matrix_to_rot6d(R0[..., 1:, :, :]) + d[..., 9:].unflatten(-1, (21, 6)))
    return t1, torch.cat([root.unsqueeze(-3), body], dim=-3)


def integrate_delta(p_prev: Tensor, d: Tensor) -> Tensor:
    """The pose p (..., 135) reached from p_prev (..., 135) by delta d (..., 135) (inverse of pose_to_delta); the 6D
    rotations are re-orthonormalised (Gram-Schmidt), so an imperfect predicted delta still gives valid rotations."""
    t0, R0 = pose_rotmats(p_prev)
    return pose_from_rotmats(*integrate_rotmats(t0, R0, d))


def poses_to_deltas(p: Tensor) -> Tensor:
    """Deltas (..., T-1, 135) of a pose sequence (..., T, 135): d_i between frames i-1 and i, for i = 1..T-1."""
    return pose_to_delta(p[..., :-1, :], p[..., 1:, :])


def state_features(p: Tensor, d_prev: Tensor, root: Tensor | None = None) -> Tensor:
    """WANDR §3.3 state p^dyn (..., 268): translation height, yaw-free root 6D, body 6D, the previous delta.
    `root` (..., 3, 3) may pass the root's rotation matrix when known."""
    _check(p, POSE_DIM, "p")
    _check(d_prev, DELTA_DIM, "d_prev")
    R = rot6d_to_matrix(p[..., 3:9]) if root is None else root
    free = matrix_to_rot6d(rotation_about_z(-yaw_of(R)) @ R)
    return torch.cat([p[..., 2:3], free, p[..., 9:], d_prev], dim=-1)


def body_transforms(p: Tensor, rest: Tensor) -> tuple[Tensor, Tensor]:
    """Forward kinematics of poses p (..., 135) with shaped rest joints (..., 22, 3) (canonical frame, from
    BodyModel.shaped): global rotations (..., 22, 3, 3) and world positions (..., 22, 3) of the body joints. Same
    convention as BodyModel: the body rotates about its root joint, world = R (x - J_0) + J_0 + t."""
    return fk_rotmats(*pose_rotmats(p), rest)


def fk_rotmats(t: Tensor, R: Tensor, rest: Tensor) -> tuple[Tensor, Tensor]:
    """body_transforms from translation (..., 3) and local rotation matrices (..., 22, 3, 3)."""
    if rest.shape[-2:] != (NUM_BODY, 3):
        raise ValueError(f"rest: expected shape (..., 22, 3), got {tuple(rest.shape)}")
    rest = rest.to(R.dtype).expand(R.shape[:-3] + (NUM_BODY, 3))
    Rg, pos = [R[..., 0, :, :]], [rest[..., 0, :]]          # the root: its own rotation, at its rest position
    for j in range(1, NUM_BODY):                              # parents come first in SMPL-X order
        q = PARENTS[j]
        Rg.append(Rg[q] @ R[..., j, :, :])
        pos.append(pos[q] + (Rg[q] @ (rest[..., j, :] - rest[..., q, :]).unsqueeze(-1)).squeeze(-1))
    return torch.stack(Rg, -3), torch.stack(pos, -2) + t.unsqueeze(-2)


def body_joints(p: Tensor, rest: Tensor) -> Tensor:
    """World positions (..., 22, 3) of the body joints of poses p (..., 135) with rest joints (..., 22, 3)."""
    return body_transforms(p, rest)[1]


def heading_of_pose(p: Tensor) -> Tensor:
    """Heading ψ (...) of poses p (..., 135)."""
    return yaw_of(rot6d_to_matrix(split_pose(p)[1]))


# ----------------------------------------------------------------------------------------------------- intention
def _to_heading_frame(v: Tensor, psi: Tensor) -> Tensor:
    """Rotate ground vectors (..., 2) by -ψ (...)."""
    c, s = torch.cos(psi), torch.sin(psi)
    return torch.stack([c * v[..., 0] + s * v[..., 1], -s * v[..., 0] + c * v[..., 1]], dim=-1)


def intention(wrist: Tensor, pelvis: Tensor, psi: Tensor | float, goal: Tensor, time_left: Tensor | float,
              goal_heading: Tensor | None = None) -> Tensor:
    """WANDR §3.2 intention I = (I^w, I^r, I^p) (..., 7) in the heading frame of the body.

    wrist, pelvis, goal (..., 3) world positions (m); psi (...) the body's heading; time_left (...) = (t_G - i) / fps
    in seconds (<= 0: the goal time has passed, the intention is zero); goal_heading (...) the heading wanted at the goal
    (training, from the body at t_G) or None (inference: the direction from the pelvis to the goal).
    """
    for x, n in ((wrist, "wrist"), (pelvis, "pelvis"), (goal, "goal")):
        _check(x, 3, n)
    dtype = wrist.dtype
    psi, time_left = (x if isinstance(x, Tensor) else torch.as_tensor(x, dtype=dtype, device=wrist.device)
                      for x in (psi, time_left))                      # a plain number is one for every body
    try:
        shape = torch.broadcast_shapes(wrist.shape[:-1], pelvis.shape[:-1], psi.shape, goal.shape[:-1], time_left.shape)
    except RuntimeError:
        raise ValueError(f"wrist, pelvis, psi, goal, time_left: expected shapes that broadcast ((..., 3) positions, "
                         f"(...) headings and times), got {tuple(wrist.shape)}, {tuple(pelvis.shape)}, "
                         f"{tuple(psi.shape)}, {tuple(goal.shape)}, {tuple(time_left.shape)}") from None
    if not bool(torch.isfinite(goal).all()):     # a NaN goal would make I^r silently 0 (NaN > eps is False)
        raise ValueError("goal: contains NaN or Inf (expected world positions in metres)")
    for x, n, unit in ((wrist, "wrist", "a position in metres"), (pelvis, "pelvis", "a position in metres"),
                       (psi, "psi", "a heading in radians"),      # past t_G the output is zeroed: a NaN body
                       (goal_heading, "goal_heading", "a heading in radians")):     # would pass unseen
        if x is not None and not bool(torch.isfinite(torch.as_tensor(x)).all()):
            raise ValueError(f"{n}: contains NaN or Inf (expected {unit})")
    if torch.isnan(time_left).any():        # NaN > 0 is False: it would read as "goal time passed", silently
        raise ValueError("time_left: contains NaN (expected seconds to the goal frame; <= 0 once it has passed)")
    time_left = time_left.to(dtype).expand(shape)
    alive = time_left > 0
    safe_t = torch.where(alive, time_left, torch.ones_like(time_left))
    wg = (goal - wrist).expand(shape + (3,))
    wg = torch.cat([_to_heading_frame(wg[..., :2], psi), wg[..., 2:]], dim=-1)
    i_w = wg / safe_t.unsqueeze(-1)

    delta = _to_heading_frame((goal - pelvis)[..., :2].expand(shape + (2,)), psi.expand(shape))
    r = delta.norm(dim=-1, keepdim=True)
    far = r > _EPS
    r_safe = torch.where(far, r, torch.ones_like(r))
    # 2 (1 - e^{-r}) / r -> 2 as r -> 0 (Taylor 2 - r + r^2/3), so I^p -> 0 smoothly
    gain = torch.where(far, 2 * (1 - torch.exp(-r_safe)) / r_safe, 2 - r + r * r / 3)
    i_p = gain * delta

    forward = torch.zeros_like(delta)
    forward[..., 0] = 1.0
    if goal_heading is None:
        want = torch.where(far, delta / r_safe, forward)
    else:
        a = (goal_heading - psi).expand(shape)
        want = torch.stack([torch.cos(a), torch.sin(a)], dim=-1)
    i_r = want - forward
    out = torch.cat([i_w, i_r, i_p], dim=-1)
    return torch.where(alive.unsqueeze(-1), out, torch.zeros_like(out))


def intention_from_pose(p: Tensor, rest: Tensor, goal: Tensor, time_left: Tensor,
                        goal_heading: Tensor | None = None, joints: Tensor | None = None) -> Tensor:
    """Intention (..., 7) of the body in pose p (..., 135) with rest joints (..., 22, 3) towards goal (..., 3);
    `joints` (..., 22, 3) may pass body_joints(p, rest) when already computed."""
    for x, n in ((p, "p"), (rest, "rest"), (joints, "joints")):    # named here, not as the wrist derived from them
        if isinstance(x, Tensor) and not bool(torch.isfinite(x).all()):
            raise ValueError(f"{n}: contains NaN or Inf (expected a pose, or joint positions in metres)")
    J = body_joints(p, rest) if joints is None else joints
    return intention(J[..., WRIST, :], J[..., PELVIS, :], heading_of_pose(p), goal, time_left, goal_heading)


def condition(p: Tensor, d_prev: Tensor, rest: Tensor, goal: Tensor, time_left: Tensor,
              goal_heading: Tensor | None = None) -> Tensor:
    """The CVAE condition c_i = (p^dyn_i, I_i) (..., 275), unnormalised (WANDR §3.3, Fig. 2)."""
    return torch.cat([state_features(p, d_prev), intention_from_pose(p, rest, goal, time_left, goal_heading)], dim=-1)


# ----------------------------------------------------------------------------------------------------- start poses
@dataclass
class StartPose:
    """Where a generated motion starts: the last two poses p_prev, p (135,) (their delta is the first state's
    dynamics), the body's rest joints (22, 3), betas (10,) and the full axis-angle pose (55, 3) (hands, jaw, eyes
    for drawing the mesh). `source` names the clip and frame it came from."""

    p_prev: Tensor
    p: Tensor
    rest: Tensor
    betas: Tensor
    full_pose: Tensor
    source: str = ""

    def canonical(self) -> "StartPose":
        """The same start moved on the ground so that its pelvis is above the origin and it faces world +x."""
        psi = heading_of_pose(self.p)
        J0 = self.rest[0].to(self.p.dtype)
        pelvis = self.p[:3] + J0
        Rz = rotation_about_z(-psi)

        def move(q: Tensor) -> Tensor:
            t, R = pose_rotmats(q)
            R = torch.cat([(Rz @ R[0])[None], R[1:]])
            shift = torch.stack([pelvis[0], pelvis[1], torch.zeros_like(pelvis[0])])
            t = (Rz @ (t + J0 - shift).unsqueeze(-1)).squeeze(-1) - J0
            return pose_from_rotmats(t, R)

        return StartPose(move(self.p_prev), move(self.p), self.rest, self.betas, self.full_pose, self.source)

    def is_canonical(self, tol: float = 1e-5) -> bool:
        """Whether the pelvis is above the origin and the body faces +x (within tol m / rad), as `canonical()` leaves
        it: the held-out starts are."""
        pelvis = self.p[:2] + self.rest[0, :2].to(self.p.dtype)
        return bool(pelvis.abs().max() <= tol) and abs(float(heading_of_pose(self.p))) <= tol

    def made_on(self, bm: BodyModel, tol: float = 1e-4) -> bool:
        """Whether the start's rest joints are bm's for its betas (within tol m): the body it was made on."""
        from graspkit.data.wandr_dataset import rest_joints

        return bool((rest_joints(bm, self.betas[None])[0] - self.rest.float()).abs().max() <= tol)

    def on_body(self, bm_from: BodyModel, bm_to: BodyModel) -> "StartPose":
        """The same start on another body model bm_to (it was made on bm_from): its rest joints from bm_to, both
        frames moved so that the first keeps its pelvis x, y and its lowest vertex's height (`restand`); a start made
        on graspkit's body and drawn on another would float or sink by the difference in their legs. The same body
        (every array of the model equal: template, bases, regressor, skinning weights, pose correctives) gives the start
        back as it is."""
        from graspkit.data.motion import Motion, restand

        a, b = bm_from.state_dict(), bm_to.state_dict()
        if a.keys() == b.keys() and all(a[k].dtype == b[k].dtype and a[k].shape == b[k].shape and torch.equal(a[k], b[k])
                                        for k in a):
            return self                                    # the same body: nothing to move
        trans, aa = pose_to_axis_angle(torch.stack([self.p_prev, self.p]), self.full_pose)
        m = restand(Motion(aa.double().numpy(), trans.double().numpy(), self.betas.double().numpy(), FPS), bm_from,
                    bm_to)
        return StartPose.from_motion(m, 1, bm_to, self.source)

    @staticmethod
    def from_motion(motion: Motion, frame: int, bm: BodyModel, source: str = "") -> "StartPose":
        """The start at `frame` (>= 1) of a Motion, on body model bm (rest joints from the motion's betas)."""
        if not 1 <= frame < motion.num_frames:
            raise ValueError(f"frame: expected 1 <= frame < {motion.num_frames}, got {frame}")
        coeffs = torch.zeros(1, bm.num_betas + bm.num_expression, dtype=torch.float32)
        k = min(bm.num_betas, len(motion.betas))
        coeffs[0, :k] = torch.as_tensor(motion.betas[:k], dtype=torch.float32)
        with torch.no_grad():
            rest = bm.shaped(coeffs.to(bm.dtype))[1][0, :NUM_BODY].float()
        trans = torch.as_tensor(motion.trans[frame - 1:frame + 1], dtype=torch.float32)
        poses = torch.as_tensor(motion.poses[frame - 1:frame + 1], dtype=torch.float32)
        p = pose_from_axis_angle(trans, poses)
        return StartPose(p[0], p[1], rest, torch.as_tensor(motion.betas[:10], dtype=torch.float32), poses[1], source)
