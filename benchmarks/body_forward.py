"""Body-model forward speed: graspkit's BodyModel against the smplx package on the same file.

Workloads: the shipped procedural humanoid (pose correctives on a few joints) and a dense random SMPL-X-format model
with non-zero pose correctives; batch sizes 1, 64, 512; forward (no grad) and forward + backward.
Prints bodies per second for both and the ratio. Run: python benchmarks/body_forward.py [--threads 2]
"""
from __future__ import annotations

import argparse
import os
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np
import torch

from graspkit.body import BodyModel
from graspkit.body.random_model import random_smplx_arrays
from graspkit.checks import count_type, positive_float
from graspkit.paths import default_model_path


def _params(B: int, grad: bool) -> dict[str, torch.Tensor]:
    """Random full SMPL-X parameters of batch B (every argument given, as smplx needs)."""
    g = torch.Generator().manual_seed(B)
    shapes = dict(betas=10, expression=10, global_orient=3, body_pose=63, left_hand_pose=45, right_hand_pose=45,
                  jaw_pose=3, leye_pose=3, reye_pose=3, transl=3)
    return {k: (torch.randn(B, n, generator=g) * 0.3).requires_grad_(grad) for k, n in shapes.items()}


def _rate(model: torch.nn.Module, B: int, backward: bool, seconds: float) -> float:
    """Bodies per second of one model at batch B (median of 3 timed blocks of at least `seconds` / 3)."""
    p = _params(B, backward)

    def step() -> None:
        if backward:
            model(**p).vertices.square().sum().backward()
        else:
            with torch.no_grad():
                model(**p)

    step()
    rates = []
    for _ in range(3):
        n, t0 = 0, time.perf_counter()
        while time.perf_counter() - t0 < seconds / 3:
            step()
            n += 1
        rates.append(B * n / (time.perf_counter() - t0))
    return float(np.median(rates))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--threads", type=count_type(1), default=2)
    ap.add_argument("--seconds", type=positive_float, default=1.5, help="time per measurement")
    ap.add_argument("--batches", type=int, nargs="+", default=[1, 64, 512])
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    warnings.filterwarnings("ignore")
    import smplx  # the reference; a test-only dependency of graspkit

    with tempfile.TemporaryDirectory() as tmp:
        dense = Path(tmp) / "dense" / "smplx"
        dense.mkdir(parents=True)
        np.savez(dense / "SMPLX_NEUTRAL.npz", **random_smplx_arrays(seed=0))
        files = {"procedural": default_model_path(), "dense random (pose correctives)": dense / "SMPLX_NEUTRAL.npz"}
        print(f"torch {torch.__version__}, {args.threads} threads, load average {os.getloadavg()[0]:.1f} (on a busy "
              "machine two threads can run slower than one: compare with --threads 1); bodies/s, higher is better\n")
        print("| model file | B | pass | graspkit | smplx | ratio | target |\n|---|---|---|---|---|---|---|")
        for label, path in files.items():
            ours = BodyModel.from_file(path)
            ref = smplx.create(str(path.parents[1]), model_type="smplx", gender="neutral", ext="npz", use_pca=False)
            for B in args.batches:
                for backward in (False, True):
                    a, b = _rate(ours, B, backward, args.seconds), _rate(ref, B, backward, args.seconds)
                    name = "fwd+bwd" if backward else "forward"
                    want = None if backward else (3.0 if B == 1 else 1.2 if B >= 64 else None)
                    verdict = "" if want is None else f">= {want:g}x: {'met' if a / b >= want else 'missed'}"
                    print(f"| {label} | {B} | {name} | {a:,.0f} | {b:,.0f} | {a / b:.2f}x | {verdict} |", flush=True)
    print("\ntargets (forward): >= 3x at B = 1, >= 1.2x at B >= 64; the dense file at B = 1 is bound by reading its 61 MB"
          "\ncorrective matrix once per call, in both libraries (docs/body_model.md)")


if __name__ == "__main__":
    main()
