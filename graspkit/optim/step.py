"""The inner step shared by the energy-minimising optimisers (GraspPose-Opt, GraspMotion-Opt)."""
from __future__ import annotations

import torch
from torch import Tensor


def energy_step(opt: torch.optim.Optimizer, terms: dict[str, Tensor], log: list[dict[str, float]], i: int, step: int,
                stage: int, log_every: int) -> None:
    """One step of `opt` on the summed energy terms {name: (B,)}; on every `log_every`-th step i of the stage, the
    terms' batch sums are appended to `log` with the global step and the stage."""
    loss = sum(t.sum() for t in terms.values())
    opt.zero_grad(set_to_none=True)
    loss.backward()
    opt.step()
    if i % log_every == 0:
        log.append({"step": step, "stage": stage, **{k: float(t.detach().sum()) for k, t in terms.items()}})
