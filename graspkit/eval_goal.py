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

from dataclasses import dataclass

import numpy as np
import torch
from torch import Tensor

from graspkit.models.gnet import pose_rotmats
from graspkit.models.mnet import MNet, MNetWindows, predict_horizon

PAPER_TAB1 = {  # GOAL Tab. 1: penetration volume (cm^3), contact ratio
    "GrabNet [57]": (2.65, 1.00), "GrabNet-SMPL-X": (7.33, 0.87), "GNet w/o opt": (5.32, 0.87),
    "GNet": (2.22, 1.00), "GRAB (GT)": (1.95, 1.00)}
PAPER_TAB2 = {  # GOAL Tab. 2: V2V (mm) body, hand, feet
    "MNet-Pose": (22.0, 30.2, 10.4), "MNet-Marker [67]": (21.1, 30.1, 9.8), "MNet-w/o-IAA": (21.0, 29.1, 10.5),
    "MNet": (19.7, 28.0, 9.9), "1 output frame": (26.7, 35.7, 17.9), "10 output frames": (19.7, 28.0, 9.9)}
PAPER_SLIDING = {"GOAL": 0.137, "GRAB (GT)": 0.067}


def part_vertex_ids(bm, joints: tuple[str, ...]) -> np.ndarray:
    """Vertex ids whose dominant skinning joint is one of `joints`."""
    from graspkit.body.skeleton import JOINT_INDEX

    part = bm.lbs_weights.argmax(1).numpy()
    return np.flatnonzero(np.isin(part, [JOINT_INDEX[j] for j in joints]))


def right_hand_ids(bm) -> np.ndarray:
    """Vertices of the right hand (wrist and fingers)."""
    from graspkit.body.skeleton import FINGERS

    return part_vertex_ids(bm, ("right_wrist",) + tuple(f"right_{f}{k}" for f in FINGERS for k in (1, 2, 3)))


def feet_ids(bm) -> np.ndarray:
    """Vertices of both feet (ankles and toes)."""
    return part_vertex_ids(bm, ("left_ankle", "right_ankle", "left_foot", "right_foot"))


@dataclass
class V2V:
    """Mean vertex-to-vertex errors in millimetres over the whole body, the right hand and the feet."""

    body: float
    hand: float
    feet: float


@torch.no_grad()
def teacher_forced_v2v(mnet: MNet, windows: MNetWindows, bm, index: Tensor, horizon: int = 10, chunk: int = 32) -> V2V:
    """Tab. 2 protocol: from the true past 5 frames of windows `index`, predict `horizon` frames (one step of a
    10-frame MNet, ten autoregressive steps of a 1-frame one, no refinement), build the SMPL-X meshes of the predicted
    and true frames, and average the per-vertex distances (mm) over the body, the right hand and the feet."""
    mnet.eval()
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
