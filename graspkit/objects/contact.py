"""Contact maps (SAGA Sec. 3.2) and interaction-aware attention (GOAL Sec. 3.2, Eq. 1).

SAGA's WholeGrasp-VAE learns binary marker contacts C_M in {0,1}^N (body markers touching the object)
and object contacts C_O in {0,1}^2048 (object surface points touching the body). The paper gives no
distance threshold; graspkit uses
- MARKER_CONTACT_THRESHOLD = 2 cm between a marker and the object SURFACE (exact point-mesh
  distance). Markers are sparse skin points (a few cm apart); 2 cm accepts the markers of a finger
  or palm region that wraps the object while rejecting the back of the hand.
- OBJECT_CONTACT_THRESHOLD = 1 cm between an object point and the BODY SURFACE (exact distance to the
  body mesh, or to the nearest body vertex when no faces are given). The body surface is dense, so a
  tighter band marks the patch under the fingers and palm, not the gaps between them.
GOAL's attention I_w(d) = exp(-w d) uses w = 5 and d = the distance in metres from each body vertex to
the object (GOAL Sec. 3.2).
"""
from __future__ import annotations

import math
import numbers
from typing import TYPE_CHECKING

import torch
import trimesh
from torch import Tensor

from graspkit.objects.distance import MeshLike, as_points, nearest_neighbours, point_mesh_distance

if TYPE_CHECKING:
    import numpy as np

MARKER_CONTACT_THRESHOLD = 0.02  # m
OBJECT_CONTACT_THRESHOLD = 0.01  # m
IAA_WEIGHT = 5.0  # GOAL Eq. 1, w


def _check_threshold(threshold: float) -> None:
    """A contact threshold must be a finite distance >= 0 in metres; ValueError naming `threshold` otherwise."""
    if isinstance(threshold, (bool, str)) or not isinstance(threshold, numbers.Real) or not math.isfinite(threshold) \
            or threshold < 0:
        raise ValueError(f"threshold: expected a finite distance >= 0 in metres, got {threshold!r}")


def distance_to(points: Tensor | np.ndarray, target: MeshLike | Tensor) -> Tensor:
    """Distance (N,)|(B,N) from points to a mesh (Trimesh or (vertices, faces): exact surface distance)
    or to a point set (M,3)|(B,M,3) (nearest point)."""
    if isinstance(target, (trimesh.Trimesh, tuple, list)):
        return point_mesh_distance(points, target).distance
    return nearest_neighbours(points, target)[0]


def marker_contact(markers: Tensor | np.ndarray, obj: MeshLike | Tensor,
                   threshold: float = MARKER_CONTACT_THRESHOLD) -> Tensor:
    """SAGA's C_M: 1.0 where a marker (N,3)|(B,N,3) is within `threshold` m of the object's surface, else 0.0 (the
    unsigned distance, as the labels are made: a marker deep inside the object reads 0; `grasp_metrics` uses the
    signed distance)."""
    markers = as_points(markers, "markers")
    _check_threshold(threshold)
    return (distance_to(markers, obj) <= threshold).to(markers.dtype)


def object_contact(object_points: Tensor | np.ndarray, body: MeshLike | Tensor,
                   threshold: float = OBJECT_CONTACT_THRESHOLD) -> Tensor:
    """SAGA's C_O: 1.0 where an object point (P,3)|(B,P,3) is within `threshold` m of the body, else 0.0.

    `body` is a body mesh (Trimesh or (vertices (V,3)|(B,V,3), faces)) or just its vertices.
    """
    object_points = as_points(object_points, "object_points")
    _check_threshold(threshold)
    return (distance_to(object_points, body) <= threshold).to(object_points.dtype)


def interaction_attention(distance: Tensor, w: float = IAA_WEIGHT) -> Tensor:
    """GOAL Eq. 1: I_w(d) = exp(-w d), elementwise, for body-to-object distances d >= 0 in metres (a tensor)."""
    if not isinstance(distance, Tensor):
        raise TypeError(f"distance: expected a torch tensor of distances in metres, got {type(distance).__name__}")
    if isinstance(w, bool) or not isinstance(w, numbers.Real) or not math.isfinite(w) or w <= 0:
        raise ValueError(f"w: GOAL's weight must be a finite positive number, got {w}")
    if not torch.isfinite(distance).all():
        raise ValueError("distance: contains NaN or infinite values")
    if (distance < 0).any():
        raise ValueError(f"distance: expected distances >= 0 (unsigned, GOAL Eq. 1), got a minimum of "
                         f"{distance.min().item():.4g}")
    return torch.exp(-w * distance)


def body_object_attention(body_vertices: Tensor | np.ndarray, obj: MeshLike | Tensor, w: float = IAA_WEIGHT) -> Tensor:
    """exp(-w d(v, O)) (N,)|(B,N) for body vertices v and an object mesh (exact) or object points O."""
    return interaction_attention(distance_to(as_points(body_vertices, "body_vertices"), obj), w)
