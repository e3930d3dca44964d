"""Bad inputs to the model loaders and samplers (GNet, WholeGrasp-VAE, PointNet++, WANDR) and to BodyModel give a
clear ValueError / TypeError naming the argument or the file, never a deep torch error or a silent NaN answer."""
import copy
import dataclasses
from pathlib import Path

import numpy as np
import pytest
import torch

from graspkit.body import BodyModel
from graspkit.body.model import ModelFileError
from graspkit.eval_wandr import starts_from_meta
from graspkit.models.gnet import GNet, load_gnet
from graspkit.models.pointnet2 import PointNet2Encoder
from graspkit.models.wandr import generate, load_wandr
from graspkit.models.wholegrasp import WholeGraspVAE, load_wholegrasp
from graspkit.paths import default_model_path

CK = Path(__file__).resolve().parents[1] / "data_stubs" / "checkpoints"
NAN = float("nan")


# ------------------------------------------------------------------------------------------------ loaders
def test_load_wholegrasp_names_the_file_of_another_models_checkpoint():
    with pytest.raises(ValueError, match=r"gnet\.pt: not a WholeGrasp-VAE checkpoint"):
        load_wholegrasp(CK / "gnet.pt")


def test_load_gnet_names_the_file_of_a_foreign_config_or_missing_weights(tmp_path):
    odd = tmp_path / "odd.pt"
    torch.save({"kind": "gnet", "config": {"enc_width": 3}, "model": {}}, odd)
    with pytest.raises(ValueError, match=r"odd\.pt: not a gnet checkpoint.*enc_width"):
        load_gnet(odd)
    bare = tmp_path / "bare.pt"
    torch.save({"kind": "gnet", "config": {}}, bare)
    with pytest.raises(ValueError, match=r"bare\.pt: not a gnet checkpoint"):
        load_gnet(bare)
    state = torch.load(CK / "wandr.pt", weights_only=True)            # the same check in load_wandr
    state["wandr_config"] = {**state["wandr_config"], "enc_width": 3}
    torch.save(state, odd)
    with pytest.raises(ValueError, match=r"odd\.pt: not a WANDR checkpoint.*enc_width.*WandrConfig"):
        load_wandr(odd)


# ------------------------------------------------------------------------------------------------ GNet.sample
@pytest.fixture(scope="module")
def gnet():
    torch.manual_seed(0)
    return GNet().eval()


def _gnet_inputs():
    g = torch.Generator().manual_seed(3)
    return torch.rand(2, 1024, generator=g), torch.rand(2, 3, generator=g), torch.rand(2, 10, generator=g)


def test_gnet_sample_converts_float64_to_the_models_dtype(gnet):
    bps, ot, be = _gnet_inputs()
    a = gnet.sample(bps, ot, be, generator=torch.Generator().manual_seed(1))
    b = gnet.sample(bps.double(), ot.double(), be.double(), generator=torch.Generator().manual_seed(1))
    for k in a:
        assert b[k].dtype == torch.float32 and torch.equal(a[k], b[k])


def test_gnet_sample_rejects_nan_bad_z_and_unbatched_inputs(gnet):
    bps, ot, be = _gnet_inputs()
    with pytest.raises(ValueError, match="bps: contains NaN"):
        gnet.sample(bps * NAN, ot, be)
    with pytest.raises(ValueError, match="betas: contains NaN"):
        gnet.sample(bps, ot, be * NAN)
    with pytest.raises(ValueError, match=r"z: expected a tensor of shape \(2, 16\)"):
        gnet.sample(bps, ot, be, z=torch.zeros(2, 8))
    with pytest.raises(TypeError, match="z: expected a floating-point tensor"):
        gnet.sample(bps, ot, be, z=torch.zeros(2, 16, dtype=torch.long))
    with pytest.raises(ValueError, match=r"bps: expected a tensor of shape \(B, 1024\)"):
        gnet.sample(bps[0], ot[0], be[0])
    with pytest.raises(ValueError, match="bps: expected distances >= 0"):     # a sign slip was sampled from
        gnet.sample(-bps, ot, be)


# ------------------------------------------------------------------------------------------------ WholeGrasp-VAE
@pytest.fixture(scope="module")
def wholegrasp():
    torch.manual_seed(0)
    return WholeGraspVAE().eval()


def _cloud(n: int):
    g = torch.Generator().manual_seed(0)
    return torch.rand(n, 3, generator=g) * 0.1, torch.nn.functional.normalize(torch.randn(n, 3, generator=g), dim=-1)


def test_wholegrasp_sample_rejects_nan_and_too_few_points(wholegrasp):
    pts, nrm = _cloud(300)
    bad = pts.clone()
    bad[5, 1] = NAN
    with pytest.raises(ValueError, match="object_points: contains NaN"):
        wholegrasp.sample(bad, nrm)
    with pytest.raises(ValueError, match="object_normals: contains NaN"):
        wholegrasp.sample(pts, nrm * NAN)
    with pytest.raises(ValueError, match="object_height: contains NaN"):
        wholegrasp.sample(pts, nrm, object_height=NAN)
    for k in (100, 0):
        with pytest.raises(ValueError, match=f"object_points: expected at least 256 points.*got {k}"):
            wholegrasp.sample(pts[:k], nrm[:k])


def test_wholegrasp_and_grasppose_refuse_millimetres(wholegrasp):
    """An object in millimetres (points spanning metres, a height of 850) is refused by name: the network would
    place markers metres away without a word."""
    from graspkit.optim.grasppose import GraspObject
    pts, nrm = _cloud(300)
    with pytest.raises(ValueError, match="object_points: largest side 99.*metres"):
        wholegrasp.sample(pts * 1000, nrm)
    for h in (850.0, -0.2, torch.tensor([900.0])):
        with pytest.raises(ValueError, match="object_height: .*expected an object-centre height in metres"):
            wholegrasp.sample(pts, nrm, object_height=h, n=2)
    for h, name in ((torch.tensor([0.8, 0.9]), "object_height"), ("abc", "object_height")):   # one object, one height
        with pytest.raises(ValueError, match=f"{name}: expected"):
            wholegrasp.sample(pts, nrm, object_height=h, n=2)
    with pytest.raises(ValueError, match=r"centre: expected a point \(3,\)"):
        wholegrasp.sample(pts, nrm, centre=torch.zeros(2))
    with pytest.raises(TypeError, match="generator: expected a torch.Generator"):
        wholegrasp.sample(pts, nrm, generator=0)
    from graspkit.optim.grasppose import GraspObject
    for R in (2 * torch.eye(3), torch.diag(torch.tensor([1.0, 1.0, -1.0]))):    # a scale, a mirror
        with pytest.raises(ValueError, match="rotation: expected a rotation matrix"):
            GraspObject(pts, nrm, 0.8, rotation=R)
    assert wholegrasp.sample(pts, nrm, object_height=0.0).markers.shape[0] == 1     # an object on the floor is fine
    with pytest.raises(ValueError, match="points: largest side"):
        GraspObject(pts * 1000, nrm, 0.8)
    with pytest.raises(ValueError, match="height: 850"):
        GraspObject(pts, nrm, 850.0)


def test_wholegrasp_and_grasppose_refuse_normals_that_are_not_unit(wholegrasp):
    """SAGA's object input is xyz + unit surface normal (App. A.2): normals scaled by 2 moved the sampled markers by
    4 mm and zero normals silently switched off E^B_colli's point-cloud sign (an independent check); both refused."""
    from graspkit.optim.grasppose import GraspObject
    pts, nrm = _cloud(300)
    for bad in (nrm * 2, nrm * 0, nrm * 0.95):
        with pytest.raises(ValueError, match="object_normals: expected unit normals"):
            wholegrasp.sample(pts, bad)
        with pytest.raises(ValueError, match="normals: expected unit normals"):
            GraspObject(pts, bad, 0.8)
    with pytest.raises(ValueError, match="normals: contains NaN"):
        GraspObject(pts, nrm.clone().fill_(float("nan")), 0.8)
    assert wholegrasp.sample(pts, nrm * (1 + 5e-3)).markers.shape[0] == 1     # float16 rounding is fine
    GraspObject(pts, nrm.half().float(), 0.8)


def test_wholegrasp_sample_requires_an_int_n(wholegrasp):
    pts, nrm = _cloud(300)
    with pytest.raises(TypeError, match="n: expected an int"):
        wholegrasp.sample(pts, nrm, n=2.0)


def test_grabnet_smplx_sample_checks_its_inputs_and_samples_a_good_cloud():
    from graspkit.models.wholegrasp import GrabNetSMPLX
    torch.manual_seed(0)
    model = GrabNetSMPLX().eval()
    pts, nrm = _cloud(300)
    out = model.sample(pts, nrm, 0.8, n=3, generator=torch.Generator().manual_seed(0))
    assert out.shape == (3, model.n_params) and torch.isfinite(out).all()
    with pytest.raises(ValueError, match="points: contains NaN"):
        model.sample(pts * NAN, nrm, 0.8, n=1)
    with pytest.raises(ValueError, match="height: contains NaN"):
        model.sample(pts, nrm, NAN, n=1)
    with pytest.raises(ValueError, match=r"normals: expected shape \(300, 3\)"):
        model.sample(pts, nrm[:, :2], 0.8, n=1)
    with pytest.raises(ValueError, match="points: expected at least 256 points.*got 10"):
        model.sample(pts[:10], nrm[:10], 0.8, n=1)
    with pytest.raises(ValueError, match="n: expected at least one sample, got 0"):
        model.sample(pts, nrm, 0.8, n=0)


def test_pointnet2_group_names_the_minimum_number_of_points():
    with pytest.raises(ValueError, match="xyz: expected at least 256 points"):
        PointNet2Encoder(3, norm=False).group(torch.rand(1, 100, 3))


# ------------------------------------------------------------------------------------------------ WANDR
@pytest.fixture(scope="module")
def wandr():
    model = load_wandr(CK / "wandr.pt")
    return model, starts_from_meta(model.meta)[0]


def test_wandr_generate_rejects_a_nan_start(wandr):
    model, st = wandr
    bad = dataclasses.replace(st, p=st.p.clone())
    bad.p[5] = NAN
    with pytest.raises(ValueError, match="start: p contains NaN"):
        generate(model, bad, torch.tensor([1.0, 0, 1]), 3)


def test_wandr_generate_converts_a_float64_start(wandr):
    model, st = wandr
    st64 = dataclasses.replace(st, p=st.p.double(), p_prev=st.p_prev.double(), rest=st.rest.double())
    a = generate(model, st, torch.tensor([1.0, 0, 1]), 3, generator=torch.Generator().manual_seed(0))
    b = generate(model, st64, torch.tensor([1.0, 0, 1]), 3, generator=torch.Generator().manual_seed(0))
    assert b.p.dtype == torch.float32 and torch.equal(a.p, b.p)
    m64 = copy.deepcopy(model).double()                    # a model the caller converted: rolls out in float64
    c = generate(m64, st64, torch.tensor([1.0, 0, 1]), 3, generator=torch.Generator().manual_seed(0))
    assert c.p.dtype == torch.float64 and torch.isfinite(c.p).all()      # (its z draws are float64 ones: other
    assert torch.equal(c.p[:, 0], st64.p[None])                               #  samples than a's; the same start)


def test_wandr_generate_and_latents_name_bad_types(wandr):
    """A bool goal frame, an int as the generator, a string as the start and a fractional frame for the latent
    optimisation gave torch's own errors."""
    from graspkit.optim.latent import optimise_latents

    model, st = wandr
    goal = torch.tensor([1.0, 0, 1])
    for kwargs, message in (({"t_goal": True}, "t_goal: expected goal frames"),
                            ({"t_goal": 3, "generator": 0}, "generator: expected a torch.Generator"),
                            ({"t_goal": 3, "start": "x"}, "start: expected a StartPose or a non-empty sequence of "
                                                          "them, got str")):
        args = {"start": st, **kwargs}
        with pytest.raises((ValueError, TypeError), match=message):
            generate(model, args.pop("start"), goal, **args)
    with pytest.raises(ValueError, match="t_goal: expected an integer >= 1, got 2.5"):
        optimise_latents(model, st, goal, t_goal=2.5, iters=1)


# ------------------------------------------------------------------------------------------------ one-call pipelines
@pytest.mark.parametrize("kwargs, message", [
    ({"seed": 1.5}, "seed: expected an integer >= 0"),
    ({"seed": -1}, "seed: expected an integer >= 0"),
    ({"start_distance": NAN}, "start_distance: expected a finite positive number"),
    ({"start_distance": float("inf")}, "start_distance: expected a finite positive number"),
    ({"grasp_steps": (-5, 10, 10)}, "grasp_steps: expected 3 step counts"),
    ({"motion_steps": (1,)}, "motion_steps: expected 2 step counts"),
    ({"hold_start": "no"}, "hold_start: expected True or False"),
    ({"object_pose": (0, 0, 1)}, "object_pose: expected a graspkit.objects.placement.ObjectPose"),
    ({"start": (0, 0, 0)}, "start: expected a Start, a one-frame Motion or None"),
])
def test_saga_synthesize_names_a_bad_argument_before_any_work(kwargs, message):
    from graspkit import saga

    with pytest.raises((ValueError, TypeError), match=message):
        saga.synthesize("mug", progress=False, checkpoints="/nonexistent", **kwargs)   # checks come before the files


def test_saga_synthesize_refuses_a_float64_body_model():
    from graspkit import saga

    bm = BodyModel.from_file(default_model_path(), dtype=torch.float64)
    with pytest.raises(ValueError, match="bm: expected a float32 BodyModel"):
        saga.synthesize("mug", bm=bm, progress=False)


@pytest.mark.parametrize("kwargs, message", [
    ({"max_frames": NAN}, "max_frames: expected an integer >= 2"),
    ({"max_frames": 2.5}, "max_frames: expected an integer >= 2"),
    ({"seed": -1}, "seed: expected an integer >= 0"),
    ({"start_distance": NAN}, "start_distance: expected a finite positive number"),
    ({"penetration": "yes"}, "penetration: expected True or False"),
    ({"object_pose": (0, 0, 1)}, "object_pose: expected a graspkit.objects.placement.ObjectPose"),
])
def test_goal_synthesize_names_a_bad_argument_before_any_work(kwargs, message):
    from graspkit import goal

    with pytest.raises((ValueError, TypeError), match=message):
        goal.synthesize("mug", checkpoints="/nonexistent", **kwargs)


# ------------------------------------------------------------------------------------------------ BodyModel
@pytest.fixture(scope="module")
def body():
    return BodyModel.from_file(default_model_path())


def test_forward_rotmats_has_the_checks_of_forward(body):
    with pytest.raises(ValueError, match="rot_mats: contains NaN"):
        body.forward_rotmats(torch.full((1, 55, 3, 3), NAN))
    with pytest.raises(TypeError, match="rot_mats: expected a torch.Tensor"):
        body.forward_rotmats(np.zeros((1, 55, 3, 3)))
    with pytest.raises(ValueError, match="rot_mats: expected a batch of at least one body"):
        body.forward_rotmats(torch.zeros(0, 55, 3, 3))
    eye = torch.eye(3).expand(1, 55, 3, 3)
    with pytest.raises(ValueError, match="betas: contains NaN"):
        body.forward_rotmats(eye, betas=torch.full((1, 10), NAN))


def test_from_file_checks_dtype_and_num_betas():
    with pytest.raises(TypeError, match="dtype: expected a floating-point torch dtype"):
        BodyModel.from_file(default_model_path(), dtype=torch.int32)
    with pytest.raises(TypeError, match="num_betas: expected an int"):
        BodyModel.from_file(default_model_path(), num_betas="10")


def test_a_model_without_shape_or_expression_coefficients_is_the_mean_shape():
    """num_betas=0 and num_expression=0 are allowed: the body is the one with all coefficients zero."""
    pose = torch.full((2, 63), 0.1)
    none = BodyModel.from_file(default_model_path(), num_betas=0, num_expression=0)(body_pose=pose)
    zero = BodyModel.from_file(default_model_path())(body_pose=pose)
    torch.testing.assert_close(none.vertices, zero.vertices, rtol=0, atol=1e-6)
    torch.testing.assert_close(none.joints, zero.joints, rtol=0, atol=1e-6)


def test_from_file_names_a_text_file_that_is_not_an_npz(tmp_path):
    text = tmp_path / "notes.npz"
    text.write_text("hello\n")
    with pytest.raises(ModelFileError, match=r"notes\.npz: not an \.npz body model"):
        BodyModel.from_file(text)


@pytest.mark.parametrize("value", [0.0, -0.5])
def test_a_zero_or_negative_start_distance_is_refused(value):
    """SAGA's and GOAL's start_distance must be a finite positive number (GOAL's at most 5 m), refused before any
    work, with the argument named."""
    from graspkit import goal, saga

    msg = "start_distance: expected a finite positive number"
    with pytest.raises(ValueError, match=msg):
        saga.synthesize("mug", progress=False, checkpoints="/nonexistent", start_distance=value)
    with pytest.raises(ValueError, match=msg):
        goal.synthesize("mug", checkpoints="/nonexistent", start_distance=value)
    with pytest.raises(ValueError, match=msg):
        goal.synthesize("mug", checkpoints="/nonexistent", start_distance=5.5)


def test_wandr_warns_about_a_start_whose_still_joints_moved(wandr):
    """72 of the shipped WANDR's 268 state features sit at the 1e-3 std floor (joints the training clips never move:
    the left wrist and collar, ...): a start with the left wrist turned 0.1 rad reads 100 stds out, and the grid's SR
    fell from 99.5 to 6 % (an independent check). generate now warns, naming the joint; the held-out starts do not."""
    import warnings

    from graspkit import intention as I
    from graspkit.body.skeleton import JOINT_INDEX
    from graspkit.rotations import axis_angle_to_matrix, matrix_to_rot6d, rot6d_to_matrix

    model, _ = wandr

    def messages(start):
        with warnings.catch_warnings(record=True) as w:
            warnings.simplefilter("always")
            generate(model, start, torch.tensor([1.0, 0.5, 1.0]), 3, generator=torch.Generator().manual_seed(0))
        assert all(x.filename == __file__ for x in w if "training stds" in str(x.message))   # the caller's line
        return [str(x.message) for x in w if "training stds" in str(x.message)]

    starts = starts_from_meta(model.meta)
    assert all(messages(s) == [] for s in starts)
    j = JOINT_INDEX["left_wrist"]
    turn = axis_angle_to_matrix(torch.tensor([0.0, 0.0, 0.1]))
    p_prev, p = (q.clone() for q in (starts[0].p_prev, starts[0].p))
    for q in (p_prev, p):
        q[3 + 6 * j:9 + 6 * j] = matrix_to_rot6d(rot6d_to_matrix(q[3 + 6 * j:9 + 6 * j]) @ turn)
    [msg] = messages(I.StartPose(p_prev, p, starts[0].rest, starts[0].betas, starts[0].full_pose, starts[0].source))
    assert msg.startswith("start: the state features of left_wrist, previous delta: left_wrist lie") or \
        msg.startswith("start: the state features of left_wrist lie")


def test_gnet_warns_about_an_object_translation_its_frame_never_has():
    """GNet's frame puts the object at x = y = 0: the shipped statistics floor those two inputs, so obj_transl
    (0.5, 0.3, 0.8) fed the decoder 500 stds (an independent check). sample now warns; (0, 0, 0.8) does not."""
    import warnings

    net = load_gnet(CK / "gnet.pt")
    bps = net.norm_cond.mean[:1024][None].clone()

    def messages(ot):
        with warnings.catch_warnings(record=True) as w:
            warnings.simplefilter("always")
            net.sample(bps, torch.tensor([ot]), torch.zeros(1, 10), generator=torch.Generator().manual_seed(0))
        assert all(x.filename == __file__ for x in w if "training stds" in str(x.message))   # not torch's wrapper
        return [str(x.message) for x in w if "training stds" in str(x.message)]

    assert messages([0.0, 0.0, 0.8]) == []
    [msg] = messages([0.5, 0.3, 0.8])
    assert msg.startswith("obj_transl: values more than 5 training stds")
