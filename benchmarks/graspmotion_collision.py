"""GraspMotion-Opt's hand-in-object term on a point cloud: the box-limited hinge against every near hand vertex.

For the shipped approach clips (data_stubs/approach): one MotionFill sample, Alg. 2's marker-fitting stage, then the
right-hand vertices of the frames near the object (as `GraspMotionOpt.energy` selects them). E^o_colli's hinge
(S(x, O) < -sigma_b)_+ with S from the nearest of every 4th object point and its normal, computed two ways:
`GraspMotionOpt.cloud_penetration` (only the vertices inside the object's box + 5 mm) and the reference, every vertex.
Prints the time of each (forward + backward, best of 5), the ratio, and where the two differ: the reference's
"inside" vertices outside the box are the nearest-normal sign's mistakes (the far face of a thin wall).
Run: python benchmarks/graspmotion_collision.py
"""
from __future__ import annotations

import argparse
import os

import torch
from geometry import _best                      # benchmarks/geometry.py: best wall time of a few calls

from graspkit.body import BodyModel
from graspkit.checks import count_type
from graspkit.eval_motionfill import approach_scene, interp, load_motionfill
from graspkit.models.pose_prior import load_pose_prior
from graspkit.optim.graspmotion import GraspMotionConfig, GraspMotionOpt, in_box
from graspkit.optim.grasppose import _signed_to_cloud
from graspkit.paths import DATA_STUBS, default_model_path
from graspkit.rotations import axis_angle_to_matrix


def near_hands(opt: GraspMotionOpt, scene: dict, seed: int) -> tuple[torch.Tensor, ...]:
    """Hand vertices (1, K*H, 3) of the frames within 2 cm of the object's box after Alg. 2's stage 1 on one
    MotionFill sample, the object's points and normals (1, P, 3) and its box lo, hi (1, 1, 3)."""
    g = torch.Generator().manual_seed(seed)
    s = load_motionfill().sample(torch.as_tensor(interp(scene["traj"])).float(), torch.as_tensor(scene["local"]),
                                 torch.as_tensor(scene["contacts"]).float(), 1, g)
    res = opt.fit(s["markers"], torch.as_tensor(scene["betas"][None]).float(), progress=False)
    pts = torch.as_tensor(scene["points"]).float()[None]
    nrm = torch.as_tensor(scene["normals"]).float()[None]
    with torch.no_grad():
        rot = axis_angle_to_matrix(res.params["poses"][0].view(-1, 55, 3))
        v, _ = opt.sparse(rot, res.params["betas"].expand(len(rot), -1), res.params["transl"][0])
        hands = v[:, opt.sl_h].float()[None]                                            # (1, F, H, 3)
        lo, hi = pts.min(1).values[:, None], pts.max(1).values[:, None]
        near = in_box(hands, lo[:, None], hi[:, None], 0.02).any(-1).any(0)
    return hands[:, near].reshape(1, -1, 3), pts, nrm, lo, hi


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--threads", type=count_type(1), default=1)
    ap.add_argument("--seed", type=count_type(0), default=0)
    args = ap.parse_args()
    print(f"load average {os.getloadavg()[0]:.1f}")
    torch.set_num_threads(args.threads)
    bm = BodyModel.from_file(default_model_path())
    opt = GraspMotionOpt(bm, load_pose_prior(), None, GraspMotionConfig(steps=(100, 0), polish=(0, 0.0)))
    sig = opt.cfg.weights.sigma_b
    print("| clip | object | near hand vertices | in the box | box-limited (ms) | every vertex (ms) | ratio | "
          "hinge sum box / every | 'inside' outside the box |")
    print("|---|---|---|---|---|---|---|---|---|")
    for f in sorted((DATA_STUBS / "approach").glob("approach_*.npz")):
        scene = approach_scene(f, bm)
        q, pts, nrm, lo, hi = near_hands(opt, scene, args.seed)
        pts, nrm = pts[:, ::opt.cfg.point_stride], nrm[:, ::opt.cfg.point_stride]
        qg = q.clone().requires_grad_(True)

        def box() -> torch.Tensor:
            return opt.cloud_penetration(qg, pts, nrm, lo, hi)

        def every() -> torch.Tensor:
            return torch.relu(-_signed_to_cloud(qg, pts, nrm)[0] - sig)

        def step(term) -> None:                       # forward + backward, as in one optimiser step
            e = term().sum()
            if e.requires_grad:
                e.backward()

        t_box, t_all = _best(lambda: step(box), 5), _best(lambda: step(every), 5)
        with torch.no_grad():
            e_box, e_all = box(), every()
            inbox = in_box(q, lo, hi, 0.005)
        print(f"| {f.stem} | {scene['name']} | {q.shape[1]} | {int(inbox.sum())} ({100 * float(inbox.float().mean()):.0f} %)"
              f" | {1000 * t_box:.1f} | {1000 * t_all:.1f} | {t_all / max(t_box, 1e-9):.1f}x | "
              f"{float(e_box.sum()):.3f} / {float(e_all.sum()):.3f} | {int(((e_all > 0) & ~inbox).sum())} |")
        assert torch.equal(e_box[inbox], e_all[inbox]), "the two must agree inside the box"


if __name__ == "__main__":
    main()
