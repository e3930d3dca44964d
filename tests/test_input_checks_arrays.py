"""Inputs of the kinds real code passes (found by an independent check): wide betas, float64 starts, integer points,
4-D clouds, optimisers called under torch.no_grad() or torch.inference_mode()."""
import math

import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

from graspkit import eval_wandr as E
from graspkit.body import BodyModel
from graspkit.body.markers import goal_vertices
from graspkit.models import wandr as W
from graspkit.models.gnet import SparseBody, pose_rotmats
from graspkit.objects import ObjectPose, apply_pose, bps_basis, bps_encode
from graspkit.optim.goal_refine import GraspRefiner, refine_frame
from graspkit.optim.latent import optimise_latents
from graspkit.paths import DATA_STUBS, default_model_path
from graspkit.rotations import axis_angle_to_rot6d


@pytest.fixture(scope="module")
def bm():
    return BodyModel.from_file(default_model_path())


@pytest.fixture(scope="module")
def start():
    return E.starts_from_meta(W.load_wandr(DATA_STUBS / "checkpoints" / "wandr.pt").meta)[0]


def _tiny_wandr():
    torch.manual_seed(0)
    return W.WandrCVAE(W.WandrConfig(latent=4, hidden=32, enc_layers=1, dec_layers=2, dropout=0.0)).eval()


def test_sparse_body_refuses_betas_the_model_would_read_as_expression(bm):
    """SparseBody stacks [betas, expression]: betas 11-16 (an AMASS file's 16) had become the face's expression."""
    body = SparseBody(bm, torch.arange(0, bm.num_vertices, 97))
    rot = pose_rotmats(axis_angle_to_rot6d(torch.zeros(2, 55, 3)))
    with pytest.raises(ValueError, match=rf"^betas: expected \(B or 1, k\) with k <= {bm.num_betas} .* got \(2, 16\)"):
        body(rot, torch.zeros(2, 16), torch.zeros(2, 3))
    with pytest.raises(ValueError, match=r"^rot: expected \(B, 55, 3, 3\) with B >= 1, got \(0, 55, 3, 3\)"):
        body(rot[:0], torch.zeros(0, 10), torch.zeros(0, 3))
    with pytest.raises(ValueError, match=r"^transl: expected \(2, 3\) or \(1, 3\), got \(3,\)"):
        body(rot, torch.zeros(2, 10), torch.zeros(3))
    b = torch.randn(1, 10, generator=torch.Generator().manual_seed(1))
    v, _ = body(rot, b, torch.zeros(1, 3))                            # (1, k) betas and (1, 3) transl broadcast
    full = bm.forward_rotmats(rot, betas=b.expand(2, -1)).vertices[:, body.ids]
    torch.testing.assert_close(v, full, atol=2e-6, rtol=0)


def test_grasp_refiner_names_betas_wider_than_the_model(bm):
    ref = GraspRefiner(bm, goal_vertices(bm))
    hat = {"rot6d": torch.zeros(1, 55, 6), "transl": torch.zeros(1, 3), "head_dir": torch.zeros(1, 3),
           "hand_offsets": torch.zeros(1, 99, 3)}
    want = rf"^betas: expected finite shape coefficients \(1 or B = 1, k <= {bm.num_betas}\)"
    with pytest.raises(ValueError, match=want):
        ref(hat, torch.zeros(1, 16), torch.zeros(50, 3))


def _frame_inputs(bm):
    gv = goal_vertices(bm)
    hand = SparseBody(bm, torch.as_tensor(gv.vertex_ids[gv.right_hand]))
    aa = torch.zeros(1, 55, 3)
    aa[0, 0] = torch.tensor([math.pi / 2, 0, 0])
    r6, t, betas = axis_angle_to_rot6d(aa), torch.zeros(1, 3), torch.zeros(1, 10)
    target = hand(pose_rotmats(r6), betas, t)[0] + torch.tensor([0.02, 0.0, -0.01])
    return hand, r6, t, betas, target


def test_optimisers_run_under_no_grad_and_name_inference_mode(bm, start):
    """Sampling pipelines run under torch.no_grad(); an optimiser called there had failed with autograd's bare
    'element 0 of tensors does not require grad'. Now the same numbers as outside; inference mode is named."""
    args = _frame_inputs(bm)
    free = refine_frame(*args)
    with torch.no_grad():
        quiet = refine_frame(*args)
    for a, b in zip(free, quiet):
        assert torch.equal(a, b)
    assert not torch.equal(free[1], args[2])                         # it did move towards the shifted target
    with torch.inference_mode(), pytest.raises(RuntimeError, match=r"^refine_frame: cannot optimise under "
                                                                   r"torch.inference_mode\(\)"):
        refine_frame(*args)
    model, goal, z0 = _tiny_wandr(), torch.tensor([0.6, 0.2, 1.0]), torch.ones(1, 5, 4)
    free = optimise_latents(model, start, goal, t_goal=5, z0=z0, iters=2)
    with torch.no_grad():
        quiet = optimise_latents(model, start, goal, t_goal=5, z0=z0, iters=2)
    assert torch.equal(free.z, quiet.z) and free.history == quiet.history
    with torch.inference_mode(), pytest.raises(RuntimeError, match=r"^optimise_latents: cannot optimise"):
        optimise_latents(model, start, goal, t_goal=5, z0=z0, iters=2)


def test_wandr_rollout_casts_float64_starts_to_the_model(start):
    """float64 poses (torch.tensor of numpy data) on the float32 model had failed inside the decoder's matmul."""
    model = _tiny_wandr()
    pp, p0, rest = start.p_prev[None], start.p[None], start.rest[None]
    goal = torch.tensor([[1.0, 0.5, 1.0]])
    a = W.rollout(model, pp, p0, rest, goal, 10, 6, generator=torch.Generator().manual_seed(3))
    b = W.rollout(model, pp.double(), p0.double(), rest.double(), goal.double(), 10, 6,
                  generator=torch.Generator().manual_seed(3))
    assert b.p.dtype == torch.float32
    assert torch.equal(a.p, b.p)                      # the float32 starts are exactly representable in float64


def test_apply_pose_takes_integer_tensors_and_lists_as_numbers():
    """An integer tensor had the pose cast to integers (all zeros out); a list failed on `.shape`."""
    pose = ObjectPose.from_yaw(0.7, (0.3, -0.2, 1.1))
    x = np.array([[1, 0, 0], [0, 2, 0], [3, -1, 2]])
    want = Rotation.from_euler("z", 0.7).apply(x) + [0.3, -0.2, 1.1]
    got = apply_pose(pose, torch.as_tensor(x))
    assert got.dtype == torch.get_default_dtype()
    np.testing.assert_allclose(got.numpy(), want, atol=1e-6)
    np.testing.assert_allclose(apply_pose(pose, x.tolist()), want, atol=1e-12)
    with pytest.raises(ValueError, match=r"^x: expected an array of numbers of shape \(\.\.\., 3\), got list"):
        apply_pose(pose, [[1.0, 0.0], [1.0]])


def test_bps_encode_names_its_own_argument_for_a_4d_cloud():
    with pytest.raises(ValueError, match=r"^points: expected \(N, 3\) or \(B, N, 3\), got \(2, 3, 64, 3\)"):
        bps_encode(torch.zeros(2, 3, 64, 3), bps_basis())
