"""Geometry speed and accuracy: graspkit's signed distance and containment against trimesh, same points, same run.

For a few catalogue objects, 10,000 points in the padded bounding box: exact signed distance (forward, and
forward + backward), the 64^3 SDF grid, and trimesh's signed_distance / contains as the reference.
Prints the time of each, the ratio against trimesh, and the sign agreement. Then nearest_neighbours on a large pair of
clouds (--nn N M): its KD-tree path (from KD_PAIRS pairs) against the same call forced to brute force, and scipy's
cKDTree alone. Run: python benchmarks/geometry.py
"""
from __future__ import annotations

import argparse
import os
import time

import numpy as np
import torch
import trimesh

from graspkit.checks import count_type
from graspkit.objects import SDFGrid, distance, make_object, nearest_neighbours, signed_distance


def _best(fn, repeat: int = 3) -> float:
    """Best wall time of `repeat` calls, in seconds."""
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return min(times)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--objects", nargs="+", default=["mug", "wine_glass", "camera", "power_drill"])
    ap.add_argument("--points", type=count_type(1), default=10_000)
    ap.add_argument("--threads", type=count_type(1), default=2)
    ap.add_argument("--nn", type=count_type(1), nargs=2, default=[100_000, 50_000], metavar=("N", "M"),
                    help="query and target points of the nearest-neighbour rows (default 100,000 and 50,000)")
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    rng = np.random.default_rng(0)
    print(f"{args.threads} torch threads; load average {os.getloadavg()[0]:.1f} (on a busy machine two threads "
          "can run slower than one: compare with --threads 1)\n")
    print("| object | faces | workload | graspkit (s) | trimesh (s) | speed-up (trimesh / graspkit) | sign agreement |")
    print("|---|---|---|---|---|---|---|")
    for name in args.objects:
        mesh = make_object(name)
        lo, hi = mesh.bounds[0] - 0.02, mesh.bounds[1] + 0.02
        pts = rng.uniform(lo, hi, size=(args.points, 3))
        p = torch.as_tensor(pts)
        ref_sd = -trimesh.proximity.signed_distance(mesh, pts)          # trimesh is positive inside
        ref_in = mesh.contains(pts)
        t_ref = _best(lambda: trimesh.proximity.signed_distance(mesh, pts))      # best of 3, as graspkit's
        t_contains = _best(lambda: mesh.contains(pts))
        ours = signed_distance(p, mesh)
        agree = float(np.mean((ours.numpy() < 0) == ref_in))
        t_fwd = _best(lambda: signed_distance(p, mesh))
        q = p.clone().requires_grad_(True)
        t_bwd = _best(lambda: signed_distance(q, mesh).sum().backward())
        grid = SDFGrid.from_mesh(mesh, resolution=64)
        gp = p.float()
        t_grid = _best(lambda: grid(gp))
        g_agree = float(np.mean((grid(gp).numpy() < 0) == ref_in))
        err = np.abs(ours.numpy() - ref_sd).max() * 1000
        rows = [("exact SDF, forward", t_fwd, t_ref, agree), ("exact SDF, fwd+bwd", t_bwd, t_ref, agree),
                ("64^3 grid SDF", t_grid, t_ref, g_agree), ("containment (exact SDF sign)", t_fwd, t_contains, agree)]
        for label, a, b, ag in rows:
            print(f"| {name} | {len(mesh.faces)} | {label} | {a:.4f} | {b:.4f} | {b / a:.1f}x | {ag:.2%} |")
        print(f"| {name} | | max abs difference to trimesh's signed distance | {err:.3f} mm | | | |")
    nearest_rows(*args.nn, rng)


def nearest_rows(n: int, m: int, rng: np.random.Generator) -> None:
    """nearest_neighbours of n uniform points against m: the KD-tree path, brute force (KD_PAIRS raised past n*m; one
    run, it is the slow one) and scipy's cKDTree alone, with the indices compared."""
    from scipy.spatial import cKDTree

    q, t = torch.as_tensor(rng.uniform(size=(n, 3))), torch.as_tensor(rng.uniform(size=(m, 3)))
    kd = distance.KD_PAIRS
    path = "KD-tree" if n * m >= kd else "brute force (below KD_PAIRS)"
    t_ours = _best(lambda: nearest_neighbours(q, t))
    distance.KD_PAIRS = n * m + 1
    try:
        t_brute = _best(lambda: nearest_neighbours(q, t), repeat=1)
        _, i_brute = nearest_neighbours(q, t)
    finally:
        distance.KD_PAIRS = kd
    t_scipy = _best(lambda: cKDTree(t.numpy()).query(q.numpy()))
    same = float((nearest_neighbours(q, t)[1] == i_brute).double().mean())
    print(f"\n| nearest_neighbours, {n:,} x {m:,} points | graspkit ({path}) (s) | brute force (s) | speed-up | "
          "scipy cKDTree alone (s) | same indices as brute force |")
    print("|---|---|---|---|---|---|")
    print(f"| | {t_ours:.3f} | {t_brute:.3f} | {t_brute / t_ours:.0f}x | {t_scipy:.3f} | {same:.2%} |")


if __name__ == "__main__":
    main()
