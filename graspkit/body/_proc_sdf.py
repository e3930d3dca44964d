"""Signed-distance primitives, their smooth union, and a warped sampling grid for marching cubes.

The procedural humanoid is the zero level set of a smooth union of simple shapes (tapered elliptic
capsules, ellipsoids, rounded boxes and one lofted trunk). Distances are the usual cheap bounds
(Quilez's ellipsoid approximation), exact enough near the surface, which is all that meshing and
blending need. Each primitive is evaluated only inside its bounding box.

The sampling grid is uniform in a *warped* space u: x = g(u) magnifies balls around the hands and the
head ("bubble lenses", identity outside each ball), so that one marching-cubes pass resolves the
fingers at ~1.8 mm while the trunk is sampled at ~4.5 mm.
"""
from __future__ import annotations

import copy
import sys
from dataclasses import dataclass, field

import numpy as np

from graspkit.progress import hidden

EPS = 1e-12


def _unit(v) -> np.ndarray:
    """Unit vector of v (3,)."""
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


def _ellipsoid_bound(k0: np.ndarray, k1: np.ndarray, rmin: float | np.ndarray) -> np.ndarray:
    """Approximate signed distance from the normalised radii k0 = |q/r| and k1 = |q/r^2| (N,) -> (N,)."""
    outside = k0 * (k0 - 1.0) / np.maximum(k1, EPS)
    return np.where(k0 < 1.0, (k0 - 1.0) * rmin, outside)


@dataclass
class Prim:
    """Base primitive: `joint` owns it for skinning (-1: none), `k` is its blend radius, `sub` subtracts."""

    joint: int = field(default=-1, kw_only=True)
    k: float = field(default=0.0, kw_only=True)
    sub: bool = field(default=False, kw_only=True)

    def sdf(self, p: np.ndarray) -> np.ndarray:  # pragma: no cover - abstract
        """Signed distance (N,) of points p (N, 3), negative inside."""
        raise NotImplementedError

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:  # pragma: no cover - abstract
        """Axis-aligned box (lo (3,), hi (3,)) holding the shape."""
        raise NotImplementedError

    def mirrored(self) -> "Prim":  # pragma: no cover - abstract
        """Copy mirrored across the plane x = 0 (same joint, blend radius and sign)."""
        raise NotImplementedError


@dataclass
class Sweep(Prim):
    """Elliptic capsule a -> b whose semi-axes (along e1, along e2 = u x e1) go linearly from sa to sb.

    caps = how far the rounded ends reach beyond a and b.
    """

    a: np.ndarray
    b: np.ndarray
    sa: tuple[float, float]
    sb: tuple[float, float]
    up: tuple[float, float, float] = (0.0, 1.0, 0.0)
    caps: tuple[float, float] | None = None

    def __post_init__(self) -> None:
        """Derived quantities (frame, radii, resampled profile)."""
        self.a, self.b = np.asarray(self.a, float), np.asarray(self.b, float)
        self.L = float(np.linalg.norm(self.b - self.a))
        self.u = (self.b - self.a) / self.L
        up = np.asarray(self.up, float)
        e1 = up - (up @ self.u) * self.u
        if np.linalg.norm(e1) < 1e-6:  # axis parallel to `up`: any perpendicular will do
            e1 = np.cross(self.u, np.eye(3)[np.argmin(np.abs(self.u))])   # the world axis least along u, never parallel
        self.e1 = _unit(e1)
        self.e2 = np.cross(self.u, self.e1)
        if self.caps is None:
            self.caps = (min(self.sa), min(self.sb))

    def sdf(self, p: np.ndarray) -> np.ndarray:
        """Signed distance (N,) of points p (N, 3)."""
        rel = p - self.a
        s = rel @ self.u
        t = np.clip(s / self.L, 0.0, 1.0)
        o = s - t * self.L                                  # overshoot beyond the ends (0 in between)
        q1, q2 = rel @ self.e1, rel @ self.e2
        r1 = self.sa[0] + t * (self.sb[0] - self.sa[0])
        r2 = self.sa[1] + t * (self.sb[1] - self.sa[1])
        c = np.where(o < 0, self.caps[0], self.caps[1])
        k0 = np.sqrt((q1 / r1) ** 2 + (q2 / r2) ** 2 + (o / c) ** 2)
        k1 = np.sqrt((q1 / r1 ** 2) ** 2 + (q2 / r2 ** 2) ** 2 + (o / c ** 2) ** 2)
        return _ellipsoid_bound(k0, k1, np.minimum(np.minimum(r1, r2), c))

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Axis-aligned box (lo (3,), hi (3,)) holding the shape."""
        r = max(*self.sa, *self.sb, *self.caps)
        return np.minimum(self.a, self.b) - r, np.maximum(self.a, self.b) + r

    def mirrored(self) -> "Sweep":
        """Copy mirrored across the plane x = 0."""
        m = np.array([-1.0, 1.0, 1.0])
        return Sweep(self.a * m, self.b * m, self.sa, self.sb, tuple(np.asarray(self.up) * m), self.caps,
                     joint=self.joint, k=self.k, sub=self.sub)


@dataclass
class Ellipsoid(Prim):
    """Ellipsoid with centre c, semi-axes r along the columns of the rotation R (default: world axes)."""

    c: np.ndarray
    r: tuple[float, float, float]
    R: np.ndarray | None = None

    def __post_init__(self) -> None:
        """Derived quantities (frame, radii, resampled profile)."""
        self.c = np.asarray(self.c, float)
        self.R = np.eye(3) if self.R is None else np.asarray(self.R, float)
        self.rv = np.asarray(self.r, float)

    def sdf(self, p: np.ndarray) -> np.ndarray:
        """Signed distance (N,) of points p (N, 3)."""
        q = (p - self.c) @ self.R
        k0 = np.linalg.norm(q / self.rv, axis=1)
        k1 = np.linalg.norm(q / self.rv ** 2, axis=1)
        return _ellipsoid_bound(k0, k1, self.rv.min())

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Axis-aligned box (lo (3,), hi (3,)) holding the shape."""
        ext = np.abs(self.R) @ self.rv
        return self.c - ext, self.c + ext

    def mirrored(self) -> "Ellipsoid":
        """Copy mirrored across the plane x = 0."""
        m = np.diag([-1.0, 1.0, 1.0])
        return Ellipsoid(self.c @ m, self.r, m @ self.R @ m, joint=self.joint, k=self.k, sub=self.sub)


@dataclass
class RoundBox(Prim):
    """Box with centre c, half sizes h along the columns of R, edges rounded by radius `round`."""

    c: np.ndarray
    h: tuple[float, float, float]
    round: float
    R: np.ndarray | None = None

    def __post_init__(self) -> None:
        """Derived quantities (frame, radii, resampled profile)."""
        self.c = np.asarray(self.c, float)
        self.R = np.eye(3) if self.R is None else np.asarray(self.R, float)
        self.hv = np.asarray(self.h, float)

    def sdf(self, p: np.ndarray) -> np.ndarray:
        """Signed distance (N,) of points p (N, 3)."""
        q = np.abs((p - self.c) @ self.R) - self.hv
        return np.linalg.norm(np.maximum(q, 0.0), axis=1) + np.minimum(q.max(axis=1), 0.0) - self.round

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Axis-aligned box (lo (3,), hi (3,)) holding the shape."""
        ext = np.abs(self.R) @ (self.hv + self.round)
        return self.c - ext, self.c + ext

    def mirrored(self) -> "RoundBox":
        """Copy mirrored across the plane x = 0."""
        m = np.diag([-1.0, 1.0, 1.0])
        return RoundBox(self.c @ m, self.h, self.round, m @ self.R @ m, joint=self.joint, k=self.k, sub=self.sub)


@dataclass
class Loft(Prim):
    """Trunk: elliptic cross-sections (half-width a, half-depth b, centre z c) interpolated along y.

    profile rows are (y, a, b, c), y increasing; the ends are closed by elliptic caps of depth caps.
    """

    profile: np.ndarray
    caps: tuple[float, float] = (0.04, 0.03)

    def __post_init__(self) -> None:
        """Derived quantities (frame, radii, resampled profile)."""
        from scipy.interpolate import PchipInterpolator

        self.profile = np.asarray(self.profile, float)
        # resample the sections with a shape-preserving cubic, so the trunk has no creases at the rows
        y = np.linspace(self.profile[0, 0], self.profile[-1, 0], 256)
        self._fine = np.column_stack([y, PchipInterpolator(self.profile[:, 0], self.profile[:, 1:])(y)])

    def sdf(self, p: np.ndarray) -> np.ndarray:
        """Signed distance (N,) of points p (N, 3)."""
        y, a, b, c = self._fine.T
        yc = np.clip(p[:, 1], y[0], y[-1])
        A, Bd, C = np.interp(yc, y, a), np.interp(yc, y, b), np.interp(yc, y, c)
        o = p[:, 1] - yc
        cap = np.where(o < 0, self.caps[0], self.caps[1])
        qx, qz = p[:, 0], p[:, 2] - C
        k0 = np.sqrt((qx / A) ** 2 + (qz / Bd) ** 2 + (o / cap) ** 2)
        k1 = np.sqrt((qx / A ** 2) ** 2 + (qz / Bd ** 2) ** 2 + (o / cap ** 2) ** 2)
        return _ellipsoid_bound(k0, k1, np.minimum(np.minimum(A, Bd), cap))

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Axis-aligned box (lo (3,), hi (3,)) holding the shape."""
        y, a, b, c = self.profile.T
        lo = np.array([-a.max(), y[0] - self.caps[0], (c - b).min()])
        hi = np.array([a.max(), y[-1] + self.caps[1], (c + b).max()])
        return lo, hi

    def mirrored(self) -> "Loft":
        """Copy mirrored across the plane x = 0 (the trunk is symmetric: the same shape, a new object)."""
        return copy.copy(self)


def smin(a: np.ndarray, b: np.ndarray, k: float) -> np.ndarray:
    """Polynomial smooth minimum of two distance arrays with blend radius k (k = 0: plain min)."""
    if k <= 0:
        return np.minimum(a, b)
    h = np.clip(0.5 + 0.5 * (b - a) / k, 0.0, 1.0)
    return b + (a - b) * h - k * h * (1.0 - h)


def smax(a: np.ndarray, b: np.ndarray, k: float) -> np.ndarray:
    """Polynomial smooth maximum (intersection) of two distance arrays."""
    return -smin(-a, -b, k)


@dataclass
class Floor:
    """Half-space y >= level, intersected smoothly with radius k (flat soles)."""

    level: float
    k: float


@dataclass
class Body:
    """The primitives in blending order and the floor that flattens the soles."""

    prims: list[Prim]
    floor: Floor

    def subset(self, joints: set[int]) -> "Body":
        """The body made of the primitives owned by the given joints only (same order and floor)."""
        return Body([q for q in self.prims if q.joint in joints], self.floor)

    def evaluate(self, p: np.ndarray,
                 pose: tuple[np.ndarray, np.ndarray] | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Signed distance (N,) and owning primitive index (N,) (-1 where none) of points p (N, 3).

        pose: optional rigid transforms (R (55,3,3), t (55,3)) moving each primitive with its joint
        (x_posed = R x_rest + t), for a posed body; primitives without a joint stay put.
        """
        d = np.full(len(p), 1.0)
        raw = np.full(len(p), np.inf)
        owner = np.full(len(p), -1, np.int64)
        frames: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}   # joint -> (points, their box)
        for i, prim in enumerate(self.prims):
            j = prim.joint if pose is not None and prim.joint >= 0 else -1
            if j not in frames:
                q = p if j < 0 else (p - pose[1][j]) @ pose[0][j]          # R^T (p - t), row-wise
                frames[j] = (q, q.min(0), q.max(0))
            q, qlo, qhi = frames[j]
            lo, hi = prim.bounds()
            lo, hi = lo - prim.k - 0.01, hi + prim.k + 0.01
            if np.any(qlo > hi) or np.any(qhi < lo):
                continue
            m = np.all((q >= lo) & (q <= hi), axis=1)
            if not m.any():
                continue
            di = prim.sdf(q[m])
            self._combine(d, raw, owner, m, di, i, prim)
        return self._floor(d, p), owner

    @staticmethod
    def _combine(d: np.ndarray, raw: np.ndarray, owner: np.ndarray, m: np.ndarray | slice, di: np.ndarray,
                 i: int, prim: Prim) -> None:
        """Blend primitive i's distances di into the field d (in place) on the selection m."""
        if prim.sub:
            d[m] = smax(d[m], -di, prim.k)
            return
        d[m] = smin(d[m], di, prim.k)
        if prim.joint >= 0:
            closer = di < raw[m]
            sel_raw, sel_own = raw[m], owner[m]
            sel_raw[closer], sel_own[closer] = di[closer], i
            raw[m], owner[m] = sel_raw, sel_own

    def _floor(self, d: np.ndarray, p: np.ndarray) -> np.ndarray:
        """Intersect the field with the floor half-space."""
        low = p[:, 1] < self.floor.level + 0.05
        d[low] = smax(d[low], self.floor.level - p[low, 1], self.floor.k)
        return d


# ----------------------------------------------------------------------------- warped grid
@dataclass(frozen=True)
class Lens:
    """Bubble lens: the u-ball of radius r0 around c shows the world ball of radius r0/m; identity beyond r1."""

    c: tuple[float, float, float]
    r0: float
    r1: float
    m: float

    def rho(self, r: np.ndarray) -> np.ndarray:
        """World radius for u radius r (monotone; C1 cubic Hermite in the shell r0..r1)."""
        r0, r1, m = self.r0, self.r1, self.m
        t = np.clip((r - r0) / (r1 - r0), 0.0, 1.0)
        D = r1 - r0
        h00, h10, h01, h11 = 2 * t**3 - 3 * t**2 + 1, t**3 - 2 * t**2 + t, -2 * t**3 + 3 * t**2, t**3 - t**2
        shell = h00 * (r0 / m) + h10 * (D / m) + h01 * r1 + h11 * D
        return np.where(r < r0, r / m, np.where(r > r1, r, shell))

    def forward(self, u: np.ndarray) -> np.ndarray:
        """World points (N,3) of u points (N,3)."""
        c = np.asarray(self.c)
        rel = u - c
        r = np.linalg.norm(rel, axis=1)
        scale = np.where(r > 1e-12, self.rho(r) / np.maximum(r, 1e-12), 1.0 / self.m)
        return c + rel * scale[:, None]

    def inverse(self, x: np.ndarray) -> np.ndarray:
        """u points (N,3) of world points (N,3), by bisection on the monotone radius map."""
        c = np.asarray(self.c)
        rel = x - c
        R = np.linalg.norm(rel, axis=1)
        lo, hi = np.zeros_like(R), np.maximum(R * self.m, R) + 1e-9
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            below = self.rho(mid) < R
            lo, hi = np.where(below, mid, lo), np.where(below, hi, mid)
        r = 0.5 * (lo + hi)
        scale = np.where(R > 1e-12, r / np.maximum(R, 1e-12), self.m)
        return c + rel * scale[:, None]


def warp(u: np.ndarray, lenses: list[Lens]) -> np.ndarray:
    """x = g(u): apply the lenses in order (each a diffeomorphism, so the composition is one too)."""
    for lens in lenses:
        u = lens.forward(u)
    return u


def unwarp(x: np.ndarray, lenses: list[Lens]) -> np.ndarray:
    """u = g^-1(x)."""
    for lens in reversed(lenses):
        x = lens.inverse(x)
    return x


BLOCK = 8


def sample_grid(body: Body, lenses: list[Lens], h: float, progress: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Evaluate the body's distance on a uniform u-grid of spacing h: returns (field (nx,ny,nz), u origin (3,)).

    The grid is stored in 8^3 blocks; each primitive is evaluated only on the blocks whose world
    bounding box meets its own.
    """
    corners = []
    for prim in body.prims:
        lo, hi = prim.bounds()
        g = np.stack(np.meshgrid(*[np.linspace(lo[i], hi[i], 5) for i in range(3)], indexing="ij"), -1)
        corners.append(g.reshape(-1, 3))
    uc = unwarp(np.concatenate(corners), lenses)
    u0 = uc.min(0) - 3 * h
    n = np.ceil((uc.max(0) + 3 * h - u0) / h / BLOCK).astype(int) * BLOCK
    nb = n // BLOCK
    # node u coordinates in block-major order: (blocks, 512, 3)
    bi = np.stack(np.meshgrid(*[np.arange(k) for k in nb], indexing="ij"), -1).reshape(-1, 3)
    li = np.stack(np.meshgrid(*[np.arange(BLOCK)] * 3, indexing="ij"), -1).reshape(-1, 3)
    # node u coordinates, coordinate-major (3, B, 512): per-block reductions run over contiguous memory
    X = np.stack([(u0[a] + (bi[:, a, None] * BLOCK + li[None, :, a]) * h).astype(np.float32) for a in range(3)])
    for lens in lenses:  # warp only the blocks that meet each lens's ball
        c = np.asarray(lens.c, np.float32)[:, None]
        gap = np.maximum(np.maximum(X.min(2) - c, c - X.max(2)), 0.0)
        sel = np.nonzero(np.linalg.norm(gap, axis=0) < lens.r1)[0]
        pts = X[:, sel].reshape(3, -1).T.astype(np.float64)
        X[:, sel] = lens.forward(pts).T.reshape(3, len(sel), -1)
    blo, bhi = X.min(2).T, X.max(2).T                                    # (B, 3) world box per block
    D = np.ones(X.shape[1:], np.float32)
    for prim in body.prims:
        lo, hi = prim.bounds()
        sel = np.nonzero(np.all((bhi >= lo - prim.k) & (blo <= hi + prim.k), axis=1))[0]
        if len(sel) == 0:
            continue
        di = prim.sdf(X[:, sel].reshape(3, -1).T).reshape(len(sel), -1).astype(np.float32)
        if prim.sub:
            D[sel] = smax(D[sel], -di, prim.k)
        else:
            D[sel] = smin(D[sel], di, prim.k)
    low = np.nonzero(blo[:, 1] < body.floor.level + 0.05)[0]
    D[low] = smax(D[low], body.floor.level - X[1, low], body.floor.k)
    if not hidden(progress):
        print(f"  grid {tuple(int(k) for k in n)} = {np.prod(n) / 1e6:.1f}M nodes, spacing {h * 1e3:.1f} mm (u space)",
              file=sys.stderr)
    B = BLOCK
    field_ = D.reshape(*nb, B, B, B).transpose(0, 3, 1, 4, 2, 5).reshape(tuple(n))
    return field_, u0
