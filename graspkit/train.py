"""One training loop for every model of the workbook: seeded, resumable, atomic checkpoints, DDP-ready.

    model = MyModel(...)
    def step(model, batch, epoch) -> dict[str, Tensor]:      # returns {"loss": ..., other scalars to log}
        ...
    history = fit(model, step, dataset, TrainConfig(epochs=20, batch_size=64, lr=1e-3, seed=0),
                  checkpoint="runs/my_model.pt")

A checkpoint holds only tensors and plain Python values (model and optimiser state, epoch, history, config,
extra such as normalisation statistics), so it loads with `torch.load(path, weights_only=True)`. Training
stopped at any point resumes from the last finished epoch with the same numbers as an uninterrupted run: the
data order of each epoch comes from `seed + epoch`, and the RNG state is saved. A `time_limit_s` is the exception:
it is wall time, so where it stops depends on the machine, and a resumed run gets the whole limit again (a finished
time-limited command run a second time trains further). The state also records `code_version()`, a hash of
graspkit's sources: a run resumed by other code warns (the run key names the settings, not the code).

DDP: when `torch.distributed` is initialised (`init_distributed()` under `torchrun --nproc_per_node=2 ...`), `fit`
wraps the model in DistributedDataParallel, shards every epoch with a DistributedSampler, sums the logged terms over
the ranks and lets rank 0 alone write checkpoints. Training stays on the CPU (gloo): the workbook's models are sized
for CPU cores, and `fit` does not move models or batches to a GPU. The step function then receives the DDP wrapper
and must run the model through its `forward` (gradients are averaged across ranks in backward), so every rank keeps
identical weights. GNet's and MNet's steps do; WholeGrasp, the pose prior, MotionFill and WANDR call other methods
(`loss`, `encode` / `decode`), pass `ddp=False` and train in one process.
"""
from __future__ import annotations

import functools
import math
import os
import sys
import time
import zipfile
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, TypeVar

import numpy as np
import torch
from torch.utils.data import DataLoader, Dataset
from tqdm.auto import tqdm

from graspkit.models.blocks import evaluating
from graspkit.optim.step import with_autograd
from graspkit.paths import check_suffix, naming_errors, publish, sweep_stale_temps, temp_beside, write_atomic
from graspkit.progress import hidden
from graspkit.state import keeps_torch_state

StepFn = Callable[[torch.nn.Module, Any, int], dict[str, torch.Tensor]]
M = TypeVar("M")


RUNS: list[Path] = []        # the training states `fit` wrote in this process (`graspkit train` names their logs)


@dataclass
class TrainConfig:
    """Optimisation settings: epochs, batch size, Adam learning rate (cosine-decayed to lr * lr_min_ratio), seed."""

    epochs: int = 10
    batch_size: int = 64
    lr: float = 1e-3
    weight_decay: float = 0.0
    lr_min_ratio: float = 0.1
    grad_clip: float | None = 1.0
    seed: int = 0
    num_threads: int | None = None      # torch threads (None: leave as is)
    extra: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        for name in ("epochs", "batch_size", "seed") + (("num_threads",) if self.num_threads is not None else ()):
            v, low = getattr(self, name), 0 if name == "seed" else 1
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < low:
                raise ValueError(f"{name}: expected an integer >= {low}, got {v!r}")
        for name, low, high in (("lr", 0.0, math.inf), ("weight_decay", 0.0, math.inf), ("lr_min_ratio", 0.0, 1.0)):
            v = getattr(self, name)          # lr 0: a run that leaves the weights as they are
            if isinstance(v, bool) or not isinstance(v, (int, float, np.number)) or not (low <= v <= high) \
                    or not np.isfinite(v):
                raise ValueError(f"{name}: expected a finite number in [{low:g}, {high:g}], got {v!r}")
        if self.grad_clip is not None and (isinstance(self.grad_clip, bool) or not isinstance(
                self.grad_clip, (int, float, np.number)) or not (np.isfinite(self.grad_clip) and self.grad_clip > 0)):
            raise ValueError(f"grad_clip: expected None or a positive norm, got {self.grad_clip!r}")


def _canonical(obj: Any) -> Any:
    """obj with every string in its dicts (state dicts' OrderedDicts and their _metadata too), lists and tuples
    interned: pickle writes a string once and then refers back to it only when it is the same object, so equal
    values must be the same objects to give the same bytes (a resumed run's history mixed unpickled keys with the
    code's and wrote other bytes than a run in one go). Containers are copied: one shared by two entries is saved
    twice."""
    if type(obj) is str:
        return sys.intern(obj)
    if type(obj) in (dict, OrderedDict):
        out = type(obj)((_canonical(k), _canonical(v)) for k, v in obj.items())
        if hasattr(obj, "_metadata"):                    # what nn.Module.state_dict() attaches
            out._metadata = _canonical(obj._metadata)  # type: ignore[attr-defined]
        return out
    if type(obj) in (list, tuple):
        return type(obj)(_canonical(v) for v in obj)
    return obj


def save_checkpoint(path: str | Path, state: dict[str, Any]) -> Path:
    """Write a checkpoint atomically (temporary file, then rename); returns the path. The same state gives the same
    bytes whatever the path, also when its strings were made apart (unpickled, built at run time: `_canonical`), so
    that `file_key` hashes the values."""
    import errno
    import shutil

    path = Path(path)
    tmp = temp_beside(path)
    try:
        with naming_errors(path):
            with open(tmp, "wb") as fh:     # torch.save(state, <path>) names the archive's folder after the random temp
                try:                        # file; a file object gets torch's fixed name
                    torch.save(_canonical(state), fh)
                except RuntimeError as e:   # torch's zip writer reports a failed write ("unexpected pos ...") so
                    if not any(s in str(e) for s in ("inline_container", "unexpected pos", "PytorchStreamWriter")):
                        raise
                    free = shutil.disk_usage(tmp.parent).free
                    raise OSError(errno.EIO, f"the checkpoint could not be written ({str(e)[:120]}); {free} bytes "
                                  "free there: is the disk full?", str(path)) from e
            publish(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    sweep_stale_temps(path)
    return path


def run_path(name: str, seed: int, run_dir: str | Path | None = None, **settings: Any) -> Path:
    """The resumable training checkpoint of one run, `<run_dir>/<name>_s<seed>_<key>.pt` (run_dir: <cache>/runs): `key`
    hashes every setting that shapes the run (config, epochs, data, init), so a changed command never resumes
    another run's file."""
    import hashlib
    import json

    from graspkit.paths import cache_dir

    key = hashlib.blake2b(json.dumps(settings, sort_keys=True, default=str).encode(), digest_size=5).hexdigest()
    return Path(run_dir or cache_dir() / "runs") / f"{name}_s{seed}_{key}.pt"


def file_key(path: str | Path | None) -> str:
    """A short content hash of a file (e.g. an init checkpoint, for `run_path`); 'none' when there is no file."""
    import hashlib

    p = Path(path) if path is not None else None
    if p is None or not p.is_file():
        return "none"
    return hashlib.blake2b(p.read_bytes(), digest_size=6).hexdigest()


def files_key(folders: str | Path | list[str | Path], pattern: str = "*.npz") -> str:
    """A short content hash of the files matching `pattern` in one or more folders (names and bytes), for
    `run_path`: data remade in place (the same names and sizes) is a new run, not the old one resumed."""
    import hashlib

    h = hashlib.blake2b(digest_size=6)
    for folder in [folders] if isinstance(folders, (str, Path)) else folders:
        for f in sorted(Path(folder).glob(pattern)):
            h.update(f.name.encode())
            with open(f, "rb") as fh:
                for chunk in iter(lambda: fh.read(1 << 20), b""):
                    h.update(chunk)
    return h.hexdigest()


def _foreign_archive(path: Path) -> str | None:
    """None when `path` is a zip archive as torch.save writes it (an entry <name>/data.pkl); else what it is instead,
    as a clause for an error message ('' when it is no zip archive at all)."""
    if not zipfile.is_zipfile(path):
        return ""
    with zipfile.ZipFile(path) as zf:
        names = zf.namelist()
    if any(n.endswith("/data.pkl") or n == "data.pkl" for n in names):
        return None
    if names and all(n.endswith(".npy") for n in names):
        return "; this is a NumPy .npz archive, not a torch file"
    return "; this zip archive has no data.pkl entry"


def code_version(root: str | Path | None = None) -> str:
    """A short content hash of the Python sources under `root` (default: graspkit's own; relative names and bytes),
    kept in every training state so that a run resumed by other code says so."""
    return _code_version(Path(root or Path(__file__).resolve().parent).resolve())


@functools.lru_cache(maxsize=4)
def _code_version(root: Path) -> str:
    """code_version of one folder (read once per process: the sources do not change under a running program)."""
    import hashlib

    h = hashlib.blake2b(digest_size=6)
    for f in sorted(root.rglob("*.py")):
        h.update(f.relative_to(root).as_posix().encode() + b"\0" + f.read_bytes() + b"\0")
    return h.hexdigest()


def load_checkpoint(path: str | Path) -> dict[str, Any]:
    """Read a checkpoint without pickle (weights_only); a missing or foreign file gives an error naming it."""
    path = Path(path)
    if path.is_dir():
        raise IsADirectoryError(f"checkpoint: {path} is a folder, expected a checkpoint file (.pt)")
    if not path.is_file():
        raise FileNotFoundError(f"checkpoint: no file at {path}")
    if zipfile.is_zipfile(path):             # torch.load does not check the archive's CRCs: bytes changed in place
        try:
            with zipfile.ZipFile(path) as zf:
                bad = zf.testzip()
        except Exception as e:  # noqa: BLE001 - a broken entry header
            bad = f"? ({e})"
        if bad is not None:
            raise ValueError(f"checkpoint {path}: damaged (its entry {bad} fails its checksum)")
    try:
        state = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as e:  # noqa: BLE001 - re-raised with the file named
        foreign = _foreign_archive(path)
        if foreign is not None:
            raise ValueError(f"checkpoint {path}: not a torch checkpoint (expected the zip archive torch.save "
                             f"writes{foreign})") from e
        # torch's message suggests weights_only=False; graspkit never unpickles, so keep only what the file holds
        detail = (str(e).split("WeightsUnpickler error:", 1)[-1].strip() or type(e).__name__).splitlines()[0]
        raise ValueError(f"checkpoint {path}: holds more than tensors, numbers, strings and plain containers, "
                         f"so it cannot be read without pickle ({detail})") from e
    if not isinstance(state, dict):
        raise ValueError(f"checkpoint {path}: expected a graspkit checkpoint (a dict of weights and settings), "
                         f"got a {type(state).__name__}")
    weights = state.get("model")
    if isinstance(weights, dict):   # a diverged run's weights would load silently and make NaN bodies
        bad = [k for k, v in weights.items() if torch.is_tensor(v) and v.is_floating_point()
               and not torch.isfinite(v).all()]
        if bad:
            raise ValueError(f"checkpoint {path}: {len(bad)} weight tensors hold NaN or infinite values "
                             f"({', '.join(bad[:3])}{', ...' if len(bad) > 3 else ''}; a diverged training run?)")
    return state


def load_into(model: torch.nn.Module, weights: dict[str, Any], path: str | Path, what: str) -> torch.nn.Module:
    """`model` with `weights` (a state dict read from checkpoint `path`) loaded; a ValueError naming the file and
    `what` it should hold when the weights are another model's or another size's."""
    try:
        model.load_state_dict(weights)
    except RuntimeError as e:
        raise ValueError(f"checkpoint {path}: not {what} of this configuration ({state_dict_problem(e)})") from None
    return model


def build_named(path: str | Path, what: str, build: Callable[[], M]) -> M:
    """build() (a model made from checkpoint `path`'s config and weights); a ValueError naming the file and `what` it
    should hold when a config value or a weight does not fit (a wrong type fails deep inside torch otherwise)."""
    try:
        return build()
    except (TypeError, ValueError, KeyError, AttributeError, RuntimeError) as e:
        if str(path) in str(e):
            raise
        raise ValueError(f"checkpoint {path}: not {what} ({type(e).__name__}: {e})") from None


def check_config(config: Any, config_cls: type, path: str | Path, what: str) -> None:
    """ValueError naming checkpoint `path` unless `config` is a dict whose entries are fields of dataclass
    `config_cls` (a checkpoint of another model would otherwise fail inside the constructor, unnamed)."""
    from dataclasses import fields

    known = {f.name for f in fields(config_cls)}
    if not isinstance(config, dict) or not set(config) <= known:
        odd = sorted(set(config) - known) if isinstance(config, dict) else type(config).__name__
        raise ValueError(f"checkpoint {path}: not {what} (config entries {odd} are not {config_cls.__name__}'s)")


def state_dict_problem(e: Exception) -> str:
    """The line of load_state_dict's error that says which key or size differs (its first line only says
    "Error(s) in loading state_dict")."""
    lines = [s.strip() for s in str(e).splitlines() if s.strip()] or [type(e).__name__]
    return lines[1] if len(lines) > 1 else lines[0]


def init_distributed() -> bool:
    """Join the process group that `torchrun` describes (env WORLD_SIZE > 1), with the gloo backend: `fit` trains on
    the CPU. Returns whether training is distributed. Call once at the start of a script run with torchrun."""
    if int(os.environ.get("WORLD_SIZE", "1")) <= 1 or not torch.distributed.is_available():
        return False
    if not torch.distributed.is_initialized():
        torch.distributed.init_process_group("gloo")
    return True


def _distributed() -> tuple[bool, int, int]:
    """(initialised, rank, world size) of torch.distributed."""
    if torch.distributed.is_available() and torch.distributed.is_initialized():
        return True, torch.distributed.get_rank(), torch.distributed.get_world_size()
    return False, 0, 1


def _agree(flag: bool) -> bool:
    """Rank 0's decision (e.g. the time limit) for every rank, so that all ranks stop at the same epoch."""
    t = torch.tensor([int(flag)])
    torch.distributed.broadcast(t, src=0)
    return bool(t.item())


def _has_batchnorm(model: torch.nn.Module) -> bool:
    """Whether any layer of `model` is a BatchNorm (which cannot train on a batch of one sample)."""
    return any(isinstance(m, torch.nn.modules.batchnorm._BatchNorm) for m in model.modules())


def _loader(dataset: Dataset, cfg: TrainConfig, epoch: int, world: tuple[bool, int, int],
            no_single: bool = False) -> DataLoader:
    """A DataLoader whose order depends only on (seed, epoch), sharded across ranks under DDP.

    no_single: drop a last batch of one sample (BatchNorm models: a one-row batch cannot be normalised in training;
    the order is shuffled each epoch, so a different sample sits out each time)."""
    dist, rank, size = world
    g = torch.Generator().manual_seed(cfg.seed + epoch)
    if dist:
        sampler = torch.utils.data.DistributedSampler(dataset, num_replicas=size, rank=rank, shuffle=True,
                                                      seed=cfg.seed, drop_last=False)
        sampler.set_epoch(epoch)
        drop = no_single and len(sampler) % cfg.batch_size == 1
        return DataLoader(dataset, batch_size=cfg.batch_size, sampler=sampler, drop_last=drop)
    drop = no_single and len(dataset) % cfg.batch_size == 1  # type: ignore[arg-type]
    return DataLoader(dataset, batch_size=cfg.batch_size, shuffle=True, generator=g, drop_last=drop)


def batch_len(batch: Any) -> int:
    """Samples in a batch: the leading size of its first tensor (a tensor, or one inside a dict / list / tuple)."""
    if isinstance(batch, torch.Tensor):
        return len(batch) if batch.dim() else 1
    items = batch.values() if isinstance(batch, dict) else batch if isinstance(batch, (list, tuple)) else ()
    for x in items:
        n = batch_len(x)
        if n:
            return n
    return 0


def _add_logs(sums: dict[str, float], logs: dict[str, Any], weight: int) -> None:
    """Accumulate step logs (batch means) weighted by the batch's size (in place)."""
    for k, v in logs.items():
        sums[k] = sums.get(k, 0.0) + weight * float(v.detach() if isinstance(v, torch.Tensor) else v)


def evaluate(model: torch.nn.Module, step: StepFn, dataset: Dataset, cfg: TrainConfig, epoch: int = 0
             ) -> dict[str, float]:
    """Per-sample mean of step's logs over `dataset` (each batch's means weighted by its size, so a short last
    batch counts as its samples) in eval mode (the model's mode restored after), without gradients (fixed order)."""
    sums: dict[str, float] = {}
    n = 0
    with torch.no_grad(), evaluating(model):
        for batch in DataLoader(dataset, batch_size=cfg.batch_size, shuffle=False):
            w = batch_len(batch) or 1
            _add_logs(sums, step(model, batch, epoch), w)
            n += w
    return {k: v / max(n, 1) for k, v in sums.items()}


def write_history_csv(path: str | Path, history: list[dict[str, float]]) -> Path:
    """Per-epoch logs (train and val_ columns) to a CSV file, written atomically."""
    path = Path(path)
    check_suffix(path, ".csv")
    keys = list(dict.fromkeys(k for h in history for k in h))
    return write_atomic(path, ",".join(keys) + "\n" + "".join(",".join(f"{h.get(k, float('nan')):.6g}" for k in keys)
                                                              + "\n" for h in history))


def plot_history(history: list[dict[str, float]], keys: list[str] | None = None, ax: Any = None) -> Any:
    """Train / validation curves of the logged terms against the epoch (log scale where positive); returns the axes."""
    import matplotlib.pyplot as plt

    keys = keys or [k for k in history[0] if k != "epoch" and not k.startswith("val_")]
    if ax is None:
        _, ax = plt.subplots(figsize=(5, 3))
    ep = [h["epoch"] for h in history]
    for k in keys:
        line, = ax.plot(ep, [h[k] for h in history], label=k)
        if f"val_{k}" in history[0]:
            ax.plot(ep, [h[f"val_{k}"] for h in history], "--", color=line.get_color(), label=f"val {k}")
    if all(h[k] > 0 for h in history for k in keys):
        ax.set_yscale("log")
    ax.set_xlabel("epoch")
    ax.set_ylabel("loss")
    ax.legend(fontsize=7)
    return ax


def write_history_plot(path: str | Path, history: list[dict[str, float]]) -> Path:
    """`plot_history` of the loss (train and val) to a PNG, written atomically (beside a run's CSV)."""
    import io

    from matplotlib.figure import Figure

    check_suffix(path, ".png")
    fig = Figure(figsize=(5, 3), layout="constrained")
    plot_history(history, ["loss"], ax=fig.add_subplot())
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100)
    return write_atomic(path, buf.getvalue())


@with_autograd
@keeps_torch_state
def fit(model: torch.nn.Module, step: StepFn, dataset: Dataset, cfg: TrainConfig,
        checkpoint: str | Path | None = None, extra: dict[str, Any] | None = None,
        val_dataset: Dataset | None = None,
        progress: bool = True, time_limit_s: float | None = None, stop_at: int | None = None,
        ddp: bool = True) -> list[dict[str, float]]:
    """Train `model` with `step(model, batch, epoch) -> {'loss': ..}`; returns per-epoch mean logs.

    With `checkpoint`, an existing file is resumed from and the file is rewritten after every epoch (with
    `extra`, e.g. normalisation statistics). `time_limit_s` stops after the epoch that crosses the limit,
    `stop_at` after that epoch (both leave a checkpoint to resume from). With `val_dataset`, each epoch also logs
    `val_<term>`; the history goes to `<checkpoint>.csv` beside the checkpoint (every epoch) and its loss curves to
    `<checkpoint>.png` (at the end). The logged terms are per-sample means over the epoch (each batch's means
    weighted by its size; under DDP summed over the ranks); a model with BatchNorm layers skips a last batch of one
    sample (shuffled each epoch, so another sample each time). Resuming refuses a file of another network or of other
    settings; a state already at `stop_at` returns its history without training. `ddp=False` marks a step that calls
    model methods other than `forward` (DDP synchronises only what runs through it): such a model is refused under
    an initialised process group instead of training out of step.
    """
    _check_fit(model, dataset, cfg, checkpoint, time_limit_s)
    if cfg.num_threads:
        torch.set_num_threads(cfg.num_threads)
    world = _distributed()
    if world[0] and not ddp:
        raise RuntimeError(f"fit: {type(model).__name__}'s training step calls methods other than forward, which "
                           "DistributedDataParallel does not synchronise; train it in one process (without torchrun)")
    torch.manual_seed(cfg.seed)
    net = torch.nn.parallel.DistributedDataParallel(model) if world[0] else model
    opt = torch.optim.AdamW(model.parameters(), lr=cfg.lr, weight_decay=cfg.weight_decay)
    sched = torch.optim.lr_scheduler.LambdaLR(opt, lambda e: cfg.lr_min_ratio + (1 - cfg.lr_min_ratio)
                                              * 0.5 * (1 + math.cos(math.pi * min(e / max(cfg.epochs, 1), 1.0))))
    history: list[dict[str, float]] = []
    start = 0
    if checkpoint is not None and Path(checkpoint).is_file():
        history, start = _resume(checkpoint, model, opt, sched, cfg)
        if stop_at is not None and start >= stop_at:         # already there (a run killed after saving that epoch)
            model.eval()
            return history
    no_single = _has_batchnorm(model)
    t0 = time.perf_counter()
    bar = tqdm(desc=type(model).__name__, unit="epoch", disable=hidden(progress) or world[1] != 0, initial=start,
               total=cfg.epochs)
    for epoch in range(start, cfg.epochs):
        history.append({"epoch": epoch + 1, **_train_epoch(net, step, dataset, cfg, epoch, opt, world, no_single)})
        sched.step()
        if val_dataset is not None:
            history[-1].update({f"val_{k}": v for k, v in evaluate(model, step, val_dataset, cfg, epoch).items()})
        bar.set_postfix(loss=f"{history[-1]['loss']:.4f}", refresh=False)
        bar.update(1)
        if checkpoint is not None and world[1] == 0:
            save_checkpoint(checkpoint, {"model": model.state_dict(), "optimizer": opt.state_dict(),
                                         "scheduler": sched.state_dict(), "epoch": epoch + 1, "history": history,
                                         "rng": torch.get_rng_state(), "config": asdict(cfg), "extra": extra or {},
                                         "code": code_version()})
            write_history_csv(Path(checkpoint).with_suffix(".csv"), history)
        stop = (time_limit_s is not None and time.perf_counter() - t0 > time_limit_s) or epoch + 1 == stop_at
        if world[0]:
            stop = _agree(stop)
        if stop:
            break
    bar.close()
    if checkpoint is not None and world[1] == 0 and history:
        if Path(checkpoint) not in RUNS:
            RUNS.append(Path(checkpoint))
        # the CSV again: a run killed between an epoch's checkpoint and its CSV resumes past the loop
        write_history_csv(Path(checkpoint).with_suffix(".csv"), history)
        write_history_plot(Path(checkpoint).with_suffix(".png"), history)
    if world[0]:
        torch.distributed.barrier()      # no rank leaves (and tears down gloo) while rank 0 still writes
    model.eval()
    return history


def _check_fit(model: torch.nn.Module, dataset: Dataset, cfg: TrainConfig, checkpoint: str | Path | None,
               time_limit_s: float | None) -> None:
    """fit's arguments, before anything trains (ValueError naming the argument and what was expected)."""
    if len(dataset) == 0:
        raise ValueError("dataset: empty")
    if _has_batchnorm(model) and len(dataset) < 2:
        raise ValueError(f"dataset: {type(model).__name__} has BatchNorm layers, which need at least 2 samples to "
                         f"train on; got {len(dataset)}")
    if _has_batchnorm(model) and cfg.batch_size < 2:
        raise ValueError(f"batch_size: {type(model).__name__} has BatchNorm layers, which cannot train on batches of "
                         f"one sample; expected at least 2, got {cfg.batch_size}")
    if time_limit_s is not None and not (isinstance(time_limit_s, (int, float)) and time_limit_s > 0):
        raise ValueError(f"time_limit_s: expected None or a positive number of seconds, got {time_limit_s!r}")
    if checkpoint is not None and (Path(checkpoint).is_dir() or Path(checkpoint).parent.is_file()):
        what = "a folder" if Path(checkpoint).is_dir() else f"in {Path(checkpoint).parent}, which is a file"
        raise ValueError(f"checkpoint: {checkpoint} is {what}; expected the path of a checkpoint file (.pt)")


def _resume(checkpoint: str | Path, model: torch.nn.Module, opt: torch.optim.Optimizer,
            sched: torch.optim.lr_scheduler.LRScheduler, cfg: TrainConfig) -> tuple[list[dict[str, float]], int]:
    """Load fit's training state from `checkpoint` into model, opt, sched and torch's RNG; its history and epoch.
    Refuses (ValueError naming the file) a damaged file, a weights file, another network or other settings."""
    try:
        state = load_checkpoint(checkpoint)
    except ValueError as e:                  # a run file cut short by a full disk, say: every rerun would stop here
        raise ValueError(f"{e}; delete it (graspkit's run file) or pass another path to train anew") from None
    if not all(k in state for k in ("model", "optimizer", "scheduler", "history", "epoch", "rng")):
        raise ValueError(f"checkpoint {checkpoint}: not a training state of graspkit.train.fit (a weights file?); "
                         "delete it (graspkit's run file) or pass another path to train anew")
    ours = {k: tuple(v.shape) for k, v in model.state_dict().items()}
    theirs = {k: tuple(v.shape) for k, v in state["model"].items()}
    if ours != theirs:
        raise ValueError(f"checkpoint {checkpoint}: holds another network than {type(model).__name__} (its weights "
                         f"differ in {sorted(set(ours.items()) ^ set(theirs.items()))[:3]}...); delete "
                         "it (graspkit's run file) or pass another path to train anew")
    saved = {k: v for k, v in state.get("config", {}).items() if k not in ("num_threads", "extra")}
    now = {k: v for k, v in asdict(cfg).items() if k not in ("num_threads", "extra")}
    if saved and saved != now:
        differ = ", ".join(f"{k} {saved.get(k)!r} there, {now[k]!r} here" for k in now if saved.get(k) != now[k])
        raise ValueError(f"checkpoint {checkpoint}: a run with other settings ({differ}); delete it (graspkit's "
                         "run file) or pass another path to train anew")
    code, code_now = state.get("code"), code_version()
    if code != code_now:                  # the same settings, other code: the user decides whether the change matters
        import warnings

        from graspkit.checks import GraspkitWarning, user_stacklevel

        written = f"other graspkit sources ({code}, now {code_now})" if code else "graspkit of before 2026-12-07, " \
            "which did not record its sources"
        warnings.warn(f"checkpoint {checkpoint}: a training state written by {written}; resuming it continues that "
                      "run with this code (delete it, graspkit's run file, or pass another path to train anew)",
                      GraspkitWarning, stacklevel=user_stacklevel())
    model.load_state_dict(state["model"])
    opt.load_state_dict(state["optimizer"])
    sched.load_state_dict(state["scheduler"])
    torch.set_rng_state(state["rng"])
    return list(state["history"]), int(state["epoch"])


def _train_epoch(net: torch.nn.Module, step: StepFn, dataset: Dataset, cfg: TrainConfig, epoch: int,
                 opt: torch.optim.Optimizer, world: tuple[bool, int, int], no_single: bool) -> dict[str, float]:
    """One epoch of `step` over the dataset's batches (AdamW, gradients clipped at cfg.grad_clip); the logged terms'
    per-sample means (each batch's means weighted by its size; under DDP over every rank's samples)."""
    model = net.module if isinstance(net, torch.nn.parallel.DistributedDataParallel) else net
    model.train()
    sums: dict[str, float] = {}
    n = 0
    for batch in _loader(dataset, cfg, epoch, world, no_single):
        logs = step(net, batch, epoch)
        opt.zero_grad(set_to_none=True)
        logs["loss"].backward()
        if cfg.grad_clip:
            torch.nn.utils.clip_grad_norm_(model.parameters(), cfg.grad_clip)
        opt.step()
        w = batch_len(batch) or 1
        _add_logs(sums, logs, w)
        n += w
    if world[0]:                                      # every rank's samples, not rank 0's shard alone
        keys = sorted(sums)
        t = torch.tensor([sums[k] for k in keys] + [n], dtype=torch.float64)
        torch.distributed.all_reduce(t)
        sums, n = dict(zip(keys, t[:-1].tolist())), t[-1].item()
    return {k: v / n for k, v in sums.items()}
