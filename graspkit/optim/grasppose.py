"""GraspPose-Opt (SAGA §3.2, Eq. 4-7, Alg. 1, A.4): fit an SMPL-X body to generated markers and contacts.

    E_opt(Theta) = E_fit + E^o_colli + E^o_cont + E^g_cont                                        (Eq. 4)
    E_fit        = sum |M^ - M(Theta)|_1 + alpha_theta |theta|^2                                 (Eq. 5)
    E^o_cont     = alpha^o_cont sum_o C^_o d(o, V_B) + alpha^m_cont sum_m C^_m d(m, O)            (Eq. 6)
    E_colli      = alpha^B_colli sum_{b in V^h_B} max(-S(b, O), sigma_b)
                 + alpha^O_colli sum_{o in O} max(-S(o, V^h_B), sigma_o)                          (Eq. 7)
    E^g_cont     = alpha_g sum_{v in V^f_B} |h(v)|                                                (§3.2)

d(x, Y) = min_y |x - y|^2 (squared, as Eq. 3), S = signed distance (negative inside), V^h_B the hand vertices,
V^f_B the sole vertices, h the height above the floor. Theta = (t, R (6D), beta, theta_b, theta_h, theta_e):
theta_b is the 32-D latent of the pose prior (graspkit.models.pose_prior, in place of VPoser), theta_h 24 hand-PCA
coefficients per hand (SAGA: theta_h in R^48), theta_e the two eye rotations.

Alg. 1 (A.4): stage 1, 300 Adam steps on t, R with E_fit (lr 0.016); stage 2, 400 steps on t, R, beta, theta_b with
E_fit (lr 0.012); stage 3, 500 steps on theta_b, theta_h, theta_e with the full energy (lr 0.008).
Weights (A.4): alpha^o_cont = alpha^m_cont = 15, alpha^O_colli = 100, alpha^B_colli = 200, alpha_theta = 0.0005.

graspkit's choices where the paper is silent (all in `GraspPoseWeights` / `GraspPoseConfig`):
- sigma_b = sigma_o = 0: every penetration costs, as in the authors' released code (its collision terms have no
  floor); each hinge is written max(-S - sigma, 0) (the paper's max(-S, sigma) minus the constant sigma, so a grasp
  without penetration reads 0; the gradient is the same). Chosen on the validation objects (apple, toothbrush; 4
  placements x 10 samples): against 1 mm, contact 0.94 -> 0.96, volume 0.26 -> 0.14 cm3, depth 0.09 -> 0.05 cm
  (docs/saga.md). alpha_g = 1 per sole vertex.
- Initialisation: theta_b = 0 (the prior's mean pose), beta = 0, hands at the PCA mean, eyes 0; R and t from the
  least-squares rigid fit (Kabsch) of that body's body and face markers to the target ones.
- V_B in d(o, V_B) is the hand vertices (contacts are with the hands; the rest of the body is far), and only the
  256 object points with the highest C^_o enter that sum per sample; S(o, V^h_B) is taken for the 512 object points
  nearest the hand at the start of stage 3 (the hand moves little in stage 3), signed by the hand's vertex normals;
  points that end inside the hand outside that set are not seen (docs/saga.md: up to 7.1 against a reported 0.31).
  S(b, O) uses the object's signed-distance grid when one is given, else the point cloud with its normals (SAGA's
  "signed distance from point x to point cloud Y"; the nearest point's normal signs it, so beside a sharp edge of a
  sparse cloud a point outside can read as inside). The evaluation, the lessons and `graspkit.saga` pass
  `collision_sdf_grid(name)` (graspkit.data.grasp_io): cells of at most 2 mm. A 64-node grid (cells up to 7.5 mm)
  reads most points 1-2 mm inside the thin walls of the frying pan and wine glass as outside, so E^B_colli could
  not see a finger there (docs/objects.md).
- In stage 3 the nearest-neighbour pairs behind d and S are recomputed every 10 steps and held in between (the
  distances stay differentiable through the held pairs; the body moves little in 10 steps); energies reported
  before and after a stage use fresh pairs.
- The polish (`GraspPoseConfig.polish`, graspkit's): stage 3 goes on for 100 more steps of the same energy at lr
  0.001. Adam moves every parameter by about its learning rate per step whatever the gradient, so at stage 3's
  0.008 the fingers jitter by millimetres across the surface and the last step decides contact or penetration.
  Chosen on the validation and training objects (docs/saga.md); `polish=(0, 0.0)` is Alg. 1's schedule.
- Energies are summed over the samples of a batch (the samples are independent; Adam's steps are per parameter).
- The free arm joints (`GraspPoseConfig.free_joints`, default `ARM_JOINTS`; `()` is Alg. 1): both collars,
  shoulders, elbows and wrists get a 6D rotation on top of the prior's decoded pose, optimised with theta_b in stages
  2-3, penalised by `weights.free_joints` (5e-4 = alpha_theta) on the 6D offsets and by `weights.limits` (0.5 per
  degree) past the human range of metrics.joint_limit_excess. Our prior is narrower than VPoser: through theta_b
  alone, ground-truth markers are refitted with the hands up to 0.8 cm off and 2.40 cm3 of penetration (E_fit + E_g)
  where the ground-truth meshes have 0.41; with the arms free 0.40. Chosen on the training objects (2 placements x 5
  samples of nine objects: mean volume 2.77 -> 1.41 cm3, arm joints past the range 0.1 %, none by more than 0.05
  deg); the limits weight there too (0.05/deg: 0.7 % of arm joints past the range, up to 7 deg); docs/saga.md.
- The restart (`GraspPoseConfig.restart_sunk`, graspkit's, default 5 mm; None is Alg. 1's single run): stage 3 runs
  a second time from the same stage-2 state with E^O_colli off for a sample while one of its hand vertices is more
  than 5 mm inside the object (`sunk_depth`), and each sample keeps the run with the lower full (ungated) energy.
  A sunk hand is pushed deeper by E^O_colli (its object points leave the hand fastest through the back of the hand);
  the gate lets E^B_colli lift it, but alone it lets thin objects through hands that were not sunk, which the full
  energy tells apart. Chosen on the training objects (mean volume 1.41 -> 1.04 cm3; docs/saga.md).
- Stage-2 collision and E^B_colli's extra points (`GraspPoseConfig.stage2_collision`, `inner_depths`, `forearms`;
  graspkit's, on by default; False, (), False is Alg. 1): E^B_colli is on in stage 2 as well (where `collision` is),
  and in stages 2 and 3 its points are the hand vertices, the same moved 5 and 10 mm inward along the hand's vertex
  normals, and the forearm vertices. Why: the samples that penetrate most put the hand where the object is (into a
  mug's or bowl's opening with the wall through the palm, or round a tube that passes through the palm). No hand
  vertex is then inside the object (a 4 mm wall passes between them), so E^B_colli sees nothing, and E^O_colli
  pushes each object point out through the nearer side of the hand, which cancels for a wall through its middle.
  With E^B_colli in stage 2 the body comes to the markers from outside and the hand stops at the surface; the inner
  points see a wall through the palm; a hand held out lets the forearm in, hence its vertices. Chosen on the
  training objects (2 placements x 5 samples of nine objects, the same draws): mean volume 1.56 -> 0.29 cm3,
  contact 1.00 -> 1.00, depth 0.05 -> 0.02 cm; without the forearms 0.35 (one forearm through the cracker box,
  14 cm3); with the extra points in stage 2 but not stage 3, 0.93 (docs/saga.md).
- Stage-2 ground (`GraspPoseConfig.stage2_ground`, graspkit's, on by default; False is Alg. 1): E^g_cont is on in
  stage 2 as well (where `ground` is), where t is free. Why: when a hand brushes into the object during stage 2,
  E^B_colli's gradient is hundreds of times E_fit's, and Adam carries that kick on for ten-odd steps (momentum) and
  then scales E_fit's steps down for hundreds (its second moment): t and R jump and stay off, and stage 3, which
  cannot move them, fits the pose to the markers from there. Whole bodies ended 5 cm under or 13 cm above the
  floor (the lowest vertex; E_fit after stage 2 up to 65 against 2-3 without the stage-2 collision). The soles'
  202 vertices at alpha_g = 1 outweigh E_fit's 143 markers in height, so the body stands on the floor through
  stage 2 (docs/saga.md).
- Ground from the rest shape (`GraspPoseConfig.ground_rest`, graspkit's, on by default; False is the paper's
  |h(v)|): E^g_cont is alpha_g sum |h(v) - h0(v)|, h0(v) the sole vertex's height above its foot's lowest vertex at
  rest (mean shape; 0 to 2 cm, median 0.8 cm). V^f_B is each foot's lowest 2 cm, so the paper's |h| (an L1, which
  sets the median on the floor) sinks each foot's lowest vertices about 1 cm under it; with h0 a foot flat as at
  rest reads 0 with its lowest vertex on the floor (docs/saga.md).
- A floor term (`GraspPoseWeights.floor`, graspkit's, since 2026-12-02; 0 turns it off): with E^g_cont, in the same
  stages, a_floor (-min_{v in V^f_B} h(v))_+ with a_floor = 1000 per metre, GraspMotion-Opt's term (and its weight
  until 2026-12-07; graspkit.optim.graspmotion). Why: a foot turned from its rest shape (the sampled markers turn
  it) has its toes under the floor and its heels above, and E^g_cont's L1 balances the two ends, so grasp bodies
  stood up to 2.5 cm into the floor with their toes. It is one-sided: a foot may lift (Adam carries a correction a
  few mm on), not sink (docs/saga.md, "The floor").
Frames: everything in the object frame of WholeGrasp-VAE (object centre at 0, z up, floor at z = -t_O).
"""
from __future__ import annotations

import copy
import math
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

import numpy as np
import torch
from torch import Tensor
from tqdm.auto import tqdm

from graspkit.body.markers import foot_vertices, saga_markers, sole_rest_heights, vertex_normals
from graspkit.checks import check_bool, check_finite, check_int, check_probabilities, check_rotation, check_weight
from graspkit.body.skeleton import FINGERS, JOINT_INDEX, JOINT_NAMES
from graspkit.metrics import joint_limit_excess
from graspkit.models.gnet import SparseBody
from graspkit.models.wholegrasp import check_height
from graspkit.objects.distance import centred_cdist, require_points_in_metres, require_unit_normals
from graspkit.objects.sdf import SDFGrid
from graspkit.optim.step import energy_step, with_autograd
from graspkit.progress import hidden
from graspkit.rotations import axis_angle_to_matrix, matrix_to_axis_angle, matrix_to_rot6d, rot6d_to_matrix

if TYPE_CHECKING:
    from graspkit.body import BodyModel
    from graspkit.models.pose_prior import PosePrior

TERMS = ("fit", "prior", "contact_object", "contact_marker", "colli_body", "colli_object", "ground", "heuristic",
         "limits")


@dataclass
class GraspPoseWeights:
    """Weights and thresholds of Eq. 5-7 and S.3 (A.4 where the paper gives them; see the module docstring)."""

    prior: float = 5e-4           # alpha_theta
    contact_object: float = 15.0  # alpha^o_cont
    contact_marker: float = 15.0  # alpha^m_cont
    colli_object: float = 100.0   # alpha^O_colli (object points inside the hand)
    colli_body: float = 200.0     # alpha^B_colli (hand vertices inside the object)
    sigma_b: float = 0.0          # m: hinge floor of E^B_colli (penetration allowed for free)
    sigma_o: float = 0.0          # m: hinge floor of E^O_colli
    free_joints: float = 5e-4     # on the 6D offsets of GraspPoseConfig.free_joints (graspkit's; = alpha_theta)
    limits: float = 0.5           # per degree a free joint turns past the human range (metrics.joint_limit_excess)
    ground: float = 1.0           # alpha_g (not in the paper)
    floor: float = 1000.0         # per metre the lowest sole vertex is under the floor (graspkit's; 0: none)
    heuristic: float = 15.0       # alpha^h_cont of S.3 (not in the paper)
    heuristic_prior: float = 0.7  # S.3: hand vertices with prior contact probability above this ...
    heuristic_radius: float = 0.02  # ... and closer than this (m) are pulled to the object

    def __post_init__(self) -> None:
        for name, value in vars(self).items():        # a negative weight rewards what its term removes
            check_weight(value, name)


PARAMS = ("transl", "orient6d", "betas", "z", "left_pca", "right_pca", "eyes", "joint6d")
STAGE3_FREE = ("z", "left_pca", "right_pca", "eyes")
# the arm chains, GraspPoseConfig.free_joints' default (graspkit's; Alg. 1 has none: docs/saga.md)
ARM_JOINTS = ("left_collar", "right_collar", "left_shoulder", "right_shoulder", "left_elbow", "right_elbow",
              "left_wrist", "right_wrist")


@dataclass
class GraspPoseConfig:
    """Alg. 1 schedule and which terms stage 3 uses (Tab. 2 ablations switch them)."""

    steps: tuple[int, int, int] = (300, 400, 500)
    lrs: tuple[float, float, float] = (0.016, 0.012, 0.008)
    collision: bool = True        # E_colli in stage 3
    contact: bool = True          # E^o_cont in stage 3 (needs contact maps)
    ground: bool = True           # E^g_cont in stage 3
    heuristic: bool = False       # S.3's heuristic contact instead of E^o_cont (WholeGrasp-single)
    contact_points: int = 256     # object points (highest C^_o) in d(o, V_B)
    collision_points: int = 512   # object points (nearest the hand) in S(o, V^h_B)
    n_pca: int = 24               # hand PCA components per hand (SAGA)
    log_every: int = 10
    nn_every: int = 10            # stage 3: nearest-neighbour pairs recomputed every this many steps (held between)
    sunk_depth: float | None = None  # m: E^O_colli off for a sample while a hand vertex is deeper inside (docs/saga.md)
    # m: stage 3 runs a second time from the same start with sunk_depth = this, and each sample keeps the run with the
    # lower full (ungated) energy (graspkit's; None: Alg. 1's single run; only with collision and sunk_depth None)
    restart_sunk: float | None = 0.005
    # E^B_colli in stage 2 too where `collision` (graspkit's; False: Alg. 1's E_fit-only stage 2; docs/saga.md)
    stage2_collision: bool = True
    # E^g_cont in stage 2 too where `ground` (graspkit's; False: Alg. 1's E_fit-only stage 2; docs/saga.md)
    stage2_ground: bool = True
    # E^g_cont measures each sole vertex's height from its own height above its foot's lowest vertex at rest
    # (graspkit's; False: the paper's |h(v)|, which sets the soles' median on the floor and the rest under it)
    ground_rest: bool = True
    inner_depths: tuple[float, ...] = (0.005, 0.01)  # m: E^B_colli also at the hand vertices moved this far inward
    forearms: bool = True          # E^B_colli also on the forearm vertices (graspkit's; with inner_depths=(): Alg. 1)
    stage3_free: tuple[str, ...] = STAGE3_FREE     # Alg. 1's stage-3 variables (an experiment may add t, R: docs/saga.md)
    polish: tuple[int, float] = (100, 1e-3)  # stage 3 goes on polish[0] steps at lr polish[1] (graspkit's; docs)
    # body joints (SMPL-X names) given a free rotation on top of the prior's decoded pose, optimised with theta_b in
    # stages 2-3, penalised by weights.free_joints and weights.limits (graspkit's; () is Alg. 1: docs/saga.md)
    free_joints: tuple[str, ...] = ARM_JOINTS
    weights: GraspPoseWeights = field(default_factory=GraspPoseWeights)

    def __post_init__(self) -> None:
        for name in ("contact_points", "collision_points", "log_every", "nn_every"):
            check_int(getattr(self, name), name, least=1)
        check_int(self.n_pca, "n_pca", least=1)
        if self.n_pca > 45:
            raise ValueError(f"n_pca: expected at most the model's 45 hand components, got {self.n_pca}")
        lrs = tuple(self.lrs) if isinstance(self.lrs, (tuple, list)) else ()
        if len(lrs) != 3 or not all(isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)
                                    and x > 0 for x in lrs):
            raise ValueError(f"lrs: expected three learning rates > 0 (stages 1-3 of Alg. 1), got {self.lrs!r}")
        for name in ("collision", "contact", "ground", "heuristic"):
            check_bool(getattr(self, name), name)


@dataclass
class GraspObject:
    """The object in WholeGrasp-VAE's frame: points and normals (P,3) (or (B,P,3), one object pose per sample), its
    height t_O (float or (B,)), optionally its signed-distance grid in the mesh's own frame (or a list of B grids, one
    per sample), the rotation (3,3) or (B,3,3) from that frame into this one and the mesh origin's place here (3,) or
    (B,3) (x = R x_mesh + origin; default 0: the frame is centred at the object)."""

    points: Tensor
    normals: Tensor
    height: float | Tensor
    sdf: SDFGrid | list[SDFGrid] | None = None
    rotation: Tensor | None = None
    origin: Tensor | None = None

    def __post_init__(self) -> None:
        for name in ("points", "normals"):
            x = getattr(self, name)
            if not isinstance(x, Tensor) or x.dim() not in (2, 3) or x.shape[-1] != 3:
                got = tuple(x.shape) if isinstance(x, Tensor) else type(x).__name__
                raise ValueError(f"{name}: expected a tensor of shape (P, 3) or (B, P, 3), got {got}")
        if self.points.shape != self.normals.shape:
            raise ValueError(f"normals: expected the shape of points {tuple(self.points.shape)}, "
                             f"got {tuple(self.normals.shape)}")
        if self.rotation is not None and tuple(self.rotation.shape[-2:]) != (3, 3):
            raise ValueError(f"rotation: expected shape (3, 3) or (B, 3, 3), got {tuple(self.rotation.shape)}")
        if self.rotation is not None:
            check_rotation(self.rotation, "rotation")
        if self.origin is not None and (self.origin.dim() not in (1, 2) or self.origin.shape[-1] != 3):
            raise ValueError(f"origin: expected shape (3,) or (B, 3), got {tuple(self.origin.shape)}")
        if self.origin is not None:
            check_finite(self.origin, "origin", "the mesh origin's place in metres")
        require_points_in_metres(self.points, "points")
        if not bool(torch.isfinite(self.normals).all()):
            raise ValueError("normals: contains NaN or Inf")
        require_unit_normals(self.normals, "normals")
        check_height(self.height, "height")
        self.points, self.normals = self.points.float(), self.normals.float()

    @property
    def num_points(self) -> int:
        return self.points.shape[-2]

    def batch(self, B: int) -> tuple[Tensor, Tensor, Tensor]:
        """Points, normals (B,P,3) and heights (B,1) for a batch of B samples."""
        h = torch.as_tensor(self.height, dtype=torch.float32).reshape(-1, 1).expand(B, 1)
        return self.points.expand(B, -1, -1), self.normals.expand(B, -1, -1), h

    def signed_distance(self, x: Tensor) -> Tensor:
        """S(x, O) (B,N) from the grid for x (B,N,3) (negative inside); the grid must be set."""
        if self.origin is not None:
            o = self.origin.to(x.dtype)
            x = x - (o if o.dim() == 1 else o[:, None])
        if self.rotation is not None:
            x = x @ self.rotation.to(x.dtype)            # row vectors: R^T x
        if isinstance(self.sdf, (list, tuple)):
            if len(self.sdf) != len(x):
                raise ValueError(f"sdf: {len(self.sdf)} grids for a batch of {len(x)}")
            return torch.cat([g(x[i:i + 1]) for i, g in enumerate(self.sdf)])
        return self.sdf(x)


@dataclass
class GraspPoseResult:
    """Fitted bodies (object frame): SMPL-X parameters, vertices, markers, energies per stage and a step log."""

    params: dict[str, Tensor]                     # betas, global_orient, body_pose, *_hand_pose (absolute), ...
    vertices: Tensor                              # (B, V, 3)
    markers: Tensor                               # (B, 143, 3)
    energies: list[dict[str, Any]]                # per stage: {'before': {term: (B,)}, 'after': {...}} (+ stage 3's
                                                  # 'restarted' (B,) bool: the sample kept the gated run)
    log: list[dict[str, float]]                   # every log_every steps: step, stage, each term (batch sum)
    state: dict[str, Tensor] = field(default_factory=dict)  # the optimised variables (init= of another fit)

    def to_world(self, translation: Tensor) -> "GraspPoseResult":
        """The same result moved by the object centre `translation` (3,) into the world."""
        t = torch.as_tensor(translation, dtype=self.vertices.dtype)
        params = dict(self.params, transl=self.params["transl"] + t)
        return replace(self, params=params, vertices=self.vertices + t, markers=self.markers + t)


_EYE6 = matrix_to_rot6d(torch.eye(3))


def with_free_joints(body: Tensor, joint6d: Tensor, free_ids: Tensor) -> Tensor:
    """The 21 body rotations (N,21,3,3) with each free joint's 6D offset from the identity (N, n_free, 6) composed
    on (GraspPose-Opt's and GraspMotion-Opt's free joints; zero offsets give `body` back)."""
    body = body.clone()
    body[:, free_ids] = body[:, free_ids] @ rot6d_to_matrix(joint6d + _EYE6)
    return body


def free_joint_excess(rot: Tensor, free_ids: Tensor) -> Tensor:
    """Degrees (N,) the free joints of 55 joint rotations (N,55,3,3) turn past the human range, summed
    (metrics.joint_limit_excess; differentiable)."""
    j = 1 + free_ids                                                     # the free joints among the 55
    aa = torch.zeros(rot.shape[0], rot.shape[1], 3, dtype=rot.dtype).index_copy(1, j, matrix_to_axis_angle(rot[:, j]))
    return joint_limit_excess(aa)[:, j].sum(-1)


def expand_free_joints(names: list[str] | tuple[str, ...]) -> tuple[str, ...]:
    """Command-line joint names -> GraspPoseConfig.free_joints: 'arms' stands for ARM_JOINTS, 'none' for no joint
    (Alg. 1), others pass as given."""
    return tuple(j for name in names if name != "none" for j in (ARM_JOINTS if name == "arms" else (name,)))


BODY_JOINTS = JOINT_NAMES[1:22]   # the 21 SMPL-X body joints (pelvis, jaw, eyes and fingers left out)


def valid_body_joints(names: tuple[str, ...] | list[str]) -> bool:
    """Whether `names` are distinct names of BODY_JOINTS (GraspPoseConfig.free_joints' rule, also the CLI's)."""
    return all(n in BODY_JOINTS for n in names) and len(set(names)) == len(names)


def body_joint_ids(names: tuple[str, ...]) -> Tensor:
    """Indices (k,) into BODY_JOINTS of distinct joint names; ValueError naming free_joints otherwise."""
    if not valid_body_joints(names):
        raise ValueError(f"free_joints: expected distinct body-joint names of {BODY_JOINTS}, got {tuple(names)}")
    return torch.tensor([BODY_JOINTS.index(n) for n in names], dtype=torch.long)


def hand_vertex_ids(bm: BodyModel, sides: tuple[str, ...] = ("left", "right")) -> np.ndarray:
    """Vertex ids (sorted) dominated by the wrists and fingers of the given hands."""
    parts = [JOINT_INDEX[f"{s}_wrist"] for s in sides]
    parts += [JOINT_INDEX[f"{s}_{f}{k}"] for s in sides for f in FINGERS for k in (1, 2, 3)]
    return np.flatnonzero(np.isin(bm.lbs_weights.argmax(1).numpy(), parts))


def hand_faces(bm: BodyModel, hands: Tensor) -> Tensor:
    """The body's faces whose three vertices are all hand vertices (ids `hands` (n,)), re-indexed into 0..n-1 (F,3)."""
    pos = torch.full((bm.num_vertices,), -1, dtype=torch.long)
    pos[hands] = torch.arange(len(hands))
    f = pos[bm.faces.long()]
    return f[(f >= 0).all(1)]


def collision_points(hands: Tensor, faces: Tensor, inner_depths: tuple[float, ...], arms: Tensor | None = None,
                     with_hands: bool = True, normals: Tensor | None = None) -> Tensor:
    """E^B_colli's query points (B,M,3) beyond Alg. 1's: the hand vertices (B,n_h,3) (if `with_hands`), the same moved
    each of `inner_depths` inward along the hand's vertex normals (of `faces`; computed unless `normals` is given),
    and the forearm vertices `arms` (B,n_a,3) if given. M may be 0."""
    q = [hands] if with_hands else []
    if inner_depths:
        n = vertex_normals(hands, faces) if normals is None else normals
        q += [hands - d * n for d in inner_depths]
    if arms is not None:
        q.append(arms)
    return torch.cat(q, 1) if q else hands[:, :0]


def forearm_vertex_ids(bm: BodyModel) -> np.ndarray:
    """Vertex ids (sorted) dominated by the elbows' joints (the forearms)."""
    parts = [JOINT_INDEX[f"{s}_elbow"] for s in ("left", "right")]
    return np.flatnonzero(np.isin(bm.lbs_weights.argmax(1).numpy(), parts))


def kabsch(source: Tensor, target: Tensor) -> tuple[Tensor, Tensor]:
    """Least-squares rotation R (B,3,3) and translation c (B,3) with target ~ R source + c; (B,N,3) each."""
    ms, mt = source.mean(1, keepdim=True), target.mean(1, keepdim=True)
    H = (source - ms).transpose(1, 2) @ (target - mt)
    U, _, Vt = torch.linalg.svd(H)
    d = torch.sign(torch.det(Vt.transpose(1, 2) @ U.transpose(1, 2)))
    D = torch.diag_embed(torch.stack([torch.ones_like(d), torch.ones_like(d), d], -1))
    R = Vt.transpose(1, 2) @ D @ U.transpose(1, 2)
    return R, (mt - ms @ R.transpose(1, 2)).squeeze(1)


def _nearest(q: Tensor, t: Tensor, idx: Tensor | None = None) -> tuple[Tensor, Tensor]:
    """Nearest target row for every query: (B,N,3), (B,M,3) -> squared distance (B,N) (differentiable), index (B,N).
    With `idx` the pairs are taken as given (held correspondences)."""
    if idx is None:
        with torch.no_grad():
            idx = centred_cdist(q.detach(), t.detach()).argmin(-1)
    near = torch.gather(t, 1, idx.unsqueeze(-1).expand(-1, -1, 3))
    return (q - near).pow(2).sum(-1), idx


def nearest_points(points: Tensor, targets: Tensor, k: int) -> Tensor:
    """Indices (B,k) of the rows of points (B,P,3) nearest any of targets (B,N,3), one sample at a time (a batch of
    hundreds would hold B x P x N distances at once)."""
    with torch.no_grad():
        d2 = torch.cat([_nearest(p[None], t[None])[0] for p, t in zip(points.detach(), targets.detach())])
        return d2.topk(min(k, points.shape[1]), -1, largest=False).indices


def _signed_to_cloud(q: Tensor, cloud: Tensor, normals: Tensor, idx: Tensor | None = None
                     ) -> tuple[Tensor, Tensor]:
    """Signed distance (B,N) from q to a cloud with outward normals (negative inside), as SAGA's S(x, Y); and the
    nearest-point indices."""
    d2, idx = _nearest(q, cloud, idx)
    i3 = idx.unsqueeze(-1).expand(-1, -1, 3)
    near, n = torch.gather(cloud, 1, i3), torch.gather(normals, 1, i3)
    sign = torch.where(((q - near) * n).sum(-1) < 0, -1.0, 1.0).to(q.dtype).detach()
    return sign * torch.sqrt(d2 + 1e-12), idx


class GraspPoseOpt:
    """SAGA's GraspPose-Opt for a BodyModel and a pose prior; call `fit` with markers, contacts and the object."""

    def __init__(self, bm: BodyModel, prior: PosePrior, config: GraspPoseConfig | None = None,
                 hand_contact_prior: Tensor | None = None) -> None:
        self.bm, self.prior = bm, copy.deepcopy(prior).eval().requires_grad_(False)   # frozen; the caller's untouched
        self.cfg = config or GraspPoseConfig()
        self.free_ids = body_joint_ids(self.cfg.free_joints)
        ms = saga_markers(bm)
        self.marker_ids = torch.as_tensor(ms.vertex_ids)
        self.body_face = torch.arange(ms.groups["face"][1])              # body + face markers for Kabsch
        hands = torch.as_tensor(hand_vertex_ids(bm))
        sole = foot_vertices(bm)
        feet = torch.as_tensor(np.concatenate(list(sole.values())))
        arms = torch.as_tensor(forearm_vertex_ids(bm))
        ids = torch.cat([self.marker_ids, hands, feet, arms])
        self.sparse = SparseBody(bm, ids)
        n_m, n_h, n_f = len(self.marker_ids), len(hands), len(feet)
        self.sl_markers, self.sl_hands = slice(0, n_m), slice(n_m, n_m + n_h)
        self.sl_feet, self.sl_arms = slice(n_m + n_h, n_m + n_h + n_f), slice(n_m + n_h + n_f, None)
        self.sole_rest = torch.as_tensor(sole_rest_heights(bm, sole), dtype=torch.float32)  # (n_f,) m, mean shape
        self.hand_faces = hand_faces(bm, hands)      # into the hand slice, for vertex normals of the hand surface
        self.hand_ids = hands
        k = self.cfg.n_pca
        self.pca = {s: getattr(bm, f"{s}_hand_components")[:k].float() for s in ("left", "right")}
        self.hand_mean = {"left": bm.pose_mean[75:120].float(), "right": bm.pose_mean[120:165].float()}
        if bm.flat_hand_mean:
            raise ValueError("bm: build the BodyModel with flat_hand_mean=False (hand PCA about the mean hand)")
        if hand_contact_prior is not None and hand_contact_prior.shape != (n_h,):
            raise ValueError(f"hand_contact_prior: expected shape ({n_h},) (one per hand vertex), "
                             f"got {tuple(hand_contact_prior.shape)}")
        self.hand_contact_prior = hand_contact_prior

    def with_config(self, **changes: Any) -> "GraspPoseOpt":
        """A copy that shares the body, prior and vertex sets, with some GraspPoseConfig fields changed."""
        other = copy.copy(self)
        other.cfg = replace(self.cfg, **changes)
        other.free_ids = body_joint_ids(other.cfg.free_joints)
        return other

    # ------------------------------------------------------------------ the body
    def rotmats(self, p: dict[str, Tensor]) -> Tensor:
        """All 55 joint rotations (B,55,3,3) from the optimised parameters (hand mean added)."""
        B = p["transl"].shape[0]
        eye = torch.eye(3).expand(B, 1, 3, 3)
        hands = [axis_angle_to_matrix((p[f"{s}_pca"] @ self.pca[s] + self.hand_mean[s]).view(B, 15, 3))
                 for s in ("left", "right")]
        body = self.prior.decode_rotmats(p["z"])
        if len(self.free_ids):
            body = with_free_joints(body, p["joint6d"], self.free_ids)
        return torch.cat([rot6d_to_matrix(p["orient6d"]).unsqueeze(1), body, eye,
                          axis_angle_to_matrix(p["eyes"].view(B, 2, 3)), hands[0], hands[1]], 1)

    def body(self, p: dict[str, Tensor]) -> Tensor:
        """Markers, hand and foot vertices (B, n, 3) of the current parameters."""
        return self.sparse(self.rotmats(p), p["betas"], p["transl"])[0]

    def init_params(self, markers: Tensor) -> dict[str, Tensor]:
        """Alg. 1's starting point (see the module docstring): prior mean pose, rigidly aligned to the markers."""
        B = markers.shape[0]
        p = {"transl": torch.zeros(B, 3), "orient6d": matrix_to_rot6d(torch.eye(3).expand(B, 3, 3)).clone(),
             "betas": torch.zeros(B, 10), "z": torch.zeros(B, self.prior.cfg.latent),
             "left_pca": torch.zeros(B, self.cfg.n_pca), "right_pca": torch.zeros(B, self.cfg.n_pca),
             "eyes": torch.zeros(B, 6), "joint6d": torch.zeros(B, len(self.free_ids), 6)}
        with torch.no_grad():
            rot = self.rotmats(p)
            v, J = self.sparse(rot, p["betas"], p["transl"])
            src = v[:, self.sl_markers][:, self.body_face]
            R, c = kabsch(src, markers[:, self.body_face])
            J0 = J[:, 0]
            p["orient6d"] = matrix_to_rot6d(R)
            p["transl"] = (R @ J0.unsqueeze(-1)).squeeze(-1) + c - J0
        return p

    # ------------------------------------------------------------------ the energy
    def energy(self, p: dict[str, Tensor], target: Tensor, obj: GraspObject, stage: int,
               marker_contact: Tensor | None, object_contact: Tensor | None,
               cache: dict[str, Tensor], refresh: bool = True) -> dict[str, Tensor]:
        """Each term of Eq. 4-7 (and S.3) per sample (B,) for the current parameters.

        `refresh=False` reuses the nearest-neighbour pairs kept in `cache` from the last refresh."""
        cfg, w = self.cfg, self.cfg.weights
        rot = self.rotmats(p)
        v = self.sparse(rot, p["betas"], p["transl"])[0]
        m, hands, feet = v[:, self.sl_markers], v[:, self.sl_hands], v[:, self.sl_feet]
        B = v.shape[0]
        e = {"fit": (m - target).abs().sum((1, 2)),
             "prior": w.prior * (p["z"].pow(2).sum(-1) + p["left_pca"].pow(2).sum(-1)
                                 + p["right_pca"].pow(2).sum(-1) + p["eyes"].pow(2).sum(-1))}
        if len(self.free_ids):
            e["prior"] = e["prior"] + w.free_joints * p["joint6d"].pow(2).sum((1, 2))
            if w.limits > 0:
                e["limits"] = w.limits * free_joint_excess(rot, self.free_ids)
        pts, nrm, height = obj.batch(B)
        if stage == 2 and cfg.collision and cfg.stage2_collision:
            e["colli_body"] = w.colli_body * self._extra_inside(v, obj, hands=True)   # no other E^B in stage 2
        if cfg.ground and (stage == 3 or (stage == 2 and cfg.stage2_ground)):
            rest = self.sole_rest if cfg.ground_rest else torch.zeros_like(self.sole_rest)
            e["ground"] = w.ground * (feet[..., 2] + height - rest).abs().sum(-1)
            if w.floor > 0:
                e["ground"] = e["ground"] + w.floor * torch.relu(-(feet[..., 2].min(-1).values + height[:, 0]))
        if stage < 3:
            return e

        def nn(name: str, q: Tensor, t: Tensor) -> Tensor:
            d2, cache[name] = _nearest(q, t, None if refresh or name not in cache else cache[name])
            return d2

        if cfg.contact and object_contact is not None and marker_contact is not None:
            co_idx = cache["contact_idx"]
            po = torch.gather(pts, 1, co_idx.unsqueeze(-1).expand(-1, -1, 3))
            e["contact_object"] = w.contact_object * (torch.gather(object_contact, 1, co_idx)
                                                      * nn("nn_contact_object", po, hands)).sum(-1)
            e["contact_marker"] = w.contact_marker * (marker_contact * nn("nn_contact_marker", m, pts)).sum(-1)
        if cfg.heuristic and self.hand_contact_prior is not None:
            d2 = nn("nn_heuristic", hands, pts)
            ch = self.hand_contact_prior.to(d2.dtype)
            on = (ch > w.heuristic_prior) & (d2.detach() < w.heuristic_radius ** 2)
            e["heuristic"] = w.heuristic * (on * ch * d2).sum(-1)
        if cfg.collision:
            if obj.sdf is not None:
                sd = obj.signed_distance(hands)
            else:
                sd, cache["nn_colli_body"] = _signed_to_cloud(hands, pts, nrm, None if refresh else
                                                              cache.get("nn_colli_body"))
            hn = vertex_normals(hands, self.hand_faces)
            e["colli_body"] = w.colli_body * (torch.relu(-sd - w.sigma_b).sum(-1) + self._extra_inside(v, obj, hn))
            cp = torch.gather(pts, 1, cache["collision_idx"].unsqueeze(-1).expand(-1, -1, 3))
            so, cache["nn_colli_object"] = _signed_to_cloud(cp, hands, hn, None if refresh else
                                                            cache.get("nn_colli_object"))
            pen = torch.relu(-so - w.sigma_o).sum(-1)
            if cfg.sunk_depth is not None:
                # while the hand is sunk into the object, the object points inside the hand leave it fastest through
                # the back of the hand, i.e. by pushing the hand deeper: E^O waits until E^B has lifted it out
                pen = pen * (sd.detach().min(-1).values > -cfg.sunk_depth).to(pen.dtype)
            e["colli_object"] = w.colli_object * pen
        return e

    def _extra_inside(self, v: Tensor, obj: GraspObject, normals: Tensor | None = None, hands: bool = False) -> Tensor:
        """Summed depth past sigma_b (B,) inside the object of E^B_colli's points beyond the hand vertices, for the
        sparse body v (B,n,3): the hand vertices moved cfg.inner_depths inward along their normals (B,n_h,3; computed
        if not given) and the forearm vertices (and the hand vertices themselves if `hands`)."""
        cfg, w = self.cfg, self.cfg.weights
        q = collision_points(v[:, self.sl_hands], self.hand_faces, cfg.inner_depths,
                             v[:, self.sl_arms] if cfg.forearms else None, with_hands=hands, normals=normals)
        if q.shape[1] == 0:
            return torch.zeros(v.shape[0], dtype=v.dtype)
        if obj.sdf is not None:
            sd = obj.signed_distance(q)
        else:
            pts, nrm, _ = obj.batch(v.shape[0])
            sd = _signed_to_cloud(q, pts, nrm)[0]
        return torch.relu(-sd - w.sigma_b).sum(-1)

    # ------------------------------------------------------------------ Alg. 1
    @with_autograd
    def fit(self, markers: Tensor, obj: GraspObject, marker_contact: Tensor | None = None,
            object_contact: Tensor | None = None, progress: bool = True, init: dict[str, Tensor] | None = None,
            stages: tuple[int, ...] = (1, 2, 3)) -> GraspPoseResult:
        """Alg. 1 on a batch: markers (B,143,3), contacts (B,143), (B,P) (probabilities) -> GraspPoseResult.

        `init` (e.g. a previous result's `state`) and `stages` let the Tab. 2 ablations share stages 1-2.
        """
        if not isinstance(markers, Tensor) or markers.dim() != 3 or markers.shape[1:] != (len(self.marker_ids), 3):
            got = tuple(markers.shape) if isinstance(markers, Tensor) else type(markers).__name__
            raise ValueError(f"markers: expected shape (B, {len(self.marker_ids)}, 3), got {got}")
        B = markers.shape[0]
        if B == 0:
            raise ValueError("markers: expected at least one marker set (B >= 1), got 0")
        if len(self.cfg.steps) != 3 or any(isinstance(k, bool) or not isinstance(k, int) or k < 0 for k in self.cfg.steps):
            raise ValueError(f"steps: expected three step counts >= 0 (stages 1-3 of Alg. 1), got {self.cfg.steps}")
        if not bool(torch.isfinite(markers).all()):
            raise ValueError("markers: contains NaN or Inf")
        require_points_in_metres(markers, "markers", "markers in millimetres need a scale of 0.001")
        if (marker_contact is None) != (object_contact is None):
            raise ValueError("marker_contact, object_contact: E^o_cont and E^m_cont need both contact maps (or "
                             "neither: E_fit alone)")
        for name, c in (("marker_contact", marker_contact), ("object_contact", object_contact)):
            check_probabilities(c, name)
        if marker_contact is not None and marker_contact.shape != markers.shape[:2]:
            raise ValueError(f"marker_contact: expected shape {tuple(markers.shape[:2])}, "
                             f"got {tuple(marker_contact.shape)}")
        if object_contact is not None and object_contact.shape != (B, obj.num_points):
            raise ValueError(f"object_contact: expected shape ({B}, {obj.num_points}), "
                             f"got {tuple(object_contact.shape)}")
        if self.cfg.heuristic and self.hand_contact_prior is None:
            raise ValueError("hand_contact_prior: the heuristic contact of S.3 needs it")
        n_polish, lr_polish = self.cfg.polish
        if n_polish < 0 or (n_polish > 0 and lr_polish <= 0):
            raise ValueError(f"polish: expected (steps >= 0, learning rate > 0), got {self.cfg.polish}")
        if any(not (0 < d < 0.05) for d in self.cfg.inner_depths):
            raise ValueError(f"inner_depths: expected depths in metres in (0, 0.05), got {self.cfg.inner_depths}")
        if not self.cfg.stage3_free or set(self.cfg.stage3_free) - set(PARAMS):
            raise ValueError(f"stage3_free: expected a non-empty subset of {PARAMS}, got {self.cfg.stage3_free}")
        target = markers.detach().float()
        p = {k: v.detach().clone() for k, v in (init or self.init_params(target)).items()}
        if p.get("joint6d") is None or p["joint6d"].shape[1] != len(self.free_ids):   # e.g. an init without them
            p["joint6d"] = torch.zeros(B, len(self.free_ids), 6)
        extra = ("joint6d",) if len(self.free_ids) else ()
        free = {1: ("transl", "orient6d"), 2: ("transl", "orient6d", "betas", "z") + extra,
                3: tuple(dict.fromkeys(tuple(self.cfg.stage3_free) + extra))}
        energies: list[dict[str, Any]] = []
        log: list[dict[str, float]] = []
        cache: dict[str, Tensor] = {}
        restart = 3 in stages and self._restarts()
        total = sum(self.cfg.steps[s - 1] for s in stages) + (n_polish if 3 in stages else 0)
        total += (self.cfg.steps[2] + n_polish) if restart else 0
        bar = tqdm(total=total, desc="GraspPose-Opt", disable=hidden(progress))
        step = 0
        for stage in stages:
            if stage == 3:
                cache = self._stage3_cache(p, obj, object_contact)
                start = {k: v.detach().clone() for k, v in p.items()}
            names = free[stage]
            for k in p:
                p[k].requires_grad_(k in names)
            opt = torch.optim.Adam([p[k] for k in names], lr=self.cfg.lrs[stage - 1])
            with torch.no_grad():
                before = {k: v.detach() for k, v in self.energy(p, target, obj, stage, marker_contact,
                                                                object_contact, cache).items()}
            n_steps = self.cfg.steps[stage - 1] + (n_polish if stage == 3 else 0)
            for i in range(n_steps):
                if stage == 3 and n_polish and i == self.cfg.steps[2]:     # the polish: same energy, lower lr
                    for group in opt.param_groups:
                        group["lr"] = lr_polish
                e = self.energy(p, target, obj, stage, marker_contact, object_contact, cache,
                                refresh=i % self.cfg.nn_every == 0)
                energy_step(opt, e, log, i, step, stage, self.cfg.log_every)
                step += 1
                bar.update(1)
            with torch.no_grad():
                after = {k: v.detach() for k, v in self.energy(p, target, obj, stage, marker_contact,
                                                               object_contact, cache).items()}
            entry = {"stage": stage, "before": before, "after": after}
            if stage == 3 and restart:
                p, entry["after"], entry["restarted"] = self._restart(p, after, start, target, obj, marker_contact,
                                                                      object_contact, cache, bar)
            energies.append(entry)
        bar.close()
        return self._result(p, energies, log)

    def _restarts(self) -> bool:
        """Whether stage 3 runs twice (cfg.restart_sunk; only where E^O_colli is on and not already gated)."""
        r = self.cfg.restart_sunk
        if r is not None and r <= 0:
            raise ValueError(f"restart_sunk: expected a depth in metres > 0 or None, got {r}")
        return r is not None and self.cfg.collision and self.cfg.sunk_depth is None

    def _restart(self, p: dict[str, Tensor], after: dict[str, Tensor], start: dict[str, Tensor], target: Tensor,
                 obj: GraspObject, marker_contact: Tensor | None, object_contact: Tensor | None,
                 cache: dict[str, Tensor], bar: Any) -> tuple[dict[str, Tensor], dict[str, Tensor], Tensor]:
        """Stage 3 again from `start` with E^O_colli gated by cfg.restart_sunk; per sample, the run with the lower
        full stage-3 energy. -> (parameters, their energies {term: (B,)}, restarted (B,) bool).

        Why: a hand sunk into the object is pushed deeper by E^O_colli (its object points leave the hand fastest
        through the back of the hand) and stays; gated, E^B_colli lifts it out, but a thin object can then pass
        through a hand that was not sunk. The full energy, E^O included, tells which run is the better fit."""
        gated = self.with_config(sunk_depth=self.cfg.restart_sunk, restart_sunk=None)
        other = gated.fit(target, obj, marker_contact, object_contact, progress=False,
                          init={k: v.clone() for k, v in start.items()}, stages=(3,)).state
        bar.update(self.cfg.steps[2] + self.cfg.polish[0])
        with torch.no_grad():
            e_other = self.energy(other, target, obj, 3, marker_contact, object_contact, cache)
            pick = sum(e_other.values()) < sum(after.values())
            merged = {k: torch.where(pick.view(-1, *[1] * (v.dim() - 1)), other[k], v.detach()) for k, v in p.items()}
            e = {k: torch.where(pick, e_other[k], after[k]) for k in after}   # samples are independent
        return merged, e, pick

    def _stage3_cache(self, p: dict[str, Tensor], obj: GraspObject, object_contact: Tensor | None
                      ) -> dict[str, Tensor]:
        """Object points used in stage 3: the highest-contact ones (d(o, V_B)) and those nearest the hand (S(o, V^h))."""
        B = p["transl"].shape[0]
        P = obj.num_points
        with torch.no_grad():
            hands = self.body(p)[:, self.sl_hands]
            cache = {"collision_idx": nearest_points(obj.batch(B)[0], hands, self.cfg.collision_points)}
            if object_contact is not None:
                cache["contact_idx"] = object_contact.topk(min(self.cfg.contact_points, P), -1).indices
        return cache

    def _result(self, p: dict[str, Tensor], energies: list, log: list) -> GraspPoseResult:
        """Full-mesh forward and SMPL-X parameters (axis-angle, absolute hand poses) of the final parameters."""
        with torch.no_grad():
            rot = self.rotmats(p)
            out = self.bm.forward_rotmats(rot, betas=p["betas"], transl=p["transl"])
            aa = matrix_to_axis_angle(rot)
            B = rot.shape[0]
            params = {"betas": p["betas"].clone(), "transl": p["transl"].clone(), "global_orient": aa[:, 0],
                      "body_pose": aa[:, 1:22].reshape(B, 63), "jaw_pose": aa[:, 22], "leye_pose": aa[:, 23],
                      "reye_pose": aa[:, 24], "left_hand_pose": aa[:, 25:40].reshape(B, 45),
                      "right_hand_pose": aa[:, 40:55].reshape(B, 45), "pose_latent": p["z"].clone(),
                      "left_hand_pca": p["left_pca"].clone(), "right_hand_pca": p["right_pca"].clone()}
        state = {k: v.detach().clone() for k, v in p.items()}
        return GraspPoseResult(params, out.vertices, out.vertices[:, self.marker_ids], energies, log, state)


def energies_table(result: GraspPoseResult) -> list[dict[str, Any]]:
    """Rows (stage, term, before, after) with each term summed over the batch, for printing or plotting."""
    rows = []
    for e in result.energies:
        for k in e["after"]:
            rows.append({"stage": e["stage"], "term": k, "before": float(e["before"][k].sum()),
                         "after": float(e["after"][k].sum())})
    return rows
