"""Procedural anatomy (_proc_anatomy) and signed-distance builders (_proc_sdf) against independent truths: analytic
distances of spheres, ellipsoids, capsules and boxes, the polynomial smooth minimum by hand, mirror symmetry, the lens
round trip, and the documented ranges of the proportions' jitter."""
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from graspkit.body._proc_anatomy import (Proportions, _chain, body_plan, landmark_targets, left_hand, mirror_joint,
                                         rest_joints)
from graspkit.body._proc_sdf import Body, Ellipsoid, Floor, RoundBox, Sweep, smax, smin, unwarp, warp
from graspkit.body.skeleton import FINGERS, JOINT_INDEX as JI, JOINT_NAMES, NUM_JOINTS

MX = np.array([-1.0, 1.0, 1.0])                                          # the mirror x -> -x


def _seg_dist(p, a, b):
    """Euclidean distance (N,) of points p (N, 3) to the segment a-b, by projection."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    t = np.clip((p - a) @ (b - a) / ((b - a) @ (b - a)), 0.0, 1.0)
    return np.linalg.norm(p - (a + t[:, None] * (b - a)), axis=1)


def _smin_hand(a, b, k):
    """Quilez's polynomial smooth minimum in its other closed form: min(a, b) - max(k - |a - b|, 0)^2 / (4 k)."""
    return np.minimum(a, b) - np.maximum(k - np.abs(a - b), 0.0) ** 2 / (4 * k)


# ----------------------------------------------------------------------------- primitives
def test_sphere_capsule_and_ellipsoid_distances_are_analytic():
    """A round Ellipsoid is the sphere |p - c| - r, a round Sweep (any axis, one along its `up` included: x gave NaNs)
    the capsule dist(p, segment) - r beyond its ends too; an ellipsoid is zero at its semi-axes' ends,
    -min(r) at its centre, and its box holds its exact extent sqrt(sum_j R_ij^2 r_j^2)."""
    rng = np.random.default_rng(0)
    c = np.array([0.1, -0.2, 0.3])
    p = c + rng.normal(scale=0.1, size=(400, 3))
    sph = Ellipsoid(c, (0.07, 0.07, 0.07))
    np.testing.assert_allclose(sph.sdf(p), np.linalg.norm(p - c, axis=1) - 0.07, atol=1e-12)
    for a, b, up in (((0.0, 0.0, 0.0), (0.1, 0.2, -0.05), (0, 1, 0)), ((0.0, -0.1, 0.0), (0.0, 0.15, 0.0), (0, 1, 0)),
                     ((0.0, 0.0, 0.0), (0.2, 0.0, 0.0), (1, 0, 0)), ((0.0, 0.0, 0.0), (0.0, 0.0, -0.2), (0, 0, 1))):
        cap = Sweep(a, b, (0.03, 0.03), (0.03, 0.03), up=up)          # the last two: axis along `up` (x, z)
        q = np.asarray(a) + rng.normal(scale=0.12, size=(400, 3))
        np.testing.assert_allclose(cap.sdf(q), _seg_dist(q, a, b) - 0.03, atol=1e-12)
    r = np.array([0.1, 0.04, 0.06])
    R = Rotation.from_rotvec([0.4, -0.9, 0.7]).as_matrix()
    e = Ellipsoid(c, tuple(r), R)
    ends = c + np.concatenate([R * r, -(R * r)], 1).T                 # c +- r_j R[:, j]
    np.testing.assert_allclose(e.sdf(ends), 0.0, atol=1e-12)
    assert e.sdf(c[None])[0] == pytest.approx(-0.04, abs=1e-12)
    assert e.sdf(c[None] + 0.5 * (R[:, 1] * 0.04))[0] == pytest.approx(-0.02, abs=1e-12)
    ext = np.sqrt((R ** 2) @ r ** 2)
    lo, hi = e.bounds()
    assert np.all(lo <= c - ext + 1e-12) and np.all(hi >= c + ext - 1e-12)


def test_round_box_distance_and_bounds_are_analytic():
    """A RoundBox is the exact rounded-box distance: -(min h) - round at the centre, (distance to the box) - round
    outside, and its bounds hold the rounded surface c +- (h + round) along each axis."""
    c, h, rd = np.array([0.2, 0.1, -0.1]), np.array([0.05, 0.02, 0.04]), 0.01
    R = Rotation.from_rotvec([0.3, 0.5, -0.2]).as_matrix()
    box = RoundBox(c, tuple(h), rd, R)
    assert box.sdf(c[None])[0] == pytest.approx(-0.02 - rd, abs=1e-12)
    inner = c + R @ np.array([0.03, 0.0, 0.0])                           # 0.02 from the x faces, 0.02 from the y faces
    assert box.sdf(inner[None])[0] == pytest.approx(-0.02 - rd, abs=1e-12)
    inner2 = c + R @ np.array([0.0, 0.015, 0.0])                        # 0.005 from the y faces
    assert box.sdf(inner2[None])[0] == pytest.approx(-0.005 - rd, abs=1e-12)
    corner = c + R @ (h + np.array([0.03, 0.04, 0.0]))                  # 5 cm from the box's edge
    assert box.sdf(corner[None])[0] == pytest.approx(0.05 - rd, abs=1e-12)
    surf = c + (R * (h + rd)).T                                          # on the rounded faces
    np.testing.assert_allclose(box.sdf(np.concatenate([surf, 2 * c - surf])), 0.0, atol=1e-12)
    for b in (box, RoundBox(c, tuple(h), rd)):
        lo, hi = b.bounds()
        s = np.concatenate([b.c + (b.R * (h + rd)).T, b.c - (b.R * (h + rd)).T])
        np.testing.assert_allclose(b.sdf(s), 0.0, atol=1e-12)
        assert np.all(lo <= s + 1e-12) and np.all(s <= hi + 1e-12)


def test_mirrored_primitives_are_the_mirror_images():
    """p.mirrored() has at x' = (-x, y, z) the distance p has at x, keeps joint, blend radius and sign, and its box is
    the mirrored box: for rotated ellipsoids and boxes and a sweep with a tilted `up`."""
    rng = np.random.default_rng(1)
    R = Rotation.from_rotvec([0.4, -0.9, 0.7]).as_matrix()
    prims = [Ellipsoid((0.3, 0.1, 0.05), (0.08, 0.03, 0.05), R, joint=3, k=0.02),
             RoundBox((0.25, 0.0, 0.1), (0.04, 0.01, 0.03), 0.005, R, joint=4, k=0.01, sub=True),
             Sweep((0.2, 0.0, 0.0), (0.35, 0.1, 0.05), (0.02, 0.04), (0.015, 0.03), up=(0.3, 0.8, 0.5), joint=5)]
    for p in prims:
        q = p.mirrored()
        x = np.asarray(p.c if hasattr(p, "c") else p.a) + rng.normal(scale=0.06, size=(300, 3))
        np.testing.assert_allclose(q.sdf(x * MX), p.sdf(x), atol=1e-12, err_msg=type(p).__name__)
        assert (q.joint, q.k, q.sub) == (p.joint, p.k, p.sub)
        (lo, hi), (mlo, mhi) = p.bounds(), q.bounds()
        np.testing.assert_allclose(mlo, np.minimum(lo * MX, hi * MX), atol=1e-12)
        np.testing.assert_allclose(mhi, np.maximum(lo * MX, hi * MX), atol=1e-12)


# ----------------------------------------------------------------------------- blending, floor, owners
def test_smooth_min_and_max_are_the_polynomial_blend_by_hand():
    """smin(a, b, k) = min(a, b) - max(k - |a - b|, 0)^2 / (4 k) (Quilez's closed form; plain min at k = 0, ties
    included) and smax(a, b, k) = -smin(-a, -b, k)."""
    rng = np.random.default_rng(2)
    a, b = rng.normal(scale=0.05, size=500), rng.normal(scale=0.05, size=500)
    b[:50] = a[:50]                                                       # ties
    for k in (0.01, 0.04):
        np.testing.assert_allclose(smin(a, b, k), _smin_hand(a, b, k), atol=1e-15)
        np.testing.assert_allclose(smax(a, b, k), -_smin_hand(-a, -b, k), atol=1e-15)
    np.testing.assert_array_equal(smin(a, b, 0.0), np.minimum(a, b))
    np.testing.assert_array_equal(smax(a, b, 0.0), np.maximum(a, b))


def test_evaluate_is_the_smooth_union_of_two_spheres_near_the_surface():
    """Body.evaluate of two spheres blended with the same radius k equals the hand-computed smooth union of their exact distances
    wherever that union is near or inside the surface (< 1 cm): the bounding boxes prune nothing that the blend
    needs; a single large sphere reads its exact distance |p - c| - r everywhere in its box."""
    k = 0.04
    A = Ellipsoid((0.0, 0.0, 0.0), (0.05, 0.05, 0.05), joint=1, k=k)
    B = Ellipsoid((0.12, 0.0, 0.0), (0.05, 0.05, 0.05), joint=2, k=k)
    body = Body([A, B], Floor(-10.0, 0.01))
    g, h = np.linspace(-0.1, 0.22, 33), np.linspace(-0.08, 0.08, 17)
    p = np.stack(np.meshgrid(g, h, h, indexing="ij"), -1).reshape(-1, 3)
    d1, d2 = np.linalg.norm(p, axis=1) - 0.05, np.linalg.norm(p - B.c, axis=1) - 0.05
    want = _smin_hand(d1, d2, k)
    got, _ = body.evaluate(p)
    near = want < 0.01
    assert near.sum() > 500
    np.testing.assert_allclose(got[near], want[near], atol=1e-12)
    big = Ellipsoid((0.0, 0.3, 0.0), (0.3, 0.3, 0.3), joint=0, k=0.01)
    lo, hi = big.bounds()
    q = lo + np.random.default_rng(3).random((2000, 3)) * (hi - lo)
    got, _ = Body([big], Floor(-10.0, 0.01)).evaluate(q)
    np.testing.assert_allclose(got, np.linalg.norm(q - big.c, axis=1) - 0.3, atol=1e-12)


def test_owner_is_the_nearest_jointed_additive_primitive():
    """Body.evaluate's owner is the index of the primitive nearest the point (the smallest raw distance) among those
    with a joint (-1: none) that add material: a jointless primitive and a subtracted one never own, and the
    subtracted sphere carves smax(d, -d_sub, k) out of the field."""
    A = Ellipsoid((0.0, 0.0, 0.0), (0.06, 0.06, 0.06), joint=3, k=0.01)
    B = Ellipsoid((0.1, 0.0, 0.0), (0.04, 0.04, 0.04), joint=4, k=0.01)
    C = Ellipsoid((0.05, 0.05, 0.0), (0.03, 0.03, 0.03), k=0.0)                      # no joint
    D = Ellipsoid((-0.04, 0.0, 0.0), (0.025, 0.025, 0.025), joint=5, sub=True, k=0.005)  # a dent in A
    body = Body([A, B, C, D], Floor(-10.0, 0.01))
    rng = np.random.default_rng(4)
    p = rng.uniform((-0.09, -0.07, -0.07), (0.15, 0.09, 0.07), size=(3000, 3))
    p = np.concatenate([p, D.c + rng.normal(scale=0.006, size=(100, 3))])
    dA, dB, dC, dD = (np.linalg.norm(p - e.c, axis=1) - e.rv[0] for e in (A, B, C, D))
    d, owner = body.evaluate(p)
    want = np.where(dA < dB, 0, 1)
    assert not np.isin(owner, (2, 3)).any()
    near = (np.minimum(dA, dB) < 0.02) & (np.abs(dA - dB) > 1e-9)     # within every blend margin of the surface
    assert near.sum() > 500
    np.testing.assert_array_equal(owner[near], want[near])
    u = np.minimum(_smin_hand(dA, dB, 0.01), dC)
    carved = -_smin_hand(-u, dD, 0.005)
    deep = np.linalg.norm(p - D.c, axis=1) < 0.015                      # well inside the dent: all 4 boxes hold it
    assert deep.sum() > 5
    np.testing.assert_allclose(d[deep], carved[deep], atol=1e-12)
    assert np.all(d[deep] > 0)


def test_floor_intersects_the_field_smoothly_with_the_half_space():
    """Near the floor (within 3 cm of its level) the field is the smooth intersection smax(d, level - y, k) of a sphere
    with the half-space y >= level, by hand; the sphere below the floor is cut away."""
    level, k = -1.3, 0.02
    S = Ellipsoid((0.0, level + 0.04, 0.0), (0.08, 0.08, 0.08), joint=0, k=0.01)
    body = Body([S], Floor(level, k))
    rng = np.random.default_rng(5)
    p = rng.uniform((-0.09, level - 0.03, -0.09), (0.09, level + 0.03, 0.09), size=(3000, 3))
    ds = np.linalg.norm(p - S.c, axis=1) - 0.08
    want = -_smin_hand(-ds, p[:, 1] - level, k)
    got, _ = body.evaluate(p)
    np.testing.assert_allclose(got, want, atol=1e-12)
    assert np.all(got[p[:, 1] < level] > 0)


# ----------------------------------------------------------------------------- lenses
def test_the_body_plans_lenses_round_trip_fix_far_points_and_commute_with_the_mirror():
    """The body plan's overlapping hand and head lenses: unwarp(warp(u)) = u, warp is the identity away from every
    ball, and warp(u') = warp(u)' for the mirror ' (the hands' lenses are mirror images, the head's is centred)."""
    _, lenses, _ = body_plan(Proportions())
    rng = np.random.default_rng(6)
    u = np.concatenate([np.asarray(lenses[0].c) + rng.normal(scale=0.35, size=(400, 3)),
                        np.array([0.0, 0.29, 0.015]) + rng.normal(scale=0.3, size=(400, 3))])
    x = warp(u, lenses)
    assert np.abs(x - u).max() > 0.05
    np.testing.assert_allclose(unwarp(x, lenses), u, atol=1e-8)
    np.testing.assert_allclose(warp(u * MX, lenses), x * MX, atol=1e-12)
    far = np.array([[0.0, -1.2, 0.0], [0.3, -0.6, 0.1], [2.5, 0.0, 0.0]])
    np.testing.assert_allclose(warp(far, lenses), far, rtol=0, atol=1e-15)


# ----------------------------------------------------------------------------- anatomy
def test_jitter_stays_in_its_documented_range_about_the_instance_and_is_seeded():
    """Proportions.jittered: each field times (1 + 0.02 n) with n clipped to +-1.5 (so within +-3 %; knee_y within
    +-1.5 cm), relative to the instance's own values; the same seed gives the same proportions, other seeds others."""
    base = Proportions(shoulder_x=0.2, upper_arm=0.3, forearm=0.22, hip_x=0.09, knee_y=-0.9, hand=1.1, girth=0.95)
    names = [f for f in base.__dataclass_fields__ if f != "knee_y"]
    ratios, knee = [], []
    for seed in range(150):
        P = base.jittered(seed)
        assert P == base.jittered(seed)
        ratios.append([getattr(P, f) / getattr(base, f) for f in names])
        knee.append(P.knee_y - base.knee_y)
    ratios, knee = np.array(ratios), np.array(knee)
    assert np.all(np.abs(ratios - 1) <= 0.03 + 1e-12) and np.all(np.abs(knee) <= 0.015 + 1e-12)
    assert np.abs(ratios - 1).max() > 0.029 and np.abs(knee).max() > 0.0145      # the clip is reached
    assert np.std(ratios - 1) == pytest.approx(0.02, rel=0.25)
    assert len({tuple(r) for r in ratios}) == 150


def test_mirror_joint_is_an_involution_between_left_and_right_names():
    """mirror_joint swaps each left_X with right_X (an involution) and fixes every unpaired joint."""
    for j in range(NUM_JOINTS):
        m, n = mirror_joint(j), JOINT_NAMES[j]
        assert mirror_joint(m) == j
        if n.startswith("left_"):
            assert JOINT_NAMES[m] == "right_" + n[5:]
        elif n.startswith("right_"):
            assert JOINT_NAMES[m] == "left_" + n[6:]
        else:
            assert m == j


def test_rest_joints_mirror_and_the_arm_lengths_are_the_proportions():
    """Rest joints: each right joint is the mirror image of its left one, midline joints sit on x = 0, the arm runs
    out along +x by upper_arm then forearm, and seed 0 puts shoulders, elbows and wrists where docs/body_model.md
    says (x = 0.180, 0.445, 0.698 to 2 mm)."""
    P = Proportions(shoulder_x=0.2, upper_arm=0.3, forearm=0.22)
    j = rest_joints(P)
    perm = [mirror_joint(i) for i in range(NUM_JOINTS)]
    np.testing.assert_allclose(j[perm], j * MX, atol=1e-15)
    S, E, W = j[JI["left_shoulder"]], j[JI["left_elbow"]], j[JI["left_wrist"]]
    assert (S[0], E[0] - S[0], W[0] - E[0]) == pytest.approx((0.2, 0.3, 0.22), abs=1e-12)
    j0 = rest_joints(Proportions().jittered(0))
    for n, x in (("left_shoulder", 0.180), ("left_elbow", 0.445), ("left_wrist", 0.698)):
        assert j0[JI[n], 0] == pytest.approx(x, abs=2e-3) and j0[JI["right" + n[4:]], 0] == pytest.approx(-x, abs=2e-3)


def test_hand_layout_scales_with_the_hand_proportion_and_chains_use_unit_directions():
    """P.hand scales the whole hand layout (joints, tips and radii, relative to the wrist) by the same factor; a
    3-bone chain with non-unit directions places its joints at exactly the given bone lengths."""
    h1, h2 = left_hand(Proportions(hand=1.0)), left_hand(Proportions(hand=1.25))
    for f in FINGERS:
        np.testing.assert_allclose(h2[f].joints, 1.25 * h1[f].joints, atol=1e-15)
        np.testing.assert_allclose(h2[f].tip, 1.25 * h1[f].tip, atol=1e-15)
        np.testing.assert_allclose(h2[f].radii, 1.25 * np.array(h1[f].radii), atol=1e-15)
    joints, tip = _chain((0.1, 0.2, 0.3), [(3.0, 0.0, 4.0), (0.0, 2.0, 0.0), (1.0, 1.0, 1.0)], (0.05, 0.02, 0.01))
    pts = np.vstack([joints, tip])
    np.testing.assert_allclose(np.linalg.norm(np.diff(pts, axis=0), axis=1), (0.05, 0.02, 0.01), atol=1e-15)
    np.testing.assert_allclose(pts[1] - pts[0], 0.05 * np.array([0.6, 0.0, 0.8]), atol=1e-15)


def test_body_plan_is_mirror_symmetric_and_fingertip_targets_lie_on_its_surface():
    """Every primitive of the body plan has a joint (docs/body_model.md: each owned by the joint that will skin it),
    as many for each joint as for its mirror; the field is mirror symmetric away from the midline (distance at x'
    equals that at x, and the owning primitive's joint is the mirrored joint), and every fingertip landmark target lies on the zero level set
    (the tip of the finger's last phalanx, on both hands)."""
    P = Proportions().jittered(0)
    body, _, joints = body_plan(P)
    owners = [q.joint for q in body.prims]                   # each primitive owned by the joint that skins it
    assert min(owners) >= 0 and all(owners.count(j) == owners.count(mirror_joint(j)) for j in owners)
    rng = np.random.default_rng(7)
    p = np.concatenate([joints[JI[n]] + rng.normal(scale=0.05, size=(300, 3))
                        for n in ("left_wrist", "left_elbow", "left_shoulder", "left_knee", "left_ankle")])
    p = p[p[:, 0] > 0.05]                    # off the midline, where no left part blends with a right one
    d, o = body.evaluate(p)
    dm, om = body.evaluate(p * MX)
    np.testing.assert_allclose(dm, d, atol=1e-9)
    hit = o >= 0
    assert hit.sum() > 1000 and np.array_equal(om >= 0, hit)
    jo = np.array([body.prims[i].joint for i in o[hit]])
    jm = np.array([body.prims[i].joint for i in om[hit]])
    np.testing.assert_array_equal(jm, [mirror_joint(j) for j in jo])
    T = landmark_targets(P, joints)
    tips = np.array([T[s + f] for f in FINGERS for s in "lr"])
    dt, _ = body.evaluate(tips)
    np.testing.assert_allclose(dt, 0.0, atol=5e-4)
