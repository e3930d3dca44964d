"""WholeGrasp-VAE (SAGA §3.2, Fig. 3, App. A.2, A.4): a multi-task CVAE over whole-body grasps as body markers plus
mutual contact maps, conditioned on the object.

Data (SAGA §3 "Preliminaries", A.1, A.3): the 143 markers M (49 body, 14 face, 6 hand, 30 finger, 44 palm), their
contacts C_M in {0,1}^143, the object as 2,048 surface points O (xyz + normal), its contacts C_O in {0,1}^2048 and
its height t_O (the height of its centre above the floor); object and markers are centred at the object's centre.

    encoder  q(z | M, C_M, C_O, t_O, O):  body branch  [M, C_M] -> Linear + ResBlock -> F_B
                                          object branch PointNet++(xyz; normal, C_O) -> F_O   (C_O in the encoder only)
                                          [F_B, F_O, t_O] -> Linear + LeakyReLU -> Gaussian over z (16-D)
    decoder  p(M, C_M, C_O | z, t_O, O): PointNet++(xyz; normal) -> F'_O and its levels
                                          [z, F'_O, t_O] -> Linear + ResBlock -> markers (143x3), sigmoid C_M (143)
                                          per-point sigmoid C_O by feature propagation of [z-conditioned feature]
                                          down the PointNet++ levels to the 2,048 points

Losses (Eq. 1-3, weights A.4): L = L_rec + lambda_KL L_KL + lambda_c L_c with
    L_rec = |M - M~|_1 + lambda_M BCE_w(C_M, C~_M) + lambda_O BCE_w(C_O, C~_O)        (Eq. 1)
    L_KL  = Psi(KL(q || N(0, I))), Psi(s) = sqrt(s^2 + 1) - 1                          (Eq. 2)
    L_c   = sum_m C~_m |d(m~, O) - d(m, O)| + sum_o C~_o |d(o, M~) - d(o, M)|          (Eq. 3)
d(x, Y) = min_y |x - y|^2 (squared, as the paper); in Eq. 3 the predicted contacts weight the distances without
passing gradients back (see `consistency_loss`). Weights: lambda_M = lambda_O = lambda_c = 1, in-contact class
weights 5 (markers) and 3 (object), lambda_KL = 0.005 e (epoch e) over SAGA's 40 epochs, i.e. rising linearly to
0.2; graspkit trains fewer epochs and keeps that end point: lambda_KL = 0.2 e / E.
Reductions (the paper does not give them): |.|_1 and the sums of Eq. 3 are summed over markers / points and
averaged over the batch (as written); the BCEs are means over markers / points (the usual L_bce).
`consistency="signed"` takes Eq. 3's distances as the authors' released code does rather than as printed: Euclidean
(not squared), and d(m, O) signed by the normal of the nearest object point (negative inside), so that a palm 2 cm
inside the object no longer costs what one 2 cm outside does. Measured (docs/saga.md) it does not keep sampled palms
out of unseen objects, so the default stays Eq. 3 as printed (`consistency="paper"`).
`multitask=False` gives the paper's WholeGrasp-single baseline (App. B.1, Fig. S3b): markers only.

Marker normalisation (graspkit's choice): the networks see and emit standardised markers whose mean depends
linearly on the object height, M = mean + slope (t_O - mean t_O) + std * (network units), the slope fitted per marker
coordinate by least squares on the training grasps (feet come out near -1: they stay on the floor; the hand near 0:
it stays at the object). The losses, inputs and outputs stay object-centred as A.3. Without it the decoder learned
one body for every t_O (the posterior carried the body's height and the decoder ignored t_O, so prior samples put
the feet up to 0.6 m under or above the floor; measured on the first shipped checkpoint); with the opposite fix,
markers measured from the floor, the hand drifted 10-35 cm off the object instead. `height_slope=False` is the plain
object-centred standardisation (checkpoints written before this option load with it).
"""
from __future__ import annotations

import math
import numbers
from dataclasses import asdict, dataclass, fields
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable

import torch
from torch import Tensor, nn

from graspkit.checks import check_generator, check_labels
from graspkit.objects.distance import (MAX_METRES, centred_cdist, nearest_neighbours, require_points_in_metres,
                                      require_unit_normals)
from graspkit.objects.placement import GRASP_HEIGHTS
from graspkit.objects.sdf import signed_distance_to_points
from graspkit.paths import DATA_STUBS
from graspkit.models.blocks import (GaussianHead, ResBlock, annealed_kl_weight, in_eval_mode, kl_standard_normal,
                                   reparameterize, robust_kl)
from graspkit.models.pointnet2 import (FeaturePropagation, Grouping, PointNet2Encoder, gather, groupings_from_tensors,
                                       groupings_to_tensors, interpolation_weights)
from graspkit.state import keeps_torch_state

if TYPE_CHECKING:
    from graspkit.body import BodyModel
    from graspkit.models.gnet import SparseBody
    from graspkit.models.pose_prior import PosePrior


CONSISTENCY = ("paper", "signed")   # Eq. 3 as printed; as the authors' released code computes it


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
    height_slope: bool = True         # marker means linear in t_O (module docstring: marker normalisation)
    consistency: str = "paper"        # Eq. 3's distances: "paper" (as printed) or "signed" (authors' code)

    def __post_init__(self) -> None:
        if self.consistency not in CONSISTENCY:
            raise ValueError(f"consistency: expected one of {CONSISTENCY}, got {self.consistency!r}")


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
    return centred_cdist(x, y).pow(2).min(-1).values


def weighted_bce(prob: Tensor, target: Tensor, pos_weight: float) -> Tensor:
    """Class-weighted binary cross-entropy (mean over elements): in-contact terms weighted by pos_weight."""
    p = prob.clamp(1e-6, 1 - 1e-6)
    loss = -(pos_weight * target * torch.log(p) + (1 - target) * torch.log1p(-p))
    return loss.mean()


def consistency_distances(markers: Tensor, points: Tensor, normals: Tensor | None = None) -> tuple[Tensor, Tensor]:
    """Eq. 3's d(m, O) (B,N) and d(o, M) (B,P) for markers (B,N,3), points (B,P,3): squared and unsigned as printed
    (normals None), or, with the object normals (B,P,3), Euclidean with d(m, O) signed (negative inside)."""
    if normals is None:
        D = centred_cdist(markers, points).pow(2)                              # (B, N, P): both directions at once
        return D.min(2).values, D.min(1).values
    return signed_distance_to_points(markers, points, normals), nearest_neighbours(points, markers)[0]


def consistency_loss(markers_pred: Tensor, markers: Tensor | None, contact_pred_m: Tensor, points: Tensor,
                     contact_pred_o: Tensor, truth: tuple[Tensor, Tensor] | None = None,
                     normals: Tensor | None = None) -> Tensor:
    """SAGA Eq. 3: marker-object and object-marker distances of the generated vs. ground-truth markers, weighted by
    the predicted contacts. markers (B,N,3), contacts (B,N), points (B,P,3), (B,P) -> scalar. Squared and unsigned
    as printed; with `normals` (B,P,3) as the authors' code (`consistency_distances`).

    `truth` = (d(m, O) (B,N), d(o, M) (B,P)) of the ground truth when precomputed (then `markers` may be None)."""
    if truth is None:
        truth = consistency_distances(markers, points, normals)
    pred = consistency_distances(markers_pred, points, normals)
    dm = (pred[0] - truth[0]).abs()
    do = (pred[1] - truth[1]).abs()
    # the contact weights act as weights only (no gradient): summed over 2,048 points, Eq. 3 otherwise outweighs
    # the mean BCE of every point and is lowered most cheaply by predicting no contact where the markers are still
    # wrong, i.e. at the true contacts (measured: C_O's validation AUC fell to 0.38 within two epochs)
    return ((contact_pred_m.detach() * dm).sum(-1) + (contact_pred_o.detach() * do).sum(-1)).mean()


class WholeGraspVAE(nn.Module):
    """SAGA's WholeGrasp-VAE (multi-task) or WholeGrasp-single (cfg.multitask=False); see the module docstring."""

    # buffers, registered in __init__ (declared for type checkers)
    marker_mean: Tensor
    marker_std: Tensor
    marker_slope: Tensor
    height_mean: Tensor

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
        # marker normalisation (training-set mean per marker coordinate, one std per axis): the networks see and
        # emit standardised markers, the losses are in metres
        self.register_buffer("marker_mean", torch.zeros(n, 3))
        self.register_buffer("marker_std", torch.ones(3))
        self.register_buffer("marker_slope", torch.zeros(n, 3))   # d mean / d t_O (height_slope)
        self.register_buffer("height_mean", torch.zeros(1))
        nn.init.zeros_(self.out_markers.weight)           # training starts from the mean grasp
        nn.init.zeros_(self.out_markers.bias)
        if mt:
            self.out_marker_contact = nn.Linear(h, n)
            lv = self.obj_dec.level_channels                      # [3, 128, 256, 512]
            self.global_proj = nn.Linear(o + h, 128)
            self.fp3 = FeaturePropagation(128 + lv[2], [128], norm=cfg.point_norm)
            self.fp2 = FeaturePropagation(128 + lv[1], [64], norm=cfg.point_norm)
            self.fp1 = FeaturePropagation(64 + 3 + lv[0], [64, 64], norm=cfg.point_norm)   # + xyz of each point
            self.out_object_contact = nn.Linear(64, 1)

    def fit_normalisation(self, markers: Tensor, height: Tensor | None = None) -> None:
        """Set the marker statistics from training markers (B, N, 3) and their object heights (B, 1): the mean, the
        least-squares slope on t_O (with `height_slope`) and one residual std per axis."""
        mean = markers.mean(0)
        if height is not None and self.cfg.height_slope:
            h = height.reshape(-1, 1, 1).to(markers.dtype)
            hc = h - h.mean()
            self.height_mean.copy_(h.mean().reshape(1))
            self.marker_slope.copy_((hc * (markers - mean)).sum(0) / hc.pow(2).sum().clamp_min(1e-8))
        self.marker_mean.copy_(mean)
        self.marker_std.copy_((markers - mean - self._offset(height)).std(dim=(0, 1)).clamp_min(1e-3))

    def _offset(self, height: Tensor | None) -> Tensor:
        """(B, N, 3) height-dependent part of the marker mean, slope (t_O - mean t_O); 0 without height_slope."""
        if height is None or not self.cfg.height_slope:
            return torch.zeros_like(self.marker_mean)
        return self.marker_slope * (height.reshape(-1, 1, 1) - self.height_mean)

    # ------------------------------------------------------------------ pieces
    @staticmethod
    def _check(name: str, x: Tensor, shape: tuple[int | None, ...]) -> None:
        """ValueError naming `name` unless x matches shape (None = any size)."""
        if not isinstance(x, Tensor):                   # a numpy array's shape may be right: say what is wrong
            raise ValueError(f"{name}: expected a torch.Tensor of shape {shape} (None = any), got "
                             f"{type(x).__name__} (torch.as_tensor(x, dtype=torch.float32) makes one)")
        if x.dim() != len(shape) or any(s is not None and s != d for s, d in zip(shape, x.shape)):
            raise ValueError(f"{name}: expected shape {shape} (None = any), got {tuple(x.shape)}")

    def group(self, points: Tensor) -> list[Grouping | None]:
        """PointNet++ neighbourhoods of object points (B, P, 3), shared by the encoder and decoder branches."""
        return self.obj_dec.group(points)

    @torch.no_grad()
    def precompute(self, points: Tensor, markers: Tensor | None = None, normals: Tensor | None = None
                   ) -> dict[str, Tensor]:
        """Everything of a batch that depends on geometry only, as tensors for a dataset to store once: the
        PointNet++ groupings and interpolation weights (invariant to rigid motions of the cloud) and, with the
        ground-truth markers, Eq. 3's d(m, O) (B,N) and d(o, M) (B,P) (`consistency="signed"` needs the normals)."""
        grp = self.group(points)
        out = groupings_to_tensors(grp)
        xyz = [points]
        for g in grp[:-1]:
            xyz.append(gather(xyz[-1], g.centres))
        out["fp1_idx"], out["fp1_w"] = interpolation_weights(xyz[0], xyz[1])
        out["fp2_idx"], out["fp2_w"] = interpolation_weights(xyz[1], xyz[2])
        if markers is not None:
            signed = self.cfg.consistency == "signed"
            if signed and normals is None:
                raise ValueError("normals: consistency='signed' needs the object normals with the markers")
            out["dist_markers"], out["dist_points"] = consistency_distances(markers, points,
                                                                            normals if signed else None)
        return out

    def encode(self, markers: Tensor, marker_contact: Tensor | None, points: Tensor, normals: Tensor,
               object_contact: Tensor | None, height: Tensor, groupings: list[Grouping | None] | None = None
               ) -> tuple[Tensor, Tensor]:
        """q(z | M, C_M, C_O, t_O, O): markers (B,N,3), contacts (B,N), (B,P), points/normals (B,P,3), height (B,1)
        -> mean, log-variance (B, latent)."""
        B = markers.shape[0]
        body = ((markers - self._offset(height) - self.marker_mean) / self.marker_std).reshape(B, -1)
        feat = normals
        if self.cfg.multitask:
            body = torch.cat([body, marker_contact], -1)
            feat = torch.cat([normals, object_contact.unsqueeze(-1)], -1)
        f_o = self.obj_enc_proj(self.obj_enc(points, feat, groupings).global_feature)
        return self.head(self.fuse(torch.cat([self.body_enc(body), f_o, height], -1)))

    def decode(self, z: Tensor, points: Tensor, normals: Tensor, height: Tensor,
               groupings: list[Grouping | None] | None = None, pre: dict[str, Tensor] | None = None
               ) -> dict[str, Tensor]:
        """p(M, C_M, C_O | z, t_O, O): z (B, latent) -> {'markers' (B,N,3), 'marker_contact' (B,N),
        'object_contact' (B,P)} (contacts as probabilities; absent for WholeGrasp-single)."""
        B = z.shape[0]
        lv = self.obj_dec(points, normals, groupings)
        f_o = self.obj_dec_proj(lv.global_feature)
        h = self.dec(torch.cat([z, f_o, height], -1))
        out = {"markers": self.out_markers(h).view(B, self.cfg.n_markers, 3) * self.marker_std + self.marker_mean
                          + self._offset(height)}
        if self.cfg.multitask:
            out["marker_contact"] = torch.sigmoid(self.out_marker_contact(h))
            g = self.global_proj(torch.cat([f_o, h], -1)).unsqueeze(1)          # (B, 1, 128)
            f = self.fp3(lv.xyz[2], lv.xyz[3], lv.features[2], torch.relu(g))
            w2 = (pre["fp2_idx"], pre["fp2_w"]) if pre and "fp2_idx" in pre else None
            w1 = (pre["fp1_idx"], pre["fp1_w"]) if pre and "fp1_idx" in pre else None
            f = self.fp2(lv.xyz[1], lv.xyz[2], lv.features[1], f, w2)
            f = self.fp1(lv.xyz[0], lv.xyz[1], torch.cat([lv.xyz[0], lv.features[0]], -1), f, w1)
            out["object_contact"] = torch.sigmoid(self.out_object_contact(f).squeeze(-1))
        return out

    def forward(self, batch: dict[str, Tensor], generator: torch.Generator | None = None) -> dict[str, Tensor]:
        """Reconstruction of a batch: decoder outputs plus 'mu', 'logvar'.

        Keys: markers (B,N,3), marker_contact (B,N), points, normals (B,P,3), object_contact (B,P), height (B,1),
        optionally what `precompute` gives (PointNet++ groupings and interpolation weights, Eq. 3's ground-truth
        distances), which a dataset computes once.
        """
        self.check_batch(batch)
        groupings = groupings_from_tensors(batch, len(self.obj_dec.sa)) or self.group(batch["points"])
        mu, logvar = self.encode(batch["markers"], batch.get("marker_contact"), batch["points"], batch["normals"],
                                 batch.get("object_contact"), batch["height"], groupings)
        z = reparameterize(mu, logvar, generator) if self.training else mu
        out = self.decode(z, batch["points"], batch["normals"], batch["height"], groupings, batch)
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
            for k in ("marker_contact", "object_contact"):
                check_labels(batch[k], k)

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
            truth = (batch["dist_markers"], batch["dist_points"]) if "dist_markers" in batch else None
            logs["consistency"] = consistency_loss(out["markers"], batch["markers"], out["marker_contact"],
                                                   batch["points"], out["object_contact"], truth,
                                                   batch["normals"] if cfg.consistency == "signed" else None)
            rec = rec + cfg.lambda_m * logs["bce_markers"] + cfg.lambda_o * logs["bce_object"]
        logs["kl"] = kl_standard_normal(out["mu"], out["logvar"])
        kl_w = annealed_kl_weight(cfg.kl_final, epoch, epochs)
        loss = rec + kl_w * robust_kl(out["mu"], out["logvar"])
        if cfg.multitask:
            loss = loss + cfg.lambda_c * logs["consistency"]
        logs["marker_error_cm"] = (out["markers"] - batch["markers"]).norm(dim=-1).mean().detach() * 100
        return {"loss": loss, **logs}

    # ------------------------------------------------------------------ inference
    @torch.no_grad()
    def sample(self, object_points: Tensor, object_normals: Tensor, object_height: float | Tensor | None = None,
               n: int = 1, generator: torch.Generator | None = None, centre: Tensor | None = None,
               progress: bool = False) -> Grasps:
        """n grasps for one object: points/normals (P,3) in the world (z up, floor z=0) -> Grasps in the object frame.

        The object frame is the world translated to the object centre (default: the centre of the points'
        bounding box, SAGA A.3); `object_height` defaults to the centre's height. z ~ N(0, I) from `generator`.
        `progress`: a bar over chunks of SAMPLE_CHUNK samples (n = 1,000 takes about 40 s on two cores).
        """
        check_sample_inputs(object_points, object_normals, n, self.obj_dec.sa[0].npoint,
                            object_height=object_height, centre=centre)
        check_generator(generator)
        n = int(n)
        was = self.training
        self.eval()
        dev = self.out_markers.weight.device
        pts = object_points.to(dev, torch.float32)
        if centre is None:
            centre = 0.5 * (pts.min(0).values + pts.max(0).values)
        centre = torch.as_tensor(centre, dtype=torch.float32, device=dev)
        h = centre[2] if object_height is None else torch.as_tensor(object_height, dtype=torch.float32, device=dev)
        z = torch.randn(n, self.cfg.latent, generator=generator, device=dev)
        p, nrm = pts - centre, object_normals.to(dev, torch.float32)
        out = _in_chunks(lambda zc: self.decode(zc, p.expand(len(zc), -1, -1), nrm.expand(len(zc), -1, -1),
                                                h.reshape(1, 1).expand(len(zc), 1)), z, progress)
        self.train(was)
        return Grasps(out["markers"], out.get("marker_contact"), out.get("object_contact"), centre)

    # ------------------------------------------------------------------ files
    def state(self) -> dict[str, Any]:
        """Weights and config as plain values (a weights-only checkpoint)."""
        return {"model": self.state_dict(), "model_config": asdict(self.cfg)}

    @classmethod
    def from_state(cls, state: dict[str, Any]) -> "WholeGraspVAE":
        """Rebuild from `state()` or a training checkpoint written by graspkit.train.fit (config under extra)."""
        cfg = state.get("model_config") or state.get("extra", {}).get("model_config") or state.get("config")
        if isinstance(cfg, dict) and "latent" not in cfg and "model_config" in state.get("extra", {}):
            cfg = state["extra"]["model_config"]
        if cfg is None or "latent" not in cfg:
            raise ValueError("state: no WholeGrasp config in it (expected key 'config' or extra['model_config'])")
        unknown = sorted(set(cfg) - {f.name for f in fields(WholeGraspConfig)})
        if unknown:
            raise ValueError(f"state: config entries {unknown} are not WholeGraspConfig's (another model's config?)")
        # older checkpoints: object-centred markers, Eq. 3 as printed
        model = cls(WholeGraspConfig(**{"height_slope": False, "consistency": "paper", **cfg}))
        weights = dequantize_state(state["model"])
        for k, v in (("marker_slope", model.marker_slope), ("height_mean", model.height_mean)):
            weights.setdefault(k, v)                                       # absent from older checkpoints
        model.load_state_dict(weights)
        model.eval()
        return model


INT8_SCALE = "::int8_scale"     # key suffix of the per-row scales of a matrix stored as int8


def quantize_state(weights: dict[str, Tensor], min_numel: int = 4096) -> dict[str, Tensor]:
    """Compact weights for shipping: matrices with at least `min_numel` entries as int8 with one float16 scale per
    output row (symmetric, round to nearest: |error| <= scale / 2 = max|row| / 254), other floats as float16."""
    out: dict[str, Tensor] = {}
    for k, v in weights.items():
        if v.is_floating_point() and v.dim() >= 2 and v.numel() >= min_numel:
            rows = v.float().reshape(v.shape[0], -1)
            scale = (rows.abs().amax(1, keepdim=True) / 127).clamp_min(1e-12).half()
            out[k] = torch.round(rows / scale.float()).clamp(-127, 127).to(torch.int8).reshape(v.shape)
            out[k + INT8_SCALE] = scale
        else:
            out[k] = v.half() if v.is_floating_point() else v
    return out


def dequantize_state(weights: dict[str, Tensor]) -> dict[str, Tensor]:
    """Float32 weights from `quantize_state`'s output (or from plain float16/float32 weights)."""
    out = {}
    for k, v in weights.items():
        if k.endswith(INT8_SCALE):
            continue
        s = weights.get(k + INT8_SCALE)
        if s is not None:
            out[k] = (v.float().reshape(v.shape[0], -1) * s.float()).reshape(v.shape)
        else:
            out[k] = v.float() if v.is_floating_point() else v
    return out


# ------------------------------------------------------------------------------------------------ data and training
WHOLEGRASP_PATH = DATA_STUBS / "checkpoints" / "wholegrasp.pt"
WHOLEGRASP_SINGLE_PATH = DATA_STUBS / "checkpoints" / "wholegrasp_single.pt"


class WholeGraspTrainingSet(torch.utils.data.Dataset):
    """graspkit's synthetic grasps (graspkit.data.grasp_datasets.WholeGraspDataset items) in the model's keys, with
    `WholeGraspVAE.precompute` done once; `augment_yaw` turns each item by a random angle about the vertical axis
    through the object centre (draws from torch's global RNG, which graspkit.train.fit seeds and checkpoints)."""

    def __init__(self, items: dict[str, Tensor], model: WholeGraspVAE, augment_yaw: bool = False,
                 chunk: int = 64) -> None:
        self.data = {"markers": items["markers"].float(), "marker_contact": items["marker_contacts"].float(),
                     "points": items["object_points"].float(), "normals": items["object_normals"].float(),
                     "object_contact": items["object_contacts"].float(),
                     "height": items["object_height"].float().reshape(-1, 1)}
        pre = [model.precompute(self.data["points"][i:i + chunk], self.data["markers"][i:i + chunk],
                                self.data["normals"][i:i + chunk])
               for i in range(0, len(self), chunk)]
        self.data.update({k: torch.cat([p[k] for p in pre]) for k in pre[0]})
        self.augment_yaw = augment_yaw

    @classmethod
    def from_folder(cls, root: str | Path, split: str, model: WholeGraspVAE, augment_yaw: bool = False
                    ) -> "WholeGraspTrainingSet":
        """Read `<root>/grasp_*.npz` of one split through graspkit.data.grasp_datasets.WholeGraspDataset."""
        from graspkit.data.grasp_datasets import WholeGraspDataset

        ds = WholeGraspDataset(root, split=split)
        return cls(ds.data, model, augment_yaw)

    def __len__(self) -> int:
        return len(self.data["markers"])

    def __getitem__(self, i: int) -> dict[str, Tensor]:
        item = {k: v[i] for k, v in self.data.items()}
        if self.augment_yaw:
            a = float(torch.rand(()) * 2 * math.pi)
            c, s = math.cos(a), math.sin(a)
            R = torch.tensor([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
            for k in ("markers", "points", "normals"):
                item[k] = item[k] @ R.T
        return item


def yaw_spread(markers: Tensor, turns: int = 8) -> Tensor:
    """Markers (B,N,3) turned by `turns` even yaw angles about z (the statistics of a yaw-augmented set)."""
    out = []
    for k in range(turns):
        a = 2 * math.pi * k / turns
        R = torch.tensor([[math.cos(a), -math.sin(a), 0.0], [math.sin(a), math.cos(a), 0.0], [0.0, 0.0, 1.0]],
                         dtype=markers.dtype, device=markers.device)
        out.append(markers @ R.T)
    return torch.cat(out)


def contact_auc(scores: Tensor, labels: Tensor) -> float:
    """Area under the ROC curve of contact probabilities against binary labels (Mann-Whitney, ties averaged)."""
    s, y = scores.reshape(-1).double(), labels.reshape(-1) > 0.5
    n1, n0 = int(y.sum()), int((~y).sum())
    if n1 == 0 or n0 == 0:
        return float("nan")
    order = torch.argsort(s)
    ranks = torch.empty_like(s)
    ranks[order] = torch.arange(1, len(s) + 1, dtype=s.dtype)
    uniq, inv, counts = torch.unique(s, return_inverse=True, return_counts=True)
    mean_rank = torch.zeros(len(uniq), dtype=s.dtype).index_add_(0, inv, ranks) / counts
    r = mean_rank[inv]
    return float((r[y].sum() - n1 * (n1 + 1) / 2) / (n1 * n0))


@torch.no_grad()
@in_eval_mode
def reconstruction_metrics(model: WholeGraspVAE, data: WholeGraspTrainingSet, batch_size: int = 32
                           ) -> dict[str, float]:
    """Validation figures of the posterior mean: marker error (cm, mean per marker), contact AUCs of C_M and C_O."""
    err, cm, cm_t, co, co_t = [], [], [], [], []
    for i in range(0, len(data), batch_size):
        b = {k: v[i:i + batch_size] for k, v in data.data.items()}
        out = model(b)
        err.append((out["markers"] - b["markers"]).norm(dim=-1).mean(1))
        if model.cfg.multitask:
            cm.append(out["marker_contact"]), cm_t.append(b["marker_contact"])
            co.append(out["object_contact"]), co_t.append(b["object_contact"])
    res = {"marker_error_cm": float(torch.cat(err).mean()) * 100}
    if cm:
        res["auc_marker_contact"] = contact_auc(torch.cat(cm), torch.cat(cm_t))
        res["auc_object_contact"] = contact_auc(torch.cat(co), torch.cat(co_t))
    return res


@keeps_torch_state
def train_wholegrasp(root: str | Path, out: str | Path | None = None, multitask: bool = True, epochs: int = 12,
                     batch_size: int = 32, lr: float = 1e-3, seed: int = 0, time_limit_s: float | None = 600.0,
                     threads: int | None = 1, progress: bool = True, half: bool = True,
                     augment_yaw: bool = False, consistency: str = "paper") -> dict[str, Any]:
    """Train WholeGrasp-VAE (or WholeGrasp-single) on `<root>/grasp_*.npz` (train split; the val split logged)
    with graspkit.train.fit; write weights-only `out` (compact when `half`: `quantize_state`); the resumable run is
    graspkit.train.run_path's file (named by every setting and the data).
    Returns {'history', 'seconds', 'val': reconstruction_metrics on the val split, 'out'}.

    As in SAGA (GRAB), the data keep the world orientation: people come to the object from the side they start
    on, so grasps are not spread evenly around it; `augment_yaw` would spread them (not SAGA's setting)."""
    import time

    from graspkit.train import TrainConfig, fit, run_path, save_checkpoint

    if threads:
        torch.set_num_threads(threads)
    out = Path(out or (WHOLEGRASP_PATH if multitask else WHOLEGRASP_SINGLE_PATH))
    torch.manual_seed(seed)
    model = WholeGraspVAE(WholeGraspConfig(multitask=multitask, consistency=consistency))
    t0 = time.perf_counter()
    train = WholeGraspTrainingSet.from_folder(root, "train", model, augment_yaw=augment_yaw)
    val = WholeGraspTrainingSet.from_folder(root, "val", model)
    h = train.data["height"]
    model.fit_normalisation(yaw_spread(train.data["markers"]) if train.augment_yaw else train.data["markers"],
                            h.repeat(8, 1) if train.augment_yaw else h)     # yaw_spread stacks 8 turns of the set
    prep = time.perf_counter() - t0

    def step(m: nn.Module, batch: dict[str, Tensor], epoch: int) -> dict[str, Tensor]:
        """One batch of Eq. 1-3."""
        return m.loss(batch, m(batch), epoch, epochs)

    cfg = TrainConfig(epochs=epochs, batch_size=batch_size, lr=lr, seed=seed)
    run = run_path("wholegrasp" if multitask else "wholegrasp_single", seed, epochs=epochs, batch_size=batch_size,
                   lr=lr, config=asdict(model.cfg), augment_yaw=augment_yaw, data=_data_key(root))
    hist = fit(model, step, train, cfg, checkpoint=run, extra={"model_config": asdict(model.cfg)},
               val_dataset=val, progress=progress, time_limit_s=None if time_limit_s is None
               else max(time_limit_s - prep, 1e-9), ddp=False)   # the step calls m.loss; one epoch at least
    seconds = time.perf_counter() - t0
    metrics = reconstruction_metrics(model, val)
    state = model.state()
    if half:   # float16, the large matrices int8 with per-row scales (`quantize_state`): ~1.4 MB instead of 5.4
        state["model"] = quantize_state(state["model"])
    state.update(history=hist, val=metrics, seconds=seconds, train_items=len(train))
    if not multitask:   # S.3's hand contact prior C_H (per body vertex) for the heuristic optimisation
        from graspkit.eval_saga import hand_contact_prior
        state["hand_contact_prior"] = hand_contact_prior(root).half()
    save_checkpoint(out, state)
    return {"history": hist, "seconds": seconds, "val": metrics, "out": out}


def _data_key(root: str | Path) -> dict[str, Any]:
    """What a training run's data are, for its run_path: the folder and its grasp files' content (`files_key`)."""
    from graspkit.train import files_key

    return {"root": str(Path(root).resolve()), "files": files_key(root, "grasp_*.npz")}


@keeps_torch_state
def load_wholegrasp(path: str | Path | None = None, multitask: bool = True) -> WholeGraspVAE:
    """A trained WholeGrasp-VAE (default: the shipped checkpoint; multitask=False: WholeGrasp-single), eval mode."""
    from graspkit.train import load_checkpoint

    path = path or (WHOLEGRASP_PATH if multitask else WHOLEGRASP_SINGLE_PATH)
    state = load_checkpoint(path)
    if not isinstance(state, dict) or "model" not in state or "kind" in state:
        what = f"a {state['kind']!r} checkpoint" if isinstance(state, dict) and "kind" in state else "no weights"
        raise ValueError(f"{path}: not a WholeGrasp-VAE checkpoint ({what}; expected what train_wholegrasp writes)")
    try:
        return WholeGraspVAE.from_state(state)
    except (ValueError, RuntimeError, TypeError, KeyError, AttributeError) as e:  # another model's config or weights
        raise ValueError(f"{path}: not a WholeGrasp-VAE checkpoint ({type(e).__name__}: {e})") from None


# ------------------------------------------------------------------------------------------------ GrabNet-SMPLX
GRABNET_SMPLX_PATH = DATA_STUBS / "checkpoints" / "wholegrasp_grabnet_smplx.pt"
N_PCA = 24


class HandPCA:
    """SAGA's hand pose space: 24 PCA coefficients per hand about the model's mean hand (absolute axis-angle)."""

    def __init__(self, bm: BodyModel, n: int = N_PCA) -> None:
        if bm.use_pca or bm.flat_hand_mean:
            raise ValueError("bm: build the BodyModel with the defaults (use_pca=False, flat_hand_mean=False)")
        self.comps = {s: getattr(bm, f"{s}_hand_components")[:n].float() for s in ("left", "right")}
        self.mean = {"left": bm.pose_mean[75:120].float(), "right": bm.pose_mean[120:165].float()}

    def encode(self, hand_pose: Tensor, side: str) -> Tensor:
        """Absolute hand poses (B, 45) -> coefficients (B, n) (projection onto the components)."""
        return (hand_pose.float() - self.mean[side]) @ self.comps[side].T

    def decode(self, coeffs: Tensor, side: str) -> Tensor:
        """Coefficients (B, n) -> absolute hand poses (B, 45)."""
        return coeffs @ self.comps[side] + self.mean[side]


SAMPLE_CHUNK = 128        # samples decoded at a time: ~3 MB each (the object decoded per sample), 1,000 passed 4 GB


def _in_chunks(decode: Callable[[Tensor], Any], z: Tensor, progress: bool = False) -> Any:
    """decode(z) of latents z (n, latent) SAMPLE_CHUNK rows at a time, joined (a tensor, or a dict of tensors); at most
    one chunk (the usual n) is one call, bit for bit; `progress`: a bar over the chunks when there are several."""
    from tqdm.auto import tqdm

    from graspkit.progress import hidden

    starts = range(0, max(len(z), 1), SAMPLE_CHUNK)
    parts = [decode(z[s:s + SAMPLE_CHUNK]) for s in tqdm(starts, desc="decoding samples", unit="chunk",
                                                         disable=hidden(progress) or len(starts) == 1)]
    if len(parts) == 1:
        return parts[0]
    if isinstance(parts[0], dict):
        return {k: torch.cat([q[k] for q in parts]) for k in parts[0]}
    return torch.cat(parts)


def check_height(h: float | Tensor, name: str) -> None:
    """A ValueError naming `name` unless the object height(s) t_O are in [0, MAX_METRES] m (the data's 0.5-1.7 m:
    GRASP_HEIGHTS); a height in millimetres would give markers metres away without a word."""
    t = torch.as_tensor(h, dtype=torch.float64)
    if t.numel() and not ((t >= 0) & (t <= MAX_METRES)).all():
        bad = float(t[~((t >= 0) & (t <= MAX_METRES))].reshape(-1)[0])          # NaN too
        raise ValueError(f"{name}: {bad:g}, expected an object-centre height in metres above the floor, 0 to "
                         f"{MAX_METRES:g} (the training data's {GRASP_HEIGHTS[0]}-{GRASP_HEIGHTS[1]} m)")


def check_sample_inputs(points: Tensor, normals: Tensor, n: int, least: int, names: tuple[str, str] =
                        ("object_points", "object_normals"), **extra: Any) -> None:
    """ValueError/TypeError naming the argument unless points, normals are (P>=least, 3) finite tensors, n a
    positive int and each `extra` value (a float, a tensor or None) finite."""
    WholeGraspVAE._check(names[0], points, (None, 3))
    WholeGraspVAE._check(names[1], normals, tuple(points.shape))
    if len(points) < least:
        raise ValueError(f"{names[0]}: expected at least {least} points (PointNet++'s first level samples "
                         f"{least} centres), got {len(points)}")
    for name, x in extra.items():                  # one object: a height is one number, a centre one point
        want = (3,) if name == "centre" else ()
        try:
            shape = None if x is None else tuple(torch.as_tensor(x, dtype=torch.float32).reshape(-1).shape)
        except (TypeError, ValueError, RuntimeError):
            raise ValueError(f"{name}: expected {'a point (3,)' if want else 'a number'} in metres, got "
                             f"{type(x).__name__}") from None
        if shape is not None and shape != (want[0] if want else 1,):
            raise ValueError(f"{name}: expected {'a point (3,)' if want else 'one number'} in metres for the one "
                             f"object, got {shape[0]} values")
    for name, x in ((names[0], points), (names[1], normals), *extra.items()):
        if x is not None and not torch.isfinite(torch.as_tensor(x, dtype=torch.float32)).all():
            raise ValueError(f"{name}: contains NaN or Inf")
    require_points_in_metres(points, names[0])
    require_unit_normals(normals, names[1])
    for name, x in extra.items():
        if name.endswith("height") and x is not None:
            check_height(x, name)
    if isinstance(n, bool) or not isinstance(n, numbers.Integral):     # numpy integers too, as the other samplers
        raise TypeError(f"n: expected an int number of samples, got {n!r}")
    if n < 1:
        raise ValueError(f"n: expected at least one sample, got {n}")


def params_to_rotmats(x: Tensor, pca: HandPCA, prior: PosePrior | None = None) -> tuple[Tensor, Tensor, Tensor]:
    """GrabNet-SMPLX's parameter vector -> rotation matrices (B, 55, 3, 3), betas (B, 10), transl (B, 3) (jaw and
    eyes at rest). x (B, 99) = [transl 3, root 6D, betas 10, body latent 32, left 24, right 24] with `prior` (the
    pose prior whose latent the body pose is in), or (B, 193) with the 21 body joints as 6D rotations (prior None)."""
    from graspkit.rotations import axis_angle_to_matrix, rot6d_to_matrix

    B, nb = x.shape[0], x.shape[1] - 67
    if (prior is None) != (nb == 126) or (prior is not None and nb != prior.cfg.latent):
        want = 193 if prior is None else 67 + prior.cfg.latent
        raise ValueError(f"x: expected (B, {want}) parameter vectors, got {tuple(x.shape)}")
    transl, root, betas, body = x[:, :3], x[:, 3:9], x[:, 9:19], x[:, 19:19 + nb]
    body_rot = rot6d_to_matrix(body.view(B, 21, 6)) if prior is None else prior.decode_rotmats(body)
    hands = [axis_angle_to_matrix(pca.decode(x[:, 19 + nb + 24 * k:43 + nb + 24 * k], s).view(B, 15, 3))
             for k, s in enumerate(("left", "right"))]
    rot = torch.cat([rot6d_to_matrix(root).unsqueeze(1), body_rot,
                     torch.eye(3).expand(B, 3, 3, 3), hands[0], hands[1]], 1)
    return rot, betas, transl


class GrabNetSMPLX(nn.Module):
    """SAGA's GrabNet-SMPLX baseline (§4.1, App. B.1, Fig. S3a): a CVAE that generates SMPL-X parameters directly
    for an object encoded by the same PointNet++, in the object frame: t, R (6D), beta, the body pose theta_b and
    24 + 24 hand PCA coefficients. `body_space="prior"` (default) is SAGA's Theta (§3, Preliminaries): theta_b in the
    32-D latent space of a pose prior (VPoser there; graspkit's PosePrior, held frozen inside the model), 99 numbers;
    "rot6d" generates the 21 joints as 6D rotations (193 numbers). The eyes stay at rest (SAGA's theta_e is not
    generated).

    Loss (GrabNet-style): L1 of the markers the parameters pose (143, summed, as WholeGrasp's) + L1 of the
    parameters (mean) + lambda_KL Psi(KL), lambda_KL rising linearly to 0.2 and Psi SAGA's robust KL (Eq. 2), both as
    WholeGrasp's, so that the two CVAEs differ in what they generate, not in how their latent is regularised."""

    # buffers, registered in __init__ (declared for type checkers)
    param_mean: Tensor
    param_std: Tensor

    def __init__(self, hidden: int = 256, latent: int = 16, nsample: int = 8, object_feature: int = 128,
                 kl_final: float = 0.2, body_space: str = "prior", prior: Any = None,
                 prior_config: dict[str, Any] | None = None) -> None:
        super().__init__()
        from graspkit.models.pose_prior import PosePrior, PosePriorConfig, load_pose_prior

        if body_space not in ("prior", "rot6d"):
            raise ValueError(f"body_space: expected 'prior' or 'rot6d', got {body_space!r}")
        self.prior: PosePrior | None = None
        if body_space == "prior":          # frozen: its weights travel in this model's state dict
            # load_pose_prior's undecorated body: building the prior draws from the global generator, as it did
            # when the documented GrabNet-SMPLX runs were made, so the layers after it get the same initial weights
            self.prior = prior if prior is not None else (
                PosePrior(PosePriorConfig(**prior_config)) if prior_config else load_pose_prior.__wrapped__())
            self.prior.eval().requires_grad_(False)
        self.hparams = dict(hidden=hidden, latent=latent, nsample=nsample, object_feature=object_feature,
                            kl_final=kl_final, body_space=body_space,
                            prior_config=None if self.prior is None else asdict(self.prior.cfg))
        self.n_params = 67 + (126 if self.prior is None else self.prior.cfg.latent)
        act = nn.LeakyReLU(0.2)
        self.obj_enc = PointNet2Encoder(3, nsample=nsample, norm=False)
        self.obj_dec = PointNet2Encoder(3, nsample=nsample, norm=False)
        c = self.obj_enc.out_channels
        self.enc_proj, self.dec_proj = nn.Linear(c, object_feature), nn.Linear(c, object_feature)
        self.enc = nn.Sequential(nn.Linear(self.n_params + object_feature + 1, hidden), act,
                                 ResBlock(hidden, hidden, n_hidden=hidden // 2))
        self.head = GaussianHead(hidden, latent)
        self.dec = nn.Sequential(nn.Linear(latent + object_feature + 1, hidden), act,
                                 ResBlock(hidden, hidden, n_hidden=hidden // 2), nn.Linear(hidden, self.n_params))
        self.register_buffer("param_mean", torch.zeros(self.n_params))     # standardised parameters in and out
        self.register_buffer("param_std", torch.ones(self.n_params))
        nn.init.zeros_(self.dec[-1].weight)                                 # training starts from the mean grasp
        nn.init.zeros_(self.dec[-1].bias)

    def to_rotmats(self, x: Tensor, pca: HandPCA) -> tuple[Tensor, Tensor, Tensor]:
        """Parameter vectors (B, n_params) -> rotation matrices (B,55,3,3), betas (B,10), transl (B,3)."""
        return params_to_rotmats(x, pca, self.prior)

    def params_of(self, fullpose: Tensor, transl: Tensor, betas: Tensor, object_transl: Tensor,
                  pca: HandPCA) -> Tensor:
        """This model's parameter vectors (B, n_params) of grasps (see grasp_params)."""
        return grasp_params(fullpose, transl, betas, object_transl, pca, self.prior)

    def fit_normalisation(self, params: Tensor) -> None:
        """Set the parameter statistics from training parameter vectors (B, n_params)."""
        self.param_mean.copy_(params.mean(0))
        self.param_std.copy_(params.std(0).clamp_min(1e-2))

    def decode(self, z: Tensor, points: Tensor, normals: Tensor, height: Tensor,
               groupings: list[Grouping | None] | None = None) -> Tensor:
        """z (B, latent) -> parameter vector (B, n_params)."""
        f = self.dec_proj(self.obj_dec(points, normals, groupings).global_feature)
        return self.dec(torch.cat([z, f, height], -1)) * self.param_std + self.param_mean

    def forward(self, batch: dict[str, Tensor], generator: torch.Generator | None = None) -> dict[str, Tensor]:
        """Reconstruction: {'params' (B,n_params), 'mu', 'logvar'} for a batch with params, points, normals,
        height."""
        g = groupings_from_tensors(batch, len(self.obj_dec.sa)) or self.obj_dec.group(batch["points"])
        f = self.enc_proj(self.obj_enc(batch["points"], batch["normals"], g).global_feature)
        x = (batch["params"] - self.param_mean) / self.param_std
        mu, logvar = self.head(self.enc(torch.cat([x, f, batch["height"]], -1)))
        z = reparameterize(mu, logvar, generator) if self.training else mu
        return {"params": self.decode(z, batch["points"], batch["normals"], batch["height"], g), "mu": mu,
                "logvar": logvar}

    def loss(self, batch: dict[str, Tensor], out: dict[str, Tensor], body: SparseBody, pca: HandPCA, epoch: int,
             epochs: int) -> dict[str, Tensor]:
        """Marker L1 through `body` (SparseBody at the 143 markers) + parameter L1 + annealed KL."""
        rot, betas, transl = self.to_rotmats(out["params"], pca)
        markers = body(rot, betas, transl)[0]
        logs = {"rec_markers": (markers - batch["markers"]).abs().sum((1, 2)).mean(),
                "rec_params": ((out["params"] - batch["params"]) / self.param_std).abs().mean(),
                "kl": kl_standard_normal(out["mu"], out["logvar"])}
        kl_w = annealed_kl_weight(self.hparams["kl_final"], epoch, epochs)
        loss = logs["rec_markers"] + logs["rec_params"] + kl_w * robust_kl(out["mu"], out["logvar"])
        logs["marker_error_cm"] = (markers - batch["markers"]).norm(dim=-1).mean().detach() * 100
        return {"loss": loss, **logs}

    @torch.no_grad()
    def sample(self, points: Tensor, normals: Tensor, height: float, n: int,
               generator: torch.Generator | None = None) -> Tensor:
        """n parameter vectors (n, n_params) for one object (points, normals (P,3) in the object frame)."""
        check_sample_inputs(points, normals, n, self.obj_dec.sa[0].npoint, ("points", "normals"), height=height)
        n = int(n)
        was = self.training
        self.eval()
        z = torch.randn(n, self.hparams["latent"], generator=generator)
        out = _in_chunks(lambda zc: self.decode(zc, points.float().expand(len(zc), -1, -1),
                                                normals.float().expand(len(zc), -1, -1),
                                                torch.full((len(zc), 1), float(height))), z)
        self.train(was)
        return out

    def state(self) -> dict[str, Any]:
        """Weights and hyper-parameters (weights-only checkpoint)."""
        return {"model": self.state_dict(), "model_config": dict(self.hparams)}

    @classmethod
    def from_state(cls, state: dict[str, Any]) -> "GrabNetSMPLX":
        """Rebuild from `state()` (or a fit checkpoint whose extra holds model_config)."""
        cfg = state.get("model_config") or state.get("extra", {}).get("model_config")
        if not isinstance(cfg, dict):
            raise ValueError("state: no GrabNet-SMPLX config in it (expected key 'model_config' or "
                             "extra['model_config'])")
        cfg = dict(cfg)
        cfg.setdefault("body_space", "rot6d")     # checkpoints made before the pose-prior space
        model = cls(**cfg)
        model.load_state_dict({k: v.float() if v.is_floating_point() else v for k, v in state["model"].items()})
        return model.eval()


@keeps_torch_state
def load_grabnet_smplx(path: str | Path = GRABNET_SMPLX_PATH) -> GrabNetSMPLX:
    """A trained GrabNet-SMPLX baseline (`graspkit train grabnet_smplx`), eval mode; a ValueError naming the file
    when it holds another model."""
    from graspkit.train import build_named, load_checkpoint

    state = load_checkpoint(path)
    if "kind" in state:
        raise ValueError(f"{path}: not a GrabNet-SMPLX checkpoint (a {state['kind']!r} checkpoint)")
    return build_named(path, "a GrabNet-SMPLX checkpoint", lambda: GrabNetSMPLX.from_state(state))


def rest_root_joint(bm: BodyModel, betas: Tensor) -> Tensor:
    """The rest-pose pelvis joint (B,3) of bodies with shapes betas (B,10)."""
    with torch.no_grad():
        coeffs = torch.cat([betas.to(bm.dtype), torch.zeros(len(betas), bm.num_expression, dtype=bm.dtype)], -1)
        return (bm.J_template[0] + (coeffs @ bm.J_basis).view(-1, 55, 3)[:, 0]).float()


def grasp_params(fullpose: Tensor, transl: Tensor, betas: Tensor, object_transl: Tensor, pca: HandPCA,
                 prior: PosePrior | None = None) -> Tensor:
    """GrabNet-SMPLX parameter vectors of grasps: fullpose (B,55,3) absolute, world transl (B,3), betas (B,10), the
    object translation (B,3) (the object frame's origin); the body pose as `prior`'s posterior mean (B, 99) or,
    prior None, as 6D rotations (B, 193)."""
    from graspkit.rotations import axis_angle_to_rot6d

    B = fullpose.shape[0]
    if prior is None:
        body = axis_angle_to_rot6d(fullpose[:, 1:22]).reshape(B, 126)
    else:
        with torch.no_grad():
            body = prior.encode(fullpose[:, 1:22].reshape(B, 63))
    return torch.cat([transl - object_transl, axis_angle_to_rot6d(fullpose[:, 0]), betas, body,
                      pca.encode(fullpose[:, 25:40].reshape(B, 45), "left"),
                      pca.encode(fullpose[:, 40:55].reshape(B, 45), "right")], -1).float()


class GrabNetTrainingSet(torch.utils.data.Dataset):
    """Parameter vectors, markers and objects of graspkit's grasps (one split), PointNet++ groupings precomputed;
    `augment_yaw` turns each item about the vertical axis through the object centre (root and translation)."""

    def __init__(self, root: str | Path, split: str, bm: BodyModel, model: GrabNetSMPLX,
                 augment_yaw: bool = False) -> None:
        from graspkit.data.grab import check_made_on
        from graspkit.data.grasp_datasets import GNetDataset, WholeGraspDataset

        wg, gn = WholeGraspDataset(root, split=split), GNetDataset(root, split=split)
        check_made_on(bm, gn.files, f"root: {root}", "grasp")        # the parameters are posed on bm
        pca = HandPCA(bm)
        d = gn.data
        self.data = {"params": model.params_of(d["fullpose"], d["transl"], d["betas"], d["object_transl"], pca),
                     "markers": wg.data["markers"], "points": wg.data["object_points"],
                     "normals": wg.data["object_normals"], "height": wg.data["object_height"].reshape(-1, 1)}
        self.data["root_joint"] = rest_root_joint(bm, d["betas"])
        with torch.no_grad():
            pre = [model.obj_dec.group(self.data["points"][i:i + 64]) for i in range(0, len(self), 64)]
        t = [groupings_to_tensors(g) for g in pre]
        self.data.update({k: torch.cat([x[k] for x in t]) for k in t[0]})
        self.augment_yaw = augment_yaw

    def __len__(self) -> int:
        return len(self.data["params"])

    def __getitem__(self, i: int) -> dict[str, Tensor]:
        item = {k: v[i] for k, v in self.data.items()}
        if self.augment_yaw:
            a = float(torch.rand(()) * 2 * math.pi)
            c, s = math.cos(a), math.sin(a)
            Q = torch.tensor([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
            for k in ("markers", "points", "normals"):
                item[k] = item[k] @ Q.T
            item["params"] = turn_params(item["params"][None], item["root_joint"][None], Q)[0]
        return item


def _yaw(a: float) -> Tensor:
    """Rotation (3,3) by a radians about z."""
    return torch.tensor([[math.cos(a), -math.sin(a), 0.0], [math.sin(a), math.cos(a), 0.0], [0.0, 0.0, 1.0]])


def turn_params(params: Tensor, root_joint: Tensor, Q: Tensor) -> Tensor:
    """GrabNet-SMPLX parameters (B, n_params) of bodies turned by Q (3,3) about the origin: R -> Q R and
    t -> Q (J0 + t) - J0, J0 (B,3) the rest root joint (SMPL-X turns the body about it)."""
    from graspkit.rotations import matrix_to_rot6d, rot6d_to_matrix

    p = params.clone()
    p[:, :3] = (root_joint + p[:, :3]) @ Q.T - root_joint
    p[:, 3:9] = matrix_to_rot6d(Q @ rot6d_to_matrix(p[:, 3:9]))
    return p


@keeps_torch_state
def train_grabnet_smplx(root: str | Path, out: str | Path | None = None, epochs: int = 12, batch_size: int = 32,
                        lr: float = 1e-3, seed: int = 0, time_limit_s: float | None = 600.0, threads: int | None = 1,
                        progress: bool = True, half: bool = True, augment_yaw: bool = False,
                        body_space: str = "prior") -> dict[str, Any]:
    """Train the GrabNet-SMPLX baseline like `train_wholegrasp` (body_space: see GrabNetSMPLX; "prior" uses the
    shipped pose prior); returns {'history', 'seconds', 'out'}."""
    import time

    from graspkit.body import BodyModel
    from graspkit.models.gnet import SparseBody
    from graspkit.paths import default_model_path
    from graspkit.train import TrainConfig, fit, run_path, save_checkpoint
    from graspkit.body.markers import saga_markers

    if threads:
        torch.set_num_threads(threads)
    out = Path(out or GRABNET_SMPLX_PATH)
    torch.manual_seed(seed)
    bm = BodyModel.from_file(default_model_path())
    body, pca = SparseBody(bm, saga_markers(bm).vertex_ids), HandPCA(bm)
    model = GrabNetSMPLX(body_space=body_space)
    t0 = time.perf_counter()
    train = GrabNetTrainingSet(root, "train", bm, model, augment_yaw=augment_yaw)
    val = GrabNetTrainingSet(root, "val", bm, model)
    if augment_yaw:                               # statistics of the yaw-augmented training parameters
        g = torch.Generator().manual_seed(seed)
        model.fit_normalisation(torch.cat([turn_params(train.data["params"], train.data["root_joint"],
                                                       _yaw(float(torch.rand((), generator=g)) * 2 * math.pi))
                                           for _ in range(8)]))
    else:
        model.fit_normalisation(train.data["params"])

    def step(m: nn.Module, batch: dict[str, Tensor], epoch: int) -> dict[str, Tensor]:
        """One batch of the GrabNet-style loss."""
        return m.loss(batch, m(batch), body, pca, epoch, epochs)

    cfg = TrainConfig(epochs=epochs, batch_size=batch_size, lr=lr, seed=seed)
    run = run_path("grabnet_smplx", seed, epochs=epochs, batch_size=batch_size, lr=lr, config=dict(model.hparams),
                   augment_yaw=augment_yaw, data=_data_key(root), body=bm.digest())   # its loss poses this body
    hist = fit(model, step, train, cfg, checkpoint=run,
               extra={"model_config": dict(model.hparams)}, val_dataset=val, progress=progress,
               time_limit_s=None if time_limit_s is None else max(time_limit_s - (time.perf_counter() - t0), 1e-9),
               ddp=False)                                                          # the step calls m.loss
    state = model.state()
    if half:
        state["model"] = {k: v.half() if v.is_floating_point() else v for k, v in state["model"].items()}
    seconds = time.perf_counter() - t0
    state.update(history=hist, seconds=seconds)
    save_checkpoint(out, state)
    return {"history": hist, "seconds": seconds, "out": out}
