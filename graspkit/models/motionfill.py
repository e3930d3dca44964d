"""MotionFill-VAE (SAGA §3.3, Fig. 4, Eq. 8-9, App. A.2-A.4): generative infilling of the motion between a start
pose and a grasp, as two chained CVAEs.

Data (graspkit.data.motionfill_dataset, A.3): windows of T + 1 = 61 frames at 30 fps, canonicalised at the first
frame; root states Gamma_t = (x, y, cos g, sin g) for t = 0..T+1 (62); the sparse-hand markers (79) in each frame's
heading frame (local motion); root velocities; four foot contacts.

TrajFill (A.2): a CVAE over the trajectory deviation dGamma = Gamma - Gamma_bar from the straight trajectory Gamma_bar
(linear interpolation Gamma_0 -> Gamma_T plus one extrapolated step), conditioned on Gamma_bar. Encoder: two residual
blocks as wide as their input [dGamma, Gamma_bar] (2 x 62 x 4 = 496, i.e. ~8T), two linear heads to a 512-D latent.
Decoder: [z, Gamma_bar] -> residual blocks of widths 8T and 4T -> dGamma; output Gamma_bar + dGamma. graspkit's
output layer writes dGamma as its 16 lowest DCT frequencies per channel (`traj_basis`; 0 gives A.2's full layer).

LocalMotionFill (A.2, after LEMO [64]): a CNN CVAE over the four-channel motion image I (4 x 61 x (79*3 + 4)):
channel 0 the normalised local markers with the foot contacts, channels 1-3 the normalised root velocities; the
condition image I_c is I with the in-between frames of channel 0 zeroed. Decoder output: channel 0 (markers and
contact logits) as a residual over the linear blend of the two known frames (graspkit's choice, as TrajFill's
residual over Gamma_bar; zero-initialised). Two networks (`MotionFillConfig.local_arch`):
- "temporal" (shipped, `TemporalMotionFill`): the first convolution reads each frame's row of I whole (3 frames x
  all features), then convolutions run over time only (61 -> 31 -> 16 -> 8 frames, 96 maps); the decoder is a
  temporal U-Net on z and the encoding of I_c, upsampling by linear resizing + convolution.
- "image" (`LocalMotionFill`, LEMO's layout): 3 x 3 convolutions over the image with strides 2, a U-Net decoder with
  transposed convolutions and skips from the I_c encoder; the four contact logits add a linear read-out of each
  frame's last feature map (a convolution alone cannot tell the contact columns from the marker columns). Widths
  8-16-32-32-32 (`paper()`: 16-32-64-64-64, 128-D latent).
The paper defers the CNN to LEMO and gives no widths; both are graspkit's, sized for two CPU cores. The image
network's kernels slide across neighbouring marker coordinates, which generalised to held-out objects worse than a
per-frame LSTM (docs/saga_motion.md: Tab. 3's ADE and PSKL, both networks measured).

Losses (Eq. 8-9, A.4): L = L_rec + lambda_KL L_KL,
    L_rec = sum_t |Gamma_t - Gamma~_t| + l1 sum_t |v^Gamma_t - v~^Gamma_t| + l2 BCE(C_F, C~_F)
            + l3 sum_t |M^l_t - M~^l_t| + l4 sum_t |v^Ml_t - v~^Ml_t|                               (Eq. 8)
    L_KL  = Psi(KL(q(z_t | ...))) + Psi(KL(q(z_m | I, I_c)))                                     (Eq. 9)
with {lambda_KL, l1, l2, l3, l4} = {1, 0.05, 1, 1, 0.5}. Reduced as the authors' released code does
(`reduction="mean"`, default): each L1 / BCE term averaged over its elements, Psi of the KL averaged over the latent's
dimensions. `reduction="sum"` reads Eq. 8 as printed (|.| the L1 norm of a frame's vector summed over frames, Psi of
the summed KL); with the temporal network it lets the motion latent carry ~200 nats and the samples land further
from the data (docs/saga_motion.md). The local markers enter in their normalised units (the image's).
"""
from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
import torch
from torch import Tensor, nn
from torch.nn import functional as F

from graspkit.checks import check_generator, check_labels, check_probabilities
from graspkit.models.blocks import GaussianHead, ResBlock, kl_standard_normal, reparameterize, robust_kl
from graspkit.objects.distance import require_points_in_metres

T = 60
NUM_ROOT = T + 2          # root states Gamma_{0:T+1}
NUM_FRAMES = T + 1        # local motion frames
NUM_MARKERS = 79
FEATURES = NUM_MARKERS * 3 + 4


WINDOW_SHAPES = {"traj": (NUM_ROOT, 4), "traj_interp": (NUM_ROOT, 4), "vel": (NUM_FRAMES, 3),
                 "local": (NUM_FRAMES, NUM_MARKERS, 3), "contacts": (NUM_FRAMES, 4)}


def check_window_batch(batch: dict[str, Tensor], keys: tuple[str, ...]) -> None:
    """ValueError naming the first of `keys` missing from a batch of MotionFillDataset items or of a wrong shape
    (B, *WINDOW_SHAPES[key]); contact labels must lie in [0, 1]."""
    if not isinstance(batch, dict):
        raise ValueError(f"batch: expected a dict of MotionFillDataset tensors, got {type(batch).__name__}")
    B = None
    for k in keys:
        if k not in batch:
            raise ValueError(f"batch: missing key {k!r} (a MotionFillDataset batch has {sorted(WINDOW_SHAPES)})")
        x = batch[k]
        want = WINDOW_SHAPES[k]
        if not isinstance(x, Tensor) or x.dim() != len(want) + 1 or tuple(x.shape[1:]) != want \
                or (B is not None and x.shape[0] != B):
            got = tuple(x.shape) if isinstance(x, Tensor) else type(x).__name__
            raise ValueError(f"batch[{k!r}]: expected shape (B, {', '.join(map(str, want))})"
                             f"{'' if B is None else f' with B={B}'}, got {got}")
        B = x.shape[0]
    if "contacts" in keys:
        check_labels(batch["contacts"], "batch['contacts']")


def _reduce(err: Tensor, reduction: str) -> Tensor:
    """Per-element errors (B, frames, features) -> scalar: summed over frames and features and averaged over the
    batch ("sum", Eq. 8 as printed), or averaged over every element ("mean", the authors' released code)."""
    return err.sum((1, 2)).mean() if reduction == "sum" else err.mean()


@dataclass
class MotionFillConfig:
    """Sizes and loss weights (A.2, A.4). The defaults are the shipped model: A.2's TrajFill (512-D latent, encoder
    blocks as wide as their input; decoder blocks 8T and 4T read with T = 60, 480 and 240, where A.2's T = 62 and the
    authors' code give 496 and 248 and no output layer) with graspkit's 16-frequency output layer, the temporal
    LocalMotionFill (96 maps, 64-D latent): 3.58 M weights, 7.2 MB in float16. `paper()` keeps that TrajFill with a
    per-frame output layer (the nearest to A.2) and the image network at LEMO-like widths (3.8 M weights)."""

    traj_latent: int = 512                # A.2
    traj_enc: int = 2 * NUM_ROOT * 4      # encoder block width (A.2: as wide as its input, 2 * 62 * 4 = 496)
    traj_widths: tuple[int, int] = (8 * T, 4 * T)     # decoder residual blocks (A.2)
    traj_basis: int = 16      # TrajFill's output: the K lowest DCT frequencies per channel (0: a full linear layer, A.2)
    motion_latent: int = 64
    channels: tuple[int, ...] = (8, 16, 32, 32, 32)
    local_arch: str = "temporal"  # "temporal": rows of the motion image read whole, convolutions over time;
    temporal_width: int = 96      # "image": 2-D convolutions over the image (LEMO) with `channels`
    lambda_kl: float = 1.0
    l1: float = 0.05          # trajectory velocity
    l2: float = 1.0           # foot-contact BCE
    l3: float = 1.0           # local markers
    l4: float = 0.5           # local marker velocity
    reduction: str = "mean"   # "mean": per element, KL per latent dim (the authors' code); "sum": Eq. 8 as printed

    @classmethod
    def paper(cls) -> "MotionFillConfig":
        """SAGA A.2's layout: the defaults' TrajFill sizes with a per-frame output layer (decoder 480/240 + a linear
        layer, against A.2's 496/248 alone), and the image network (LEMO's layout; its widths and 128-D latent are
        graspkit's, LEMO-like)."""
        return cls(traj_basis=0, motion_latent=128, local_arch="image", channels=(16, 32, 64, 64, 64))


# ------------------------------------------------------------------------------------------------ TrajFill
def dct_basis(frames: int, k: int) -> Tensor:
    """Orthonormal DCT-II synthesis matrix (frames, k): column j is the j-th cosine, cos(pi (t + 1/2) j / frames)."""
    t = torch.arange(frames, dtype=torch.float64)[:, None] + 0.5
    j = torch.arange(k, dtype=torch.float64)[None]
    b = torch.cos(torch.pi * t * j / frames) * (2.0 / frames) ** 0.5
    b[:, 0] /= 2 ** 0.5
    return b.float()


class TrajFill(nn.Module):
    """CVAE over root trajectories (B, 62, 4) conditioned on the straight trajectory Gamma_bar (B, 62, 4)."""

    # buffers, registered in __init__ (declared for type checkers)
    dct: Tensor

    def __init__(self, latent: int = 512, frames: int = NUM_ROOT, enc: int | None = None,
                 widths: tuple[int, int] | None = None, basis: int = 0) -> None:
        super().__init__()
        n = frames * 4
        t = frames - 2
        enc = enc or 2 * n
        w1, w2 = widths or (8 * t, 4 * t)
        if not 0 <= basis <= frames:
            raise ValueError(f"basis: expected 0 (full output) to {frames} DCT frequencies, got {basis}")
        self.frames = frames
        self.enc = nn.Sequential(ResBlock(2 * n, enc), ResBlock(enc, enc))
        self.head = GaussianHead(enc, latent)
        self.dec = nn.Sequential(ResBlock(latent + n, w1), ResBlock(w1, w2))
        # basis > 0: the deviation is synthesised from its `basis` lowest DCT-II frequencies per channel (16 of 62:
        # up to 3.6 Hz at 30 fps). A per-frame output's sub-millimetre noise is doubled twice by the second difference
        # and swamps the spectrum of a root's acceleration (SAGA's PSKL); the data's trajectories lose 0.1 of their
        # 4-unit L1 error to this truncation (docs/saga_motion.md).
        self.register_buffer("dct", dct_basis(frames, basis) if basis else torch.zeros(0, 0), persistent=False)
        self.out = nn.Linear(w2, 4 * basis if basis else n)
        nn.init.zeros_(self.out.weight)           # starts at the straight trajectory
        nn.init.zeros_(self.out.bias)
        self.latent = latent

    def encode(self, traj: Tensor, traj_interp: Tensor) -> tuple[Tensor, Tensor]:
        """q(z_t | Gamma, Gamma_bar): (B,62,4) x2 -> mean, log-variance (B, latent)."""
        B = traj.shape[0]
        return self.head(self.enc(torch.cat([(traj - traj_interp).reshape(B, -1), traj_interp.reshape(B, -1)], -1)))

    def decode(self, z: Tensor, traj_interp: Tensor) -> Tensor:
        """p(Gamma | z_t, Gamma_bar): Gamma_bar + the decoded deviation (B, 62, 4)."""
        B = z.shape[0]
        d = self.out(self.dec(torch.cat([z, traj_interp.reshape(B, -1)], -1)))
        if self.dct.numel():                                   # (B, K, 4) coefficients -> (B, frames, 4)
            return traj_interp + self.dct @ d.view(B, -1, 4)
        return traj_interp + d.view(B, self.frames, 4)

    def forward(self, traj: Tensor, traj_interp: Tensor, generator: torch.Generator | None = None
                ) -> tuple[Tensor, Tensor, Tensor]:
        """Reconstruction (B,62,4), mean, log-variance."""
        mu, logvar = self.encode(traj, traj_interp)
        z = reparameterize(mu, logvar, generator) if self.training else mu
        return self.decode(z, traj_interp), mu, logvar


# ------------------------------------------------------------------------------------------------ LocalMotionFill
class _InfillCVAE(nn.Module):
    """What the two LocalMotionFill networks share: the residual's starting point and the CVAE's forward pass (their
    own `encode` (I, I_c) -> q(z_m) and `decode` (z_m, I_c) -> channel 0)."""

    latent: int

    def encode(self, image: Tensor, cond: Tensor) -> tuple[Tensor, Tensor]:
        raise NotImplementedError

    def decode(self, z: Tensor, cond: Tensor) -> Tensor:
        raise NotImplementedError

    @staticmethod
    def base(cond: Tensor) -> Tensor:
        """The decoder's starting point: channel 0 blended linearly from frame 0 to frame T (markers), zero contact
        logits (B, T+1, F) (graspkit's residual, as TrajFill's over Gamma_bar)."""
        c = cond[:, 0]
        s = torch.linspace(0, 1, c.shape[1], dtype=c.dtype, device=c.device)[None, :, None]
        b = (1 - s) * c[:, :1] + s * c[:, -1:]
        return torch.cat([b[..., :-4], torch.zeros_like(b[..., -4:])], -1)

    def forward(self, image: Tensor, cond: Tensor, generator: torch.Generator | None = None
                ) -> tuple[Tensor, Tensor, Tensor]:
        """Reconstruction of channel 0 (B,61,F), mean, log-variance."""
        mu, logvar = self.encode(image, cond)
        z = reparameterize(mu, logvar, generator) if self.training else mu
        return self.decode(z, cond), mu, logvar


def _conv(a: int, b: int) -> nn.Sequential:
    """3x3 convolution, stride 2, LeakyReLU."""
    return nn.Sequential(nn.Conv2d(a, b, 3, stride=2, padding=1), nn.LeakyReLU(0.2))


def _crop(x: Tensor, like: Tensor) -> Tensor:
    """x cropped to like's spatial size (top-left)."""
    return x[..., :like.shape[-2], :like.shape[-1]]


class _ConvEncoder(nn.Module):
    """Strided convolutions; returns every level's feature map (finest first)."""

    def __init__(self, c_in: int, channels: tuple[int, ...]) -> None:
        super().__init__()
        cs = (c_in,) + tuple(channels)
        self.layers = nn.ModuleList(_conv(a, b) for a, b in zip(cs[:-1], cs[1:]))

    def forward(self, x: Tensor) -> list[Tensor]:
        """(B, C, H, W) -> [level 1, ..., level L] feature maps."""
        out = []
        for layer in self.layers:
            x = layer(x)
            out.append(x)
        return out


class LocalMotionFill(_InfillCVAE):
    """CNN CVAE over motion images (B, 4, 61, F): encoder on [I, I_c], U-Net decoder on z and I_c -> channel 0."""

    def __init__(self, latent: int = 128, channels: tuple[int, ...] = (16, 32, 64, 64, 64),
                 size: tuple[int, int] = (NUM_FRAMES, FEATURES)) -> None:
        super().__init__()
        self.latent, self.size = latent, size
        self.enc = _ConvEncoder(8, channels)
        self.cond = _ConvEncoder(4, channels)
        with torch.no_grad():
            shapes = [f.shape[1:] for f in self.cond(torch.zeros(1, 4, *size))]
        self.shapes = shapes
        flat = int(torch.tensor(shapes[-1]).prod())
        self.head = GaussianHead(flat, latent)
        self.from_z = nn.Linear(latent, flat)
        cs = list(channels)
        ups = []
        for lvl in range(len(cs) - 1, -1, -1):        # from the coarsest level up to the input resolution
            c_in = 2 * cs[lvl] if lvl == len(cs) - 1 else cs[lvl] + cs[lvl]
            c_out = cs[lvl - 1] if lvl > 0 else cs[0]
            ups.append(nn.ModuleDict({"up": nn.ConvTranspose2d(c_in, c_out, 4, stride=2, padding=1),
                                      "act": nn.LeakyReLU(0.2)}))
        self.ups = nn.ModuleList(ups)
        self.out = nn.Conv2d(cs[0] + 4, 1, 3, padding=1)
        nn.init.zeros_(self.out.weight)               # starts at the linear blend of the known frames (`base`)
        nn.init.zeros_(self.out.bias)
        self.contact_head = nn.Linear((cs[0] + 4) * size[1], 4)      # foot-contact logits read from a whole frame
        nn.init.zeros_(self.contact_head.weight)
        nn.init.zeros_(self.contact_head.bias)

    def encode(self, image: Tensor, cond: Tensor) -> tuple[Tensor, Tensor]:
        """q(z_m | I, I_c): (B,4,61,F) x2 -> mean, log-variance (B, latent)."""
        return self.head(self.enc(torch.cat([image, cond], 1))[-1].flatten(1))

    def decode(self, z: Tensor, cond: Tensor) -> Tensor:
        """p(I | z_m, I_c): channel 0 of the motion image (B, 61, F) (markers normalised, contact logits)."""
        skips = self.cond(cond)
        h = self.from_z(z).view(z.shape[0], *self.shapes[-1])
        h = torch.cat([h, skips[-1]], 1)
        for k, up in enumerate(self.ups):
            h = up["act"](up["up"](h))
            target = skips[len(skips) - 2 - k] if k < len(self.ups) - 1 else cond
            h = torch.cat([_crop(h, target), target], 1)
        y = self.out(h)[:, 0] + self.base(cond)
        logits = self.contact_head(h.permute(0, 2, 1, 3).flatten(2))             # per frame, all features
        return torch.cat([y[..., :-4], y[..., -4:] + logits], -1)


def _rows(image: Tensor) -> Tensor:
    """Motion or condition image (B, 4, 61, F) -> per-frame rows (B, F + 3, 61): channel 0 whole and the three root
    velocities once (channels 1-3 hold each frame's velocity in every column)."""
    return torch.cat([image[:, 0], image[:, 1:, :, 0].transpose(1, 2)], -1).transpose(1, 2)


def _tconv(a: int, b: int, stride: int) -> nn.Sequential:
    """Temporal convolution, kernel 3 (stride 1 or 2), LeakyReLU: (B, a, T) -> (B, b, T')."""
    return nn.Sequential(nn.Conv1d(a, b, 3, stride=stride, padding=1), nn.LeakyReLU(0.2))


class TemporalMotionFill(_InfillCVAE):
    """LocalMotionFill with convolutions over time only (`MotionFillConfig(local_arch="temporal")`, graspkit's
    variant): the first convolution reads each frame's row of the motion image whole (kernel 3 frames x all features),
    then strided temporal convolutions (61 -> 31 -> 16 -> 8 frames); the decoder is a temporal U-Net on z and the
    condition image's encoding. Same interface and losses as `LocalMotionFill`."""

    def __init__(self, latent: int = 64, width: int = 96, size: tuple[int, int] = (NUM_FRAMES, FEATURES),
                 levels: int = 3) -> None:
        super().__init__()
        self.latent, self.size = latent, size
        F_in = size[1] + 3
        self.enc = nn.Sequential(_tconv(2 * F_in, width, 1), *[_tconv(width, width, 2) for _ in range(levels)])
        self.cond = nn.ModuleList([_tconv(F_in, width, 1)] + [_tconv(width, width, 2) for _ in range(levels)])
        lengths = [size[0]]                            # frames per level: 61, 31, 16, 8
        for _ in range(levels):
            lengths.append((lengths[-1] - 1) // 2 + 1)
        self.lengths = lengths
        self.head = GaussianHead(width * lengths[-1], latent)
        self.from_z = nn.Linear(latent, width * lengths[-1])
        # resize-convolutions (linear upsampling, then a convolution): transposed convolutions of stride 2 leave a
        # two-frame ripple in the output, which shows in the accelerations (PSKL)
        self.ups = nn.ModuleList(nn.Sequential(nn.Upsample(scale_factor=2, mode="linear", align_corners=False),
                                               _tconv(2 * width, width, 1)) for _ in range(levels))
        self.fuse = _tconv(2 * width, width, 1)
        self.out = nn.Conv1d(width, size[1], 3, padding=1)
        nn.init.zeros_(self.out.weight)               # starts at the linear blend of the known frames (`base`)
        nn.init.zeros_(self.out.bias)

    def encode(self, image: Tensor, cond: Tensor) -> tuple[Tensor, Tensor]:
        """q(z_m | I, I_c): (B,4,61,F) x2 -> mean, log-variance (B, latent)."""
        return self.head(self.enc(torch.cat([_rows(image), _rows(cond)], 1)).flatten(1))

    def decode(self, z: Tensor, cond: Tensor) -> Tensor:
        """p(I | z_m, I_c): channel 0 of the motion image (B, 61, F) (markers normalised, contact logits)."""
        skips, h = [], _rows(cond)
        for layer in self.cond:
            h = layer(h)
            skips.append(h)
        h = self.from_z(z).view(z.shape[0], -1, self.lengths[-1])
        for k, up in enumerate(self.ups):
            h = up(torch.cat([h, skips[-1 - k]], 1))[..., :self.lengths[-2 - k]]
        y = self.out(self.fuse(torch.cat([h, skips[0]], 1))).transpose(1, 2)
        return y + self.base(cond)


# ------------------------------------------------------------------------------------------------ the whole model
def traj_velocity(traj: Tensor) -> Tensor:
    """Root velocities in each frame's heading frame (B, T+1, 3) = (dx, dy, dgamma) from Gamma (B, T+2, 4)
    (as graspkit.data.motionfill_dataset.local_motion; differentiable)."""
    g = torch.atan2(traj[..., 3], traj[..., 2])
    c, s = torch.cos(g[:, :-1]), torch.sin(g[:, :-1])
    d = traj[:, 1:, :2] - traj[:, :-1, :2]
    dx, dy = c * d[..., 0] + s * d[..., 1], -s * d[..., 0] + c * d[..., 1]
    dg = torch.atan2(torch.sin(g[:, 1:] - g[:, :-1]), torch.cos(g[:, 1:] - g[:, :-1]))
    return torch.stack([dx, dy, dg], -1)


def check_known_frames(local: Tensor, contacts: Tensor) -> None:
    """The frames 0 and T that infilling reads: local markers (61,79,3) in metres from the root and contacts (61,4)
    in [0, 1]; a ValueError naming local / contacts otherwise (markers in mm came back hundreds of metres away)."""
    require_points_in_metres(torch.as_tensor(local)[[0, -1]].double(), "local", "local markers are metres from the root")
    check_probabilities(torch.as_tensor(contacts)[[0, -1]].double(), "contacts")


class MotionFillVAE(nn.Module):
    """TrajFill + LocalMotionFill with their normalisation statistics (buffers: marker_mean/std, vel_mean/std)."""

    # buffers, registered in __init__ (declared for type checkers)
    marker_mean: Tensor
    marker_std: Tensor
    vel_mean: Tensor
    vel_std: Tensor

    def __init__(self, cfg: MotionFillConfig | None = None) -> None:
        super().__init__()
        self.cfg = cfg = cfg or MotionFillConfig()
        self.traj = TrajFill(cfg.traj_latent, enc=cfg.traj_enc, widths=tuple(cfg.traj_widths), basis=cfg.traj_basis)
        if cfg.local_arch == "image":
            self.local: _InfillCVAE = LocalMotionFill(cfg.motion_latent, cfg.channels)
        elif cfg.local_arch == "temporal":
            self.local = TemporalMotionFill(cfg.motion_latent, cfg.temporal_width)
        else:
            raise ValueError(f"local_arch: expected 'image' or 'temporal', got {cfg.local_arch!r}")
        for k, n in (("marker_mean", NUM_MARKERS * 3), ("marker_std", NUM_MARKERS * 3), ("vel_mean", 3),
                     ("vel_std", 3)):
            self.register_buffer(k, torch.zeros(n) if "mean" in k else torch.ones(n))

    def set_stats(self, stats: Any) -> None:
        """Copy MotionFillStats (graspkit.data.motionfill_dataset) into the buffers."""
        for k in ("marker_mean", "marker_std", "vel_mean", "vel_std"):
            getattr(self, k).copy_(getattr(stats, k))

    def image(self, local: Tensor, contacts: Tensor, vel: Tensor) -> tuple[Tensor, Tensor]:
        """Motion image I and condition image I_c (B, 4, 61, F) from local markers, contacts, root velocities."""
        x = (local.flatten(2) - self.marker_mean) / self.marker_std
        ch0 = torch.cat([x, contacts.to(x.dtype)], -1)
        v = ((vel - self.vel_mean) / self.vel_std).permute(0, 2, 1)[..., None].expand(-1, -1, -1, ch0.shape[-1])
        img = torch.cat([ch0[:, None], v], 1)
        cond = img.clone()
        cond[:, 0, 1:-1] = 0.0
        return img, cond

    def split(self, ch0: Tensor) -> tuple[Tensor, Tensor]:
        """Decoded channel 0 (B, 61, F) -> local markers in metres (B, 61, 79, 3), contact logits (B, 61, 4)."""
        local = (ch0[..., :-4] * self.marker_std + self.marker_mean).unflatten(-1, (NUM_MARKERS, 3))
        return local, ch0[..., -4:]

    def loss(self, batch: dict[str, Tensor], parts: tuple[str, ...] = ("traj", "local"),
             trajectory: str = "truth") -> dict[str, Tensor]:
        """Eq. 8-9 on a batch of MotionFillDataset items; `parts` picks the CVAEs trained; `trajectory` ('truth' or
        'predicted') says which root velocities build LocalMotionFill's condition image (the fine-tuning uses TrajFill's,
        without gradient into TrajFill)."""
        cfg = self.cfg
        if cfg.reduction not in ("sum", "mean"):
            raise ValueError(f"reduction: expected 'sum' or 'mean', got {cfg.reduction!r}")
        if not isinstance(parts, (tuple, list)) or not parts or not set(parts) <= {"traj", "local"}:
            raise ValueError(f"parts: expected a non-empty subset of ('traj', 'local'), got {parts!r}")
        if trajectory not in ("truth", "predicted"):
            raise ValueError(f"trajectory: expected 'truth' or 'predicted', got {trajectory!r}")
        if trajectory == "predicted" and "traj" not in parts:
            raise ValueError("trajectory: 'predicted' needs TrajFill's prediction, so parts must include 'traj'")
        check_window_batch(batch, ("traj", "traj_interp", "vel") if "local" not in parts
                           else ("traj", "traj_interp", "vel", "local", "contacts") if "traj" in parts
                           else ("vel", "local", "contacts"))
        logs: dict[str, Tensor] = {}
        loss = torch.zeros(())
        vel = batch["vel"]
        if "traj" in parts:
            traj_hat, mu, logvar = self.traj(batch["traj"], batch["traj_interp"])
            logs["traj"] = _reduce((traj_hat - batch["traj"]).abs(), cfg.reduction)
            v_hat = traj_hat[:, 1:] - traj_hat[:, :-1]
            logs["traj_vel"] = _reduce((v_hat - (batch["traj"][:, 1:] - batch["traj"][:, :-1])).abs(), cfg.reduction)
            logs["kl_traj"] = kl_standard_normal(mu, logvar)
            loss = (loss + logs["traj"] + cfg.l1 * logs["traj_vel"]
                    + cfg.lambda_kl * robust_kl(mu, logvar, per_dim=cfg.reduction == "mean"))
            if trajectory == "predicted":      # detached: the local terms would pull TrajFill off the data
                vel = traj_velocity(traj_hat).detach()
        if "local" in parts:
            _, cond = self.image(batch["local"], batch["contacts"], vel)             # the condition: vel as chosen
            target, _ = self.image(batch["local"], batch["contacts"], batch["vel"])   # the encoder sees the truth
            ch0, mu, logvar = self.local(target, cond)
            x, c = ch0[..., :-4], ch0[..., -4:]
            xt, ct = target[:, 0, :, :-4], target[:, 0, :, -4:]
            logs["markers"] = _reduce((x - xt).abs(), cfg.reduction)
            logs["markers_vel"] = _reduce(((x[:, 1:] - x[:, :-1]) - (xt[:, 1:] - xt[:, :-1])).abs(), cfg.reduction)
            logs["contacts"] = _reduce(F.binary_cross_entropy_with_logits(c, ct, reduction="none"), cfg.reduction)
            logs["kl_motion"] = kl_standard_normal(mu, logvar)
            loss = (loss + cfg.l2 * logs["contacts"] + cfg.l3 * logs["markers"] + cfg.l4 * logs["markers_vel"]
                    + cfg.lambda_kl * robust_kl(mu, logvar, per_dim=cfg.reduction == "mean"))
            with torch.no_grad():
                local, _ = self.split(ch0)
                logs["marker_error_cm"] = (local - batch["local"]).norm(dim=-1).mean() * 100
        return {"loss": loss, **logs}

    @torch.no_grad()
    def sample(self, traj_interp: Tensor, local: Tensor, contacts: Tensor, n: int = 1,
               generator: torch.Generator | None = None, traj: Tensor | None = None) -> dict[str, Tensor]:
        """n infillings of one window: Gamma_bar (62,4), local markers (61,79,3) and contacts (61,4) of which only
        frames 0 and T are used; `traj` (62,4) replaces TrajFill's sample (local infilling with a given trajectory).
        Returns traj (n,62,4), local (n,61,79,3), contacts (n,61,4) probabilities, markers (n,61,79,3) canonical."""
        from graspkit.data.motionfill_dataset import global_motion

        shapes = {"traj_interp": (traj_interp, (NUM_ROOT, 4)), "local": (local, (NUM_FRAMES, NUM_MARKERS, 3)),
                  "contacts": (contacts, (NUM_FRAMES, 4)), "traj": (traj, (NUM_ROOT, 4))}
        for name, (x, shape) in shapes.items():
            if x is None:
                continue
            try:
                x = torch.as_tensor(x)
            except (TypeError, ValueError, RuntimeError):
                raise ValueError(f"{name}: expected a tensor of shape {shape}, got {type(x).__name__}") from None
            if tuple(x.shape) != shape:
                raise ValueError(f"{name}: expected shape {shape}, got {tuple(x.shape)}")
            if x.is_complex() or (x.is_floating_point() and not bool(torch.isfinite(x).all())):
                raise ValueError(f"{name}: expected finite real values (no NaN or Inf)")
        traj_interp, local, contacts = (torch.as_tensor(x) for x in (traj_interp, local, contacts))
        traj = None if traj is None else torch.as_tensor(traj)
        check_known_frames(local, contacts)
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
            raise ValueError(f"n: expected a whole number >= 1 of samples, got {n!r}")
        check_generator(generator)
        was = self.training
        self.eval()
        ti = traj_interp.float().expand(n, -1, -1)
        if traj is None:
            zt = torch.randn(n, self.traj.latent, generator=generator)
            traj_hat = self.traj.decode(zt, ti)
        else:
            traj_hat = traj.float().expand(n, -1, -1)
        vel = traj_velocity(traj_hat)
        loc = local.float().expand(n, -1, -1, -1).clone()
        _, cond = self.image(loc, contacts.float().expand(n, -1, -1), vel)
        zm = torch.randn(n, self.local.latent, generator=generator)
        loc_hat, logits = self.split(self.local.decode(zm, cond))
        markers = torch.as_tensor(global_motion(loc_hat.double().numpy(), traj_hat.double().numpy())).float()
        self.train(was)
        return {"traj": traj_hat, "local": loc_hat, "contacts": torch.sigmoid(logits), "markers": markers}

    def state(self) -> dict[str, Any]:
        """Weights, buffers and config (weights-only checkpoint)."""
        return {"model": self.state_dict(), "model_config": asdict(self.cfg)}

    @classmethod
    def from_state(cls, state: dict[str, Any]) -> "MotionFillVAE":
        """Rebuild from `state()` (or a fit checkpoint whose extra holds model_config)."""
        cfg = state.get("model_config") or state.get("extra", {}).get("model_config")
        if not isinstance(cfg, dict) or "traj_widths" not in cfg or not isinstance(state.get("model"), dict):
            raise ValueError("state: not a MotionFill-VAE checkpoint (no MotionFill model_config and weights in it)")
        cfg = dict(cfg)
        cfg["channels"], cfg["traj_widths"] = tuple(cfg["channels"]), tuple(cfg["traj_widths"])
        cfg.setdefault("traj_basis", 0)                 # checkpoints from before these options
        cfg.setdefault("local_arch", "image")
        try:
            model = cls(MotionFillConfig(**cfg))
            model.load_state_dict({k: v.float() if v.is_floating_point() else v for k, v in state["model"].items()})
        except (TypeError, RuntimeError) as e:          # another model's config keys or weights
            raise ValueError(f"state: not a MotionFill-VAE checkpoint of this version ({e})") from None
        return model.eval()
