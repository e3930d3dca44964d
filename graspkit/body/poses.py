"""A few named example poses, written joint by joint in the SMPL-X canonical frame (y up, facing +z, left = +x).

Each local rotation is an axis-angle in its parent's rest frame. Rules of thumb for this frame:
left arm lowered = shoulder about -z, right arm lowered = about +z; elbow flexion = about -y (left) / +y (right);
hip flexion (thigh forward) = about -x; knee flexion = about +x; bending the spine forward = about +x.
"""
from __future__ import annotations

import torch

from graspkit.body.skeleton import JOINT_INDEX, NUM_BODY_JOINTS

POSES: dict[str, dict[str, tuple[float, float, float]]] = {
    "t_pose": {},
    "a_pose": {"left_shoulder": (0, 0, -1.1), "right_shoulder": (0, 0, 1.1)},
    "walk": {"left_hip": (-0.45, 0, 0), "right_hip": (0.3, 0, 0), "left_knee": (0.25, 0, 0), "right_knee": (0.5, 0, 0),
             "left_shoulder": (0.3, 0, -1.25), "right_shoulder": (-0.3, 0, 1.25),
             "left_elbow": (0, -0.3, 0), "right_elbow": (0, 0.3, 0)},
    "squat": {"left_hip": (-1.6, 0, -0.15), "right_hip": (-1.6, 0, 0.15), "left_knee": (1.9, 0, 0), "right_knee": (1.9, 0, 0),
              "left_ankle": (-0.45, 0, 0), "right_ankle": (-0.45, 0, 0), "spine1": (0.35, 0, 0),
              "left_shoulder": (0, -0.9, -0.4), "right_shoulder": (0, 0.9, 0.4)},
    "reach_high": {"right_shoulder": (0, 0, -1.1), "right_elbow": (0, 0.15, 0), "left_shoulder": (0, 0, -1.2),
                   "spine2": (-0.1, 0, 0), "head": (-0.3, 0, 0)},
    "bend_pick": {"spine1": (0.5, 0, 0), "spine2": (0.3, 0, 0), "spine3": (0.2, 0, 0), "left_hip": (-0.3, 0, 0),
                  "right_hip": (-0.3, 0, 0), "left_knee": (0.5, 0, 0), "right_knee": (0.5, 0, 0),
                  "right_shoulder": (0, -1.0, 1.3), "left_shoulder": (0, 0, -1.2)},
}


def body_pose(name: str, dtype: torch.dtype = torch.float32) -> torch.Tensor:
    """The named pose as SMPL-X `body_pose` (1, 63) axis-angle; unknown name -> ValueError listing the names."""
    if name not in POSES:
        raise ValueError(f"name: unknown pose {name!r}; expected one of {sorted(POSES)}")
    pose = torch.zeros(NUM_BODY_JOINTS + 1, 3, dtype=dtype)
    for joint, aa in POSES[name].items():
        pose[JOINT_INDEX[joint]] = torch.tensor(aa, dtype=dtype)
    return pose[1:].reshape(1, -1)


def y_up_to_z_up(dtype: torch.dtype = torch.float32) -> torch.Tensor:
    """global_orient (1, 3): +90 deg about x, turning the canonical y-up body into the z-up world (it then faces -y)."""
    return torch.tensor([[torch.pi / 2, 0.0, 0.0]], dtype=dtype)
