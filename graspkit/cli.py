"""The `graspkit` command: build the body model, run the demo (more subcommands join as the workbook grows)."""
from __future__ import annotations

import argparse
import contextlib
import functools
import math
import os
import sys
import tempfile
import warnings
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, TextIO

from graspkit import __version__

if TYPE_CHECKING:
    from graspkit.objects.placement import ObjectPose


def _cmd_body_build(args: argparse.Namespace) -> int:
    """Build the procedural humanoid and write it atomically."""
    from graspkit.body.procedural import build_procedural_smplx, save_model_npz

    path = save_model_npz(build_procedural_smplx(seed=args.seed), args.out)
    print(f"wrote {path}")
    return 0


def _cmd_body_info(args: argparse.Namespace) -> int:
    """Print what a body-model file holds."""
    bm = _body_model(args.model, build=False)
    out = bm()
    v = out.vertices[0]
    print(bm.extra_repr())
    print(f"faces: {tuple(bm.faces.shape)}; rest-pose extent (m): {(v.max(0).values - v.min(0).values).tolist()}")
    return 0


def _cmd_demo(args: argparse.Namespace) -> int:
    """Run the main job: everything the workbook can show so far, written to --out."""
    from graspkit.body.model import ModelFileError
    from graspkit.demo import run_demo

    stages = tuple(s for s in args.stages.split(",") if s)
    if not stages:
        raise ValueError("--stages: expected one or more stage names separated by commas, got none")
    import torch

    torch.set_num_threads(args.threads)
    try:
        written = run_demo(Path(args.out), model_path=args.model, stages=stages)
    except ModelFileError as e:
        raise ValueError(f"{_model_source(args.model)}: {e}") from None
    for path in written:
        print(f"wrote {path}")
    return 0


def _check_object(obj: str, outputs: str) -> Any:
    """--object's mesh (a catalogue name or a mesh file), read before a pipeline starts so that an error names the
    option; `outputs`: the output files' name with {name} for the object's (a mesh file's stem), which must fit a file
    name."""
    from graspkit.objects.user import as_object

    name, mesh = as_object(obj, "--object")
    longest = outputs.format(name=name) + "_final.glb"
    if len(longest.encode()) > 255:
        raise ValueError(f"--object: {obj}: the outputs' names ({longest[:40]}...) would be {len(longest.encode())} "
                         "bytes, past the file system's 255; give the mesh file a shorter name")
    return mesh


def _scene_objects(name: str, mesh: object) -> dict[str, object]:
    """The exported scene's objects: the object under its name, or 'body_object' for a mesh file named body.*
    (the body mesh has that name)."""
    return {"body_object" if name == "body" else name: mesh}


def _object_pose(at: list[float] | None):
    """--at X Y Z YAW_DEG -> an ObjectPose (None stays None: drawn from --seed); ValueError naming --at."""
    import numpy as np

    from graspkit.objects.placement import ObjectPose

    if at is None:
        return None
    if not all(math.isfinite(v) for v in at):
        raise ValueError(f"--at: expected four finite numbers X Y Z YAW_DEG, got {' '.join(map(str, at))}")
    if at[2] < 0:
        raise ValueError(f"--at: the object's centre is {-at[2]:g} m below the floor (z = 0); expected Z >= 0 m "
                         "(the training grasps hold it 0.5-1.7 m high)")
    if max(abs(at[0]), abs(at[1])) > WANDR_GOAL_LIMIT or at[2] > AT_HEIGHT_LIMIT:
        raise ValueError(f"--at: expected the object within {WANDR_GOAL_LIMIT:g} m of the origin in X and Y and at "
                         f"most {AT_HEIGHT_LIMIT:g} m high (no one reaches higher), got {' '.join(map(str, at))}")
    return ObjectPose.from_yaw(np.deg2rad(at[3]), np.array(at[:3]))


def object_range_notes(pose: ObjectPose | None, mesh: Any = None) -> list[str]:
    """Warnings when an object placed with --at (an ObjectPose, or None: drawn in range) has its centre outside the
    0.5-1.7 m heights of the grasp and approach data the SAGA and GOAL networks were trained on; with the object's
    `mesh`, a ValueError naming --at when the object at that pose sinks into the floor."""
    from graspkit.objects.placement import GRASP_HEIGHTS, floor_note

    if pose is None:
        return []
    note = None if mesh is None else floor_note(pose, mesh)
    if note:
        raise ValueError(f"--at: {note.removeprefix('object_pose: ')}")
    z, (lo, hi) = float(pose.translation[2]), GRASP_HEIGHTS
    if lo <= z <= hi:
        return []
    return [f"the object's centre is {z:.2f} m high, {'below' if z < lo else 'above'} the {lo:g}-{hi:g} m of the "
            "training grasps and approach clips (docs/grasps.md); expect the grasp or the motion to fall short"]


def _print_notes(notes: list[str]) -> None:
    """Each note on stderr as `graspkit: note: ...` (the run goes on)."""
    for note in notes:
        print(f"graspkit: note: {note}", file=sys.stderr)


def _free_joints(names: list[str]) -> tuple[str, ...]:
    """--free-joints -> GraspPoseConfig.free_joints (and GraspMotionConfig's), checked before any work; ValueError
    naming the option."""
    from graspkit.optim.grasppose import BODY_JOINTS, expand_free_joints, valid_body_joints

    joints = expand_free_joints(names)
    if not valid_body_joints(joints):
        raise ValueError(f"--free-joints: expected 'arms', 'none' or distinct body-joint names of {BODY_JOINTS}, "
                         f"got {' '.join(names)}")
    return joints


def _model_source(path: Path | None) -> str:
    """Where a body model path came from, for an error: --model, or the GRASPKIT_MODEL variable."""
    return "--model" if path is not None or not os.environ.get("GRASPKIT_MODEL") else "GRASPKIT_MODEL"


def _body_model(path: Path | None, build: bool = True):
    """The body model of --model (None: $GRASPKIT_MODEL or the shipped humanoid, built if missing when `build`); a
    bad file names where its path came from."""
    from graspkit.body import BodyModel
    from graspkit.body.model import ModelFileError
    from graspkit.demo import load_or_build_body
    from graspkit.paths import default_model_path

    try:
        return load_or_build_body(path) if build else BodyModel.from_file(path or default_model_path())
    except ModelFileError as e:
        raise ValueError(f"{_model_source(path)}: {e}") from None
    except OSError as e:
        raise _os_error(_model_source(path), path or os.environ.get("GRASPKIT_MODEL"), e) from None


def _os_error(flag: str, path: object, e: OSError) -> ValueError:
    """A ValueError naming `flag` and `path` for an OSError of the file system (a name past 255 bytes, say)."""
    return ValueError(f"{flag}: {path}: {e.strerror or e}")


def _cmd_saga(args: argparse.Namespace) -> int:
    """`graspkit saga --object NAME|MESH`: SAGA end to end (object -> grasp -> motion) with the shipped checkpoints."""
    import torch

    from graspkit.demo import _write_clip
    from graspkit.saga import check_checkpoints, synthesize

    mesh = _check_object(args.object, f"saga_{{name}}_s{args.seed}")
    check_checkpoints()                               # before the body, which a plain `pip install` has to build
    pose, free_joints = _object_pose(args.at), _free_joints(args.free_joints)
    _print_notes(object_range_notes(pose, mesh))
    bm = _body_model(args.model)
    torch.set_num_threads(args.threads)
    r = synthesize(args.object, bm, object_pose=pose, seed=args.seed, free_joints=free_joints,
                   hold_start=args.hold_start)
    args.out.mkdir(parents=True, exist_ok=True)
    paths, _ = _write_clip(bm, r.motion, args.out, f"saga_{r.name}_s{args.seed}", _scene_objects(r.name, r.mesh),
                           f"SAGA: {r.name}")
    print(", ".join(f"{k} {v:.3f}" for k, v in r.metrics.items()))
    for path in paths:
        print(f"wrote {path}")
    return 0


def _cmd_goal(args: argparse.Namespace) -> int:
    """`graspkit goal --object NAME|MESH`: GOAL end to end (GNet grasp + refinement, MNet approach)."""
    import torch

    from graspkit.demo import _write_clip
    from graspkit.goal import check_checkpoints, synthesize
    from graspkit.models.mnet import STALL_FRAMES

    mesh = _check_object(args.object, f"goal_{{name}}_s{args.seed}")
    check_checkpoints()                               # before the body, which a plain `pip install` has to build
    check_counts(args, stall=0, max_frames=2)
    pose = _object_pose(args.at)
    _print_notes(object_range_notes(pose, mesh))
    bm = _body_model(args.model)                      # a bad --model fails here, before any work
    torch.set_num_threads(args.threads)
    r = synthesize(args.object, object_pose=pose, seed=args.seed, max_frames=args.max_frames,
                   model=str(args.model) if args.model else None,
                   stall=STALL_FRAMES if args.stall is None else args.stall or None)
    args.out.mkdir(parents=True, exist_ok=True)
    paths, _ = _write_clip(bm, r.motion, args.out, f"goal_{r.name}_s{args.seed}", _scene_objects(r.name, r.mesh),
                           f"GOAL: {r.name}")
    print(f"goal grasp {'reached' if r.reached else 'not reached'} (hand vertices within 1 cm of the goal hand's "
          f"on average) in {r.motion.num_frames} frames; "
          + ", ".join(f"{k} {v:.3f}" for k, v in r.metrics.items()))
    for path in paths:
        print(f"wrote {path}")
    return 0


WANDR_GOAL_LIMIT = 50.0       # m: the farthest goal `graspkit wandr` takes (30 s at 1.5 m/s is 45 m), and --at's X, Y
AT_HEIGHT_LIMIT = 3.0         # m: the highest object centre `graspkit saga/goal --at` takes


def wandr_range_notes(goal: Sequence[float], seconds: float) -> list[str]:
    """graspkit.models.wandr.range_notes for a goal in the start's frame (the pelvis above the origin)."""
    import math

    from graspkit.models.wandr import range_notes

    x, y, z = (float(v) for v in goal)
    return list(range_notes(math.hypot(x, y), z, seconds).values())


def _cmd_wandr(args: argparse.Namespace) -> int:
    """`graspkit wandr --goal X Y Z`: WANDR from its held-out start pose to a goal (start frame) in --seconds."""
    import numpy as np
    import torch
    import trimesh

    from graspkit.benchmark import wandr_motions
    from graspkit.demo import _write_clip
    from graspkit.eval_wandr import FOOT_ON_FLOOR, SUNK_DEPTH
    from graspkit.metrics import floating_share, floor_figures, foot_skating_wandr
    from graspkit.viz.scene import sphere

    if not all(math.isfinite(v) for v in args.goal):
        raise ValueError(f"--goal: expected three finite numbers X Y Z (m), got {' '.join(map(str, args.goal))}")
    if max(abs(v) for v in args.goal) > WANDR_GOAL_LIMIT:
        raise ValueError(f"--goal: expected coordinates within {WANDR_GOAL_LIMIT:g} m of the start, got "
                         f"{' '.join(map(str, args.goal))}")
    if not 0 < args.seconds <= 30:
        raise ValueError(f"--seconds: expected a time to the goal in (0, 30] s, got {args.seconds}")
    frames = int(round(args.seconds * 30.0))
    if frames < 1:
        raise ValueError(f"--seconds: expected at least one frame (1/30 s), got {args.seconds}")
    check_file(args.checkpoint, "--checkpoint", see="docs/wandr.md")
    goal = torch.tensor(args.goal, dtype=torch.float32)
    _print_notes(wandr_range_notes(args.goal, frames / 30.0))
    torch.set_num_threads(args.threads)
    from graspkit.models.wandr import RangeWarning

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RangeWarning)           # printed above, from the goal as given
        bm = _body_model(args.model)                          # the start is stood on it (StartPose.on_body)
        motion = wandr_motions(args.checkpoint, goal[None], frames, seed=args.seed, lift=args.lift, bm=bm)[0]
    sv, sf = sphere(goal.numpy(), 0.05)
    args.out.mkdir(parents=True, exist_ok=True)
    paths, _ = _write_clip(bm, motion, args.out, f"wandr_s{args.seed}",
                           {"goal": trimesh.Trimesh(sv, sf, process=False)},
                           f"WANDR{' (+ lift)' if args.lift else ''}: reach the goal in {frames / 30.0:.2f} s",
                           goals=goal[None].numpy())
    wrist = motion.joint_positions(bm)[:, 21]                   # SMPL-X joint 21: the right wrist
    d = np.linalg.norm(wrist - goal.numpy(), axis=-1)
    print(f"closest right-wrist distance to the goal {d.min() * 100:.1f} cm at {d.argmin() / 30.0:.2f} s "
          f"(t_G {frames / 30.0:.2f} s, frame {frames})")
    v = motion.vertices(bm)
    floor = floor_figures(v)
    sunk = float((v[:, :, 2].amin(1) < -SUNK_DEPTH).double().mean())
    print(f"foot skating (WANDR's FS: the lowest vertex moves > 0.66 cm horizontally) in "
          f"{100 * foot_skating_wandr(v).mean():.1f} % of the frame pairs; the body {floor['floor_deepest_cm']:.1f} cm "
          f"below the floor at the deepest, {100 * sunk:.0f} % of the frames more than 1 cm below it"
          + ("" if args.lift or sunk == 0 else " (without --no-lift the feet are held at the floor)"))
    floating = floating_share(v, height=FOOT_ON_FLOOR)
    print(f"no part of the body within {100 * FOOT_ON_FLOOR:.0f} cm of the floor (floating) in {100 * floating:.0f} % of "
          "the frames")
    for path in paths:
        print(f"wrote {path}")
    return 0


def _cmd_eval_all(args: argparse.Namespace) -> int:
    """`graspkit eval --all`: run the cross-method benchmark and write its report (without --all: usage)."""
    if not args.all:
        raise ValueError("eval: name a model (e.g. `graspkit eval wandr ...`) or pass --all")
    from graspkit.benchmark import METHODS, markdown, read_csv, run_all, update, write_report

    methods = tuple(m.strip() for m in args.methods.split(",") if m.strip())
    unknown = sorted(set(methods) - set(METHODS))
    if not methods or unknown:
        raise ValueError(f"--methods: expected a comma-separated list of {', '.join(METHODS)}, got {args.methods!r}"
                         + (f" (unknown: {', '.join(unknown)})" if unknown else ""))
    if args.update:
        if not (args.out / "benchmark.csv").is_file():
            raise FileNotFoundError(f"--update: no benchmark.csv in --out {args.out} to update")
        read_csv(args.out / "benchmark.csv")           # a damaged one is named before the work
    rows = run_all(args.out, data=args.data, quick=args.quick, methods=methods, reuse=args.reuse)
    from contextlib import nullcontext

    from graspkit.paths import locked

    # --update reads, merges and writes under a lock (`.benchmark.lock` in --out), reading the file again: two updates
    # started together each read it before the other wrote, and the later writer dropped the other's rows
    with locked(args.out / ".benchmark.lock") if args.update else nullcontext():
        if args.update:
            rows = update(read_csv(args.out / "benchmark.csv"), rows)
        print(markdown(rows))
        for path in write_report(rows, args.out):
            print(f"wrote {path}")
    return 0


DATA_HELP = "procedural motion data (graspkit data make --kind ...)"
# every `graspkit train` command's --time-limit
TIME_LIMIT_HELP = ("seconds; stops after the epoch that crosses it, so how far one run gets depends on the machine; "
                   "the same command again resumes towards --epochs")


# The data, train and eval commands' parsers live in modules that import torch and scipy (seconds to load): they are
# registered in full only when the command line names them, so that `graspkit --help` and the other commands' parsers
# come up at once.
def _command_named(argv: list[str] | None) -> str | None:
    """The subcommand on a command line (its first word not starting with '-'), or None."""
    return next((a for a in (sys.argv[1:] if argv is None else argv) if not a.startswith("-")), None)


def build_parser(argv: list[str] | None = None) -> argparse.ArgumentParser:
    """The argument parser of the `graspkit` command for the command line `argv` (None: sys.argv[1:]; the
    subcommands of data, train and eval are only added when argv names that command)."""
    named = _command_named(argv)

    p = argparse.ArgumentParser(prog="graspkit", description="graspkit: whole-body motion synthesis towards "
                                "objects and goals (SAGA, GOAL, WANDR), at workbook scale.")
    p.add_argument("--version", action="version", version=f"graspkit {__version__}")
    p.add_argument("--quiet", action="store_true", dest="quiet_all",   # data make's own --quiet would overwrite `quiet`
                   help="no progress bars or progress lines (before the command: graspkit --quiet train ...; the "
                   "library's switch is the environment's TQDM_DISABLE=1)")
    sub = p.add_subparsers(dest="command", required=True)

    _add_body_commands(sub)
    _add_demo_command(sub)
    _add_method_commands(sub)
    _add_wandr_command(sub)
    if named == "data":
        from graspkit.data.cli import add_data_commands
        add_data_commands(sub)
    else:
        sub.add_parser("data", help=DATA_HELP)

    # `graspkit train <model>`: each model family adds its own subcommands to this parser
    train = sub.add_parser("train", help="train a model of the workbook: wholegrasp, wholegrasp_single, "
                           "grabnet_smplx, pose_prior, motionfill, motionfill_baseline, gnet, mnet, wandr")
    train = train.add_subparsers(dest="train_command", required=True)
    if named == "train":
        from graspkit.eval_goal import add_goal_train_commands
        add_goal_train_commands(train)

    # `graspkit eval <model>`: each model family adds its own evaluation subcommands to this parser;
    # `graspkit eval --all`: every method on the same objects and goals (graspkit.benchmark)
    ev = _add_eval_parser(sub)
    evaluate = ev.add_subparsers(dest="eval_command", required=False)
    if named in ("train", "eval"):
        from graspkit.eval_wandr import add_wandr_commands
        add_wandr_commands(train, evaluate)
    if named == "train":
        from graspkit.eval_saga import add_saga_train_commands
        add_saga_train_commands(train)
        from graspkit.eval_motionfill import add_motionfill_train_commands
        add_motionfill_train_commands(train)
    return p


def _add_body_commands(sub: argparse._SubParsersAction) -> None:
    """`graspkit body build` and `graspkit body info` on the subcommands `sub`."""
    from graspkit.paths import procedural_model_path

    body = sub.add_parser("body", help="the body model").add_subparsers(dest="body_command", required=True)
    b = body.add_parser("build", help="build the procedural SMPL-X-format humanoid")
    b.add_argument("--seed", type=int, default=0)
    b.add_argument("--out", type=Path, default=procedural_model_path(), help="where to write it (default: the "
                   "procedural body's own file, rebuilt in place, never the one GRASPKIT_MODEL names: %(default)s)")
    b.set_defaults(func=_cmd_body_build, out_is_file=True)
    i = body.add_parser("info", help="describe a body-model file")
    i.add_argument("--model", type=Path, default=None, help="default: $GRASPKIT_MODEL, else the procedural humanoid")
    i.set_defaults(func=_cmd_body_info)


def _add_demo_command(sub: argparse._SubParsersAction) -> None:
    """`graspkit demo` (the main job) on the subcommands `sub`."""
    d = sub.add_parser("demo", help="run the main job and write its figures to --out")
    d.add_argument("--out", type=Path, default=Path("outputs/demo"))
    d.add_argument("--model", type=Path, default=None, help="an SMPL-X .npz (default: the procedural humanoid)")
    d.add_argument("--stages", default="body,planner,saga,saga_motion,goal,wandr",
                   help="comma-separated subset of body, planner, saga, saga_motion, goal, wandr")
    d.add_argument("--threads", type=int, default=2, help="torch threads (default 2; another count can move the "
                   "optimised and rolled-out figures in their last digits, or more)")
    d.set_defaults(func=_cmd_demo, out_is_file=False)


def _add_method_commands(sub: argparse._SubParsersAction) -> None:
    """`graspkit saga` and `graspkit goal` (one method end to end for one object) on the subcommands `sub`."""
    for method, cmd, what in (("saga", _cmd_saga, "SAGA end to end for one object: grasp, then the approach "
                               "motion into it"),
                              ("goal", _cmd_goal, "GOAL end to end for one object: GNet's grasp, then MNet's "
                               "approach into it")):
        sg = sub.add_parser(method, help=what)
        sg.add_argument("--object", required=True,
                        help="a catalogue object (graspkit.objects.list_objects()) or a mesh file of one's own "
                             "(closed, metres, z up; .obj, .ply, .stl, .glb)")
        sg.add_argument("--at", type=float, nargs=4, default=None, metavar=("X", "Y", "Z", "YAW_DEG"),
                        help="the object's centre (m; |X|, |Y| <= 50, 0 <= Z <= 3) and yaw (default: drawn from "
                             "--seed)")
        sg.add_argument("--seed", type=int, default=0)
        sg.add_argument("--out", type=Path, default=Path(f"outputs/{method}"))
        sg.add_argument("--model", type=Path, default=None, help="an SMPL-X .npz (default: the procedural humanoid)")
        sg.add_argument("--threads", type=int, default=1,
                        help="torch threads (default 1; another count rounds the optimisers' sums differently, so "
                             "the result can differ from the 1-thread one; the same count repeats it)")
        if method == "saga":
            sg.add_argument("--free-joints", nargs="*", default=["arms"], metavar="JOINT",
                            help="GraspPose-Opt and GraspMotion-Opt: body joints given a free rotation on top of the "
                                 "pose prior ('arms', the default: collars, shoulders, elbows, wrists; 'none': Alg. 1 "
                                 "and 2; docs/saga.md)")
            sg.add_argument("--hold-start", action=argparse.BooleanOptionalAction, default=True,
                            help="GraspMotion-Opt holds frame 0 at the start body, with a heavier planted heel (the "
                                 "default; --no-hold-start: Alg. 2, whose planted feet drag it along the first steps; "
                                 "docs/saga_motion.md)")
        if method == "goal":
            sg.add_argument("--max-frames", type=int, default=150, help="MNet's rollout stops here if not at the grasp")
            sg.add_argument("--stall", type=int, default=None, metavar="FRAMES",
                            help="graspkit's stall rule's window: at each MNet step a hand within 25 cm of the goal hand "
                                 "that is not 5 mm closer than at its closest in this many frames before starts the "
                                 "refinement (default 10; 0: off, GOAL's rollout; docs/goal.md)")
        sg.set_defaults(func=cmd, out_is_file=False)


def _add_wandr_command(sub: argparse._SubParsersAction) -> None:
    """`graspkit wandr` (WANDR from a held-out start to one goal) on the subcommands `sub`."""
    from graspkit.paths import DATA_STUBS

    wa = sub.add_parser("wandr", help="WANDR from its held-out start pose to one goal in a given time")
    wa.add_argument("--goal", type=float, nargs=3, required=True, metavar=("X", "Y", "Z"),
                    help="the goal (m) in the start's frame: pelvis above the origin, facing +x, floor z = 0")
    wa.add_argument("--seconds", type=float, default=4.0, help="time to the goal, t_G (default 4)")
    wa.add_argument("--seed", type=int, default=0)
    wa.add_argument("--lift", action=argparse.BooleanOptionalAction, default=True,
                    help="raise the body back to the floor whenever its lowest foot joint sinks below its start height "
                         "(graspkit's, on by default; --no-lift: WANDR's own rollout, which sinks; docs/wandr.md)")
    wa.add_argument("--checkpoint", type=Path, default=DATA_STUBS / "checkpoints" / "wandr.pt")
    wa.add_argument("--out", type=Path, default=Path("outputs/wandr"))
    wa.add_argument("--model", type=Path, default=None, help="an SMPL-X .npz to move and draw (default: the "
                    "procedural humanoid, which WANDR was trained on; another body starts from the same pose, standing "
                    "where it stood)")
    wa.add_argument("--threads", type=int, default=1, help="torch threads (default 1; another count can move the "
                    "rollout in its last digits)")
    wa.set_defaults(func=_cmd_wandr, out_is_file=False)


def _add_eval_parser(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """`graspkit eval` with its --all options (the cross-method benchmark) on the subcommands `sub`; returns its
    parser (the methods add their `eval` subcommands to it)."""
    ev = sub.add_parser("eval", help="evaluate WANDR's goal grid (eval wandr), or every method with --all")
    ev.add_argument("--all", action="store_true", help="the cross-method benchmark (table, CSV and figure in --out)")
    ev.add_argument("--out", type=Path, default=Path("outputs/benchmark"), help="folder for --all's report")
    ev.add_argument("--quick", action="store_true",
                    help="with --all: a few samples per method (about 6 CPU minutes; 10.5 on a busy 2-core machine)")
    ev.add_argument("--data", type=Path, action="append", default=None,
                    help="with --all: a folder of grasp_*/approach_*.npz files (repeatable; default: made "
                         "sets or stubs)")
    ev.add_argument("--methods", default="gt,saga,saga_motion,goal,wandr,motion",
                    help="with --all: comma-separated subset of gt, saga, saga_motion, goal, wandr, motion")
    ev.add_argument("--reuse", action="store_true",
                    help="with --all: take each method's shipped evaluation (data_stubs/checkpoints/*_eval.json)")
    ev.add_argument("--update", action="store_true",
                    help="with --all: keep --out's benchmark.csv and replace only the rows the --methods make (a "
                         "row whole: run together the methods that fill one row, e.g. saga_motion,motion)")
    ev.set_defaults(func=_cmd_eval_all, out_is_file=False)       # --all's --out is a folder, whatever its name
    return ev


FILE_SUFFIXES = (".npz", ".pt", ".json", ".csv")      # an --out with one of these names a file, otherwise a folder


def check_out(path: Path, is_file: bool | None = None, flag: str = "--out") -> None:
    """Before any work: `path` (a file when is_file, a folder when not; None: a file if its suffix is in
    FILE_SUFFIXES) can be written, i.e. it is not the other kind of thing and its nearest existing ancestor is a
    writable folder; ValueError naming `flag` (also for a path the system refuses to look at: a name past 255 bytes)."""
    try:
        _check_out(Path(path), is_file, flag)
    except OSError as e:
        raise _os_error(flag, path, e) from None


def _check_out(path: Path, is_file: bool | None, flag: str) -> None:
    """check_out's checks (an OSError of the file system passes)."""
    is_file = path.suffix in FILE_SUFFIXES if is_file is None else is_file
    if is_file and path.is_symlink():                  # written through (paths.writes_to): check where it leads
        target = Path(os.path.realpath(path))
        if not target.exists() and not target.parent.is_dir():
            raise ValueError(f"{flag}: {path} is a symbolic link to {os.readlink(path)}, whose folder does not exist")
        if target != path:
            check_out(target, True, f"{flag} {path} -> {target}")          # names what the user gave
            return
    if is_file and path.is_dir():
        raise ValueError(f"{flag}: {path} is a folder; expected a file path" + (f" ending in {path.suffix}"
                                                                                 if path.suffix else ""))
    if not is_file and path.exists() and not path.is_dir():
        raise ValueError(f"{flag}: {path} is a file; expected a folder")
    for p in (path.parent if is_file else path, *(path.parent if is_file else path).parents):
        if p.is_symlink() and not p.exists():           # exists() follows the link: mkdir would say "File exists"
            raise ValueError(f"{flag}: {p} is a symbolic link to {os.readlink(p)}, which does not exist")
        if p.exists():
            if not p.is_dir():
                raise ValueError(f"{flag}: {p} is a file, so {path} cannot be written")
            made = "" if p == path else f", so {path} cannot be made"      # the path may be a default not typed
            if not os.access(p, os.W_OK | os.X_OK):
                raise ValueError(f"{flag}: {p} is not writable{made}")
            try:                        # os.access says yes to root everywhere, also in /proc and /sys: try it
                with tempfile.TemporaryFile(dir=p):
                    pass
            except OSError as e:
                raise ValueError(f"{flag}: {p} is not writable ({e.strerror}){made}") from None
            return


def check_cache() -> None:
    """Before any work: graspkit's cache folder (`paths.cache_dir()`) can be written; ValueError naming
    GRASPKIT_CACHE."""
    from graspkit.paths import cache_dir

    unset = not os.environ.get("GRASPKIT_CACHE")
    flag = f"graspkit's cache {cache_dir()} (the default: GRASPKIT_CACHE is not set)" if unset else "GRASPKIT_CACHE"
    try:
        check_out(cache_dir(), is_file=False, flag=flag)
    except ValueError as e:
        raise ValueError(f"{e} (set GRASPKIT_CACHE to a writable folder)") from None


def check_train_out(out: Path | None) -> None:
    """Before training (or python -m graspkit.eval_saga): an --out in data_stubs/checkpoints (None: the default there)
    needs the data_stubs/ of a clone (a plain `pip install` has none, and graspkit does not write in its package
    folder) that can be written; ValueError naming --out."""
    from graspkit.paths import DATA_STUBS, shipped

    if out is not None and not Path(out).resolve().is_relative_to(DATA_STUBS.resolve()):
        return
    if not shipped():
        raise ValueError(f"--out: required here: the default, {DATA_STUBS / 'checkpoints'}, is data_stubs/ of a clone "
                         "of graspkit's repository (installed with `pip install -e .`), and this graspkit has none")
    if out is None:
        check_out(DATA_STUBS / "checkpoints", is_file=False, flag="--out (default: data_stubs/checkpoints)")


def check_counts(args: argparse.Namespace, **least: int) -> None:
    """ValueError naming the flag unless each parsed count args.<name> (when given) is at least `least[name]`."""
    for name, low in least.items():
        v = getattr(args, name, None)
        if v is not None and v < low:
            raise ValueError(f"--{name.replace('_', '-')}: expected an integer >= {low}, got {v}")


def check_folders(paths: Path | list[Path] | None, flag: str = "--data") -> None:
    """FileNotFoundError naming `flag` unless each of `paths` (one, a list, or None: nothing to check) is a folder."""
    for d in paths if isinstance(paths, list) else [] if paths is None else [paths]:
        try:
            found = Path(d).is_dir()
        except OSError as e:
            raise _os_error(flag, d, e) from None
        if not found:
            what = "is a file, expected a folder" if Path(d).exists() else "no such folder"
            raise FileNotFoundError(f"{flag}: {d}: {what} (make the data with `graspkit data make`, docs/data.md)")


def check_file(path: Path, flag: str, what: str = "a checkpoint file", see: str = "") -> None:
    """FileNotFoundError naming `flag` unless `path` is a file (`what` it should be; `see`: where to read on), with
    a word on data_stubs/ when a shipped file is missing because graspkit runs without its repository."""
    from graspkit.paths import stub_hint

    path = Path(path)
    try:
        found = path.is_file()
    except OSError as e:
        raise _os_error(flag, path, e) from None
    if not found:
        problem = f"is a folder, expected {what}" if path.is_dir() else "is missing"
        raise FileNotFoundError(f"{flag}: {path} {problem}" + (f" (see {see})" if see else "") + stub_hint(path))


@contextlib.contextmanager
def as_flags(**flags: str) -> Iterator[None]:
    """Re-raise a ValueError or OSError whose message starts with `name:` for a name in `flags` (a library function's
    parameter) as `flag:` (the command-line flag it came from), so that the error names what the user typed."""
    try:
        yield
    except (ValueError, OSError) as e:
        msg = str(e)
        for name, flag in flags.items():
            if msg.startswith(f"{name}:"):
                raise type(e)(flag + msg[len(name):]) from None
        raise


def reports_errors(prog: str) -> Callable[[Callable[..., int]], Callable[..., int]]:
    """Decorate a module's `main(argv)` so that a bad input (ValueError, OSError) ends as the graspkit command's do:
    `<prog>: error: <message>` on stderr and exit status 2, no traceback; Ctrl-C as one line and exit status 130;
    graspkit's warnings as `<prog>: note: ...` lines."""
    def wrap(main: Callable[..., int]) -> Callable[..., int]:
        @functools.wraps(main)
        def run(argv: list[str] | None = None) -> int:
            try:
                with notes(prog):
                    return int(main(argv) or 0)
            except (ValueError, OSError) as e:
                print(f"{prog}: error: {e}", file=sys.stderr)
                return 2
            except KeyboardInterrupt:
                print(f"\n{prog}: interrupted", file=sys.stderr)
                return 130
        return run
    return wrap


def print_run_logs() -> None:
    """After `graspkit train`: where each training state that graspkit.train.fit wrote keeps its log and loss plot
    (a run stopped part-way resumes from that state when the same command is run again)."""
    from graspkit.train import RUNS

    for run in RUNS:
        print(f"training state {run}; per-epoch log {run.with_suffix('.csv').name}, loss plot "
              f"{run.with_suffix('.png').name} beside it")


@contextlib.contextmanager
def notes(prog: str) -> Iterator[None]:
    """graspkit's own warnings shown as `<prog>: note: ...` lines on stderr while the block runs (others as Python
    shows them)."""
    with warnings.catch_warnings():
        shown = warnings.showwarning

        def note(message: Warning | str, category: type[Warning], filename: str, lineno: int,
                 file: TextIO | None = None, line: str | None = None) -> None:
            from graspkit.checks import GraspkitWarning     # here: `graspkit --help` loads no torch

            if issubclass(category, GraspkitWarning):     # they point at the caller's line, outside graspkit
                print(f"{prog}: note: {message}", file=sys.stderr)
            else:
                shown(message, category, filename, lineno, file, line)

        warnings.showwarning = note
        yield


def main(argv: list[str] | None = None) -> int:
    """Entry point of the `graspkit` console command (graspkit's own warnings show as `graspkit: note: ...` lines)."""
    with notes("graspkit"):
        return _main(argv)


@contextlib.contextmanager
def _quiet(on: bool) -> Iterator[None]:
    """TQDM_DISABLE=1 while a command runs (graspkit.progress: every bar and progress line off), as it was after."""
    from graspkit.progress import QUIET_ENV

    if not on:
        yield
        return
    old = os.environ.get(QUIET_ENV)
    os.environ[QUIET_ENV] = "1"
    try:
        yield
    finally:
        if old is None:
            os.environ.pop(QUIET_ENV, None)
        else:
            os.environ[QUIET_ENV] = old


def _main(argv: list[str] | None) -> int:
    """`main` with graspkit's warnings shown as notes."""
    try:
        parser = build_parser(argv)          # defaults read GRASPKIT_CACHE / GRASPKIT_MODEL
    except ValueError as e:
        print(f"graspkit: error: {e}", file=sys.stderr)
        return 2
    args = parser.parse_args(argv)
    if getattr(args, "out_is_file", False):
        try:
            refuse_folder_out(argv)
        except ValueError as e:
            print(f"graspkit: error: {e}", file=sys.stderr)
            return 2
    with _quiet(args.quiet_all):
        return _run(args)


def refuse_folder_out(argv: list[str] | None) -> None:
    """ValueError naming --out when the command line `argv` (None: sys.argv[1:]) types it with a trailing separator
    for a command that writes one file: argparse's Path drops the '/', and `--out newdir/` became a file newdir."""
    argv = sys.argv[1:] if argv is None else argv
    typed = ""
    for i, a in enumerate(argv):             # --out, --out=X and argparse's abbreviations (--ou X, --ou=X)
        key, eq, value = a.partition("=")
        if len(key) >= 3 and "--out".startswith(key):
            typed = value if eq else (argv[i + 1] if i + 1 < len(argv) else "")
    if typed.endswith(("/", os.sep)):
        raise ValueError(f"--out: {typed} names a folder; this command writes one file: expected its path")


def expand_user_paths(args: argparse.Namespace) -> None:
    """`~` and `~user` expanded in every path argument, as in GRASPKIT_CACHE: `--out=~/x` (the shell leaves a `~`
    after `=` alone) wrote into a folder named `~` in the working folder."""
    from graspkit.paths import expand_home

    def expand(p: Any, name: str) -> Any:
        if not isinstance(p, Path):
            return p
        try:
            return expand_home(p)
        except RuntimeError as e:
            raise ValueError(f"--{name.replace('_', '-')}: {p}: {e}") from None

    for name, value in vars(args).items():
        setattr(args, name, [expand(v, name) for v in value] if isinstance(value, list) else expand(value, name))


def _run(args: argparse.Namespace) -> int:
    """Run a parsed command: its checks, then its function; errors and Ctrl-C as one line and an exit status."""
    try:
        expand_user_paths(args)
        if getattr(args, "seed", None) is not None and not 0 <= args.seed < 2**63:
            raise ValueError(f"--seed: expected a non-negative integer below 2^63, got {args.seed}")
        check_counts(args, **dict.fromkeys(("threads", "epochs", "batch_size", "workers", "n", "chunk"), 1))
        check_folders(getattr(args, "data", None))   # every command's --data names a folder (or several)
        if args.command == "train":
            check_train_out(args.out)
        if getattr(args, "out", None) is not None:
            check_out(args.out, getattr(args, "out_is_file", None))
        if args.command == "train" or (args.command == "data" and getattr(args, "data_command", None) == "make"
                                       and args.out is None):
            check_cache()                               # training states and default data folders live there
        if args.command == "train":
            from graspkit.train import RUNS
            RUNS.clear()
        rc = int(args.func(args) or 0)
        if args.command == "train":
            print_run_logs()
        return rc
    except (ValueError, OSError) as e:      # OSError: FileNotFoundError, a folder that cannot be written, ...
        print(f"graspkit: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        # a new line first: a progress bar's line is still open
        print("\ngraspkit: interrupted (data make and train pick up where they stopped when run again)", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
