"""WholeGrasp-VAE (SAGA §3.2): shapes, gradients, the losses of Eq. 1-3 on hand-made cases, deterministic sampling."""
import math

import numpy as np
import pytest
import torch
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from graspkit.models.wholegrasp import (WholeGraspConfig, WholeGraspVAE, consistency_distances, consistency_loss,
                                        squared_min_distance, weighted_bce, yaw_spread)

P = 512  # object points in these tests (the model takes any P >= 256; SAGA uses 2,048)


def _batch(B: int = 3, seed: int = 0, contact: float = 0.1) -> dict[str, torch.Tensor]:
    """A seeded batch of WholeGrasp inputs; `contact` is the share of markers and points in contact."""
    g = torch.Generator().manual_seed(seed)
    pts = torch.randn(B, P, 3, generator=g) * 0.05
    return dict(markers=torch.randn(B, 143, 3, generator=g) * 0.3,
                marker_contact=(torch.rand(B, 143, generator=g) < contact).float(),
                points=pts, normals=torch.nn.functional.normalize(pts, dim=-1),
                object_contact=(torch.rand(B, P, generator=g) < contact).float(),
                height=torch.rand(B, 1, generator=g) + 0.5)


def test_forward_shapes_and_every_parameter_gets_a_gradient():
    torch.manual_seed(0)
    model = WholeGraspVAE()
    batch = _batch()
    out = model(batch)
    assert out["markers"].shape == (3, 143, 3) and out["mu"].shape == (3, 16)
    assert out["marker_contact"].shape == (3, 143) and out["object_contact"].shape == (3, P)
    for k in ("marker_contact", "object_contact"):
        assert ((out[k] > 0) & (out[k] < 1)).all()
    logs = model.loss(batch, out, epoch=0, epochs=10)
    logs["loss"].backward()
    missing = [n for n, p in model.named_parameters() if p.grad is None or p.grad.abs().sum() == 0]
    assert not missing


def test_single_task_model_learns_markers_only():
    model = WholeGraspVAE(WholeGraspConfig(multitask=False))
    batch = {k: v for k, v in _batch().items() if "contact" not in k}
    out = model(batch)
    assert "marker_contact" not in out and "object_contact" not in out
    logs = model.loss(batch, out, 0, 10)
    assert "bce_object" not in logs and torch.isfinite(logs["loss"])


def test_weighted_bce_matches_the_formula():
    p = torch.tensor([0.5, 0.9, 0.2, 0.7])
    t = torch.tensor([1.0, 1.0, 0.0, 0.0])
    want = -(5 * math.log(0.5) + 5 * math.log(0.9) + math.log(0.8) + math.log(0.3)) / 4
    assert weighted_bce(p, t, 5.0).item() == pytest.approx(want, rel=1e-6)
    # the in-contact weight is torch's per-element weight on the positive class
    w = torch.where(t > 0, 5.0, 1.0)
    assert weighted_bce(p, t, 5.0).item() == pytest.approx(
        torch.nn.functional.binary_cross_entropy(p, t, weight=w).item(), rel=1e-6)


def test_consistency_loss_on_a_hand_made_case():
    pts = torch.tensor([[[0.0, 0, 0], [1.0, 0, 0]]])                         # object: two points
    m = torch.tensor([[[0.0, 0.01, 0], [1.0, 0.5, 0]]])                      # markers 1 cm and 50 cm away
    m_pred = torch.tensor([[[0.0, 0.03, 0], [1.0, 0.5, 0]]])                 # the first now 3 cm away
    torch.testing.assert_close(squared_min_distance(m, pts), torch.tensor([[1e-4, 0.25]]))
    cm = torch.tensor([[1.0, 1.0]])
    co = torch.tensor([[1.0, 0.0]])
    # marker term: |0.03^2 - 0.01^2| = 8e-4; object term: point 0 is nearest to marker 0 in both: 8e-4 again
    assert consistency_loss(m_pred, m, cm, pts, co).item() == pytest.approx(1.6e-3, rel=1e-4)
    assert consistency_loss(m, m, cm, pts, co).item() == 0.0
    assert consistency_loss(m_pred, m, torch.zeros_like(cm), pts, torch.zeros_like(co)).item() == 0.0


def test_signed_consistency_tells_inside_from_outside():
    pts = torch.tensor([[[0.0, 0, 0], [1.0, 0, 0]]])
    nrm = torch.tensor([[[0.0, 1, 0], [0.0, 1, 0]]])                          # outward normals along +y
    m = torch.tensor([[[0.0, 0.02, 0], [1.0, 0.5, 0]]])                      # true marker 2 cm outside
    inside = torch.tensor([[[0.0, -0.02, 0], [1.0, 0.5, 0]]])                # 2 cm inside: the mirror image
    cm, co = torch.tensor([[1.0, 1.0]]), torch.tensor([[0.0, 0.0]])
    dm, do = consistency_distances(inside, pts, nrm)
    torch.testing.assert_close(dm, torch.tensor([[-0.02, 0.5]]))
    torch.testing.assert_close(do, torch.tensor([[0.02, 0.5]]))
    # as printed (unsigned, squared) the mirror image costs nothing; signed it costs |-0.02 - 0.02| = 0.04
    assert consistency_loss(inside, m, cm, pts, co).item() == 0.0
    assert consistency_loss(inside, m, cm, pts, co, normals=nrm).item() == pytest.approx(0.04, rel=1e-5)
    assert consistency_loss(m, m, cm, pts, co, normals=nrm).item() == 0.0
    with pytest.raises(ValueError, match="consistency"):
        WholeGraspConfig(consistency="squared")
    # the model's precomputed truths follow its setting: squared as printed, signed Euclidean otherwise
    b = _batch(B=2)
    signed = WholeGraspVAE(WholeGraspConfig(consistency="signed")).precompute(b["points"], b["markers"], b["normals"])
    plain = WholeGraspVAE().precompute(b["points"], b["markers"])
    torch.testing.assert_close(signed["dist_markers"].pow(2), plain["dist_markers"], atol=1e-7, rtol=1e-4)
    torch.testing.assert_close(signed["dist_points"].pow(2), plain["dist_points"], atol=1e-7, rtol=1e-4)
    with pytest.raises(ValueError, match="normals"):
        WholeGraspVAE(WholeGraspConfig(consistency="signed")).precompute(b["points"], b["markers"])


def test_kl_weight_rises_linearly_to_the_papers_end_point():
    torch.manual_seed(0)
    model = WholeGraspVAE()
    batch = _batch()
    model.eval()
    out = dict(model(batch), mu=torch.full((3, 16), 2.0), logvar=torch.zeros(3, 16))   # KL = 32 per sample
    rest = lambda e: (model.loss(batch, out, e, 40)["loss"] - model.loss(batch, out, 0, 40)["loss"]).item()  # noqa: E731
    from graspkit.models.blocks import robust_kl
    psi = robust_kl(out["mu"], out["logvar"]).item()
    assert psi == pytest.approx(math.sqrt(1 + 32 ** 2) - 1)
    # SAGA A.4: lambda_KL = 0.005 e over 40 epochs
    assert rest(39) == pytest.approx((0.2 - 0.005) * psi, rel=1e-4, abs=1e-6)
    assert rest(19) == pytest.approx((0.1 - 0.005) * psi, rel=1e-4, abs=1e-6)
    # and the weight itself: the first epoch's KL term is 0.005 psi (epoch is 0-based), the last one's 0.2 psi
    for e, w in ((0, 0.005), (39, 0.2)):
        logs = model.loss(batch, out, e, 40)
        others = logs["rec_markers"] + logs["bce_markers"] + logs["bce_object"] + logs["consistency"]
        assert (logs["loss"] - others).item() == pytest.approx(w * psi, rel=1e-4)


def test_contact_class_weights_are_the_papers():
    """SAGA A.4: in-contact terms of C_M weigh 5 and of C_O 3 in the default config (what `train_wholegrasp` uses);
    with every prediction at 0.25, the BCE is -w log 0.25 on in-contact targets and -log 0.75 on the others."""
    cfg = WholeGraspConfig()
    assert (cfg.marker_contact_weight, cfg.object_contact_weight) == (5.0, 3.0)
    model = WholeGraspVAE(cfg).eval()
    batch = _batch()
    out = dict(model(batch))
    out["marker_contact"], out["object_contact"] = torch.full((3, 143), 0.25), torch.full((3, P), 0.25)
    for mc, oc, want_m, want_o in ((1.0, 0.0, -5 * math.log(0.25), -math.log(0.75)),
                                   (0.0, 1.0, -math.log(0.75), -3 * math.log(0.25))):
        b = dict(batch, marker_contact=torch.full((3, 143), mc), object_contact=torch.full((3, P), oc))
        logs = model.loss(b, out, 0, 40)
        assert logs["bce_markers"].item() == pytest.approx(want_m, rel=1e-5)
        assert logs["bce_object"].item() == pytest.approx(want_o, rel=1e-5)


def test_sample_is_deterministic_for_a_generator_and_returns_world_transform():
    torch.manual_seed(0)
    model = WholeGraspVAE().eval()
    torch.nn.init.normal_(model.out_markers.weight, std=0.1)    # an untrained model starts at the mean grasp
    g = torch.Generator().manual_seed(5)
    pts = torch.randn(P, 3, generator=g) * 0.05 + torch.tensor([0.3, -0.6, 0.9])
    nrm = torch.nn.functional.normalize(torch.randn(P, 3, generator=g), dim=-1)
    a = model.sample(pts, nrm, n=4, generator=torch.Generator().manual_seed(1))
    b = model.sample(pts, nrm, n=4, generator=torch.Generator().manual_seed(1))
    c = model.sample(pts, nrm, n=4, generator=torch.Generator().manual_seed(2))
    assert torch.equal(a.markers, b.markers) and torch.equal(a.object_contact, b.object_contact)
    assert not torch.allclose(a.markers, c.markers)
    assert a.markers.shape == (4, 143, 3) and a.marker_contact.shape == (4, 143) and a.object_contact.shape == (4, P)
    centre = 0.5 * (pts.min(0).values + pts.max(0).values)
    torch.testing.assert_close(a.translation, centre)
    torch.testing.assert_close(a.markers_world(), a.markers + centre)
    # the decoder sees the centred cloud: the same object elsewhere in the world gives the same grasp (object frame)
    d = model.sample(pts + torch.tensor([1.0, 2.0, 0.0]), nrm, object_height=centre[2], n=4,
                     generator=torch.Generator().manual_seed(1))
    torch.testing.assert_close(d.markers, a.markers, atol=1e-5, rtol=0)
    with pytest.raises(ValueError, match="object_normals"):
        model.sample(pts, nrm[:10])
    with pytest.raises(ValueError, match="n:"):
        model.sample(pts, nrm, n=0)
    # a numpy count is a count (MotionFill and WANDR took it; this refused it), numpy points are named as such (the
    # message said "expected shape (None, 3), got ndarray" of an array of that very shape: an independent check)
    e = model.sample(pts, nrm, n=np.int64(4), generator=torch.Generator().manual_seed(1))
    assert torch.equal(e.markers, a.markers)
    with pytest.raises(ValueError, match=r"^object_points: expected a torch.Tensor of shape \(None, 3\) .*got ndarray"):
        model.sample(pts.numpy(), nrm)


def test_state_round_trip_and_bad_batches():
    torch.manual_seed(0)
    model = WholeGraspVAE().eval()
    again = WholeGraspVAE.from_state(model.state())
    batch = _batch()
    torch.testing.assert_close(again(batch)["markers"], model(batch)["markers"])
    bad = dict(batch, markers=batch["markers"][:, :100])
    with pytest.raises(ValueError, match="markers"):
        model(bad)
    with pytest.raises(ValueError, match="object_contact"):
        model({k: v for k, v in batch.items() if k != "object_contact"})


def test_contact_auc_matches_scipy_mann_whitney():
    from scipy.stats import mannwhitneyu

    from graspkit.models.wholegrasp import contact_auc
    g = torch.Generator().manual_seed(0)
    labels = (torch.rand(500, generator=g) < 0.2).float()
    scores = torch.round(torch.rand(500, generator=g) * 10 + labels * 3) / 10        # with ties
    u = mannwhitneyu(scores[labels > 0].numpy(), scores[labels == 0].numpy()).statistic
    assert contact_auc(scores, labels) == pytest.approx(u / (labels.sum() * (500 - labels.sum())).item(), rel=1e-9)
    assert contact_auc(labels, labels) == 1.0 and contact_auc(1 - labels, labels) == 0.0


def test_training_set_precomputes_and_yaw_augmentation_keeps_the_geometry():
    from graspkit.models.wholegrasp import WholeGraspTrainingSet, squared_min_distance
    b = _batch(B=4)
    items = {"markers": b["markers"], "marker_contacts": b["marker_contact"], "object_points": b["points"],
             "object_normals": b["normals"], "object_contacts": b["object_contact"], "object_height": b["height"][:, 0]}
    model = WholeGraspVAE()
    ds = WholeGraspTrainingSet(items, model, augment_yaw=True)
    torch.manual_seed(3)
    it = ds[2]
    # turned about z: heights kept, every distance kept (so the precomputed Eq. 3 truths and groupings stay valid)
    assert not torch.allclose(it["markers"], b["markers"][2])
    torch.testing.assert_close(it["markers"][:, 2], b["markers"][2, :, 2])
    torch.testing.assert_close(squared_min_distance(it["markers"][None], it["points"][None])[0], it["dist_markers"],
                               atol=1e-6, rtol=1e-4)
    torch.testing.assert_close(it["normals"].norm(dim=-1), torch.ones(P))
    # precomputed batches give the same outputs as computing everything in forward
    model.eval()
    full = {k: torch.stack([ds.data[k][i] for i in range(4)]) for k in ds.data}
    torch.testing.assert_close(model(full)["object_contact"], model(b)["object_contact"], atol=1e-5, rtol=1e-4)
    torch.testing.assert_close(model.loss(full, model(full), 0, 10)["consistency"],
                               model.loss(b, model(b), 0, 10)["consistency"], atol=1e-6, rtol=1e-4)


@pytest.mark.parametrize("space", ["rot6d", "prior"])
def test_grabnet_parameters_turn_with_the_body(space):
    from graspkit.body import BodyModel
    from graspkit.body.markers import saga_markers
    from graspkit.models.gnet import SparseBody
    from graspkit.models.pose_prior import load_pose_prior
    from graspkit.models.wholegrasp import HandPCA, grasp_params, params_to_rotmats, rest_root_joint, turn_params
    from graspkit.paths import default_model_path
    from graspkit.rotations import axis_angle_to_matrix
    bm = BodyModel.from_file(default_model_path())
    body, pca = SparseBody(bm, saga_markers(bm).vertex_ids), HandPCA(bm)
    prior = load_pose_prior() if space == "prior" else None
    g = torch.Generator().manual_seed(0)
    fp = torch.randn(3, 55, 3, generator=g) * 0.2
    fp[:, 25:] = pca.decode(torch.randn(6, 24, generator=g) * 0.5, "left").view(3, 2, 15, 3).reshape(3, 30, 3)
    betas = torch.randn(3, 10, generator=g)
    x = grasp_params(fp, torch.randn(3, 3, generator=g), betas, torch.zeros(3, 3), pca, prior)
    assert x.shape == (3, 193 if prior is None else 99)
    Q = axis_angle_to_matrix(torch.tensor([0.0, 0.0, 1.1]))
    m0 = body(*params_to_rotmats(x, pca, prior))[0]
    m1 = body(*params_to_rotmats(turn_params(x, rest_root_joint(bm, betas), Q), pca, prior))[0]
    torch.testing.assert_close(m1, m0 @ Q.T, atol=1e-5, rtol=0)


def test_grabnet_prior_space_poses_the_body_the_pose_prior_decodes():
    """A 99-number vector (body as the pose prior's latent) poses the same markers as the 193-number vector that
    carries the prior's decoded joints as 6D rotations, and a grasp's own body pose comes back within the prior's
    reconstruction error."""
    from graspkit.body import BodyModel
    from graspkit.body.markers import saga_markers
    from graspkit.models.gnet import SparseBody
    from graspkit.models.pose_prior import load_pose_prior
    from graspkit.models.wholegrasp import HandPCA, grasp_params, params_to_rotmats
    from graspkit.paths import default_model_path
    from graspkit.rotations import matrix_to_rot6d
    bm = BodyModel.from_file(default_model_path())
    body, pca, prior = SparseBody(bm, saga_markers(bm).vertex_ids), HandPCA(bm), load_pose_prior()
    g = torch.Generator().manual_seed(1)
    x = torch.cat([torch.randn(4, 3, generator=g) * 0.3, torch.randn(4, 6, generator=g),   # any 6 numbers: a rotation
                   torch.randn(4, 10, generator=g), torch.randn(4, 32, generator=g), torch.randn(4, 48, generator=g)], 1)
    rot, betas, transl = params_to_rotmats(x, pca, prior)
    x6 = torch.cat([x[:, :19], matrix_to_rot6d(prior.decode_rotmats(x[:, 19:51])).reshape(4, 126), x[:, 51:]], 1)
    rot6, _, _ = params_to_rotmats(x6, pca)
    torch.testing.assert_close(body(rot, betas, transl)[0], body(rot6, betas, transl)[0], atol=1e-5, rtol=0)
    with pytest.raises(ValueError, match=r"x: expected \(B, 99\)"):
        params_to_rotmats(x6, pca, prior)
    with pytest.raises(ValueError, match=r"x: expected \(B, 193\)"):
        params_to_rotmats(x, pca)
    # a pose the prior was trained on (the prior decodes its own latent): the round trip keeps it
    fp = torch.zeros(4, 55, 3)
    fp[:, 1:22] = prior.decode(torch.randn(4, 32, generator=g) * 0.5).view(4, 21, 3)
    fp[:, 25:40], fp[:, 40:55] = pca.mean["left"].view(15, 3), pca.mean["right"].view(15, 3)
    y = grasp_params(fp, torch.zeros(4, 3), torch.zeros(4, 10), torch.zeros(4, 3), pca, prior)
    back = prior.decode(y[:, 19:51]).view(4, 21, 3)
    assert (back - fp[:, 1:22]).norm(dim=-1).mean() < 0.05      # rad, mean over joints


def test_many_samples_are_decoded_in_chunks_with_the_draws_and_grasps_of_one_call(monkeypatch):
    """sample(n=1000) decoded the object once per sample in one batch (4 GB within 28 s): above SAMPLE_CHUNK the
    latents, drawn up front, are decoded a chunk at a time; the grasps are those of one call to float rounding."""
    import graspkit.models.wholegrasp as W

    torch.manual_seed(0)
    model = WholeGraspVAE().eval()
    torch.nn.init.normal_(model.out_markers.weight, std=0.1)
    g = torch.Generator().manual_seed(5)
    pts = torch.randn(P, 3, generator=g) * 0.05 + torch.tensor([0.3, -0.6, 0.9])
    nrm = torch.nn.functional.normalize(torch.randn(P, 3, generator=g), dim=-1)
    whole = model.sample(pts, nrm, n=5, generator=torch.Generator().manual_seed(1))
    calls = []
    decode = model.decode
    monkeypatch.setattr(model, "decode", lambda z, *a, **k: calls.append(len(z)) or decode(z, *a, **k))
    monkeypatch.setattr(W, "SAMPLE_CHUNK", 2)
    parts = model.sample(pts, nrm, n=5, generator=torch.Generator().manual_seed(1))
    assert calls == [2, 2, 1]
    for k in ("markers", "marker_contact", "object_contact"):
        torch.testing.assert_close(getattr(parts, k), getattr(whole, k), atol=1e-5, rtol=1e-5)


def test_grabnet_state_round_trip_keeps_the_body_space_and_the_samples():
    from graspkit.models.wholegrasp import GrabNetSMPLX
    g = torch.Generator().manual_seed(0)
    pts = torch.nn.functional.normalize(torch.randn(300, 3, generator=g), dim=-1) * 0.05   # a 5 cm sphere
    nrm = pts / 0.05
    for space in ("prior", "rot6d"):
        torch.manual_seed(0)
        model = GrabNetSMPLX(body_space=space)
        for p in model.dec[-1].parameters():      # a decoder that is not the zero init
            torch.nn.init.normal_(p, std=0.01, generator=torch.Generator().manual_seed(2))
        again = GrabNetSMPLX.from_state(model.state())
        assert again.hparams["body_space"] == space and again.n_params == (99 if space == "prior" else 193)
        a = model.sample(pts, nrm, 0.8, 3, torch.Generator().manual_seed(3))
        b = again.sample(pts, nrm, 0.8, 3, torch.Generator().manual_seed(3))
        torch.testing.assert_close(a, b)
    old = GrabNetSMPLX(body_space="rot6d").state()    # a checkpoint made before body_space existed
    for k in ("body_space", "prior_config"):
        old["model_config"].pop(k)
    assert GrabNetSMPLX.from_state(old).n_params == 193
    with pytest.raises(ValueError, match="body_space: expected"):
        GrabNetSMPLX(body_space="vposer")


def test_int8_storage_round_trip_error_is_within_half_a_step_and_the_model_reloads(tmp_path):
    from graspkit.models.wholegrasp import INT8_SCALE, dequantize_state, quantize_state
    from graspkit.train import load_checkpoint, save_checkpoint

    torch.manual_seed(0)
    model = WholeGraspVAE()
    for p in model.parameters():                        # non-zero output layers, so the comparison means something
        torch.nn.init.normal_(p, std=0.05)
    sd = model.state_dict()
    q = quantize_state(sd)
    w = sd["body_enc.0.weight"]
    assert q["body_enc.0.weight"].dtype == torch.int8
    step = w.abs().amax(1, keepdim=True) / 127                      # the quantisation step of each row
    err = (dequantize_state(q)["body_enc.0.weight"] - w).abs()
    assert (err <= step / 2 + 1e-3 * step + 1e-7).all()             # + float16 rounding of the scale
    assert q["body_enc.0.bias"].dtype == torch.float16 and q["marker_mean"].dtype == torch.float16
    assert not any(k.endswith(INT8_SCALE) for k in dequantize_state(q))
    path = save_checkpoint(tmp_path / "wg.pt", {"model": q, "model_config": model.state()["model_config"]})
    back = WholeGraspVAE.from_state(load_checkpoint(path))          # weights_only load
    g = torch.Generator
    pts = torch.randn(P, 3, generator=g().manual_seed(3)) * 0.05
    nrm = torch.nn.functional.normalize(pts, dim=-1)
    a = model.sample(pts, nrm, 0.8, 3, g().manual_seed(1))
    b = back.sample(pts, nrm, 0.8, 3, g().manual_seed(1))
    assert (a.markers - b.markers).abs().max() < 0.02 * a.markers.abs().max()
    assert (a.object_contact - b.object_contact).abs().max() < 0.02


def test_height_slope_normalisation_recovers_a_linear_height_dependence():
    """Markers built so that marker 0 (a 'foot') sits at z = -t_O (on the floor) and marker 1 (a 'hand') at a fixed
    place by the object: the fitted slopes are -1 and 0, and the untrained decoder (the conditional mean grasp) keeps
    the foot on the floor and the hand at the object at any height."""
    torch.manual_seed(0)
    batch = _batch(B=40)
    h = batch["height"]
    m = batch["markers"] * 0.01
    m[:, 0, 2] = -h[:, 0]
    m[:, 1] = torch.tensor([0.05, 0.0, 0.02])
    model = WholeGraspVAE().eval()
    model.fit_normalisation(m, h)
    assert model.marker_slope[0, 2].item() == pytest.approx(-1.0, abs=1e-5)
    assert model.marker_slope[1].abs().max().item() < 1e-6
    z = torch.zeros(2, 16)
    pts, nrm = batch["points"][:2], batch["normals"][:2]
    for t in (0.6, 1.4):
        out = model.decode(z, pts, nrm, torch.full((2, 1), t))["markers"]
        torch.testing.assert_close(out[:, 0, 2], torch.full((2,), -t), atol=1e-4, rtol=0)
        torch.testing.assert_close(out[:, 1], torch.tensor([[0.05, 0.0, 0.02]] * 2), atol=1e-5, rtol=0)
    # the residual std is what is left after the slope (the foot's z is exact here)
    resid = m - model.marker_mean - model.marker_slope * (h[:, :, None] - model.height_mean)
    torch.testing.assert_close(model.marker_std, resid.std(dim=(0, 1)).clamp_min(1e-3))
    # without it the decoder's mean ignores t_O, and checkpoints without the option load that way
    old = WholeGraspVAE(WholeGraspConfig(height_slope=False)).eval()
    old.fit_normalisation(m, h)
    a = old.decode(z, pts, nrm, torch.full((2, 1), 0.6))["markers"]
    b = old.decode(z, pts, nrm, torch.full((2, 1), 1.4))["markers"]
    torch.testing.assert_close(a, b)
    st = model.state()
    st["model_config"].pop("height_slope")
    for k in ("marker_slope", "height_mean"):
        st["model"].pop(k)
    assert WholeGraspVAE.from_state(st).cfg.height_slope is False


def test_hand_pca_codes_each_hand_about_its_own_mean():
    """HandPCA is each hand's PCA about that hand's mean (the file's hands_meanl / hands_meanr, as smplx adds them):
    zero coefficients decode to that side's mean, and a pose in the span of the first 24 components round-trips."""
    from graspkit.body import BodyModel
    from graspkit.models.wholegrasp import HandPCA
    from graspkit.paths import default_model_path

    pca = HandPCA(BodyModel.from_file(default_model_path()))
    with np.load(default_model_path(), allow_pickle=False) as f:
        mean = {"left": f["hands_meanl"], "right": f["hands_meanr"]}
        comps = {"left": f["hands_componentsl"], "right": f["hands_componentsr"]}
    assert not np.allclose(mean["left"], mean["right"])                       # mirrored hands: not the same
    c = torch.randn(3, 24, generator=torch.Generator().manual_seed(0)) * 0.5
    for side in ("left", "right"):
        np.testing.assert_allclose(pca.decode(torch.zeros(1, 24), side)[0].numpy(), mean[side], atol=1e-6)
        pose = mean[side] + c.numpy() @ comps[side][:24]
        np.testing.assert_allclose(pca.decode(c, side).numpy(), pose, atol=1e-5)
        np.testing.assert_allclose(pca.encode(torch.as_tensor(pose, dtype=torch.float32), side).numpy(), c.numpy(),
                                   atol=1e-5)


def test_marker_error_is_the_mean_marker_distance_in_cm():
    """The logged marker_error_cm is the mean distance between generated and true markers in cm (3 cm / 4 cm off along two
    axes: 5 cm; a second sample twice as far: 7.5 cm on average)."""
    model = WholeGraspVAE(WholeGraspConfig(multitask=False))
    truth = torch.randn(2, 143, 3)
    shift = torch.zeros(2, 143, 3)
    shift[..., 0], shift[..., 1] = 0.03, -0.04                      # every marker 5 cm off
    shift[1, :, :] *= 2                                             # the second sample 10 cm off
    out = {"markers": truth + shift, "mu": torch.zeros(2, 16), "logvar": torch.zeros(2, 16)}
    logs = model.loss({"markers": truth}, out, 0, 1)
    torch.testing.assert_close(logs["marker_error_cm"], torch.tensor(7.5), atol=1e-4, rtol=0)


def test_eq1_marker_l1_is_summed_over_markers_and_averaged_over_the_batch():
    """Module doc (Reductions): |M - M~|_1 is summed over the 143 markers (and their coordinates) and averaged over the
    batch. Every marker 3 cm / 4 cm off along x / y (L1 7 cm), the second sample twice as far: 143 * 0.07 * (1 + 2) / 2."""
    model = WholeGraspVAE(WholeGraspConfig(multitask=False))
    truth = torch.randn(2, 143, 3, generator=torch.Generator().manual_seed(0))
    shift = torch.zeros(2, 143, 3)
    shift[..., 0], shift[..., 1] = 0.03, -0.04
    shift[1] *= 2
    out = {"markers": truth + shift, "mu": torch.zeros(2, 16), "logvar": torch.zeros(2, 16)}
    logs = model.loss({"markers": truth}, out, 0, 1)
    torch.testing.assert_close(logs["rec_markers"], torch.tensor(143 * 0.07 * 1.5), atol=1e-4, rtol=0)
    # with a zero posterior (KL 0) the single-task loss is that L1 alone
    torch.testing.assert_close(logs["loss"], torch.tensor(143 * 0.07 * 1.5), atol=1e-4, rtol=0)


def test_grabnet_parameters_put_the_body_in_the_object_frame():
    """grasp_params: the translation is the body's in the object frame (world transl minus the object translation),
    so the markers the parameters pose are the world markers minus the object translation. Truth: the same body posed
    directly from the absolute fullpose and world translation (hands in the PCA span, so their codes are exact)."""
    from graspkit.body import BodyModel
    from graspkit.body.markers import saga_markers
    from graspkit.models.gnet import SparseBody
    from graspkit.models.wholegrasp import HandPCA, grasp_params, params_to_rotmats
    from graspkit.paths import default_model_path
    from graspkit.rotations import axis_angle_to_matrix
    bm = BodyModel.from_file(default_model_path())
    body, pca = SparseBody(bm, saga_markers(bm).vertex_ids), HandPCA(bm)
    g = torch.Generator().manual_seed(2)
    fp = torch.randn(3, 55, 3, generator=g) * 0.2
    fp[:, 22:25] = 0.0                                               # jaw and eyes at rest (not in the parameters)
    fp[:, 25:] = pca.decode(torch.randn(6, 24, generator=g) * 0.5, "left").view(3, 2, 15, 3).reshape(3, 30, 3)
    fp[:, 40:55] = pca.decode(torch.randn(3, 24, generator=g) * 0.5, "right").view(3, 15, 3)
    transl, betas = torch.randn(3, 3, generator=g), torch.randn(3, 10, generator=g)
    obj = torch.tensor([[0.4, -0.2, 0.9], [1.0, 0.5, 0.7], [-0.3, 0.8, 1.1]])
    x = grasp_params(fp, transl, betas, obj, pca)
    world = body(axis_angle_to_matrix(fp), betas, transl)[0]
    local = body(*params_to_rotmats(x, pca))[0]
    torch.testing.assert_close(local, world - obj[:, None], atol=1e-4, rtol=0)


def test_reconstruction_marker_error_is_the_mean_distance_in_cm():
    """reconstruction_metrics' marker_error_cm (the validation figure train_wholegrasp reports) is the mean Euclidean
    distance between reconstructed and true markers, in cm. An untrained decoder (zero output layer, zero
    normalisation) returns every marker at the origin; true markers 3 cm / 4 cm off along x / y (5 cm away), the second
    sample twice as far: 7.5 cm (an L1 |dx| + |dy| would give 10.5)."""
    from graspkit.models.wholegrasp import reconstruction_metrics
    model = WholeGraspVAE(WholeGraspConfig(multitask=False))
    g = torch.Generator().manual_seed(1)
    pts = torch.randn(2, 512, 3, generator=g) * 0.05
    markers = torch.zeros(2, 143, 3)
    markers[..., 0], markers[..., 1] = 0.03, -0.04
    markers[1] *= 2

    class Data:
        data = {"markers": markers, "points": pts, "normals": torch.nn.functional.normalize(pts, dim=-1),
                "height": torch.full((2, 1), 0.8)}

        def __len__(self):
            return 2

    res = reconstruction_metrics(model.train(), Data())
    assert abs(res["marker_error_cm"] - 7.5) < 1e-4
    assert model.training                                  # the caller's mode restored


def _eq3_numpy(mp, m, cm, pts, co, nrm=None):
    """Eq. 3 per sample with scipy KD-trees: squared unsigned distances (as printed), or with normals Euclidean and
    d(m, O) signed by the nearest point's normal; contacts weight, summed over markers / points."""
    out = []
    for b in range(len(m)):
        tree = cKDTree(pts[b])

        def dmo(x):
            d, i = tree.query(x)
            if nrm is None:
                return d ** 2
            return d * np.sign(((x - pts[b][i]) * nrm[b][i]).sum(-1))

        def dom(x):
            d, _ = cKDTree(x).query(pts[b])
            return d ** 2 if nrm is None else d
        out.append((cm[b] * np.abs(dmo(mp[b]) - dmo(m[b]))).sum() + (co[b] * np.abs(dom(mp[b]) - dom(m[b]))).sum())
    return np.array(out)


def test_eq3_consistency_averages_over_the_batch_and_passes_no_gradient_to_the_contacts():
    """Module doc: Eq. 3's sums are averaged over the batch, and the predicted contacts weight the distances without
    passing gradients back. Two samples, the hand-made case (1.6e-3: 8e-4 each side) and one that fits (0): 8e-4."""
    pts = torch.tensor([[[0.0, 0, 0], [1.0, 0, 0]]]).expand(2, -1, -1)
    m = torch.tensor([[[0.0, 0.01, 0], [1.0, 0.5, 0]]]).expand(2, -1, -1)
    m_pred = torch.stack([torch.tensor([[0.0, 0.03, 0], [1.0, 0.5, 0]]), m[1]]).requires_grad_(True)
    cm = torch.ones(2, 2, requires_grad=True)
    co = torch.tensor([[1.0, 0.0], [1.0, 0.0]], requires_grad=True)
    loss = consistency_loss(m_pred, m, cm, pts, co)
    assert loss.item() == pytest.approx(0.5 * 1.6e-3, rel=1e-4)
    loss.backward()
    assert cm.grad is None and co.grad is None
    assert m_pred.grad.abs().sum() > 0


@pytest.mark.parametrize("consistency", ["paper", "signed"])
def test_eq1_to_3_total_loss_weights_each_term_by_its_lambda(consistency):
    """SAGA Eq. 1-3: L = |M - M~|_1 + lambda_M BCE_5(C_M) + lambda_O BCE_3(C_O) + lambda_c L_c (+ lambda_KL Psi(KL),
    0 at a zero posterior), L_c weighted by the PREDICTED contacts C~; each piece computed here independently (torch's
    weighted BCE, scipy KD-trees for Eq. 3, signed by the normals for consistency='signed'), lambdas 2, 3, 5."""
    torch.manual_seed(0)
    model = WholeGraspVAE(WholeGraspConfig(lambda_m=2.0, lambda_o=3.0, lambda_c=5.0, consistency=consistency)).eval()
    torch.nn.init.normal_(model.out_markers.weight, std=0.02)
    b = _batch(B=2, contact=0.3)
    with torch.no_grad():
        out = dict(model(b))
    out["mu"], out["logvar"] = torch.zeros(2, 16), torch.zeros(2, 16)
    logs = model.loss(b, out, 0, 10)
    F = torch.nn.functional
    rec = (out["markers"] - b["markers"]).abs().sum((1, 2)).mean()
    bce_m = F.binary_cross_entropy(out["marker_contact"], b["marker_contact"],
                                   weight=torch.where(b["marker_contact"] > 0, 5.0, 1.0))
    bce_o = F.binary_cross_entropy(out["object_contact"], b["object_contact"],
                                   weight=torch.where(b["object_contact"] > 0, 3.0, 1.0))
    n = lambda k: out[k].double().numpy() if k in out else None  # noqa: E731
    c = _eq3_numpy(n("markers"), b["markers"].double().numpy(), n("marker_contact"), b["points"].double().numpy(),
                   n("object_contact"), b["normals"].double().numpy() if consistency == "signed" else None).mean()
    assert c > 1e-3
    assert logs["consistency"].item() == pytest.approx(c, rel=1e-3)
    want = rec.item() + 2 * bce_m.item() + 3 * bce_o.item() + 5 * c
    assert logs["loss"].item() == pytest.approx(want, rel=1e-4)


def test_encoder_reads_the_standardised_markers_the_decoder_emits():
    """Module doc (marker normalisation): the networks see and emit standardised markers, M = mean + slope (t_O -
    mean t_O) + std * u. Round trip: the markers the decoder makes from its output u, fed to the encoder, reach the
    encoder's body branch as u again (at heights other than the mean, with a fitted slope and per-axis std != 1)."""
    torch.manual_seed(0)
    model = WholeGraspVAE().eval()
    b = _batch(B=40, seed=1, contact=0.3)
    m = b["markers"].clone()
    m[:, :, 2] += -b["height"]                                                # a height dependence to fit
    model.fit_normalisation(m, b["height"])
    assert model.marker_slope.abs().max() > 0.5 and (model.marker_std - 1).abs().min() > 0.3
    torch.nn.init.normal_(model.out_markers.weight, std=0.3)
    seen = {}
    model.out_markers.register_forward_hook(lambda mod, i, o: seen.__setitem__("u", o.detach()))
    model.body_enc.register_forward_hook(lambda mod, i, o: seen.__setitem__("x", i[0].detach()))
    h = torch.tensor([[0.55], [1.45]])
    with torch.no_grad():
        dec = model.decode(torch.randn(2, 16), b["points"][:2], b["normals"][:2], h)
        model.encode(dec["markers"], dec["marker_contact"], b["points"][:2], b["normals"][:2], dec["object_contact"], h)
    torch.testing.assert_close(seen["x"][:, :143 * 3], seen["u"], atol=1e-4, rtol=1e-4)


def test_sampling_leaves_the_model_in_the_mode_it_found():
    """sample() switches to eval for inference and must hand the model back as it was: a model being trained
    (dropout/BatchNorm in train mode) stays in training mode, an evaluated one in eval mode."""
    torch.manual_seed(0)
    model = WholeGraspVAE()
    g = torch.Generator().manual_seed(2)
    pts = torch.randn(P, 3, generator=g) * 0.05
    nrm = torch.nn.functional.normalize(pts, dim=-1)
    model.train()
    model.sample(pts, nrm, 0.9, 1, g)
    assert model.training and all(mod.training for mod in model.modules())
    model.eval()
    model.sample(pts, nrm, 0.9, 1, g)
    assert not model.training


def test_yaw_spread_is_even_turns_about_z_round_the_full_circle():
    """yaw_spread(m, 8): the set turned by 0, 45, ..., 315 degrees about z (scipy's Rotation), stacked turn by turn;
    over the full circle each marker's 8 copies average to its height on the z axis; float64 markers stay float64."""
    for dtype, tol in ((torch.float32, 1e-5), (torch.float64, 1e-12)):
        m = torch.randn(2, 5, 3, generator=torch.Generator().manual_seed(0), dtype=dtype)
        s = yaw_spread(m, 8)
        assert s.shape == (16, 5, 3) and s.dtype == dtype
        for k in range(8):
            R = Rotation.from_euler("z", 45 * k, degrees=True)
            np.testing.assert_allclose(s[2 * k:2 * k + 2].numpy(),
                                       R.apply(m.reshape(-1, 3).double().numpy()).reshape(2, 5, 3), atol=tol)
        mean = s.view(8, 2, 5, 3).mean(0)
        np.testing.assert_allclose(mean[..., :2].numpy(), 0.0, atol=tol)


def test_sample_accepts_the_documented_bounds_of_height_and_point_count():
    """check_height's docstring: heights in [0, MAX_METRES] m (0 included); check_sample_inputs: P >= the first
    PointNet++ level's centres (exactly that many included, one fewer named)."""
    from graspkit.models.wholegrasp import check_height
    check_height(0.0, "object_height")
    torch.manual_seed(0)
    model = WholeGraspVAE().eval()
    least = model.obj_dec.sa[0].npoint
    g = torch.Generator().manual_seed(3)
    pts = torch.randn(least, 3, generator=g) * 0.05
    nrm = torch.nn.functional.normalize(pts, dim=-1)
    out = model.sample(pts, nrm, object_height=0.0, n=1, generator=g)
    assert out.markers.shape == (1, 143, 3)
    with pytest.raises(ValueError, match="object_points"):
        model.sample(pts[1:], nrm[1:], n=1)


def test_grabnet_kl_weight_rises_linearly_to_the_papers_end_point(bm):
    """GrabNet-SMPLX's loss (docstring: lambda_KL rising linearly to 0.2 as WholeGrasp's, SAGA A.4's 0.005 e over
    40 epochs): with the parameters and markers exact, the loss is lambda_KL Psi(KL), 0.005 Psi in the first epoch
    (0-based) and 0.2 Psi in the 40th, Psi(s) = sqrt(s^2 + 1) - 1 of KL = 32 (mu = 2 in 16 dimensions)."""
    from graspkit.body.markers import saga_markers
    from graspkit.models.gnet import SparseBody
    from graspkit.models.wholegrasp import GrabNetSMPLX, HandPCA
    torch.manual_seed(0)
    model = GrabNetSMPLX(body_space="rot6d")
    body, pca = SparseBody(bm, saga_markers(bm).vertex_ids), HandPCA(bm)
    x = torch.zeros(2, model.n_params)
    x[:, 3:9] = torch.tensor([1.0, 0, 0, 0, 1.0, 0])                        # identity rotations (6D)
    x[:, 19:19 + 126] = torch.tensor([1.0, 0, 0, 0, 1.0, 0]).repeat(21)
    with torch.no_grad():
        markers = body(*model.to_rotmats(x, pca))[0]
    out = {"params": x, "mu": torch.full((2, 16), 2.0), "logvar": torch.zeros(2, 16)}
    psi = math.sqrt(32 ** 2 + 1) - 1
    for e, w in ((0, 0.005), (19, 0.1), (39, 0.2)):
        logs = model.loss({"params": x, "markers": markers}, out, body, pca, e, 40)
        assert logs["loss"].item() == pytest.approx(w * psi, rel=1e-4, abs=1e-5), e


def test_the_kl_weight_is_annealed_over_valid_epochs_only_and_bool_labels_are_named():
    """lambda_KL = 0.2 (e + 1) / E for 0 <= e < E (A.4); an epoch past the schedule gave a weight past the paper's
    end value and a negative epoch a negative one (the KL term then rewarded a large KL), an independent check."""
    from graspkit.models.blocks import annealed_kl_weight

    assert [annealed_kl_weight(0.2, e, 4) for e in range(4)] == pytest.approx([0.05, 0.1, 0.15, 0.2])
    model = WholeGraspVAE()
    batch = _batch()
    out = model(batch)
    for epoch, epochs, name in ((10, 10, "epoch"), (-5, 10, "epoch"), (0, 0, "epochs"), (1.5, 10, "epoch")):
        with pytest.raises(ValueError, match=f"^{name}:"):
            model.loss(batch, out, epoch, epochs)
    with pytest.raises(ValueError, match="marker_contact: expected float contact labels in \\[0, 1\\]"):
        model({**batch, "marker_contact": batch["marker_contact"] > 0.5})
    with pytest.raises(ValueError, match="object_contact: expected float contact labels"):
        model({**batch, "object_contact": batch["object_contact"] * 2})


def test_eq3_distances_of_float32_points_far_from_the_origin_are_those_near_it():
    """SAGA's d(x, Y) through cdist's |a|^2 + |b|^2 - 2ab read a touching marker 25 cm away 1,000 m out in float32:
    the distances are now taken about the object's mean (truth: float64 on the same rounded inputs)."""
    g = torch.Generator().manual_seed(3)
    for shift in (10.0, 1000.0):
        pts = (torch.randn(1, 400, 3, generator=g, dtype=torch.float64) * 0.05 + shift).float()
        mk = (pts[:, :50].double() + torch.randn(1, 50, 3, generator=g, dtype=torch.float64) * 0.01).float()
        want = torch.cdist(mk.double() - shift, pts.double() - shift).pow(2)
        d_m, d_o = consistency_distances(mk, pts)
        assert (d_m.double() - want.min(2).values).abs().max() < 1e-6            # m²: a 1-mm error at 1 cm reads 2e-5
        assert (d_o.double() - want.min(1).values).abs().max() < 1e-6
        assert (squared_min_distance(mk, pts).double() - want.min(2).values).abs().max() < 1e-6
