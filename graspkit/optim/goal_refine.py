"""GOAL's optimisation post-processing (Taheri et al., CVPR 2022): GNet's grasp (§3.3, Eq. 4–8) and MNet's
approach (§3.4, Eq. 12–13), both by gradient descent with Adam (§3.5), over the whole body's θ (6D) and γ.

GNet refinement, E_GNet = λ_d E_d + λ_θ E_θ + λ_γ E_γ + λ_q E_q + λ_f E_f  (Eq. 8):
    E_d(θ, γ) = ‖d^{h→o} − d̂^{h→o}‖₁   (Eq. 4) the 99 hand-to-object offsets, *recomputed at every step* from the
                current hand vertices to their closest object points, against GNet's predicted ones
    E_θ = ‖θ − θ̂‖₂², E_γ = ‖γ − γ̂‖₁    (Eq. 5) coupling to GNet's pose and translation (squared here, so that the
                gradient is defined where θ = θ̂, i.e. at the start)
    E_q = ‖q(θ, γ) − q̂‖₁               (Eq. 6) head direction (back of the head -> nose) against GNet's q̂
    E_f = |v_z(k) − g|, k = argmin_i v_z(i)  (Eq. 7) the lowest body vertex on the ground. GOAL's world has y up;
                graspkit's has z up, so the vertical axis is z (g = 0 is the floor). The lowest vertex is searched
                among the feet and the 400 sampled vertices, which hold the lowest point of any standing body.
All terms are means over their elements (metres for E_d, E_γ, E_f), per sample; the batch sums them, so every
sample is refined independently.

graspkit's addition, E_pen (not in GOAL; on only when the refiner is given the object's signed distance, `PosedSDF`,
and `GraspRefineWeights.pen` > 0) — SAGA's E_colli (Eq. 7) both ways, with the points GraspPose-Opt uses
(docs/saga.md):
    λ_pen Σ_x max(−S(x, O), 0)      x: the vertices of both hands, the same moved 5 and 10 mm inward along the hand's
                                    vertex normals, and the forearm vertices (E^B_colli)
  + λ_pen^O Σ_o max(−S(o, V^h), 0)  o: the `object_near` object points nearest the hands (re-chosen every `refresh`
                                    steps), S(o, V^h) signed by the normal of the nearest hand vertex (E^O_colli)
Why: Eq. 4–8 have no penetration term, and E_d pulls each of the 99 hand vertices to the object point closest to it
*now*, which is on the far side of a thin wall as often as on the near one once a hand is inside; GNet's offsets are
off by ~1.5 cm per coordinate, so the refinement pulls some hands into the object as it pulls others out
(docs/goal.md). The inner points see a wall that passes between the hand's vertices; the second sum sees an edge of
the object (a mug's rim or handle) cutting into the palm between vertices, which no hand point sees. GOAL's Eq. 4–8
alone: `pen=0` or no `sdf`.

The restart (graspkit's, with E_pen only; `GraspRefineWeights.restart_sunk`): a hand that starts with the object
through it (a handle through the palm) can stay there, as E_pen's pushes on the two sides of the handle cancel. After
the run, a sample with an E_pen point deeper than `restart_sunk` is refined a second time from GNet's θ̂ with γ̂
moved rigidly by the one of `RESTART_SHIFTS` (0, and 2–8 cm along each axis) that has the lowest full energy there,
and keeps the run with the lower full energy (E_pen's both sums included) — SAGA's restart (docs/saga.md) with a
different second start.

MNet refinement (Eq. 12–13), once the hand is within 10 cm of the goal hand: each hand vertex is moved towards its goal
position along the straight line at MNet's average predicted hand speed, v_{t+1} = v_t + ‖v̇_t‖ l (Eq. 12, ‖v̇_t‖ read
as the mean of the hand vertices' speeds, not the length of their mean velocity, which is smaller for a turning hand;
graspkit stops at the goal instead of overshooting it), and the frame's θ, γ are fitted to those hand vertices with
E_MNet = λ_Θ E_Θ + λ_v^h E_v^h (Eq. 13): E_Θ couples to MNet's Θ̂ (squared), E_v^h = ‖v^h − v^h_{t+1}‖₁.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
import torch
from torch import Tensor

from graspkit.body.skeleton import JOINT_INDEX
from graspkit.checks import check_finite, check_int, check_real, check_rotation, check_weight
from graspkit.models.gnet import SparseBody, pose_rotmats
from graspkit.objects.distance import nearest_neighbours
from graspkit.objects.sdf import SDFGrid
from graspkit.optim.step import with_autograd

if TYPE_CHECKING:
    from graspkit.body import BodyModel
    from graspkit.body.markers import GoalVertices

FEET_PARTS = ("left_ankle", "right_ankle", "left_foot", "right_foot")
GOAL_HAND_RADIUS = 0.10   # m: MNet's refinement starts when the hand is this close to the goal hand (§3.4)


def hand_object_offsets(points: Tensor, object_points: Tensor) -> Tensor:
    """Offsets (B,N,3) from points (B,N,3) to their closest object points (B,P,3) (or (P,3)); differentiable in points."""
    obj = object_points if object_points.dim() == 3 else object_points[None]
    obj = obj.expand(points.shape[0], -1, -1).to(points.dtype)
    _, idx = nearest_neighbours(points.detach(), obj.detach())
    nearest = torch.gather(obj, 1, idx[..., None].expand(-1, -1, 3))
    return nearest - points


def feet_vertex_ids(bm: BodyModel) -> np.ndarray:
    """Ids of the vertices whose dominant skinning joint is an ankle or a foot (the soles and toes among them)."""
    part = bm.lbs_weights.argmax(1).numpy()
    return np.flatnonzero(np.isin(part, [JOINT_INDEX[j] for j in FEET_PARTS]))


@dataclass
class GraspRefineWeights:
    """λ of Eq. 8 and the Adam settings (graspkit's values, tuned on the procedural data)."""

    d: float = 1.0
    theta: float = 0.05
    gamma: float = 0.02
    q: float = 0.05
    f: float = 1.0
    pen: float = 0.0          # graspkit's E_pen (module docstring); used only with a PosedSDF
    inner_depths: tuple[float, ...] = (0.005, 0.01)   # m: E_pen also at the hand vertices moved this far inward
    pen_floor: float = 0.0    # m: E_pen's hinge floor, max(-S - floor, 0) (depth allowed for free)
    pen_object: float = 0.0   # λ_pen^O: E_pen's other way, object points inside the hands (only with pen > 0)
    object_near: int = 512    # object points (nearest the hands) that the other way looks at
    refresh: int = 10         # steps between choosing them again
    restart_sunk: float | None = None   # m: a second run, from a shifted start, for samples with an E_pen point
                                        # deeper than this after the first (module docstring; None: one run)
    steps: int = 200
    lr: float = 3e-3

    def __post_init__(self) -> None:
        for name in ("d", "theta", "gamma", "q", "f", "pen", "pen_floor", "pen_object"):   # a negative λ rewards
            check_weight(getattr(self, name), name)                                      # what its term removes

    def lambdas(self) -> dict[str, float]:
        """λ of each energy term, by the term's name in GraspRefiner.energy."""
        return {"d": self.d, "theta": self.theta, "gamma": self.gamma, "q": self.q, "f": self.f, "pen": self.pen,
                "pen_object": self.pen_object}


# The restart's candidate starts: γ̂ + each of these (m); 0 first, then 2, 4, 6, 8 cm along ±x, ±y, ±z.
RESTART_SHIFTS = torch.cat([torch.zeros(1, 3)] + [s * torch.cat([torch.eye(3), -torch.eye(3)])
                                                   for s in (0.02, 0.04, 0.06, 0.08)])

# graspkit's refinement with E_pen (module docstring): λ_d 3, λ_pen 0.1 and λ_pen^O PEN_OBJECT, chosen on the
# validation objects (apple, toothbrush); 400 steps (at 200 the deepest hands were still being pushed out) and the
# restart for hands left more than 1 mm inside, chosen on the validation and training objects (docs/goal.md).
# Eq. 4–8 alone: GraspRefineWeights().
PEN_OBJECT = 0.03
PEN_WEIGHTS = GraspRefineWeights(d=3.0, pen=0.1, pen_object=PEN_OBJECT, steps=400, restart_sunk=0.001)


class PosedSDF:
    """Signed distance S(x, O) (B,N) for a batch of posed objects: sample b's object is grids[b] (an SDFGrid in the
    mesh's own frame) placed by x = R[b] x_mesh + t[b]; samples that share a grid object are looked up together."""

    def __init__(self, grids: list[SDFGrid], R: Tensor, t: Tensor) -> None:
        if R.dim() != 3 or R.shape[1:] != (3, 3) or t.shape != (R.shape[0], 3) or len(grids) != R.shape[0]:
            raise ValueError(f"grids, R, t: expected B grids, R (B,3,3), t (B,3); got {len(grids)}, "
                             f"{tuple(R.shape)}, {tuple(t.shape)}")
        check_rotation(R, "R")
        check_finite(t, "t", "translations in metres")
        self.grids, self.R, self.t = grids, R.float(), t.float()
        groups: dict[int, list[int]] = {}
        for b, g in enumerate(grids):
            groups.setdefault(id(g), []).append(b)
        self.groups = [(grids[ix[0]], torch.as_tensor(ix)) for ix in groups.values()]

    @classmethod
    def in_frame(cls, grids: list[SDFGrid], R_obj: Tensor, t_obj: Tensor, R: Tensor, o: Tensor) -> "PosedSDF":
        """Objects posed in the world by x_w = R_obj x_mesh + t_obj ((B,3,3), (B,3)), seen in the frame
        x' = R (x_w - o) ((B,3,3), (B,3)): R' = R R_obj, t' = R (t_obj - o)."""
        R, o = R.float(), o.float()
        return cls(grids, R @ R_obj.float(), ((t_obj.float() - o)[:, None] @ R.transpose(1, 2))[:, 0])

    def __len__(self) -> int:
        return len(self.grids)

    def subset(self, ix: Tensor) -> "PosedSDF":
        """The posed objects of samples `ix` (K,) (long)."""
        return PosedSDF([self.grids[int(i)] for i in ix], self.R[ix], self.t[ix])

    def __call__(self, x: Tensor) -> Tensor:
        """x (B,N,3) in the posed frame -> signed distances (B,N), negative inside; differentiable in x."""
        if x.dim() != 3 or x.shape[0] != len(self):
            raise ValueError(f"x: expected shape ({len(self)}, N, 3), got {tuple(x.shape)}")
        local = (x - self.t[:, None].to(x.dtype)) @ self.R.to(x.dtype)       # row vectors: R^T (x - t)
        out = x.new_zeros(x.shape[:2])
        for grid, ix in self.groups:
            out = out.index_put((ix,), grid(local[ix]))
        return out


@dataclass
class RefinedGrasp:
    """The refined Θ: rot6d (B,55,6), transl (B,3); energy terms (batch means) at the first and last step of the
    first run."""

    rot6d: Tensor
    transl: Tensor
    history: list[dict[str, float]] = field(default_factory=list)
    restarted: Tensor | None = None     # (B,) bool: the sample kept the restart's run (None: no restart was asked)


class GraspRefiner:
    """Eq. 4–8 on one body model: the sampled vertices (hand first), the head pair and the feet, evaluated sparsely."""

    def __init__(self, bm: BodyModel, gv: GoalVertices, n_hand: int = 99) -> None:
        from graspkit.optim.grasppose import forearm_vertex_ids, hand_faces, hand_vertex_ids

        self.n_hand, self.n_sampled = n_hand, len(gv.vertex_ids)
        base = np.concatenate([gv.vertex_ids, [gv.head_back, gv.head_front], feet_vertex_ids(bm)])
        self.body = SparseBody(bm, torch.as_tensor(base))
        hands, arms = hand_vertex_ids(bm), forearm_vertex_ids(bm)
        self.pen_body = SparseBody(bm, torch.as_tensor(np.concatenate([base, hands, arms])))   # E_pen's points too
        n0, nh = len(base), len(hands)
        self.sl_hands, self.sl_arms = slice(n0, n0 + nh), slice(n0 + nh, None)
        self.hand_faces = hand_faces(bm, torch.as_tensor(hands))

    def vertices(self, rot6d: Tensor, transl: Tensor, betas: Tensor, pen: bool = False) -> Tensor:
        """Sparse vertices (B, 400 + 2 + feet [+ hands + forearms], 3): sampled (hand first), head back, nose, feet
        (and, if `pen`, E_pen's hand and forearm vertices)."""
        return (self.pen_body if pen else self.body)(pose_rotmats(rot6d), betas, transl)[0]

    def pen_points(self, v: Tensor, inner_depths: tuple[float, ...], hands: Tensor | None = None,
                   normals: Tensor | None = None) -> Tensor:
        """E_pen's points (B,M,3) of `vertices(..., pen=True)`: hand vertices, the same moved inward, forearms
        (GraspPose-Opt's E^B_colli points, grasppose.collision_points); `hands` (the slice of v) and their vertex
        `normals` (B,n_h,3) are computed unless given."""
        from graspkit.optim.grasppose import collision_points

        hands = v[:, self.sl_hands] if hands is None else hands
        return collision_points(hands, self.hand_faces, inner_depths, v[:, self.sl_arms], normals=normals)

    def near_object_points(self, v: Tensor, object_points: Tensor, k: int) -> Tensor:
        """Indices (B,k) of the object points (B,P,3) nearest the hands of `vertices(..., pen=True)` (B,V,3)."""
        from graspkit.optim.grasppose import nearest_points

        hands = v[:, self.sl_hands]
        return nearest_points(object_points.expand(len(v), -1, -1).to(hands.dtype), hands, k)

    def energy(self, rot6d: Tensor, transl: Tensor, betas: Tensor, hat: dict[str, Tensor], object_points: Tensor,
               ground: float = 0.0, sdf: PosedSDF | None = None,
               inner_depths: tuple[float, ...] = (0.005, 0.01), pen_floor: float = 0.0,
               near: Tensor | None = None, v: Tensor | None = None) -> dict[str, Tensor]:
        """Per-sample terms (B,) of Eq. 4–7 at (rot6d, transl) against GNet's `hat` (rot6d, transl, head_dir,
        hand_offsets), and E_pen (summed depth, m) when `sdf` is given: 'pen' the hand points inside the object, and
        with `near` (B,K) (indices of object points) 'pen_object' those object points inside the hands. `v`: the
        vertices at (rot6d, transl) if already computed (`vertices(..., pen=sdf is not None)`)."""
        v = self.vertices(rot6d, transl, betas, pen=sdf is not None) if v is None else v
        hand = v[:, :self.n_hand]
        d = hand_object_offsets(hand, object_points)
        back, front = v[:, self.n_sampled], v[:, self.n_sampled + 1]
        q = torch.nn.functional.normalize(front - back, dim=-1)
        low = v[:, :self.sl_hands.start, 2] if sdf is not None else v[..., 2]
        e = {"d": (d - hat["hand_offsets"]).abs().mean((1, 2)),
             "theta": (rot6d - hat["rot6d"]).pow(2).mean((1, 2)),
             "gamma": (transl - hat["transl"]).abs().mean(1),
             "q": (q - hat["head_dir"]).abs().mean(1),
             "f": (low.min(1).values - ground).abs()}
        if sdf is not None:
            from graspkit.body.markers import vertex_normals

            hands = v[:, self.sl_hands]
            normals = vertex_normals(hands, self.hand_faces) if inner_depths or near is not None else None
            e["pen"] = torch.relu(-sdf(self.pen_points(v, inner_depths, hands, normals)) - pen_floor).sum(-1)
            if near is not None:
                from graspkit.optim.grasppose import _signed_to_cloud

                # the normals only sign this term (no gradient through them); a slice of its own keeps the order in
                # which backward sums the gradients on v, so the refinement is the one with the normals computed
                # twice, bit for bit (tests/test_goal_refine.py)
                cloud = v[:, self.sl_hands]
                obj = object_points.expand(len(v), -1, -1).to(cloud.dtype)
                o = torch.gather(obj, 1, near[..., None].expand(-1, -1, 3))
                so, _ = _signed_to_cloud(o, cloud, normals)
                e["pen_object"] = torch.relu(-so).sum(-1)
        return e

    @with_autograd
    def __call__(self, hat: dict[str, Tensor], betas: Tensor, object_points: Tensor,
                 weights: GraspRefineWeights | None = None, ground: float = 0.0,
                 sdf: PosedSDF | None = None) -> RefinedGrasp:
        """Refine GNet's outputs `hat` {rot6d (B,55,6), transl (B,3), head_dir (B,3), hand_offsets (B,99,3)}
        for bodies `betas` (B,10) and object points (B,P,3)|(P,3), world frame, z up; with `sdf` (the objects'
        signed distance in this frame) and weights.pen > 0, graspkit's E_pen as well (and, with
        weights.restart_sunk, the restart of the module docstring)."""
        for k, shape in (("rot6d", (55, 6)), ("transl", (3,)), ("head_dir", (3,)), ("hand_offsets", (self.n_hand, 3))):
            if k not in hat or tuple(hat[k].shape[1:]) != shape:
                raise ValueError(f"hat[{k!r}]: expected shape (B, {', '.join(map(str, shape))}), "
                                 f"got {None if k not in hat else tuple(hat[k].shape)}")
        B = hat["rot6d"].shape[0]
        if B == 0:
            raise ValueError("hat: expected at least one sample, got 0 rows")
        for k in ("rot6d", "transl", "head_dir", "hand_offsets"):
            if hat[k].shape[0] != B or not bool(torch.isfinite(hat[k]).all()):
                raise ValueError(f"hat[{k!r}]: expected {B} finite rows (one per sample)")
        nb = self.body.bm.num_betas
        if not isinstance(betas, Tensor) or betas.dim() != 2 or betas.shape[0] not in (1, B) \
                or betas.shape[1] > nb or not bool(torch.isfinite(betas).all()):
            got = tuple(betas.shape) if isinstance(betas, Tensor) else type(betas).__name__
            raise ValueError(f"betas: expected finite shape coefficients (1 or B = {B}, k <= {nb}), got {got}")
        if not isinstance(object_points, Tensor) or object_points.shape[-1] != 3 or object_points.dim() not in (2, 3) \
                or not bool(torch.isfinite(object_points).all()):
            raise ValueError("object_points: expected finite points (P, 3) or (B, P, 3) in metres")
        if object_points.shape[-2] == 0:
            raise ValueError(f"object_points: expected at least one point, got shape {tuple(object_points.shape)}")
        ground = check_real(ground, "ground", "a finite floor height in metres")
        w = weights or GraspRefineWeights()
        check_int(w.steps, "weights.steps", least=0)
        check_real(w.lr, "weights.lr", "a learning rate > 0", positive=True)
        if any(not 0 < x < 0.05 for x in w.inner_depths):
            raise ValueError(f"weights.inner_depths: expected depths in metres in (0, 0.05), got {w.inner_depths}")
        if sdf is not None and len(sdf) != hat["rot6d"].shape[0]:
            raise ValueError(f"sdf: expected one object per sample ({hat['rot6d'].shape[0]}), got {len(sdf)}")
        sdf = sdf if w.pen > 0 else None
        if w.object_near < 1 or w.refresh < 1:
            raise ValueError(f"weights.object_near, weights.refresh: expected >= 1, got {w.object_near}, {w.refresh}")
        if w.restart_sunk is not None and not w.restart_sunk > 0:
            raise ValueError(f"weights.restart_sunk: expected a depth in metres > 0 or None, got {w.restart_sunk}")
        object_points = object_points if object_points.dim() == 3 else object_points[None]
        hat = {k: t.detach() for k, t in hat.items()}
        rot6d, transl, history = self._descend(hat, betas, object_points, w, ground, sdf, hat["transl"])
        if sdf is None or w.restart_sunk is None:
            return RefinedGrasp(rot6d, transl, history)
        restarted = torch.zeros(len(rot6d), dtype=torch.bool)
        energy, depth = self.full_energy(rot6d, transl, betas, hat, object_points, w, ground, sdf)
        ix = torch.nonzero(depth > w.restart_sunk)[:, 0]
        if len(ix):
            sub, b_ix, sdf_ix = {k: t[ix] for k, t in hat.items()}, betas[ix], sdf.subset(ix)
            pts = object_points[ix] if len(object_points) > 1 else object_points
            args = (b_ix, sub, pts, w, ground, sdf_ix)
            e0 = torch.stack([self.full_energy(sub["rot6d"], sub["transl"] + d, *args)[0] for d in RESTART_SHIFTS])
            start = sub["transl"] + RESTART_SHIFTS[e0.argmin(0)]
            r2, t2, _ = self._descend(sub, b_ix, pts, w, ground, sdf_ix, start)
            better = self.full_energy(r2, t2, *args)[0] < energy[ix]
            keep = ix[better]
            rot6d[keep], transl[keep], restarted[keep] = r2[better], t2[better], True
        return RefinedGrasp(rot6d, transl, history, restarted)

    def _descend(self, hat: dict[str, Tensor], betas: Tensor, object_points: Tensor, w: GraspRefineWeights,
                 ground: float, sdf: PosedSDF | None, transl0: Tensor) -> tuple[Tensor, Tensor, list[dict[str, float]]]:
        """Adam on (θ, γ) from (θ̂, transl0 (B,3)) for w.steps -> rot6d (B,55,6), transl (B,3), the energies (batch
        means) at the first and last step."""
        lam = w.lambdas()
        near = None
        rot6d = hat["rot6d"].clone().requires_grad_(True)
        transl = transl0.detach().clone().requires_grad_(True)
        opt = torch.optim.Adam([rot6d, transl], lr=w.lr)
        history = []
        for step in range(w.steps + 1):
            v = self.vertices(rot6d, transl, betas, pen=sdf is not None)
            if sdf is not None and w.pen_object > 0 and step % w.refresh == 0:
                near = self.near_object_points(v, object_points, w.object_near)
            terms = self.energy(rot6d, transl, betas, hat, object_points, ground, sdf, w.inner_depths, w.pen_floor,
                                near, v)
            total = sum(lam[k] * t for k, t in terms.items())
            if step in (0, w.steps):
                history.append({"step": step, "E": float(total.detach().mean()),
                                **{k: float(t.detach().mean()) for k, t in terms.items()}})
            if step == w.steps:
                break
            opt.zero_grad()
            total.sum().backward()
            opt.step()
        return rot6d.detach(), transl.detach(), history

    def full_energy(self, rot6d: Tensor, transl: Tensor, betas: Tensor, hat: dict[str, Tensor], object_points: Tensor,
                    w: GraspRefineWeights, ground: float, sdf: PosedSDF) -> tuple[Tensor, Tensor]:
        """Per sample (B,): E_GNet + E_pen (both sums, the object points nearest the hands chosen here) at
        (rot6d, transl), and the depth (m) of the deepest E_pen point inside the object (negative: all outside)."""
        lam = w.lambdas()
        with torch.no_grad():
            v = self.vertices(rot6d, transl, betas, pen=True)
            near = self.near_object_points(v, object_points, w.object_near) if w.pen_object > 0 else None
            terms = self.energy(rot6d, transl, betas, hat, object_points, ground, sdf, w.inner_depths, w.pen_floor,
                                near, v)
            depth = (-sdf(self.pen_points(v, w.inner_depths))).max(1).values
        return sum(lam[k] * t for k, t in terms.items()), depth


# ------------------------------------------------------------------------------------------- MNet (Eq. 12-13)

def hand_step_targets(hand_now: Tensor, hand_goal: Tensor, speed: Tensor) -> Tensor:
    """Eq. 12: v_{t+1} = v_t + s l, l the unit vector to the goal, s (B,) the average hand speed (m/frame),
    not past the goal: hand vertices (B,N,3) -> (B,N,3)."""
    if hand_now.shape != hand_goal.shape or hand_now.dim() != 3 or hand_now.shape[-1] != 3:
        raise ValueError(f"hand_now, hand_goal: expected the same shape (B, N, 3), got {tuple(hand_now.shape)}, "
                         f"{tuple(hand_goal.shape)}")
    for x, n, what in ((hand_now, "hand_now", "positions in metres"), (hand_goal, "hand_goal", "positions in metres"),
                       (speed, "speed", "speeds in m/frame")):
        check_finite(x, n, what)
    if bool((torch.as_tensor(speed) < 0).any()):
        raise ValueError("speed: expected speeds >= 0 (m/frame; Eq. 12 steps towards the goal)")
    delta = hand_goal - hand_now
    dist = delta.norm(dim=-1, keepdim=True)
    step = torch.minimum(speed.reshape(-1, 1, 1).expand_as(dist), dist)
    return hand_now + step * delta / dist.clamp_min(1e-9)


@dataclass
class MotionRefineWeights:
    """λ of Eq. 13 and the Adam settings."""

    theta: float = 1.0
    transl: float = 1000.0    # within E_Θ: γ weighs more than a 6D entry, so the body does not slide to help the hand
    hand: float = 1.0
    steps: int = 40
    lr: float = 2e-3


@with_autograd
def refine_frame(hand_body: SparseBody, rot6d_hat: Tensor, transl_hat: Tensor, betas: Tensor, hand_target: Tensor,
                 weights: MotionRefineWeights | None = None) -> tuple[Tensor, Tensor]:
    """Eq. 13 for one frame: Θ (B,55,6), (B,3) fitted so that `hand_body`'s vertices (B,N,3) meet `hand_target`,
    coupled to MNet's Θ̂; returns the refined (rot6d, transl)."""
    w = weights or MotionRefineWeights()
    check_int(w.steps, "weights.steps", least=0)
    check_real(w.lr, "weights.lr", "a learning rate > 0", positive=True)
    for name in ("theta", "transl", "hand"):
        check_weight(getattr(w, name), f"weights.{name}")
    B = rot6d_hat.shape[0] if rot6d_hat.dim() == 3 else -1
    for x, n, shape in ((rot6d_hat, "rot6d_hat", (B, 55, 6)), (transl_hat, "transl_hat", (B, 3)),
                        (hand_target, "hand_target", (B, hand_body.n, 3))):
        if B < 1 or tuple(x.shape) != shape:
            raise ValueError(f"{n}: expected shape {shape if B >= 1 else '(B >= 1, ...)'}, got {tuple(x.shape)}")
        check_finite(x, n, "finite values")
    check_finite(betas, "betas", "shape coefficients")
    rot6d_hat, transl_hat, hand_target = rot6d_hat.detach(), transl_hat.detach(), hand_target.detach()
    rot6d = rot6d_hat.clone().requires_grad_(True)
    transl = transl_hat.clone().requires_grad_(True)
    opt = torch.optim.Adam([rot6d, transl], lr=w.lr)
    for _ in range(w.steps):
        v = hand_body(pose_rotmats(rot6d), betas, transl)[0]
        e_theta = (rot6d - rot6d_hat).pow(2).mean((1, 2)) + w.transl * (transl - transl_hat).pow(2).mean(1)
        e_hand = (v - hand_target).abs().mean((1, 2))
        opt.zero_grad()
        (w.theta * e_theta + w.hand * e_hand).sum().backward()
        opt.step()
    return rot6d.detach(), transl.detach()
