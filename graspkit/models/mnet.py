"""GOAL's MNet (Taheri et al., CVPR 2022, §3.4, Eq. 9–13): deterministic, autoregressive approach-and-grasp motion.

Input at frame t (Eq. 9), everything in the *canonical frame of frame t* (z up, origin on the floor under the
pelvis, the body's heading along +y), re-computed at every autoregressive step:
    Θ_{t−4:t}   the last 5 frames' 55 joint rotations (6D) and translations      (5 × 333)
    β           shape                                                              (10)
    v_t, v̇_t    the 400 sampled vertices and their velocities (v_t − v_{t−1})      (400 × 3 each)
    d^h_{t→g}   hand-vertex offsets from frame t to the goal grasp: v^h_g − v^h_t  (99 × 3)
    b^h_g       BPS of the goal hand's 99 vertices on the object's basis (1024 points in 0.15 m around the object
                centre, not rotated): the goal hand relative to the object, as the object's own code (§3.4)
    IAA         interaction-aware attention (§3.2, Eq. 1, w = 5): for each of the 400 vertices the offset d to its
                closest object point weighted by exp(−w|d|), and exp(−w z) for its height z above the floor
                (400 × 3 + 400) — vertices near the object (hands) and near the ground (feet) get the attention.
                The floor term is graspkit's: Eq. 1's d is a body-to-object distance only; the same kernel on the
                height is our reading of §3.2's "feet for walking", which the paper does not write as a formula.
                `attention=False` (GOAL Tab. 2 "MNet-w/o-IAA") feeds the raw offsets instead.
Output (Eq. 10): the next 10 frames as changes from frame t, in the same canonical frame:
    ΔΘ_{t:t+10} (10 × 333: 6D rotations added to frame t's, translations), Δv_{t:t+10} (10 × 400 × 3) and
    Δd^h_{t:t+10} (10 × 99 × 3), read here as the change of the hand-to-object offsets (the closest object point to
    each hand vertex minus the vertex), as Eq. 11's L_d^{h→o} names them.
Loss (Eq. 11): λ_v L_v + λ_v^h L_v^h + λ_Θ L_Θ + λ_d L_d^{h→o} + λ_f L_v^f, with L_v^f on the sampled foot
vertices that are within 5 cm of the floor in the ground truth. No latent: MNet is deterministic.

Size: GOAL's MNet has ~117M parameters (the issue's figure; the paper's text gives no count); graspkit's has 0.61M
with the default config (613,850: grouped input projections, a two-block residual trunk, and an output head factorised
as a per-frame code times one shared linear decoder), so that it trains on two CPU cores in minutes and ships as a
~1.3 MB checkpoint (float16).
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import torch
from scipy.spatial import cKDTree
from torch import Tensor, nn

from graspkit.checks import check_int
from graspkit.models.blocks import ResBlock, in_eval_mode
from graspkit.models.gnet import NUM_JOINTS, POSE_DIM, Standardiser
from graspkit.objects.bps import bps_encode
from graspkit.objects.contact import IAA_WEIGHT
from graspkit.rotations import matrix_to_rot6d, rot6d_to_matrix, rotation_about_z
from graspkit.state import keeps_torch_state

if TYPE_CHECKING:
    from graspkit.body import BodyModel
    from graspkit.models.gnet import SparseBody
    from graspkit.optim.goal_refine import MotionRefineWeights
    from graspkit.train import TrainConfig

FOOT_CONTACT_HEIGHT = 0.05   # m: L_v^f covers the sampled foot vertices this close to the floor (ground truth)


# ------------------------------------------------------------------------------------------- canonical frames

def rest_root(bm: BodyModel, betas: Tensor) -> Tensor:
    """The rest-pose root (pelvis) joint J_0(β) (B,3): the point the root rotation turns the body about."""
    coeffs = torch.zeros(betas.shape[0], bm.num_betas + bm.num_expression, dtype=bm.dtype)
    coeffs[:, :betas.shape[1]] = betas.to(bm.dtype)
    return (bm.J_template[0] + coeffs @ bm.J_basis[:, :3]).to(betas.dtype)


def heading(root_rot: Tensor) -> Tensor:
    """Yaw (...) in radians from world +x of the body's forward direction (canonical +z) for root rotations (...,3,3)."""
    return torch.atan2(root_rot[..., 1, 2], root_rot[..., 0, 2])


def canonical_frame(root_rot: Tensor, pelvis: Tensor) -> tuple[Tensor, Tensor]:
    """Frame of a body (root rotation (B,3,3), pelvis (B,3)): x' = R (x − o), o on the floor under the pelvis,
    the heading along +y. Returns R (B,3,3), o (B,3)."""
    R = rotation_about_z(math.pi / 2 - heading(root_rot))
    o = torch.cat([pelvis[:, :2], torch.zeros_like(pelvis[:, :1])], 1)
    return R, o


def transform_params(rot6d: Tensor, transl: Tensor, root: Tensor, R: Tensor, o: Tensor) -> tuple[Tensor, Tensor]:
    """SMPL-X parameters of the body moved by x -> R (x − o): rot6d (B,...,55,6), transl (B,...,3), rest root (B,3).

    The root rotation becomes R R_root and γ' = R (J_0 + γ − o) − J_0; the other joints are local and unchanged."""
    shape = transl.shape[1:-1]
    Rx = R.reshape(R.shape[0], *([1] * len(shape)), 3, 3)
    J0 = root.reshape(root.shape[0], *([1] * len(shape)), 3)
    ox = o.reshape(o.shape[0], *([1] * len(shape)), 3)
    root_rot = Rx @ rot6d_to_matrix(rot6d[..., 0, :])
    out = torch.cat([matrix_to_rot6d(root_rot).unsqueeze(-2), rot6d[..., 1:, :]], dim=-2)
    t = (Rx @ (J0 + transl - ox).unsqueeze(-1)).squeeze(-1) - J0
    return out, t


def transform_points(x: Tensor, R: Tensor, o: Tensor | None = None) -> Tensor:
    """Points (B,...,3) -> R (x − o); vectors when o is None."""
    shape = x.shape
    if o is not None:
        x = x - o.reshape(o.shape[0], *([1] * (x.dim() - 2)), 3)
    return torch.bmm(x.reshape(shape[0], -1, 3), R.transpose(1, 2).to(x.dtype)).reshape(shape)


# ------------------------------------------------------------------------------------------- inputs and targets

@dataclass
class MNetState:
    """World-frame quantities MNet needs at frame t (B samples): past Θ (frames t−4..t), shape, vertices at t and
    t−1, the goal hand, the object centre, the 400 body-to-object offsets at t and the rest root J_0(β)."""

    rot6d: Tensor          # (B,5,55,6)
    transl: Tensor         # (B,5,3)
    betas: Tensor          # (B,10)
    verts: Tensor          # (B,400,3) frame t
    verts_prev: Tensor     # (B,400,3) frame t−1
    goal_hand: Tensor      # (B,99,3)
    obj_centre: Tensor     # (B,3)
    obj_offsets: Tensor    # (B,400,3) closest object point − vertex, frame t
    root: Tensor           # (B,3)


def goal_hand_bps(s: MNetState, R: Tensor, basis: Tensor) -> Tensor:
    """b^h_g (B,1024): BPS of the goal hand on the object's basis, in the canonical frame R of frame t."""
    return bps_encode(transform_points(s.goal_hand - s.obj_centre[:, None], R), basis.to(s.goal_hand.dtype))


def mnet_inputs(s: MNetState, basis: Tensor, attention: bool = True, n_hand: int = 99, bps: Tensor | None = None
                ) -> tuple[dict[str, Tensor], Tensor, Tensor]:
    """Eq. 9 in the canonical frame of frame t: {'pose', 'verts', 'goal', 'iaa'} (B, ·) and the frame's R, o
    (`bps`: b^h_g when already computed, see `goal_hand_bps`)."""
    B = s.betas.shape[0]
    R, o = canonical_frame(rot6d_to_matrix(s.rot6d[:, -1, 0]), s.root + s.transl[:, -1])
    rot6d, transl = transform_params(s.rot6d, s.transl, s.root, R, o)
    v, vp = transform_points(s.verts, R, o), transform_points(s.verts_prev, R, o)
    goal = transform_points(s.goal_hand, R, o)
    d = transform_points(s.obj_offsets, R)
    bps = goal_hand_bps(s, R, basis) if bps is None else bps
    if attention:
        iaa = torch.cat([(torch.exp(-IAA_WEIGHT * d.norm(dim=-1, keepdim=True)) * d).reshape(B, -1),
                         torch.exp(-IAA_WEIGHT * v[..., 2].clamp_min(0))], 1)
    else:
        iaa = d.reshape(B, -1)
    feats = {"pose": torch.cat([torch.cat([rot6d.flatten(2), transl], 2).reshape(B, -1), s.betas], 1),
             "verts": torch.cat([v.reshape(B, -1), (v - vp).reshape(B, -1)], 1),
             "goal": torch.cat([(goal - v[:, :n_hand]).reshape(B, -1), bps], 1),
             "iaa": iaa}
    return feats, R, o


def mnet_targets(s: MNetState, R: Tensor, o: Tensor, rot6d: Tensor, transl: Tensor, verts: Tensor,
                 obj_offsets: Tensor, n_hand: int = 99) -> dict[str, Tensor]:
    """Eq. 10 targets: future frames (B,F,...) in the world -> changes from frame t in its canonical frame."""
    r_now, t_now = transform_params(s.rot6d[:, -1], s.transl[:, -1], s.root, R, o)
    r_f, t_f = transform_params(rot6d, transl, s.root, R, o)
    return {"d_rot6d": r_f - r_now[:, None], "d_transl": t_f - t_now[:, None],
            "d_verts": transform_points(verts - s.verts[:, None], R),
            "d_hand_obj": transform_points(obj_offsets[:, :, :n_hand] - s.obj_offsets[:, None, :n_hand], R)}


# ------------------------------------------------------------------------------------------- the network

@dataclass
class MNetConfig:
    """MNet sizes and variants (GOAL Tab. 2): attention (IAA), outputs 'full' or 'pose' (MNet-Pose), n_future frames."""

    n_past: int = 5
    n_future: int = 10
    n_verts: int = 400
    n_hand: int = 99
    n_betas: int = 10
    n_bps: int = 1024
    hidden: int = 160
    code: int = 40            # per-frame code width of the factorised output head
    proj: tuple[int, int, int, int] = (64, 40, 48, 32)   # projection widths of the pose, vertex, goal and attention groups
    attention: bool = True
    outputs: str = "full"     # 'full': ΔΘ, Δv, Δd (Eq. 10); 'pose': ΔΘ only


@dataclass
class MNetLossWeights:
    """λ of Eq. 11 (vertex and offset terms: mean absolute errors in metres; Θ: mean squared error)."""

    v: float = 1.0
    v_hand: float = 1.0
    theta: float = 10.0
    d: float = 1.0
    feet: float = 1.0


def _group_sizes(cfg: MNetConfig) -> dict[str, tuple[int, int]]:
    """(input size, projection width) per input group."""
    iaa = 4 * cfg.n_verts if cfg.attention else 3 * cfg.n_verts
    w = tuple(cfg.proj)
    return {"pose": (cfg.n_past * POSE_DIM + cfg.n_betas, w[0]), "verts": (6 * cfg.n_verts, w[1]),
            "goal": (3 * cfg.n_hand + cfg.n_bps, w[2]), "iaa": (iaa, w[3])}


class MNet(nn.Module):
    """GOAL §3.4: grouped input projections -> residual trunk -> per-frame codes -> shared frame decoder."""

    def __init__(self, cfg: MNetConfig | None = None) -> None:
        super().__init__()
        if (cfg or MNetConfig()).outputs not in ("full", "pose"):
            raise ValueError(f"cfg.outputs: expected 'full' or 'pose', got {cfg.outputs!r}")
        self.cfg = cfg = cfg or MNetConfig()
        groups = _group_sizes(cfg)
        self.norms = nn.ModuleDict({k: Standardiser(n) for k, (n, _) in groups.items()})
        self.proj = nn.ModuleDict({k: nn.Sequential(nn.Linear(n, w), nn.LayerNorm(w), nn.LeakyReLU(0.2))
                                   for k, (n, w) in groups.items()})
        width = sum(w for _, w in groups.values())
        self.trunk = nn.Sequential(ResBlock(width, cfg.hidden, norm="layer"), ResBlock(cfg.hidden, cfg.hidden, norm="layer"))
        self.codes = nn.Linear(cfg.hidden, cfg.n_future * cfg.code)
        self.frame_dim = POSE_DIM + (3 * cfg.n_verts + 3 * cfg.n_hand if cfg.outputs == "full" else 0)
        self.decoder = nn.Linear(cfg.code, self.frame_dim)
        self.frame_bias = nn.Parameter(torch.zeros(cfg.n_future, self.frame_dim))
        self.norm_out = Standardiser(cfg.n_future * self.frame_dim)
        nn.init.zeros_(self.decoder.weight)                                 # start at the mean change
        nn.init.zeros_(self.decoder.bias)

    def pack_targets(self, tgt: dict[str, Tensor]) -> Tensor:
        """Targets dict (B,F,...) -> (B, F * frame_dim) in the network's output layout."""
        B, F = tgt["d_transl"].shape[:2]
        parts = [tgt["d_rot6d"].reshape(B, F, -1), tgt["d_transl"]]
        if self.cfg.outputs == "full":
            parts += [tgt["d_verts"].reshape(B, F, -1), tgt["d_hand_obj"].reshape(B, F, -1)]
        return torch.cat(parts, 2).reshape(B, -1)

    def unpack(self, y: Tensor) -> dict[str, Tensor]:
        """(B, F * frame_dim) -> {'d_rot6d' (B,F,55,6), 'd_transl' (B,F,3)[, 'd_verts' (B,F,400,3), 'd_hand_obj' (B,F,99,3)]}."""
        c, B, F = self.cfg, y.shape[0], self.cfg.n_future
        y = y.reshape(B, F, self.frame_dim)
        out = {"d_rot6d": y[..., :NUM_JOINTS * 6].reshape(B, F, NUM_JOINTS, 6), "d_transl": y[..., NUM_JOINTS * 6:POSE_DIM]}
        if c.outputs == "full":
            out["d_verts"] = y[..., POSE_DIM:POSE_DIM + 3 * c.n_verts].reshape(B, F, c.n_verts, 3)
            out["d_hand_obj"] = y[..., POSE_DIM + 3 * c.n_verts:].reshape(B, F, c.n_hand, 3)
        return out

    @torch.no_grad()
    def fit_normalisation(self, feats: dict[str, Tensor], targets: dict[str, Tensor]) -> None:
        """Standardisation statistics of each input group and of the outputs from training samples."""
        for k, n in self.norms.items():
            n.fit(feats[k])
        self.norm_out.fit(self.pack_targets(targets))

    def forward(self, feats: dict[str, Tensor]) -> dict[str, Tensor]:
        """Eq. 9 features {'pose', 'verts', 'goal', 'iaa'} (B, ·) -> Eq. 10 changes (see `unpack`)."""
        if not isinstance(feats, dict):
            raise ValueError(f"feats: expected a dict of feature groups {sorted(self.proj)}, got {type(feats).__name__}")
        for k in self.proj:
            want = self.proj[k][0].in_features
            x = feats.get(k)
            if not isinstance(x, torch.Tensor) or x.dim() != 2 or x.shape[1] != want:
                got = tuple(x.shape) if isinstance(x, torch.Tensor) else ("missing" if x is None else type(x).__name__)
                raise ValueError(f"feats[{k!r}]: expected shape (B, {want}) (mnet.features), got {got}")
        # Inputs and outputs the training clips held still (std at the floor: the jaw, eyes, left collar, some 6D
        # entries of the left fingers, toes and knees, ...) are held at their training values: the network never
        # learned what a change there means, and a jaw turned 3 degrees (50 floored stds) or its own drift there (up
        # to 32 stds in a rollout) otherwise steers the whole body (docs/goal.md "Features the training clips held
        # still"). The current frame's translation x, y moves the past frames' with it (see `_shift_translation`).
        feats = {**feats, "pose": self._shift_translation(feats["pose"])}
        h = torch.cat([self.proj[k](self.norms[k](feats[k]).masked_fill(self.norms[k].floored(), 0.0))
                       for k in self.proj], 1)
        h = self.trunk(h)
        B = h.shape[0]
        codes = self.codes(h).reshape(B, self.cfg.n_future, self.cfg.code)
        y = (self.decoder(codes) + self.frame_bias).reshape(B, -1).masked_fill(self.norm_out.floored(), 0.0)
        return self.unpack(self.norm_out.inverse(y))

    def _shift_translation(self, pose: Tensor) -> Tensor:
        """Pose features (B, ·) with every past frame's translation x, y moved by what puts the current frame's at its
        training value, where that one is held (std at the floor). Frame t's x, y in its own canonical frame is the
        body's rest pelvis offset (−J_0 turned), the same for all the training bodies; holding it alone would read
        another body's offset as a jump between the past frames and this one (a body 15 % larger walked backwards)."""
        n, k = self.norms["pose"], self.cfg.n_past
        cur = [(k - 1) * POSE_DIM + NUM_JOINTS * 6 + i for i in (0, 1)]
        shift = (n.mean[cur] - pose[:, cur]) * n.floored()[cur]          # (B,2); 0 where frame t's x, y is not held
        cols = [f * POSE_DIM + NUM_JOINTS * 6 + i for f in range(k) for i in (0, 1)]
        out = pose.clone()
        out[:, cols] = out[:, cols] + shift.repeat(1, k)
        return out

    def config_dict(self) -> dict:
        """The config as plain values (for checkpoints)."""
        return asdict(self.cfg)


def feet_mask(targets_abs_z: Tensor, feet: Tensor, height: float = FOOT_CONTACT_HEIGHT) -> Tensor:
    """(B,F,400) float mask: sampled foot vertices (positions `feet`) whose true height is below `height`."""
    m = torch.zeros_like(targets_abs_z)
    m[..., feet] = (targets_abs_z[..., feet] < height).to(m.dtype)
    return m


def mnet_loss(out: dict[str, Tensor], tgt: dict[str, Tensor], foot: Tensor | None = None,
              w: MNetLossWeights | None = None, n_hand: int = 99) -> dict[str, Tensor]:
    """Eq. 11: {'loss', 'theta', ['v', 'v_hand', 'd', 'feet']}; `foot` (B,F,400) masks L_v^f (see `feet_mask`)."""
    w = w or MNetLossWeights()
    terms = {"theta": torch.cat([(out["d_rot6d"] - tgt["d_rot6d"]).flatten(2), out["d_transl"] - tgt["d_transl"]],
                                2).pow(2).mean()}
    lam = {"theta": w.theta, "v": w.v, "v_hand": w.v_hand, "d": w.d, "feet": w.feet}
    if "d_verts" in out:
        err = (out["d_verts"] - tgt["d_verts"]).abs()               # (B,F,400,3)
        terms["v"] = err.mean()
        terms["v_hand"] = err[:, :, :n_hand].mean()
        terms["d"] = (out["d_hand_obj"] - tgt["d_hand_obj"]).abs().mean()
        if foot is not None:
            terms["feet"] = (err.mean(-1) * foot).sum() / foot.sum().clamp_min(1.0)
    terms["loss"] = sum(lam[k] * t for k, t in terms.items())
    return terms


def apply_changes(rot6d_t: Tensor, transl_t: Tensor, out: dict[str, Tensor]) -> tuple[Tensor, Tensor]:
    """Frame t's canonical Θ (B,55,6), (B,3) plus MNet's changes -> future Θ (B,F,55,6) (re-orthonormalised), (B,F,3)."""
    r = matrix_to_rot6d(rot6d_to_matrix(rot6d_t[:, None] + out["d_rot6d"]))
    return r, transl_t[:, None] + out["d_transl"]


# ------------------------------------------------------------------------------------------- rollout

@dataclass
class Rollout:
    """A generated motion in the world: rot6d (T,55,6), transl (T,3); the mean hand-to-goal distance per frame (T,),
    whether the goal grasp was reached, and the first refined frame (None if the refinement never started)."""

    rot6d: Tensor
    transl: Tensor
    hand_dist: Tensor
    reached: bool
    first_refined: int | None


def _invert(R: Tensor, o: Tensor) -> tuple[Tensor, Tensor]:
    """(R, o) of the inverse map x' -> R^T x' + o, written as R_inv (x' − o_inv)."""
    return R.transpose(1, 2), -(R @ o.unsqueeze(-1)).squeeze(-1)


def mnet_step(mnet: MNet, s: MNetState, basis: Tensor) -> tuple[Tensor, Tensor, dict[str, Tensor]]:
    """One autoregressive step: state at t (world) -> the next F frames' Θ in the world, rot6d (B,F,55,6), transl
    (B,F,3), and MNet's raw outputs (canonical frame of t)."""
    feats, R, o = mnet_inputs(s, basis, mnet.cfg.attention, mnet.cfg.n_hand)
    out = mnet(feats)
    r_now, t_now = transform_params(s.rot6d[:, -1], s.transl[:, -1], s.root, R, o)
    r_c, t_c = apply_changes(r_now, t_now, out)
    Ri, oi = _invert(R, o)
    r_w, t_w = transform_params(r_c, t_c, s.root, Ri, oi)
    return r_w, t_w, out


@torch.no_grad()
@in_eval_mode
def predict_horizon(mnet: MNet, body: SparseBody, s: MNetState, object_points: Tensor, basis: Tensor, horizon: int = 10
                    ) -> tuple[Tensor, Tensor]:
    """Autoregress from state s (B samples) until `horizon` frames exist (one step for a 10-frame MNet, ten for a
    1-frame one), no refinement: world rot6d (B,horizon,55,6), transl (B,horizon,3). Object points (B,P,3)."""
    from graspkit.models.gnet import pose_rotmats
    from graspkit.optim.goal_refine import hand_object_offsets

    rs, ts, fr, ft = list(s.rot6d.unbind(1)), list(s.transl.unbind(1)), [], []
    v_prev, v_now = s.verts_prev, s.verts
    B = s.betas.shape[0]
    while len(fr) < horizon:
        r_w, t_w, _ = mnet_step(mnet, s, basis)
        F = r_w.shape[1]
        fr += list(r_w.unbind(1))
        ft += list(t_w.unbind(1))
        rs += list(r_w.unbind(1))
        ts += list(t_w.unbind(1))
        last = body(pose_rotmats(torch.stack(rs[-2:], 1).reshape(-1, 55, 6)), s.betas.repeat_interleave(2, 0),
                    torch.stack(ts[-2:], 1).reshape(-1, 3))[0].reshape(B, 2, -1, 3)
        v_prev, v_now = (last[:, 0], last[:, 1]) if F > 0 else (v_prev, v_now)
        s = MNetState(torch.stack(rs[-mnet.cfg.n_past:], 1), torch.stack(ts[-mnet.cfg.n_past:], 1), s.betas, v_now,
                      v_prev, s.goal_hand, s.obj_centre, hand_object_offsets(v_now, object_points), s.root)
    return torch.stack(fr[:horizon], 1), torch.stack(ft[:horizon], 1)


STALL_GAIN = 0.005   # m: `rollout`'s stall rule (graspkit's): a last frame less than this below the window's closest
STALL_RADIUS = 0.25  # m: ... and only for a hand this close to the goal hand (not a body still standing at its start)
STALL_FRAMES = 10    # frames: the window graspkit's pipelines give `rollout`'s stall rule (one MNet step)


def check_stall(stall: Any) -> None:
    """ValueError naming `stall` unless it is None (off) or a whole number of frames >= 1."""
    if stall is not None and (isinstance(stall, bool) or not isinstance(stall, int) or stall < 1):
        raise ValueError(f"stall: expected a whole number of frames >= 1, or None (off), got {stall!r}")


def _check_rollout_inputs(start: Any, goal: Any, betas: Any, max_frames: Any, reach_tol: Any, min_speed: Any,
                          floor: Any) -> None:
    """`rollout`'s arguments, each named in a ValueError when it is not what `rollout` expects."""
    for name, pose in (("start", start), ("goal", goal)):
        ok = isinstance(pose, (tuple, list)) and len(pose) == 2 and all(isinstance(x, Tensor) for x in pose)
        if not ok or tuple(pose[0].shape) != (55, 6) or tuple(pose[1].shape) != (3,):
            got = tuple(tuple(x.shape) for x in pose) if ok else type(pose).__name__
            raise ValueError(f"{name}: expected (rot6d (55, 6), transl (3,)) tensors, got {got}")
        if not all(bool(torch.isfinite(x).all()) for x in pose):
            raise ValueError(f"{name}: contains NaN or Inf")
    if not isinstance(betas, Tensor) or betas.numel() != 10 or not bool(torch.isfinite(betas).all()):
        got = tuple(betas.shape) if isinstance(betas, Tensor) else type(betas).__name__
        raise ValueError(f"betas: expected 10 finite shape coefficients (GOAL's networks take 10), got {got}")
    check_int(max_frames, "max_frames", least=1)
    for name, value, low in (("reach_tol", reach_tol, 0.0), ("min_speed", min_speed, None)):
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) \
                or (value <= low if low is not None else value < 0):
            raise ValueError(f"{name}: expected a finite distance in metres {'> 0' if low is not None else '>= 0'}, "
                             f"got {value!r}")
    if floor is not None and (isinstance(floor, bool) or not isinstance(floor, (int, float)) or not math.isfinite(floor)):
        raise ValueError(f"floor: expected None (off) or a finite height in metres, got {floor!r}")


@torch.no_grad()
@in_eval_mode
def rollout(mnet: MNet, body: SparseBody, start: tuple[Tensor, Tensor], goal: tuple[Tensor, Tensor], betas: Tensor,
            object_points: Tensor, obj_centre: Tensor, basis: Tensor, max_frames: int = 300, refine: bool = True,
            reach_tol: float = 0.01, min_speed: float = 0.003, refine_weights: MotionRefineWeights | None = None,
            floor: float | None = None, stall: int | None = None) -> Rollout:
    """GOAL's autoregressive inference (§3.4) for one body: from `start` (rot6d (55,6), transl (3,)) to the grasp
    `goal` (same), re-canonicalised at every step; 10 frames per step while far, one frame per step once the hand is
    within 10 cm of the goal hand, each then refined by Eq. 12–13 (`min_speed` m/frame floors Eq. 12's step so that a
    hand MNet slows early still arrives). Stops when the mean hand-to-goal distance is below `reach_tol` m or at
    `max_frames`. `body` is a SparseBody over the 400 sampled vertices (hand first); object points (P,3) and the
    object centre (3,) (the BPS basis centre) in the world. `floor` (m; None: off, GOAL's rollout) is graspkit's floor
    step, not in the paper: a frame whose lowest sole vertex is below this height is raised onto it before it is
    kept (MNet's frames sank up to 4.4 cm on the evaluation's rollouts: docs/goal.md). `stall` (frames; None: off,
    GOAL's rollout) is graspkit's stall rule, not in the paper: at each MNet step, a hand within `STALL_RADIUS` m of
    the goal hand whose distance is not `STALL_GAIN` m below the closest of the `stall` frames before (for a hand
    coming steadily closer: one that gained less than `STALL_GAIN` in its last frame) starts Eq. 12–13's refinement
    there (MNet's hand can stop 10–25 cm short and stay there: docs/goal.md)."""
    from graspkit.optim.goal_refine import (GOAL_HAND_RADIUS, MotionRefineWeights, hand_object_offsets,
                                            hand_step_targets, refine_frame)
    from graspkit.models.gnet import SparseBody, pose_rotmats

    check_stall(stall)
    _check_rollout_inputs(start, goal, betas, max_frames, reach_tol, min_speed, floor)
    c = mnet.cfg
    betas = betas.reshape(1, -1).float()
    root = rest_root(body.bm, betas)
    hand_body = SparseBody(body.bm, body.ids[:c.n_hand])
    obj = object_points.reshape(1, -1, 3).float()
    centre = obj_centre.reshape(1, 3).float()

    def verts(r6: Tensor, t: Tensor) -> Tensor:
        return body(pose_rotmats(r6), betas.expand(len(r6), -1), t)[0].float()

    if floor is not None:
        from graspkit.body.markers import foot_vertices

        soles = SparseBody(body.bm, torch.as_tensor(np.concatenate(list(foot_vertices(body.bm).values()))))

    def on_floor(r6: Tensor, t: Tensor) -> Tensor:
        """t (1,3) raised so that the lowest sole vertex of (r6, t) is not below `floor`."""
        if floor is None:
            return t
        low = soles(pose_rotmats(r6), betas, t)[0][..., 2].amin(-1)
        return t + torch.stack([torch.zeros_like(low), torch.zeros_like(low), torch.relu(floor - low)], -1).to(t.dtype)

    goal_hand = verts(goal[0][None].float(), goal[1][None].float())[:, :c.n_hand]
    rs, ts = [start[0].float()], [start[1].float()]
    vs = [verts(rs[0][None], ts[0][None])[0]]
    dist = [float((vs[0][:c.n_hand] - goal_hand[0]).norm(dim=-1).mean())]
    first_refined = None
    while len(rs) < max_frames and dist[-1] > reach_tol:
        idx = [max(len(rs) - c.n_past + k, 0) for k in range(c.n_past)]
        s = MNetState(torch.stack([rs[i] for i in idx])[None], torch.stack([ts[i] for i in idx])[None], betas,
                      vs[-1][None], vs[max(len(vs) - 2, 0)][None], goal_hand, centre,
                      hand_object_offsets(vs[-1][None], obj), root)
        r_w, t_w, out = mnet_step(mnet, s, basis)                                    # (1,F,55,6), (1,F,3) world
        stalled = (stall is not None and dist[-1] < STALL_RADIUS and len(dist) > stall
                   and dist[-1] > min(dist[-stall - 1:-1]) - STALL_GAIN)
        near = refine and (dist[-1] < GOAL_HAND_RADIUS or stalled)
        for k in range(1 if near else c.n_future):
            r, t = r_w[:, k], t_w[:, k]
            if near:
                first_refined = len(rs) if first_refined is None else first_refined
                if "d_verts" in out:
                    prev = out["d_verts"][:, k - 1, :c.n_hand] if k else torch.zeros_like(out["d_verts"][:, 0, :c.n_hand])
                    speed = (out["d_verts"][:, k, :c.n_hand] - prev).norm(dim=-1).mean(1)
                else:
                    speed = (verts(r, t)[:, :c.n_hand] - vs[-1][None, :c.n_hand]).norm(dim=-1).mean(1)
                target = hand_step_targets(vs[-1][None, :c.n_hand], goal_hand, speed.clamp_min(min_speed))
                r, t = refine_frame(hand_body, r, t, betas, target, refine_weights or MotionRefineWeights())
            t = on_floor(r, t)
            rs.append(r[0])
            ts.append(t[0])
            vs.append(verts(r, t)[0])
            dist.append(float((vs[-1][:c.n_hand] - goal_hand[0]).norm(dim=-1).mean().detach()))
            if len(rs) >= max_frames or dist[-1] <= reach_tol or (refine and not near and dist[-1] < GOAL_HAND_RADIUS):
                break                                  # (within 10 cm: the rest of this step's frames are re-planned)
    return Rollout(torch.stack(rs), torch.stack(ts), torch.tensor(dist), dist[-1] <= reach_tol, first_refined)


# ------------------------------------------------------------------------------------------- training windows

@dataclass
class ApproachClip:
    """One approach-and-grasp sequence in the world (z up): rot6d (T,55,6), transl (T,3), betas (10,), the goal frame
    (first frame of the final grasp), object surface points (P,3) and the object centre (3,) (the BPS basis centre)."""

    rot6d: Tensor
    transl: Tensor
    betas: Tensor
    goal_frame: int
    object_points: Tensor
    obj_centre: Tensor
    name: str = ""


class MNetWindows:
    """All (past 5, current, future 10) windows of a set of clips, features built per batch (Eq. 9-10).

    Frames before a clip's start repeat its first frame (a static start, as in a rollout); frames after its end
    repeat its last (the grasp holds). Per frame the 400 sampled vertices and their offsets to the object are
    computed once; everything that depends on frame t's canonical frame is computed in `batch`."""

    def __init__(self, clips: list[ApproachClip], body: SparseBody, basis: Tensor, cfg: MNetConfig | None = None,
                 stride: int = 1, chunk: int = 256, goal_repeat: int = 1, goal_span: tuple[int, int] = (-30, 5)) -> None:
        from graspkit.models.gnet import pose_rotmats

        if not clips:
            raise ValueError("clips: empty")
        self.cfg, self.basis, self.body = cfg or MNetConfig(), basis, body
        P = min(len(c.object_points) for c in clips)
        self.points = torch.stack([c.object_points[:P].float() for c in clips])       # (clips, P, 3)
        rot, tr, vs, offs, start, end, goal, clip_of, betas, centre = [], [], [], [], [], [], [], [], [], []
        goals: list[int] = []
        n = 0
        for k, c in enumerate(clips):
            T = len(c.rot6d)
            if not 0 <= c.goal_frame < T:
                raise ValueError(f"clips[{k}].goal_frame: expected a frame in [0, {T}), got {c.goal_frame}")
            b = c.betas.reshape(1, -1).float()
            with torch.no_grad():
                v = torch.cat([body(pose_rotmats(c.rot6d[i:i + chunk].float()), b.expand(len(c.rot6d[i:i + chunk]), -1),
                                    c.transl[i:i + chunk].float())[0] for i in range(0, T, chunk)]).float()
            pts = c.object_points.double().numpy()
            _, near = cKDTree(pts).query(v.reshape(-1, 3).double().numpy())      # the object does not move
            offs.append(torch.as_tensor(pts[near]).float().reshape(v.shape) - v)
            rot.append(c.rot6d.float())
            tr.append(c.transl.float())
            vs.append(v.detach())
            goal.append(v[c.goal_frame, :self.cfg.n_hand].detach())
            betas.append(b[0])
            centre.append(c.obj_centre.float().reshape(3))
            goals.append(n + c.goal_frame)
            start.append(torch.full((T,), n))
            end.append(torch.full((T,), n + T - 1))
            clip_of.append(torch.full((T,), k))
            n += T
        self.rot6d, self.transl, self.verts, self.offsets = torch.cat(rot), torch.cat(tr), torch.cat(vs), torch.cat(offs)
        self.start, self.end, self.clip = torch.cat(start), torch.cat(end), torch.cat(clip_of)
        self.goal_hand, self.betas, self.centre = torch.stack(goal), torch.stack(betas), torch.stack(centre)
        self.root = rest_root(body.bm, self.betas)
        self.feet = torch.as_tensor(feet_positions(body))
        self.windows = torch.arange(0, n, stride)
        if goal_repeat > 1:          # the reach and the grasp are a small share of each clip: show them more often
            g = torch.as_tensor(goals)[self.clip[self.windows]]
            near = self.windows[(self.windows - g >= goal_span[0]) & (self.windows - g <= goal_span[1])]
            self.windows = torch.cat([self.windows] + [near] * (goal_repeat - 1))
        self.bps = torch.cat([self._bps(self.windows[i:i + chunk]) for i in range(0, len(self.windows), chunk)])

    def _bps(self, t: Tensor) -> Tensor:
        """b^h_g of windows at global frames t, computed once with a KD-tree of each clip's goal hand: the distance from
        basis point b to the turned hand R x is the distance from R^T b to x, so only the basis turns."""
        s = self.state(t)
        R, _ = canonical_frame(rot6d_to_matrix(s.rot6d[:, -1, 0]), s.root + s.transl[:, -1])
        basis = self.basis.double().numpy()
        out = torch.empty(len(t), len(basis))
        clips = self.clip[t]
        for k in torch.unique(clips).tolist():
            rows = torch.nonzero(clips == k)[:, 0]
            tree = cKDTree((self.goal_hand[k] - self.centre[k]).double().numpy())
            q = np.einsum("kj,bji->bki", basis, R[rows].double().numpy())               # b_row @ R = (R^T b)^T
            out[rows] = torch.as_tensor(tree.query(q.reshape(-1, 3))[0]).float().reshape(len(rows), -1)
        return out

    def __len__(self) -> int:
        return len(self.windows)

    def state(self, t: Tensor) -> MNetState:
        """MNetState at global frames t (B,)."""
        c, s = self.clip[t], self.start[t]
        past = torch.maximum(t[:, None] + torch.arange(-self.cfg.n_past + 1, 1), s[:, None])
        prev = torch.maximum(t - 1, s)
        return MNetState(self.rot6d[past], self.transl[past], self.betas[c], self.verts[t], self.verts[prev],
                         self.goal_hand[c], self.centre[c], self.offsets[t], self.root[c])

    def batch(self, index: Tensor, vel_noise: float = 0.0) -> tuple[dict[str, Tensor], dict[str, Tensor], Tensor]:
        """Features, targets and the foot mask of windows `index` (B,) (positions in this set); `vel_noise` (m/frame)
        perturbs the input velocities v̇_t (training only), so that MNet does not merely continue the past motion."""
        t = self.windows[index]
        s = self.state(t)
        if vel_noise > 0:
            s.verts_prev = s.verts_prev + vel_noise * torch.randn(s.verts_prev.shape[0], 1, 3)
        feats, R, o = mnet_inputs(s, self.basis, self.cfg.attention, self.cfg.n_hand, self.bps[index])
        fut = torch.minimum(t[:, None] + torch.arange(1, self.cfg.n_future + 1), self.end[t][:, None])
        tgt = mnet_targets(s, R, o, self.rot6d[fut], self.transl[fut], self.verts[fut], self.offsets[fut], self.cfg.n_hand)
        return feats, tgt, feet_mask(self.verts[fut][..., 2], self.feet)


def feet_positions(body: SparseBody) -> list[int]:
    """Positions, among a SparseBody's vertices, of those dominated by an ankle or foot joint."""
    from graspkit.optim.goal_refine import feet_vertex_ids

    feet = set(feet_vertex_ids(body.bm).tolist())
    return [i for i, v in enumerate(body.ids.tolist()) if v in feet]


@keeps_torch_state
def train_mnet(train: MNetWindows, val: MNetWindows | None, cfg: MNetConfig | None = None,
               weights: MNetLossWeights | None = None, train_cfg: TrainConfig | None = None,
               checkpoint: str | Path | None = None, time_limit_s: float | None = None,
               progress: bool = True, vel_noise: float = 0.0) -> tuple[MNet, list[dict[str, float]]]:
    """Fit MNet with the shared loop (graspkit.train.fit) on windows; normalisation from up to 4096 windows."""
    from graspkit.train import TrainConfig, fit

    train_cfg = train_cfg or TrainConfig(epochs=10, batch_size=128, lr=1e-3)
    torch.manual_seed(train_cfg.seed)
    net = MNet(cfg or train.cfg)
    if net.cfg.attention != train.cfg.attention:
        raise ValueError("cfg.attention: the windows were built with a different attention setting")
    g = torch.Generator().manual_seed(train_cfg.seed)
    sub = torch.randperm(len(train), generator=g)[:4096]
    feats, tgt, _ = train.batch(sub)
    net.fit_normalisation(feats, tgt)

    def step(model: nn.Module, batch: list[Tensor], epoch: int) -> dict[str, Tensor]:
        f, y, foot = train.batch(batch[0], vel_noise) if model.training else val.batch(batch[0])
        return mnet_loss(model(f), y, foot, weights, net.cfg.n_hand)

    data = torch.utils.data.TensorDataset(torch.arange(len(train)))
    val_data = None if val is None else torch.utils.data.TensorDataset(torch.arange(len(val)))
    hist = fit(net, step, data, train_cfg, checkpoint=checkpoint, val_dataset=val_data, progress=progress,
               time_limit_s=time_limit_s, extra={"mnet_config": net.config_dict()})
    return net, hist


@keeps_torch_state
def load_mnet(path: str | Path) -> MNet:
    """An MNet from a shipped (or training) checkpoint, in float32 and eval mode."""
    from graspkit.models.gnet import load_weights
    from graspkit.train import build_named, load_into

    state, config = load_weights(path, "mnet", MNetConfig)
    return build_named(path, "an MNet checkpoint",
                       lambda: load_into(MNet(MNetConfig(**config)), state, path, "an MNet checkpoint")).eval()
