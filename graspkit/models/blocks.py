"""Blocks shared by the workbook's networks: residual MLP blocks, Gaussian latents and their KL terms.

SAGA (App. A.2) and GOAL (§3.3, after GrabNet) build their encoders and decoders from fully connected residual
blocks; WANDR (Sup. B.1) uses MLPs with LayerNorm. All CVAEs sample with the reparameterisation trick and regularise
with KL(q(z|.) || N(0, I)); SAGA wraps the KL in the robust function Psi(s) = sqrt(1 + s^2) - 1 (Eq. 2).
"""
from __future__ import annotations

import functools
import inspect
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any, TypeVar

import torch
from torch import nn

from graspkit.checks import check_int


@contextmanager
def evaluating(model: nn.Module) -> Iterator[nn.Module]:
    """`model` in eval mode inside the block and in the mode it had after it (a caller that is training keeps its
    dropout)."""
    was = getattr(model, "training", None)           # None: a stand-in with only eval() (tests' replay models)
    model.eval()
    try:
        yield model
    finally:
        if was is not None:
            model.train(was)


F = TypeVar("F", bound=Callable[..., Any])


def in_eval_mode(fn: F) -> F:
    """Decorator: fn(model, ...) runs with its first argument (positional or by its name) in eval mode, and the
    model's mode is restored after."""
    name = next(iter(inspect.signature(fn).parameters))

    @functools.wraps(fn)
    def wrapped(*args: Any, **kwargs: Any) -> Any:
        model = args[0] if args else kwargs.get(name)
        if model is None:                               # let fn's own signature name what is missing
            return fn(*args, **kwargs)
        with evaluating(model):
            return fn(*args, **kwargs)
    return wrapped  # type: ignore[return-value]


class ResBlock(nn.Module):
    """Fully connected residual block: x (B, n_in) -> (B, n_out); two Linear+BatchNorm layers, LeakyReLU, skip."""

    def __init__(self, n_in: int, n_out: int, n_hidden: int | None = None, norm: str = "batch") -> None:
        super().__init__()
        n_hidden = n_hidden or n_out
        make_norm = {"batch": nn.BatchNorm1d, "layer": nn.LayerNorm}[norm]
        self.fc1, self.n1 = nn.Linear(n_in, n_hidden), make_norm(n_hidden)
        self.fc2, self.n2 = nn.Linear(n_hidden, n_out), make_norm(n_out)
        self.skip = nn.Identity() if n_in == n_out else nn.Linear(n_in, n_out)
        self.act = nn.LeakyReLU(0.2)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """(B, n_in) -> (B, n_out)."""
        h = self.act(self.n1(self.fc1(x)))
        return self.act(self.n2(self.fc2(h)) + self.skip(x))


def mlp(sizes: list[int], layer_norm: bool = True, act: type[nn.Module] = nn.GELU) -> nn.Sequential:
    """An MLP through `sizes` (n_in, h1, ..., n_out): Linear (+LayerNorm) + activation between layers, linear output."""
    layers: list[nn.Module] = []
    for i, (a, b) in enumerate(zip(sizes[:-1], sizes[1:])):
        layers.append(nn.Linear(a, b))
        if i < len(sizes) - 2:
            layers += ([nn.LayerNorm(b)] if layer_norm else []) + [act()]
    return nn.Sequential(*layers)


class GaussianHead(nn.Module):
    """Features (B, n) -> (mean, log-variance) of a diagonal Gaussian over a latent (B, d)."""

    def __init__(self, n_in: int, d: int) -> None:
        super().__init__()
        self.mu, self.logvar = nn.Linear(n_in, d), nn.Linear(n_in, d)

    def forward(self, h: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(B, n) -> mean (B, d), log-variance (B, d) clamped to [-10, 10] for stability."""
        return self.mu(h), self.logvar(h).clamp(-10.0, 10.0)


def reparameterize(mu: torch.Tensor, logvar: torch.Tensor, generator: torch.Generator | None = None) -> torch.Tensor:
    """z = mu + sigma * eps with eps ~ N(0, I) drawn from `generator`: (B, d) -> (B, d)."""
    eps = torch.randn(mu.shape, generator=generator, device=mu.device, dtype=mu.dtype)
    return mu + torch.exp(0.5 * logvar) * eps


def kl_standard_normal(mu: torch.Tensor, logvar: torch.Tensor) -> torch.Tensor:
    """KL(N(mu, exp(logvar)) || N(0, I)) summed over the latent, averaged over the batch: (B, d) -> scalar."""
    return (0.5 * (mu.pow(2) + logvar.exp() - 1.0 - logvar)).sum(-1).mean()


def robust_kl(mu: torch.Tensor, logvar: torch.Tensor, per_dim: bool = False) -> torch.Tensor:
    """SAGA Eq. 2: Psi(KL) with Psi(s) = sqrt(1 + s^2) - 1, which keeps the KL from collapsing the posterior; of the
    KL summed over the latent, or with `per_dim` averaged over its dimensions (SAGA's released code)."""
    kl = kl_standard_normal(mu, logvar)
    if per_dim:
        kl = kl / mu.shape[-1]
    return torch.sqrt(1.0 + kl.pow(2)) - 1.0


def annealed_kl_weight(final: float, epoch: int, epochs: int) -> float:
    """SAGA's KL weight annealed linearly with the epoch (A.4): final * (epoch + 1) / epochs, epoch 0-based in
    [0, epochs)."""
    epochs = check_int(epochs, "epochs", 1)
    epoch = check_int(epoch, "epoch", 0)
    if epoch >= epochs:
        raise ValueError(f"epoch: expected a 0-based epoch below epochs={epochs}, got {epoch}")
    return final * (epoch + 1) / epochs
