"""GRAB-style grasp files: a whole-body SMPL-X sequence with an object, its per-frame pose and contact labels.

GRAB (Taheri et al., ECCV 2020; used by SAGA App. A.3 and GOAL Sec. 3.5) stores each sequence as an `.npz` of
pickled nested dictionaries (`body.params.*`, `object.params.*`, `contact.*`, `framerate`, `obj_name`, ...).
graspkit writes the same tree WITHOUT pickle: every leaf is a plain array under its dotted path, e.g.

| key | shape | meaning |
|---|---|---|
| `body.params.global_orient`, `.body_pose`, `.jaw_pose`, `.leye_pose`, `.reye_pose` | (T,3), (T,63), (T,3) x 3 | axis-angle |
| `body.params.left_hand_pose`, `.right_hand_pose` | (T,45) | axis-angle, ABSOLUTE (`body.flat_hand_mean` = True) |
| `body.params.transl`, `.expression`, `.fullpose` | (T,3), (T,10), (T,165) | fullpose = all 55 joints |
| `body.betas`, `body.flat_hand_mean`, `body.model` | (10,), (), () | shape; hand mean not added; the model file |
| `object.params.transl`, `.global_orient` | (T,3), (T,3) | object pose per frame: x_world = R(orient) x_obj + transl |
| `object.object_mesh`, `object.points`, `object.normals` | (), (P,3), (P,3) | PLY path relative to the file (read back absolute when it is there); SAGA's 2048 points |
| `contact.object`, `contact.markers`, `contact.body`, `contact.feet` | (T,P), (T,143), (T,V), (T,4) uint8 | C_O, C_M, body vertices, feet |
| `framerate`, `n_frames`, `obj_name`, `gender`, `sbj_id`, `motion_intent` | () | as GRAB |
| `grasp.*`, `goal.*`, `saga.*` | | graspkit's extras: grasp type, grasp frame, GOAL / SAGA labels |

`load_grasp_sequence` reads these files, and real GRAB files when `allow_pickle=True` is passed explicitly (their
dictionaries are pickled; only open files you trust). GRAB's `body.params.fullpose` is smplx's `full_pose`, absolute
(the hand mean already in it: smplx adds it, and GOAL feeds it to flat_hand_mean=True layers), and is read as it is;
`hands_mean` (90,) (e.g. a model's hands_meanl/r) is for files with per-part 45-D hand poses stored relative to the
mean (a flat_hand_mean=False model's). GRAB gives each subject's shape as a template mesh (`body.vtemp`), not betas:
the body is posed with betas 0, with a warning (the path stays in `extras`).
Sequences are resampled to `fps` (GRAB: 120 Hz) with slerp (graspkit.data.formats.resample).
"""
from __future__ import annotations

import os
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import torch

from graspkit.checks import GraspkitWarning, user_stacklevel
from graspkit.data.formats import (SequenceFileError, _numbers, _scalar, check_source_rate, npz_load_error, resample,
                                   write_npz_atomic)
from graspkit.data.motion import Motion, check_fps
from graspkit.paths import check_suffix

if TYPE_CHECKING:
    from graspkit.body import BodyModel

BODY_PARTS = (("global_orient", 0, 1), ("body_pose", 1, 22), ("jaw_pose", 22, 23), ("leye_pose", 23, 24),
              ("reye_pose", 24, 25), ("left_hand_pose", 25, 40), ("right_hand_pose", 40, 55))


@dataclass
class GraspSequence:
    """One GRAB-style sequence: poses (T,55,3) absolute axis-angle, trans (T,3), betas (10,), fps; the object's
    name, per-frame translation (T,3) and axis-angle orientation (T,3), mesh path (stored relative to the file; loaded
    as an absolute path when the mesh is there, so a copy saved elsewhere points at it); contacts {name: (T,N) uint8};
    extras {key: array} (graspkit's labels); object points / normals (P,3) in the object frame."""

    poses: np.ndarray
    trans: np.ndarray
    betas: np.ndarray
    fps: float
    object_name: str
    object_transl: np.ndarray
    object_orient: np.ndarray
    object_mesh: str = ""
    contacts: dict[str, np.ndarray] = field(default_factory=dict)
    extras: dict[str, np.ndarray] = field(default_factory=dict)
    object_points: np.ndarray | None = None
    object_normals: np.ndarray | None = None
    gender: str = "neutral"
    subject: str = "graspkit"
    intent: str = "lift"

    def __post_init__(self) -> None:
        self.poses = np.asarray(self.poses, np.float32).reshape(-1, 55, 3)
        T = len(self.poses)
        self.trans = np.asarray(self.trans, np.float32).reshape(T, 3)
        self.betas = np.asarray(self.betas, np.float32).reshape(-1)
        self.object_transl = np.asarray(self.object_transl, np.float32).reshape(T, 3)
        self.object_orient = np.asarray(self.object_orient, np.float32).reshape(T, 3)
        for k, c in self.contacts.items():
            if len(c) != T:
                raise ValueError(f"contacts: {k!r} has {len(c)} frames, poses has {T}")

    @property
    def num_frames(self) -> int:
        return len(self.poses)

    def object_rotation(self) -> np.ndarray:
        """Object rotation matrices (T,3,3)."""
        from graspkit.data.ik import axis_angle_matrix
        return axis_angle_matrix(self.object_orient.astype(np.float64))


FRAME_EXTRAS = {"grasp.goal_frame", "grasp.frame"}   # extras that are frame numbers (rescaled when resampled)
DEFAULT_MODEL_NAME = "graspkit procedural SMPLX_NEUTRAL.npz"   # body.model of files made with the shipped body
MADE_ON_TOL = 1e-3      # m: a file made on the body lies ~1e-6 m from it; another body's legs or arms, centimetres


def grasp_frame(extras: Mapping[str, np.ndarray]) -> int:
    """The frame of a file's grasp from its extras (or read_arrays' dictionary): an approach clip's goal frame, a grasp
    file's grasp frame, else 0."""
    return int(extras.get("grasp.goal_frame", extras.get("grasp.frame", np.array(0))))


def body_offset(bm: BodyModel, path: str | os.PathLike) -> float | None:
    """How far (m, the largest distance) bm's vertices for a grasp file's parameters at its grasp frame lie from GOAL's
    400 vertices stored with them (`goal.vertex_ids`, `goal.vertices`: `graspkit data make`'s labels); None when the
    file stores none (one's own GRAB files). ~1e-6 m when the file was made on bm. A clip moved as a whole, body and
    object, is the same body: the vertices are taken back by the object's move since the labels (its translation at
    the grasp frame minus `goal.object_transl`); a body moved away from its object, or another body's, is not. The
    closest of the vertices interpolated between the grasp frame and its neighbours counts: a clip resampled to another
    frame rate (its goal frame rounded) holds the labelled instant between two frames."""
    a = read_arrays(path)
    keys = ("body.params.fullpose", "body.params.transl", "body.betas", "goal.vertex_ids", "goal.vertices")
    if not all(k in a for k in keys):
        return None
    ids = np.asarray(a["goal.vertex_ids"]).reshape(-1).astype(np.int64)
    stored = np.asarray(a["goal.vertices"], np.float64).reshape(-1, 3)
    if not len(ids) or len(ids) != len(stored) or ids.min() < 0 or ids.max() >= bm.num_vertices:
        return float("inf")                                             # another mesh layout altogether
    f = grasp_frame(a)
    poses = np.asarray(a["body.params.fullpose"], np.float64).reshape(-1, 55, 3)
    if not 0 <= f < len(poses):
        raise SequenceFileError(f"{path}: grasp frame {f} outside its {len(poses)} frames")
    lo, hi = max(f - 1, 0), min(f + 2, len(poses))
    m = Motion(poses[lo:hi], np.asarray(a["body.params.transl"], np.float64).reshape(-1, 3)[lo:hi],
               np.asarray(a["body.betas"], np.float64).reshape(-1), 30.0)
    v = m.vertices(bm)[:, torch.as_tensor(ids)].double()                          # (frames, n, 3)
    if "object.params.transl" in a and "goal.object_transl" in a:              # the clip's move since its labels
        obj = torch.as_tensor(np.asarray(a["object.params.transl"], np.float64).reshape(-1, 3)[lo:hi])
        v = v - (obj - torch.as_tensor(np.asarray(a["goal.object_transl"], np.float64).reshape(3)))[:, None]
    w = torch.linspace(0, 1, 11, dtype=torch.float64)[:, None, None, None]
    between = (1 - w) * v[:-1] + w * v[1:] if len(v) > 1 else v[None]             # (11, frames - 1, n, 3)
    return float((between - torch.as_tensor(stored)).norm(dim=-1).amax(-1).min())


def check_made_on(bm: BodyModel, paths: Sequence[str | os.PathLike], where: str, kind: str) -> None:
    """ValueError naming `where` when the first of `paths` was made on another body model than bm (`body_offset` above
    MADE_ON_TOL): its poses on bm would sink, float or miss the object by the difference of the bodies, and every figure
    measured on them with it. Files without GOAL's labels pass; so does an empty list."""
    off = body_offset(bm, paths[0]) if len(paths) else None
    if off is not None and off > MADE_ON_TOL:
        raise ValueError(f"{where}: its {kind} files were made on another body model than "
                         f"{bm.source or 'the one given'} ({Path(paths[0]).name}'s stored GOAL vertices lie up to "
                         f"{1000 * off:.0f} mm from that body's for the same parameters; GRASPKIT_MODEL names the "
                         "body; a body moved apart from its object since it was labelled reads the same): use the "
                         f"body that made them, or make data on this one (`graspkit data make --kind {kind} --out DIR`)")


def to_arrays(seq: GraspSequence, model: str = DEFAULT_MODEL_NAME) -> dict[str, np.ndarray]:
    """The flat dotted-key dictionary of a sequence (what save_grasp_sequence writes)."""
    T = seq.num_frames
    a: dict[str, np.ndarray] = {}
    for name, lo, hi in BODY_PARTS:
        a[f"body.params.{name}"] = seq.poses[:, lo:hi].reshape(T, -1).astype(np.float32)
    a["body.params.transl"] = seq.trans.astype(np.float32)
    a["body.params.expression"] = np.zeros((T, 10), np.float32)
    a["body.params.fullpose"] = seq.poses.reshape(T, 165).astype(np.float32)
    a["body.betas"] = seq.betas[:10].astype(np.float32)
    a["body.flat_hand_mean"] = np.array(True)
    a["body.model"] = np.array(model)
    a["object.params.transl"] = seq.object_transl.astype(np.float32)
    a["object.params.global_orient"] = seq.object_orient.astype(np.float32)
    a["object.object_mesh"] = np.array(seq.object_mesh)
    if (seq.object_points is None) != (seq.object_normals is None):
        raise ValueError("object_points, object_normals: give both (P,3) arrays or neither, got only "
                         + ("object_points" if seq.object_normals is None else "object_normals"))
    if seq.object_points is not None:
        a["object.points"] = np.asarray(seq.object_points, np.float32)
        a["object.normals"] = np.asarray(seq.object_normals, np.float32)
    for k, c in seq.contacts.items():
        a[f"contact.{k}"] = np.asarray(c).astype(np.uint8)
    a.update(framerate=np.array(float(seq.fps)), n_frames=np.array(T), obj_name=np.array(seq.object_name),
             gender=np.array(seq.gender), sbj_id=np.array(seq.subject), motion_intent=np.array(seq.intent))
    for k, v in seq.extras.items():
        if k in a:
            raise ValueError(f"extras: key {k!r} clashes with a GRAB key")
        a[k] = np.asarray(v)
    return a


def save_grasp_sequence(path: str | os.PathLike, seq: GraspSequence, model: str = DEFAULT_MODEL_NAME) -> Path:
    """Write a GraspSequence as a GRAB-style .npz without pickle, atomically (equal content gives equal bytes);
    `model` names the body model the poses are for (`body.model`)."""
    path = Path(path)
    check_suffix(path, ".npz")
    check_fps(seq.fps, "seq.fps")
    a = to_arrays(seq, model)
    a["object.object_mesh"] = np.array(_mesh_path_for(seq.object_mesh, path.parent))
    for key in ("body.params.fullpose", "body.params.transl", "body.betas", "object.params.transl",
                "object.params.global_orient", "object.points", "object.normals"):
        if key in a and not np.isfinite(a[key]).all():
            raise ValueError(f"seq: {key!r} contains NaN or Inf")
    write_npz_atomic(path, a)
    return path


def _flatten(prefix: str, value, out: dict[str, np.ndarray]) -> None:
    """Flatten GRAB's nested dictionaries into dotted keys."""
    if isinstance(value, dict):
        for k, v in value.items():
            _flatten(f"{prefix}.{k}" if prefix else str(k), v, out)
    else:
        out[prefix] = np.asarray(value)


def read_arrays(path: str | os.PathLike, allow_pickle: bool = False) -> dict[str, np.ndarray]:
    """All leaves of a GRAB-style or real GRAB .npz as a flat dotted-key dictionary."""
    path = Path(path)
    if not path.is_file():
        raise SequenceFileError(f"{path}: no such grasp file")
    try:
        npz = np.load(path, allow_pickle=allow_pickle)
    except Exception as e:
        raise SequenceFileError(f"{path}: not a readable .npz file ({npz_load_error(path, e)})") from None
    if not isinstance(npz, np.lib.npyio.NpzFile):
        raise SequenceFileError(f"{path}: expected an .npz archive of arrays, got a single array")
    out: dict[str, np.ndarray] = {}
    with npz:
        for key in npz.files:
            try:
                a = npz[key]
            except ValueError:
                raise SequenceFileError(
                    f"{path}: key {key!r} holds pickled Python objects (a real GRAB file?); pass allow_pickle=True "
                    "only if you trust the file") from None
            except Exception as e:      # a damaged member: BadZipFile (CRC), zlib.error, EOFError
                raise SequenceFileError(f"{path}: key {key!r} is corrupt ({type(e).__name__}: {e})") from None
            if a.dtype == object:
                _flatten(key, a.item() if a.shape == () else list(a), out)
            else:
                out[key] = a
    return out


def _str(a: np.ndarray | None, default: str = "") -> str:
    """A scalar string array as str."""
    if a is None:
        return default
    v = a.item() if a.shape == () else a.reshape(-1)[0]
    return v.decode() if isinstance(v, bytes) else str(v)


def load_grasp_sequence(path: str | os.PathLike, allow_pickle: bool = False, hands_mean: np.ndarray | None = None,
                        fps: float | None = 30.0) -> GraspSequence:
    """Read a graspkit GRAB-style file (or a real GRAB file with allow_pickle=True) into a GraspSequence at `fps`.

    hands_mean (90,): added to per-part 45-D hand poses stored relative to the hand mean (files without
    'body.params.fullpose', which already holds it and refuses hands_mean; graspkit's own files say
    `body.flat_hand_mean` = True and are never changed)."""
    path = Path(path)
    if fps is not None:
        check_fps(fps, where=" (or None)")
    a = read_arrays(path, allow_pickle)

    def numbers(key: str) -> np.ndarray:
        return _key_numbers(a, key, path)

    def per_frame(key: str, width: int) -> np.ndarray:
        v = numbers(key)
        if len(v.shape) == 0 or v.shape[0] != T or v.size != T * width:
            raise SequenceFileError(f"{path}: key {key!r} has shape {v.shape}, expected ({T}, {width})")
        return v.reshape(T, width)

    poses = _body_poses(a, path, hands_mean)
    T = len(poses)
    trans = per_frame("body.params.transl", 3)
    if "body.vtemp" in a and "body.betas" not in a:
        warnings.warn(f"{path}: the subject's shape is a template mesh (body.vtemp, GRAB's), not betas: the body is "
                      "posed with betas 0 (the average shape); extras['body.vtemp'] keeps its path", GraspkitWarning,
                      stacklevel=user_stacklevel())
    betas = np.zeros(10)
    if "body.betas" in a:
        b = numbers("body.betas").reshape(-1)
        if not np.isfinite(b).all():
            raise SequenceFileError(f"{path}: key 'body.betas' contains NaN or Inf")
        betas[:min(10, len(b))] = b[:10]
    src = check_source_rate(_scalar(a.get("framerate", np.array(30.0)), "framerate", path), "framerate", path)
    o_t = per_frame("object.params.transl", 3)
    o_r = per_frame("object.params.global_orient", 3)
    contacts = {k[len("contact."):]: np.asarray(v) for k, v in a.items() if k.startswith("contact.")}
    _check_sequence(a, path, T, {"poses": poses, "body.params.transl": trans, "object.params.transl": o_t,
                                 "object.params.global_orient": o_r}, contacts)
    frame_scale = None
    if fps is not None and abs(src - fps) > 1e-6 and T > 1:
        n_old, frame_scale = T, fps / src
        poses, trans, _, _ = resample(poses, trans, src, fps)
        o_r3, o_t, _, _ = resample(o_r[:, None], o_t, src, fps)
        o_r = o_r3[:, 0]
        idx = np.minimum(np.round(np.arange(len(poses)) * src / fps).astype(int), n_old - 1)
        contacts = {k: c[idx] for k, c in contacts.items()}
    if fps is not None:
        src = fps  # a one-frame file has nothing to resample, but it is still returned at the rate asked for
    skip = {"framerate", "n_frames", "obj_name", "gender", "sbj_id", "motion_intent", "body.betas", "body.model",
            "body.flat_hand_mean", "object.object_mesh", "object.points", "object.normals"}
    extras = {k: v for k, v in a.items() if not (k in skip or k.startswith(("body.params.", "object.params.", "contact.")))}
    if frame_scale is not None:                   # resampled: the frame numbers graspkit's files carry follow
        for k in FRAME_EXTRAS & set(extras):      # (as formats.resample moves a motion's goal frame)
            f = np.asarray(extras[k])
            extras[k] = np.array(min(int(round(float(f) * frame_scale)), len(poses) - 1), dtype=f.dtype)
    mesh = _str(a.get("object.object_mesh"))
    if mesh and not os.path.isabs(mesh) and (path.parent / mesh).is_file():
        mesh = os.path.normpath(path.parent.absolute() / mesh)  # so that a copy saved elsewhere still finds it
    return GraspSequence(poses, trans, betas, src, _str(a.get("obj_name")), o_t, o_r, mesh,
                         contacts, extras, a.get("object.points"), a.get("object.normals"), _str(a.get("gender"), "neutral"),
                         _str(a.get("sbj_id"), ""), _str(a.get("motion_intent"), ""))


def _key_numbers(a: dict[str, np.ndarray], key: str, path: Path) -> np.ndarray:
    """a[key] as numbers (formats._numbers); SequenceFileError naming `path` and the key when it is missing."""
    if key not in a:
        raise SequenceFileError(f"{path}: missing key {key!r}")
    return _numbers(a[key], key, path)


def _body_poses(a: dict[str, np.ndarray], path: Path, hands_mean: np.ndarray | None) -> np.ndarray:
    """The absolute SMPL-X poses (T,55,3) of a GRAB-style file's arrays `a`: 'body.params.fullpose', or the per-part
    poses with `hands_mean` (90,) added to hands stored relative to the mean (not to `body.flat_hand_mean` files)."""
    flat = False
    if "body.flat_hand_mean" in a:
        f = a["body.flat_hand_mean"]
        if f.size != 1 or f.dtype.kind not in "biu":
            raise SequenceFileError(f"{path}: key 'body.flat_hand_mean' holds {f.size} {f.dtype} value(s), expected one "
                                    "boolean")
        flat = bool(f.reshape(-1)[0])
    if "body.params.fullpose" in a:
        if hands_mean is not None and not flat:
            raise ValueError(f"hands_mean: {path} has 'body.params.fullpose', smplx's full_pose, which already holds "
                             "the hand mean (smplx adds it; GOAL feeds GRAB's fullpose to flat_hand_mean=True layers); "
                             "leave hands_mean out (it is for per-part hand poses stored relative to the mean)")
        full = _key_numbers(a, "body.params.fullpose", path)
        if full.ndim != 2 or full.shape[1] != 165:
            raise SequenceFileError(f"{path}: key 'body.params.fullpose' has shape {full.shape}, expected (T, 165)")
        poses = full.reshape(-1, 55, 3)
    else:
        parts = []
        for name, lo, hi in BODY_PARTS:
            p = _key_numbers(a, f"body.params.{name}", path)
            if p.ndim != 2 or (parts and len(p) != len(parts[0])):
                n = len(parts[0]) if parts else "T"
                raise SequenceFileError(f"{path}: key 'body.params.{name}' has shape {p.shape}, "
                                        f"expected ({n}, {3 * (hi - lo)})")
            if p.shape[-1] != 3 * (hi - lo):
                raise SequenceFileError(f"{path}: key 'body.params.{name}' has {p.shape[-1]} values per frame, "
                                        f"expected {3 * (hi - lo)} (PCA hand poses need 'body.params.fullpose')")
            parts.append(p.reshape(len(p), hi - lo, 3))
        poses = np.concatenate(parts, 1)
    if hands_mean is not None and not flat:
        hm = np.asarray(hands_mean, np.float64)
        if hm.size != 90 or not np.isfinite(hm).all():
            raise ValueError(f"hands_mean: expected 90 finite values (left then right hand), got shape {hm.shape}")
        poses = poses.copy()
        poses[:, 25:55] += hm.reshape(30, 3)
    return poses


def _check_sequence(a: dict[str, np.ndarray], path: Path, T: int, arrays: dict[str, np.ndarray],
                    contacts: dict[str, np.ndarray]) -> None:
    """SequenceFileError naming `path` and the key unless the contact labels have T frames, the object's points and
    normals are (P,3) and come together, `arrays` (named by their keys) and the numbers are finite, and the frame
    numbers (FRAME_EXTRAS) are whole and within [0, T)."""
    for k, c in contacts.items():
        if c.ndim == 0 or c.dtype.kind not in "biuf":
            raise SequenceFileError(f"{path}: key 'contact.{k}' holds {c.shape} {c.dtype}, expected a number per frame")
        if len(c) != T:
            raise SequenceFileError(f"{path}: key 'contact.{k}' has {len(c)} frames, expected {T}")
    for key in ("object.points", "object.normals"):
        if key in a and (a[key].dtype.kind not in "iuf" or a[key].ndim != 2 or a[key].shape[1] != 3):
            raise SequenceFileError(f"{path}: key {key!r} has shape {a[key].shape} ({a[key].dtype}), expected (P, 3)")
    if ("object.points" in a) != ("object.normals" in a):
        raise SequenceFileError(f"{path}: has only one of 'object.points' and 'object.normals', expected both or neither")
    numeric = [(f"contact.{k}", c) for k, c in contacts.items() if c.dtype.kind == "f"]
    numeric += [(k, a[k]) for k in ("object.points", "object.normals") if k in a]
    for key, arr in (*arrays.items(), *numeric):
        if not np.isfinite(arr).all():
            raise SequenceFileError(f"{path}: key {key!r} contains NaN or Inf")
    for k in sorted(FRAME_EXTRAS & set(a)):       # frame numbers: whole, within the clip
        f = a[k]
        if f.size != 1 or f.dtype.kind not in "iuf" or not np.isfinite(f).all() or float(f.reshape(())) % 1 \
                or not 0 <= float(f.reshape(())) < T:
            shown = f.reshape(()).item() if f.size == 1 else f"of shape {f.shape}"
            raise SequenceFileError(f"{path}: key {k!r} is {shown}, expected a whole frame number in [0, {T})")


def _mesh_path_for(mesh: str, folder: Path) -> str:
    """The object_mesh string to store in a file in `folder`: an absolute path made relative to it, any other as is."""
    if not mesh or not os.path.isabs(mesh):
        return mesh
    try:
        return Path(os.path.relpath(mesh, folder.absolute())).as_posix()
    except ValueError:  # another drive (Windows): no relative path exists
        return mesh


def export_object_ply(name: str, folder: str | os.PathLike) -> Path:
    """Write catalogue object `name` (canonical, object frame) as `folder/name.ply` (binary PLY), atomically."""
    import trimesh

    from graspkit.objects.catalogue import make_object
    from graspkit.viz.export import write_atomic

    mesh = make_object(name)
    data = trimesh.exchange.ply.export_ply(mesh, encoding="binary", include_attributes=False)
    return write_atomic(Path(folder) / f"{name}.ply", data)
