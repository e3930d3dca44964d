"""The procedural humanoid's anatomy: proportions, rest joints, primitives and landmark targets.

Canonical SMPL-X space: y up, facing +z, the body's left at +x, metres. An adult of 1.70 m stands
with the soles at y = -1.30 and the top of the head at y = +0.40 (as the real SMPL-X template), arms
straight out along +-x with the palms down (-y), legs straight and slightly apart. Everything is
written for the left side and mirrored (x -> -x) for the right.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from graspkit.body._proc_sdf import Body, Ellipsoid, Floor, Lens, Loft, Prim, RoundBox, Sweep
from graspkit.body.skeleton import FINGERS, JOINT_INDEX, JOINT_NAMES, NUM_JOINTS

J = JOINT_INDEX
SOLE_Y = -1.30


def mirror_joint(j: int) -> int:
    """Index of the joint mirroring joint j (left <-> right); unpaired joints map to themselves."""
    n = JOINT_NAMES[j]
    if n.startswith("left_"):
        return J["right_" + n[5:]]
    if n.startswith("right_"):
        return J["left_" + n[6:]]
    return j


@dataclass(frozen=True)
class Proportions:
    """Lengths that the seed may vary by a few percent; all other sizes are fixed."""

    shoulder_x: float = 0.180      # shoulder joint, distance from the midline
    upper_arm: float = 0.265       # shoulder -> elbow
    forearm: float = 0.250         # elbow -> wrist
    hip_x: float = 0.085
    knee_y: float = -0.815
    hand: float = 1.0              # scale of the hand layout
    girth: float = 1.0             # scale of trunk and limb cross-sections

    def jittered(self, seed: int) -> "Proportions":
        """Each field times (1 + 0.02 n), n ~ N(0,1) clipped to +-1.5; seed 0 included (deterministic)."""
        rng = np.random.default_rng(seed)
        names = list(self.__dataclass_fields__)
        n = np.clip(rng.standard_normal(len(names)), -1.5, 1.5)
        vals = {k: getattr(self, k) * (1 + 0.02 * float(e)) for k, e in zip(names, n)}
        vals["knee_y"] = self.knee_y + 0.01 * float(n[names.index("knee_y")])  # +-1 cm, not percent
        return replace(self, **vals)


@dataclass(frozen=True)
class Finger:
    """One finger of the left hand in the rest pose: joint positions (3,3) relative to the wrist, tip, radii (4,)."""

    joints: np.ndarray
    tip: np.ndarray
    radii: tuple[float, float, float, float]


def _chain(base, dirs, lengths) -> tuple[np.ndarray, np.ndarray]:
    """Joint positions (3,3) and tip (3,) of a 3-bone chain starting at base with unit dirs and lengths."""
    pts = [np.asarray(base, float)]
    for d, L in zip(dirs, lengths):
        d = np.asarray(d, float) / np.linalg.norm(d)
        pts.append(pts[-1] + L * d)
    return np.stack(pts[:3]), pts[3]


def left_hand(P: Proportions) -> dict[str, Finger]:
    """The five fingers of the left hand (fingers along +x, palm facing -y, thumb towards +z)."""
    s = P.hand
    out = {}
    # name: (MCP offset from wrist, fan angle in degrees towards +z, bone lengths, radii MCP/PIP/DIP/tip)
    layout = {
        "index": ((0.087, -0.002, 0.0275), 7.0, (0.038, 0.022, 0.019), (0.0086, 0.0078, 0.0071, 0.0064)),
        "middle": ((0.090, -0.002, 0.0080), 1.0, (0.042, 0.025, 0.020), (0.0089, 0.0081, 0.0073, 0.0066)),
        "pinky": ((0.081, -0.002, -0.0310), -12.0, (0.031, 0.018, 0.017), (0.0074, 0.0067, 0.0061, 0.0056)),
        "ring": ((0.087, -0.002, -0.0115), -5.0, (0.040, 0.024, 0.019), (0.0083, 0.0076, 0.0069, 0.0062)),
    }
    for name, (base, ang, lengths, radii) in layout.items():
        a = np.deg2rad(ang)
        d = (np.cos(a), -0.02, np.sin(a))
        joints, tip = _chain(np.asarray(base) * s, [d] * 3, np.asarray(lengths) * s)
        out[name] = Finger(joints, tip, tuple(r * s for r in radii))
    thumb_dirs = [(0.50, -0.33, 0.80), (0.70, -0.25, 0.67), (0.78, -0.22, 0.58)]
    joints, tip = _chain(np.array([0.020, -0.014, 0.021]) * s, thumb_dirs, np.array([0.043, 0.032, 0.026]) * s)
    out["thumb"] = Finger(joints, tip, tuple(r * s for r in (0.0125, 0.0105, 0.0096, 0.0088)))
    return out


def rest_joints(P: Proportions) -> np.ndarray:
    """The 55 rest-pose joint positions (55, 3) in SMPL-X order."""
    j = np.zeros((NUM_JOINTS, 3))
    left = {
        "left_hip": (P.hip_x, -0.440, -0.005), "left_knee": (P.hip_x + 0.015, P.knee_y, 0.0),
        "left_ankle": (P.hip_x + 0.007, -1.225, -0.045), "left_foot": (P.hip_x + 0.027, -1.281, 0.085),
        "left_collar": (0.075, 0.095, -0.025), "left_shoulder": (P.shoulder_x, 0.090, -0.030),
        "left_elbow": (P.shoulder_x + P.upper_arm, 0.075, -0.035),
        "left_wrist": (P.shoulder_x + P.upper_arm + P.forearm, 0.070, -0.030),
        "left_eye_smplhf": (0.032, 0.289, 0.068),
    }
    mid = {"pelvis": (0, -0.350, 0.0), "spine1": (0, -0.235, -0.020), "spine2": (0, -0.105, -0.010),
           "spine3": (0, -0.045, 0.005), "neck": (0, 0.165, -0.025), "head": (0, 0.245, 0.000),
           "jaw": (0, 0.230, 0.020)}
    for n, p in {**mid, **left}.items():
        j[J[n]] = p
    W = j[J["left_wrist"]]
    for f, finger in left_hand(P).items():
        for k in range(3):
            j[J[f"left_{f}{k + 1}"]] = W + finger.joints[k]
    for i in range(NUM_JOINTS):
        m = mirror_joint(i)
        if m != i and JOINT_NAMES[i].startswith("left_"):
            j[m] = j[i] * (-1, 1, 1)
    return j


# ----------------------------------------------------------------------------- primitives
def _rot(x_axis, y_hint=(0.0, 1.0, 0.0)) -> np.ndarray:
    """Rotation (3,3) whose first column is x_axis and second the part of y_hint perpendicular to it."""
    x = np.asarray(x_axis, float) / np.linalg.norm(x_axis)
    y = np.asarray(y_hint, float) - (np.asarray(y_hint, float) @ x) * x
    y /= np.linalg.norm(y)
    return np.stack([x, y, np.cross(x, y)], 1)


def _trunk_and_head(P: Proportions) -> tuple[list[Prim], list[Prim], list[Prim]]:
    """Midline parts, left-side parts of trunk and head, and the left eye (socket, then eyeball)."""
    g = P.girth
    prof = np.array([  # y, half-width, half-depth, centre z
        (-0.40, 0.152, 0.098, -0.010), (-0.35, 0.153, 0.099, -0.005),
        (-0.24, 0.138, 0.094, 0.000), (-0.12, 0.145, 0.102, 0.005), (-0.02, 0.155, 0.110, 0.008),
        (0.06, 0.160, 0.105, 0.000), (0.12, 0.135, 0.085, -0.015), (0.155, 0.090, 0.065, -0.025)])
    prof[:, 1:3] *= g
    pelvis, neck, head, jaw = J["pelvis"], J["neck"], J["head"], J["jaw"]
    mid: list[Prim] = [
        Loft(prof, (0.06, 0.03), joint=pelvis),
        Ellipsoid((0, -0.425, -0.012), (0.156 * g, 0.095, 0.100 * g), joint=pelvis, k=0.05),        # hips
        Ellipsoid((0, -0.20, 0.035), (0.12 * g, 0.11, 0.075 * g), joint=pelvis, k=0.04),            # belly
        Sweep((0, 0.12, -0.025), (0, 0.275, -0.008), (0.055, 0.056), (0.051, 0.053), up=(1, 0, 0),
              joint=neck, k=0.035),                                                                  # neck
        Ellipsoid((0, 0.305, -0.008), (0.076, 0.095, 0.097), joint=head, k=0.03),                   # cranium
        Ellipsoid((0, 0.262, 0.020), (0.064, 0.068, 0.067), joint=head, k=0.03),                    # mid face
        Ellipsoid((0, 0.207, 0.028), (0.054, 0.040, 0.057), joint=jaw, k=0.025),                    # jaw
        Ellipsoid((0, 0.182, 0.066), (0.020, 0.016, 0.020), joint=jaw, k=0.012),                    # chin
        Sweep((0, 0.292, 0.080), (0, 0.250, 0.103), (0.008, 0.0075), (0.0125, 0.0105), up=(1, 0, 0),
              caps=(0.008, 0.011), joint=head, k=0.008),                                           # nose
        Sweep((-0.048, 0.309, 0.078), (0.048, 0.309, 0.078), (0.010, 0.010), (0.010, 0.010),
              joint=head, k=0.012),                                                                 # brow ridge
        Ellipsoid((0, 0.214, 0.083), (0.023, 0.0075, 0.009), joint=head, k=0.005),                  # upper lip
        Ellipsoid((0, 0.200, 0.081), (0.021, 0.0075, 0.009), joint=jaw, k=0.005),                   # lower lip
    ]
    left: list[Prim] = [
        Ellipsoid((0.065, -0.475, -0.070), (0.085 * g, 0.090, 0.075 * g), joint=pelvis, k=0.03),   # buttock
        Sweep((0.035, 0.150, -0.035), (0.165, 0.112, -0.035), (0.030, 0.045), (0.036, 0.046),
              joint=J["left_collar"], k=0.03),                                                      # trapezius
        Ellipsoid((0.013, 0.246, 0.091), (0.009, 0.008, 0.009), joint=head, k=0.005),              # nostril
        Ellipsoid((0.077, 0.283, -0.008), (0.011, 0.030, 0.019), _rot((1, 0, 0.25)), joint=head, k=0.006),  # ear
    ]
    eye: list[Prim] = [
        Ellipsoid((0.032, 0.291, 0.094), (0.017, 0.016, 0.017), sub=True, k=0.006, joint=J["head"]),  # eye socket
        Ellipsoid((0.032, 0.289, 0.069), (0.0125, 0.0125, 0.0125), joint=head, k=0.003),           # eyeball
    ]
    return mid, left, eye


def _left_arm(P: Proportions, joints: np.ndarray) -> list[Prim]:
    """Left arm and hand (fingers first, so that the palm's blend makes short webbing)."""
    g = P.girth
    S, E, W = joints[J["left_shoulder"]], joints[J["left_elbow"]], joints[J["left_wrist"]]
    ax = (E - S) / np.linalg.norm(E - S)
    fx = (W - E) / np.linalg.norm(W - E)
    prims: list[Prim] = [
        Sweep(S - 0.01 * ax, E, (0.045 * g, 0.047 * g), (0.036 * g, 0.038 * g), joint=J["left_shoulder"], k=0.035),
        Ellipsoid(S + (0.015, -0.003, 0), (0.058, 0.052 * g, 0.055 * g), joint=J["left_shoulder"], k=0.03),  # deltoid
        Ellipsoid(S + 0.45 * (E - S) + (0, 0.004, 0.006), (0.085, 0.040 * g, 0.043 * g), _rot(ax),
                  joint=J["left_shoulder"], k=0.03),                                                # biceps
        Sweep(E, W, (0.037 * g, 0.041 * g), (0.020, 0.029), joint=J["left_elbow"], k=0.02),
        Ellipsoid(E + 0.28 * (W - E), (0.080, 0.035 * g, 0.040 * g), _rot(fx), joint=J["left_elbow"], k=0.025),
    ]
    hand = left_hand(P)
    s = P.hand
    for f in ("index", "middle", "ring", "pinky", "thumb"):
        fg = hand[f]
        pts = [W + p for p in fg.joints] + [W + fg.tip]
        first = 1 if f == "thumb" else 0     # the thumb metacarpal is inside the thenar sweep below
        for b in range(first, 3):
            cap = fg.radii[b + 1] if b == 2 else None
            prims.append(Sweep(pts[b], pts[b + 1], (fg.radii[b] * 0.92, fg.radii[b]),
                               (fg.radii[b + 1] * 0.92, fg.radii[b + 1]),
                               caps=None if cap is None else (fg.radii[b] * 0.92, cap),
                               joint=J[f"left_{f}{b + 1}"], k=0.0015))
    th = hand["thumb"]
    prims += [
        Sweep(W - (0.012, 0, 0), W + (0.030, -0.002, 0), (0.021, 0.030), (0.016, 0.036),
              joint=J["left_wrist"], k=0.012),                                                      # wrist
        RoundBox(W + np.array([0.043, -0.003, -0.0015]) * s, (0.029 * s, 0.0015 * s, 0.027 * s), 0.0125 * s,
                 joint=J["left_wrist"], k=0.008),                                                   # palm
        *[Sweep(W + hand[a].joints[0] - (0.004 * s, 0, 0), W + hand[b].joints[0] - (0.004 * s, 0, 0),
                (0.0100 * s, 0.0100 * s), (0.0100 * s, 0.0100 * s), joint=J["left_wrist"], k=0.008)
          for a, b in (("index", "middle"), ("middle", "ring"), ("ring", "pinky"))],               # knuckles
        Sweep(W + th.joints[0], W + th.joints[1], (0.0150 * s, 0.017 * s), (0.0105 * s, 0.0115 * s),
              up=(0, 0, -1), joint=J["left_thumb1"], k=0.012),                                      # thenar
        Sweep(W + np.array([0.020, -0.012, -0.028]) * s, W + np.array([0.072, -0.010, -0.028]) * s,
              (0.008 * s, 0.010 * s), (0.006 * s, 0.009 * s), joint=J["left_wrist"], k=0.008),     # hypothenar
    ]
    return prims


def _left_leg(P: Proportions, joints: np.ndarray) -> list[Prim]:
    """Left thigh, shank and foot."""
    g = P.girth
    H, K, A = joints[J["left_hip"]], joints[J["left_knee"]], joints[J["left_ankle"]]
    x = A[0]
    return [
        Sweep(H + (0.003, 0.04, 0), K, (0.080 * g, 0.084 * g), (0.051 * g, 0.052 * g), up=(1, 0, 0),
              caps=(0.06, 0.05), joint=J["left_hip"], k=0.05),
        Ellipsoid(K + (0.0, 0.012, 0.036), (0.034, 0.040, 0.020), joint=J["left_knee"], k=0.015),    # knee cap
        Sweep(K, A + (0, 0.010, 0.005), (0.049 * g, 0.051 * g), (0.031, 0.033), up=(1, 0, 0),
              joint=J["left_knee"], k=0.03),
        Ellipsoid(K + (0.002, -0.135, -0.032), (0.044 * g, 0.100, 0.042 * g), joint=J["left_knee"], k=0.025),  # calf
        Ellipsoid((x - 0.002, -1.266, -0.060), (0.033, 0.040, 0.042), joint=J["left_ankle"], k=0.015),    # heel
        Sweep((x, -1.250, -0.050), (x + 0.020, -1.277, 0.080), (0.038, 0.040), (0.022, 0.047),
              joint=J["left_ankle"], k=0.02),                                                       # foot body
        Sweep(A + (0, 0.0, 0.01), (x + 0.013, -1.262, 0.055), (0.032, 0.032), (0.020, 0.040),
              joint=J["left_ankle"], k=0.02),                                                       # instep
        Sweep((x + 0.021, -1.279, 0.080), (x + 0.030, -1.283, 0.122), (0.020, 0.046), (0.015, 0.034),
              caps=(0.02, 0.016), joint=J["left_foot"], k=0.01),                                    # toes
        Ellipsoid((x + 0.004, -1.283, 0.128), (0.014, 0.0135, 0.023), joint=J["left_foot"], k=0.008),  # big toe
    ]


def body_plan(P: Proportions) -> tuple[Body, list[Lens], np.ndarray]:
    """The body's primitives in blending order, the sampling lenses, and the rest joints (55, 3)."""
    joints = rest_joints(P)
    mid, left, eye = _trunk_and_head(P)
    arm, leg = _left_arm(P, joints), _left_leg(P, joints)
    both = lambda ps: ps + [_mirror(p) for p in ps]  # noqa: E731
    # order matters for smooth union: trunk and head, eyes, then limbs (each finger before its palm)
    prims = mid + both(left) + both(eye) + both(leg) + both(arm)
    W = joints[J["left_wrist"]]
    hand_c = W + np.array([0.085, -0.010, 0.015]) * P.hand
    lenses = [Lens(tuple(hand_c), 0.2875, 0.60, 2.5), Lens(tuple(hand_c * (-1, 1, 1)), 0.2875, 0.60, 2.5),
              Lens((0.0, 0.29, 0.015), 0.195, 0.40, 1.5)]
    return Body(prims, Floor(SOLE_Y, 0.006)), lenses, joints


def _mirror(p: Prim) -> Prim:
    """Right-side copy of a left-side primitive."""
    q = p.mirrored()
    q.joint = mirror_joint(p.joint) if p.joint >= 0 else -1
    return q


# ----------------------------------------------------------------------------- landmark targets
def landmark_targets(P: Proportions, joints: np.ndarray) -> dict[str, np.ndarray]:
    """Anatomical points (3,) for the SMPL-X landmark vertex ids of skeleton.SMPLX_LANDMARK_VERTEX_IDS."""
    t = {"nose": np.array([0.0, 0.250, 0.118]),
         "leye": np.array([0.032, 0.289, 0.082]), "reye": np.array([-0.032, 0.289, 0.082]),
         "lear": np.array([0.090, 0.283, -0.006]), "rear": np.array([-0.090, 0.283, -0.006])}
    hand = left_hand(P)
    short = {"thumb": "thumb", "index": "index", "middle": "middle", "ring": "ring", "pinky": "pinky"}
    for f in FINGERS:
        fg = hand[f]
        d = (fg.tip - fg.joints[2]) / np.linalg.norm(fg.tip - fg.joints[2])
        tip = joints[J["left_wrist"]] + fg.tip + d * fg.radii[3]
        t["l" + short[f]] = tip
        t["r" + short[f]] = tip * (-1, 1, 1)
    x = joints[J["left_ankle"]][0]
    for side, s in (("L", 1), ("R", -1)):
        t[f"{side}BigToe"] = np.array([s * (x + 0.004), SOLE_Y + 0.012, 0.152])
        t[f"{side}SmallToe"] = np.array([s * (x + 0.050), SOLE_Y + 0.010, 0.110])
        t[f"{side}Heel"] = np.array([s * (x - 0.002), SOLE_Y, -0.090])
    return t
