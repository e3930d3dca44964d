"""MotionFill-VAE's data (SAGA §3.3, App. A.3): 2-s clips at 30 fps as root trajectories and four-channel motion images.

A window has T + 1 = 61 frames of body motion M_{0:T} (T = 60) and T + 2 = 62 root states Γ_{0:T+1}; a clip shorter
than 62 frames is padded at the front with its first frame (A.3). Every window is canonicalised as A.3: origin at
the first frame's pelvis, x the horizontal left->right shoulder direction, y forward, z up (`data.canonicalize`).

- root state Γ_t = (x, y, cos γ, sin γ): pelvis on the ground plane and heading γ (radians from canonical +x) of the
  facing direction z × (right hip − left hip);
- Γ̄ (TrajFill's condition, §3.3): the linear interpolation from Γ_0 to Γ_T plus a one-step extrapolation at T+1;
- markers: SAGA's sparse-hand set (49 body + 14 face + 6 hand + 10 fingertips = 79, `body.markers`);
- local markers M^l_t = R(−γ_t) (M_t − (x_t, y_t, 0)): the body in its own heading frame at its ground point;
- root velocities v_t = (R(−γ_t)(p_{t+1} − p_t), wrap(γ_{t+1} − γ_t)), t = 0..T (per frame, not per second);
- foot contacts C_F (left heel, left toe, right heel, right toe), t = 0..T. The paper does not define them: graspkit
  uses the generator's own gait phases where the clip carries them, and otherwise a foot part is in contact when its
  marker is within `CONTACT_HEIGHT` of the clip's lowest marker height and moves slower than `CONTACT_SPEED`;
- the motion image I (4, T+1, 79·3 + 4): channel 0 the normalised local markers with the contacts stacked after
  them, channels 1–3 the normalised root velocities (vx, vy, vγ) broadcast along the features (after LEMO-style
  motion images, SAGA [64]); the condition image I_c is I with frames 1..T−1 of channel 0 set to 0 (the unknown
  in-between motion); the velocity channels stay, as they come from TrajFill at inference.

Normalisation statistics (mean, std per marker coordinate and per velocity component) come from the training
split only and travel with a checkpoint as the model's buffers (`MotionFillVAE.set_stats`).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import torch
from torch.utils.data import Dataset
from tqdm.auto import tqdm

from graspkit.body.markers import saga_sparse_markers
from graspkit.body.skeleton import JOINT_INDEX
from graspkit.checks import check_int, seeded_rng
from graspkit.data.formats import npz_arrays, open_npz
from graspkit.data.motion import Motion, canonicalize
from graspkit.progress import hidden

if TYPE_CHECKING:
    from graspkit.body import BodyModel

T = 60                          # in-between span: frames 0..T
NUM_FRAMES = T + 1              # local motion frames
NUM_ROOT = T + 2                # root states Γ_{0:T+1}
CONTACT_HEIGHT = 0.05           # m above the clip's lowest foot marker (SAGA's heel-height threshold, Sec. 4.2)
CONTACT_SPEED = 0.2             # m/s
FOOT_MARKERS = ("LHEE", "LTOE", "RHEE", "RTOE")   # in CONTACT_NAMES order


def _rot2(a: np.ndarray) -> np.ndarray:
    """2D rotation matrices (..., 2, 2) for angles (...)."""
    c, s = np.cos(a), np.sin(a)
    return np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)


def root_states(joints: np.ndarray) -> np.ndarray:
    """Γ (n, 4) = (x, y, cos γ, sin γ) from canonical joints (n, 55, 3): pelvis on the ground plane, heading from the hips."""
    hips = joints[:, JOINT_INDEX["right_hip"]] - joints[:, JOINT_INDEX["left_hip"]]
    fwd = np.stack([-hips[:, 1], hips[:, 0]], -1)             # z × hips on the ground plane
    g = np.arctan2(fwd[:, 1], fwd[:, 0])
    p = joints[:, JOINT_INDEX["pelvis"], :2]
    return np.concatenate([p, np.cos(g)[:, None], np.sin(g)[:, None]], 1)


def interpolated_trajectory(traj: np.ndarray) -> np.ndarray:
    """Γ̄ (..., T+2, 4): linear interpolation Γ_0 -> Γ_T over frames 0..T and one more step past Γ_T (TrajFill, §3.3),
    from a window's root states traj (..., T+2, 4) (only frames 0 and T are read)."""
    _check_root_states(traj, "traj")
    g0, gT = traj[..., 0:1, :], traj[..., T:T + 1, :]
    s = np.arange(NUM_ROOT, dtype=traj.dtype)[:, None] / T       # 0 .. 1 at T, 61/60 at T+1
    return g0 + s * (gT - g0)


def _check_root_states(traj: np.ndarray, name: str, batch: bool = True) -> None:
    """ValueError naming `name` unless it holds a window's root states (..., T+2, 4) (batch=False: exactly one window,
    (T+2, 4)); a longer trajectory would be read at frame T, not its end."""
    if np.ndim(traj) < 2 or np.shape(traj)[-2:] != (NUM_ROOT, 4) or (not batch and np.ndim(traj) != 2):
        raise ValueError(f"{name}: expected a window's root states (..., {NUM_ROOT}, 4) (x, y, cos γ, sin γ for frames "
                         f"0..{T + 1}), got shape {np.shape(traj)}")


def local_motion(markers: np.ndarray, traj: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Canonical markers (T+1, M, 3) and Γ (T+2, 4) -> local markers (T+1, M, 3), root velocities (T+1, 3)."""
    _check_root_states(traj, "traj", batch=False)
    if np.ndim(markers) != 3 or np.shape(markers)[0] != NUM_FRAMES or np.shape(markers)[2] != 3:
        raise ValueError(f"markers: expected one window's canonical markers ({NUM_FRAMES}, M, 3), got shape "
                         f"{np.shape(markers)}")
    g = np.arctan2(traj[:, 3], traj[:, 2])
    R = _rot2(-g[:NUM_FRAMES])                                     # world -> heading frame
    rel = markers.copy()
    rel[..., :2] -= traj[:NUM_FRAMES, None, :2]
    rel[..., :2] = np.einsum("tij,tmj->tmi", R, rel[..., :2])
    dp = np.einsum("tij,tj->ti", R, traj[1:, :2] - traj[:-1, :2])
    dg = np.angle(np.exp(1j * (g[1:] - g[:-1])))
    return rel, np.concatenate([dp, dg[:, None]], 1)


def global_motion(local: np.ndarray, traj: np.ndarray) -> np.ndarray:
    """Inverse of `local_motion`: local markers (..., T+1, M, 3) and Γ (..., T+2, 4) -> canonical markers."""
    _check_root_states(traj, "traj")
    g = np.arctan2(traj[..., :NUM_FRAMES, 3], traj[..., :NUM_FRAMES, 2])
    out = local.copy()
    out[..., :2] = np.einsum("...tij,...tmj->...tmi", _rot2(g), local[..., :2]) + traj[..., :NUM_FRAMES, None, :2]
    return out


def geometric_contacts(foot: np.ndarray, fps: float = 30.0, first_at_rest: bool = False) -> np.ndarray:
    """Contacts (n, 4) bool from foot markers (n, 4, 3): near the clip's lowest foot height and slow.

    Frame 0 takes the speed of frame 0 -> 1; `first_at_rest` gives it speed 0 instead, for a window that joins a
    start pose at rest to a later pose (`graspkit.saga.synthesize`: the jump between them is not a motion)."""
    low = foot[..., 2] < foot[..., 2].min() + CONTACT_HEIGHT
    v = np.linalg.norm(np.diff(foot, axis=0), axis=-1) * fps
    v = np.concatenate([np.zeros_like(v[:1]) if first_at_rest else v[:1], v], 0)
    return low & (v < CONTACT_SPEED)


def make_windows(motions: list[Motion], bm: BodyModel, stride: int | None = 30, align_end: bool = False,
                 progress: bool = True, start_at_rest: bool = False) -> dict[str, np.ndarray]:
    """Canonical 62-frame windows of many clips -> arrays {traj (N,62,4), markers (N,61,79,3), local, vel (N,61,3),
    contacts (N,61,4), clip (N,)}. `align_end`: one window per clip ending at its last frame (approach clips, whose
    last frames hold the grasp); otherwise windows every `stride` frames. `start_at_rest`: clips without contact
    labels get geometric ones with their first frame at rest (`geometric_contacts`' first_at_rest)."""
    if stride is not None:
        check_int(stride, "stride", least=1)
    mk = saga_sparse_markers(bm)
    foot_cols = [mk.names.index(n) for n in FOOT_MARKERS]
    out: dict[str, list[np.ndarray]] = {k: [] for k in ("traj", "markers", "local", "vel", "contacts", "clip")}
    for ci, m in enumerate(tqdm(motions, desc="MotionFill windows", unit="clip", disable=hidden(progress))):
        if abs(m.fps - 30.0) > 1e-6:
            raise ValueError(f"motions[{ci}]: expected 30 fps, got {m.fps} (resample with data.load_motion)")
        joints = m.joint_positions(bm)
        mark = mk.select(m.vertices(bm)).numpy().astype(np.float64)
        if m.contacts is not None:
            contacts = m.contacts
        else:
            contacts = geometric_contacts(mark[:, foot_cols], m.fps, first_at_rest=start_at_rest)
        n = m.num_frames
        if n < NUM_ROOT:                                         # pad the front with the first frame (A.3)
            pad = NUM_ROOT - n
            joints, mark = np.concatenate([joints[:1].repeat(pad, 0), joints]), np.concatenate([mark[:1].repeat(pad, 0), mark])
            contacts = np.concatenate([contacts[:1].repeat(pad, 0), contacts])
            n = NUM_ROOT
        starts = [n - NUM_ROOT] if align_end else list(range(0, n - NUM_ROOT + 1, stride or NUM_ROOT))
        for s in starts:
            # approach clips end at the grasp (frame T); the extra root state T+1 repeats it
            sl = slice(s, s + NUM_ROOT) if not align_end else slice(s + 1, s + NUM_ROOT)
            j, mw, cw = joints[sl], mark[sl], contacts[sl]
            if align_end:
                j, mw, cw = (np.concatenate([a, a[-1:]]) for a in (j, mw, cw))
            R, o = canonicalize(j)
            j, mw = (j - o) @ R.T, (mw - o) @ R.T
            traj = root_states(j)
            loc, vel = local_motion(mw[:NUM_FRAMES], traj)
            for k, v in (("traj", traj), ("markers", mw[:NUM_FRAMES]), ("local", loc), ("vel", vel),
                         ("contacts", cw[:NUM_FRAMES]), ("clip", np.int64(ci))):
                out[k].append(v)
    if not out["traj"]:
        raise ValueError("motions: no clip gave a window")
    arr = {k: np.stack(v) for k, v in out.items()}
    for k in ("traj", "markers", "local", "vel"):
        arr[k] = arr[k].astype(np.float32)
    arr["contacts"] = arr["contacts"].astype(bool)
    return arr


def split_clips(num_clips: int, seed: int = 0, fractions: tuple[float, float] = (0.8, 0.1)) -> dict[str, np.ndarray]:
    """Deterministic clip-level split {train, val, test} of clip ids (windows of a clip stay together); `fractions`
    are train's and val's shares, test has the rest."""
    num_clips = check_int(num_clips, "num_clips", 0)
    if len(fractions) != 2 or min(fractions) < 0 or sum(fractions) > 1 + 1e-9:
        raise ValueError(f"fractions: expected two non-negative numbers (train, val) summing to at most 1, got "
                         f"{fractions}")
    perm = seeded_rng(seed).permutation(num_clips)
    a = int(round(fractions[0] * num_clips))
    b = a + int(round(fractions[1] * num_clips))
    return {"train": np.sort(perm[:a]), "val": np.sort(perm[a:b]), "test": np.sort(perm[b:])}


@dataclass
class MotionFillStats:
    """Mean / std of the local marker coordinates (M·3,) and of the root velocities (3,), from the training split."""

    marker_mean: torch.Tensor
    marker_std: torch.Tensor
    vel_mean: torch.Tensor
    vel_std: torch.Tensor

    @classmethod
    def fit(cls, arrays: dict[str, np.ndarray]) -> "MotionFillStats":
        """Statistics of windows {local (N,61,M,3), vel (N,61,3)}; std floored at 1e-3."""
        loc = torch.as_tensor(arrays["local"]).flatten(2).flatten(0, 1).double()
        vel = torch.as_tensor(arrays["vel"]).flatten(0, 1).double()
        f = lambda x: x.float()  # noqa: E731
        return cls(f(loc.mean(0)), f(loc.std(0).clamp_min(1e-3)), f(vel.mean(0)), f(vel.std(0).clamp_min(1e-3)))


def motion_image(local: torch.Tensor, contacts: torch.Tensor, vel: torch.Tensor, stats: MotionFillStats) -> torch.Tensor:
    """The four-channel motion image (B, 4, T+1, M·3+4) from local markers (B,T+1,M,3), contacts (B,T+1,4), vel (B,T+1,3)."""
    x = (local.flatten(2) - stats.marker_mean) / stats.marker_std
    ch0 = torch.cat([x, contacts.to(x.dtype)], -1)
    v = (vel - stats.vel_mean) / stats.vel_std
    return torch.cat([ch0[:, None], v.permute(0, 2, 1)[..., None].expand(-1, -1, -1, ch0.shape[-1])], 1)


def condition_image(image: torch.Tensor) -> torch.Tensor:
    """I_c: the motion image with the in-between frames 1..T-1 of channel 0 zeroed (B, 4, T+1, F)."""
    c = image.clone()
    c[:, 0, 1:-1] = 0.0
    return c


def split_image(image: torch.Tensor, stats: MotionFillStats) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Inverse of `motion_image`: (B,4,T+1,F) -> local markers (B,T+1,M,3), contact logits/values (B,T+1,4), vel (B,T+1,3)."""
    ch0 = image[:, 0]
    local = (ch0[..., :-4] * stats.marker_std + stats.marker_mean).unflatten(-1, (-1, 3))
    vel = image[:, 1:].mean(-1).permute(0, 2, 1) * stats.vel_std + stats.vel_mean
    return local, ch0[..., -4:], vel


class MotionFillDataset(Dataset):
    """Windows as tensors: traj, traj_interp (62,4); markers, local (61,79,3); vel (61,3); contacts (61,4); image, cond."""

    def __init__(self, arrays: dict[str, np.ndarray], stats: MotionFillStats, clips: np.ndarray | None = None) -> None:
        keep = np.ones(len(arrays["traj"]), bool) if clips is None else np.isin(arrays["clip"], clips)
        self.a = {k: torch.as_tensor(v[keep]) for k, v in arrays.items()}
        self.a["traj_interp"] = torch.as_tensor(interpolated_trajectory(arrays["traj"][keep]))
        self.stats = stats

    def __len__(self) -> int:
        return len(self.a["traj"])

    def __getitem__(self, i: int) -> dict[str, torch.Tensor]:
        item = {k: v[i] for k, v in self.a.items() if k != "clip"}
        item["contacts"] = item["contacts"].float()
        img = motion_image(item["local"][None], item["contacts"][None], item["vel"][None], self.stats)
        item["image"], item["cond"] = img[0], condition_image(img)[0]
        return item


def save_windows(path: str | Path, arrays: dict[str, np.ndarray]) -> Path:
    """Windows to an .npz, atomically."""
    from graspkit.data.formats import write_npz_atomic
    from graspkit.paths import check_suffix

    check_suffix(path, ".npz")
    write_npz_atomic(Path(path), arrays)
    return Path(path)


def load_windows(path: str | Path) -> dict[str, np.ndarray]:
    """Windows back from `save_windows` (no pickle); a missing key gives an error naming the file."""
    with open_npz(path, "a MotionFill windows file (save_windows)") as z:
        missing = {"traj", "markers", "local", "vel", "contacts", "clip"} - set(z.files)
        if missing:
            raise ValueError(f"{path}: not a MotionFill windows file, missing {sorted(missing)}")
        a = npz_arrays(z, z.files, path)
    n = len(a["clip"]) if a["clip"].ndim == 1 else -1
    ndim = {"traj": 3, "markers": 4, "local": 4, "vel": 3, "contacts": 3}
    for k, d in ndim.items():
        if a[k].ndim != d or len(a[k]) != n or a[k].dtype.kind not in "biuf" or not np.isfinite(a[k]).all():
            raise ValueError(f"{path}: key {k!r} is {a[k].dtype} of shape {a[k].shape}, expected {d} dimensions of "
                             f"finite numbers with one row per window ({n}, from 'clip')")
    return a
