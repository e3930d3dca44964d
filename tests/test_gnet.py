"""GNet (GOAL §3.3, Eq. 2-3): sparse LBS against the full model, attention, CVAE shapes, loss values, learning."""
import math

import pytest
import torch

from graspkit.body import BodyModel
from graspkit.models.gnet import (GNet, GNetConfig, GNetLossWeights, SparseBody, Standardiser, attention_offsets,
                                  gnet_loss, pose_rotmats)
from graspkit.objects.contact import interaction_attention
from graspkit.rotations import axis_angle_to_rot6d
from graspkit.train import TrainConfig, fit


@pytest.fixture(scope="module")
def bm(random_model_dir):
    return BodyModel.from_file(random_model_dir / "smplx" / "SMPLX_NEUTRAL.npz", flat_hand_mean=True)


def _params(B, seed, scale=0.3):
    g = torch.Generator().manual_seed(seed)
    aa = scale * torch.randn(B, 55, 3, generator=g)
    return axis_angle_to_rot6d(aa), 0.2 * torch.randn(B, 3, generator=g), torch.randn(B, 10, generator=g)


def _batch(bm, body, B, seed):
    """A self-consistent GNet batch: vertices from the body at the parameters, offsets to a random object."""
    rot6d, transl, betas = _params(B, seed)
    g = torch.Generator().manual_seed(seed + 1)
    with torch.no_grad():
        verts = body(pose_rotmats(rot6d), betas, transl)[0].float()
    obj = 0.3 * torch.randn(B, 1, 3, generator=g)
    return {"rot6d": rot6d, "transl": transl, "betas": betas, "verts": verts,
            "head_dir": torch.nn.functional.normalize(torch.randn(B, 3, generator=g), dim=-1),
            "obj_transl": obj[:, 0], "bps": torch.rand(B, 1024, generator=g) * 0.1, "offsets": obj - verts}


def test_sparse_body_matches_the_full_model(bm):
    ids = torch.randperm(bm.num_vertices, generator=torch.Generator().manual_seed(0))[:300]
    rot6d, transl, betas = _params(3, 1, scale=0.5)
    full = bm.forward_rotmats(pose_rotmats(rot6d), betas=betas, transl=transl)
    v, joints = SparseBody(bm, ids)(pose_rotmats(rot6d), betas, transl)
    torch.testing.assert_close(v, full.vertices[:, ids], atol=1e-5, rtol=1e-5)
    torch.testing.assert_close(joints, full.joints, atol=1e-5, rtol=1e-5)


def test_sparse_body_names_bad_vertex_ids(bm):
    with pytest.raises(ValueError, match="vertex_ids"):
        SparseBody(bm, [0, bm.num_vertices])


def test_attention_offsets_are_eq1_weighted_offsets():
    d = torch.tensor([[0.0, 0.0, 0.01], [0.6, 0.8, 0.0], [0.0, -0.2, 0.0]])
    w = interaction_attention(d.norm(dim=-1))
    torch.testing.assert_close(attention_offsets(d), w[:, None] * d)
    assert math.isclose(float(attention_offsets(d)[1].norm()), math.exp(-5.0), rel_tol=1e-6)   # 1 m away: e^-5


def test_standardiser_round_trip():
    s = Standardiser(4)
    x = torch.randn(50, 4, generator=torch.Generator().manual_seed(0)) * torch.tensor([1.0, 10.0, 0.1, 0.0]) + 3
    s.fit(x)
    y = s(x)
    torch.testing.assert_close(y[:, :3].mean(0), torch.zeros(3), atol=1e-5, rtol=0)
    torch.testing.assert_close(y[:, :3].std(0), torch.ones(3), atol=1e-5, rtol=0)
    torch.testing.assert_close(s.inverse(y), x)


def test_shapes_and_seeded_sampling(bm):
    body = SparseBody(bm, torch.arange(400))
    batch = _batch(bm, body, 6, 0)
    net = GNet()
    net.fit_normalisation(batch)
    mu, logvar = net.encode(batch)
    assert mu.shape == logvar.shape == (6, 16)
    torch.nn.init.normal_(net.out.weight, std=0.1)       # as if trained: the output depends on z
    s1 = net.sample(batch["bps"], batch["obj_transl"], batch["betas"], generator=torch.Generator().manual_seed(4))
    s2 = net.sample(batch["bps"], batch["obj_transl"], batch["betas"], generator=torch.Generator().manual_seed(4))
    s3 = net.sample(batch["bps"], batch["obj_transl"], batch["betas"], generator=torch.Generator().manual_seed(5))
    assert s1["rot6d"].shape == (6, 55, 6) and s1["transl"].shape == (6, 3)
    assert s1["hand_offsets"].shape == (6, 99, 3) and s1["head_dir"].shape == (6, 3)
    torch.testing.assert_close(s1["head_dir"].norm(dim=-1), torch.ones(6))
    for k in s1:
        assert torch.equal(s1[k], s2[k])
    assert not torch.allclose(s1["rot6d"], s3["rot6d"])
    for name, args in (("bps", (batch["bps"][:, :100], batch["obj_transl"], batch["betas"])),
                       ("obj_transl", (batch["bps"], batch["obj_transl"][:2], batch["betas"])),
                       ("betas", (batch["bps"], batch["obj_transl"], batch["betas"][:, :5]))):
        with pytest.raises(ValueError, match=name):
            net.sample(*args)


def test_untrained_decoder_outputs_the_training_mean(bm):
    body = SparseBody(bm, torch.arange(400))
    batch = _batch(bm, body, 8, 1)
    net = GNet()
    net.fit_normalisation(batch)
    out = net.sample(batch["bps"], batch["obj_transl"], batch["betas"], generator=torch.Generator().manual_seed(0))
    torch.testing.assert_close(out["rot6d"], batch["rot6d"].mean(0).expand(8, -1, -1), atol=1e-5, rtol=1e-5)
    torch.testing.assert_close(out["hand_offsets"], batch["offsets"][:, :99].mean(0).expand(8, -1, -1),
                               atol=1e-5, rtol=1e-5)


def test_loss_is_zero_at_the_truth_and_exact_for_a_shift(bm):
    body = SparseBody(bm, torch.arange(400))
    batch = _batch(bm, body, 4, 2)
    truth = {"rot6d": batch["rot6d"], "transl": batch["transl"], "head_dir": batch["head_dir"],
             "hand_offsets": batch["offsets"][:, :99]}
    zero = torch.zeros(4, 16)
    terms = gnet_loss(truth, zero, zero, batch, body)
    for k in ("v", "v_hand", "theta", "q", "d", "kl", "loss"):
        assert float(terms[k]) < 1e-6, k
    shifted = dict(truth, transl=truth["transl"] + torch.tensor([0.03, 0.0, 0.0]))
    terms = gnet_loss(shifted, zero, zero, batch, body, GNetLossWeights(kl=0.0))
    assert math.isclose(float(terms["v"]), 0.01, rel_tol=1e-4)          # |0.03| on one of 3 coordinates
    assert math.isclose(float(terms["theta"]), 0.03 ** 2 / 333, rel_tol=1e-4)
    assert math.isclose(float(terms["loss"]), 10 * 0.01 + 10 * 0.01 + 0.03 ** 2 / 333, rel_tol=1e-4)


def test_the_hand_term_reads_the_first_99_vertices(bm):
    """Eq. 3's hand-vertex term is over the 99 right-hand vertices, which come first among the 400: a 1 cm error on
    them alone gives v_hand = 1/3 cm (the mean over 99 x 3 coordinates) and v = 99 / 400 of that; an error on the
    other 301 vertices alone leaves v_hand at 0."""
    body = SparseBody(bm, torch.arange(400))
    batch = _batch(bm, body, 4, 5)
    truth = {"rot6d": batch["rot6d"], "transl": batch["transl"]}
    zero = torch.zeros(4, 16)
    for first, want_hand, want_all in ((True, 0.01 / 3, 0.01 * 99 / (400 * 3)), (False, 0.0, 0.01 * 301 / (400 * 3))):
        verts = batch["verts"].clone()
        part = slice(0, 99) if first else slice(99, 400)
        verts[:, part, 0] += 0.01
        terms = gnet_loss(truth, zero, zero, dict(batch, verts=verts), body)
        assert math.isclose(float(terms["v_hand"]), want_hand, abs_tol=1e-7)
        assert math.isclose(float(terms["v"]), want_all, rel_tol=1e-4)


def test_grabnet_style_baseline_outputs_parameters_only(bm):
    body = SparseBody(bm, torch.arange(400))
    batch = _batch(bm, body, 4, 3)
    net = GNet(GNetConfig(offsets=False))
    net.fit_normalisation(batch)
    out, mu, logvar = net(batch, generator=torch.Generator().manual_seed(0))
    assert set(out) == {"rot6d", "transl"}
    assert set(gnet_loss(out, mu, logvar, batch, body)) == {"v", "v_hand", "theta", "kl", "loss"}


def test_gnet_fits_a_small_set_through_the_training_loop(bm):
    torch.manual_seed(0)
    body = SparseBody(bm, torch.arange(400))
    batch = _batch(bm, body, 32, 4)
    keys = list(batch)
    data = torch.utils.data.TensorDataset(*[batch[k] for k in keys])
    net = GNet(GNetConfig(hidden=128))
    net.fit_normalisation(batch)

    def step(model, b, epoch):
        b = dict(zip(keys, b))
        out, mu, logvar = model(b)
        return gnet_loss(out, mu, logvar, b, body)

    hist = fit(net, step, data, TrainConfig(epochs=50, batch_size=32, lr=3e-3, seed=0), progress=False)
    assert hist[-1]["v"] < 0.2 * hist[0]["v"] and hist[-1]["d"] < 0.2 * hist[0]["d"]


def test_decoder_blocks_see_the_latent_and_the_condition_bps_translation_and_betas():
    """GNet's decoder is conditioned on [b°, γ°, β] ('Decoder: [z, C = (b°, γ°), β]', §3.3), and its second block gets the
    latent and the condition again (the skip); another body shape with the same object and latent gives another grasp."""
    torch.manual_seed(0)
    net = GNet().eval()
    torch.nn.init.normal_(net.out.weight, std=0.1)                  # as if trained: outputs depend on the inputs
    g = torch.Generator().manual_seed(1)
    B = 4
    z, bps = torch.randn(B, 16, generator=g), 0.1 * torch.rand(B, 1024, generator=g)
    t, betas = 0.3 * torch.randn(B, 3, generator=g), torch.randn(B, 10, generator=g)
    seen = {}
    hooks = [net.dec1.register_forward_hook(lambda m, i, o: seen.update(dec1_in=i[0], dec1_out=o)),
             net.dec2.register_forward_hook(lambda m, i, o: seen.update(dec2_in=i[0]))]
    with torch.no_grad():
        out = net.sample(bps, t, betas, z=z)
        for h in hooks:
            h.remove()
        c = net.cond_net(net.norm_cond(torch.cat([bps, t, betas], 1)))    # C = [b°, γ°] and β, coded once
        other = net.sample(bps, t, betas + 1.0, z=z)
    torch.testing.assert_close(seen["dec1_in"], torch.cat([z, c], 1))
    torch.testing.assert_close(seen["dec2_in"], torch.cat([seen["dec1_out"], z, c], 1))
    # another body shape, the same object and latent: another grasp (the arm length matters)
    assert (other["rot6d"] - out["rot6d"]).abs().max() > 1e-3
    assert (other["transl"] - out["transl"]).abs().max() > 1e-4


def test_q_term_is_the_squared_length_of_the_head_direction_error():
    """GNetLossWeights doc / GOAL Eq. 3: the q term is ||q - q^||^2 (squared length) averaged over the batch. One of
    two samples off by (0.3, 0.4, 0): squared length 0.25, mean 0.125 (an L1 would give 0.35); the weighted sum adds
    lambda_q times it."""
    from graspkit.body.random_model import random_smplx_arrays
    bm = BodyModel(random_smplx_arrays(num_vertices=500, num_faces=200, seed=3), flat_hand_mean=True)
    body = SparseBody(bm, torch.arange(400))
    g = torch.Generator().manual_seed(4)
    rot6d = axis_angle_to_rot6d(0.2 * torch.randn(2, 55, 3, generator=g))
    transl, betas = 0.1 * torch.randn(2, 3, generator=g), torch.randn(2, 10, generator=g)
    with torch.no_grad():
        verts = body(pose_rotmats(rot6d), betas, transl)[0].float()
    head = torch.nn.functional.normalize(torch.randn(2, 3, generator=g), dim=-1)
    offsets = 0.1 * torch.randn(2, 400, 3, generator=g)
    batch = {"rot6d": rot6d, "transl": transl, "betas": betas, "verts": verts, "head_dir": head, "offsets": offsets}
    out = {"rot6d": rot6d, "transl": transl, "head_dir": head + torch.tensor([[0.3, 0.4, 0.0], [0.0, 0.0, 0.0]]),
           "hand_offsets": offsets[:, :99]}
    zero = torch.zeros(2, 16)
    terms = gnet_loss(out, zero, zero, batch, body, GNetLossWeights(q=2.0, kl=0.0))
    assert math.isclose(float(terms["q"]), 0.125, rel_tol=1e-5)
    assert math.isclose(float(terms["loss"]), 2.0 * 0.125, rel_tol=1e-4, abs_tol=1e-6)


def test_sample_names_a_generator_that_is_not_a_torch_generator():
    """generator=0 or a numpy Generator failed inside torch.randn with its 20-line overload list (an independent
    check); GNet.sample answers as the other samplers do, and a torch.Generator still gives the same grasp twice."""
    import numpy as np

    torch.manual_seed(0)
    net = GNet().eval()
    g = torch.Generator().manual_seed(1)
    bps, t, betas = 0.1 * torch.rand(2, 1024, generator=g), 0.3 * torch.randn(2, 3, generator=g), torch.zeros(2, 10)
    for bad in (0, np.random.default_rng(0)):
        with pytest.raises(TypeError, match="^generator: expected a torch.Generator or None"):
            net.sample(bps, t, betas, generator=bad)
    a, b = (net.sample(bps, t, betas, generator=torch.Generator().manual_seed(3)) for _ in range(2))
    for k in a:
        torch.testing.assert_close(a[k], b[k], rtol=0, atol=0)
