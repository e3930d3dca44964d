"""WANDR's goal-grid evaluation (§4.2-4.3, Tab. 1-2, Fig. 5): every goal of a cylinder around the body, from held-out
start poses, several samples each, the full 8 s always (no early stop).

    starts = held_out_starts(...)                                  # 6 start poses, canonical (pelvis at 0, facing +x)
    res = evaluate_grid(model, starts, bm, n=5, seed=0)            # 6 x 125 x 5 = 3,750 rollouts, one batch
    summary(res)                                                   # {'SR': %, 'FS': %, 'DTG': cm, ...}
    breakdown(res, "height")                                       # SR per goal height (Fig. 5)

Grid (§4.2): angles 0, 72, 144, 216, 288 deg from the start's facing direction (counter-clockwise seen from above);
heights 0, 0.45, 0.9, 1.35, 1.8 m above the ground; distances 0.5, 1.625, 2.75, 3.875, 5 m from the start's pelvis on
the ground; 240 frames (8 s at 30 fps: the start and 239 generated frames), t_G = frame 239.
Metrics (§4.3): SR, the share of motions whose right wrist comes within 10 cm of the goal at any frame; FS, per motion
the share of frame pairs whose lowest mesh vertex moves more than 0.66 cm horizontally to the next frame, averaged
over motions; DTG, the closest the wrist gets to the goal (cm), averaged.

FS is computed on the fly, frame by frame, without building meshes: the lowest vertex is searched among the foot
vertices (the 524 vertices skinned mostly to ankles and feet), which are posed exactly by linear blend skinning from
the knee, ankle and foot transforms (they carry no pose correctives). `fs_agreement` measures, on full meshes, how often
the lowest vertex of the whole body is one of them.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np
import torch
from torch import Tensor

from graspkit import intention as I
from graspkit.body.skeleton import JOINT_INDEX
from graspkit.data.reaching import EVAL_ANGLES_DEG, EVAL_DISTANCES, EVAL_FRAMES, EVAL_HEIGHTS, Start, evaluation_goals
from graspkit.metrics import WANDR_SKATE_THRESHOLD, WANDR_SUCCESS_RADIUS

T_GOAL = EVAL_FRAMES - 1          # frame 239: 8 s after the start frame

# the paper's figures (Tab. 1 and Tab. 2): SR %, FS %, DTG cm
PAPER = {
    "WANDR": (32.0, 16.0, 24.8), "WANDR / reaching only (Circle)": (0.0, 56.0, 205.4),
    "WANDR / locomotion only (AMASS)": (16.0, 19.0, 48.0), "GOAL": (0.0, 29.0, 149.2),
    "WANDR (I^w)": (15.0, 13.0, 62.9), "WANDR (I^w + I^p)": (18.0, 17.0, 44.9), "WANDR (I^w + I^r)": (19.0, 19.0, 36.0),
    "VAE + opt": (3.0, 4.0, 217.0),
}


def grid_goals() -> tuple[Tensor, np.ndarray]:
    """The 125 goals (125, 3) around a canonical start (pelvis above the origin, facing +x) and their (angle deg,
    height m, distance m) rows (125, 3)."""
    rows = evaluation_goals(Start(0.0, 0.0, 0.0))
    goals = torch.as_tensor(np.stack([rows[:, 3], rows[:, 4], rows[:, 1]], 1), dtype=torch.float32)
    return goals, rows[:, :3]


class FootVertices:
    """The foot vertices of one or more bodies (betas (S, 10)), posed by LBS from body-joint transforms."""

    def __init__(self, bm, betas: Tensor) -> None:
        weights = bm.lbs_weights.float()                                  # (V, 55)
        feet = [JOINT_INDEX[n] for n in ("left_ankle", "right_ankle", "left_foot", "right_foot")]
        self.ids = torch.isin(weights.argmax(1), torch.tensor(feet)).nonzero()[:, 0]
        w = weights[self.ids]
        self.joints = (w.sum(0) > 0).nonzero()[:, 0]
        if int(self.joints.max()) >= I.NUM_BODY:
            raise ValueError("bm: foot vertices skinned to joints outside the body chain")
        if bm.has_posedirs and bm.posedirs.view(bm.posedirs.shape[0], 3, -1)[:, :, self.ids].abs().max() > 0:
            raise ValueError("bm: foot vertices carry pose correctives; the fast FS would not be exact")
        self.w = w[:, self.joints]                                        # (Vf, K)
        betas = torch.as_tensor(betas).reshape(len(betas), -1).to(bm.dtype)
        coeffs = torch.zeros(len(betas), bm.num_betas + bm.num_expression, dtype=bm.dtype)
        k = min(bm.num_betas, betas.shape[1])
        coeffs[:, :k] = betas[:, :k]
        with torch.no_grad():
            v, J = bm.shaped(coeffs)
        self.rest_v = v[:, self.ids].float()                             # (S, Vf, 3)
        self.rest_j = J[:, self.joints].float()                          # (S, K, 3)
        self.xw = (self.w[None, :, :, None] * self.rest_v[:, :, None, :]).flatten(2)   # (S, Vf, 3K): w_vk x_v

    def _affine(self, Rg: Tensor, pos: Tensor, body: Tensor) -> tuple[Tensor, Tensor]:
        """Skinning transforms x -> R_k x + t_k (B, K, 3, 3), (B, K, 3) of the K joints the feet are skinned to."""
        R = Rg[:, self.joints]
        t = pos[:, self.joints] - (R @ self.rest_j[body].unsqueeze(-1)).squeeze(-1)
        return R, t

    def heights(self, Rg: Tensor, pos: Tensor, body: Tensor) -> Tensor:
        """Heights (B, Vf) of the foot vertices of poses with global rotations Rg (B, 22, 3, 3) and world joint
        positions pos (B, 22, 3), for bodies `body` (B,) (indices into betas): z_v = sum_k w_vk (R_k[2] . x_v + t_k^z),
        one small matrix product per body."""
        R, t = self._affine(Rg, pos, body)
        Rz, tz = R[:, :, 2, :].flatten(1), t[:, :, 2]                                  # (B, 3K), (B, K)
        z = tz @ self.w.T                                                               # (B, Vf)
        for s in body.unique().tolist():
            rows = (body == s).nonzero()[:, 0]
            z[rows] += Rz[rows] @ self.xw[s].T
        return z

    def points(self, Rg: Tensor, pos: Tensor, body: Tensor, vertex: Tensor | None = None) -> Tensor:
        """World positions of foot vertices: all (B, Vf, 3), or one per pose (B, 3) (indices into the foot ids)."""
        R, t = self._affine(Rg, pos, body)
        if vertex is None:
            x, w = self.rest_v[body], self.w                                            # (B, Vf, 3), (Vf, K)
            moved = torch.einsum("bkij,bvj->bvki", R, x) + t[:, None]                  # (B, Vf, K, 3)
            return (moved * w[None, :, :, None]).sum(2)
        x, w = self.rest_v[body, vertex], self.w[vertex]                                # (B, 3), (B, K)
        moved = (R @ x[:, None, :, None]).squeeze(-1) + t                               # (B, K, 3)
        return (moved * w[..., None]).sum(1)


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

    @property
    def success(self) -> np.ndarray:
        """Right wrist within 10 cm of the goal at some frame (B,) bool."""
        return self.dtg <= WANDR_SUCCESS_RADIUS


class GridMeter:
    """A `rollout` frame hook that accumulates SR / DTG / FS per sequence without storing the motion."""

    def __init__(self, feet: FootVertices, body: Tensor, rest: Tensor, goals: Tensor, t_goal: int) -> None:
        """feet for bodies `body` (B,) (indices into its betas), rest joints (B, 22, 3), goals (B, 3), t_G frame."""
        self.feet, self.body, self.rest, self.goals, self.t_goal = feet, body, rest, goals, t_goal
        B = len(body)
        self.dtg = torch.full((B,), float("inf"))
        self.reach = torch.full((B,), -1, dtype=torch.long)
        self.skate = torch.zeros(B)
        self.pairs = 0
        self.err = torch.full((B,), float("nan"))
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
            pos = joints
            if self._lowest is not None:       # the vertex lowest at the previous frame: its horizontal move
                now = self.feet.points(Rg, pos, self.body, self._lowest)
                move = (now[:, :2] - self._at[:, :2]).norm(dim=-1)
                self.skate += (move > WANDR_SKATE_THRESHOLD).float()
                self.pairs += 1
            self._lowest = self.feet.heights(Rg, pos, self.body).argmin(1)
            self._at = self.feet.points(Rg, pos, self.body, self._lowest)


def evaluate_grid(model, starts: Sequence[I.StartPose], bm, n: int = 5, seed: int = 0, goals: Tensor | None = None,
                  cells: np.ndarray | None = None, t_goal: int = T_GOAL, frames: int | None = None) -> GridResult:
    """Roll the model out on the grid (or `goals` (G, 3) with their `cells` rows) from every start, n samples each,
    all in one batch (torch.Generator seeded with `seed`), measuring on the fly."""
    from graspkit.models.wandr import expand_starts, rollout

    if goals is None:
        goals, cells = grid_goals()
    cells = np.zeros((len(goals), 3)) if cells is None else np.asarray(cells)
    pp, p0, rest, g, idx = expand_starts(starts, goals, n)
    feet = FootVertices(bm, torch.stack([s.betas for s in starts]))
    meter = GridMeter(feet, idx[:, 0], rest, g, t_goal)
    gen = torch.Generator().manual_seed(seed)
    model.eval()
    with torch.no_grad():
        rollout(model, pp, p0, rest, g, t_goal, frames if frames is not None else t_goal, generator=gen, keep=False,
                on_frame=meter)
    return _result(meter, idx, cells)


def _result(meter: GridMeter, idx: Tensor, cells: np.ndarray) -> GridResult:
    """GridResult from a finished meter."""
    gi = idx[:, 1].numpy()
    return GridResult(idx[:, 0].numpy(), gi, idx[:, 2].numpy(), cells[gi], meter.dtg.double().numpy(),
                      meter.reach.numpy(), (meter.skate / max(meter.pairs, 1)).double().numpy(),
                      meter.err.double().numpy())


def evaluate_motions(p: Tensor, rest: Tensor, goals: Tensor, betas: Tensor, bm, t_goal: int = T_GOAL,
                     cells: np.ndarray | None = None, index: Tensor | None = None) -> GridResult:
    """Score given motions p (B, T, 135) with rest joints (B, 22, 3), goals (B, 3) and betas (B, 10) the same way."""
    B, T = p.shape[:2]
    feet = FootVertices(bm, betas)
    meter = GridMeter(feet, torch.arange(B), rest, goals, t_goal)
    with torch.no_grad():
        for k in range(T):
            Rg, J = I.body_transforms(p[:, k], rest)
            meter(k, p[:, k], J, Rg)
    idx = index if index is not None else torch.stack([torch.zeros(B, dtype=torch.long), torch.arange(B),
                                                       torch.zeros(B, dtype=torch.long)], 1)
    return _result(meter, idx, cells if cells is not None else np.zeros((B, 3)))


def evaluate_planner(starts: Sequence[I.StartPose], bm, t_goal: int = T_GOAL, seed: int = 0) -> GridResult:
    """The procedural planner (graspkit.data.plan_reach) on the grid, one motion per goal and start body (it starts
    standing at rest, not from the start pose: it cannot take an arbitrary pose), scored as the model is."""
    from graspkit.data import plan_reach

    goals, cells = grid_goals()
    ps, rests, gs, bs, idx = [], [], [], [], []
    for s_i, s in enumerate(starts):
        for g_i, goal in enumerate(goals):
            m = plan_reach(Start(0.0, 0.0, 0.0), goal.numpy(), t_goal, betas=s.betas.numpy(), seed=seed + g_i, bm=bm,
                           hold_frames=0)
            ps.append(I.pose_from_axis_angle(torch.as_tensor(m.trans), torch.as_tensor(m.poses)))
            rests.append(s.rest)
            gs.append(goal)
            bs.append(s.betas)
            idx.append((s_i, g_i, 0))
    res = evaluate_motions(torch.stack(ps), torch.stack(rests), torch.stack(gs), torch.stack(bs), bm, t_goal,
                           cells[[i[1] for i in idx]], torch.tensor(idx))
    res.cell = cells[res.goal_index]
    return res


def summary(res: GridResult) -> dict[str, float]:
    """SR (%), FS (%), DTG (cm, mean), the median DTG (cm), the mean wrist error at t_G (cm) and the rollout count."""
    return {"SR": 100 * float(res.success.mean()), "FS": 100 * float(res.fs.mean()), "DTG": 100 * float(res.dtg.mean()),
            "DTG_median": 100 * float(np.median(res.dtg)), "error_at_goal": 100 * float(np.nanmean(res.error_at_goal)),
            "rollouts": int(len(res.dtg))}


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
        p = paper.get(name)
        ref = " | ".join(f"{x:g}" for x in p) if p else "— | — | —"
        out.append(f"| {name} | {s['SR']:.1f} | {s['FS']:.1f} | {s['DTG']:.1f} | {ref} |")
    return "\n".join(out)


GRID_DESCRIPTION = {"angles_deg": EVAL_ANGLES_DEG, "heights_m": tuple(float(h) for h in EVAL_HEIGHTS),
                    "distances_m": tuple(float(d) for d in EVAL_DISTANCES), "frames": EVAL_FRAMES, "t_goal": T_GOAL}
