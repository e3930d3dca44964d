"""Basis Point Set encoding (Prokudin, Lassner & Romero, ICCV 2019), as GOAL uses it (Sec. 3.3-3.4, Eq. 2 and 9).

A fixed set of K basis points sampled uniformly in a ball (GOAL: K = 1024; the radius is graspkit's, 0.15 m
around the object centre, as the paper gives none) encodes a point cloud by, for each basis point, the distance
to its nearest cloud point (and optionally the offset vector to it). GOAL encodes the object (b^o) and the
goal-frame hand (b_g^h) with the SAME basis, so the two codes share one frame: express both clouds in the object
frame first.
"""
from __future__ import annotations

import numpy as np
import torch
from torch import Tensor

from graspkit.objects.distance import as_points, nearest_neighbours


def bps_basis(n: int = 1024, radius: float = 0.15, seed: int = 0, dtype: torch.dtype = torch.float32) -> Tensor:
    """n basis points (n,3) uniform in the ball of `radius` metres about the origin; same seed -> same points."""
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n <= 0:
        raise ValueError(f"n: expected a positive whole number of basis points, got {n!r}")
    if not (isinstance(radius, (int, float, np.number)) and np.isfinite(radius) and radius > 0):
        raise ValueError(f"radius: expected a positive finite radius in metres, got {radius!r}")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:   # None would draw a new
        raise ValueError(f"seed: expected a non-negative integer (the basis is fixed), got {seed!r}")  # basis per call
    rng = np.random.default_rng(seed)
    direction = rng.standard_normal((n, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    r = radius * rng.random(n) ** (1.0 / 3.0)  # P(r < s) = (s / R)^3: uniform in volume
    return torch.as_tensor(direction * r[:, None], dtype=dtype)


def bps_encode(points: Tensor | np.ndarray, basis: Tensor,
               return_deltas: bool = False) -> Tensor | tuple[Tensor, Tensor]:
    """BPS code of point clouds (N,3)|(B,N,3): distances (B,K) from each basis point to its nearest point.

    With return_deltas, also the offsets (B,K,3) = nearest point - basis point. Differentiable w.r.t.
    the points. Unbatched input gives (K,) and (K,3).
    """
    pts = as_points(points, "points")
    if pts.dim() > 3:
        raise ValueError(f"points: expected (N, 3) or (B, N, 3), got {tuple(pts.shape)}")
    b = as_points(basis, "basis").to(pts.dtype)
    if b.dim() != 2:
        raise ValueError(f"basis: expected (K, 3), got {tuple(b.shape)}")
    p3 = pts if pts.dim() == 3 else pts[None]
    dist, idx = nearest_neighbours(b[None].expand(len(p3), -1, -1), p3)
    if pts.dim() == 2:
        dist, idx = dist[0], idx[0]
    if not return_deltas:
        return dist
    nearest = torch.gather(p3, 1, idx.reshape(len(p3), -1, 1).expand(-1, -1, 3)) - b
    return dist, nearest if pts.dim() == 3 else nearest[0]
