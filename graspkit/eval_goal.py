"""GOAL's evaluation (Taheri et al., CVPR 2022, §4.2): Tab. 1 (GNet grasps), Tab. 2 (MNet V2V), foot sliding.

Tab. 1 — for the held-out test objects, grasps from (1) a GrabNet-style SMPL-X CVAE (GNet's network with a decoder
of SMPL-X parameters only, no offsets, no refinement), (2) GNet without the refinement, (3) GNet with it (Eq. 4-8),
and (4) the synthetic ground truth: the mean interpenetration volume (cm³, exact ray casting) and the contact ratio
(share of grasps whose body touches the object; `graspkit.metrics.grasp_metrics`).
Tab. 2 — MNet's vertex-to-vertex errors (mm) between predicted and ground-truth SMPL-X meshes, over the whole body,
the right hand and the feet, for MNet, MNet without the interaction-aware attention, MNet on parameters only
(MNet-Pose) and MNet with 1 instead of 10 output frames, on windows of the test objects' approach clips: from the
true past 5 frames, the next 10 frames are predicted (autoregressively for the 1-frame model) and compared.
Foot sliding (§4.2): the share of frames whose vertex closest to the ground moves more than 1 cm to the next frame,
for GOAL's rollouts, the synthetic ground truth and (when available) SAGA.
The perceptual studies (Tab. 3-4) are not reproduced.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from functools import lru_cache
from itertools import zip_longest
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import torch
from scipy.spatial import cKDTree
from torch import Tensor

from graspkit.checks import count_type, nonneg_float, positive_float, seeded_rng
from graspkit.cli import (TIME_LIMIT_HELP, check_counts, check_folders, check_out, expand_user_paths, refuse_folder_out,
                          reports_errors)
from graspkit.metrics import GOAL_GRAB_SLIDING
from graspkit.models.blocks import in_eval_mode
from graspkit.models.gnet import pose_rotmats
from graspkit.models.mnet import STALL_FRAMES, MNet, MNetWindows, predict_horizon
from graspkit.rotations import rotation_about_z
from graspkit.state import keeps_torch_state

if TYPE_CHECKING:
    import argparse

    import trimesh

    from graspkit.body import BodyModel
    from graspkit.data.grab import GraspSequence
    from graspkit.models.gnet import GNet
    from graspkit.models.mnet import ApproachClip, MNetConfig
    from graspkit.optim.goal_refine import GraspRefineWeights, PosedSDF

PAPER_TAB1 = {  # GOAL Tab. 1: penetration volume (cm^3), contact ratio
    "GrabNet [57]": (2.65, 1.00), "GrabNet-SMPL-X": (7.33, 0.87), "GNet w/o opt": (5.32, 0.87),
    "GNet": (2.22, 1.00), "GRAB (GT)": (1.95, 1.00)}
PAPER_TAB2 = {  # GOAL Tab. 2: V2V (mm) body, hand, feet
    "MNet-Pose": (22.0, 30.2, 10.4), "MNet-Marker [67]": (21.1, 30.1, 9.8), "MNet-w/o-IAA": (21.0, 29.1, 10.5),
    "MNet": (19.7, 28.0, 9.9), "1 output frame": (26.7, 35.7, 17.9), "10 output frames": (19.7, 28.0, 9.9)}
PAPER_SLIDING = {"GOAL": 0.137, "GRAB (GT)": GOAL_GRAB_SLIDING}
PEN_ROW = "GNet + E_pen (graspkit)"   # Tab. 1's extra row: the refinement with graspkit's penetration term
TAB1_ROWS = ("GrabNet-SMPL-X", "GNet w/o opt", "GNet", PEN_ROW, "synthetic GT")   # Tab. 1's rows, in order


def part_vertex_ids(bm: BodyModel, joints: tuple[str, ...]) -> np.ndarray:
    """Vertex ids whose dominant skinning joint is one of `joints`."""
    from graspkit.body.skeleton import JOINT_INDEX

    part = bm.lbs_weights.argmax(1).numpy()
    return np.flatnonzero(np.isin(part, [JOINT_INDEX[j] for j in joints]))


def right_hand_ids(bm: BodyModel) -> np.ndarray:
    """Vertices of the right hand (wrist and fingers)."""
    from graspkit.body.skeleton import FINGERS

    return part_vertex_ids(bm, ("right_wrist",) + tuple(f"right_{f}{k}" for f in FINGERS for k in (1, 2, 3)))


def feet_ids(bm: BodyModel) -> np.ndarray:
    """Vertices of both feet (ankles and toes)."""
    return part_vertex_ids(bm, ("left_ankle", "right_ankle", "left_foot", "right_foot"))


@dataclass
class V2V:
    """Mean vertex-to-vertex errors in millimetres over the whole body, the right hand and the feet."""

    body: float
    hand: float
    feet: float


@torch.no_grad()
@in_eval_mode
def teacher_forced_v2v(mnet: MNet, windows: MNetWindows, bm: BodyModel, index: Tensor, horizon: int = 10,
                       chunk: int = 32) -> V2V:
    """Tab. 2 protocol: from the true past 5 frames of windows `index`, predict `horizon` frames (one step of a
    10-frame MNet, ten autoregressive steps of a 1-frame one, no refinement), build the SMPL-X meshes of the predicted
    and true frames, and average the per-vertex distances (mm) over the body, the right hand and the feet."""
    hand, feet = torch.as_tensor(right_hand_ids(bm)), torch.as_tensor(feet_ids(bm))
    sums, n = np.zeros(3), 0
    for i in range(0, len(index), chunk):
        t = windows.windows[index[i:i + chunk]]
        s = windows.state(t)
        r_p, t_p = predict_horizon(mnet, windows.body, s, windows.points[windows.clip[t]], windows.basis, horizon)
        fut = torch.minimum(t[:, None] + torch.arange(1, horizon + 1), windows.end[t][:, None])
        betas = s.betas.repeat_interleave(horizon, 0)
        vp = bm.forward_rotmats(pose_rotmats(r_p.reshape(-1, 55, 6)), betas=betas, transl=t_p.reshape(-1, 3)).vertices
        vg = bm.forward_rotmats(pose_rotmats(windows.rot6d[fut].reshape(-1, 55, 6)), betas=betas,
                                transl=windows.transl[fut].reshape(-1, 3)).vertices
        d = (vp - vg).norm(dim=-1)                                                     # (B*horizon, V)
        sums += [float(d.mean(1).sum()), float(d[:, hand].mean(1).sum()), float(d[:, feet].mean(1).sum())]
        n += d.shape[0]
    return V2V(*(1000.0 * sums / max(n, 1)))


# ------------------------------------------------------------------------------------------- data (graspkit.data.grab files)

def _files(folder, kind: str, split: str | None) -> list:
    """GRAB-style files `<folder>/<kind>_*.npz` (`formats.clip_files`) whose object is in `split` ('train', 'val',
    'test' or None: all); a ValueError when they were made on another body than `_body()`'s (`grab.check_made_on`)."""
    from graspkit.data.formats import clip_files
    from graspkit.data.grab import check_made_on, load_grasp_sequence
    from graspkit.data.grasp import file_split

    paths = clip_files(folder, kind)
    if not paths:
        raise FileNotFoundError(f"folder: no {kind}_*.npz files in {folder} (make them with "
                                f"`graspkit data make --kind {kind}`)")
    check_made_on(_body()[0], paths, f"folder: {folder}", kind)
    seqs = [(p, load_grasp_sequence(p)) for p in paths]
    return [s for p, s in seqs if split is None or file_split(s.object_name, p) == split]


def object_points_world(seq: GraspSequence, frame: int = 0) -> Tensor:
    """The sequence's object surface points (P,3) moved to the world by its pose at `frame`."""
    R, t = seq.object_rotation()[frame], seq.object_transl[frame].astype(np.float64)
    if seq.object_points is None:
        raise ValueError(f"seq: the {seq.object_name} sequence stores no object points")
    return torch.as_tensor(np.asarray(seq.object_points, np.float64) @ R.T + t).float()


def kd_offsets(v: Tensor, points: Tensor) -> Tensor:
    """Offsets (B,N,3) from v (B,N,3) to the closest of points (B,P,3), by a KD-tree per sample (no gradient)."""
    out = torch.empty_like(v)
    for b in range(len(v)):
        pts = points[b].double().numpy()
        _, idx = cKDTree(pts).query(v[b].double().numpy())
        out[b] = torch.as_tensor(pts[idx]).to(v.dtype) - v[b]
    return out


def kd_bps(points: Tensor, basis: Tensor) -> Tensor:
    """BPS codes (B,K) of point clouds (B,P,3) (already relative to the basis centre), by a KD-tree per sample."""
    return torch.stack([torch.as_tensor(cKDTree(p.double().numpy()).query(basis.double().numpy())[0]).float()
                        for p in points])


@torch.no_grad()
def goal_labels(rot6d: Tensor, transl: Tensor, betas: Tensor, points: Tensor, obj_transl: Tensor) -> dict[str, Tensor]:
    """GOAL's labels of grasps (B,...) recomputed on graspkit's body (Eq. 2): the 400 sampled vertices, their offsets
    to the closest object point (points (B,P,3)), the head direction q and the object's BPS code (points minus the
    object translation, the fixed 1024-point basis of radius 0.15 m)."""
    from graspkit.objects.bps import bps_basis

    _, gv, body = _body()
    head = _head_body()
    v = body(pose_rotmats(rot6d), betas, transl)[0].float()
    hv = head(pose_rotmats(rot6d), betas, transl)[0].float()
    return {"verts": v, "offsets": kd_offsets(v, points), "head_dir": torch.nn.functional.normalize(
            hv[:, 1] - hv[:, 0], dim=-1), "bps": kd_bps(points - obj_transl[:, None], bps_basis())}


def gnet_frame(start_xy: Tensor, centre: Tensor) -> tuple[Tensor, Tensor]:
    """GNet's frame (x' = R (x − o)) for starts (B,2) and object centres (B,3): the origin on the floor under the object
    centre, the horizontal direction from the start to the object along −y (the data's start faces −y)."""
    d = centre[:, :2] - start_xy
    R = rotation_about_z(-math.pi / 2 - torch.atan2(d[:, 1], d[:, 0]))
    return R.to(centre.dtype), torch.cat([centre[:, :2], torch.zeros_like(centre[:, :1])], 1)


def _start_xy(seq) -> np.ndarray:
    """Where the sequence's person started (x, y): the stored task start, else the first frame's pelvis."""
    if "grasp.start" in seq.extras:
        return np.asarray(seq.extras["grasp.start"], np.float64)[:2]
    bm, _, _ = _body()
    from graspkit.models.mnet import rest_root
    return (rest_root(bm, torch.as_tensor(seq.betas[None, :10]).float())[0].double().numpy() + seq.trans[0])[:2]


def grasp_frames(seqs: list) -> list[int]:
    """The frame of each sequence's grasp: an approach clip's goal frame, a grasp file's grasp frame (else 0)."""
    from graspkit.data.grab import grasp_frame

    return [grasp_frame(s.extras) for s in seqs]


def gnet_samples(seqs: list, accepted_only: bool = True) -> dict[str, Tensor]:
    """GNet's tensors (see GNet.features) from GRAB-style grasp or approach sequences at their grasp frame, in GNet's
    frame (`gnet_frame`); the labels are recomputed from the stored parameters and object (`goal_labels`), so they
    always match graspkit's body. Also: 'points' (B,P,3) the object's points, 'R' (B,3,3), 'o' (B,3) the frame."""
    from graspkit.models.mnet import rest_root, transform_params, transform_points
    from graspkit.rotations import axis_angle_to_rot6d

    if accepted_only:
        seqs = [s for s in seqs if bool(s.extras.get("grasp.accepted", True))]
    if not seqs:
        raise ValueError("seqs: no (accepted) sequences")
    bm, _, _ = _body()
    frames = grasp_frames(seqs)
    rot6d = torch.stack([axis_angle_to_rot6d(torch.as_tensor(s.poses[f], dtype=torch.float64)).float()
                         for s, f in zip(seqs, frames)])
    transl = torch.stack([torch.as_tensor(np.array(s.trans[f])) for s, f in zip(seqs, frames)]).float()
    betas = torch.stack([torch.as_tensor(s.betas[:10]) for s in seqs]).float()
    obj_t = torch.stack([torch.as_tensor(np.array(s.object_transl[f])) for s, f in zip(seqs, frames)]).float()
    P = min(len(s.object_points) for s in seqs)
    points = torch.stack([object_points_world(s, f)[:P] for s, f in zip(seqs, frames)])
    R, o = gnet_frame(torch.as_tensor(np.stack([_start_xy(s) for s in seqs])).float(), obj_t)
    rot6d, transl = transform_params(rot6d, transl, rest_root(bm, betas), R, o)
    points, obj_t = transform_points(points, R, o), transform_points(obj_t[:, None], R, o)[:, 0]
    out = {"rot6d": rot6d, "transl": transl, "betas": betas, "obj_transl": obj_t, "points": points, "R": R, "o": o}
    for i in range(0, len(seqs), 256):
        lab = goal_labels(rot6d[i:i + 256], transl[i:i + 256], betas[i:i + 256], points[i:i + 256], obj_t[i:i + 256])
        for k, v in lab.items():
            out.setdefault(k, []).append(v)
    return {k: torch.cat(v) if isinstance(v, list) else v for k, v in out.items()}


def approach_clips(seqs: list) -> list:
    """MNet's ApproachClips from GRAB-style approach sequences (object points in the world, goal = grasp frame)."""
    from graspkit.models.mnet import ApproachClip
    from graspkit.rotations import axis_angle_to_rot6d

    out = []
    for s in seqs:
        if "grasp.goal_frame" not in s.extras:
            raise ValueError(f"seqs: a {s.object_name} sequence has no 'grasp.goal_frame' (not an approach clip)")
        pts, t = object_points_world(s, 0), s.object_transl[0].astype(np.float64)
        out.append(ApproachClip(axis_angle_to_rot6d(torch.as_tensor(s.poses, dtype=torch.float64)).float(),
                                torch.as_tensor(s.trans).float(), torch.as_tensor(s.betas[:10]).float(),
                                int(s.extras["grasp.goal_frame"]), pts, torch.as_tensor(t).float(), s.object_name))
    return out


# ------------------------------------------------------------------------------------------- training drivers, CLI

MNET_VARIANTS = {  # GOAL Tab. 2 rows -> MNetConfig changes
    "mnet": {}, "no_iaa": {"attention": False}, "pose": {"outputs": "pose"}, "1frame": {"n_future": 1}}


def _all_files(folders, kind: str, split: str) -> list:
    """Sequences of `kind` in `split` from every folder that has such files."""
    out = []
    for f in folders:
        try:
            out += _files(f, kind, split)
        except FileNotFoundError:
            continue
    return out


def default_data_folders() -> list:
    """Where `graspkit data make --kind {grasp,approach}` writes by default."""
    from graspkit.paths import cache_dir

    return [cache_dir() / "grasps" / "grasp", cache_dir() / "grasps" / "approach"]


def _body(model: str | Path | None = None):
    """The body model (default: graspkit's, the file default_model_path() names now; hand mean not added: the files
    store absolute poses), GOAL's vertex sampler and a SparseBody over its 400 vertices (built once per model file)."""
    from graspkit.body import shared_body

    return _goal_parts(shared_body(model, flat_hand_mean=True))     # follows GRASPKIT_MODEL and files rewritten


@lru_cache(maxsize=2)
def _goal_parts(bm):
    """_body for one shared body model."""
    from graspkit.body.markers import goal_vertices
    from graspkit.models.gnet import SparseBody

    gv = goal_vertices(bm)
    return bm, gv, SparseBody(bm, torch.as_tensor(gv.vertex_ids))


@lru_cache(maxsize=2)
def _head_parts(bm):
    """A SparseBody over the head-direction pair (back of the head, nose) of one shared body model."""
    from graspkit.models.gnet import SparseBody

    _, gv, body = _goal_parts(bm)
    return SparseBody(body.bm, torch.tensor([gv.head_back, gv.head_front]))


def _head_body():
    """_head_parts of the default body (the file default_model_path() names now, as `_body`)."""
    return _head_parts(_body()[0])


def gnet_data(folders: Sequence[str | Path]) -> tuple[dict[str, Tensor], dict[str, Tensor] | None]:
    """GNet's train and validation samples (None: no validation files): static grasps and the grasp frames of approach
    clips."""
    train = _all_files(folders, "grasp", "train") + _all_files(folders, "approach", "train")
    val = _all_files(folders, "grasp", "val") + _all_files(folders, "approach", "val")
    if not train:
        raise FileNotFoundError(f"data: no training grasps in {[str(f) for f in folders]}")
    return gnet_samples(train), (gnet_samples(val) if val else None)


@keeps_torch_state
def run_train_gnet(folders: Sequence[str | Path], out: str | Path, variant: str = "gnet", epochs: int = 60,
                   time_limit_s: float | None = 600.0, seed: int = 0, threads: int = 2,
                   run_dir: str | Path | None = None, progress: bool = True, kl: float | None = None) -> dict:
    """Train GNet ('gnet') or the GrabNet-style SMPL-X CVAE ('smplx') and ship its float16 weights to `out`;
    `kl` overrides λ_KL of Eq. 3 (GNetLossWeights.kl)."""
    import time

    from graspkit.models.gnet import GNetConfig, GNetLossWeights, save_weights, train_gnet
    from graspkit.train import TrainConfig, files_key, run_path

    if variant not in ("gnet", "smplx"):
        raise ValueError(f"variant: expected 'gnet' or 'smplx', got {variant!r}")
    torch.set_num_threads(threads)
    bm, gv, body = _body()
    train, val = gnet_data(folders)
    weights = GNetLossWeights() if kl is None else GNetLossWeights(kl=kl)
    cfg = GNetConfig(offsets=variant == "gnet")
    run = run_path(f"gnet_{variant}", seed, run_dir, cfg=asdict(cfg), weights=asdict(weights), epochs=epochs,
                    data=[str(f) for f in folders], n=len(train["rot6d"]), files=files_key(folders),
                    body=bm.digest())   # the labels are recomputed on this body: another never resumes the run
    t0 = time.perf_counter()
    net, hist = train_gnet(train, val, body, cfg, weights,
                           train_cfg=TrainConfig(epochs=epochs, batch_size=64, lr=1e-3, seed=seed, num_threads=threads),
                           checkpoint=run, time_limit_s=time_limit_s, progress=progress)
    info = {"variant": variant, "train_samples": len(train["rot6d"]), "epochs": len(hist), "kl_weight": weights.kl,
            "seconds": time.perf_counter() - t0, "history": hist}
    save_weights(out, net, "gnet", extra=info)
    return info


def mnet_windows(folders: Sequence[str | Path], split: str, cfg: MNetConfig | None = None, stride: int = 1,
                 goal_repeat: int = 1) -> MNetWindows:
    """MNet windows of the approach clips of `split` (`goal_repeat`: see MNetWindows)."""
    from graspkit.objects.bps import bps_basis

    _, _, body = _body()
    seqs = _all_files(folders, "approach", split)
    if not seqs:
        raise FileNotFoundError(f"data: no {split} approach clips in {[str(f) for f in folders]}")
    return MNetWindows(approach_clips(seqs), body, bps_basis(), cfg, stride=stride, goal_repeat=goal_repeat)


@keeps_torch_state
def run_train_mnet(folders: Sequence[str | Path], out: str | Path, variant: str = "mnet", epochs: int = 20,
                   time_limit_s: float | None = 600.0, seed: int = 0, threads: int = 2, stride: int = 1,
                   run_dir: str | Path | None = None, progress: bool = True,
                   goal_repeat: int = 4, vel_noise: float = 0.005) -> dict:
    """Train MNet or one of its Tab. 2 ablations (MNET_VARIANTS) and ship its float16 weights to `out`; windows within
    30 frames before / 5 after the goal frame are shown `goal_repeat` times per epoch, and the input velocities are
    perturbed by `vel_noise` m/frame (Gaussian) during training."""
    import time

    from graspkit.models.gnet import save_weights
    from graspkit.models.mnet import MNetConfig, train_mnet
    from graspkit.train import TrainConfig, files_key, run_path

    if variant not in MNET_VARIANTS:
        raise ValueError(f"variant: expected one of {list(MNET_VARIANTS)}, got {variant!r}")
    torch.set_num_threads(threads)
    cfg = MNetConfig(**MNET_VARIANTS[variant])
    t0 = time.perf_counter()
    train = mnet_windows(folders, "train", cfg, stride, goal_repeat)
    val = mnet_windows(folders, "val", cfg, max(stride, 4))
    # held: MNet.forward holds the features training held still (2026-12-07); a run file from before is not resumed
    run = run_path(f"mnet_{variant}", seed, run_dir, cfg=asdict(cfg), epochs=epochs, stride=stride,
                    data=[str(f) for f in folders], n=len(train), goal_repeat=goal_repeat, vel_noise=vel_noise,
                    files=files_key(folders), body=_body()[0].digest(), held="floored")
    net, hist = train_mnet(train, val, cfg, train_cfg=TrainConfig(epochs=epochs, batch_size=128, lr=1e-3, seed=seed,
                                                                   num_threads=threads),
                           checkpoint=run, time_limit_s=time_limit_s, progress=progress, vel_noise=vel_noise)
    info = {"variant": variant, "train_windows": len(train), "epochs": len(hist), "goal_repeat": goal_repeat,
            "vel_noise": vel_noise, "seed": seed, "files": files_key(folders),
            "seconds": time.perf_counter() - t0, "history": hist}
    save_weights(out, net, "mnet", extra=info)
    return info


def add_goal_train_commands(train_sub: argparse._SubParsersAction) -> None:
    """`graspkit train gnet` and `graspkit train mnet` (subcommands of `graspkit train`)."""
    from pathlib import Path

    from graspkit.paths import DATA_STUBS

    for name, variants, default_epochs in (("gnet", ("gnet", "smplx"), 60), ("mnet", tuple(MNET_VARIANTS), 20)):
        p = train_sub.add_parser(name, help=f"train GOAL's {name[0].upper() + name[1:].replace('net', 'Net')} "
                                 "(or an ablation) on the synthetic grasp data")
        p.add_argument("--data", type=Path, action="append", default=None,
                       help="folder with grasp_*.npz / approach_*.npz (repeatable; default: the data-make cache)")
        p.add_argument("--variant", choices=variants, default=variants[0])
        p.add_argument("--out", type=Path, default=None, help=f"shipped weights (default data_stubs/checkpoints/"
                       f"{name}.pt, {name}_<variant>.pt for another --variant)")
        p.set_defaults(out_is_file=True)
        p.add_argument("--epochs", type=int, default=default_epochs)
        p.add_argument("--time-limit", type=positive_float, default=600.0, help=TIME_LIMIT_HELP + " (default 600)")
        p.add_argument("--seed", type=int, default=0)
        p.add_argument("--threads", type=int, default=2)
        if name == "gnet":
            p.add_argument("--kl", type=nonneg_float, default=None, help="λ_KL of Eq. 3 (default GNetLossWeights.kl)")
        else:
            p.add_argument("--goal-repeat", type=count_type(1), default=4,
                           help="times the windows near the goal frame are shown")
            p.add_argument("--vel-noise", type=nonneg_float, default=0.005,
                           help="m/frame of noise on the input velocities")
        p.set_defaults(func=lambda a, name=name: _cmd_train(a, name, DATA_STUBS / "checkpoints"))


def _cmd_train(args, name: str, stubs) -> int:
    """Run one training command and print where the weights went."""
    folders = args.data or default_data_folders()
    suffix = "" if args.variant == name else f"_{args.variant}"
    out = args.out or stubs / f"{name}{suffix}.pt"
    if name == "gnet":
        info = run_train_gnet(folders, out, args.variant, args.epochs, args.time_limit, args.seed, args.threads,
                              kl=args.kl)
    else:
        info = run_train_mnet(folders, out, args.variant, args.epochs, args.time_limit, args.seed, args.threads,
                              goal_repeat=args.goal_repeat, vel_noise=args.vel_noise)
    print(f"wrote {out}: {info['epochs']} epochs in {info['seconds']:.0f} s; last loss {info['history'][-1]['loss']:.4f}")
    return 0


# ------------------------------------------------------------------------------------------- Tab. 1: GNet grasps

def object_mesh_world(seq: GraspSequence, frame: int = 0) -> trimesh.Trimesh:
    """The sequence's catalogue object as a trimesh at its pose at `frame`."""
    from graspkit.objects.catalogue import make_object
    from graspkit.objects.placement import ObjectPose, apply_pose

    return apply_pose(ObjectPose(seq.object_transl[frame].astype(np.float64), seq.object_rotation()[frame]),
                      make_object(seq.object_name))


def _grasp_row(bm, rot6d: Tensor, transl: Tensor, betas: Tensor, meshes: list) -> list[dict[str, float]]:
    """graspkit.metrics.grasp_metrics of each body (full mesh) against its object mesh."""
    from graspkit.metrics import grasp_metrics

    with torch.no_grad():
        v = bm.forward_rotmats(pose_rotmats(rot6d), betas=betas, transl=transl).vertices
    rows = []
    for b in range(len(v)):
        m = grasp_metrics(v[b].double(), bm.faces, meshes[b])
        m["feet_cm"] = 100.0 * float(v[b, :, 2].min())
        rows.append(m)
    return rows


def posed_sdfs(seqs: list, frames: list[int], R: Tensor, o: Tensor) -> PosedSDF:
    """GraspRefiner's PosedSDF for sequences' objects at `frames` in GNet's frames (x' = R (x - o); R (B,3,3), o (B,3)),
    from each object's collision grid (graspkit.data.grasp_io.collision_sdf_grid, cached on disk)."""
    from graspkit.data.grasp_io import collision_sdf_grid
    from graspkit.optim.goal_refine import PosedSDF

    grids = {n: collision_sdf_grid(n) for n in sorted({s.object_name for s in seqs})}
    Ro = torch.stack([torch.as_tensor(s.object_rotation()[f]) for s, f in zip(seqs, frames)]).float()
    to = torch.stack([torch.as_tensor(np.asarray(s.object_transl[f])) for s, f in zip(seqs, frames)]).float()
    return PosedSDF.in_frame([grids[s.object_name] for s in seqs], Ro, to, R, o)


def gnet_table(gnet: GNet, baseline: GNet | None, seqs: list, seed: int = 0,
               refine_weights: GraspRefineWeights | None = None, penetration: bool = False,
               pen_weights: GraspRefineWeights | None = None, rows: tuple[str, ...] | None = None) -> dict:
    """GOAL Tab. 1 on grasps `seqs` (one GNet sample per ground-truth grasp, same object pose, start and body shape),
    in GNet's frame: {row: {'volume_cm3', 'contact_ratio', 'depth_cm', 'feet_cm', 'n'}}, per-grasp metrics and bodies
    under 'samples', the refinement's energies under 'refine_history'. With `penetration`, also the row PEN_ROW:
    the same samples refined with graspkit's E_pen (`pen_weights`, default goal_refine.PEN_WEIGHTS). `rows` (names
    in TAB1_ROWS; None: all) measures only those, and always 'GNet w/o opt', the paired counts' reference."""
    from graspkit.optim.goal_refine import PEN_WEIGHTS, GraspRefiner

    bad = sorted(set(rows or ()) - set(TAB1_ROWS))
    if bad:
        raise ValueError(f"rows: expected names in {TAB1_ROWS}, got {bad}")
    want = set(TAB1_ROWS if rows is None else rows) | {"GNet w/o opt"}

    bm, gv, _ = _body()
    gt = gnet_samples(seqs, accepted_only=False)
    frames = grasp_frames(seqs)
    meshes = []
    for b, (s, f) in enumerate(zip(seqs, frames)):
        m = object_mesh_world(s, f)
        T = np.eye(4)
        T[:3, :3] = gt["R"][b].double().numpy()
        T[:3, 3] = -T[:3, :3] @ gt["o"][b].double().numpy()
        m.apply_transform(T)
        meshes.append(m)
    z = torch.randn(len(seqs), gnet.cfg.latent, generator=torch.Generator().manual_seed(seed))
    hat = gnet.sample(gt["bps"], gt["obj_transl"], gt["betas"], z=z)
    refiner = GraspRefiner(bm, gv)
    bodies, history = {"GNet w/o opt": (hat["rot6d"], hat["transl"])}, []
    if "GNet" in want:
        refined = refiner(hat, gt["betas"], gt["points"], refine_weights)
        bodies["GNet"], history = (refined.rot6d, refined.transl), refined.history
    if penetration and PEN_ROW in want:
        pen = refiner(hat, gt["betas"], gt["points"], pen_weights or PEN_WEIGHTS,
                      sdf=posed_sdfs(seqs, frames, gt["R"], gt["o"]))
        bodies[PEN_ROW] = (pen.rot6d, pen.transl)
    if "synthetic GT" in want:
        bodies["synthetic GT"] = (gt["rot6d"], gt["transl"])
    if baseline is not None and "GrabNet-SMPL-X" in want:
        b = baseline.sample(gt["bps"], gt["obj_transl"], gt["betas"], z=z)
        bodies = {"GrabNet-SMPL-X": (b["rot6d"], b["transl"]), **bodies}
    table, samples = {}, {}
    for name, body in bodies.items():
        rows = _grasp_row(bm, body[0], body[1], gt["betas"], meshes)
        samples[name] = {"rows": rows, "rot6d": body[0], "transl": body[1]}
        vol = np.array([r["volume_cm3"] for r in rows])
        table[name] = {"volume_cm3": float(vol.mean()), "volume_median_cm3": float(np.median(vol)),
                       "volume_p90_cm3": float(np.percentile(vol, 90)),
                       "contact_ratio": float(np.mean([r["contact"] for r in rows])),
                       "depth_cm": float(np.mean([r["depth_cm"] for r in rows])),
                       "feet_cm": float(np.mean([abs(r["feet_cm"]) for r in rows])), "n": len(rows)}
    raw = np.array([r["volume_cm3"] for r in samples["GNet w/o opt"]["rows"]])
    paired: dict[str, int] = {}
    for name, key in (("GNet", "refined"), (PEN_ROW, "pen")):
        if name in samples:
            v = np.array([r["volume_cm3"] for r in samples[name]["rows"]])
            paired.update({f"{key}_lower": int((v < raw).sum()), f"{key}_higher": int((v > raw).sum())})
    paired["n"] = len(raw)
    return {"table": table, "samples": samples, "refine_history": history, "hat": hat, "gt": gt,
            "meshes": meshes, "paired": paired}


# ------------------------------------------------------------------------------------------- rollouts, foot sliding

def full_vertices(bm: BodyModel, rot6d: Tensor, transl: Tensor, betas: Tensor, chunk: int = 64) -> Tensor:
    """Full SMPL-X meshes (T,V,3) of a sequence (T,55,6), (T,3) with shape betas (10,)."""
    out = []
    with torch.no_grad():
        for i in range(0, len(rot6d), chunk):
            r = rot6d[i:i + chunk]
            out.append(bm.forward_rotmats(pose_rotmats(r), betas=betas.reshape(1, -1).expand(len(r), -1),
                                          transl=transl[i:i + chunk]).vertices)
    return torch.cat(out)


def sliding(vertices: Tensor) -> tuple[int, int]:
    """(sliding frames, frame pairs) by GOAL's §4.2 definition (graspkit.metrics.foot_sliding_goal)."""
    from graspkit.metrics import foot_sliding_goal

    s = foot_sliding_goal(vertices)
    return int(s.sum()), int(len(s))


def rollout_eval(mnet: MNet, clips: list, goals: list | None = None, max_frames: int = 300, refine: bool = True,
                 floor: float | None = 0.0, stall: int | None = STALL_FRAMES) -> dict:
    """MNet rollouts from each clip's first frame to its goal grasp (or to `goals[i]` = (rot6d, transl)): per clip the
    frames, whether the goal was reached, the final mean hand-to-goal distance, GOAL's foot sliding and how deep the
    lowest vertex goes under the floor z = 0 (cm). `floor` and `stall`: `mnet.rollout`'s floor step and stall rule
    (graspkit's; None: GOAL's rollout as the paper has it)."""
    from graspkit.metrics import ground_penetration
    from graspkit.models.mnet import rollout
    from graspkit.objects.bps import bps_basis

    bm, _, body = _body()
    basis = bps_basis()
    per, slide, pairs = [], 0, 0
    rolls = []
    for i, c in enumerate(clips):
        goal = goals[i] if goals is not None else (c.rot6d[c.goal_frame], c.transl[c.goal_frame])
        r = rollout(mnet, body, (c.rot6d[0], c.transl[0]), goal, c.betas, c.object_points, c.obj_centre, basis,
                    max_frames=max_frames, refine=refine, floor=floor, stall=stall)
        v = full_vertices(bm, r.rot6d, r.transl, c.betas)
        s, n = sliding(v)
        slide, pairs = slide + s, pairs + n
        per.append({"frames": len(r.rot6d), "reached": r.reached, "final_hand_cm": 100 * float(r.hand_dist[-1]),
                    "first_refined": r.first_refined, "gt_frames": c.goal_frame + 1, "sliding": s / max(n, 1),
                    "below_floor_max_cm": 100 * float(ground_penetration(v).max())})
        rolls.append(r)
    return {"clips": per, "rollouts": rolls, "sliding": slide / max(pairs, 1),
            "reached": float(np.mean([p["reached"] for p in per])),
            "final_hand_cm": float(np.mean([p["final_hand_cm"] for p in per]))}


def clip_sliding(clips: list, until_goal: bool = True) -> float:
    """GOAL's foot sliding of the ground-truth clips (frames up to the goal frame, or all)."""
    bm, _, _ = _body()
    slide, pairs = 0, 0
    for c in clips:
        stop = c.goal_frame + 1 if until_goal else len(c.rot6d)
        s, n = sliding(full_vertices(bm, c.rot6d[:stop], c.transl[:stop], c.betas))
        slide, pairs = slide + s, pairs + n
    return slide / max(pairs, 1)


def saga_sliding(seqs: list, seed: int = 0, progress: bool = False, **saga_kwargs: Any) -> dict:
    """SAGA's motions (graspkit.saga.synthesize: WholeGrasp + GraspPose-Opt, MotionFill + GraspMotion-Opt) for GRAB-style
    approach sequences: each sequence's object where it stands and its first frame as the start body (in the grasp's
    shape, standing where it stood: `saga.reshaped_in_place`); GOAL's foot sliding over the 61 frames, the end
    grasp's contact and the share of frames standing more than 1 cm above the floor (`metrics.floating_share`).
    Returns the pooled sliding, per-sequence figures (their mean contact and floating share too) and the
    SagaResults ('results'); saga_kwargs go to synthesize (e.g. fewer optimiser steps; hold_start defaults to False
    here: the shipped row is Alg. 2's fit, measured before `synthesize` held frame 0 at the start body)."""
    from graspkit.body import BodyModel
    from graspkit.data.motion import Motion
    from graspkit.metrics import floating_share
    from graspkit.objects.placement import ObjectPose
    from graspkit.paths import default_model_path
    from graspkit.rotations import axis_angle_to_rot6d
    from graspkit.saga import synthesize

    bm, _, _ = _body()                                   # flat hand mean: SAGA's motions carry absolute hand poses
    saga_bm = BodyModel.from_file(default_model_path())  # GraspPose-Opt's hand PCA is about the mean hand
    saga_kwargs.setdefault("hold_start", False)
    per, results, slide, pairs = [], [], 0, 0
    for k, sq in enumerate(seqs):
        pose = ObjectPose(np.asarray(sq.object_transl[0], np.float64), np.asarray(sq.object_rotation()[0], np.float64))
        start = Motion(np.asarray(sq.poses[:1], np.float64), np.asarray(sq.trans[:1], np.float64),
                       np.asarray(sq.betas[:10], np.float64), 30.0)
        r = synthesize(sq.object_name, saga_bm, pose, start, seed=seed + k, progress=progress, **saga_kwargs)
        m = r.motion
        results.append(r)
        v = full_vertices(bm, axis_angle_to_rot6d(torch.as_tensor(m.poses)).float(), torch.as_tensor(m.trans).float(),
                          torch.as_tensor(m.betas[:10]).float())
        n_s, n = sliding(v)
        slide, pairs = slide + n_s, pairs + n
        per.append({"object": sq.object_name, "frames": m.num_frames, "sliding": n_s / max(n, 1),
                    "end_contact": r.metrics["end_contact"], "end_volume_cm3": r.metrics["end_volume_cm3"],
                    "floating": floating_share(v)})
    mean = lambda k: float(np.mean([p[k] for p in per])) if per else float("nan")  # noqa: E731
    return {"sliding": slide / max(pairs, 1), "per_clip": per, "results": results, "end_contact": mean("end_contact"),
            "floating": mean("floating")}


def rollout_sequences(folders: Sequence[str | Path], n_rollouts: int) -> list:
    """The test approach sequences of the rollout evaluation: accepted, starting 0.5-1.5 m from the object, n of them
    taken in turn from each test object (file order within an object)."""
    seqs = [s for s in _all_files(folders, "approach", "test") if bool(s.extras.get("grasp.accepted", True))]
    keep = [s for s, c in zip(seqs, approach_clips(seqs)) if 0.5 <= start_distance(c) <= 1.5]
    by_object: dict[str, list] = {}
    for s in keep:
        by_object.setdefault(s.object_name, []).append(s)
    turns = [s for group in zip_longest(*by_object.values()) for s in group if s is not None]
    return turns[:n_rollouts]


# ------------------------------------------------------------------------------------------- the whole evaluation

def start_distance(clip: ApproachClip) -> float:
    """Horizontal distance (m) from the clip's first pelvis position to the object centre."""
    bm, _, _ = _body()
    from graspkit.models.mnet import rest_root

    pelvis = rest_root(bm, clip.betas.reshape(1, -1))[0] + clip.transl[0]
    return float((pelvis[:2] - clip.obj_centre[:2]).norm())


def evaluate(folders: Sequence[str | Path] | None = None, stubs: str | Path | None = None, n_grasps: int = 60,
             n_rollouts: int = 24, window_stride: int = 5, seed: int = 0, out: str | Path | None = None,
             max_frames: int = 300, progress: bool = True) -> dict:
    """GOAL Tab. 1, Tab. 2 and foot sliding on the test objects with the shipped checkpoints (MNet's rollouts up to
    `max_frames` each); written as JSON. `progress`: a bar over the four phases (minutes each at the defaults)."""
    from pathlib import Path

    from tqdm.auto import tqdm

    from graspkit.models.gnet import load_gnet
    from graspkit.paths import DATA_STUBS, write_json
    from graspkit.progress import hidden

    folders = folders or default_data_folders()
    stubs = Path(stubs or DATA_STUBS / "checkpoints")
    with tqdm(total=4, desc="GOAL eval", unit="phase", disable=hidden(progress)) as bar:
        bar.set_postfix_str("Tab. 1: GNet samples, refined")
        res: dict = {"paper": {"tab1": PAPER_TAB1, "tab2": PAPER_TAB2, "sliding": PAPER_SLIDING},
                     "config": {"n_grasps": n_grasps, "n_rollouts": n_rollouts, "window_stride": window_stride,
                                "seed": seed, "max_frames": max_frames, "threads": torch.get_num_threads()}}
        res.update(tab1_results(folders, stubs, n_grasps, seed))
        bar.update()
        bar.set_postfix_str("Tab. 2: MNet, teacher-forced")
        res.update(tab2_results(folders, stubs, window_stride))
        bar.update()
        bar.set_postfix_str("rollouts: MNet from the clips' starts")
        seqs = rollout_sequences(folders, n_rollouts)
        res.update(rollout_results(seqs, stubs, load_gnet(stubs / "gnet.pt"), seed, max_frames))
        out = Path(out or stubs / "goal_eval.json")
        write_json(out, res)                   # GOAL's tables first: SAGA's row takes minutes
        bar.update()
        bar.set_postfix_str("SAGA's rows: synthesize per clip")
        write_json(out, add_saga_rows(res, seqs, seed))
        bar.update()
    return res


def rollout_results(seqs: list, stubs: str | Path, gnet: GNet, seed: int = 0, max_frames: int = 300) -> dict:
    """The rollout part of the evaluation on `rollout_sequences`: MNet (stubs/mnet.pt) from each test clip's start
    (0.5-1.5 m from the object) to the true goal grasp and to GNet's grasp, up to `max_frames` each, with the floor
    step and stall rule of `rollout_eval`. {'rollouts', 'sliding' (GOAL's rows and the ground truth's),
    'rollout_seconds'}."""
    import time
    from pathlib import Path

    from graspkit.models.mnet import load_mnet

    t0 = time.perf_counter()
    clips = approach_clips(seqs)
    mnet = load_mnet(Path(stubs) / "mnet.pt")
    to_gt = rollout_eval(mnet, clips, max_frames=max_frames)
    full = rollout_eval(mnet, clips, _gnet_goals(gnet, clips, seed), max_frames=max_frames)
    keys = ("sliding", "reached", "final_hand_cm")
    return {"rollouts": {"clips": len(clips), "max_frames": max_frames, "to_true_goal": {k: to_gt[k] for k in keys},
                         "goal_pipeline": {k: full[k] for k in keys},
                         "per_clip_true_goal": to_gt["clips"], "per_clip_pipeline": full["clips"]},
            "sliding": {"GOAL (GNet + MNet, ours)": full["sliding"], "MNet to the true goal": to_gt["sliding"],
                        "synthetic GT (approach frames)": clip_sliding(clips)},
            "rollout_seconds": time.perf_counter() - t0}


TAB2_ROWS = {"mnet.pt": "MNet", "mnet_no_iaa.pt": "MNet-w/o-IAA", "mnet_pose.pt": "MNet-Pose",
             "mnet_1frame.pt": "1 output frame"}   # GOAL Tab. 2's rows and the checkpoint each is measured with


def tab2_results(folders: Sequence[str | Path], stubs: str | Path, window_stride: int = 5) -> dict:
    """Tab. 2: the teacher-forced 10-frame errors of MNet and of each ablation found in `stubs` (mnet.pt,
    mnet_<variant>.pt) on every `window_stride`-th window of the test clips. {'tab2', 'tab2_windows', 'tab2_seconds'}."""
    import time
    from pathlib import Path

    from graspkit.models.mnet import MNetConfig, load_mnet

    t0 = time.perf_counter()
    bm, _, _ = _body()
    windows = mnet_windows(folders, "test", MNetConfig(), stride=window_stride)
    idx = torch.arange(len(windows))
    tab2 = {}
    for file, name in TAB2_ROWS.items():
        if (Path(stubs) / file).is_file():
            e = teacher_forced_v2v(load_mnet(Path(stubs) / file), windows, bm, idx)
            tab2[name] = {"body": e.body, "hand": e.hand, "feet": e.feet}
    return {"tab2": tab2, "tab2_windows": len(idx), "tab2_seconds": time.perf_counter() - t0}


def tab1_results(folders: Sequence[str | Path], stubs: str | Path, n_grasps: int = 60, seed: int = 0,
                 penetration: bool = True, rows: tuple[str, ...] | None = None) -> dict:
    """Tab. 1 with the checkpoints in `stubs`: one sample per accepted test grasp of `folders` (n_grasps of them drawn
    with `seed`; 0: every one); `rows` as gnet_table. {'tab1', 'tab1_paired', 'tab1_refine_energy', 'tab1_seconds'}
    ('tab1_refine_energy' only when the row 'GNet' was measured)."""
    import time
    from pathlib import Path

    from graspkit.models.gnet import load_gnet

    t0 = time.perf_counter()
    tests = [s for s in _all_files(folders, "grasp", "test") + _all_files(folders, "approach", "test")
             if bool(s.extras.get("grasp.accepted", True))]
    if not tests:
        raise ValueError(f"folders: no accepted test grasps in {[str(f) for f in folders]}")
    n = len(tests) if n_grasps <= 0 else n_grasps
    pick = sorted(seeded_rng(seed).permutation(len(tests))[:n].tolist())
    gnet = load_gnet(Path(stubs) / "gnet.pt")
    base = load_gnet(Path(stubs) / "gnet_smplx.pt") if (Path(stubs) / "gnet_smplx.pt").is_file() else None
    tab1 = gnet_table(gnet, base, [tests[i] for i in pick], seed=seed, penetration=penetration, rows=rows)
    out = {"tab1": tab1["table"], "tab1_paired": tab1["paired"], "tab1_seconds": time.perf_counter() - t0}
    if "GNet" in tab1["table"]:
        out["tab1_refine_energy"] = tab1["refine_history"]
    return out


def gnet_goal(gnet: GNet, start: tuple[Tensor, Tensor], betas: Tensor, object_points: Tensor, obj_centre: Tensor,
              z: Tensor | None = None, generator: torch.Generator | None = None,
              refine_weights: GraspRefineWeights | None = None,
              sdf: tuple | None = None, model: str | Path | None = None) -> tuple[Tensor, Tensor, dict]:
    """GOAL's first stage for one start pose (rot6d (55,6), transl (3,)) and object (points (P,3), centre (3,)) in the
    world: GNet's frame from the start pelvis to the object, a sample, the refinement (Eq. 4-8), back to the world.
    With `sdf` = (SDFGrid in the mesh's frame, the object's world rotation (3,3), translation (3,)) the refinement
    adds graspkit's E_pen (weights default goal_refine.PEN_WEIGHTS). `model`: the SMPL-X .npz the grasp is refined on
    (default graspkit's body); the betas are that body's.
    Returns the goal grasp's rot6d (55,6), transl (3,) and {'hat', 'refined', 'R', 'o'} (GNet's frame)."""
    from graspkit.models.mnet import _invert, rest_root, transform_params, transform_points
    from graspkit.objects.bps import bps_basis
    from graspkit.optim.goal_refine import PEN_WEIGHTS, GraspRefiner, PosedSDF

    bm, gv, _ = _body(model)
    b = betas.reshape(1, -1).float()
    root = rest_root(bm, b)
    R, o = gnet_frame((root[0] + start[1].float())[None, :2], obj_centre.reshape(1, 3).float())
    pts = transform_points(object_points.reshape(1, -1, 3).float(), R, o)
    c = transform_points(obj_centre.reshape(1, 1, 3).float(), R, o)[:, 0]
    hat = gnet.sample(kd_bps(pts - c[:, None], bps_basis()), c, b, generator=generator, z=z)
    posed = None
    if sdf is not None:
        grid, Ro, to = sdf
        posed = PosedSDF.in_frame([grid], torch.as_tensor(Ro).reshape(1, 3, 3), torch.as_tensor(to).reshape(1, 3), R, o)
        refine_weights = refine_weights or PEN_WEIGHTS
    ref = GraspRefiner(bm, gv)(hat, b, pts, refine_weights, sdf=posed)
    Ri, oi = _invert(R, o)
    r6, t = transform_params(ref.rot6d, ref.transl, root, Ri, oi)
    return r6[0], t[0], {"hat": hat, "refined": ref, "R": R, "o": o}


def add_saga_rows(res: dict, seqs: list, seed: int = 0) -> dict:
    """Put SAGA's foot sliding on the rollout sequences (`saga_sliding`) into an evaluation result, in place."""
    import time

    t = time.perf_counter()
    saga = saga_sliding(seqs, seed)
    res["sliding"]["SAGA (WholeGrasp + MotionFill, ours)"] = saga["sliding"]
    res["saga"] = {"per_clip": saga["per_clip"], "end_contact": saga["end_contact"], "floating": saga["floating"],
                   "seconds": time.perf_counter() - t}
    return res


def _gnet_goals(gnet, clips: list, seed: int) -> list:
    """GNet + refinement grasps (rot6d, transl) in the world for each clip's start, object and body (one sample each)."""
    g = torch.Generator().manual_seed(seed + 1)
    return [gnet_goal(gnet, (c.rot6d[0], c.transl[0]), c.betas, c.object_points, c.obj_centre, generator=g)[:2]
            for c in clips]


@reports_errors("python -m graspkit.eval_goal")
def main(argv: list[str] | None = None) -> int:
    """`python -m graspkit.eval_goal [--data DIR ...] [--checkpoints DIR] [--out FILE] [--n-grasps N] [--n-rollouts N]`."""
    import argparse
    import json
    from pathlib import Path

    p = argparse.ArgumentParser(prog="python -m graspkit.eval_goal", description=evaluate.__doc__)
    p.add_argument("--data", type=Path, action="append", default=None, help="grasp/approach folders (repeatable)")
    p.add_argument("--checkpoints", type=Path, default=None, help="gnet.pt, gnet_smplx.pt, mnet[_variant].pt")
    p.add_argument("--out", type=Path, default=None, help="JSON (default <checkpoints>/goal_eval.json)")
    p.add_argument("--n-grasps", type=int, default=60, help="test grasps for Tab. 1 (0: every one)")
    p.add_argument("--n-rollouts", type=int, default=24)
    p.add_argument("--max-frames", type=int, default=300, help="the longest MNet rollout (frames, 30 fps)")
    p.add_argument("--window-stride", type=int, default=5)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--tab1-row", action="append", default=None, choices=TAB1_ROWS, metavar="ROW",
                   help=f"with --tab1-only: recompute only this row of Tab. 1 (repeatable; one of {TAB1_ROWS}); "
                        "'GNet w/o opt' is always measured, the others are kept")
    only = p.add_mutually_exclusive_group()
    only.add_argument("--tab1-only", action="store_true",
                      help="recompute only Tab. 1 in an existing JSON (--n-grasps 0: every test grasp)")
    only.add_argument("--saga-only", action="store_true",
                      help="add only SAGA's foot-sliding row to an existing JSON (the same rollout sequences)")
    only.add_argument("--rollouts-only", action="store_true",
                      help="recompute only the MNet rollouts and GOAL's sliding rows in an existing JSON (SAGA's kept)")
    only.add_argument("--tab2-only", action="store_true",
                      help="recompute only Tab. 2's rows of the MNet checkpoints in --checkpoints (mnet.pt, "
                           "mnet_<variant>.pt) in an existing JSON; the other rows are kept")
    a = p.parse_args(argv)
    refuse_folder_out(argv)
    expand_user_paths(a)
    if a.tab1_row and not a.tab1_only:
        raise ValueError("--tab1-row: only with --tab1-only (it names a row of Tab. 1 to measure again)")
    check_counts(a, n_grasps=0, n_rollouts=1, max_frames=2, window_stride=1, threads=1, seed=0)
    check_folders(a.data)
    if a.out is not None:
        check_out(a.out, is_file=True)                # before any work
    torch.set_num_threads(a.threads)
    if a.tab1_only or a.saga_only or a.rollouts_only or a.tab2_only:     # update one part of an existing evaluation
        from graspkit.paths import DATA_STUBS, write_json

        stubs = Path(a.checkpoints or DATA_STUBS / "checkpoints")
        out = Path(a.out or stubs / "goal_eval.json")
        flag = ("--tab1-only" if a.tab1_only else "--saga-only" if a.saga_only else
                "--tab2-only" if a.tab2_only else "--rollouts-only")
        if not out.is_file():
            raise FileNotFoundError(f"--out: no evaluation at {out} to update (run without {flag})")
        try:                                            # read now: the update is written after minutes of work
            r = json.loads(out.read_text())
        except ValueError as e:
            raise ValueError(f"--out: {out} is not a JSON file to update ({e})") from None
        merged = ("sliding", "tab1", "tab1_paired", "tab2", "rollouts", "saga")   # the parts an update reads or replaces
        bad = ("it is no JSON object" if not isinstance(r, dict) else
               "it has no 'sliding' rows" if a.saga_only and "sliding" not in r else
               next((f"its '{k}' is no object" for k in merged if k in r and not isinstance(r[k], dict)),
                    "its 'updates' is no list" if not isinstance(r.get("updates", []), list) else None))
        if bad:
            raise ValueError(f"--out: {out} is not a GOAL evaluation to update with {flag} ({bad}); run without {flag}")
        folders = a.data or default_data_folders()
        if a.tab1_only:
            new = tab1_results(folders, stubs, a.n_grasps, a.seed, rows=tuple(a.tab1_row) if a.tab1_row else None)
            if a.tab1_row:                                      # merge into the table and paired counts kept
                for k in ("tab1", "tab1_paired"):
                    new[k] = {**r.get(k, {}), **new[k]}
                new["tab1_seconds_rows"] = new.pop("tab1_seconds")
            r.update(new)
            shown = {k: r[k] for k in ("tab1", "tab1_paired")}
        elif a.tab2_only:
            if not any((stubs / f).is_file() for f in TAB2_ROWS):
                raise FileNotFoundError(f"--checkpoints: none of {list(TAB2_ROWS)} in {stubs} to measure Tab. 2 with")
            new = tab2_results(folders, stubs, a.window_stride)
            new["tab2"] = {**r.get("tab2", {}), **new["tab2"]}      # a variant without its checkpoint keeps its row
            r.update(new)
            shown = {"tab2": r["tab2"]}
        elif a.rollouts_only:
            from graspkit.models.gnet import load_gnet

            new = rollout_results(rollout_sequences(folders, a.n_rollouts), stubs, load_gnet(stubs / "gnet.pt"), a.seed,
                                  a.max_frames)
            new["sliding"].update({k: v for k, v in r.get("sliding", {}).items() if k not in new["sliding"]})
            r.update(new)
            shown = {"sliding": r["sliding"], **{k: r["rollouts"][k] for k in ("to_true_goal", "goal_pipeline")}}
        else:
            r = add_saga_rows(r, rollout_sequences(folders, a.n_rollouts), a.seed)
            shown = {"sliding": r["sliding"], "saga_end_contact": r["saga"]["end_contact"],
                     "saga_floating": r["saga"]["floating"]}
        r.setdefault("updates", []).append({"flag": flag, "n_grasps": a.n_grasps, "n_rollouts": a.n_rollouts,
                                            "seed": a.seed, "max_frames": a.max_frames,
                                            "window_stride": a.window_stride,
                                            "threads": torch.get_num_threads()})     # what changed the file since
        write_json(out, r)
        print(json.dumps(shown, indent=1))
        return 0
    r = evaluate(a.data, a.checkpoints, a.n_grasps, a.n_rollouts, a.window_stride, a.seed, a.out, a.max_frames)
    print(json.dumps({k: r[k] for k in ("tab1", "tab2", "sliding")}, indent=1, default=float))
    return 0


if __name__ == "__main__":
    import sys

    sys.exit(main())
