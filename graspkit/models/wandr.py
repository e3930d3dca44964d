"""WANDR (Diomataris et al., CVPR 2024): an autoregressive conditional VAE on pose deltas, steered by intention.

    model = WandrCVAE(WandrConfig(), stats)                            # stats: compute_stats(train clips)
    history = train_wandr(model, train_clips, TrainConfig(...))        # §3.4 losses, Sup. B.2 rollout schedule
    out = generate(model, start, goals, t_goal=239, n=5, generator=g)  # §3.5: batched rollout, fresh z every frame

Model (§3.3, Sup. B.1): encoder q(z | d_i, c_i) and decoder (z, c_i) -> d̂_i, both MLPs with LayerNorm, ReLU and
dropout; the prior is fixed at N(0, I) (no prior network). The condition c_i = (p^dyn_i, I_i) is the state and the
intention (graspkit.intention); deltas, states and intentions enter normalised with training statistics, which live
in the model's buffers (so in every checkpoint). Ablations (Tab. 2) drop intention parts from the condition.

Loss (§3.4): L = L_rec + α L_KL + L_J with α = 1e-2: L_rec the squared error of the normalised deltas (summed over
the 135 values, mean over the batch), L_KL the KL of q(z | .) from N(0, I) (summed over the latent, mean over the
batch), L_J the squared distance of the 22 body joints after integrating d̂ and forward kinematics, in cm² (mean
over joints and batch). The paper does not say how its MSEs are reduced; with means over the 135 values, α = 1e-2
made the posterior collapse here (KL ≈ 0.003 nats: the decoder ignored z and predicted means), so the sums keep
z informative, and centimetres put L_J on the scale of L_rec. No goal-reaching loss. An optional term that is not in
the paper, w_foot (default 0) times the squared error of the foot joints' horizontal step per frame (mm²), was tried
against foot skating and is off in the shipped model (docs/wandr.md). w_contact (default 0; 1 in the shipped model) is a
foot-contact term: the squared horizontal step (mm²) of each foot joint that is planted in the data at that frame (it
moves less than 1 mm there), so only standing feet are held, never the swing foot. w_floor (default 0) is a floor
term, not in the paper either: the squared difference (cm²) between the height of the lowest foot joint and the
data's at that frame, against a body that rises off the floor as the rollout goes on (docs/wandr.md, "Feet off the
floor"); it does not depend on the gait's phase, unlike the per-joint L_J.

Rollout schedule (Sup. B.2): after the reconstruction step, the model runs s more steps on its own output: each step
integrates the predicted delta, recomputes state and intention from the generated pose, samples z from the prior and
decodes; the losses are taken against the ground truth of those frames. s grows linearly from 0 to `max_steps` (10)
over `ramp_epochs`, then stays.
"""
from __future__ import annotations

import numbers
import warnings
from collections.abc import Callable, Iterable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Sequence

import numpy as np
import torch
from torch import Tensor, nn

from graspkit import intention as I
from graspkit.body.skeleton import JOINT_NAMES
from graspkit.checks import GraspkitWarning, check_finite, check_generator, check_int, user_stacklevel
from graspkit.data.wandr_dataset import (FOOT_JOINTS, GOAL_FRAMES, STD_FLOOR, ClipSet, WindowDataset, lowest_foot,
                                         make_batch)
from graspkit.models.blocks import GaussianHead, evaluating, kl_standard_normal
from graspkit.state import keeps_torch_state
from graspkit.train import TrainConfig, build_named, check_config, fit, load_checkpoint, load_into, save_checkpoint

FULL_INTENTION = ("wrist", "orientation", "pelvis")
FEET = FOOT_JOINTS                                   # ankles and feet: the foot-velocity, contact and floor terms
OUT_OF_TRAINING_SIGMA = 5.0  # a start's state feature this many stds from the mean, where training hardly moved it
PLANTED_STEP = 1e-3          # m per frame: a foot joint the data moves less than this is planted (w_contact)


@dataclass
class WandrConfig:
    """Network and loss settings (paper values in brackets: latent 64, 15-layer MLPs, α = 1e-2, rollout 0 -> 10)."""

    latent: int = 32
    hidden: int = 256
    enc_layers: int = 3
    dec_layers: int = 4
    dropout: float = 0.05
    intention: tuple[str, ...] = FULL_INTENTION        # Tab. 2 ablations: ("wrist",), ("wrist", "pelvis"), ...
    alpha_kl: float = 1e-2
    w_joint: float = 1.0
    w_foot: float = 0.0                                # not in the paper: foot-joint velocity term (docs/wandr.md)
    w_contact: float = 0.0                             # not in the paper: planted feet held in place (docs/wandr.md)
    w_floor: float = 0.0                               # not in the paper: the lowest foot joint's height (docs/wandr.md)
    max_steps: int = 10
    ramp_epochs: int = 4
    rollout_latent: str = "prior"                      # "prior" (Sup. B.2) or "posterior" (encoder on the truth)
    rollout_grad: str = "through"                      # "through": backpropagate through the rollout; "step": roll out
                                                       # without gradient, then one batched step from every state
    step_stride: int = 1                               # rollout_grad="step": recompute every n-th step (random phase)
    goal_frame: str = "reach"                          # reaching clips' t_G: "reach" (arrival) or "hold" (its end)

    def __post_init__(self) -> None:
        self.intention = tuple(self.intention)
        bad = [x for x in self.intention if x not in I.INTENTION_PARTS]
        if bad:
            raise ValueError(f"intention: unknown parts {bad}; expected a subset of {tuple(I.INTENTION_PARTS)}")
        if self.rollout_latent not in ("prior", "posterior"):
            raise ValueError(f"rollout_latent: expected 'prior' or 'posterior', got {self.rollout_latent!r}")
        if self.rollout_grad not in ("through", "step"):
            raise ValueError(f"rollout_grad: expected 'through' or 'step', got {self.rollout_grad!r}")
        if self.step_stride < 1:
            raise ValueError(f"step_stride: expected >= 1, got {self.step_stride}")
        if self.rollout_grad == "step" and self.rollout_latent != "prior":
            raise ValueError("rollout_grad: 'step' draws the rollout's z from the prior; it does not combine with "
                             f"rollout_latent={self.rollout_latent!r}")
        if self.goal_frame not in GOAL_FRAMES:
            raise ValueError(f"goal_frame: expected one of {GOAL_FRAMES}, got {self.goal_frame!r}")

    def rollout_steps(self, epoch: int) -> int:
        """s at `epoch` (0-based): linear from 0 to max_steps over ramp_epochs, then max_steps."""
        if self.ramp_epochs <= 0:
            return self.max_steps
        return min(self.max_steps, int(round(self.max_steps * epoch / self.ramp_epochs)))


def _mlp(n_in: int, hidden: int, layers: int, n_out: int, dropout: float) -> nn.Sequential:
    """`layers` blocks of Linear + LayerNorm + ReLU + Dropout (Sup. B.1), then a linear output: (B, n_in) -> (B, n_out)."""
    mods: list[nn.Module] = []
    for k in range(layers):
        mods += [nn.Linear(n_in if k == 0 else hidden, hidden), nn.LayerNorm(hidden), nn.ReLU(), nn.Dropout(dropout)]
    mods.append(nn.Linear(hidden if layers else n_in, n_out))
    return nn.Sequential(*mods)


def _default_stats() -> dict[str, Tensor]:
    """Identity normalisation (mean 0, std 1) for a model built before statistics exist."""
    return {"delta_mean": torch.zeros(I.DELTA_DIM), "delta_std": torch.ones(I.DELTA_DIM),
            "state_mean": torch.zeros(I.STATE_DIM), "state_std": torch.ones(I.STATE_DIM),
            "intention_mean": torch.zeros(I.INTENTION_DIM), "intention_std": torch.ones(I.INTENTION_DIM)}


class WandrCVAE(nn.Module):
    """The c-VAE: encoder (d_i, c_i) -> q(z), decoder (z, c_i) -> d̂_i; c_i = normalised (state, kept intention)."""

    # buffers, registered in __init__ (declared for type checkers)
    delta_mean: Tensor
    delta_std: Tensor
    state_mean: Tensor
    state_std: Tensor
    intention_mean: Tensor
    intention_std: Tensor
    intention_keep: Tensor

    def __init__(self, cfg: WandrConfig | None = None, stats: dict[str, Tensor] | None = None) -> None:
        super().__init__()
        self.cfg = cfg = cfg or WandrConfig()
        for k, v in (stats or _default_stats()).items():
            self.register_buffer(k, torch.as_tensor(v, dtype=torch.float32).clone())
        keep = torch.zeros(I.INTENTION_DIM, dtype=torch.bool)
        for part in cfg.intention:
            keep[I.INTENTION_PARTS[part]] = True
        self.register_buffer("intention_keep", keep)
        self.cond_dim = I.STATE_DIM + int(keep.sum())
        self.encoder = _mlp(I.DELTA_DIM + self.cond_dim, cfg.hidden, cfg.enc_layers, cfg.hidden, cfg.dropout)
        self.head = GaussianHead(cfg.hidden, cfg.latent)
        self.decoder = _mlp(cfg.latent + self.cond_dim, cfg.hidden, cfg.dec_layers, I.DELTA_DIM, cfg.dropout)

    @property
    def dtype(self) -> torch.dtype:
        """The weights' dtype (float32 unless the caller converted the model): rollouts run in it."""
        return self.decoder[0].weight.dtype

    def condition(self, state: Tensor, inten: Tensor) -> Tensor:
        """Normalised condition (B, cond_dim) from raw state (B, 268) and intention (B, 7); dropped parts removed."""
        s = (state - self.state_mean) / self.state_std
        i = ((inten - self.intention_mean) / self.intention_std)[..., self.intention_keep]
        return torch.cat([s, i], dim=-1)

    def untrained_features(self, state: Tensor, sigma: float = OUT_OF_TRAINING_SIGMA) -> list[str]:
        """Names of the state features (B, 268) that lie more than `sigma` stds from the training mean where training
        hardly moved them (std at STD_FLOOR): the joints the model has only ever seen still (docs/wandr.md)."""
        floored = self.state_std <= STD_FLOOR * (1 + 1e-3)
        far = ((((state - self.state_mean) / self.state_std).abs() > sigma) & floored).any(0)
        return sorted({state_feature_name(int(i)) for i in torch.nonzero(far).flatten()})

    def normalise_delta(self, d: Tensor) -> Tensor:
        """Raw delta (B, 135) -> normalised."""
        return (d - self.delta_mean) / self.delta_std

    def encode(self, d: Tensor, cond: Tensor) -> tuple[Tensor, Tensor]:
        """q(z | d, c): raw delta (B, 135), condition (B, cond_dim) -> mean, log-variance (B, latent)."""
        return self.head(self.encoder(torch.cat([self.normalise_delta(d), cond], dim=-1)))

    def decode(self, z: Tensor, cond: Tensor) -> Tensor:
        """Decoder: z (B, latent), condition (B, cond_dim) -> raw delta d̂ (B, 135)."""
        return self.decoder(torch.cat([z, cond], dim=-1)) * self.delta_std + self.delta_mean


# ----------------------------------------------------------------------------------------------------- training
def training_losses(model: WandrCVAE, clips: ClipSet, items: Tensor, steps: int,
                    generator: torch.Generator | None = None) -> dict[str, Tensor]:
    """§3.4 losses over a batch of windows (items (B, 2)) with `steps` rollout steps (Sup. B.2)."""
    cfg = model.cfg
    b = make_batch(clips, items, steps, generator=generator, goal_frame=cfg.goal_frame)
    p, rest, goal, t_goal, gh = b["p"], b["rest"], b["goal"], b["t_goal"], b["goal_heading"]
    d_gt = I.poses_to_deltas(p)                                  # (B, steps+2, 135): d_i .. d_{i+1+steps}
    with torch.no_grad():
        J_gt = I.body_joints(p[:, 1:], rest[:, None])             # (B, steps+2, 22, 3): frames i .. i+1+steps
    cur_p, cur_d = p[:, 1], d_gt[:, 0]
    if cfg.rollout_grad == "step" and steps > 0:
        return _step_losses(model, b, d_gt, J_gt, steps, generator)
    t, R = I.pose_rotmats(cur_p)
    J = I.fk_rotmats(t, R, rest)[1]
    rec = joint = kl = foot = contact = floor = torch.zeros((), dtype=p.dtype)
    for k in range(steps + 1):
        state = I.state_features(cur_p, cur_d, root=R[:, 0])
        inten = I.intention(J[:, I.WRIST], J[:, I.PELVIS], I.yaw_of(R[:, 0]), goal, (t_goal - k).to(p.dtype) / I.FPS, gh)
        cond = model.condition(state, inten)
        target = d_gt[:, k + 1]
        if k == 0 or cfg.rollout_latent == "posterior":
            mu, logvar = model.encode(target, cond)
            z = mu + torch.exp(0.5 * logvar) * torch.randn(mu.shape, generator=generator)
            kl = kl + kl_standard_normal(mu, logvar)
        else:
            z = torch.randn(len(cur_p), cfg.latent, generator=generator)
        d_hat = model.decode(z, cond)
        t, R = I.integrate_rotmats(t, R, d_hat)
        cur_p, cur_d, J_prev = I.pose_from_rotmats(t, R), d_hat, J
        J = I.fk_rotmats(t, R, rest)[1]
        e = _step_terms(model, d_hat, target, J, J_prev, J_gt[:, k + 1], J_gt[:, k])
        rec, joint = rec + e["rec"], joint + e["joint"]
        if cfg.w_foot or cfg.w_contact:
            foot, contact = foot + e["foot"], contact + e["contact"]
        if cfg.w_floor:
            floor = floor + e["floor"]
    n = steps + 1
    n_kl = n if cfg.rollout_latent == "posterior" else 1
    return _total(cfg, {"rec": rec / n, "joint": joint / n, "foot": foot / n, "contact": contact / n,
                        "floor": floor / n}, kl / n_kl, steps)


def _step_terms(model: WandrCVAE, d_hat: Tensor, target: Tensor, J: Tensor, J_prev: Tensor, J_true: Tensor,
                J_true_prev: Tensor) -> dict[str, Tensor]:
    """§3.4's terms of one decoded step, means over its rows: decoded / data delta (R, 135), the joints (R, 22, 3)
    after and before the step, and the data's at the same frames; plus the optional foot, contact and floor terms."""
    cfg = model.cfg
    e = {"rec": (model.normalise_delta(d_hat) - model.normalise_delta(target)).pow(2).sum(-1).mean(),
         "joint": (100 * (J - J_true)).pow(2).sum(-1).mean()}
    if cfg.w_foot or cfg.w_contact:     # the foot joints' horizontal step here and in the data (R, 4, 2)
        v, v_gt = J[:, FEET, :2] - J_prev[:, FEET, :2], J_true[:, FEET, :2] - J_true_prev[:, FEET, :2]
        e["foot"] = (1000 * (v - v_gt)).pow(2).sum(-1).mean()                 # every foot joint as the data (mm²)
        planted = v_gt.norm(dim=-1) < PLANTED_STEP                             # still in the data: held still here
        e["contact"] = (planted * (1000 * v).pow(2).sum(-1)).mean()
    if cfg.w_floor:                     # the lowest foot joint's height here and in the data (R,), cm²
        e["floor"] = (100 * (lowest_foot(J) - lowest_foot(J_true))).pow(2).mean()
    return e


def _total(cfg: WandrConfig, e: dict[str, Tensor], kl: Tensor, steps: int) -> dict[str, Tensor]:
    """The weighted loss of the step-averaged terms `e` and the KL, and the logged terms."""
    zero = torch.zeros(())
    foot, contact, floor = (e.get(k, zero) for k in ("foot", "contact", "floor"))
    loss = (e["rec"] + cfg.alpha_kl * kl + cfg.w_joint * e["joint"] + cfg.w_foot * foot + cfg.w_contact * contact
            + cfg.w_floor * floor)
    return {"loss": loss, "rec": e["rec"].detach(), "kl": kl.detach(), "joint_cm2": e["joint"].detach(),
            **({"foot_mm2": foot.detach()} if cfg.w_foot else {}),
            **({"contact_mm2": contact.detach()} if cfg.w_contact else {}),
            **({"floor_cm2": floor.detach()} if cfg.w_floor else {}),
            "steps": torch.tensor(float(steps))}


def _step_losses(model: WandrCVAE, b: dict[str, Tensor], d_gt: Tensor, J_gt: Tensor, steps: int,
                 generator: torch.Generator | None) -> dict[str, Tensor]:
    """`training_losses` with rollout_grad="step" (not in the paper): the rollout (frames i+1 .. i+steps) runs without
    gradient and in eval mode (no dropout: the states the model visits when it generates), then its steps are
    recomputed with gradient in one batch, each from the state the rollout visited and with the noise it drew: the
    reconstruction step (with its KL) and every `step_stride`-th rollout step (a random phase per batch). The
    gradient stops at each step's input state (no backpropagation through time); the terms and weights are
    `training_losses`'s, averaged over the recomputed steps."""
    cfg = model.cfg
    p, rest, goal, t_goal, gh = b["p"], b["rest"], b["goal"], b["t_goal"], b["goal_heading"]
    B = len(p)
    t, R = I.pose_rotmats(p[:, 1])
    cur_p, cur_d = p[:, 1], d_gt[:, 0]
    ts, Rs, ds, noise = [t], [R], [cur_d], []
    was_training = model.training
    model.eval()
    with torch.no_grad():                                           # the states the model itself visits
        for k in range(steps):
            J = I.fk_rotmats(t, R, rest)[1]
            cond = model.condition(I.state_features(cur_p, cur_d, root=R[:, 0]),
                                   I.intention(J[:, I.WRIST], J[:, I.PELVIS], I.yaw_of(R[:, 0]), goal,
                                               (t_goal - k).to(p.dtype) / I.FPS, gh))
            if k == 0:                                              # the reconstruction step: z from q(z | d, c)
                mu, logvar = model.encode(d_gt[:, 1], cond)
                eps = torch.randn(mu.shape, generator=generator)
                z = mu + torch.exp(0.5 * logvar) * eps
                noise.append(eps)
            else:
                z = torch.randn(B, cfg.latent, generator=generator)
                noise.append(z)
            cur_d = model.decode(z, cond)
            t, R = I.integrate_rotmats(t, R, cur_d)
            cur_p = I.pose_from_rotmats(t, R)
            ts.append(t), Rs.append(R), ds.append(cur_d)
        noise.append(torch.randn(B, cfg.latent, generator=generator))   # the last step's, as "through" draws it
    model.train(was_training)
    phase = int(torch.randint(cfg.step_stride, (1,), generator=generator)) if cfg.step_stride > 1 else 0
    keep = [0] + [k for k in range(1, steps + 1) if k % cfg.step_stride == phase]
    n = len(keep)
    # the kept steps again with gradient, from the visited states (rows block-major: block j = step keep[j])
    t0, R0, d0 = (torch.cat([x[k] for k in keep]) for x in (ts, Rs, ds))
    ks = torch.tensor(keep)
    rest_n = rest.repeat(n, 1, 1)
    k_of = ks.repeat_interleave(B)
    J0 = I.fk_rotmats(t0, R0, rest_n)[1]
    cond = model.condition(I.state_features(I.pose_from_rotmats(t0, R0), d0, root=R0[:, 0]),
                           I.intention(J0[:, I.WRIST], J0[:, I.PELVIS], I.yaw_of(R0[:, 0]), goal.repeat(n, 1),
                                       (t_goal.repeat(n) - k_of).to(p.dtype) / I.FPS, gh.repeat(n)))
    target = d_gt[:, ks + 1].transpose(0, 1).reshape(n * B, -1)
    mu, logvar = model.encode(target[:B], cond[:B])
    z = torch.cat([mu + torch.exp(0.5 * logvar) * noise[0]] + [noise[k] for k in keep[1:]])
    d_hat = model.decode(z, cond)
    t1, R1 = I.integrate_rotmats(t0, R0, d_hat)
    J1 = I.fk_rotmats(t1, R1, rest_n)[1]
    rows = lambda x: x.transpose(0, 1).reshape(n * B, I.NUM_BODY, 3)      # noqa: E731 - (B, n, 22, 3) -> (nB, ...)
    e = _step_terms(model, d_hat, target, J1, J0, rows(J_gt[:, ks + 1]), rows(J_gt[:, ks]))
    return _total(cfg, e, kl_standard_normal(mu, logvar), steps)


def train_wandr(model: WandrCVAE, clips: ClipSet, cfg: TrainConfig, checkpoint: str | Path | None = None,
                stride: dict[str, int] | None = None, progress: bool = True, time_limit_s: float | None = None,
                stop_at: int | None = None) -> list[dict[str, float]]:
    """Train with graspkit's loop (seeded, resumable): every epoch one pass over the windows (frame strides per kind,
    e.g. {'locomotion': 4, 'reach': 2}, keep epochs short); the stats and the model config go into the checkpoint;
    `stop_at` stops after that epoch (the same command resumes: one epoch at a time gives the same weights)."""
    ds = WindowDataset(clips, max_steps=model.cfg.max_steps)
    if stride:
        keep = torch.ones(len(ds), dtype=torch.bool)
        for k, kind in enumerate(("locomotion", "reach")):
            s = int(stride.get(kind, 1))
            if s < 1:
                raise ValueError(f"stride: expected >= 1 for {kind}, got {s}")
            of_kind = clips.kind[ds.items[:, 0]] == k
            keep &= ~of_kind | (ds.items[:, 1] % s == 0)
        ds.items = ds.items[keep]

    def step(net: nn.Module, items: Tensor, epoch: int) -> dict[str, Tensor]:
        return training_losses(net, clips, items, model.cfg.rollout_steps(epoch))

    extra = {"wandr_config": asdict(model.cfg)}
    return fit(model, step, ds, cfg, checkpoint=checkpoint, extra=extra, progress=progress, time_limit_s=time_limit_s,
               stop_at=stop_at, ddp=False)           # training_losses calls encode / decode, not forward


def save_wandr(path: str | Path, model: WandrCVAE, history: Sequence[dict] = (), meta: dict[str, Any] | None = None,
               half: bool = True) -> Path:
    """A small shippable checkpoint: weights (float16 when `half`, the normalisation buffers float32), config, history,
    meta; atomic write. Load with load_wandr (weights back in float32)."""
    cfg = asdict(model.cfg)
    cfg["intention"] = list(cfg["intention"])
    stats = set(_default_stats())
    weights = {k: (v.half() if half and v.is_floating_point() and k not in stats else v.clone())
               for k, v in model.state_dict().items()}
    return save_checkpoint(path, {"model": weights, "wandr_config": cfg, "history": list(history),
                                  "meta": dict(meta or {})})


@keeps_torch_state
def load_wandr(path: str | Path) -> WandrCVAE:
    """A WandrCVAE from save_wandr's file or a `train_wandr` checkpoint (weights_only load); in eval mode."""
    state = load_checkpoint(path)
    cfg = state.get("wandr_config") or state.get("extra", {}).get("wandr_config")
    if not isinstance(cfg, dict) or not isinstance(state.get("model"), dict):
        raise ValueError(f"checkpoint {path}: not a WANDR checkpoint (no 'wandr_config' / 'model')")
    check_config(cfg, WandrConfig, path, "a WANDR checkpoint")
    if not all(torch.is_tensor(v) for v in state["model"].values()):
        raise ValueError(f"checkpoint {path}: not a WANDR checkpoint (its 'model' holds values other than tensors)")
    weights = {k: v.float() if v.is_floating_point() else v for k, v in state["model"].items()}
    model = build_named(path, "a WANDR checkpoint",
                        lambda: load_into(WandrCVAE(WandrConfig(**cfg)), weights, path, "a WANDR checkpoint"))
    model.meta = state.get("meta", {})
    model.history = state.get("history", [])
    return model.eval()


# ----------------------------------------------------------------------------------------------------- generation
@dataclass
class Rollout:
    """A batch of generated motions: poses p (B, T, 135) and body joints (B, T, 22, 3) (frame 0 = the start), the goal
    per frame (B, T, 3), rest joints (B, 22, 3); None where not kept."""

    p: Tensor | None
    joints: Tensor | None
    goal: Tensor
    rest: Tensor
    info: dict[str, Any] = field(default_factory=dict)


FrameHook = Callable[[int, Tensor, Tensor, Tensor], None]


def check_floor(floor: Any) -> None:
    """A ValueError unless floor (rollout's floor constraint) is None or a tolerance >= 0 in metres (bools refused)."""
    if floor is not None and (isinstance(floor, bool) or not isinstance(floor, numbers.Real)
                              or not 0 <= floor < float("inf")):                    # NaN fails this too
        raise ValueError(f"floor: expected None or a finite tolerance >= 0 in metres, got {floor!r}")


def _per_frame(x: Tensor | int, B: int, T: int, width: int | None, name: str) -> Tensor:
    """A goal / goal frame given once (w,), per sequence (B, w), per frame (1, T, w) or both (B, T, w) -> (B, T, w)
    (w omitted for goal frames)."""
    x = torch.as_tensor(x)
    w = (width,) if width else ()
    if x.shape == w:
        return x.expand((B, T) + w)
    if x.shape == (B,) + w:
        return x.unsqueeze(1).expand((B, T) + w)
    if x.dim() == len(w) + 2 and x.shape[1:] == (T,) + w and x.shape[0] in (1, B):
        return x.expand((B, T) + w)
    raise ValueError(f"{name}: expected shape {w}, {(B,) + w}, {(1, T) + w} or {(B, T) + w}, got {tuple(x.shape)}")


def state_feature_name(i: int) -> str:
    """What state feature i (of 268, `intention.state_features`) describes: a joint's rotation or its change."""
    body = JOINT_NAMES[1:I.NUM_BODY]
    if i == 0:
        return "pelvis height"
    if i < 7:
        return "root (yaw-free)"
    if i < 7 + 6 * len(body):
        return body[(i - 7) // 6]
    j = i - 7 - 6 * len(body)                     # the previous delta: translation (3), root (6), body joints (126)
    return "previous delta: " + ("translation" if j < 3 else "root" if j < 9 else body[(j - 9) // 6])


def rollout(model: WandrCVAE, p_prev: Tensor, p0: Tensor, rest: Tensor, goal: Tensor, t_goal: Tensor | int,
            frames: int, z: Tensor | None = None, generator: torch.Generator | None = None,
            keep: bool = True, on_frame: FrameHook | None = None, goal_heading: Tensor | None = None,
            floor: float | None = None, lift: bool = False) -> Rollout:
    """WANDR §3.5: from starts p_prev, p0 (B, 135) with rest joints (B, 22, 3), generate `frames` more frames (in the
    model's dtype: other float inputs are cast to it).

    goal (B, 3) or per frame (B, frames+1, 3); t_goal the goal frame (int, (B,) or per frame (B, frames+1)) counted
    from the start (frame 0). Each frame: intention from the current pose (inference form of I^r), z from N(0, I) drawn
    from `generator` (or z[:, k] when z (B, frames, latent) is given: differentiable, for latent optimisation), decode,
    integrate. on_frame(k, p_k (B, 135), joints_k (B, 22, 3), global rotations (B, 22, 3, 3)) is called for
    k = 0..frames; keep=False stores nothing. goal_heading (B,) switches I^r to its training form (the heading wanted
    at the goal) instead of the direction from the pelvis to the goal. floor (m; None: off, the paper's rollout) is a
    floor constraint that is not in the paper: after every generated frame the body is lowered so that its lowest
    foot joint is at most `floor` above its height at the start (the training clips hold it there to 0.1 mm), and the
    frame's delta is the one that lowered pose had (docs/wandr.md, "Feet off the floor"). lift (not in the paper
    either): a body whose lowest foot joint is below its height at the start is raised to it, the same way (against
    the body sinking into the floor; both together pin that joint at its start height).
    """
    B = p0.shape[0]
    T = check_int(frames, "frames", least=1) + 1
    if p_prev.shape != p0.shape or p0.shape[-1] != I.POSE_DIM or p0.dim() != 2:
        raise ValueError(f"p0: expected (B, 135) with p_prev alike, got {tuple(p0.shape)} and {tuple(p_prev.shape)}")
    if rest.shape != (B, I.NUM_BODY, 3):
        raise ValueError(f"rest: expected shape ({B}, 22, 3), got {tuple(rest.shape)}")
    for x, name, what in ((p_prev, "p_prev", "poses"), (p0, "p0", "poses"), (rest, "rest", "rest joints in metres")):
        check_finite(x, name, what)
    if goal_heading is not None:
        if tuple(goal_heading.shape) != (B,):
            raise ValueError(f"goal_heading: expected shape ({B},), got {tuple(goal_heading.shape)}")
        check_finite(goal_heading, "goal_heading", "headings in radians")
    if z is not None and tuple(z.shape) != (B, frames, model.cfg.latent):
        raise ValueError(f"z: expected shape ({B}, {frames}, {model.cfg.latent}), got {tuple(z.shape)}")
    check_floor(floor)
    if not isinstance(lift, bool):
        raise ValueError(f"lift: expected True or False, got {lift!r}")
    dtype = model.dtype                                    # float64 poses on a float32 model are cast
    p_prev, p0, rest = p_prev.to(dtype), p0.to(dtype), rest.to(dtype)
    z = None if z is None else z.to(dtype)
    goal_heading = None if goal_heading is None else goal_heading.to(dtype)
    goals = _per_frame(goal, B, T, 3, "goal").to(p0.dtype)
    tg = _per_frame(torch.as_tensor(t_goal), B, T, None, "t_goal")
    if not bool(torch.isfinite(goals).all()):
        raise ValueError("goal: contains NaN or Inf (expected world positions in metres)")
    if not bool((tg >= 1).all()) or bool((tg != tg.round()).any()):       # NaN fails this too
        raise ValueError(f"t_goal: expected whole goal frames >= 1 (counted from the start, frame 0), got "
                         f"{tg.unique()[:5].tolist()}")
    cur_p, cur_d = p0, I.pose_to_delta(p_prev, p0)
    t, R = I.pose_rotmats(p0)
    with torch.no_grad():
        untrained = model.untrained_features(I.state_features(p0.detach(), cur_d.detach()))
    if untrained:
        warnings.warn(f"start: the state features of {', '.join(untrained)} lie more than {OUT_OF_TRAINING_SIGMA:g} training stds from where "
                      "the training clips held them (they never moved there, std at the 1e-3 floor); the shipped "
                      "model then reaches far less often (a left wrist turned 0.1 rad: SR 99.5 -> 6 %, docs/wandr.md). "
                      "Start from a pose of the training distribution (eval_wandr.starts_from_meta, or the planner's)",
                      GraspkitWarning, stacklevel=user_stacklevel())
    ps, js = [], []
    low0 = None
    for k in range(T):
        Rg, J = I.fk_rotmats(t, R, rest)
        if floor is not None or lift:
            low = lowest_foot(J)
            if low0 is None:
                low0 = low
            else:                   # move the body onto the floor: translation, joints and the last delta alike
                dz = torch.zeros_like(t)
                if floor is not None:
                    dz[:, 2] = (low - low0 - floor).clamp(min=0)
                if lift:
                    dz[:, 2] = dz[:, 2] + (low - low0).clamp(max=0)
                t, J, cur_d = t - dz, J - dz[:, None], torch.cat([cur_d[:, :3] - dz, cur_d[:, 3:]], -1)
                cur_p = torch.cat([t, cur_p[:, 3:]], -1)
        if keep:
            ps.append(cur_p)
            js.append(J)
        if on_frame is not None:
            on_frame(k, cur_p, J, Rg)
        if k == frames:
            break
        state = I.state_features(cur_p, cur_d, root=R[:, 0])
        inten = I.intention(J[:, I.WRIST], J[:, I.PELVIS], I.yaw_of(R[:, 0]), goals[:, k],
                            (tg[:, k] - k).to(p0.dtype) / I.FPS, goal_heading)
        cond = model.condition(state, inten)
        zk = z[:, k] if z is not None else torch.randn(B, model.cfg.latent, generator=generator, dtype=p0.dtype)
        d_hat = model.decode(zk, cond)
        t, R = I.integrate_rotmats(t, R, d_hat)
        cur_p, cur_d = I.pose_from_rotmats(t, R), d_hat
    return Rollout(torch.stack(ps, 1) if keep else None, torch.stack(js, 1) if keep else None, goals, rest)


def expand_starts(starts: I.StartPose | Sequence[I.StartPose], goals: Tensor, n: int
                  ) -> tuple[Tensor, Tensor, Tensor, Tensor, Tensor]:
    """Batch every (start, goal, sample) combination, start-major: p_prev, p0 (B, 135), rest (B, 22, 3), goal (B, 3),
    and the index table (B, 3) = (start, goal, sample); B = S * G * n."""
    if isinstance(starts, (str, bytes)) or not isinstance(starts, (I.StartPose, Sequence)):
        raise ValueError(f"start: expected a StartPose or a non-empty sequence of them, got {type(starts).__name__}")
    starts = [starts] if isinstance(starts, I.StartPose) else list(starts)
    if not starts or not all(isinstance(s, I.StartPose) for s in starts):
        raise ValueError(f"start: expected a StartPose or a non-empty sequence of them, got {len(starts)} items")
    for k, s in enumerate(starts):
        for name, shape in (("p_prev", (I.POSE_DIM,)), ("p", (I.POSE_DIM,)), ("rest", (I.NUM_BODY, 3))):
            x = getattr(s, name)
            if not isinstance(x, Tensor) or tuple(x.shape) != shape or not x.is_floating_point():
                got = f"{x.dtype} {tuple(x.shape)}" if isinstance(x, Tensor) else type(x).__name__
                raise ValueError(f"start: expected {name} a float tensor of shape {shape}, got {got} (start {k})")
            if not torch.isfinite(x).all():
                raise ValueError(f"start: {name} contains NaN or Inf (start {k})")
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)):
        raise ValueError(f"n: expected a whole number of samples, got {n!r}")
    goals = torch.as_tensor(goals, dtype=torch.float32)
    if goals.dim() not in (1, 2) or goals.shape[-1] != 3 or goals.numel() == 0:
        raise ValueError(f"goal: expected (3,) or (G, 3) positions in metres, got shape {tuple(goals.shape)}")
    if not torch.isfinite(goals).all():
        raise ValueError("goal: expected finite positions, got NaN or inf")
    goals = goals.reshape(-1, 3)
    if n < 1:
        raise ValueError(f"n: expected >= 1, got {n}")
    S, G = len(starts), len(goals)
    idx = torch.stack(torch.meshgrid(torch.arange(S), torch.arange(G), torch.arange(n), indexing="ij"), -1).reshape(-1, 3)
    pp = torch.stack([s.p_prev for s in starts]).float()[idx[:, 0]]        # float32, as the model and the goals
    p0 = torch.stack([s.p for s in starts]).float()[idx[:, 0]]
    rest = torch.stack([s.rest for s in starts]).float()[idx[:, 0]]
    return pp, p0, rest, goals[idx[:, 1]], idx


@torch.no_grad()
def generate(model: WandrCVAE, start: I.StartPose | Sequence[I.StartPose], goal: Tensor, t_goal: int | Tensor,
             n: int = 1, generator: torch.Generator | None = None, frames: int | None = None, keep: bool = True,
             on_frame: FrameHook | None = None, floor: float | None = None, lift: bool = False) -> Rollout:
    """Reach goals (G, 3) from one or more starts, n samples each, all in one batched rollout (B = S * G * n,
    start-major). t_goal: the goal frame (int or (G,)); frames: how many to generate (default max t_goal: the clip has
    frames + 1 poses, the start included); floor, lift: `rollout`'s floor constraints (off, as the paper).
    Every frame draws z for the whole batch from `generator`, so a sequence's draws depend on the batch it is in:
    the same seed gives the same motions for the same starts, goals and n, not for one goal taken out of them.
    The model runs in eval mode (no dropout) and is left in the mode it came in."""
    check_generator(generator)
    pp, p0, rest, g, idx = expand_starts(start, goal, n)
    dtype = model.dtype                                    # float32 unless the caller converted the model
    pp, p0, rest, g = (x.to(dtype) for x in (pp, p0, rest, g))
    try:
        tg = torch.as_tensor(t_goal)
    except (TypeError, ValueError, RuntimeError):
        raise ValueError(f"t_goal: expected goal frames (integers >= 1), got {t_goal!r}") from None
    if tg.dim() > 1 or (tg.dim() == 1 and len(tg) != int(idx[:, 1].max()) + 1):
        raise ValueError(f"t_goal: expected a frame or one per goal, got shape {tuple(tg.shape)}")
    if tg.dtype.is_floating_point or tg.dtype == torch.bool or int(tg.min()) < 1:
        raise ValueError(f"t_goal: expected goal frames (integers >= 1), got {t_goal}")
    if tg.dim() == 1:
        tg = tg[idx[:, 1]]
    frames = int(tg.max()) if frames is None else check_int(frames, "frames", least=1)
    _warn_out_of_range(p0, rest, g, tg.expand(len(g)) if tg.dim() == 0 else tg)
    with evaluating(model):
        out = rollout(model, pp, p0, rest, g, tg, frames, generator=generator, keep=keep, on_frame=on_frame,
                      floor=floor, lift=lift)
    out.info["index"] = idx
    return out


MAX_SECONDS = 8.0       # the goal grid's horizon (§4.2): what the shipped model is trained and measured for
MAX_HEIGHT = 1.9        # m: the highest goals of the training clips (room-scale, docs/data.md); the grid's: 1.8
MAX_SPEED = 1.5         # m/s: the fastest walk of the training clips (the hurried room-scale tasks, docs/data.md)


class RangeWarning(GraspkitWarning):
    """A goal outside the range the shipped model was trained and evaluated on (range_notes)."""


def range_notes(distance: float, height: float, seconds: float) -> dict[str, str]:
    """What to expect, by kind ('time', 'speed', 'below', 'above'), when a goal `distance` m away on the ground and
    `height` m above the floor, due in `seconds`, leaves the range the shipped model was trained and evaluated on:
    beyond 8 s, faster than 1.5 m/s, below the floor or above the highest training goals (1.9 m); {} inside it."""
    notes = {}
    if seconds > MAX_SECONDS:
        notes["time"] = (f"{seconds:g} s is past the {MAX_SECONDS:g} s the model was trained and evaluated for; past it "
                         "the body drifts and lifts off the floor, by metres on a long walk (docs/wandr.md, \"Out of "
                         "range\")")
    if distance / seconds > MAX_SPEED:
        notes["speed"] = (f"the goal is {distance:.1f} m away: {distance / seconds:.1f} m/s on average, faster than the "
                          f"{MAX_SPEED:g} m/s walks of the training clips; expect a poor motion")
    if height < 0:
        notes["below"] = f"the goal is {-height:.2f} m below the floor; the wrist cannot reach it"
    elif height > MAX_HEIGHT:
        notes["above"] = (f"the goal is {height:.2f} m high, above the {MAX_HEIGHT:g} m of the highest training goals "
                          "(the evaluation grid's highest: 1.8 m); expect the wrist to fall short and the feet to "
                          "leave the floor")
    return notes


def _warn_out_of_range(p0: Tensor, rest: Tensor, goal: Tensor, t_goal: Tensor) -> None:
    """A RangeWarning for each kind of range_notes that a start-goal pair of the batch (p0 (B, 135), rest joints
    (B, J, 3), goal (B, 3), t_goal (B,) frames) meets, naming its worst pair. The distance is the pelvis's, as the
    command's (the translation is the model's origin's: the rest pelvis sits off it, ~0.35 m on the held-out starts)."""
    pelvis = p0[:, :2].double() + rest[:, 0, :2].double()
    dist = torch.linalg.vector_norm(goal[:, :2].double() - pelvis, dim=-1)
    sec = t_goal.double() / I.FPS
    worst = {"time": sec.argmax(), "speed": (dist / sec).argmax(), "below": goal[:, 2].argmin(),
             "above": goal[:, 2].argmax()}
    for kind, b in worst.items():
        note = range_notes(float(dist[b]), float(goal[b, 2]), float(sec[b])).get(kind)
        if note:
            which = f"sequence {int(b)} of the batch: " if len(goal) > 1 else ""
            warnings.warn(which + note, RangeWarning, stacklevel=user_stacklevel())


def goal_schedule(goals: Tensor, t_goals: Iterable[int] | Tensor, frames: int) -> tuple[Tensor, Tensor]:
    """Several goals in a row (Sup. C.2, Fig. S.2): goal k is active from t_{k-1} + 1 to its frame t_k. Returns the goal
    (frames+1, 3) and goal frame (frames+1,) per frame, for `rollout` (expand to (B, T, ...)).

    At frame t_k the time left is 0, so that one frame's intention is zero (as after t_G in training); switching at
    t_k instead moved the wrist's closest approach by at most 2 cm (docs/wandr.md)."""
    goals = torch.as_tensor(goals, dtype=torch.float32)
    goals = goals.reshape(1, 3) if goals.shape == (3,) else goals
    if goals.dim() != 2 or goals.shape[1] != 3:
        raise ValueError(f"goals: expected (G, 3) world positions in metres, got shape {tuple(goals.shape)}")
    check_finite(goals, "goals", "world positions in metres")
    frames = check_int(frames, "frames", least=1)
    ts = list(t_goals)                          # once: an iterator is read here and nowhere else
    whole = all((isinstance(t, (int, np.integer)) and not isinstance(t, bool)) or (isinstance(t, Tensor) and t.dim() == 0
                and not t.is_floating_point() and t.dtype != torch.bool) for t in ts)
    if len(ts) != len(goals) or not ts or not whole or ts[0] < 1 or any(b <= a for a, b in zip(ts, ts[1:])):
        raise ValueError(f"t_goals: expected {len(goals)} strictly increasing whole frames >= 1, got {ts}")
    if len(ts) > 1 and ts[-2] >= frames:
        raise ValueError(f"t_goals: every goal but the last must fall before frame {frames} (the next one gets the "
                         f"frames after it), got {ts}")
    g = torch.empty(frames + 1, 3)
    tg = torch.empty(frames + 1, dtype=torch.long)
    lo = 0
    for k, t in enumerate(ts):
        hi = frames + 1 if k == len(ts) - 1 else int(t) + 1
        g[lo:hi], tg[lo:hi] = goals[k], int(t)
        lo = hi
    return g, tg


__all__ = ["WandrConfig", "WandrCVAE", "training_losses", "train_wandr", "save_wandr", "load_wandr", "Rollout",
           "rollout", "generate", "expand_starts", "goal_schedule", "range_notes", "RangeWarning", "FULL_INTENTION"]
