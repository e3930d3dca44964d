"""Motion: one SMPL-X sequence in the z-up world (AMASS convention), plus what graspkit's generators know.

`poses` are absolute local rotations (the hand mean is NOT added, as in AMASS files), so the body is
`bm.forward_rotmats(axis_angle_to_matrix(poses), betas, transl=trans)` or equivalently a BodyModel /
smplx model built with flat_hand_mean=True.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Iterator

import numpy as np
import torch

from graspkit.body.skeleton import JOINT_INDEX, NUM_JOINTS
from graspkit.checks import check_finite
from graspkit.rotations import axis_angle_to_matrix

if TYPE_CHECKING:
    from graspkit.body import BodyModel

CONTACT_NAMES = ("left_heel", "left_toe", "right_heel", "right_toe")
HANDS = ("right", "left")


def check_fps(fps: object, name: str = "fps", where: str = "") -> float:
    """fps as a float after checking it is a finite frame rate > 0 (TypeError / ValueError naming `name`; `where`
    ends the message, e.g. ' to read <file>')."""
    if isinstance(fps, bool) or not isinstance(fps, (int, float, np.integer, np.floating)):
        raise TypeError(f"{name}: expected a number (frames per second){where}, got {type(fps).__name__}")
    if not (np.isfinite(fps) and fps > 0):
        raise ValueError(f"{name}: expected a finite positive frame rate{where}, got {fps!r}")
    return float(fps)


@dataclass
class Motion:
    """poses (T,55,3) or (T,165) axis-angle, trans (T,3) (one frame too: poses[None], trans[None]; finite), betas
    (10,), fps; contacts (T,4) bool [l heel, l toe, r heel, r toe]; for reaching clips the goal (3,) (world, m), the
    frame goal_frame at which `hand`'s wrist is on it (a floor goal: the wrist FLOOR_WRIST, scaled with the body,
    above it). Other layouts are refused by name (a reshape would scramble a (3, T) translation into frames)."""

    poses: np.ndarray
    trans: np.ndarray
    betas: np.ndarray
    fps: float = 30.0
    contacts: np.ndarray | None = None
    goal: np.ndarray | None = None
    goal_frame: int | None = None
    hand: str | None = None
    gender: str = "neutral"

    def __post_init__(self) -> None:
        poses, trans = np.asarray(self.poses, np.float32), np.asarray(self.trans, np.float32)
        # only the documented layouts: a reshape would take a (3, T) translation or (55, 3, T) poses as scrambled frames
        if not (poses.ndim == 3 and poses.shape[1:] == (NUM_JOINTS, 3) or poses.ndim == 2
                and poses.shape[1] == 3 * NUM_JOINTS):
            raise ValueError(f"poses: expected (T, {NUM_JOINTS}, 3) or (T, {3 * NUM_JOINTS}) axis-angle (SMPL-X; one "
                             f"frame: poses[None]), got shape {poses.shape} (load_motion converts SMPL-H files)")
        if trans.ndim != 2 or trans.shape[1] != 3:
            raise ValueError(f"trans: expected (T, 3) translations in metres (one frame: trans[None]), got shape "
                             f"{trans.shape}")
        check_finite(poses, "poses", "axis-angle rotations in radians")
        check_finite(trans, "trans", "translations in metres")
        self.poses, self.trans = poses.reshape(-1, NUM_JOINTS, 3), trans
        b = np.asarray(self.betas, np.float32)
        if b.ndim > 1 and b.shape[0] != 1:              # (1, K) is one body's; (2, 10) would read as 20 coefficients
            raise ValueError(f"betas: expected one body's shape coefficients (K,), got shape {b.shape}")
        self.betas = b.reshape(-1)
        T = len(self.poses)
        if T == 0:                                      # duration, slices and exports all need a frame
            raise ValueError("poses: expected at least one frame, got 0 (T = 0)")
        self.fps = check_fps(self.fps)
        if len(self.trans) != T:
            raise ValueError(f"trans: {len(self.trans)} frames, poses has {T}")
        if self.contacts is not None:
            self.contacts = np.asarray(self.contacts, bool)
            if self.contacts.shape != (T, 4):
                raise ValueError(f"contacts: expected shape ({T}, 4), got {self.contacts.shape}")
        if self.goal is not None:
            self.goal = np.asarray(self.goal, np.float32).reshape(3)
            gf = np.asarray(self.goal_frame)                  # an int, or a 0-d integer array read from a file
            if gf.ndim != 0 or gf.dtype.kind not in "iu" or not 0 <= int(gf) < T:
                raise ValueError(f"goal_frame: expected a whole frame in [0, {T}) with a goal, got {self.goal_frame!r}")
            self.goal_frame = int(gf)
            if self.hand not in HANDS:
                raise ValueError(f"hand: expected one of {HANDS}, got {self.hand!r}")
        elif self.goal_frame is not None or self.hand is not None:
            raise ValueError(f"goal_frame, hand: given ({self.goal_frame!r}, {self.hand!r}) without a goal; a Motion "
                             "keeps them only with its goal (3,)")

    @property
    def num_frames(self) -> int:
        return len(self.poses)

    @property
    def duration(self) -> float:
        """Seconds from the first to the last frame."""
        return (self.num_frames - 1) / self.fps

    def slice(self, start: int, stop: int | None = None) -> "Motion":
        """Frames [start, stop) as a new Motion (goal_frame shifted; the goal dropped if it falls outside); an empty
        range is refused, as the constructor refuses T = 0 (named by start and stop here)."""
        sl = slice(start, stop)
        goal, gf, hand = self.goal, self.goal_frame, self.hand
        first, last, _ = sl.indices(self.num_frames)       # a negative start counts from the end, as numpy's
        n = len(range(first, last))
        if n == 0:
            raise ValueError(f"start, stop: frames [{start}, {stop}) of {self.num_frames} hold no frame")
        if gf is not None:
            gf = gf - first
            if not 0 <= gf < n:
                goal, gf, hand = None, None, None
        return replace(self, poses=self.poses[sl], trans=self.trans[sl],
                       contacts=None if self.contacts is None else self.contacts[sl], goal=goal, goal_frame=gf, hand=hand)

    def rotmats(self, dtype: torch.dtype = torch.float32) -> torch.Tensor:
        """Local rotation matrices (T,55,3,3)."""
        return axis_angle_to_matrix(torch.as_tensor(self.poses, dtype=dtype))

    def joint_positions(self, bm: BodyModel) -> np.ndarray:
        """World joint positions (T,55,3) by joints-only forward kinematics on `bm`."""
        coeffs = torch.zeros(1, bm.num_betas + bm.num_expression, dtype=bm.dtype)
        coeffs[0, :min(bm.num_betas, len(self.betas))] = torch.as_tensor(self.betas[:bm.num_betas], dtype=bm.dtype)
        with torch.no_grad():
            _, J = bm.shaped(coeffs)
            _, t = bm.global_transforms(self.rotmats(bm.dtype), J.expand(self.num_frames, -1, -1))
        return (t + torch.as_tensor(self.trans, dtype=bm.dtype)[:, None]).numpy()

    def vertices(self, bm: BodyModel, start: int = 0, stop: int | None = None) -> torch.Tensor:
        """Mesh vertices (n,V,3) of frames [start, stop) on `bm` (hand mean not added)."""
        sl = slice(start, stop)
        rot = self.rotmats(bm.dtype)[sl]
        betas = torch.as_tensor(self.betas[None, :bm.num_betas], dtype=bm.dtype)
        with torch.no_grad():
            return bm.forward_rotmats(rot, betas=betas, transl=torch.as_tensor(self.trans[sl], dtype=bm.dtype)).vertices

    def iter_vertices(self, bm: BodyModel, chunk: int = 64, overlap: int = 0) -> Iterator[tuple[int, torch.Tensor]]:
        """(first frame, vertices (n,V,3)) for consecutive chunks of frames; chunks share `overlap` frames."""
        for name, value in (("chunk", chunk), ("overlap", overlap)):
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
                raise TypeError(f"{name}: expected an integer, got {type(value).__name__}")
        if overlap < 0:
            raise ValueError(f"overlap: expected an integer >= 0, got {overlap}")
        if chunk <= overlap:
            raise ValueError(f"chunk: expected an integer > overlap ({overlap}), got {chunk}")
        return self._chunks(bm, int(chunk), int(overlap))

    def _chunks(self, bm, chunk: int, overlap: int) -> Iterator[tuple[int, torch.Tensor]]:
        """The generator behind iter_vertices (arguments checked)."""
        start = 0
        while start < self.num_frames:
            stop = min(start + chunk, self.num_frames)
            yield start, self.vertices(bm, start, stop)
            if stop == self.num_frames:
                break
            start = stop - overlap


def restand(motion: Motion, bm_from: BodyModel, bm_to: BodyModel, betas: np.ndarray | None = None) -> Motion:
    """The motion's poses on another body: model bm_to (it was made on bm_from) and `betas` (default: its own), every
    frame moved by one shift that keeps frame 0's pelvis joint x, y and its lowest vertex's height (a body standing on
    the floor stays on it). Keeping the translation instead floats or sinks a body of other legs by the difference."""
    first = motion.slice(0, 1)
    new = Motion(first.poses, first.trans, first.betas if betas is None else np.asarray(betas, np.float64), motion.fps)
    shift = np.zeros(3)
    shift[:2] = first.joint_positions(bm_from)[0, 0, :2] - new.joint_positions(bm_to)[0, 0, :2]
    shift[2] = float(first.vertices(bm_from)[0, :, 2].min() - new.vertices(bm_to)[0, :, 2].min())
    return replace(motion, trans=motion.trans + shift, betas=new.betas)


def heading_of(global_orient: np.ndarray) -> np.ndarray:
    """Facing direction (radians from world +x) of root orientations (T,3): the canonical +z axis projected on the ground."""
    R = axis_angle_to_matrix(torch.as_tensor(np.asarray(global_orient, np.float64))).numpy()
    f = R[..., :, 2]
    return np.arctan2(f[..., 1], f[..., 0])


def canonicalize(joints: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """SAGA A.3 clip frame for world joints (T,55,3): origin at the first-frame pelvis, x the horizontal
    left->right shoulder direction, y forward, z up. Returns the rotation (3,3) and origin (3,) (x' = R (x - o))."""
    o = joints[0, JOINT_INDEX["pelvis"]].copy()
    x = joints[0, JOINT_INDEX["right_shoulder"]] - joints[0, JOINT_INDEX["left_shoulder"]]
    x[2] = 0.0
    x /= np.linalg.norm(x)
    z = np.array([0.0, 0.0, 1.0])
    y = np.cross(z, x)
    return np.stack([x, y, z]), o
