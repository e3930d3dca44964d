"""Triangle-quality pass for the decimated humanoid: Delaunay edge flips, tangential relaxation, and
projection back onto the fine marching-cubes surface. The vertex count and the topology class
(closed, oriented, genus 0) are unchanged; only connectivity of near-flat quads and positions move.
"""
from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from graspkit.body._proc_mesh import vertex_neighbours


def _angle(p: np.ndarray, q: np.ndarray, r: np.ndarray) -> float:
    """Angle at p of triangle pqr (radians)."""
    u, w = q - p, r - p
    c = u @ w / (np.linalg.norm(u) * np.linalg.norm(w) + 1e-300)
    return float(np.arccos(np.clip(c, -1.0, 1.0)))


def _normal(p: np.ndarray, q: np.ndarray, r: np.ndarray) -> np.ndarray:
    """Unit normal of triangle pqr."""
    n = np.cross(q - p, r - p)
    return n / (np.linalg.norm(n) + 1e-300)


def delaunay_flips(v: np.ndarray, f: np.ndarray, max_dihedral_deg: float = 12.0, passes: int = 6) -> np.ndarray:
    """Flip edges of near-flat face pairs that violate the Delaunay condition; returns new faces (F, 3).

    A flip is made only when the two faces are within max_dihedral_deg of coplanar (so the surface
    barely moves), the new edge does not exist yet, no vertex drops below valence 4, and the new faces
    keep the old orientation.
    """
    f = [list(t) for t in f.tolist()]
    emap: dict[tuple[int, int], list[int]] = {}
    for fi, (a, b, c) in enumerate(f):
        for p, q in ((a, b), (b, c), (c, a)):
            emap.setdefault((min(p, q), max(p, q)), []).append(fi)
    valence = np.bincount(np.asarray(f).ravel(), minlength=len(v)) 
    cos_max = np.cos(np.deg2rad(max_dihedral_deg))
    for _ in range(passes):
        flipped = 0
        for key in sorted(emap):
            faces = emap.get(key)
            if faces is None or len(faces) != 2:
                continue
            f1, f2 = faces
            t1, t2 = f[f1], f[f2]
            # orient so that t1 = (a, b, c) contains a->b and t2 = (b, a, d)
            i = next(k for k in range(3) if {t1[k], t1[(k + 1) % 3]} == set(key))
            a, b, c = t1[i], t1[(i + 1) % 3], t1[(i + 2) % 3]
            j = t2.index(b)
            if t2[(j + 1) % 3] != a:
                continue
            d = t2[(j + 2) % 3]
            if c == d or (min(c, d), max(c, d)) in emap or valence[a] <= 4 or valence[b] <= 4:
                continue
            pa, pb, pc, pd = v[a], v[b], v[c], v[d]
            if _angle(pc, pa, pb) + _angle(pd, pb, pa) <= np.pi + 1e-6:
                continue
            n1, n2 = _normal(pa, pb, pc), _normal(pb, pa, pd)
            if n1 @ n2 < cos_max:
                continue
            m1, m2 = _normal(pa, pd, pc), _normal(pd, pb, pc)
            navg = n1 + n2
            if m1 @ navg <= 0 or m2 @ navg <= 0 or m1 @ m2 < cos_max:
                continue
            f[f1], f[f2] = [a, d, c], [d, b, c]
            del emap[key]
            emap[(min(c, d), max(c, d))] = [f1, f2]
            ad, bc = emap[(min(a, d), max(a, d))], emap[(min(b, c), max(b, c))]
            ad[ad.index(f2)] = f1
            bc[bc.index(f1)] = f2
            valence[a] -= 1
            valence[b] -= 1
            valence[c] += 1
            valence[d] += 1
            flipped += 1
        if flipped == 0:
            break
    return np.asarray(f, np.int64)


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
