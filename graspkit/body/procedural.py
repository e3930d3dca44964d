"""graspkit's procedural humanoid, written in the SMPL-X file format (the licensed model cannot be had).

    body plan (primitives, _proc_anatomy) -> signed distance on a lens-warped grid (_proc_sdf)
    -> marching cubes -> largest component -> quadric decimation -> Delaunay flips, tangential
    relaxation onto the fine surface, edge splits to exactly 10,475 vertices (_proc_remesh) -> checks (closed, manifold, oriented, genus 0, no self-intersection) (_proc_mesh)
    -> skinning weights, joint regressor, shape and expression bases (_proc_rig), hand-pose PCA
    (hand_poses) -> SMPL-X landmark vertex ids moved onto the matching anatomy -> arrays.

Deterministic: the same seed gives byte-identical arrays; the seed varies a few proportions only.
`docs/body_model.md` describes the result and its measured figures.
"""
from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np

from graspkit.body import _proc_mesh as M
from graspkit.body._proc_anatomy import J, Proportions, body_plan, landmark_targets
from graspkit.body._proc_correctives import fit_correctives
from graspkit.body._proc_rig import (bone_ends, expression_basis, joint_regressor, part_of_vertex, shape_basis,
                                     skinning_weights)
from graspkit.body._proc_remesh import SurfaceProjector, delaunay_flips, relax
from graspkit.body._proc_sdf import Body, Lens, sample_grid, warp
from graspkit.body.hand_poses import hand_pca
from graspkit.body.skeleton import NUM_JOINTS, NUM_VERTICES, PARENTS, SMPLX_LANDMARK_VERTEX_IDS

__all__ = ["build_procedural_smplx", "save_model_npz", "part_of_vertex", "GRID_SPACING"]

GRID_SPACING = 0.0045        # metres in the lens-warped grid (about 1.8 mm on the hands, 3 mm on the face)
NUM_SPLITS = 1975            # the decimation stops this many vertices short; longest-edge splits add the rest
ROOT_PARENT = 4294967295     # the root's parent in the real files' kintree_table (uint32 -1)


def _say(progress: bool, t0: float, msg: str) -> None:
    """Print a progress line with the elapsed time."""
    if progress:
        print(f"[{time.perf_counter() - t0:6.1f} s] {msg}", flush=True)


def project_to_surface(v: np.ndarray, body: Body, iters: int = 3, eps: float = 1e-4) -> np.ndarray:
    """Move points (N,3) onto the body's zero level set along the field gradient (Newton steps)."""
    v = v.copy()
    off = np.eye(3) * eps
    for _ in range(iters):
        d, _ = body.evaluate(v)
        g = np.stack([(body.evaluate(v + o)[0] - body.evaluate(v - o)[0]) / (2 * eps) for o in off], 1)
        step = d / np.maximum((g * g).sum(1), 1e-8)
        v -= np.clip(step, -0.002, 0.002)[:, None] * g
    return v


def _mesh(body: Body, lenses: list[Lens], h: float, n_vertices: int, progress: bool, t0: float):
    """Closed genus-0 triangle mesh (V,3), (F,3) of the body with exactly n_vertices vertices."""
    field, u0 = sample_grid(body, lenses, h, progress)
    _say(progress, t0, "sampled the signed distance")
    vu, f = M.marching_cubes(field, h, u0)
    del field
    vu, f = M.largest_component(vu, f)
    x = warp(vu, lenses)
    _say(progress, t0, f"marching cubes: {len(x)} vertices")
    import fast_simplification

    n0 = n_vertices - NUM_SPLITS * n_vertices // NUM_VERTICES
    f_mc = f
    vs, fs = fast_simplification.simplify(x, f.astype(np.int64), target_count=2 * (n0 - 2), agg=7)
    v, f = M.compact(np.asarray(vs, np.float64), np.asarray(fs, np.int64))
    if len(v) > n_vertices:
        raise RuntimeError(f"decimation left {len(v)} vertices, more than {n_vertices}")
    project = SurfaceProjector(x, f_mc)
    f = delaunay_flips(v, f)
    v = relax(v, f, project, iters=4)
    f = delaunay_flips(v, f)
    v, f = M.split_longest_edges(v, f, n_vertices)   # flat midpoint splits: the surface does not move
    f = delaunay_flips(v, f)
    v = relax(v, f, project, iters=3)
    f = delaunay_flips(v, f)
    _say(progress, t0, f"decimated and split: {len(v)} vertices, {len(f)} faces")
    return v, f


def _landmark_permutation(v: np.ndarray, targets: dict[str, np.ndarray]) -> np.ndarray:
    """order (V,) with new vertex i = old vertex order[i], placing each SMPL-X landmark id on its anatomy."""
    order = np.arange(len(v))
    where = np.arange(len(v))           # where[old] = current new position of old vertex
    taken: set[int] = set()
    for name, vid in SMPLX_LANDMARK_VERTEX_IDS.items():
        d = np.linalg.norm(v - targets[name], axis=1)
        d[list(taken)] = np.inf
        old = int(np.argmin(d))
        taken.add(old)
        a, b = where[old], vid                 # swap positions a and b
        oa, ob = order[a], order[b]
        order[a], order[b] = ob, oa
        where[oa], where[ob] = b, a
    return order


def _surface_points(v: np.ndarray, f: np.ndarray, pts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Nearest surface point of each target (N,3): face index (N,) and barycentric coordinates (N,3)."""
    import trimesh

    mesh = trimesh.Trimesh(v, f, process=False)
    closest, _, tri = trimesh.proximity.closest_point(mesh, pts)
    bary = trimesh.triangles.points_to_barycentric(v[f[tri]], closest)
    bary = np.clip(bary, 0.0, 1.0)
    return tri.astype(np.int64), bary / bary.sum(1, keepdims=True)


def face_landmark_targets() -> np.ndarray:
    """The 51 static face landmarks (iBUG 68 points 17..67: brows, nose, eyes, lips) as 3D targets (51, 3)."""
    pts = []
    for xs in (np.linspace(-0.056, -0.012, 5), np.linspace(0.012, 0.056, 5)):        # brows (subject right, left)
        pts += [(x, 0.306 + 0.006 * np.cos((abs(x) - 0.034) / 0.022 * 1.2), 0.09) for x in xs]
    pts += [(0, y, 0.09 + (0.292 - y) * 0.45) for y in np.linspace(0.292, 0.258, 4)]   # nose bridge
    pts += [(x, 0.245 - 0.004 * (abs(x) < 0.001), 0.10) for x in np.linspace(-0.014, 0.014, 5)]  # nostrils
    for cx, inner_first in ((-0.032, False), (0.032, True)):                          # eyes
        ang = np.deg2rad([180, 120, 60, 0, -60, -120])
        if inner_first:
            ang = np.deg2rad([180, 120, 60, 0, -60, -120])
        ex = cx + 0.013 * np.cos(ang) * (1 if cx < 0 else -1) * -1
        pts += [(x, 0.290 + 0.005 * np.sin(a), 0.09) for x, a in zip(ex, ang)]
    a = np.deg2rad(np.linspace(180, -150, 12))                                          # outer lips
    pts += [(0.025 * np.cos(t) * -1, 0.207 + 0.009 * np.sin(t), 0.09) for t in a]
    a = np.deg2rad(np.array([180, 135, 90, 45, 0, -45, -90, -135]))                     # inner lips
    pts += [(0.016 * np.cos(t) * -1, 0.207 + 0.002 * np.sin(t), 0.09) for t in a]
    return np.asarray(pts, float)


def contour_targets() -> np.ndarray:
    """Jaw-line contour targets (79, 17, 3): one row of 17 points (right ear -> chin -> left ear) per yaw bin."""
    out = np.zeros((79, 17, 3))
    for i, yaw in enumerate(np.linspace(-39, 39, 79)):
        phi = np.deg2rad(np.linspace(-80, 80, 17) * (1 - abs(yaw) / 200) + 0.5 * yaw)
        y = 0.255 - 0.075 * np.cos(phi) ** 1.5
        out[i] = np.stack([0.07 * np.sin(phi), y, 0.02 + 0.07 * np.cos(phi)], 1)
    return out


def build_procedural_smplx(seed: int = 0, progress: bool = True, grid_spacing: float = GRID_SPACING,
                           n_vertices: int = NUM_VERTICES) -> dict[str, np.ndarray]:
    """Build the procedural humanoid as SMPL-X arrays (v_template (V,3), f, shapedirs (V,3,20), ...).

    grid_spacing and n_vertices are knobs for quick tests; the shipped file uses the defaults.
    """
    t0 = time.perf_counter()
    P = Proportions().jittered(seed)
    body, lenses, joints = body_plan(P)
    v, f = _mesh(body, lenses, grid_spacing, n_vertices, progress, t0)
    report = M.topology_report(v, f)
    if not (report["watertight"] and report["winding_consistent"] and report["genus"] == 0
            and report["degenerate_faces"] == 0 and report["volume"] > 0):
        raise RuntimeError(f"procedural mesh is not a closed oriented genus-0 surface: {report}")
    hits = M.self_intersections(v, f)
    if len(hits):
        raise RuntimeError(f"procedural mesh intersects itself ({len(hits)} face pairs)")
    _say(progress, t0, f"checked: closed, oriented, genus 0, no self-intersection")

    if n_vertices == NUM_VERTICES:
        order = _landmark_permutation(v, landmark_targets(P, joints))
        inv = np.empty_like(order)
        inv[order] = np.arange(len(order))
        v, f = v[order], inv[f]

    _, owner = body.evaluate(v)
    labels = np.array([body.prims[o].joint if o >= 0 else J["head"] for o in owner])
    ends = bone_ends(P, joints)
    weights = skinning_weights(v, f, labels, joints, ends, P)
    J_reg = joint_regressor(v, weights, joints)
    _say(progress, t0, "skinning weights and joint regressor")
    posedirs = fit_correctives(v, f, weights, joints, body)
    _say(progress, t0, "pose correctives (elbows, knees)")
    shapedirs = np.concatenate([shape_basis(v, weights, joints, ends), expression_basis(v, weights, joints)], 2)
    lmk_f, lmk_b = _surface_points(v, f, face_landmark_targets())
    ct = contour_targets()
    dyn_f, dyn_b = _surface_points(v, f, ct.reshape(-1, 3))
    hands = {s: hand_pca(joints, side, seed=seed) for s, side in (("l", "left"), ("r", "right"))}
    _say(progress, t0, "shape space, landmarks, hand PCA")
    kintree = np.stack([np.array([ROOT_PARENT] + list(PARENTS[1:]), np.int64), np.arange(NUM_JOINTS, dtype=np.int64)])
    return {
        "v_template": v, "f": f.astype(np.int64),
        "shapedirs": shapedirs, "posedirs": posedirs,
        "J_regressor": J_reg, "weights": weights, "kintree_table": kintree,
        "hands_componentsl": hands["l"][0], "hands_componentsr": hands["r"][0],
        "hands_meanl": hands["l"][1], "hands_meanr": hands["r"][1],
        "lmk_faces_idx": lmk_f, "lmk_bary_coords": lmk_b,
        "dynamic_lmk_faces_idx": dyn_f.reshape(79, 17), "dynamic_lmk_bary_coords": dyn_b.reshape(79, 17, 3),
        "procedural": np.array(f"graspkit procedural humanoid (not the licensed SMPL-X model): {len(v)} vertices, "
                               f"built by graspkit.body.procedural.build_procedural_smplx, seed={seed}"),
    }


def save_model_npz(arrays: dict[str, np.ndarray], path: str | os.PathLike) -> Path:
    """Write arrays to a compressed .npz atomically (temporary file in the same folder, then os.replace)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp.npz")
    try:
        with open(tmp, "wb") as fh:
            np.savez_compressed(fh, **arrays)
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()
    return path
