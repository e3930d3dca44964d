"""Metrics of the three papers, with their thresholds as named constants (one module for all methods).

Motion metrics (this section) take world vertices / joints in the z-up frame, metres, at `fps`:

| metric | paper | definition |
|---|---|---|
| foot skating (FS) | WANDR Sec. 4.3 | a frame skates if the mesh's lowest vertex moves more than 0.66 cm (at 30 fps) to the next frame; graspkit measures the horizontal move (see below) |
| foot skating | SAGA Sec. 4.2 (following MOJO, its ref. [65]) | both heels are within 5 cm of the ground and both move faster than 75 mm/s (no foot planted) |
| foot sliding | GOAL Sec. 4.2 | the vertex closest to the ground moves more than 1 cm per frame, read at 30 fps (GOAL gives no rate) (GRAB's captured motion: 6.7 %) |
| success rate (SR), distance to goal (DTG) | WANDR Sec. 4.3 | the right wrist comes within 10 cm of the goal; DTG its closest distance |
| ground penetration | SAGA Sec. 4.2 (non-collision), GOAL Sec. 3.3 (Eq. 7's lowest vertex) | depth of the lowest vertex below the ground plane z = 0 |
| non-collision score | SAGA Sec. 4.2 | share of body mesh vertices above the ground (GRAB 0.9771, SAGA 0.9743), per frame |
| joint speed, jerk | smoothness | finite differences of joint positions (body joints 0..21) |
| joint limits | human range of motion | rotation of each joint beyond the ranges in `JOINT_LIMITS_DEG`, `HINGES` and `FINGER_LIMIT_DEG` |

Two readings are graspkit's, where the papers leave room:
- "The lowest vertex moves" is measured on the same vertex from frame t to t+1 (the vertex that is lowest at t). Taking
  the lowest vertex of each frame instead (a different vertex as the foot rolls) reads 9-31 % skating on clean
  locomotion clips, so it would not measure sliding.
- WANDR says only "moves more than 0.66cm"; graspkit counts the horizontal move, as the authors' evaluation code does
  (docs/wandr.md: a foot lifting or setting down is not skating); GOAL's sliding counts the 3D move.
Both per-frame thresholds are taken at 30 fps (WANDR's evaluation rate; GOAL states none, and 30 fps is graspkit's
reading of its "per frame"); for a clip at another `fps` they scale by
30 / fps, the same speed (0.198 m/s for WANDR, 0.30 m/s for GOAL), so a clip reads the same resampled or not.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
import torch
from scipy.spatial.distance import pdist
from tqdm.auto import tqdm

from graspkit.body.skeleton import JOINT_INDEX, JOINT_NAMES, NUM_JOINTS
from graspkit.progress import hidden
from graspkit.rotations import axis_angle_to_matrix

if TYPE_CHECKING:
    from graspkit.body import BodyModel
    from graspkit.data.motion import Motion

# ----------------------------------------------------------------------------- motion: thresholds
WANDR_SKATE_THRESHOLD = 0.0066       # m per frame at 30 fps (WANDR Sec. 4.3, CIRCLE's 1 cm adjusted to 30 fps)
METRIC_FPS = 30.0                    # the frame rate the papers' per-frame thresholds are given at
SAGA_SKATE_HEEL_HEIGHT = 0.05        # m (SAGA Sec. 4.2, following MOJO)
SAGA_SKATE_HEEL_SPEED = 0.075        # m/s, both heels (SAGA Sec. 4.2)
GOAL_SLIDE_THRESHOLD = 0.01          # m per frame (GOAL Sec. 4.2), read at 30 fps: GOAL states no frame rate
GOAL_GRAB_SLIDING = 0.067            # fraction of GRAB's captured frames that "slide" (GOAL Sec. 4.2)
WANDR_SUCCESS_RADIUS = 0.10          # m, right wrist to goal (WANDR Sec. 4.3, as CIRCLE)
BODY_JOINTS = slice(0, 22)           # pelvis .. right wrist: speed and jerk are reported on these
TURN_JOINTS = slice(0, 25)           # body, jaw and eyes: how fast they turn (a head turning about its own joint
                                     # barely moves a joint position, so speed and jerk do not see it)

# Human range of motion, degrees (adult norms, e.g. Soucie et al. 2011; AAOS). Hinge joints: signed flexion
# about the hinge axis (canonical frame) and the largest rotation off that axis; other joints: the
# largest total rotation from the rest pose (the T-pose for shoulders: arms down is ~75 deg there); every finger
# joint (SMPL-X joints 25-54): FINGER_LIMIT_DEG of total rotation.
FINGER_LIMIT_DEG = 100.0
HINGES = {  # joint: (axis, flexion min, flexion max, off-axis max)
    "left_knee": ((1, 0, 0), -10, 155, 35), "right_knee": ((1, 0, 0), -10, 155, 35),
    "left_elbow": ((0, -1, 0), -10, 155, 95), "right_elbow": ((0, 1, 0), -10, 155, 95),
}
JOINT_LIMITS_DEG: dict[str, float] = {
    "pelvis": 360.0, "left_hip": 135.0, "right_hip": 135.0, "spine1": 45.0, "spine2": 45.0, "spine3": 45.0,
    "left_ankle": 60.0, "right_ankle": 60.0, "left_foot": 80.0, "right_foot": 80.0, "neck": 60.0, "head": 60.0,
    "left_collar": 45.0, "right_collar": 45.0, "left_shoulder": 180.0, "right_shoulder": 180.0,
    "left_wrist": 90.0, "right_wrist": 90.0, "jaw": 30.0, "left_eye_smplhf": 30.0, "right_eye_smplhf": 30.0,
}


def _t(x: Any, name: str = "input") -> torch.Tensor:
    """A float tensor of an array, list or tensor (detached: metrics are measurements; integers become float64); a
    ValueError naming the argument `name` for anything that is not numbers."""
    try:
        t = x.detach() if isinstance(x, torch.Tensor) else torch.as_tensor(np.ascontiguousarray(x))   # any strides
        return t if t.is_floating_point() else t.to(torch.float64)
    except (TypeError, ValueError, RuntimeError) as e:
        raise ValueError(f"{name}: expected an array of numbers, got {type(x).__name__} ({e})") from None


def _shaped(x: Any, name: str, shape: str, min_frames: int = 1) -> torch.Tensor:
    """`x` as a float tensor after checking it against `shape` (comma-separated: a digit is a fixed size, a letter
    any non-zero size, e.g. 'T,V,3') and that it is finite; a ValueError names the argument otherwise. `min_frames`
    is the least T."""
    t = _t(x, name)
    dims = shape.split(",")
    ok = t.dim() == len(dims) and all(t.shape[i] == int(d) if d.isdigit() else t.shape[i] > 0
                                      for i, d in enumerate(dims))
    if not ok or (dims[0] == "T" and t.shape[0] < min_frames):
        need = f" with T >= {min_frames}" if min_frames > 1 else ""
        raise ValueError(f"{name}: expected shape ({shape}){need}, no size zero, got {tuple(t.shape)}")
    if not torch.isfinite(t).all():
        raise ValueError(f"{name}: contains NaN or Inf")
    return t


def _number(x: Any, name: str, positive: bool = True) -> float:
    """x as a float after checking it is a finite number, > 0 if `positive` (a frame rate, a threshold); a 0-d tensor
    or array gives its number."""
    if isinstance(x, (torch.Tensor, np.ndarray)) and tuple(x.shape) == ():
        x = x.item()
    if isinstance(x, (bool, np.bool_)) or not isinstance(x, (int, float, np.integer, np.floating)) \
            or not (np.isfinite(x) and (x > 0 or not positive)):
        raise ValueError(f"{name}: expected {'a positive number' if positive else 'a finite distance in metres'}, "
                         f"got {x!r}")
    return float(x)


def lowest_vertex_motion(vertices: Any) -> tuple[np.ndarray, np.ndarray]:
    """Horizontal and 3D displacement (T-1,) from frame t to t+1 of the vertex lowest at frame t; vertices (T,V,3).

    Of several vertices equally low at frame t (an exact tie, e.g. soles clamped to z = 0) the first in vertex order
    is followed (argmin's rule; the papers name no rule for ties)."""
    v = _shaped(vertices, "vertices", "T,V,3", min_frames=2)
    idx = v[:-1, :, 2].argmin(1)
    ar = torch.arange(len(idx))
    d = v[1:][ar, idx] - v[:-1][ar, idx]
    return d[:, :2].norm(dim=-1).double().numpy(), d.norm(dim=-1).double().numpy()


def per_frame_threshold(threshold: float, fps: float) -> float:
    """A per-frame distance threshold given at 30 fps (METRIC_FPS) as the same speed at `fps`: threshold * 30 / fps."""
    return _number(threshold, "threshold") * METRIC_FPS / _number(fps, "fps")


def foot_skating_wandr(vertices: Any, threshold: float = WANDR_SKATE_THRESHOLD, fps: float = METRIC_FPS) -> np.ndarray:
    """WANDR's FS per frame (T-1,) bool: the lowest vertex moves more than `threshold` m (per frame at 30 fps, scaled
    to `fps`) horizontally to the next frame; vertices (T,V,3)."""
    return lowest_vertex_motion(vertices)[0] > per_frame_threshold(threshold, fps)


def foot_sliding_goal(vertices: Any, threshold: float = GOAL_SLIDE_THRESHOLD, fps: float = METRIC_FPS) -> np.ndarray:
    """GOAL's foot sliding per frame (T-1,) bool: the vertex closest to the ground moves more than `threshold` m (per
    frame at 30 fps, scaled to `fps`); vertices (T,V,3).

    graspkit takes the lowest vertex (argmin z, as GOAL's Eq. 7 finds it): the closest to the ground whenever the body
    is on or above the floor; for a body sunk below it, the deepest vertex rather than one crossing z = 0."""
    return lowest_vertex_motion(vertices)[1] > per_frame_threshold(threshold, fps)


def foot_skating_saga(heels: Any, fps: float = 30.0, height: float = SAGA_SKATE_HEEL_HEIGHT,
                      speed: float = SAGA_SKATE_HEEL_SPEED) -> np.ndarray:
    """SAGA's skating per frame (T-1,) bool from heel positions (T,2,3) [left, right]: both heels within `height`
    of the ground at frame t and both faster than `speed` m/s from frame t to t+1: no foot is planted."""
    height, speed = _number(height, "height"), _number(speed, "speed")
    h = _shaped(heels, "heels", "T,2,3", min_frames=2).double()
    v = (h[1:] - h[:-1]).norm(dim=-1) * _number(fps, "fps")                     # (T-1, 2)
    return ((h[:-1, :, 2] < height) & (v > speed)).all(1).numpy()


def grasp_and_end_figures(grasp_vertices: Any, end_vertices: Any, faces: Any, obj: Any) -> dict[str, float]:
    """`grasp_metrics` of a generated grasp body (V,3) and of its motion's last frame (V,3) against one object mesh,
    keyed grasp_* and end_* (contact, volume_cm3, depth_cm), as the one-call pipelines report them."""
    out = {}
    for prefix, v in (("grasp", grasp_vertices), ("end", end_vertices)):
        m = grasp_metrics(v, faces, obj)
        out.update({f"{prefix}_{k}": m[k] for k in ("contact", "volume_cm3", "depth_cm")})
    return out


def ground_penetration(vertices: Any) -> np.ndarray:
    """Depth (T,) of the lowest vertex below the ground z = 0 (0 when above)."""
    return (torch.clamp(-_shaped(vertices, "vertices", "T,V,3")[:, :, 2].min(1).values, min=0) + 0.0).double().numpy()


def floor_figures(vertices: Any) -> dict[str, float]:
    """A motion's body against the floor z = 0, vertices (T,V,3): the deepest any vertex goes below it over the clip
    and the lowest vertex's height at the last frame, in cm, and the share of frames in the air (`floating_share`;
    the one-call pipelines report them)."""
    v = _shaped(vertices, "vertices", "T,V,3")
    return {"floor_deepest_cm": 100 * float(ground_penetration(v).max()),
            "end_floor_cm": 100 * float(v[-1, :, 2].min()), "floating_share": floating_share(v)}


def floating_share(vertices: Any, floor: float = 0.0, height: float = 0.01) -> float:
    """The share of frames whose lowest vertex stands more than `height` m above the floor z = `floor`, vertices
    (T,V,3): a body in the air (graspkit's; walking and reaching keep a foot down on every frame, and 1 cm is above
    the soles' rest unevenness)."""
    v = _shaped(vertices, "vertices", "T,V,3")
    lowest = v[..., 2].amin(-1) - _number(floor, "floor", positive=False)
    return float((lowest > _number(height, "height")).double().mean())


def non_collision_score(vertices: Any, floor: float = 0.0) -> np.ndarray:
    """SAGA's non-collision score per frame (T,): the share of the mesh vertices (T,V,3) at or above the ground
    z = floor (SAGA Sec. 4.2: "the number of body mesh vertices above the ground divided by the total")."""
    floor = _number(floor, "floor", positive=False)
    return (_shaped(vertices, "vertices", "T,V,3")[..., 2] >= floor).double().mean(-1).numpy()


def joint_speed(joints: Any, fps: float = 30.0) -> np.ndarray:
    """Speeds (T-1,J) of joints (T,J,3) in m/s."""
    j = _shaped(joints, "joints", "T,J,3", min_frames=2).double()
    return ((j[1:] - j[:-1]).norm(dim=-1) * _number(fps, "fps")).numpy()


def joint_jerk(joints: Any, fps: float = 30.0) -> np.ndarray:
    """Jerk magnitudes (T-3,J) in m/s^3: third finite differences of joints (T,J,3)."""
    j = _shaped(joints, "joints", "T,J,3", min_frames=4).double()
    d3 = j[3:] - 3 * j[2:-1] + 3 * j[1:-2] - j[:-3]
    return (d3.norm(dim=-1) * _number(fps, "fps") ** 3).numpy()


def joint_turn_speed(poses: Any, fps: float = 30.0) -> np.ndarray:
    """How fast each joint's local rotation turns (T-1,J), deg/s: the angle of R_t^T R_t+1 for axis-angle poses
    (T,J,3), times fps."""
    R = axis_angle_to_matrix(_shaped(poses, "poses", "T,J,3", min_frames=2).double())
    rel = R[:-1].transpose(-1, -2) @ R[1:]
    cos = ((rel.diagonal(dim1=-2, dim2=-1).sum(-1) - 1) / 2).clamp(-1.0, 1.0)
    return (torch.rad2deg(torch.arccos(cos)) * _number(fps, "fps")).numpy()


def joint_limit_violation(poses: Any) -> np.ndarray:
    """Degrees beyond the human range (T,55) of local rotations poses (T,55,3) axis-angle; 0 inside the range."""
    with torch.no_grad():
        return joint_limit_excess(_shaped(poses, "poses", f"T,{NUM_JOINTS},3").double()).numpy()


def shortest_axis_angle(p: torch.Tensor) -> torch.Tensor:
    """Axis-angle vectors (...,3) with every angle above 180 deg rewritten as the same rotation the short way round
    (angle 2*pi*k - theta about the opposite axis, at most 180 deg); vectors within 180 deg keep their values and
    their gradients bit for bit."""
    th = p.norm(dim=-1, keepdim=True)
    k = torch.round(th / (2 * math.pi))
    return torch.where(th > math.pi, p * (1 - 2 * math.pi * k / th.clamp_min(1e-12)), p)


def joint_limit_excess(poses: torch.Tensor) -> torch.Tensor:
    """joint_limit_violation as a differentiable tensor (T,55) in the dtype of poses (T,55,3) (an energy term). An
    angle above 180 deg is read as the same rotation the short way round (shortest_axis_angle): a knee flexed 160 deg
    written as -200 deg is 160 deg of flexion."""
    p = shortest_axis_angle(poses.reshape(-1, NUM_JOINTS, 3))
    ang = torch.rad2deg(p.norm(dim=-1))
    out = torch.zeros_like(ang)
    for name, lim in JOINT_LIMITS_DEG.items():
        j = JOINT_INDEX[name]
        out[:, j] = torch.clamp(ang[:, j] - lim, min=0)
    for name, (axis, lo, hi, off) in HINGES.items():
        j = JOINT_INDEX[name]
        a = torch.tensor(axis, dtype=p.dtype, device=p.device)
        flex = torch.rad2deg(p[:, j] @ a)
        rest = torch.rad2deg((p[:, j] - (p[:, j] @ a)[:, None] * a).norm(dim=-1))
        out[:, j] = torch.clamp(lo - flex, min=0) + torch.clamp(flex - hi, min=0) + torch.clamp(rest - off, min=0)
    finger = torch.clamp(ang[:, 25:] - FINGER_LIMIT_DEG, min=0)
    out[:, 25:] = finger
    return out


def distance_to_goal(wrist: Any, goal: Any) -> float:
    """WANDR's DTG: closest distance (m) of the wrist track (T,3) to the goal (3,) or (1,3)."""
    g = _t(goal, "goal")
    g = g.reshape(3) if g.shape == (1, 3) else g
    w, g = _shaped(wrist, "wrist", "T,3").double(), _shaped(g, "goal", "3").double()
    return float((w - g).norm(dim=-1).min())


def goal_reached(wrist: Any, goal: Any, radius: float = WANDR_SUCCESS_RADIUS) -> bool:
    """WANDR's success: the wrist comes within `radius` m of the goal."""
    return distance_to_goal(wrist, goal) <= _number(radius, "radius")


def heel_vertex_ids() -> tuple[int, int]:
    """SMPL-X heel landmark vertex ids (left, right), as used for SAGA's skating metric."""
    from graspkit.body.skeleton import SMPLX_LANDMARK_VERTEX_IDS as L
    return L["LHeel"], L["RHeel"]


def motion_quality(bm: BodyModel, motions: Sequence[Motion], chunk: int = 96, progress: bool = False) -> dict[str, Any]:
    """All motion metrics over Motion clips, measured on their meshes (chunks of `chunk` frames, nothing stored;
    `progress`: a bar over the clips, for long lists: 64 clips of 300 frames take about a minute on two cores).

    Returns WANDR's FS (fs_wandr: per motion the share of its frame pairs that skate, averaged over the motions, as
    WANDR's grid and graspkit.eval_wandr count it), the shares of all frame pairs that skate (skate_saga) or slide
    (slide_goal: GOAL's share of frames, as graspkit.eval_goal counts it), ground
    penetration (max and mean per-frame depth, m), the largest joint speed (m/s, body joints) and where, the largest
    turning speed of a joint's rotation (deg/s, body, jaw and eyes: a head snapping round) and where, the mean jerk
    (m/s^3, body joints), the largest joint-limit violation (deg) and where, and counts (clips, frames, frame pairs).
    Rates with nothing to count (one-frame clips: no pairs; no clip of four frames: no jerk) are NaN, not 0.
    """
    hl, hr = heel_vertex_ids()
    clips = pairs = sk = sl = frames = 0
    fs_shares = []                                                       # WANDR's FS of each motion with a frame pair
    pen_max = pen_sum = jerk_sum = 0.0
    jerk_n = 0
    speed = turn = limit = (0.0, "")                                     # the largest value so far and where
    for k, m in enumerate(tqdm(motions, desc="motion quality", unit="clip", disable=hidden(progress))):
        clips += 1
        fs = n = 0                                                       # this motion's skating pairs and pairs
        for start, v in m.iter_vertices(bm, chunk=chunk, overlap=1):   # chunks share one frame: every pair once
            if len(v) >= 2:                                              # a one-frame clip has no frame pair
                fs += int(foot_skating_wandr(v, fps=m.fps).sum())
                sl += int(foot_sliding_goal(v, fps=m.fps).sum())
                sk += int(foot_skating_saga(v[:, [hl, hr]], m.fps).sum())
                n += len(v) - 1
            pen = ground_penetration(v if start == 0 else v[1:])
            pen_max, pen_sum, frames = max(pen_max, float(pen.max(initial=0))), pen_sum + float(pen.sum()), frames + len(pen)
        if n:
            fs_shares.append(fs / n)
            pairs += n
        j = m.joint_positions(bm)[:, BODY_JOINTS]
        if len(j) >= 2:
            speed = _largest(speed, joint_speed(j, m.fps), k)
            rot = np.asarray(m.poses).reshape(len(j), -1, 3)[:, TURN_JOINTS]
            turn = _largest(turn, joint_turn_speed(rot, m.fps), k)
        if len(j) >= 4:                                                  # jerk needs four frames; shorter clips add none
            jk = joint_jerk(j, m.fps)
            jerk_sum, jerk_n = jerk_sum + float(jk.sum()), jerk_n + jk.size
        limit = _largest(limit, joint_limit_violation(m.poses), k)
    per_pair = (lambda x: x / pairs) if pairs else (lambda x: float("nan"))   # no frame pairs: no rate, not 0 %
    fs_wandr = float(np.mean(fs_shares)) if fs_shares else float("nan")
    return {"clips": clips, "frames": frames, "pairs": pairs, "fs_wandr": fs_wandr, "skate_saga": per_pair(sk),
            "slide_goal": per_pair(sl), "penetration_max": pen_max, "penetration_mean": pen_sum / max(frames, 1),
            "max_joint_speed": speed[0], "max_joint_speed_at": speed[1], "max_joint_turn": turn[0],
            "max_joint_turn_at": turn[1], "mean_jerk": jerk_sum / jerk_n if jerk_n else float("nan"),
            "joint_limit_max": limit[0], "joint_limit_at": limit[1]}


def _largest(best: tuple[float, str], values: np.ndarray, clip: int) -> tuple[float, str]:
    """The larger of `best` (value, where) and the maximum of values (T, J) of clip `clip`, with where it is."""
    if not values.size or values.max() <= best[0]:
        return best
    t, j = np.unravel_index(np.argmax(values), values.shape)
    return float(values.max()), f"clip {clip} frame {t} {JOINT_NAMES[j]}"


# ----------------------------------------------------------------------------- grasps (SAGA Sec. 4.1 / Tab. 1-2, GOAL Tab. 1)
# | metric | paper | definition here |
# |---|---|---|
# | contact ratio | SAGA Sec. 4.1 ("ratio of body meshes in minimal contact with the object"), GOAL Tab. 1 (after PSI [68]) |
# |   | | fraction of grasps whose body mesh comes within GRASP_CONTACT_THRESHOLD of the object surface (signed distance of
# |   | | the body vertices, so touching counts) or overlaps it (interpenetration volume > 0: an object poking through
# |   | | between body vertices, or wholly inside the body, is in contact too) |
# | interpenetration volume | SAGA Tab. 1-2, GOAL Tab. 1 | cm^3 inside both the body mesh and the object mesh (exact ray casting,
# |   | | graspkit.objects.interpenetration) |
# | interpenetration depth | SAGA Tab. 1-2 | cm, deepest body vertex inside the object |
# | APD | SAGA Sec. 4.1 (after DLow) | average L2 distance between all pairs of K samples (flattened markers), for one object placement |
GRASP_CONTACT_THRESHOLD = 0.002      # m: "minimal contact" (the papers give no number; 2 mm on the exact signed distance)


def grasp_contact_distance(vertices: Any, obj: Any, margin: float = 0.05) -> float:
    """Smallest signed distance (m, < 0 inside) from body vertices (V,3) to an object mesh (Trimesh or (verts, faces)).

    Exact, with a shortcut: the vertices within `margin` of the object's bounding box are measured first; a vertex
    outside that padded box is more than `margin` from the object, so when the nearest measured one is within
    `margin` it is the answer. Otherwise every vertex whose distance to the box (a lower bound) is below the best
    distance found so far is measured too."""
    from graspkit.objects.distance import mesh_arrays, require_closed
    from graspkit.objects.sdf import signed_distance

    v = _t(vertices, "vertices").double()
    if v.dim() != 2 or v.shape[1] != 3 or len(v) == 0:
        raise ValueError(f"vertices: expected (V, 3) positions of one body with V > 0, got shape {tuple(v.shape)}")
    if not torch.isfinite(v).all():
        raise ValueError("vertices: contains NaN or Inf")
    ov, of = mesh_arrays(obj, "obj")
    ov = ov.double()
    require_closed(ov, of, "obj")            # the sign needs a closed, outward-wound surface (checked once here)
    lo, hi = ov.min(0).values, ov.max(0).values
    box = torch.maximum(torch.maximum(lo - v, v - hi), torch.zeros_like(v)).norm(dim=1)   # <= the true distance
    near = box <= margin
    best = float(signed_distance(v[near], (ov, of), check=False).min()) if near.any() else float("inf")
    if best <= margin:
        return best
    if not near.any():                      # seed the bound with the vertex nearest to the box
        best = float(signed_distance(v[box.argmin()][None], (ov, of), check=False).min())
    rest = ~near & (box < best)
    if rest.any():
        best = min(best, float(signed_distance(v[rest], (ov, of), check=False).min()))
    return best


def grasp_metrics(vertices: Any, faces: Any, obj: Any, threshold: float = GRASP_CONTACT_THRESHOLD,
                  refine: int | None = None) -> dict[str, float]:
    """Contact, interpenetration volume (cm^3) and depth (cm) of one body mesh (V,3)+(F,3) and one object mesh, and
    min_distance (m), the body vertices' smallest signed distance to the object. In contact: min_distance <= threshold
    or a volume inside both meshes (the vertices alone miss an object between them). refine: `interpenetration`'s rays
    per cell side along walls (None: its default)."""
    from graspkit.objects.penetration import REFINE, penetration_with_depth

    threshold = _number(threshold, "threshold", positive=False)
    d = grasp_contact_distance(vertices, obj)
    f = _t(faces, "faces")
    if f.is_floating_point() and not bool((f == f.round()).all()):    # .long() would truncate them silently
        raise ValueError("faces: expected integer vertex indices, got fractional values")
    # the depth is -d when a vertex is inside (the deepest is in the object's box, which d's search covers): not
    # searched twice (a quarter of the time on a scan-sized object)
    pen = penetration_with_depth((_t(vertices, "vertices").double(), f.long()), obj, max(0.0, -d),
                                 refine=REFINE if refine is None else refine)
    return {"min_distance": d, "contact": float(d <= threshold or pen.volume_cm3 > 0), "volume_cm3": pen.volume_cm3,
            "depth_cm": pen.depth_cm}


def contact_ratio(min_distances: Any, threshold: float = GRASP_CONTACT_THRESHOLD, volumes_cm3: Any = None) -> float:
    """Fraction of grasps in contact: min body-object signed distances (N,) <= threshold, or (with volumes_cm3 (N,),
    the interpenetration volumes) a volume > 0, the rule of grasp_metrics: an object poking through between body
    vertices is in contact although no vertex is near it. Without volumes only the distances count. Distances are
    compared in their own precision, as marker_contact / object_contact do (float32 0.002 is in contact at 2 mm)."""
    def numbers(x: Any, name: str) -> np.ndarray:
        try:
            a = _t(x).numpy()
        except (TypeError, ValueError) as e:
            raise ValueError(f"{name}: expected numbers, got {type(x).__name__}: {e}") from None
        if a.ndim != 1:
            raise ValueError(f"{name}: expected one number per grasp, shape (N,), got shape {a.shape}")
        if not a.size:
            raise ValueError(f"{name}: expected at least one grasp, got none")
        if not np.isfinite(a).all():
            raise ValueError(f"{name}: contains NaN or Inf")
        return a

    d = numbers(min_distances, "min_distances")
    touch = d <= _number(threshold, "threshold", positive=False)
    if volumes_cm3 is not None:
        vol = numbers(volumes_cm3, "volumes_cm3")
        if vol.shape != d.shape:
            raise ValueError(f"volumes_cm3: expected one volume per grasp ({len(d)}), got {len(vol)}")
        touch |= vol > 0
    return float(touch.mean())


def apd(samples: Any) -> float:
    """Average pairwise L2 distance between K samples (K, ...) flattened (SAGA Sec. 4.1 after DLow): mean over i != j."""
    x = _t(samples, "samples").double()
    if x.dim() < 1 or x.numel() == 0:
        raise ValueError(f"samples: expected (K, ...) with non-empty samples, got shape {tuple(x.shape)}")
    if not torch.isfinite(x).all():
        raise ValueError("samples: contains NaN or Inf")
    x = x.reshape(len(x), -1)
    K = x.shape[0]
    if K < 2:
        raise ValueError(f"samples: APD needs at least 2 samples, got {K}")
    d = pdist(x.numpy())                      # each pair once, exact differences (not |a|²+|b|²-2ab)
    return float(2 * d.sum() / (K * (K - 1)))


def grasp_quality_table(rows: list[dict[str, float]]) -> dict[str, float]:
    """Summary over grasps: rows of grasp_metrics (+ optional 'feet_cm': distance of the lower foot sole to the ground,
    cm): contact ratio, penetration volume mean / median / max, depth mean / max, share with feet within 1 cm."""
    if not rows:
        raise ValueError("rows: no grasps to summarise")
    for k in ("contact", "volume_cm3", "depth_cm") + (("feet_cm",) if all("feet_cm" in r for r in rows) else ()):
        if any(k not in r for r in rows):
            raise ValueError(f"rows: every row needs '{k}' (a grasp_metrics dict)")
        x = np.array([r[k] for r in rows], np.float64)
        if not np.isfinite(x).all():
            raise ValueError(f"rows: '{k}' contains NaN or Inf (row {int(np.argmin(np.isfinite(x)))})")
    vol = np.array([r["volume_cm3"] for r in rows])
    dep = np.array([r["depth_cm"] for r in rows])
    out = {"grasps": len(rows), "contact_ratio": float(np.mean([r["contact"] for r in rows])),
           "volume_mean_cm3": float(vol.mean()), "volume_median_cm3": float(np.median(vol)), "volume_max_cm3": float(vol.max()),
           "depth_mean_cm": float(dep.mean()), "depth_max_cm": float(dep.max())}
    if all("feet_cm" in r for r in rows):
        feet = np.array([r["feet_cm"] for r in rows])
        out.update(feet_within_1cm=float((feet <= 1.0).mean()), feet_max_cm=float(feet.max()))
    return out
