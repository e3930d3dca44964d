"""WANDR's goal grid (§4.2): 6 held-out starts x 125 goals x 5 samples = 3,750 rollouts of 240 frames, in one batch,
against a per-goal sequential loop of the same model in the same run.

    python benchmarks/wandr_grid.py                              # the shipped checkpoint, two torch threads
    python benchmarks/wandr_grid.py --checkpoint X.pt --loop 20  # time 20 rollouts of the per-goal loop

The batched run rolls all 3,750 sequences forward together (one decoder call per frame for all of them) and measures
SR / FS / DTG on the fly. The reference is what a straightforward implementation does: one goal and one sample at a
time, the same model, the same per-frame work; `--loop` rollouts are timed and scaled to 3,750. Both print below.
"""
from __future__ import annotations

import argparse
import os
import time

import numpy as np
import torch

from graspkit.body import BodyModel
from graspkit.checks import count_type
from graspkit.eval_wandr import (PAPER, breakdown, evaluate_grid, grid_goals, starts_body_problem, starts_from_meta,
                                 summary)
from graspkit.models.wandr import load_wandr
from graspkit.paths import DATA_STUBS, default_model_path


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--checkpoint", default=str(DATA_STUBS / "checkpoints" / "wandr.pt"))
    ap.add_argument("--threads", type=count_type(1), default=2)
    ap.add_argument("--loop", type=count_type(1), default=12, help="rollouts timed in the per-goal loop")
    ap.add_argument("--n", type=count_type(1), default=5, help="samples per start and goal")
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    bm = BodyModel.from_file(default_model_path())
    model = load_wandr(args.checkpoint)
    starts = starts_from_meta(model.meta)
    problem = starts_body_problem(starts, bm, args.checkpoint)     # the rollout would move another body than bm
    if problem:
        raise SystemExit(problem)
    goals, cells = grid_goals()
    total = len(starts) * len(goals) * args.n

    t0 = time.perf_counter()
    res = evaluate_grid(model, starts, bm, n=args.n, seed=0)
    t_batch = time.perf_counter() - t0

    t0 = time.perf_counter()
    for k in range(args.loop):                      # goals spread over the grid, one rollout each
        g = (k * 37) % len(goals)
        evaluate_grid(model, [starts[k % len(starts)]], bm, n=1, seed=k, goals=goals[g:g + 1], cells=cells[g:g + 1])
    t_loop = (time.perf_counter() - t0) / args.loop * total

    s = summary(res)
    print(f"checkpoint {args.checkpoint}; {args.threads} torch threads; load average {os.getloadavg()[0]:.1f}")
    print("| workload | graspkit (batched) | per-goal loop, same model | ratio |")
    print("|---|---|---|---|")
    print(f"| {total:,} rollouts x 240 frames, SR/FS/DTG on the fly | {t_batch:.1f} s | {t_loop:.0f} s "
          f"(measured on {args.loop}, scaled) | {t_loop / t_batch:.0f}x |")
    print()
    paper = PAPER["WANDR"]
    print("| | SR % | FS % | DTG cm (mean) | DTG cm (median) | wrist error at t_G cm | time to goal s |")
    print("|---|---|---|---|---|---|---|")
    print(f"| graspkit WANDR ({s['rollouts']} rollouts) | {s['SR']:.1f} | {s['FS']:.1f} | {s['DTG']:.1f} | "
          f"{s['DTG_median']:.1f} | {s['error_at_goal']:.1f} | {s['time_to_goal_s']:.2f} |")
    print(f"| WANDR paper (Tab. 1) | {paper[0]:g} | {paper[1]:g} | {paper[2]:g} | — | — | — |")
    for b in ("height", "angle", "distance"):
        col = {"angle": 0, "height": 1, "distance": 2}[b]
        dtg = {k: 100 * res.dtg[np.isclose(res.cell[:, col], k)].mean() for k in np.unique(res.cell[:, col])}
        print(f"SR by {b}: " + ", ".join(f"{k:g}: {v:.1f} %" for k, v in breakdown(res, b).items())
              + "; mean DTG: " + ", ".join(f"{k:g}: {v:.0f} cm" for k, v in dtg.items()))


if __name__ == "__main__":
    main()
