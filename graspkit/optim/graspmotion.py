"""GraspMotion-Opt (SAGA §3.4, Eq. 10-11, App. A.4 Eq. S.1-S.2, Alg. 2): fit SMPL-X bodies to an infilled marker
sequence.

    E_basic  = sum_t (E_fit(Theta_t) + E^o_colli(Theta_t)) + sum_{t=T-4..T} E^o_cont(Theta_t)          (Eq. 10)
    E_g      = sum_t alpha_t sum_{m in V^p_B} 1(d(m, O) < sigma) (cos gamma_m - 1)^2, alpha_t = 1 - (t/T)^2  (Eq. 11)
    E_smooth = a^B_s sum_t |S_{t+1} - S_t|^2 + a^h_s sum_t |V^h_{t+1} - V^h_t|^2, S = AE(M_{1:T} - M_{0:T-1}) (S.1)
    E_skat   = a_skat sum_{t in T_c} sum_{|v^foot_t| >= sigma} (|v^foot_t| - sigma)                          (S.2)

E_fit, E^o_colli, E^o_cont as GraspPose-Opt (Eq. 5-7, graspkit.optim.grasppose): L1 marker distance plus a small
prior on the latents; the hand vertices' signed distance to the object below -sigma_b; sum_o C^_o d(o, V^h_B).
Theta_t = (t, R (6D), theta_b (pose-prior latent, in place of VPoser), theta_h (24 PCA per hand)); beta is fixed.
V^p_B: the right palm's vertices (`body.markers.palm_vertices`), gamma_m the angle between the palm normal and the
vector to the closest object point, sigma = 1 cm. S: the latent sequence of a small temporal-convolution
autoencoder of marker differences (`MarkerDiffAE`, trained on the motion windows; shipped). T_c: frames whose
predicted foot contact (left heel, left toe, right heel, right toe) is above 0.5; v^foot: each sole vertex's
displacement to the next frame.

Alg. 2: stage 1, 100 Adam steps of E_fit on (t, R, theta) (lr 0.1 for the first frame, 0.01 for the others; 0.01 for
all after step 60, 0.003 after step 80); stage 2, 300 steps of E_basic + E_g + E_smooth + E_skat (lr 0.01, 0.005
after step 150), then graspkit's polish: 100 more steps of the same energy at lr 0.001 (`GraspMotionConfig.polish`).

graspkit's choices (the paper leaves them out; all in `GraspMotionWeights`):
- S.2's sigma = 0.1 would be 3 m/s for a per-frame displacement at 30 fps and never switch on; graspkit uses 0.05 m/s
  (1.7 mm per frame), below the 75 mm/s of SAGA's skating metric (with 0.1 m/s and a_skat = 100 the skating rate of
  two test clips fell only from 0.68 / 0.82 to 0.58 / 0.47; with these values to 0.10 / 0.25). a_skat = 300 per sole
  vertex and metre; a^B_s = 1, a^h_s = 10 on the mean squared hand-vertex displacement (m^2);
  alpha_g (E_g's weight) = 10; contact and collision weights as GraspPose-Opt (15, 200), sigma_b = 1 mm.
- T_c: S.2 takes MotionFill's predicted contacts; graspkit also counts, on every frame, the foot part (heel or toe)
  with the highest predicted probability (`GraspMotionConfig.one_foot_down`): a walking or standing person always
  has a foot on the ground, and the samples' probabilities often fall below 0.5 for all four parts mid-stride, which
  left both feet free to glide (SAGA's skating metric counts exactly the frames where no heel is planted).
- Only the right hand meets the object (graspkit's grasps are right-handed); E^o_colli is both sums of Eq. 7 as in
  GraspPose-Opt: the hand vertices inside the object (from the object's collision grid when the GraspObject has one,
  `graspkit.data.grasp_io.collision_sdf_grid`, posed by its rotation and origin; else from the point cloud's
  normals) and the object points inside the hand (`object_in_hand`: the sign from the hand's vertex normals,
  alpha^O_colli = 100, sigma_o = 1 mm; since 2026-11-30). E^o_cont has both sides of Eq. 6: the object points with
  the highest C^_O pulled to the hand vertices, and, when `fit` gets stage 1's 143-marker map C^_M, those markers
  read off the fitted mesh pulled to the object (alpha^m_cont = 15 as GraspPose-Opt; since 2026-12-02: the SAGA
  sequences of GOAL's evaluation end in contact 8 -> 11 of 12, docs/saga_motion.md). On the twelve test clips of
  docs/saga_motion.md (one thread) the last frame's penetration was 6.81 cm³ with the cloud's hand-in-object term
  alone, 3.23 with the grid, 2.05 with the grid and the object points (the mug's handle through the hand 18.3 ->
  6.5 -> 0.04 cm³), in 542 / 422 / 691 s.
- The polish after Alg. 2's stage 2: Adam moves every parameter by about its learning rate per step however small
  the gradient, so at the paper's final lr 0.005 each frame's translation jitters by millimetres between steps, and
  neighbouring frames independently: up to 5 mm per frame is 0.15 m/s, twice the 75 mm/s of SAGA's skating metric.
  Measured on the first approach clip of each of the 11 training objects (one MotionFill sample each, seed 0): skating
  0.23 after Alg. 2, 0.10 with the polish (0.12 when the last 100 of the 300 steps run at 0.001 instead); on a body
  standing still the median heel-marker speed after the fit falls from 0.031 to 0.007 m/s
  (tests/test_graspmotion.py). `polish=(0, 0.0)` is the paper's schedule.
- Two foot terms beside S.2 (graspkit's, on with the defaults; `terms` without "heel" and `foot_acc=0` give S.2
  alone). (1) A planted heel: a_heel sum_t 1(both heel markers within 6 cm of the floor) (min(|v^LHEE_t|,
  |v^RHEE_t|) - sigma)_+, a_heel = 1e4 per metre: SAGA's skating metric counts the frames where both heels are low
  and both move, and after S.2 these were mostly a planted toe with its heel rolling while the other foot shuffled
  low. The floor is `fit(floor=...)` (default: the lowest heel marker of the target). (2) The feet's acceleration,
  a_acc sum_t mean_v |V^foot_{t+1} - 2 V^foot_t + V^foot_{t-1}|^2, a_acc = 1e5 (m per frame^2): S.2's hinge is
  linear, so a foot can stand still and then jump several centimetres in one frame at no extra cost, and the fit
  did (heel markers up to 3.4 m/s, 99th-percentile acceleration 56 m/s^2 against the clips' 11). Chosen on the
  first approach clip of each of the 11 training objects (one MotionFill sample each, seed 0; skating after Opt /
  heel acceleration p99 m/s^2 / fitted vs sampled cm): S.2 alone 0.105 / 56 / 7.02; + heel 3e3 0.044 / 87 / 7.04;
  + heel 3e3 and acc 1e4 0.044 / 43; 1e5: 0.065 / 19; heel 1e4 and acc 1e5 (shipped) 0.005 / 23 / 7.21; heel 3e4
  0.000 / 27 / 7.14. Ground truth: 0.021 / 11.
- A floor term (graspkit's, since 2026-12-01; Eq. 10 has no ground term, SAGA only measures the non-collision score):
  a_floor sum_t (floor - min_{v in soles} v_z,t)_+, a_floor = 3000 per metre (1000 until 2026-12-07, below), on each
  frame's lowest sole vertex (`foot_vertices`), in stage 2 and only when `fit` is given the floor (the heel markers'
  default is not the ground).
  MotionFill's markers and the grasp body they end at put the feet up to 3.3 cm under the floor. Measured with
  `saga.synthesize` (default steps, one thread, a_floor = 1000) on a capsule, a box and a torus no model saw, seeds
  0 and 1: the deepest vertex over the clip 1.2, 0.8 / 3.3, 2.4 / 1.0, 1.5 cm without the term, at most 0.12 mm with it;
  last-frame contact, volume and skating as before (the box's seed 0 even ends in contact, which it missed). The
  weight matters because Adam divides each step by the root of its running squared gradient: a_floor = 100 left
  0.4-2.7 cm (it loses to the marker fit and the hand's contact), and on markers sunk 2 cm into the floor, fitted
  without foot contacts (so without the stand term below), a_floor = 3000 throws the body up to 2.6 cm above it,
  where the fit's small gradients then barely move it (1000: 0.9 cm; tests/test_graspmotion.py); a sum over all
  sole vertices overshot the same way. With the contacts the stand term holds it down, and 1000 lost to S.2's
  skating term, whose gradient sums over every sole vertex in contact: a mug clip's first twelve frames sank 0.78 cm
  under the floor with both terms at 1000, 0.08 cm at 3000 (found to hold; docs/saga_motion.md, "The stand term").
- A stand term (graspkit's, since 2026-12-07), the floor term's other side: a_stand sum_t 1(a part in T_c) (min_{v in
  soles} v_z,t - floor - h)_+, a_stand = a_floor = 3000 per metre (both 1000 on its first day), h = 5 mm, with T_c as
  S.2's (MotionFill's foot contacts > 0.5, and each frame's most probable part with `one_foot_down`, the default: then
  every frame), in stage 2 and only when `fit` is given the floor and the contacts. It acts on the floor term's
  vertex, so the two hold it between the floor and h above (on the lowest vertex of the parts in contact instead, the
  two fought where a part not in contact dipped under the floor: a mug clip's deepest vertex 0.17 -> 1.18 cm). The
  floor term only pushes up, so a body MotionFill puts above the floor stayed there: on GOAL's twelve test sequences
  (`eval_goal.saga_sliding`, frame 0 free) 70 of 732 frames stood more than 1 cm above it (at most 3.4 cm), every one
  with a foot part predicted in contact; with both terms at 1000, 2 of them (GOAL's sliding 9.7 -> 9.2 %, end contact
  11 -> 9 of 12), at 3000 none (9.4 %, end contact 11 of 12, end volume 0.37 -> 0.22 cm3); on the twelve clips of
  `graspmotion_eval` 14.5 % of the frames -> 0, end contact 12 of 12 throughout, the deepest vertex under the floor
  0.17 cm without the term, 0.78 with both at 1000, 0.08 at 3000 (docs/saga_motion.md, "The stand term").
- A touch term (graspkit's, since 2026-12-08), in stage 2's polish only (`GraspMotionConfig.polish`; none with the
  paper's schedule): a_touch sum over the last contact_frames frames of (min over the hand vertices of the object's
  signed distance - 1 mm)_+, a_touch = 1000 per metre. Eq. 6 pulls on squared distances, 2 alpha d per point (0.24 at
  8 mm), which fade as the hand nears the object: on GOAL's twelve sequences a hand that touched at frame 50 drifted
  7.8 mm off by the last, and the row ended 11 of 12 in contact. With the term, 12 of 12 at the same sliding and end
  volume; on the whole of stage 2 it pulled hands in early (the twelve clips' end volume 0.16 -> 0.45 cm3); in the
  polish it leaves them as they were (docs/saga_motion.md, "The touch term").
- Free arm joints (`GraspMotionConfig.free_joints`, graspkit's, since 2026-12-02; () is Alg. 2's prior latent
  alone): per frame, the collar, shoulder, elbow and wrist joints get a free rotation on top of the prior's decoded
  pose (6D offsets from the identity, weight 5e-4 as alpha_theta, and 0.5 per degree past the human range:
  `GraspMotionWeights.free_joints`, `limits`), as GraspPose-Opt's arms (graspkit.optim.grasppose). Why: through
  the 32-D latent alone the fitted bodies stayed 6.3 cm (mean over markers and frames) from MotionFill's markers on
  the twelve test clips, and two of them ended with the hand short of the object (7 and 25 mm); with `synthesize`
  on two shapes no model saw, the last frame was 3.0-3.3 cm from MotionFill's last markers, which were 3 mm from the
  grasp's. With the arms free: 3.1 cm, 12 of 12 clips end in contact, last-frame volume 1.92 -> 1.20 cm3 (docs).
- The start frame (graspkit's, since 2026-12-03; `fit(start=...)`, passed by `saga.synthesize`): stage 1 fits frame 0
  to the start body's markers and stage 2 leaves it there. Without it S.2's planted feet drag frame 0 along the
  sample's first steps, 8-22 cm off the start body in the calls measured; held, it is 2-3 mm from it. The fit then
  follows the sample's first steps, which slide feet its contact head calls planted; at a_heel = 1e4 the heel that
  should stand crept at 0.08-0.14 m/s while the other moved too (SAGA's metric counts it: 0.18 on a mug), so a held
  start weighs the planted heel by `heel_held` = 3e4 (since 2026-12-07). `synthesize` on the 11 training objects, seeds 0-2 (33 calls): skating
  0.053 (15 calls above 0, every seed-1 call 0.10-0.18) -> 0.000, at the price of jerkier heels (heel acceleration
  p99 23.6 -> 30.8 m/s^2, mean over calls) and a little more end penetration (0.36 -> 0.48 cm^3, most of it two
  pitcher grasps); docs/saga_motion.md, "The start frame".
- Initialisation: the prior's mean pose, rigidly aligned per frame (Kabsch on the body and face markers).
- E^o_colli and E_g are evaluated on the frames where a hand vertex is within 2 cm of the object's bounding box
  (chosen without gradient each step; elsewhere both are 0 by definition: no vertex can be inside or within 1 cm),
  against every 4th object point (512 of 2048); without a grid, the hand-in-object sign comes from the nearest
  point's normal and E^o_colli is taken only on the hand vertices inside the object's box widened by 5 mm
  (`cloud_penetration`), the object-in-hand sum only on the points inside the hand's box: outside it no
  vertex can be inside the object, but the nearest point's normal called some inside — near a thin wall the nearest
  sample can be on the far face — and pushed hands away from objects they did not touch (since 2026-11-27; the
  weight choices above were measured before it). It also makes the term about 10x cheaper (9 % of the near frames'
  hand vertices are in that box on the test clips): six test clips with 10 + 40 + 100 steps 52 -> 34 s, the
  twelve-clip evaluation 299 -> 229 s on two threads.
- Energies are summed over the sequences of a batch (independent sequences; Adam's steps are per parameter), up to
  floating-point summation order, which Adam amplifies: a test clip fitted alone and batched with another differed by
  0.5 mm (largest marker difference after 20 + 40 + 100 steps) and, in an independent check (the mug stub beside
  the bottle stub, 20 + 40 + 20 steps), by 5.2 mm (mean 0.27 mm; energies and gradients at equal parameters agree
  to float precision, and equal inputs give equal bits), and over the full schedule such differences can settle a
  frame's feet differently (eval_motionfill's skating per clip moves by a few frames when the batch changes).
"""
from __future__ import annotations

import copy
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import torch
from torch import Tensor, nn
from tqdm.auto import tqdm

from graspkit.body.markers import foot_vertices, palm_vertices, saga_markers, saga_sparse_markers, vertex_normals
from graspkit.checks import check_bool, check_int, check_probabilities, check_steps, check_weight
from graspkit.models.gnet import SparseBody
from graspkit.objects.sdf import signed_distance_to_points
from graspkit.optim.grasppose import (ARM_JOINTS, GraspObject, _nearest, body_joint_ids, free_joint_excess,
                                     hand_vertex_ids, kabsch, with_free_joints)
from graspkit.optim.step import energy_step, with_autograd
from graspkit.progress import hidden
from graspkit.rotations import axis_angle_to_matrix, matrix_to_axis_angle, matrix_to_rot6d, rot6d_to_matrix
from graspkit.state import keeps_torch_state
from graspkit.train import load_checkpoint, state_dict_problem

if TYPE_CHECKING:
    from graspkit.body import BodyModel
    from graspkit.models.pose_prior import PosePrior

SMOOTH_AE_PATH = Path(__file__).resolve().parents[2] / "data_stubs" / "checkpoints" / "motionfill_smooth_ae.pt"
FOOT_PARTS = ("left_heel", "left_toe", "right_heel", "right_toe")


# ------------------------------------------------------------------------------------------------ S.1's autoencoder
class MarkerDiffAE(nn.Module):
    """Temporal-convolution autoencoder of marker differences (S.1, after LEMO): (B, T, M*3) -> latents (B, T, d)."""

    # buffers, registered in __init__ (declared for type checkers)
    scale: Tensor

    def __init__(self, n_in: int = 79 * 3, hidden: int = 128, latent: int = 32) -> None:
        super().__init__()
        self.n_in, self.hidden, self.latent_dim = n_in, hidden, latent
        self.enc = nn.Sequential(nn.Conv1d(n_in, hidden, 3, padding=1), nn.LeakyReLU(0.2),
                                 nn.Conv1d(hidden, latent, 3, padding=1))
        self.dec = nn.Sequential(nn.Conv1d(latent, hidden, 3, padding=1), nn.LeakyReLU(0.2),
                                 nn.Conv1d(hidden, n_in, 3, padding=1))
        self.register_buffer("scale", torch.ones(()))

    def encode(self, diffs: Tensor) -> Tensor:
        """Marker differences (B, T, M*3) in metres -> latents (B, T, d)."""
        return self.enc((diffs / self.scale).transpose(1, 2)).transpose(1, 2)

    def forward(self, diffs: Tensor) -> Tensor:
        """Reconstructed differences (B, T, M*3)."""
        return self.dec(self.encode(diffs).transpose(1, 2)).transpose(1, 2) * self.scale

    def state(self) -> dict[str, Any]:
        """Weights and sizes (weights-only checkpoint)."""
        return {"model": self.state_dict(), "sizes": [self.n_in, self.hidden, self.latent_dim]}

    @classmethod
    def from_state(cls, state: dict[str, Any]) -> "MarkerDiffAE":
        """Back from `state()`."""
        m = cls(*[int(s) for s in state["sizes"]])
        m.load_state_dict({k: v.float() for k, v in state["model"].items()})
        return m.eval()


@with_autograd
@keeps_torch_state
def train_smooth_ae(markers: np.ndarray, epochs: int = 30, seed: int = 0, out: str | Path | None = SMOOTH_AE_PATH,
                    batch_size: int = 64, lr: float = 2e-3) -> tuple[MarkerDiffAE, list[float]]:
    """Train S.1's autoencoder on marker windows (N, T+1, M, 3) (reconstruction L1 of the differences); save it."""
    from graspkit.train import save_checkpoint

    g = torch.Generator().manual_seed(seed)
    torch.manual_seed(seed)
    d = torch.as_tensor(np.diff(markers, axis=1)).float().flatten(2)          # (N, T, M*3)
    ae = MarkerDiffAE(d.shape[-1])
    ae.scale.fill_(float(d.abs().mean()))
    opt = torch.optim.Adam(ae.parameters(), lr=lr)
    hist = []
    for _ in range(epochs):
        perm = torch.randperm(len(d), generator=g)
        tot = 0.0
        for a in range(0, len(d), batch_size):
            x = d[perm[a:a + batch_size]]
            loss = ((ae(x) - x) / ae.scale).abs().mean()
            opt.zero_grad()
            loss.backward()
            opt.step()
            tot += float(loss.detach()) * len(x)
        hist.append(tot / len(d))
    ae.eval()
    if out is not None:
        st = ae.state()
        st["model"] = {k: v.half() if k != "scale" else v for k, v in st["model"].items()}
        save_checkpoint(out, st)
    return ae, hist


@keeps_torch_state
def load_smooth_ae(path: str | Path = SMOOTH_AE_PATH) -> MarkerDiffAE:
    """The shipped S.1 autoencoder (weights_only)."""
    if not Path(path).is_file():
        raise FileNotFoundError(f"path: no marker-difference autoencoder at {path} (graspkit train motionfill "
                                "--stage smooth_ae)")
    state = load_checkpoint(path)
    if not isinstance(state.get("sizes"), (list, tuple)) or not isinstance(state.get("model"), dict):
        raise ValueError(f"checkpoint {path}: not a marker-difference autoencoder (no 'sizes' / 'model'; expected "
                         "what train_smooth_ae writes)")
    try:
        return MarkerDiffAE.from_state(state)
    except (RuntimeError, TypeError, ValueError) as e:
        raise ValueError(f"checkpoint {path}: not a marker-difference autoencoder of these sizes "
                         f"({state_dict_problem(e)})") from None


def in_box(x: Tensor, lo: Tensor, hi: Tensor, margin: float) -> Tensor:
    """Which points x (B, ..., 3) lie inside the box [lo - margin, hi + margin] (lo, hi broadcastable) -> (B, ...)."""
    return ((x > lo - margin) & (x < hi + margin)).all(-1)


def _boxed_hinge(q: Tensor, inside: Tensor, cloud: Tensor, normals: Tensor, sigma: float) -> Tensor:
    """(S(q, cloud) below -sigma)_+ (B, N) for queries q (B, N, 3), computed only where `inside` (B, N) and 0
    elsewhere; S from the nearest cloud point (B, P, 3) and its outward normal (SAGA's S(x, Y))."""
    from graspkit.optim.grasppose import _signed_to_cloud

    B, N, _ = q.shape
    k = int(inside.sum(1).max())
    if k == 0:
        return q.new_zeros(B, N)
    idx = inside.to(q.dtype).topk(k, dim=1).indices          # each row's inside queries first, padded with others
    sd, _ = _signed_to_cloud(torch.gather(q, 1, idx.unsqueeze(-1).expand(-1, -1, 3)), cloud, normals)
    val = torch.relu(-sd - sigma) * torch.gather(inside, 1, idx).to(q.dtype)
    return q.new_zeros(B, N).scatter(1, idx, val)


# ------------------------------------------------------------------------------------------------ the optimiser
# stage 2's terms, all on by default (touch in the polish only)
TERMS = ("colli", "contact", "touch", "palm", "smooth", "skate", "heel", "floor", "stand")


@dataclass
class GraspMotionWeights:
    """Weights and thresholds (see the module docstring for which are the paper's)."""

    prior: float = 5e-4            # alpha_theta (Eq. 5, as GraspPose-Opt)
    colli: float = 200.0           # alpha^B_colli
    sigma_b: float = 1e-3          # m
    colli_object: float = 100.0    # alpha^O_colli: object points inside the hand (Eq. 7's second sum; as GraspPose-Opt)
    sigma_o: float = 1e-3          # m
    contact: float = 15.0          # alpha^o_cont
    contact_marker: float = 15.0   # alpha^m_cont: Eq. 6's marker side, when fit gets C^_M (as GraspPose-Opt)
    palm: float = 10.0             # E_g's weight
    touch: float = 1000.0          # graspkit's: per metre the hand's closest vertex stands off the object past
    touch_gap: float = 0.001       # touch_gap (m) on each of the last contact_frames frames, in stage 2's polish
    palm_sigma: float = 0.01       # m (Eq. 11)
    smooth_latent: float = 1.0     # a^B_s
    smooth_hand: float = 10.0      # a^h_s (on the mean over hand vertices)
    skate: float = 300.0           # a_skat
    skate_sigma: float = 0.05 / 30  # m per frame (0.05 m/s: below SAGA's 75 mm/s skating threshold)
    heel: float = 1e4              # graspkit's planted heel: the slower heel marker's speed above skate_sigma
    heel_held: float = 3e4         # a_heel when fit holds frame 0 at a start body (fit(start=...), saga.synthesize);
                                   # heel=0 leaves it on: set both to 0 to drop the planted heel there
    heel_height: float = 0.06      # m above the floor: with both heels this low, one of them should stand still
    foot_acc: float = 1e5          # graspkit's: squared foot-vertex acceleration (m/frame^2), mean over vertices
    floor: float = 3000.0          # graspkit's: each frame's lowest sole vertex below the floor (m), when fit gets it
    stand: float = 3000.0          # graspkit's: each frame's lowest sole vertex above the floor while a foot part is
                                   # in contact (T_c), when fit gets the floor and the contacts
    stand_height: float = 0.005    # m above the floor the lowest sole vertex may stand at no cost
    free_joints: float = 5e-4      # on the 6D offsets of GraspMotionConfig.free_joints (graspkit's; = alpha_theta)
    limits: float = 0.5            # per degree a free joint turns past the human range (metrics.joint_limit_excess)

    def __post_init__(self) -> None:
        for name, value in vars(self).items():        # a negative weight rewards what its term removes
            check_weight(value, name)
        for name in ("palm_sigma", "skate_sigma", "heel_height", "stand_height", "touch_gap"):  # sigma_b, sigma_o: 0 ok
            if getattr(self, name) <= 0:
                raise ValueError(f"{name}: expected a threshold > 0, got {getattr(self, name)!r}")


@dataclass
class GraspMotionConfig:
    """Alg. 2's schedule and the switches of stage 2's terms."""

    steps: tuple[int, int] = (100, 300)
    polish: tuple[int, float] = (100, 1e-3)   # stage 2 goes on for polish[0] steps at lr polish[1] (graspkit's)
    n_pca: int = 24
    contact_frames: int = 5        # Eq. 10: object contact on the last 5 frames
    point_stride: int = 4          # E^o_colli and E_g use every 4th object point (512 of SAGA's 2048)
    log_every: int = 10
    terms: tuple[str, ...] = TERMS
    one_foot_down: bool = True     # T_c also holds each frame's most probable foot part (a foot is always planted)
    # body joints (SMPL-X names) given a free rotation per frame on top of the prior's decoded pose, penalised by
    # weights.free_joints and weights.limits (graspkit's, as GraspPose-Opt's; () is Alg. 2's prior latent alone)
    free_joints: tuple[str, ...] = ARM_JOINTS
    weights: GraspMotionWeights = field(default_factory=GraspMotionWeights)

    def __post_init__(self) -> None:
        n, lr = self.polish
        if int(n) != n or n < 0 or (n > 0 and not lr > 0):
            raise ValueError(f"polish: expected (steps >= 0, learning rate > 0), got {self.polish}")
        check_steps(self.steps, "steps", 2)           # (stage-1 steps, stage-2 steps)
        check_int(self.n_pca, "n_pca", least=1)
        if self.n_pca > 45:
            raise ValueError(f"n_pca: expected at most the model's 45 hand components, got {self.n_pca}")
        check_int(self.contact_frames, "contact_frames", least=0)     # 0: no object contact term
        check_int(self.point_stride, "point_stride", least=1)
        check_int(self.log_every, "log_every", least=1)
        check_bool(self.one_foot_down, "one_foot_down")
        unknown = [t for t in self.terms if t not in TERMS]
        if isinstance(self.terms, str) or unknown:
            raise ValueError(f"terms: expected a tuple of {TERMS}, got unknown {unknown or self.terms!r}")


@dataclass
class GraspMotionResult:
    """Fitted sequences: SMPL-X parameters per frame (B, T+1, ...), fitted markers, joints, energies, a step log."""

    params: dict[str, Tensor]
    markers: Tensor                 # (B, T+1, 79, 3)
    joints: Tensor                  # (B, T+1, 55, 3)
    energies: dict[str, dict[str, Tensor]]     # {'stage1': {term: (B,)}, 'stage2': ...} after each stage
    log: list[dict[str, float]]


class GraspMotionOpt:
    """SAGA's GraspMotion-Opt for a BodyModel (flat_hand_mean=False), the pose prior and S.1's autoencoder."""

    def __init__(self, bm: BodyModel, prior: PosePrior, smooth_ae: MarkerDiffAE | None = None,
                 config: GraspMotionConfig | None = None) -> None:
        if bm.flat_hand_mean:
            raise ValueError("bm: build the BodyModel with flat_hand_mean=False (hand PCA about the mean hand)")
        # frozen copies: the caller's prior and autoencoder keep their mode and gradients
        self.bm, self.prior = bm, copy.deepcopy(prior).eval().requires_grad_(False)
        self.ae = None if smooth_ae is None else copy.deepcopy(smooth_ae).requires_grad_(False)
        self.cfg = config or GraspMotionConfig()
        self.free_ids = body_joint_ids(self.cfg.free_joints)
        ms = saga_sparse_markers(bm)
        self.n_markers = len(ms)
        contact_ids = saga_markers(bm).vertex_ids               # the 143 markers of C^_M (Eq. 6's marker side)
        self.heels = [ms.names.index("LHEE"), ms.names.index("RHEE")]
        self.body_face = torch.arange(ms.groups["face"][1])
        hands = np.union1d(hand_vertex_ids(bm, ("right",)), palm_vertices(bm)["right"])
        feet = foot_vertices(bm)
        foot_ids = np.concatenate([feet[k] for k in FOOT_PARTS])
        self.foot_part = torch.as_tensor(np.concatenate([np.full(len(feet[k]), i) for i, k in enumerate(FOOT_PARTS)]))
        ids = np.concatenate([ms.vertex_ids, hands, foot_ids, contact_ids])
        self.sparse = SparseBody(bm, torch.as_tensor(ids))
        n_m, n_h, n_f = len(ms.vertex_ids), len(hands), len(foot_ids)
        self.sl_m, self.sl_h = slice(0, n_m), slice(n_m, n_m + n_h)
        self.sl_f, self.sl_c = slice(n_m + n_h, n_m + n_h + n_f), slice(n_m + n_h + n_f, None)
        self.n_contact_markers = len(contact_ids)
        pos = torch.full((bm.num_vertices,), -1, dtype=torch.long)
        pos[torch.as_tensor(hands)] = torch.arange(n_h)
        f = pos[bm.faces.long()]
        self.hand_faces = f[(f >= 0).all(1)]
        self.palm = pos[torch.as_tensor(palm_vertices(bm)["right"])]
        k = self.cfg.n_pca
        self.pca = {s: getattr(bm, f"{s}_hand_components")[:k].float() for s in ("left", "right")}
        self.hand_mean = {"left": bm.pose_mean[75:120].float(), "right": bm.pose_mean[120:165].float()}

    # ------------------------------------------------------------------ the body
    def rotmats(self, p: dict[str, Tensor]) -> Tensor:
        """All 55 joint rotations (N,55,3,3) of frame parameters (N, ...) (hand mean added, jaw and eyes zero; the
        free joints' 6D offsets `joint6d` (N, n_free * 6) on top of the prior's pose where given)."""
        N = p["transl"].shape[0]
        eye = torch.eye(3).expand(N, 3, 3, 3)
        hands = [axis_angle_to_matrix((p[f"{s}_pca"] @ self.pca[s] + self.hand_mean[s]).view(N, 15, 3))
                 for s in ("left", "right")]
        body = self.prior.decode_rotmats(p["z"])
        if len(self.free_ids) and "joint6d" in p:     # (parameters without the offsets: the prior's pose)
            body = with_free_joints(body, p["joint6d"].view(N, -1, 6), self.free_ids)
        return torch.cat([rot6d_to_matrix(p["orient6d"]).unsqueeze(1), body, eye, hands[0], hands[1]], 1)

    def body(self, p: dict[str, Tensor], betas: Tensor) -> tuple[Tensor, Tensor]:
        """Markers, hand and foot vertices (N, n, 3) and joints (N, 55, 3) of frame parameters."""
        return self.sparse(self.rotmats(p), betas, p["transl"])

    def init_params(self, markers: Tensor, betas: Tensor) -> dict[str, Tensor]:
        """Per-frame start (N = B (T+1) frames): the prior's mean pose, Kabsch-aligned to the body and face markers."""
        N = markers.shape[0]
        p = {"transl": torch.zeros(N, 3), "orient6d": matrix_to_rot6d(torch.eye(3).expand(N, 3, 3)).clone(),
             "z": torch.zeros(N, self.prior.cfg.latent), "left_pca": torch.zeros(N, self.cfg.n_pca),
             "right_pca": torch.zeros(N, self.cfg.n_pca)}
        if len(self.free_ids):
            p["joint6d"] = torch.zeros(N, len(self.free_ids), 6)
        with torch.no_grad():
            v, J = self.body(p, betas)
            R, c = kabsch(v[:, self.sl_m][:, self.body_face].float(), markers[:, self.body_face])
            J0 = J[:, 0].float()
            p["orient6d"] = matrix_to_rot6d(R)
            p["transl"] = (R @ J0.unsqueeze(-1)).squeeze(-1) + c - J0
        return p

    # ------------------------------------------------------------------ the energy
    def energy(self, p: dict[str, Tensor], target: Tensor, betas: Tensor, stage: int, foot_contact: Tensor | None,
               obj: GraspObject | None, object_contact: Tensor | None, floor: Tensor | None = None,
               marker_contact: Tensor | None = None, held: bool = False, polish: bool = False) -> dict[str, Tensor]:
        """Each term per sequence (B,) for frame parameters (B*(T+1), ...) and target markers (B, T+1, M, 3);
        `held`: frame 0 is held at a start body, so the planted heel takes weights.heel_held; `polish`: stage 2's
        polish steps, which add the touch term."""
        cfg, w = self.cfg, self.cfg.weights
        B, F = target.shape[:2]
        rot = self.rotmats(p)
        v = self.sparse(rot, betas, p["transl"])[0].float().view(B, F, -1, 3)
        m, hands, feet = v[:, :, self.sl_m], v[:, :, self.sl_h], v[:, :, self.sl_f]
        e = {"fit": (m - target).abs().sum((1, 2, 3)),
             "prior": w.prior * (p["z"].pow(2).sum(-1) + p["left_pca"].pow(2).sum(-1)
                                 + p["right_pca"].pow(2).sum(-1)).view(B, F).sum(1)}
        if len(self.free_ids) and "joint6d" in p:   # the free joints' offsets and how far they turn past the human range
            e["prior"] = e["prior"] + w.free_joints * p["joint6d"].pow(2).view(B, F, -1).sum((1, 2))
            if w.limits > 0:
                e["limits"] = w.limits * free_joint_excess(rot, self.free_ids).view(B, F).sum(1)
        if stage < 2:
            return e
        terms = cfg.terms
        k_c = min(cfg.contact_frames, F)                           # the last k_c frames: contact and touch (0: none)
        if obj is not None:
            pts, nrm, _ = obj.batch(B)
            with torch.no_grad():               # frames with a hand vertex within 2 cm of the object's box
                lo, hi = pts.min(1).values[:, None], pts.max(1).values[:, None]                   # (B, 1, 3)
                near = in_box(hands, lo[:, None], hi[:, None], 0.02).any(-1).any(0).nonzero()[:, 0]   # (K,)
            hf = hands[:, near].reshape(B, -1, 3)
            pts, nrm = pts[:, ::cfg.point_stride], nrm[:, ::cfg.point_stride]
            if "colli" in terms:
                if obj.sdf is not None:              # (a grid wants at least one point: no frame may be near)
                    pen = torch.relu(-obj.signed_distance(hf) - w.sigma_b) if len(near) else hf.new_zeros(B, 0)
                else:
                    pen = self.cloud_penetration(hf, pts, nrm, lo, hi)
                e["colli"] = w.colli * pen.sum(-1)
                if w.colli_object > 0 and len(near):
                    K = len(near)
                    inner = self.object_in_hand(hf.reshape(B * K, -1, 3), pts.repeat_interleave(K, 0))
                    e["colli"] = e["colli"] + w.colli_object * inner.view(B, -1).sum(-1)
            if "contact" in terms and object_contact is not None and k_c:
                last = hands[:, hands.shape[1] - k_c:]
                idx = object_contact.topk(min(256, object_contact.shape[1]), -1).indices
                po = torch.gather(obj.batch(B)[0], 1, idx.unsqueeze(-1).expand(-1, -1, 3))
                d2 = torch.stack([_nearest(po, last[:, k])[0] for k in range(last.shape[1])], 1)   # (B, 5, 256)
                e["contact"] = w.contact * (torch.gather(object_contact, 1, idx)[:, None] * d2).sum((1, 2))
            if "contact" in terms and marker_contact is not None and k_c:   # Eq. 6's other side: C^_M to the object
                cm = v[:, v.shape[1] - k_c:, self.sl_c]                                      # (B, 5, 143, 3)
                whole = obj.batch(B)[0]
                d2 = torch.stack([_nearest(cm[:, k], whole)[0] for k in range(cm.shape[1])], 1)    # (B, 5, 143)
                e["contact"] = e.get("contact", 0) + w.contact_marker * (marker_contact[:, None] * d2).sum((1, 2))
            if "palm" in terms:
                e["palm"] = w.palm * self.palm_term(hands[:, near], pts, near, F)
        if "smooth" in terms:
            hv = (hands[:, 1:] - hands[:, :-1]).pow(2).sum(-1).mean(-1).sum(1)       # mean over the hand vertices
            e["smooth"] = w.smooth_hand * hv
            if self.ae is not None:
                S = self.ae.encode((m[:, 1:] - m[:, :-1]).flatten(2))
                e["smooth"] = e["smooth"] + w.smooth_latent * (S[:, 1:] - S[:, :-1]).pow(2).sum((1, 2))
        down = None if foot_contact is None else self.parts_down(foot_contact)   # (B, F, n_foot) T_c: skate, stand
        if "skate" in terms and down is not None:
            speed = (feet[:, 1:] - feet[:, :-1]).norm(dim=-1)                     # (B, T, n_foot)
            e["skate"] = w.skate * (down[:, :-1].to(speed.dtype) * torch.relu(speed - w.skate_sigma)).sum((1, 2))
        if "skate" in terms and w.foot_acc > 0:
            e["foot_acc"] = w.foot_acc * (feet[:, 2:] - 2 * feet[:, 1:-1] + feet[:, :-2]).pow(2).sum(-1).mean(-1).sum(1)
        lowest = feet[..., 2].amin(-1)                  # (B, F) each frame's lowest sole vertex (floor and stand)
        if "floor" in terms and w.floor > 0 and floor is not None:    # only a floor given: the heel markers' is not it
            e["floor"] = w.floor * torch.relu(floor[:, None] - lowest).sum(1)
        if "stand" in terms and w.stand > 0 and floor is not None and down is not None:
            # the floor term's vertex: a part's own lowest vertex would fight it where another part dips under;
            # a frame counts when a part is in T_c (every frame with one_foot_down)
            e["stand"] = w.stand * (down.any(-1) * torch.relu(lowest - floor[:, None] - w.stand_height)).sum(1)
        a_heel = w.heel_held if held else w.heel
        if "heel" in terms and a_heel > 0:
            if floor is None:                   # the lowest heel marker of the target sequence
                floor = target[:, :, self.heels, 2].amin((1, 2))
            h = m[:, :, self.heels]                                                 # (B, F, 2, 3)
            speed = (h[:, 1:] - h[:, :-1]).norm(dim=-1)                             # (B, T, 2)
            low = ((h[:, :-1, :, 2] - floor[:, None, None]) < w.heel_height).all(-1).detach()
            e["heel"] = a_heel * (low * torch.relu(speed.min(-1).values - w.skate_sigma)).sum(1)
        if "touch" in terms and polish and w.touch > 0 and obj is not None and k_c:
            # graspkit's (docs/saga_motion.md, "The touch term"): Eq. 6 pulls on squared distances, which fade as the
            # hand nears the object; this pulls the closest hand vertex linearly to within touch_gap of the surface
            # and no further (the collision hinges push back past sigma_b)
            last = hands[:, F - k_c:].reshape(B, -1, 3)
            if obj.sdf is not None:
                d = obj.signed_distance(last)
            else:
                cloud, normals, _ = obj.batch(B)
                d = signed_distance_to_points(last, cloud[:, ::cfg.point_stride], normals[:, ::cfg.point_stride])
            e["touch"] = w.touch * torch.relu(d.view(B, k_c, -1).amin(-1) - w.touch_gap).sum(1)
        return e

    def parts_down(self, foot_contact: Tensor) -> Tensor:
        """T_c of S.2 per sole vertex: (B, F, 4) foot-contact probabilities -> (B, F, n_foot) bool, a part down where
        its probability is above 0.5 (and, with `one_foot_down`, each frame's most probable part, first of ties)."""
        on = foot_contact > 0.5
        if self.cfg.one_foot_down:
            on = on | torch.nn.functional.one_hot(foot_contact.argmax(-1), 4).bool()
        return on[:, :, self.foot_part]

    def cloud_penetration(self, q: Tensor, pts: Tensor, nrm: Tensor, lo: Tensor, hi: Tensor) -> Tensor:
        """E^o_colli's hinge (S(q, O) below -sigma_b)_+ per query (B, N) against a point cloud with normals (B, P, 3),
        computed only for the queries inside the cloud's box [lo, hi] (B, 1, 3) widened by 5 mm (elsewhere the
        object's signed distance is positive and the hinge 0): most hand vertices of a near frame are outside it."""
        return _boxed_hinge(q, in_box(q, lo, hi, 0.005), pts, nrm, self.cfg.weights.sigma_b)

    def object_in_hand(self, hands: Tensor, pts: Tensor) -> Tensor:
        """Eq. 7's second hinge (S(o, V^h_B) below -sigma_o)_+ (N, P) of object points pts (N, P, 3) against the hand
        vertices (N, H, 3) of N frames, the sign from the hand's vertex normals; only points inside the hand's box
        widened by 5 mm are measured (no other point can be inside the hand)."""
        from graspkit.body.markers import vertex_normals

        with torch.no_grad():
            inside = in_box(pts, hands.min(1, keepdim=True).values, hands.max(1, keepdim=True).values, 0.005)
        if not inside.any():                  # the hand's normals are not needed
            return pts.new_zeros(pts.shape[:2])
        return _boxed_hinge(pts, inside, hands, vertex_normals(hands, self.hand_faces), self.cfg.weights.sigma_o)

    def palm_term(self, hands: Tensor, pts: Tensor, frames: Tensor | None = None, total: int | None = None) -> Tensor:
        """Eq. 11 per sequence (B,): alpha_t 1(d < sigma) (cos gamma - 1)^2 over the palm vertices of every frame;
        `frames` (F,) are the frame indices of `hands` (B, F, H, 3) in a sequence of `total` frames (default: all)."""
        B, F, H, _ = hands.shape
        if F == 0:
            return hands.new_zeros(B)
        hn = vertex_normals(hands.reshape(B * F, H, 3), self.hand_faces)[:, self.palm]      # (BF, P, 3)
        pv = hands.reshape(B * F, H, 3)[:, self.palm]
        ptsf = pts.repeat_interleave(F, 0)
        d2, idx = _nearest(pv, ptsf)
        near = torch.gather(ptsf, 1, idx.unsqueeze(-1).expand(-1, -1, 3))
        cos = torch.nn.functional.cosine_similarity(hn, near - pv, dim=-1)
        on = (d2.detach() < self.cfg.weights.palm_sigma ** 2).to(cos.dtype)
        t = torch.arange(F, dtype=cos.dtype) if frames is None else frames.to(cos.dtype)
        alpha = 1.0 - (t / ((total or F) - 1)) ** 2
        return (alpha[None, :, None] * (on * (cos - 1) ** 2).view(B, F, -1)).sum((1, 2))

    # ------------------------------------------------------------------ Alg. 2
    @with_autograd
    def fit(self, markers: Tensor, betas: Tensor, foot_contact: Tensor | None = None, obj: GraspObject | None = None,
            object_contact: Tensor | None = None, progress: bool = True, floor: Tensor | None = None,
            marker_contact: Tensor | None = None, start: Tensor | None = None) -> GraspMotionResult:
        """Alg. 2 on a batch: markers (B, T+1, 79, 3), betas (B, 10), foot contacts (B, T+1, 4) probabilities, the
        object in the markers' frame, its contact map (B, P), the floor's height (B,) for the floor and stand terms
        and the planted-heel term (default: neither, and each target's lowest heel marker for the heel), the grasp's
        143-marker contacts C^_M (B, 143) for E^o_cont's marker side (default: left out), and the start body's
        markers (B, 79, 3): stage 1 fits frame 0 to them and stage 2 holds frame 0 there (graspkit's; default: Alg. 2,
        frame 0 fits the sample's first frame like any other) -> GraspMotionResult."""
        if not isinstance(markers, Tensor) or markers.dim() != 4 or tuple(markers.shape[2:]) != (self.n_markers, 3):
            got = tuple(markers.shape) if isinstance(markers, Tensor) else type(markers).__name__
            raise ValueError(f"markers: expected shape (B, T+1, {self.n_markers}, 3), got {got}")
        B, F = markers.shape[:2]
        if B < 1:
            raise ValueError("markers: expected at least one sequence (B >= 1), got 0")
        if F < 2:
            raise ValueError(f"markers: expected a sequence of at least 2 frames, got {F}")
        if not isinstance(betas, Tensor) or betas.dim() != 2:
            got = tuple(betas.shape) if isinstance(betas, Tensor) else type(betas).__name__
            raise ValueError(f"betas: expected a tensor (B, num_betas), got {got}")
        for name, x in (("markers", markers), ("betas", betas), ("start", start)):
            if x is not None and isinstance(x, Tensor) and not bool(torch.isfinite(x).all()):
                raise ValueError(f"{name}: contains NaN or Inf")
        if betas.shape[0] != B:
            raise ValueError(f"betas: expected {B} rows (one per sequence), got {tuple(betas.shape)}")
        if betas.shape[1] > self.bm.num_betas:
            raise ValueError(f"betas: expected at most the body model's {self.bm.num_betas} shape coefficients, "
                             f"got {betas.shape[1]}")
        if foot_contact is not None and tuple(foot_contact.shape) != (B, F, 4):
            raise ValueError(f"foot_contact: expected shape ({B}, {F}, 4), got {tuple(foot_contact.shape)}")
        for name, x in (("foot_contact", foot_contact), ("object_contact", object_contact),
                        ("marker_contact", marker_contact)):
            check_probabilities(x, name)
        if object_contact is not None and (obj is None or tuple(object_contact.shape) != (B, obj.num_points)):
            raise ValueError(f"object_contact: expected shape ({B}, P) with an object of P points")
        if marker_contact is not None:
            got = tuple(marker_contact.shape) if isinstance(marker_contact, Tensor) else type(marker_contact).__name__
            if obj is None or got != (B, self.n_contact_markers):
                raise ValueError(f"marker_contact: expected shape ({B}, {self.n_contact_markers}) (the grasp's SAGA "
                                 f"marker contacts) and an object, got {got} and obj={'given' if obj else None}")
        if floor is not None and (not isinstance(floor, Tensor) or tuple(floor.shape) != (B,)
                                  or not bool(torch.isfinite(floor).all())):
            got = tuple(floor.shape) if isinstance(floor, Tensor) else type(floor).__name__
            raise ValueError(f"floor: expected a finite tensor of shape ({B},) (each sequence's floor height, m), "
                             f"got {got}")
        if start is not None and (not isinstance(start, Tensor) or tuple(start.shape) != (B, self.n_markers, 3)):
            got = tuple(start.shape) if isinstance(start, Tensor) else type(start).__name__
            raise ValueError(f"start: expected the start body's markers, shape ({B}, {self.n_markers}, 3), got {got}")
        target = markers.detach().float()
        if start is not None:
            target = torch.cat([start.detach().float()[:, None], target[:, 1:]], 1)
        mc = None if marker_contact is None else marker_contact.detach().float()
        held = start is not None
        bet = betas.float().repeat_interleave(F, 0)
        p0 = self.init_params(target.flatten(0, 1), bet)
        first = {k: v.view(B, F, -1)[:, :1].clone().requires_grad_(True) for k, v in p0.items()}
        rest = {k: v.view(B, F, -1)[:, 1:].clone().requires_grad_(True) for k, v in p0.items()}

        def params() -> dict[str, Tensor]:
            return {k: torch.cat([first[k], rest[k]], 1).flatten(0, 1) for k in first}

        log: list[dict[str, float]] = []
        energies: dict[str, dict[str, Tensor]] = {}
        n_polish, lr_polish = self.cfg.polish
        bar = tqdm(total=sum(self.cfg.steps) + n_polish, desc="GraspMotion-Opt", disable=hidden(progress))
        step = 0
        for stage, n in ((1, self.cfg.steps[0]), (2, self.cfg.steps[1] + n_polish)):
            # with a start body, stage 2 leaves frame 0 where stage 1 fitted it: S.2's planted feet would otherwise
            # drag it along the sample's first steps, 12 cm off the start (docs/saga_motion.md, "The start frame")
            fit_first = stage == 1 or start is None
            for t in first.values():
                t.requires_grad_(fit_first)
            groups = [{"params": list(rest.values()), "lr": 0.01}]
            if fit_first:
                groups.insert(0, {"params": list(first.values()), "lr": 0.1 if stage == 1 else 0.01})
            opt = torch.optim.Adam(groups)
            for i in range(n):
                if stage == 1 and i in (60, 80):
                    for g in opt.param_groups:
                        g["lr"] = 0.01 if i == 60 else 0.003
                if stage == 2 and i in (150, self.cfg.steps[1]):      # the paper's decay, then the polish
                    for g in opt.param_groups:
                        g["lr"] = lr_polish if i >= self.cfg.steps[1] else 0.005
                e = self.energy(params(), target, bet, stage, foot_contact, obj, object_contact, floor, mc, held,
                                stage == 2 and i >= self.cfg.steps[1])
                energy_step(opt, e, log, i, step, stage, self.cfg.log_every)
                step += 1
                bar.update(1)
            with torch.no_grad():
                energies[f"stage{stage}"] = {k: t.detach() for k, t in self.energy(
                    params(), target, bet, 2, foot_contact, obj, object_contact, floor, mc, held,
                    stage == 2 and n_polish > 0).items()}
        bar.close()
        with torch.no_grad():
            p = params()
            rot = self.rotmats(p)
            v, J = self.sparse(rot, bet, p["transl"])
            aa = matrix_to_axis_angle(rot).view(B, F, 55, 3)
            out = {"betas": betas.float(), "transl": p["transl"].view(B, F, 3), "global_orient": aa[:, :, 0],
                   "body_pose": aa[:, :, 1:22].reshape(B, F, 63), "left_hand_pose": aa[:, :, 25:40].reshape(B, F, 45),
                   "right_hand_pose": aa[:, :, 40:55].reshape(B, F, 45), "poses": aa.reshape(B, F, 165)}
        return GraspMotionResult(out, v[:, self.sl_m].float().view(B, F, -1, 3), J.float().view(B, F, 55, 3),
                                 energies, log)

    def vertices(self, result: GraspMotionResult, b: int = 0) -> Tensor:
        """Full meshes (T+1, V, 3) of sequence b (absolute rotations, this BodyModel's hand mean included)."""
        pr = result.params
        F = pr["transl"].shape[1]
        rot = axis_angle_to_matrix(pr["poses"][b].view(F, 55, 3))
        with torch.no_grad():
            return self.bm.forward_rotmats(rot, betas=pr["betas"][b:b + 1].expand(F, -1),
                                           transl=pr["transl"][b]).vertices.float()
