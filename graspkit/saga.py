"""SAGA end to end (`../shared/papers/SAGA.txt` §3, Fig. 2): an object in, an approach-and-grasp motion out, one call.

    object -> WholeGrasp-VAE sample (§3.2) -> GraspPose-Opt (Alg. 1) -> the grasp body
    start pose + grasp body -> MotionFill-VAE sample (§3.3) -> GraspMotion-Opt (Alg. 2) -> 61 frames (2 s, 30 fps)

`synthesize("mug")` runs it for any catalogue object with the shipped checkpoints, and `synthesize(mesh)` for an object
of one's own (a trimesh.Trimesh or a mesh file: closed, metres, z up; `graspkit.objects.user.as_object`). The object
is placed within reach of the start (`graspkit.objects.placement.within_reach_pose`, seeded) unless a pose is
given; the start is a standing body (the procedural planner's first frame) `start_distance` metres from the grasp,
facing the object, unless a `Start` is given. Everything is returned in the world frame (z up, floor z = 0).
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import torch

from graspkit.checks import (GraspkitWarning, ShapeWarning, check_bool, check_int, check_positive, check_steps,
                             check_type, user_stacklevel)
from graspkit.data.motion import Motion
from graspkit.data.reaching import Start
from graspkit.objects.placement import ObjectPose
from graspkit.paths import DATA_STUBS, require_checkpoints

if TYPE_CHECKING:
    from graspkit.body import BodyModel
    from graspkit.optim.graspmotion import GraspMotionConfig
    from graspkit.optim.grasppose import GraspObject, GraspPoseConfig

CHECKPOINTS = DATA_STUBS / "checkpoints"
MAX_START_DISTANCE = 3.0     # m: the farthest start taken; MotionFill fills 2 s, so past WALK_START_DISTANCE it runs
WALK_START_DISTANCE = 1.5    # m: a start farther from the grasp than this gets a note (measured: 1.5 m peaks at 2.3 m/s)
_RUN_NOTE = (f"covered in MotionFill's 2 s that is a run, not a walk (1.5 m: the pelvis peaks at 2.3 m/s, 2 m: 3.3 m/s, "
             "3 m: 4.4 m/s with both feet off the floor; the training approaches start a median 0.38 m away); keep "
             f"the start within {WALK_START_DISTANCE:g} m of the grasp's pelvis for a walk (docs/saga_motion.md)")


@dataclass
class SagaResult:
    """The grasp (object frame moved to the world), the motion (world), the sampled markers and the figures."""

    name: str
    object_pose: ObjectPose
    mesh: Any                        # trimesh.Trimesh in the world
    grasp: Any                       # GraspPoseResult in the world (the WholeGrasp sample after Alg. 1)
    motion: Motion                   # 61 frames, world, absolute hand poses
    start: Motion                    # the start body (1 frame)
    markers: torch.Tensor            # MotionFill's sampled markers (61, 79, 3), world
    foot_contact: torch.Tensor       # MotionFill's foot-contact probabilities (61, 4)
    metrics: dict[str, float]        # grasp figures of the grasp body (its lowest vertex too) and of the motion's
                                     # last frame, skating, floor


def rigid_params(poses: np.ndarray, transl: np.ndarray, betas: np.ndarray, R: np.ndarray, o: np.ndarray,
                 bm: BodyModel) -> tuple[np.ndarray, np.ndarray]:
    """SMPL-X poses (T,55,3) and transl (T,3) of bodies moved by x -> R x + o: the global rotation turns about the
    rest pelvis J0 (which depends on betas), so transl' = R (J0 + t) + o - J0."""
    from graspkit.rotations import axis_angle_to_matrix, matrix_to_axis_angle

    with torch.no_grad():
        J0 = bm(betas=torch.as_tensor(betas, dtype=torch.float32).reshape(1, -1)).joints[0, 0].double().numpy()
    g = axis_angle_to_matrix(torch.as_tensor(poses[:, 0], dtype=torch.float64)).numpy()
    out = np.array(poses, np.float64, copy=True)
    out[:, 0] = matrix_to_axis_angle(torch.as_tensor(R[None] @ g)).numpy()
    return out, (np.asarray(transl, np.float64) + J0) @ R.T + o - J0


def default_start(grasp_pelvis: np.ndarray, centre: np.ndarray, betas: np.ndarray, distance: float,
                  bm: BodyModel, seed: int = 0) -> Motion:
    """A standing body (the procedural planner's first frame) `distance` m from the grasp pelvis, on the side away
    from the object centre, facing it."""
    from graspkit.data.reaching import plan_reach

    d = np.asarray(grasp_pelvis, np.float64)[:2] - np.asarray(centre, np.float64)[:2]
    n = np.linalg.norm(d)
    d = d / n if n > 1e-6 else np.array([1.0, 0.0])
    xy = np.asarray(grasp_pelvis, np.float64)[:2] + distance * d
    heading = float(np.arctan2(-d[1], -d[0]))
    plan = plan_reach(Start(float(xy[0]), float(xy[1]), heading), centre, 60, betas=betas, seed=seed, bm=bm)
    return plan.slice(0, 1)


def check_checkpoints(checkpoints: str | Path | None = None) -> Path:
    """The folder `checkpoints` once the four files SAGA needs are in it (else FileNotFoundError naming the first
    missing; None: the shipped ones)."""
    return require_checkpoints(checkpoints if checkpoints is not None else CHECKPOINTS,
                               ("wholegrasp.pt", "pose_prior.pt", "motionfill.pt", "motionfill_smooth_ae.pt"),
                               "docs/saga.md and docs/saga_motion.md")


def synthesize(name: str | Path | Any, bm: BodyModel | None = None, object_pose: ObjectPose | None = None,
               start: Start | Motion | None = None, seed: int = 0, start_distance: float = 0.4,
               grasp_steps: tuple[int, int, int] = (300, 400, 500),
               motion_steps: tuple[int, int] = (100, 300), checkpoints: str | Path = CHECKPOINTS,
               progress: bool = True, free_joints: tuple[str, ...] | None = None,
               polish_steps: tuple[int, int] | None = None, hold_start: bool = True) -> SagaResult:
    """SAGA for object `name` (a catalogue name, a mesh file or a trimesh.Trimesh, closed and in metres): one grasp
    and one 2-s approach motion into it (Fig. 2), seeded: the same seed and torch thread count give the same numbers
    (it runs on torch's current threads; another count rounds the optimisers' sums differently; the command uses 1).

    object_pose: where the object is (default: drawn by `within_reach_pose(seed)` in front of the origin);
    start: a Start (x, y, heading: a standing body there) or a one-frame Motion (any body: its pose, in the grasp's
    shape, where it stands, `reshaped_in_place`; SagaResult.start is that body) or None: a standing body
    `start_distance` m (at most 3) from the grasp's pelvis, facing the object (see module doc). MotionFill fills 2 s:
    a start more than 1.5 m from the grasp's pelvis gets a warning (it makes a run, docs/saga_motion.md).
    free_joints: the body joints freed on top of the pose prior in GraspPose-Opt and GraspMotion-Opt
    (`GraspPoseConfig.free_joints`, `GraspMotionConfig.free_joints`; None: their default, the arm chains; () is
    Alg. 1's and Alg. 2's prior latent alone; docs/saga.md, docs/saga_motion.md).
    polish_steps: the polish steps of GraspPose-Opt and of GraspMotion-Opt (None: their configs' 100 each; a lesson
    with fewer steps throughout passes fewer).
    hold_start: GraspMotion-Opt fits frame 0 to the start body and holds it there, with the planted heel weighed by
    `GraspMotionWeights.heel_held` (graspkit's; False: Alg. 2, where S.2's planted feet drag frame 0 some 8-22 cm
    along the sample's first steps; docs/saga_motion.md, "The start frame").
    """
    from graspkit.body import BodyModel
    from graspkit.data.grasp_io import object_collision_grid
    from graspkit.models.pose_prior import load_pose_prior
    from graspkit.models.wholegrasp import load_wholegrasp
    from graspkit.objects.placement import apply_pose, warn_floor, within_reach_pose
    from graspkit.objects.user import as_object
    from graspkit.optim.grasppose import GraspObject
    from graspkit.paths import default_model_path

    check_int(seed, "seed")
    check_positive(start_distance, "start_distance", most=MAX_START_DISTANCE)
    if start is None and start_distance > WALK_START_DISTANCE:
        warnings.warn(f"start_distance: {start_distance:g} m; {_RUN_NOTE}", GraspkitWarning, stacklevel=user_stacklevel())
    gcfg, mcfg = _configs(grasp_steps, motion_steps, free_joints, polish_steps)
    _check_args(bm, start, object_pose, hold_start)
    given = name                     # as the caller gave it: a catalogue name keeps its cached grid
    name, obj_mesh = as_object(name, "name")
    ck = check_checkpoints(checkpoints)
    bm = bm if bm is not None else BodyModel.from_file(default_model_path())
    pose = object_pose if object_pose is not None else within_reach_pose(seed)
    warn_floor(pose, obj_mesh)
    g = torch.Generator().manual_seed(seed)
    R_o, centre = np.asarray(pose.rotation, np.float64), np.asarray(pose.translation, np.float64)
    P, N = _object_points(obj_mesh, R_o)
    prior = load_pose_prior(ck / "pose_prior.pt")
    s = load_wholegrasp(ck / "wholegrasp.pt").sample(P, N, float(centre[2]), 1, g, centre=torch.zeros(3))
    obj = GraspObject(P, N, float(centre[2]), object_collision_grid(given, obj_mesh, progress),
                      torch.as_tensor(R_o).float())
    res, grasp_body = _grasp_stage(s, obj, centre, bm, prior, gcfg, progress)
    st = _start_body(start, grasp_body, centre, start_distance, bm, seed)
    motion, markers_w, contacts, fitted = _motion_stage(ck, bm, prior, obj, R_o, centre, grasp_body, st, s, mcfg,
                                                         g, hold_start, progress)
    mesh = apply_pose(pose, obj_mesh)
    return SagaResult(name, pose, mesh, res, motion, st, markers_w, contacts,
                      _figures(res, motion, markers_w, fitted, mesh, bm))


def _check_args(bm: BodyModel | None, start: Start | Motion | None, object_pose: ObjectPose | None,
                hold_start: bool) -> None:
    """synthesize's body, start, object pose and hold_start (ValueError / TypeError naming the argument)."""
    check_bool(hold_start, "hold_start")
    check_type(object_pose, ObjectPose, "object_pose", optional=True)
    if start is not None and not isinstance(start, (Start, Motion)):
        raise ValueError(f"start: expected a Start, a one-frame Motion or None, got {type(start).__name__}")
    if isinstance(start, Motion) and start.num_frames < 1:
        raise ValueError("start: expected a Motion with at least one frame (its first is the start body), got none")
    if bm is not None and getattr(bm, "dtype", None) != torch.float32:
        raise ValueError(f"bm: expected a float32 BodyModel (the networks and optimisers run in float32), got "
                         f"{getattr(bm, 'dtype', type(bm).__name__)}")


def _configs(grasp_steps: tuple[int, int, int], motion_steps: tuple[int, int], free_joints: tuple[str, ...] | None,
             polish_steps: tuple[int, int] | None) -> tuple[GraspPoseConfig, GraspMotionConfig]:
    """GraspPose-Opt's and GraspMotion-Opt's configs from synthesize's step counts and freed joints (checked)."""
    from graspkit.optim.graspmotion import GraspMotionConfig
    from graspkit.optim.grasppose import GraspPoseConfig

    gcfg = GraspPoseConfig(steps=check_steps(grasp_steps, "grasp_steps", 3))
    mcfg = GraspMotionConfig(steps=check_steps(motion_steps, "motion_steps", 2))
    if polish_steps is not None:
        polish_steps = check_steps(polish_steps, "polish_steps", 2)
        gcfg = replace(gcfg, polish=(int(polish_steps[0]), gcfg.polish[1]))
        mcfg = replace(mcfg, polish=(int(polish_steps[1]), mcfg.polish[1]))
    if free_joints is not None:
        gcfg, mcfg = replace(gcfg, free_joints=tuple(free_joints)), replace(mcfg, free_joints=tuple(free_joints))
    return gcfg, mcfg


def _object_points(obj_mesh: Any, R_o: np.ndarray) -> tuple[torch.Tensor, torch.Tensor]:
    """The object's 2048 surface points and normals (2048,3) in the object frame: centred at the mesh origin, turned
    by its world rotation R_o (3,3)."""
    from graspkit.objects.sampling import sample_surface

    pts, nrm = sample_surface(obj_mesh, 2048, seed=0)      # as graspkit.data.grasp.object_points for the catalogue
    R_t = torch.as_tensor(R_o).float()
    return torch.as_tensor(pts).float() @ R_t.T, torch.as_tensor(nrm).float() @ R_t.T


def _grasp_stage(s: Any, obj: GraspObject, centre: np.ndarray, bm: BodyModel, prior: Any, gcfg: GraspPoseConfig,
                 progress: bool) -> tuple[Any, Motion]:
    """Stage 1 (§3.2, Alg. 1): GraspPose-Opt fits the WholeGrasp-VAE sample `s` in the object frame; the fit moved
    into the world (the object's centre (3,) there) and the grasp body as a one-frame Motion (world)."""
    from graspkit.optim.grasppose import GraspPoseOpt

    res = GraspPoseOpt(bm, prior, gcfg).fit(s.markers, obj, s.marker_contact, s.object_contact,
                                            progress=progress).to_world(torch.as_tensor(centre).float())
    pr = res.params
    gpose = torch.cat([pr["global_orient"][:, None], pr["body_pose"].view(1, 21, 3), pr["jaw_pose"][:, None],
                       pr["leye_pose"][:, None], pr["reye_pose"][:, None], pr["left_hand_pose"].view(1, 15, 3),
                       pr["right_hand_pose"].view(1, 15, 3)], 1)[0].detach().double().numpy()
    gtransl, betas = pr["transl"][0].detach().double().numpy(), pr["betas"][0].detach().double().numpy()
    return res, Motion(gpose[None], gtransl[None], betas, 30.0)


def _start_body(start: Start | Motion | None, grasp_body: Motion, centre: np.ndarray, start_distance: float,
                bm: BodyModel, seed: int) -> Motion:
    """The start body (one frame, world) in the grasp body's shape, from synthesize's `start` (module doc; a given
    body is reshaped where it stands, `reshaped_in_place`); a warning when a given start stands farther than
    WALK_START_DISTANCE from the grasp's pelvis."""
    pelvis = grasp_body.joint_positions(bm)[0, 0]
    betas = grasp_body.betas
    if start is None or isinstance(start, Start):
        # GraspPose-Opt fits betas without a bound (the mug's ends at -2.8 in one coefficient), so the planner's
        # note on betas past ±2 would blame the caller for them
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ShapeWarning)
            if isinstance(start, Start):
                from graspkit.data.reaching import plan_reach

                st = plan_reach(start, centre, 60, betas=betas, seed=seed, bm=bm).slice(0, 1)
            else:
                st = default_start(pelvis, centre, betas, start_distance, bm, seed)
    else:                                                  # a Motion (checked by _check_args)
        st = reshaped_in_place(start.slice(0, 1), betas, bm)
    st = Motion(st.poses, st.trans, betas, 30.0)         # the grasp's shape: beta is fixed in GraspMotion-Opt
    if start is not None:                                  # start_distance was checked by _check_args
        away = float(np.linalg.norm(st.joint_positions(bm)[0, 0, :2] - pelvis[:2]))
        if away > WALK_START_DISTANCE:
            warnings.warn(f"start: its pelvis is {away:.2f} m from the grasp's; {_RUN_NOTE}", GraspkitWarning,
                          stacklevel=user_stacklevel())
    return st


def reshaped_in_place(body: Motion, betas: np.ndarray, bm: BodyModel) -> Motion:
    """A one-frame body in another shape `betas`, standing where it stood: the same pose, its pelvis joint at the
    same x, y and its lowest vertex at the same height (a body on the floor stays on it; `graspkit.data.motion.restand`).
    Keeping the translation instead would float or sink it by the change in leg length (-7 to +14 cm on GOAL's twelve
    test starts)."""
    from graspkit.data.motion import restand

    return restand(body.slice(0, 1), bm, bm, betas)


def _motion_stage(ck: Path, bm: BodyModel, prior: Any, obj: GraspObject, R_o: np.ndarray, centre: np.ndarray,
                  grasp_body: Motion, st: Motion, s: Any, mcfg: GraspMotionConfig, g: torch.Generator, hold_start: bool,
                  progress: bool) -> tuple[Motion, torch.Tensor, torch.Tensor, np.ndarray]:
    """Stage 2 (§3.3-3.4): the window from the start (frame 0) to the grasp (frame T), of which only those two frames
    are known, infilled by a MotionFill-VAE sample and fitted by GraspMotion-Opt (Alg. 2) in the window's canonical
    frame; the motion (T+1 frames, world), the sampled markers (T+1,79,3) in the world, their foot contacts (T+1,4)
    and the fitted markers (T+1,79,3) in the world. `s` is stage 1's WholeGrasp sample (its contact maps)."""
    from graspkit.body.markers import saga_sparse_markers
    from graspkit.data.motion import canonicalize
    from graspkit.data.motionfill_dataset import make_windows
    from graspkit.eval_motionfill import interp, load_motionfill
    from graspkit.optim.graspmotion import GraspMotionOpt, load_smooth_ae
    from graspkit.optim.grasppose import GraspObject

    T, betas = 60, grasp_body.betas
    gpose, gtransl = grasp_body.poses[0], grasp_body.trans[0]
    clip = Motion(np.concatenate([st.poses[:1], np.repeat(gpose[None], T, 0)]),
                  np.concatenate([st.trans[:1], np.repeat(gtransl[None], T, 0)]), betas, 30.0)
    win = make_windows([clip], bm, align_end=True, progress=False, start_at_rest=True)   # frame 0 stands; 0 -> 1 is a jump
    j = clip.joint_positions(bm)
    R_c, o_c = canonicalize(np.concatenate([j, j[-1:]]))
    mf = load_motionfill(ck / "motionfill.pt")
    smp = mf.sample(torch.as_tensor(interp(win["traj"][0])).float(), torch.as_tensor(win["local"][0]),
                    torch.as_tensor(win["contacts"][0]).float(), 1, g)
    to_c = lambda x: (np.asarray(x, np.float64) - o_c) @ R_c.T  # noqa: E731
    cobj = GraspObject(torch.as_tensor(to_c(obj.points.double().numpy() + centre)).float()[None],
                       torch.as_tensor(obj.normals.double().numpy() @ R_c.T).float()[None], 0.0, obj.sdf,
                       torch.as_tensor(R_c @ R_o).float(), torch.as_tensor(to_c(centre)).float())
    mopt = GraspMotionOpt(bm, prior, load_smooth_ae(ck / "motionfill_smooth_ae.pt"), mcfg)
    start_markers = None                             # frame 0's target: the start body's markers in the sample's frame
    if hold_start:
        start_markers = torch.as_tensor(to_c(saga_sparse_markers(bm).select(st.vertices(bm))[0].double().numpy()))
    mres = mopt.fit(smp["markers"], torch.as_tensor(betas[None, :10]).float(), smp["contacts"], cobj,
                    s.object_contact.float(), progress=progress, floor=torch.tensor([to_c(np.zeros(3))[2]]).float(),
                    marker_contact=s.marker_contact.float(),
                    start=None if start_markers is None else start_markers.float()[None])
    poses_w, transl_w = rigid_params(mres.params["poses"][0].view(-1, 55, 3).double().numpy(),
                                     mres.params["transl"][0].double().numpy(), betas, R_c.T, o_c, bm)
    markers_w = torch.as_tensor(smp["markers"][0].double().numpy() @ R_c + o_c).float()
    fitted = mres.markers[0].double().numpy() @ R_c + o_c
    return Motion(poses_w, transl_w, betas, 30.0), markers_w, smp["contacts"][0], fitted


def _figures(res: Any, motion: Motion, markers_w: torch.Tensor, fitted: np.ndarray, mesh: Any,
             bm: BodyModel) -> dict[str, float]:
    """The grasp body and the motion's last frame against the object (world), the grasp body's lowest vertex, SAGA's
    skating of the sampled and the fitted markers, and the motion's floor figures."""
    from graspkit.eval_motionfill import heel_columns, skating
    from graspkit.metrics import floor_figures, grasp_and_end_figures

    last = motion.vertices(bm, motion.num_frames - 1, motion.num_frames)[0]
    heels = heel_columns()
    return {**grasp_and_end_figures(res.vertices[0], last, bm.faces, mesh),
            "grasp_floor_cm": 100 * float(res.vertices[0, :, 2].min()),      # the grasp body's lowest vertex
            "skating_sample": skating(markers_w.double().numpy()[None], np.zeros(1), heels),
            "skating_opt": skating(fitted[None], np.zeros(1), heels), **floor_figures(motion.vertices(bm))}
