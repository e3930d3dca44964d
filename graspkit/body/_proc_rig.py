"""Rigging of the procedural humanoid: skinning weights, joint regressor, shape and expression bases.

- weights: each vertex starts on the joint owning its nearest primitive; then, joint by joint (parents
  first), the mass shared by a joint c and its parent p is split across a plane through c (normal =
  bisector of the parent and child bone directions) with a smoothstep of half-width h, for vertices
  within a lateral radius of c's bone; finally a few rounds of mesh-Laplacian smoothing.
- J_regressor: each joint is an exponentially tilted Gaussian average of nearby vertices of its own
  parts, tilted so that the average hits the designed joint exactly (non-negative, rows sum to 1).
- shapedirs: linear displacement fields built from per-part affine maps blended by the skinning
  weights, sum_k w_k (t_k + A_k (x - o_k)), plus smooth face bumps for the expressions.
"""
from __future__ import annotations

import numpy as np

from graspkit.body._proc_anatomy import J, left_hand, mirror_joint, Proportions
from graspkit.body._proc_mesh import vertex_neighbours
from graspkit.body.skeleton import FINGERS, JOINT_NAMES, NUM_JOINTS, PARENTS


def _unit(v: np.ndarray) -> np.ndarray:
    """Rows of v normalised."""
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def bone_ends(P: Proportions, joints: np.ndarray) -> np.ndarray:
    """Far end (55, 3) of the bone each joint drives (its main child, or a point for end bones)."""
    end = np.zeros_like(joints)
    main_child = {"pelvis": "spine1", "spine1": "spine2", "spine2": "spine3", "spine3": "neck", "neck": "head",
                  "left_collar": "left_shoulder", "left_shoulder": "left_elbow", "left_elbow": "left_wrist",
                  "left_wrist": "left_middle1", "left_hip": "left_knee", "left_knee": "left_ankle",
                  "left_ankle": "left_foot"}
    for a, b in main_child.items():
        end[J[a]] = joints[J[b]]
    end[J["head"]] = joints[J["head"]] + (0, 0.15, 0.02)
    end[J["jaw"]] = (0, 0.180, 0.075)
    end[J["left_eye_smplhf"]] = joints[J["left_eye_smplhf"]] + (0, 0, 0.015)
    end[J["left_foot"]] = joints[J["left_foot"]] + (0.01, -0.002, 0.06)
    hand = left_hand(P)
    W = joints[J["left_wrist"]]
    for f in FINGERS:
        for k in range(3):
            end[J[f"left_{f}{k + 1}"]] = W + (hand[f].joints[k + 1] if k < 2 else hand[f].tip)
    for i, n in enumerate(JOINT_NAMES):
        if n.startswith("right_"):
            end[i] = end[mirror_joint(i)] * (-1, 1, 1)
    return end


# joint -> (kind, size, lateral radius of the affected zone). 'plane': smoothstep across the joint plane,
# half-width `size` metres (trunk, ball joints). 'cone': the weight follows the vertex's cone angle
# alpha = atan2(distance from the bone axis, distance along it) around the joint, over 90 +- size degrees,
# so that a 90-120 degree bend keeps the vertices' angular order (no fold in the crease; see
# _cone_weight). Fingers get their radii from the hand layout.
_BLEND = {"spine1": ("plane", 0.05, np.inf), "spine2": ("plane", 0.05, np.inf), "spine3": ("plane", 0.05, np.inf),
          "neck": ("plane", 0.03, 0.075), "head": ("plane", 0.03, 0.12), "left_collar": ("plane", 0.04, 0.09),
          "left_shoulder": ("cone", 60.0, 0.12), "left_elbow": ("cone", 55.0, 0.08),
          "left_wrist": ("cone", 45.0, 0.07), "left_hip": ("cone", 55.0, 0.15), "left_knee": ("cone", 55.0, 0.10),
          "left_ankle": ("cone", 45.0, 0.08), "left_foot": ("cone", 45.0, 0.07)}


def _blend_table(P: Proportions) -> dict[int, tuple[str, float, float]]:
    """(kind, size, lateral radius) per joint index, both sides."""
    out = {J[n]: v for n, v in _BLEND.items()}
    hand = left_hand(P)
    for f in FINGERS:
        for k in range(3):
            out[J[f"left_{f}{k + 1}"]] = ("cone", 50.0, 1.6 * hand[f].radii[k])
    out[J["left_thumb1"]] = ("plane", 0.012, 0.022)
    for j in list(out):
        out[mirror_joint(j)] = out[j]
    return out


def _cone_weight(alpha: np.ndarray, beta: float) -> np.ndarray:
    """Child weight t for cone angles alpha (degrees, 180 = far along the parent, 0 = far along the child).

    Blending x with its rotated copy R x at weight t moves it by psi(t) = atan(t / (1 - t)) around the
    axis for a 90 degree bend; t is chosen so that psi grows linearly as alpha goes from 90 + beta to
    90 - beta, which keeps the blended surface's angular order (beta >= 45 for 90 degrees).
    """
    psi = np.deg2rad(90.0) * np.clip((90.0 + beta - alpha) / (2 * beta), 0.0, 1.0)
    return np.sin(psi) / (np.sin(psi) + np.cos(psi))


def skinning_weights(v: np.ndarray, f: np.ndarray, labels: np.ndarray, joints: np.ndarray, ends: np.ndarray,
                     P: Proportions, smooth_iters: int = 3) -> np.ndarray:
    """Skinning weights (V, 55) from vertex labels (V,) (owning joint per vertex): joint blends, then smoothing."""
    V = len(v)
    w = np.zeros((V, NUM_JOINTS))
    w[np.arange(V), labels] = 1.0
    table = _blend_table(P)
    for _ in range(2):  # a second pass settles mass that flowed back to a parent after its own step
        for c in range(1, NUM_JOINTS):
            if c not in table:
                continue
            p = PARENTS[c]
            kind, size, R = table[c]
            u_out = _unit(ends[c] - joints[c])
            u_in = _unit(joints[c] - joints[p]) if np.linalg.norm(joints[c] - joints[p]) > 1e-9 else u_out
            n = _unit(u_in + u_out)
            rel = v - joints[c]
            lateral = np.linalg.norm(rel - np.outer(rel @ u_out, u_out), axis=1)
            mass = w[:, p] + w[:, c]
            sel = (mass > 0) & (lateral < R)
            s = rel[sel] @ n
            if kind == "plane":
                t = np.clip((s + size) / (2 * size), 0.0, 1.0)
                t = t * t * (3 - 2 * t)
            else:
                rho = np.linalg.norm(rel[sel] - np.outer(s, n), axis=1)
                t = _cone_weight(np.degrees(np.arctan2(rho, s)), size)
            w[sel, c], w[sel, p] = t * mass[sel], (1 - t) * mass[sel]
    A = vertex_neighbours(f, V)
    deg = np.asarray(A.sum(1)).ravel()
    for _ in range(smooth_iters):
        w = 0.5 * w + 0.5 * (A @ w) / deg[:, None]
    w[w < 1e-6] = 0.0
    return w / w.sum(1, keepdims=True)


# ----------------------------------------------------------------------------- joint regressor
def _tilt(x: np.ndarray, g: np.ndarray, target: np.ndarray, iters: int = 100) -> tuple[np.ndarray, float]:
    """Weights (N,) proportional to g * exp(lam . (x - target)) whose mean is target; returns (weights, residual)."""
    d = x - target
    lam = np.zeros(3)
    logg = np.log(g)
    for _ in range(iters):
        a = logg + d @ lam
        w = np.exp(a - a.max())
        w /= w.sum()
        grad = w @ d
        if np.linalg.norm(grad) < 1e-12:
            break
        H = (d * w[:, None]).T @ d - np.outer(grad, grad) + 1e-12 * np.eye(3)
        step = np.linalg.solve(H, grad)
        # damped Newton on the convex log-partition function
        f0 = np.log(np.exp(a - a.max()).sum()) + a.max()
        s = 1.0
        while s > 1e-6:
            a1 = logg + d @ (lam - s * step)
            if np.log(np.exp(a1 - a1.max()).sum()) + a1.max() <= f0 - 1e-4 * s * grad @ step:
                break
            s *= 0.5
        lam = lam - s * step
    a = logg + d @ lam
    w = np.exp(a - a.max())
    w /= w.sum()
    return w, float(np.linalg.norm(w @ d))


def joint_regressor(v: np.ndarray, weights: np.ndarray, joints: np.ndarray) -> np.ndarray:
    """J_regressor (55, V): row j averages vertices of joint j's own and neighbouring parts around joint j."""
    V = len(v)
    reg = np.zeros((NUM_JOINTS, V))
    children = {j: [c for c in range(NUM_JOINTS) if PARENTS[c] == j] for j in range(NUM_JOINTS)}
    for j in range(NUM_JOINTS):
        family = [j] + children[j] + ([PARENTS[j]] if PARENTS[j] >= 0 else [])
        if JOINT_NAMES[j] in ("jaw", "left_eye_smplhf", "right_eye_smplhf"):
            family = [J["head"], J["jaw"]]
        own = weights[:, family].sum(1) > 0.3
        dist = np.linalg.norm(v - joints[j], axis=1)
        R = 2.0 * dist[own].min()
        for _ in range(30):
            sup = np.nonzero(own & (dist < R))[0]
            if len(sup) >= 8:
                g = np.exp(-0.5 * (dist[sup] / (0.5 * R)) ** 2)
                w, res = _tilt(v[sup], g, joints[j])
                if res < 1e-10 and w.max() < 0.5:
                    break
            R *= 1.25
        else:
            raise RuntimeError(f"joint {JOINT_NAMES[j]}: cannot be written as an average of nearby vertices")
        w[w < 1e-8 * w.max()] = 0.0
        reg[j, sup] = w / w.sum()
    return reg


# ----------------------------------------------------------------------------- shape space
def _smoothstep(x: np.ndarray) -> np.ndarray:
    """Cubic smoothstep of x clipped to [0, 1]."""
    t = np.clip(x, 0.0, 1.0)
    return t * t * (3 - 2 * t)


def _side_joints(*names: str) -> list[int]:
    """Indices of the given left-side joint names and their right mirrors."""
    out = []
    for n in names:
        out += [J[n], mirror_joint(J[n])]
    return out


def _arm_joints(side: str) -> list[int]:
    """Shoulder, elbow, wrist and finger joints of one side ('left' / 'right')."""
    return [i for i, n in enumerate(JOINT_NAMES) if n.startswith(side + "_") and
            any(k in n for k in ("shoulder", "elbow", "wrist", "index", "middle", "pinky", "ring", "thumb"))]


def _leg_joints(side: str) -> list[int]:
    """Hip, knee, ankle and foot joints of one side."""
    return [J[f"{side}_{n}"] for n in ("hip", "knee", "ankle", "foot")]


def shape_basis(v: np.ndarray, w: np.ndarray, joints: np.ndarray, ends: np.ndarray) -> np.ndarray:
    """Ten shape components (V, 3, 10): height, girth, shoulders, hips, arms, legs, torso, head, chest, muscle."""
    V = len(v)
    out = np.zeros((V, 3, 10))
    pelvis = joints[J["pelvis"]]
    head_like = w[:, [J["head"], J["jaw"], J["left_eye_smplhf"], J["right_eye_smplhf"]]].sum(1)

    # 0 height: uniform scale about the pelvis joint, 5 % per unit (1.70 m -> 1.53 .. 1.87 m at -+2)
    out[:, :, 0] = 0.05 * (v - pelvis)

    # 1 girth / weight: cross-sections grow about each bone axis; belly forward; inner thighs grow less
    amount = np.zeros(NUM_JOINTS)
    for names, a in ((("pelvis", "spine1", "spine2"), 0.10), (("spine3",), 0.08), (("neck",), 0.06),
                     (("left_collar",), 0.05), (("left_shoulder", "left_hip"), 0.08),
                     (("left_elbow", "left_knee"), 0.06),
                     (("head", "jaw"), 0.02), (("left_wrist", "left_ankle", "left_foot"), 0.02)):
        for n in names:
            amount[J[n]] = a
            amount[mirror_joint(J[n])] = a
    out[:, :, 1] = _radial(v, w, joints, ends, amount)
    inner = np.zeros(V)
    for j in _side_joints("left_hip", "left_knee"):
        side = np.sign(joints[j, 0])
        inner += w[:, j] * (1 - _smoothstep((v[:, 0] * side - joints[j, 0] * side) / 0.03 + 0.5))
    out[:, :, 1] *= (1 - 0.6 * inner)[:, None]
    belly = np.exp(-(v[:, 0] / 0.13) ** 2 - ((v[:, 1] + 0.20) / 0.13) ** 2) * _smoothstep(v[:, 2] / 0.08 + 0.5)
    out[:, 2, 1] += 0.02 * belly * (1 - head_like)

    # 2 shoulder width: arms move out 2.2 cm per unit; collars and upper chest stretch sideways
    f = np.zeros((NUM_JOINTS, 3))
    lin = np.zeros((NUM_JOINTS, 3, 3))
    for side, s in (("left", 1.0), ("right", -1.0)):
        for j in _arm_joints(side):
            f[j] = (0.022 * s, 0, 0)
        lin[J[f"{side}_collar"]] = np.diag([0.022 / abs(joints[J[f"{side}_shoulder"], 0]), 0, 0])
    lin[J["spine3"]] = np.diag([0.06, 0, 0])
    out[:, :, 2] = _affine_blend(v, w, f, lin, np.zeros_like(joints))

    # 3 hip width: the pelvis stretches sideways 10 % per unit, the legs follow by 0.5 cm (the crotch stays open)
    f[:], lin[:] = 0.0, 0.0
    for side, s in (("left", 1.0), ("right", -1.0)):
        for j in _leg_joints(side):
            f[j] = (0.005 * s, 0, 0)
    lin[J["pelvis"]] = np.diag([0.10, 0, 0])
    lin[J["spine1"]] = np.diag([0.03, 0, 0])
    out[:, :, 3] = _affine_blend(v, w, f, lin, np.zeros_like(joints))

    # 4 arm length, 5 leg length: bones stretch 4 % (arms) / 4.5 % (legs) per unit along their axes
    out[:, :, 4] = _limb_stretch(v, w, joints, ("shoulder", "elbow"), "wrist", 0.04, _arm_joints)
    out[:, :, 5] = _limb_stretch(v, w, joints, ("hip", "knee"), "ankle", 0.045, _leg_joints)

    # 6 torso length: the trunk between pelvis and neck stretches 5 % per unit; everything above moves up
    f[:], lin[:] = 0.0, 0.0
    a, y0 = 0.05, pelvis[1]
    up = np.zeros((3, 3))
    up[1, 1] = a
    for j in range(NUM_JOINTS):
        if JOINT_NAMES[j] in ("pelvis",) or "hip" in JOINT_NAMES[j] or "knee" in JOINT_NAMES[j] \
                or "ankle" in JOINT_NAMES[j] or JOINT_NAMES[j].endswith("_foot"):
            continue
        f[j] = (0, a * (joints[j, 1] - y0), 0)
    for side in ("left", "right"):
        for j in _arm_joints(side) + [J[f"{side}_collar"]]:
            f[j] = (0, a * (joints[J[f"{side}_collar"], 1] - y0), 0)
    for n in ("head", "jaw", "left_eye_smplhf", "right_eye_smplhf"):
        f[J[n]] = (0, a * (joints[J["neck"], 1] - y0), 0)
    for n in ("spine1", "spine2", "spine3"):
        lin[J[n]] = up
    out[:, :, 6] = _affine_blend(v, w, f, lin, joints)

    # 7 head size: head, jaw and eyes scale 4 % per unit about the head joint
    out[:, :, 7] = 0.04 * head_like[:, None] * (v - joints[J["head"]])

    # 8 chest depth: the chest moves forward, the back stays
    chest = w[:, [J["spine2"], J["spine3"]]].sum(1) + 0.5 * w[:, _side_joints("left_collar")].sum(1)
    out[:, 2, 8] = 0.12 * chest * np.maximum(v[:, 2] + 0.10, 0.0)

    # 9 muscularity: limbs, shoulders and chest fuller, waist a little slimmer
    amount[:] = 0.0
    for names, a in ((("left_shoulder",), 0.12), (("left_elbow",), 0.09), (("left_hip",), 0.06),
                     (("left_knee",), 0.09), (("left_collar",), 0.08), (("spine3",), 0.05), (("spine1",), -0.04),
                     (("neck",), 0.06)):
        for n in names:
            amount[J[n]] = a
            amount[mirror_joint(J[n])] = a
    out[:, :, 9] = _radial(v, w, joints, ends, amount)
    inner = np.zeros(V)
    for j in _side_joints("left_hip", "left_knee"):
        side = np.sign(joints[j, 0])
        inner += w[:, j] * (1 - _smoothstep((v[:, 0] * side - joints[j, 0] * side) / 0.03 + 0.5))
    out[:, :, 9] *= (1 - 0.6 * inner)[:, None]
    return out


def _radial(v: np.ndarray, w: np.ndarray, joints: np.ndarray, ends: np.ndarray, amount: np.ndarray) -> np.ndarray:
    """Displacement (V, 3): sum_k w_k amount_k (offset of v from bone k's axis, perpendicular part)."""
    out = np.zeros_like(v)
    trunk = {J[n] for n in ("pelvis", "spine1", "spine2", "spine3", "neck", "head", "jaw")}
    for k in np.nonzero(amount)[0]:
        m = w[:, k] > 0
        rel = v[m] - joints[k]
        u = np.array([0.0, 1.0, 0.0]) if k in trunk else _unit(ends[k] - joints[k])
        perp = rel - np.outer(rel @ u, u)
        out[m] += w[m, k, None] * amount[k] * perp
    return out


def _affine_blend(v: np.ndarray, w: np.ndarray, t: np.ndarray, A: np.ndarray, o: np.ndarray) -> np.ndarray:
    """Displacement (V, 3) = sum_k w_k (t_k + A_k (v - o_k)) for per-joint t (55,3), A (55,3,3), o (55,3)."""
    per = t[None] + np.einsum("kij,vkj->vki", A, v[:, None, :] - o[None])
    return np.einsum("vk,vki->vi", w, per)


def _limb_stretch(v, w, joints, bones: tuple[str, str], distal: str, a: float, joints_of) -> np.ndarray:
    """Displacement (V,3) stretching the two bones of each limb by factor a; distal parts translate."""
    t = np.zeros((NUM_JOINTS, 3))
    A = np.zeros((NUM_JOINTS, 3, 3))
    for side in ("left", "right"):
        j0, j1 = J[f"{side}_{bones[0]}"], J[f"{side}_{bones[1]}"]
        u0, u1 = _unit(joints[j1] - joints[j0]), _unit(joints[J[f"{side}_{distal}"]] - joints[j1])
        A[j0] = a * np.outer(u0, u0)
        t[j1] = a * (joints[j1] - joints[j0]) @ np.outer(u0, u0)
        A[j1] = a * np.outer(u1, u1)
        tip = t[j1] + a * (joints[J[f"{side}_{distal}"]] - joints[j1]) @ np.outer(u1, u1)
        for j in joints_of(side):
            if j not in (j0, j1):
                t[j] = tip
    return _affine_blend(v, w, t, A, joints)


def expression_basis(v: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Ten face-only expression components (V, 3, 10): smooth compact bumps of a few millimetres."""
    face = _smoothstep((w[:, [J["head"], J["jaw"]]].sum(1) - 0.3) / 0.5) * _smoothstep((v[:, 2] + 0.01) / 0.04)

    def bump(c: tuple[float, float, float], sigma: float, d: tuple[float, float, float],
             mirror: bool = False) -> np.ndarray:
        """Displacement (V,3) d times a smooth compact bump of radius 3 sigma around c (and its mirror)."""
        out = np.zeros_like(v)
        for cc, dd in ((np.asarray(c, float), np.asarray(d, float)),) + (
                ((np.asarray(c, float) * (-1, 1, 1), np.asarray(d, float) * (-1, 1, 1)),) if mirror else ()):
            r2 = np.sum((v - cc) ** 2, 1) / (3 * sigma) ** 2
            out += (np.clip(1 - r2, 0, None) ** 3)[:, None] * dd
        return out

    # the jaw drops, fading out towards the lip line so that the closed lips never press into each other
    jaw = (w[:, J["jaw"]] * _smoothstep((0.207 - v[:, 1]) / 0.03))[:, None] * np.array([0.0, -0.004, -0.001])
    comps = [
        jaw,                                                                                 # mouth open
        bump((0.024, 0.207, 0.078), 0.012, (0.002, 0.004, -0.002), True),                   # smile
        bump((0.032, 0.312, 0.085), 0.018, (0, 0.005, 0.001), True),                        # brows up
        bump((0.013, 0.306, 0.088), 0.012, (-0.002, -0.004, 0.001), True),                  # frown
        bump((0, 0.207, 0.085), 0.014, (0, 0, 0.005)),                                      # pucker
        bump((0.045, 0.245, 0.065), 0.018, (0.004, 0, 0.003), True),                        # cheeks puff
        bump((0.032, 0.292, 0.080), 0.010, (0, -0.002, -0.001), True),                      # squint
        bump((0.0, 0.262, 0.100), 0.012, (0, 0.003, -0.001)),                               # nose wrinkle
        bump((0.024, 0.207, 0.078), 0.012, (0.004, 0, -0.002), True),                       # mouth wide
        bump((0.024, 0.205, 0.078), 0.012, (0, -0.004, 0), True),                           # mouth corners down
    ]
    return np.stack(comps, axis=2) * face[:, None, None]
