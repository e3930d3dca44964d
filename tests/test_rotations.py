"""Rotation conversions against scipy's Rotation, by round trips, at angle 0 and near pi, and by gradcheck."""
import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

from graspkit import rotations as rot


def _random_aa(n: int, seed: int = 0) -> np.ndarray:
    """Axis-angle vectors with angles spread over [0, pi), plus exact 0, tiny and near-pi angles."""
    rng = np.random.default_rng(seed)
    axes = rng.normal(size=(n, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    angles = rng.uniform(0, np.pi, n)
    angles[:4] = [0.0, 1e-9, 1e-4, np.pi - 1e-7]
    return axes * angles[:, None]


def test_axis_angle_to_matrix_matches_scipy():
    aa = _random_aa(500)
    ours = rot.axis_angle_to_matrix(torch.from_numpy(aa)).numpy()
    np.testing.assert_allclose(ours, Rotation.from_rotvec(aa).as_matrix(), atol=1e-12)


def test_matrix_to_quaternion_matches_scipy_up_to_sign():
    R = Rotation.random(500, random_state=1).as_matrix()
    q = rot.matrix_to_quaternion(torch.from_numpy(R)).numpy()
    ref = Rotation.from_matrix(R).as_quat()[:, [3, 0, 1, 2]]  # scipy is scalar-last
    ref *= np.sign(ref[:, :1] + 1e-300)
    np.testing.assert_allclose(q, ref, atol=1e-10)


def test_matrix_to_axis_angle_matches_scipy_including_near_pi():
    aa = _random_aa(500, seed=2)
    R = Rotation.from_rotvec(aa).as_matrix()
    ours = rot.matrix_to_axis_angle(torch.from_numpy(R)).numpy()
    # compare as rotations (near pi, v and -v describe the same rotation)
    np.testing.assert_allclose(Rotation.from_rotvec(ours).as_matrix(), R, atol=1e-6)
    far = np.linalg.norm(aa, axis=1) < np.pi - 1e-3
    np.testing.assert_allclose(ours[far], aa[far], atol=1e-8)


@pytest.mark.parametrize("pair", [
    (rot.axis_angle_to_quaternion, rot.quaternion_to_axis_angle),
    (rot.axis_angle_to_rot6d, rot.rot6d_to_axis_angle),
])
def test_axis_angle_round_trips(pair):
    fwd, back = pair
    aa = torch.from_numpy(_random_aa(300, seed=3))
    keep = aa.norm(dim=-1) < np.pi - 1e-3
    np.testing.assert_allclose(back(fwd(aa))[keep].numpy(), aa[keep].numpy(), atol=1e-7)


def test_quaternion_matrix_round_trip_and_scipy():
    q = torch.from_numpy(Rotation.random(200, random_state=4).as_quat()[:, [3, 0, 1, 2]])
    R = rot.quaternion_to_matrix(q)
    np.testing.assert_allclose(R.numpy(), Rotation.from_quat(q.numpy()[:, [1, 2, 3, 0]]).as_matrix(), atol=1e-12)
    q2 = rot.matrix_to_quaternion(R)
    np.testing.assert_allclose((q2 * q).sum(-1).abs().numpy(), 1.0, atol=1e-10)


def test_rot6d_gram_schmidt_projects_noisy_input_to_a_rotation():
    d6 = torch.randn(100, 6, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    R = rot.rot6d_to_matrix(d6)
    eye = torch.eye(3, dtype=torch.float64).expand_as(R)
    np.testing.assert_allclose((R.transpose(1, 2) @ R).numpy(), eye.numpy(), atol=1e-12)
    np.testing.assert_allclose(torch.linalg.det(R).numpy(), 1.0, atol=1e-12)
    # the first column keeps the direction of the first 3 numbers
    np.testing.assert_allclose(R[:, :, 0].numpy(), torch.nn.functional.normalize(d6[:, :3], dim=-1).numpy())


def test_gradients_finite_at_zero_and_gradcheck():
    aa = torch.zeros(2, 3, dtype=torch.float64, requires_grad=True)
    rot.axis_angle_to_matrix(aa).sum().backward()
    assert torch.isfinite(aa.grad).all()
    x = torch.from_numpy(_random_aa(6, seed=5)[4:]).requires_grad_(True)
    assert torch.autograd.gradcheck(rot.axis_angle_to_matrix, (x,))
    assert torch.autograd.gradcheck(rot.matrix_to_axis_angle, (rot.axis_angle_to_matrix(x.detach()).requires_grad_(True),))
    d6 = torch.randn(3, 6, dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(rot.rot6d_to_matrix, (d6,))


def test_rotation_about_z_matches_scipy():
    a = torch.linspace(-3, 3, 7, dtype=torch.float64)
    ref = Rotation.from_euler("z", a.numpy()[:, None]).as_matrix()
    np.testing.assert_allclose(rot.rotation_about_z(a).numpy(), ref, atol=1e-12)


def test_bad_shape_names_argument():
    with pytest.raises(ValueError, match="aa"):
        rot.axis_angle_to_matrix(torch.zeros(4, 2))


@pytest.mark.parametrize("dtype", [torch.float16, torch.bfloat16])
def test_half_precision_zero_angle_is_the_identity_and_others_match_scipy(dtype):
    """In float16 the series threshold 1e-12 rounds to 0: a zero angle once took sin(t)/t = 0/0 (NaN bodies)."""
    aa = _random_aa(64, seed=3)
    R = rot.axis_angle_to_matrix(torch.as_tensor(aa, dtype=dtype))
    q = rot.axis_angle_to_quaternion(torch.as_tensor(aa, dtype=dtype))
    assert torch.isfinite(R).all() and torch.isfinite(q).all()
    assert torch.equal(R[0].float(), torch.eye(3)) and torch.equal(q[0].float(), torch.tensor([1.0, 0, 0, 0]))
    tol = 4e-3 if dtype == torch.float16 else 3e-2
    assert np.allclose(R.float().numpy(), Rotation.from_rotvec(aa).as_matrix(), atol=tol)
