"""Area-weighted random sampling of points and outward normals on a triangle-mesh surface.

SAGA represents an object by 2,048 surface points with normals (Sec. 3, "Preliminaries"); this is the
sampler. Deterministic for a seed (numpy Generator; trimesh's global random state is never touched).
"""
from __future__ import annotations

import numpy as np

from graspkit.objects.distance import MeshLike, mesh_arrays


def sample_surface(mesh: MeshLike, n: int = 2048, seed: int | np.random.Generator = 0
                   ) -> tuple[np.ndarray, np.ndarray]:
    """n points (n,3) uniformly distributed over the surface area, and the unit face normals (n,3) there.

    Normals point outward for a consistently outward-oriented mesh (every catalogue object).
    """
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n <= 0:
        raise ValueError(f"n: expected a positive number of points, got {n!r}")
    verts, faces = mesh_arrays(mesh, "mesh")
    if verts.dim() != 2:
        raise ValueError("mesh: sample_surface takes one mesh with vertices (V, 3)")
    tri = verts.detach().cpu().double().numpy()[faces.cpu().numpy()]  # (F, 3, 3)
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    area2 = np.linalg.norm(cross, axis=1)
    if area2.sum() <= 0:
        raise ValueError("mesh: the surface has zero area")
    if not (isinstance(seed, np.random.Generator)                 # None (numpy's OS entropy) is refused: same seed,
            or (isinstance(seed, (int, np.integer)) and not isinstance(seed, bool) and seed >= 0)):   # same points
        raise ValueError(f"seed: expected a non-negative integer or a numpy Generator, got {seed!r}")
    rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
    face = rng.choice(len(tri), size=n, p=area2 / area2.sum())
    # uniform barycentrics by the square-root warp (Osada et al. 2002, Eq. 1)
    r1, r2 = np.sqrt(rng.random(n)), rng.random(n)
    bary = np.stack([1.0 - r1, r1 * (1.0 - r2), r1 * r2], axis=1)
    points = np.einsum("nk,nkd->nd", bary, tri[face])
    normals = cross[face] / np.maximum(area2[face], 1e-300)[:, None]
    return points, normals
