"""Write tests/data/goal_restart_case.npz: the GNet grasp whose hand one run of the refinement with E_pen leaves
deepest inside its object, among the power drill's grasps of the training objects' draw in docs/goal.md (120
accepted grasps of the grasp and approach sets drawn with seed 0, one GNet sample each, z with seed 0). The test of
GraspRefineWeights.restart_sunk refines it (tests/test_goal_refine.py).

    graspkit data make --kind grasp --n 1700 --seed 0 && graspkit data make --kind approach --n 272 --seed 0
    python tools/goal_restart_case.py [--object power_drill] [--out tests/data/goal_restart_case.npz]
"""
from __future__ import annotations

import argparse
import io
from dataclasses import replace
from pathlib import Path

import numpy as np
import torch

ROOT = Path(__file__).resolve().parents[1]


def main(argv: list[str] | None = None) -> int:
    from graspkit import eval_goal as eg
    from graspkit.models.gnet import load_gnet
    from graspkit.optim.goal_refine import PEN_WEIGHTS, GraspRefiner
    from graspkit.paths import DATA_STUBS
    from graspkit.viz.export import write_atomic

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--object", default="power_drill")
    p.add_argument("--out", type=Path, default=ROOT / "tests" / "data" / "goal_restart_case.npz")
    a = p.parse_args(argv)
    torch.set_num_threads(1)
    folders = eg.default_data_folders()
    seqs = [s for s in eg._all_files(folders, "grasp", "train") + eg._all_files(folders, "approach", "train")
            if bool(s.extras.get("grasp.accepted", True))]
    pick = sorted(np.random.default_rng(0).permutation(len(seqs))[:120].tolist())
    seqs = [seqs[i] for i in pick]
    gnet = load_gnet(DATA_STUBS / "checkpoints" / "gnet.pt")
    gt = eg.gnet_samples(seqs, accepted_only=False)
    z = torch.randn(len(seqs), gnet.cfg.latent, generator=torch.Generator().manual_seed(0))
    hat = gnet.sample(gt["bps"], gt["obj_transl"], gt["betas"], z=z)
    ix = [i for i, s in enumerate(seqs) if s.object_name == a.object]
    if not ix:
        raise ValueError(f"--object: no {a.object!r} grasp among the 120 drawn training grasps")
    seqs = [seqs[i] for i in ix]
    hat = {k: v[ix] for k, v in hat.items()}
    betas, points = gt["betas"][ix], gt["points"][ix]
    frames = eg.grasp_frames(seqs)
    sdf = eg.posed_sdfs(seqs, frames, gt["R"][ix], gt["o"][ix])
    bm, gv, _ = eg._body()
    ref = GraspRefiner(bm, gv)
    one = ref(hat, betas, points, replace(PEN_WEIGHTS, restart_sunk=None), sdf=sdf)     # one run, no restart
    _, depth = ref.full_energy(one.rot6d, one.transl, betas, hat, points, PEN_WEIGHTS, 0.0, sdf)
    b = int(depth.argmax())
    print(f"{a.object}: {len(ix)} grasps, deepest E_pen point after one run {100 * float(depth[b]):.2f} cm (grasp {b})")
    buf = io.BytesIO()
    np.savez_compressed(buf, object_name=np.array(a.object), betas=betas[b].numpy(), points=points[b].numpy(),
                        R=sdf.R[b].numpy(), t=sdf.t[b].numpy(), **{f"hat_{k}": v[b].numpy() for k, v in hat.items()})
    write_atomic(a.out, buf.getvalue())
    print(f"wrote {a.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
