"""Pose correctives (posedirs) for the procedural humanoid, fitted to the body's own bent shape.

For a joint c and a sample rotation R of it, linear blend skinning gives v_lbs; the *target* is
v_lbs moved onto the zero level set of the body's signed-distance field with every primitive
carried rigidly by its joint (a bent union of capsules keeps its volume and never crosses itself).
The rest-space offset delta = (sum_k w_k R_k)^-1 (target - v_lbs) is fitted, vertex by vertex, as a
linear function of the 9 entries of (R - I) over all samples (ridge least squares): exactly the form
of SMPL's pose blend shapes B_P(theta) = sum_j (vec(R_j) - vec(I)) P_j.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from graspkit.body._proc_anatomy import J, mirror_joint
from scipy.sparse import diags
from scipy.sparse.linalg import spsolve

from graspkit.body._proc_mesh import vertex_neighbours
from graspkit.body._proc_sdf import Body
from graspkit.body.skeleton import NUM_JOINTS, PARENTS

if TYPE_CHECKING:
    from scipy.sparse import csr_matrix


def rodrigues(aa: np.ndarray) -> np.ndarray:
    """Rotation matrix (3,3) of an axis-angle vector (3,)."""
    th = np.linalg.norm(aa)
    if th < 1e-12:
        return np.eye(3)
    k = aa / th
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(th) * K + (1 - np.cos(th)) * K @ K


def _rotvec(R: np.ndarray) -> np.ndarray:
    """Axis-angle vector (3,) of a rotation matrix (angles below 180 degrees)."""
    th = np.arccos(np.clip((np.trace(R) - 1) / 2, -1.0, 1.0))
    if th < 1e-9:
        return np.zeros(3)
    return th / (2 * np.sin(th)) * np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])


def subtree(c: int) -> list[int]:
    """Joint c and all its descendants."""
    out = [c]
    for j in range(c + 1, NUM_JOINTS):
        if PARENTS[j] in out:
            out.append(j)
    return out


@dataclass(frozen=True)
class CorrectiveSpec:
    """Sampling of one (left-side) joint: axes in the rest frame, angle grids in degrees, region radius."""

    joint: str
    flex_axis: tuple[float, float, float]
    flex_deg: tuple[float, ...]
    twist_axis: tuple[float, float, float]
    twist_deg: tuple[float, ...]
    radius: float
    max_move: float


SPECS = (
    CorrectiveSpec("left_elbow", (0, -1, 0), (-10, 20, 45, 70, 95, 120), (1, 0, 0), (-40, 0, 40), 0.10, 0.03),
    CorrectiveSpec("left_knee", (1, 0, 0), (-5, 20, 45, 70, 95, 120), (0, 1, 0), (-20, 0, 20), 0.13, 0.045),
    CorrectiveSpec("left_hip", (-1, 0, 0), (-20, 20, 45, 70, 95), (0, 1, 0), (-20, 0, 20), 0.18, 0.05),
)


def fit_correctives(v: np.ndarray, f: np.ndarray, weights: np.ndarray, joints: np.ndarray, body: Body,
                    specs: tuple[CorrectiveSpec, ...] = SPECS, ridge: float = 1e-3) -> np.ndarray:
    """posedirs (V, 3, 486) with correctives for the given joints (and their mirrors), zeros elsewhere."""
    V = len(v)
    posedirs = np.zeros((V, 3, 9 * (NUM_JOINTS - 1)))
    for spec in specs:
        for side in (1, -1):
            c = J[spec.joint] if side == 1 else mirror_joint(J[spec.joint])
            # rotation vectors are pseudo-vectors: the mirror image of r is -M r, M = diag(-1, 1, 1)
            m = np.array([1.0, -1.0, -1.0]) if side == -1 else np.ones(3)
            fa, ta = np.asarray(spec.flex_axis, float) * m, np.asarray(spec.twist_axis, float) * m
            posedirs[:, :, (c - 1) * 9:c * 9] = _fit_joint(v, f, weights, joints, body, c, fa, ta, spec, ridge)
    return posedirs


def radial_target(x: np.ndarray, centre: np.ndarray, axis: np.ndarray, body: Body,
                  pose: tuple[np.ndarray, np.ndarray], max_move: float,
                  n_grid: int = 48, reach: float = 1.5) -> tuple[np.ndarray, np.ndarray]:
    """Points (N,3) moved onto the posed zero level set along the ray from the rotation axis (through centre),
    and which of them moved (N,) bool.

    Only the distance rho from the axis changes, so the angular order of the vertices around the joint
    (hence the orientation of the triangles in the crease) is kept. The root nearest to the current
    rho is bracketed on a grid over [rho / (1 + reach), rho (1 + reach)] and refined by bisection; points
    near the axis itself, or without a root within max_move, stay.
    """
    rel = x - centre
    along = rel @ axis
    perp = rel - np.outer(along, axis)
    rho0 = np.linalg.norm(perp, axis=1)
    e = perp / np.maximum(rho0, 1e-12)[:, None]
    base = centre + np.outer(along, axis)
    at = lambda r: body.evaluate((base[:, None, :] + r[..., None] * e[:, None, :]).reshape(-1, 3), pose)[0]  # noqa: E731
    scale = np.exp(np.linspace(-np.log1p(reach), np.log1p(reach), n_grid))            # (K,), 1 in the middle
    grid = rho0[:, None] * scale[None]                                                  # (N, K)
    d = at(grid).reshape(grid.shape)
    sign_change = (d[:, :-1] <= 0) & (d[:, 1:] > 0)                                     # inside -> outside
    dist = np.abs(0.5 * (grid[:, :-1] + grid[:, 1:]) - rho0[:, None])
    k = np.where(sign_change, dist, np.inf).argmin(1)
    found = sign_change[np.arange(len(x)), k] & (rho0 > 0.005) & (dist[np.arange(len(x)), k] < max_move)
    lo, hi = grid[np.arange(len(x)), k], grid[np.arange(len(x)), k + 1]
    for _ in range(12):
        m = 0.5 * (lo + hi)
        inside = at(m[:, None]).reshape(-1) <= 0
        lo, hi = np.where(inside, m, lo), np.where(inside, hi, m)
    rho = 0.5 * (lo + hi)
    y = base + rho[:, None] * e
    # only where the ray crosses the surface steeply: near the axis's exit points the ray runs along the
    # surface and a root there would slide the vertex over its neighbours
    eps = 2e-4
    g = np.stack([(body.evaluate(y + o, pose)[0] - body.evaluate(y - o, pose)[0]) for o in np.eye(3) * eps], 1)
    ge = np.abs((g * e).sum(1))
    g_plane = np.linalg.norm(g - np.outer(g @ axis, axis), axis=1)
    # transversal within the bending plane, and the surface not nearly parallel to that plane
    steep = (ge > 0.6 * g_plane) & (ge > 0.25 * np.linalg.norm(g, axis=1))
    ok = found & steep
    return np.where(ok[:, None], y, x), ok


def harmonic_fill(delta: np.ndarray, known: np.ndarray, region: np.ndarray, A: csr_matrix) -> np.ndarray:
    """Displacements (V,3): known rows kept, other region rows harmonic (graph Laplacian), zero outside region."""
    out = np.zeros_like(delta)
    out[region[known]] = delta[region[known]]
    unknown = region[~known]
    if len(unknown) == 0:
        return out
    deg = np.asarray(A.sum(1)).ravel()
    L_uu = diags(deg[unknown]) - A[unknown][:, unknown]
    rhs = A[unknown] @ out
    out[unknown] = np.stack([spsolve(L_uu.tocsc(), rhs[:, k]) for k in range(3)], 1)
    return out


def _fit_joint(v, f, weights, joints, body, c, flex_axis, twist_axis, spec: CorrectiveSpec, ridge: float) -> np.ndarray:
    """Corrective coefficients (V, 3, 9) of joint c from its rotation samples."""
    sub = subtree(c)
    w_sub = weights[:, sub].sum(1)
    near = np.linalg.norm(v - joints[c], axis=1) < spec.radius
    family = weights[:, sub + [PARENTS[c]]].sum(1) > 0.5
    region = np.nonzero(near & family)[0]
    fade = np.clip((spec.radius - np.linalg.norm(v[region] - joints[c], axis=1)) / (0.3 * spec.radius), 0, 1)
    fade = fade * fade * (3 - 2 * fade)
    A = vertex_neighbours(f, len(v))
    local = body.subset(set(sub) | {PARENTS[c]})     # the field near joint c only needs these primitives
    feats, offsets = [], []
    for fl in spec.flex_deg:
        for tw in spec.twist_deg:
            R = rodrigues(np.deg2rad(tw) * twist_axis) @ rodrigues(np.deg2rad(fl) * flex_axis)
            Rs = np.tile(np.eye(3), (NUM_JOINTS, 1, 1))
            ts = np.zeros((NUM_JOINTS, 3))
            Rs[sub] = R
            ts[sub] = joints[c] - R @ joints[c]
            x = v[region]
            ws = w_sub[region, None]
            lbs = (1 - ws) * x + ws * (x @ R.T + ts[c])
            rv = _rotvec(R)
            axis = rv / np.linalg.norm(rv) if np.linalg.norm(rv) > 1e-9 else np.asarray(flex_axis, float)
            target, known = radial_target(lbs, joints[c], axis, local, (Rs, ts), spec.max_move)
            full = np.zeros_like(v)
            full[region] = target - lbs
            target = lbs + harmonic_fill(full, known, region, A)[region]
            Mb = (1 - ws)[:, :, None] * np.eye(3) + ws[:, :, None] * R          # blended rotation per vertex
            delta = np.linalg.solve(Mb, (target - lbs)[:, :, None])[:, :, 0] * fade[:, None]
            feats.append((R - np.eye(3)).reshape(9))
            offsets.append(delta.reshape(-1))
    Phi, D = np.asarray(feats), np.asarray(offsets)
    P = np.linalg.solve(Phi.T @ Phi + ridge * np.eye(9), Phi.T @ D)                # (9, 3 * region)
    out = np.zeros((len(v), 3, 9))
    out[region] = P.reshape(9, len(region), 3).transpose(1, 2, 0)
    return out
