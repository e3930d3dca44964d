"""Mesh steps of the procedural humanoid: marching cubes, decimation, edge splits, and checks.

Checks are plain numpy: closed 2-manifold (each undirected edge in exactly two faces, each directed
edge once), Euler characteristic, signed volume, and self-intersection of non-adjacent triangles
(spatial-hash candidate pairs, then exact segment/triangle orientation tests).
"""
from __future__ import annotations

import numpy as np
from scipy.sparse import coo_matrix, csr_matrix
from scipy.sparse.csgraph import connected_components


def marching_cubes(field: np.ndarray, h: float, u0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Zero level set of field (nx,ny,nz), spacing h, origin u0 -> vertices (N,3) in u space, faces (F,3) outward."""
    from skimage.measure import marching_cubes as mc

    v, f, _, _ = mc(field, level=0.0, spacing=(h, h, h), allow_degenerate=False)
    v = v.astype(np.float64) + u0
    f = f.astype(np.int64)
    if signed_volume(v, f) < 0:
        f = f[:, ::-1].copy()
    return v, f


def largest_component(v: np.ndarray, f: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Keep the connected component with the most faces; drop unreferenced vertices."""
    n = len(v)
    e = np.concatenate([f[:, [0, 1]], f[:, [1, 2]]])
    adj = coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n))
    _, lab = connected_components(adj, directed=False)
    flab = lab[f[:, 0]]
    keep = f[flab == np.bincount(flab).argmax()]
    return compact(v, keep)


def drop_doubled_faces(f: np.ndarray) -> np.ndarray:
    """Remove every face whose vertex set occurs more than once (the collapsed sheets decimation can leave)."""
    key = np.sort(f, 1)
    _, inv, cnt = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    return f[cnt[inv.ravel()] == 1]


def compact(v: np.ndarray, f: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Drop vertices no face uses and renumber faces."""
    used = np.unique(f)
    remap = np.full(len(v), -1, np.int64)
    remap[used] = np.arange(len(used))
    return v[used], remap[f]


def signed_volume(v: np.ndarray, f: np.ndarray) -> float:
    """Enclosed volume of a closed mesh (positive when faces wind counter-clockwise seen from outside)."""
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)


def edges(f: np.ndarray) -> np.ndarray:
    """Directed edges (3F, 2) of faces (F, 3): (f0,f1), (f1,f2), (f2,f0) per face, face-major."""
    return np.stack([f, np.roll(f, -1, axis=1)], axis=2).reshape(-1, 2)


def topology_report(v: np.ndarray, f: np.ndarray) -> dict[str, object]:
    """Closedness, manifoldness, orientation, Euler characteristic and genus of a triangle mesh."""
    de = edges(f)
    und = np.sort(de, axis=1)
    _, cnt = np.unique(und, axis=0, return_counts=True)
    _, dcnt = np.unique(de, axis=0, return_counts=True)
    degenerate = int((np.sort(f, 1)[:, :-1] == np.sort(f, 1)[:, 1:]).any(1).sum())
    V, E, F = len(np.unique(f)), len(cnt), len(f)
    chi = V - E + F
    return {"vertices": len(v), "faces": F, "unused_vertices": len(v) - V,
            "watertight": bool((cnt == 2).all()), "winding_consistent": bool((dcnt == 1).all()),
            "degenerate_faces": degenerate, "euler": chi, "genus": (2 - chi) // 2,
            "volume": signed_volume(v, f)}


def pinched_vertices(f: np.ndarray, n: int) -> int:
    """Number of vertices whose incident faces form more than one fan (needs an edge-manifold, oriented mesh)."""
    a = f.reshape(-1)
    nxt = np.roll(f, -1, axis=1).reshape(-1)
    prv = np.roll(f, 1, axis=1).reshape(-1)
    # corner (a, next b) is followed, rotating around a, by the corner of a whose previous vertex is b
    lookup = {k: i for i, k in enumerate((a * n + prv).tolist())}
    succ = np.array([lookup.get(k, -1) for k in (a * n + nxt).tolist()])
    ok = succ >= 0
    m = len(a)
    G = coo_matrix((np.ones(ok.sum()), (np.arange(m)[ok], succ[ok])), shape=(m, m))
    n_fans, _ = connected_components(G, directed=False)
    return int(n_fans - len(np.unique(a)))


def split_longest_edges(v: np.ndarray, f: np.ndarray, n_target: int, batch: int = 64) -> tuple[np.ndarray, np.ndarray]:
    """Split edges at their midpoints, longest first, until there are n_target vertices (+1 per split).

    Each round splits up to `batch` of the longest edges that share no face (so the splits are
    independent); a flat midpoint split does not move the surface.
    """
    v, f = v.copy(), f.copy()
    while len(v) < n_target:
        de = edges(f)                                  # (3F, 2); face of directed edge e is e // 3
        L = np.linalg.norm(v[de[:, 0]] - v[de[:, 1]], axis=1)
        key = np.minimum(de[:, 0], de[:, 1]) * len(v) + np.maximum(de[:, 0], de[:, 1])
        order = np.lexsort((key, -L))                  # longest first, ties by vertex ids (deterministic)
        used = np.zeros(len(f), bool)
        done: set[int] = set()
        picked = []
        want = min(batch, n_target - len(v))
        for e in order[: 40 * want].tolist():
            if key[e] in done:
                continue
            a, b = de[e]
            fb_all = np.nonzero((f == b).any(1) & (f == a).any(1))[0]
            if used[fb_all].any():
                continue
            used[fb_all] = True
            done.add(int(key[e]))
            picked.append((a, b, fb_all))
            if len(picked) == want:
                break
        new_faces = []
        new_v = []
        for a, b, faces in picked:
            m = len(v) + len(new_v)
            new_v.append(0.5 * (v[a] + v[b]))
            for fi in faces:
                tri = f[fi].tolist()
                k = next(k for k in range(3) if {tri[k], tri[(k + 1) % 3]} == {a, b})   # the split edge first
                tri = tri[k:] + tri[:k]
                p, q, r = tri
                f[fi] = (p, m, r)
                new_faces.append((m, q, r))
        v = np.vstack([v, np.asarray(new_v)])
        f = np.vstack([f, np.asarray(new_faces, np.int64)])
    return v, f


# ----------------------------------------------------------------------------- self-intersection
def _orient(a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Signed volume det[b-a, c-a, d-a] for stacked points (N,3) -> (N,)."""
    return np.einsum("ij,ij->i", np.cross(b - a, c - a), d - a)


def _segment_hits_triangle(p, q, a, b, c) -> np.ndarray:
    """Whether segments p-q properly cross triangles abc (all (N,3)) -> (N,) bool."""
    s1, s2 = _orient(a, b, c, p), _orient(a, b, c, q)
    cross = (s1 > 0) != (s2 > 0)
    cross &= (s1 != 0) & (s2 != 0)
    o1, o2, o3 = _orient(p, q, a, b), _orient(p, q, b, c), _orient(p, q, c, a)
    same = ((o1 > 0) & (o2 > 0) & (o3 > 0)) | ((o1 < 0) & (o2 < 0) & (o3 < 0))
    return cross & same


def candidate_pairs(v: np.ndarray, f: np.ndarray, cell: float | None = None) -> np.ndarray:
    """Pairs (P, 2) of faces, i < j, sharing no vertex, whose bounding boxes overlap (spatial hash)."""
    tri = v[f]
    lo, hi = tri.min(1), tri.max(1)
    if cell is None:
        cell = float(np.percentile((hi - lo).max(1), 90)) * 1.5
    c0 = np.floor(lo / cell).astype(np.int64)
    c1 = np.floor(hi / cell).astype(np.int64)
    span = c1 - c0 + 1
    cnt = span.prod(1)
    owner = np.repeat(np.arange(len(f)), cnt)
    k = np.arange(cnt.sum()) - np.repeat(np.cumsum(cnt) - cnt, cnt)          # index within the triangle's cells
    sx, sy = span[owner, 0], span[owner, 1]
    cx = c0[owner, 0] + k % sx
    cy = c0[owner, 1] + (k // sx) % sy
    cz = c0[owner, 2] + k // (sx * sy)
    key = (cx * 1_000_003 + cy) * 1_000_033 + cz
    order = np.argsort(key, kind="stable")
    key, owner = key[order], owner[order]
    starts = np.r_[0, np.nonzero(np.diff(key))[0] + 1]
    ends = np.r_[starts[1:], len(key)]
    gsize = ends - starts
    pos = np.arange(len(key))
    gend = np.repeat(ends, gsize)
    npair = gend - pos - 1
    first = np.repeat(pos, npair)
    second = first + 1 + (np.arange(npair.sum()) - np.repeat(np.cumsum(npair) - npair, npair))
    i, j = owner[first], owner[second]
    i, j = np.minimum(i, j), np.maximum(i, j)
    pairs = np.unique(i * len(f) + j)
    i, j = pairs // len(f), pairs % len(f)
    ok = (i != j) & np.all((lo[i] <= hi[j]) & (lo[j] <= hi[i]), axis=1)
    i, j = i[ok], j[ok]
    share = (f[i][:, :, None] == f[j][:, None, :]).any((1, 2))
    return np.stack([i[~share], j[~share]], 1)


def self_intersections(v: np.ndarray, f: np.ndarray, subset: np.ndarray | None = None,
                       chunk: int = 200_000) -> np.ndarray:
    """Pairs (K, 2) of non-adjacent faces that intersect (exact orientation tests in float64).

    subset: optional face indices; then only pairs within the subset are tested (ids stay global).
    """
    if subset is not None:
        subset = np.asarray(subset)
        return subset[self_intersections(v, f[subset], None, chunk)] if len(subset) else np.zeros((0, 2), np.int64)
    pairs = candidate_pairs(v, f)
    hits = []
    for s in range(0, len(pairs), chunk):
        pi = pairs[s:s + chunk]
        A, B = v[f[pi[:, 0]]], v[f[pi[:, 1]]]
        hit = np.zeros(len(pi), bool)
        for X, Y in ((A, B), (B, A)):
            for e in range(3):
                hit |= _segment_hits_triangle(X[:, e], X[:, (e + 1) % 3], Y[:, 0], Y[:, 1], Y[:, 2])
        hits.append(pi[hit])
    return np.concatenate(hits) if hits else np.zeros((0, 2), np.int64)


def vertex_neighbours(f: np.ndarray, n: int) -> csr_matrix:
    """Sparse (n, n) adjacency matrix (CSR, 1 per edge) of a triangle mesh."""
    e = edges(f)
    A = coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n)).tocsr()
    A = ((A + A.T) > 0).astype(np.float64)
    return A
