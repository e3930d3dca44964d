"""The main job (`graspkit demo`): the whole pipeline on one object and one goal, written to an output folder.

Stages (each writes stills, animations (GIF), AMASS-style npz and GLB exports of its final scene):
- body: the procedural humanoid in several poses and shapes;
- planner: the procedural approach-and-grasp clip (the synthetic ground truth) for the mug;
- saga: SAGA stage 1 (WholeGrasp-VAE sample + GraspPose-Opt, Sec. 3.2, Alg. 1) on the mug at the placement of the
  first shipped test grasp, with 100 / 150 / 200 GraspPose-Opt steps (Alg. 1: 300 / 400 / 500) to keep it short;
- saga_motion: SAGA end to end (graspkit.saga.synthesize) for the mug where the planner's clip puts it (another
  placement than the saga stage's, and its own grasp): object -> WholeGrasp-VAE + GraspPose-Opt (Alg. 1's steps) ->
  MotionFill-VAE + GraspMotion-Opt (Sec. 3.2-3.4, Alg. 1-2), a standing start walking into the sampled grasp;
- goal: GOAL (GNet grasp + refinement, then MNet's autoregressive approach, Sec. 3.1-3.5) from the clip's start;
- wandr: WANDR reaching a goal in 4 s from a held-out start pose (Sec. 3.2-3.5).
A method whose shipped checkpoint is missing is skipped with a message naming the file.
"""
from __future__ import annotations

import dataclasses
import os
import sys
from functools import lru_cache
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import torch
from tqdm import tqdm

from graspkit.body import BodyModel
from graspkit.body.poses import body_pose, y_up_to_z_up
from graspkit.paths import DATA_STUBS, default_model_path, stub_hint, writes_to
from graspkit.progress import hidden
from graspkit.viz.export import save_png
from graspkit.viz.style import OBJECT

STAGES = ("body", "planner", "saga", "saga_motion", "goal", "wandr")
CHECKPOINTS = DATA_STUBS / "checkpoints"

DEMO_BODIES = [("t_pose", 0.0), ("a_pose", 0.0), ("walk", 0.0), ("reach_high", 0.0), ("squat", 0.0),
               ("bend_pick", 0.0), ("a_pose", -2.0), ("a_pose", 2.0)]


def load_or_build_body(model_path: Path | None = None) -> BodyModel:
    """The body model at model_path (default: the shipped humanoid; built and saved if it is missing: in a plain
    `pip install`, in the cache, paths.built_model_path(); a file GRASPKIT_MODEL names is never built)."""
    path = Path(model_path) if model_path else default_model_path()
    if not path.exists() and model_path is None and os.environ.get("GRASPKIT_MODEL"):     # a typo: not built there
        raise FileNotFoundError(f"GRASPKIT_MODEL: {path}: no such body-model file (expected an SMPL-X-format .npz)")
    if not path.exists() and model_path is None:
        import tempfile

        from graspkit.body.procedural import build_procedural_smplx, save_model_npz
        from graspkit.paths import cannot_write

        try:                       # before the 20-40 s build: a folder it cannot be kept in is named first
            path.parent.mkdir(parents=True, exist_ok=True)
            with tempfile.TemporaryFile(dir=path.parent):
                pass
        except OSError as e:
            raise cannot_write(path.parent, e) from None
        save_model_npz(build_procedural_smplx(seed=0), path)
    return BodyModel.from_file(path)


def body_gallery(bm: BodyModel, bodies: list[tuple[str, float]] = DEMO_BODIES) -> tuple[plt.Figure, torch.Tensor]:
    """A row of bodies (pose name, height beta) side by side in the z-up world; returns the figure and vertices
    (N,V,3)."""

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


Panel = tuple[str, np.ndarray, list, object]   # title, last-frame vertices (V,3), object meshes, goals (G,3) or None


def _write_clip(bm: BodyModel, motion, out_dir: Path, name: str, objects: dict, title: str,
                goals=None) -> tuple[list[Path], Panel]:
    """A clip's GIF (front and side views), still of its last frame, npz, animated GLB and final-scene GLB; returns
    the paths and the last frame for the overview. An earlier run's files of the same name go first: a run stopped
    part-way then leaves fewer files, not a set mixing two runs' (an independent check found one)."""
    from graspkit.viz import animate, save_animation, show_scene
    from graspkit.viz.export import export_motion, motion_vertices

    for suffix in (".gif", ".png", ".npz", ".glb", "_final.glb"):
        earlier = writes_to(out_dir / f"{name}{suffix}")                    # a link stays, to be written through
        if earlier.is_file():
            earlier.unlink()
    v = motion_vertices(motion, bm)
    faces = bm.faces.numpy()
    objs = [(np.asarray(m.vertices), np.asarray(m.faces)) for m in objects.values()]
    anim = animate(v, faces, objects=objs, goals=goals, title=title, max_frames=45, size=2.6)
    try:
        paths = [save_animation(anim, out_dir / f"{name}.gif", progress=False)]
    finally:                                          # also when the save fails or is interrupted: no figure left open
        plt.close(anim._fig)
    fig = show_scene(meshes=[(v[-1], faces)] + [(ov, of, OBJECT) for ov, of in objs], title=f"{title}: last frame")
    paths.append(save_png(fig, out_dir / f"{name}.png", dpi=90))
    paths += list(export_motion(motion, bm, out_dir, name, objects=objects, stride=3).values())
    return paths, (title, v[-1], objs, goals)


def overview(panels: list[Panel], faces: np.ndarray) -> plt.Figure:
    """One row: the last frame of every method's clip, seen from the side, on the same scale."""
    from graspkit.viz import draw_ground, draw_mesh, set_equal
    from graspkit.viz.scene import draw_goal

    fig = plt.figure(figsize=(3.2 * len(panels), 3.6))
    for k, (title, v, objs, goals) in enumerate(panels):
        ax = fig.add_subplot(1, len(panels), k + 1, projection="3d", proj_type="ortho")
        draw_mesh(ax, v, faces)
        for ov, of in objs:
            draw_mesh(ax, ov, of, color=OBJECT)
        for g in ([] if goals is None else np.asarray(goals).reshape(-1, 3)):
            draw_goal(ax, g)
        c = v.mean(0)
        draw_ground(ax, (c[0] - 1.0, c[0] + 1.0, c[1] - 1.0, c[1] + 1.0))
        set_equal(ax, np.array([[c[0] - 1.0, c[1] - 1.0, 0.0], [c[0] + 1.0, c[1] + 1.0, 2.0]]), pad=0.0, zoom=1.3)
        ax.view_init(elev=12, azim=-60)
        ax.set_axis_off()
        ax.set_title(title, fontsize=9)
    fig.subplots_adjust(0, 0, 1, 0.95, wspace=0)
    return fig


@lru_cache(maxsize=1)
def _test_clip():
    """The first shipped approach-and-grasp clip of a test-split object, and its object mesh in the world."""
    from graspkit.benchmark import object_mesh_at, split_sequences

    seqs = split_sequences([DATA_STUBS / "approach"], "approach", "test")
    if not seqs:
        raise FileNotFoundError(f"data_stubs: no test-split approach clip in {DATA_STUBS / 'approach'}"
                                + stub_hint(DATA_STUBS / "approach"))
    return seqs[0], object_mesh_at(seqs[0], 0)


def _on(bm: BodyModel, motion, made_on: Path | None = None):
    """A motion made on the body model file `made_on` (default: graspkit's procedural body, that of the shipped clips)
    drawn on bm, standing where it stood (`graspkit.data.motion.restand`; unchanged on the same body): a body of
    other legs would float or sink by the difference."""
    from graspkit.body import shared_body
    from graspkit.data.motion import restand
    from graspkit.paths import procedural_model_path

    return restand(motion, shared_body(made_on or procedural_model_path(), flat_hand_mean=True), bm)


def planner_stage(bm: BodyModel, out_dir: Path) -> tuple[list[Path], Panel]:
    """The synthetic ground truth: the procedural approach-and-grasp clip."""
    from graspkit.benchmark import sequence_motion

    seq, obj = _test_clip()
    return _write_clip(bm, _on(bm, sequence_motion(seq)), out_dir, "planner_approach", {seq.object_name: obj},
                       f"procedural planner: {seq.object_name}")


def saga_stage(bm: BodyModel, out_dir: Path, steps: tuple[int, int, int] = (100, 150, 200)
               ) -> tuple[list[Path], Panel]:
    """SAGA stage 1 on the first shipped test-object grasp's placement (the clip's object): a WholeGrasp-VAE sample
    fitted by GraspPose-Opt (Alg. 1), shown in the world."""
    from graspkit.data.grab import read_arrays
    from graspkit.data.grasp_datasets import grasp_files
    from graspkit.data.grasp_io import collision_sdf_grid
    from graspkit.data.motion import Motion
    from graspkit.eval_saga import _object_batch, fit_variants, load_placements
    from graspkit.models.pose_prior import load_pose_prior
    from graspkit.models.wholegrasp import load_wholegrasp
    from graspkit.objects.catalogue import make_object
    from graspkit.optim.grasppose import GraspPoseConfig, GraspPoseOpt

    seq, _ = _test_clip()
    pl = load_placements(DATA_STUBS / "grasps", seq.object_name, 1)[0]
    first = next(f for f in grasp_files(DATA_STUBS / "grasps", "grasp", split="test")
                 if str(read_arrays(f)["obj_name"]) == seq.object_name)
    centre = read_arrays(first)["object.params.transl"][0].astype(np.float64)   # the placement frame's origin
    wg = load_wholegrasp(CHECKPOINTS / "wholegrasp.pt")
    prior = load_pose_prior(CHECKPOINTS / "pose_prior.pt")
    g = torch.Generator().manual_seed(0)
    s = wg.sample(pl.points, pl.normals, pl.height, 1, g, centre=torch.zeros(3))
    opt = GraspPoseOpt(bm, prior, GraspPoseConfig(steps=steps))
    res = fit_variants(opt, s.markers, _object_batch([pl], 1, collision_sdf_grid(pl.name)), s.marker_contact,
                       s.object_contact, ["full"])["full"]
    p = res.params
    full = torch.cat([p["global_orient"][:, None], p["body_pose"].view(1, 21, 3), p["jaw_pose"][:, None],
                      p["leye_pose"][:, None], p["reye_pose"][:, None], p["left_hand_pose"].view(1, 15, 3),
                      p["right_hand_pose"].view(1, 15, 3)], 1)
    mesh = make_object(pl.name)
    mesh.vertices = np.asarray(mesh.vertices) @ pl.rotation.double().numpy().T + centre
    motion = Motion(full.detach().numpy(), p["transl"].detach().numpy() + centre, p["betas"][0].detach().numpy(), 30.0)
    return _write_clip(bm, motion, out_dir, "saga_grasp", {pl.name: mesh}, "SAGA: WholeGrasp + GraspPose-Opt")


def saga_motion_stage(bm: BodyModel, out_dir: Path, steps: tuple[int, int] = (100, 300)
                      ) -> tuple[list[Path], Panel]:
    """SAGA end to end (`graspkit.saga.synthesize`) for the clip's object where the clip puts it: a WholeGrasp-VAE
    grasp fitted by GraspPose-Opt (Alg. 1), then 2 s of MotionFill-VAE motion from a standing start into that grasp,
    fitted by GraspMotion-Opt (Alg. 2 with frame 0 held at the start, synthesize's default); in the world."""
    from graspkit.objects.placement import ObjectPose
    from graspkit.saga import synthesize

    seq, _ = _test_clip()
    pose = ObjectPose(seq.object_transl[0].astype(np.float64), seq.object_rotation()[0])
    r = synthesize(seq.object_name, bm, object_pose=pose, seed=0, motion_steps=steps, checkpoints=CHECKPOINTS,
                   progress=False)
    return _write_clip(bm, r.motion, out_dir, "saga_motion", {seq.object_name: r.mesh},
                       "SAGA: object -> grasp -> motion")


def goal_stage(bm: BodyModel, out_dir: Path) -> tuple[list[Path], Panel]:
    """GOAL from the clip's start: GNet's grasp (refined), then MNet's approach to it (§3.4)."""
    from graspkit.benchmark import goal_motions, sequence_motion
    from graspkit.body import shared_body

    seq, obj = _test_clip()
    start = _on(shared_body(default_model_path(), flat_hand_mean=True), sequence_motion(seq))   # the clip's start on
    seq = dataclasses.replace(seq, trans=start.trans.astype(np.float32))       # that body, standing where it stood
    motion = goal_motions([seq], CHECKPOINTS)[0]                # on eval_goal's body: default_model_path()
    return _write_clip(bm, _on(bm, motion, default_model_path()), out_dir, "goal_approach",
                       {seq.object_name: obj}, "GOAL: GNet + MNet")


def wandr_stage(bm: BodyModel, out_dir: Path, seconds: float = 4.0) -> tuple[list[Path], Panel]:
    """WANDR from its first held-out start pose to a goal 2 m ahead-left, 1 m high, in `seconds` (with graspkit's
    lift, which holds the feet out of the floor: docs/wandr.md)."""
    import trimesh

    from graspkit.benchmark import wandr_motions
    from graspkit.eval_wandr import goal_from_cylinder
    from graspkit.viz.scene import sphere

    goal = goal_from_cylinder(45.0, 2.0, 1.0)
    motion = wandr_motions(CHECKPOINTS / "wandr.pt", goal[None], int(round(seconds * 30.0)), lift=True, bm=bm)[0]
    sv, sf = sphere(goal.numpy(), 0.05)
    return _write_clip(bm, motion, out_dir, "wandr_reach", {"goal": trimesh.Trimesh(sv, sf, process=False)},
                       f"WANDR (+ lift): reach the goal in {seconds:g} s", goals=goal[None].numpy())


METHOD_STAGES = {"planner": (planner_stage, ()), "saga": (saga_stage, ("wholegrasp.pt", "pose_prior.pt")),   # every
                 "saga_motion": (saga_motion_stage, ("wholegrasp.pt", "pose_prior.pt", "motionfill.pt",  # file a
                                                     "motionfill_smooth_ae.pt")),                        # stage loads
                 "goal": (goal_stage, ("gnet.pt", "mnet.pt")), "wandr": (wandr_stage, ("wandr.pt",))}


def run_demo(out_dir: Path, model_path: Path | None = None, stages: tuple[str, ...] = STAGES) -> list[Path]:
    """Run the demo's stages into out_dir (see the module doc), then `pipeline_overview.png` (every method's last
    frame side by side) when a method stage ran; returns the files written."""
    from graspkit.viz.export import export_scene

    bad = [s for s in stages if s not in STAGES]
    if bad:
        raise ValueError(f"stages (--stages): unknown {bad}; expected some of {list(STAGES)}")
    stages = tuple(dict.fromkeys(stages))                # each stage once, in the order given
    if not stages:
        raise ValueError(f"stages (--stages): expected at least one of {list(STAGES)}")
    missing = {s: [CHECKPOINTS / ck for ck in METHOD_STAGES[s][1] if not (CHECKPOINTS / ck).is_file()]
               for s in stages if s not in ("body", "planner")}
    if "planner" in stages:
        try:
            _test_clip()
            missing["planner"] = []
        except FileNotFoundError:
            missing["planner"] = [DATA_STUBS / "approach"]
    if all(missing.get(s) for s in stages):              # nothing could be written: an error, not an empty folder
        first = missing[stages[0]][0]
        what = "(its sample clips)" if stages[0] == "planner" else "(train it with `graspkit train ...`, see README)"
        raise FileNotFoundError(f"stages (--stages): none of {', '.join(stages)} can run: {first} is missing "
                                f"{what}{stub_hint(first)}")
    bm = load_or_build_body(model_path)                 # before the folder: a bad model file leaves nothing behind
    out_dir.mkdir(parents=True, exist_ok=True)
    written: list[Path] = []
    panels: list[Panel] = []
    steps = tqdm(list(stages), desc="demo", unit="stage", disable=hidden())
    for stage in steps:
        steps.set_postfix_str(stage)
        if stage == "body":
            fig, verts = body_gallery(bm)
            path = save_png(fig, out_dir / "body_poses_shapes.png", dpi=110)
            faces = bm.faces.numpy()
            # side by side along x, 1 m apart, as in the picture (each body is centred above the origin)
            scene = {f"body_{k}": (verts[k].numpy() + [1.0 * k, 0.0, 0.0], faces) for k in range(len(verts))}
            written += [path, export_scene(scene, out_dir / "body_poses_shapes.glb")]
            continue
        fn, _ = METHOD_STAGES[stage]
        if missing[stage] and stage == "planner":
            tqdm.write(f"demo: skipping planner: no test-split approach clip in {missing[stage][0]}"
                       f"{stub_hint(missing[stage][0])}", file=sys.stderr)
            continue
        if missing[stage]:
            tqdm.write(f"demo: skipping {stage}: its checkpoint {missing[stage][0]} is missing "
                       f"(train it with `graspkit train ...`, see README){stub_hint(missing[stage][0])}",
                       file=sys.stderr)
            continue
        paths, panel = fn(bm, out_dir)
        written += paths
        panels.append(panel)
    if panels:
        fig = overview(panels, bm.faces.numpy())
        written.append(save_png(fig, out_dir / "pipeline_overview.png", dpi=100))
    return written
