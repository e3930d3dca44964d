"""WholeGrasp-VAE (SAGA §3.2, Fig. 3, App. A.2, A.4): a multi-task CVAE over whole-body grasps as body markers plus
mutual contact maps, conditioned on the object.

Data (SAGA §3 "Preliminaries", A.1, A.3): the 143 markers M (49 body, 14 face, 6 hand, 30 finger, 44 palm), their
contacts C_M in {0,1}^143, the object as 2,048 surface points O (xyz + normal), its contacts C_O in {0,1}^2048 and
its height t_O (the height of its centre above the floor); object and markers are centred at the object's centre.

    encoder  q(z | M, C_M, C_O, t_O, O):  body branch  [M, C_M] -> ResBlocks -> F_B
                                          object branch PointNet++(xyz; normal, C_O) -> F_O   (C_O in the encoder only)
                                          [F_B, F_O, t_O] -> ResBlock -> Gaussian over z (16-D)
    decoder  p(M, C_M, C_O | z, t_O, O): PointNet++(xyz; normal) -> F'_O and its levels
                                          [z, F'_O, t_O] -> ResBlocks -> markers (143x3), sigmoid C_M (143)
                                          per-point sigmoid C_O by feature propagation of [z-conditioned feature]
                                          down the PointNet++ levels to the 2,048 points

Losses (Eq. 1-3, weights A.4): L = L_rec + lambda_KL L_KL + lambda_c L_c with
    L_rec = |M - M~|_1 + lambda_M BCE_w(C_M, C~_M) + lambda_O BCE_w(C_O, C~_O)        (Eq. 1)
    L_KL  = Psi(KL(q || N(0, I))), Psi(s) = sqrt(s^2 + 1) - 1                          (Eq. 2)
    L_c   = sum_m C~_m |d(m~, O) - d(m, O)| + sum_o C~_o |d(o, M~) - d(o, M)|          (Eq. 3)
d(x, Y) = min_y |x - y|^2 (squared, as the paper). Weights: lambda_M = lambda_O = lambda_c = 1, in-contact class
weights 5 (markers) and 3 (object), lambda_KL = 0.005 e (epoch e) over SAGA's 40 epochs, i.e. rising linearly to
0.2; graspkit trains fewer epochs and keeps that end point: lambda_KL = 0.2 e / E.
Reductions (the paper does not give them): |.|_1 and the sums of Eq. 3 are summed over markers / points and
averaged over the batch (as written); the BCEs are means over markers / points (the usual L_bce).
`multitask=False` gives the paper's WholeGrasp-single baseline (App. B.1, Fig. S3b): markers only.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import torch
from torch import Tensor, nn
from torch.nn import functional as F

from graspkit.models.blocks import GaussianHead, ResBlock, kl_standard_normal, reparameterize, robust_kl
from graspkit.models.pointnet2 import FeaturePropagation, Grouping, PointNet2Encoder, groupings_from_tensors


@dataclass
class WholeGraspConfig:
    """Sizes and loss weights of WholeGrasp-VAE (SAGA A.2, A.4)."""

    n_markers: int = 143
    latent: int = 16                  # SAGA A.2: a 16-dimensional joint latent
    hidden: int = 256                 # width of the marker branches
    object_feature: int = 128         # the PointNet++ global feature (512) projected to this width
    nsample: int = 8                  # PointNet++ neighbours per centre (not in the paper)
    point_norm: bool = False          # BatchNorm inside the PointNet++ MLPs (off: ~2x faster on CPU)
    multitask: bool = True            # False: WholeGrasp-single (markers only, App. B.1)
    marker_contact_weight: float = 5.0   # A.4: in-contact class weight of C_M
    object_contact_weight: float = 3.0   # A.4: in-contact class weight of C_O
    lambda_m: float = 1.0             # A.4: lambda_M of Eq. 1
    lambda_o: float = 1.0             # A.4: lambda_O of Eq. 1
    lambda_c: float = 1.0             # A.4: lambda_c
    kl_final: float = 0.2             # A.4: 0.005 e at SAGA's last epoch e = 40


@dataclass
class Grasps:
    """Sampled whole-body grasps in the object frame (object centre at 0, z up); world = object frame + translation."""

    markers: Tensor                   # (n, N, 3)
    marker_contact: Tensor | None     # (n, N) in-contact probabilities (None for WholeGrasp-single)
    object_contact: Tensor | None     # (n, P)
    translation: Tensor               # (3,) object centre in the world

    def markers_world(self) -> Tensor:
        """(n, N, 3) markers in the world frame."""
        return self.markers + self.translation


def squared_min_distance(x: Tensor, y: Tensor) -> Tensor:
    """SAGA's d(x, Y) = min_y |x - y|^2 for every x: x (B, N, 3), y (B, M, 3) -> (B, N)."""
    return torch.cdist(x, y).pow(2).min(-1).values


def weighted_bce(prob: Tensor, target: Tensor, pos_weight: float) -> Tensor:
    """Class-weighted binary cross-entropy (mean over elements): in-contact terms weighted by pos_weight."""
    p = prob.clamp(1e-6, 1 - 1e-6)
    loss = -(pos_weight * target * torch.log(p) + (1 - target) * torch.log1p(-p))
    return loss.mean()


def consistency_loss(markers_pred: Tensor, markers: Tensor, contact_pred_m: Tensor, points: Tensor,
                     contact_pred_o: Tensor) -> Tensor:
    """SAGA Eq. 3: marker-object and object-marker squared distances of the generated vs. ground-truth markers,
    weighted by the predicted contacts. markers (B,N,3), contacts (B,N), points (B,P,3), (B,P) -> scalar."""
    dm = (squared_min_distance(markers_pred, points) - squared_min_distance(markers, points)).abs()
    do = (squared_min_distance(points, markers_pred) - squared_min_distance(points, markers)).abs()
    return ((contact_pred_m * dm).sum(-1) + (contact_pred_o * do).sum(-1)).mean()


class WholeGraspVAE(nn.Module):
    """SAGA's WholeGrasp-VAE (multi-task) or WholeGrasp-single (cfg.multitask=False); see the module docstring."""

    def __init__(self, cfg: WholeGraspConfig | None = None) -> None:
        super().__init__()
        self.cfg = cfg = cfg or WholeGraspConfig()
        n, h, mt, o = cfg.n_markers, cfg.hidden, cfg.multitask, cfg.object_feature
        act = nn.LeakyReLU(0.2)
        self.obj_enc = PointNet2Encoder(3 + int(mt), nsample=cfg.nsample, norm=cfg.point_norm)
        self.obj_dec = PointNet2Encoder(3, nsample=cfg.nsample, norm=cfg.point_norm)
        c = self.obj_enc.out_channels
        # encoder: body branch, object branch (projected to o), fused into the 16-D Gaussian
        self.body_enc = nn.Sequential(nn.Linear(n * (3 + int(mt)), h), act, ResBlock(h, h, n_hidden=h // 2))
        self.obj_enc_proj = nn.Linear(c, o)
        self.fuse = nn.Sequential(nn.Linear(h + o + 1, h), act)
        self.head = GaussianHead(h, cfg.latent)
        # decoder: [z, object feature, t_O] -> ResBlocks -> markers, marker contacts; FP head -> object contacts
        self.obj_dec_proj = nn.Linear(c, o)
        self.dec = nn.Sequential(nn.Linear(cfg.latent + o + 1, h), act, ResBlock(h, h, n_hidden=h // 2))
        self.out_markers = nn.Linear(h, n * 3)
        if mt:
            self.out_marker_contact = nn.Linear(h, n)
            lv = self.obj_dec.level_channels                      # [3, 128, 256, 512]
            self.global_proj = nn.Linear(o + h, 128)
            self.fp3 = FeaturePropagation(128 + lv[2], [128], norm=cfg.point_norm)
            self.fp2 = FeaturePropagation(128 + lv[1], [64], norm=cfg.point_norm)
            self.fp1 = FeaturePropagation(64 + lv[0], [64, 64], norm=cfg.point_norm)
            self.out_object_contact = nn.Linear(64, 1)

    # ------------------------------------------------------------------ pieces
    @staticmethod
    def _check(name: str, x: Tensor, shape: tuple[int | None, ...]) -> None:
        """ValueError naming `name` unless x matches shape (None = any size)."""
        if not isinstance(x, Tensor) or x.dim() != len(shape) or any(s is not None and s != d
                                                                     for s, d in zip(shape, x.shape)):
            got = tuple(x.shape) if isinstance(x, Tensor) else type(x).__name__
            raise ValueError(f"{name}: expected shape {shape} (None = any), got {got}")

    def group(self, points: Tensor) -> list[Grouping | None]:
        """PointNet++ neighbourhoods of object points (B, P, 3), shared by the encoder and decoder branches."""
        return self.obj_dec.group(points)

    def encode(self, markers: Tensor, marker_contact: Tensor | None, points: Tensor, normals: Tensor,
               object_contact: Tensor | None, height: Tensor, groupings: list[Grouping | None] | None = None
               ) -> tuple[Tensor, Tensor]:
        """q(z | M, C_M, C_O, t_O, O): markers (B,N,3), contacts (B,N), (B,P), points/normals (B,P,3), height (B,1)
        -> mean, log-variance (B, latent)."""
        B = markers.shape[0]
        body = markers.reshape(B, -1)
        feat = normals
        if self.cfg.multitask:
            body = torch.cat([body, marker_contact], -1)
            feat = torch.cat([normals, object_contact.unsqueeze(-1)], -1)
        f_o = self.obj_enc_proj(self.obj_enc(points, feat, groupings).global_feature)
        return self.head(self.fuse(torch.cat([self.body_enc(body), f_o, height], -1)))

    def decode(self, z: Tensor, points: Tensor, normals: Tensor, height: Tensor,
               groupings: list[Grouping | None] | None = None) -> dict[str, Tensor]:
        """p(M, C_M, C_O | z, t_O, O): z (B, latent) -> {'markers' (B,N,3), 'marker_contact' (B,N),
        'object_contact' (B,P)} (contacts as probabilities; absent for WholeGrasp-single)."""
        B = z.shape[0]
        lv = self.obj_dec(points, normals, groupings)
        f_o = self.obj_dec_proj(lv.global_feature)
        h = self.dec(torch.cat([z, f_o, height], -1))
        out = {"markers": self.out_markers(h).view(B, self.cfg.n_markers, 3)}
        if self.cfg.multitask:
            out["marker_contact"] = torch.sigmoid(self.out_marker_contact(h))
            g = self.global_proj(torch.cat([f_o, h], -1)).unsqueeze(1)          # (B, 1, 128)
            f = self.fp3(lv.xyz[2], lv.xyz[3], lv.features[2], torch.relu(g))
            f = self.fp2(lv.xyz[1], lv.xyz[2], lv.features[1], f)
            f = self.fp1(lv.xyz[0], lv.xyz[1], lv.features[0], f)
            out["object_contact"] = torch.sigmoid(self.out_object_contact(f).squeeze(-1))
        return out

    def forward(self, batch: dict[str, Tensor], generator: torch.Generator | None = None) -> dict[str, Tensor]:
        """Reconstruction of a batch: decoder outputs plus 'mu', 'logvar'.

        Keys: markers (B,N,3), marker_contact (B,N), points, normals (B,P,3), object_contact (B,P), height (B,1),
        optionally precomputed PointNet++ groupings (pointnet2.groupings_to_tensors; they are invariant to rigid
        motions of the cloud, so a dataset computes them once).
        """
        self.check_batch(batch)
        groupings = groupings_from_tensors(batch, len(self.obj_dec.sa)) or self.group(batch["points"])
        mu, logvar = self.encode(batch["markers"], batch.get("marker_contact"), batch["points"], batch["normals"],
                                 batch.get("object_contact"), batch["height"], groupings)
        z = reparameterize(mu, logvar, generator) if self.training else mu
        out = self.decode(z, batch["points"], batch["normals"], batch["height"], groupings)
        out.update(mu=mu, logvar=logvar)
        return out

    def check_batch(self, batch: dict[str, Tensor]) -> None:
        """ValueError naming the first key with a wrong shape."""
        for k in ("markers", "points", "normals", "height") + (("marker_contact", "object_contact")
                                                                if self.cfg.multitask else ()):
            if k not in batch:
                raise ValueError(f"batch: missing key {k!r}")
        B, P = batch["points"].shape[0], batch["points"].shape[1]
        N = self.cfg.n_markers
        self._check("markers", batch["markers"], (B, N, 3))
        self._check("points", batch["points"], (B, P, 3))
        self._check("normals", batch["normals"], (B, P, 3))
        self._check("height", batch["height"], (B, 1))
        if self.cfg.multitask:
            self._check("marker_contact", batch["marker_contact"], (B, N))
            self._check("object_contact", batch["object_contact"], (B, P))

    # ------------------------------------------------------------------ losses
    def loss(self, batch: dict[str, Tensor], out: dict[str, Tensor], epoch: int, epochs: int) -> dict[str, Tensor]:
        """SAGA Eq. 1-3 and A.4 for one batch; `epoch` is 0-based, lambda_KL = kl_final (epoch + 1) / epochs."""
        cfg = self.cfg
        logs: dict[str, Tensor] = {}
        logs["rec_markers"] = (out["markers"] - batch["markers"]).abs().sum((1, 2)).mean()
        rec = logs["rec_markers"]
        if cfg.multitask:
            logs["bce_markers"] = weighted_bce(out["marker_contact"], batch["marker_contact"], cfg.marker_contact_weight)
            logs["bce_object"] = weighted_bce(out["object_contact"], batch["object_contact"], cfg.object_contact_weight)
            logs["consistency"] = consistency_loss(out["markers"], batch["markers"], out["marker_contact"],
                                                   batch["points"], out["object_contact"])
            rec = rec + cfg.lambda_m * logs["bce_markers"] + cfg.lambda_o * logs["bce_object"]
        logs["kl"] = kl_standard_normal(out["mu"], out["logvar"])
        kl_w = cfg.kl_final * (epoch + 1) / max(epochs, 1)
        loss = rec + kl_w * robust_kl(out["mu"], out["logvar"])
        if cfg.multitask:
            loss = loss + cfg.lambda_c * logs["consistency"]
        logs["marker_error_cm"] = (out["markers"] - batch["markers"]).norm(dim=-1).mean().detach() * 100
        return {"loss": loss, **logs}

    # ------------------------------------------------------------------ inference
    @torch.no_grad()
    def sample(self, object_points: Tensor, object_normals: Tensor, object_height: float | Tensor | None = None,
               n: int = 1, generator: torch.Generator | None = None, centre: Tensor | None = None) -> Grasps:
        """n grasps for one object: points/normals (P,3) in the world (z up, floor z=0) -> Grasps in the object frame.

        The object frame is the world translated to the object centre (default: the centre of the points'
        bounding box, SAGA A.3); `object_height` defaults to the centre's height. z ~ N(0, I) from `generator`.
        """
        self._check("object_points", object_points, (None, 3))
        self._check("object_normals", object_normals, tuple(object_points.shape))
        if n < 1:
            raise ValueError(f"n: expected at least one sample, got {n}")
        was = self.training
        self.eval()
        dev = self.out_markers.weight.device
        pts = object_points.to(dev, torch.float32)
        if centre is None:
            centre = 0.5 * (pts.min(0).values + pts.max(0).values)
        centre = torch.as_tensor(centre, dtype=torch.float32, device=dev)
        h = centre[2] if object_height is None else torch.as_tensor(object_height, dtype=torch.float32, device=dev)
        z = torch.randn(n, self.cfg.latent, generator=generator, device=dev)
        p = (pts - centre).expand(n, -1, -1)
        nrm = object_normals.to(dev, torch.float32).expand(n, -1, -1)
        out = self.decode(z, p, nrm, h.reshape(1, 1).expand(n, 1))
        self.train(was)
        return Grasps(out["markers"], out.get("marker_contact"), out.get("object_contact"), centre)

    # ------------------------------------------------------------------ files
    def state(self) -> dict[str, Any]:
        """Weights and config as plain values (a weights-only checkpoint)."""
        return {"model": self.state_dict(), "config": asdict(self.cfg)}

    @classmethod
    def from_state(cls, state: dict[str, Any]) -> "WholeGraspVAE":
        """Rebuild from `state()` or a training checkpoint written by graspkit.train.fit (config under extra)."""
        cfg = state.get("model_config") or state.get("extra", {}).get("model_config") or state.get("config")
        if cfg is None or "latent" not in cfg:
            raise ValueError("state: no WholeGrasp config in it (expected key 'config' or extra['model_config'])")
        model = cls(WholeGraspConfig(**cfg))
        model.load_state_dict(state["model"])
        model.eval()
        return model
