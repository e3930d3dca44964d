"""Rig: what the motion generators need to know about one body (a model and its betas).

Everything is measured on the shaped rest mesh in the SMPL-X canonical frame (y up, facing +z, left
= +x): rest joints, bone vectors, the sole height, and per foot the points that the foot pivots about
(heel at heel strike, ball joint at toe-off) plus a few sole points that must clear the ground in swing.
`R_BASE` turns the canonical frame into the z-up world facing +x, as an AMASS root orientation does.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import torch

from graspkit.body.markers import foot_vertices
from graspkit.body.skeleton import JOINT_INDEX

if TYPE_CHECKING:
    from graspkit.body import BodyModel

J = JOINT_INDEX
# canonical x (left) -> world +y, canonical y (up) -> world +z, canonical z (forward) -> world +x
R_BASE = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
SIDES = ("left", "right")


@dataclass(frozen=True)
class FootGeometry:
    """Canonical rest points of one foot (3,): ankle, ball (the foot joint), heel pivot, ground point under the ankle; sole points (K,3)."""

    ankle: np.ndarray
    ball: np.ndarray
    heel: np.ndarray
    ref: np.ndarray
    toe_tip: np.ndarray
    sole: np.ndarray


@dataclass(frozen=True)
class Rig:
    """Rest joints (55,3), sole height, per-side feet, and the body's scale relative to the 1.70 m reference."""

    joints: np.ndarray
    sole_y: float
    feet: dict[str, FootGeometry]
    height: float

    @property
    def leg_length(self) -> float:
        """Hip -> knee -> ankle length (m) of the left leg."""
        j = self.joints
        return float(np.linalg.norm(j[J["left_knee"]] - j[J["left_hip"]]) + np.linalg.norm(j[J["left_ankle"]] - j[J["left_knee"]]))

    @property
    def arm_length(self) -> float:
        """Shoulder -> elbow -> wrist length (m) of the right arm."""
        j = self.joints
        return float(np.linalg.norm(j[J["right_elbow"]] - j[J["right_shoulder"]]) + np.linalg.norm(j[J["right_wrist"]] - j[J["right_elbow"]]))

    @property
    def pelvis_height(self) -> float:
        """Height of the pelvis joint above the soles when standing in the rest pose (m)."""
        return float(self.joints[0, 1] - self.sole_y)

    @property
    def scale(self) -> float:
        """Body height / 1.70 m."""
        return self.height / 1.70

    def bone(self, parent: str, child: str) -> np.ndarray:
        """Rest vector (3,) from joint `parent` to joint `child`."""
        return self.joints[J[child]] - self.joints[J[parent]]


def _foot(side: str, v: np.ndarray, joints: np.ndarray, weights: np.ndarray, soles: dict[str, np.ndarray],
          sole_y: float, strike_angle: float) -> FootGeometry:
    """The pivot and clearance points of one foot from the shaped rest mesh."""
    ankle, ball = joints[J[f"{side}_ankle"]], joints[J[f"{side}_foot"]]
    seg = np.argmax(weights, 1)
    rear = np.flatnonzero((seg == J[f"{side}_ankle"]) & (v[:, 2] < ankle[2]) & (v[:, 1] < ankle[1]))
    # heel pivot: the rear vertex that is lowest when the toes are raised by strike_angle (about canonical x)
    c, s = np.cos(strike_angle), np.sin(strike_angle)
    rel = v[rear] - ankle
    h = c * rel[:, 1] + s * rel[:, 2]  # y after raising the toes by strike_angle (about canonical -x)
    heel = v[rear[np.argmin(h)]].copy()
    sole_ids = np.concatenate([soles[f"{side}_heel"], soles[f"{side}_toe"]])
    sole = v[sole_ids]
    toe_tip = sole[np.argmax(sole[:, 2])].copy()
    # a handful of sole points spanning the foot (extremes and a grid along it) for swing clearance
    order = np.argsort(sole[:, 2])
    pick = order[np.linspace(0, len(order) - 1, 9).round().astype(int)]
    pts = np.concatenate([sole[pick], sole[[np.argmin(sole[:, 0]), np.argmax(sole[:, 0])]], toe_tip[None]])
    ref = np.array([ankle[0], sole_y, ankle[2]])
    return FootGeometry(ankle, ball, heel, ref, toe_tip, pts)


def _shaped(bm: BodyModel, betas: np.ndarray | torch.Tensor | None) -> tuple[np.ndarray, np.ndarray]:
    """Rest vertices (V,3) and joints (55,3) (float64) of `bm` for betas (K,) (None: zeros; zero-padded or cut to the
    model's, as BodyModel)."""
    b = torch.zeros(1, bm.num_betas, dtype=bm.dtype)
    if betas is not None:
        x = np.asarray(betas, np.float64).reshape(-1)[:bm.num_betas]
        if not np.isfinite(x).all():
            raise ValueError(f"betas: expected finite shape coefficients, got {x.tolist()}")
        b[0, :len(x)] = torch.as_tensor(x, dtype=bm.dtype)
    coeffs = torch.cat([b, torch.zeros(1, bm.num_expression, dtype=bm.dtype)], 1)
    with torch.no_grad():
        v, j = bm.shaped(coeffs)
    return v[0].double().numpy(), j[0].double().numpy()


def rest_joints(bm: BodyModel, betas: np.ndarray | torch.Tensor | None = None) -> np.ndarray:
    """The shaped rest joints (55,3) (float64) of `bm` for betas (K,) (None: zeros; padded or cut as build_rig)."""
    return _shaped(bm, betas)[1]


def check_rig(rig: Rig, bm: BodyModel, betas: np.ndarray | None) -> None:
    """ValueError naming `rig` unless it was built for this body (build_rig(bm, betas): its rest joints, to 0.1 mm)."""
    err = float(np.abs(rig.joints - rest_joints(bm, betas)).max())
    if err > 1e-4:
        raise ValueError(f"rig: built for another body (its rest joints are {100 * err:.1f} cm off those of bm with "
                         "the clip's betas: the ones given, or else the ones drawn from the seed); pass the same betas "
                         "to build_rig and here, or rig=None")


def build_rig(bm: BodyModel, betas: np.ndarray | torch.Tensor | None = None, strike_angle: float = 0.3) -> Rig:
    """Measure a Rig on model `bm` for betas (K,) (None: zeros; zero-padded or cut to the model's, as BodyModel)."""
    v, j = _shaped(bm, betas)
    weights = bm.lbs_weights.double().numpy()
    soles = foot_vertices(bm)
    sole_y = float(v[:, 1].min())
    feet = {s: _foot(s, v, j, weights, soles, sole_y, strike_angle) for s in SIDES}
    return Rig(j, sole_y, feet, float(v[:, 1].max() - sole_y))
