"""`graspkit data make`: generate locomotion (AMASS-style) or reaching (CIRCLE-style) clips into a folder.

    graspkit data make --kind locomotion --n 2000 --seed 0 --out ~/.cache/graspkit/motion/locomotion

Parallel over processes, resumable (finished files are kept, a damaged one is made again; each file is written to a
temporary name and renamed, so no partial file is ever left), deterministic: clip i's seed derives from
(seed, kind, i), so the same command writes the same files whatever the number of workers or interruptions.
"""
from __future__ import annotations

import argparse
import os
from pathlib import Path

import numpy as np

from graspkit.checks import GraspkitWarning, user_stacklevel
from graspkit.cli import DATA_HELP
from graspkit.paths import drop_damaged, pool_results
from graspkit.state import keeps_torch_state

KINDS = ("locomotion", "reach", "reach_far", "reach_chain", "reach_near")   # reach_far: room-scale CIRCLE-style tasks
# (WANDR's grid); reach_chain: room-scale, starting from a finished reach; reach_near: near goals, floor or overhead
GRASP_KINDS = ("grasp", "approach")          # graspkit.data.grasp_make (chunked, batched grasp fitting)
DEFAULT_N = {"locomotion": 2000, "reach": 2000, "reach_far": 2000, "reach_chain": 1000, "reach_near": 500,
             "grasp": 1700, "approach": 510}
_BM = None


def claim_folder(out: Path, kind: str, settings: dict) -> None:
    """Record the settings that shape a folder's `kind` files (<out>/graspkit_make_<kind>.json) on its first run, and
    refuse to add files made with other settings (another seed, body model, chunk or object list) to it: a resumed or
    extended run must be the same run. The record is created exclusively (of two runs started together into one new
    folder, the second is refused like a later one). A folder of files made before this record existed is taken as it
    is, with a warning, and the record notes how many files it did not check ("preexisting")."""
    import json
    import re
    import warnings

    from graspkit.body import BodyModel
    from graspkit.paths import create_exclusive, default_model_path

    record = Path(out) / f"graspkit_make_{kind}.json"
    settings = dict(settings)
    # the body by its content too: the path (or $GRASPKIT_MODEL) may name another model file than last time
    body = BodyModel.from_file(settings.get("model") or default_model_path()).digest()
    if settings.get("model") is not None:           # the default body given by its path is the default body
        m = Path(settings["model"]).resolve()
        settings["model"] = None if m == Path(default_model_path()).resolve() else str(m)
    want = {"kind": kind, **settings, "body": body}
    if not record.is_file():
        older = [f for f in Path(out).glob(f"{kind}_*.npz") if re.fullmatch(rf"{kind}_\d{{6}}\.npz", f.name)]
        if older:                                    # (reach_* would match reach_far_* too: the exact name)
            warnings.warn(f"--out: {out} holds {len(older)} {kind} files and no record of the run that made them: "
                          "taken as they are, unchecked; this run's settings are recorded for the next",
                          GraspkitWarning, stacklevel=user_stacklevel())
        # the record says how many files it did not check; later runs are checked against it
        if create_exclusive(record, json.dumps({**want, "preexisting": len(older)} if older else want,
                                               sort_keys=True)):
            return                                   # else another run created it meanwhile: its record decides
    try:
        have = json.loads(record.read_text())
    except (UnicodeDecodeError, json.JSONDecodeError) as e:
        raise ValueError(f"--out: {record} is damaged ({e}); remove it only if the folder's files were made "
                         "with the settings given now (the next run records them, unchecked)") from None
    if not isinstance(have, dict):
        raise ValueError(f"--out: {record} holds a {type(have).__name__}, expected the settings of a run")
    have.pop("preexisting", None)
    if "body" not in have:                      # a record written before the body's digest was kept
        want.pop("body")
    else:                                       # the body is its content: the same file moved (or copied) is the same
        have.pop("model", None)
        want.pop("model", None)
    if have != want:
        diff = "; ".join(f"{k}: {have.get(k)!r} there, {want.get(k)!r} now"
                         for k in sorted(set(have) | set(want)) if have.get(k) != want.get(k))
        raise ValueError(f"--out: {out} holds {kind} files made with other settings ({diff}); "
                         "use another --out or remove its files")


def check_model(model: str | None) -> None:
    """Load the body-model file once here, so a bad --model fails with its own error before any worker starts."""
    if model is not None:
        from graspkit.body import BodyModel
        from graspkit.body.model import ModelFileError

        try:
            BodyModel.from_file(model)
        except ModelFileError as e:
            raise ValueError(f"--model: {e}") from None


def clip_seed(seed: int, kind: str, index: int) -> int:
    """The seed of clip `index` of a set: derived from (seed, kind, index) by numpy's SeedSequence."""
    return int(np.random.SeedSequence([seed, KINDS.index(kind), index]).generate_state(1)[0])


def clip_path(out: Path, kind: str, index: int) -> Path:
    """File name of clip `index`."""
    return out / f"{kind}_{index:06d}.npz"


def _init_worker(model: str | None, parent: int | None = None) -> None:
    """Load the body model once per worker process (and keep torch to one thread per process); a pool's worker
    (`parent`: the pool's process) exits when that process is gone."""
    if parent is not None:
        from graspkit.paths import exit_with_parent

        exit_with_parent(parent)
    import torch

    from graspkit.body import BodyModel
    from graspkit.paths import default_model_path

    global _BM
    torch.set_num_threads(1)
    _BM = BodyModel.from_file(model or default_model_path())


def make_clip(kind: str, seed: int, index: int, out: str) -> str:
    """Generate and write one clip (in a worker); returns its path."""
    from graspkit.data.formats import save_motion
    from graspkit.data.locomotion import generate_locomotion
    from graspkit.data.reaching import generate_reach, generate_reach_chain

    s = clip_seed(seed, kind, index)
    m = (generate_locomotion(s, _BM) if kind == "locomotion" else generate_reach_chain(s, _BM)
         if kind == "reach_chain" else generate_reach(s, _BM, far=kind == "reach_far", near=kind == "reach_near"))
    return str(save_motion(clip_path(Path(out), kind, index), m))


@keeps_torch_state
def make_dataset(kind: str, n: int, seed: int, out: Path, workers: int = 2, model: str | None = None,
                 progress: bool = True) -> list[Path]:
    """Write clips 0..n-1 of `kind` that are not there yet; returns all n paths."""
    from tqdm import tqdm

    from graspkit.progress import hidden

    if kind not in KINDS:
        raise ValueError(f"kind: expected one of {KINDS}, got {kind!r}")
    for name, value, least in (("n", n, 0), ("workers", workers, 1)):
        if value < least:
            raise ValueError(f"{name}: expected an integer >= {least}, got {value}")
    out = Path(out)
    check_model(model)
    out.mkdir(parents=True, exist_ok=True)
    claim_folder(out, kind, {"seed": seed, "model": model})
    drop_damaged([clip_path(out, kind, i) for i in range(n)], f"{kind} clips")
    todo = [i for i in range(n) if not clip_path(out, kind, i).exists()]
    bar = tqdm(total=n, initial=n - len(todo), desc=f"{kind} clips", unit="clip", disable=hidden(progress))
    if workers == 1:
        _init_worker(model)
        for i in todo:
            make_clip(kind, seed, i, str(out))
            bar.update()
    elif todo:
        for _ in pool_results([(make_clip, (kind, seed, i, str(out))) for i in todo], workers, _init_worker,
                              (model, os.getpid())):
            bar.update()
    bar.close()
    return [clip_path(out, kind, i) for i in range(n)]


def _cmd_make(args: argparse.Namespace) -> int:
    """Run `graspkit data make`."""
    from graspkit.body.model import ModelFileError
    from graspkit.demo import load_or_build_body

    try:                       # before any folder: the default body built if missing (a plain `pip install`)
        load_or_build_body(args.model)
    except ModelFileError as e:
        raise ValueError(f"--model: {e}") from None
    n = args.n if args.n is not None else DEFAULT_N[args.kind]
    out = args.out
    if out is None:
        from graspkit.paths import cache_dir

        out = cache_dir() / ("grasps" if args.kind in GRASP_KINDS else "motion") / args.kind
    if args.kind not in GRASP_KINDS:
        given = [f for f, v in (("--chunk", args.chunk), ("--objects", args.objects)) if v is not None]
        if given:
            raise ValueError(f"{' and '.join(given)}: only for --kind grasp or approach, not {args.kind} "
                             "(motion clips are made one at a time, with no object)")
    if args.kind in GRASP_KINDS:
        from graspkit.data.grasp_make import CHUNK, OBJECT_ORDER, make_grasp_dataset

        objects = None
        if args.objects is not None:
            objects = tuple(o.strip() for o in args.objects.split(",") if o.strip())
            bad = [o for o in objects if o not in OBJECT_ORDER]
            if not objects or bad:
                raise ValueError(f"--objects: expected object names of {list(OBJECT_ORDER)} separated by commas, got "
                                 f"{args.objects!r}")
        make_grasp_dataset(args.kind, n, args.seed, out, args.workers, str(args.model) if args.model else None,
                           progress=not args.quiet, chunk=CHUNK if args.chunk is None else args.chunk,
                           objects=objects)
        print(f"{n} {args.kind} files in {out}")
        return 0
    make_dataset(args.kind, n, args.seed, out, args.workers, str(args.model) if args.model else None,
                 progress=not args.quiet)
    print(f"{n} {args.kind} clips in {out}")
    return 0


def add_data_commands(subparsers: argparse._SubParsersAction) -> None:
    """Register `graspkit data ...` on the top-level subparsers."""
    data = subparsers.add_parser("data", help=DATA_HELP).add_subparsers(dest="data_command", required=True)
    m = data.add_parser("make", help="generate locomotion (AMASS-style) or reaching (CIRCLE-style) clips, "
                        "whole-body grasps or approach-and-grasp clips (GRAB-style)")
    m.add_argument("--kind", choices=KINDS + GRASP_KINDS, required=True)
    m.add_argument("--n", type=int, default=None, help=f"number of clips (default {DEFAULT_N})")
    m.add_argument("--seed", type=int, default=0)
    m.add_argument("--out", type=Path, default=None, help="folder (default: <cache>/motion/<kind>, <cache>/grasps/<kind>)")
    m.add_argument("--workers", type=int, default=2, help="processes (default 2)")
    m.add_argument("--model", type=Path, default=None, help="an SMPL-X .npz (default: the procedural humanoid)")
    m.add_argument("--quiet", action="store_true", help="no progress bar")
    m.add_argument("--chunk", type=int, default=None,
                   help="grasp/approach: grasps fitted together (default 16; files depend on it)")
    m.add_argument("--objects", default=None, help="grasp/approach: comma-separated objects (default: all 17)")
    m.set_defaults(func=_cmd_make, out_is_file=False)
