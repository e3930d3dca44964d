"""graspkit's procedural humanoid, written in the SMPL-X file format (the licensed model cannot be had).

    body plan (primitives, _proc_anatomy) -> signed distance on a lens-warped grid (_proc_sdf)
    -> marching cubes -> largest component -> quadric decimation -> Delaunay flips, tangential
    relaxation onto the fine surface, edge splits to exactly 10,475 vertices (_proc_remesh)
    -> checks: closed, manifold, oriented, genus 0, no self-intersection (_proc_mesh)
    -> SMPL-X landmark vertex ids moved onto the matching anatomy
    -> skinning weights, joint regressor, shape and expression bases (_proc_rig), pose correctives
    for elbows and knees (_proc_correctives), hand-pose PCA (hand_poses), face landmarks -> arrays.

Deterministic: the same seed gives byte-identical arrays; the seed varies a few proportions only.
`docs/body_model.md` describes the result and its measured figures.
"""
from __future__ import annotations

import os
import sys
import time
from pathlib import Path
from typing import Mapping

import numpy as np

from graspkit.body import _proc_mesh as M
from graspkit.body._proc_anatomy import J, Proportions, body_plan, landmark_targets
from graspkit.body._proc_correctives import fit_correctives
from graspkit.body._proc_rig import bone_ends, expression_basis, joint_regressor, shape_basis, skinning_weights
from graspkit.body._proc_remesh import SurfaceProjector, delaunay_flips, relax
from graspkit.body._proc_sdf import Body, Lens, sample_grid, warp
from graspkit.body.hand_poses import hand_pca
from graspkit.body.skeleton import NUM_JOINTS, NUM_VERTICES, PARENTS, SMPLX_LANDMARK_VERTEX_IDS
from graspkit.paths import naming_errors, publish, sweep_stale_temps, temp_beside
from graspkit.progress import hidden

__all__ = ["build_procedural_smplx", "save_model_npz", "part_of_vertex", "GRID_SPACING"]

GRID_SPACING = 0.0045        # metres in the lens-warped grid (about 1.8 mm on the hands, 3 mm on the face)
NUM_SPLITS = 1975            # the decimation stops this many vertices short; longest-edge splits add the rest
ROOT_PARENT = 4294967295     # the root's parent in the real files' kintree_table (uint32 -1)


def _say(progress: bool, t0: float, msg: str) -> None:
    """Print a progress line with the elapsed time (on stderr, as the bars: stdout keeps the results)."""
    if not hidden(progress):
        print(f"[{time.perf_counter() - t0:6.1f} s] {msg}", file=sys.stderr, flush=True)


def mesh_problems(v: np.ndarray, f: np.ndarray, intersections: bool = True) -> list[str]:
    """What keeps (v, f) from being a closed, oriented, genus-0, self-intersection-free surface ([] if nothing)."""
    r = M.topology_report(v, f)
    out = [k for k in ("watertight", "winding_consistent") if not r[k]]
    out += [f"genus {r['genus']}"] if r["genus"] != 0 else []
    out += [f"{r['degenerate_faces']} degenerate faces"] if r["degenerate_faces"] else []
    out += ["inward orientation"] if r["volume"] <= 0 else []
    if not out:
        out += [f"{M.pinched_vertices(f, len(v))} pinched vertices"] if M.pinched_vertices(f, len(v)) else []
    if not out and intersections:
        n = len(M.self_intersections(v, f))
        out += [f"{n} self-intersecting face pairs"] if n else []
    return out


def _mesh(body: Body, lenses: list[Lens], h: float, n_vertices: int, progress: bool, t0: float):
    """Closed genus-0 triangle mesh (V,3), (F,3) of the body with exactly n_vertices vertices.

    Quadric decimation occasionally leaves a non-manifold spot; then the next of a fixed sequence of
    target counts is tried (deterministic), until the finished mesh passes every check.
    """
    import fast_simplification

    field, u0 = sample_grid(body, lenses, h, progress)
    _say(progress, t0, "sampled the signed distance")
    vu, f_mc = M.marching_cubes(field, h, u0)
    del field
    vu, f_mc = M.largest_component(vu, f_mc)
    x = warp(vu, lenses)
    project = SurfaceProjector(x, f_mc)
    _say(progress, t0, f"marching cubes: {len(x)} vertices")
    n0 = n_vertices - NUM_SPLITS * n_vertices // NUM_VERTICES
    problems: list[str] = []
    for attempt, dn in enumerate((0, -7, 11, -19, 23, -31, 37, -43)):
        vs, fs = fast_simplification.simplify(x, f_mc.astype(np.int64), target_count=2 * (n0 + dn - 2), agg=7)
        v, f = M.largest_component(np.asarray(vs, np.float64), M.drop_doubled_faces(np.asarray(fs, np.int64)))
        problems = ["too many vertices"] if len(v) > n_vertices else mesh_problems(v, f, intersections=False)
        if problems:
            problems = ["decimation: " + ", ".join(problems)]
            continue
        f = delaunay_flips(v, f)
        v = relax(v, f, project, iters=4)
        f = delaunay_flips(v, f)
        v, f = M.split_longest_edges(v, f, n_vertices)   # flat midpoint splits: the surface does not move
        f = delaunay_flips(v, f)
        v = relax(v, f, project, iters=3)
        f = delaunay_flips(v, f)
        problems = mesh_problems(v, f)
        if not problems:
            _say(progress, t0, f"decimated, remeshed and split: {len(v)} vertices, {len(f)} faces "
                               f"(attempt {attempt + 1}); closed, oriented, genus 0, no self-intersection")
            return v, f
    raise RuntimeError(f"procedural mesh: no valid decimation found (last: {problems})")


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
    """The 51 static face landmarks (iBUG-68 points 17..67: brows, nose, eyes, lips) as 3D targets (51, 3).

    As in the 68-point scheme, each group runs from the subject's right (-x) to the left (+x).
    """
    pts = []
    for xs in (np.linspace(-0.056, -0.012, 5), np.linspace(0.012, 0.056, 5)):        # brows 17-21, 22-26
        pts += [(x, 0.306 + 0.006 * np.cos((abs(x) - 0.034) / 0.022 * 1.2), 0.09) for x in xs]
    pts += [(0, y, 0.09 + (0.292 - y) * 0.45) for y in np.linspace(0.292, 0.258, 4)]   # nose bridge 27-30
    pts += [(x, 0.245, 0.10) for x in np.linspace(-0.014, 0.014, 5)]                    # nostrils 31-35
    lid = np.deg2rad([180, 120, 60, 0, -60, -120])       # corner, upper lid, corner, lower lid (36-41, 42-47)
    for cx in (-0.032, 0.032):
        pts += [(cx + 0.013 * np.cos(a), 0.290 + 0.005 * np.sin(a), 0.09) for a in lid]
    pts += [(0.025 * np.cos(t), 0.207 + 0.009 * np.sin(t), 0.09)                       # outer lips 48-59
            for t in np.deg2rad(180 - 30 * np.arange(12))]
    pts += [(0.016 * np.cos(t), 0.207 + 0.002 * np.sin(t), 0.09)                       # inner lips 60-67
            for t in np.deg2rad(180 - 45 * np.arange(8))]
    return np.asarray(pts, float)


def contour_yaws() -> np.ndarray:
    """The yaw (degrees) of each of the 79 dynamic-contour bins (79,), in SMPL-X's order: bin 0 is 0°, bins 1..39
    are +1..+39°, bins 40..78 are -1..-39° (smplx's `find_dynamic_lmk_idx_and_bcoords` reads the bins this way, the
    yaw being minus the neck chain's rotation about the vertical axis)."""
    return np.concatenate([np.arange(0, 40), -np.arange(1, 40)]).astype(float)


def contour_targets() -> np.ndarray:
    """Jaw-line contour targets (79, 17, 3): one row of 17 points (right ear -> chin -> left ear) per yaw bin, bins
    ordered as `contour_yaws`."""
    out = np.zeros((79, 17, 3))
    for i, yaw in enumerate(contour_yaws()):
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
    _say(progress, t0, "pose correctives (elbows, knees, hips)")
    shapedirs = np.concatenate([shape_basis(v, weights, joints, ends), expression_basis(v, weights)], 2)
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


def part_of_vertex(arrays: Mapping[str, np.ndarray]) -> np.ndarray:
    """The joint (V,) whose part each vertex belongs to: argmax of the skinning weights of a model's arrays."""
    return np.asarray(arrays["weights"]).argmax(1)


def save_model_npz(arrays: dict[str, np.ndarray], path: str | os.PathLike) -> Path:
    """Write arrays to a compressed .npz atomically (temporary file in the same folder, synced, then renamed)."""
    path = Path(path)
    tmp = temp_beside(path)          # .<name>.<random>.tmp: not a *.npz that a folder listing offers as a model
    try:
        with naming_errors(path), open(tmp, "wb") as fh:
            np.savez_compressed(fh, **arrays)
        with naming_errors(path):
            publish(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    sweep_stale_temps(path)          # a killed build's
    return path
