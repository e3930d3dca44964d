"""Labels, GRAB-style files and the `graspkit data make --kind {grasp,approach}` generator.

Labels of one frame (`frame_labels`, all in the world frame, z up, metres):
- SAGA (Sec. 3.2, App. A.1): the 143 markers, C_M (marker within 2 cm of the object surface), the 2048 object points
  and normals, C_O (object point within 1 cm of the body surface) (graspkit's thresholds: graspkit.objects.contact);
- GOAL (Sec. 3.2-3.4, Eq. 2, 9): the 400 sampled vertices (99 on the right hand), the offset from each to its closest
  object point, the head direction q, the object translation, the object's BPS code (1024 basis points, 15 cm
  ball, object points minus the object translation) and the goal hand's BPS code with the same basis;
- the object height (SAGA's t_O) and GRAB's per-vertex body contact (body vertex within 1 cm of the object).

Files: `<out>/grasp_000000.npz` ... (static grasps, one frame) or `<out>/approach_000000.npz` ... (approach clips),
GRAB-style (graspkit.data.grab), and `<out>/meshes/<object>.ply`. Grasps are made in chunks of CHUNK of one object
(chunk c: object OBJECT_ORDER[c mod 17]); a chunk is always fitted whole, and grasp i's task seed derives from
(seed, kind, i, attempt), so the same command writes the same bytes whatever the number of workers, interruptions
or --n. A grasp that fails the acceptance test (`accepted`) is drawn again (up to MAX_ATTEMPTS); the best attempt is
kept and its file says whether it passed (`grasp.accepted`).
"""
from __future__ import annotations

import os
from functools import lru_cache
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import torch

from graspkit.body.markers import goal_vertices, saga_markers
from graspkit.checks import check_int, check_seed
from graspkit.data.approach import approach_motion
from graspkit.data.grab import DEFAULT_MODEL_NAME, GraspSequence, export_object_ply, save_grasp_sequence
from graspkit.data.grasp import GRASP_PARTS, GraspFitter, GraspResult, object_points, sample_grasp_task
from graspkit.data.ik import matrix_axis_angle
from graspkit.objects.bps import bps_basis, bps_encode
from graspkit.objects.catalogue import make_object
from graspkit.objects.contact import OBJECT_CONTACT_THRESHOLD, marker_contact
from graspkit.objects.distance import nearest_neighbours, point_mesh_distance
from graspkit.objects.placement import ObjectPose, apply_pose
from graspkit.paths import default_model_path, drop_damaged, pool_results
from graspkit.state import keeps_torch_state

if TYPE_CHECKING:
    from graspkit.body import BodyModel

KINDS = ("grasp", "approach")
KIND_IDS = {"grasp": 11, "approach": 12}
DEFAULT_N = {"grasp": 1700, "approach": 510}
CHUNK = 16
MAX_ATTEMPTS = 4
OBJECT_ORDER = tuple(sorted(GRASP_PARTS))
LABEL_MARGIN = 0.03          # m: body vertices this close to the object's box are measured exactly


def task_seed(seed: int, kind: str, index: int, attempt: int = 0) -> int:
    """Seed of grasp `index`'s attempt, from (seed, kind, index, attempt) through numpy's SeedSequence."""
    return int(np.random.SeedSequence([seed, KIND_IDS[kind], index, attempt]).generate_state(1)[0])


def chunk_object(chunk: int, objects: tuple[str, ...] = OBJECT_ORDER) -> str:
    """The object of chunk `chunk` (objects cycle in the given order)."""
    return objects[chunk % len(objects)]


def file_path(out: Path, kind: str, index: int) -> Path:
    """File name of item `index`."""
    return Path(out) / f"{kind}_{index:06d}.npz"


def accepted(q: dict, grasp_type: str) -> bool:
    """The acceptance test of a fitted grasp's quality dict: in contact, penetration <= 0.5 cm deep and <= 4 cm^3,
    both feet within 1 cm of the ground, the wrist within 75 deg of its rest, and a real grasp: pinch = thumb and
    index or middle pad within 3 mm; other types = at least three regions (palm, pads) within 3 mm, with the palm
    within 6 mm or the thumb within 3 mm."""
    r = np.asarray(q["regions_mm"])            # palm, thumb, index, middle, ring, pinky
    touch = r <= 3.0
    grip = ((touch[1] and (touch[2] or touch[3])) if grasp_type == "pinch"
            else ((r[0] <= 6.0 or touch[1]) and touch.sum() >= 3))
    return bool(q["contact"] and q["depth_cm"] <= 0.5 and q["volume_cm3"] <= 4.0 and q["feet_cm"] <= 1.0
                and q["arm_residual_deg"] <= 75.0 and grip)


def badness(q: dict) -> float:
    """A score to keep the best of several failed attempts (lower is better)."""
    r = np.asarray(q["regions_mm"])
    return (10.0 * (not q["contact"]) + q["depth_cm"] * 4 + q["volume_cm3"] + 10.0 * (q["feet_cm"] > 1.0)
            + float(np.clip(r, 0, 20).sum()) / 10)


@lru_cache(maxsize=4)
def _goal_vertices(bm):
    return goal_vertices(bm)


@lru_cache(maxsize=1)
def _basis() -> torch.Tensor:
    return bps_basis().double()


def frame_labels(bm: BodyModel, vertices: torch.Tensor, name: str, pose: ObjectPose,
                 hand_ids: np.ndarray) -> dict[str, np.ndarray]:
    """SAGA and GOAL labels of one body (V,3) (world, float64) grasping object `name` at `pose` (module docstring)."""
    obj = apply_pose(pose, make_object(name))
    V = vertices.double()
    markers = saga_markers(bm).select(V)
    c_m = marker_contact(markers, obj)
    pts, _ = object_points(name)
    O = torch.as_tensor(pts @ pose.rotation.T + pose.translation)
    lo = torch.as_tensor(obj.bounds[0] - LABEL_MARGIN)
    hi = torch.as_tensor(obj.bounds[1] + LABEL_MARGIN)
    near = ((V >= lo) & (V <= hi)).all(1)
    c_o = torch.zeros(len(O), dtype=torch.float64)
    c_b = np.zeros(len(V), np.uint8)
    if near.any():
        faces = bm.faces
        keep = near[faces].any(1)
        if keep.any():
            d = point_mesh_distance(O, (V, faces[keep])).distance
            c_o = (d <= OBJECT_CONTACT_THRESHOLD).double()
        ids = torch.nonzero(near)[:, 0]
        dv = point_mesh_distance(V[ids], obj).distance
        c_b[ids.numpy()] = (dv <= OBJECT_CONTACT_THRESHOLD).numpy()
    gv = _goal_vertices(bm)
    v400 = V[torch.as_tensor(gv.vertex_ids)]
    _, idx = nearest_neighbours(v400, O)
    offsets = O[idx] - v400
    t = torch.as_tensor(pose.translation)
    basis = _basis()
    return {
        "saga.markers": markers.float().numpy(), "saga.marker_ids": saga_markers(bm).vertex_ids.astype(np.int64),
        "contact.markers": c_m.numpy().astype(np.uint8),
        "contact.object": c_o.numpy().astype(np.uint8), "contact.body": c_b,
        "goal.vertex_ids": gv.vertex_ids.astype(np.int64), "goal.right_hand": gv.right_hand.astype(np.int64),
        "goal.vertices": v400.float().numpy(), "goal.offsets": offsets.float().numpy(),
        "goal.hand_offsets": offsets[torch.as_tensor(gv.right_hand)].float().numpy(),
        "goal.head_direction": gv.head_direction(V).float().numpy(),
        "goal.object_transl": pose.translation.astype(np.float32),
        "goal.bps_object": bps_encode(O - t, basis).float().numpy(),
        "goal.bps_hand": bps_encode(V[torch.as_tensor(hand_ids)] - t, basis).float().numpy(),
        "object.height": np.array(np.float32(pose.translation[2])),
    }


FRAME_KEYS = ("contact.markers", "contact.object", "contact.body")


def _extras(r: GraspResult, index: int, seed: int, attempt: int, ok: bool) -> dict[str, np.ndarray]:
    """graspkit's bookkeeping keys of one grasp."""
    from graspkit.data.grasp import GRASP_PARTS, grasp_candidates

    t = r.task
    cand = grasp_candidates(t.object_name, t.grasp_type)
    q = r.quality
    return {"grasp.type": np.array(t.grasp_type), "grasp.part": np.array(GRASP_PARTS[t.object_name][cand.part[t.candidate]].name),
            "grasp.accepted": np.array(ok), "grasp.attempt": np.array(attempt), "grasp.index": np.array(index),
            "grasp.seed": np.array(seed), "grasp.curls": r.curls.astype(np.float32),
            "grasp.start": np.array([t.start.x, t.start.y, t.start.heading], np.float32),
            "grasp.start_pose": np.array(t.start_pose),
            "grasp.quality.min_distance_mm": np.array(np.float32(1000 * q["min_distance"])),
            "grasp.quality.volume_cm3": np.array(np.float32(q["volume_cm3"])),
            "grasp.quality.depth_cm": np.array(np.float32(q["depth_cm"])),
            "grasp.quality.feet_cm": np.array(np.float32(q["feet_cm"])),
            "grasp.quality.regions_mm": np.asarray(q["regions_mm"], np.float32),
            "grasp.quality.arm_residual_deg": np.array(np.float32(q["arm_residual_deg"]))}


def grasp_sequence(fitter: GraspFitter, r: GraspResult, vertices: torch.Tensor, index: int, seed: int, attempt: int,
                   ok: bool, mesh_path: str) -> GraspSequence:
    """The one-frame GRAB-style sequence of a static grasp, with its labels."""
    t = r.task
    lab = frame_labels(fitter.bm, vertices, t.object_name, t.object_pose, fitter.hm.hand_ids)
    pts, nrm = object_points(t.object_name)
    orient = matrix_axis_angle(t.object_pose.rotation)
    contacts = {k.split(".", 1)[1]: lab.pop(k)[None] for k in FRAME_KEYS}
    contacts["feet"] = np.ones((1, 4), np.uint8)
    extras = {**lab, **_extras(r, index, seed, attempt, ok), "grasp.frame": np.array(0)}
    return GraspSequence(r.poses[None], r.trans[None], r.betas, 30.0, t.object_name, t.object_pose.translation[None],
                         orient[None], mesh_path, contacts, extras, pts, nrm)


def approach_sequence(fitter: GraspFitter, r: GraspResult, vertices: torch.Tensor, index: int, seed: int, attempt: int,
                      ok: bool, mesh_path: str) -> GraspSequence:
    """The GRAB-style approach-and-grasp clip of a fitted grasp, labelled per frame (contacts) and at the goal frame."""
    t = r.task
    bm = fitter.bm
    from graspkit.data.rig import build_rig
    m = approach_motion(r.plan, r.grasp_frame, r.poses, r.init_poses[40:55], t.start_pose, r.approach_dir,
                        build_rig(bm, t.betas))
    g = r.grasp_frame
    lab = frame_labels(bm, vertices, t.object_name, t.object_pose, fitter.hm.hand_ids)
    T = m.num_frames
    contacts = {k.split(".", 1)[1]: np.zeros((T,) + lab[k].shape, np.uint8) for k in FRAME_KEYS}
    for k in FRAME_KEYS:
        contacts[k.split(".", 1)[1]][g:] = lab.pop(k)
    obj = apply_pose(t.object_pose, make_object(t.object_name))
    lo, hi = obj.bounds[0] - 0.05, obj.bounds[1] + 0.05
    rot = m.rotmats(bm.dtype)
    for f in range(g):                       # frames before the grasp where the body is near the object
        with torch.no_grad():
            v = bm.forward_rotmats(rot[f:f + 1], betas=torch.as_tensor(m.betas[None]),
                                   transl=torch.as_tensor(m.trans[f:f + 1], dtype=bm.dtype)).vertices[0].double()
        if not ((v >= torch.as_tensor(lo)) & (v <= torch.as_tensor(hi))).all(1).any():
            continue
        lf = frame_labels(bm, v, t.object_name, t.object_pose, fitter.hm.hand_ids)
        for k in FRAME_KEYS:
            contacts[k.split(".", 1)[1]][f] = lf[k]
    contacts["feet"] = m.contacts.astype(np.uint8)
    pts, nrm = object_points(t.object_name)
    orient = matrix_axis_angle(t.object_pose.rotation)
    extras = {**lab, **_extras(r, index, seed, attempt, ok), "grasp.goal_frame": np.array(g)}
    return GraspSequence(m.poses, m.trans, m.betas, m.fps, t.object_name, np.broadcast_to(t.object_pose.translation, (T, 3)),
                         np.broadcast_to(orient, (T, 3)), mesh_path, contacts, extras, pts, nrm)


def fit_chunk(fitter: GraspFitter, kind: str, seed: int, chunk: int, size: int = CHUNK,
              objects: tuple[str, ...] = OBJECT_ORDER) -> list[tuple[GraspResult, int, bool]]:
    """Fit the `size` grasps of chunk `chunk` (retrying failures): (result, attempt, accepted) per item."""
    name = chunk_object(chunk, objects)
    idx = list(range(chunk * size, (chunk + 1) * size))
    tasks = [sample_grasp_task(np.random.default_rng(task_seed(seed, kind, i, 0)), name) for i in idx]
    res = fitter.fit(tasks)
    fitter.evaluate(res)
    best = [(r, 0, accepted(r.quality, r.task.grasp_type)) for r in res]
    for attempt in range(1, MAX_ATTEMPTS):
        todo = [k for k, (_, _, ok) in enumerate(best) if not ok]
        if not todo:
            break
        tasks = [sample_grasp_task(np.random.default_rng(task_seed(seed, kind, idx[k], attempt)), name) for k in todo]
        res = fitter.fit(tasks)
        fitter.evaluate(res)
        for k, r in zip(todo, res):
            ok = accepted(r.quality, r.task.grasp_type)
            if ok or badness(r.quality) < badness(best[k][0].quality):
                best[k] = (r, attempt, ok)
    return best


def write_chunk(fitter: GraspFitter, kind: str, seed: int, chunk: int, out: Path, n: int, size: int = CHUNK,
                objects: tuple[str, ...] = OBJECT_ORDER) -> list[str]:
    """Fit chunk `chunk` (of `size` grasps) and write its files with index < n that are missing; returns their paths."""
    out = Path(out)
    idx = list(range(chunk * size, (chunk + 1) * size))
    want = [i for i in idx if i < n and not file_path(out, kind, i).exists()]
    if not want:
        return []
    name = chunk_object(chunk, objects)
    mesh_dir = out / "meshes"
    if not (mesh_dir / f"{name}.ply").exists():
        export_object_ply(name, mesh_dir)
    best = fit_chunk(fitter, kind, seed, chunk, size, objects)
    V = fitter.vertices([b[0] for b in best])
    make = grasp_sequence if kind == "grasp" else approach_sequence
    written = []
    for k, i in enumerate(idx):
        if i not in want:
            continue
        r, attempt, ok = best[k]
        seq = make(fitter, r, V[k], i, seed, attempt, ok, f"meshes/{name}.ply")
        written.append(str(save_grasp_sequence(file_path(out, kind, i), seq, model_name(fitter.bm))))
    return written


def model_name(bm: BodyModel) -> str:
    """What a file's `body.model` says: graspkit's name for the shipped body, else the model file as given."""
    same = Path(bm.source).resolve() == default_model_path().resolve()
    return DEFAULT_MODEL_NAME if same else str(bm.source)


_FITTER: GraspFitter | None = None


def _init_worker(model: str | None, parent: int | None = None) -> None:
    """One torch thread per worker; load the body model and the fitter once; a pool's worker (`parent`: the pool's
    process) exits when that process is gone."""
    if parent is not None:
        from graspkit.paths import exit_with_parent

        exit_with_parent(parent)
    from graspkit.body import BodyModel
    from graspkit.paths import default_model_path

    global _FITTER
    torch.set_num_threads(1)
    _FITTER = GraspFitter(BodyModel.from_file(model or default_model_path()))


def _run(kind: str, seed: int, chunk: int, out: str, n: int, size: int, objects: tuple[str, ...]) -> int:
    """Worker entry: write one chunk; returns how many files it wrote."""
    return len(write_chunk(_FITTER, kind, seed, chunk, Path(out), n, size, objects))


@keeps_torch_state
def make_grasp_dataset(kind: str, n: int, seed: int, out: Path, workers: int = 2, model: str | None = None,
                       progress: bool = True, chunk: int = CHUNK, objects: tuple[str, ...] | None = None) -> list[Path]:
    """Write items 0..n-1 of `kind` ('grasp' or 'approach') that are not there yet; returns all n paths.

    chunk: grasps fitted together (one object per chunk); the files depend on it (default CHUNK).
    objects: the objects chunks cycle through (default: all 17, alphabetically)."""
    objects = OBJECT_ORDER if not objects else tuple(objects)
    bad = [o for o in objects if o not in GRASP_PARTS]
    if bad:
        raise ValueError(f"objects: unknown {bad}; valid names are {list(OBJECT_ORDER)}")
    from tqdm import tqdm

    from graspkit.progress import hidden

    if kind not in KINDS:
        raise ValueError(f"kind: expected one of {KINDS}, got {kind!r}")
    for name, value, least in (("n", n, 0), ("workers", workers, 1), ("chunk", chunk, 1)):
        check_int(value, name, least)
    check_seed(seed)
    out = Path(out)
    from graspkit.data.cli import check_model, claim_folder

    check_model(model)
    out.mkdir(parents=True, exist_ok=True)
    claim_folder(out, kind, {"seed": seed, "model": model, "chunk": chunk, "objects": list(objects)})
    drop_damaged([file_path(out, kind, i) for i in range(n)], f"{kind} files")
    missing = [i for i in range(n) if not file_path(out, kind, i).exists()]
    chunks = sorted({i // chunk for i in missing})
    done = n - len(missing)
    bar = tqdm(total=n, initial=done, desc=f"{kind} files", unit=kind, disable=hidden(progress))
    if workers == 1 or len(chunks) <= 1:
        _init_worker(model)
        for c in chunks:
            bar.update(_run(kind, seed, c, str(out), n, chunk, objects))
    elif chunks:
        for k in pool_results([(_run, (kind, seed, c, str(out), n, chunk, objects)) for c in chunks], workers,
                              _init_worker, (model, os.getpid())):
            bar.update(k)
    bar.close()
    return [file_path(out, kind, i) for i in range(n)]
