"""Torch datasets over graspkit's GRAB-style grasp files, for SAGA's WholeGrasp-VAE, GOAL's GNet and the approach
models (SAGA's MotionFill-VAE, GOAL's MNet). Splits by object: graspkit.data.grasp.SPLITS (docs/grasps.md).

    from graspkit.data.grasp_datasets import WholeGraspDataset, GNetDataset, ApproachDataset
    ds = WholeGraspDataset("~/.cache/graspkit/grasps/grasp", split="train")
    ds[0]["markers"].shape          # (143, 3), centred at the object (SAGA App. A.3)

Every dataset reads all its files once (no pickle) into float32 tensors and returns dicts of tensors; keys and
shapes are listed in each class docstring and in docs/grasps.md.
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import torch
from torch.utils.data import Dataset

from graspkit.data.formats import clip_files, npz_arrays, open_npz
from graspkit.data.grab import read_arrays
from graspkit.data.grasp import SPLITS, file_split
from graspkit.rotations import axis_angle_to_matrix, axis_angle_to_rot6d

if TYPE_CHECKING:
    from graspkit.body import BodyModel

SAGA_CLIP_FRAMES = 62        # SAGA App. A.3: 2-s clips at 30 fps ending in a stable grasp; 62 = MotionFill's T + 2
                             # root states (T = 60: 61 marker frames, docs/data.md)


def grasp_files(root: str | os.PathLike, kind: str = "grasp", split: str | None = None,
                accepted_only: bool = True) -> list[Path]:
    """Sorted `<root>/<kind>_*.npz` files, optionally of one split ('train' / 'val' / 'test') and accepted grasps only."""
    root = Path(root).expanduser()
    if split is not None and split not in SPLITS:
        raise ValueError(f"split: expected one of {tuple(SPLITS)} or None, got {split!r}")
    if not root.is_dir():
        raise FileNotFoundError(f"root: no such folder {root} (make the data with `graspkit data make --kind {kind}`)")
    out = []
    for p in clip_files(root, kind):
        with open_npz(p, f"{'an' if kind[0] in 'aeiou' else 'a'} {kind} file (graspkit data make --kind {kind})") as z:
            if "obj_name" not in z.files:
                raise ValueError(f"{p}: missing key 'obj_name' (expected a {kind} file of graspkit data make)")
            a = npz_arrays(z, ["obj_name"] + (["grasp.accepted"] if "grasp.accepted" in z.files else []), p)
            name = str(a["obj_name"])
            ok = bool(a["grasp.accepted"]) if "grasp.accepted" in a else True
        if (split is None or file_split(name, p) == split) and (ok or not accepted_only):
            out.append(p)
    return out


def moved_since_labels(a: dict[str, np.ndarray]) -> np.ndarray:
    """How far (m, (3,)) a file's scene was moved as a whole since `graspkit data make` labelled it: the object's
    translation at the grasp frame minus `goal.object_transl` (zeros without that key). The world-frame labels
    (`saga.markers`, `goal.vertices`) are where the body was then; adding this puts them where it is now, so a clip
    moved along the floor, body and object (which `grab.body_offset` takes as the same body's), keeps its markers,
    GOAL vertices and hand-to-goal offsets on its body (they were off by the move)."""
    from graspkit.data.grab import grasp_frame

    if "goal.object_transl" not in a or "object.params.transl" not in a:
        return np.zeros(3)
    obj = np.asarray(a["object.params.transl"], np.float64).reshape(-1, 3)
    f = min(max(grasp_frame(a), 0), len(obj) - 1)
    return obj[f] - np.asarray(a["goal.object_transl"], np.float64).reshape(3)


def _rot(aa: np.ndarray) -> np.ndarray:
    """Rotation matrix (3,3) of an axis-angle vector (3,)."""
    return axis_angle_to_matrix(torch.as_tensor(np.asarray(aa, np.float64))).numpy()


# the shapes of the keys the datasets read (docs/grasps.md's file table); "T": the file's frames, None: any size
SHAPES: dict[str, tuple[int | str | None, ...]] = {
    "body.params.fullpose": ("T", 165), "body.params.transl": ("T", 3), "body.betas": (10,),
    "object.params.transl": ("T", 3), "object.params.global_orient": ("T", 3), "object.points": (None, 3),
    "object.normals": (None, 3), "object.height": (), "saga.markers": (143, 3), "contact.markers": ("T", 143),
    "contact.object": ("T", None), "contact.feet": ("T", 4), "grasp.goal_frame": (),
    "goal.vertices": (400, 3), "goal.offsets": (400, 3), "goal.hand_offsets": (99, 3), "goal.head_direction": (3,),
    "goal.bps_object": (1024,), "goal.bps_hand": (1024,), "goal.right_hand": (99,), "goal.vertex_ids": (400,),
    "goal.object_transl": (3,),
    "body.params.body_pose": ("T", 63), "contact.body": ("T", None), "obj_name": ()}
STRING_KEYS = {"obj_name"}


def read_checked(path: Path, keys: tuple[str, ...]) -> dict[str, np.ndarray]:
    """A graspkit data file's arrays (read_arrays), `keys` checked by check_arrays."""
    a = read_arrays(path)
    check_arrays(a, keys, path)
    return a


def check_arrays(a: dict[str, np.ndarray], keys: tuple[str, ...], path: Path) -> None:
    """ValueError naming `path` and the key when one of `keys` is missing from a file's arrays `a`, has another shape
    than SHAPES gives, holds no numbers (a string where STRING_KEYS do not list it), a NaN or an inf (a model trained
    on it would learn NaN weights without any other sign), a contact label other than 0 / 1, or a goal frame outside
    the clip."""
    T = len(a["body.params.fullpose"]) if "body.params.fullpose" in a else None
    for k in keys:
        if k not in a:
            raise ValueError(f"{path}: missing key {k!r} (expected a file of `graspkit data make`)")
        v = a[k]
        if v.dtype.kind not in ("US" if k in STRING_KEYS else "biuf"):
            raise ValueError(f"{path}: key {k!r} holds {v.dtype} values, expected "
                             + ("a string" if k in STRING_KEYS else "numbers"))
        want = tuple(T if d == "T" else d for d in SHAPES.get(k, (None,) * v.ndim))
        if v.ndim != len(want) or any(d is not None and d != n for d, n in zip(want, v.shape)):
            shown = "(" + ", ".join("any" if d is None else str(d) for d in want) + ("," if len(want) == 1 else "") + ")"
            raise ValueError(f"{path}: key {k!r} has shape {v.shape}, expected {shown}")
        if v.dtype.kind in "fc" and not np.isfinite(v).all():
            raise ValueError(f"{path}: key {k!r} holds {int((~np.isfinite(v)).sum())} NaN or infinite values")
    for k in keys:
        if k.startswith("contact.") and not np.isin(a[k], (0, 1)).all():
            raise ValueError(f"{path}: key {k!r} holds values other than 0 and 1, expected contact labels")
    if "grasp.goal_frame" in keys and T is not None:
        g = float(a["grasp.goal_frame"])
        if g % 1 or not 0 <= g < T:
            raise ValueError(f"{path}: key 'grasp.goal_frame' is {a['grasp.goal_frame']}, expected a whole frame "
                             f"number in [0, {T})")
    if "goal.right_hand" in keys and not ((a["goal.right_hand"] >= 0) & (a["goal.right_hand"] < 400)).all():
        raise ValueError(f"{path}: key 'goal.right_hand' holds positions outside [0, 400)")


class _Files(Dataset):
    """Common part: the file list, the object names and their indices in graspkit.objects.list_objects(); every
    file's `keys` are checked present and finite."""

    kind = "grasp"
    keys: tuple[str, ...] = ()

    def __init__(self, root: str | os.PathLike, split: str | None = "train", accepted_only: bool = True) -> None:
        from graspkit.objects.catalogue import list_objects

        self.files = grasp_files(root, self.kind, split, accepted_only)
        if not self.files:
            raise ValueError(f"root: no {self.kind} files of split {split!r} in {root}")
        self.split = split
        self.arrays = [read_arrays(p) for p in self.files]
        for p, a in zip(self.files, self.arrays):
            check_arrays(a, self.keys + (("goal.object_transl",) if "goal.object_transl" in a else ()), p)
        self.object_names = [str(a["obj_name"]) for a in self.arrays]
        names = list_objects()
        for p, n in zip(self.files, self.object_names):
            if n not in names:
                raise ValueError(f"{p}: key 'obj_name' is {n!r}, not an object of the catalogue ({', '.join(names)})")
        self.object_ids = torch.tensor([names.index(n) for n in self.object_names])

    def __len__(self) -> int:
        return len(self.files)


class WholeGraspDataset(_Files):
    """SAGA's WholeGrasp-VAE data (Sec. 3.2, App. A.3): one static grasp per item, centred at the object's centre.

    Keys: markers (143,3), marker_contacts (143,) C_M, object_points (2048,3), object_normals (2048,3),
    object_contacts (2048,) C_O, object_height () t_O, betas (10,), object_id () (index in list_objects()).
    Positions are world-oriented (z up) minus the object translation; the object is rotated by its pose."""

    keys = ("object.params.transl", "object.params.global_orient", "saga.markers", "contact.markers", "object.points",
            "object.normals", "contact.object", "object.height", "body.betas")

    def __init__(self, root: str | os.PathLike, split: str | None = "train", accepted_only: bool = True) -> None:
        super().__init__(root, split, accepted_only)
        m, cm, op, on, co, h, b = [], [], [], [], [], [], []
        for a in self.arrays:
            t = a["object.params.transl"][0].astype(np.float64)
            R = _rot(a["object.params.global_orient"][0])
            m.append(a["saga.markers"] + moved_since_labels(a) - t)
            cm.append(a["contact.markers"][0])
            op.append(a["object.points"] @ R.T)
            on.append(a["object.normals"] @ R.T)
            co.append(a["contact.object"][0])
            h.append(a["object.height"])
            b.append(a["body.betas"])
        f = lambda x: torch.as_tensor(np.stack(x), dtype=torch.float32)  # noqa: E731
        self.data = {"markers": f(m), "marker_contacts": f(cm), "object_points": f(op), "object_normals": f(on),
                     "object_contacts": f(co), "object_height": f(h), "betas": f(b)}

    def __getitem__(self, i: int) -> dict[str, torch.Tensor]:
        return {**{k: v[i] for k, v in self.data.items()}, "object_id": self.object_ids[i]}


class GNetDataset(_Files):
    """GOAL's GNet data (Sec. 3.3, Eq. 2-3): one static grasp per item, in the world frame of its task (the person
    started at the origin facing -y, z up; the object translation is gamma^o).

    Keys: fullpose (55,3) axis-angle (absolute hand poses), fullpose_6d (55,6), transl (3,), betas (10,),
    verts (400,3) sampled vertices, offsets (400,3) vertex -> closest object point, hand_offsets (99,3) (the right-hand
    rows of offsets), head_dir (3,) q, object_transl (3,), object_orient (3,) axis-angle, bps_object (1024,),
    bps_hand (1024,) the hand's BPS with the same basis, object_height (), object_id ()."""

    keys = ("body.params.fullpose", "body.params.transl", "body.betas", "goal.vertices", "goal.offsets",
            "goal.hand_offsets", "goal.head_direction", "object.params.transl", "object.params.global_orient",
            "goal.bps_object", "goal.bps_hand", "object.height", "goal.right_hand", "goal.vertex_ids")

    def __init__(self, root: str | os.PathLike, split: str | None = "train", accepted_only: bool = True) -> None:
        super().__init__(root, split, accepted_only)
        keys = {"fullpose": ("body.params.fullpose", (55, 3)), "transl": ("body.params.transl", (3,)),
                "betas": ("body.betas", (10,)), "verts": ("goal.vertices", (400, 3)), "offsets": ("goal.offsets", (400, 3)),
                "hand_offsets": ("goal.hand_offsets", (99, 3)), "head_dir": ("goal.head_direction", (3,)),
                "object_transl": ("object.params.transl", (3,)), "object_orient": ("object.params.global_orient", (3,)),
                "bps_object": ("goal.bps_object", (1024,)), "bps_hand": ("goal.bps_hand", (1024,)),
                "object_height": ("object.height", ())}
        self.data = {k: torch.as_tensor(np.stack([np.asarray(a[src], np.float32).reshape(shape) for a in self.arrays]))
                     for k, (src, shape) in keys.items()}
        moved = np.stack([moved_since_labels(a) for a in self.arrays])
        self.data["verts"] += torch.as_tensor(moved, dtype=torch.float32)[:, None]
        self.data["fullpose_6d"] = axis_angle_to_rot6d(self.data["fullpose"])
        for key in ("goal.vertex_ids", "goal.right_hand"):      # one GOAL layout for the whole set
            for p, a in zip(self.files[1:], self.arrays[1:]):
                if not np.array_equal(a[key], self.arrays[0][key]):
                    raise ValueError(f"{p}: key {key!r} differs from {self.files[0].name}'s: files of another GOAL "
                                     "vertex layout (another body model) cannot share one GNetDataset")
        self.right_hand = torch.as_tensor(self.arrays[0]["goal.right_hand"])
        self.vertex_ids = torch.as_tensor(self.arrays[0]["goal.vertex_ids"])

    def __getitem__(self, i: int) -> dict[str, torch.Tensor]:
        return {**{k: v[i] for k, v in self.data.items()}, "object_id": self.object_ids[i]}


class ApproachDataset(_Files):
    """Approach-and-grasp clips for SAGA's MotionFill-VAE (App. A.3: 2-s clips ending in a stable grasp) and GOAL's
    MNet (Sec. 3.4: variable length, goal frame, goal hand BPS, hand-to-goal offsets).

    window=62 (default): every item is the LAST 62 frames of a clip (the first frame repeated in front when the clip
    is shorter, as SAGA pads); window=None: whole clips (variable T; use batch_size=1). With `bm` (a BodyModel), the
    per-frame GOAL vertices and SAGA's sparse markers are skinned once at load time.

    Keys: fullpose (T,55,3), fullpose_6d (T,55,6), transl (T,3), betas (10,), foot_contacts (T,4) [l heel, l toe,
    r heel, r toe], goal_frame () (index within the item; GOAL's goal frame = first frame of the held grasp),
    valid (T,) (False on padded frames), object_transl (3,), object_orient (3,), bps_object (1024,), bps_goal_hand
    (1024,), object_id (); with bm: verts (T,400,3), hand_to_goal (T,99,3) (GOAL's d^h_{t->g}: goal-frame hand
    vertex minus current), markers (T,79,3) (SAGA's stage-2 markers)."""

    kind = "approach"
    keys = ("body.params.fullpose", "body.params.transl", "body.betas", "grasp.goal_frame", "contact.feet",
            "object.params.transl", "object.params.global_orient", "goal.bps_object", "goal.bps_hand",
            "goal.vertex_ids", "goal.vertices", "goal.right_hand")

    def __init__(self, root: str | os.PathLike, split: str | None = "train", window: int | None = SAGA_CLIP_FRAMES,
                 bm: BodyModel | None = None, accepted_only: bool = True) -> None:
        super().__init__(root, split, accepted_only)
        if window is not None and (isinstance(window, (bool, np.bool_)) or not isinstance(window, (int, np.integer))
                                   or window < 2):
            raise ValueError(f"window: expected None or a whole number >= 2 frames, got {window!r}")
        self.window = None if window is None else int(window)
        self.items = [self._item(a, bm, p) for p, a in zip(self.files, self.arrays)]

    def _item(self, a: dict[str, np.ndarray], bm, path: Path) -> dict[str, torch.Tensor]:
        """One clip's tensors (windowed and padded as configured) from file `path`'s arrays `a`."""
        pose = np.asarray(a["body.params.fullpose"], np.float32).reshape(-1, 55, 3)
        T, g = len(pose), int(a["grasp.goal_frame"])
        if not 0 <= g < T:
            raise ValueError(f"{path}: key 'grasp.goal_frame' is {g}, expected a frame in [0, {T - 1}]")
        raw = np.arange(T) if self.window is None else np.arange(T - self.window, T)
        valid, sel, first = raw >= 0, np.maximum(raw, 0), int(raw[0])
        if g < first:
            raise ValueError(f"window: the last {self.window} frames of {path} ({T} frames) start after its goal "
                             f"frame {g}; expected a window of at least {T - g} frames (or None)")
        item = {"fullpose": torch.as_tensor(pose[sel]), "transl": torch.as_tensor(a["body.params.transl"][sel]),
                "betas": torch.as_tensor(a["body.betas"]), "foot_contacts": torch.as_tensor(a["contact.feet"][sel].astype(bool)),
                "goal_frame": torch.tensor(g - first),
                "valid": torch.as_tensor(valid), "object_transl": torch.as_tensor(a["object.params.transl"][0]),
                "object_orient": torch.as_tensor(a["object.params.global_orient"][0]),
                "bps_object": torch.as_tensor(a["goal.bps_object"]), "bps_goal_hand": torch.as_tensor(a["goal.bps_hand"])}
        item["fullpose_6d"] = axis_angle_to_rot6d(item["fullpose"])
        if bm is not None:
            from graspkit.body.markers import saga_sparse_markers
            from graspkit.data.grasp_opt import PartialBody, coeffs_of

            vid = np.asarray(a["goal.vertex_ids"])
            ids = np.concatenate([vid, saga_sparse_markers(bm).vertex_ids])
            pb = PartialBody(bm, ids)
            with torch.no_grad():
                v, _ = pb(axis_angle_to_matrix(item["fullpose"].to(bm.dtype)),
                          coeffs_of(bm, item["betas"].numpy()[None]).expand(len(sel), -1), item["transl"].to(bm.dtype))
            item["verts"] = v[:, :len(vid)].float()
            item["markers"] = v[:, len(vid):].float()
            rh = torch.as_tensor(a["goal.right_hand"])
            goal_hand = torch.as_tensor(a["goal.vertices"] + moved_since_labels(a), dtype=torch.float32)[rh]
            item["hand_to_goal"] = goal_hand[None] - item["verts"][:, rh]
        return item

    def __getitem__(self, i: int) -> dict[str, torch.Tensor]:
        return {**self.items[i], "object_id": self.object_ids[i]}
