"""Rotation helpers (numpy, batched over leading dims) and analytic two-bone inverse kinematics.

Two-bone IK (hip-knee-ankle, shoulder-elbow-wrist) is solved in closed form: the law of cosines gives
the angle at the root joint, the pole vector picks the plane in which the middle joint bends, and each
bone's global rotation maps its rest frame (bone direction, bend direction) onto the posed one. With
rest bones that are almost collinear, the middle joint's local rotation is then a hinge about the
plane normal, as a knee or an elbow should be.
"""
from __future__ import annotations

import numpy as np

_EPS = 1e-9


def normalize(v: np.ndarray) -> np.ndarray:
    """Unit vectors (..., 3); zero vectors stay zero."""
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.maximum(n, _EPS)


def axis_rotation(axis: int, angle: np.ndarray | float) -> np.ndarray:
    """Rotations about coordinate axis 0/1/2 (x/y/z) by angles (...) in radians -> (..., 3, 3)."""
    a = np.asarray(angle, np.float64)
    c, s = np.cos(a), np.sin(a)
    R = np.zeros(a.shape + (3, 3))
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    R[..., axis, axis] = 1.0
    R[..., i, i], R[..., i, j], R[..., j, i], R[..., j, j] = c, -s, s, c
    return R


def rot_x(a: np.ndarray | float) -> np.ndarray: return axis_rotation(0, a)  # noqa: E704
def rot_y(a: np.ndarray | float) -> np.ndarray: return axis_rotation(1, a)  # noqa: E704
def rot_z(a: np.ndarray | float) -> np.ndarray: return axis_rotation(2, a)  # noqa: E704


def axis_angle_matrix(aa: np.ndarray) -> np.ndarray:
    """Rodrigues: axis-angle (..., 3) -> (..., 3, 3)."""
    aa = np.asarray(aa, np.float64)
    th = np.linalg.norm(aa, axis=-1)[..., None, None]
    k = aa / np.maximum(th[..., 0], _EPS)
    K = np.zeros(aa.shape + (3,))
    K[..., 0, 1], K[..., 0, 2], K[..., 1, 2] = -k[..., 2], k[..., 1], -k[..., 0]
    K = K - np.swapaxes(K, -1, -2)
    return np.eye(3) + np.sin(th) * K + (1 - np.cos(th)) * (K @ K)


def matrix_axis_angle(R: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) -> axis-angle (..., 3), via the quaternion (stable near 0 and pi)."""
    R = np.asarray(R, np.float64)
    tr = R[..., 0, 0] + R[..., 1, 1] + R[..., 2, 2]
    # Shepperd: pick the largest of 4 candidate quaternion components for stability
    cand = np.stack([tr, R[..., 0, 0], R[..., 1, 1], R[..., 2, 2]], -1)
    k = np.argmax(cand, -1)
    q = np.zeros(R.shape[:-2] + (4,))
    m = lambda a, b: R[..., a, b]  # noqa: E731
    for case in range(4):
        sel = k == case
        if not sel.any():
            continue
        if case == 0:
            r = np.sqrt(np.maximum(1 + tr, _EPS)) * 2
            qq = [0.25 * r, (m(2, 1) - m(1, 2)) / r, (m(0, 2) - m(2, 0)) / r, (m(1, 0) - m(0, 1)) / r]
        elif case == 1:
            r = np.sqrt(np.maximum(1 + m(0, 0) - m(1, 1) - m(2, 2), _EPS)) * 2
            qq = [(m(2, 1) - m(1, 2)) / r, 0.25 * r, (m(0, 1) + m(1, 0)) / r, (m(0, 2) + m(2, 0)) / r]
        elif case == 2:
            r = np.sqrt(np.maximum(1 - m(0, 0) + m(1, 1) - m(2, 2), _EPS)) * 2
            qq = [(m(0, 2) - m(2, 0)) / r, (m(0, 1) + m(1, 0)) / r, 0.25 * r, (m(1, 2) + m(2, 1)) / r]
        else:
            r = np.sqrt(np.maximum(1 - m(0, 0) - m(1, 1) + m(2, 2), _EPS)) * 2
            qq = [(m(1, 0) - m(0, 1)) / r, (m(0, 2) + m(2, 0)) / r, (m(1, 2) + m(2, 1)) / r, 0.25 * r]
        q[sel] = np.stack(qq, -1)[sel]
    q = q * np.where(q[..., :1] < 0, -1.0, 1.0)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    s = np.linalg.norm(q[..., 1:], axis=-1)
    angle = 2 * np.arctan2(s, q[..., 0])
    scale = np.where(s > 1e-12, angle / np.maximum(s, 1e-12), 2.0)
    return q[..., 1:] * scale[..., None]


def frame(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Orthonormal frames (..., 3, 3) with columns (a, b', a x b'), b' = b made perpendicular to a."""
    a = normalize(a)
    b = normalize(b - (b * a).sum(-1, keepdims=True) * a)
    return np.stack([a, b, np.cross(a, b)], -1)


def two_bone_ik(root: np.ndarray, target: np.ndarray, pole: np.ndarray, bone1: np.ndarray, bone2: np.ndarray,
                bend: np.ndarray, max_stretch: float = 0.9995, soft: float = 0.0
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Global rotations of both bones and the middle-joint position for a chain root -> mid -> end.

    root, target, pole (..., 3): world root position, wanted end position, direction the middle joint
    should bend towards (not parallel to target - root, and target not at root: a ValueError names them, the
    bend plane being undefined there); bone1, bone2 (3,) or (..., 3): rest vectors root->mid and mid->end;
    bend (3,): rest direction in which the middle joint moves when the chain flexes (knee: forward, elbow: backward).
    Returns R1, R2 (..., 3, 3) (rest -> posed, global) and mid (..., 3). A target beyond
    max_stretch * (l1 + l2) (or closer than |l1 - l2|) is reached as far as the chain allows. soft > 0: the last
    soft * (l1 + l2) before full stretch is approached exponentially (the end stops short of the target there). The
    bend grows as the square root of the distance short of full stretch, so with a hard limit a target sweeping in
    from beyond reach bends the middle joint tens of degrees in one frame; the soft limit bends it gradually.
    """
    l1, l2 = np.linalg.norm(bone1, axis=-1), np.linalg.norm(bone2, axis=-1)
    d_vec = target - root
    d = np.linalg.norm(d_vec, axis=-1)
    reach = max_stretch * (l1 + l2)
    if soft > 0:
        w = soft * (l1 + l2)
        d = np.where(d > reach - w, reach - w * np.exp(-np.maximum(d - reach + w, 0.0) / w), d)
    d_cl = np.clip(d, np.abs(l1 - l2) + 1e-6, reach)
    if (np.linalg.norm(d_vec, axis=-1) < 1e-9).any():
        raise ValueError("target: expected a target away from root (the reach direction is undefined there)")
    ahat = normalize(d_vec)
    cos_a = np.clip((l1**2 + d_cl**2 - l2**2) / (2 * l1 * d_cl), -1.0, 1.0)      # law of cosines at the root
    p_perp = pole - (pole * ahat).sum(-1, keepdims=True) * ahat
    if (np.linalg.norm(p_perp, axis=-1) <= 1e-9 * np.linalg.norm(pole, axis=-1)).any():
        raise ValueError("pole: expected a direction not parallel to target - root (the bend plane is undefined)")
    p_perp = normalize(p_perp)
    mid = root + l1[..., None] * (cos_a[..., None] * ahat + np.sqrt(1 - cos_a**2)[..., None] * p_perp)
    end = root + d_cl[..., None] * ahat
    rest1, rest2 = frame(np.broadcast_to(bone1, mid.shape), np.broadcast_to(bend, mid.shape)), \
        frame(np.broadcast_to(bone2, mid.shape), np.broadcast_to(bend, mid.shape))
    R1 = frame(mid - root, p_perp) @ np.swapaxes(rest1, -1, -2)
    R2 = frame(end - mid, p_perp) @ np.swapaxes(rest2, -1, -2)
    return R1, R2, mid


def smoothstep(u: np.ndarray | float) -> np.ndarray | float:
    """Minimum-jerk ramp 10u^3 - 15u^4 + 6u^5 on [0, 1] (clipped outside): zero velocity and acceleration at both ends."""
    u = np.clip(u, 0.0, 1.0)
    return u**3 * (10 - 15 * u + 6 * u**2)


def wrap_angle(a: np.ndarray | float) -> np.ndarray | float:
    """Angles wrapped to (-pi, pi]."""
    return np.pi - np.mod(np.pi - np.asarray(a, np.float64), 2 * np.pi)
