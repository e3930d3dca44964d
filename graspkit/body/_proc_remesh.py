"""Triangle-quality pass for the decimated humanoid: Delaunay edge flips, tangential relaxation, and
projection back onto the fine marching-cubes surface. The vertex count and the topology class
(closed, oriented, genus 0) are unchanged; only connectivity of near-flat quads and positions move.
"""
from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from graspkit.body._proc_mesh import vertex_neighbours


def _angles_at(p: np.ndarray, q: np.ndarray, r: np.ndarray) -> np.ndarray:
    """Angles (N,) at p of triangles pqr (stacked (N,3) points), radians."""
    u, w = q - p, r - p
    c = (u * w).sum(1) / (np.linalg.norm(u, axis=1) * np.linalg.norm(w, axis=1) + 1e-300)
    return np.arccos(np.clip(c, -1.0, 1.0))


def _normals(p: np.ndarray, q: np.ndarray, r: np.ndarray) -> np.ndarray:
    """Unit normals (N,3) of triangles pqr."""
    n = np.cross(q - p, r - p)
    return n / (np.linalg.norm(n, axis=1, keepdims=True) + 1e-300)


def delaunay_flips(v: np.ndarray, f: np.ndarray, max_dihedral_deg: float = 12.0, rounds: int = 60) -> np.ndarray:
    """Flip edges of near-flat face pairs that violate the Delaunay condition; returns new faces (F, 3).

    A flip is made only when the two faces are within max_dihedral_deg of coplanar (so the surface
    barely moves), the new edge does not exist yet, no vertex drops below valence 4, and the new faces
    keep the old orientation. Each round flips a set of edges that share no vertex, worst first.
    """
    f = f.copy()
    V = len(v)
    cos_max = np.cos(np.deg2rad(max_dihedral_deg))
    for _ in range(rounds):
        de = np.stack([f, np.roll(f, -1, axis=1)], 2).reshape(-1, 2)          # directed edge e in face e // 3
        key = de[:, 0] * V + de[:, 1]
        twin_key = de[:, 1] * V + de[:, 0]
        order = np.argsort(key)
        pos = np.searchsorted(key[order], twin_key)
        twin = order[np.clip(pos, 0, len(order) - 1)]
        e = np.nonzero((de[:, 0] < de[:, 1]) & (key[twin] == twin_key))[0]   # each interior edge once
        e2 = twin[e]
        f1, f2 = e // 3, e2 // 3
        a, b = de[e, 0], de[e, 1]
        c = f[f1, (e % 3 + 2) % 3]
        d = f[f2, (e2 % 3 + 2) % 3]
        pa, pb, pc, pd = v[a], v[b], v[c], v[d]
        excess = _angles_at(pc, pa, pb) + _angles_at(pd, pb, pa) - np.pi
        n1, n2 = _normals(pa, pb, pc), _normals(pb, pa, pd)
        m1, m2 = _normals(pa, pd, pc), _normals(pd, pb, pc)
        navg = n1 + n2
        valence = np.bincount(f.ravel(), minlength=V)
        exists = np.isin(np.minimum(c, d) * V + np.maximum(c, d), np.minimum(de[:, 0], de[:, 1]) * V
                         + np.maximum(de[:, 0], de[:, 1]))
        ok = ((excess > 1e-6) & (c != d) & ~exists & (valence[a] > 4) & (valence[b] > 4)
              & ((n1 * n2).sum(1) >= cos_max) & ((m1 * navg).sum(1) > 0) & ((m2 * navg).sum(1) > 0)
              & ((m1 * m2).sum(1) >= cos_max))
        cand = np.nonzero(ok)[0]
        if len(cand) == 0:
            break
        cand = cand[np.lexsort((e[cand], -excess[cand]))]                     # worst first, ties by edge id
        # keep a set of flips that share no vertex: a flip survives if it is the first to use each of its 4
        verts = np.stack([a[cand], b[cand], c[cand], d[cand]], 1)
        first = np.full(V, len(cand))
        np.minimum.at(first, verts.ravel(), np.repeat(np.arange(len(cand)), 4))
        keep = cand[(first[verts] == np.arange(len(cand))[:, None]).all(1)]
        f[f1[keep]] = np.stack([a[keep], d[keep], c[keep]], 1)
        f[f2[keep]] = np.stack([d[keep], b[keep], c[keep]], 1)
    return f


def vertex_normals(v: np.ndarray, f: np.ndarray) -> np.ndarray:
    """Area-weighted unit vertex normals (V, 3)."""
    fn = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    n = np.zeros_like(v)
    for k in range(3):
        np.add.at(n, f[:, k], fn)
    return n / (np.linalg.norm(n, axis=1, keepdims=True) + 1e-300)


class SurfaceProjector:
    """Nearest points on a fine reference mesh (vertices (N,3), faces (M,3)), via a k-d tree of face centroids."""

    def __init__(self, v: np.ndarray, f: np.ndarray, k: int = 12) -> None:
        """Index the reference triangles; k = candidate triangles examined per query point."""
        self.tri = v[f]
        self.tree = cKDTree(self.tri.mean(1))
        self.k = k

    def __call__(self, p: np.ndarray) -> np.ndarray:
        """Closest points (P, 3) on the reference surface to points p (P, 3)."""
        _, idx = self.tree.query(p, k=self.k)
        tri = self.tri[idx]                                    # (P, k, 3, 3)
        q = closest_point_on_triangles(np.repeat(p[:, None], self.k, 1).reshape(-1, 3), tri.reshape(-1, 3, 3))
        q = q.reshape(len(p), self.k, 3)
        best = np.linalg.norm(q - p[:, None], axis=2).argmin(1)
        return q[np.arange(len(p)), best]


def closest_point_on_triangles(p: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """Closest point (N,3) on each triangle tri (N,3,3) to p (N,3) (Ericson, Real-Time Collision Detection 5.1.5)."""
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    ab, ac, ap = b - a, c - a, p - a
    d1, d2 = (ab * ap).sum(1), (ac * ap).sum(1)
    bp = p - b
    d3, d4 = (ab * bp).sum(1), (ac * bp).sum(1)
    cp = p - c
    d5, d6 = (ab * cp).sum(1), (ac * cp).sum(1)
    va = d3 * d6 - d5 * d4
    vb = d5 * d2 - d1 * d6
    vc = d1 * d4 - d3 * d2
    denom = va + vb + vc
    denom = np.where(np.abs(denom) < 1e-300, 1e-300, denom)
    v_ = vb / denom
    w_ = vc / denom
    out = a + ab * v_[:, None] + ac * w_[:, None]              # interior by default
    # regions, checked from the least to the most specific so that later ones win
    with np.errstate(divide="ignore", invalid="ignore"):
        m = (va <= 0) & ((d4 - d3) >= 0) & ((d5 - d6) >= 0)    # edge bc
        t = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        out = np.where(m[:, None], b + (c - b) * t[:, None], out)
        m = (vb <= 0) & (d2 >= 0) & (d6 <= 0)                   # edge ac
        t = d2 / (d2 - d6)
        out = np.where(m[:, None], a + ac * t[:, None], out)
        m = (vc <= 0) & (d1 >= 0) & (d3 <= 0)                   # edge ab
        t = d1 / (d1 - d3)
        out = np.where(m[:, None], a + ab * t[:, None], out)
    out = np.where(((d6 >= 0) & (d5 <= d6))[:, None], c, out)   # vertex c
    out = np.where(((d3 >= 0) & (d4 <= d3))[:, None], b, out)   # vertex b
    out = np.where(((d1 <= 0) & (d2 <= 0))[:, None], a, out)    # vertex a
    return out


def relax(v: np.ndarray, f: np.ndarray, project: SurfaceProjector, iters: int = 4, step: float = 0.5) -> np.ndarray:
    """Tangential Laplacian relaxation (uniform weights), each step projected back onto the reference surface."""
    A = vertex_neighbours(f, len(v))
    deg = np.asarray(A.sum(1)).ravel()
    for _ in range(iters):
        n = vertex_normals(v, f)
        d = (A @ v) / deg[:, None] - v
        d -= (d * n).sum(1, keepdims=True) * n
        v = project(v + step * d)
    return v
