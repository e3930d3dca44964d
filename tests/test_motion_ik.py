"""Rotation helpers and analytic two-bone IK against scipy and closed-form truths."""
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from graspkit.data.ik import (axis_angle_matrix, frame, matrix_axis_angle, normalize, rot_x, rot_y, rot_z, smoothstep,
                              two_bone_ik, wrap_angle)


def _is_rotation(R):
    return np.allclose(R @ np.swapaxes(R, -1, -2), np.eye(3), atol=1e-9) and np.allclose(np.linalg.det(R), 1, atol=1e-9)


def test_axis_angle_round_trip_matches_scipy_including_near_pi():
    rng = np.random.default_rng(0)
    aa = rng.normal(size=(200, 3))
    aa[:20] *= (np.pi - 1e-7) / np.linalg.norm(aa[:20], axis=1, keepdims=True)   # angles at pi
    aa[20:40] *= 1e-9                                                                 # and near zero
    R = axis_angle_matrix(aa)
    assert np.allclose(R, Rotation.from_rotvec(aa).as_matrix(), atol=1e-9)
    back = matrix_axis_angle(R)
    assert np.allclose(axis_angle_matrix(back), R, atol=1e-7)
    assert np.allclose(back[40:], Rotation.from_matrix(R[40:]).as_rotvec(), atol=1e-7)


def test_two_bone_ik_reaches_reachable_targets_with_exact_bone_lengths_and_pole_side():
    rng = np.random.default_rng(1)
    n = 500
    b1, b2 = np.array([0.01, -0.375, 0.005]), np.array([-0.008, -0.41, -0.045])
    root = rng.normal(size=(n, 3))
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    target = root + d * rng.uniform(0.1, 0.75, (n, 1))
    pole = rng.normal(size=(n, 3))
    R1, R2, mid = two_bone_ik(root, target, pole, b1, b2, np.array([0.0, 0.0, 1.0]))
    assert _is_rotation(R1) and _is_rotation(R2)
    assert np.allclose(root + R1 @ b1, mid, atol=1e-9)                       # rest bones land on the solved chain
    assert np.allclose(mid + R2 @ b2, target, atol=1e-9)
    # the middle joint bends towards the pole: it lies on the pole's side of the root-target line
    a = (target - root) / np.linalg.norm(target - root, axis=1, keepdims=True)
    off = (mid - root) - ((mid - root) * a).sum(1, keepdims=True) * a
    p_perp = pole - (pole * a).sum(1, keepdims=True) * a
    assert ((off * p_perp).sum(1) > 0).all()
    assert np.allclose(np.linalg.norm(np.cross(off, p_perp), axis=1) / np.linalg.norm(off, axis=1)
                       / np.linalg.norm(p_perp, axis=1), 0, atol=1e-9)      # in the pole plane


def test_two_bone_ik_middle_joint_is_a_hinge_for_collinear_rest_bones():
    b1, b2 = np.array([0, -0.4, 0.0]), np.array([0, -0.4, 0.0])
    rng = np.random.default_rng(2)
    d = rng.normal(size=(50, 3))
    root, target = np.zeros((50, 3)), d / np.linalg.norm(d, axis=1, keepdims=True) * rng.uniform(0.05, 0.79, (50, 1))
    R1, R2, _ = two_bone_ik(root, target, rng.normal(size=(50, 3)), b1, b2, np.array([0.0, 0.0, 1.0]))
    local = np.swapaxes(R1, -1, -2) @ R2
    aa = matrix_axis_angle(local)
    assert np.allclose(aa[:, 1:], 0, atol=1e-9)            # a rotation about x only (the knee hinge)
    assert (aa[:, 0] >= -1e-9).all()                        # flexion in one direction: the knee never bends backwards
    dist = np.linalg.norm(target, axis=1)                   # and the law of cosines gives its angle
    assert np.allclose(np.cos(np.pi - aa[:, 0]), (0.32 - dist**2) / 0.32, atol=1e-9)


def test_two_bone_ik_out_of_reach_stretches_towards_the_target():
    b = np.array([0, -0.4, 0.0])
    R1, R2, mid = two_bone_ik(np.zeros(3), np.array([2.0, 0, 0]), np.array([0, 0, 1.0]), b, b, np.array([0, 0, 1.0]),
                              max_stretch=0.999)
    end = mid + R2 @ b
    assert np.allclose(end, [0.8 * 0.999, 0, 0], atol=1e-9)


def test_two_bone_ik_soft_limit_bends_gradually_as_a_target_sweeps_into_reach():
    b = np.array([0, -0.4, 0.0])
    d = np.linspace(1.2, 0.4, 801)                          # 1 mm steps, from beyond reach (0.8 m) to well within
    target = np.stack([d, np.zeros_like(d), np.zeros_like(d)], 1)
    bend = lambda R1, R2: np.arccos(np.clip(((np.swapaxes(R1, -1, -2) @ R2).trace(axis1=-2, axis2=-1) - 1) / 2, -1, 1))
    R1h, R2h, _ = two_bone_ik(np.zeros((801, 3)), target, np.array([0, 0, 1.0]), b, b, np.array([0, 0, 1.0]))
    R1s, R2s, mids = two_bone_ik(np.zeros((801, 3)), target, np.array([0, 0, 1.0]), b, b, np.array([0, 0, 1.0]),
                                 soft=0.15)
    # the end's distance: exact below the soft zone, then reach - w exp(-(d - (reach - w)) / w)
    reach, w = 0.9995 * 0.8, 0.15 * 0.8
    want = np.where(d > reach - w, reach - w * np.exp(-(d - reach + w) / w), d)
    assert np.allclose(np.linalg.norm(mids + R2s @ b, axis=1), want, atol=1e-9)
    assert np.allclose((mids + R2s @ b)[d < reach - w], target[d < reach - w], atol=1e-9)
    hard, soft = np.abs(np.diff(bend(R1h, R2h))), np.abs(np.diff(bend(R1s, R2s)))
    # hard limit: the bend jumps as the target crosses full stretch (the square-root law); soft: at most the rate at
    # the soft zone's edge, d(bend)/d(dist) = 1 / (l sin(bend / 2)) for two bones of length l (0.27 deg per mm here)
    assert np.degrees(hard.max()) > 2.0 and np.degrees(soft.max()) < 0.5
    assert soft.max() < 0.25 * hard.max()


def test_two_bone_ik_names_a_pole_along_the_reach_and_a_target_at_the_root():
    """Both left the bend plane undefined and returned matrices with determinant 0 without a word (an independent
    check); a pole slightly off the reach still solves, with proper rotations."""
    b, bend = np.array([0, -0.4, 0.0]), np.array([0, 0, 1.0])
    with pytest.raises(ValueError, match="pole: expected a direction not parallel"):
        two_bone_ik(np.zeros(3), np.array([0, 0, -0.5]), np.array([0, 0, 1.0]), b, b, bend)
    with pytest.raises(ValueError, match="target: expected a target away from root"):
        two_bone_ik(np.ones(3), np.ones(3), np.array([0, 0, 1.0]), b, b, bend)
    R1, R2, _ = two_bone_ik(np.zeros(3), np.array([0, 0, -0.5]), np.array([1e-6, 0, 1.0]), b, b, bend)
    for R in (R1, R2):
        np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-9)
        assert abs(np.linalg.det(R) - 1) < 1e-9


def test_smoothstep_and_wrap_angle():
    u = np.linspace(-0.5, 1.5, 201)
    s = smoothstep(u)
    assert s[0] == 0 and s[-1] == 1 and np.all(np.diff(s) >= 0)
    assert np.isclose(smoothstep(np.array(0.5)), 0.5)
    assert np.allclose(wrap_angle(np.array([3 * np.pi, -3 * np.pi / 2, 0.1])), [np.pi, np.pi / 2, 0.1])


def test_axis_rotations_turn_by_plus_angle_as_scipy():
    a = np.random.default_rng(0).uniform(-3, 3, 7)
    for f, ax in ((rot_x, "x"), (rot_y, "y"), (rot_z, "z")):
        np.testing.assert_allclose(f(a), Rotation.from_euler(ax, a[:, None]).as_matrix(), atol=1e-12, err_msg=ax)
    np.testing.assert_allclose(rot_z(np.pi / 2) @ [1.0, 0, 0], [0, 1.0, 0], atol=1e-12)     # +x turns to +y


def test_frame_is_a_proper_rotation_with_the_given_axes():
    """frame(a, b): columns a, b made perpendicular to a, and a x b: a rotation, never a reflection."""
    rng = np.random.default_rng(1)
    a, b = rng.normal(size=(50, 3)), rng.normal(size=(50, 3))
    F = frame(a, b)
    assert _is_rotation(F)
    np.testing.assert_allclose(F[..., 0], a / np.linalg.norm(a, axis=1, keepdims=True), atol=1e-12)
    np.testing.assert_allclose(frame(np.array([1.0, 0, 0]), np.array([0.3, 1.0, 0])), np.eye(3), atol=1e-12)


def test_normalize_gives_unit_directions_and_keeps_zero_vectors_zero():
    """normalize: a batch of vectors -> unit vectors along them (|v| and v/|v| by hand); zero vectors stay zero (docstring),
    never NaN."""
    rng = np.random.default_rng(0)
    v = rng.normal(size=(4, 5, 3))
    v[1, 2] = 0.0
    with np.errstate(all="raise"):
        u = normalize(v)
    n = np.linalg.norm(v, axis=-1)
    ok = n > 0
    np.testing.assert_allclose(np.linalg.norm(u, axis=-1)[ok], 1.0, atol=1e-12)
    np.testing.assert_allclose(u[ok] * n[ok][:, None], v[ok], atol=1e-12)
    np.testing.assert_array_equal(u[1, 2], 0.0)


def test_matrix_axis_angle_matches_scipy_close_to_pi_and_for_batched_leading_dims():
    """matrix_axis_angle against scipy's as_rotvec for angles in (pi/2, pi - 1e-4] about random axes (the branches of
    Shepperd's method on the diagonal, where the rotation vector is still unique) and for a (2, 3, 3, 3) batch."""
    rng = np.random.default_rng(3)
    ax = rng.normal(size=(300, 3))
    ax /= np.linalg.norm(ax, axis=1, keepdims=True)
    ang = rng.uniform(np.pi / 2, np.pi - 1e-4, (300, 1))
    for k in range(3):                                   # axes close to each coordinate axis: each diagonal case
        ax[100 * k:100 * k + 50, k] += 3.0
    ax /= np.linalg.norm(ax, axis=1, keepdims=True)
    rv = ax * ang
    R = Rotation.from_rotvec(rv).as_matrix()
    np.testing.assert_allclose(matrix_axis_angle(R), rv, atol=1e-8)
    Rb = R[:18].reshape(2, 3, 3, 3, 3)
    np.testing.assert_allclose(matrix_axis_angle(Rb), rv[:18].reshape(2, 3, 3, 3), atol=1e-8)


def test_two_bone_ik_with_per_item_bones_matches_one_chain_at_a_time():
    """Bones given per item (n, 3) (docstring: "(3,) or (..., 3)"): each item's chain keeps its own bone lengths, its end
    lands on its reachable target by forward kinematics, and it equals the same chain solved alone with (3,) bones."""
    rng = np.random.default_rng(4)
    n = 6
    b1 = rng.normal(size=(n, 3)) * 0.05 + np.array([0, -0.3, 0])
    b2 = rng.normal(size=(n, 3)) * 0.05 + np.array([0, -0.25, 0])
    b1 *= rng.uniform(0.6, 1.6, (n, 1))
    l1, l2 = np.linalg.norm(b1, axis=1), np.linalg.norm(b2, axis=1)
    root = rng.normal(size=(n, 3))
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    target = root + d * (np.abs(l1 - l2) + rng.uniform(0.2, 0.8, n) * (l1 + l2 - np.abs(l1 - l2)))[:, None]
    pole, bend = rng.normal(size=(n, 3)), np.array([0.0, 0.0, 1.0])
    R1, R2, mid = two_bone_ik(root, target, pole, b1, b2, bend)
    np.testing.assert_allclose(np.linalg.norm(mid - root, axis=1), l1, atol=1e-9)
    np.testing.assert_allclose(root + np.einsum("nij,nj->ni", R1, b1), mid, atol=1e-9)
    np.testing.assert_allclose(mid + np.einsum("nij,nj->ni", R2, b2), target, atol=1e-9)
    for k in range(n):
        r1, r2, m = two_bone_ik(root[k], target[k], pole[k], b1[k], b2[k], bend)
        np.testing.assert_allclose(r1, R1[k], atol=1e-12)
        np.testing.assert_allclose(r2, R2[k], atol=1e-12)
        np.testing.assert_allclose(m, mid[k], atol=1e-12)


def test_smoothstep_is_the_minimum_jerk_quintic():
    """smoothstep is 10u^3 - 15u^4 + 6u^5 (docstring): hand values at u = 1/4, 3/4, and zero velocity and zero
    acceleration at both ends (finite differences), which the cubic 3u^2 - 2u^3 lacks."""
    assert smoothstep(np.array(0.25)) == pytest.approx(10 / 64 - 15 / 256 + 6 / 1024, abs=1e-12)
    assert smoothstep(np.array(0.75)) == pytest.approx(1 - (10 / 64 - 15 / 256 + 6 / 1024), abs=1e-12)
    h = 1e-4
    for uu in (np.array([0.0, h, 2 * h]), np.array([1.0, 1 - h, 1 - 2 * h])):     # one-sided at each end
        s = smoothstep(uu)
        assert abs((s[1] - s[0]) / h) < 1e-6                       # velocity (the cubic's is 6u there: 6e-4)
        assert abs((s[2] - 2 * s[1] + s[0]) / h**2) < 0.01         # acceleration (the cubic's is 6 there)
