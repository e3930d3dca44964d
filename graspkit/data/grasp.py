"""Synthetic whole-body grasps: where the hand goes on an object, the grasp tasks, and the batched fitting pipeline.

GRAB (used by SAGA App. A.3 and GOAL Sec. 3.5) captured people grasping 51 objects; graspkit makes the same kind of
data on its procedural body and object catalogue. A grasp is made in five steps (docs/grasps.md):

1. task      `sample_grasp_task`: an object at SAGA's test placement (Sec. 4.3: height 0.5-1.7 m, yaw 0-360 deg)
             in front of a person who starts at the world origin facing -y (within +-10 deg, GOAL Sec. 3); a body
             shape, a grasp type and a grasp frame on one of the object's parts, chosen among those a right hand
             reaches comfortably from where the person comes from.
2. reach     the reaching planner (graspkit.data.plan_reach) walks the person to a stand-off and puts the right
             wrist where the hand must be: the frame at the goal is the initial whole-body pose (both feet on the
             ground, pelvis over the feet, gaze on the object).
3. arm       the arm is re-solved analytically so the hand also has the grasp frame's orientation (grasp_opt).
4. fingers   every digit closes from the grasp type's open pre-shape until it touches (grasp_opt.close_fingers).
5. polish    a few dozen Adam steps on the SMPL-X pose with SAGA's collision (Eq. 7) and contact (Eq. 6) terms,
             GOAL's head-direction (Eq. 6) and pose-coupling (Eq. 5) terms (grasp_opt.polish).

Grasp types: `power` (the hand wraps a part: palm and fingers around it), `side` (the palm flat on a side, fingers
along it), `pinch` (thumb and index pads on either side of a thin part, palm off the surface), `handle` (a power grasp
of a handle: mug, frying pan, pitcher, power drill). Each catalogue object lists the parts a hand can take and
the grasp types each allows (`GRASP_PARTS`); frames are sampled on those parts.

Splits follow GRAB's object split as SAGA uses it (`SPLITS`): test = GRAB's six test objects, validation = apple
and toothbrush (GRAB's other two validation objects, elephant and hand, have no stand-in), train = the rest.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache
from typing import TYPE_CHECKING

import numpy as np
import torch

from graspkit.body.markers import goal_vertices
from graspkit.body.skeleton import JOINT_INDEX, SMPLX_LANDMARK_VERTEX_IDS
from graspkit.data import grasp_opt as go
from graspkit.data.formats import SequenceFileError
from graspkit.data.ik import frame, normalize
from graspkit.data.locomotion import sample_betas
from graspkit.data.motion import Motion
from graspkit.data.posing import forward_kinematics
from graspkit.data.reaching import Start, plan_reach
from graspkit.data.rig import build_rig
from graspkit.objects.catalogue import SPECS, TEST_OBJECTS, list_objects, make_object
from graspkit.objects.placement import ObjectPose, sample_object_pose, warn_floor
from graspkit.optim.step import with_autograd
from graspkit.rotations import axis_angle_to_matrix

if TYPE_CHECKING:
    from graspkit.body import BodyModel
    from graspkit.objects.sdf import SDFGrid

J = JOINT_INDEX
GRASP_TYPES = ("power", "side", "pinch", "handle")
SPLITS: dict[str, tuple[str, ...]] = {
    "test": TEST_OBJECTS,                                   # mug, camera, toothpaste, wine_glass, frying_pan, binoculars
    "val": ("apple", "toothbrush"),
    "train": tuple(n for n in sorted(SPECS) if n not in TEST_OBJECTS and n not in ("apple", "toothbrush")),
}
SETTLE_FRAMES = 45        # extra frames planned after the goal frame, so the last step can land before the grasp frame
RIM_DEPTH = 0.012         # m: a rim is pinched this far below its top
PALM_GAP = 0.004          # m: the palm centre is placed this far out of the surface (the palm is slightly concave)
START_DISTANCE = (0.05, 1.5)   # m, start to object centre (SAGA Sec. 4.3 from 5 cm, GOAL Sec. 3 up to 1.5 m)
START_CLEARANCE = 0.15    # m: the start is at least the object's horizontal radius + this from the object centre


def split_of(name: str) -> str:
    """'train', 'val' or 'test' for a catalogue object name."""
    for split, names in SPLITS.items():
        if name in names:
            return split
    raise ValueError(f"name: unknown object {name!r}; valid names are {list_objects()}")


def file_split(name: str, path: object) -> str:
    """split_of for the obj_name of the file at `path`: a name outside the catalogue is that file's error
    (SequenceFileError naming it and the key; the splits are GRAB's, by catalogue object)."""
    try:
        return split_of(name)
    except ValueError:
        raise SequenceFileError(f"{path}: key 'obj_name' is {name!r}, expected a catalogue object (the train/val/test "
                                f"splits are by object): {list_objects()}") from None


# ----------------------------------------------------------------------------- graspable parts
@dataclass(frozen=True)
class Part:
    """A graspable part in the object's builder coordinates (catalogue.py, before centring): a cylinder
    (size = (radius, half length), axis), box (size = full extents, axis-aligned), sphere (size = (radius,)) or
    ring (size = (radius,), axis = its normal); `facing` (direction, max angle deg) limits where the palm may be."""

    name: str
    shape: str
    centre: tuple[float, float, float]
    size: tuple[float, ...]
    types: tuple[str, ...]
    axis: tuple[float, float, float] = (0.0, 0.0, 1.0)
    facing: tuple[tuple[float, float, float], float] | None = None


def _drill_grip_axis() -> tuple[float, float, float]:
    a = np.array([-0.02, 0.0, 0.10])
    return tuple(a / np.linalg.norm(a))


_PAN_AXIS = (float(np.sin(np.deg2rad(80))), 0.0, float(np.cos(np.deg2rad(80))))
GRASP_PARTS: dict[str, tuple[Part, ...]] = {
    "apple": (Part("body", "sphere", (0, 0, 0.039), (0.041,), ("power",)),),
    "banana": (Part("middle", "cylinder", (0, 0.004, 0), (0.017, 0.035), ("power", "pinch"), axis=(1, 0, 0)),),
    "binoculars": (Part("barrel", "cylinder", (-0.035, 0, 0), (0.024, 0.035), ("power",), axis=(0, 1, 0),
                        facing=((0, 0, 1), 100.0)),
                   Part("body", "box", (0, 0, 0), (0.118, 0.14, 0.048), ("side",))),
    "bottle": (Part("body", "cylinder", (0, 0, 0.08), (0.033, 0.04), ("power",)),
               Part("neck", "cylinder", (0, 0, 0.213), (0.0135, 0.008), ("pinch", "power"))),
    "bowl": (Part("wall", "cylinder", (0, 0, 0.035), (0.079, 0.005), ("side",)),),
    "camera": (Part("body", "box", (0, 0, 0), (0.12, 0.065, 0.08), ("side", "power")),),
    "can": (Part("body", "cylinder", (0, 0, 0.061), (0.033, 0.028), ("power",)),),
    "cracker_box": (Part("body", "box", (0, 0, 0), (0.16, 0.06, 0.21), ("power", "side")),),
    "flashlight": (Part("body", "cylinder", (0.065, 0, 0), (0.015, 0.04), ("power", "pinch"), axis=(1, 0, 0)),),
    "frying_pan": (Part("handle", "cylinder", tuple(np.array([0.112, 0, 0.035]) + 0.115 * np.array(_PAN_AXIS)),
                        (0.012, 0.035), ("handle",), axis=_PAN_AXIS, facing=((0, 0, 1), 100.0)),),
    "mug": (Part("body", "cylinder", (0, 0, 0.0475), (0.041, 0.02), ("power",), facing=((-1, 0, 0), 120.0)),
            Part("handle", "cylinder", (0.0593, 0, 0.05), (0.0055, 0.006), ("handle",), facing=((1, 0, 0), 35.0))),
    "pitcher": (Part("handle", "cylinder", (0.112, 0, 0.13), (0.009, 0.02), ("handle",), facing=((1, 0, 0), 35.0)),
                Part("body", "cylinder", (0, 0, 0.12), (0.072, 0.04), ("side",), facing=((-1, 0, 0), 120.0))),
    "power_drill": (Part("grip", "cylinder", (-0.045, 0, -0.01), (0.018, 0.03), ("handle",), axis=_drill_grip_axis(),
                         facing=((-1, 0, 0), 45.0)),
                    Part("body", "cylinder", (0, 0, 0.065), (0.03, 0.035), ("power",), axis=(1, 0, 0),
                         facing=((0, 0, 1), 60.0))),
    "sugar_box": (Part("body", "box", (0, 0, 0), (0.09, 0.045, 0.175), ("power", "side")),),
    "toothbrush": (Part("handle", "box", (0, 0, 0.06), (0.014, 0.010, 0.08), ("power", "pinch")),),
    "toothpaste": (Part("tube", "box", (0, 0, 0.1), (0.044, 0.03, 0.11), ("power", "pinch")),),
    "wine_glass": (Part("stem", "cylinder", (0, 0, 0.05), (0.0045, 0.022), ("pinch", "power")),
                   Part("bowl", "sphere", (0, 0, 0.15), (0.038,), ("power",))),
}


# hollow objects: (r, z) outer profiles (builder coordinates, about the z axis) that the fit treats as solid
SOLIDS: dict[str, tuple[tuple[tuple[float, float], ...], ...]] = {
    "mug": (((0, 0), (0.041, 0), (0.041, 0.095), (0, 0.095)),),
    "wine_glass": (((0, 0.085), (0.025, 0.095), (0.037, 0.115), (0.040, 0.14), (0.038, 0.17), (0.036, 0.21),
                    (0, 0.21)),),
    "pitcher": (((0, 0), (0.06, 0), (0.07, 0.05), (0.072, 0.12), (0.062, 0.19), (0.058, 0.235), (0, 0.235)),),
    "bowl": (tuple([(0.0, 0.0)] + [(0.05 + 0.03 * np.sin(x), 0.055 * (1 - np.cos(x))) for x in np.linspace(0, np.pi / 2, 8)]
                   + [(0.0, 0.059)]),),
    "frying_pan": (((0, 0), (0.1, 0), (0.122, 0.045), (0, 0.045)),),
}


def solid_profiles(name: str) -> list[np.ndarray]:
    """The SOLIDS profiles of object `name` in its object frame ((r, z) (K,2), z shifted by the builder centre)."""
    shift = builder_centre(name)
    return [np.asarray(p, float) - [0.0, shift[2]] for p in SOLIDS.get(name, ())]


def grasp_types(name: str) -> tuple[str, ...]:
    """The grasp types object `name` affords (union over its parts, in GRASP_TYPES order)."""
    if name not in GRASP_PARTS:
        raise ValueError(f"name: unknown object {name!r}; valid names are {list_objects()}")
    have = {t for p in GRASP_PARTS[name] for t in p.types}
    return tuple(t for t in GRASP_TYPES if t in have)


@dataclass(frozen=True)
class Candidates:
    """Grasp frames in the object frame (M rows): anchor point p, approach direction s (the palm faces -s), a
    direction y that one hand axis must follow (`kind` 'thumb', 'finger' or 'pinch'), and the part index."""

    p: np.ndarray
    s: np.ndarray
    y: np.ndarray
    kind: tuple[str, ...]
    part: np.ndarray


@lru_cache(maxsize=None)
def builder_centre(name: str) -> np.ndarray:
    """Where the catalogue builder's bounding-box centre was (the canonical mesh is shifted by minus this)."""
    mesh = SPECS[name].build().to_mesh()
    v = np.asarray(mesh.vert_properties, np.float64)[:, :3]
    return 0.5 * (v.min(0) + v.max(0))


def _tangents(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors (3,) completing a to an orthonormal basis."""
    a = normalize(np.asarray(a, float))
    h = np.array([1.0, 0, 0]) if abs(a[0]) < 0.9 else np.array([0, 1.0, 0])
    e1 = normalize(np.cross(a, h))
    return e1, np.cross(a, e1)


def _allowed(part: Part, s: np.ndarray) -> np.ndarray:
    """Mask (M,) of approach directions s (M,3) that the part's `facing` allows."""
    if part.facing is None:
        return np.ones(len(s), bool)
    d, ang = part.facing
    return s @ normalize(np.asarray(d, float)) >= np.cos(np.deg2rad(ang)) - 1e-9


@lru_cache(maxsize=None)
def grasp_candidates(name: str, grasp_type: str) -> Candidates:
    """All grasp frames of one type on object `name` (object frame), from GRASP_PARTS."""
    if grasp_type not in grasp_types(name):
        raise ValueError(f"grasp_type: {name!r} affords {grasp_types(name)}, got {grasp_type!r}")
    P, S, Y, K, I = [], [], [], [], []
    shift = builder_centre(name)
    for pi, part in enumerate(GRASP_PARTS[name]):
        if grasp_type not in part.types:
            continue
        c = np.asarray(part.centre, float) - shift
        a = normalize(np.asarray(part.axis, float))
        if part.shape in ("cylinder", "sphere", "ring"):
            e1, e2 = _tangents(a)
        if part.shape == "cylinder":
            r, hl = part.size
            phi = np.linspace(0, 2 * np.pi, 24, endpoint=False)
            s = np.cos(phi)[:, None] * e1 + np.sin(phi)[:, None] * e2
            for u in np.linspace(-hl, hl, 5):
                ok = _allowed(part, s)
                if grasp_type == "pinch":
                    P.append(c + u * a + 0 * s[ok]); Y.append(np.cross(a, s[ok])); K += ["pinch"] * ok.sum()
                else:   # power, handle and side: the fingers go round the axis (side: a part too wide to wrap)
                    P.append(c + u * a + r * s[ok]); Y.append(np.broadcast_to(a, s[ok].shape))
                    K += ["thumb"] * ok.sum()
                S.append(s[ok]); I.append(np.full(ok.sum(), pi))
        elif part.shape == "sphere":
            (r,) = part.size
            k = np.arange(40) + 0.5
            z = 1 - 2 * k / 40
            th = np.pi * (1 + 5 ** 0.5) * k
            s = np.stack([np.sqrt(1 - z**2) * np.cos(th), np.sqrt(1 - z**2) * np.sin(th), z], 1)
            s = s[(s[:, 2] > -0.3) & _allowed(part, s)]
            for s_i in s:
                t1, t2 = _tangents(s_i)
                for t in (t1, normalize(t1 + t2), t2, normalize(t2 - t1)):
                    P.append((c + (0.0 if grasp_type == "pinch" else r) * s_i)[None]); S.append(s_i[None])
                    Y.append(t[None]); K.append("pinch" if grasp_type == "pinch" else "thumb"); I.append(np.array([pi]))
        elif part.shape == "ring":
            (R,) = part.size
            phi = np.linspace(0, 2 * np.pi, 24, endpoint=False)
            radial = np.cos(phi)[:, None] * e1 + np.sin(phi)[:, None] * e2
            for tilt in (0.0, 0.5):   # pinch the wall just below the rim, approaching from above or above-outside
                s = normalize(a + tilt * radial)
                P.append(c + R * radial - RIM_DEPTH * a); S.append(s); Y.append(radial); K += ["pinch"] * len(phi)
                I.append(np.full(len(phi), pi))
        elif part.shape == "box":
            size = np.asarray(part.size, float)
            for k in range(3):
                for sign in (-1.0, 1.0):
                    s = np.zeros(3); s[k] = sign
                    t = [i for i in range(3) if i != k]
                    d = size[t]
                    if grasp_type == "power":
                        if d.min() > 0.09:
                            continue
                        thin, long_ = t[int(np.argmin(d))], t[int(np.argmax(d))]
                        y = np.eye(3)[long_]
                        kind = "thumb"
                        grid = [(u, 0.0) for u in np.linspace(-0.3, 0.3, 5)]   # along the long side, centred on the thin
                        pts = [c + size[k] / 2 * s + u * size[long_] * np.eye(3)[long_] + v * np.eye(3)[thin]
                               for u, v in grid]
                    elif grasp_type == "side":   # palm flat on a face, fingers horizontal (on the top face: lengthwise)
                        if d.min() < 0.04:
                            continue
                        long_ = t[int(np.argmax(d))] if k == 2 else [i for i in t if i != 2][0]
                        y = np.eye(3)[long_]
                        kind = "finger"
                        pts = [c + size[k] / 2 * s + u * size[t[0]] * np.eye(3)[t[0]] + v * size[t[1]] * np.eye(3)[t[1]]
                               for u in (-0.2, 0.0, 0.2) for v in (-0.2, 0.0, 0.2)]
                    else:   # pinch across the thinnest axis, approaching from a face beside it
                        thin = int(np.argmin(size))
                        if size[thin] > 0.05 or k == thin:
                            continue
                        y = np.eye(3)[thin]
                        kind = "pinch"
                        other = [i for i in range(3) if i not in (k, thin)][0]
                        pts = [c + (size[k] / 2 - 0.015) * s + u * size[other] * np.eye(3)[other] for u in (-0.3, 0.0, 0.3)]
                    pts = np.asarray(pts)
                    ok = _allowed(part, np.broadcast_to(s, pts.shape))
                    P.append(pts[ok]); S.append(np.broadcast_to(s, pts[ok].shape)); Y.append(np.broadcast_to(y, pts[ok].shape))
                    K += [kind] * ok.sum(); I.append(np.full(ok.sum(), pi))
        else:
            raise ValueError(f"part: unknown shape {part.shape!r}")
    if not P or sum(len(p) for p in P) == 0:
        raise ValueError(f"grasp_type: no {grasp_type!r} frames on {name!r}")
    P, S, Y, I = np.concatenate(P), normalize(np.concatenate(S)), normalize(np.concatenate(Y)), np.concatenate(I)
    # the parts only approximate the shapes: keep palm frames within 1 cm of the surface, pinch points inside or
    # within 5 mm of it (exact signed distance to the mesh)
    from graspkit.objects.sdf import signed_distance
    d = signed_distance(torch.as_tensor(P), make_object(name), check=False).numpy()
    ok = d < 0.005 if grasp_type == "pinch" else np.abs(d) < 0.01
    if not ok.any():
        raise ValueError(f"grasp_type: no {grasp_type!r} frame of {name!r} is on its surface")
    return Candidates(P[ok], S[ok], Y[ok], tuple(k for k, o in zip(K, ok) if o), I[ok])


# ----------------------------------------------------------------------------- tasks
@dataclass
class GraspTask:
    """Everything that defines one grasp: object, its pose, the person (betas, start), the grasp frame, the seeds."""

    object_name: str
    object_pose: ObjectPose
    grasp_type: str
    choice: float                     # in [0, 1): which of the comfortable grasp frames (GraspFitter.choose_frame)
    betas: np.ndarray                 # (10,)
    start: Start
    goal_frame: int                   # frame of the reach plan at which the hand arrives
    hold_frames: int
    plan_seed: int
    hand_noise: np.ndarray            # (21,) degrees on the open pre-shape
    start_pose: str = "idle"          # 'idle' (standing, arms down) or 't_pose' (GRAB's start)
    candidate: int | None = None      # chosen row of grasp_candidates(object_name, grasp_type) (set by the fitter)
    flip: bool | None = None          # the hand axis follows -y instead of y (set by the fitter)


def natural_hand_rotation(u: np.ndarray, height: float) -> np.ndarray:
    """World rotation (3,3) of the hand frame (columns: finger, palm normal, finger x normal) of a right hand
    reaching towards an object at `height` m by a person standing in direction u (3,) from it: fingers
    forward and down (more for low objects), palm facing the person's left, thumb up."""
    u = normalize(np.array([u[0], u[1], 0.0]))
    down = float(np.clip(1.35 - height, 0.1, 1.0))
    f = normalize(-u - np.array([0, 0, down]))
    left = np.cross(np.array([0, 0, 1.0]), -u)
    return frame(f, left)


def hand_rotation(hf: go.HandFrame, axis_h: np.ndarray, s: np.ndarray, y: np.ndarray, pinch_from: np.ndarray | None = None
                  ) -> np.ndarray:
    """Rotation (3,3) of the rest hand onto a grasp frame. Palm grasps: palm normal hf.normal onto -s exactly, the hand
    axis axis_h as close to y as a rotation about s allows. Pinch (pinch_from = the rest direction from the palm
    centre to the pinch point): the pinch axis axis_h onto y exactly, pinch_from as close to -s as allowed."""
    if pinch_from is not None:
        return frame(y, -s) @ frame(axis_h, pinch_from).T
    return frame(-s, y) @ frame(hf.normal, axis_h).T


def hand_anchor(hm: go.HandModel, betas: np.ndarray, grasp_type: str) -> tuple[np.ndarray, np.ndarray | None, go.HandFrame]:
    """Rest-pose anchor point (3,) of the hand for a grasp type (palm centre; pinch: between the thumb and index
    pads of the closed pinch), the pinch axis (3,) that follows the frame's y (None for other grasps), and the hand
    frame."""
    hf = hm.frame(betas)
    if grasp_type != "pinch":
        return hf.palm, None, hf
    tips = _pinch_tips(hm, tuple(np.round(np.asarray(betas, float), 6)))
    return tips[2], tips[3], hf


@lru_cache(maxsize=256)
def _pinch_tips(hm: go.HandModel, betas: tuple) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The pinch on the rest body `betas`: thumb and index tips where they meet (the curl with the smallest gap along
    the pinch's closing path), their midpoint (the pinch point) and the pinch axis (thumb -> index when open)."""
    bm = hm.bm
    axes = hm.axes(np.asarray(betas))
    curls = np.linspace(0.0, 1.0, 21)
    hands = go.hand_path(go.HAND_SHAPES["pinch"], axes, np.repeat(curls[:, None], 5, 1))
    K = len(curls)
    rot = torch.eye(3, dtype=bm.dtype).repeat(K, 55, 1, 1)
    rot[:, 40:55] = axis_angle_to_matrix(torch.as_tensor(hands, dtype=bm.dtype))
    ids = np.array([SMPLX_LANDMARK_VERTEX_IDS["rthumb"], SMPLX_LANDMARK_VERTEX_IDS["rindex"]])
    pb = go.PartialBody(bm, ids)
    with torch.no_grad():
        v, _ = pb(rot, go.coeffs_of(bm, np.asarray(betas)[None]).expand(K, -1), torch.zeros(K, 3, dtype=bm.dtype))
    v = v.double().numpy()
    k = int(np.argmin(np.linalg.norm(v[:, 0] - v[:, 1], axis=1)))
    return v[k, 0], v[k, 1], 0.5 * (v[k, 0] + v[k, 1]), normalize(v[0, 1] - v[0, 0])


def _hand_axis(hf: go.HandFrame, kind: str, pinch_axis: np.ndarray | None) -> np.ndarray:
    """The rest hand axis that a candidate's y constrains."""
    return {"thumb": hf.thumb, "finger": hf.finger}.get(kind, pinch_axis)


def object_radius(name: str) -> float:
    """Largest horizontal distance (m) of the canonical object's vertices from its centre (any yaw)."""
    v = make_object(name).vertices
    return float(np.linalg.norm(v[:, :2], axis=1).max())


def sample_grasp_task(rng: np.random.Generator, name: str, grasp_type: str | None = None,
                      object_pose: ObjectPose | None = None, start_pose: str | None = None,
                      start_distance: tuple[float, float] = START_DISTANCE) -> GraspTask:
    """Draw one grasp task for object `name` (see the module docstring); grasp_type / object_pose fix those draws."""
    if name not in GRASP_PARTS:
        raise ValueError(f"name: unknown object {name!r}; valid names are {list_objects()}")
    if not isinstance(rng, np.random.Generator):
        raise ValueError(f"rng: expected a numpy Generator (np.random.default_rng(seed)), got {type(rng).__name__}")
    if grasp_type is not None and grasp_type not in grasp_types(name):
        raise ValueError(f"grasp_type: {name} affords {list(grasp_types(name))}, got {grasp_type!r}")
    if start_pose is not None and start_pose not in ("idle", "t_pose"):
        raise ValueError(f"start_pose: expected None, 'idle' or 't_pose', got {start_pose!r}")
    if len(start_distance) != 2 or not 0 <= start_distance[0] <= start_distance[1] <= 3.0:
        raise ValueError(f"start_distance: expected (low, high) metres with 0 <= low <= high <= 3, got "
                         f"{tuple(start_distance)}")
    betas = sample_betas(rng)
    if grasp_type is None:
        grasp_type = str(rng.choice(grasp_types(name)))
    lo = max(start_distance[0], object_radius(name) + START_CLEARANCE)
    pose = object_pose if object_pose is not None else sample_object_pose(
        rng, distance_range=(lo, max(lo, start_distance[1])), bearing_range_deg=(-10.0, 10.0))
    start = Start(0.0, 0.0, -np.pi / 2)
    if object_pose is not None:        # a given placement: the person starts facing it (within +-10 deg)
        warn_floor(object_pose, make_object(name))
        d = rng.uniform(lo, max(lo, start_distance[1]))
        ang = rng.uniform(0, 2 * np.pi)
        xy = pose.translation[:2] + d * np.array([np.cos(ang), np.sin(ang)])
        to = pose.translation[:2] - xy
        start = Start(float(xy[0]), float(xy[1]), float(np.arctan2(to[1], to[0]) + np.deg2rad(rng.uniform(-10, 10))))
    u = np.array([start.x, start.y, 0.0]) - pose.translation * [1, 1, 0]
    # the plan: the goal frame is when a person would get there (a step closer if needed, slower for low objects)
    D = float(np.linalg.norm(u[:2]))
    walk = max(D - 0.55, 0.0) / 0.9 + (0.6 if D > 0.55 else 0.0)
    reach = 0.9 + 0.5 * max(0.9 - pose.translation[2], 0.0)
    goal_frame = int(round((walk + reach + rng.uniform(0.2, 0.6)) * 30))
    hold = int(rng.integers(15, 31))
    sp = start_pose if start_pose is not None else ("t_pose" if rng.random() < 0.5 else "idle")
    return GraspTask(name, pose, grasp_type, float(rng.random()), betas, start, goal_frame, hold,
                     int(rng.integers(2**31)), rng.normal(0.0, 4.0, 21), sp)


# ----------------------------------------------------------------------------- the fitting pipeline
@dataclass
class GraspResult:
    """A fitted grasp: the task, the absolute SMPL-X pose (55,3) and translation (3,), the reach plan it ends,
    the hand's curls per digit (5,), the polish history (if recorded) and quality figures."""

    task: GraspTask
    poses: np.ndarray
    trans: np.ndarray
    plan: Motion
    curls: np.ndarray
    init_poses: np.ndarray
    grasp_frame: int
    approach_dir: np.ndarray          # (3,) unit: the hand comes in along -approach_dir (the frame's s, world)
    quality: dict = field(default_factory=dict)

    @property
    def betas(self) -> np.ndarray:
        return np.asarray(self.task.betas, np.float32)


@dataclass
class GraspFitter:
    """Holds the body model, its hand model and the per-object SDF grids; `fit(tasks)` runs the pipeline."""

    bm: BodyModel
    steps: int = 40
    grid_resolution: int = 64
    _grids: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.hm = go.HandModel(self.bm)
        self.pb = go.PartialBody(self.bm, self.hm.fit_ids)
        gv = goal_vertices(self.bm)
        self.head_pb = go.PartialBody(self.bm, np.array([gv.head_back, gv.head_front]))

    def grid(self, name: str) -> SDFGrid:
        """The object's SDF grid (built once; see graspkit.data.grasp_io.cached_sdf_grid)."""
        if name not in self._grids:
            from graspkit.data.grasp_io import cached_sdf_grid
            self._grids[name] = cached_sdf_grid(name, self.grid_resolution)
        return self._grids[name]

    def _frames(self, task: GraspTask) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Every candidate grasp frame and sign of a task in the world: anchor targets (M,3), approach s (M,3), hand
        rotations (M,3,3), wrist targets (M,3), and the (candidate, flip) index pairs (M,2)."""
        cand = grasp_candidates(task.object_name, task.grasp_type)
        Ro, to = task.object_pose.rotation, task.object_pose.translation
        anchor, pinch_axis, hf = hand_anchor(self.hm, task.betas, task.grasp_type)
        rows, T, S, R, Wr = [], [], [], [], []
        for i in range(len(cand.p)):
            s_w = Ro @ cand.s[i]
            if s_w[2] < -0.35:                     # no grasps from below
                continue
            axis_h = _hand_axis(hf, cand.kind[i], pinch_axis)
            target = Ro @ cand.p[i] + to + (0.0 if task.grasp_type == "pinch" else PALM_GAP) * s_w
            pinch_from = normalize(anchor - hf.palm) if task.grasp_type == "pinch" else None
            for flip in (0, 1):
                R_hand = hand_rotation(hf, axis_h, s_w, (-1.0 if flip else 1.0) * (Ro @ cand.y[i]), pinch_from)
                rows.append((i, flip)); T.append(target); S.append(s_w); R.append(R_hand)
                Wr.append(target - R_hand @ (anchor - hf.wrist))
        return np.asarray(T), np.asarray(S), np.asarray(R), np.asarray(Wr), np.asarray(rows)

    def _plan(self, task: GraspTask, wrist: np.ndarray) -> tuple[Motion, np.ndarray, np.ndarray, np.ndarray, object, int]:
        """The reach plan to `wrist` and its grasp frame: the first frame at or after the goal frame from which both
        feet stay flat on the ground (the wrist is held on its target meanwhile). Returns the plan (cut to the grasp
        frame + task.hold_frames), the grasp frame's local rotations (55,3,3), global rotations, joints, the rig and
        the grasp frame index."""
        plan = plan_reach(task.start, wrist, task.goal_frame, betas=task.betas, seed=task.plan_seed, bm=self.bm,
                          hold_frames=task.hold_frames + SETTLE_FRAMES)
        down = plan.contacts.all(1)
        settled = np.flatnonzero(np.logical_and.accumulate(down[::-1])[::-1])      # both feet down from here on
        after = settled[settled >= task.goal_frame]
        f = int(after[0]) if len(after) else plan.num_frames - 1
        plan = plan.slice(0, min(plan.num_frames, f + task.hold_frames + 1))
        rig = build_rig(self.bm, task.betas)
        local = axis_angle_matrix_np(plan.poses[f])
        Rg, pos = forward_kinematics(rig, local[None], (plan.trans[f] + rig.joints[0])[None])
        return plan, local, Rg[0], pos[0], rig, f

    def choose_frame(self, task: GraspTask) -> None:
        """Pick the task's grasp frame (sets task.candidate and task.flip): plan a reach to the object's centre, solve
        the arm for every candidate frame, keep those the wrist reaches within 55 deg of rotation (or the best few),
        and draw one with weight exp(-(residual / 25 deg)^2) using task.choice."""
        T, S, R, Wr, rows = self._frames(task)
        if len(rows) == 0:
            raise ValueError(f"task: no grasp frame of {task.grasp_type!r} on {task.object_name!r} faces up or sideways")
        _, _, Rg, pos, rig, _ = self._plan(task, task.object_pose.translation.copy())
        _, _, _, resid = go.solve_arm(Rg[J["right_collar"]], pos[J["right_shoulder"]], rig.joints, Wr, R)
        nat = natural_hand_rotation(np.array([task.start.x, task.start.y, 0]) - task.object_pose.translation,
                                    task.object_pose.translation[2])
        hf = self.hm.frame(task.betas)
        world = R @ hf.rot
        cos = (np.einsum("mij,ij->m", world, nat) - 1) / 2
        cost = resid + 0.3 * np.arccos(np.clip(cos, -1, 1))
        ok = resid < np.deg2rad(55.0)
        if ok.sum() < 3:
            ok = cost <= np.sort(cost)[min(2, len(cost) - 1)]
        w = np.where(ok, np.exp(-(cost / np.deg2rad(25.0)) ** 2), 0.0)
        k = int(np.searchsorted(np.cumsum(w) / w.sum(), task.choice, side="right"))
        task.candidate, task.flip = int(rows[min(k, len(rows) - 1), 0]), bool(rows[min(k, len(rows) - 1), 1])

    def initial_pose(self, task: GraspTask) -> tuple[np.ndarray, np.ndarray, Motion, float, dict]:
        """The reach plan ending at the grasp's wrist target and its goal frame's pose with the arm re-solved:
        local rotations (55,3,3), translation (3,), the plan, the arm's residual wrist angle (rad), and the targets."""
        if task.candidate is None:
            self.choose_frame(task)
        T, S, R, Wr, rows = self._frames(task)
        m = int(np.flatnonzero((rows[:, 0] == task.candidate) & (rows[:, 1] == int(task.flip)))[0])
        plan, local, Rg, pos, rig, f = self._plan(task, Wr[m])
        sh, el, wr, resid = go.solve_arm(Rg[J["right_collar"]], pos[J["right_shoulder"]], rig.joints, Wr[m:m + 1],
                                         R[m:m + 1])
        local[J["right_shoulder"]], local[J["right_elbow"]], local[J["right_wrist"]] = sh[0], el[0], wr[0]
        anchor, _, hf = hand_anchor(self.hm, task.betas, task.grasp_type)
        palm_target = T[m] if task.grasp_type != "pinch" else T[m] + R[m] @ (hf.palm - anchor)
        info = {"palm": palm_target, "normal": S[m], "centre": task.object_pose.translation, "wrist": Wr[m],
                "hand_rot": R[m], "reach": float(np.linalg.norm(Wr[m] - pos[J["right_shoulder"]]) / rig.arm_length),
                "grasp_frame": f}
        return local, plan.trans[f].astype(np.float64), plan, float(resid[0]), info

    @with_autograd
    def fit(self, tasks: list[GraspTask], history: list | None = None, polish_steps: int | None = None
            ) -> list[GraspResult]:
        """Fit B grasps of ONE object (batched), returning them with quality figures (see `evaluate`)."""
        if not tasks:
            return []
        names = {t.object_name for t in tasks}
        if len(names) != 1:
            raise ValueError(f"tasks: expected one object per batch, got {sorted(names)}")
        name = tasks[0].object_name
        bm, hm = self.bm, self.hm
        inits = [self.initial_pose(t) for t in tasks]
        B = len(tasks)
        dtype = bm.dtype
        rot0 = torch.as_tensor(np.stack([i[0] for i in inits]), dtype=dtype)
        transl = torch.as_tensor(np.stack([i[1] for i in inits]), dtype=dtype)
        coeffs = go.coeffs_of(bm, np.stack([t.betas for t in tasks]))
        sdf = go.PosedSDF(self.grid(name), np.stack([t.object_pose.rotation for t in tasks]),
                          np.stack([t.object_pose.translation for t in tasks]), dtype, solid_profiles(name),
                          -builder_centre(name)[:2])
        paths = []
        for t in tasks:
            axes = hm.axes(t.betas)
            shape = go.HAND_SHAPES[t.grasp_type]
            paths.append(lambda c, axes=axes, shape=shape, e=t.hand_noise: go.hand_path(shape, axes, c, e))
        open_hands = np.stack([p(np.zeros((1, 5)))[0] for p in paths])
        rot0[:, 40:55] = axis_angle_to_matrix(torch.as_tensor(open_hands, dtype=dtype))
        init_rot = rot0.clone()
        curls, hands = go.close_fingers(self.pb, hm, rot0, coeffs, transl, sdf, paths)
        rot0[:, 40:55] = axis_angle_to_matrix(torch.as_tensor(hands, dtype=dtype))
        regions = np.ones((B, 6))
        for b, t in enumerate(tasks):
            if t.grasp_type == "pinch":
                regions[b] = [0, 1, 1, 0, 0, 0]
            regions[b, 1:] *= curls[b, [4, 0, 1, 3, 2]] < 0.999       # digits that never touched are not asked to
        targets = go.PolishTargets(np.stack([i[4]["palm"] for i in inits]), np.stack([i[4]["normal"] for i in inits]),
                                   np.stack([i[4]["centre"] for i in inits]), regions)
        pts = torch.as_tensor(np.stack([object_points_world(name, t.object_pose) for t in tasks]), dtype=dtype)
        rot = go.polish(self.pb, hm, self.head_pb, (0, 1), rot0, coeffs, transl, sdf, targets, pts,
                        steps=self.steps if polish_steps is None else polish_steps, history=history)
        from graspkit.rotations import matrix_to_axis_angle
        aa = matrix_to_axis_angle(rot).double().numpy()
        aa0 = matrix_to_axis_angle(init_rot).double().numpy()
        out = []
        for b, t in enumerate(tasks):
            q = {"arm_residual_deg": float(np.rad2deg(inits[b][3])), "reach": inits[b][4]["reach"]}
            out.append(GraspResult(t, aa[b].astype(np.float32), inits[b][1].astype(np.float32), inits[b][2], curls[b],
                                   aa0[b].astype(np.float32), inits[b][4]["grasp_frame"], inits[b][4]["normal"], q))
        return out


    def vertices(self, results: list[GraspResult]) -> torch.Tensor:
        """Full body vertices (B,V,3) of fitted grasps."""
        rot = axis_angle_to_matrix(torch.as_tensor(np.stack([r.poses for r in results]), dtype=self.bm.dtype))
        with torch.no_grad():
            return self.bm.forward_rotmats(rot, betas=torch.as_tensor(np.stack([r.betas for r in results])),
                                           transl=torch.as_tensor(np.stack([r.trans for r in results]))).vertices

    def evaluate(self, results: list[GraspResult]) -> None:
        """Measure each grasp on its full mesh (graspkit.metrics.grasp_metrics, exact): contact distance, penetration
        volume and depth, the feet's distance to the ground (cm), and which hand regions touch; stored in .quality."""
        from graspkit import metrics as M
        from graspkit.objects.placement import apply_pose
        from graspkit.objects.sdf import signed_distance

        if not results:
            return
        V = self.vertices(results).double()
        faces = self.bm.faces
        feet = _foot_ids(self.bm)
        for b, r in enumerate(results):
            obj = apply_pose(r.task.object_pose, make_object(r.task.object_name))   # each its own object
            q = M.grasp_metrics(V[b], faces, obj, refine=1)    # one ray per column: the shipped sets were made so
            # the shipped sets were accepted on the vertices' distance alone (grasp_metrics also counts an overlap)
            q["contact"] = float(q["min_distance"] <= M.GRASP_CONTACT_THRESHOLD)
            q["feet_cm"] = 100.0 * max(abs(float(V[b, ids, 2].min())) for ids in feet)
            ids = np.concatenate([self.hm.palm_ids] + [self.hm.pad_ids[f] for f in REGION_DIGITS])
            d = signed_distance(V[b, ids], obj, check=False).numpy()
            sizes = np.cumsum([0, len(self.hm.palm_ids)] + [len(self.hm.pad_ids[f]) for f in REGION_DIGITS])
            q["regions_mm"] = [float(1000 * d[sizes[k]:sizes[k + 1]].min()) for k in range(len(sizes) - 1)]
            r.quality.update(q)


REGION_DIGITS = ("thumb", "index", "middle", "ring", "pinky")


@lru_cache(maxsize=4)
def _foot_ids(bm) -> tuple[np.ndarray, np.ndarray]:
    """Vertex ids of the left and right foot (ankle and toe segments)."""
    return (go.part_vertices(bm, [J["left_ankle"], J["left_foot"]]), go.part_vertices(bm, [J["right_ankle"], J["right_foot"]]))


def axis_angle_matrix_np(aa: np.ndarray) -> np.ndarray:
    """Rotation matrices (...,3,3) of axis-angle vectors (...,3) (float64)."""
    from graspkit.data.ik import axis_angle_matrix
    return axis_angle_matrix(np.asarray(aa, np.float64))


@lru_cache(maxsize=None)
def object_points(name: str, n: int = 2048) -> tuple[np.ndarray, np.ndarray]:
    """SAGA's object representation (Sec. 3): n surface points and outward normals (n,3) in the object frame, seed 0."""
    from graspkit.objects.sampling import sample_surface
    return sample_surface(make_object(name), n, seed=0)


def object_points_world(name: str, pose: ObjectPose) -> np.ndarray:
    """The object's 2048 surface points (2048,3) in the world."""
    return object_points(name)[0] @ pose.rotation.T + pose.translation
