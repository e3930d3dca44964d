"""GOAL's GNet (Taheri et al., CVPR 2022, §3.3, Eq. 2–3): a CVAE over static whole-body right-hand grasps.

Encoder input (Eq. 2)   X = [Θ, β, v, q, γ°, b°, d^{b→o}]
    Θ = {θ ∈ R^{55×6} (6D rotations, Zhou et al.), γ ∈ R^3}   SMPL-X pose and translation
    β ∈ R^10                                                  shape
    v ∈ R^{400×3}                                             GOAL's N_b = 400 sampled body vertices
    q ∈ R^3                                                   unit head direction (back of the head -> nose)
    γ° ∈ R^3, b° ∈ R^1024                                     object translation and BPS code
    d^{b→o} ∈ R^{400×3}                                       offset from each sampled vertex to its closest object point
Latent z ∈ R^16 (N(μ, σ) at training time, N(0, I) at inference).
Decoder: [z, C = (b°, γ°), β] -> Θ̂, q̂ and the offsets d̂^{h→o} ∈ R^{99×3} of the N_h = 99 right-hand vertices.
(GOAL's C is [b°, γ°]; β is added so that one decoder serves every body shape: the grasp depends on arm length.)

Interaction-aware attention (§3.2, Eq. 1): the encoder sees the body-to-object offsets weighted by
I_w(d) = exp(-w d), w = 5, with d = |d^{b→o}| the distance (m) from each sampled vertex to the nearest object
point, so that vertices far from the object (knees, the other hand) say little and the grasping hand a lot.

BPS (Prokudin et al.): 1024 basis points fixed once (seeded), uniform in a ball of 0.15 m around the object
centre, *not* rotated with the object: the code of a turned object changes, so it carries the object's
orientation as well as its shape (`graspkit.objects.bps_basis`).

Loss (Eq. 3): λ_v‖v − v̂‖₁ + λ_v^h‖v^h − v̂^h‖₁ + λ_Θ‖Θ − Θ̂‖₂² + λ_q‖q − q̂‖₂² + λ_d‖d^{h→o} − d̂^{h→o}‖₁ + λ_KL KL,
where v̂ = SMPL-X(Θ̂, β) at the sampled vertices (`SparseBody`). The weights are `GNetLossWeights`.

`offsets=False` gives the GrabNet-style SMPL-X CVAE of GOAL Tab. 1 row 2: the same network with a decoder that
outputs Θ only (no offsets to refine with, no head direction), trained with the vertex, Θ and KL terms.
"""
from __future__ import annotations

import warnings
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import torch
from torch import Tensor, nn

from graspkit.checks import GraspkitWarning, check_generator, user_stacklevel
from graspkit.models.blocks import GaussianHead, ResBlock, kl_standard_normal, reparameterize
from graspkit.objects.contact import IAA_WEIGHT
from graspkit.rotations import rot6d_to_matrix
from graspkit.state import keeps_torch_state

if TYPE_CHECKING:
    from collections.abc import Sequence

    import numpy as np

    from graspkit.body import BodyModel
    from graspkit.train import TrainConfig

NUM_JOINTS = 55
POSE_DIM = NUM_JOINTS * 6 + 3        # Θ = 55 6D rotations + translation γ
GNET_KEYS = ("rot6d", "transl", "betas", "verts", "head_dir", "obj_transl", "bps", "offsets")


# ------------------------------------------------------------------------------------------- the body at few vertices

class SparseBody(nn.Module):
    """SMPL-X LBS of a BodyModel evaluated at `vertex_ids` only (exactly the full model's vertices there)."""

    # buffers, registered in __init__ (declared for type checkers)
    ids: Tensor
    v_cm: Tensor
    basis: Tensor
    posedirs: Tensor
    weights_t: Tensor

    def __init__(self, bm: BodyModel, vertex_ids: Tensor | np.ndarray | Sequence[int]) -> None:
        super().__init__()
        ids = torch.as_tensor(vertex_ids, dtype=torch.long).reshape(-1)
        if ids.numel() == 0 or int(ids.min()) < 0 or int(ids.max()) >= bm.num_vertices:
            raise ValueError(f"vertex_ids: expected ids in [0, {bm.num_vertices}), got {ids.numel()} ids")
        V, n = bm.num_vertices, ids.numel()
        cm = torch.cat([c * V + ids for c in range(3)])          # coordinate-major columns of the chosen vertices
        self.bm = bm
        self.n = n
        self.register_buffer("ids", ids)
        self.register_buffer("v_cm", bm.v_template[ids].T.reshape(1, 3 * n).clone())
        self.register_buffer("basis", bm.shape_basis[:, cm].clone())
        self.register_buffer("posedirs", bm.posedirs[:, cm].clone() if bm.has_posedirs else torch.zeros(0))
        self.register_buffer("weights_t", bm.lbs_weights[ids].T.contiguous())

    def forward(self, rot: Tensor, betas: Tensor, transl: Tensor) -> tuple[Tensor, Tensor]:
        """rot (B,55,3,3), betas (B or 1, k <= num_betas), transl (B,3) -> vertices (B,n,3), joints (B,55,3)."""
        bm, B = self.bm, rot.shape[0]
        if rot.dim() != 4 or rot.shape[1:] != (NUM_JOINTS, 3, 3) or B == 0:
            raise ValueError(f"rot: expected (B, {NUM_JOINTS}, 3, 3) with B >= 1, got {tuple(rot.shape)}")
        if betas.dim() != 2 or betas.shape[0] not in (1, B) or betas.shape[1] > bm.num_betas:
            raise ValueError(f"betas: expected (B or 1, k) with k <= {bm.num_betas} (the model's shape components; "
                             f"more would be read as expression), got {tuple(betas.shape)} for B = {B}")
        if transl.shape not in ((B, 3), (1, 3)):
            raise ValueError(f"transl: expected ({B}, 3) or (1, 3), got {tuple(transl.shape)}")
        rot = rot.to(bm.dtype)
        coeffs = torch.zeros(B, bm.num_betas + bm.num_expression, dtype=bm.dtype, device=rot.device)
        coeffs[:, :betas.shape[1]] = betas.to(bm.dtype)
        v = torch.addmm(self.v_cm, coeffs, self.basis).view(B, 3, self.n)
        J = torch.addmm(bm.J_template.view(1, -1), coeffs, bm.J_basis).view(B, NUM_JOINTS, 3)
        if self.posedirs.numel():
            eye = torch.eye(3, dtype=rot.dtype, device=rot.device)
            v = v + ((rot[:, 1:] - eye).reshape(B, -1) @ self.posedirs).view(B, 3, self.n)
        Rg, tg = bm.global_transforms(rot, J)
        t = transl.to(bm.dtype).unsqueeze(1)
        offset = tg + t - (Rg @ J.unsqueeze(-1)).squeeze(-1)
        A = torch.cat([Rg.transpose(2, 3), offset.unsqueeze(2)], dim=2).reshape(B, NUM_JOINTS, 12)
        T = (A.transpose(1, 2) @ self.weights_t).view(B, 4, 3, self.n)
        verts = T[:, 3] + T[:, 0] * v[:, 0:1] + T[:, 1] * v[:, 1:2] + T[:, 2] * v[:, 2:3]
        return verts.transpose(1, 2), tg + t


def pose_rotmats(rot6d: Tensor) -> Tensor:
    """6D joint rotations (B,55,6) -> rotation matrices (B,55,3,3)."""
    return rot6d_to_matrix(rot6d)


def attention_offsets(offsets: Tensor, w: float = IAA_WEIGHT) -> Tensor:
    """GOAL Eq. 1 applied to offsets (..., N, 3): I_w(|d|) d with I_w(d) = exp(-w d), d the distance in metres."""
    return torch.exp(-w * offsets.norm(dim=-1, keepdim=True)) * offsets


# ------------------------------------------------------------------------------------------- normalisation

MIN_STD = 1e-3     # Standardiser's floor on a feature's std


class Standardiser(nn.Module):
    """Feature-wise (x - mean) / std with statistics kept as buffers (saved with the weights): (B,D) -> (B,D)."""

    # buffers, registered in __init__ (declared for type checkers)
    mean: Tensor
    std: Tensor

    def __init__(self, dim: int) -> None:
        super().__init__()
        self.register_buffer("mean", torch.zeros(dim))
        self.register_buffer("std", torch.ones(dim))

    def fit(self, x: Tensor, min_std: float = MIN_STD) -> None:
        """Set the statistics from samples x (N,D); a feature with std < min_std gets std min_std (not 1: a feature
        that hardly varied in training is scaled up 1/min_std times, so `untrained` names inputs far from it)."""
        if x.dim() != 2 or x.shape[1] != self.mean.numel():
            raise ValueError(f"x: expected (N, {self.mean.numel()}), got {tuple(x.shape)}")
        self.mean.copy_(x.mean(0))
        self.std.copy_(x.std(0).clamp_min(min_std) if len(x) > 1 else torch.ones_like(self.std))

    def forward(self, x: Tensor) -> Tensor:
        """Standardise (B,D) -> (B,D)."""
        return (x - self.mean) / self.std

    def inverse(self, y: Tensor) -> Tensor:
        """Undo: (B,D) -> (B,D)."""
        return y * self.std + self.mean

    def floored(self, min_std: float = MIN_STD) -> Tensor:
        """(D,) bool: the features whose std sits at the floor (the training data hardly moved them)."""
        return self.std <= min_std * (1 + 1e-3)         # fp32 statistics land a little above the floor

    def untrained(self, x: Tensor, sigma: float = 5.0, min_std: float = MIN_STD) -> Tensor:
        """(D,) bool: features of x (B,D) more than `sigma` stds from the mean where the std sits at the floor (the
        training data hardly moved them, and the network has only seen them still)."""
        return ((((x - self.mean) / self.std).abs() > sigma) & self.floored(min_std)).any(0)


# ------------------------------------------------------------------------------------------- GNet

@dataclass
class GNetConfig:
    """GNet sizes. GOAL: 16-D latent, N_b = 400, N_h = 99, 1024 BPS points; widths are graspkit's (small)."""

    latent: int = 16
    enc_hidden: int = 64     # encoder width
    hidden: int = 128        # decoder width
    cond: int = 96           # width of the shared code of the condition [b°, γ°, β]
    n_bps: int = 1024
    n_verts: int = 400
    n_hand: int = 99
    n_betas: int = 10
    offsets: bool = True     # False: the GrabNet-style SMPL-X CVAE baseline (Θ only)
    attention: bool = True   # interaction-aware attention on the encoder's offsets (Eq. 1)


@dataclass
class GNetLossWeights:
    """λ of Eq. 3 (vertex and offset terms: mean absolute errors in metres; Θ: mean squared error over its entries;
    q: the squared length ‖q − q̂‖² averaged over the batch)."""

    v: float = 10.0
    v_hand: float = 10.0
    theta: float = 1.0
    q: float = 1.0
    d: float = 10.0
    kl: float = 5e-3


def _fields(cfg: GNetConfig) -> dict[str, int]:
    """Sizes of the encoder's body features, the condition and the decoder's outputs."""
    return {"body": POSE_DIM + cfg.n_betas + 3 * cfg.n_verts + 3 + 3 * cfg.n_verts,
            "cond": cfg.n_bps + 3 + cfg.n_betas,
            "out": POSE_DIM + ((3 + 3 * cfg.n_hand) if cfg.offsets else 0)}


class GNet(nn.Module):
    """GOAL §3.3: the grasp CVAE. Batches are dicts of tensors (see `GNet.features` for the keys and shapes)."""

    def __init__(self, cfg: GNetConfig | None = None) -> None:
        super().__init__()
        self.cfg = cfg = cfg or GNetConfig()
        f = _fields(cfg)
        self.norm_body, self.norm_cond, self.norm_out = Standardiser(f["body"]), Standardiser(f["cond"]), Standardiser(f["out"])
        E, H, C = cfg.enc_hidden, cfg.hidden, cfg.cond
        self.cond_net = nn.Sequential(nn.Linear(f["cond"], C), nn.LayerNorm(C), nn.LeakyReLU(0.2))
        self.enc_in = nn.Sequential(nn.Linear(f["body"], E), nn.LayerNorm(E), nn.LeakyReLU(0.2))
        self.enc = ResBlock(E + C, E, norm="layer")
        self.head = GaussianHead(E, cfg.latent)
        self.dec1 = ResBlock(cfg.latent + C, H, norm="layer")
        self.dec2 = ResBlock(H + cfg.latent + C, H, norm="layer")     # skip: the latent and condition again
        self.out = nn.Linear(H, f["out"])
        nn.init.zeros_(self.out.weight)                                 # start at the data mean
        nn.init.zeros_(self.out.bias)

    # -- features
    def features(self, batch: dict[str, Tensor]) -> tuple[Tensor, Tensor]:
        """Raw encoder body features (B, body) and condition (B, cond) from a batch with keys
        rot6d (B,55,6), transl (B,3), betas (B,10), verts (B,400,3), head_dir (B,3), obj_transl (B,3),
        bps (B,1024), offsets (B,400,3) [body-to-object, Eq. 2]."""
        B = batch["rot6d"].shape[0]
        d = batch["offsets"]
        d = attention_offsets(d) if self.cfg.attention else d
        body = torch.cat([batch["rot6d"].reshape(B, -1), batch["transl"], batch["betas"],
                          batch["verts"].reshape(B, -1), batch["head_dir"], d.reshape(B, -1)], dim=1)
        return body, self.condition(batch["bps"], batch["obj_transl"], batch["betas"])

    @staticmethod
    def condition(bps: Tensor, obj_transl: Tensor, betas: Tensor) -> Tensor:
        """Raw condition [b°, γ°, β] (B, 1024 + 3 + 10)."""
        return torch.cat([bps, obj_transl, betas], dim=1)

    def targets(self, batch: dict[str, Tensor], hand_ids: Tensor | None = None) -> Tensor:
        """Raw decoder targets (B, out): [θ 6D, γ] (+ [q, hand offsets] when cfg.offsets)."""
        B = batch["rot6d"].shape[0]
        parts = [batch["rot6d"].reshape(B, -1), batch["transl"]]
        if self.cfg.offsets:
            hand = batch["offsets"][:, :self.cfg.n_hand] if hand_ids is None else batch["offsets"][:, hand_ids]
            parts += [batch["head_dir"], hand.reshape(B, -1)]
        return torch.cat(parts, dim=1)

    @torch.no_grad()
    def fit_normalisation(self, batch: dict[str, Tensor]) -> None:
        """Standardisation statistics from a (large) batch of training samples."""
        body, cond = self.features(batch)
        self.norm_body.fit(body)
        self.norm_cond.fit(cond)
        self.norm_out.fit(self.targets(batch))

    # -- networks
    def encode(self, batch: dict[str, Tensor]) -> tuple[Tensor, Tensor]:
        """q(z | X, C): mean and log-variance (B, latent)."""
        body, cond = self.features(batch)
        c = self.cond_net(self.norm_cond(cond))
        return self.head(self.enc(torch.cat([self.enc_in(self.norm_body(body)), c], dim=1)))

    def decode(self, z: Tensor, bps: Tensor, obj_transl: Tensor, betas: Tensor) -> dict[str, Tensor]:
        """p(X | z, C): z (B,latent) -> rot6d (B,55,6), transl (B,3) [+ head_dir (B,3) unit, hand_offsets (B,99,3)]."""
        c = self.cond_net(self.norm_cond(self.condition(bps, obj_transl, betas)))
        h = self.dec1(torch.cat([z, c], dim=1))
        y = self.norm_out.inverse(self.out(self.dec2(torch.cat([h, z, c], dim=1))))
        B = z.shape[0]
        out = {"rot6d": y[:, :NUM_JOINTS * 6].reshape(B, NUM_JOINTS, 6), "transl": y[:, NUM_JOINTS * 6:POSE_DIM]}
        if self.cfg.offsets:
            out["head_dir"] = nn.functional.normalize(y[:, POSE_DIM:POSE_DIM + 3], dim=-1)
            out["hand_offsets"] = y[:, POSE_DIM + 3:].reshape(B, self.cfg.n_hand, 3)
        return out

    def forward(self, batch: dict[str, Tensor], generator: torch.Generator | None = None
                ) -> tuple[dict[str, Tensor], Tensor, Tensor]:
        """Training pass: encode, sample z by reparameterisation, decode; returns (outputs, mu, logvar)."""
        mu, logvar = self.encode(batch)
        z = reparameterize(mu, logvar, generator)
        return self.decode(z, batch["bps"], batch["obj_transl"], batch["betas"]), mu, logvar

    @torch.no_grad()
    def sample(self, bps: Tensor, obj_transl: Tensor, betas: Tensor, generator: torch.Generator | None = None,
               z: Tensor | None = None) -> dict[str, Tensor]:
        """Inference (§3.3): skip the encoder, z ~ N(0, I) from `generator` (or given), decode: (B,...) -> outputs."""
        check_generator(generator)
        cfg = self.cfg
        B = len(bps) if isinstance(bps, Tensor) and bps.dim() == 2 else "B"
        bps, obj_transl, betas = (self._sample_input(name, x, (B, width)) for name, x, width in
                                  (("bps", bps, cfg.n_bps), ("obj_transl", obj_transl, 3), ("betas", betas, cfg.n_betas)))
        if bool((bps < 0).any()):
            raise ValueError(f"bps: expected distances >= 0 (m) from the basis points to the object, got a minimum of "
                             f"{float(bps.min()):g}")
        if z is not None:
            z = self._sample_input("z", z, (B, cfg.latent))
        far = torch.nonzero(self.norm_cond.untrained(self.condition(bps, obj_transl, betas))).flatten().tolist()
        if far:
            names = sorted({"bps" if i < cfg.n_bps else "obj_transl" if i < cfg.n_bps + 3 else "betas" for i in far})
            warnings.warn(f"{', '.join(names)}: values more than 5 training stds from where the training data held "
                          "them (std at the 1e-3 floor; GNet's frame puts the object at x = y = 0, so obj_transl is "
                          "(0, 0, height)); the decoder has never seen such a condition", GraspkitWarning,
                          stacklevel=user_stacklevel())
        was = self.training
        self.eval()
        if z is None:
            z = torch.randn(bps.shape[0], self.cfg.latent, generator=generator, dtype=bps.dtype)
        out = self.decode(z, bps, obj_transl, betas)
        self.train(was)
        return out

    def _sample_input(self, name: str, x: Tensor, shape: tuple[int | str, int]) -> Tensor:
        """`sample`'s check of one input: a finite floating tensor of `shape`, returned in the model's dtype."""
        if not isinstance(x, Tensor) or x.dim() != 2 or x.shape[1] != shape[1] or \
                (isinstance(shape[0], int) and len(x) != shape[0]):
            got = tuple(x.shape) if isinstance(x, Tensor) else type(x).__name__
            raise ValueError(f"{name}: expected a tensor of shape ({shape[0]}, {shape[1]}) (batch first), got {got}")
        if not x.is_floating_point():
            raise TypeError(f"{name}: expected a floating-point tensor, got {x.dtype}")
        if not torch.isfinite(x).all():
            raise ValueError(f"{name}: contains NaN or Inf")
        return x.to(self.out.weight.dtype)

    def config_dict(self) -> dict:
        """The config as plain values (for checkpoints)."""
        return asdict(self.cfg)


def gnet_loss(out: dict[str, Tensor], mu: Tensor, logvar: Tensor, batch: dict[str, Tensor], body: SparseBody,
              w: GNetLossWeights | None = None, n_hand: int = 99) -> dict[str, Tensor]:
    """Eq. 3 for one batch; `body` evaluates SMPL-X at the 400 sampled vertices (the 99 hand ones first).

    Returns {'loss', 'v', 'v_hand', 'theta', 'q', 'd', 'kl'} (the unweighted terms and the weighted sum)."""
    w = w or GNetLossWeights()
    v_hat, _ = body(pose_rotmats(out["rot6d"]), batch["betas"], out["transl"])
    v = batch["verts"]
    terms = {"v": (v_hat - v).abs().mean(),
             "v_hand": (v_hat[:, :n_hand] - v[:, :n_hand]).abs().mean(),
             "theta": torch.cat([(out["rot6d"] - batch["rot6d"]).flatten(1), out["transl"] - batch["transl"]],
                                1).pow(2).mean(),
             "kl": kl_standard_normal(mu, logvar)}
    if "hand_offsets" in out:
        terms["q"] = (out["head_dir"] - batch["head_dir"]).pow(2).sum(-1).mean()
        terms["d"] = (out["hand_offsets"] - batch["offsets"][:, :n_hand]).abs().mean()
    weights = {"v": w.v, "v_hand": w.v_hand, "theta": w.theta, "q": w.q, "d": w.d, "kl": w.kl}
    terms["loss"] = sum(weights[k] * t for k, t in terms.items())
    return terms


def count_parameters(model: nn.Module) -> int:
    """Number of trainable parameters."""
    return sum(p.numel() for p in model.parameters() if p.requires_grad)


# ------------------------------------------------------------------------------------------- checkpoints

def save_weights(path: str | Path, model: nn.Module, kind: str, extra: dict | None = None, half: bool = True) -> Path:
    """A shipped checkpoint (atomic, weights only): {'kind', 'config', 'model' (float16 if `half`), 'extra'}."""
    from graspkit.train import save_checkpoint

    state = {k: (v.half() if half and v.is_floating_point() else v).clone() for k, v in model.state_dict().items()}
    return save_checkpoint(path, {"kind": kind, "config": model.config_dict(), "model": state, "extra": extra or {}})


def load_weights(path: str | Path, kind: str, config_cls: type | None = None) -> tuple[dict[str, Tensor], dict]:
    """(float32 state dict, config) from a shipped checkpoint or a training checkpoint of graspkit.train.fit; with
    `config_cls` (a dataclass) the config's entries must be its fields."""
    from graspkit.train import check_config, load_checkpoint

    ck = load_checkpoint(path)
    if not isinstance(ck, dict) or not isinstance(ck.get("model"), dict):
        raise ValueError(f"{path}: not a {kind} checkpoint (expected a dict with 'model' weights written by graspkit)")
    if "kind" in ck and ck["kind"] != kind:
        raise ValueError(f"{path}: a {ck['kind']!r} checkpoint, expected {kind!r}")
    config = ck.get("config") if "kind" in ck else ck.get("extra", {}).get(f"{kind}_config")
    if config is None:
        raise ValueError(f"{path}: no {kind} config inside (expected a checkpoint written by graspkit)")
    if config_cls is not None:
        check_config(config, config_cls, path, f"a {kind} checkpoint")
    if not all(torch.is_tensor(v) for v in ck["model"].values()):
        raise ValueError(f"{path}: not a {kind} checkpoint (its 'model' holds values other than tensors)")
    state = {k: v.float() if v.is_floating_point() else v for k, v in ck["model"].items()}
    return state, config


@keeps_torch_state
def load_gnet(path: str | Path) -> GNet:
    """A GNet from a shipped (or training) checkpoint, in float32 and eval mode."""
    from graspkit.train import build_named, load_into

    state, config = load_weights(path, "gnet", GNetConfig)
    return build_named(path, "a GNet checkpoint",
                       lambda: load_into(GNet(GNetConfig(**config)), state, path, "a GNet checkpoint")).eval()


@keeps_torch_state
def train_gnet(train: dict[str, Tensor], val: dict[str, Tensor] | None, body: SparseBody,
               cfg: GNetConfig | None = None, weights: GNetLossWeights | None = None,
               train_cfg: TrainConfig | None = None, checkpoint: str | Path | None = None,
               time_limit_s: float | None = None, progress: bool = True) -> tuple[GNet, list[dict[str, float]]]:
    """Fit GNet (Eq. 3) with the shared loop on samples {key: (N, ...)} (see GNet.features for the keys)."""
    from graspkit.train import TrainConfig, fit

    train_cfg = train_cfg or TrainConfig(epochs=60, batch_size=64, lr=1e-3)
    torch.manual_seed(train_cfg.seed)
    net = GNet(cfg)
    net.fit_normalisation(train)
    keys = list(GNET_KEYS)

    def step(model: nn.Module, batch: list[Tensor], epoch: int) -> dict[str, Tensor]:
        b = dict(zip(keys, batch))     # training draws z from torch's RNG, which fit() saves and restores on resume
        out, mu, logvar = model(b, generator=None if model.training else torch.Generator().manual_seed(0))
        return gnet_loss(out, mu, logvar, b, body, weights, net.cfg.n_hand)

    def tensors(d: dict[str, Tensor]) -> torch.utils.data.TensorDataset:
        missing = [k for k in keys if k not in d]
        if missing:
            raise ValueError(f"samples: missing {missing} (expected {keys})")
        return torch.utils.data.TensorDataset(*[d[k].float() for k in keys])

    hist = fit(net, step, tensors(train), train_cfg, checkpoint=checkpoint,
               val_dataset=None if val is None else tensors(val), progress=progress, time_limit_s=time_limit_s,
               extra={"gnet_config": net.config_dict()})
    return net, hist
