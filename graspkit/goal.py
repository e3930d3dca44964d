"""GOAL end to end (`../shared/papers/GOAL.txt` §3, Fig. 3): an object in, a grasp and the approach motion into it out.

    object -> GNet sample (§3.3) -> refinement towards its offsets (Eq. 4-8) -> the goal grasp
    start body + goal grasp -> MNet, 10 frames a step, re-canonicalised, refined near the goal (§3.4, Eq. 9-13),
    each frame raised onto the floor z = 0 where its soles sink below it (graspkit's floor step, not GOAL's),
    the refinement started early for a hand that stalls within 25 cm of the goal hand (graspkit's stall rule)

`synthesize("mug")` runs it for any catalogue object with the shipped `gnet.pt` and `mnet.pt`, and
`synthesize(mesh)` for an object of one's own (a trimesh.Trimesh or a mesh file: closed, metres, z up;
`graspkit.objects.user.as_object`). The object is placed by `within_reach_pose(seed)` unless a pose is given; the
start is a standing body (the procedural planner's first frame) `start_distance` m from the object centre on the
ground, facing it (GOAL's protocol: 0.5-1.5 m, facing it within ±10°), unless a `Start` is given. World frame, z up.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

from graspkit.checks import check_bool, check_int, check_positive, check_type
from graspkit.data.motion import Motion
from graspkit.data.reaching import Start
from graspkit.models.mnet import STALL_FRAMES, check_stall
from graspkit.objects.placement import ObjectPose
from graspkit.paths import require_checkpoints
from graspkit.saga import CHECKPOINTS


# Rest heights, relative to graspkit's procedural body (the one body GNet and MNet were trained on), at which
# `synthesize` was measured to walk to a box's grasp from 1 m within 300 frames (docs/goal.md, "Other bodies"):
# 0.8 times arrives at frame 154 (past the default max_frames, 150), 1.5 times at 118, 0.7 times not at all.
MEASURED_HEIGHTS = (0.8, 1.5)
PROCEDURAL_HEIGHT = 1.6996      # m: the rest height of graspkit's procedural body (zero betas; a test measures it)


@dataclass
class GoalResult:
    """The goal grasp and the approach motion (world, absolute hand poses), the object mesh there and the figures."""

    name: str
    object_pose: ObjectPose
    mesh: Any                        # trimesh.Trimesh in the world
    grasp: Motion                    # the refined GNet grasp (1 frame)
    motion: Motion                   # MNet's rollout from the start to the grasp (up to max_frames)
    reached: bool                    # the rollout met the goal grasp's hand before max_frames
    metrics: dict[str, float]        # grasp figures of the goal grasp and of the motion's last frame, sliding, floor


def default_start(centre: np.ndarray, distance: float, yaw_offset: float = 0.0) -> Start:
    """A standing start `distance` m from the object centre on the ground, on the -y side turned by `yaw_offset`
    (rad) about the centre, facing the centre."""
    a = -np.pi / 2 + yaw_offset
    x, y = float(centre[0] + distance * np.cos(a)), float(centre[1] + distance * np.sin(a))
    return Start(x, y, float(np.arctan2(centre[1] - y, centre[0] - x)))


def height_ratio(bm: Any, betas: torch.Tensor) -> float:
    """Rest height of body model `bm` shaped by `betas` (k,) (the vertical, y, extent of its shaped rest vertices) over
    PROCEDURAL_HEIGHT, that of graspkit's procedural body (a constant: a plain `pip install` may not have built it)."""
    from graspkit.data.wandr_dataset import shaped_rest

    v = shaped_rest(bm, betas[None])[0][0]
    return float(v[:, 1].max() - v[:, 1].min()) / PROCEDURAL_HEIGHT


def warn_height(bm: Any, betas: torch.Tensor) -> None:
    """A warning when the body is outside MEASURED_HEIGHTS times the training body's height."""
    import warnings

    from graspkit.checks import GraspkitWarning, user_stacklevel

    r, (lo, hi) = height_ratio(bm, betas), MEASURED_HEIGHTS
    if not lo <= r <= hi:
        warnings.warn(f"model: a body {r:.2f} times the height of graspkit's procedural body, the one GNet and MNet "
                      f"were trained on; synthesize was measured to arrive within 300 frames (max_frames) for "
                      f"{lo}-{hi} times, bodies under 0.88 times after more than the default 150, and a body 0.7 "
                      "times as tall not at all (docs/goal.md, 'Other bodies')", GraspkitWarning,
                      stacklevel=user_stacklevel())


def check_checkpoints(checkpoints: str | Path | None = None) -> Path:
    """The folder `checkpoints` once GNet's and MNet's files are in it (else FileNotFoundError naming the first
    missing; None: the shipped ones)."""
    return require_checkpoints(checkpoints if checkpoints is not None else CHECKPOINTS, ("gnet.pt", "mnet.pt"),
                               "docs/goal.md")


def synthesize(name: str | Path | Any, object_pose: ObjectPose | None = None, start: Start | None = None,
               seed: int = 0, start_distance: float = 1.0, max_frames: int = 150,
               checkpoints: str | Path = CHECKPOINTS, penetration: bool = True,
               model: str | Path | None = None, stall: int | None = STALL_FRAMES, progress: bool = True) -> GoalResult:
    """GOAL for object `name` (a catalogue name, a mesh file or a trimesh.Trimesh, closed and in metres): one
    refined GNet grasp and MNet's approach into it from a standing start, seeded (the same seed and torch thread
    count give the same numbers; another thread count can move the result, the command uses 1). `penetration`: the
    refinement adds graspkit's E_pen on the object's collision grid (False: GOAL's Eq. 4-8 alone; docs/goal.md);
    `model`: an SMPL-X .npz for the body (default: graspkit's procedural one, which the networks were trained on; a
    warning when its height is outside MEASURED_HEIGHTS times that one's);
    `stall`: MNet's stall window in frames (`mnet.rollout`; None: GOAL's rollout, which may stop with the hand
    10-25 cm short); `progress`: a bar over the stages (half a minute in all on two cores)."""
    from tqdm.auto import tqdm

    from graspkit.data.grasp_io import object_collision_grid
    from graspkit.data.reaching import plan_reach
    from graspkit.eval_goal import _body, gnet_goal, sliding
    from graspkit.metrics import floor_figures, grasp_and_end_figures
    from graspkit.models.gnet import load_gnet
    from graspkit.models.mnet import load_mnet, rollout
    from graspkit.objects.bps import bps_basis
    from graspkit.objects.placement import apply_pose, warn_floor, within_reach_pose
    from graspkit.objects.sampling import sample_surface
    from graspkit.objects.user import as_object
    from graspkit.progress import hidden
    from graspkit.rotations import axis_angle_to_rot6d, matrix_to_axis_angle, rot6d_to_matrix

    check_int(seed, "seed")
    check_positive(start_distance, "start_distance", most=5.0)
    check_int(max_frames, "max_frames", least=2)
    check_bool(penetration, "penetration")
    check_stall(stall)
    check_type(object_pose, ObjectPose, "object_pose", optional=True)
    given = name                     # as the caller gave it: a catalogue name keeps its cached grid
    name, obj_mesh = as_object(name, "name")
    if start is not None and not isinstance(start, Start):
        raise ValueError(f"start: expected a graspkit.data.reaching.Start or None, got {type(start).__name__}")
    check_bool(progress, "progress")
    ck = check_checkpoints(checkpoints)
    with tqdm(total=3, desc="GOAL", unit="stage", disable=hidden(progress)) as bar:
        bar.set_postfix_str("body, start, collision grid")
        pose = object_pose if object_pose is not None else within_reach_pose(seed)
        warn_floor(pose, obj_mesh)
        centre = np.asarray(pose.translation, np.float64)
        mesh = apply_pose(pose, obj_mesh)
        pts = torch.as_tensor(apply_pose(pose, sample_surface(obj_mesh, 2048, seed=0)[0])).float()
        c = torch.as_tensor(centre).float()

        bm, _, body = _body(model)                   # flat hand mean: poses are absolute, as in the data files
        st = start if start is not None else default_start(centre, start_distance)
        first = plan_reach(st, centre, 60, seed=seed, bm=bm).slice(0, 1)
        betas = torch.as_tensor(first.betas[:10]).float()
        warn_height(bm, betas)
        s = (axis_angle_to_rot6d(torch.as_tensor(first.poses[0], dtype=torch.float64)).float(),
             torch.as_tensor(first.trans[0]).float())
        g = torch.Generator().manual_seed(seed)
        grid = object_collision_grid(given, obj_mesh, progress) if penetration else None
        sdf = (grid, pose.rotation, pose.translation) if penetration else None
        bar.set_postfix_str("GNet grasp, refined (Eq. 4-8)")
        goal = gnet_goal(load_gnet(ck / "gnet.pt"), s, betas, pts, c, generator=g, sdf=sdf, model=model)[:2]
        bar.update()
        bar.set_postfix_str("MNet approach (Eq. 9-13)")
        r = rollout(load_mnet(ck / "mnet.pt"), body, s, goal, betas, pts, c, bps_basis(), max_frames=max_frames,
                    floor=0.0, stall=stall)      # graspkit's floor step and stall rule (not GOAL's): docs/goal.md
        bar.update()
        bar.set_postfix_str("figures")

        to_motion = lambda r6, t: Motion(matrix_to_axis_angle(rot6d_to_matrix(r6.double())).numpy(),  # noqa: E731
                                         t.detach().double().numpy(), betas.double().numpy(), 30.0)
        grasp, motion = to_motion(goal[0][None], goal[1][None]), to_motion(r.rot6d, r.transl)
        gv, lv = grasp.vertices(bm)[0], motion.vertices(bm)
        slid, pairs = sliding(lv)
        metrics = {**grasp_and_end_figures(gv, lv[-1], bm.faces, mesh), "frames": float(motion.num_frames),
                   "sliding": slid / max(pairs, 1), **floor_figures(lv)}
        bar.update()
    return GoalResult(name, pose, mesh, grasp, motion, bool(r.reached), metrics)
