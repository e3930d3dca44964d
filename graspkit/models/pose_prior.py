"""A small learned body-pose prior in place of VPoser (SAGA §3 "Preliminaries": theta_b in R^32 is the body pose in
VPoser's latent space; GraspPose-Opt optimises that latent with the prior term alpha_theta |theta|^2 of Eq. 5).

VPoser (Pavlakos et al., CVPR 2019) is a VAE over SMPL-X body poses trained on AMASS; it is licensed and cannot be
shipped, and there is no AMASS here. graspkit trains the same kind of model on its own synthetic body poses:
a VAE over the 21 body-joint rotations (6D, Zhou et al.) with a 32-D latent, trained on frames of the procedural
locomotion and reaching clips (mirrored left/right) plus any extra poses given (e.g. the synthetic grasps). It is
smaller than VPoser and only knows the poses it saw; with z ~ N(0, I) it decodes plausible standing, walking,
reaching and bending poses, and |z|^2 is small for them.

    prior = load_pose_prior()                     # the shipped checkpoint (data_stubs/checkpoints/pose_prior.pt)
    body_pose = prior.decode(z)                   # (B, 32) -> (B, 63) axis-angle, SMPL-X body_pose
    z = prior.encode(body_pose)                   # (B, 63) -> (B, 32) posterior mean
"""
from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import torch
from torch import Tensor, nn

from graspkit.body.skeleton import JOINT_NAMES
from graspkit.checks import check_finite
from graspkit.models.blocks import GaussianHead, kl_standard_normal, reparameterize
from graspkit.paths import DATA_STUBS
from graspkit.rotations import axis_angle_to_matrix, matrix_to_axis_angle, matrix_to_rot6d, rot6d_to_matrix
from graspkit.state import keeps_torch_state

if TYPE_CHECKING:
    from graspkit.body import BodyModel

POSE_PRIOR_PATH = DATA_STUBS / "checkpoints" / "pose_prior.pt"
NUM_BODY_JOINTS = 21


@dataclass
class PosePriorConfig:
    """Sizes and loss weights of the pose prior."""

    latent: int = 32             # as VPoser (SAGA: theta_b in R^32)
    hidden: int = 256
    kl_weight: float = 5e-3      # beta of the beta-VAE objective (squared rotation-matrix errors + beta KL)


def _mlp(sizes: list[int]) -> nn.Sequential:
    """Linear + LayerNorm + LeakyReLU between layers (no activation after the last)."""
    layers: list[nn.Module] = []
    for i, (a, b) in enumerate(zip(sizes[:-1], sizes[1:])):
        layers.append(nn.Linear(a, b))
        if i < len(sizes) - 2:
            layers += [nn.LayerNorm(b), nn.LeakyReLU(0.2)]
    return nn.Sequential(*layers)


class PosePrior(nn.Module):
    """A VAE over SMPL-X body poses (21 joints): encode (B,63) axis-angle -> (B,32); decode (B,32) -> (B,63)."""

    def __init__(self, cfg: PosePriorConfig | None = None) -> None:
        super().__init__()
        self.cfg = cfg = cfg or PosePriorConfig()
        d = NUM_BODY_JOINTS * 6
        self.enc = _mlp([d, cfg.hidden, cfg.hidden])
        self.act = nn.LeakyReLU(0.2)
        self.head = GaussianHead(cfg.hidden, cfg.latent)
        self.dec = _mlp([cfg.latent, cfg.hidden, cfg.hidden, d])

    @staticmethod
    def _check_pose(body_pose: Tensor) -> Tensor:
        """(B, 63) or (B, 21, 3) -> (B, 21, 3); ValueError naming body_pose otherwise."""
        if not isinstance(body_pose, Tensor) or body_pose.dim() not in (2, 3) or body_pose.shape[1:] not in (
                (63,), (21, 3)):
            got = tuple(body_pose.shape) if isinstance(body_pose, Tensor) else type(body_pose).__name__
            raise ValueError(f"body_pose: expected shape (B, 63) or (B, 21, 3), got {got}")
        check_finite(body_pose, "body_pose", "axis-angle rotations in radians")
        return body_pose.reshape(-1, NUM_BODY_JOINTS, 3)

    def posterior(self, body_pose: Tensor) -> tuple[Tensor, Tensor]:
        """q(z | pose): (B, 63) axis-angle -> mean, log-variance (B, latent)."""
        pose = self._check_pose(body_pose).to(self.enc[0].weight.dtype)
        x = matrix_to_rot6d(axis_angle_to_matrix(pose)).reshape(len(body_pose), -1)
        return self.head(self.act(self.enc(x)))

    def encode(self, body_pose: Tensor) -> Tensor:
        """Posterior mean (B, latent) of body poses (B, 63)."""
        return self.posterior(body_pose)[0]

    def _check_z(self, z: Tensor) -> Tensor:
        """z itself if it is a (B, latent) tensor; ValueError naming z otherwise."""
        if not isinstance(z, Tensor) or z.dim() != 2 or z.shape[1] != self.cfg.latent:
            got = tuple(z.shape) if isinstance(z, Tensor) else type(z).__name__
            raise ValueError(f"z: expected shape (B, {self.cfg.latent}), got {got}")
        return z

    def decode_rotmats(self, z: Tensor) -> Tensor:
        """Latent (B, latent) -> body-joint rotation matrices (B, 21, 3, 3)."""
        self._check_z(z)
        w = self.dec[0].weight
        return rot6d_to_matrix(self.dec(z.to(w.dtype)).view(len(z), NUM_BODY_JOINTS, 6))

    def decode(self, z: Tensor) -> Tensor:
        """Latent (B, latent) -> SMPL-X body_pose (B, 63) axis-angle."""
        check_finite(self._check_z(z), "z", "a latent code")
        return matrix_to_axis_angle(self.decode_rotmats(z)).reshape(len(z), -1)

    def loss(self, body_pose: Tensor, generator: torch.Generator | None = None) -> dict[str, Tensor]:
        """beta-VAE objective: squared error of the decoded rotation matrices (summed per pose) + beta KL."""
        mu, logvar = self.posterior(body_pose)
        z = reparameterize(mu, logvar, generator) if self.training else mu
        R = self.decode_rotmats(z)
        target = axis_angle_to_matrix(self._check_pose(body_pose).to(R.dtype))
        rec = (R - target).pow(2).sum((1, 2, 3)).mean()
        kl = kl_standard_normal(mu, logvar)
        with torch.no_grad():
            err = _mean_angle_deg(R, target)
        return {"loss": rec + self.cfg.kl_weight * kl, "rec": rec, "kl": kl, "angle_error_deg": err}

    def state(self) -> dict[str, Any]:
        """Weights and config as plain values (a weights-only checkpoint)."""
        return {"model": self.state_dict(), "model_config": asdict(self.cfg)}

    @classmethod
    def from_state(cls, state: dict[str, Any]) -> "PosePrior":
        """Rebuild from `state()` or a checkpoint of graspkit.train.fit whose extra holds model_config."""
        cfg = state.get("model_config") or state.get("extra", {}).get("model_config")
        if not isinstance(cfg, dict) or not isinstance(state.get("model"), dict):
            raise ValueError("state: no pose-prior config and weights in it (expected 'model_config' and 'model')")
        try:
            model = cls(PosePriorConfig(**cfg))
            model.load_state_dict({k: v.float() for k, v in state["model"].items()})
        except (TypeError, RuntimeError) as e:          # another model's config keys or weights
            raise ValueError(f"state: not a pose-prior checkpoint ({e})") from None
        model.eval()
        return model


@keeps_torch_state
def load_pose_prior(path: str | Path | None = None) -> PosePrior:
    """The pose prior of a checkpoint (default: the shipped one), in eval mode, weights loaded without pickle."""
    from graspkit.train import load_checkpoint

    path = path or POSE_PRIOR_PATH
    try:
        return PosePrior.from_state(load_checkpoint(path))
    except ValueError as e:
        raise ValueError(f"{path}: {e}") from None


# ------------------------------------------------------------------------------------------------ training data
_MIRROR = [JOINT_NAMES.index(n.replace("left", "@").replace("right", "left").replace("@", "right"))
           for n in JOINT_NAMES[:22]]


def mirror_body_pose(body_pose: np.ndarray) -> np.ndarray:
    """Left-right mirror of body poses (..., 21, 3) (canonical x -> -x): swap sides, negate the y, z components."""
    full = np.concatenate([np.zeros(body_pose.shape[:-2] + (1, 3), body_pose.dtype), body_pose], -2)
    out = full[..., _MIRROR, :] * np.array([1.0, -1.0, -1.0], body_pose.dtype)
    return out[..., 1:, :]


def body_poses_from_motions(motions: list, stride: int = 4) -> np.ndarray:
    """Every `stride`-th frame's body pose (joints 1..21) of graspkit Motions -> (n, 21, 3) float32."""
    if stride < 1:
        raise ValueError(f"stride: expected >= 1, got {stride}")
    return np.concatenate([m.poses[::stride, 1:22] for m in motions]).astype(np.float32)


def _clip_poses(seeds: np.ndarray, bm: BodyModel | None, stride: int, progress: bool = False) -> np.ndarray:
    """Body poses (n, 21, 3) of clips made in memory from `seeds` (locomotion, reaching, in turn), every `stride`-th
    frame."""
    from tqdm.auto import tqdm

    from graspkit.body import BodyModel
    from graspkit.data import generate_locomotion, generate_reach
    from graspkit.paths import default_model_path
    from graspkit.progress import hidden

    bm = bm or BodyModel.from_file(default_model_path())
    clips = [(generate_locomotion if i % 2 == 0 else generate_reach)(int(s), bm)
             for i, s in enumerate(tqdm(seeds, desc="pose-prior clips", disable=hidden(progress)))]
    return body_poses_from_motions(clips, stride)


def pose_training_set(n_clips: int = 300, seed: int = 0, extra: np.ndarray | None = None,
                      bm: BodyModel | None = None, stride: int = 4, progress: bool = True) -> np.ndarray:
    """Body poses (n, 21, 3) for the prior: frames of n_clips locomotion + n_clips reaching clips generated in
    memory from `seed` (graspkit.data), plus `extra` poses (n', 21, 3), all also mirrored left/right."""
    poses = _clip_poses(np.random.SeedSequence(seed).generate_state(2 * n_clips), bm, stride, progress)
    if extra is not None:
        poses = np.concatenate([poses, np.asarray(extra, np.float32).reshape(-1, NUM_BODY_JOINTS, 3)])
    return np.concatenate([poses, mirror_body_pose(poses)])


def heldout_clip_poses(n_clips: int = 20, seed: int = 0, bm: BodyModel | None = None, stride: int = 4) -> np.ndarray:
    """Body poses (n, 21, 3), mirrored too, of n_clips locomotion + n_clips reaching clips that no training run of
    the prior sees: their seeds come from SeedSequence([seed, 1]), the training clips' from SeedSequence(seed)."""
    poses = _clip_poses(np.random.SeedSequence([seed, 1]).generate_state(2 * n_clips), bm, stride)
    return np.concatenate([poses, mirror_body_pose(poses)])


@torch.no_grad()
def angle_error(model: PosePrior, body_pose: np.ndarray | Tensor) -> float:
    """Mean angle (degrees) between each joint's rotation in body poses (n, 21, 3) and its round trip through the prior
    (encoder mean -> decoder), over the n x 21 joints: the figure the training logs as angle_error_deg."""
    x = torch.as_tensor(np.asarray(body_pose, np.float32)).reshape(-1, NUM_BODY_JOINTS * 3)
    if len(x) == 0:
        raise ValueError("body_pose: expected at least one pose (n, 21, 3)")
    R = model.decode_rotmats(model.posterior(x)[0])
    return float(_mean_angle_deg(R, axis_angle_to_matrix(x.view(-1, NUM_BODY_JOINTS, 3))))


def _mean_angle_deg(R: Tensor, target: Tensor) -> Tensor:
    """Mean geodesic angle (degrees) between rotation matrices R and target (..., 3, 3)."""
    cos = ((R * target).sum((-1, -2)) - 1) / 2
    return torch.rad2deg(torch.acos(cos.clamp(-1, 1))).mean()


@keeps_torch_state
def train_pose_prior(out: str | Path = POSE_PRIOR_PATH, poses: np.ndarray | None = None, epochs: int = 30,
                     batch_size: int = 256, lr: float = 2e-3, seed: int = 0, n_clips: int = 200,
                     val_fraction: float = 0.05, progress: bool = True, half: bool = True,
                     config: PosePriorConfig | None = None, time_limit_s: float | None = None
                     ) -> list[dict[str, float]]:
    """Train the prior on `poses` (n, 21, 3) (default: `pose_training_set(n_clips, seed)`) with graspkit.train.fit;
    the final weights go to `out` (float16 when `half`, a weights-only checkpoint), the resumable run to
    graspkit.train.run_path's file (named by every setting and the data, so a changed command starts afresh)."""
    from torch.utils.data import TensorDataset

    import hashlib

    from graspkit.train import TrainConfig, fit, run_path, save_checkpoint

    poses = pose_training_set(n_clips, seed, progress=progress) if poses is None else np.asarray(poses, np.float32)
    x = torch.as_tensor(poses.reshape(-1, 63))
    perm = torch.randperm(len(x), generator=torch.Generator().manual_seed(seed))
    n_val = max(1, int(len(x) * val_fraction))
    train, val = TensorDataset(x[perm[n_val:]]), TensorDataset(x[perm[:n_val]])
    torch.manual_seed(seed)
    model = PosePrior(config)
    out = Path(out)
    run = run_path("pose_prior", seed, epochs=epochs, batch_size=batch_size, lr=lr, val_fraction=val_fraction,
                   config=asdict(model.cfg), data=hashlib.blake2b(x.numpy().tobytes(), digest_size=6).hexdigest())

    def step(m: nn.Module, batch: list[Tensor], epoch: int) -> dict[str, Tensor]:
        """One batch of the beta-VAE objective."""
        return m.loss(batch[0])

    cfg = TrainConfig(epochs=epochs, batch_size=batch_size, lr=lr, seed=seed)
    hist = fit(model, step, train, cfg, checkpoint=run, extra={"model_config": asdict(model.cfg)},
               val_dataset=val, progress=progress, ddp=False, time_limit_s=time_limit_s)   # the step calls m.loss
    state = model.state()
    if half:
        state["model"] = {k: v.half() if v.is_floating_point() else v for k, v in state["model"].items()}
    state["history"] = hist
    save_checkpoint(out, state)
    return hist
