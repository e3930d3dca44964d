"""Synthetic grasps: generation throughput and the quality table over a generated set.

    python benchmarks/grasp_throughput.py --chunks 2                  # throughput: 2 chunks of 16 grasps, one core
    python benchmarks/grasp_throughput.py --quality /path/to/grasps  # quality table over a folder of grasp files

Throughput is process CPU time in one process with one torch thread (so the figure is per core and does not
depend on what else the machine runs), for whole chunks as `graspkit data make` makes them (fit, evaluate,
retries, labels, files), split by stage; the default training sets' time on two cores follows from it. The quality
table is graspkit.metrics over the files (recomputed on the meshes, not read from the files), with the papers'
reference figures beside.
"""
from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

from graspkit import metrics as M
from graspkit.body import BodyModel
from graspkit.data import grasp_make as gm
from graspkit.data.grab import load_grasp_sequence
from graspkit.data.grasp import GraspFitter
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
            v = bm.forward_rotmats(rot, betas=torch.as_tensor(s.betas[None]), transl=torch.as_tensor(s.trans[k:k + 1]))
        v = v.vertices[0].double()
        obj = apply_pose(ObjectPose(s.object_transl[k], s.object_rotation()[k]), make_object(s.object_name))
        r = M.grasp_metrics(v, bm.faces, obj)
        ids = [np.flatnonzero(bm.lbs_weights.argmax(1).numpy() == j) for j in (7, 10, 8, 11)]
        r["feet_cm"] = 100 * max(abs(float(v[np.concatenate(ids[:2]), 2].min())), abs(float(v[np.concatenate(ids[2:]), 2].min())))
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
    print("\n| object | grasps | contact | volume mean (cm^3) | depth max (cm) |\n|---|---|---|---|---|")
    for name in sorted(per):
        tt = M.grasp_quality_table(per[name])
        print(f"| {name} | {tt['grasps']} | {tt['contact_ratio']:.2f} | {tt['volume_mean_cm3']:.2f} | {tt['depth_max_cm']:.2f} |")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--chunks", type=int, default=0, help="chunks of 16 grasps to time (0: skip)")
    p.add_argument("--kind", default="grasp", choices=gm.KINDS)
    p.add_argument("--quality", type=Path, default=None, help="a folder of grasp or approach files")
    args = p.parse_args()
    torch.set_num_threads(1)
    bm = BodyModel.from_file(default_model_path())
    if args.chunks:
        print("| kind | items | CPU per item | items/s/core | accepted | default set | time on 2 cores |")
        print("|---|---|---|---|---|---|---|")
        throughput(bm, args.chunks, args.kind)
    if args.quality is not None:
        quality(bm, args.quality)


if __name__ == "__main__":
    t0 = time.perf_counter()
    main()
    print(f"({time.perf_counter() - t0:.0f} s)")
