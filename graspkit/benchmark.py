"""One benchmark for every method (`graspkit eval --all`): grasp and motion quality with one metrics module.

Grasp quality (SAGA Sec. 4.1 / Tab. 1-2, GOAL Sec. 4.2 / Tab. 1): contact ratio, interpenetration volume (cm^3)
and depth (cm), APD, all from `graspkit.metrics`, on the held-out (test-split) objects, for the synthetic ground
truth, SAGA (WholeGrasp-VAE + GraspPose-Opt, and the GrabNet-SMPLX baseline) and GOAL (GNet + refinement).
Motion quality (SAGA Sec. 4.2, GOAL Sec. 4.2, WANDR Sec. 4.3): foot skating (WANDR's and SAGA's definitions),
foot sliding (GOAL's), mean jerk, and for reaching the success rate (SR) and distance to goal (DTG), for the
procedural planner (the synthetic approach clips and the WANDR goal grid), GOAL's MNet and WANDR.

Every method is evaluated by its own evaluator (`graspkit.eval_saga`, `graspkit.eval_goal`, `graspkit.eval_wandr`,
all measuring with `graspkit.metrics`); this module runs them on the same objects and the same grid, measures the
ground truth and the planner itself, runs every motion method on the same few motions (`common_motion_rows`), and
writes one table (markdown + CSV) and figures, the papers' published figures beside ours in rows labelled with their
source. A row holds one protocol's figures: an evaluator's own rows and the common motions' rows ("· 4 common
motions") are kept apart. A method whose checkpoint is missing is listed as such.

Reproducibility: every draw is seeded, so a rerun on the same machine with the same number of torch threads gives
the same table. Across thread counts the float sums run in another order, and an autoregressive rollout that stops
at a distance threshold can end a frame earlier or later (GOAL's four common rollouts: 97 / 53 / 100 / 47 frames on
one thread in the shipped table), which moves the motion rows in their last digit. The shipped table
(docs/benchmark) is made on one thread.
"""
from __future__ import annotations

import csv
import io
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import torch

if TYPE_CHECKING:
    import trimesh
    from matplotlib.figure import Figure

    from graspkit.body import BodyModel
    from graspkit.data.grab import GraspSequence
    from graspkit.data.motion import Motion

GRASP_METRICS = {  # key: (column title, higher is better)
    "contact_ratio": ("contact ratio ↑", True), "volume_cm3": ("penetration volume cm³ ↓", False),
    "depth_cm": ("penetration depth cm ↓", False), "apd": ("APD ↑", True)}
MOTION_METRICS = {
    "fs_wandr": ("foot skating % (WANDR) ↓", False), "skate_saga": ("foot skating (SAGA) ↓", False),
    "slide_goal": ("foot sliding % (GOAL) ↓", False), "mean_jerk": ("jerk m/s³ ↓", False),
    "ade": ("ADE m ↓", False), "SR": ("SR % ↑", True), "DTG": ("DTG cm ↓", False)}

# The papers' published figures (their data: GRAB, AMASS, CIRCLE; ours: graspkit's synthetic data). Percentages as %.
PAPER_ROWS: list[tuple[str, str, str, dict[str, float]]] = [
    ("grasp", "SAGA (WholeGrasp w/ opt.)", "SAGA Tab. 1", {"apd": 2.92, "contact_ratio": 0.94, "volume_cm3": 0.48,
                                                             "depth_cm": 0.16}),
    ("grasp", "GrabNet-SMPLX", "SAGA Tab. 1", {"apd": 0.33, "contact_ratio": 0.65, "volume_cm3": 14.15,
                                                "depth_cm": 0.78}),
    ("grasp", "ground truth (GRAB)", "SAGA Tab. 2", {"contact_ratio": 0.99, "volume_cm3": 2.04, "depth_cm": 0.45}),
    ("grasp", "GOAL (GNet + refinement)", "GOAL Tab. 1", {"contact_ratio": 1.00, "volume_cm3": 2.22}),
    ("grasp", "ground truth (GRAB)", "GOAL Tab. 1", {"contact_ratio": 1.00, "volume_cm3": 1.95}),
    ("motion", "SAGA (MotionFill, traj + local)", "SAGA Tab. 3", {"ade": 0.083, "skate_saga": 0.394}),
    ("motion", "GOAL (GNet + MNet)", "GOAL Sec. 4.2", {"slide_goal": 13.7}),
    ("motion", "ground truth (GRAB)", "GOAL Sec. 4.2", {"slide_goal": 6.7}),
    ("motion", "WANDR", "WANDR Tab. 1", {"SR": 32.0, "fs_wandr": 16.0, "DTG": 24.8}),
    ("motion", "GOAL (on WANDR's grid)", "WANDR Tab. 1", {"SR": 0.0, "fs_wandr": 29.0, "DTG": 149.2}),
]


METHODS = ("gt", "saga", "saga_motion", "goal", "wandr", "motion")
# Row-name suffixes: a row holds the figures of one protocol only (an evaluator's own, or the common motions'), so
# that a column never mixes two (it did until 2026-12-03: WANDR's FS was the grid's 6.5 % beside the common
# motions' sliding, and on the common motions it is 16.7 %).
COMMON = " · 4 common motions"            # the full run's; a --quick run names its count (`common_motion_rows`)


@dataclass
class Row:
    """One line of the benchmark: which table ('grasp' / 'motion'), the method, where the figures come from
    ('graspkit' for ours, else the paper and table), the metric values, and a note (counts, what is missing)."""

    table: str
    method: str
    source: str
    values: dict[str, float] = field(default_factory=dict)
    note: str = ""


# ----------------------------------------------------------------------------------------------- ours, measured here

def split_sequences(folders: list[Path], kind: str, split: str, bm: BodyModel | None = None) -> list:
    """GRAB-style sequences of `kind` whose object is in `split`, from every folder that has such files; with the body
    model `bm` they will be posed on, files made on another body are refused (`grab.check_made_on`)."""
    from graspkit.data.formats import clip_files
    from graspkit.data.grab import check_made_on, load_grasp_sequence
    from graspkit.data.grasp import file_split

    out = []
    for f in folders:
        if bm is not None:
            check_made_on(bm, clip_files(f, kind), f"data: {f}", kind)
        for p in clip_files(f, kind):
            s = load_grasp_sequence(p)
            if file_split(s.object_name, p) == split and bool(s.extras.get("grasp.accepted", True)):
                out.append(s)
    return out


def object_mesh_at(seq: GraspSequence, frame: int) -> trimesh.Trimesh:
    """The sequence's catalogue object as a trimesh at its pose at `frame`."""
    from graspkit.objects.catalogue import make_object
    from graspkit.objects.placement import ObjectPose, apply_pose

    return apply_pose(ObjectPose(seq.object_transl[frame].astype(np.float64), seq.object_rotation()[frame]),
                      make_object(seq.object_name))


def sequence_motion(seq: GraspSequence) -> Motion:
    """A GraspSequence as a graspkit Motion (same poses, translation, shape and frame rate)."""
    from graspkit.data.motion import Motion

    return Motion(seq.poses, seq.trans, seq.betas[:10], seq.fps)


def ground_truth_grasps(bm: BodyModel, folders: list[Path], split: str = "test", n: int | None = None) -> Row:
    """Grasp quality of the synthetic ground truth: the last frame of every accepted `split` grasp file (<= n)."""
    from graspkit.metrics import grasp_metrics, grasp_quality_table

    seqs = split_sequences(folders, "grasp", split, bm)[:n]
    if not seqs:
        return Row("grasp", "ground truth (synthetic)", "graspkit", note=f"no accepted {split} grasps in {folders}")
    rows = [grasp_metrics(sequence_motion(s).vertices(bm, s.num_frames - 1)[0].double(), bm.faces,
                          object_mesh_at(s, -1))
            for s in seqs]
    q = grasp_quality_table(rows)
    objs = sorted({s.object_name for s in seqs})
    return Row("grasp", "ground truth (synthetic)", "graspkit",
               {"contact_ratio": q["contact_ratio"], "volume_cm3": q["volume_mean_cm3"],
                "depth_cm": q["depth_mean_cm"]},
               f"{len(seqs)} grasps of {', '.join(objs)}")


def planner_motion(bm: BodyModel, folders: list[Path], split: str = "test", n: int | None = None) -> Row:
    """Motion quality of the procedural planner's approach-and-grasp clips (`split` objects, <= n clips)."""
    from graspkit.metrics import motion_quality

    seqs = split_sequences(folders, "approach", split, bm)[:n]
    if not seqs:
        return Row("motion", "procedural planner (approach clips)", "graspkit", note=f"no {split} approach clips")
    q = motion_quality(bm, [sequence_motion(s) for s in seqs])
    return Row("motion", "procedural planner (approach clips)", "graspkit",
               {"fs_wandr": 100 * q["fs_wandr"], "skate_saga": q["skate_saga"], "slide_goal": 100 * q["slide_goal"],
                "mean_jerk": q["mean_jerk"]}, f"{q['clips']} clips, {q['frames']} frames")


# ------------------------------------------------------------------------------------- ours, from each evaluator

def saga_rows(res: dict) -> list[Row]:
    """SAGA's Tab. 1 rows (ours and the GrabNet-SMPLX baseline) from a graspkit.eval_saga result."""
    objs = ", ".join(res.get("config", {}).get("objects", []))
    names = {"WholeGrasp w/ opt. (Ours)": "SAGA (WholeGrasp w/ opt.)", "GrabNet-SMPLX": "GrabNet-SMPLX"}
    rows = []
    for key, name in names.items():
        r = res.get("rows", {}).get(key)
        if r:
            rows.append(Row("grasp", name, "graspkit", {k: float(r[k]) for k in GRASP_METRICS if k in r},
                            f"{r.get('n', '?')} grasps of {objs}"))
    return rows


def goal_rows(res: dict) -> list[Row]:
    """GOAL's Tab. 1 rows (GNet + refinement: Eq. 4-8, and with graspkit's E_pen) and its motions' sliding (GNet + MNet)
    from a graspkit.eval_goal result."""
    from graspkit.eval_goal import PEN_ROW

    rows = []
    names = {"GNet": "GOAL (GNet + refinement)", PEN_ROW: "GOAL (GNet + refinement + E_pen, graspkit's)"}
    for key, name in names.items():
        r = res.get("tab1", {}).get(key)
        if r:
            rows.append(Row("grasp", name, "graspkit",
                            {k: float(r[k]) for k in ("contact_ratio", "volume_cm3", "depth_cm") if k in r},
                            f"{r.get('n', '?')} grasps"))
    clips = res.get("rollouts", {}).get("clips", "?")
    for key, v in res.get("sliding", {}).items():     # GOAL's Sec. 4.2 protocol: the same clips for both methods
        if key.startswith("GOAL"):
            rows.append(Row("motion", "GOAL (GNet + MNet)", "graspkit", {"slide_goal": 100 * float(v)},
                            f"{clips} rollouts of GOAL's evaluation"))
        elif key.startswith("SAGA"):
            rows.append(Row("motion", f"SAGA (MotionFill + GraspMotion-Opt) · GOAL's {clips} clips", "graspkit",
                            {"slide_goal": 100 * float(v)}, f"the {clips} clips of GOAL's evaluation, eval_goal"))
    return rows


def saga_motion_rows(res: dict) -> list[Row]:
    """SAGA's Tab. 3 rows (MotionFill-VAE with its own trajectory, and with the true one) from graspkit.eval_motionfill
    results ({'rows': {...}, 'test_windows': n}); skating is SAGA's heel definition on the sampled markers."""
    names = {"Ours": "SAGA (MotionFill, traj + local)", "Ours-Local": "SAGA (MotionFill, local, true trajectory)"}
    rows = []
    for key, name in names.items():
        r = res.get("rows", {}).get(key)
        if r:
            rows.append(Row("motion", name, "graspkit", {"ade": float(r["ADE"]), "skate_saga": float(r["skating"])},
                            f"{res.get('test_windows', '?')} test windows, min of {res.get('samples', 10)} samples"))
    return rows


def wandr_rows(res: dict) -> list[Row]:
    """WANDR's goal-grid row and the procedural planner's on the same grid from graspkit.eval_wandr.run_eval_wandr."""
    pick = lambda s: {"SR": float(s["SR"]), "fs_wandr": float(s["FS"]), "DTG": float(s["DTG"])}  # noqa: E731
    rows = [Row("motion", "WANDR", "graspkit", pick(res["summary"]),
                f"{res['summary']['rollouts']} rollouts on the grid")]
    if "planner" in res:
        rows.append(Row("motion", "procedural planner (WANDR grid)", "graspkit", pick(res["planner"]),
                        f"{res['planner']['rollouts']} motions"))
    return rows


def run_saga(root: Path, out: Path, quick: bool, checkpoints: Path) -> dict:
    """graspkit.eval_saga on the test objects found in `root` (quick: one placement, three samples each)."""
    from graspkit.eval_saga import EvalConfig, evaluate

    objs = tuple(sorted({s.object_name for s in split_sequences([root], "grasp", "test")}))
    if not objs:
        raise FileNotFoundError(f"data: no accepted test-split grasps in {root}")
    cfg = EvalConfig(objects=objs, placements=1, samples=3, gt_grasps=1) if quick else EvalConfig(objects=objs)
    return evaluate(root, cfg, progress=True, out=out, checkpoints=checkpoints)


def run_saga_motion(approach: Path, out: Path, quick: bool, checkpoints: Path) -> dict:
    """graspkit.eval_motionfill's Tab. 3 on the test-object approach windows in `approach` (quick: 3 samples)."""
    from graspkit.body import BodyModel
    from graspkit.data.grasp import split_of
    from graspkit.data.motionfill_dataset import make_windows
    from graspkit.eval_motionfill import approach_motions, evaluate, load_motionfill
    from graspkit.paths import default_model_path, write_json

    bm = BodyModel.from_file(default_model_path())
    motions, names = approach_motions(approach, bm=bm)
    if not motions:
        raise FileNotFoundError(f"data: no approach clips (approach_*.npz) in {approach}")
    arr = make_windows(motions, bm, stride=30, align_end=True, progress=False)
    test = np.unique(arr["clip"][[split_of(names[c]) == "test" for c in arr["clip"]]])
    if not len(test):
        raise FileNotFoundError(f"data: no test-object approach clips in {approach}")
    n = 3 if quick else 10
    rows = evaluate(load_motionfill(checkpoints / "motionfill.pt"), arr, test, n=n)
    res = {"rows": rows, "test_windows": int(np.isin(arr["clip"], test).sum()), "samples": n}
    write_json(out, res)
    return res


def run_goal(folders: list[Path], out: Path, quick: bool, checkpoints: Path) -> dict:
    """graspkit.eval_goal on the test objects in `folders` (quick: 4 grasps, 2 rollouts)."""
    from graspkit.eval_goal import evaluate

    kw = dict(n_grasps=4, n_rollouts=2, window_stride=20) if quick else {}
    return evaluate(folders, checkpoints, out=out, **kw)


def run_wandr(checkpoint: Path, out: Path, quick: bool) -> dict:
    """graspkit.eval_wandr's goal grid (quick: one sample per start and goal), with the planner; saved as JSON."""
    from graspkit.eval_wandr import run_eval_wandr
    from graspkit.paths import write_json

    res = run_eval_wandr(str(checkpoint), n=1 if quick else 5, planner=True, threads=torch.get_num_threads())
    write_json(out, res)
    return res


# ------------------------------------------------------------------------ every method's motions, one metrics function

def motionfill_motions(files: list[Path], checkpoints: Path, steps: tuple[int, int] = (100, 300), seed: int = 0
                       ) -> tuple[list[Motion], list[dict]]:
    """SAGA stage 2 on approach clips `files`: one MotionFill-VAE sample each into the clip's grasp, fitted by
    GraspMotion-Opt (Alg. 2, batched); Motions in MotionFill's canonical frame (A.3) with the floor at z = 0, and
    the scenes (object mesh moved the same way)."""
    from graspkit.data.motion import Motion
    from graspkit.eval_motionfill import graspmotion_eval, load_motionfill

    ev = graspmotion_eval(load_motionfill(checkpoints / "motionfill.pt"), files, seed=seed, steps=steps,
                          progress=False)
    pr, out = ev["result"].params, []
    F = pr["transl"].shape[1]
    for b, scene in enumerate(ev["scenes"]):
        lift = np.array([0.0, 0.0, -scene["floor"]])
        out.append(Motion(pr["poses"][b].view(F, 55, 3).detach().numpy(), pr["transl"][b].detach().numpy() + lift,
                          pr["betas"][b].detach().numpy(), 30.0))
        scene["mesh"] = scene["mesh"].copy()
        scene["mesh"].apply_translation(lift)
    return out, ev["scenes"]


def goal_motions(seqs: list, checkpoints: Path, seed: int = 0, max_frames: int = 150) -> list:
    """GOAL from each approach clip's start: GNet's grasp (refined), then MNet's rollout to it (§3.4); Motions."""
    from graspkit.data.motion import Motion
    from graspkit.eval_goal import _body, approach_clips, gnet_goal
    from graspkit.models.gnet import load_gnet
    from graspkit.models.mnet import STALL_FRAMES, load_mnet, rollout
    from graspkit.objects.bps import bps_basis
    from graspkit.rotations import matrix_to_axis_angle, rot6d_to_matrix

    gnet, mnet = load_gnet(checkpoints / "gnet.pt"), load_mnet(checkpoints / "mnet.pt")
    _, _, body = _body()
    g, out = torch.Generator().manual_seed(seed), []
    for clip in approach_clips(seqs):
        start = (clip.rot6d[0], clip.transl[0])
        goal = gnet_goal(gnet, start, clip.betas, clip.object_points, clip.obj_centre, generator=g)[:2]
        r = rollout(mnet, body, start, goal, clip.betas, clip.object_points, clip.obj_centre, bps_basis(),
                    max_frames=max_frames, floor=0.0, stall=STALL_FRAMES)
        aa = matrix_to_axis_angle(rot6d_to_matrix(r.rot6d.double())).float()
        out.append(Motion(aa.numpy(), r.transl.detach().numpy(), clip.betas.reshape(-1)[:10].numpy(), 30.0))
    return out


def wandr_motions(checkpoint: Path, goals: torch.Tensor, t_goal: int, seed: int = 0, lift: bool = False,
                  bm: BodyModel | None = None) -> list:
    """WANDR from its first held-out start pose (canonical) to each goal (G,3) at frame t_goal, one batch; Motions
    (lift: `rollout`'s guard against sinking into the floor, not in the paper). bm: another body model to move on (the
    start, made on graspkit's body, is stood on it: `StartPose.on_body`; None: graspkit's)."""
    import graspkit.intention as I
    from graspkit.body import shared_body
    from graspkit.data.motion import Motion
    from graspkit.eval_wandr import starts_from_meta
    from graspkit.models.wandr import generate, load_wandr
    from graspkit.paths import procedural_model_path

    model = load_wandr(checkpoint)
    start = starts_from_meta(model.meta)[0]
    if bm is not None and not start.made_on(bm):
        ours = shared_body(procedural_model_path(), flat_hand_mean=True)
        if not start.made_on(ours):
            raise ValueError(f"checkpoint: {checkpoint}'s held-out starts were made on neither the body model given "
                             "nor graspkit's (their rest joints are another body's): generate on the body it was "
                             "trained on (--model, or GRASPKIT_MODEL, naming that file)")
        start = start.on_body(ours, bm)
    start = start.canonical()
    out = generate(model, start, goals, t_goal, n=1, generator=torch.Generator().manual_seed(seed), lift=lift)
    motions = []
    for b, goal in enumerate(goals):
        trans, aa = I.pose_to_axis_angle(out.p[b], start.full_pose)
        motions.append(Motion(aa.numpy(), trans.numpy(), start.betas.numpy(), I.FPS, goal=goal.numpy(),
                              goal_frame=t_goal, hand="right"))
    return motions


def common_motion_rows(bm: BodyModel, folders: list[Path], checkpoints: Path, k: int = 4) -> list[Row]:
    """graspkit.metrics.motion_quality (WANDR's FS, SAGA's skating, GOAL's sliding, jerk) on k motions of each
    method: SAGA's MotionFill + GraspMotion-Opt and GOAL's GNet + MNet from the first k test-object approach clips,
    WANDR to k goals of its grid (2 m, 0.9 m high, k directions, 4 s). Rows of their own ("<method> · k common
    motions"), never merged into the evaluators' rows, whose protocols differ."""
    from graspkit.eval_wandr import goal_from_cylinder
    from graspkit.metrics import motion_quality

    seqs = split_sequences(folders, "approach", "test", bm)[:k]
    files = _approach_files(folders, k)
    goals = torch.stack([goal_from_cylinder(a, 2.0, 0.9) for a in np.linspace(0.0, 360.0, k, endpoint=False)])
    methods = (  # name, weights, what it needs, its motions, what they are
        ("SAGA (MotionFill + GraspMotion-Opt)", ("motionfill.pt", "pose_prior.pt", "motionfill_smooth_ae.pt"), files,
         lambda: motionfill_motions(files, checkpoints)[0],
         "2 s windows ending at the grasp of the first test-object approach clips"),
        ("GOAL (GNet + MNet)", ("gnet.pt", "mnet.pt"), seqs, lambda: goal_motions(seqs, checkpoints),
         "GNet + MNet rollouts from the same clips' first frames"),
        ("WANDR", ("wandr.pt",), True, lambda: wandr_motions(checkpoints / "wandr.pt", goals, 120, bm=bm),
         "4 s towards goals 2 m away, 0.9 m high, no object"))
    suffix = f" · {k} common motion{'s' * (k != 1)}"          # COMMON for k = 4
    rows = []
    for name, weights, data, motions, what in methods:
        missing = [checkpoints / w for w in weights if not (checkpoints / w).is_file()]   # every file it loads
        if missing:
            rows.append(Row("motion", name + suffix, "graspkit", {}, f"checkpoint missing: {missing[0]}"))
        elif not data:
            rows.append(Row("motion", name + suffix, "graspkit", {}, "no test-object approach clip in the data"))
        else:
            q = motion_quality(bm, motions())
            values = {"fs_wandr": 100 * q["fs_wandr"], "skate_saga": q["skate_saga"],
                      "slide_goal": 100 * q["slide_goal"], "mean_jerk": q["mean_jerk"]}
            rows.append(Row("motion", name + suffix, "graspkit", values,
                            f"{q['clips']} motions ({q['frames']} frames): {what}"))
    return rows


def _approach_files(folders: list[Path], k: int) -> list[Path]:
    """The first k accepted test-object approach files in `folders`."""
    from graspkit.data.grasp_datasets import grasp_files

    out = []
    for f in folders:
        if Path(f).is_dir():
            out += grasp_files(f, "approach", split="test")
    return out[:k]


# ---------------------------------------------------------------------------------------------------------- driver

def paper_rows() -> list[Row]:
    """The papers' published figures as rows."""
    return [Row(t, m, s, dict(v), "published") for t, m, s, v in PAPER_ROWS]


def run_all(out_dir: str | Path, data: list[Path] | None = None, quick: bool = False,
            checkpoints: str | Path | None = None, methods: tuple[str, ...] = METHODS,
            reuse: bool = False) -> list[Row]:
    """Evaluate every method (and the ground truth / planner) into out_dir; returns all rows, papers' included.

    data: folders with grasp_*.npz / approach_*.npz (default: the made training sets if present, else data_stubs);
    quick: a few samples per method (minutes on two cores) instead of the full protocol (200 ground-truth grasps,
    40 approach clips, each evaluator's own defaults); reuse: take a method's shipped evaluation
    (data_stubs/checkpoints/<method>_eval.json, written by its evaluator with the shipped checkpoint) instead of
    running it again."""
    from tqdm.auto import tqdm

    from graspkit.body import BodyModel
    from graspkit.eval_goal import default_data_folders
    from graspkit.paths import DATA_STUBS, default_model_path, stub_hint
    from graspkit.progress import hidden

    unknown = set(methods) - set(METHODS)
    if unknown:
        raise ValueError(f"methods: unknown {sorted(unknown)}; expected some of {', '.join(METHODS)}")
    out = Path(out_dir)
    ck = Path(checkpoints) if checkpoints else DATA_STUBS / "checkpoints"
    if not ck.is_dir():
        raise FileNotFoundError(f"checkpoints: no folder {ck}{stub_hint(ck)}")
    made = default_data_folders()                       # where `graspkit data make` writes by default
    folders = [Path(p) for p in data] if data else (made if any(any(p.glob("*.npz")) for p in made if p.is_dir())
                                                    else [DATA_STUBS / "grasps", DATA_STUBS / "approach"])
    for f in folders:
        if not f.is_dir():
            raise FileNotFoundError(f"data: no folder {f}{stub_hint(f)}")
    grasps, approach = _holding(folders, "grasp_*.npz"), _holding(folders, "approach_*.npz")   # in any --data order
    shipped = {"saga": "wholegrasp_eval.json", "saga_motion": "motionfill_eval.json", "goal": "goal_eval.json",
               "wandr": "wandr_eval.json"}
    rows_of = {"saga": saga_rows, "saga_motion": saga_motion_rows, "goal": goal_rows, "wandr": wandr_rows}
    reused = {m: reused_rows(ck / shipped[m], rows_of[m], m) for m in methods      # read (and a damaged one named)
              if reuse and m in shipped and (ck / shipped[m]).is_file()}           # before any work
    bm = BodyModel.from_file(default_model_path(), flat_hand_mean=True)
    if "wandr" in methods and "wandr" not in reused and (ck / "wandr.pt").is_file():   # before hours of other methods
        from graspkit.eval_wandr import starts_body_problem, starts_from_meta
        from graspkit.models.wandr import load_wandr

        try:
            problem = starts_body_problem(starts_from_meta(load_wandr(ck / "wandr.pt").meta), bm, ck / "wandr.pt")
        except (OSError, ValueError):      # a damaged checkpoint: the method's own run says so in its row
            problem = None
        if problem:
            raise ValueError(problem)
    if any(m != "wandr" and m not in reused for m in methods):      # the others pose the data's grasps on bm
        from graspkit.data.formats import clip_files
        from graspkit.data.grab import check_made_on

        for folder in folders:                                       # gt and motion read every one of them
            for kind in ("grasp", "approach"):
                check_made_on(bm, clip_files(folder, kind), f"data: {folder}", kind)
    out.mkdir(parents=True, exist_ok=True)                # after the checks: a refused run leaves no folder
    rows: list[Row] = []
    steps = tqdm(list(methods), desc="eval --all", unit="method", disable=hidden())
    for m in steps:
        steps.set_postfix_str(m)
        t0 = time.perf_counter()
        if m in reused:
            new = reused[m]
        elif m == "gt":
            new = [ground_truth_grasps(bm, folders, n=8 if quick else 200),
                   planner_motion(bm, folders, n=4 if quick else 40)]
        elif m == "saga":
            new = _method((ck / "wholegrasp.pt", ck / "pose_prior.pt"), out / "saga_eval.json", saga_rows,
                          lambda o: run_saga(grasps, o, quick, ck), "SAGA (WholeGrasp w/ opt.)", "grasp")
        elif m == "saga_motion":
            new = _method(ck / "motionfill.pt", out / "motionfill_eval.json", saga_motion_rows,
                          lambda o: run_saga_motion(approach, o, quick, ck), "SAGA (MotionFill, traj + local)",
                          "motion")
        elif m == "motion":
            new = common_motion_rows(bm, folders, ck, k=2 if quick else 4)
        elif m == "goal":
            new = _method((ck / "gnet.pt", ck / "mnet.pt"), out / "goal_eval.json", goal_rows,
                          lambda o: run_goal(folders, o, quick, ck), "GOAL (GNet + refinement)", "grasp")
        else:
            new = _method(ck / "wandr.pt", out / "wandr_eval.json", wandr_rows,
                          lambda o: run_wandr(ck / "wandr.pt", o, quick), "WANDR", "motion")
        for r in new:                                     # wall time of what ran here (a reused result took none)
            if "(from " not in r.note:
                r.note = (r.note + "; " if r.note else "") + f"{time.perf_counter() - t0:.0f} s"
        rows += new
    return merge(rows) + paper_rows()


def _holding(folders: list[Path], pattern: str) -> Path:
    """The first of the folders with a file matching pattern (else the first folder: its evaluator says what is missing)."""
    return next((f for f in folders if any(f.glob(pattern))), folders[0])


def merge(rows: list[Row]) -> list[Row]:
    """One row per (table, method, source): values joined (the first row's value kept where both give one), notes
    joined; order of first appearance."""
    out: dict[tuple[str, str, str], Row] = {}
    for r in rows:
        key = (r.table, r.method, r.source)
        if key not in out:
            out[key] = Row(r.table, r.method, r.source, dict(r.values), r.note)
            continue
        o = out[key]
        o.values = {**r.values, **o.values}
        o.note = "; ".join(n for n in (o.note, r.note) if n)
    return list(out.values())


def update(old: list[Row], new: list[Row]) -> list[Row]:
    """`old` report rows with every row of `new` put in place of the old row of the same (table, method, source)
    (a whole row: values and note); rows only in `new` appended; order of `old`."""
    fresh = {(r.table, r.method, r.source): r for r in new}
    out = [fresh.pop((r.table, r.method, r.source), r) for r in old]
    return out + list(fresh.values())


def reused_rows(shipped: Path, rows_of: Callable[[dict], list[Row]], method: str) -> list[Row]:
    """A method's rows from its shipped evaluation JSON (`--reuse`); ValueError naming the file when it is damaged or
    is not that method's evaluation (a JSON that is no object, or lacks or misshapes what rows_of reads)."""
    import json

    try:
        rows = rows_of(json.loads(shipped.read_text()))
    except (ValueError, KeyError, TypeError, IndexError, AttributeError) as e:
        raise ValueError(f"--reuse: {shipped} is damaged or not {method}'s evaluation ({type(e).__name__}: {e}); "
                         "restore it (git checkout) or run without --reuse") from None
    if not rows:
        raise ValueError(f"--reuse: {shipped} is damaged or not {method}'s evaluation (it holds none of its rows); "
                         "restore it (git checkout) or run without --reuse")
    for r in rows:
        r.note += f" (from {shipped.name})"
    return rows


def _method(checkpoint: Path | tuple[Path, ...], out: Path, rows_of: Callable[[dict], list[Row]],
            run: Callable[[Path], dict], method: str, table: str) -> list[Row]:
    """A method's rows by running its evaluator into `out`; a row naming the file when a checkpoint it loads (one path
    or several) is missing."""
    missing = [c for c in (checkpoint if isinstance(checkpoint, tuple) else (checkpoint,)) if not c.is_file()]
    if missing:
        return [Row(table, method, "graspkit", note=f"checkpoint missing: {missing[0]}")]
    return rows_of(run(out))


# ---------------------------------------------------------------------------------------------------------- report

def _fmt(v: float | None, exact: bool = False) -> str:
    """A table cell: 3 significant figures (`exact`: as published, up to 6, for a paper's figure), '—' for missing."""
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return "—"
    return f"{v:g}" if exact else f"{v:.3g}"


def markdown(rows: list[Row]) -> str:
    """Two markdown tables (grasp, motion); ours first, the papers' rows after, each row with its source."""
    parts = []
    for table, metrics in (("grasp", GRASP_METRICS), ("motion", MOTION_METRICS)):
        sel = sorted([r for r in rows if r.table == table], key=lambda r: r.source != "graspkit")
        cols = [k for k in metrics if any(k in r.values for r in sel)]
        head = "| method | source | " + " | ".join(metrics[k][0] for k in cols) + " | note |"
        lines = [f"### {table} quality", "", head, "|" + "---|" * (len(cols) + 3)]
        for r in sel:
            src = "graspkit (ours)" if r.source == "graspkit" else f"paper: {r.source}"
            cells = " | ".join(_fmt(r.values.get(k), exact=r.source != "graspkit") for k in cols)
            lines.append(f"| {r.method} | {src} | {cells} | {r.note} |")
        parts.append("\n".join(lines))
    return "\n\n".join(parts) + "\n"


def to_csv(rows: list[Row]) -> str:
    """Long-format CSV: table, method, source, metric, value, note."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["table", "method", "source", "metric", "value", "note"])
    for r in rows:
        for k, v in r.values.items():
            w.writerow([r.table, r.method, r.source, k, f"{v:.6g}", r.note])
        if not r.values:
            w.writerow([r.table, r.method, r.source, "", "", r.note])
    return buf.getvalue()


def figure(rows: list[Row]) -> Figure:
    """Bar charts, one panel per metric that any row gives: ours solid, the papers' hatched (where they give one)."""
    import matplotlib.pyplot as plt

    keys = [(t, k) for t, ms in (("grasp", GRASP_METRICS), ("motion", MOTION_METRICS)) for k in ms
            if any(k in r.values for r in rows if r.table == t)]
    ncol = 3                                    # the methods' long names need the width: 4 columns clipped titles
    nrow = max(1, math.ceil(len(keys) / ncol))
    fig, axes = plt.subplots(nrow, ncol, figsize=(16, 3.4 * nrow), squeeze=False, layout="constrained")
    for ax in axes.flat[len(keys):]:
        ax.set_axis_off()
    for ax, (t, k) in zip(axes.flat, keys):
        sel = [r for r in rows if r.table == t and k in r.values]
        names = [f"{r.method}\n({'ours' if r.source == 'graspkit' else r.source})" for r in sel]
        ours = [r.source == "graspkit" for r in sel]
        bars = ax.barh(range(len(sel)), [r.values[k] for r in sel], edgecolor="#333333",
                       color=["#4C72B0" if o else "#DDDDDD" for o in ours])
        for bar, o in zip(bars, ours):
            bar.set_hatch(None if o else "//")
        ax.bar_label(bars, labels=[_fmt(r.values[k]) for r in sel], fontsize=7, padding=2)
        ax.margins(x=0.25)
        ax.set_yticks(range(len(sel)), names, fontsize=7)
        ax.invert_yaxis()
        ax.set_title(f"{t}: " + (GRASP_METRICS | MOTION_METRICS)[k][0], fontsize=9)
        ax.tick_params(axis="x", labelsize=7)
    return fig


def write_report(rows: list[Row], out_dir: str | Path) -> list[Path]:
    """benchmark.md, benchmark.csv and benchmark.png in out_dir (each written atomically); returns the paths."""
    from graspkit.viz.export import save_png, write_atomic

    out = Path(out_dir)
    title = "# graspkit: every method on the same objects and goals\n\n"
    md = write_atomic(out / "benchmark.md", title + markdown(rows))
    cs = write_atomic(out / "benchmark.csv", to_csv(rows))
    png = save_png(figure(rows), out / "benchmark.png", dpi=110)
    return [md, cs, png]


def read_csv(path: str | Path) -> list[Row]:
    """Rows back from a benchmark.csv (the inverse of to_csv)."""
    rows: dict[tuple[str, str, str], Row] = {}
    with open(path, newline="") as f:
        text = f.read()
    if text and not text.endswith("\n"):                 # to_csv ends every line: a copy cut short does not
        raise ValueError(f"path: {path} is cut short (its last line has no end); restore it or run without --update")
    r = csv.DictReader(io.StringIO(text, newline=""))
    if r.fieldnames != ["table", "method", "source", "metric", "value", "note"]:
        raise ValueError(f"path: {path} is not a graspkit benchmark.csv (columns {r.fieldnames})")
    for line in r:
        if None in line or None in line.values():     # DictReader pads a short line with None, keeps extras under None
            raise ValueError(f"path: {path}, line {r.line_num}: expected 6 fields (table, method, source, metric, "
                             "value, note); restore it or run without --update")
        row = rows.setdefault((line["table"], line["method"], line["source"]),
                              Row(line["table"], line["method"], line["source"], note=line["note"]))
        if line["metric"]:
            try:
                row.values[line["metric"]] = float(line["value"])
            except (TypeError, ValueError):
                raise ValueError(f"path: {path}, line {r.line_num}: {line['metric']} is not a number "
                                 f"({line['value']!r})") from None
    return list(rows.values())
