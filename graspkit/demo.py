"""The main job (`graspkit demo`): everything the workbook can show, written to an output folder.

So far: the body model in several poses and shapes (figure + GLB). Later stages add SAGA, GOAL and WANDR.
"""
from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import torch  # noqa: E402
from tqdm import tqdm  # noqa: E402

from graspkit.body import BodyModel  # noqa: E402
from graspkit.body.poses import body_pose, y_up_to_z_up  # noqa: E402
from graspkit.paths import default_model_path  # noqa: E402

DEMO_BODIES = [("t_pose", 0.0), ("a_pose", 0.0), ("walk", 0.0), ("reach_high", 0.0), ("squat", 0.0),
               ("bend_pick", 0.0), ("a_pose", -2.0), ("a_pose", 2.0)]


def load_or_build_body(model_path: Path | None = None) -> BodyModel:
    """The body model at model_path (default: the shipped humanoid; built and saved if it is missing)."""
    path = Path(model_path) if model_path else default_model_path()
    if not path.exists() and model_path is None:
        from graspkit.body.procedural import build_procedural_smplx, save_model_npz

        save_model_npz(build_procedural_smplx(seed=0), path)
    return BodyModel.from_file(path)


def body_gallery(bm: BodyModel, bodies: list[tuple[str, float]] = DEMO_BODIES) -> tuple[plt.Figure, torch.Tensor]:
    """A row of bodies (pose name, height beta) side by side in the z-up world; returns the figure and vertices (N,V,3)."""
    import numpy as np

    from graspkit.viz import draw_ground, draw_mesh, set_equal

    with torch.no_grad():
        betas = torch.zeros(len(bodies), bm.num_betas)
        betas[:, 0] = torch.tensor([b for _, b in bodies])
        out = bm(betas=betas, body_pose=torch.cat([body_pose(p) for p, _ in bodies]),
                 global_orient=y_up_to_z_up().expand(len(bodies), 3))
    v = out.vertices.clone()
    v[..., 2] -= v[..., 2].amin(dim=1, keepdim=True)          # stand on the ground
    v[..., :2] -= v[..., :2].mean(dim=1, keepdim=True)         # centred above the origin
    fig = plt.figure(figsize=(1.9 * len(bodies), 3.6))
    box = np.array([[-0.9, -0.6, 0.0], [0.9, 0.6, 2.1]])      # the same scale for every body
    for k, (pose, beta) in enumerate(bodies):
        ax = fig.add_subplot(1, len(bodies), k + 1, projection="3d", proj_type="ortho")
        draw_mesh(ax, v[k].numpy(), bm.faces.numpy())
        draw_ground(ax, (-0.7, 0.7, -0.5, 0.5))
        set_equal(ax, box, pad=0.0, zoom=1.35)
        ax.view_init(elev=8, azim=-80)
        ax.set_axis_off()
        ax.set_title(pose.replace("_", " ") + (f", beta0 {beta:+.0f}" if beta else ""), fontsize=10, y=0.97)
    fig.subplots_adjust(0, 0, 1, 1, wspace=0)
    return fig, v


def run_demo(out_dir: Path, model_path: Path | None = None) -> list[Path]:
    """Run every stage of the demo into out_dir; returns the files written."""
    from graspkit.viz.export import export_scene

    out_dir.mkdir(parents=True, exist_ok=True)
    written: list[Path] = []
    steps = tqdm(["body model", "gallery figure", "GLB export"], desc="demo", unit="step")
    for step in steps:
        steps.set_postfix_str(step)
        if step == "body model":
            bm = load_or_build_body(model_path)
        elif step == "gallery figure":
            fig, verts = body_gallery(bm)
            path = out_dir / "body_poses_shapes.png"
            fig.savefig(path, dpi=110)
            plt.close(fig)
            written.append(path)
        else:
            faces = bm.faces.numpy()
            scene = {f"body_{k}": (verts[k].numpy(), faces) for k in range(len(verts))}
            written.append(export_scene(scene, out_dir / "body_poses_shapes.glb"))
    return written
