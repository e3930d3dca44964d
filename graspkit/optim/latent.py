"""Latent optimisation through WANDR's differentiable rollout (Sup. B.3, C.2): "VAE + opt" and waypoints.

The decoder turns one latent z_k per frame into a pose delta, and the whole rollout (decode, integrate, forward
kinematics, intention) is differentiable, so the per-frame latents Z = (z_1 .. z_T) of a motion can be optimised:

    L_opt = w_norm L_norm + w_goal L_goal (+ w_way L_way)
    L_norm = mean_k,j z_kj^2 / 2           the negative log-likelihood of Z under N(0, I) up to a constant, divided
                                            by frames x latent size (so w_norm does not grow with the motion's
                                            length): keeps the motion where the prior puts its mass
    L_goal = |W_{t_G} - G|^2               the right wrist at the goal frame vs the goal (m^2)
    L_way  = sum_w |P^xy_{t_w} - w^xy|^2   the pelvis's ground projection at frame t_w vs each waypoint (m^2, Sup. C.2)

"VAE + opt" (Tab. 2) optimises from random Z a model trained without intention; waypoints (Fig. S.3) start from the
latents of a WANDR rollout and keep its intention. The paper writes L_opt = L_norm + L_goal with unit weights, L_norm
"the log-likelihood" of the latents and L_goal "the mean square error" of the wrist, and gives no optimiser; read
literally (L_norm summed over the (T-1) x latent entries, L_goal averaged over x, y, z) its prior term is ~10^6 times
ours against L_goal and holds the latents at the prior's centre: lesson 09's waypoint 88 -> 93 cm (lr 1) and 88 -> 91
cm (lr 0.05) in 10 iterations, against 88 -> 57 cm with the lesson's w_norm = 0.001 (docs/wandr.md). graspkit's
choices: Adam, learning rate 0.05, w_norm = 0.01 on the mean, w_goal = w_way = 1 (m^-2), a fixed number of
iterations; the best iterate is kept.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Sequence

import torch
from torch import Tensor
from tqdm.auto import tqdm

from graspkit import intention as I
from graspkit.checks import check_finite, check_generator, check_int, check_real, check_weight
from graspkit.models.blocks import evaluating
from graspkit.models.wandr import Rollout, WandrCVAE, expand_starts, rollout
from graspkit.optim.step import with_autograd
from graspkit.progress import hidden

if TYPE_CHECKING:
    from graspkit.body import BodyModel
    from graspkit.eval_wandr import GridResult


@dataclass
class LatentResult:
    """Optimised latents z (B, T-1, latent), the motion they decode to, and the loss terms per iteration."""

    z: Tensor
    motion: Rollout
    history: list[dict[str, float]] = field(default_factory=list)


def latent_loss(out: Rollout, z: Tensor, goal: Tensor, t_goal: int, waypoints: Sequence[tuple[int, Sequence[float]]] = (),
                w_norm: float = 0.01, w_goal: float = 1.0, w_way: float = 1.0) -> dict[str, Tensor]:
    """The loss terms (per sequence, (B,)) of a rollout `out` decoded from latents z (B, T-1, latent): norm, goal, way,
    and their weighted sum 'loss'."""
    norm = 0.5 * z.pow(2).mean(dim=(1, 2))
    g = (out.joints[:, t_goal, I.WRIST] - goal).pow(2).sum(-1)
    way = torch.zeros_like(g)
    for frame, xy in waypoints:
        target = torch.as_tensor(xy, dtype=out.joints.dtype)[:2]
        way = way + (out.joints[:, frame, I.PELVIS, :2] - target).pow(2).sum(-1)
    return {"loss": w_norm * norm + w_goal * g + w_way * way, "norm": norm, "goal": g, "way": way}


@with_autograd
def optimise_latents(model: WandrCVAE, start: I.StartPose | Sequence[I.StartPose], goal: Sequence[float] | Tensor,
                     t_goal: int, frames: int | None = None, n: int = 1,
                     waypoints: Sequence[tuple[int, Sequence[float]]] = (), z0: Tensor | None = None, iters: int = 40,
                     lr: float = 0.05, w_norm: float = 0.01, w_goal: float = 1.0, w_way: float = 1.0,
                     generator: torch.Generator | None = None, progress: bool = False) -> LatentResult:
    """Optimise the per-frame latents of motions from `start` (one or more) towards goals (3,) or (G, 3) (the wrist
    there at frame t_goal), n each (B = S * G * n, start-major as `generate`), the pelvis over `waypoints`
    [(frame, (x, y))]. z0 (B, frames, latent), or random N(0, I) from `generator` (the latents of a plain rollout).
    Adam is element-wise and the loss a sum over sequences, so a batch optimises each sequence independently.
    progress: a bar over the iterations (each a rollout and its backward pass: 50 goals of 120 frames, 40 iterations
    take two minutes on two cores)."""
    check_int(t_goal, "t_goal", least=1)
    check_generator(generator)
    frames = t_goal if frames is None else check_int(frames, "frames", least=1)
    if not 1 <= t_goal <= frames:
        raise ValueError(f"t_goal: expected 1 <= t_goal <= frames ({frames}), got {t_goal}")
    for w in waypoints:
        frame, xy = w if isinstance(w, (tuple, list)) and len(w) == 2 else (None, None)
        try:
            xy = torch.as_tensor(xy, dtype=torch.float64)
        except (TypeError, ValueError, RuntimeError):
            xy = torch.zeros(0)
        if frame is None or check_int(frame, "waypoints: a frame") > frames or xy.shape not in ((2,), (3,)):
            raise ValueError(f"waypoints: expected (frame in [0, {frames}], (x, y)), got {w!r}")
        check_finite(xy, "waypoints", "finite (x, y) in metres")
    check_int(iters, "iters")
    lr = check_real(lr, "lr", "a finite learning rate > 0", positive=True)
    for v, name in ((w_norm, "w_norm"), (w_goal, "w_goal"), (w_way, "w_way")):
        check_weight(v, name)
    if z0 is not None:
        check_finite(z0, "z0", "latents")
    with evaluating(model):
        return _optimise(model, start, goal, t_goal, frames, n, waypoints, z0, iters, lr, w_norm, w_goal, w_way,
                         generator, progress)


def _optimise(model: WandrCVAE, start, goal, t_goal: int, frames: int, n: int, waypoints, z0: Tensor | None,
              iters: int, lr: float, w_norm: float, w_goal: float, w_way: float,
              generator: torch.Generator | None, progress: bool = False) -> LatentResult:
    """`optimise_latents` after its checks, the model in eval mode."""
    pp, p0, rest, g, idx = expand_starts(start, torch.as_tensor(goal, dtype=torch.float32).reshape(-1, 3), n)
    dtype = model.dtype                                    # float32 unless the caller converted the model (as generate)
    pp, p0, rest, g = (x.to(dtype) for x in (pp, p0, rest, g))
    B, L = len(g), model.cfg.latent
    z = (torch.randn(B, frames, L, generator=generator) if z0 is None else z0.detach().clone()).to(dtype)
    z.requires_grad_(True)
    if z.shape != (B, frames, L):
        raise ValueError(f"z0: expected shape ({B}, {frames}, {L}), got {tuple(z.shape)}")
    opt = torch.optim.Adam([z], lr=lr)
    best_z, best = z.detach().clone(), torch.full((B,), float("inf"), dtype=dtype)
    history: list[dict[str, float]] = []
    grads = [q.requires_grad for q in model.parameters()]
    for q in model.parameters():
        q.requires_grad_(False)
    try:
        for it in tqdm(range(iters + 1), desc="latent optimisation", unit="iter", disable=hidden(progress)):
            out = rollout(model, pp, p0, rest, g, t_goal, frames, z=z)
            terms = latent_loss(out, z, g, t_goal, waypoints, w_norm, w_goal, w_way)
            history.append({k: float(v.detach().mean()) for k, v in terms.items()})
            better = terms["loss"].detach() < best
            best = torch.where(better, terms["loss"].detach(), best)
            best_z[better] = z.detach()[better]
            if it == iters:
                break
            opt.zero_grad()
            terms["loss"].sum().backward()
            opt.step()
    finally:
        for q, r in zip(model.parameters(), grads):
            q.requires_grad_(r)
    with torch.no_grad():
        final = rollout(model, pp, p0, rest, g, t_goal, frames, z=best_z)
    final.info["index"] = idx
    return LatentResult(best_z, final, history)


def evaluate_vae_opt(model: WandrCVAE, starts: Sequence[I.StartPose], bm: BodyModel, seed: int = 0, n_starts: int = 2,
                     iters: int = 30, chunk: int = 125, progress: bool = False, **kw: Any) -> GridResult:
    """Tab. 2's "VAE + opt" on the goal grid: a model without intention, latents optimised from random draws towards
    each goal (L_norm + L_goal at t_G), scored as evaluate_grid scores WANDR. Cost: every iteration is a rollout and its
    backward pass, so this runs on the first `n_starts` starts with one sample per goal (documented in docs/wandr.md);
    progress: a bar over the (start, chunk of goals) optimisations."""
    import numpy as np

    from graspkit.eval_wandr import T_GOAL, GridResult, evaluate_motions, grid_goals

    goals, cells = grid_goals()
    gen = torch.Generator().manual_seed(seed)
    parts = []
    jobs = [(s_i, lo) for s_i in range(len(starts[:n_starts])) for lo in range(0, len(goals), chunk)]
    for s_i, lo in tqdm(jobs, desc="VAE + opt", unit="batch", disable=hidden(progress)):
        s = starts[s_i]
        res = optimise_latents(model, s, goals[lo:lo + chunk], T_GOAL, iters=iters, generator=gen, **kw)
        m = res.motion
        idx = res.motion.info["index"].clone()
        idx[:, 0], idx[:, 1] = s_i, idx[:, 1] + lo
        parts.append(evaluate_motions(m.p, m.rest, m.goal[:, 0], s.betas[None].expand(len(idx), -1), bm, T_GOAL,
                                      cells, idx, s.full_pose))      # cells by goal: idx's goal column
    cat = lambda k: np.concatenate([getattr(p, k) for p in parts])  # noqa: E731
    return GridResult(cat("start"), cat("goal_index"), cat("sample"), cat("cell"), cat("dtg"), cat("reach_frame"),
                      cat("fs"), cat("error_at_goal"), {"iters": iters, "starts": n_starts})
