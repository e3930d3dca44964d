"""What the optimisers share: autograd switched on for them, and the inner step of GraspPose-Opt / GraspMotion-Opt."""
from __future__ import annotations

import functools
from collections.abc import Callable
from typing import Any, TypeVar

import torch
from torch import Tensor

F = TypeVar("F", bound=Callable[..., Any])


def with_autograd(fn: F) -> F:
    """`fn` (an optimiser or a training loop) run with autograd on, also when called under torch.no_grad() (as sampling
    pipelines are); under torch.inference_mode(), which cannot be left for tensors made inside it, a clear error."""
    @functools.wraps(fn)
    def run(*args: Any, **kwargs: Any) -> Any:
        if torch.is_inference_mode_enabled():
            raise RuntimeError(f"{fn.__qualname__}: cannot optimise under torch.inference_mode() (it turns autograd off "
                               "for good); call it outside the inference_mode block")
        with torch.enable_grad():
            return fn(*args, **kwargs)
    return run  # type: ignore[return-value]


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
