"""Procedural motion data: generation throughput, motion quality on the meshes, and the planner on WANDR's grid.

    python benchmarks/motion_throughput.py                      # throughput (clips/s per core), 40 clips per kind
    python benchmarks/motion_throughput.py --quality 200        # + quality table over 200 clips of each kind
    python benchmarks/motion_throughput.py --grid               # + the planner on WANDR's 125-goal grid

Throughput is measured in one process with one torch thread (one core): generation alone, and generation
plus writing the .npz file as `graspkit data make` does. Quality metrics (graspkit.metrics) are measured on
the generated SMPL-X meshes of the procedural humanoid; reference figures from the papers are printed beside.
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
from graspkit.data.cli import DEFAULT_N, clip_seed
from graspkit.data.formats import save_motion
from graspkit.data.locomotion import generate_locomotion
from graspkit.data.reaching import evaluate_planner, generate_reach
from graspkit.paths import default_model_path

GENERATORS = {"locomotion": generate_locomotion, "reach": generate_reach}


def throughput(bm, n: int) -> None:
    """Clips and frames per second per core (CPU time of this process), for each kind, and the time of the default
    training sets on 2 cores (at that rate, perfectly parallel: a lower bound on a busy machine)."""
    print(f"load average {os.getloadavg()[0]:.1f}; rates from CPU time (time.process_time), one torch thread\n")
    print("| kind | clips | mean frames | generate (clips/s/core) | generate + write (clips/s/core) | default set | time on 2 cores |")
    print("|---|---|---|---|---|---|---|")
    for kind, gen in GENERATORS.items():
        gen(clip_seed(0, kind, 10**6), bm)                                   # warm-up
        t0 = time.process_time()                   # CPU time: one core's work, whatever else the machine runs
        clips = [gen(clip_seed(0, kind, i), bm) for i in range(n)]
        t_gen = time.process_time() - t0
        with tempfile.TemporaryDirectory() as d:
            t0 = time.process_time()
            for i in range(n):
                save_motion(Path(d) / f"{i}.npz", gen(clip_seed(0, kind, i), bm))
            t_all = time.process_time() - t0
        rate = n / t_all
        N = DEFAULT_N[kind]
        print(f"| {kind} | {n} | {np.mean([c.num_frames for c in clips]):.0f} | {n / t_gen:.1f} | {rate:.1f} | {N} | "
              f"{N / (2 * rate) / 60:.1f} min |")


def quality(bm, n: int) -> None:
    """The motion-quality table over n clips of each kind, measured on the meshes."""
    print("| data | clips | frames | FS WANDR (<= 5 %) | SAGA skating | GOAL sliding (<= 3 %; GRAB 6.7 %) | "
          "penetration max / mean (cm) | max joint speed (m/s) | max joint turn (deg/s) | mean jerk (m/s^3) | "
          "joint limits (deg beyond) |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for kind, gen in GENERATORS.items():
        q = M.motion_quality(bm, (gen(clip_seed(0, kind, i), bm) for i in range(n)), progress=True)
        print(f"| {kind} | {q['clips']} | {q['frames']} | {100 * q['fs_wandr']:.2f} % | {100 * q['skate_saga']:.2f} % | "
              f"{100 * q['slide_goal']:.2f} % | {100 * q['penetration_max']:.2f} / {100 * q['penetration_mean']:.3f} | "
              f"{q['max_joint_speed']:.2f} ({q['max_joint_speed_at']}) | {q['max_joint_turn']:.0f} ({q['max_joint_turn_at']}) | "
              f"{q['mean_jerk']:.1f} | {q['joint_limit_max']:.1f} |")


def grid(bm) -> None:
    """plan_reach on WANDR's 5 x 5 x 5 evaluation grid: success rate per height and distance, FS, DTG."""
    rows = evaluate_planner(bm)
    heights, dists = sorted({r["height"] for r in rows}), sorted({r["distance"] for r in rows})
    print("success over the 5 angles, per goal height (rows, m) and distance (columns, m):\n")
    print("| height \\ distance | " + " | ".join(f"{d:.3g}" for d in dists) + " |")
    print("|---" * (len(dists) + 1) + "|")
    for h in heights:
        cells = [sum(r["success"] for r in rows if r["height"] == h and r["distance"] == d) for d in dists]
        print(f"| {h:.2f} | " + " | ".join(f"{c}/5" for c in cells) + " |")
    sr = np.mean([r["success"] for r in rows])
    print(f"\nSR {100 * sr:.1f} % ({sum(r['success'] for r in rows)}/{len(rows)}), mean DTG "
          f"{100 * np.mean([r['dtg'] for r in rows]):.2f} cm, max wrist error at t_G "
          f"{100 * max(r['error_at_goal_frame'] for r in rows):.2f} cm, FS {100 * np.mean([r['fs_wandr'] for r in rows]):.2f} %, "
          f"GOAL sliding {100 * np.mean([r['slide_goal'] for r in rows]):.2f} %, max penetration "
          f"{100 * max(r['penetration'] for r in rows):.2f} cm  (WANDR: SR 32 %, FS 16 %, DTG 24.8 cm)")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n", type=count_type(1), default=40, help="clips per kind for the throughput")
    ap.add_argument("--quality", type=count_type(0), default=0, help="clips per kind for the quality table (0: skip)")
    ap.add_argument("--grid", action="store_true", help="evaluate the planner on WANDR's grid")
    args = ap.parse_args()
    torch.set_num_threads(1)
    bm = BodyModel.from_file(default_model_path())
    throughput(bm, args.n)
    if args.quality:
        print()
        quality(bm, args.quality)
    if args.grid:
        print()
        grid(bm)


if __name__ == "__main__":
    main()
