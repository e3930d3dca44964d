"""WANDR's training data (§3.1-3.4, §4.1, Sup. B.2): clips as pose sequences, training windows with real or hindsight
goals, normalisation statistics, deterministic splits and the held-out start poses of the evaluation.

    clips = load_clips(list_clips(cache_dir() / "motion"), bm)        # AMASS-style locomotion + CIRCLE-style reaching
    split = split_clips(clips.names)                                   # {'train': [...], 'val': [...], 'test': [...]}
    train = clips.subset(split["train"])
    stats = compute_stats(train)                                       # mean / std of deltas, states, intentions
    ds = WindowDataset(train, max_steps=10)                            # items: (clip, frame) pairs
    batch = make_batch(train, ds_items, steps=4, generator=g)          # frames i-1 .. i+1+steps, goal, t_G, ...
    starts = held_out_starts(test_clips_or_motions, bm)                # 6 start poses (WANDR §4.2)

- Poses p_i (135) and deltas d_i (135, yaw removed) as `graspkit.intention` defines them (§3.2-3.3).
- Goals (§3.2, Fig. 3): CIRCLE-style clips carry a goal and its frame t_G; for goal-less (AMASS-style) clips a future
  frame is drawn as t_G and the right wrist there becomes the goal (hindsight, after Andrychowicz et al. 2017). The
  horizon is uniform over [steps + 1, min(240, frames left)] frames, so the 8 s test horizon is covered; t_G falls at
  the window's last frame at the earliest (a loss target, never a conditioned frame), so a goal-less walk is never
  taught "the goal time has passed, stand still". Frames at or
  after a real t_G get the zero intention (the reaching clips hold the pose there).
- The orientation intention in training uses the body's heading at t_G (§3.2).
- Filter (§4.1): clips whose feet (the lowest of the ankle and foot joints) are ever more than 20 cm above the ground
  are left out.
- Splits (§4.1: 80 / 10 / 10): by a hash of each clip's file name and the seed, so a clip keeps its split whatever
  else is in the folder.
"""
from __future__ import annotations

import hashlib
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Sequence

import numpy as np
import torch
from torch import Tensor
from torch.utils.data import Dataset

from graspkit import intention as I
from graspkit.body.skeleton import JOINT_INDEX
from graspkit.checks import check_int
from graspkit.data.formats import clip_files, load_motion, member_crcs, npz_arrays, open_npz
from graspkit.data.motion import Motion
from graspkit.paths import read_cache

if TYPE_CHECKING:
    from graspkit.body import BodyModel

MAX_FOOT_HEIGHT = 0.20          # m (WANDR §4.1)
HINDSIGHT_HORIZON = 240         # frames: the 8 s test horizon (§4.2)
SPLIT_FRACTIONS = (0.8, 0.1, 0.1)
FOOT_JOINTS = [JOINT_INDEX[n] for n in ("left_ankle", "right_ankle", "left_foot", "right_foot")]
KINDS = ("locomotion", "reach")
FOLDERS = {"locomotion": "locomotion", "reach": "reach", "reach_far": "reach",   # clip folder -> kind (reach_far:
           "reach_chain": "reach", "reach_near": "reach"}   # room-scale CIRCLE-style tasks; reach_chain: those from a
                                                            # finished reach; reach_near: near goals, floor or overhead)
STD_FLOOR = 1e-3
GOAL_FRAMES = ("reach", "hold")  # t_G of a reaching clip: the frame the hand arrives, or the end of the hold after it


@dataclass
class ClipSet:
    """Clips concatenated along frames: p (N, 135) float32, start offsets (C+1,), rest joints (C, 22, 3), betas (C, 10),
    goal (C, 3) and goal_frame (C,) (-1: no goal), kind (C,) (0 locomotion, 1 reach), names (C,)."""

    p: Tensor
    offsets: Tensor
    rest: Tensor
    betas: Tensor
    goal: Tensor
    goal_frame: Tensor
    kind: Tensor
    names: list[str]

    def __len__(self) -> int:
        return len(self.names)

    @property
    def lengths(self) -> Tensor:
        """Frames per clip (C,)."""
        return self.offsets[1:] - self.offsets[:-1]

    def clip(self, c: int) -> Tensor:
        """Poses (T, 135) of clip c."""
        return self.p[self.offsets[c]:self.offsets[c + 1]]

    def subset(self, names: Sequence[str]) -> "ClipSet":
        """The clips named `names`, in that order; an unknown name is an error."""
        where = {n: k for k, n in enumerate(self.names)}
        missing = [n for n in names if n not in where]
        if missing:
            raise ValueError(f"names: {len(missing)} not in this set, e.g. {missing[0]!r}")
        idx = [where[n] for n in names]
        parts = [self.clip(k) for k in idx]
        lengths = torch.tensor([len(q) for q in parts], dtype=torch.long)
        offsets = torch.cat([torch.zeros(1, dtype=torch.long), lengths.cumsum(0)])
        p = torch.cat(parts) if parts else self.p[:0]
        ix = torch.tensor(idx, dtype=torch.long)
        return ClipSet(p, offsets, self.rest[ix], self.betas[ix], self.goal[ix], self.goal_frame[ix], self.kind[ix],
                       list(names))

    def of_kind(self, kind: str) -> "ClipSet":
        """Only the clips of one kind ('locomotion' or 'reach')."""
        if kind not in KINDS:
            raise ValueError(f"kind: expected one of {KINDS}, got {kind!r}")
        k = KINDS.index(kind)
        return self.subset([n for n, c in zip(self.names, self.kind.tolist()) if c == k])


def list_clips(folder: str | Path, kinds: Sequence[str] = KINDS, limit: int | None = None) -> list[Path]:
    """The clip files `<folder>/<sub>/<sub>_*.npz` (`formats.clip_files`, sorted: never another kind's, so a reach
    clip written into locomotion/ is not taken for locomotion) of the sub-folders `kinds` (of locomotion, reach
    and the opt-in reach_far, reach_chain and reach_near; a missing one is skipped), at most `limit` per sub-folder."""
    folder = Path(folder)
    out: list[Path] = []
    for kind in kinds:
        if kind not in FOLDERS:
            raise ValueError(f"kinds: expected names from {tuple(FOLDERS)}, got {kind!r}")
        files = clip_files(folder / kind, kind)
        out += files[:limit] if limit is not None else files
    if not out:
        raise FileNotFoundError(f"folder: no clips under {folder}/{{{','.join(kinds)}}}/<kind>_*.npz "
                                "(make them with `graspkit data make --kind locomotion` and `--kind reach`)")
    return out


def shaped_rest(bm: BodyModel, betas: np.ndarray | Tensor) -> tuple[Tensor, Tensor]:
    """Shaped rest vertices (B, V, 3) and joints (B, 55, 3), in bm's dtype, for betas (B, k) (no expression)."""
    b = torch.as_tensor(np.asarray(betas), dtype=bm.dtype).reshape(len(betas), -1)
    coeffs = torch.zeros(len(b), bm.num_betas + bm.num_expression, dtype=bm.dtype)
    k = min(bm.num_betas, b.shape[1])
    coeffs[:, :k] = b[:, :k]
    with torch.no_grad():
        return bm.shaped(coeffs)


def rest_joints(bm: BodyModel, betas: np.ndarray | Tensor) -> Tensor:
    """Shaped rest joints (B, 22, 3) float32 of the body joints for betas (B, k)."""
    return shaped_rest(bm, betas)[1][:, :I.NUM_BODY].float()


def lowest_foot(joints: Tensor) -> Tensor:
    """Height (...) of the lowest ankle / foot joint of body joints (..., 22, 3)."""
    return joints[..., FOOT_JOINTS, 2].amin(-1)


def feet_height(p: Tensor, rest: Tensor) -> Tensor:
    """Per frame (T,) the height of the lowest ankle / foot joint, for poses (T, 135) and rest joints (22, 3)."""
    with torch.no_grad():
        return lowest_foot(I.body_joints(p, rest))


def motion_kind(m: Motion) -> str:
    """'reach' for a clip with a right-hand goal (CIRCLE-style), else 'locomotion' (goal-less, AMASS-style)."""
    return "reach" if m.goal is not None and m.hand == "right" else "locomotion"


def clips_from_motions(motions: Sequence[Motion], names: Sequence[str], bm: BodyModel,
                       max_foot_height: float | None = MAX_FOOT_HEIGHT) -> ClipSet:
    """A ClipSet from Motion objects (30 fps, >= 3 frames); clips failing WANDR's foot filter are dropped."""
    if len(motions) != len(names):
        raise ValueError(f"names: {len(names)} names for {len(motions)} motions")
    keep_p, keep = [], []
    rest = rest_joints(bm, np.stack([m.betas[:10] for m in motions])) if motions else torch.zeros(0, 22, 3)
    for k, m in enumerate(motions):
        if abs(m.fps - I.FPS) > 1e-6:
            raise ValueError(f"motions[{k}] ({names[k]}): {m.fps} fps, expected {I.FPS} (load_motion resamples)")
        if m.num_frames < 3:
            continue
        p = I.pose_from_axis_angle(torch.as_tensor(m.trans), torch.as_tensor(m.poses)).float()
        if max_foot_height is not None and float(feet_height(p, rest[k]).max()) > max_foot_height:
            continue
        keep_p.append(p)
        keep.append(k)
    lengths = torch.tensor([len(q) for q in keep_p], dtype=torch.long)
    goal = torch.zeros(len(keep), 3)
    gf = torch.full((len(keep),), -1, dtype=torch.long)
    kind = torch.zeros(len(keep), dtype=torch.long)
    for j, k in enumerate(keep):
        m = motions[k]
        if motion_kind(m) == "reach":
            goal[j], gf[j], kind[j] = torch.as_tensor(m.goal), int(m.goal_frame), 1
    betas = torch.zeros(len(keep), 10)
    for j, k in enumerate(keep):
        b = torch.as_tensor(motions[k].betas[:10])
        betas[j, :len(b)] = b
    return ClipSet(torch.cat(keep_p) if keep_p else torch.zeros(0, I.POSE_DIM),
                   torch.cat([torch.zeros(1, dtype=torch.long), lengths.cumsum(0)]),
                   rest[keep] if keep else torch.zeros(0, I.NUM_BODY, 3), betas, goal, gf, kind,
                   [names[k] for k in keep])


def check_folders_made_on(bm: BodyModel, paths: Sequence[Path], arg: str) -> None:
    """Refuse clip files made on another body than bm: the first of each folder among `paths`
    (`made_on.check_clips_made_on`, its error naming `arg` and the folder, the folder's name as the kind)."""
    from graspkit.data.made_on import check_clips_made_on

    first: dict[Path, Path] = {}
    for p in paths:
        first.setdefault(p.parent, p)
    for folder, p in first.items():
        check_clips_made_on(bm, [p], f"{arg}: {folder}", folder.name)


def load_clips(paths: Sequence[str | Path], bm: BodyModel,
               max_foot_height: float | None = MAX_FOOT_HEIGHT, check: bool = True) -> ClipSet:
    """Load clip files (AMASS / CIRCLE-style .npz, resampled to 30 fps) into a ClipSet named '<kind folder>/<file>'.
    check: refuse clips made on another body than bm (`made_on.check_clips_made_on`, the first file of each folder)."""
    paths = [Path(p) for p in paths]
    if check:
        check_folders_made_on(bm, paths, "paths")
    motions = [load_motion(p) for p in paths]
    names = [f"{p.parent.name}/{p.name}" for p in paths]
    return clips_from_motions(motions, names, bm, max_foot_height)


def split_of(name: str, seed: int = 0, fractions: tuple[float, float, float] = SPLIT_FRACTIONS) -> str:
    """'train', 'val' or 'test' for a clip name: a hash of (seed, name) mapped to [0, 1) against the fractions."""
    h = hashlib.blake2b(f"{seed}:{name}".encode(), digest_size=8).digest()
    u = int.from_bytes(h, "little") / 2.0**64
    return "train" if u < fractions[0] else "val" if u < fractions[0] + fractions[1] else "test"


def split_clips(names: Sequence[str], seed: int = 0,
                fractions: tuple[float, float, float] = SPLIT_FRACTIONS) -> dict[str, list[str]]:
    """WANDR §4.1's 80/10/10 split of clip names (deterministic, independent of order and of the other names)."""
    if len(fractions) != 3 or abs(sum(fractions) - 1) > 1e-9 or min(fractions) < 0:
        raise ValueError(f"fractions: expected three non-negative numbers summing to 1, got {fractions}")
    out: dict[str, list[str]] = {"train": [], "val": [], "test": []}
    for n in names:
        out[split_of(n, seed, fractions)].append(n)
    return out


# ----------------------------------------------------------------------------------------------------- windows
class WindowDataset(Dataset):
    """Training items (clip, frame i) for every i with frames i-1 .. i+1+max_steps inside the clip: the model sees the
    state at i and predicts d_{i+1}, then rolls out up to max_steps more frames (Sup. B.2)."""

    def __init__(self, clips: ClipSet, max_steps: int = 10) -> None:
        max_steps = check_int(max_steps, "max_steps", 0)
        rows = []
        for c, T in enumerate(clips.lengths.tolist()):
            hi = T - 2 - max_steps               # i + 1 + max_steps <= T - 1
            if hi >= 1:
                i = torch.arange(1, hi + 1)
                rows.append(torch.stack([torch.full_like(i, c), i], 1))
        self.items = torch.cat(rows) if rows else torch.zeros(0, 2, dtype=torch.long)
        self.max_steps = max_steps

    def __len__(self) -> int:
        return len(self.items)

    def __getitem__(self, k: int) -> Tensor:
        return self.items[k]


def make_batch(clips: ClipSet, items: Tensor, steps: int, generator: torch.Generator | None = None,
               horizon: int = HINDSIGHT_HORIZON, goal_frame: str = "reach") -> dict[str, Tensor]:
    """Training windows for items (B, 2) = (clip, frame i): poses p (B, steps+3, 135) of frames i-1 .. i+1+steps,
    rest (B, 22, 3), goal (B, 3), the goal frame relative to i `t_goal` (B,) (frames), the heading at t_G `goal_heading`
    (B,), and `hindsight` (B,) bool. Goal-less clips draw t_G from `generator` (see the module docstring).
    goal_frame: t_G of a reaching clip, "reach" (its stored goal frame: the hand arrives) or "hold" (its last frame:
    the end of the hold that follows, so the clip reads "be at the goal by t_G and stay")."""
    if goal_frame not in GOAL_FRAMES:
        raise ValueError(f"goal_frame: expected one of {GOAL_FRAMES}, got {goal_frame!r}")
    steps = check_int(steps, "steps", 0)
    horizon = check_int(horizon, "horizon", 1)      # a horizon under steps + 1 puts t_G at the window's last frame
    items = torch.as_tensor(items, dtype=torch.long).reshape(-1, 2)
    c, i = items[:, 0], items[:, 1]
    if len(c) and not (0 <= int(c.min()) and int(c.max()) < len(clips)):
        raise ValueError(f"items: clip indices expected in [0, {len(clips)}), got {int(c.min())} .. {int(c.max())}")
    start = clips.offsets[c]
    T = clips.lengths[c]
    if (i < 1).any() or (i + 1 + steps > T - 1).any():
        raise ValueError(f"items: a window of {steps} steps does not fit in its clip")
    frames = start[:, None] + i[:, None] + torch.arange(-1, steps + 2)[None]
    p = clips.p[frames]
    rest = clips.rest[c]
    labelled = clips.goal_frame[c] >= 0
    # hindsight: t_G - i uniform over [steps + 1, min(horizon, T - 1 - i)], or steps + 1 when that range is empty
    # (the shipped chain's 240-step rollouts with the 240-frame horizon)
    lo = torch.full_like(i, steps + 1)
    hi = torch.minimum(torch.full_like(i, horizon), T - 1 - i)
    u = torch.rand(len(i), generator=generator)
    offset = lo + (u * (hi - lo + 1).float()).long().clamp(min=0).clamp(max=(hi - lo).clamp(min=0))
    labelled_tg = clips.goal_frame[c] if goal_frame == "reach" else T - 1
    tg_abs = torch.where(labelled, labelled_tg, i + offset)
    p_goal = clips.p[start + tg_abs]
    with torch.no_grad():
        wrist = I.body_joints(p_goal, rest)[:, I.WRIST]
    goal = torch.where(labelled[:, None], clips.goal[c], wrist)
    return {"p": p, "rest": rest, "goal": goal, "t_goal": tg_abs - i, "goal_heading": I.heading_of_pose(p_goal),
            "hindsight": ~labelled}


def window_condition(p: Tensor, d_prev: Tensor, rest: Tensor, goal: Tensor, frames_left: Tensor,
                     goal_heading: Tensor | None, joints: Tensor | None = None) -> tuple[Tensor, Tensor]:
    """(state (B, 268), intention (B, 7)) at poses p (B, 135) with `frames_left` (B,) frames to t_G."""
    state = I.state_features(p, d_prev)
    inten = I.intention_from_pose(p, rest, goal, frames_left.to(p.dtype) / I.FPS, goal_heading, joints)
    return state, inten


# ----------------------------------------------------------------------------------------------------- statistics
def compute_stats(clips: ClipSet, samples: int = 20000, seed: int = 0, goal_frame: str = "reach") -> dict[str, Tensor]:
    """Normalisation statistics of the training split: mean and std (floored at 1e-3) of the deltas (135,), the states
    (268,) over every frame, and of the intentions (7,) over `samples` windows (goals drawn as in training, with the
    run's `goal_frame` rule for t_G: `make_batch`)."""
    if len(clips) == 0:
        raise ValueError("clips: empty")
    samples = check_int(samples, "samples", 2)                # a std needs two
    # every frame i with a frame before and after it in its clip: delta d_{i+1} and state (p_i, d_i), in chunks
    start = clips.offsets[:-1].repeat_interleave(clips.lengths)
    end = clips.offsets[1:].repeat_interleave(clips.lengths)
    i = torch.arange(len(clips.p))
    mid = i[(i - 1 >= start) & (i + 1 < end)]
    d_all, s_all = [], []
    for chunk in mid.split(65536):
        prev, cur, nxt = clips.p[chunk - 1], clips.p[chunk], clips.p[chunk + 1]
        d_in = I.pose_to_delta(prev, cur)
        d_all.append(I.pose_to_delta(cur, nxt))
        s_all.append(I.state_features(cur, d_in))
    ds = WindowDataset(clips, max_steps=0)
    g = torch.Generator().manual_seed(seed)
    pick = torch.randint(len(ds), (min(samples, len(ds)),), generator=g)
    b = make_batch(clips, ds.items[pick], steps=0, generator=g, goal_frame=goal_frame)
    p1, p0 = b["p"][:, 1], b["p"][:, 0]
    _, inten = window_condition(p1, I.pose_to_delta(p0, p1), b["rest"], b["goal"], b["t_goal"], b["goal_heading"])

    def ms(chunks: list[Tensor], block: int = 64) -> tuple[Tensor, Tensor]:
        # float64 over every row, a block of columns at a time: all columns of a million frames at once in float64
        # (and std's temporaries) put a WANDR training run's peak at 4.3 GB, 2.8 GB so; the same result (checked)
        mean, std = [], []
        for a in range(0, chunks[0].shape[1], block):
            x = torch.cat([c[:, a:a + block] for c in chunks]).double()
            mean.append(x.mean(0))
            std.append(x.std(0, correction=1 if len(x) > 1 else 0))      # one row: 0 (then the floor), not NaN
        return torch.cat(mean).float(), torch.cat(std).clamp(min=STD_FLOOR).float()

    (dm, dsd), (sm, ssd), (im, isd) = ms(d_all), ms(s_all), ms([inten])
    return {"delta_mean": dm, "delta_std": dsd, "state_mean": sm, "state_std": ssd,
            "intention_mean": im, "intention_std": isd}


# ----------------------------------------------------------------------------------------------------- starts
def held_out_starts(motions: Sequence[Motion], names: Sequence[str], bm: BodyModel, n: int = 6,
                    frame: int = 1) -> list[I.StartPose]:
    """WANDR §4.2's held-out start poses: frame `frame` (with the frame before it for the dynamics) of the first n
    clips given (pass test-split clips, alternating kinds), each moved to the origin facing +x."""
    if len(motions) < n:
        raise ValueError(f"motions: {len(motions)} clips for {n} start poses")
    return [I.StartPose.from_motion(m, frame, bm, source=f"{nm}#{frame}").canonical()
            for m, nm in zip(motions[:n], names[:n])]


def test_start_names(clips_folder: str | Path, n: int = 6, seed: int = 0, split: str = "test") -> list[str]:
    """Names '<kind>/<file>' of the n start clips: `split` clips of the folder (test: the grid's; val: model
    selection's), alternating locomotion and reach."""
    per_kind = []
    for kind in KINDS:
        files = clip_files(Path(clips_folder, kind), kind)
        per_kind.append([f"{kind}/{f.name}" for f in files if split_of(f"{kind}/{f.name}", seed) == split])
    out = [nm for pair in zip(*per_kind) for nm in pair][:n]
    if len(out) < n:
        raise ValueError(f"clips_folder: only {len(out)} {split}-split start clips under {clips_folder}")
    return out


# ----------------------------------------------------------------------------------------------------- cache
_CLIPSET_KEYS = ("p", "offsets", "rest", "betas", "goal", "goal_frame", "kind")


def save_clipset(path: str | Path, clips: ClipSet) -> Path:
    """Write a ClipSet as a plain .npz (no pickle; names as a unicode array), atomically."""
    from graspkit.data.formats import write_npz_atomic

    arrays = {k: getattr(clips, k).numpy() for k in _CLIPSET_KEYS}
    arrays["names"] = np.array(clips.names, dtype=np.str_)
    path = Path(path)
    write_npz_atomic(path, arrays)
    return path


def load_clipset(path: str | Path) -> ClipSet:
    """Read save_clipset's file (allow_pickle=False)."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"path: no clip set at {path}")
    with open_npz(path, "a clip set (save_clipset)") as z:
        missing = [k for k in _CLIPSET_KEYS + ("names",) if k not in z.files]
        if missing:
            raise ValueError(f"{path}: missing keys {missing}")
        a = npz_arrays(z, _CLIPSET_KEYS + ("names",), path)
    _check_clipset(a, path)
    t = {k: torch.from_numpy(a[k].copy()) for k in _CLIPSET_KEYS}
    return ClipSet(names=[str(n) for n in a["names"]], **t)


def _check_clipset(a: dict[str, np.ndarray], path: Path) -> None:
    """ValueError naming `path` unless save_clipset's arrays agree: p (N, 135) finite, offsets rising from 0 to N,
    one row per clip in the others (finite; goal frames -1 or inside the clip)."""
    p, off = a["p"], a["offsets"]
    if p.ndim != 2 or p.shape[1] != 135 or p.dtype.kind != "f" or not np.isfinite(p).all():
        raise ValueError(f"{path}: key 'p' is {p.dtype} of shape {p.shape}, expected finite poses (N, 135)")
    if off.ndim != 1 or off.dtype.kind not in "iu" or len(off) < 1 or off[0] != 0 or off[-1] != len(p) \
            or (np.diff(off) < 0).any():
        raise ValueError(f"{path}: key 'offsets' is not whole numbers rising from 0 to {len(p)} (the frames of 'p')")
    C = len(off) - 1
    want = {"rest": (C, 22, 3), "betas": (C, 10), "goal": (C, 3), "goal_frame": (C,), "kind": (C,), "names": (C,)}
    for k, shape in want.items():
        if a[k].shape != shape or a[k].dtype.kind not in ("US" if k == "names" else "iuf") \
                or (a[k].dtype.kind == "f" and not np.isfinite(a[k]).all()):
            raise ValueError(f"{path}: key {k!r} is {a[k].dtype} of shape {a[k].shape}, expected {shape} "
                             + ("strings" if k == "names" else "finite numbers"))
    gf, lengths = a["goal_frame"], np.diff(off)
    for c in np.flatnonzero((gf != -1) & ((gf < 0) | (gf >= lengths)))[:1]:
        raise ValueError(f"{path}: key 'goal_frame' is {gf[c]} for clip {c} ({a['names'][c]}), expected -1 (no goal) "
                         f"or a frame in [0, {lengths[c]})")
    for c in np.flatnonzero(~np.isin(a["kind"], (0, 1)))[:1]:
        raise ValueError(f"{path}: key 'kind' is {a['kind'][c]} for clip {c} ({a['names'][c]}), expected 0 (locomotion) "
                         "or 1 (reach)")


# The clip code's version, part of every cached ClipSet's name: raise it when load_clips would give other arrays for
# the same files and body.
CLIPSET_VERSION = 1


def cached_clips(folder: str | Path, bm: BodyModel, limit: int | None = None, cache: str | Path | None = None,
                 kinds: Sequence[str] = KINDS) -> ClipSet:
    """All clips under `folder` (<kind>/*.npz for the sub-folders `kinds`, at most `limit` per kind) as a ClipSet, read
    from / written to a cache file named after the folder's file list with each file's member CRC-32s (read from the
    npz's zip directory, no decompression: a clip remade in place at the same size is new data), the body model
    (`bm.digest()`) and CLIPSET_VERSION (so new or changed clips, another body or another clip code rebuild it).
    Clips made on another body than bm are refused (`made_on.check_clips_made_on`, the first of each kind)."""
    files = list_clips(folder, kinds=kinds, limit=limit)
    listing = "\n".join(f"{f.parent.name}/{f.name}:{f.stat().st_size}:{member_crcs(f)}" for f in files)
    key = hashlib.blake2b(f"{listing}\nbody={bm.digest()};version={CLIPSET_VERSION}".encode(),
                          digest_size=6).hexdigest()
    if cache is None:
        from graspkit.paths import cache_dir
        cache = cache_dir() / "wandr"
    path = Path(cache) / f"clips_{len(files)}_{key}.npz"
    # their labels on bm: clips of another body are refused, not learnt (before the cache too: one written before
    # this check answers for any body)
    check_folders_made_on(bm, files, "folder")
    clips = read_cache(path, load_clipset)
    if clips is not None:
        return clips
    clips = load_clips(files, bm, check=False)
    save_clipset(path, clips)
    return clips
