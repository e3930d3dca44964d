"""Procedural hand poses (axis-angle of the 15 finger joints, SMPL-X order) and their PCA.

A pose is written per joint as flexion (towards the palm), spread (in the palm plane, towards the
thumb side) and, for the thumb's base, palmar abduction and axial twist (opposition). The axes come
from a model's rest joints, so the same code serves the procedural humanoid and a real SMPL-X file,
and the left and right hands come out mirrored (axis-angle vectors are pseudo-vectors: the right
hand's axes are minus the mirror images of the left hand's).

Grasp kinds follow the usual taxonomy (open, relaxed, power, pinch, tripod, lateral/key, hook, point,
fist); each sample adds Gaussian noise to its kind's template.
"""
from __future__ import annotations

import numpy as np

from graspkit.body.skeleton import FINGERS, JOINT_INDEX
from graspkit.checks import check_int, check_weight, seeded_rng

HAND_KINDS = ("flat", "relaxed", "power", "pinch", "tripod", "lateral", "hook", "point", "fist")

# degrees; per finger (MCP, PIP, DIP) flexion, in skeleton.FINGERS order without the thumb
_FINGER_TEMPLATES: dict[str, dict[str, tuple[float, float, float]]] = {
    "flat": {"index": (0, 0, 0), "middle": (0, 0, 0), "pinky": (0, 0, 0), "ring": (0, 0, 0)},
    "relaxed": {"index": (15, 22, 10), "middle": (18, 27, 12), "pinky": (26, 30, 12), "ring": (22, 30, 12)},
    "power": {"index": (55, 65, 35), "middle": (60, 70, 35), "pinky": (65, 70, 35), "ring": (62, 70, 35)},
    "pinch": {"index": (40, 50, 25), "middle": (35, 45, 20), "pinky": (45, 60, 25), "ring": (40, 55, 25)},
    "tripod": {"index": (40, 45, 20), "middle": (45, 45, 20), "pinky": (65, 80, 40), "ring": (60, 75, 40)},
    "lateral": {"index": (60, 80, 40), "middle": (75, 90, 45), "pinky": (85, 95, 45), "ring": (80, 95, 45)},
    "hook": {"index": (5, 85, 55), "middle": (5, 85, 55), "pinky": (5, 85, 50), "ring": (5, 85, 55)},
    "point": {"index": (5, 5, 0), "middle": (80, 100, 50), "pinky": (85, 100, 50), "ring": (85, 100, 50)},
    "fist": {"index": (85, 100, 55), "middle": (85, 100, 55), "pinky": (85, 100, 55), "ring": (85, 100, 55)},
}
# thumb: (CMC flexion, CMC palmar abduction, CMC twist, MCP flexion, IP flexion); pinch, tripod and
# lateral were tuned on the procedural hand so that the thumb pad meets the index tip (pinch), the
# index and middle tips (tripod) or the side of the index's middle phalanx (lateral/key grip)
_THUMB_TEMPLATES: dict[str, tuple[float, float, float, float, float]] = {
    "flat": (0, 0, 0, 0, 0), "relaxed": (8, 12, 8, 10, 10), "power": (35, 40, 45, 25, 25),
    "pinch": (13, 36, 51, 16, 17), "tripod": (20, 37, 47, 12, 11), "lateral": (11, -10, 42, 30, 32),
    "hook": (0, 5, 0, 0, 0), "point": (35, 20, 30, 30, 30), "fist": (40, 25, 35, 40, 45),
}
# spread (degrees, towards the thumb side) of each finger's MCP in the flat hand; other kinds use a fraction
_SPREAD = {"index": 4.0, "middle": 0.0, "pinky": -6.0, "ring": -3.0}


def _unit(v: np.ndarray) -> np.ndarray:
    """v (3,) normalised."""
    return v / np.linalg.norm(v)


def hand_axes(joints: np.ndarray, side: str) -> dict[str, np.ndarray]:
    """Axes of one hand from rest joints (55,3): 'flex' (15,3), 'spread' (15,3), thumb 'abduct' (3,), 'twist' (3,)."""
    p = "left_" if side == "left" else "right_"
    j = lambda n: joints[JOINT_INDEX[p + n]]  # noqa: E731
    wrist = joints[JOINT_INDEX[p + "wrist"]]
    thumb_side = _unit(j("index1") - j("pinky1"))
    back = np.cross(thumb_side, j("middle1") - wrist)
    palm = _unit(-back) if side == "left" else _unit(back)      # normal out of the palm (-y in the rest pose)
    chirality = 1.0 if side == "left" else -1.0
    flex, spread = np.zeros((15, 3)), np.zeros((15, 3))
    for fi, f in enumerate(FINGERS):
        pts = [j(f"{f}{k}") for k in (1, 2, 3)]
        dirs = [_unit(pts[1] - pts[0]), _unit(pts[2] - pts[1]), _unit(pts[2] - pts[1])]
        for k, d in enumerate(dirs):
            if f == "thumb":  # the thumb flexes across the palm, towards the little finger's base
                bend = _unit(0.6 * palm + 0.4 * _unit(j("pinky1") - pts[1]))
            else:
                bend = palm
            a = np.cross(d, bend)
            flex[3 * fi + k] = _unit(a)
            s = _unit(palm) if np.cross(palm, d) @ thumb_side > 0 else -_unit(palm)
            spread[3 * fi + k] = s
    d1 = _unit(j("thumb2") - j("thumb1"))
    return {"flex": flex, "spread": spread, "abduct": _unit(np.cross(d1, palm)), "twist": chirality * d1}


def template_pose(kind: str, axes: dict[str, np.ndarray]) -> np.ndarray:
    """The noise-free pose (45,) of a kind from its angle template."""
    return _pose(kind, axes, np.zeros(17 + 4))


def _pose(kind: str, axes: dict[str, np.ndarray], noise_deg: np.ndarray) -> np.ndarray:
    """Pose (45,) of a kind, with per-parameter noise (21,) in degrees (12 finger flexions, 5 thumb, 4 spreads)."""
    if kind not in HAND_KINDS:
        raise ValueError(f"kind: unknown hand pose kind {kind!r}; expected one of {HAND_KINDS}")
    out = np.zeros((15, 3))
    rad = np.deg2rad
    spread_scale = {"flat": 1.0, "relaxed": 0.6}.get(kind, 0.3)
    for fi, f in enumerate(FINGERS[:4]):
        angles = np.asarray(_FINGER_TEMPLATES[kind][f], float) + noise_deg[3 * fi:3 * fi + 3]
        angles = np.maximum(angles, -10.0)   # a little hyperextension at most
        for k in range(3):
            out[3 * fi + k] = rad(angles[k]) * axes["flex"][3 * fi + k]
        out[3 * fi] += rad(_SPREAD[f] * spread_scale + noise_deg[17 + fi]) * axes["spread"][3 * fi]
    t = np.asarray(_THUMB_TEMPLATES[kind], float) + noise_deg[12:17]
    cmc, mcp, ip = 12, 13, 14
    out[cmc] = rad(t[0]) * axes["flex"][cmc] + rad(t[1]) * axes["abduct"] + rad(t[2]) * axes["twist"]
    out[mcp] = rad(max(t[3], -10.0)) * axes["flex"][mcp]
    out[ip] = rad(max(t[4], -10.0)) * axes["flex"][ip]
    return out.reshape(45)


def sample_hand_poses(n: int, kind: str = "mixture", rng: np.random.Generator | int = 0, side: str = "right",
                      joints: np.ndarray | None = None, noise_deg: float = 5.0) -> np.ndarray:
    """n hand poses (n, 45) of one kind (or 'mixture': kinds drawn uniformly), seeded, for side 'left'/'right'.

    joints: rest joints (55, 3) of the model the poses are for (default: the shipped procedural humanoid,
    seed 0, whose rest joints are exactly its designed ones).
    """
    if side not in ("left", "right"):
        raise ValueError(f"side: expected 'left' or 'right', got {side!r}")
    if kind != "mixture" and kind not in HAND_KINDS:
        raise ValueError(f"kind: unknown hand pose kind {kind!r}; expected 'mixture' or one of {HAND_KINDS}")
    n = check_int(n, "n", 0)
    noise_deg = check_weight(noise_deg, "noise_deg")
    rng = seeded_rng(rng, "rng") if not isinstance(rng, np.random.Generator) else rng
    if joints is None:
        from graspkit.body._proc_anatomy import Proportions, rest_joints
        joints = rest_joints(Proportions().jittered(0))
    axes = hand_axes(np.asarray(joints, float), side)
    kinds = rng.integers(0, len(HAND_KINDS), n) if kind == "mixture" else np.full(n, HAND_KINDS.index(kind))
    noise = rng.normal(scale=noise_deg, size=(n, 21))
    return np.stack([_pose(HAND_KINDS[k], axes, e) for k, e in zip(kinds, noise)]) if n else np.zeros((0, 45))


def hand_pca(joints: np.ndarray, side: str, n_per_kind: int = 400, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """PCA of the procedural hand poses of one side: components (45, 45) (rows, by variance) and mean (45,).

    The mean is the relaxed, slightly curled hand (as SMPL-X's hands_mean); components come from the
    SVD of the samples minus that mean, so coefficients @ components + mean recovers a pose.
    """
    rng = seeded_rng(seed)
    X = np.concatenate([sample_hand_poses(n_per_kind, k, rng, side, joints) for k in HAND_KINDS])
    mean = template_pose("relaxed", hand_axes(np.asarray(joints, float), side))
    _, _, Vt = np.linalg.svd(X - mean, full_matrices=True)
    # fix each component's sign (largest entry positive) so the result does not depend on LAPACK details
    signs = np.sign(Vt[np.arange(45), np.abs(Vt).argmax(1)])
    return Vt * signs[:, None], mean
