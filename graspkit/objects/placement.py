"""Rigid object poses and SAGA's random test placement (SAGA Sec. 4.3, "Experiment setup").

SAGA places each unseen object in front of the human at a height of 0.5-1.7 m, with a random
orientation of 0-360 deg about the gravity axis, 5 cm-1.1 m from the start point. World frame: z up,
metres. A pose maps object-frame coordinates to the world: x_world = R @ x_obj + t.
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass
from typing import TypeVar, overload

import numpy as np
import torch
import trimesh
from torch import Tensor

from graspkit.checks import GraspkitWarning, seeded_rng, user_stacklevel

Array = TypeVar("Array", np.ndarray, Tensor)


@dataclass(frozen=True, eq=False)
class ObjectPose:
    """A rigid pose: translation (3,) and rotation (3,3), both float64; x_world = rotation @ x_obj + translation."""

    translation: np.ndarray
    rotation: np.ndarray

    def __post_init__(self) -> None:
        t = np.asarray(self.translation, dtype=np.float64)
        r = np.asarray(self.rotation, dtype=np.float64)
        if t.shape != (3,) or not np.isfinite(t).all():
            raise ValueError(f"translation: expected 3 finite numbers, got shape {t.shape}")
        if r.shape != (3, 3) or not np.allclose(r @ r.T, np.eye(3), atol=1e-6) or np.linalg.det(r) < 0:
            raise ValueError("rotation: expected a proper 3x3 rotation matrix (orthonormal, det +1)")
        object.__setattr__(self, "translation", t)
        object.__setattr__(self, "rotation", r)

    @staticmethod
    def identity() -> ObjectPose:
        """The pose that leaves everything in place."""
        return ObjectPose(np.zeros(3), np.eye(3))

    @staticmethod
    def from_yaw(yaw: float, translation: np.ndarray | tuple[float, float, float]) -> ObjectPose:
        """Rotation by `yaw` radians about the world z (gravity) axis, then translation."""
        c, s = np.cos(yaw), np.sin(yaw)
        return ObjectPose(np.asarray(translation, dtype=np.float64), np.array([[c, -s, 0.0], [s, c, 0.0], [0, 0, 1]]))

    def matrix(self) -> np.ndarray:
        """The 4x4 homogeneous transform."""
        out = np.eye(4)
        out[:3, :3], out[:3, 3] = self.rotation, self.translation
        return out

    def inverse(self) -> ObjectPose:
        """The pose that undoes this one: x_obj = R^T (x_world - t)."""
        return ObjectPose(-self.rotation.T @ self.translation, self.rotation.T.copy())

    def compose(self, other: ObjectPose) -> ObjectPose:
        """self after other: x -> R_s (R_o x + t_o) + t_s."""
        return ObjectPose(self.rotation @ other.translation + self.translation, self.rotation @ other.rotation)


GRASP_HEIGHTS = (0.5, 1.7)   # m: object-centre heights of graspkit's grasp and approach data (sample_object_pose)


def sample_object_pose(
    rng: np.random.Generator | int,
    height_range: tuple[float, float] = GRASP_HEIGHTS,
    yaw_range_deg: tuple[float, float] = (0.0, 360.0),
    distance_range: tuple[float, float] = (0.05, 1.1),
    bearing_range_deg: tuple[float, float] = (-30.0, 30.0),
    start: tuple[float, float] = (0.0, 0.0),
    facing_deg: float = -90.0,
) -> ObjectPose:
    """A random object pose in front of a person standing at `start` (x, y) and facing `facing_deg` (SAGA Sec. 4.3).

    The object centre is at horizontal distance U(distance_range) from `start`, in the direction
    facing + U(bearing_range_deg) degrees (measured from +x towards +y), at height U(height_range); the
    object is rotated by U(yaw_range_deg) degrees about z. The default facing, -y (-90 deg), is where
    SMPL-X's forward (+z) points under the root rotation R_x(+90 deg) that takes the y-up body into the
    z-up world (R_x(90) maps y -> z and z -> -y); pass the person's actual heading. The bearing spread
    ("in front of") is our choice: the paper does not give one.
    """
    for name, (lo, hi) in [("height_range", height_range), ("yaw_range_deg", yaw_range_deg),
                           ("distance_range", distance_range), ("bearing_range_deg", bearing_range_deg)]:
        if not (np.isfinite(lo) and np.isfinite(hi) and lo <= hi):
            raise ValueError(f"{name}: expected finite (low, high) with low <= high, got {(lo, hi)}")
    if distance_range[0] < 0:
        raise ValueError(f"distance_range: distances must be >= 0, got {distance_range}")
    if not (isinstance(rng, np.random.Generator)
            or (isinstance(rng, (int, np.integer)) and not isinstance(rng, bool) and rng >= 0)):
        raise ValueError(f"rng: expected a numpy Generator or a non-negative integer seed, got {rng!r}")
    rng = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
    dist = rng.uniform(*distance_range)
    bearing = np.deg2rad(facing_deg + rng.uniform(*bearing_range_deg))
    height = rng.uniform(*height_range)
    yaw = np.deg2rad(rng.uniform(*yaw_range_deg))
    t = np.array([start[0] + dist * np.cos(bearing), start[1] + dist * np.sin(bearing), height])
    return ObjectPose.from_yaw(yaw, t)


FLOOR_TOLERANCE = 0.002   # m: an object placed lower than this under the floor (z = 0) sinks into it


def floor_note(pose: ObjectPose, mesh: trimesh.Trimesh) -> str | None:
    """A note when the mesh at `pose` reaches more than FLOOR_TOLERANCE under the floor z = 0 (a centre above the
    floor does not make the object so: an upright 18 cm capsule centred 5 cm up sinks 4 cm), else None."""
    lowest = float(apply_pose(pose, mesh).bounds[0, 2])
    if lowest >= -FLOOR_TOLERANCE:
        return None
    return (f"object_pose: the object reaches {-100 * lowest:.1f} cm under the floor (z = 0): its lowest point is "
            f"{float(pose.translation[2]) - lowest:.3f} m below its centre, so a centre at least that high keeps it "
            "on or above the floor")


def warn_floor(pose: ObjectPose, mesh: trimesh.Trimesh) -> None:
    """floor_note as a GraspkitWarning (saga.synthesize, goal.synthesize and data.grasp.sample_grasp_task with a given
    pose: the run goes on)."""
    note = floor_note(pose, mesh)
    if note:
        warnings.warn(note, GraspkitWarning, stacklevel=user_stacklevel())


def within_reach_pose(seed: int) -> ObjectPose:
    """The object pose `graspkit.saga.synthesize` and `graspkit.goal.synthesize` draw when none is given:
    `sample_object_pose(seed)` at heights 0.6-1.2 m and 0.5-0.8 m in front of a person at the origin facing -y."""
    return sample_object_pose(seeded_rng(seed), height_range=(0.6, 1.2), distance_range=(0.5, 0.8))


@overload
def apply_pose(pose: ObjectPose, x: trimesh.Trimesh, normals: None = None) -> trimesh.Trimesh: ...
@overload
def apply_pose(pose: ObjectPose, x: Array, normals: None = None) -> Array: ...
@overload
def apply_pose(pose: ObjectPose, x: Array, normals: Array) -> tuple[Array, Array]: ...


def apply_pose(pose: ObjectPose, x: trimesh.Trimesh | np.ndarray | Tensor,
               normals: np.ndarray | Tensor | None = None
               ) -> trimesh.Trimesh | np.ndarray | Tensor | tuple[np.ndarray | Tensor, np.ndarray | Tensor]:
    """Move a mesh (copy), or points (..., 3) [and their normals (..., 3)] by `pose`; normals rotate only.

    numpy (or a list) in -> numpy float64 out, torch in -> torch out (same dtype/device, differentiable; an integer
    tensor comes out in the default float dtype).
    """
    if isinstance(x, trimesh.Trimesh):
        if normals is not None:
            raise ValueError("normals: pass normals with a point array, not with a mesh (a mesh carries its own)")
        out = x.copy()
        out.apply_transform(pose.matrix())
        return out
    pts = _transform(x, pose.rotation, pose.translation, "x")
    if normals is None:
        return pts
    nrm = _transform(normals, pose.rotation, None, "normals")
    if nrm.shape != pts.shape:
        raise ValueError(f"normals: expected the shape of the points {tuple(pts.shape)}, got {tuple(nrm.shape)}")
    return pts, nrm


def _transform(x: Array, rot: np.ndarray, trans: np.ndarray | None, name: str) -> Array:
    """x @ R^T (+ t) for numpy arrays (float64) or torch tensors (their dtype; integer ones the default float dtype) of
    shape (..., 3)."""
    if isinstance(x, Tensor) and not x.is_floating_point():
        x = x.to(torch.get_default_dtype())             # else the pose would be cast to integers: zeros
    elif not isinstance(x, Tensor):
        try:
            x = np.asarray(x, dtype=np.float64)
        except (TypeError, ValueError):
            raise ValueError(f"{name}: expected an array of numbers of shape (..., 3), got {type(x).__name__}") from None
    if x.shape[-1:] != (3,):
        raise ValueError(f"{name}: expected shape (..., 3), got {tuple(x.shape)}")
    if isinstance(x, Tensor):
        r = torch.as_tensor(rot, dtype=x.dtype, device=x.device)
        out = x @ r.T
        return out if trans is None else out + torch.as_tensor(trans, dtype=x.dtype, device=x.device)
    out = x @ rot.T
    return out if trans is None else out + trans
