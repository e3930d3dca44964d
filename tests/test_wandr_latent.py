"""WANDR's latent optimisation (Sup. B.3, C.2; graspkit.optim.latent) on tiny random models: the loss terms by hand,
Adam's first step, the model left as it was, batches that optimise each sequence as if alone, argument checks."""
import os
from types import SimpleNamespace

import numpy as np
import pytest
import torch

from graspkit import eval_wandr as E
from graspkit import intention as I
from graspkit.models import wandr as M
from graspkit.optim.latent import latent_loss, optimise_latents
from graspkit.paths import DATA_STUBS

TINY = dict(latent=4, hidden=32, enc_layers=1, dec_layers=2, dropout=0.0)


@pytest.fixture(scope="module")
def start():
    return E.starts_from_meta(M.load_wandr(DATA_STUBS / "checkpoints" / "wandr.pt").meta)[0]


def _tiny(**kw):
    torch.manual_seed(0)
    return M.WandrCVAE(M.WandrConfig(**{**TINY, **kw})).eval()


def test_latent_loss_sums_every_waypoint_and_uses_the_documented_default_weights():
    """L_way = sum over waypoints of |P^xy_tw - w^xy|^2 (module docstring, Sup. C.2), hand-computed on made-up joints
    with two waypoints (their xy only, a third coordinate ignored); the default weights are the documented
    w_norm = 0.01, w_goal = w_way = 1."""
    B, T, L = 2, 8, 3
    joints = torch.zeros(B, T + 1, I.NUM_BODY, 3)
    joints[:, 2, I.PELVIS] = torch.tensor([0.1, 0.2, 0.9])
    joints[:, 5, I.PELVIS] = torch.tensor([-0.4, 0.0, 0.9])
    joints[:, 5, I.WRIST] = torch.tensor([0.3, 0.0, 1.0])
    z = torch.ones(B, T, L) * torch.tensor([1.0, 2.0])[:, None, None]
    goal = torch.tensor([[0.0, 0.0, 1.0]]).expand(B, 3)
    t = latent_loss(SimpleNamespace(joints=joints), z, goal, 5, [(2, (0.0, 0.0)), (5, (0.0, 0.3))])
    way = (0.1**2 + 0.2**2) + (0.4**2 + 0.3**2)
    torch.testing.assert_close(t["way"], torch.full((B,), way))
    torch.testing.assert_close(t["goal"], torch.full((B,), 0.09))
    torch.testing.assert_close(t["norm"], torch.tensor([0.5, 2.0]))
    torch.testing.assert_close(t["loss"], 0.01 * torch.tensor([0.5, 2.0]) + 0.09 + way)
    t3 = latent_loss(SimpleNamespace(joints=joints), z, goal, 5, [(2, (0.0, 0.0, 7.0)), (5, (0.0, 0.3, -1.0))])
    torch.testing.assert_close(t3["way"], t["way"])      # a waypoint's height, if given, is not the ground projection's


def test_optimise_latents_first_adam_step_history_and_weights(start):
    """From z0 = 1 with only L_norm (w_goal = 0): Adam's first step moves every latent by the learning rate (documented
    default 0.05) downhill, so one iteration returns z = 0.95 (the better, last iterate) with history [0.5, 0.5 * 0.95^2]
    (L_norm = mean z^2 / 2); the caller's z0 is not modified; each history entry is w_norm L_norm + w_goal L_goal +
    w_way L_way with the documented defaults (0.01, 1, 1) or the weights given."""
    model = _tiny()
    goal = torch.tensor([0.6, 0.2, 1.0])
    z0 = torch.ones(1, 5, 4)
    res = optimise_latents(model, start, goal, t_goal=5, z0=z0, iters=1, w_goal=0.0)
    torch.testing.assert_close(z0, torch.ones(1, 5, 4))
    torch.testing.assert_close(res.z, torch.full((1, 5, 4), 0.95), atol=1e-5, rtol=0)
    assert len(res.history) == 2
    assert [h["norm"] for h in res.history] == pytest.approx([0.5, 0.5 * 0.95**2], rel=1e-5)
    res = optimise_latents(model, start, goal, t_goal=5, z0=z0, iters=0, waypoints=[(3, (0.3, -0.2))])
    h = res.history[0]
    assert h["goal"] > 0 and h["way"] > 0
    assert h["loss"] == pytest.approx(0.01 * h["norm"] + h["goal"] + h["way"], rel=1e-5)
    res = optimise_latents(model, start, goal, t_goal=5, z0=z0, iters=0, waypoints=[(3, (0.3, -0.2))],
                           w_norm=0.5, w_goal=2.0, w_way=3.0)
    h = res.history[0]
    assert h["loss"] == pytest.approx(0.5 * h["norm"] + 2.0 * h["goal"] + 3.0 * h["way"], rel=1e-5)


def test_optimise_latents_leaves_the_model_untouched_and_decodes_without_dropout(start):
    """Only the latents are optimised: the model's weights, their requires_grad flags (one frozen on purpose) and
    their .grad (None) are as before; a model left in train mode with dropout still decodes deterministically (the
    rollout is inference: two runs from the same z0 give the same motion, equal to the eval-mode model's)."""
    model = _tiny(dropout=0.5).train()
    before = {k: v.clone() for k, v in model.state_dict().items()}
    frozen = model.decoder[0].weight
    frozen.requires_grad_(False)
    goal = torch.tensor([0.6, 0.2, 1.0])
    z0 = torch.randn(1, 6, 4, generator=torch.Generator().manual_seed(1))
    a = optimise_latents(model, start, goal, t_goal=6, z0=z0, iters=2)
    assert all(torch.equal(before[k], v) for k, v in model.state_dict().items())
    assert [q.requires_grad for q in model.parameters()] == [q is not frozen for q in model.parameters()]
    assert all(q.grad is None for q in model.parameters())
    assert model.training                        # the caller's mode comes back (dropout off only inside)
    b = optimise_latents(model, start, goal, t_goal=6, z0=a.z, iters=0)
    c = optimise_latents(model, start, goal, t_goal=6, z0=a.z, iters=0)
    assert model.training
    torch.testing.assert_close(b.motion.joints, c.motion.joints)
    torch.testing.assert_close(b.motion.joints, a.motion.joints)


def test_optimise_latents_refuses_frames_and_waypoints_outside_the_motion(start):
    """t_goal past the last frame, a waypoint before frame 0, a waypoint without (x, y) and a negative iteration count are
    refused with a ValueError naming the argument; a waypoint on the last frame (frames, the start being frame 0) is a
    valid one and is pulled towards."""
    model = _tiny()
    goal = torch.tensor([0.6, 0.2, 1.0])
    with pytest.raises(ValueError, match="t_goal"):
        optimise_latents(model, start, goal, t_goal=5, frames=4, iters=0)
    with pytest.raises(ValueError, match="waypoints"):
        optimise_latents(model, start, goal, t_goal=4, waypoints=[(-1, (0.0, 0.0))], iters=0)
    with pytest.raises(ValueError, match="waypoints"):
        optimise_latents(model, start, goal, t_goal=4, waypoints=[(2, (0.5,))], iters=0)
    with pytest.raises(ValueError, match="iters"):
        optimise_latents(model, start, goal, t_goal=4, iters=-1)
    for bad in ([(2, (float("nan"), 0.0))], [(2, (0.0, float("inf")))]):       # refused before any rollout, iters=0 too
        with pytest.raises(ValueError, match="waypoints: contains NaN or Inf"):
            optimise_latents(model, start, goal, t_goal=4, waypoints=bad, iters=0)
    for bad in ([(5, 0.5)], [(2,)], [(2, "ab")]):
        with pytest.raises(ValueError, match="waypoints: expected"):
            optimise_latents(model, start, goal, t_goal=4, waypoints=bad, iters=0)
    for name in ("w_norm", "w_goal", "w_way"):
        for bad in (float("nan"), -1.0, True):
            with pytest.raises(ValueError, match=f"{name}: expected a finite number >= 0"):
                optimise_latents(model, start, goal, t_goal=4, iters=0, **{name: bad})
    with pytest.raises(ValueError, match="z0: contains NaN"):
        optimise_latents(model, start, goal, t_goal=4, iters=0, z0=torch.full((1, 4, 4), float("nan")))
    for bad in (float("inf"), float("nan"), 0.0, -0.1, True, "0.1"):    # inf failed after a step, as "wrist: ... NaN"
        with pytest.raises(ValueError, match="^lr: expected a finite learning rate > 0"):
            optimise_latents(model, start, goal, t_goal=4, iters=1, lr=bad)
    for good in (np.float32(0.05), torch.tensor(0.05)):          # numbers of numpy and torch are numbers
        optimise_latents(model, start, goal, t_goal=4, iters=1, lr=good)
    res = optimise_latents(model, start, goal, t_goal=4, waypoints=[(4, (0.5, 0.5))], iters=6, lr=0.3, w_goal=0.0,
                           w_norm=0.0, generator=torch.Generator().manual_seed(0))
    P = res.motion.joints[0, 4, I.PELVIS, :2]
    assert res.history[0]["way"] > 0
    assert float(((P - torch.tensor([0.5, 0.5])) ** 2).sum()) == pytest.approx(min(h["way"] for h in res.history), rel=1e-4)
    assert min(h["way"] for h in res.history) < res.history[0]["way"]


def test_a_batch_of_goals_optimises_each_sequence_as_if_alone(start):
    """Adam is element-wise and the loss a sum over sequences (docstring), so a batch of two goals optimised together
    returns, per sequence, the latents and motion of that goal optimised alone from the same z0 -- also the best-iterate
    choice, with a step size where Adam overshoots and the two goals' best iterates differ."""
    model = _tiny()
    goals = torch.tensor([[0.6, 0.2, 1.0], [-0.3, 0.7, 0.4]])
    z0 = torch.randn(2, 6, 4, generator=torch.Generator().manual_seed(2))
    kw = dict(t_goal=6, iters=6, lr=0.5, w_norm=1e-3)     # the two goals' best iterates: 2 and 4
    both = optimise_latents(model, start, goals, z0=z0, **kw)
    for k in range(2):
        one = optimise_latents(model, start, goals[k], z0=z0[k:k + 1], **kw)
        torch.testing.assert_close(both.z[k:k + 1], one.z, atol=1e-4, rtol=0)      # float32 rounding, through Adam
        torch.testing.assert_close(both.motion.joints[k:k + 1], one.motion.joints, atol=1e-4, rtol=0)


@pytest.fixture(scope="module")
def two_starts():
    return E.starts_from_meta(M.load_wandr(DATA_STUBS / "checkpoints" / "wandr.pt").meta)[:2]


def test_optimise_latents_batches_starts_goals_and_samples_start_major(two_starts):
    """B = S * G * n sequences, start-major as `generate` (docstring): 2 starts x 2 goals x 2 samples -> 8 latent
    sequences of `frames` steps, the index table (start, goal, sample) in that order, and each motion begins at its
    own start pose and carries its own goal; frames longer than t_goal gives frames + 1 poses."""
    model = _tiny()
    goals = torch.tensor([[0.6, 0.2, 1.0], [-0.3, 0.7, 0.4]])
    res = optimise_latents(model, two_starts, goals, t_goal=4, frames=7, n=2, iters=0,
                           generator=torch.Generator().manual_seed(0))
    assert tuple(res.z.shape) == (8, 7, 4) and tuple(res.motion.joints.shape[:2]) == (8, 8)
    want = torch.tensor([(s, g, k) for s in range(2) for g in range(2) for k in range(2)])
    torch.testing.assert_close(res.motion.info["index"], want)
    for b, (s, g, _) in enumerate(want.tolist()):
        torch.testing.assert_close(res.motion.p[b, 0], two_starts[s].p.float())
        torch.testing.assert_close(res.motion.goal[b, 0], goals[g])


def test_latent_optimisation_shows_a_bar_that_one_switch_turns_off(start, capsys, monkeypatch):
    """progress=True draws a bar over the iterations on stderr; TQDM_DISABLE=1 (what `graspkit --quiet` sets) turns it
    off; stdout stays empty either way."""
    from graspkit import cli

    model, goal = _tiny(), torch.tensor([0.6, 0.2, 1.0])
    optimise_latents(model, start, goal, t_goal=3, iters=2, progress=True, generator=torch.Generator().manual_seed(0))
    out, err = capsys.readouterr()
    assert out == "" and "latent optimisation" in err
    monkeypatch.setenv("TQDM_DISABLE", "1")
    optimise_latents(model, start, goal, t_goal=3, iters=2, progress=True, generator=torch.Generator().manual_seed(0))
    assert capsys.readouterr() == ("", "")
    monkeypatch.delenv("TQDM_DISABLE")
    with cli._quiet(True):
        optimise_latents(model, start, goal, t_goal=3, iters=2, progress=True)
    assert capsys.readouterr() == ("", "") and "TQDM_DISABLE" not in os.environ
    for argv in (["--quiet", "body", "info"], ["--quiet", "data", "make", "--kind", "reach"]):   # data make has its own
        assert cli.build_parser(argv).parse_args(argv).quiet_all                                 # --quiet, which kept
    argv = ["data", "make", "--kind", "reach", "--quiet"]                                        # the default False
    assert cli.build_parser(argv).parse_args(argv).quiet
