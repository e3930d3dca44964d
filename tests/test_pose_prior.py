"""The learned pose prior (VPoser's role in SAGA's GraspPose-Opt): mirroring, round trips, plausible samples."""
import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

from graspkit.data import load_motion
from graspkit.metrics import joint_limit_violation
from graspkit.models.pose_prior import (POSE_PRIOR_PATH, PosePrior, PosePriorConfig, body_poses_from_motions,
                                        load_pose_prior, mirror_body_pose)
from graspkit.paths import DATA_STUBS


@pytest.fixture(scope="module")
def held_out_poses():
    """Body poses of the shipped reaching clips (seed 0, not among the prior's training clips, which come from
    SeedSequence(0)-derived seeds)."""
    clips = [load_motion(p) for p in sorted((DATA_STUBS / "motion" / "reach").glob("*.npz"))[:4]]
    return torch.as_tensor(body_poses_from_motions(clips, stride=10))


def test_mirroring_is_an_involution_and_mirrors_the_skeleton(bm):
    g = np.random.default_rng(0)
    p = (g.normal(size=(3, 21, 3)) * 0.4).astype(np.float32)
    np.testing.assert_allclose(mirror_body_pose(mirror_body_pose(p)), p)
    with torch.no_grad():
        j = bm(body_pose=torch.as_tensor(p).reshape(3, 63)).joints[:, :22].numpy()
        jm = bm(body_pose=torch.as_tensor(mirror_body_pose(p)).reshape(3, 63)).joints[:, :22].numpy()
    from graspkit.models.pose_prior import _MIRROR
    # the procedural body is left-right symmetric: the mirrored pose puts every joint at the mirror image of its twin
    np.testing.assert_allclose(jm[:, _MIRROR] * np.array([-1, 1, 1]), j, atol=2e-3)


def test_shipped_prior_round_trips_held_out_poses(held_out_poses):
    prior = load_pose_prior()
    assert POSE_PRIOR_PATH.stat().st_size < 2_000_000
    with torch.no_grad():
        z = prior.encode(held_out_poses)
        back = prior.decode(z)
    from graspkit.rotations import axis_angle_to_matrix
    R1 = axis_angle_to_matrix(held_out_poses.reshape(-1, 21, 3))
    R2 = axis_angle_to_matrix(back.reshape(-1, 21, 3))
    angle = torch.rad2deg(torch.acos(((R1 * R2).sum((-1, -2)) - 1).div(2).clamp(-1, 1)))
    assert angle.mean() < 5.0, f"mean joint angle error {angle.mean():.2f} deg"
    # poses it knows sit near the prior's centre (|z|^2 about the latent size or less)
    assert z.pow(2).sum(-1).median() < 2 * prior.cfg.latent


def test_prior_samples_respect_joint_limits():
    prior = load_pose_prior()
    with torch.no_grad():
        pose = prior.decode(torch.randn(200, 32, generator=torch.Generator().manual_seed(0)))
    full = torch.zeros(200, 55, 3)
    full[:, 1:22] = pose.view(200, 21, 3)
    worst = joint_limit_violation(full.numpy()).max(1)                  # per sample, the worst joint (deg)
    assert (worst <= 5.0).mean() > 0.9, f"{(worst > 5).mean():.2f} of samples break a joint limit by > 5 deg"


def test_untrained_and_bad_inputs():
    prior = PosePrior()
    with pytest.raises(ValueError, match="body_pose"):
        prior.encode(torch.zeros(2, 60))
    with pytest.raises(ValueError, match="z"):
        prior.decode(torch.zeros(2, 31))
    with pytest.raises(ValueError, match=r"z: expected shape \(B, 32\), got NoneType"):
        prior.decode(None)
    with pytest.raises(ValueError, match="z: contains NaN"):          # NaN poses came back silently
        prior.decode(torch.full((2, 32), float("nan")))
    with pytest.raises(ValueError, match="body_pose: contains NaN"):
        prior.encode(torch.full((2, 63), float("nan")))
    z64 = torch.randn(2, 32, dtype=torch.float64)                      # failed inside the MLP on a dtype mismatch
    torch.testing.assert_close(prior.eval().decode(z64), prior.decode(z64.float()), rtol=0, atol=0)
    out = prior.loss(torch.zeros(4, 63))
    assert set(out) >= {"loss", "rec", "kl"} and torch.isfinite(out["loss"])
    again = PosePrior.from_state(prior.state())
    z = torch.randn(3, 32)
    torch.testing.assert_close(again.decode(z), prior.eval().decode(z))


def test_a_changed_seed_or_epoch_count_starts_a_new_run(tmp_path, monkeypatch):
    """The resumable run is named by every setting and the data (train.run_path), not by --out: training again to the
    same file with another seed or epoch count gives what a fresh run gives (it used to resume the old run)."""
    from graspkit.models.pose_prior import train_pose_prior
    from graspkit.train import load_checkpoint

    monkeypatch.setenv("GRASPKIT_CACHE", str(tmp_path / "cache"))
    poses = (0.3 * np.random.default_rng(0).standard_normal((300, 21, 3))).astype(np.float32)
    weights = lambda p: load_checkpoint(p)["model"]                                 # noqa: E731
    kw = dict(poses=poses, batch_size=64, progress=False)
    train_pose_prior(tmp_path / "x.pt", epochs=1, seed=0, **kw)
    train_pose_prior(tmp_path / "y.pt", epochs=1, seed=1, **kw)
    train_pose_prior(tmp_path / "x.pt", epochs=1, seed=1, **kw)                     # same --out, another seed
    a, b = weights(tmp_path / "x.pt"), weights(tmp_path / "y.pt")
    assert all(torch.equal(a[k], b[k]) for k in a)
    train_pose_prior(tmp_path / "z.pt", epochs=2, seed=1, **kw)
    train_pose_prior(tmp_path / "x.pt", epochs=2, seed=1, **kw)                     # more epochs: a fresh 2-epoch run
    a, c = weights(tmp_path / "x.pt"), weights(tmp_path / "z.pt")
    assert all(torch.equal(a[k], c[k]) for k in a)


def test_rec_is_the_per_pose_sum_of_squared_matrix_errors():
    """The pose prior's reconstruction term: the squared error of the 21 decoded rotation matrices summed per pose,
    averaged over the batch, against scipy's matrices of the input axis-angles."""
    from scipy.spatial.transform import Rotation

    torch.manual_seed(0)
    m = PosePrior().eval()
    x = 0.3 * torch.randn(4, 63)
    out = m.loss(x)
    R = m.decode_rotmats(m.encode(x)).detach().double().numpy()
    target = Rotation.from_rotvec(x.double().numpy().reshape(-1, 3)).as_matrix().reshape(4, 21, 3, 3)
    np.testing.assert_allclose(out["rec"].item(), ((R - target) ** 2).sum((1, 2, 3)).mean(), rtol=1e-4)


def test_angle_error_is_the_mean_geodesic_angle_of_the_decoded_rotations():
    """The logged angle error is the mean geodesic angle between the decoded and the input rotations (scipy)."""
    torch.manual_seed(0)                                   # the network's initial weights
    m = PosePrior().eval()
    x = 0.4 * torch.randn(3, 63, generator=torch.Generator().manual_seed(1))
    out = m.loss(x)
    R = m.decode_rotmats(m.encode(x)).detach().double().numpy().reshape(-1, 3, 3)
    target = Rotation.from_rotvec(x.double().numpy().reshape(-1, 3))
    ang = (Rotation.from_matrix(R).inv() * target).magnitude()
    assert out["angle_error_deg"].item() == pytest.approx(np.rad2deg(ang).mean(), abs=0.05)


def test_loss_is_rec_plus_beta_times_the_closed_form_kl():
    """The beta-VAE objective: loss = rec + kl_weight * KL(q || N(0, I)), the KL in closed form from the posterior
    (summed over the latent, averaged over the batch), for a kl_weight that is not 1."""
    torch.manual_seed(0)
    m = PosePrior(PosePriorConfig(kl_weight=0.37)).eval()
    x = 0.3 * torch.randn(5, 63, generator=torch.Generator().manual_seed(2))
    with torch.no_grad():
        out = m.loss(x)
        mu, logvar = m.posterior(x)
        mu, logvar = mu.double(), logvar.double()
        kl = (0.5 * (mu ** 2 + logvar.exp() - 1 - logvar)).sum(-1).mean()
    assert float(out["kl"]) == pytest.approx(float(kl), rel=1e-5)
    assert float(out["loss"]) == pytest.approx(float(out["rec"]) + 0.37 * float(kl), rel=1e-5)


def test_train_pose_prior_holds_out_its_validation_poses(tmp_path, monkeypatch):
    """train_pose_prior's split: the validation poses (val_fraction of them) are not in the training set, and the two
    sets together are every pose once."""
    import graspkit.train as train
    from graspkit.models.pose_prior import train_pose_prior

    monkeypatch.setenv("GRASPKIT_CACHE", str(tmp_path / "cache"))
    got = {}

    def fake_fit(model, step, dataset, cfg, **kw):
        got["train"], got["val"] = dataset.tensors[0], kw["val_dataset"].tensors[0]
        return []

    monkeypatch.setattr(train, "fit", fake_fit)
    poses = (0.3 * np.random.default_rng(0).standard_normal((40, 21, 3))).astype(np.float32)
    train_pose_prior(tmp_path / "x.pt", poses=poses, epochs=1, val_fraction=0.25, progress=False)
    tr, va = got["train"].numpy(), got["val"].numpy()
    assert len(va) == 10 and len(tr) == 30
    rows = lambda a: {r.tobytes() for r in a}           # noqa: E731
    assert not rows(tr) & rows(va)
    assert rows(tr) | rows(va) == rows(poses.reshape(-1, 63))


def test_held_out_figures_use_other_clips_and_match_scipy(held_out_poses, tmp_path, monkeypatch, capsys):
    """The logged "val" rows of training are a row split of the tiled, mirrored array (copies of training rows among
    them, an independent check found): the held-out clips come from another seed stream, and angle_error is the mean
    joint angle between the poses and their round trip, as scipy measures it; `train pose_prior` prints both."""
    from graspkit import cli
    from graspkit.models import pose_prior as P

    for seed in (0, 1, 7):
        train = set(np.random.SeedSequence(seed).generate_state(400).tolist())
        assert not train & set(np.random.SeedSequence([seed, 1]).generate_state(400).tolist())
    m = load_pose_prior()
    x = held_out_poses[:40]
    back = m.decode(m.posterior(x.reshape(len(x), -1))[0]).detach().numpy().reshape(-1, 3)
    want = np.rad2deg((Rotation.from_rotvec(back).inv() * Rotation.from_rotvec(x.reshape(-1, 3).numpy())).magnitude())
    assert P.angle_error(m, x) == pytest.approx(want.mean(), abs=2e-3)
    small = (0.3 * np.random.default_rng(0).standard_normal((200, 21, 3))).astype(np.float32)
    monkeypatch.setenv("GRASPKIT_CACHE", str(tmp_path / "cache"))
    monkeypatch.setattr(P, "pose_training_set", lambda n, seed, extra=None: small)
    monkeypatch.setattr(P, "heldout_clip_poses", lambda n, seed: held_out_poses.numpy())
    data = tmp_path / "grasps"                   # the shipped training grasps and one relabelled as the apple's
    data.mkdir()
    for f in sorted((DATA_STUBS / "grasps").glob("grasp_*.npz")):
        with np.load(f, allow_pickle=False) as z:
            a = {k: z[k] for k in z.files}
        if str(a["obj_name"]) == "pitcher":
            np.savez(data / f.name, **a)
    np.savez(data / "grasp_009999.npz", **dict(a, obj_name=np.array("apple")))
    assert cli.main(["train", "pose_prior", "--epochs", "1", "--out", str(tmp_path / "p.pt"), "--data", str(data)]) == 0
    line = [s for s in capsys.readouterr().out.splitlines() if s.startswith("wrote")][0]
    prior = load_pose_prior(tmp_path / "p.pt")
    held, val = P.angle_error(prior, held_out_poses), P.angle_error(prior, a["body.params.body_pose"].reshape(1, 21, 3))
    assert "joint angle error (deg): row split" in line and f"held-out clips {held:.2f}" in line
    assert f"validation-object grasps {val:.2f} (1)" in line
