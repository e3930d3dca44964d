"""Batched, differentiable rotation conversions: axis-angle, rotation matrix, 6D and quaternion.

Conventions
- axis-angle: (..., 3), the rotation vector (unit axis times angle in radians).
- matrix: (..., 3, 3), rotating column vectors (x' = R x).
- quaternion: (..., 4) as (w, x, y, z), scalar first.
- 6D (Zhou et al., CVPR 2019): (..., 6) = the first two columns of R, concatenated [R[:, 0], R[:, 1]];
  back to R by Gram-Schmidt. Networks predict 6D; files store axis-angle; LBS uses matrices.

All functions are stable at angle 0 (Taylor terms instead of sin(x)/x) and near pi (axis from the
matrix through the quaternion, Shepperd's branch choice). Limits an independent check measured (2026-12-06), kept
because no caller meets them and a change would move every body's last bits: first derivatives only (the second
derivative of the conversions to axis-angle is NaN at the identity; nothing in graspkit differentiates twice), and
axis_angle_to_matrix's (1 - cos t) / t^2 loses digits for small t, so its float32 gradient there is good to ~1e-4
(float64: ~1e-12).
"""
from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import Tensor

_EPS = 1e-6


def _check_last(x: Tensor, shape: tuple[int, ...], name: str) -> None:
    """Raise a ValueError naming `name` when x's trailing dims are not `shape`."""
    if not isinstance(x, Tensor):
        raise TypeError(f"{name}: expected a torch.Tensor, got {type(x).__name__}")
    if tuple(x.shape[-len(shape):]) != shape or x.dim() < len(shape):
        raise ValueError(f"{name}: expected shape (..., {', '.join(map(str, shape))}), got {tuple(x.shape)}")


def _skew(v: Tensor) -> Tensor:
    """Cross-product matrices of vectors: (..., 3) -> (..., 3, 3)."""
    x, y, z = v.unbind(-1)
    o = torch.zeros_like(x)
    return torch.stack([o, -z, y, z, o, -x, -y, x, o], dim=-1).reshape(v.shape + (3,))


def axis_angle_to_matrix(aa: Tensor) -> Tensor:
    """Rodrigues' formula: axis-angle (..., 3) -> rotation matrices (..., 3, 3)."""
    _check_last(aa, (3,), "aa")
    theta2 = (aa * aa).sum(-1, keepdim=True)[..., None]  # (..., 1, 1)
    small = theta2 <= _EPS**2      # <=: in float16 _EPS**2 rounds to 0, and a zero angle must take the series
    theta2_safe = torch.where(small, torch.ones_like(theta2), theta2)
    theta = theta2_safe.sqrt()
    # sin(t)/t and (1-cos(t))/t^2, with their Taylor series near t = 0 (keeps gradients finite)
    a = torch.where(small, 1 - theta2 / 6, torch.sin(theta) / theta)
    b = torch.where(small, 0.5 - theta2 / 24, (1 - torch.cos(theta)) / theta2_safe)
    K = _skew(aa)
    eye = torch.eye(3, dtype=aa.dtype, device=aa.device).expand_as(K)
    return eye + a * K + b * (K @ K)


def quaternion_to_matrix(q: Tensor) -> Tensor:
    """Unit quaternions (w, x, y, z) (..., 4) -> rotation matrices (..., 3, 3). q is normalised first; a zero
    quaternion (no rotation defined) gives the identity."""
    _check_last(q, (4,), "q")
    w, x, y, z = F.normalize(q, dim=-1).unbind(-1)
    m = [
        1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
        2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
        2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y),
    ]
    return torch.stack(m, dim=-1).reshape(q.shape[:-1] + (3, 3))


def matrix_to_quaternion(R: Tensor) -> Tensor:
    """Rotation matrices (..., 3, 3) -> unit quaternions (w, x, y, z) (..., 4) with w >= 0.

    Shepperd's method: of the four candidate formulas, use the one with the largest
    denominator, so that no branch divides by a number near zero (angle near pi included).
    """
    _check_last(R, (3, 3), "R")
    m00, m01, m02 = R[..., 0, 0], R[..., 0, 1], R[..., 0, 2]
    m10, m11, m12 = R[..., 1, 0], R[..., 1, 1], R[..., 1, 2]
    m20, m21, m22 = R[..., 2, 0], R[..., 2, 1], R[..., 2, 2]
    # 4 * (w^2, x^2, y^2, z^2): the diagonal of the symmetric 4x4 form
    sq = torch.stack([1 + m00 + m11 + m22, 1 + m00 - m11 - m22,
                      1 - m00 + m11 - m22, 1 - m00 - m11 + m22], dim=-1)
    root = torch.sqrt(torch.clamp(sq, min=1e-12))  # 2|w|, 2|x|, 2|y|, 2|z|
    # each row: the quaternion times (2 * its largest component), from one branch
    cand = torch.stack([
        torch.stack([root[..., 0] ** 2, m21 - m12, m02 - m20, m10 - m01], -1),
        torch.stack([m21 - m12, root[..., 1] ** 2, m10 + m01, m02 + m20], -1),
        torch.stack([m02 - m20, m10 + m01, root[..., 2] ** 2, m12 + m21], -1),
        torch.stack([m10 - m01, m02 + m20, m12 + m21, root[..., 3] ** 2], -1),
    ], dim=-2) / (2 * root[..., :, None])
    best = sq.argmax(dim=-1)
    q = torch.gather(cand, -2, best[..., None, None].expand(best.shape + (1, 4))).squeeze(-2)
    q = F.normalize(q, dim=-1)
    return torch.where(q[..., :1] < 0, -q, q)


def quaternion_to_axis_angle(q: Tensor) -> Tensor:
    """Quaternions (w, x, y, z) (..., 4) -> axis-angle (..., 3), angle in [0, pi]."""
    _check_last(q, (4,), "q")
    q = F.normalize(q, dim=-1)
    q = torch.where(q[..., :1] < 0, -q, q)
    xyz = q[..., 1:]
    s = xyz.norm(dim=-1, keepdim=True)
    angle = 2 * torch.atan2(s, q[..., :1])
    small = s < _EPS
    # angle / sin(angle/2) -> 2 as s -> 0 (Taylor: 2 + s^2/3 for w ~ 1)
    factor = torch.where(small, 2 + s * s / 3, angle / torch.where(small, torch.ones_like(s), s))
    return xyz * factor


def axis_angle_to_quaternion(aa: Tensor) -> Tensor:
    """Axis-angle (..., 3) -> unit quaternions (w, x, y, z) (..., 4)."""
    _check_last(aa, (3,), "aa")
    theta2 = (aa * aa).sum(-1, keepdim=True)
    small = theta2 <= _EPS**2      # <=: in float16 _EPS**2 rounds to 0, and a zero angle must take the series
    theta = torch.where(small, torch.ones_like(theta2), theta2).sqrt()
    half_sinc = torch.where(small, 0.5 - theta2 / 48, torch.sin(theta / 2) / theta)
    w = torch.where(small, 1 - theta2 / 8, torch.cos(theta / 2))
    return torch.cat([w, aa * half_sinc], dim=-1)


def matrix_to_axis_angle(R: Tensor) -> Tensor:
    """Rotation matrices (..., 3, 3) -> axis-angle (..., 3), through the quaternion (stable near pi)."""
    return quaternion_to_axis_angle(matrix_to_quaternion(R))


def matrix_to_rot6d(R: Tensor) -> Tensor:
    """Rotation matrices (..., 3, 3) -> 6D (..., 6): first column then second column."""
    _check_last(R, (3, 3), "R")
    return torch.cat([R[..., :, 0], R[..., :, 1]], dim=-1)


def rot6d_to_matrix(d6: Tensor) -> Tensor:
    """6D (..., 6) -> rotation matrices (..., 3, 3) by Gram-Schmidt (Zhou et al. 2019, Sec. 4). Undefined where the
    two 3-vectors are parallel or zero (the result is then not a rotation, and rot6d_to_axis_angle reads it as the
    identity); near there rounding shows: in float32, |R^T R - I| is about 3e-7 / (the angle between them, rad), 3e-4
    at 1e-3 rad (float64 holds to 1e-9 rad). Networks' outputs come nowhere near; pass float64 for such inputs."""
    _check_last(d6, (6,), "d6")
    b1 = F.normalize(d6[..., :3], dim=-1)
    a2 = d6[..., 3:]
    b2 = F.normalize(a2 - (b1 * a2).sum(-1, keepdim=True) * b1, dim=-1)
    b3 = torch.cross(b1, b2, dim=-1)
    return torch.stack([b1, b2, b3], dim=-1)


def axis_angle_to_rot6d(aa: Tensor) -> Tensor:
    """Axis-angle (..., 3) -> 6D (..., 6)."""
    return matrix_to_rot6d(axis_angle_to_matrix(aa))


def rot6d_to_axis_angle(d6: Tensor) -> Tensor:
    """6D (..., 6) -> axis-angle (..., 3)."""
    return matrix_to_axis_angle(rot6d_to_matrix(d6))


def rotation_about_z(angle: Tensor | float) -> Tensor:
    """Rotations about the world's vertical z axis: angles (...) in radians (a tensor, or a number) -> (..., 3, 3)."""
    angle = angle if isinstance(angle, Tensor) else torch.as_tensor(angle, dtype=torch.get_default_dtype())
    c, s = torch.cos(angle), torch.sin(angle)
    o, i = torch.zeros_like(angle), torch.ones_like(angle)
    return torch.stack([c, -s, o, s, c, o, o, o, i], dim=-1).reshape(angle.shape + (3, 3))
