"""Marker sets and vertex sets on an SMPL-X-format body, placed by anatomical rules.

SAGA (App. A.1, Fig. S1) follows GRAB's mocap layout: 49 body, 14 face, 6 hand and 30 finger markers,
plus 44 palm markers (143 in all, stage 1); stage 2 uses a sparse hand: 49 + 14 + 6 + 10 fingertips (79).
GOAL (Sec. 3.2) samples N_b = 400 body vertices and N_h = 99 for each hand, and uses a head direction q;
graspkit's 400 hold 99 on the right (grasping) hand and 40 on the left (`GOAL_BUDGET`). The papers give these
as vertex ids of the licensed SMPL-X mesh; graspkit instead *places* them by rules on whatever model it is
given (procedural or real), so the ids always match the mesh:

- a marker = (anchor on a bone: joint a -> joint b at fraction t, a direction in the canonical rest
  frame (y up, +z forward, +x = body's left), the parts it may lie on); it goes on the vertex of those
  parts whose direction from the anchor is closest to the given one;
- SMPL-X landmark vertices (nose, fingertips, toes, heels) are used where they exist.

GOAL chose its 400 vertices with GRAB's contact heat-maps, which cannot be had here; graspkit spends the
budget by hand on the parts that touch things (right hand 99, left hand 40, feet 40, ...) and spreads each
part's share by farthest-point sampling. Rest pose, betas = 0; deterministic. The layout depends on the model
file only, not on how the BodyModel was built: SAGA's markers, the palms and the feet are placed on the rest body
with the file's mean (relaxed) hands, the pose SAGA's data and checkpoints were made at; GOAL's 400 vertices on
the rest body with flat hands (the template's), the layout GOAL's checkpoints were trained on.
"""
from __future__ import annotations

import weakref
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
import torch

from graspkit.body.skeleton import FINGERS, JOINT_INDEX, SMPLX_LANDMARK_VERTEX_IDS
from graspkit.checks import check_int
from graspkit.rotations import axis_angle_to_matrix

if TYPE_CHECKING:
    from graspkit.body.model import BodyModel

F, B, U, D, L, R = (0, 0, 1), (0, 0, -1), (0, 1, 0), (0, -1, 0), (1, 0, 0), (-1, 0, 0)


def _d(*dirs: tuple[float, float, float]) -> np.ndarray:
    """Sum of unit directions, normalised."""
    v = np.sum(np.asarray(dirs, float), axis=0)
    return v / np.linalg.norm(v)


@dataclass(frozen=True)
class MarkerSet:
    """Named vertex ids on the body, in groups (e.g. body / face / hand / finger / palm)."""

    name: str
    names: tuple[str, ...]
    vertex_ids: np.ndarray                      # (N,) int64
    groups: dict[str, tuple[int, int]] = field(default_factory=dict)  # group -> [start, stop)

    def __len__(self) -> int:
        return len(self.names)

    def select(self, vertices: torch.Tensor) -> torch.Tensor:
        """Marker positions from vertices (..., V, 3) -> (..., N, 3)."""
        return vertices[..., torch.as_tensor(self.vertex_ids, device=vertices.device), :]


class _Rest:
    """The rest-pose mesh of a model with what the rules need: vertices, joints, dominant part per vertex.

    hands: 'mean' puts the file's mean (relaxed) hands on the rest body, 'flat' the template's flat hands; either way,
    whatever the BodyModel's flat_hand_mean, so one file gives one layout."""

    def __init__(self, bm: BodyModel, hands: str = "mean") -> None:
        if hands not in ("mean", "flat"):
            raise ValueError(f"hands: expected 'mean' or 'flat', got {hands!r}")
        pose = torch.zeros(1, len(bm.parents), 3, dtype=bm.dtype, device=bm.v_template.device)
        if hands == "mean":
            pose[0, -30:] = bm.hands_mean.view(30, 3)
        with torch.no_grad():
            out = bm.forward_rotmats(axis_angle_to_matrix(pose))
        self.v = out.vertices[0].double().cpu().numpy()
        self.j = out.joints[0].double().cpu().numpy()
        self.part = bm.lbs_weights.argmax(1).cpu().numpy()
        self.n_vertices = len(self.v)
        self.used: set[int] = set()  # ids already taken by a marker of the set being built (no duplicates)

    def on_parts(self, joints: list[str]) -> np.ndarray:
        """Vertex ids dominated by any of the named joints."""
        ids = np.flatnonzero(np.isin(self.part, [JOINT_INDEX[j] for j in joints]))
        if len(ids) == 0:
            raise ValueError(f"no vertex is dominated by {joints}: is the skinning-weight layout SMPL-X's?")
        return ids

    def place(self, a: str | np.ndarray, b: str | np.ndarray | None, t: float, d: np.ndarray, parts: list[str]) -> int:
        """The vertex of `parts` whose direction from the anchor lerp(a, b, t) is closest to d."""
        pa = self.j[JOINT_INDEX[a]] if isinstance(a, str) else a
        pb = pa if b is None else (self.j[JOINT_INDEX[b]] if isinstance(b, str) else b)
        anchor = (1 - t) * pa + t * pb
        ids = self.on_parts(parts)
        ids = ids[~np.isin(ids, list(self.used))]
        u = self.v[ids] - anchor
        cos = u @ d / np.maximum(np.linalg.norm(u, axis=1), 1e-9)
        chosen = int(ids[np.argmax(cos)])
        self.used.add(chosen)
        return chosen


def _landmark(rest: _Rest, key: str) -> int:
    """An SMPL-X landmark vertex id (valid on any 10,475-vertex SMPL-X mesh)."""
    if rest.n_vertices != 10475:
        raise ValueError(f"landmark {key!r} needs the SMPL-X topology (10,475 vertices), got {rest.n_vertices}")
    rest.used.add(SMPLX_LANDMARK_VERTEX_IDS[key])
    return SMPLX_LANDMARK_VERTEX_IDS[key]


def _body_markers(r: _Rest) -> list[tuple[str, int]]:
    """SAGA's 49 body markers (GRAB layout): head, torso, pelvis, arms, legs, feet."""
    m: list[tuple[str, int]] = []
    head = ["head", "jaw", "left_eye_smplhf", "right_eye_smplhf"]
    hc = r.v[r.on_parts(head)].mean(0)
    m += [("ARIEL", r.place(hc, None, 0, _d(U), head)),
          ("LFHD", r.place(hc, None, 0, _d(F, U, L), head)), ("RFHD", r.place(hc, None, 0, _d(F, U, R), head)),
          ("LBHD", r.place(hc, None, 0, _d(B, U, L), head)), ("RBHD", r.place(hc, None, 0, _d(B, U, R), head))]
    m += [("C7", r.place("neck", None, 0, _d(B), ["neck", "spine3"])),
          ("CLAV", r.place("spine3", "neck", 0.6, _d(F), ["spine3", "neck"])),
          ("STRN", r.place("spine3", None, 0, _d(F), ["spine3", "spine2"])),
          ("T10", r.place("spine2", None, 0, _d(B), ["spine2", "spine3"])),
          ("LBAK", r.place("spine3", None, 0, _d(B, B, L), ["spine3", "left_collar"])),
          ("RBAK", r.place("spine3", None, 0, _d(B, B, R), ["spine3", "right_collar"]))]
    for s, S, out, inn in (("left", "L", L, R), ("right", "R", R, L)):
        m += [(f"{S}FWT", r.place("pelvis", f"{s}_hip", 1.0, _d(F, out), ["pelvis", "spine1"])),
              (f"{S}BWT", r.place("pelvis", f"{s}_hip", 0.7, _d(B, out), ["pelvis", "spine1"])),
              (f"{S}SHO", r.place(f"{s}_shoulder", None, 0, _d(U), [f"{s}_shoulder", f"{s}_collar"])),
              (f"{S}UPA", r.place(f"{s}_shoulder", f"{s}_elbow", 0.5, _d(U, B), [f"{s}_shoulder"])),
              (f"{S}BIC", r.place(f"{s}_shoulder", f"{s}_elbow", 0.5, _d(F), [f"{s}_shoulder"])),
              (f"{S}ELB", r.place(f"{s}_elbow", None, 0, _d(B), [f"{s}_elbow", f"{s}_shoulder"])),
              (f"{S}ELBIN", r.place(f"{s}_elbow", None, 0, _d(F), [f"{s}_elbow", f"{s}_shoulder"])),
              (f"{S}FRM", r.place(f"{s}_elbow", f"{s}_wrist", 0.5, _d(U), [f"{s}_elbow"])),
              (f"{S}FRI", r.place(f"{s}_elbow", f"{s}_wrist", 0.5, _d(D), [f"{s}_elbow"])),
              (f"{S}THI", r.place(f"{s}_hip", f"{s}_knee", 0.5, _d(out), [f"{s}_hip"])),
              (f"{S}THF", r.place(f"{s}_hip", f"{s}_knee", 0.4, _d(F), [f"{s}_hip"])),
              (f"{S}KNE", r.place(f"{s}_knee", None, 0, _d(out), [f"{s}_knee", f"{s}_hip"])),
              (f"{S}KNI", r.place(f"{s}_knee", None, 0, _d(inn), [f"{s}_knee", f"{s}_hip"])),
              (f"{S}SHN", r.place(f"{s}_knee", f"{s}_ankle", 0.5, _d(F), [f"{s}_knee"])),
              (f"{S}ANK", r.place(f"{s}_ankle", None, 0, _d(out), [f"{s}_ankle", f"{s}_knee"])),
              (f"{S}ANI", r.place(f"{s}_ankle", None, 0, _d(inn), [f"{s}_ankle", f"{s}_knee"])),
              (f"{S}HEE", _landmark(r, f"{S}Heel")),
              (f"{S}TOE", _landmark(r, f"{S}BigToe")),
              (f"{S}MT5", _landmark(r, f"{S}SmallToe"))]
    return m


def _face_markers(r: _Rest) -> list[tuple[str, int]]:
    """SAGA's 14 face markers: forehead, brows, eyes, nose, cheeks, mouth, chin (directions from the head centre)."""
    head = ["head", "jaw", "left_eye_smplhf", "right_eye_smplhf"]
    hc = r.v[r.on_parts(head)].mean(0)
    spec = {"FHC": (0, .55, 1), "NBRG": (0, .22, 1), "LBRW": (.33, .38, 1), "RBRW": (-.33, .38, 1),
            "LEYO": (.55, .15, 1), "REYO": (-.55, .15, 1), "LCHK": (.5, -.25, 1), "RCHK": (-.5, -.25, 1),
            "LMTH": (.28, -.55, 1), "RMTH": (-.28, -.55, 1), "LIPU": (0, -.42, 1), "LIPD": (0, -.62, 1),
            "CHIN": (0, -.9, 1)}
    nose = ("NOSE", _landmark(r, "nose"))
    m = [(k, r.place(hc, None, 0, _d(v), head)) for k, v in spec.items()]
    return m[:1] + [nose] + m[1:]


def _hand_parts(s: str) -> list[str]:
    """The wrist and 15 finger joints of one side."""
    return [f"{s}_wrist"] + [f"{s}_{f}{k}" for f in FINGERS for k in (1, 2, 3)]


def _hand_markers(r: _Rest) -> list[tuple[str, int]]:
    """SAGA's 6 hand markers: thumb-side and little-finger-side wrist, back of the hand (both hands)."""
    m = []
    for s, S in (("left", "L"), ("right", "R")):
        w = f"{s}_wrist"
        m += [(f"{S}WRA", r.place(w, None, 0, _d(F), [w, f"{s}_elbow"])),
              (f"{S}WRB", r.place(w, None, 0, _d(B), [w, f"{s}_elbow"])),
              (f"{S}FIN", r.place(w, f"{s}_middle1", 0.6, _d(U), [w]))]
    return m


def _finger_markers(r: _Rest) -> list[tuple[str, int]]:
    """SAGA's 30 finger markers: the back of each phalanx (3 per finger, both hands)."""
    m = []
    for s, S in (("left", "L"), ("right", "R")):
        for f in FINGERS:
            tip = r.v[_landmark(r, f"{S.lower()}{f}")]
            for k in (1, 2, 3):
                nxt = f"{s}_{f}{k + 1}" if k < 3 else tip
                up = _d(U, F) if f == "thumb" else _d(U)  # the thumb's back faces up and forward at rest
                m.append((f"{S}{f.upper()}{k}", r.place(f"{s}_{f}{k}", nxt, 0.5, up, [f"{s}_{f}{k}"])))
    return m


def _palm_markers(r: _Rest) -> list[tuple[str, int]]:
    """SAGA's 44 palm markers: 22 per palm, a 4x4 grid from wrist to knuckles, the proximal phalanges, the thumb base."""
    m = []
    for s, S in (("left", "L"), ("right", "R")):
        w = f"{s}_wrist"
        for f in ("index", "middle", "ring", "pinky"):
            for i, t in enumerate((0.2, 0.45, 0.7, 0.95)):
                m.append((f"{S}PALM_{f}{i}", r.place(w, f"{s}_{f}1", t, _d(D), [w])))
            m.append((f"{S}PALM_{f}P", r.place(f"{s}_{f}1", f"{s}_{f}2", 0.5, _d(D), [f"{s}_{f}1"])))
        for k in (1, 2):
            m.append((f"{S}PALM_thumb{k}", r.place(f"{s}_thumb{k}", f"{s}_thumb{k + 1}", 0.5, _d(D, B), [f"{s}_thumb{k}"])))
    return m


def _fingertips(r: _Rest) -> list[tuple[str, int]]:
    """The 10 fingertip landmarks (SAGA's sparse hand for MotionFill)."""
    return [(f"{S}{f.upper()}TIP", _landmark(r, f"{S.lower()}{f}")) for S in "LR" for f in FINGERS]


def _assemble(name: str, groups: list[tuple[str, list[tuple[str, int]]]]) -> MarkerSet:
    """A MarkerSet from ordered (group, [(marker, vertex id)]) lists."""
    names, ids, spans, start = [], [], {}, 0
    for g, items in groups:
        names += [n for n, _ in items]
        ids += [i for _, i in items]
        spans[g] = (start, start + len(items))
        start += len(items)
    return MarkerSet(name, tuple(names), np.asarray(ids, np.int64), spans)


_SETS: "weakref.WeakKeyDictionary[object, dict[str, MarkerSet]]" = weakref.WeakKeyDictionary()


def _cached(bm) -> dict[str, MarkerSet]:
    """All marker sets of one model, computed once while the model lives (a weak key: the cache does not keep a
    model of ~150 MB alive)."""
    if bm not in _SETS:
        _SETS[bm] = _marker_sets(bm)
    return _SETS[bm]


def _marker_sets(bm) -> dict[str, MarkerSet]:
    """SAGA's 143 and sparse 79 markers of one model."""
    r = _Rest(bm)
    body, face, hand = _body_markers(r), _face_markers(r), _hand_markers(r)
    return {
        "saga": _assemble("saga", [("body", body), ("face", face), ("hand", hand),
                                   ("finger", _finger_markers(r)), ("palm", _palm_markers(r))]),
        "saga_sparse": _assemble("saga_sparse", [("body", body), ("face", face), ("hand", hand),
                                                 ("fingertip", _fingertips(r))]),
    }


def saga_markers(bm: BodyModel) -> MarkerSet:
    """SAGA's 143 markers (49 body, 14 face, 6 hand, 30 finger, 44 palm) on a BodyModel."""
    return _cached(bm)["saga"]


def saga_sparse_markers(bm: BodyModel) -> MarkerSet:
    """SAGA's stage-2 markers (49 body, 14 face, 6 hand, 10 fingertips) on a BodyModel."""
    return _cached(bm)["saga_sparse"]


def farthest_point_sampling(points: np.ndarray, n: int, start: int = 0) -> np.ndarray:
    """Indices (n,) of points (N,3) chosen greedily farthest from those already chosen, from `start`; deterministic."""
    points = np.asarray(points)
    if points.ndim != 2 or points.shape[1] != 3 or points.dtype.kind not in "iuf":
        raise ValueError(f"points: expected an array of numbers of shape (N, 3), got {points.dtype} of shape "
                         f"{points.shape}")
    if points.dtype.kind in "iu":           # (unsigned differences would wrap)
        points = points.astype(np.float64)
    if not np.isfinite(points).all():
        raise ValueError("points: contain NaN or Inf")
    if check_int(n, "n", least=1) > len(points):
        raise ValueError(f"n: expected at most {len(points)} samples, got {n}")
    if check_int(start, "start") >= len(points):
        raise ValueError(f"start: expected a point index in 0..{len(points) - 1}, got {start}")
    chosen = np.empty(n, np.int64)
    chosen[0] = start
    dist = np.linalg.norm(points - points[start], axis=1)
    for i in range(1, n):
        chosen[i] = int(np.argmax(dist))
        dist = np.minimum(dist, np.linalg.norm(points - points[chosen[i]], axis=1))
    return chosen


GOAL_BUDGET = {"right_hand": 99, "left_hand": 40, "feet": 40, "head": 20, "arms": 60, "torso": 80, "legs": 61}


@dataclass(frozen=True)
class GoalVertices:
    """GOAL's sampled vertices: 400 body vertex ids, which of them are the 99 right-hand ones, head-direction pair."""

    vertex_ids: np.ndarray       # (400,)
    right_hand: np.ndarray       # (99,) positions within vertex_ids
    head_back: int               # vertex id at the back of the head
    head_front: int              # vertex id at the nose tip

    def head_direction(self, vertices: torch.Tensor) -> torch.Tensor:
        """GOAL's head direction q: unit vector from the back of the head to the nose, (..., V, 3) -> (..., 3)."""
        q = vertices[..., self.head_front, :] - vertices[..., self.head_back, :]
        return q / q.norm(dim=-1, keepdim=True)


def goal_vertices(bm: BodyModel) -> GoalVertices:
    """The 400 GOAL vertices (right hand 99 first), spread by farthest-point sampling within each part's budget, on
    the rest body with flat hands (the template's; GOAL's checkpoints were trained on this layout)."""
    r = _Rest(bm, hands="flat")
    parts = {
        "right_hand": _hand_parts("right"), "left_hand": _hand_parts("left"),
        "feet": ["left_ankle", "right_ankle", "left_foot", "right_foot"],
        "head": ["head", "jaw", "left_eye_smplhf", "right_eye_smplhf", "neck"],
        "arms": [f"{s}_{j}" for s in ("left", "right") for j in ("collar", "shoulder", "elbow")],
        "torso": ["pelvis", "spine1", "spine2", "spine3"],
        "legs": [f"{s}_{j}" for s in ("left", "right") for j in ("hip", "knee")],
    }
    ids = []
    for key, n in GOAL_BUDGET.items():
        cand = r.on_parts(parts[key])
        ids.append(cand[farthest_point_sampling(r.v[cand], n)])
    all_ids = np.concatenate(ids)
    head = parts["head"][:4]
    hc = r.v[r.on_parts(head)].mean(0)
    return GoalVertices(all_ids, np.arange(GOAL_BUDGET["right_hand"]),
                        r.place(hc, None, 0, _d(B), head), _landmark(r, "nose"))


def foot_vertices(bm: BodyModel, height: float = 0.02) -> dict[str, np.ndarray]:
    """Sole vertex ids per foot part: {'left_heel', 'left_toe', 'right_heel', 'right_toe'} (lowest `height` m at rest)."""
    r = _Rest(bm)
    out = {}
    for s in ("left", "right"):
        ids = r.on_parts([f"{s}_ankle", f"{s}_foot"])
        sole = ids[r.v[ids, 1] < r.v[ids, 1].min() + height]
        mid = 0.5 * (r.v[sole, 2].min() + r.v[sole, 2].max())
        out[f"{s}_heel"] = sole[r.v[sole, 2] < mid]
        out[f"{s}_toe"] = sole[r.v[sole, 2] >= mid]
    return out


def sole_rest_heights(bm: BodyModel, feet: dict[str, np.ndarray] | None = None) -> np.ndarray:
    """Each sole vertex's height (m) above its foot's lowest vertex at rest: (N,), in the order of `feet` (default
    foot_vertices(bm)) concatenated."""
    r = _Rest(bm)
    f = foot_vertices(bm) if feet is None else feet
    lowest = {s: min(r.v[ids, 1].min() for k, ids in f.items() if k.startswith(s)) for s in ("left", "right")}
    return np.concatenate([r.v[ids, 1] - lowest[k.split("_")[0]] for k, ids in f.items()])


def palm_vertices(bm: BodyModel, min_cos: float = 0.7) -> dict[str, np.ndarray]:
    """Palm-side vertex ids of each hand: {'left', 'right'}: wrist-dominated vertices whose normal faces the palm (-y at rest)."""
    r = _Rest(bm)
    n = vertex_normals(torch.as_tensor(r.v)[None], bm.faces.cpu())[0].numpy()
    out = {}
    for s in ("left", "right"):
        ids = r.on_parts([f"{s}_wrist"] + [f"{s}_{f}1" for f in FINGERS if f != "thumb"])
        out[s] = ids[n[ids, 1] < -min_cos]
    return out


def vertex_normals(vertices: torch.Tensor, faces: torch.Tensor) -> torch.Tensor:
    """Area-weighted unit vertex normals: vertices (B,V,3), faces (F,3) -> (B,V,3); differentiable."""
    f = faces.long()
    a, b, c = vertices[:, f[:, 0]], vertices[:, f[:, 1]], vertices[:, f[:, 2]]
    fn = torch.cross(b - a, c - a, dim=-1)                  # (B,F,3), length = 2 * area
    n = torch.zeros_like(vertices)
    for k in range(3):
        n = n.index_add(1, f[:, k], fn)
    return torch.nn.functional.normalize(n, dim=-1)
