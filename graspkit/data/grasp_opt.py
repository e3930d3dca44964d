"""Whole-body grasp fitting: the optimisation that turns a planned reaching pose into a grasp (SAGA Sec. 3.2, GOAL Sec. 3.3).

Three stages, all batched over B grasps of one object (each with its own body shape and object pose):

1. arm     `solve_arm`: analytic. The right wrist must sit where the hand's palm lands on the grasp frame, with the
           hand turned to it; two-bone IK for 24 elbow swivel angles, forearm twist moved from the wrist into the
           elbow, the swivel with the smallest residual wrist rotation (and the elbow below the shoulder) wins.
2. fingers `close_fingers`: "closed until contact". Each finger (and the thumb) follows its own path from an open
           pre-shape to a closed one; all K steps of all fingers are skinned at once, a finger stops at the first step
           whose vertices enter the object (signed distance < -1 mm), refined by bisection.
3. polish  `polish`: Adam over the SMPL-X pose (spine, neck, head, right arm, fingers; the legs and pelvis keep the
           planner's stance, so both feet stay on the ground and the pelvis over the support) minimising
              E = E_colli (after SAGA Eq. 7, hand/arm vertices and object points vs the hand) + E_cont (after SAGA
                  Eq. 6: the palm and fingertip regions touch) + E_anchor (after GOAL Eq. 4: palm on the chosen spot,
                  facing it) + E_q (after GOAL Eq. 6: head towards the object) + E_theta (after GOAL Eq. 5: coupling
                  to the initial pose) + wrist / elbow range-of-motion penalties.
           "After": this is graspkit's data generator, not a paper's model, and its terms are squared where the papers'
           are not: Eq. 7's hinge max(-S, σ) becomes the squared penetration, Eq. 5's ‖θ − θ̂‖₂ the squared change,
           and Eq. 6's ‖q − q̂‖₁ (against GNet's predicted q̂) 1 − cos(q, object − head) (no network here).
           Signed distances come from the object's SDF grid (graspkit.objects.SDFGrid: differentiable, < 0 inside).

Skinning during the fit only touches the vertices that matter (`PartialBody`: the right arm and hand, 1,400 of
10,475 vertices), with the same equations as BodyModel (tested equal); metrics are computed on full meshes.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from torch import Tensor

from graspkit.body.hand_poses import hand_axes
from graspkit.body.markers import palm_vertices
from graspkit.body.model import NUM_POSE_BASIS, BodyModel
from graspkit.body.skeleton import FINGERS, JOINT_INDEX, NUM_JOINTS
from graspkit.data.ik import axis_angle_matrix, frame, matrix_axis_angle, normalize, two_bone_ik
from graspkit.objects.sdf import SDFGrid
from graspkit.rotations import axis_angle_to_matrix

J = JOINT_INDEX
RIGHT_HAND = tuple(range(40, 55))                              # 15 finger joints, SMPL-X order
FINGER_JOINTS = {f: (40 + 3 * k, 41 + 3 * k, 42 + 3 * k) for k, f in enumerate(FINGERS)}
ARM = ("right_collar", "right_shoulder", "right_elbow", "right_wrist")
FREE_BODY = ("spine1", "spine2", "spine3", "neck", "head") + ARM
PENETRATION_STOP = 1e-3       # m: a closing finger stops before it enters the object deeper than this
NEAR_POINTS = 256             # object points per grasp checked against the hand in the polish (the closest ones)


# ----------------------------------------------------------------------------- partial skinning
class PartialBody:
    """SMPL-X skinning of a subset of vertices (the same equations as BodyModel.lbs, on `ids` only)."""

    def __init__(self, bm: BodyModel, ids: np.ndarray) -> None:
        ids_t = torch.as_tensor(np.asarray(ids, np.int64))
        V, n = bm.num_vertices, len(ids_t)
        self.bm, self.ids, self.n = bm, ids_t, n
        self.v_template = bm._v_template_cm.view(3, V)[:, ids_t].reshape(1, 3 * n)
        self.shape_basis = bm.shape_basis.view(-1, 3, V)[:, :, ids_t].reshape(-1, 3 * n)
        self.posedirs = (bm.posedirs.view(NUM_POSE_BASIS, 3, V)[:, :, ids_t].reshape(NUM_POSE_BASIS, 3 * n)
                         if bm.has_posedirs else None)
        self.weights_t = bm._weights_t[:, ids_t]                      # (55, n)

    def __call__(self, rot: Tensor, coeffs: Tensor, transl: Tensor) -> tuple[Tensor, Tensor]:
        """rot (B,55,3,3) absolute local rotations, coeffs (B,20) [betas, expression], transl (B,3) -> vertices (B,n,3), joints (B,55,3)."""
        bm, B = self.bm, rot.shape[0]
        v = torch.addmm(self.v_template, coeffs, self.shape_basis).view(B, 3, self.n)
        Jr = torch.addmm(bm.J_template.view(1, -1), coeffs, bm.J_basis).view(B, NUM_JOINTS, 3)
        if self.posedirs is not None:
            eye = torch.eye(3, dtype=rot.dtype)
            v = v + ((rot[:, 1:] - eye).reshape(B, NUM_POSE_BASIS) @ self.posedirs).view(B, 3, self.n)
        Rg, tg = bm.global_transforms(rot, Jr)
        offset = (tg + transl[:, None]) - (Rg @ Jr[..., None])[..., 0]
        A = torch.cat([Rg.transpose(2, 3), offset[:, :, None]], dim=2).reshape(B, NUM_JOINTS, 12)
        T = (A.transpose(1, 2) @ self.weights_t).view(B, 4, 3, self.n)
        verts = T[:, 3] + T[:, 0] * v[:, 0:1] + T[:, 1] * v[:, 1:2] + T[:, 2] * v[:, 2:3]
        return verts.transpose(1, 2), tg + transl[:, None]


def part_vertices(bm: BodyModel, joints: tuple[int, ...] | list[int]) -> np.ndarray:
    """Vertex ids (n,) whose largest skinning weight belongs to one of `joints`."""
    return np.flatnonzero(np.isin(bm.lbs_weights.argmax(1).numpy(), list(joints)))


def coeffs_of(bm: BodyModel, betas: np.ndarray | Tensor) -> Tensor:
    """[betas, zero expression] (B, num_betas + num_expression) for betas (B,10)."""
    b = torch.as_tensor(np.asarray(betas), dtype=bm.dtype).reshape(-1, bm.num_betas)
    return torch.cat([b, b.new_zeros(len(b), bm.num_expression)], 1)


# ----------------------------------------------------------------------------- hand geometry
@dataclass(frozen=True)
class HandFrame:
    """The right hand in the canonical rest pose of one body: wrist joint, palm centre, unit palm normal,
    finger direction (wrist -> middle knuckle) and thumb side, all (3,); rot (3,3) columns = (finger, normal, f x n)."""

    wrist: np.ndarray
    palm: np.ndarray
    normal: np.ndarray
    finger: np.ndarray
    thumb: np.ndarray

    @property
    def rot(self) -> np.ndarray:
        """Frame (3,3) with columns finger, palm normal, finger x normal."""
        return frame(self.finger, self.normal)


class HandModel:
    """What the fitter knows about the right hand of a model: vertex groups and per-body hand frames / axes."""

    def __init__(self, bm: BodyModel) -> None:
        self.bm = bm
        self._rest: dict[bytes, tuple[np.ndarray, np.ndarray]] = {}
        self.hand_ids = part_vertices(bm, [J["right_wrist"], *RIGHT_HAND])
        self.arm_ids = part_vertices(bm, [J["right_elbow"], J["right_shoulder"]])
        self.palm_ids = np.asarray(palm_vertices(bm)["right"], np.int64)
        part = bm.lbs_weights.argmax(1).numpy()
        self.finger_ids = {f: np.flatnonzero(np.isin(part, js)) for f, js in FINGER_JOINTS.items()}
        # fingertip pads: the third of each distal segment's vertices whose rest normals face the palm side (-y),
        # the regions that touch in a grasp; on the rest body with the file's mean hands whatever bm.flat_hand_mean
        # (as the marker layouts), so one model file gives one set of pads (the flat hands' gave other pads)
        from graspkit.body.markers import _Rest, vertex_normals
        v = torch.as_tensor(_Rest(bm, "mean").v, dtype=bm.dtype)[None]
        n = vertex_normals(v, bm.faces)[0].numpy()
        self.pad_ids = {}
        for f, js in FINGER_JOINTS.items():
            dist = np.flatnonzero(part == js[2])
            self.pad_ids[f] = dist[np.argsort(n[dist, 1])[:max(4, len(dist) // 3)]]
        # vertices used by the polish: hand + forearm + upper arm (order: hand first)
        self.fit_ids = np.concatenate([self.hand_ids, self.arm_ids])
        pos = {int(v): k for k, v in enumerate(self.fit_ids)}
        self.fit_palm = np.array([pos[int(v)] for v in self.palm_ids])
        self.fit_pads = {f: np.array([pos[int(v)] for v in ids]) for f, ids in self.pad_ids.items()}
        self.fit_fingers = {f: np.array([pos[int(v)] for v in ids]) for f, ids in self.finger_ids.items()}
        self.n_hand = len(self.hand_ids)

    def rest(self, betas: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Shaped rest vertices (V,3) and joints (55,3) for betas (10,) (numpy, float64)."""
        key = np.asarray(betas, np.float64).tobytes()
        if key not in self._rest:
            if len(self._rest) > 64:
                self._rest.clear()
            self._rest[key] = self._shaped(betas)
        return self._rest[key]

    def _shaped(self, betas: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Uncached rest vertices and joints."""
        with torch.no_grad():
            v, j = self.bm.shaped(coeffs_of(self.bm, betas))
        return v[0].double().numpy(), j[0].double().numpy()

    def frame(self, betas: np.ndarray) -> HandFrame:
        """The hand frame of body `betas` in its canonical rest pose."""
        v, j = self.rest(betas)
        palm = v[self.palm_ids]
        normal = _mean_normal(v, self.bm.faces.numpy(), self.palm_ids)
        finger = j[J["right_middle1"]] - j[J["right_wrist"]]
        finger = normalize(finger - (finger @ normal) * normal)
        thumb = normalize(np.cross(normal, finger))
        if thumb @ (j[J["right_index1"]] - j[J["right_pinky1"]]) < 0:
            thumb = -thumb
        return HandFrame(j[J["right_wrist"]], palm.mean(0), normal, finger, thumb)

    def axes(self, betas: np.ndarray) -> dict[str, np.ndarray]:
        """Right-hand joint axes (graspkit.body.hand_poses.hand_axes) of body `betas`."""
        return hand_axes(self.rest(betas)[1], "right")


def _mean_normal(v: np.ndarray, faces: np.ndarray, ids: np.ndarray) -> np.ndarray:
    """Unit mean of the area-weighted vertex normals of `ids`."""
    from graspkit.body.markers import vertex_normals
    n = vertex_normals(torch.as_tensor(v)[None], torch.as_tensor(faces))[0].numpy()
    return normalize(n[ids].mean(0))


# ----------------------------------------------------------------------------- hand shapes
# degrees: per finger (index, middle, pinky, ring) (MCP, PIP, DIP) flexion; thumb (CMC flexion, CMC palmar
# abduction, CMC twist, MCP flexion, IP flexion); MCP spread (index, middle, pinky, ring). Each grasp type
# closes every digit from `open` towards `closed` until it touches (close_fingers); no joint beyond 100 deg
# (graspkit.metrics' finger range).
@dataclass(frozen=True)
class HandShape:
    """Open and closed finger angles of one grasp type (degrees)."""

    open_fingers: tuple[tuple[float, float, float], ...]
    closed_fingers: tuple[tuple[float, float, float], ...]
    open_thumb: tuple[float, float, float, float, float]
    closed_thumb: tuple[float, float, float, float, float]
    spread: tuple[float, float, float, float] = (4.0, 0.0, -6.0, -3.0)


HAND_SHAPES: dict[str, HandShape] = {
    "power": HandShape(((8, 8, 2),) * 4, ((90, 100, 65),) * 4, (-5, 5, 25, 0, 0), (45, 60, 60, 45, 50)),
    "handle": HandShape(((5, 5, 0),) * 4, ((90, 100, 70),) * 4, (-5, 5, 25, 0, 0), (45, 55, 55, 45, 50),
                        (1.0, 0.0, -2.0, -1.0)),
    "side": HandShape(((0, 0, 0),) * 4, ((80, 100, 60),) * 4, (-5, 0, 15, 0, 0), (35, 45, 40, 40, 45)),
    # pinch closes onto graspkit.body.hand_poses' 'pinch' template, where the thumb pad meets the index tip
    "pinch": HandShape(((8, 12, 5), (8, 12, 5), (45, 60, 25), (40, 55, 25)),
                       ((40, 50, 25), (35, 45, 20), (45, 60, 25), (40, 55, 25)),
                       (0, 20, 40, 0, 0), (13, 36, 51, 16, 17)),
}


def hand_pose_from_angles(axes: dict[str, np.ndarray], fingers: np.ndarray, thumb: np.ndarray,
                          spread: np.ndarray) -> np.ndarray:
    """Axis-angle (15,3) of the right hand from finger flexions (4,3), thumb angles (5,) and MCP spreads (4,), degrees."""
    out = np.zeros((15, 3))
    rad = np.deg2rad
    for fi in range(4):
        for k in range(3):
            out[3 * fi + k] = rad(fingers[fi, k]) * axes["flex"][3 * fi + k]
        out[3 * fi] += rad(spread[fi]) * axes["spread"][3 * fi]
    out[12] = rad(thumb[0]) * axes["flex"][12] + rad(thumb[1]) * axes["abduct"] + rad(thumb[2]) * axes["twist"]
    out[13] = rad(thumb[3]) * axes["flex"][13]
    out[14] = rad(thumb[4]) * axes["flex"][14]
    return out


def hand_path(shape: HandShape, axes: dict[str, np.ndarray], curls: np.ndarray, noise_deg: np.ndarray | None = None
              ) -> np.ndarray:
    """Hand poses (K,15,3) along the open -> closed path: digit d at curl curls[k, d] (K,5) in [0,1] (fingers, thumb).

    noise_deg (21,) perturbs the open shape (12 finger flexions, 5 thumb angles, 4 spreads), as a person's pre-shape varies."""
    e = np.zeros(21) if noise_deg is None else np.asarray(noise_deg, float)
    of = np.asarray(shape.open_fingers, float) + e[:12].reshape(4, 3)
    cf = np.asarray(shape.closed_fingers, float)
    ot = np.asarray(shape.open_thumb, float) + e[12:17]
    ct = np.asarray(shape.closed_thumb, float)
    sp = np.asarray(shape.spread, float) + e[17:21]
    out = np.zeros((len(curls), 15, 3))
    for k, c in enumerate(np.asarray(curls, float)):
        fingers = of + c[:4, None] * (cf - of)
        thumb = ot + c[4] * (ct - ot)
        out[k] = hand_pose_from_angles(axes, fingers, thumb, sp)
    return out


# ----------------------------------------------------------------------------- stage 1: the arm
def solve_arm(collar_rot: np.ndarray, shoulder: np.ndarray, rest_joints: np.ndarray, wrist_target: np.ndarray,
              hand_rot: np.ndarray, n_swivel: int = 24, max_twist: float = np.deg2rad(85.0)
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Local rotations (M,3,3) of the right shoulder, elbow and wrist that put the wrist on wrist_target (M,3) with the
    hand's global rotation hand_rot (M,3,3), given the collar's global rotation (3,3) and the shoulder joint (3,) (world).

    Returns (shoulder, elbow, wrist, residual wrist angle (M,) in rad). The elbow swivel about the shoulder -> wrist
    line is searched over n_swivel angles; forearm twist up to max_twist goes into the elbow (pronation/supination),
    the rest stays in the wrist; the swivel with the smallest residual wrist rotation (elbow below the shoulder) wins."""
    W = np.asarray(wrist_target, float).reshape(-1, 3)
    H = np.asarray(hand_rot, float).reshape(-1, 3, 3)
    M = len(W)
    b1 = rest_joints[J["right_elbow"]] - rest_joints[J["right_shoulder"]]
    b2 = rest_joints[J["right_wrist"]] - rest_joints[J["right_elbow"]]
    axis = normalize(W - shoulder)                                             # (M,3)
    down = np.array([0.0, 0.0, -1.0])
    # the swivel circle is searched whole, so any reference off the arm's line will do where the arm points straight
    # down or up (down itself would give zero poles there)
    ref = np.where((np.abs(axis @ down) > 1 - 1e-9)[:, None], np.array([1.0, 0.0, 0.0]), down)
    p0 = normalize(ref - (axis * ref).sum(-1, keepdims=True) * axis)
    p1 = np.cross(axis, p0)
    phis = np.linspace(-np.pi, np.pi, n_swivel, endpoint=False)
    poles = np.cos(phis)[None, :, None] * p0[:, None] + np.sin(phis)[None, :, None] * p1[:, None]   # (M,n,3)
    root = np.broadcast_to(shoulder, poles.shape)
    R_up, R_fore, mid = two_bone_ik(root, np.broadcast_to(W[:, None], poles.shape), poles, b1, b2,
                                    np.array([0.0, 0.0, -1.0]))
    d = normalize(b2)
    wrist = np.swapaxes(R_fore, -1, -2) @ H[:, None]                          # (M,n,3,3) before the twist split
    aa = matrix_axis_angle(wrist)
    ang = np.linalg.norm(aa, axis=-1)
    half = 0.5 * ang
    qv = aa / np.maximum(ang, 1e-9)[..., None] * np.sin(half)[..., None]
    twist = 2.0 * np.arctan2(qv @ d, np.cos(half))                             # swing-twist split about d
    twist = (twist + np.pi) % (2 * np.pi) - np.pi
    tw = np.clip(twist, -max_twist, max_twist)
    Rt = axis_angle_matrix(tw[..., None] * d)
    wrist2 = np.swapaxes(Rt, -1, -2) @ wrist
    resid = np.linalg.norm(matrix_axis_angle(wrist2), axis=-1)               # (M,n)
    cost = resid + 2.0 * np.maximum(mid[..., 2] - shoulder[2] + 0.05, 0.0) + 0.15 * np.abs(tw)
    k = np.argmin(cost, axis=1)
    m = np.arange(M)
    R_up_k, R_fore_k = R_up[m, k], R_fore[m, k] @ Rt[m, k]
    sh = collar_rot.T @ R_up_k
    el = np.swapaxes(R_up_k, -1, -2) @ R_fore_k
    return sh, el, wrist2[m, k], resid[m, k]


# ----------------------------------------------------------------------------- signed distance to posed objects
def profile_sdf(rz: Tensor, profile: Tensor) -> Tensor:
    """Signed distance (...,) of points given as (r, z) (...,2) to the closed polygon `profile` (K,2) in the (r, z)
    half-plane: the exact SDF of the solid of revolution about z (negative inside); differentiable."""
    a, b = profile, torch.roll(profile, -1, 0)                              # edges a -> b
    e = b - a
    w = rz[..., None, :] - a                                                # (...,K,2)
    h = ((w * e).sum(-1) / (e * e).sum(-1).clamp_min(1e-18)).clamp(0, 1)
    on_axis = (a[:, 0] <= 1e-12) & (b[:, 0] <= 1e-12)                      # the axis is no surface in 3D
    d = (w - h[..., None] * e).norm(dim=-1).masked_fill(on_axis, float("inf")).min(-1).values
    # crossing number of a ray along +r
    up = (a[:, 1] <= rz[..., None, 1]) != (b[:, 1] <= rz[..., None, 1])
    x = a[:, 0] + (rz[..., None, 1] - a[:, 1]) / torch.where(e[:, 1] == 0, torch.ones_like(e[:, 1]), e[:, 1]) * e[:, 0]
    inside = ((up & (rz[..., None, 0] < x)).sum(-1) % 2) == 1
    return torch.where(inside, -d, d)


class PosedSDF:
    """One object's SDF grid seen in the world through per-grasp poses: x_obj = R^T (x - t).

    `solids` ((K,2) (r, z) profiles in the object frame, about its vertical axis through `axis_xy`): solids of
    revolution that fill a hollow object's cavity up to its outer surface. The fit sees min(grid, solids), so a
    finger can neither enter a cup nor pass through a wall thinner than the grid's cells; the metrics use the
    real, hollow mesh."""

    def __init__(self, grid: SDFGrid, rot: np.ndarray, transl: np.ndarray, dtype: torch.dtype = torch.float32,
                 solids: list[np.ndarray] | None = None, axis_xy: np.ndarray | None = None) -> None:
        self.grid = grid.to(dtype=dtype)
        self.rot = torch.as_tensor(np.asarray(rot), dtype=dtype).reshape(-1, 3, 3)       # (B,3,3)
        self.transl = torch.as_tensor(np.asarray(transl), dtype=dtype).reshape(-1, 3)    # (B,3)
        self.solids = [torch.as_tensor(np.asarray(p), dtype=dtype) for p in (solids or [])]
        self.axis_xy = torch.zeros(2, dtype=dtype) if axis_xy is None else torch.as_tensor(axis_xy, dtype=dtype)

    def __call__(self, points: Tensor, index: Tensor | None = None) -> Tensor:
        """Signed distance (B,N) of world points (B,N,3) (or (M,N,3) with index (M,) choosing each row's grasp)."""
        local = self.to_object(points, index)
        d = self.grid(local)
        if self.solids:
            rz = torch.stack([(local[..., :2] - self.axis_xy).norm(dim=-1), local[..., 2]], -1)
            for prof in self.solids:
                d = torch.minimum(d, profile_sdf(rz, prof))
        return d

    def to_object(self, points: Tensor, index: Tensor | None = None) -> Tensor:
        """World points (B,N,3) in each grasp's object frame."""
        R, t = (self.rot, self.transl) if index is None else (self.rot[index], self.transl[index])
        return (points - t[:, None]) @ R


# ----------------------------------------------------------------------------- stage 2: fingers
def close_fingers(pb: PartialBody, hm: HandModel, rot: Tensor, coeffs: Tensor, transl: Tensor, sdf: PosedSDF,
                  paths: list, steps: int = 16, bisect: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """Close every digit of B hands from open to closed until it touches the object (SAGA's "closed until contact").

    rot (B,55,3,3) poses with the body set (fingers are replaced), paths[b](curls (K,5)) -> hand poses (K,15,3);
    returns the curls (B,5) chosen per digit and the hand poses (B,15,3) at those curls. A digit that already
    penetrates when fully open stays open; one that never touches closes fully."""
    B = rot.shape[0]
    digits = list(FINGERS)
    lo = np.zeros((B, 5))
    hi = np.ones((B, 5))
    grid = np.linspace(0.0, 1.0, steps)

    def depth(curls: np.ndarray) -> np.ndarray:
        """Deepest penetration (B,K,5) of each digit at curls (B,K,5)."""
        K = curls.shape[1]
        hands = np.stack([paths[b](curls[b]) for b in range(B)])               # (B,K,15,3)
        R = rot[:, None].expand(B, K, NUM_JOINTS, 3, 3).clone()
        R[:, :, 40:55] = axis_angle_to_matrix(torch.as_tensor(hands, dtype=rot.dtype))
        idx = torch.arange(B).repeat_interleave(K)
        with torch.no_grad():
            v, _ = pb(R.reshape(B * K, NUM_JOINTS, 3, 3), coeffs[idx], transl[idx])
            d = sdf(v, idx)                                                    # (B*K, n)
        out = np.zeros((B * K, 5))
        for k, f in enumerate(digits):
            out[:, k] = -d[:, hm.fit_fingers[f]].min(1).values.double().numpy()
        return out.reshape(B, K, 5)

    dep = depth(np.broadcast_to(grid[None, :, None], (B, steps, 5)).copy())       # (B,K,5)
    for b in range(B):
        for k in range(5):
            bad = np.flatnonzero(dep[b, :, k] > PENETRATION_STOP)
            if len(bad) == 0:
                lo[b, k] = hi[b, k] = 1.0
            elif bad[0] == 0:
                lo[b, k] = hi[b, k] = 0.0
            else:
                lo[b, k], hi[b, k] = grid[bad[0] - 1], grid[bad[0]]
    for _ in range(bisect):
        mid = 0.5 * (lo + hi)
        dm = depth(mid[:, None])[:, 0]
        inside = dm > PENETRATION_STOP
        hi = np.where(inside, mid, hi)
        lo = np.where(inside, lo, mid)
    hands = np.stack([paths[b](lo[b][None])[0] for b in range(B)])
    return lo, hands


# ----------------------------------------------------------------------------- stage 3: polish
@dataclass
class PolishWeights:
    """Weights of the polish energy terms (distances in mm inside the terms)."""

    colli: float = 1.0        # after SAGA Eq. 7: sum of squared penetrations (mm^2) of hand / arm vertices
    colli_obj: float = 0.02   # after SAGA Eq. 7: object points inside the hand (S(o, V_h): nearest vertex + normal)
    contact: float = 1.5      # after SAGA Eq. 6, squared gap (mm^2) of each contact region's closest vertex
    anchor: float = 0.2       # after GOAL Eq. 4, palm centre to its target (mm^2)
    facing: float = 30.0      # palm normal against the surface normal, 1 + n . s
    gaze: float = 20.0        # after GOAL Eq. 6 (no predicted q̂ here), 1 - cos(head direction, object)
    prior: float = 200.0      # after GOAL Eq. 5 (squared), squared rotation change (rad^2) of body joints
    prior_fingers: float = 20.0
    limits: float = 500.0     # squared excess (rad^2) over the wrist / elbow-twist limits


@dataclass
class PolishTargets:
    """Per-grasp targets (numpy): palm target (B,3), surface normal there (B,3), object centre (B,3),
    contact-region mask (B,6) over [palm, thumb, index, middle, ring, pinky]."""

    palm: np.ndarray
    normal: np.ndarray
    centre: np.ndarray
    regions: np.ndarray


REGIONS = ("palm", "thumb", "index", "middle", "ring", "pinky")


def _softmin(x: Tensor, dim: int, tau: float = 0.5) -> Tensor:
    """Smooth minimum (temperature tau, same units as x)."""
    return -tau * torch.logsumexp(-x / tau, dim=dim)


def polish(pb: PartialBody, hm: HandModel, head_pb: PartialBody, head_pair: tuple[int, int], rot0: Tensor,
           coeffs: Tensor, transl: Tensor, sdf: PosedSDF, targets: PolishTargets, object_points: Tensor,
           steps: int = 50, lr: float = 0.005, weights: PolishWeights | None = None, wrist_limit_deg: float = 80.0,
           history: list | None = None) -> Tensor:
    """Adam (learning rate decaying linearly to a tenth) on rotation offsets of the spine, neck, head, right arm and
    fingers; returns the polished rot (B,55,3,3).

    object_points (B,P,3): world points on each object for the object-in-hand term. history, if a list, receives
    per-step dicts of the mean energy terms (for plots)."""
    w = weights or PolishWeights()
    B = rot0.shape[0]
    free = [J[n] for n in FREE_BODY] + list(RIGHT_HAND)
    n_body = len(FREE_BODY)
    delta = torch.zeros(B, len(free), 3, dtype=rot0.dtype, requires_grad=True)
    opt = torch.optim.Adam([delta], lr=lr)
    sched = torch.optim.lr_scheduler.LambdaLR(opt, lambda k: 1.0 - 0.9 * k / max(steps, 1))   # linear decay to lr / 10
    t_palm = torch.as_tensor(targets.palm, dtype=rot0.dtype)
    t_norm = torch.as_tensor(targets.normal, dtype=rot0.dtype)
    t_centre = torch.as_tensor(targets.centre, dtype=rot0.dtype)
    regions = torch.as_tensor(targets.regions, dtype=rot0.dtype)
    region_idx = [torch.as_tensor(hm.fit_palm)] + [torch.as_tensor(hm.fit_pads[f]) for f in REGIONS[1:]]
    nh = hm.n_hand
    prior_w = torch.tensor([w.prior] * n_body + [w.prior_fingers] * len(RIGHT_HAND), dtype=rot0.dtype)
    prior_w[FREE_BODY.index("right_wrist")] = w.prior * 0.25
    prior_w[FREE_BODY.index("right_shoulder")] = w.prior * 0.25
    prior_w[FREE_BODY.index("right_elbow")] = w.prior * 0.25
    free_t = torch.tensor(free)
    normals_of = _hand_normal_helper(hm)
    with torch.no_grad():   # the object points that can meet the hand: the NEAR_POINTS closest to the initial hand
        v0, _ = pb(rot0, coeffs, transl)
        d0 = torch.cdist(object_points, v0[:, :hm.n_hand]).min(-1).values
        keep = d0.topk(min(NEAR_POINTS, d0.shape[1]), dim=1, largest=False).indices
        object_points = torch.gather(object_points, 1, keep[..., None].expand(-1, -1, 3))
    for it in range(steps + 1):
        R = rot0.clone()
        R[:, free_t] = rot0[:, free_t] @ axis_angle_to_matrix(delta)
        v, _ = pb(R, coeffs, transl)
        d = sdf(v) * 1000.0                                                     # mm, (B,n)
        e_colli = (torch.relu(-d) ** 2).sum(1)
        # object points inside the hand: nearest hand vertex, sign by its (approximate) outward normal
        vh = v[:, :nh]
        nrm = normals_of(v)                                                      # (B,nh,3)
        dist, idx = torch.cdist(object_points, vh.detach()).min(-1)             # (B,P)
        near = dist < 0.02
        gv = torch.gather(vh, 1, idx[..., None].expand(-1, -1, 3))
        gn = torch.gather(nrm, 1, idx[..., None].expand(-1, -1, 3))
        s = ((object_points - gv) * gn).sum(-1) * 1000.0
        e_obj = (torch.relu(-s) ** 2 * near).sum(1)
        mins = torch.stack([_softmin(d[:, ri], 1) for ri in region_idx], 1)     # (B,6) mm
        e_cont = ((mins.clamp(min=0.0) ** 2) * (mins < 25.0) * regions).sum(1)
        palm = v[:, torch.as_tensor(hm.fit_palm)]
        pc = palm.mean(1)
        e_anchor = ((pc - t_palm) * 1000.0).pow(2).sum(1)
        pn = nrm[:, torch.as_tensor(hm.fit_palm)].mean(1)
        pn = pn / pn.norm(dim=-1, keepdim=True)
        e_facing = 1.0 + (pn * t_norm).sum(1)
        hv, _ = head_pb(R, coeffs, transl)
        q = hv[:, head_pair[1]] - hv[:, head_pair[0]]
        q = q / q.norm(dim=-1, keepdim=True)
        to = t_centre - hv[:, head_pair[1]]
        to = to / to.norm(dim=-1, keepdim=True)
        e_gaze = 1.0 - (q * to).sum(1)
        e_prior = ((delta ** 2).sum(-1) * prior_w).sum(1)
        wrist_aa = _rotation_angle(R[:, J["right_wrist"]])
        e_lim = torch.relu(wrist_aa - np.deg2rad(wrist_limit_deg)) ** 2
        E = (w.colli * e_colli + w.colli_obj * e_obj + w.contact * e_cont + w.anchor * e_anchor + w.facing * e_facing
             + w.gaze * e_gaze + e_prior + w.limits * e_lim)
        if history is not None:
            history.append({k: float(x.detach().mean()) for k, x in (("total", E), ("colli", e_colli), ("colli_obj", e_obj),
                            ("contact", e_cont), ("anchor", e_anchor), ("facing", e_facing), ("gaze", e_gaze),
                            ("prior", e_prior), ("limits", e_lim))})
        if it == steps:
            break
        opt.zero_grad()
        E.sum().backward()
        opt.step()
        sched.step()
    with torch.no_grad():
        R = rot0.clone()
        R[:, free_t] = rot0[:, free_t] @ axis_angle_to_matrix(delta)
    return R


def _rotation_angle(R: Tensor) -> Tensor:
    """Rotation angle (B,) of matrices (B,3,3), safe near 0 and pi."""
    c = ((R[..., 0, 0] + R[..., 1, 1] + R[..., 2, 2] - 1.0) * 0.5).clamp(-1 + 1e-6, 1 - 1e-6)
    return torch.arccos(c)


def _hand_normal_helper(hm: HandModel):
    """A function: fit vertices (B,n,3) -> unit outward normals (B,n_hand,3) of the hand vertices (from the mesh faces
    among the hand vertices; differentiable)."""
    faces = hm.bm.faces.numpy()
    pos = -np.ones(hm.bm.num_vertices, np.int64)
    pos[hm.hand_ids] = np.arange(hm.n_hand)
    keep = (pos[faces] >= 0).all(1)
    f = torch.as_tensor(pos[faces[keep]])

    def normals(v: Tensor) -> Tensor:
        vh = v[:, :hm.n_hand]
        a, b, c = vh[:, f[:, 0]], vh[:, f[:, 1]], vh[:, f[:, 2]]
        fn = torch.cross(b - a, c - a, dim=-1)
        n = torch.zeros_like(vh)
        for k in range(3):
            n = n.index_add(1, f[:, k], fn)
        return n / n.norm(dim=-1, keepdim=True).clamp_min(1e-12)
    return normals
