"""Signed distance to a closed mesh, NEGATIVE INSIDE and positive outside (SAGA Eq. 7 uses S(x, Y) this way).

Two paths:
- exact: `signed_distance` = exact closest-point distance (graspkit.objects.distance) with the sign of
  (p - closest) . pseudo-normal of the closest feature (face normal; edge: sum of the two face normals;
  vertex: angle-weighted normal; Baerentzen & Aanaes, IEEE TVCG 2005), which is exact for a watertight,
  consistently oriented mesh. `winding_number` (generalized winding number, Jacobson et al. 2013,
  solid angles by Van Oosterom & Strackee 1983) is an independent containment test.
- fast grid: `SDFGrid` samples the exact SDF once per object on a regular grid over the padded
  bounding box and interpolates trilinearly (torch grid_sample), with gradients w.r.t. the queries.

Measured on 5,000 random points in the 2 cm-padded box of each of the 17 catalogue objects (tables in
docs/objects.md; checks in tests/test_geometry.py): the exact path's sign agrees with trimesh's
`contains` on 100.00 % of points and its distance equals a brute-force point-triangle minimum to
~1e-16 m (trimesh's own closest-point search is up to 0.03 mm too large). The default grid (64 nodes
along the longest side, 3 cm padding, cells of 2.3-7.5 mm) agrees in sign on 100 % of points farther
than one cell from the surface (98.4-100 % overall), with median |error| <= 0.07 mm and at most 0.65
cell beyond one cell from the surface. 10k queries: exact ~0.18 s, grid ~1 ms (2 CPU cores).
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import torch
import torch.nn.functional as F
from torch import Tensor
from tqdm import tqdm

from graspkit.objects.distance import (EDGE_AB, EDGE_CA, VERT_A, VERT_C, MeshLike, as_points, edge_ids, mesh_arrays,
                                       nearest_neighbours, point_mesh_distance, require_closed,
                                       require_metres)
from graspkit.progress import hidden


def pseudo_normals(verts: Tensor, faces: Tensor) -> tuple[Tensor, Tensor, Tensor]:
    """Unit face normals (...,F,3), edge pseudo-normals (...,E,3) and angle-weighted vertex normals (...,V,3)."""
    tri = verts[..., faces, :]  # (..., F, 3, 3)
    cross = torch.linalg.cross(tri[..., 1, :] - tri[..., 0, :], tri[..., 2, :] - tri[..., 0, :])
    fn = cross / torch.linalg.vector_norm(cross, dim=-1, keepdim=True).clamp_min(1e-30)
    eid = torch.as_tensor(edge_ids(faces), device=verts.device)
    en = torch.zeros(verts.shape[:-2] + (int(eid.max()) + 1, 3), dtype=verts.dtype, device=verts.device)
    en.index_add_(-2, eid.reshape(-1), fn.repeat_interleave(3, dim=-2))
    # interior angle at each corner k, between the edges to the two other corners
    e1 = tri[..., [1, 2, 0], :] - tri
    e2 = tri[..., [2, 0, 1], :] - tri
    norms = torch.linalg.vector_norm(e1, dim=-1) * torch.linalg.vector_norm(e2, dim=-1)
    angle = torch.arccos(((e1 * e2).sum(-1) / norms.clamp_min(1e-30)).clamp(-1.0, 1.0))  # (..., F, 3)
    vn = torch.zeros_like(verts)
    vn.index_add_(-2, faces.reshape(-1), (angle[..., None] * fn[..., None, :]).reshape(verts.shape[:-2] + (-1, 3)))
    return fn, en, vn


def signed_distance(points: Tensor | np.ndarray, mesh: MeshLike, check: bool = True) -> Tensor:
    """Exact signed distance (N,)|(B,N) from points (N,3)|(B,N,3) to a closed mesh; negative inside.

    Differentiable w.r.t. the points and the mesh vertices (the sign is locally constant; at a point exactly on the
    surface the gradient is 0, the distance norm's subgradient, not the normal). `check`
    verifies that the mesh is watertight, consistently wound and outward-facing (ValueError otherwise); it does
    not find solids that overlap inside one mesh (two boxes merged without a union), where the sign is wrong in
    the overlap's neighbourhood: `graspkit.objects.user.as_object` refuses those.
    """
    verts, faces = mesh_arrays(mesh, "mesh")
    if check:
        require_closed(verts, faces, "mesh")
    res = point_mesh_distance(points, (verts, faces))
    with torch.no_grad():
        fn, en, vn = pseudo_normals(verts.detach().to(res.closest.dtype), faces)
        batched = verts.dim() == 3
        if batched:  # index per batch element
            b = torch.arange(len(verts), device=verts.device)[:, None].expand_as(res.face)
            pick = lambda table, idx: table[b, idx]  # noqa: E731
        else:
            pick = lambda table, idx: table[idx]  # noqa: E731
        eid = torch.as_tensor(edge_ids(faces), device=verts.device)
        corner = torch.clamp(res.region - VERT_A, 0, 2)  # vertex regions 1..3 -> corner 0..2
        edge = torch.clamp(res.region - EDGE_AB, 0, 2)  # edge regions 4..6 -> edge 0..2 (ab, bc, ca)
        normal = pick(fn, res.face)
        is_vert = (res.region >= VERT_A) & (res.region <= VERT_C)
        is_edge = (res.region >= EDGE_AB) & (res.region <= EDGE_CA)
        normal = torch.where(is_vert[..., None], pick(vn, faces[res.face, corner]), normal)
        normal = torch.where(is_edge[..., None], pick(en, eid[res.face, edge]), normal)
        p = as_points(points, "points").to(res.closest.dtype)
        if batched and p.dim() == 2:
            p = p.expand(len(verts), -1, -1)
        sign = torch.where(((p - res.closest) * normal).sum(-1) < 0, -1.0, 1.0).to(res.distance.dtype)
    return res.distance * sign


def signed_distance_to_points(points: Tensor | np.ndarray, cloud: Tensor | np.ndarray,
                              normals: Tensor | np.ndarray) -> Tensor:
    """SAGA Eq. 7's S(x, Y) for a point cloud Y with outward normals: |x - y*| signed by (x - y*) . n(y*) (the paper
    does not say how S is signed; by the nearest point's normal is graspkit's reading).

    y* is the nearest cloud point; points (N,3)|(B,N,3), cloud and normals (M,3)|(B,M,3) -> (N,)|(B,N),
    negative inside. Differentiable w.r.t. points and cloud. Exact only as the cloud gets dense; use
    `signed_distance` when the mesh is at hand.
    """
    p, y = as_points(points, "points"), as_points(cloud, "cloud")
    n = as_points(normals, "normals").to(y.dtype)
    if n.shape != y.shape:
        raise ValueError(f"normals: expected the shape of the cloud {tuple(y.shape)}, got {tuple(n.shape)}")
    dist, idx = nearest_neighbours(p, y)
    with torch.no_grad():
        p3, y3, n3 = (t if t.dim() == 3 else t[None] for t in (p, y, n))
        batch = max(len(p3), len(y3))
        i3 = idx.reshape(batch, -1, 1).expand(-1, -1, 3)
        nearest = torch.gather(y3.expand(batch, -1, -1), 1, i3)
        normal = torch.gather(n3.expand(batch, -1, -1), 1, i3)
        sign = torch.where(((p3 - nearest) * normal).sum(-1) < 0, -1.0, 1.0).to(dist.dtype)
    return dist * sign.reshape(dist.shape)


def winding_number(points: Tensor | np.ndarray, mesh: MeshLike, chunk: int = 2_000_000) -> Tensor:
    """Generalized winding number (N,) of a single mesh at points (N,3): ~1 inside, ~0 outside (no gradient)."""
    p = as_points(points, "points").detach().to(torch.float64)
    verts, faces = mesh_arrays(mesh, "mesh")
    if verts.dim() != 2 or p.dim() != 2:
        raise ValueError("points, mesh: winding_number takes one mesh (V,3) and points (N,3)")
    tri = verts.detach().to(torch.float64)[faces]  # (F,3,3)
    out = torch.empty(len(p), dtype=torch.float64)
    rows = max(1, chunk // len(faces))
    for s in range(0, len(p), rows):
        r = tri[None] - p[s:s + rows, None, None, :]  # (n,F,3,3) corners relative to the query
        a, b, c = r.unbind(-2)
        la, lb, lc = (torch.linalg.vector_norm(x, dim=-1) for x in (a, b, c))
        num = (a * torch.linalg.cross(b, c)).sum(-1)
        den = la * lb * lc + (a * b).sum(-1) * lc + (b * c).sum(-1) * la + (c * a).sum(-1) * lb
        out[s:s + rows] = torch.atan2(num, den).sum(-1) / (2 * torch.pi)  # sum of solid angles / (4 pi)
    return out


def contains(points: Tensor | np.ndarray, mesh: MeshLike) -> Tensor:
    """Boolean (N,)|(B,N): points strictly inside the closed mesh (by the exact signed distance)."""
    return signed_distance(points, mesh) < 0


SLAB_NODES = 200_000      # grid nodes a call of SDFGrid.from_mesh(progress=True), a step of its bar
MAX_GRID_NODES = 100_000_000   # SDFGrid.from_mesh refuses more (its float64 nodes and distances take ~6 GB)


@dataclass
class SDFGrid:
    """A signed-distance grid values[z, y, x] over the box [lower, upper] (metres) with trilinear lookup.

    Outside the box the lookup continues as sdf(clamped point) + |point - clamped point|, which keeps gradients
    pointing towards the object: an upper bound of the true distance up to the grid's own interpolation error at the
    clamped point (an independent check found it up to 0.41 mm below the exact distance for the wine glass).
    A query exactly on the grid box's faces (not near them) gets a wrong gradient (zero padding beyond the upper face,
    half the clamp's at a tie): a measure-zero case an optimiser does not meet, measured and left (2026-12-06).
    """

    values: Tensor  # (D, H, W) = (nz, ny, nx)
    lower: Tensor  # (3,)
    upper: Tensor  # (3,)

    @property
    def cell(self) -> Tensor:
        """Grid spacing along x, y, z (3,)."""
        n = torch.tensor(self.values.shape[::-1], dtype=self.lower.dtype) - 1
        return (self.upper - self.lower) / n

    @staticmethod
    def from_mesh(mesh: MeshLike, resolution: int = 64, padding: float = 0.03,
                  dtype: torch.dtype = torch.float32, progress: bool = False) -> SDFGrid:
        """Sample the exact SDF of a closed mesh; `resolution` nodes along the longest side, cubic cells; `progress`:
        a bar over the grid's z layers (a scan's 2 mm grid takes minutes; the values are the same either way)."""
        verts, faces = mesh_arrays(mesh, "mesh")
        if verts.dim() != 2:
            raise ValueError("mesh: SDFGrid.from_mesh takes one mesh with vertices (V, 3)")
        if isinstance(resolution, bool) or not isinstance(resolution, (int, np.integer)) or resolution < 2:
            raise ValueError(f"resolution: expected a whole number of grid nodes >= 2, got {resolution!r}")
        if not (isinstance(padding, (int, float, np.number)) and np.isfinite(padding) and padding >= 0):
            raise ValueError(f"padding: expected a finite margin >= 0 in metres, got {padding!r}")
        require_closed(verts, faces, "mesh")
        require_metres(verts, faces, "mesh")           # padding and the cell size are in metres
        v = verts.detach().to(torch.float64)
        used = v[torch.unique(faces)]                  # the surface's own box: vertices no face uses do not count
        lo, hi = used.min(0).values - padding, used.max(0).values + padding
        h = (hi - lo).max() / (resolution - 1)
        n = torch.clamp(torch.ceil((hi - lo) / h - 1e-6).long() + 1, min=2)
        if int(n.prod()) > MAX_GRID_NODES:
            raise ValueError(f"resolution: {resolution} gives {int(n.prod()):,} grid nodes, more than "
                             f"{MAX_GRID_NODES:,} (several GB while built; a 2 mm grid of a 40 cm object: ~10 million)")
        hi = lo + (n - 1) * h  # cubic cells: stretch the box to whole cells
        axes = [lo[i] + h * torch.arange(int(n[i]), dtype=torch.float64) for i in range(3)]
        zz, yy, xx = torch.meshgrid(axes[2], axes[1], axes[0], indexing="ij")
        nodes = torch.stack([xx, yy, zz], -1).reshape(-1, 3)
        layer = zz.shape[1] * zz.shape[2]
        per = max(1, SLAB_NODES // layer) if progress else zz.shape[0]     # z layers a call
        slabs = tqdm(range(0, zz.shape[0], per), desc=f"SDF grid ({len(faces)} faces)", unit="slab",
                     disable=zz.shape[0] <= per or hidden(), leave=False)
        values = torch.cat([signed_distance(nodes[k * layer:(k + per) * layer], (v, faces), check=False)
                            for k in slabs]).reshape(zz.shape)
        return SDFGrid(values.to(dtype), lo.to(dtype), hi.to(dtype))

    def to(self, device: torch.device | str | None = None, dtype: torch.dtype | None = None) -> SDFGrid:
        """A copy on another device and/or in another dtype (do this once, not per query)."""
        return SDFGrid(*(t.to(device=device, dtype=dtype) for t in (self.values, self.lower, self.upper)))

    def __call__(self, points: Tensor | np.ndarray | Sequence[Sequence[float]]) -> Tensor:
        """Interpolated signed distance (...,) at points (..., 3); differentiable w.r.t. the points."""
        if not isinstance(points, Tensor):
            try:
                points = torch.as_tensor(np.asarray(points, np.float64))
            except (TypeError, ValueError) as e:
                raise ValueError(f"points: expected an array of numbers (..., 3), got {type(points).__name__} "
                                 f"({e})") from None
        p = _check_tensor(points)
        dtype = p.dtype
        lo, hi = self.lower.to(dtype=dtype, device=p.device), self.upper.to(dtype=dtype, device=p.device)
        inside = torch.maximum(torch.minimum(p, hi), lo)
        outside = torch.linalg.vector_norm(p - inside, dim=-1)
        coords = 2.0 * (inside - lo) / (hi - lo) - 1.0  # grid_sample wants (x, y, z) in [-1, 1]
        grid = self.values.to(dtype=dtype, device=p.device)[None, None]
        val = F.grid_sample(grid, coords.reshape(1, 1, 1, -1, 3), mode="bilinear", align_corners=True)
        return val.reshape(p.shape[:-1]) + outside


def _check_tensor(p: Tensor) -> Tensor:
    """Shape/finiteness check of a query tensor without copying it (keeps the autograd graph)."""
    if p.shape[-1] != 3 or p.numel() == 0 or not torch.isfinite(p).all():
        raise ValueError(f"points: expected finite, non-empty points of shape (..., 3), got {tuple(p.shape)}")
    return p if p.is_floating_point() else p.to(torch.float64)


@lru_cache(maxsize=32)
def object_sdf_grid(name: str, resolution: int = 64, padding: float = 0.03) -> SDFGrid:
    """The cached SDF grid of canonical catalogue object `name` (built on first use, ~0.5-2 s)."""
    from graspkit.objects.catalogue import make_object
    return SDFGrid.from_mesh(make_object(name), resolution, padding)
