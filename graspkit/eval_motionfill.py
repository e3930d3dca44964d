"""MotionFill-VAE's training and evaluation on the procedural clips (SAGA §3.3, App. A.3-A.4, §4.2 Tab. 3).

Training follows A.4 in three runs (each one `graspkit train motionfill --stage ...`, two CPU threads, about a minute):

1. `local`: LocalMotionFill alone on locomotion windows (AMASS stand-in, `graspkit data make --kind locomotion`),
   62-frame windows every 30 frames, ground-truth root velocities in the condition image;
2. `traj`: TrajFill alone on approach windows (`graspkit data make --kind approach`): one window per accepted clip,
   ending at its goal frame (the first frame of the held grasp is frame T), GRAB's object split (test objects held
   out, `graspkit.data.grasp.SPLITS`);
3. `finetune`: both CVAEs on the approach windows, LocalMotionFill conditioned on TrajFill's trajectories.

Tab. 3's deterministic baselines (CNN-AE, PoseNet, RouteNet: graspkit.models.motionfill_baselines) train with
`graspkit train motionfill_baseline --model {cnn_ae,posenet,routenet}` (`train_baseline`, on the same windows) and
join `evaluate` through `load_baselines()`.

Tab. 3 (`python -m graspkit.eval_motionfill tab3`), GraspMotion-Opt's evaluation on the first two approach clips of
each test object (`... graspmotion`) and lesson 06's worked example (`... example`) are written next to the checkpoint.

Windows are cached in `<cache>/motionfill/`; normalisation statistics come from stage 1's training windows and stay
with the model. The shipped checkpoint (`data_stubs/checkpoints/motionfill.pt`) holds float16 weights.
"""
from __future__ import annotations

import argparse
import functools
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import torch

from graspkit.checks import positive_float
from graspkit.cli import TIME_LIMIT_HELP, check_counts, check_out, expand_user_paths, refuse_folder_out, reports_errors
from graspkit.data.formats import clip_files
from graspkit.data.motionfill_dataset import (MotionFillDataset, MotionFillStats, load_windows, make_windows,
                                              save_windows, split_clips)
from graspkit.models.motionfill import MotionFillConfig, MotionFillVAE
from graspkit.paths import read_cache, stub_hint
from graspkit.state import keeps_torch_state
from graspkit.train import load_checkpoint

if TYPE_CHECKING:
    from graspkit.body import BodyModel

CHECKPOINT = Path(__file__).resolve().parent.parent / "data_stubs" / "checkpoints" / "motionfill.pt"
STAGES = {"local": ("locomotion", ("local",), "truth"), "traj": ("approach", ("traj",), "truth"),
          "finetune": ("approach", ("traj", "local"), "predicted")}
DEFAULT_CLIPS = {"locomotion": 160, "reach": 600, "approach": 144}


def approach_motions(root: str | Path, n: int | None = None, bm: BodyModel | None = None) -> tuple[list, list[str]]:
    """The first n approach-and-grasp clips in root (graspkit data make --kind approach: `clip_files`) as Motions
    cut at the goal frame (the grasp is frame T of the window), and their object names; accepted grasps only. With
    the body model `bm` they will be posed on, clips made on another body are refused (`grab.check_made_on`)."""
    from graspkit.data.grab import check_made_on
    from graspkit.data.grasp import file_split
    from graspkit.data.motion import Motion

    files = clip_files(root, "approach")[:n]
    if bm is not None:
        check_made_on(bm, files, f"data: {root}", "approach")
    motions, names = [], []
    for f in files:
        a = _approach_arrays(f, WINDOW_KEYS)
        if "grasp.accepted" in a and not bool(a["grasp.accepted"]):
            continue
        g = int(a["grasp.goal_frame"])
        motions.append(Motion(a["body.params.fullpose"][:g + 1].reshape(-1, 55, 3), a["body.params.transl"][:g + 1],
                              a["body.betas"], 30.0, contacts=a["contact.feet"][:g + 1].astype(bool)))
        names.append(str(a["obj_name"]))
        file_split(names[-1], f)                       # the windows' split is by object: a foreign name is f's error
    return motions, names


WINDOW_KEYS = ("obj_name", "body.params.fullpose", "body.params.transl", "body.betas", "grasp.goal_frame",
               "contact.feet")   # what approach_motions reads of a clip (approach_scene reads APPROACH_KEYS)


def _approach_arrays(path: Path, keys: tuple[str, ...]) -> dict[str, np.ndarray]:
    """An approach clip's arrays `keys` (and 'grasp.accepted' where the file has it), checked by check_arrays: a
    ValueError naming the file for a damaged one, a missing key, NaN or a goal frame outside the clip."""
    from graspkit.data.formats import npz_arrays, open_npz
    from graspkit.data.grasp_datasets import check_arrays

    with open_npz(path, "an approach clip (graspkit data make --kind approach)") as z:
        a = npz_arrays(z, [k for k in (*keys, "grasp.accepted") if k in z.files], path)
    check_arrays(a, keys, path)
    return a


# The window code's version, part of every cached window set's name: raise it when make_windows (or what `windows`
# does with the clips) would give other arrays for the same clips and body.
WINDOWS_VERSION = 1


def default_body_digest() -> str:
    """BodyModel.digest() of graspkit's default body model (the file default_model_path() names now: GRASPKIT_MODEL
    may change within a process; each file is loaded once)."""
    from graspkit.body import shared_body

    return _digest(shared_body())


@functools.lru_cache(maxsize=2)
def _digest(bm: BodyModel) -> str:
    """bm.digest() once per shared body (hashing every array takes ~0.1 s)."""
    return bm.digest()


def windows_source(kind: str, n: int, data: Path | None = None, body: str | None = None
                   ) -> tuple[Path, Path, list[Path]]:
    """(cache file, clip folder, the first `n` clip files) of a window set; the cache file is named by the clips'
    names, sizes and member CRC-32s (a clip rewritten at the same size is new data), the body model's digest (`body`,
    BodyModel.digest(); None: the default model's) and WINDOWS_VERSION, so remade or other clips, another body or
    another window code never read another set's windows."""
    import hashlib

    from graspkit.data.formats import member_crcs
    from graspkit.paths import cache_dir

    if kind not in ("locomotion", "reach", "approach"):
        raise ValueError(f"kind: expected 'locomotion', 'reach' or 'approach', got {kind!r}")
    if n < 1:
        raise ValueError(f"n: expected a number of clips >= 1, got {n!r}")
    sub = ("grasps", "approach") if kind == "approach" else ("motion", kind)
    root = Path(data) if data else cache_dir().joinpath(*sub)
    if not root.is_dir():
        raise FileNotFoundError(f"data: no folder {root} (graspkit data make --kind {kind} --out {root})")
    files = clip_files(root, kind)[:n]
    if len(files) < n:
        raise FileNotFoundError(f"data: {root} holds {len(files)} {kind} clips, {n} wanted "
                                f"(graspkit data make --kind {kind} --n {n})")
    listing = "\n".join(f"{f.name}:{f.stat().st_size}:{member_crcs(f)}" for f in files)
    stamp = f"\nbody={body or default_body_digest()};version={WINDOWS_VERSION}"
    key = hashlib.blake2b((listing + stamp).encode(), digest_size=5).hexdigest()
    return cache_dir() / "motionfill" / f"{kind}_{n}_{key}.npz", root, files


def windows(kind: str, n: int, bm: BodyModel | None = None, data: Path | None = None,
            progress: bool = True) -> dict[str, np.ndarray]:
    """Cached windows of the first `n` clips of a procedural set: 'locomotion' (every 30 frames) or 'reach' (one window
    per clip, ending at its goal frame: the wrist on the target, as an approach clip ends at the grasp). Clips made on
    another body than bm (None: graspkit's default) are refused (`made_on.check_clips_made_on`, `grab.check_made_on`)."""
    from graspkit.data import load_motion

    if bm is None:
        from graspkit.body import BodyModel
        from graspkit.paths import default_model_path

        bm = BodyModel.from_file(default_model_path())
    out, root, files = windows_source(kind, n, data, bm.digest())
    # their poses are posed on bm; checked before the cache too (one written before the check answers any body)
    if kind == "approach":
        from graspkit.data.grab import check_made_on

        check_made_on(bm, files, f"data: {root}", kind)
    else:
        from graspkit.data.made_on import check_clips_made_on

        check_clips_made_on(bm, files, f"data: {root}", kind)
    cached = read_cache(out, load_windows)
    if cached is not None:
        return cached
    names = None
    if kind == "approach":
        motions, names = approach_motions(root, n)                         # (checked above)
    else:
        motions = [load_motion(f) for f in files]
    if kind == "reach":
        motions = [m.slice(0, m.goal_frame + 1) for m in motions]
    arr = make_windows(motions, bm, stride=30, align_end=kind != "locomotion", progress=progress)
    if names is not None:                      # GRAB's object split (graspkit.data.grasp.SPLITS): 0 train, 1 val, 2 test
        from graspkit.data.grasp import split_of

        arr["split"] = np.array([("train", "val", "test").index(split_of(names[c])) for c in arr["clip"]], np.int64)
    save_windows(out, arr)                     # (its folder made there; an unwritable cache named)
    return arr


def clip_split(arr: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Clip ids per split: by object for approach windows (GRAB's test objects held out), else `split_clips`."""
    if "split" in arr:
        return {k: np.unique(arr["clip"][arr["split"] == i]) for i, k in enumerate(("train", "val", "test"))}
    return split_clips(int(arr["clip"].max()) + 1, seed=0)


def shipped_state(model: MotionFillVAE) -> dict[str, Any]:
    """Weights in float16 (buffers and integers kept) and the config: the shipped checkpoint."""
    st = model.state()
    st["model"] = {k: v.half() if v.is_floating_point() and "mean" not in k and "std" not in k else v
                   for k, v in st["model"].items()}
    return st


@keeps_torch_state
def load_motionfill(path: str | Path = CHECKPOINT) -> MotionFillVAE:
    """A trained MotionFill-VAE (eval mode) from a shipped or a run checkpoint (weights_only)."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"path: no MotionFill checkpoint at {path} (graspkit train motionfill)")
    state = load_checkpoint(path)                       # its errors name the file already
    try:
        return MotionFillVAE.from_state(state)
    except ValueError as e:
        raise ValueError(f"checkpoint {path}: {str(e).removeprefix('state: ')}") from None


@keeps_torch_state
def train_stage(stage: str, epochs: int, out: Path, init: Path | None = None, seed: int = 0,
                time_limit_s: float | None = 540.0, clips: dict[str, int] | None = None, batch_size: int = 32,
                lr: float = 1e-3, progress: bool = True, data: Path | None = None, reduction: str | None = None,
                local_arch: str | None = None) -> tuple[MotionFillVAE, list[dict[str, float]]]:
    """One of A.4's training runs (`STAGES`); starts from `init` (a checkpoint) when given; writes `out` (shipped
    float16 state) and a resumable run checkpoint beside it in the cache. `reduction` sets the loss's
    (`MotionFillConfig.reduction`; default: the init checkpoint's, else the config's); `local_arch` LocalMotionFill's
    network for a new model ("temporal" or "image", `MotionFillConfig.local_arch`; with `init`, the checkpoint's)."""
    from graspkit.train import TrainConfig, file_key, fit, run_path

    if stage not in STAGES:
        raise ValueError(f"stage: expected one of {list(STAGES)}, got {stage!r}")
    kind, parts, trajectory = STAGES[stage]
    clips = {**DEFAULT_CLIPS, **(clips or {})}
    arr = windows(kind, clips[kind], data=data, progress=progress)
    split = clip_split(arr)
    torch.manual_seed(seed)
    if init is not None:
        model = load_motionfill(init).train()
        if local_arch is not None and local_arch != model.cfg.local_arch:
            raise ValueError(f"local_arch: {local_arch!r} differs from the --init checkpoint's "
                             f"{model.cfg.local_arch!r} ({init})")
        if reduction is not None:
            model.cfg.reduction = reduction
    else:
        given = {"reduction": reduction, "local_arch": local_arch}
        model = MotionFillVAE(MotionFillConfig(**{k: v for k, v in given.items() if v is not None}))
        model.set_stats(MotionFillStats.fit({k: arr[k][np.isin(arr["clip"], split["train"])]
                                             for k in ("local", "vel")}))
    stats = MotionFillStats(model.marker_mean.clone(), model.marker_std.clone(), model.vel_mean.clone(),
                            model.vel_std.clone())
    train, val = MotionFillDataset(arr, stats, split["train"]), MotionFillDataset(arr, stats, split["val"])
    if stage == "traj":                     # the pretrained LocalMotionFill stays as it is
        for p in model.local.parameters():
            p.requires_grad_(False)

    def step(net: MotionFillVAE, batch: dict[str, torch.Tensor], epoch: int) -> dict[str, torch.Tensor]:
        """Eq. 8-9 on the stage's parts."""
        return net.loss(batch, parts=parts, trajectory=trajectory)

    if len(train) == 0:
        raise ValueError(f"data: no training windows among the {kind} clips (split by object: {sorted(split)})")
    tag = "" if model.cfg.reduction == "mean" else f"_{model.cfg.reduction}"
    run = run_path(f"motionfill_{stage}{tag}", seed, epochs=epochs, lr=lr, batch_size=batch_size,
                   windows=windows_source(kind, clips[kind], data)[0].name, init=file_key(init),
                   config=model.state()["model_config"])
    cfg = TrainConfig(epochs=epochs, batch_size=batch_size, lr=lr, seed=seed)
    history = fit(model, step, train, cfg, checkpoint=run, val_dataset=val if len(val) else None, progress=progress,
                  time_limit_s=time_limit_s, extra={"model_config": model.state()["model_config"]},
                  ddp=False)                                                       # the step calls net.loss
    for p in model.parameters():
        p.requires_grad_(True)
    from graspkit.train import save_checkpoint

    save_checkpoint(out, shipped_state(model.eval()))
    return model, history


BASELINE_DIR = CHECKPOINT.parent
BASELINE_DATA = {"cnn_ae": ("locomotion", "approach"), "posenet": ("locomotion", "approach"), "routenet": ("approach",)}


def baseline_path(name: str, folder: str | Path = BASELINE_DIR) -> Path:
    """Where a Tab. 3 baseline's checkpoint lives: <folder>/motionfill_<name>.pt."""
    return Path(folder) / f"motionfill_{name}.pt"


@keeps_torch_state
def train_baseline(name: str, epochs: int, out: Path | None = None, seed: int = 0, time_limit_s: float | None = 300.0,
                   lr: float = 1e-3, batch_size: int = 32, clips: dict[str, int] | None = None,
                   stats_from: Path | None = CHECKPOINT, data: Path | None = None, progress: bool = True
                   ) -> tuple[Any, list[dict[str, float]]]:
    """Train one of Tab. 3's deterministic baselines (graspkit.models.motionfill_baselines: 'cnn_ae', 'posenet',
    'routenet') through `graspkit.train.fit` on the training splits of `BASELINE_DATA[name]`'s windows (locomotion
    and approach for the local infillers, with ground-truth root velocities; approach for RouteNet; GRAB's object
    split); normalisation statistics from MotionFill-VAE's checkpoint `stats_from` (else fitted on these training
    windows). Writes `out` (float16 weights) and a resumable run checkpoint + CSV log in the cache."""
    from torch.utils.data import ConcatDataset

    from graspkit.models.motionfill_baselines import BASELINES
    from graspkit.train import TrainConfig, file_key, fit, run_path, save_checkpoint

    if name not in BASELINES:
        raise ValueError(f"name: expected one of {sorted(BASELINES)}, got {name!r}")
    clips = {**DEFAULT_CLIPS, **(clips or {})}
    keys = ("traj", "markers", "local", "vel", "contacts", "clip")
    sets = {kind: windows(kind, clips[kind], data=data if kind == "approach" else None, progress=progress)
            for kind in BASELINE_DATA[name]}
    splits = {kind: clip_split(arr) for kind, arr in sets.items()}
    torch.manual_seed(seed)
    model = BASELINES[name]()
    if stats_from is not None and Path(stats_from).is_file():
        model.set_stats(load_motionfill(stats_from))
    else:
        fit_on = {k: np.concatenate([arr[k][np.isin(arr["clip"], splits[kind]["train"])] for kind, arr in sets.items()])
                  for k in ("local", "vel")}
        model.set_stats(MotionFillStats.fit(fit_on))
    stats = MotionFillStats(model.marker_mean.clone(), model.marker_std.clone(), model.vel_mean.clone(),
                            model.vel_std.clone())
    part = {s: [MotionFillDataset({k: arr[k] for k in keys}, stats, splits[kind][s]) for kind, arr in sets.items()]
            for s in ("train", "val")}
    train, val = ConcatDataset(part["train"]), ConcatDataset(part["val"])
    if len(train) == 0:
        raise ValueError(f"data: no training windows among the {list(sets)} clips")

    def step(net: Any, batch: dict[str, torch.Tensor], epoch: int) -> dict[str, torch.Tensor]:
        """Eq. 8's deterministic terms (motionfill_baselines' module docstring)."""
        return net.loss(batch)

    out = Path(out) if out is not None else baseline_path(name)
    run = run_path(f"motionfill_{name}", seed, epochs=epochs, lr=lr, batch_size=batch_size,
                   windows=[windows_source(k, clips[k], data if k == "approach" else None)[0].name for k in sets],
                   stats=file_key(stats_from), config=model.config())
    cfg = TrainConfig(epochs=epochs, batch_size=batch_size, lr=lr, seed=seed)
    history = fit(model, step, train, cfg, checkpoint=run, val_dataset=val if len(val) else None, progress=progress,
                  time_limit_s=time_limit_s, extra={"model_config": model.config(), "kind": name},
                  ddp=False)                                                       # the step calls net.loss
    st = model.eval().state()
    st["model"] = {k: v.half() if v.is_floating_point() and "mean" not in k and "std" not in k else v
                   for k, v in st["model"].items()}
    save_checkpoint(out, st)
    return model, history


@keeps_torch_state
def load_baselines(folder: str | Path = BASELINE_DIR) -> dict[str, Any]:
    """Tab. 3's trained baselines {cnn_ae, posenet, routenet} from <folder>/motionfill_<name>.pt (weights_only);
    missing files are left out."""
    from graspkit.models.motionfill_baselines import BASELINES, baseline_from_state
    from graspkit.train import build_named

    out = {}
    for name in BASELINES:
        path = baseline_path(name, folder)
        if path.is_file():
            state = load_checkpoint(path)
            out[name] = build_named(path, f"a MotionFill {name} baseline", lambda: baseline_from_state(state))
    return out


def add_motionfill_train_commands(train_sub: argparse._SubParsersAction) -> None:
    """`graspkit train motionfill --stage {local,traj,finetune}` (A.4's three runs)."""
    p = train_sub.add_parser("motionfill", help="train SAGA's MotionFill-VAE (§3.3), one A.4 stage per run")
    p.add_argument("--stage", choices=list(STAGES) + ["smooth_ae"], required=True,
                   help="smooth_ae: GraspMotion-Opt's marker-difference autoencoder (S.1) on both window sets")
    p.add_argument("--init", type=Path, default=None, help="start from this checkpoint (stages traj, finetune)")
    p.add_argument("--out", type=Path, default=CHECKPOINT)
    p.add_argument("--epochs", type=int, default=20)
    p.add_argument("--clips", type=int, default=None, help="clips of the stage's set (default 160 locomotion, "
                   "144 approach)")
    p.add_argument("--data", type=Path, default=None, help="folder of the stage's clips (default: the cache's "
                   "motion/locomotion or grasps/approach)")
    p.add_argument("--lr", type=positive_float, default=None, help="default 1e-3 (not with --stage smooth_ae)")
    p.add_argument("--time-limit", type=positive_float, default=None,
                   help=TIME_LIMIT_HELP + " (default 540; not with --stage smooth_ae)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--reduction", choices=["sum", "mean"], default=None,
                   help="Eq. 8-9's reduction: mean (the authors' code) or sum (as printed); "
                   "default: --init's, else mean")
    p.add_argument("--local-arch", choices=["temporal", "image"], default=None,
                   help="LocalMotionFill's network for a new model (stage local): convolutions over time reading each "
                   "frame of the motion image whole (default) or 2-D convolutions over the image (LEMO); with --init, "
                   "the checkpoint's")
    p.set_defaults(func=_cmd_train, out_is_file=True)
    b = train_sub.add_parser("motionfill_baseline", help="train one of SAGA Tab. 3's deterministic infilling "
                             "baselines (CNN-AE, PoseNet, RouteNet)")
    b.add_argument("--model", choices=list(BASELINE_DATA), required=True)
    b.add_argument("--epochs", type=int, default=30)
    b.add_argument("--out", type=Path, default=None, help="default data_stubs/checkpoints/motionfill_<model>.pt")
    b.set_defaults(out_is_file=True)
    b.add_argument("--data", type=Path, default=None, help="folder of the approach clips (default: the cache's)")
    b.add_argument("--clips", type=int, default=None, help="approach clips (default 144)")
    b.add_argument("--lr", type=positive_float, default=1e-3)
    b.add_argument("--time-limit", type=positive_float, default=300.0, help=TIME_LIMIT_HELP + " (default 300)")
    b.add_argument("--seed", type=int, default=0)
    b.add_argument("--threads", type=int, default=1)
    b.set_defaults(func=_cmd_train_baseline)


def _cmd_train_baseline(args: argparse.Namespace) -> int:
    """Train one Tab. 3 baseline and print the last epoch's figures."""
    check_counts(args, clips=1)
    torch.set_num_threads(args.threads)
    t0 = time.perf_counter()
    out = args.out or baseline_path(args.model)
    _, hist = train_baseline(args.model, args.epochs, out, seed=args.seed, time_limit_s=args.time_limit, lr=args.lr,
                             data=args.data, clips=None if args.clips is None else {"approach": args.clips})
    print(f"motionfill_baseline {args.model}: {len(hist)} epochs in {time.perf_counter() - t0:.0f} s -> {out}")
    print("  " + ", ".join(f"{k} {v:.3f}" for k, v in hist[-1].items() if k != "epoch"))
    return 0


def _cmd_train(args: argparse.Namespace) -> int:
    """Run one stage and print the last epoch's figures."""
    check_counts(args, clips=1)
    torch.set_num_threads(args.threads)
    t0 = time.perf_counter()
    if args.stage == "smooth_ae":
        from graspkit.optim.graspmotion import SMOOTH_AE_PATH, train_smooth_ae

        unused = [flag for flag, v in (("--lr", args.lr), ("--time-limit", args.time_limit), ("--init", args.init),
                                       ("--reduction", args.reduction), ("--local-arch", args.local_arch),
                                       ("--clips", args.clips)) if v is not None]
        if unused:
            raise ValueError(f"{', '.join(unused)}: --stage smooth_ae trains S.1's small autoencoder in its own loop "
                             "(Adam, lr 2e-3, every epoch; not graspkit.train.fit: no resume, no CSV) on the windows "
                             f"of {DEFAULT_CLIPS['locomotion']} locomotion and {DEFAULT_CLIPS['approach']} approach "
                             "clips, from scratch; leave them out")

        out = args.out if args.out != CHECKPOINT else SMOOTH_AE_PATH
        marks = []
        for kind in ("locomotion", "approach"):
            arr = windows(kind, DEFAULT_CLIPS[kind], data=args.data if kind == "approach" else None)
            marks.append(arr["markers"][np.isin(arr["clip"], clip_split(arr)["train"])])
        _, hist = train_smooth_ae(np.concatenate(marks), epochs=args.epochs, seed=args.seed, out=out)
        print(f"smooth_ae: {len(hist)} epochs in {time.perf_counter() - t0:.0f} s -> {out}; L1 (scaled) "
              f"{hist[0]:.3f} -> {hist[-1]:.3f}")
        return 0
    kind = STAGES[args.stage][0]
    _, hist = train_stage(args.stage, args.epochs, args.out, init=args.init, seed=args.seed,
                          time_limit_s=540.0 if args.time_limit is None else args.time_limit,
                          lr=1e-3 if args.lr is None else args.lr,
                          clips=None if args.clips is None else {kind: args.clips},
                          data=args.data, reduction=args.reduction, local_arch=args.local_arch)
    last = hist[-1]
    print(f"motionfill {args.stage}: {len(hist)} epochs in {time.perf_counter() - t0:.0f} s -> {args.out}")
    print("  " + ", ".join(f"{k} {v:.3f}" for k, v in last.items() if k != "epoch"))
    return 0


# ------------------------------------------------------------------------------------------------ Tab. 3
# SAGA Tab. 3 (AMASS / GRAB): ADE (m), skating (fraction of frames), PSKL-J (P, GT) and (GT, P); PSKL-J is on joints,
# graspkit's PSKL on the 79 markers (docs/saga_motion.md)
PAPER = {"CNN-AE (local)": (0.091, 0.245, 0.804, 0.739), "LEMO (local)": (0.083, 0.152, 0.507, 0.447),
         "PoseNet (local)": (0.090, 0.236, 0.611, 0.668), "Ours-Local": (0.079, 0.137, 0.377, 0.327),
         "Route+PoseNet": (0.219, 0.575, 0.955, 0.884), "Ours": (0.083, 0.394, 0.772, 0.609)}


STILL_ACCELERATION = 1e-9   # m per frame^2: an RMS acceleration below this is no motion (rounding at most)


def pskl(pred: np.ndarray, gt: np.ndarray, eps: float = 1e-8) -> tuple[float, float]:
    """PSKL (LEMO, SAGA §4.2): KL between the normalised power spectra of the accelerations, per point and axis,
    averaged; both directions (KL(P || GT), KL(GT || P)). pred, gt (N, T, J, 3); pred may be (N, K, T, J, 3).

    A coordinate that does not accelerate at all (a linear blend's: RMS below STILL_ACCELERATION) has no spectrum to
    normalise and is left out of the mean, in both directions; an eps spectrum in its place read as KL(P || GT) = 0
    and KL(GT || P) = 16 (an independent check, 2026-12-03). `pskl_still_share` gives the share left out."""
    (p, live_p), (g, live_g) = _spectrum(pred, eps), _spectrum(gt, eps)
    if p.ndim == g.ndim + 1:
        g, live_g = g[:, None], live_g[:, None]
    live = np.broadcast_to(live_p & live_g, np.broadcast_shapes(live_p.shape, live_g.shape))
    if not live.any():
        return float("nan"), float("nan")
    return float((p * np.log(p / g)).sum(-3)[live].mean()), float((g * np.log(g / p)).sum(-3)[live].mean())


def pskl_still_share(pred: np.ndarray) -> float:
    """The share of pred's coordinates (..., T, J, 3) that `pskl` leaves out: those with no acceleration."""
    return float(1.0 - _spectrum(pred, 1e-8)[1].mean())


def _spectrum(x: np.ndarray, eps: float) -> tuple[np.ndarray, np.ndarray]:
    """Normalised power spectra (..., F, J, 3) of the accelerations of x (..., T, J, 3) along time, and which
    coordinates (..., J, 3) move at all."""
    acc = x[..., 2:, :, :] - 2 * x[..., 1:-1, :, :] + x[..., :-2, :, :]
    ps = np.abs(np.fft.rfft(acc, axis=-3)) ** 2
    total = ps.sum(-3, keepdims=True)
    live = np.sqrt((acc ** 2).mean(-3)) > STILL_ACCELERATION
    return ps / np.where(total > 0, total, 1.0) + eps, live


def heel_columns() -> list[int]:
    """Columns of the left and right heel markers in SAGA's sparse set."""
    from graspkit.body import BodyModel
    from graspkit.body.markers import saga_sparse_markers
    from graspkit.paths import default_model_path

    names = saga_sparse_markers(BodyModel.from_file(default_model_path())).names
    return [names.index("LHEE"), names.index("RHEE")]


def skating(markers: np.ndarray, floor: np.ndarray, heels: list[int]) -> float:
    """SAGA's skating rate (§4.2: both heels within 5 cm of the ground and faster than 75 mm/s) of marker sequences
    (..., T, M, 3) whose ground height is `floor` (...) (Tab. 3 passes the ground truth window's lowest heel marker)."""
    from graspkit.metrics import foot_skating_saga

    h = markers[..., heels, :].copy()
    h[..., 2] -= np.asarray(floor)[..., None, None]
    flat = h.reshape(-1, *h.shape[-3:])
    return float(np.mean([foot_skating_saga(x).mean() for x in flat]))


def heel_jerkiness(markers: np.ndarray, heels: list[int], fps: float = 30.0) -> dict[str, float]:
    """Largest heel-marker speed (m/s) and the 99th percentile of its acceleration (m/s^2) over a marker sequence
    (T, M, 3): a foot that stands still and then jumps can pass the skating metric while moving unnaturally."""
    h = np.asarray(markers, np.float64)
    if h.ndim != 3 or h.shape[0] < 3 or h.shape[-1] != 3:
        raise ValueError(f"markers: expected (T, M, 3) with T >= 3 frames (an acceleration needs three), got "
                         f"{h.shape}")
    if not np.isfinite(h).all():
        raise ValueError("markers: contains NaN or Inf")
    h = h[:, heels]
    v = np.linalg.norm(np.diff(h, axis=0), axis=-1) * fps
    a = np.linalg.norm(np.diff(h, 2, axis=0), axis=-1) * fps ** 2
    return {"heel_speed_max": float(v.max()), "heel_acc_p99": float(np.percentile(a, 99))}


def linear_local(local: np.ndarray) -> np.ndarray:
    """The linear-interpolation baseline of the local motion: frames 0 -> T blended linearly (N, T+1, M, 3)."""
    s = np.linspace(0, 1, local.shape[1])[None, :, None, None]
    return (1 - s) * local[:, :1] + s * local[:, -1:]


def evaluate(model: MotionFillVAE, arr: dict[str, np.ndarray], clips: np.ndarray, n: int = 10, seed: int = 0,
             baselines: dict[str, Any] | None = None) -> dict[str, dict[str, float]]:
    """Tab. 3 on the windows of `clips`: local infilling with the true trajectory and trajectory + local, ours (n samples,
    ADE = min over samples) and linear interpolation; skating, PSKL both ways, APD; the ground truth's skating.
    `baselines` ({cnn_ae, posenet, routenet}, e.g. `load_baselines()`) adds Tab. 3's deterministic rows (one output
    each, APD 0): "CNN-AE (local)" and "PoseNet (local)" on the true trajectory, "Route+PoseNet" (RouteNet's
    trajectory, then PoseNet)."""
    from graspkit.data.motionfill_dataset import global_motion, interpolated_trajectory
    from graspkit.metrics import apd

    keep = np.isin(arr["clip"], clips)
    a = {k: v[keep] for k, v in arr.items()}
    gt = a["markers"].astype(np.float64)
    heels = heel_columns()
    feet = [heels[0], heels[1]]
    floor = gt[:, :, feet, 2].min((1, 2))
    ti = interpolated_trajectory(a["traj"].astype(np.float64))
    g = torch.Generator().manual_seed(seed)
    out: dict[str, np.ndarray] = {"Ours-Local": [], "Ours": []}
    for i in range(len(gt)):
        for name, traj in (("Ours-Local", torch.as_tensor(a["traj"][i])), ("Ours", None)):
            s = model.sample(torch.as_tensor(ti[i]).float(), torch.as_tensor(a["local"][i]),
                             torch.as_tensor(a["contacts"][i]).float(), n, g, traj=traj)
            out[name].append(s["markers"].double().numpy())
    for name, key, route in (("CNN-AE (local)", "cnn_ae", "truth"), ("PoseNet (local)", "posenet", "truth"),
                             ("Route+PoseNet", "posenet", "routenet")):
        if not baselines or key not in baselines or (route != "truth" and route not in baselines):
            continue
        out[name] = []
        for i in range(len(gt)):
            ti_i = torch.as_tensor(ti[i]).float()
            traj = torch.as_tensor(a["traj"][i]) if route == "truth" else baselines[route].predict(ti_i)["traj"][0]
            s = baselines[key].predict(ti_i, torch.as_tensor(a["local"][i]), torch.as_tensor(a["contacts"][i]).float(),
                                       traj=traj)
            out[name].append(s["markers"].double().numpy())
    preds = {k: np.stack(v) for k, v in out.items()}                       # (N, n, T+1, M, 3)
    preds["Linear (local)"] = global_motion(linear_local(a["local"].astype(np.float64)), a["traj"].astype(np.float64))[:, None]
    preds["Linear"] = global_motion(linear_local(a["local"].astype(np.float64)), ti)[:, None]
    rows = {}
    for name, p in preds.items():
        err = np.linalg.norm(p - gt[:, None], axis=-1).mean((2, 3))         # (N, n)
        pg, gp = pskl(p, gt)
        rows[name] = {"ADE": float(err.min(1).mean()), "skating": skating(p, floor[:, None], heels), "PSKL (P, GT)": pg,
                      "PSKL (GT, P)": gp, "APD": float(np.mean([apd(x) for x in p])) if p.shape[1] > 1 else 0.0}
    rows["Ground truth"] = {"ADE": 0.0, "skating": skating(gt, floor, heels), "PSKL (P, GT)": 0.0, "PSKL (GT, P)": 0.0,
                            "APD": 0.0}
    return rows


def table(rows: dict[str, dict[str, float]]) -> str:
    """Markdown table of `evaluate`'s rows with the paper's Tab. 3 figures beside them."""
    paper_of = {"Ours-Local": "Ours-Local", "Ours": "Ours", "Linear (local)": None, "Linear": None,
                "CNN-AE (local)": "CNN-AE (local)", "PoseNet (local)": "PoseNet (local)", "Route+PoseNet": "Route+PoseNet"}
    lines = ["| method | ADE (m) | skating | PSKL (P, GT) | PSKL (GT, P) | APD (m) | paper: ADE / skating / PSKL (P,GT) / (GT,P) |",
             "|---|---|---|---|---|---|---|"]
    for k, r in rows.items():
        ref = PAPER.get(paper_of.get(k) or "", None)
        label = f"{k} (our extra)" if k.startswith("Linear") else k       # not in the paper's table
        lines.append(f"| {label} | {r['ADE']:.3f} | {r['skating']:.3f} | {r['PSKL (P, GT)']:.3f} | {r['PSKL (GT, P)']:.3f} "
                     f"| {r['APD']:.3f} | {' / '.join(f'{x:.3f}' for x in ref) if ref else '—'} |")
    for k in ("CNN-AE (local)", "LEMO (local)", "PoseNet (local)", "Route+PoseNet"):
        if k in rows:                      # measured above (evaluate(..., baselines=...))
            continue
        lines.append(f"| {k} (paper only) | | | | | | {' / '.join(f'{x:.3f}' for x in PAPER[k])} |")
    return "\n".join(lines)


# ------------------------------------------------------------------------------------------------ GraspMotion-Opt
APPROACH_KEYS = ("grasp.goal_frame", "body.params.fullpose", "body.params.transl", "body.betas", "contact.feet",
                 "object.params.global_orient", "object.params.transl", "object.points", "object.normals", "obj_name")


def approach_scene(path: str | Path, bm: BodyModel) -> dict[str, Any]:
    """One approach clip as MotionFill sees it (the window ending at the goal frame, canonical frame A.3) and its
    object in that frame: markers (61,79,3), traj (62,4), local, vel, contacts, betas, floor height, object points,
    normals (P,3), contact maps C_O (P,) and C_M (143,) at the grasp, the object's mesh (trimesh) and the pose of its
    catalogue mesh there (mesh_rotation (3,3), mesh_origin (3,): x = R x_mesh + origin), name, file name and the
    clip's last 61 frames (a Motion in the world)."""
    import zipfile
    import zlib

    from graspkit.data.formats import open_npz
    from graspkit.data.grab import check_made_on
    from graspkit.data.motion import Motion, canonicalize
    from graspkit.objects.catalogue import make_object
    from graspkit.rotations import axis_angle_to_matrix

    with open_npz(path, "an approach clip (graspkit data make --kind approach)") as a:
        missing = [k for k in APPROACH_KEYS if k not in a.files]
        if missing:
            raise ValueError(f"path: {path} is not an approach clip (graspkit data make --kind approach): "
                             f"missing {missing}")
        try:
            g = int(a["grasp.goal_frame"])
            m = Motion(a["body.params.fullpose"][:g + 1].reshape(-1, 55, 3), a["body.params.transl"][:g + 1],
                       a["body.betas"], 30.0, contacts=a["contact.feet"][:g + 1].astype(bool))
            R_o = axis_angle_to_matrix(torch.as_tensor(a["object.params.global_orient"][g]).double()).numpy()
            t_o = a["object.params.transl"][g].astype(np.float64)
            pts, nrm = a["object.points"].astype(np.float64), a["object.normals"].astype(np.float64)
            c_o = a["contact.object"][g].astype(np.float32) if "contact.object" in a.files else None
            c_m = a["contact.markers"][g].astype(np.float32) if "contact.markers" in a.files else None
            name = str(a["obj_name"])
        except (ValueError, OSError, EOFError, zipfile.BadZipFile, zlib.error) as e:   # a damaged member, bad shapes
            raise ValueError(f"path: {path}: could not read the approach clip ({e})") from None
    check_made_on(bm, [path], f"path: {path}", "approach")                  # its body is posed on bm
    arr = make_windows([m], bm, align_end=True, progress=False)
    joints = m.joint_positions(bm)
    n = len(joints)
    if n < 62:
        joints = np.concatenate([joints[:1].repeat(62 - n, 0), joints])
        n = 62
    R, o = canonicalize(joints[n - 61:])
    to_c = lambda x: (x - o) @ R.T  # noqa: E731
    mesh = make_object(name)
    mesh.vertices = to_c(mesh.vertices @ R_o.T + t_o)
    return {**{k: v[0] for k, v in arr.items()}, "betas": m.betas[:10], "floor": float(-o[2]), "name": name,
            "file": Path(path).name, "points": to_c(pts @ R_o.T + t_o), "normals": nrm @ R_o.T @ R.T,
            "object_contact": c_o, "marker_contact": c_m, "mesh": mesh, "mesh_rotation": R @ R_o,
            "mesh_origin": to_c(t_o), "motion": m.slice(max(m.num_frames - 61, 0))}


def graspmotion_eval(model: MotionFillVAE, files: list[Path], seed: int = 0, steps: tuple[int, int] = (100, 300),
                     progress: bool = True, weights: Any = None, sdf: bool = True, hold_start: bool = False
                     ) -> dict[str, Any]:
    """One MotionFill-VAE sample per approach clip, then GraspMotion-Opt (batched): skating (SAGA) of the ground truth,
    the sample and the fitted bodies; the last frame's contact, penetration volume and depth of the fitted bodies;
    SAGA's non-collision score (§4.2) of the fitted and the ground-truth meshes over the window, and how far the fitted
    mesh's lowest vertex goes below the floor (cm: the mean over frames and the deepest) and the share of frames it
    stands more than 1 cm above it (`floating_opt`, `floating_gt`: `metrics.floating_share`). Returns rows and the
    arrays for plots. E^o_cont gets the data's contact maps at the grasp frame (C_O and C_M, standing in for
    WholeGrasp-VAE's). `sdf`: E^o_colli's hand-in-object depth from each object's collision grid (GraspPose-Opt's;
    False: from the point cloud's normals). `hold_start`: frame 0 fitted to the clip's first frame and held there
    (`GraspMotionOpt.fit(start=...)`, as `saga.synthesize`, with the planted heel at `weights.heel_held`; False:
    Alg. 2). `start_cm`: the fitted frame 0's markers from the clip's first frame (mean, cm)."""
    from graspkit.body import BodyModel
    from graspkit.data.grasp_io import collision_sdf_grid
    from graspkit.metrics import floating_share, grasp_metrics, ground_penetration, non_collision_score
    from graspkit.models.pose_prior import load_pose_prior
    from graspkit.optim.graspmotion import GraspMotionConfig, GraspMotionOpt, load_smooth_ae
    from graspkit.optim.grasppose import GraspObject
    from graspkit.paths import default_model_path

    bm = BodyModel.from_file(default_model_path())
    scenes = [approach_scene(f, bm) for f in files]
    g = torch.Generator().manual_seed(seed)
    heels = heel_columns()
    samples = [model.sample(torch.as_tensor(interp(s["traj"])).float(), torch.as_tensor(s["local"]),
                            torch.as_tensor(s["contacts"]).float(), 1, g) for s in scenes]
    markers = torch.cat([s["markers"] for s in samples])
    contacts = torch.cat([s["contacts"] for s in samples])
    P = min(len(s["points"]) for s in scenes)
    grids = {n: collision_sdf_grid(n) for n in {s["name"] for s in scenes}} if sdf else {}   # one load per object
    obj = GraspObject(torch.as_tensor(np.stack([s["points"][:P] for s in scenes])).float(),
                      torch.as_tensor(np.stack([s["normals"][:P] for s in scenes])).float(), 0.0,
                      [grids[s["name"]] for s in scenes] if sdf else None,
                      torch.as_tensor(np.stack([s["mesh_rotation"] for s in scenes])).float(),
                      torch.as_tensor(np.stack([s["mesh_origin"] for s in scenes])).float())
    c_o = torch.as_tensor(np.stack([s["object_contact"][:P] for s in scenes])).float()
    c_m = torch.as_tensor(np.stack([s["marker_contact"] for s in scenes])).float()
    cfg = GraspMotionConfig(steps=steps) if weights is None else GraspMotionConfig(steps=steps, weights=weights)
    opt = GraspMotionOpt(bm, load_pose_prior(), load_smooth_ae(), cfg)
    res = opt.fit(markers, torch.as_tensor(np.stack([s["betas"] for s in scenes])).float(), contacts, obj, c_o,
                  progress=progress, floor=torch.tensor([s["floor"] for s in scenes]).float(), marker_contact=c_m,
                  start=torch.as_tensor(np.stack([s["markers"][0] for s in scenes])).float() if hold_start else None)
    rows = []
    for i, s in enumerate(scenes):
        floor = np.array(s["floor"])
        v, v_gt = opt.vertices(res, i), s["motion"].vertices(bm)
        fit = grasp_metrics(v[-1], bm.faces, s["mesh"])
        dip = ground_penetration(v - torch.tensor([0.0, 0.0, s["floor"]]))    # (T+1,) under the scene's floor
        rows.append({"object": s["name"], "clip": s["file"],
                     "skating_gt": skating(s["markers"][None].astype(np.float64), floor[None], heels),
                     "skating_sample": skating(markers[i:i + 1].double().numpy(), floor[None], heels),
                     "skating_opt": skating(res.markers[i:i + 1].double().numpy(), floor[None], heels),
                     "fit_cm": float((res.markers[i] - markers[i]).norm(dim=-1).mean() * 100),
                     "start_cm": 100 * float((res.markers[i, 0] - torch.as_tensor(s["markers"][0])).norm(dim=-1).mean()),
                     "contact_mm": fit["min_distance"] * 1000, "volume_cm3": fit["volume_cm3"], "depth_cm": fit["depth_cm"],
                     "noncollision_opt": float(non_collision_score(v, s["floor"]).mean()),
                     "noncollision_gt": float(non_collision_score(v_gt).mean()),
                     "below_floor_mean_cm": 100 * float(dip.mean()), "below_floor_max_cm": 100 * float(dip.max()),
                     "floating_opt": floating_share(v, s["floor"]),
                     "floating_gt": floating_share(v_gt),
                     **{f"{k}_{tag}": x for tag, seq in (("gt", s["markers"]), ("opt", res.markers[i].numpy()))
                        for k, x in heel_jerkiness(seq, heels).items()}})
    return {"rows": rows, "result": res, "markers": markers, "contacts": contacts, "scenes": scenes}


def interp(traj: np.ndarray) -> np.ndarray:
    """Gamma_bar of one window (62, 4)."""
    from graspkit.data.motionfill_dataset import interpolated_trajectory

    return interpolated_trajectory(np.asarray(traj, np.float64)[None])[0]


def held_out_clips(folder: str | Path, per_object: int = 1) -> list[Path]:
    """The first `per_object` accepted approach clips (by file name) of each held-out test object in `folder`, in
    file order."""
    from graspkit.objects.catalogue import TEST_OBJECTS

    if int(per_object) != per_object or per_object < 1:
        raise ValueError(f"per_object: expected a whole number >= 1, got {per_object}")
    taken: dict[str, list[Path]] = {}
    for f in clip_files(folder, "approach"):
        a = _approach_arrays(f, ("obj_name", "grasp.accepted"))
        name, ok = str(a["obj_name"]), bool(a["grasp.accepted"])
        if ok and name in TEST_OBJECTS and len(taken.setdefault(name, [])) < per_object:
            taken[name].append(f)
    if not any(taken.values()):
        raise FileNotFoundError(f"folder: no accepted approach clip of a test object {TEST_OBJECTS} in {folder} "
                                "(graspkit data make --kind approach --n 272 --seed 0)")
    return sorted(f for v in taken.values() for f in v)


def write_example(files: list[Path], out: Path, seed: int = 0) -> dict[str, Any]:
    """Lesson 06's worked example: GraspMotion-Opt on `files` (batched); the first clip's sample, fit and contacts to
    `out`.npz, every clip's row, the step log and how it was made to `out`.json."""
    import io

    from graspkit.paths import write_json
    from graspkit.viz.export import write_atomic

    ev = graspmotion_eval(load_motionfill(), files, seed=seed)
    res, pr = ev["result"], ev["result"].params
    arrays = {"markers_sample": ev["markers"][0].numpy(), "markers_fit": res.markers[0].numpy(),
              "contacts": ev["contacts"][0].numpy(), "poses": pr["poses"][0].numpy(), "transl": pr["transl"][0].numpy(),
              "betas": pr["betas"][0].numpy()}
    buf = io.BytesIO()
    np.savez(buf, **{k: np.asarray(v, np.float32) for k, v in arrays.items()})
    info = {"rows": ev["rows"], "files": [f.name for f in files], "log": res.log,
            "made_by": f"python -m graspkit.eval_motionfill example (graspmotion_eval(load_motionfill(), "
                       f"{[f.name for f in files]}, seed={seed}) with the default GraspMotionConfig)"}
    write_atomic(out.with_suffix(".npz"), buf.getvalue())
    write_json(out.with_suffix(".json"), info)
    return info


def update_json(path: Path, **sections: Any) -> dict[str, Any]:
    """Replace `sections` of the JSON file at `path` (created if missing, other keys kept; written atomically)."""
    import json

    from graspkit.paths import write_json

    doc = json.loads(path.read_text()) if path.is_file() else {}
    if not isinstance(doc, dict):
        raise ValueError(f"path: {path} holds a JSON {type(doc).__name__}, expected an object to update")
    doc.update(sections)
    path.parent.mkdir(parents=True, exist_ok=True)
    write_json(path, doc)
    return doc


@reports_errors("python -m graspkit.eval_motionfill")
def main(argv: list[str] | None = None) -> int:
    """`python -m graspkit.eval_motionfill tab3`: Tab. 3 on the test-object windows, written into
    motionfill_eval.json's rows; `... graspmotion`: GraspMotion-Opt on the first two (--per-object) approach clips
    of each test object, batched, into its "graspmotion" section (the rest of the file kept); `... example`: lesson
    06's example (the shipped mug clip batched with the first test clip) into motionfill_examples.npz/json (--out: the
    path without its suffix, or a .npz / .json path whose stem is used)."""
    from graspkit.optim.graspmotion import GraspMotionConfig
    from graspkit.paths import cache_dir

    p = argparse.ArgumentParser(prog="python -m graspkit.eval_motionfill")
    p.add_argument("part", choices=["tab3", "graspmotion", "example"])
    p.add_argument("--data", type=Path, default=None, help="approach clips (default: the cache's grasps/approach)")
    p.add_argument("--clips", type=int, default=272, help="tab3: approach clips whose test-object windows are used")
    p.add_argument("--checkpoints", type=Path, default=CHECKPOINT.parent,
                   help="tab3: folder of motionfill.pt and the baselines' motionfill_<name>.pt")
    p.add_argument("--out", type=Path, default=None,
                   help="tab3, graspmotion: the JSON to update (default data_stubs/checkpoints/motionfill_eval.json); "
                        "example: the .npz/.json pair's path (default data_stubs/checkpoints/motionfill_examples)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--per-object", type=int, default=2, help="graspmotion: accepted clips per test object")
    p.add_argument("--threads", type=int, default=1)
    args = p.parse_args(argv)
    if args.part != "example":                       # (example's --out is a stem for two files)
        refuse_folder_out(argv)
    expand_user_paths(args)
    check_counts(args, clips=1, per_object=1, threads=1, seed=0)
    if args.part == "example":
        out = (args.out or CHECKPOINT.parent / "motionfill_examples")
        out = out.with_suffix("") if out.suffix in (".npz", ".json") else out
        for suffix in (".npz", ".json"):
            check_out(out.with_name(out.name + suffix), is_file=True)
    else:
        args.out = args.out or CHECKPOINT.parent / "motionfill_eval.json"
        check_out(args.out, is_file=True)
        if args.out.is_file():                      # update_json reads it after the work: refuse a bad one now
            import json
            try:
                doc = json.loads(args.out.read_text())
            except (UnicodeDecodeError, ValueError) as e:
                raise ValueError(f"--out: {args.out} is not a JSON file to update ({e})") from None
            if not isinstance(doc, dict):
                raise ValueError(f"--out: {args.out} holds a JSON {type(doc).__name__}, expected an object to update")
    torch.set_num_threads(args.threads)
    data = args.data or cache_dir() / "grasps" / "approach"
    if args.part == "tab3":
        from graspkit.models.motionfill_baselines import BASELINES

        missing = [str(baseline_path(b, args.checkpoints)) for b in BASELINES
                   if not baseline_path(b, args.checkpoints).is_file()]
        if missing:                                 # the table would show them as "(paper only)" without a word
            raise ValueError(f"--checkpoints: the Tab. 3 baselines are missing: {missing} "
                             "(graspkit train motionfill_baseline, docs/saga_motion.md)" + stub_hint(Path(missing[0])))
        t0 = time.perf_counter()
        arr = windows("approach", args.clips, data=args.data)
        test = clip_split(arr)["test"]
        rows = evaluate(load_motionfill(args.checkpoints / "motionfill.pt"), arr, test, n=10, seed=args.seed,
                        baselines=load_baselines(args.checkpoints))
        where = (f"<cache>/grasps/approach (graspkit data make --kind approach --n {args.clips} --seed 0)"
                 if args.data is None else str(data))      # not this machine's cache folder: a shipped file says it
        protocol = (f"windows ending at the grasp of the six GRAB test objects among the first {args.clips} clips of "
                    f"{where}; "
                    f"n = 10 samples, seed {args.seed}; baselines from load_baselines({args.checkpoints.name}); "
                    "PSKL leaves out coordinates that never accelerate (the linear rows' z: pskl_still_share)")
        doc = update_json(args.out, rows=rows, test_windows=int(np.isin(arr["clip"], test).sum()), protocol=protocol)
        print(f"{doc['test_windows']} test windows, {time.perf_counter() - t0:.0f} s -> {args.out}")
        print(table(rows))
        return 0
    files = held_out_clips(data, 1 if args.part == "example" else args.per_object)
    if args.part == "example":
        from graspkit.paths import DATA_STUBS

        info = write_example([DATA_STUBS / "approach" / "approach_000000.npz", files[0]], out, seed=args.seed)
        print({k: round(v, 3) if isinstance(v, float) else v for k, v in info["rows"][0].items()})
        return 0
    t0 = time.perf_counter()
    ev = graspmotion_eval(load_motionfill(), files, seed=args.seed)
    secs = time.perf_counter() - t0
    cfg = GraspMotionConfig()                       # what graspmotion_eval ran
    update_json(args.out, graspmotion={"rows": ev["rows"], "files": [f"{f.parent.name}/{f.name}" for f in files],
                                       "per_object": args.per_object, "steps": list(cfg.steps),
                                       "polish": list(cfg.polish), "free_joints": list(cfg.free_joints),
                                       "seed": args.seed,
                                       "seconds": round(secs, 1), "threads": args.threads})
    keys = ("skating_gt", "skating_sample", "skating_opt", "contact_mm", "volume_cm3", "depth_cm", "heel_acc_p99_gt",
            "heel_acc_p99_opt", "noncollision_opt", "below_floor_mean_cm", "below_floor_max_cm", "floating_opt")
    for r in ev["rows"]:
        print(f"{r['object']:12s} " + " ".join(f"{k} {r[k]:.3f}" for k in keys))
    print("mean         " + " ".join(f"{k} {np.mean([r[k] for r in ev['rows']]):.3f}" for k in keys)
          + f"  ({secs:.0f} s) -> {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
