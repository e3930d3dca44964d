"""WANDR's goal-grid evaluation (§4.2-4.3, Tab. 1-2, Fig. 5): every goal of a cylinder around the body, from held-out
start poses, several samples each, the full 8 s always (no early stop).

    starts = held_out_starts(...)                                  # 6 start poses, canonical (pelvis at 0, facing +x)
    res = evaluate_grid(model, starts, bm, n=5, seed=0)            # 6 x 125 x 5 = 3,750 rollouts, one batch
    summary(res)                                                   # {'SR': %, 'FS': %, 'DTG': cm, ...}
    breakdown(res, "height")                                       # SR per goal height (Fig. 5)

Grid (§4.2): angles 0, 72, 144, 216, 288 deg from the start's facing direction (counter-clockwise seen from above);
heights 0, 0.45, 0.9, 1.35, 1.8 m above the ground; distances 0.5, 1.625, 2.75, 3.875, 5 m from the start's pelvis on
the ground; 240 frames (8 s at 30 fps: the start and 239 generated frames), t_G = frame 239. The paper gives the
ranges and counts; equal steps, the angles' origin and t_G at the last frame are graspkit's reading.
Metrics (§4.3): SR, the share of motions whose right wrist comes within 10 cm of the goal at any frame; FS, per motion
the share of frame pairs whose lowest mesh vertex moves more than 0.66 cm horizontally to the next frame, averaged
over motions; DTG, the closest the wrist gets to the goal (cm), averaged.

FS is computed on the fly, frame by frame, without building meshes (`LowVertices`): the lowest vertex is searched
among the foot and hand vertices (those skinned mostly to ankles and feet, or to a wrist and its fingers), posed
exactly by linear blend skinning from the body joints' transforms (the fingers keep the start's pose; on a body model
whose feet or hands carry pose correctives, as a real SMPL-X file's do, the correctives are added from the pose's
features), a hand only where it can be lower than the feet. On 750 of the shipped model's grid rollouts the whole
mesh's lowest vertex was always one of them (a foot in 99.3 % of the frames, a right-hand fingertip at some floor
goals), and the FS equals the full-mesh FS (tests/test_wandr_eval.py checks both on floor goals).

Four extra columns, not the paper's (`summary`'s SR_grounded, floating, sunk and SR_not_sunk): SR counts a wrist on
the goal however the body got there, including with both feet off the floor or sunk into it, which the procedural
clips never show (their lowest vertex stays within 3 mm of it). SR_grounded counts only the frames where a foot is
within 5 cm of the floor (the lowest foot vertex; SAGA §4.2's heel height for skating), floating is the share of
frames where none is, sunk the share where the lowest foot vertex is more than 1 cm below the floor, and SR_not_sunk
counts only the frames where it is not.
"""
from __future__ import annotations

import math
import re
import shlex
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Sequence

import numpy as np
import torch
from torch import Tensor

from graspkit import intention as I
from graspkit.body.skeleton import JOINT_INDEX
from graspkit.checks import check_int, check_seed, check_type, count_type, nonneg_float, positive_float, seeded_rng
from graspkit.data.formats import clip_files
from graspkit.data.reaching import EVAL_DISTANCES, EVAL_FRAMES, EVAL_HEIGHTS, Start, evaluation_goals
from graspkit.data.wandr_dataset import FOOT_JOINTS, shaped_rest
from graspkit.metrics import SAGA_SKATE_HEEL_HEIGHT, WANDR_SKATE_THRESHOLD, WANDR_SUCCESS_RADIUS
from graspkit.models.blocks import evaluating
from graspkit.progress import hidden
from graspkit.state import keeps_torch_state

if TYPE_CHECKING:
    import argparse

    from matplotlib.figure import Figure

    from graspkit.body import BodyModel
    from graspkit.data.wandr_dataset import ClipSet
    from graspkit.models.wandr import WandrCVAE

FOOT_ON_FLOOR = SAGA_SKATE_HEEL_HEIGHT   # m: a foot within 5 cm of the floor touches it (SAGA §4.2's skating heels)
SUNK_DEPTH = 0.01                         # m: a lowest foot vertex more than 1 cm below the floor: the body has sunk

T_GOAL = EVAL_FRAMES - 1          # frame 239, the last of the 240 frames (8 s at 30 fps, the start frame counted)

# the paper's figures (Tab. 1 and Tab. 2): SR %, FS %, DTG cm
PAPER = {
    "WANDR": (32.0, 16.0, 24.8), "WANDR / reaching only (Circle)": (0.0, 56.0, 205.4),
    "WANDR / locomotion only (AMASS)": (16.0, 19.0, 48.0), "GOAL": (0.0, 29.0, 149.2),
    "WANDR (I^w)": (15.0, 13.0, 62.9), "WANDR (I^w + I^p)": (18.0, 17.0, 44.9), "WANDR (I^w + I^r)": (19.0, 19.0, 36.0),
    "VAE + opt": (3.0, 4.0, 217.0),
}


def validation_goals(n: int = 250, seed: int = 123) -> tuple[Tensor, np.ndarray]:
    """n goals (n, 3) drawn uniformly on the grid's cylinder (any angle, height 0-1.8 m, distance 0.5-5 m), not on its
    125 points, and their (angle deg, height m, distance m) rows (n, 3): model selection's goals."""
    rng = seeded_rng(seed)
    ang, hgt = rng.uniform(0.0, 2 * np.pi, n), rng.uniform(EVAL_HEIGHTS[0], EVAL_HEIGHTS[-1], n)
    dist = rng.uniform(EVAL_DISTANCES[0], EVAL_DISTANCES[-1], n)
    goals = torch.as_tensor(np.stack([dist * np.cos(ang), dist * np.sin(ang), hgt], 1), dtype=torch.float32)
    return goals, np.stack([np.degrees(ang), hgt, dist], 1)


def validation_score(model: WandrCVAE, starts: Sequence[I.StartPose], bm: BodyModel,
                     seed: int = 1) -> dict[str, float]:
    """SR / FS / DTG of one rollout per validation start and validation goal (8 s): the score that picks the epoch
    of `graspkit train wandr --select-val` (validation-split starts, goals off the grid; the test grid is not used)."""
    goals, cells = validation_goals()
    s = summary(evaluate_grid(model, starts, bm, n=1, seed=seed, goals=goals, cells=cells))   # keeps model's mode
    return {k: float(s[k]) for k in ("SR", "FS", "DTG")}


def grid_goals() -> tuple[Tensor, np.ndarray]:
    """The 125 goals (125, 3) around a canonical start (pelvis above the origin, facing +x) and their (angle deg,
    height m, distance m) rows (125, 3)."""
    rows = evaluation_goals(Start(0.0, 0.0, 0.0))
    goals = torch.as_tensor(np.stack([rows[:, 3], rows[:, 4], rows[:, 1]], 1), dtype=torch.float32)
    return goals, rows[:, :3]


FOOT_PARTS = tuple(FOOT_JOINTS)                 # ankles and feet: the vertices skinned mostly to them are the feet
WRISTS = (JOINT_INDEX["left_wrist"], JOINT_INDEX["right_wrist"])
BODY_FEATURES = 9 * (I.NUM_BODY - 1)            # the pose features of joints 1-21: rows 0-188 of posedirs
HAND_PARTS = ((WRISTS[0],) + tuple(range(25, 40)), (WRISTS[1],) + tuple(range(40, 55)))     # wrist + its fingers


class Skinned:
    """A few vertices `ids` of bodies with rest vertices v (S, V, 3) and joints J (S, 55, 3), posed exactly by LBS
    from the global rotations Rg (B, J', 3, 3) and world positions pos (B, J', 3) of the joints they are skinned to,
    their pose correctives (if any) added from the pose's features."""

    def __init__(self, weights: Tensor, ids: Tensor, v: Tensor, J: Tensor, posedirs: Tensor | None = None,
                 pose_feature: Tensor | None = None) -> None:
        """posedirs (486, 3, V) and the bodies' constant pose features (S, 486) (jaw, eyes and fingers; the 189 of
        the body joints come with each pose): the vertices' pose correctives, None when they carry none."""
        self.ids = ids
        w = weights[ids]
        self.joints = (w.sum(0) > 0).nonzero()[:, 0]
        self.w = w[:, self.joints]                                                      # (n, K)
        self.rest_v = v[:, ids].float()                                                 # (S, n, 3)
        self.rest_j = J[:, self.joints].float()                                         # (S, K, 3)
        self.pd = None
        if posedirs is not None and bool(posedirs[:, :, ids].abs().max() > 0):
            pd = posedirs[:, :, ids].float()                                            # (486, 3, n)
            self.pd = pd[:BODY_FEATURES]                                                # (189, 3, n): body joints
            self.rest_v = self.rest_v + torch.einsum("sp,pcn->snc", pose_feature[:, BODY_FEATURES:].float(),
                                                     pd[BODY_FEATURES:])               # + the constant part
            self.bound = 2.0 * self.pd.norm(dim=1).sum(0)                              # (n,) |delta_v| (|R - I| <= 2)
        self.xw = (self.w[None, :, :, None] * self.rest_v[:, :, None, :]).flatten(2)   # (S, n, 3K): w_vk x_v

    def delta(self, feature: Tensor | None, vertex: Tensor | None = None) -> Tensor | None:
        """Corrective offsets of the body joints' pose features (B, 189): (B, n, 3), or (B, 3) of one vertex per pose
        (`vertex` (B,)); None when the vertices carry no correctives."""
        if self.pd is None:
            return None
        if vertex is None:
            return torch.einsum("bp,pcn->bnc", feature, self.pd)
        return torch.einsum("bp,pcb->bc", feature, self.pd[:, :, vertex])

    def _affine(self, Rg: Tensor, pos: Tensor, body: Tensor) -> tuple[Tensor, Tensor]:
        """Skinning transforms x -> R_k x + t_k (B, K, 3, 3), (B, K, 3) of the K joints, for bodies `body` (B,)."""
        R = Rg[:, self.joints]
        t = pos[:, self.joints] - (R @ self.rest_j[body].unsqueeze(-1)).squeeze(-1)
        return R, t

    def heights(self, Rg: Tensor, pos: Tensor, body: Tensor, feature: Tensor | None = None) -> Tensor:
        """Heights (B, n) of the vertices of bodies `body` (B,) (indices into betas): z_v = sum_k w_vk (R_k[2] .
        (x_v + delta_v) + t_k^z), one small matrix product per body; feature (B, 189): the body joints' pose
        features, for the correctives delta_v (needed when the vertices carry them)."""
        R, t = self._affine(Rg, pos, body)
        Rz, tz = R[:, :, 2, :].flatten(1), t[:, :, 2]                                  # (B, 3K), (B, K)
        z = tz @ self.w.T                                                               # (B, n)
        for s in body.unique().tolist():
            rows = (body == s).nonzero()[:, 0]
            z[rows] += Rz[rows] @ self.xw[s].T
        d = self.delta(feature)
        if d is not None:
            z += ((self.w @ R[:, :, 2, :]) * d).sum(-1)                                 # sum_k w_vk R_k[2] . delta_v
        return z

    def points(self, Rg: Tensor, pos: Tensor, body: Tensor, vertex: Tensor | None = None,
               feature: Tensor | None = None) -> Tensor:
        """World positions of the vertices: all (B, n, 3), or one per pose (B, 3) (`vertex` (B,): indices into ids);
        feature as `heights`."""
        R, t = self._affine(Rg, pos, body)
        if vertex is None:
            x, w = self.rest_v[body], self.w                                            # (B, n, 3), (n, K)
            d = self.delta(feature)
            x = x if d is None else x + d
            moved = torch.einsum("bkij,bvj->bvki", R, x) + t[:, None]                  # (B, n, K, 3)
            return (moved * w[None, :, :, None]).sum(2)
        x, w = self.rest_v[body, vertex], self.w[vertex]                                # (B, 3), (B, K)
        d = self.delta(feature, vertex)
        x = x if d is None else x + d
        moved = (R @ x[:, None, :, None]).squeeze(-1) + t                               # (B, K, 3)
        return (moved * w[..., None]).sum(1)


class LowVertices:
    """The vertices that can be a standing or reaching body's lowest — its feet and its hands (the vertices skinned
    mostly to ankles and feet, or to a wrist and its fingers) — of bodies with betas (S, 10) and finger poses
    (full_pose (S, 55, 3) or (55, 3), local axis-angle as `Motion.poses`, hand mean not added; None: zeros), posed
    exactly by LBS from the 22 body joints' transforms: the generated poses hold those joints only, the fingers keep
    the start's pose (as `body_vertices`), so their transforms follow from the wrist's. A hand is posed only for the
    poses where it can be lower than the feet: its vertices lie within `reach` (S,) of its wrist (a bound from the
    rest shape: vertex-to-joint distances plus bone lengths along the tree)."""

    def __init__(self, bm: BodyModel, betas: Tensor, full_pose: Tensor | None = None) -> None:
        from graspkit.rotations import axis_angle_to_matrix

        weights = bm.lbs_weights.float()                                  # (V, 55)
        part = weights.argmax(1)
        ids = [torch.isin(part, torch.tensor(js)).nonzero()[:, 0] for js in (FOOT_PARTS,) + HAND_PARTS]
        every = torch.cat(ids)
        if bool((weights[every][:, 22:25] > 0).any()):
            raise ValueError("bm: foot or hand vertices skinned to the jaw or the eyes")
        betas = torch.as_tensor(betas).reshape(len(betas), -1)
        v, J = shaped_rest(bm, betas)
        pose = torch.zeros(55, 3) if full_pose is None else torch.as_tensor(full_pose).float()
        pose = pose.reshape(-1, 55, 3).expand(len(betas), -1, -1)
        self.finger_rot = axis_angle_to_matrix(pose.double()).float()                            # (S, 55, 3, 3)
        posedirs = bm.posedirs.view(-1, 3, bm.num_vertices) if bm.has_posedirs else None
        feature = (self.finger_rot[:, 1:] - torch.eye(3)).flatten(1)                             # (S, 486)
        self.feet, *self.hands = (Skinned(weights, i, v, J, posedirs, feature) for i in ids)
        self.correctives = any(p.pd is not None for p in (self.feet, *self.hands))
        self.ids = every                                                  # feet, left hand, right hand
        self.offsets = [0, len(ids[0]), len(ids[0]) + len(ids[1]), len(every)]
        self.parents = torch.as_tensor(bm.parents)
        depth: dict[int, int] = {}
        for j in range(25, 55):                               # parents come before children in the SMPL-X order
            depth[j] = 1 + depth.get(int(self.parents[j]), 0)
        self.levels = [torch.tensor([j for j in depth if depth[j] == d]) for d in sorted(set(depth.values()))]
        self.bone = (J - J[:, self.parents.clamp(min=0)]).float()                                # (S, 55, 3)
        self.reach = [self._reach(h, w, J) for h, w in zip(self.hands, WRISTS)]

    def _reach(self, hand: Skinned, wrist: int, J: Tensor) -> Tensor:
        """(S,) a bound on how far a hand vertex lies from its wrist in any pose: |x_v - pos_w| <= sum_k w_vk
        (|x_v - J_k| + the tree path from joint k to the wrist) + |delta_v|, bones keeping their rest lengths (x_v the
        rest vertex, delta_v its pose corrective)."""
        length = self.bone.double().norm(dim=-1)                             # (S, 55) bone lengths (the root's: 0)

        def up(j: int) -> list[int]:
            chain = [j]
            while chain[-1] > 0:
                chain.append(int(self.parents[chain[-1]]))
            return chain

        path = []
        for k in hand.joints.tolist():
            a, b = up(k), up(wrist)
            common = next(j for j in a if j in b)
            path.append(length[:, a[:a.index(common)]].sum(1) + length[:, b[:b.index(common)]].sum(1))
        path = torch.stack(path, 1)                                                              # (S, K)
        to_joint = (hand.rest_v[:, :, None].double() - J[:, None, hand.joints]).norm(dim=-1)    # (S, n, K)
        r = (hand.w[None].double() * (to_joint + path[:, None])).sum(-1)                        # (S, n)
        return (r if hand.pd is None else r + hand.bound.double()).amax(1).float()

    def with_fingers(self, Rg: Tensor, pos: Tensor, body: Tensor) -> tuple[Tensor, Tensor]:
        """Global rotations (B, 55, 3, 3) and world positions (B, 55, 3) of the body joints (B, 22, ...) and the
        fingers below them: R_j = R_parent r_j, t_j = t_parent + R_parent (J_j - J_parent) (jaw and eyes left zero)."""
        B = len(Rg)
        Rg = torch.cat([Rg, Rg.new_zeros(B, 33, 3, 3)], 1)
        pos = torch.cat([pos, pos.new_zeros(B, 33, 3)], 1)
        for lv in self.levels:
            Rp, tp = Rg[:, self.parents[lv]], pos[:, self.parents[lv]]
            pos[:, lv] = tp + (Rp @ self.bone[body[:, None], lv].unsqueeze(-1)).squeeze(-1)
            Rg[:, lv] = Rp @ self.finger_rot[body[:, None], lv]
        return Rg, pos

    def feature(self, local: Tensor) -> Tensor | None:
        """The body joints' pose features (B, 189) of local rotations (B, 22, 3, 3), None without correctives."""
        return (local[:, 1:] - torch.eye(3)).flatten(1) if self.correctives else None

    def lowest(self, Rg: Tensor, pos: Tensor, body: Tensor, previous: Tensor | None = None,
               local: Tensor | None = None) -> tuple[Tensor, Tensor, Tensor, Tensor | None]:
        """For poses with body-joint rotations Rg (B, 22, 3, 3) and positions pos (B, 22, 3): the lowest of the
        vertices (B,) (an index into ids), its position (B, 3), the lowest foot vertex's height (B,), and where the
        vertices `previous` (B,) (indices into ids, e.g. the last frame's lowest) are now (B, 3). local: the local
        rotations (B, 22, 3, 3), needed for a body model whose feet or hands carry pose correctives."""
        if self.correctives and local is None:
            raise ValueError("local: the body model's feet or hands carry pose correctives; pass the local rotations")
        f = self.feature(local) if local is not None else None
        RgA, posA = self.with_fingers(Rg, pos, body) if bool((self.feet.joints >= I.NUM_BODY).any()) else (Rg, pos)
        z = self.feet.heights(RgA, posA, body, f)
        low, best = z.min(1)
        foot_low = low.clone()
        at = self.feet.points(RgA, posA, body, best, f)
        was = None
        if previous is not None:
            was = torch.zeros(len(body), 3)
            feet = previous < self.offsets[1]
            was[feet] = self.feet.points(RgA[feet], posA[feet], body[feet], previous[feet],
                                         None if f is None else f[feet])
        for h, (hand, wrist) in enumerate(zip(self.hands, WRISTS)):
            a, b = self.offsets[h + 1], self.offsets[h + 2]
            maybe = pos[:, wrist, 2] - self.reach[h][body] <= low + 1e-4
            mine = (previous >= a) & (previous < b) if previous is not None else torch.zeros_like(maybe)
            rows = (maybe | mine).nonzero()[:, 0]
            if not len(rows):
                continue
            RgF, posF = self.with_fingers(Rg[rows], pos[rows], body[rows])
            fr = None if f is None else f[rows]
            zh, ih = hand.heights(RgF, posF, body[rows], fr).min(1)
            lower = zh < low[rows]
            r = rows[lower]
            low[r], best[r] = zh[lower], ih[lower] + a
            at[r] = hand.points(RgF[lower], posF[lower], body[r], ih[lower], None if fr is None else fr[lower])
            if previous is not None:
                m = mine[rows]
                was[rows[m]] = hand.points(RgF[m], posF[m], body[rows[m]], previous[rows[m]] - a,
                                           None if fr is None else fr[m])
        return best, at, foot_low, was


@dataclass
class GridResult:
    """Per rollout (B = S * G * n, start-major): start, goal and sample index, the goal's (angle, height, distance),
    closest wrist distance (m), first frame within 10 cm (-1: never), share of skating frame pairs, wrist error at t_G."""

    start: np.ndarray
    goal_index: np.ndarray
    sample: np.ndarray
    cell: np.ndarray
    dtg: np.ndarray
    reach_frame: np.ndarray
    fs: np.ndarray
    error_at_goal: np.ndarray
    info: dict[str, Any] = field(default_factory=dict)
    grounded: np.ndarray | None = None      # (B,) bool: within 10 cm at a frame with a foot on the floor (not the paper's)
    floating: np.ndarray | None = None      # (B,) share of frames with both feet off the floor (lowest foot vertex > 5 cm)
    sunk: np.ndarray | None = None          # (B,) share of frames with the lowest foot vertex > 1 cm below the floor
    unsunk: np.ndarray | None = None        # (B,) bool: within 10 cm at a frame with no foot > 1 cm below the floor

    @property
    def success(self) -> np.ndarray:
        """Right wrist within 10 cm of the goal at some frame (B,) bool."""
        return self.dtg <= WANDR_SUCCESS_RADIUS


class GridMeter:
    """A `rollout` frame hook that accumulates SR / DTG / FS per sequence without storing the motion."""

    def __init__(self, low: LowVertices, body: Tensor, rest: Tensor, goals: Tensor, t_goal: int) -> None:
        """The feet and hands `low` of bodies `body` (B,) (indices into its betas), rest joints (B, 22, 3), goals
        (B, 3), t_G frame."""
        self.low, self.body, self.rest, self.goals, self.t_goal = low, body, rest, goals, t_goal
        B = len(body)
        self.dtg = torch.full((B,), float("inf"))
        self.reach = torch.full((B,), -1, dtype=torch.long)
        self.skate = torch.zeros(B)
        self.pairs = 0
        self.err = torch.full((B,), float("nan"))
        self.grounded = torch.zeros(B, dtype=torch.bool)
        self.floating = torch.zeros(B)
        self.sunk = torch.zeros(B)
        self.unsunk = torch.zeros(B, dtype=torch.bool)
        self.frames = 0
        self._lowest: Tensor | None = None
        self._at = torch.zeros(B, 3)

    def __call__(self, k: int, p: Tensor, joints: Tensor, Rg: Tensor) -> None:
        """Account for frame k: poses p (B, 135), joints (B, 22, 3), global rotations Rg (B, 22, 3, 3)."""
        with torch.no_grad():
            d = (joints[:, I.WRIST] - self.goals).norm(dim=-1)
            self.dtg = torch.minimum(self.dtg, d)
            hit = (d <= WANDR_SUCCESS_RADIUS) & (self.reach < 0)
            self.reach[hit] = k
            if k == self.t_goal:
                self.err = d.clone()
            local = I.pose_rotmats(p)[1] if self.low.correctives else None
            lowest, at, foot_low, now = self.low.lowest(Rg, joints, self.body, self._lowest, local)
            if now is not None:                # the vertex lowest at the previous frame: its horizontal move
                move = (now[:, :2] - self._at[:, :2]).norm(dim=-1)
                self.skate += (move > WANDR_SKATE_THRESHOLD).float()
                self.pairs += 1
            self._lowest, self._at = lowest, at
            on_floor = foot_low <= FOOT_ON_FLOOR
            self.grounded |= (d <= WANDR_SUCCESS_RADIUS) & on_floor
            self.floating += (~on_floor).float()
            self.sunk += (foot_low < -SUNK_DEPTH).float()
            self.unsunk |= (d <= WANDR_SUCCESS_RADIUS) & (foot_low >= -SUNK_DEPTH)
            self.frames += 1


def evaluate_grid(model: WandrCVAE, starts: Sequence[I.StartPose], bm: BodyModel, n: int = 5, seed: int = 0,
                  goals: Tensor | None = None, cells: np.ndarray | None = None, t_goal: int = T_GOAL,
                  frames: int | None = None, floor: float | None = None, lift: bool = False,
                  progress: bool = False) -> GridResult:
    """Roll the model out on the grid (or `goals` (G, 3) with their `cells` rows) from every start, n samples each,
    all in one batch (torch.Generator seeded with `seed`), measuring on the fly; floor, lift: `rollout`'s floor
    constraints (off: the paper's rollout); progress: a bar over the frames (the full grid: 15-30 s on two cores)."""
    from tqdm.auto import tqdm

    from graspkit.models.wandr import expand_starts, rollout

    if goals is None:
        goals, cells = grid_goals()
    cells = np.zeros((len(goals), 3)) if cells is None else np.asarray(cells)
    pp, p0, rest, g, idx = expand_starts(starts, goals, n)
    low = LowVertices(bm, torch.stack([s.betas for s in starts]), torch.stack([s.full_pose for s in starts]))
    meter = GridMeter(low, idx[:, 0], rest, g, t_goal)
    gen = torch.Generator().manual_seed(seed)
    F = frames if frames is not None else t_goal
    with tqdm(total=F + 1, desc="WANDR grid", unit="frame", disable=hidden(progress)) as bar:
        def on_frame(k: int, *state: Tensor) -> None:
            meter(k, *state)
            bar.update()

        with torch.no_grad(), evaluating(model):
            rollout(model, pp, p0, rest, g, t_goal, F, generator=gen, keep=False, on_frame=on_frame, floor=floor,
                    lift=lift)
    return _result(meter, idx, cells)


def _result(meter: GridMeter, idx: Tensor, cells: np.ndarray) -> GridResult:
    """GridResult from a finished meter."""
    gi = idx[:, 1].numpy()
    return GridResult(idx[:, 0].numpy(), gi, idx[:, 2].numpy(), cells[gi], meter.dtg.double().numpy(),
                      meter.reach.numpy(), (meter.skate / max(meter.pairs, 1)).double().numpy(),
                      meter.err.double().numpy(), grounded=meter.grounded.numpy(),
                      floating=(meter.floating / max(meter.frames, 1)).double().numpy(),
                      sunk=(meter.sunk / max(meter.frames, 1)).double().numpy(), unsunk=meter.unsunk.numpy())


def evaluate_motions(p: Tensor, rest: Tensor, goals: Tensor, betas: Tensor, bm: BodyModel, t_goal: int = T_GOAL,
                     cells: np.ndarray | None = None, index: Tensor | None = None,
                     full_pose: Tensor | None = None, full_mesh: bool = False) -> GridResult:
    """Score given motions p (B, T, 135) with rest joints (B, 22, 3), goals (B, 3) and betas (B, 10) the same way;
    full_pose (B, 55, 3) or (55, 3): the fingers' local pose (as `StartPose.full_pose`; None: zeros). cells: the
    (angle, height, distance) table indexed by goal, i.e. by `index`'s goal column (B, 3) = (start, goal, sample);
    without `index` the motions are goals 0..B-1.

    FS follows the lowest of the feet and hands vertices, as the grid does: exact for standing, walking and reaching
    bodies, not for one that lies, sits or kneels; full_mesh=True measures FS on every vertex of the posed mesh
    (`graspkit.metrics.foot_skating_wandr`; slower) for such motions."""
    if p.dim() != 3 or p.shape[-1] != I.POSE_DIM or p.shape[1] < 2:
        raise ValueError(f"p: expected (B, T >= 2, 135) poses (FS needs a frame pair), got {tuple(p.shape)}")
    B, T = p.shape[:2]
    meter = GridMeter(LowVertices(bm, betas, full_pose), torch.arange(B), rest, goals, t_goal)
    with torch.no_grad():
        for k in range(T):
            Rg, J = I.body_transforms(p[:, k], rest)
            meter(k, p[:, k], J, Rg)
    if full_mesh:
        from graspkit.metrics import foot_skating_wandr

        fp = (torch.zeros(55, 3) if full_pose is None else torch.as_tensor(full_pose).float()).reshape(-1, 55, 3)
        for b in range(B):
            v = _pose_vertices(bm, p[b], torch.as_tensor(betas)[b], fp[b if len(fp) > 1 else 0])
            meter.skate[b] = float(foot_skating_wandr(v).sum())
    idx = index if index is not None else torch.stack([torch.zeros(B, dtype=torch.long), torch.arange(B),
                                                       torch.zeros(B, dtype=torch.long)], 1)
    return _result(meter, idx, cells if cells is not None else np.zeros((B, 3)))


def evaluate_planner(starts: Sequence[I.StartPose], bm: BodyModel, t_goal: int = T_GOAL, seed: int = 0) -> GridResult:
    """The procedural planner (graspkit.data.plan_reach) on the grid, one motion per goal and start body (it starts
    standing at rest, not from the start pose: it cannot take an arbitrary pose), scored as the model is."""
    from graspkit.data import plan_reach

    goals, cells = grid_goals()
    ps, rests, gs, bs, idx, hands = [], [], [], [], [], []
    for s_i, s in enumerate(starts):
        for g_i, goal in enumerate(goals):
            m = plan_reach(Start(0.0, 0.0, 0.0), goal.numpy(), t_goal, betas=s.betas.numpy(), seed=seed + g_i, bm=bm,
                           hold_frames=0)
            ps.append(I.pose_from_axis_angle(torch.as_tensor(m.trans), torch.as_tensor(m.poses)))
            rests.append(s.rest)
            gs.append(goal)
            bs.append(s.betas)
            idx.append((s_i, g_i, 0))
            hands.append(torch.as_tensor(m.poses[0], dtype=torch.float32))   # the planner holds its fingers still
    return evaluate_motions(torch.stack(ps), torch.stack(rests), torch.stack(gs), torch.stack(bs), bm, t_goal, cells,
                            torch.tensor(idx), torch.stack(hands))


@torch.no_grad()
def evaluate_clips(model: WandrCVAE, clips: ClipSet, seed: int = 0, after_s: float = 1.0) -> dict[str, float]:
    """The model on held-out reaching clips (a ClipSet of goal clips, e.g. the test split's): from each clip's frames
    0-1 towards its own goal at its own goal frame (the timing of the data, not the grid's 8 s), all in one batch. SR
    (%: the wrist within 10 cm at any frame up to `after_s` seconds past t_G), DTG (cm, the closest over the same
    frames) and the wrist error at t_G (cm)."""
    from graspkit.models.wandr import rollout

    if len(clips) == 0 or bool((clips.goal_frame < 2).any()):
        raise ValueError("clips: expected reaching clips, each with a goal frame >= 2")
    p_prev = torch.stack([clips.clip(c)[0] for c in range(len(clips))])
    p0 = torch.stack([clips.clip(c)[1] for c in range(len(clips))])
    tg = clips.goal_frame - 1                        # counted from frame 1, the rollout's frame 0
    extra = int(round(after_s * I.FPS))
    with evaluating(model):
        out = rollout(model, p_prev, p0, clips.rest, clips.goal, tg, int(tg.max()) + extra,
                      generator=torch.Generator().manual_seed(seed))
    d = (out.joints[:, :, I.WRIST] - clips.goal[:, None]).norm(dim=-1)             # (B, T)
    d = d.masked_fill(torch.arange(d.shape[1])[None] > (tg + extra)[:, None], float("inf"))
    dmin = d.min(1).values
    return {"SR": 100 * float((dmin <= WANDR_SUCCESS_RADIUS).float().mean()), "DTG": 100 * float(dmin.mean()),
            "error_at_goal": 100 * float(d[torch.arange(len(tg)), tg].mean()), "clips": len(tg)}


def goal_row_schedules(n: int, legs: int = 3, seed: int = 0, spacing: tuple[float, float] = (0.8, 2.5),
                       heights: tuple[float, float] = (0.3, 1.6)) -> Tensor:
    """n random schedules of `legs` goals (n, legs, 3) around a canonical start (pelvis above the origin): each goal
    `spacing` m (uniform) from the one before in a uniform direction (the first from the start), `heights` m high."""
    check_int(n, "n", least=1)
    check_int(legs, "legs", least=1)
    for name, (lo, hi), least in (("spacing", spacing, 0.0), ("heights", heights, 0.0)):
        if not (math.isfinite(lo) and math.isfinite(hi) and least <= lo <= hi):
            raise ValueError(f"{name}: expected (low, high) in metres with {least:g} <= low <= high, got {(lo, hi)}")
    rng = seeded_rng(seed)
    out = np.zeros((n, legs, 3))
    for k in range(n):
        pos = np.zeros(2)
        for j in range(legs):
            a, d = rng.uniform(-np.pi, np.pi), rng.uniform(*spacing)
            pos = pos + d * np.array([np.cos(a), np.sin(a)])
            out[k, j] = (pos[0], pos[1], rng.uniform(*heights))
    return torch.as_tensor(out, dtype=torch.float32)


def evaluate_goal_rows(model: WandrCVAE, starts: Sequence[I.StartPose], per_start: int = 40, legs: int = 3,
                       leg_frames: int = 90, seed: int = 0, lift: bool = False) -> dict[str, Any]:
    """Several goals in a row (Sup. C.2; not a protocol of the paper): per start, `per_start` schedules of
    `goal_row_schedules` (seeded with `seed`), goal k due at frame (k+1) * leg_frames (`goal_schedule`), one rollout
    each, all in one batch. A goal counts as reached when the right wrist comes within 10 cm of it in its own window
    (the frames after the previous goal's frame up to its own). Returns SR per goal (%), all reached (%), the mean
    closest distance per goal (cm) and `closest` (B, legs) in m."""
    from graspkit.models.wandr import goal_schedule, rollout

    if len(starts) == 0:
        raise ValueError("starts: expected at least one start pose")
    check_int(per_start, "per_start", least=1)
    check_int(leg_frames, "leg_frames", least=2)
    goals = goal_row_schedules(per_start * len(starts), legs, seed)
    t_goals = [(k + 1) * leg_frames for k in range(legs)]
    frames = t_goals[-1]
    g, tg = map(torch.stack, zip(*[goal_schedule(row, t_goals, frames) for row in goals]))
    st = [s for s in starts for _ in range(per_start)]
    with torch.no_grad(), evaluating(model):
        out = rollout(model, torch.stack([s.p_prev for s in st]), torch.stack([s.p for s in st]),
                      torch.stack([s.rest for s in st]), g, tg, frames, generator=torch.Generator().manual_seed(seed),
                      lift=lift)
    d = (out.joints[:, :, I.WRIST] - g).norm(dim=-1)                   # (B, frames + 1): to the active goal
    lo = [0] + [t + 1 for t in t_goals[:-1]]
    closest = torch.stack([d[:, a:b + 1].min(1).values for a, b in zip(lo, t_goals)], 1)
    ok = closest <= WANDR_SUCCESS_RADIUS
    return {"SR_per_goal": (100 * ok.float().mean(0)).tolist(), "SR_all": 100 * float(ok.all(1).float().mean()),
            "closest_cm": (100 * closest.mean(0)).tolist(), "rollouts": len(st), "closest": closest}


def summary(res: GridResult) -> dict[str, float]:
    """SR (%), FS (%), DTG (cm, mean), the median DTG (cm), the mean wrist error at t_G (cm), the time to goal (s: the
    first frame within 10 cm, mean over successful motions; nan when none) and the rollout count; graspkit's extra
    columns where measured (% : SR_grounded, floating, sunk (the frames with a foot more than 1 cm under the floor) and
    SR_not_sunk (reached at a frame with no foot more than 1 cm under it))."""
    hit = res.reach_frame >= 0
    ttg = float(res.reach_frame[hit].mean()) / I.FPS if hit.any() else float("nan")
    err = res.error_at_goal[np.isfinite(res.error_at_goal)]      # none when the motions end before t_G
    out = {"SR": 100 * float(res.success.mean()), "FS": 100 * float(res.fs.mean()), "DTG": 100 * float(res.dtg.mean()),
           "DTG_median": 100 * float(np.median(res.dtg)),
           "error_at_goal": 100 * float(err.mean()) if err.size else float("nan"),
           "time_to_goal_s": ttg, "rollouts": int(len(res.dtg))}
    if res.grounded is not None and res.floating is not None:     # graspkit's extra columns (not the paper's)
        out.update(SR_grounded=100 * float(res.grounded.mean()), floating=100 * float(res.floating.mean()))
    if res.sunk is not None and res.unsunk is not None:
        out.update(sunk=100 * float(res.sunk.mean()), SR_not_sunk=100 * float(res.unsunk.mean()))
    return out


def breakdown(res: GridResult, by: str) -> dict[float, float]:
    """SR (%) per goal angle (deg), height (m) or distance (m) (Fig. 5)."""
    col = {"angle": 0, "height": 1, "distance": 2}
    if by not in col:
        raise ValueError(f"by: expected one of {list(col)}, got {by!r}")
    v = res.cell[:, col[by]]
    return {float(u): 100 * float(res.success[np.isclose(v, u)].mean()) for u in np.unique(v)}


def table(rows: dict[str, dict[str, float]], paper: dict[str, tuple[float, float, float]] = PAPER) -> str:
    """A markdown table of ours beside the paper's figures (SR ↑, FS ↓, DTG ↓)."""
    out = ["| method | SR % (ours) | FS % (ours) | DTG cm (ours) | SR % (paper) | FS % (paper) | DTG cm (paper) |",
           "|---|---|---|---|---|---|---|"]
    for name, s in rows.items():
        base = paper_row(name, paper)
        p = paper.get(base) if base else None
        ref = " | ".join(f"{x:g}" for x in p) if p else "— | — | —"
        label = name if base in (None, name) else f"{name} (paper: {base})"
        out.append(f"| {label} | {s['SR']:.1f} | {s['FS']:.1f} | {s['DTG']:.1f} | {ref} |")
    return "\n".join(out)


def paper_row(name: str, paper: dict[str, tuple[float, float, float]] = PAPER) -> str | None:
    """The paper's row a row name stands for: itself, or its variant's row without graspkit's suffixes (a data
    choice "[reach clips]", "+ floor constraint ...", "+ lift ...", a second checkpoint's "#2"); None where the paper
    has no such row."""
    if name in paper:
        return name
    base = re.sub(r" #\d+$", "", name)                 # another checkpoint of the variant (`graspkit eval wandr`)
    base = re.sub(r"( \+ (floor constraint|lift) .*)$", "", base)
    base = re.sub(r" \[[^\]]*\]$", "", base)
    return base if base in paper else None


# ----------------------------------------------------------------------------------------------------- variants, CLI
# Tab. 1 / Tab. 2 rows: which intention parts the condition keeps and which data the model learns from
VARIANTS: dict[str, dict[str, Any]] = {
    "wandr": {"intention": ("wrist", "orientation", "pelvis"), "kinds": ("locomotion", "reach"),
              "row": "WANDR"},
    "wandr_iw": {"intention": ("wrist",), "kinds": ("locomotion", "reach"), "row": "WANDR (I^w)"},
    "wandr_iw_ip": {"intention": ("wrist", "pelvis"), "kinds": ("locomotion", "reach"), "row": "WANDR (I^w + I^p)"},
    "wandr_iw_ir": {"intention": ("wrist", "orientation"), "kinds": ("locomotion", "reach"), "row": "WANDR (I^w + I^r)"},
    "wandr_loco": {"intention": ("wrist", "orientation", "pelvis"), "kinds": ("locomotion",),
                   "row": "WANDR / locomotion only (AMASS)"},
    "wandr_reach": {"intention": ("wrist", "orientation", "pelvis"), "kinds": ("reach",),
                    "row": "WANDR / reaching only (Circle)"},
    "wandr_noint": {"intention": (), "kinds": ("locomotion", "reach"), "row": "VAE + opt"},
}
STRIDE = {"locomotion": 8, "reach": 4}          # frames between training windows (both kinds: ~69k windows per epoch)


def starts_to_meta(starts: Sequence[I.StartPose]) -> dict[str, Any]:
    """Start poses as plain tensors and strings (for a weights-only checkpoint)."""
    return {k: torch.stack([getattr(s, k) for s in starts]) for k in ("p_prev", "p", "rest", "betas", "full_pose")} | {
        "source": [s.source for s in starts]}


def starts_body_problem(starts: Sequence[I.StartPose], bm: BodyModel, checkpoint: Any) -> str | None:
    """None when every held-out start was made on bm (`StartPose.made_on`); else why the grid cannot be run on bm: the
    rollout would move the starts' body while FS, SR and DTG were read on bm."""
    if all(s.made_on(bm) for s in starts):
        return None
    return (f"checkpoint: {checkpoint}'s held-out starts were made on another body model than {bm.source} "
            "(their rest joints differ; GRASPKIT_MODEL names the body evaluated): evaluate with the body it was "
            "trained on")


def starts_from_meta(meta: dict[str, Any]) -> list[I.StartPose]:
    """The held-out start poses stored in a checkpoint's meta."""
    s = meta.get("starts")
    if not s:
        raise ValueError("checkpoint: no held-out start poses in its meta (train it with `graspkit train wandr`)")
    return [I.StartPose(s["p_prev"][k], s["p"][k], s["rest"][k], s["betas"][k], s["full_pose"][k], s["source"][k])
            for k in range(len(s["source"]))]


def clipset_key(clips: ClipSet) -> str:
    """A short hash of every array of a ClipSet (poses, offsets, rest joints, betas, goals, goal frames, kinds) and its
    names: the training run's data key (a sum of the poses missed a moved goal and changes below its 7 digits)."""
    import hashlib

    h = hashlib.blake2b(digest_size=4)
    h.update("\n".join(clips.names).encode())
    for t in (clips.p, clips.offsets, clips.rest, clips.betas, clips.goal, clips.goal_frame, clips.kind):
        h.update(str((t.dtype, tuple(t.shape))).encode())
        h.update(t.detach().cpu().contiguous().numpy().tobytes())
    return h.hexdigest()


@keeps_torch_state
def run_train_wandr(variant: str = "wandr", folder: str | None = None, out: str | None = None, epochs: int = 6,
                    time_limit: float | None = None, seed: int = 0, threads: int = 2, batch_size: int = 512,
                    lr: float = 1e-3, progress: bool = True, max_steps: int = 10, ramp_epochs: int = 4,
                    stride_scale: int = 1, reach_far: bool = False, reach_chain: bool = False,
                    reach_near: bool = False, rollout_latent: str = "prior",
                    alpha_kl: float = 1e-2, kinds: Sequence[str] | None = None, goal_frame: str = "reach",
                    foot_weight: float = 0.0, select_val: bool = False, contact_weight: float = 0.0,
                    floor_weight: float = 0.0, init: str | None = None, window_stride: int | None = None,
                    rollout_grad: str = "through", step_stride: int = 1) -> dict[str, Any]:
    """Train one variant on the clips under `folder` (default <cache>/motion) and write a small checkpoint (with the
    normalisation statistics, the held-out start poses of the test split, and the measured times) to `out`.
    max_steps / ramp_epochs: the rollout schedule (Sup. B.2); stride_scale multiplies the window strides (fewer
    windows per epoch); window_stride sets the frames between windows directly, for every kind (instead of the scaled
    defaults; long rollouts leave few windows, 1 keeps them all); reach_far adds the room-scale reaching clips of
    <folder>/reach_far (docs/data.md; the shipped checkpoint uses them, docs/wandr.md), reach_chain those of
    <folder>/reach_chain (room-scale clips that start from a finished reach), reach_near those of <folder>/reach_near
    (near goals at the floor or overhead); rollout_latent: where the
    rollout steps draw z ("prior": Sup. B.2 read as sampling the prior; "posterior": the encoder on the true delta, see docs/wandr.md); alpha_kl: the KL
    weight α (§3.4: 1e-2); kinds: the clip kinds to train on instead of the variant's (e.g. ("reach",): the reaching
    and room-scale clips only, as the shipped checkpoint, docs/wandr.md); select_val: after every epoch score the
    model on the validation task (`validation_score`: six validation-split starts, 250 goals off the grid) and ship
    the best epoch's weights instead of the last (model selection; the scores go into meta["val"]); init: a WANDR
    checkpoint (save_wandr's file) to start from, weights and normalisation statistics, instead of a fresh model
    (continue training with another schedule, e.g. longer rollouts; the network's shape and intention must match).
    The resumable training state lives in <cache>/wandr, named by every setting."""
    import resource
    import time
    from pathlib import Path

    from graspkit.body import BodyModel
    from graspkit.data import load_motion
    from graspkit.data.wandr_dataset import (FOLDERS, cached_clips, compute_stats, held_out_starts, split_clips,
                                             test_start_names)
    from graspkit.models.wandr import WandrConfig, WandrCVAE, save_wandr, train_wandr
    from graspkit.paths import DATA_STUBS, cache_dir, default_model_path
    from graspkit.train import TrainConfig

    v = _variant_settings(variant, kinds, stride_scale, window_stride, select_val, time_limit)
    folder = Path(folder) if folder else cache_dir() / "motion"
    out = Path(out) if out else DATA_STUBS / "checkpoints" / f"{variant}.pt"
    torch.set_num_threads(threads)
    bm = BodyModel.from_file(default_model_path())
    t0 = time.perf_counter()
    extra = tuple(k for k, on in (("reach_far", reach_far), ("reach_chain", reach_chain), ("reach_near", reach_near))
                  if on)                                        # the opt-in clip folders
    clips = cached_clips(folder, bm, kinds=("locomotion", "reach") + extra)
    names = split_clips(clips.names, seed=0)["train"]
    train = clips.subset([n for n in names if FOLDERS.get(n.split("/")[0]) in v["kinds"]])
    stats = compute_stats(train, seed=seed, goal_frame=goal_frame)
    prep_s = time.perf_counter() - t0
    start_names = test_start_names(folder, n=6)
    starts = held_out_starts([load_motion(folder / n) for n in start_names], start_names, bm)
    torch.manual_seed(seed)
    model = WandrCVAE(WandrConfig(intention=v["intention"], max_steps=max_steps, ramp_epochs=ramp_epochs,
                                   rollout_latent=rollout_latent, alpha_kl=alpha_kl, goal_frame=goal_frame,
                                   w_foot=foot_weight, w_contact=contact_weight, w_floor=floor_weight,
                                   rollout_grad=rollout_grad, step_stride=step_stride), stats)
    init_model = None if init is None else _start_from(model, init)
    stride = {k: stride_scale * (s // 2 if len(v["kinds"]) == 1 else s) for k, s in STRIDE.items()}   # one kind: same epoch size
    if window_stride is not None:
        stride = {k: window_stride for k in STRIDE}
    cfg = TrainConfig(epochs=epochs, batch_size=batch_size, lr=lr, seed=seed, num_threads=threads)
    flags = _experiment_flags(variant, v, extra, rollout_latent=rollout_latent, alpha_kl=alpha_kl,
                              rollout_grad=rollout_grad, step_stride=step_stride, goal_frame=goal_frame,
                              foot_weight=foot_weight, contact_weight=contact_weight, floor_weight=floor_weight,
                              select_val=select_val, init=init, window_stride=window_stride)
    tag = (f"e{epochs}_b{batch_size}_lr{lr:g}_m{max_steps}_r{ramp_epochs}_x{stride_scale}_d{clipset_key(train)}"
           + "".join(t for _, t in flags))                       # other clips (or goals) never resume this run
    ck = cache_dir() / "wandr" / f"train_{variant}_s{seed}_{tag}.pt"
    cpu0, t1 = resource.getrusage(resource.RUSAGE_SELF), time.perf_counter()
    if select_val:
        history, val = _train_selecting(model, train, cfg, ck, stride, progress, folder, bm)
    else:
        history, val = train_wandr(model, train, cfg, checkpoint=ck, stride=stride, progress=progress,
                                   time_limit_s=time_limit), None
    cpu1 = resource.getrusage(resource.RUSAGE_SELF)
    meta = {"variant": variant, "row": v["row"], "kinds": list(v["kinds"]), "train_clips": len(train),
            "train_frames": int(train.lengths.sum()), "epochs": len(history), "train_wall_s": time.perf_counter() - t1,
            "train_cpu_s": (cpu1.ru_utime + cpu1.ru_stime) - (cpu0.ru_utime + cpu0.ru_stime), "prep_wall_s": prep_s,
            "threads": threads, "batch_size": batch_size, "lr": lr, "stride": stride, "seed": seed,
            "command": f"graspkit train wandr --variant {variant} --epochs {epochs} --batch-size {batch_size} "
                       f"--lr {lr:g} --max-steps {max_steps} --ramp-epochs {ramp_epochs} --stride-scale {stride_scale} "
                       f"--seed {seed} --threads {threads}" + "".join(c for c, _ in flags),
            "load_avg_end": float(__import__("os").getloadavg()[0]), "starts": starts_to_meta(starts),
            **({"init": str(init), "init_command": init_model.meta.get("command", "")}
               if init_model is not None else {}),
            **({"val": val["scores"], "selected_epoch": val["best"]} if val else {})}
    earlier = [] if init_model is None else (init_model.meta.get("stages") or [
        _stage_record(init_model.meta, init_model.history, init_model.cfg.max_steps)])
    meta["stages"] = earlier + [_stage_record(meta, history, max_steps)]
    save_wandr(out, model, history, meta)
    return {"out": out, **{k: meta[k] for k in ("epochs", "train_wall_s", "train_cpu_s")}, "history": history}


def _variant_settings(variant: str, kinds: Sequence[str] | None, stride_scale: int, window_stride: int | None,
                      select_val: bool, time_limit: float | None) -> dict[str, Any]:
    """run_train_wandr's arguments checked before any data loads; the variant's settings (VARIANTS) with `kinds`
    (the clip kinds to train on) in place of its own, its row named by them."""
    from graspkit.data.wandr_dataset import KINDS

    if variant not in VARIANTS:
        raise ValueError(f"variant: expected one of {list(VARIANTS)}, got {variant!r}")
    if stride_scale < 1:
        raise ValueError(f"stride_scale: expected >= 1, got {stride_scale}")
    if window_stride is not None and window_stride < 1:
        raise ValueError(f"window_stride: expected >= 1, got {window_stride}")
    if select_val and time_limit is not None:
        raise ValueError("time_limit: not supported with select_val (every epoch is trained and scored)")
    v = dict(VARIANTS[variant])
    if kinds is not None:
        chosen = tuple(k for k in KINDS if k in kinds)
        if not chosen or len(chosen) != len(set(kinds)):
            raise ValueError(f"kinds: expected a non-empty subset of {KINDS}, got {kinds!r}")
        if chosen != v["kinds"]:
            v["kinds"], v["row"] = chosen, f"{v['row']} [{' + '.join(chosen)} clips]"
    return v


def _start_from(model: WandrCVAE, init: str) -> WandrCVAE:
    """Load the WANDR checkpoint `init`'s weights and normalisation statistics into `model` (a ValueError naming it
    when its network has another shape or intention); returns the loaded init model (its meta and history)."""
    from graspkit.models.wandr import load_wandr

    init_model = load_wandr(init)
    keys = ("latent", "hidden", "enc_layers", "dec_layers", "intention")
    shape = lambda c: {k: getattr(c, k) for k in keys}         # noqa: E731 - the network's shape of a config
    if shape(init_model.cfg) != shape(model.cfg):
        raise ValueError(f"init: {init} has another network ({shape(init_model.cfg)}) than this command's "
                         f"({shape(model.cfg)})")
    model.load_state_dict(init_model.state_dict())            # weights and the statistics it was trained with
    return init_model


def _experiment_flags(variant: str, v: dict[str, Any], extra: tuple[str, ...], *, rollout_latent: str,
                      alpha_kl: float, rollout_grad: str, step_stride: int, goal_frame: str, foot_weight: float,
                      contact_weight: float, floor_weight: float, select_val: bool, init: str | None,
                      window_stride: int | None) -> list[tuple[str, str]]:
    """The experiment flags away from their defaults, each as (command-line text, run-name part); the run name's
    data key covers the opt-in clip folders (`extra`), so they add no name part."""
    from graspkit.train import file_key

    return [(f" --{k.replace('_', '-')}", "") for k in extra] \
        + ([(f" --rollout-latent {rollout_latent}", "_zpost")] if rollout_latent != "prior" else []) \
        + ([(f" --alpha-kl {alpha_kl:g}", f"_a{alpha_kl:g}")] if alpha_kl != 1e-2 else []) \
        + ([(f" --rollout-grad {rollout_grad}", f"_rg{rollout_grad}")] if rollout_grad != "through" else []) \
        + ([(f" --step-stride {step_stride}", f"_ss{step_stride}")] if step_stride != 1 else []) \
        + ([(f" --goal-frame {goal_frame}", f"_g{goal_frame}")] if goal_frame != "reach" else []) \
        + ([(f" --foot-weight {foot_weight:g}", f"_f{foot_weight:g}")] if foot_weight else []) \
        + ([(f" --contact-weight {contact_weight:g}", f"_c{contact_weight:g}")] if contact_weight else []) \
        + ([(f" --floor-weight {floor_weight:g}", f"_h{floor_weight:g}")] if floor_weight else []) \
        + ([(" --select-val", "_val")] if select_val else []) \
        + ([(f" --init {shlex.quote(str(init))}", f"_i{file_key(init)}")] if init is not None else []) \
        + ([(f" --window-stride {window_stride}", f"_w{window_stride}")] if window_stride is not None else []) \
        + ([(f" --kinds {','.join(v['kinds'])}", f"_k{''.join(k[0] for k in v['kinds'])}")]
           if v["kinds"] != VARIANTS[variant]["kinds"] else [])


def _stage_record(meta: dict[str, Any], history: Sequence[dict], max_steps: int) -> dict[str, Any]:
    """One training command of a checkpoint's chain (`--init`): its command, times, rollout length, per-epoch losses
    and validation scores, so the last checkpoint carries the whole chain (meta["stages"])."""
    keys = ("command", "epochs", "train_wall_s", "train_cpu_s", "threads", "val", "selected_epoch")
    return {**{k: meta[k] for k in keys if k in meta}, "max_steps": int(max_steps), "history": list(history)}


@keeps_torch_state
def run_eval_wandr(checkpoint: str, n: int = 5, seed: int = 0, planner: bool = False, threads: int = 2,
                   clips_folder: str | None = None, floor: float | None = None, lift: bool = False) -> dict[str, Any]:
    """Evaluate a checkpoint on the full grid from its held-out starts; SR / FS / DTG and the Fig. 5 breakdowns; with
    clips_folder, also `evaluate_clips` on the test-split reaching clips there (reach/, and reach_far/ if present);
    floor, lift: `rollout`'s floor constraints (off: the paper's rollout)."""
    import time
    from pathlib import Path

    from graspkit.body import BodyModel
    from graspkit.models.wandr import load_wandr
    from graspkit.paths import default_model_path

    if clips_folder is not None and not any(clip_files(Path(clips_folder, s), s) for s in ("reach", "reach_far")):
        raise FileNotFoundError(f"clips_folder: no reaching clips in {clips_folder}/reach or reach_far "
                                f"(graspkit data make --kind reach --out {clips_folder}/reach)")
    torch.set_num_threads(threads)
    bm = BodyModel.from_file(default_model_path())
    model = load_wandr(checkpoint)
    starts = starts_from_meta(model.meta)
    problem = starts_body_problem(starts, bm, checkpoint)
    if problem:
        raise ValueError(problem)
    t0 = time.perf_counter()
    row = model.meta.get("row", "WANDR")
    if floor is not None:
        if not model.cfg.intention:
            raise ValueError("floor: not supported for VAE + opt (its latents are optimised without the constraint)")
        row = f"{row} + floor constraint {100 * floor:g} cm (not the paper's)"
    if lift:
        if not model.cfg.intention:
            raise ValueError("lift: not supported for VAE + opt (its latents are optimised without the constraint)")
        row = f"{row} + lift (not the paper's)"
    if model.cfg.intention:
        res = evaluate_grid(model, starts, bm, n=n, seed=seed, floor=floor, lift=lift, progress=True)
    else:                                  # "VAE + opt": no intention to steer, latents optimised per goal
        from graspkit.optim.latent import evaluate_vae_opt
        res = evaluate_vae_opt(model, starts, bm, seed=seed, progress=True)
    out = {"row": row, "config": {"checkpoint": str(checkpoint), "n": n, "seed": seed, "threads": threads,
                                  "floor": floor, "lift": lift, "starts": [s.source for s in starts]},
           "summary": summary(res), "seconds": time.perf_counter() - t0,
           "breakdown": {b: breakdown(res, b) for b in ("height", "angle", "distance")}}
    if planner:
        out["planner"] = summary(evaluate_planner(starts, bm))
    if clips_folder is not None:
        from graspkit.data.wandr_dataset import cached_clips, split_clips

        out["clips"] = {}
        for sub in ("reach", "reach_far"):
            if not clip_files(Path(clips_folder, sub), sub):
                continue
            cs = cached_clips(clips_folder, bm, kinds=(sub,))
            out["clips"][sub] = evaluate_clips(model, cs.subset(split_clips(cs.names)["test"]), seed=seed)
    return out


def _train_selecting(model, train, cfg, ck, stride, progress, folder, bm) -> tuple[list[dict], dict[str, Any]]:
    """Train one epoch at a time (train_wandr's stop_at: the same weights as one run), score each epoch with
    validation_score and keep the best (SR, then DTG); the scores and the best weights sit beside the training
    state (<ck>.val.pt, atomic), so a killed run resumes. Returns the history and {'scores', 'best'}; `model` ends
    with the best weights."""
    from graspkit.data import load_motion
    from graspkit.data.wandr_dataset import held_out_starts, test_start_names
    from graspkit.models.wandr import train_wandr
    from graspkit.train import load_checkpoint, save_checkpoint

    names = test_start_names(folder, n=6, split="val")
    starts = held_out_starts([load_motion(folder / n) for n in names], names, bm, n=len(names))
    rec_path = ck.with_suffix(".val.pt")
    rec = load_checkpoint(rec_path) if rec_path.is_file() else {"scores": [], "best": 0, "model": None}
    history: list[dict] = []
    for epoch in range(1, cfg.epochs + 1):
        if epoch <= len(rec["scores"]):
            continue
        history = train_wandr(model, train, cfg, checkpoint=ck, stride=stride, progress=progress, stop_at=epoch)
        if len(history) != epoch:
            raise RuntimeError(f"{ck}: the training state is at epoch {len(history)}, its validation record at "
                               f"{len(rec['scores'])}; remove both to start over")
        score = {"epoch": len(history), **validation_score(model, starts, bm)}
        best = rec["scores"][rec["best"] - 1] if rec["best"] else None
        if best is None or (score["SR"], -score["DTG"]) > (best["SR"], -best["DTG"]):
            rec["best"], rec["model"] = score["epoch"], {k: v.clone() for k, v in model.state_dict().items()}
        rec["scores"].append(score)
        save_checkpoint(rec_path, rec)
        if not hidden(progress):
            print(f"epoch {score['epoch']}: validation SR {score['SR']:.1f} %, FS {score['FS']:.1f} %, "
                  f"DTG {score['DTG']:.1f} cm (best: epoch {rec['best']})", flush=True)
    if not history:                         # everything was done before: the history is in the training state
        history = list(load_checkpoint(ck)["history"])
    model.load_state_dict(rec["model"])
    model.eval()
    return history, {"scores": rec["scores"], "best": rec["best"]}


def _cmd_train(args) -> int:
    """`graspkit train wandr`."""
    from graspkit.cli import as_flags, check_counts, check_file

    check_counts(args, max_steps=0, stride_scale=1, window_stride=1, step_stride=1)     # before the data loads
    if args.init is not None:
        check_file(args.init, "--init")
    with as_flags(kinds="--kinds", folder="--data"):
        info = run_train_wandr(args.variant, args.data, args.out, args.epochs, args.time_limit, args.seed,
                               args.threads, args.batch_size, args.lr, max_steps=args.max_steps,
                               ramp_epochs=args.ramp_epochs, stride_scale=args.stride_scale, reach_far=args.reach_far,
                               reach_chain=args.reach_chain, reach_near=args.reach_near,
                               rollout_latent=args.rollout_latent, alpha_kl=args.alpha_kl, goal_frame=args.goal_frame,
                               foot_weight=args.foot_weight, select_val=args.select_val,
                               contact_weight=args.contact_weight, floor_weight=args.floor_weight,
                               kinds=tuple(args.kinds.split(",")) if args.kinds else None, init=args.init,
                               window_stride=args.window_stride, rollout_grad=args.rollout_grad,
                               step_stride=args.step_stride)
    print(f"wrote {info['out']}: {info['epochs']} epochs in {info['train_wall_s']:.0f} s wall "
          f"({info['train_cpu_s']:.0f} s CPU); last loss {info['history'][-1]['loss']:.4f}")
    return 0


CACHE_CLIPS = Path("<cache>/motion")   # `eval wandr --clips` alone: the cache's clips, resolved when the command runs


def _cmd_eval(args) -> int:
    """`graspkit eval wandr`."""
    from graspkit.cli import as_flags, check_file, check_folders
    from graspkit.paths import cache_dir

    from graspkit.models.wandr import check_floor

    try:
        check_floor(args.floor)
    except ValueError:
        raise ValueError(f"--floor: expected a finite tolerance >= 0 in metres, got {args.floor}") from None
    for ck in args.checkpoint:                         # every one before the first is evaluated
        check_file(ck, "--checkpoint")
    if args.clips == CACHE_CLIPS:                      # --clips alone (resolved here: GRASPKIT_CACHE may be bad)
        args.clips = cache_dir() / "motion"
    check_folders(args.clips, "--clips")
    rows, extra = {}, {}
    for ck in args.checkpoint:
        with as_flags(clips_folder="--clips"):         # a folder without reaching clips
            r = run_eval_wandr(ck, args.n, args.seed, planner=args.planner and not extra, threads=args.threads,
                               clips_folder=args.clips, floor=args.floor, lift=args.lift)
        row, k = r["row"], 1
        while row in rows:                             # a variant's checkpoints (two seeds, say): one row each
            k += 1
            row = f"{r['row']} #{k}"
        rows[row] = r["summary"]
        print(f"{ck}: {row}: SR {r['summary']['SR']:.1f} %, FS {r['summary']['FS']:.1f} %, "
              f"DTG {r['summary']['DTG']:.1f} cm ({r['summary']['rollouts']} rollouts, {r['seconds']:.0f} s)")
        if "SR_grounded" in r["summary"]:
            print(f"  not the paper's: SR with a foot on the floor {r['summary']['SR_grounded']:.1f} %, frames with "
                  f"both feet off it {r['summary']['floating']:.1f} %"
                  + (f", with a foot more than 1 cm under it {r['summary']['sunk']:.1f} %; SR with no foot that deep "
                     f"{r['summary']['SR_not_sunk']:.1f} %" if "sunk" in r["summary"] else ""))
        for b, vals in r["breakdown"].items():
            print(f"  SR by {b}: " + ", ".join(f"{k:g}: {x:.0f} %" for k, x in vals.items()))
        for sub, c in r.get("clips", {}).items():
            print(f"  {c['clips']} test {sub} clips at their own goal frames: SR {c['SR']:.1f} %, DTG {c['DTG']:.1f} cm, "
                  f"wrist error at t_G {c['error_at_goal']:.1f} cm")
        if "planner" in r:
            extra["procedural planner"] = r["planner"]
    print(table({**rows, **extra}))
    return 0


def add_wandr_commands(train_sub: argparse._SubParsersAction, eval_sub: argparse._SubParsersAction) -> None:
    """`graspkit train wandr` and `graspkit eval wandr`."""
    from graspkit.cli import TIME_LIMIT_HELP
    from graspkit.data.wandr_dataset import GOAL_FRAMES

    t = train_sub.add_parser("wandr", help="train WANDR (or a Tab. 1 / Tab. 2 ablation) on the procedural clips")
    t.add_argument("--variant", choices=list(VARIANTS), default="wandr")
    t.add_argument("--data", type=Path, default=None, help="folder with locomotion/ and reach/ clips (default: cache)")
    t.add_argument("--out", type=Path, default=None, help="weights (default data_stubs/checkpoints/<variant>.pt)")
    t.set_defaults(out_is_file=True)
    t.add_argument("--epochs", type=int, default=6)
    t.add_argument("--time-limit", type=positive_float, default=None, help=TIME_LIMIT_HELP + " (default: none)")
    t.add_argument("--seed", type=int, default=0)
    t.add_argument("--threads", type=int, default=2)
    t.add_argument("--batch-size", type=int, default=512)
    t.add_argument("--lr", type=positive_float, default=1e-3)
    t.add_argument("--max-steps", type=int, default=10, help="rollout steps at the end of the ramp (Sup. B.2)")
    t.add_argument("--ramp-epochs", type=count_type(0), default=4, help="epochs over which the rollout grows from 0")
    t.add_argument("--stride-scale", type=int, default=1, help="multiply the window strides (shorter epochs)")
    t.add_argument("--window-stride", type=int, default=None,
                   help="frames between training windows, every kind (instead of the scaled defaults; 1: every frame)")
    t.add_argument("--rollout-latent", choices=("prior", "posterior"), default="prior",
                   help="z for the rollout steps: the prior (default, Sup. B.2) or the encoder on the truth")
    t.add_argument("--rollout-grad", choices=("through", "step"), default="through",
                   help="through: backpropagate through the rollout (default); step: roll out without gradient, "
                        "then one batched step with gradient from the visited states (not in the paper; measured: "
                        "faster steps, far lower SR, docs/wandr.md)")
    t.add_argument("--step-stride", type=int, default=1,
                   help="with --rollout-grad step: recompute every n-th rollout step with gradient (default 1: all)")
    t.add_argument("--alpha-kl", type=nonneg_float, default=1e-2, help="the KL weight (paper: 1e-2)")
    t.add_argument("--goal-frame", choices=GOAL_FRAMES, default="reach",
                   help="t_G of a reaching clip: the frame the hand arrives, or the end of the hold after it")
    t.add_argument("--foot-weight", type=nonneg_float, default=0.0,
                   help="weight of the foot-joint velocity term (not in the paper; mm^2 per frame; docs/wandr.md)")
    t.add_argument("--contact-weight", type=nonneg_float, default=0.0,
                   help="weight of the planted-foot term (not in the paper; mm^2 per frame; docs/wandr.md)")
    t.add_argument("--floor-weight", type=nonneg_float, default=0.0,
                   help="weight of the floor term: the lowest foot joint's height against the data's (not in the "
                        "paper; cm^2 per frame; docs/wandr.md)")
    t.add_argument("--init", type=Path, default=None,
                   help="start from this WANDR checkpoint's weights and statistics (e.g. longer rollouts after the "
                        "first schedule: the shipped checkpoint's second command, docs/wandr.md)")
    t.add_argument("--select-val", action="store_true",
                   help="score every epoch on validation-split starts and goals off the grid; keep the best epoch")
    t.add_argument("--reach-far", action="store_true",
                   help="also train on <data>/reach_far (room-scale reaching clips, as the shipped checkpoint; docs/wandr.md)")
    t.add_argument("--reach-chain", action="store_true",
                   help="also train on <data>/reach_chain (room-scale reaching clips that start from a finished reach: "
                        "goals in a row; docs/wandr.md)")
    t.add_argument("--reach-near", action="store_true",
                   help="also train on <data>/reach_near (room-scale reaching clips with a near goal at the floor or "
                        "overhead, the grid's weakest cells; docs/wandr.md)")
    t.add_argument("--kinds", default=None,
                   help="train on these clip kinds instead of the variant's: 'reach' (reaching + room-scale clips: the "
                        "shipped checkpoint), 'locomotion' or 'locomotion,reach'")
    t.set_defaults(func=_cmd_train)
    e = eval_sub.add_parser("wandr", help="WANDR's goal grid (SR / FS / DTG) for one or more checkpoints")
    e.add_argument("--checkpoint", type=Path, action="append", required=True)
    e.add_argument("--n", type=int, default=5, help="samples per start and goal")
    e.add_argument("--seed", type=int, default=0)
    e.add_argument("--planner", action="store_true", help="add the procedural planner's row")
    e.add_argument("--floor", type=float, default=None,
                   help="metres: hold the lowest foot joint at most this far above its start height while generating "
                        "(a floor constraint, not in the paper; docs/wandr.md)")
    e.add_argument("--lift", action="store_true",
                   help="raise a body whose lowest foot joint is below its start height back to it while generating "
                        "(against sinking into the floor; not in the paper; docs/wandr.md)")
    e.add_argument("--threads", type=int, default=2)
    e.add_argument("--clips", type=Path, nargs="?", const=CACHE_CLIPS, default=None,
                   help="also roll out towards the test-split reaching clips' own goals, at their own goal frames "
                        "(folder with reach/ [reach_far/]; default: <cache>/motion)")
    e.set_defaults(func=_cmd_eval)


# ----------------------------------------------------------------------------------------------------- meshes, widget
def body_vertices(bm: BodyModel, p: Tensor, start: I.StartPose, chunk: int = 64) -> Tensor:
    """Mesh vertices (T, V, 3) of generated poses p (T, 135) on the start's body; jaw, eyes and hands keep the start's
    pose (WANDR generates the 22 body joints only)."""
    return _pose_vertices(bm, p, start.betas, start.full_pose, chunk)


def _pose_vertices(bm, p: Tensor, betas: Tensor, full_pose: Tensor, chunk: int = 64) -> Tensor:
    """Mesh vertices (T, V, 3) of poses p (T, 135) on a body of betas (10,); joints 22-54 from full_pose (55, 3)."""
    from graspkit.rotations import axis_angle_to_matrix

    other = axis_angle_to_matrix(torch.as_tensor(full_pose)[I.NUM_BODY:].to(bm.dtype))
    out = []
    with torch.no_grad():
        for a in range(0, len(p), chunk):
            t, R = I.pose_rotmats(p[a:a + chunk].to(bm.dtype))
            rot = torch.cat([R, other.expand(len(R), -1, -1, -1)], 1)
            out.append(bm.forward_rotmats(rot, betas=torch.as_tensor(betas)[None].to(bm.dtype), transl=t).vertices)
    return torch.cat(out)


def goal_from_cylinder(angle_deg: float, distance: float, height: float) -> Tensor:
    """A goal (3,) around a canonical start: `angle_deg` counter-clockwise from its facing direction (+x), `distance`
    m from its pelvis on the ground, `height` m above the ground (the grid's coordinates)."""
    a = np.radians(angle_deg)
    return torch.tensor([distance * np.cos(a), distance * np.sin(a), height], dtype=torch.float32)


class GoalReacher:
    """Place a goal around a start pose and let the model reach it (lesson 09's widget). The callback `update` is plain
    Python (tested); `widget()` only wires ipywidgets sliders to it and shows the figure as PNG bytes in an Image."""

    SLIDERS = {"angle": (0.0, 360.0, 15.0), "distance": (0.3, 5.0, 0.1), "height": (0.0, 1.8, 0.05),
               "seconds": (1.0, 8.0, 0.5)}

    def __init__(self, model: WandrCVAE, start: I.StartPose, seed: int = 0, angle: float = 45.0, distance: float = 2.0,
                 height: float = 1.0, seconds: float = 4.0, floor: float | None = None) -> None:
        """The sliders' start values (in their ranges, SLIDERS); floor: `rollout`'s floor constraint (m; None: off,
        the paper's rollout). The sliders place the goal around a canonical start (pelvis above the origin, facing
        +x): any other start (`StartPose.from_motion`, say) is moved there first (`StartPose.canonical`)."""
        from graspkit.models.wandr import check_floor

        self.values = {k: self._checked(k, v) for k, v in
                       (("angle", angle), ("distance", distance), ("height", height), ("seconds", seconds))}
        check_type(start, I.StartPose, "start", what="graspkit.intention.StartPose")
        check_floor(floor)
        self.model, self.seed, self.floor = model, check_seed(seed), floor
        self.start = start if start.is_canonical() else start.canonical()   # (bit-equal when it is)
        self.motion: Tensor | None = None
        self.joints: Tensor | None = None

    @property
    def goal(self) -> Tensor:
        """The current goal (3,)."""
        v = self.values
        return goal_from_cylinder(v["angle"], v["distance"], v["height"])

    @property
    def t_goal(self) -> int:
        """The current goal frame (30 fps)."""
        return max(1, int(round(self.values["seconds"] * I.FPS)))

    def update(self, name: str, value: float) -> dict[str, float]:
        """Set one slider (angle deg, distance m, height m, seconds), roll the model out, return the readout."""
        if name not in self.values:
            raise ValueError(f"name: expected one of {list(self.values)}, got {name!r}")
        self.values[name] = self._checked(name, value)
        return self.run()

    def _checked(self, name: str, value: Any) -> float:
        """value as a float within the slider `name`'s range, else a ValueError naming it."""
        lo, hi, _ = self.SLIDERS[name]
        if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
            raise ValueError(f"{name}: expected a number in [{lo}, {hi}], got {type(value).__name__} {value!r}")
        if not lo <= float(value) <= hi:                                  # NaN fails the range test too
            raise ValueError(f"{name}: expected a value in [{lo}, {hi}], got {value!r}")
        return float(value)

    def run(self) -> dict[str, float]:
        """Generate the motion for the current goal (one sample, fixed seed) and measure it: closest wrist distance
        and its frame, the error at t_G, and how far the lowest foot joint rose above its start height (lift_cm)."""
        from graspkit.data.wandr_dataset import lowest_foot
        from graspkit.models.wandr import generate

        out = generate(self.model, self.start, self.goal[None], self.t_goal, n=1,
                       generator=torch.Generator().manual_seed(self.seed), floor=self.floor)
        self.motion, self.joints = out.p[0], out.joints[0]
        d = (self.joints[:, I.WRIST] - self.goal).norm(dim=-1)
        low = lowest_foot(self.joints)
        k = int(d.argmin())
        return {"dtg_cm": 100 * float(d.min()), "closest_frame": k, "closest_s": k / I.FPS,
                "error_at_goal_cm": 100 * float(d[-1]), "reached": bool(d.min() <= WANDR_SUCCESS_RADIUS),
                "lift_cm": 100 * float((low - low[0]).max())}

    def figure(self) -> Figure:
        """Top view of the pelvis and wrist paths with the goal, and the wrist's distance to the goal over time (not
        left open in pyplot: the caller shows it)."""
        import matplotlib.pyplot as plt

        if self.joints is None:
            self.run()
        J, g = self.joints.numpy(), self.goal.numpy()
        fig, (ax, bx) = plt.subplots(1, 2, figsize=(8.5, 3.4), dpi=72)
        plt.close(fig)
        ax.plot(J[:, 0, 0], J[:, 0, 1], color="#6a3d9a", label="pelvis")
        ax.plot(J[:, I.WRIST, 0], J[:, I.WRIST, 1], color="#e377c2", label="right wrist")
        ax.plot(*g[:2], "x", color="#d62728", ms=10, mew=2, label=f"goal ({g[2]:.2f} m high)")
        ax.arrow(0, 0, 0.4, 0, width=0.02, color="k")
        ax.set_aspect("equal")
        ax.legend(fontsize=7, loc="best")
        ax.set_title("seen from above (start faces +x)", fontsize=9)
        d = np.linalg.norm(J[:, I.WRIST] - g, axis=-1)
        bx.plot(np.arange(len(d)) / I.FPS, 100 * d, color="#e377c2")
        bx.axhline(100 * WANDR_SUCCESS_RADIUS, color="#2ca02c", ls="--", lw=1, label="10 cm (success)")
        bx.axvline(self.t_goal / I.FPS, color="0.5", ls=":", lw=1, label="t_G")
        bx.set_xlabel("s")
        bx.set_ylabel("wrist to goal (cm)")
        bx.legend(fontsize=7)
        fig.tight_layout()
        return fig

    def png(self, dpi: float = 72.0) -> bytes:
        """The figure as PNG bytes."""
        from graspkit.viz.export import png_bytes

        return png_bytes(self.figure(), dpi)

    def widget(self) -> Any:  # pragma: no cover - UI only; update / png are tested
        """Sliders for angle, distance, height and time to the goal; the figure in an Image widget; a readout."""
        import ipywidgets as w

        image, text = w.Image(format="png"), w.HTML()

        def show(r: dict[str, float]) -> None:
            text.value = (f"closest {r['dtg_cm']:.1f} cm at {r['closest_s']:.1f} s; at t_G {r['error_at_goal_cm']:.1f} cm; "
                          f"{'reached' if r['reached'] else 'not reached'}; feet lifted up to {r['lift_cm']:.1f} cm")
            image.value = self.png()

        sliders = []
        for name, (lo, hi, step) in self.SLIDERS.items():
            s = w.FloatSlider(value=self.values[name], min=lo, max=hi, step=step, description=name,
                              continuous_update=False)
            s.observe(lambda ch, name=name: show(self.update(name, ch["new"])), names="value")
            sliders.append(s)
        show(self.run())
        return w.VBox([w.HBox([w.VBox(sliders), image]), text])
