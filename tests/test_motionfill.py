"""MotionFill-VAE (SAGA §3.3): shapes, the trajectory velocity against the data module, Eq. 8 on hand-made cases."""
from dataclasses import replace

import numpy as np
import pytest
import torch
from torch import nn

from graspkit.data.motionfill_dataset import MotionFillStats, global_motion, interpolated_trajectory, local_motion
from graspkit.models.blocks import kl_standard_normal, robust_kl
from graspkit.models.motionfill import (FEATURES, NUM_FRAMES, NUM_ROOT, LocalMotionFill, MotionFillConfig,
                                        MotionFillVAE, TemporalMotionFill, TrajFill, dct_basis, traj_velocity)


def _batch(B: int = 3, seed: int = 0) -> dict[str, torch.Tensor]:
    g = np.random.default_rng(seed)
    heading = np.cumsum(g.normal(0, 0.02, (B, NUM_ROOT)), 1)
    xy = np.cumsum(g.normal(0, 0.02, (B, NUM_ROOT, 2)), 1)
    traj = np.concatenate([xy, np.cos(heading)[..., None], np.sin(heading)[..., None]], -1).astype(np.float32)
    local, vel = zip(*[local_motion(g.normal(0, 0.3, (NUM_FRAMES, 79, 3)), t) for t in traj])
    return {"traj": torch.as_tensor(traj), "traj_interp": torch.as_tensor(interpolated_trajectory(traj)),
            "local": torch.as_tensor(np.stack(local)).float(), "vel": torch.as_tensor(np.stack(vel)).float(),
            "contacts": torch.as_tensor(g.random((B, NUM_FRAMES, 4)) < 0.5).float()}


def test_trajectory_velocity_matches_the_data_module():
    b = _batch()
    torch.testing.assert_close(traj_velocity(b["traj"]), b["vel"], atol=1e-5, rtol=1e-4)


def test_trajfill_starts_at_the_straight_trajectory_and_local_fill_keeps_the_image_size():
    b = _batch()
    tf = TrajFill().eval()
    out, mu, logvar = tf(b["traj"], b["traj_interp"])            # A.2's sizes by default
    torch.testing.assert_close(out, b["traj_interp"])            # zero-initialised output layer
    assert mu.shape == (3, 512)
    lm = LocalMotionFill()
    img = torch.randn(2, 4, NUM_FRAMES, FEATURES)
    ch0, mu, _ = lm(img, img)
    assert ch0.shape == (2, NUM_FRAMES, FEATURES) and mu.shape == (2, 128)
    # zero-initialised output: the linear blend of the two known frames, contact logits 0
    s = torch.linspace(0, 1, NUM_FRAMES)[None, :, None]
    torch.testing.assert_close(ch0[..., :-4], ((1 - s) * img[:, 0, :1] + s * img[:, 0, -1:])[..., :-4])
    assert (ch0[..., -4:] == 0).all()


def test_loss_terms_and_gradients():
    torch.manual_seed(0)
    m = MotionFillVAE()
    b = _batch()
    logs = m.loss(b, trajectory="predicted")
    logs["loss"].backward()
    assert all(torch.isfinite(v) for v in logs.values())
    # at initialisation TrajFill returns Gamma_bar, so its term is |Gamma - Gamma_bar| averaged (reduction "mean")
    want = (b["traj"] - b["traj_interp"]).abs().mean()
    m.eval()
    assert m.loss(b, parts=("traj",))["traj"].item() == pytest.approx(want.item(), rel=1e-5)
    missing = [n for n, p in m.named_parameters() if p.grad is None]
    assert not missing


def test_mean_reduction_is_the_per_element_average_of_the_sum():
    """reduction="mean" (the authors' code): each reconstruction term is the "sum" term over its element count,
    the total loss the weighted terms plus Psi of each per-dimension KL, computed here by hand."""
    b = _batch()
    torch.manual_seed(0)
    m_sum = MotionFillVAE(MotionFillConfig(reduction="sum")).eval()
    m_mean = MotionFillVAE(MotionFillConfig(reduction="mean")).eval()
    m_mean.load_state_dict(m_sum.state_dict())
    torch.manual_seed(1)
    s = m_sum.loss(b)
    torch.manual_seed(1)
    a = m_mean.loss(b)
    counts = {"traj": NUM_ROOT * 4, "traj_vel": (NUM_ROOT - 1) * 4, "markers": NUM_FRAMES * (FEATURES - 4),
              "markers_vel": (NUM_FRAMES - 1) * (FEATURES - 4), "contacts": NUM_FRAMES * 4}
    for k, n in counts.items():
        assert a[k].item() == pytest.approx(s[k].item() / n, rel=1e-5), k
    torch.testing.assert_close(a["kl_motion"], s["kl_motion"])      # logged as the summed KL in both
    cfg = m_mean.cfg
    psi = lambda kl, d: (1 + (kl / d) ** 2) ** 0.5 - 1                # noqa: E731
    want = (a["traj"] + cfg.l1 * a["traj_vel"] + psi(a["kl_traj"], cfg.traj_latent) + cfg.l2 * a["contacts"]
            + cfg.l3 * a["markers"] + cfg.l4 * a["markers_vel"] + psi(a["kl_motion"], cfg.motion_latent))
    assert a["loss"].item() == pytest.approx(want.item(), rel=1e-5)
    with pytest.raises(ValueError, match="reduction"):
        MotionFillVAE(MotionFillConfig(reduction="median")).loss(b)


def test_image_round_trip_and_deterministic_sampling():
    torch.manual_seed(0)
    m = MotionFillVAE().eval()
    b = _batch()
    img, cond = m.image(b["local"], b["contacts"], b["vel"])
    local, contacts = m.split(img[:, 0])
    torch.testing.assert_close(local, b["local"])
    assert (cond[:, 0, 1:-1] == 0).all() and torch.equal(cond[:, 0, [0, -1]], img[:, 0, [0, -1]])
    s1 = m.sample(b["traj_interp"][0], b["local"][0], b["contacts"][0], 2, torch.Generator().manual_seed(1))
    s2 = m.sample(b["traj_interp"][0], b["local"][0], b["contacts"][0], 2, torch.Generator().manual_seed(1))
    torch.testing.assert_close(s1["markers"], s2["markers"])
    assert s1["markers"].shape == (2, NUM_FRAMES, 79, 3)
    again = MotionFillVAE.from_state(m.state())
    z = torch.ones(1, m.cfg.traj_latent)
    torch.testing.assert_close(again.traj.decode(z, b["traj_interp"][:1]), m.traj.decode(z, b["traj_interp"][:1]))
    torch.nn.init.normal_(m.local.out.weight, std=0.1)           # zero-initialised outputs ignore the latents
    torch.nn.init.normal_(m.traj.out.weight, std=0.1)
    s1 = m.sample(b["traj_interp"][0], b["local"][0], b["contacts"][0], 2, torch.Generator().manual_seed(1))
    s3 = m.sample(b["traj_interp"][0], b["local"][0], b["contacts"][0], 2, torch.Generator().manual_seed(2))
    assert not torch.allclose(s1["markers"], s3["markers"])       # another seed, another sample
    with pytest.raises(ValueError, match="traj_interp"):
        m.sample(b["traj_interp"][0, :10], b["local"][0], b["contacts"][0], 2)
    with pytest.raises(ValueError, match="local"):
        m.sample(b["traj_interp"][0], b["local"][0, :, :78], b["contacts"][0], 2)
    with pytest.raises(ValueError, match="n: "):
        m.sample(b["traj_interp"][0], b["local"][0], b["contacts"][0], 0)
    for n in (2.5, True):
        with pytest.raises(ValueError, match="n: expected a whole number"):
            m.sample(b["traj_interp"][0], b["local"][0], b["contacts"][0], n)
    with pytest.raises(TypeError, match="generator: expected a torch.Generator"):     # torch's randn error before
        m.sample(b["traj_interp"][0], b["local"][0], b["contacts"][0], 2, generator="x")
    bad = b["local"][0].clone()
    bad[3, 4, 1] = float("nan")                                   # would give all-NaN markers without a word
    with pytest.raises(ValueError, match="local: expected finite"):
        m.sample(b["traj_interp"][0], bad, b["contacts"][0], 2)
    as_numpy = m.sample(b["traj_interp"][0].numpy(), b["local"][0].numpy(), b["contacts"][0].numpy(), 2,
                        torch.Generator().manual_seed(1))              # numpy arrays: the same sample
    torch.testing.assert_close(as_numpy["markers"], s1["markers"])


def test_kl_terms_against_torch_distributions():
    g = torch.Generator().manual_seed(0)
    mu, logvar = torch.randn(5, 7, generator=g), torch.randn(5, 7, generator=g)
    q = torch.distributions.Normal(mu, (0.5 * logvar).exp())
    p = torch.distributions.Normal(torch.zeros(5, 7), torch.ones(5, 7))
    want = torch.distributions.kl_divergence(q, p).sum(-1).mean()
    torch.testing.assert_close(kl_standard_normal(mu, logvar), want)
    torch.testing.assert_close(robust_kl(mu, logvar), torch.sqrt(1 + want ** 2) - 1)      # Eq. 2 / Eq. 9's Psi
    assert kl_standard_normal(torch.zeros(2, 3), torch.zeros(2, 3)).item() == 0.0


def test_paper_sizes_and_shipped_sizes():
    paper = MotionFillVAE(MotionFillConfig.paper())
    assert paper.traj.latent == 512 and paper.traj.out.in_features == 4 * 60 and paper.traj.dec[0].fc1.out_features == 8 * 60
    assert paper.traj.out.out_features == NUM_ROOT * 4 and isinstance(paper.local, LocalMotionFill)
    shipped = MotionFillVAE()                                       # A.2's TrajFill, graspkit's output layer
    assert shipped.traj.latent == 512 and shipped.traj.dec[0].fc1.out_features == 8 * 60
    assert isinstance(shipped.local, TemporalMotionFill) and shipped.traj.out.out_features == 16 * 4
    n = sum(p.numel() for p in shipped.parameters())
    assert n * 2 < 7.5e6                                            # float16 weights under 7.5 MB
    with pytest.raises(ValueError, match="local_arch"):
        MotionFillVAE(MotionFillConfig(local_arch="graph"))
    with pytest.raises(ValueError, match="basis"):
        TrajFill(basis=63)


def test_dct_basis_is_scipys_orthonormal_inverse_dct():
    from scipy.fft import idct

    c = np.random.default_rng(0).normal(size=(NUM_ROOT, 3))
    np.testing.assert_allclose(dct_basis(NUM_ROOT, NUM_ROOT).double().numpy() @ c, idct(c, axis=0, norm="ortho"),
                               atol=1e-5)
    np.testing.assert_allclose(dct_basis(NUM_ROOT, 16).double().numpy() @ c[:16],
                               idct(np.concatenate([c[:16], np.zeros((NUM_ROOT - 16, 3))]), axis=0, norm="ortho"),
                               atol=1e-5)


def test_band_limited_trajfill_has_no_frequencies_above_its_basis():
    """traj_basis = K: whatever the weights, the deviation from Gamma_bar has zero DCT coefficients above K."""
    from scipy.fft import dct

    b = _batch(B=4)
    torch.manual_seed(0)
    tf = TrajFill(latent=8, enc=64, widths=(64, 64), basis=16).eval()
    torch.nn.init.normal_(tf.out.weight, std=0.3)
    out = tf.decode(torch.randn(4, 8), b["traj_interp"]).detach().double().numpy()
    coef = dct(out - b["traj_interp"].double().numpy(), axis=1, norm="ortho")
    assert np.abs(coef[:, 16:]).max() < 1e-5 and np.abs(coef[:, :16]).max() > 1e-2
    full = TrajFill(latent=8, enc=64, widths=(64, 64)).eval()        # basis 0: A.2's per-frame output layer
    torch.nn.init.normal_(full.out.weight, std=0.3)
    coef = dct(full.decode(torch.randn(4, 8), b["traj_interp"]).detach().double().numpy()
               - b["traj_interp"].double().numpy(), axis=1, norm="ortho")
    assert np.abs(coef[:, 16:]).max() > 1e-2


def test_temporal_local_fill_starts_at_the_blend_and_reaches_about_twenty_frames():
    torch.manual_seed(0)
    lm = TemporalMotionFill(latent=8, width=16).eval()
    img = torch.randn(2, 4, NUM_FRAMES, FEATURES)
    img[:, 1:] = img[:, 1:, :, :1]                                 # velocity channels: one value per frame
    cond = img.clone()
    cond[:, 0, 1:-1] = 0
    ch0, mu, _ = lm(img, cond)
    assert ch0.shape == (2, NUM_FRAMES, FEATURES) and mu.shape == (2, 8)
    torch.testing.assert_close(ch0, LocalMotionFill.base(cond))     # zero-initialised output layer
    hidden = img.clone()
    hidden[:, 0, 1:-1] += 1.0                                       # the in-between frames: the encoder reads them
    assert not torch.allclose(lm.encode(hidden, cond)[0], mu)
    torch.nn.init.normal_(lm.out.weight, std=0.1)
    z = torch.randn(2, 8)
    out = lm.decode(z, cond)
    late = cond.clone()
    late[:, 1:, 45:] += 1.0                                         # root velocities of frames 45.. change
    diff = (lm.decode(z, late) - out).abs().amax((0, 2))            # per output frame
    # the convolutions reach about 20 frames: a frame hears of what lies further only through z and the blend
    assert diff[45:].min() > 0 and diff[:20].max() == 0


def test_checkpoints_from_before_the_temporal_network_load_as_they_were():
    """A state whose model_config predates local_arch / traj_basis rebuilds the image network and A.2's output."""
    torch.manual_seed(0)
    old = MotionFillVAE(MotionFillConfig(local_arch="image", traj_basis=0)).eval()
    state = old.state()
    for k in ("local_arch", "traj_basis", "temporal_width"):
        del state["model_config"][k]
    again = MotionFillVAE.from_state(state)
    assert again.cfg.local_arch == "image" and again.cfg.traj_basis == 0
    b = _batch()
    z = torch.randn(3, old.cfg.traj_latent)
    torch.testing.assert_close(again.traj.decode(z, b["traj_interp"]), old.traj.decode(z, b["traj_interp"]))


def test_global_motion_round_trip_through_the_model_image():
    """Canonical markers -> (local, vel) -> image -> split -> global markers gives the markers back."""
    b = _batch(B=2, seed=3)
    g = np.random.default_rng(3)
    markers = g.normal(0, 0.3, (NUM_FRAMES, 79, 3))
    local, vel = local_motion(markers, b["traj"][0].double().numpy())
    m = MotionFillVAE().eval()
    img, _ = m.image(torch.as_tensor(local)[None].float(), b["contacts"][:1], torch.as_tensor(vel)[None].float())
    loc, logits = m.split(img[:, 0])
    back = global_motion(loc[0].double().numpy(), b["traj"][0].double().numpy())
    np.testing.assert_allclose(back, markers, atol=1e-5)
    torch.testing.assert_close(logits, b["contacts"][:1])
    torch.testing.assert_close(traj_velocity(b["traj"][:1].double()).float(), torch.as_tensor(vel)[None].float(),
                               atol=1e-5, rtol=1e-4)


@pytest.mark.parametrize("arch", ["temporal", "image"])
def test_a_tiny_overfit_reduces_every_reconstruction_term(arch):
    torch.manual_seed(0)
    m = MotionFillVAE(MotionFillConfig(traj_latent=8, traj_enc=64, traj_widths=(64, 64), motion_latent=8,
                                       channels=(8, 8, 8, 8, 8), local_arch=arch, temporal_width=64,
                                       reduction="sum"))
    b = _batch(B=4, seed=1)
    t = torch.linspace(0, 1, NUM_FRAMES)[None, :, None, None]
    template = torch.as_tensor(np.random.default_rng(1).normal(0, 0.3, (1, 1, 79, 3))).float()
    b["local"] = template + 0.1 * torch.sin(2 * np.pi * t * torch.arange(1, 5).view(4, 1, 1, 1))   # smooth motions
    b["contacts"] = (torch.sin(2 * np.pi * t[..., 0] * 2 + torch.arange(4)) > 0).float().expand(4, -1, 4)
    opt = torch.optim.Adam(m.parameters(), lr=3e-3)
    m.set_stats(MotionFillStats.fit({"local": b["local"].numpy(), "vel": b["vel"].numpy()}))
    first = {k: v.item() for k, v in m.loss(b).items()}
    for _ in range(80):
        logs = m.loss(b)
        opt.zero_grad()
        logs["loss"].backward()
        opt.step()
    last = {k: v.item() for k, v in m.loss(b).items()}           # train mode: batch statistics, sampled latents
    assert last["loss"] < 0.2 * first["loss"]
    for k in ("traj", "markers", "markers_vel"):
        assert last[k] < 0.5 * first[k], k
    assert last["traj_vel"] < first["traj_vel"]
    # from 10.8 cm; in train mode (sampled latents, batch statistics) the last bits of other CPUs' kernels move it:
    # 0.49-1.29 cm under the four floating-point kernel sets measured (MKL_CBWR, ATEN_CPU_CAPABILITY)
    assert last["marker_error_cm"] < 2.0


def test_loss_weights_are_the_papers_and_weight_the_velocity_term():
    """SAGA A.4's {lambda_KL, l1, l2, l3, l4} = {1, 0.05, 1, 1, 0.5}, and TrajFill's part of Eq. 8 on a hand-built batch
    is L_traj + l1 L_vel + lambda_KL Psi(KL), recomputed here from the encoder's and decoder's outputs."""
    c = MotionFillConfig()
    assert (c.lambda_kl, c.l1, c.l2, c.l3, c.l4) == (1.0, 0.05, 1.0, 1.0, 0.5)
    torch.manual_seed(0)
    m = MotionFillVAE().eval()
    traj = torch.randn(2, 62, 4)
    batch = {"traj": traj, "traj_interp": torch.zeros(2, 62, 4), "vel": torch.zeros(2, 61, 3)}
    out = m.loss(batch, parts=("traj",))
    mu, logvar = m.traj.encode(traj, batch["traj_interp"])
    pred = m.traj.decode(mu, batch["traj_interp"])                      # eval mode: z = mu
    l_traj = (pred - traj).abs().mean()
    l_vel = ((pred[:, 1:] - pred[:, :-1]) - (traj[:, 1:] - traj[:, :-1])).abs().mean()
    torch.testing.assert_close(out["loss"], l_traj + 0.05 * l_vel + robust_kl(mu, logvar, per_dim=True),
                               atol=1e-5, rtol=1e-5)


def test_each_local_weight_multiplies_its_own_term():
    """Eq. 9's weights sit on their documented terms (l2 foot-contact BCE, l3 local markers, l4 marker velocity):
    raising one weight by 1 raises the loss by exactly its own term."""
    torch.manual_seed(0)
    m = MotionFillVAE().eval()                     # eval: z = mu, the loss is a deterministic function of the weights
    b = _batch()
    base_cfg = m.cfg
    with torch.no_grad():
        base = m.loss(b, parts=("local",))
        assert not torch.isclose(base["contacts"], base["markers"], rtol=1e-3)   # the terms can be told apart
        for weight, term in (("l2", "contacts"), ("l3", "markers"), ("l4", "markers_vel")):
            m.cfg = replace(base_cfg, **{weight: getattr(base_cfg, weight) + 1.0})
            more = m.loss(b, parts=("local",))
            torch.testing.assert_close(more["loss"] - base["loss"], base[term], atol=1e-5, rtol=1e-4)
    m.cfg = base_cfg


def _batch_with_markers(B: int = 2, seed: int = 0) -> dict[str, torch.Tensor]:
    g = np.random.default_rng(seed)
    heading = np.cumsum(g.normal(0, 0.05, (B, NUM_ROOT)), 1)
    xy = np.cumsum(g.normal(0, 0.03, (B, NUM_ROOT, 2)), 1)
    traj = np.concatenate([xy, np.cos(heading)[..., None], np.sin(heading)[..., None]], -1).astype(np.float32)
    markers = g.normal(0, 0.3, (B, NUM_FRAMES, 79, 3))
    local, vel = zip(*[local_motion(m, t) for m, t in zip(markers, traj)])
    return {"traj": torch.as_tensor(traj), "traj_interp": torch.as_tensor(interpolated_trajectory(traj)),
            "local": torch.as_tensor(np.stack(local)).float(), "vel": torch.as_tensor(np.stack(vel)).float(),
            "contacts": torch.as_tensor(g.random((B, NUM_FRAMES, 4)) < 0.5).float(), "markers": markers}


class _Echo(nn.Module):
    """A stand-in LocalMotionFill: returns the target's channel 0 with `shift` (normalised units) added to every
    marker x coordinate, and records the condition image it was given."""

    def __init__(self, shift: float = 0.0):
        super().__init__()
        self.shift, self.cond = shift, None

    def forward(self, target, cond):
        self.cond = cond
        ch0 = target[:, 0].clone()
        ch0[..., 0:-4:3] += self.shift
        z = torch.zeros(len(target), 4, requires_grad=True)
        return ch0, z, z


def test_marker_error_cm_is_the_mean_marker_distance_in_centimetres():
    """With unit marker statistics, decoded markers 2 cm off in x give marker_error_cm = 2.0."""
    m = MotionFillVAE().eval()
    m.local = _Echo(0.02)
    logs = m.loss(_batch_with_markers(), parts=("local",))
    assert logs["marker_error_cm"].item() == pytest.approx(2.0, rel=1e-4)


def test_fine_tuning_conditions_local_fill_on_trajfills_trajectory():
    """trajectory='predicted': the condition image's velocity channels are the root velocities of TrajFill's output
    (at initialisation exactly Gamma_bar), by the data module's local_motion, not those of the true trajectory."""
    torch.manual_seed(0)
    m = MotionFillVAE().eval()
    echo = _Echo()
    m.local = echo
    b = _batch_with_markers()
    m.loss(b, trajectory="predicted")
    got = echo.cond[:, 1:, :, 0].permute(0, 2, 1).double().numpy()          # (B, 61, 3) normalised = raw (stats 0/1)
    want = np.stack([local_motion(mk, ti)[1] for mk, ti in zip(b["markers"], b["traj_interp"].double().numpy())])
    np.testing.assert_allclose(got, want, atol=1e-5)
    assert np.abs(want - b["vel"].double().numpy()).max() > 1e-3             # the two trajectories differ


def test_sampled_contacts_are_probabilities():
    """sample() returns contact probabilities in [0, 1] (the sigmoid of the decoded logits), even when the decoded
    logits reach far outside it."""
    torch.manual_seed(0)
    m = MotionFillVAE().eval()
    torch.nn.init.normal_(m.local.out.weight, std=1.0)
    b = _batch_with_markers()
    s = m.sample(b["traj_interp"][0], b["local"][0], b["contacts"][0], 2, torch.Generator().manual_seed(1))
    c = s["contacts"]
    assert ((c >= 0) & (c <= 1)).all()
    assert ((c > 0.01) & (c < 0.99)).any()


def test_sample_refuses_contacts_outside_0_1_and_local_markers_in_millimetres():
    """sample() took contact labels of 5 and local markers in millimetres (returning markers 923 m away) without a
    word, where the loss and WholeGraspVAE.sample refuse them (an independent check); a bool mask stays accepted."""
    m = MotionFillVAE().eval()
    b = _batch_with_markers()
    args = b["traj_interp"][0], b["local"][0], b["contacts"][0]
    with pytest.raises(ValueError, match=r"contacts: expected contact probabilities in \[0, 1\]"):
        m.sample(args[0], args[1], torch.full_like(args[2], 5.0))
    with pytest.raises(ValueError, match="local: largest side .* metres"):
        m.sample(args[0], args[1] * 1000, args[2])
    s = m.sample(args[0], args[1], args[2] > 0.5, 1, torch.Generator().manual_seed(1))
    assert s["markers"].shape == (1, *args[1].shape)


def test_sampled_markers_follow_the_given_trajectory():
    """sample(traj=...) places the sampled local markers along the given trajectory: markers = global_motion(local,
    traj) (the data module's inverse of local_motion), not along the straight Gamma_bar."""
    torch.manual_seed(0)
    m = MotionFillVAE().eval()
    b = _batch_with_markers()
    s = m.sample(b["traj_interp"][0], b["local"][0], b["contacts"][0], 2, torch.Generator().manual_seed(1),
                 traj=b["traj"][0])
    want = global_motion(s["local"].double().numpy(), b["traj"][0].double().numpy()[None].repeat(2, 0))
    np.testing.assert_allclose(s["markers"].double().numpy(), want, atol=1e-4)
    straight = global_motion(s["local"].double().numpy(), b["traj_interp"][0].double().numpy()[None].repeat(2, 0))
    assert np.abs(straight - want).max() > 1e-2


def test_loss_names_unknown_parts_trajectory_and_a_batch_of_wrong_shape():
    """A typo in `parts` trained nothing and one in `trajectory` silently used the true velocities; wrong shapes
    failed deep in torch (an independent check). Each is now a ValueError naming the argument or the key."""
    m = MotionFillVAE()
    b = _batch()
    for kwargs, message in (({"parts": ("trajectory",)}, "parts:"), ({"parts": ()}, "parts:"),
                            ({"trajectory": "pred"}, "trajectory:"),
                            ({"parts": ("local",), "trajectory": "predicted"}, "trajectory: 'predicted' needs")):
        with pytest.raises(ValueError, match=message):
            m.loss(b, **kwargs)
    for key, value, message in (("local", b["local"][:, :, :78], r"batch\['local'\]: expected shape \(B, 61, 79, 3\)"),
                                ("vel", b["vel"][:, :60], r"batch\['vel'\]"),
                                ("vel", b["vel"][:2], r"batch\['vel'\]: expected shape \(B, 61, 3\) with B=3, got \(2, 61, 3\)"),
                                ("contacts", b["contacts"] * 2, r"batch\['contacts'\]: expected float contact labels")):
        with pytest.raises(ValueError, match=message):
            m.loss({**b, key: value})
    with pytest.raises(ValueError, match="missing key 'vel'"):
        m.loss({k: v for k, v in b.items() if k != "vel"})
    assert set(m.loss(b, parts=("local",))) >= {"markers", "contacts"}     # the checks leave valid calls alone
