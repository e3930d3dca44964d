"""WANDR's CVAE, losses, rollout schedule, batched generation and latent optimisation (tiny networks, sample clips)."""
import pytest
import torch

from graspkit import eval_wandr as E
from graspkit import intention as I
from graspkit.data import load_motion
from graspkit.data import wandr_dataset as W
from graspkit.models import wandr as M
from graspkit.optim.latent import latent_loss, optimise_latents
from graspkit.paths import DATA_STUBS

STUBS = DATA_STUBS / "motion"
# short, fast requests on tiny untrained networks: generate's notes on the shipped model's range do not apply here
pytestmark = pytest.mark.filterwarnings("ignore::graspkit.models.wandr.RangeWarning")
TINY = dict(latent=4, hidden=32, enc_layers=1, dec_layers=2, dropout=0.0)


@pytest.fixture(scope="module")
def clips(bm):
    return W.load_clips(W.list_clips(STUBS, limit=3), bm)


@pytest.fixture(scope="module")
def stats(clips):
    return W.compute_stats(clips, samples=500)


@pytest.fixture(scope="module")
def starts(bm):
    names = ["locomotion/locomotion_000000.npz", "reach/reach_000001.npz"]
    return W.held_out_starts([load_motion(STUBS / n) for n in names], names, bm, n=2, frame=3)


def _model(stats, **kw):
    torch.manual_seed(0)
    return M.WandrCVAE(M.WandrConfig(**{**TINY, **kw}), stats).eval()


def test_rollout_schedule_grows_linearly_to_ten():
    cfg = M.WandrConfig(ramp_epochs=5)
    assert [cfg.rollout_steps(e) for e in range(8)] == [0, 2, 4, 6, 8, 10, 10, 10]
    assert M.WandrConfig(ramp_epochs=0).rollout_steps(0) == 10


def test_ablations_drop_intention_parts_from_the_condition(stats):
    full = _model(stats)
    assert full.cond_dim == 268 + 7
    assert _model(stats, intention=("wrist",)).cond_dim == 268 + 3
    assert _model(stats, intention=("wrist", "pelvis")).cond_dim == 268 + 5
    assert _model(stats, intention=()).cond_dim == 268
    with pytest.raises(ValueError, match="intention"):
        M.WandrConfig(intention=("elbow",))
    s, i = torch.randn(2, 268), torch.randn(2, 7)
    c = _model(stats, intention=("wrist", "orientation")).condition(s, i)
    assert torch.allclose(c[:, 268:], ((i - stats["intention_mean"]) / stats["intention_std"])[:, :5])


def test_losses_are_the_papers_terms(clips, stats):
    model = _model(stats)
    ds = W.WindowDataset(clips, max_steps=3)
    items = ds.items[::40]
    torch.manual_seed(0)
    out = M.training_losses(model, clips, items, steps=3, generator=torch.Generator().manual_seed(0))
    cfg = model.cfg
    assert torch.isfinite(out["loss"])
    assert out["loss"].item() == pytest.approx((out["rec"] + cfg.alpha_kl * out["kl"] + cfg.w_joint * out["joint_cm2"]).item(),
                                               rel=1e-5)
    assert cfg.alpha_kl == 1e-2 and out["steps"] == 3


def test_step_gradient_mode_has_the_rollouts_losses_and_stops_the_gradient_at_each_state(clips, stats):
    """rollout_grad="step" (not in the paper) recomputes the rollout's steps from the states it visited with its
    noise: without dropout the losses equal "through"'s to rounding; its gradient differs (no backpropagation
    through time); step_stride keeps the reconstruction step and every n-th rollout step."""
    items = W.WindowDataset(clips, max_steps=6).items[::40]
    outs, grads = {}, {}
    for mode in ("through", "step"):
        model = _model(stats, w_contact=1.0, w_floor=1.0, w_foot=0.5, rollout_grad=mode).train()
        out = M.training_losses(model, clips, items, 6, generator=torch.Generator().manual_seed(3))
        out["loss"].backward()
        outs[mode], grads[mode] = out, model.decoder[0].weight.grad.clone()
    for k in ("loss", "rec", "kl", "joint_cm2", "contact_mm2", "floor_cm2", "foot_mm2"):
        assert outs["step"][k].item() == pytest.approx(outs["through"][k].item(), rel=1e-4), k
    assert not torch.allclose(grads["step"], grads["through"], rtol=1e-3)
    model = _model(stats, rollout_grad="step", step_stride=3).train()
    seen = []
    model.decode = (lambda f: (lambda z, c: seen.append(len(z)) or f(z, c)))(model.decode)
    M.training_losses(model, clips, items, 6, generator=torch.Generator().manual_seed(3))
    assert seen[:6] == [len(items)] * 6 and seen[6] == 3 * len(items)   # 6 rollout steps, then 0 + 2 of the 6
    with pytest.raises(ValueError, match="rollout_grad"):
        M.WandrConfig(rollout_grad="none")


def _windows(clips):
    """Every 40th window of the sample clips (3 rollout steps), its batch and the data's deltas (B, 5, 135)."""
    items = W.WindowDataset(clips, max_steps=3).items[::40]
    b = W.make_batch(clips, items, 3, generator=torch.Generator().manual_seed(0))
    return items, b, I.poses_to_deltas(b["p"])


def _replayed_losses(model, clips, items, d_gt, axis: int = 0, shift: float = 0.0):
    """training_losses over 3 rollout steps with a decoder that returns the data's next delta, `shift` (m) added to
    translation component `axis` (in the previous frame's heading frame) at every step."""
    calls = iter(range(4))

    def decode(z, cond):
        d = d_gt[:, next(calls) + 1].clone()
        d[:, axis] += shift
        return d
    model.decode = decode
    return M.training_losses(model, clips, items, 3, generator=torch.Generator().manual_seed(0))


def test_true_deltas_give_zero_joint_and_foot_terms(clips, stats):
    """A decoder that returns the data's next delta reproduces the clip: the joint loss and the foot-velocity term
    (w_foot, not in the paper) vanish over a rollout; a decoder that slides the root makes the feet's term grow as
    the square of the slide (a constant 5 mm/frame: 25 mm², four foot joints at the same step)."""
    items, _, d_gt = _windows(clips)
    for slide, want in ((0.0, 0.0), (0.005, 25.0)):
        out = _replayed_losses(_model(stats, w_foot=1.0), clips, items, d_gt, axis=0, shift=slide)
        assert out["foot_mm2"].item() == pytest.approx(want, abs=1e-2)
        if slide == 0.0:
            assert out["joint_cm2"].item() == pytest.approx(0.0, abs=1e-6)
            assert out["rec"].item() == pytest.approx(0.0, abs=1e-6)
    assert "foot_mm2" not in M.training_losses(_model(stats), clips, items, 1, generator=torch.Generator().manual_seed(0))


def test_contact_term_holds_planted_feet_only(clips, stats):
    """The planted-foot term (w_contact, not in the paper): with the data's deltas the model's feet step as the data's,
    so the term is the data's own planted steps squared (< 1 mm², the swing foot free); sliding the root 5 mm a frame
    moves every planted joint by 5 ± 1 mm, so the term (a mean over windows, steps and the four foot joints) lies
    within 16-36 mm² times the share of planted joints, counted here from the data's joints."""
    items, b, d_gt = _windows(clips)
    J = I.body_joints(b["p"][:, 1:], b["rest"][:, None])[..., M.FEET, :2]          # (B, 5, 4, 2): frames i .. i+4
    planted = ((J[:, 1:] - J[:, :-1]).norm(dim=-1) < 1e-3).float().mean().item()      # share of planted joints
    assert 0.1 < planted < 1.0
    for slide in (0.0, 0.005):
        out = _replayed_losses(_model(stats, w_contact=1.0), clips, items, d_gt, axis=0, shift=slide)
        if slide == 0.0:
            assert 0.0 <= out["contact_mm2"].item() < 1.0
        else:
            assert 16.0 * planted <= out["contact_mm2"].item() <= 36.0 * planted
            assert out["loss"].item() == pytest.approx((out["rec"] + 1e-2 * out["kl"] + out["joint_cm2"]
                                                        + out["contact_mm2"]).item(), rel=1e-5)
    assert "contact_mm2" not in M.training_losses(_model(stats), clips, items, 1, generator=torch.Generator().manual_seed(0))


def test_floor_term_is_the_lowest_foot_joints_height_error(clips, stats):
    """The floor term (w_floor, not in the paper): with the data's deltas it is 0; a body that rises 1 cm more each
    frame (z of the translation delta, which the yaw frame leaves alone) is (k + 1) cm high at step k, so over four
    steps the term is (1 + 4 + 9 + 16) / 4 = 7.5 cm², whatever the feet's phase; it enters the loss times its weight.
    §3.4's joint loss sees every joint (k + 1) cm off at step k: its squared distance, summed over x, y, z, is also
    7.5 cm² on average."""
    items, _, d_gt = _windows(clips)
    for rise in (0.0, 0.01):
        out = _replayed_losses(_model(stats, w_floor=2.0), clips, items, d_gt, axis=2, shift=rise)
        assert out["floor_cm2"].item() == pytest.approx(7.5 if rise else 0.0, abs=1e-3)
        assert out["joint_cm2"].item() == pytest.approx(7.5 if rise else 0.0, abs=1e-3)
        assert out["loss"].item() == pytest.approx((out["rec"] + 1e-2 * out["kl"] + out["joint_cm2"]
                                                    + 2.0 * out["floor_cm2"]).item(), rel=1e-5)
    assert "floor_cm2" not in M.training_losses(_model(stats), clips, items, 1, generator=torch.Generator().manual_seed(0))


def test_posterior_rollout_latents_change_only_the_rollout_steps(clips, stats):
    """rollout_latent="posterior" draws the rollout steps' z from the encoder: the same losses without rollout steps,
    different reconstruction and KL with them."""
    items = W.WindowDataset(clips, max_steps=3).items[::40]
    run = lambda mode, steps: M.training_losses(_model(stats, rollout_latent=mode), clips, items, steps,  # noqa: E731
                                               generator=torch.Generator().manual_seed(0))
    a, b = run("prior", 0), run("posterior", 0)
    assert all(torch.equal(a[k], b[k]) for k in ("loss", "rec", "kl", "joint_cm2"))
    a, b = run("prior", 3), run("posterior", 3)
    assert torch.isfinite(b["loss"]) and not torch.equal(a["kl"], b["kl"]) and not torch.equal(a["rec"], b["rec"])
    with pytest.raises(ValueError, match="rollout_latent"):
        M.WandrConfig(rollout_latent="mean")


def test_a_few_steps_of_training_lower_the_loss(clips, stats):
    model = _model(stats).train()
    ds = W.WindowDataset(clips, max_steps=2)
    items = ds.items[torch.randperm(len(ds), generator=torch.Generator().manual_seed(0))[:64]]
    opt = torch.optim.Adam(model.parameters(), 1e-2)
    losses = []
    for k in range(20):
        out = M.training_losses(model, clips, items, steps=1, generator=torch.Generator().manual_seed(k))
        opt.zero_grad()
        out["loss"].backward()
        opt.step()
        losses.append(out["rec"].item())
    assert sum(losses[-5:]) < 0.6 * sum(losses[:5])


def test_generation_is_batched_deterministic_and_starts_at_the_start(stats, starts):
    model = _model(stats)
    goals = torch.tensor([[1.0, 0.5, 1.0], [-2.0, 0.0, 0.3], [0.0, 3.0, 1.6]])
    a = M.generate(model, starts, goals, t_goal=20, n=2, generator=torch.Generator().manual_seed(0))
    b = M.generate(model, starts, goals, t_goal=20, n=2, generator=torch.Generator().manual_seed(0))
    c = M.generate(model, starts, goals, t_goal=20, n=2, generator=torch.Generator().manual_seed(1))
    assert a.p.shape == (12, 21, 135) and a.joints.shape == (12, 21, 22, 3)
    assert torch.equal(a.p, b.p) and not torch.allclose(a.p[:, 1:], c.p[:, 1:])
    idx = a.info["index"]
    assert idx.tolist()[:3] == [[0, 0, 0], [0, 0, 1], [0, 1, 0]]
    for k, (s, g, _) in enumerate(idx.tolist()):
        assert torch.equal(a.p[k, 0], starts[s].p) and torch.equal(a.goal[k, 0], goals[g])
        assert torch.allclose(a.joints[k, 0], I.body_joints(starts[s].p, starts[s].rest))


def test_batched_rollout_equals_a_loop_over_sequences(stats, starts):
    """The batch computes exactly what a per-goal sequential loop computes with the same latents."""
    model = _model(stats)
    goals = torch.tensor([[1.0, 0.5, 1.0], [-2.0, 0.0, 0.3], [0.0, 3.0, 1.6]])
    pp, p0, rest, g, _ = M.expand_starts(starts, goals, 1)
    z = torch.randn(len(g), 15, 4, generator=torch.Generator().manual_seed(0))
    with torch.no_grad():
        batch = M.rollout(model, pp, p0, rest, g, 12, 15, z=z)
        for k in range(len(g)):
            one = M.rollout(model, pp[k:k + 1], p0[k:k + 1], rest[k:k + 1], g[k:k + 1], 12, 15, z=z[k:k + 1])
            assert torch.allclose(one.p[0], batch.p[k], atol=1e-5)


def test_each_frame_integrates_the_decoded_delta_of_its_intention(stats, starts):
    model = _model(stats)
    s = starts[0]
    goal = torch.tensor([[2.0, -1.0, 0.8]])
    z = torch.randn(1, 6, 4, generator=torch.Generator().manual_seed(3))
    with torch.no_grad():
        out = M.rollout(model, s.p_prev[None], s.p[None], s.rest[None], goal, 4, 6, z=z)
        d_prev = I.pose_to_delta(s.p_prev, s.p)[None]
        for k in range(6):
            p = out.p[:, k]
            inten = I.intention_from_pose(p, s.rest[None], goal, torch.tensor([(4 - k) / 30.0]))
            if k >= 4:
                assert torch.equal(inten, torch.zeros(1, 7))           # at and past t_G
            d = model.decode(z[:, k], model.condition(I.state_features(p, d_prev), inten))
            assert torch.allclose(out.p[:, k + 1], I.integrate_delta(p, d), atol=1e-5)
            d_prev = d


def test_frame_hook_sees_every_frame_without_storing(stats, starts):
    model = _model(stats)
    seen = []
    kept = M.generate(model, starts[0], torch.tensor([[1.0, 1.0, 1.0]]), 8, generator=torch.Generator().manual_seed(0))
    none = M.generate(model, starts[0], torch.tensor([[1.0, 1.0, 1.0]]), 8, generator=torch.Generator().manual_seed(0),
                      keep=False, on_frame=lambda k, p, j, r: seen.append((k, p.clone())))
    assert none.p is None and [k for k, _ in seen] == list(range(9))
    assert all(torch.equal(p, kept.p[:, k]) for k, p in seen)


def _rising(model, rise: float = 0.01):
    """The model with its decoder's output bias shifted so that every delta lifts the body `rise` m more."""
    with torch.no_grad():
        model.decoder[-1].bias[2] += rise / model.delta_std[2]
    return model


def _lowest_foot(p, rest):
    return I.body_joints(p, rest)[..., M.FEET, 2].amin(-1)


def test_floor_constraint_holds_the_lowest_foot_joint_at_its_start_height(stats, starts):
    s = starts[0]
    goal = torch.tensor([[2.0, -1.0, 0.8]])
    z = torch.randn(1, 12, 4, generator=torch.Generator().manual_seed(3))
    with torch.no_grad():
        free = M.rollout(_rising(_model(stats), 0.02), s.p_prev[None], s.p[None], s.rest[None], goal, 12, 12, z=z)
        low0 = _lowest_foot(s.p, s.rest)
        assert float(_lowest_foot(free.p[0, -1], s.rest) - low0) > 0.15           # the model lifts the body
        for floor in (0.0, 0.03):
            model = _rising(_model(stats), 0.02)
            out = M.rollout(model, s.p_prev[None], s.p[None], s.rest[None], goal, 12, 12, z=z, floor=floor)
            rise = _lowest_foot(out.p[0], s.rest) - low0
            assert float(rise.max()) <= floor + 1e-5 and float(rise[-1]) >= floor - 1e-5
            assert torch.allclose(out.joints[0], I.body_joints(out.p[0], s.rest), atol=1e-5)
            # every frame: the decoded delta integrated, then the body lowered straight down by what lifts its lowest
            # foot joint above the tolerance; the next state's dynamics is that delta, lowered alike
            d_prev = I.pose_to_delta(s.p_prev, s.p)[None]
            for k in range(12):
                p = out.p[:, k]
                inten = I.intention_from_pose(p, s.rest[None], goal, torch.tensor([(12 - k) / 30.0]))
                d = model.decode(z[:, k], model.condition(I.state_features(p, d_prev), inten))
                q = I.integrate_delta(p, d)
                down = torch.tensor([0, 0, 1.0]) * (_lowest_foot(q, s.rest[None]) - low0 - floor).clamp(min=0)
                assert torch.allclose(out.p[:, k + 1, 3:], q[:, 3:], atol=1e-5)
                assert torch.allclose(out.p[:, k + 1, :3], q[:, :3] - down, atol=1e-5)
                d_prev = torch.cat([d[:, :3] - down, d[:, 3:]], -1)
    with pytest.raises(ValueError, match="floor"):
        M.rollout(model, s.p_prev[None], s.p[None], s.rest[None], goal, 5, 5, floor=-0.01)


def test_lift_holds_a_sinking_body_at_its_start_height(stats, starts):
    """lift (not in the paper): a model whose every delta sinks the body 2 cm goes 20+ cm down without it; with it the
    lowest foot joint never goes below its start height and the rest of each pose is the decoded one; with floor=0
    as well the joint is pinned there, and lift leaves a rising body alone."""
    s = starts[0]
    goal = torch.tensor([[2.0, -1.0, 0.8]])
    z = torch.randn(1, 12, 4, generator=torch.Generator().manual_seed(3))
    low0 = _lowest_foot(s.p, s.rest)
    with torch.no_grad():
        free = M.rollout(_rising(_model(stats), -0.02), s.p_prev[None], s.p[None], s.rest[None], goal, 12, 12, z=z)
        assert float(_lowest_foot(free.p[0, -1], s.rest) - low0) < -0.2
        model = _rising(_model(stats), -0.02)
        out = M.rollout(model, s.p_prev[None], s.p[None], s.rest[None], goal, 12, 12, z=z, lift=True)
        drop = _lowest_foot(out.p[0], s.rest) - low0
        assert float(drop.min()) >= -1e-5 and float(drop[1:].max()) <= 1e-5             # held at the start height
        assert torch.allclose(out.joints[0], I.body_joints(out.p[0], s.rest), atol=1e-5)
        d_prev = I.pose_to_delta(s.p_prev, s.p)[None]
        for k in range(12):                   # every frame: the decoded delta integrated, then raised straight up
            p = out.p[:, k]
            inten = I.intention_from_pose(p, s.rest[None], goal, torch.tensor([(12 - k) / 30.0]))
            d = model.decode(z[:, k], model.condition(I.state_features(p, d_prev), inten))
            q = I.integrate_delta(p, d)
            up = torch.tensor([0, 0, 1.0]) * (low0 - _lowest_foot(q, s.rest[None])).clamp(min=0)
            assert torch.allclose(out.p[:, k + 1, 3:], q[:, 3:], atol=1e-5)
            assert torch.allclose(out.p[:, k + 1, :3], q[:, :3] + up, atol=1e-5)
            d_prev = torch.cat([d[:, :3] + up, d[:, 3:]], -1)
        rising = _rising(_model(stats), 0.02)
        a = M.rollout(rising, s.p_prev[None], s.p[None], s.rest[None], goal, 12, 12, z=z, lift=True)
        b = M.rollout(rising, s.p_prev[None], s.p[None], s.rest[None], goal, 12, 12, z=z)
        assert torch.equal(a.p, b.p)
        for sign in (-0.02, 0.02):
            pinned = M.rollout(_rising(_model(stats), sign), s.p_prev[None], s.p[None], s.rest[None], goal, 12, 12,
                               z=z, lift=True, floor=0.0)
            assert float((_lowest_foot(pinned.p[0], s.rest) - low0).abs().max()) <= 1e-5
    with pytest.raises(ValueError, match="lift"):
        M.rollout(model, s.p_prev[None], s.p[None], s.rest[None], goal, 5, 5, lift=1)


def test_goal_schedule_switches_goals_after_each_goal_frame():
    g, tg = M.goal_schedule(torch.tensor([[1.0, 0, 1], [2.0, 0, 1], [3.0, 0, 1]]), [10, 20, 30], 35)
    assert g.shape == (36, 3) and tg.shape == (36,)
    assert g[10, 0] == 1 and g[11, 0] == 2 and g[20, 0] == 2 and g[21, 0] == 3 and g[35, 0] == 3
    assert tg[0] == 10 and tg[11] == 20 and tg[35] == 30
    with pytest.raises(ValueError, match="t_goals"):
        M.goal_schedule(torch.zeros(2, 3), [20, 10], 30)
    with pytest.raises(ValueError, match="strictly increasing"):       # goal 2 would get no frame
        M.goal_schedule(torch.zeros(3, 3), [10, 10, 30], 35)
    with pytest.raises(ValueError, match="before frame 35"):           # goal 3 would never start
        M.goal_schedule(torch.zeros(3, 3), [10, 40, 50], 35)
    assert M.goal_schedule(torch.zeros(2, 3), [10, 50], 35)[1][-1] == 50   # the last goal may lie past the clip
    with pytest.raises(ValueError, match="goals: contains NaN"):
        M.goal_schedule(torch.tensor([[1.0, 0, 1], [float("nan"), 0, 1]]), [10, 20], 35)


def test_rollout_errors_name_the_argument(stats, starts):
    model = _model(stats)
    s = starts[0]
    with pytest.raises(ValueError, match="rest"):
        M.rollout(model, s.p_prev[None], s.p[None], s.rest, torch.zeros(1, 3), 5, 5)
    with pytest.raises(ValueError, match="goal"):
        M.rollout(model, s.p_prev[None], s.p[None], s.rest[None], torch.zeros(2, 2), 5, 5)
    with pytest.raises(ValueError, match="z"):
        M.rollout(model, s.p_prev[None], s.p[None], s.rest[None], torch.zeros(3), 5, 5, z=torch.zeros(1, 4, 4))
    with pytest.raises(ValueError, match="goal: contains NaN"):     # below generate's checks, NaN poses otherwise
        M.rollout(model, s.p_prev[None], s.p[None], s.rest[None], torch.tensor([[float("nan"), 0, 1]]), 5, 5)
    with pytest.raises(ValueError, match="t_goal: expected whole goal frames >= 1"):
        M.rollout(model, s.p_prev[None], s.p[None], s.rest[None], torch.zeros(3), 0, 5)
    goal = torch.tensor([[1.0, 0.5, 1.0]])
    for bad_goal in (torch.tensor([[1.0, 0.5]]), torch.tensor([[float("nan"), 0.5, 1.0]]), torch.zeros(0, 3)):
        with pytest.raises(ValueError, match="goal"):
            M.generate(model, s, bad_goal, 5)
    for bad_t in (0, -3, 2.5, torch.tensor([5, 6])):
        with pytest.raises(ValueError, match="t_goal"):
            M.generate(model, s, goal, bad_t)
    for bad_n in (2.5, True, 0):
        with pytest.raises(ValueError, match="n: expected"):
            M.generate(model, s, goal, 5, n=bad_n)
    with pytest.raises(ValueError, match="start: expected"):
        M.generate(model, [], goal, 5)


def test_checkpoint_round_trip_is_weights_only(stats, starts, tmp_path):
    model = _model(stats, intention=("wrist", "pelvis"))
    path = M.save_wandr(tmp_path / "w.pt", model, [{"epoch": 1, "loss": 0.5}], {"note": "test"}, half=False)
    torch.load(path, weights_only=True)
    back = M.load_wandr(path)
    assert back.cfg == model.cfg and back.meta == {"note": "test"}
    goal = torch.tensor([[1.0, 0.0, 1.0]])
    a = M.generate(model, starts[0], goal, 5, generator=torch.Generator().manual_seed(0))
    b = M.generate(back, starts[0], goal, 5, generator=torch.Generator().manual_seed(0))
    assert torch.equal(a.p, b.p) and torch.equal(back.delta_std, stats["delta_std"])
    small = M.load_wandr(M.save_wandr(tmp_path / "h.pt", model))                 # float16 weights, float32 statistics
    assert small.decoder[0].weight.dtype == torch.float32 and torch.equal(small.delta_std, stats["delta_std"])
    assert torch.allclose(small.decoder[0].weight, model.decoder[0].weight, rtol=1e-3, atol=1e-4)
    assert (tmp_path / "h.pt").stat().st_size < 0.7 * path.stat().st_size


def test_train_wandr_writes_a_resumable_checkpoint(clips, stats, tmp_path):
    from graspkit.train import TrainConfig

    model = _model(stats, max_steps=1, ramp_epochs=1)
    cfg = TrainConfig(epochs=2, batch_size=256, lr=1e-3, seed=0)
    hist = M.train_wandr(model, clips, cfg, checkpoint=tmp_path / "ck.pt", stride={"locomotion": 8, "reach": 8},
                         progress=False)
    assert [h["steps"] for h in hist] == [0.0, 1.0]
    again = M.load_wandr(tmp_path / "ck.pt")
    assert all(torch.equal(a, b) for a, b in zip(again.state_dict().values(), model.state_dict().values()))


def test_training_one_epoch_at_a_time_gives_the_weights_of_one_run(clips, stats, tmp_path):
    # `graspkit train wandr --select-val` scores every epoch by stopping and resuming (stop_at): it must not change
    # what is trained
    from graspkit.train import TrainConfig

    cfg = TrainConfig(epochs=3, batch_size=256, lr=1e-3, seed=0)
    kw = dict(stride={"locomotion": 8, "reach": 8}, progress=False)
    straight = _model(stats, max_steps=1, ramp_epochs=2)
    M.train_wandr(straight, clips, cfg, checkpoint=tmp_path / "a.pt", **kw)
    stepped = _model(stats, max_steps=1, ramp_epochs=2)
    for e in (1, 2, 3):
        hist = M.train_wandr(stepped, clips, cfg, checkpoint=tmp_path / "b.pt", stop_at=e, **kw)
        assert len(hist) == e
    assert all(torch.equal(a, b) for a, b in zip(straight.state_dict().values(), stepped.state_dict().values()))


def test_latent_optimisation_pulls_the_wrist_to_the_goal_and_the_pelvis_over_a_waypoint(stats, starts):
    model = _model(stats)
    goal = torch.tensor([0.8, 0.3, 1.0])
    res = optimise_latents(model, starts[1], goal, t_goal=20, iters=20, lr=0.2, w_norm=1e-4,
                           waypoints=[(10, (0.2, 0.2))], generator=torch.Generator().manual_seed(0))
    h = res.history
    assert h[-1]["goal"] < 0.9 * h[0]["goal"] and h[-1]["way"] < 0.9 * h[0]["way"]
    assert all(b["loss"] <= a["loss"] + 1e-6 for a, b in zip(h[:-1], h[1:]))      # Adam steps go downhill here
    terms = latent_loss(res.motion, res.z, goal[None], 20, [(10, (0.2, 0.2))], 1e-4)
    assert terms["loss"].item() == pytest.approx(min(x["loss"] for x in h), rel=1e-4)   # the best iterate is kept
    assert all(q.requires_grad for q in model.parameters())
    with pytest.raises(ValueError, match="waypoints"):
        optimise_latents(model, starts[1], goal, t_goal=10, waypoints=[(50, (0, 0))])


def test_latent_optimisation_runs_in_the_models_dtype_and_names_bad_arguments(stats, starts):
    """A float64 copy of the model (generate takes one) optimises the same latents as the float32 model, to float32
    rounding; a fractional or boolean waypoint frame and a fractional iteration count are refused by name."""
    import copy
    model = _model(stats)
    goal = torch.tensor([0.6, 0.2, 1.0])
    z0 = torch.randn(1, 8, model.cfg.latent, generator=torch.Generator().manual_seed(3))
    a = optimise_latents(model, starts[1], goal, t_goal=8, iters=3, z0=z0)
    b = optimise_latents(copy.deepcopy(model).double(), starts[1], goal, t_goal=8, iters=3, z0=z0)
    assert b.z.dtype == torch.float64 and b.motion.joints.dtype == torch.float64
    assert torch.allclose(b.z.float(), a.z, atol=1e-4)
    assert torch.allclose(b.motion.joints.float(), a.motion.joints, atol=1e-4)
    for kw, name in ((dict(waypoints=[(2.5, (0, 0))]), "waypoints"), (dict(waypoints=[(True, (0, 0))]), "waypoints"),
                     (dict(iters=2.0), "iters")):
        with pytest.raises(ValueError, match=name):
            optimise_latents(model, starts[1], goal, t_goal=8, **kw)


def test_goal_frame_hold_changes_only_the_reaching_windows(clips, stats):
    """goal_frame="hold" moves t_G of the reaching clips to the end of their hold: locomotion windows (hindsight
    goals) keep their losses, reaching windows get a different intention and so a different loss."""
    ds = W.WindowDataset(clips, max_steps=2)
    for kind, changes in ((0, False), (1, True)):
        items = ds.items[(clips.kind[ds.items[:, 0]] == kind).nonzero()[::25, 0]]
        out = []
        for mode in ("reach", "hold"):
            out.append(M.training_losses(_model(stats, goal_frame=mode), clips, items, 2,
                                         generator=torch.Generator().manual_seed(0))["loss"])
        assert torch.equal(out[0], out[1]) != changes
    with pytest.raises(ValueError, match="goal_frame"):
        M.WandrConfig(goal_frame="arrival")


def test_latent_loss_terms_are_the_modules_formulas():
    """L_norm = mean z^2 / 2 per sequence, L_goal = |W_tG - G|^2 at the goal frame itself, L_way = |P^xy_tw - w^xy|^2,
    on hand-made joints whose right wrist is on the goal at t_G only (latent_loss reads only the rollout's joints)."""
    from types import SimpleNamespace

    B, T, L = 2, 12, 16
    joints = torch.zeros(B, T + 1, I.NUM_BODY, 3)
    joints[:, :, I.WRIST] = torch.tensor([0.0, 0.0, 1.0])
    joints[:, 7, I.WRIST] = torch.tensor([0.5, 0.2, 1.0])
    joints[:, 4, I.PELVIS] = torch.tensor([0.3, -0.1, 0.9])
    z = torch.arange(B * T * L, dtype=torch.float32).reshape(B, T, L) / (B * T * L)
    goal = torch.tensor([[0.5, 0.2, 1.0]]).expand(B, 3)
    t = latent_loss(SimpleNamespace(joints=joints), z, goal, 7, [(4, (0.0, 0.3))], w_norm=0.01, w_goal=1.0, w_way=2.0)
    torch.testing.assert_close(t["norm"], 0.5 * (z ** 2).mean(dim=(1, 2)))
    torch.testing.assert_close(t["goal"], torch.zeros(B))
    torch.testing.assert_close(t["way"], torch.full((B,), 0.3 ** 2 + 0.4 ** 2))
    torch.testing.assert_close(t["loss"], 0.01 * t["norm"] + 2.0 * t["way"])
    t6 = latent_loss(SimpleNamespace(joints=joints), z, goal, 6)
    torch.testing.assert_close(t6["goal"], torch.full((B,), 0.5 ** 2 + 0.2 ** 2))


def test_per_goal_frames_reach_their_own_goals():
    """generate's per-goal frames t_goal (G,) belong to their goals: one goal's frame changed changes that goal's
    motion only, and the default length is the latest goal frame."""
    model = M.load_wandr(DATA_STUBS / "checkpoints" / "wandr.pt")
    start = E.starts_from_meta(model.meta)[0]
    goals = torch.stack([E.goal_from_cylinder(30, 1.0, 0.9), E.goal_from_cylinder(-30, 1.0, 0.9)])
    run = lambda tg: M.generate(model, start, goals, torch.tensor(tg), generator=torch.Generator().manual_seed(0))  # noqa: E731
    a, b = run([5, 9]), run([9, 9])
    assert a.p.shape[1] == b.p.shape[1] == 10                   # frames: the latest goal frame (9), start included
    torch.testing.assert_close(a.p[1], b.p[1])                   # goal 1 keeps t_goal = 9 in both: the same motion
    assert not torch.allclose(a.p[0], b.p[0])                    # goal 0's time left differs: another motion
    c = run([9, 5])
    torch.testing.assert_close(c.p[0], b.p[0])


def test_initial_latents_come_from_the_generator():
    """optimise_latents draws its initial latents from `generator`: the same seed, the same latents and motion."""
    model = M.load_wandr(DATA_STUBS / "checkpoints" / "wandr.pt")
    start = E.starts_from_meta(model.meta)[0]
    goal = E.goal_from_cylinder(30, 1.0, 0.9)
    run = lambda s: optimise_latents(model, start, goal, t_goal=5, iters=0, generator=torch.Generator().manual_seed(s))  # noqa: E731
    a, b, c = run(0), run(0), run(1)
    torch.testing.assert_close(a.z, b.z)
    torch.testing.assert_close(a.motion.p, b.motion.p)
    assert not torch.allclose(a.z, c.z)
    torch.testing.assert_close(a.z, torch.randn(a.z.shape, generator=torch.Generator().manual_seed(0)))


def test_the_returned_motion_is_decoded_from_the_returned_best_latents_when_adam_overshoots(bm, stats):
    """With a step size large enough that Adam overshoots (the loss goes up at some iterations, the last one not the
    lowest), the returned z is the best iterate and the returned motion is its rollout: latent_loss of (motion, z)
    is the smallest loss of the history, and a rollout of z alone (iters=0 from z0 = z) gives the same joints."""
    start = W.held_out_starts([load_motion(STUBS / "reach/reach_000001.npz")], ["reach/reach_000001.npz"], bm,
                              n=1, frame=3)[0]
    model = _model(stats)
    goal = torch.tensor([0.8, 0.3, 1.0])
    res = optimise_latents(model, start, goal, t_goal=12, iters=5, lr=2.0, w_norm=1e-4,
                           generator=torch.Generator().manual_seed(0))
    losses = [h["loss"] for h in res.history]
    assert min(losses) < losses[-1]                         # the case: the last iterate is not the best
    terms = latent_loss(res.motion, res.z, goal[None], 12, (), 1e-4)
    assert terms["loss"].item() == pytest.approx(min(losses), rel=1e-5)
    again = optimise_latents(model, start, goal, t_goal=12, iters=0, z0=res.z, w_norm=1e-4)
    assert torch.allclose(again.motion.joints, res.motion.joints, atol=1e-5)


def test_floor_term_compares_with_the_datas_lowest_foot_at_the_same_frame():
    """The floor term is (100 (lowest foot joint here - the data's at the same frame))² (cm²): a hand-made step where
    the data's lowest foot joint is 3 cm up at the step's frame and 0 cm at the frame before, and the decoded body's
    is 1 cm up, gives (1 - 3)² = 4 cm², not (1 - 0)² = 1."""
    torch.manual_seed(0)
    model = M.WandrCVAE(M.WandrConfig(**TINY, w_floor=1.0)).eval()
    J = torch.zeros(2, I.NUM_BODY, 3)
    J[..., 2] = 0.5                                   # every joint 50 cm up, the foot joints set below
    J_prev, J_true, J_true_prev = J.clone(), J.clone(), J.clone()
    J[:, list(M.FEET), 2] = 0.01
    J_prev[:, list(M.FEET), 2] = 0.01
    J_true[:, list(M.FEET), 2] = 0.03
    J_true_prev[:, list(M.FEET), 2] = 0.0
    d = torch.zeros(2, I.DELTA_DIM)
    e = M._step_terms(model, d, d, J, J_prev, J_true, J_true_prev)
    assert e["floor"].item() == pytest.approx(4.0, rel=1e-4)


def test_train_wandr_strides_each_kind_by_its_own_stride(bm, monkeypatch):
    """train_wandr(stride={'locomotion': 3, 'reach': 1}) keeps every reaching window and the locomotion windows whose
    start frame is a multiple of 3 (the windows fit sees, against WindowDataset's full list)."""
    clips = W.load_clips(W.list_clips(DATA_STUBS / "motion", limit=3), bm)
    assert {0, 1} <= set(clips.kind.tolist())
    full = W.WindowDataset(clips, max_steps=2).items
    got = {}

    def fake_fit(model, step, ds, cfg, **kw):
        got["items"] = ds.items.clone()
        return []

    monkeypatch.setattr(M, "fit", fake_fit)
    torch.manual_seed(0)
    model = M.WandrCVAE(M.WandrConfig(**TINY, max_steps=2))
    M.train_wandr(model, clips, M.TrainConfig(epochs=1), stride={"locomotion": 3, "reach": 1}, progress=False)
    kind = clips.kind[full[:, 0]]
    want = full[(kind != 0) | (full[:, 1] % 3 == 0)]
    assert torch.equal(got["items"], want)
    assert (clips.kind[want[:, 0]] == 1).sum() == (kind == 1).sum()


def test_goal_schedule_reads_an_iterator_of_frames_as_the_list():
    """The frames may come as any iterable: an iterator gives the list's schedule (it was read twice, and the second
    pass found it empty, leaving the tensors uninitialised); fractional frames and flat goals are named."""
    goals = torch.tensor([[1.0, 0, 1], [2.0, 0, 1]])
    want = M.goal_schedule(goals, [30, 60], 60)
    for frames in (iter([30, 60]), (t for t in [30, 60]), torch.tensor([30, 60])):
        got = M.goal_schedule(goals, frames, 60)
        assert torch.equal(got[0], want[0]) and torch.equal(got[1], want[1])
    assert torch.equal(want[1][:31], torch.full((31,), 30)) and torch.equal(want[1][31:], torch.full((30,), 60))
    with pytest.raises(ValueError, match="t_goals: expected 2 strictly increasing whole frames"):
        M.goal_schedule(goals, [30.5, 60], 60)
    with pytest.raises(ValueError, match="goals: expected"):
        M.goal_schedule(torch.zeros(2, 2), [30, 60], 60)
    with pytest.raises(ValueError, match="frames: expected an integer >= 1"):
        M.goal_schedule(goals, [30, 60], -4)


def test_generation_keeps_the_callers_training_mode_and_decodes_without_dropout(stats, starts):
    """generate runs in eval mode and gives the model back in the mode it came in: a model in training (dropout on)
    generates what its eval-mode self generates, and is still training afterwards."""
    model = _model(stats, dropout=0.5)
    goal = torch.tensor([[1.0, 0.5, 1.0]])
    ref = M.generate(model.eval(), starts[0], goal, 8, generator=torch.Generator().manual_seed(0))
    got = M.generate(model.train(), starts[0], goal, 8, generator=torch.Generator().manual_seed(0))
    assert model.training
    torch.testing.assert_close(got.joints, ref.joints, rtol=0, atol=0)


def test_rollout_and_generate_name_a_bad_value(stats, starts):
    """NaN poses, rest joints or goal headings, a fractional goal frame and bad frame counts are named (a NaN used to
    surface as 'wrist: contains NaN', an argument nobody passed)."""
    model = _model(stats)
    s = starts[0]
    pp, p0, rest, goal = s.p_prev[None], s.p[None], s.rest[None], torch.tensor([[1.0, 0.5, 1.0]])
    nan = lambda x: x.clone().index_fill_(-1, torch.tensor([1]), float("nan"))  # noqa: E731
    for kw, name in ((dict(p_prev=nan(pp)), "p_prev"), (dict(p0=nan(p0)), "p0"), (dict(rest=nan(rest)), "rest")):
        args = {**dict(p_prev=pp, p0=p0, rest=rest), **kw}
        with pytest.raises(ValueError, match=f"{name}: contains NaN"):
            M.rollout(model, args["p_prev"], args["p0"], args["rest"], goal, 5, 5)
    with pytest.raises(ValueError, match="goal_heading: contains NaN"):
        M.rollout(model, pp, p0, rest, goal, 5, 5, goal_heading=torch.tensor([float("nan")]))
    with pytest.raises(ValueError, match="goal_heading: expected shape"):
        M.rollout(model, pp, p0, rest, goal, 5, 5, goal_heading=torch.zeros(5))
    with pytest.raises(ValueError, match="t_goal: expected whole goal frames"):
        M.rollout(model, pp, p0, rest, goal, 10.5, 12)
    for bad in (-1, 0, 2.5, True):
        with pytest.raises(ValueError, match="frames: expected an integer >= 1"):
            M.rollout(model, pp, p0, rest, goal, 5, bad)
    for bad in (5.5, True, 0):
        with pytest.raises(ValueError, match="frames: expected an integer >= 1"):
            M.generate(model, s, goal, 5, frames=bad)
    with pytest.raises(ValueError, match="t_goal: expected goal frames"):
        M.generate(model, s, goal, "10")
    out = M.rollout(model, pp, p0, rest, goal, torch.tensor(5.0), 6)       # a float tensor of whole frames is fine
    assert out.p.shape == (1, 7, 135)
