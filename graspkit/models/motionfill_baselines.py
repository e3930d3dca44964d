"""SAGA Tab. 3's deterministic motion-infilling baselines (§4.2, App. B.2), on MotionFill-VAE's data representation.

SAGA compares MotionFill-VAE with three learned, deterministic infilling networks, all retrained on "the same body
markers and the trajectory representation" as MotionFill (graspkit.data.motionfill_dataset: 61 frames of 79 local
markers and four foot contacts, 62 root states Gamma_t = (x, y, cos g, sin g), per-frame root velocities):

- `CNNAE` (Kaufmann et al. [26], the convolutional autoencoder for motion infilling): a fully convolutional
  encoder-decoder (strided convolutions, then transposed convolutions, each with a GroupNorm over its whole feature
  map (without it the contact BCE stalled the marker fit in graspkit's overfit test); no latent, no skip
  connections) over the
  condition image I_c that `MotionFillVAE.image` builds (the four-channel motion image with the in-between frames of
  channel 0 zeroed); output channel 0 (normalised local markers and four contact logits). Local infilling: the root
  velocities of I_c come from the given (ground-truth) trajectory.
- `PoseNet` (Wang et al. [59], scene branch removed as B.2 says): an LSTM over the frames t = 0..T whose per-frame
  input is the start frame's and the end frame's normalised local markers, the frame's normalised root velocity (the
  route) and the normalised time t / T; output the frame's normalised local markers and contact logits.
- `RouteNet` (Wang et al. [59]): an LSTM over the root states t = 0..T+1 whose per-step input is Gamma_0, Gamma_T and
  t / T; output Gamma_t. `RoutePoseNet` chains them (Tab. 3's Route+PoseNet: RouteNet's trajectory, then PoseNet).

graspkit's choices (the paper gives no sizes): each network predicts a residual over the linear interpolation of its
known ends (the local markers blended from frame 0 to frame T, contact logits 0; Gamma_bar for the route), with a
zero-initialised output layer, as MotionFill-VAE's decoders do; the known frames (local markers of frames 0 and T,
root states 0 and T) are written back into the output, so every baseline reproduces its inputs exactly. Sizes are
small (CNN-AE 53 k, PoseNet 0.14 M, RouteNet 26 k weights; 0.47 MB together in float16). Every network keeps
MotionFill-VAE's normalisation statistics (buffers marker_mean/std, vel_mean/std, copied with `set_stats`).

Losses (the deterministic parts of SAGA Eq. 8, with Eq. 8's weights; |.| the L1 norm of a frame's vector, summed
over frames, averaged over the batch):
    CNN-AE, PoseNet:  L = sum_t |M^l_t - M~^l_t| + 0.5 sum_t |v^Ml_t - v~^Ml_t| + 1.0 BCE(C_F, C~_F)
                      (normalised local markers, their frame differences, the four foot contacts);
    RouteNet:         L = sum_t |Gamma_t - Gamma~_t| + 0.05 sum_t |v^Gamma_t - v~^Gamma_t|.
"""
from __future__ import annotations

from typing import Any

import torch
from torch import Tensor, nn
from torch.nn import functional as F

from graspkit.models.motionfill import (FEATURES, NUM_FRAMES, NUM_MARKERS, NUM_ROOT, T, check_known_frames,
                                       traj_velocity)

L_MARKERS, L_MARKERS_VEL, L_CONTACTS = 1.0, 0.5, 1.0     # Eq. 8's l3, l4, l2
L_TRAJ, L_TRAJ_VEL = 1.0, 0.05                           # Eq. 8's trajectory term and l1


def _check(name: str, x: Tensor, shape: tuple[int, ...]) -> None:
    """Raise a ValueError naming `name` unless x has `shape` (or (1, *shape)) and finite values."""
    if not isinstance(x, Tensor) or tuple(x.shape) not in (shape, (1,) + shape):
        got = tuple(x.shape) if isinstance(x, Tensor) else type(x).__name__
        raise ValueError(f"{name}: expected shape {shape} (one window), got {got}")
    if not bool(torch.isfinite(x).all()):
        raise ValueError(f"{name}: expected finite real values, got NaN or Inf")


def blend(x: Tensor) -> Tensor:
    """Linear blend from frame 0 to the last frame along dim 1 of (B, n, ...) (the baselines' starting point)."""
    s = torch.linspace(0, 1, x.shape[1], dtype=x.dtype, device=x.device).view(1, -1, *([1] * (x.dim() - 2)))
    return (1 - s) * x[:, :1] + s * x[:, -1:]


class _Baseline(nn.Module):
    """Shared parts: normalisation buffers, the markers' normalisation, state round trip, the Eq. 8 local loss."""

    # buffers, registered in __init__ (declared for type checkers)
    marker_mean: Tensor
    marker_std: Tensor
    vel_mean: Tensor
    vel_std: Tensor

    kind = ""

    def __init__(self) -> None:
        super().__init__()
        for k, n in (("marker_mean", NUM_MARKERS * 3), ("marker_std", NUM_MARKERS * 3), ("vel_mean", 3),
                     ("vel_std", 3)):
            self.register_buffer(k, torch.zeros(n) if "mean" in k else torch.ones(n))

    def set_stats(self, stats: Any) -> "_Baseline":
        """Copy the normalisation statistics from a MotionFillVAE or MotionFillStats (anything with the 4 fields)."""
        for k in ("marker_mean", "marker_std", "vel_mean", "vel_std"):
            getattr(self, k).copy_(torch.as_tensor(getattr(stats, k)).float())
        return self

    def config(self) -> dict[str, Any]:
        """Constructor arguments."""
        raise NotImplementedError

    def state(self) -> dict[str, Any]:
        """Weights, buffers, kind and config (a weights-only checkpoint)."""
        return {"kind": self.kind, "model": self.state_dict(), "model_config": self.config()}

    @classmethod
    def from_state(cls, state: dict[str, Any]) -> "_Baseline":
        """Rebuild from `state()` (float16 weights back to float32), in eval mode."""
        cfg = state.get("model_config") or state.get("extra", {}).get("model_config")
        model = cls(**{k: tuple(v) if isinstance(v, list) else v for k, v in dict(cfg).items()})
        model.load_state_dict({k: v.float() if v.is_floating_point() else v for k, v in state["model"].items()})
        return model.eval()

    def normalise(self, local: Tensor) -> Tensor:
        """Local markers (B, 61, 79, 3) -> normalised (B, 61, 237)."""
        return (local.flatten(2) - self.marker_mean) / self.marker_std

    def denormalise(self, x: Tensor) -> Tensor:
        """Normalised markers (B, 61, 237) -> metres (B, 61, 79, 3)."""
        return (x * self.marker_std + self.marker_mean).unflatten(-1, (NUM_MARKERS, 3))

    def infill(self, local: Tensor, contacts: Tensor, vel: Tensor) -> Tensor:
        """Channel 0 (B, 61, 241): normalised local markers (frames 0 and T as given) and contact logits, from local
        markers (B,61,79,3) and contacts (B,61,4) of which frames 0 and T are read, and root velocities (B,61,3)."""
        raise NotImplementedError

    def _local_loss(self, batch: dict[str, Tensor]) -> dict[str, Tensor]:
        """Eq. 8's local terms on a batch {local, contacts, vel}: L1 markers + 0.5 L1 marker velocity + BCE contacts."""
        ch0 = self.infill(batch["local"], batch["contacts"], batch["vel"])
        x, c = ch0[..., :-4], ch0[..., -4:]
        xt, ct = self.normalise(batch["local"]), batch["contacts"].to(x.dtype)
        logs = {"markers": (x - xt).abs().sum((1, 2)).mean(),
                "markers_vel": ((x[:, 1:] - x[:, :-1]) - (xt[:, 1:] - xt[:, :-1])).abs().sum((1, 2)).mean(),
                "contacts": F.binary_cross_entropy_with_logits(c, ct, reduction="none").sum((1, 2)).mean()}
        loss = L_MARKERS * logs["markers"] + L_MARKERS_VEL * logs["markers_vel"] + L_CONTACTS * logs["contacts"]
        with torch.no_grad():
            logs["marker_error_cm"] = (self.denormalise(x) - batch["local"]).norm(dim=-1).mean() * 100
        return {"loss": loss, **logs}

    def loss(self, batch: dict[str, Tensor]) -> dict[str, Tensor]:
        """Training loss on a batch of MotionFillDataset items (keys traj, local, contacts, vel)."""
        return self._local_loss(batch)

    @torch.no_grad()
    def predict(self, traj_interp: Tensor, local: Tensor, contacts: Tensor, n: int = 1,
                generator: torch.Generator | None = None, traj: Tensor | None = None) -> dict[str, Tensor]:
        """Local infilling of one window, as `MotionFillVAE.sample` (n and generator ignored: deterministic, one
        output): Gamma_bar (62,4), local markers (61,79,3) and contacts (61,4) of which frames 0 and T are read; the
        route `traj` (62,4) (default Gamma_bar). Returns traj (1,62,4), local (1,61,79,3), contacts (1,61,4)
        probabilities, markers (1,61,79,3) canonical."""
        _check("traj_interp", traj_interp, (NUM_ROOT, 4))
        _check("local", local, (NUM_FRAMES, NUM_MARKERS, 3))
        _check("contacts", contacts, (NUM_FRAMES, 4))
        check_known_frames(local, contacts)
        route = traj_interp if traj is None else traj
        _check("traj", route, (NUM_ROOT, 4))
        return self._decode(route.float().reshape(1, NUM_ROOT, 4), local, contacts)

    def _decode(self, route: Tensor, local: Tensor, contacts: Tensor) -> dict[str, Tensor]:
        """Infill the local motion along `route` (1, 62, 4) and place it in the canonical frame."""
        from graspkit.data.motionfill_dataset import global_motion

        was = self.training
        self.eval()
        ch0 = self.infill(local.float().reshape(1, NUM_FRAMES, NUM_MARKERS, 3),
                          contacts.float().reshape(1, NUM_FRAMES, 4), traj_velocity(route))
        loc = self.denormalise(ch0[..., :-4])
        markers = torch.as_tensor(global_motion(loc.double().numpy(), route.double().numpy())).float()
        self.train(was)
        return {"traj": route, "local": loc, "contacts": torch.sigmoid(ch0[..., -4:]), "markers": markers}

    def _ends(self, x: Tensor, known: Tensor) -> Tensor:
        """x (B, 61, 237) with frames 0 and T replaced by `known`'s (B, 61, 237)."""
        keep = torch.zeros(x.shape[1], 1, dtype=x.dtype, device=x.device)
        keep[[0, -1]] = 1.0
        return x * (1 - keep) + known * keep


# ------------------------------------------------------------------------------------------------ CNN-AE
class CNNAE(_Baseline):
    """Convolutional autoencoder (Kaufmann et al. [26]) over the condition image I_c (B, 4, 61, 241) -> channel 0."""

    kind = "cnn_ae"

    def __init__(self, channels: tuple[int, ...] = (8, 16, 32, 32)) -> None:
        super().__init__()
        self.channels = tuple(channels)
        cs = (4,) + self.channels
        self.enc = nn.Sequential(*[m for a, b in zip(cs[:-1], cs[1:])
                                   for m in (nn.Conv2d(a, b, 3, stride=2, padding=1), nn.GroupNorm(1, b),
                                             nn.LeakyReLU(0.2))])
        rs = self.channels[::-1] + (self.channels[0],)
        self.dec = nn.Sequential(*[m for a, b in zip(rs[:-1], rs[1:])
                                   for m in (nn.ConvTranspose2d(a, b, 4, stride=2, padding=1), nn.GroupNorm(1, b),
                                             nn.LeakyReLU(0.2))])
        # read-outs (zero-initialised: the network starts at the linear blend): per feature column, a weighting of
        # the last feature map's channels (a convolution alone is blind to which marker coordinate a column holds);
        # the contact logits from a whole frame's feature map
        self.out = nn.Parameter(torch.zeros(self.channels[0], FEATURES))
        self.out_bias = nn.Parameter(torch.zeros(FEATURES))
        self.contact_head = nn.Linear(self.channels[0] * FEATURES, 4)
        nn.init.zeros_(self.contact_head.weight)
        nn.init.zeros_(self.contact_head.bias)

    def config(self) -> dict[str, Any]:
        """Constructor arguments."""
        return {"channels": list(self.channels)}

    def condition(self, local: Tensor, contacts: Tensor, vel: Tensor) -> Tensor:
        """I_c (B, 4, 61, 241) as `MotionFillVAE.image` builds it: frames 1..T-1 of channel 0 zeroed."""
        x = self.normalise(local)
        ch0 = torch.cat([x, contacts.to(x.dtype)], -1)
        v = ((vel - self.vel_mean) / self.vel_std).permute(0, 2, 1)[..., None].expand(-1, -1, -1, ch0.shape[-1])
        cond = torch.cat([ch0[:, None], v], 1).clone()
        cond[:, 0, 1:-1] = 0.0
        return cond

    def infill(self, local: Tensor, contacts: Tensor, vel: Tensor) -> Tensor:
        """Channel 0 (B, 61, 241) decoded from I_c: a residual over the blend of frames 0 and T, ends as given."""
        cond = self.condition(local, contacts, vel)
        h = self.dec(self.enc(cond))[..., :NUM_FRAMES, :FEATURES]             # (B, c0, 61, 241)
        y = torch.einsum("bctf,cf->btf", h, self.out) + self.out_bias
        base = blend(cond[:, 0])                                            # reads frames 0 and T only
        x = self._ends(base[..., :-4] + y[..., :-4], cond[:, 0, :, :-4])
        logits = y[..., -4:] + self.contact_head(h.permute(0, 2, 1, 3).flatten(2))
        return torch.cat([x, logits], -1)


# ------------------------------------------------------------------------------------------------ PoseNet
class PoseNet(_Baseline):
    """LSTM over frames (Wang et al. [59]): [start markers, end markers, root velocity, t/T] per frame -> channel 0."""

    kind = "posenet"

    def __init__(self, hidden: int = 96, layers: int = 1) -> None:
        super().__init__()
        self.hidden, self.layers = hidden, layers
        self.inp = nn.Sequential(nn.Linear(2 * NUM_MARKERS * 3 + 3 + 1, hidden), nn.LeakyReLU(0.2))
        self.lstm = nn.LSTM(hidden, hidden, num_layers=layers, batch_first=True)
        self.out = nn.Linear(hidden, FEATURES)
        nn.init.zeros_(self.out.weight)                 # starts at the linear blend
        nn.init.zeros_(self.out.bias)

    def config(self) -> dict[str, Any]:
        """Constructor arguments."""
        return {"hidden": self.hidden, "layers": self.layers}

    def infill(self, local: Tensor, contacts: Tensor, vel: Tensor) -> Tensor:
        """Channel 0 (B, 61, 241): per-frame LSTM read-out as a residual over the blend of frames 0 and T; PoseNet reads
        no contacts (its inputs: the end frames' markers, the velocities, t/T), so its contact logits at frames 0 and T
        are predicted, not the given ones."""
        x = self.normalise(local)
        B = x.shape[0]
        t = torch.linspace(0, 1, NUM_FRAMES, dtype=x.dtype)[None, :, None].expand(B, -1, 1)
        v = (vel - self.vel_mean) / self.vel_std
        feats = torch.cat([x[:, :1].expand(-1, NUM_FRAMES, -1), x[:, -1:].expand(-1, NUM_FRAMES, -1), v, t], -1)
        h, _ = self.lstm(self.inp(feats))
        y = self.out(h)
        return torch.cat([self._ends(blend(x) + y[..., :-4], x), y[..., -4:]], -1)


# ------------------------------------------------------------------------------------------------ RouteNet
class RouteNet(_Baseline):
    """LSTM over root states (Wang et al. [59]): [Gamma_0, Gamma_T, t/T] per step -> Gamma_t (B, 62, 4)."""

    kind = "routenet"

    def __init__(self, hidden: int = 64, embed: int = 32) -> None:
        super().__init__()
        self.hidden, self.embed = hidden, embed
        self.inp = nn.Sequential(nn.Linear(9, embed), nn.LeakyReLU(0.2))
        self.lstm = nn.LSTM(embed, hidden, batch_first=True)
        self.out = nn.Linear(hidden, 4)
        nn.init.zeros_(self.out.weight)                 # starts at Gamma_bar
        nn.init.zeros_(self.out.bias)

    def config(self) -> dict[str, Any]:
        """Constructor arguments."""
        return {"hidden": self.hidden, "embed": self.embed}

    def route(self, traj_interp: Tensor) -> Tensor:
        """Gamma (B, 62, 4) from Gamma_bar (B, 62, 4) (its states 0 and T are Gamma_0, Gamma_T): a residual over
        Gamma_bar, states 0 and T as given."""
        B = traj_interp.shape[0]
        g0, gT = traj_interp[:, :1], traj_interp[:, T:T + 1]
        t = (torch.arange(NUM_ROOT, dtype=traj_interp.dtype) / T)[None, :, None].expand(B, -1, 1)
        h, _ = self.lstm(self.inp(torch.cat([g0.expand(-1, NUM_ROOT, -1), gT.expand(-1, NUM_ROOT, -1), t], -1)))
        out = traj_interp + self.out(h)
        keep = torch.zeros(NUM_ROOT, 1, dtype=out.dtype)
        keep[[0, T]] = 1.0
        return out * (1 - keep) + traj_interp * keep

    def loss(self, batch: dict[str, Tensor]) -> dict[str, Tensor]:
        """Eq. 8's trajectory terms on a batch {traj, traj_interp}: L1 on Gamma + 0.05 L1 on its velocities."""
        pred, true = self.route(batch["traj_interp"]), batch["traj"]
        logs = {"traj": (pred - true).abs().sum((1, 2)).mean(),
                "traj_vel": ((pred[:, 1:] - pred[:, :-1]) - (true[:, 1:] - true[:, :-1])).abs().sum((1, 2)).mean()}
        with torch.no_grad():
            logs["root_error_cm"] = (pred[..., :2] - true[..., :2]).norm(dim=-1).mean() * 100
        return {"loss": L_TRAJ * logs["traj"] + L_TRAJ_VEL * logs["traj_vel"], **logs}

    @torch.no_grad()
    def predict(self, traj_interp: Tensor, local: Tensor | None = None, contacts: Tensor | None = None, n: int = 1,
                generator: torch.Generator | None = None, traj: Tensor | None = None) -> dict[str, Tensor]:
        """The route of one window: Gamma_bar (62, 4) -> {traj (1, 62, 4)} (the other inputs are ignored)."""
        _check("traj_interp", traj_interp, (NUM_ROOT, 4))
        was = self.training
        self.eval()
        out = self.route(traj_interp.float().reshape(1, NUM_ROOT, 4))
        self.train(was)
        return {"traj": out}


class RoutePoseNet(nn.Module):
    """Tab. 3's Route+PoseNet: RouteNet's trajectory, then PoseNet's local motion along it (full infilling)."""

    def __init__(self, route: RouteNet, pose: PoseNet) -> None:
        super().__init__()
        self.route, self.pose = route, pose

    @torch.no_grad()
    def predict(self, traj_interp: Tensor, local: Tensor, contacts: Tensor, n: int = 1,
                generator: torch.Generator | None = None, traj: Tensor | None = None) -> dict[str, Tensor]:
        """As `MotionFillVAE.sample` with traj=None (a given `traj` replaces RouteNet's); one deterministic output; the
        contacts are not read (PoseNet takes none)."""
        route = self.route.predict(traj_interp)["traj"][0] if traj is None else traj
        return self.pose.predict(traj_interp, local, contacts, traj=route)


BASELINES: dict[str, type[_Baseline]] = {"cnn_ae": CNNAE, "posenet": PoseNet, "routenet": RouteNet}


def baseline_from_state(state: dict[str, Any]) -> _Baseline:
    """Any baseline back from its `state()` (dispatch on state['kind'])."""
    kind = state.get("kind") or state.get("extra", {}).get("kind")
    if kind not in BASELINES:
        raise ValueError(f"state: kind {kind!r} is not one of {sorted(BASELINES)}")
    return BASELINES[kind].from_state(state)


def num_weights(model: nn.Module) -> int:
    """Number of trainable weights."""
    return sum(p.numel() for p in model.parameters())
