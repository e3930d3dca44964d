"""Synthetic grasps: generation throughput and the quality table over a generated set.

    python benchmarks/grasp_throughput.py --chunks 2                  # throughput: 2 chunks of 16 grasps, one core
    python benchmarks/grasp_throughput.py --quality /path/to/grasps  # quality table over a folder of grasp files
    python benchmarks/grasp_throughput.py --motion /path/to/approach # approach clips' motion quality vs the motion data's
    python benchmarks/grasp_throughput.py --apd mug,bottle           # APD over grasps of one object placement

Throughput is process CPU time in one process with one torch thread (so the figure is per core and does not
depend on what else the machine runs), for whole chunks as `graspkit data make` makes them (fit, evaluate,
retries, labels, files), split by stage; the default training sets' time on two cores follows from it. The quality
table is graspkit.metrics over the files (recomputed on the meshes, not read from the files), with the papers'
reference figures beside. The motion table measures the approach clips' feet (WANDR FS, SAGA skating, GOAL sliding,
ground penetration; graspkit.metrics.motion_quality) beside locomotion and reach clips of the motion data generated
in the same run, and the deepest body-object penetration before the goal frame.
"""
from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

from graspkit import metrics as M
from graspkit.body import BodyModel
from graspkit.checks import count_type
from graspkit.data import grasp_make as gm
from graspkit.data.grab import load_grasp_sequence
from graspkit.data.grasp import GraspFitter, sample_grasp_task
from graspkit.data.motion import Motion
from graspkit.data.reaching import Start
from graspkit.objects import ObjectPose, apply_pose, make_object
from graspkit.paths import default_model_path
from graspkit.rotations import axis_angle_to_matrix


def throughput(bm, chunks: int, kind: str) -> None:
    """CPU seconds per grasp for `chunks` chunks (objects in OBJECT_ORDER from the middle of the catalogue)."""
    fitter = GraspFitter(bm)
    with tempfile.TemporaryDirectory() as tmp:
        for c in range(chunks):
            fitter.grid(gm.chunk_object(c + 5))                                 # grids are built once per machine
        t0 = time.process_time()
        n = 0
        for c in range(chunks):
            n += len(gm.write_chunk(fitter, kind, 0, c + 5, Path(tmp), 10**9))
        dt = time.process_time() - t0
        acc = [bool(load_grasp_sequence(p).extras["grasp.accepted"]) for p in sorted(Path(tmp).glob("*.npz"))]
    rate = n / dt
    default = gm.DEFAULT_N[kind]
    print(f"| {kind} | {n} | {dt / n:.2f} s | {rate:.2f} | {sum(acc)}/{len(acc)} | {default} | "
          f"{default / (2 * rate) / 60:.1f} min |")


def quality(bm, folder: Path) -> None:
    """graspkit.metrics over every accepted file in `folder` (all frames' poses are recomputed on the mesh)."""
    from scipy.spatial import ConvexHull

    from graspkit.body.markers import goal_vertices

    gv = goal_vertices(bm)
    rows, per, files = [], {}, sorted(Path(folder).glob("*.npz"))
    kept = 0
    for f in files:
        s = load_grasp_sequence(f)
        if not bool(s.extras.get("grasp.accepted", True)):
            continue
        kept += 1
        k = int(s.extras.get("grasp.goal_frame", s.extras.get("grasp.frame", 0)))
        rot = axis_angle_to_matrix(torch.as_tensor(s.poses[k:k + 1]))
        with torch.no_grad():
            out = bm.forward_rotmats(rot, betas=torch.as_tensor(s.betas[None]), transl=torch.as_tensor(s.trans[k:k + 1]))
        v, pelvis = out.vertices[0].double(), out.joints[0, 0].double().numpy()
        obj = apply_pose(ObjectPose(s.object_transl[k], s.object_rotation()[k]), make_object(s.object_name))
        r = M.grasp_metrics(v, bm.faces, obj)
        ids = [np.flatnonzero(bm.lbs_weights.argmax(1).numpy() == j) for j in (7, 10, 8, 11)]
        r["feet_cm"] = 100 * max(abs(float(v[np.concatenate(ids[:2]), 2].min())), abs(float(v[np.concatenate(ids[2:]), 2].min())))
        sole = v[np.concatenate(ids)].numpy()
        sole = sole[sole[:, 2] <= 0.01, :2]                   # the support area: foot vertices within 1 cm of the floor
        hull = ConvexHull(sole)
        r["pelvis_out_cm"] = 100 * float((hull.equations[:, :2] @ pelvis[:2] + hull.equations[:, 2]).max())
        q = gv.head_direction(v).numpy()
        to = s.object_transl[k] - v[gv.head_front].numpy()
        r["head_deg"] = float(np.degrees(np.arccos(np.clip(q @ to / np.linalg.norm(to), -1, 1))))
        rows.append(r)
        per.setdefault(s.object_name, []).append(r)
    t = M.grasp_quality_table(rows)
    print(f"{kept} accepted of {len(files)} files")
    print("| set | grasps | contact ratio | volume mean / median / max (cm^3) | depth mean / max (cm) | feet within 1 cm |")
    print("|---|---|---|---|---|---|")
    print(f"| graspkit | {t['grasps']} | {t['contact_ratio']:.3f} | {t['volume_mean_cm3']:.2f} / {t['volume_median_cm3']:.2f} / "
          f"{t['volume_max_cm3']:.2f} | {t['depth_mean_cm']:.2f} / {t['depth_max_cm']:.2f} | {100 * t['feet_within_1cm']:.1f} % |")
    print("| GRAB captured grasps (GOAL Tab. 1) | - | 1.00 | 1.95 / - / - | - | - |")
    print("| GRAB ground-truth meshes (SAGA Tab. 2) | - | 0.99 | 2.04 / - / - | 0.45 / - | - |")
    out = np.array([r["pelvis_out_cm"] for r in rows])
    head = np.array([r["head_deg"] for r in rows])
    print(f"\nbalance: pelvis over the support area (convex hull of the foot vertices within 1 cm of the floor) in "
          f"{100 * (out <= 0).mean():.1f} % of grasps, within 2 cm of it in {100 * (out <= 2).mean():.1f} % "
          f"(worst {out.max():.1f} cm outside); gaze: head direction to the object centre mean {head.mean():.1f} deg, "
          f"95th percentile {np.percentile(head, 95):.1f}, max {head.max():.1f}")
    print("\n| object | grasps | contact | volume mean (cm^3) | depth max (cm) |\n|---|---|---|---|---|")
    for name in sorted(per):
        tt = M.grasp_quality_table(per[name])
        print(f"| {name} | {tt['grasps']} | {tt['contact_ratio']:.2f} | {tt['volume_mean_cm3']:.2f} | {tt['depth_max_cm']:.2f} |")


def motion(bm, folder: Path) -> None:
    """Foot skating / sliding of the approach clips in `folder` beside as many motion-data clips of each kind."""
    from graspkit.data.cli import clip_seed
    from graspkit.data.locomotion import generate_locomotion
    from graspkit.data.reaching import generate_reach

    files = sorted(Path(folder).glob("approach_*.npz"))
    if not files:
        raise SystemExit(f"--motion: no approach_*.npz files in {folder}")
    seqs = [load_grasp_sequence(f) for f in files]
    clips = [Motion(s.poses, s.trans, s.betas, s.fps, contacts=s.contacts["feet"].astype(bool)) for s in seqs]
    depth = []                                       # deepest body vertex inside the object before the goal frame
    for s, m in zip(seqs, clips):
        g = int(s.extras["grasp.goal_frame"])
        obj = apply_pose(ObjectPose(s.object_transl[0], s.object_rotation()[0]), make_object(s.object_name))
        with torch.no_grad():
            d = min(M.grasp_contact_distance(v, obj) for v in m.vertices(bm)[:g])
        depth.append(max(0.0, -d))
    n = len(clips)
    print("| data | clips | frames | FS WANDR | SAGA skating | GOAL sliding (GRAB 6.7 %) | ground penetration max / mean (cm) "
          "| max joint speed (m/s) | mean jerk (m/s^3) |")
    print("|---|---|---|---|---|---|---|---|---|")
    sets = {"approach clips": clips,
            "motion data: locomotion": (generate_locomotion(clip_seed(0, "locomotion", i), bm) for i in range(n)),
            "motion data: reach": (generate_reach(clip_seed(0, "reach", i), bm) for i in range(n))}
    for name, ms in sets.items():
        q = M.motion_quality(bm, ms)
        print(f"| {name} | {q['clips']} | {q['frames']} | {100 * q['fs_wandr']:.2f} % | {100 * q['skate_saga']:.2f} % | "
              f"{100 * q['slide_goal']:.2f} % | {100 * q['penetration_max']:.2f} / {100 * q['penetration_mean']:.3f} | "
              f"{q['max_joint_speed']:.2f} | {q['mean_jerk']:.1f} |")
    depth = np.array(depth) * 100
    print(f"\nbody inside the object before the goal frame: max {depth.max():.2f} cm, mean {depth.mean():.2f} cm, "
          f"{(depth > 0.5).sum()} of {n} clips deeper than 0.5 cm")


def diversity(bm, names: list[str], k: int = 10) -> None:
    """APD (SAGA Sec. 4.1) of the 143 markers over k tasks of one placement per object (accepted grasps, centred at
    the object): starts anywhere around it, then one fixed start (shape, grasp type and frame vary)."""
    from graspkit.body.markers import saga_markers

    fitter = GraspFitter(bm)
    pose = ObjectPose.from_yaw(1.0, (0.0, -0.9, 1.0))
    print("| object | starts around the object: accepted, APD | one start: accepted, APD |\n|---|---|---|")
    for name in names:
        rng = np.random.default_rng(7)
        around = [sample_grasp_task(rng, name, object_pose=pose) for _ in range(k)]
        fixed = []
        for i in range(k):
            t = sample_grasp_task(np.random.default_rng(100 + i), name)
            t.object_pose, t.start = pose, Start(0.0, 0.0, -np.pi / 2)
            fixed.append(t)
        cells = []
        for tasks in (around, fixed):
            res = fitter.fit(tasks)
            fitter.evaluate(res)
            ok = [r for r in res if gm.accepted(r.quality, r.task.grasp_type)]
            m = saga_markers(bm).select(fitter.vertices(ok)).numpy() - pose.translation
            cells.append(f"{len(ok)}/{k}, {M.apd(m):.2f}" if len(ok) > 1 else f"{len(ok)}/{k}, -")
        print(f"| {name} | {cells[0]} | {cells[1]} |")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--chunks", type=count_type(0), default=0, help="chunks of 16 grasps to time (0: skip)")
    p.add_argument("--kind", default="grasp", choices=gm.KINDS)
    p.add_argument("--quality", type=Path, default=None, help="a folder of grasp or approach files")
    p.add_argument("--motion", type=Path, default=None, help="a folder of approach files: foot skating and sliding")
    p.add_argument("--apd", default="", help="comma-separated objects: APD over grasps of one placement")
    args = p.parse_args()
    print(f"load average {os.getloadavg()[0]:.1f}")
    torch.set_num_threads(1)
    bm = BodyModel.from_file(default_model_path())
    if args.chunks:
        print("| kind | items | CPU per item | items/s/core | accepted | default set | time on 2 cores |")
        print("|---|---|---|---|---|---|---|")
        throughput(bm, args.chunks, args.kind)
    if args.quality is not None:
        quality(bm, args.quality)
    if args.motion is not None:
        motion(bm, args.motion)
    if args.apd:
        diversity(bm, [n for n in args.apd.split(",") if n])


if __name__ == "__main__":
    t0 = time.perf_counter()
    main()
    print(f"({time.perf_counter() - t0:.0f} s)")
