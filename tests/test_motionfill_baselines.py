"""SAGA Tab. 3's deterministic baselines (CNN-AE, PoseNet, RouteNet): shapes, determinism, the known frames, Eq. 8's
deterministic terms, a tiny overfit against the linear blend, the checkpoint round trip, Tab. 3 rows, the command."""
import numpy as np
import pytest
import torch

from graspkit.data.motionfill_dataset import MotionFillStats, global_motion, interpolated_trajectory, local_motion
from graspkit.eval_motionfill import linear_local
from graspkit.models.motionfill import NUM_FRAMES, NUM_MARKERS
from graspkit.models.motionfill_baselines import (CNNAE, PoseNet, RouteNet, RoutePoseNet, baseline_from_state,
                                                  num_weights)

NF, NR = 61, 62


def _windows(B: int = 2, seed: int = 0) -> dict[str, torch.Tensor]:
    """Synthetic windows: curved walks, local markers moving from a start to an end pose with a smooth sway on top,
    alternating foot contacts."""
    g = np.random.default_rng(seed)
    t = np.arange(NR) / 60.0
    traj = []
    for b in range(B):
        heading = np.pi / 2 + 0.6 * np.sin(np.pi * t * (b + 1)) * g.uniform(0.5, 1.0)
        xy = np.cumsum(0.03 * np.stack([np.cos(heading), np.sin(heading)], -1), 0)
        xy -= xy[0]
        traj.append(np.concatenate([xy, np.cos(heading)[:, None], np.sin(heading)[:, None]], -1))
    traj = np.stack(traj)
    template = g.normal(0, 0.3, (79, 3))
    tt = np.linspace(0, 1, NF)[:, None, None]
    out = {"local": [], "vel": []}
    for b in range(B):
        start, end = template + g.normal(0, 0.05, (2, 79, 3))      # each window its own start and end poses
        local = (1 - tt) * start + tt * end + 0.1 * np.sin(2 * np.pi * (b + 1) * tt) * g.normal(0, 1, (1, 79, 3))
        loc, vel = local_motion(global_motion(local, traj[b]), traj[b])   # consistent (local, vel) pairs
        out["local"].append(loc)
        out["vel"].append(vel)
    contacts = (np.sin(2 * np.pi * 2 * tt[..., 0] + np.arange(4)) > 0)[None].repeat(B, 0)
    f = lambda x: torch.as_tensor(np.asarray(x)).float()  # noqa: E731
    return {"traj": f(traj), "traj_interp": f(interpolated_trajectory(traj)), "local": f(np.stack(out["local"])),
            "vel": f(np.stack(out["vel"])), "contacts": f(contacts)}


def _stats(w: dict[str, torch.Tensor]) -> MotionFillStats:
    return MotionFillStats.fit({"local": w["local"].numpy(), "vel": w["vel"].numpy()})


def _perturbed(model: torch.nn.Module, seed: int = 0) -> torch.nn.Module:
    """The zero-initialised output layers given random weights (so outputs differ from the blend)."""
    torch.manual_seed(seed)
    for name, p in model.named_parameters():
        if name.startswith(("out", "contact_head.")):
            torch.nn.init.normal_(p, std=0.05)
    return model.eval()


def test_sizes_shapes_and_the_linear_blend_at_initialisation():
    w = _windows()
    for cls in (CNNAE, PoseNet, RouteNet):
        assert num_weights(cls()) < 300_000
    for m in (CNNAE(), PoseNet()):
        m.set_stats(_stats(w)).eval()
        ch0 = m.infill(w["local"], w["contacts"], w["vel"])
        assert ch0.shape == (2, NF, 79 * 3 + 4)
        # zero-initialised outputs: the local markers blended linearly (numpy), contact logits 0
        np.testing.assert_allclose(m.denormalise(ch0[..., :-4]).detach().numpy(),
                                   linear_local(w["local"].double().numpy()), atol=2e-5)
        assert (ch0[..., -4:] == 0).all()
        s = m.predict(w["traj_interp"][0], w["local"][0], w["contacts"][0], traj=w["traj"][0])
        assert s.keys() == {"traj", "local", "contacts", "markers"}
        assert s["markers"].shape == (1, NF, 79, 3) and s["contacts"].shape == (1, NF, 4)
        np.testing.assert_allclose(s["markers"][0].numpy(), global_motion(s["local"][0].double().numpy(),
                                                                          w["traj"][0].double().numpy()), atol=1e-5)
    r = RouteNet().eval()
    torch.testing.assert_close(r.route(w["traj_interp"]), w["traj_interp"])     # starts at Gamma_bar


def test_predict_refuses_non_finite_inputs_as_the_vae_does():
    """A NaN contact made CNN-AE return NaN markers without a word; MotionFillVAE.sample refuses it, so do they."""
    w = _windows()
    for m in (CNNAE(), PoseNet()):
        m.set_stats(_stats(w)).eval()
        c = w["contacts"][0].clone()
        c[3, 1] = float("nan")
        with pytest.raises(ValueError, match="contacts: expected finite real values"):
            m.predict(w["traj_interp"][0], w["local"][0], c, traj=w["traj"][0])
        loc = w["local"][0].clone()
        loc[0, 0, 0] = float("inf")
        with pytest.raises(ValueError, match="local: expected finite real values"):
            m.predict(w["traj_interp"][0], loc, w["contacts"][0], traj=w["traj"][0])
        # as MotionFillVAE.sample: markers in mm came back ~850 m away, contacts of 5 were read (an independent check)
        with pytest.raises(ValueError, match="local: largest side .* metres"):
            m.predict(w["traj_interp"][0], w["local"][0] * 1000, w["contacts"][0], traj=w["traj"][0])
        with pytest.raises(ValueError, match=r"contacts: expected contact probabilities in \[0, 1\]"):
            m.predict(w["traj_interp"][0], w["local"][0], w["contacts"][0] * 0 + 5, traj=w["traj"][0])


def test_deterministic_outputs_keep_the_known_frames():
    w = _windows(seed=1)
    route = _perturbed(RouteNet(), 2)
    for m in (_perturbed(CNNAE().set_stats(_stats(w)), 0), _perturbed(PoseNet().set_stats(_stats(w)), 1),
              RoutePoseNet(route, _perturbed(PoseNet().set_stats(_stats(w)), 1))):
        a = m.predict(w["traj_interp"][0], w["local"][0], w["contacts"][0], traj=w["traj"][0])
        b = m.predict(w["traj_interp"][0], w["local"][0], w["contacts"][0], n=5, generator=torch.Generator().manual_seed(3),
                      traj=w["traj"][0])
        for k in a:
            torch.testing.assert_close(a[k], b[k])                   # no sampling: the same single output
        torch.testing.assert_close(a["local"][0, [0, -1]], w["local"][0, [0, -1]], atol=1e-5, rtol=0)
        want = global_motion(w["local"][0].double().numpy(), w["traj"][0].double().numpy())[[0, -1]]
        np.testing.assert_allclose(a["markers"][0, [0, -1]].numpy(), want, atol=1e-5)
        assert not torch.allclose(a["local"][0, 30], torch.as_tensor(linear_local(w["local"][:1].numpy())[0, 30]).float(),
                                  atol=1e-3)                          # the in-between frames are the network's
    full = RoutePoseNet(route, PoseNet().set_stats(_stats(w))).predict(w["traj_interp"][0], w["local"][0],
                                                                       w["contacts"][0])
    g = route.predict(w["traj_interp"][0])["traj"][0]
    torch.testing.assert_close(full["traj"][0], g)
    torch.testing.assert_close(g[[0, 60]], w["traj"][0, [0, 60]])   # the known root states
    assert not torch.allclose(g[30], w["traj_interp"][0, 30], atol=1e-3)


def test_local_loss_is_eq8_deterministic_part():
    """At initialisation (the blend) the loss equals the L1 terms and the BCE computed independently in numpy."""
    w = _windows(seed=2)
    m = PoseNet().set_stats(_stats(w)).eval()
    logs = m.loss(w)
    mean, std = m.marker_mean.numpy(), m.marker_std.numpy()
    xt = (w["local"].numpy().reshape(2, NF, -1) - mean) / std
    x = (linear_local(w["local"].double().numpy()).reshape(2, NF, -1) - mean) / std
    l1 = np.abs(x - xt).sum((1, 2)).mean()
    l1v = np.abs(np.diff(x, axis=1) - np.diff(xt, axis=1)).sum((1, 2)).mean()
    bce = np.log(2.0) * NF * 4                                       # logits 0: -log(1/2) per contact
    assert logs["markers"].item() == pytest.approx(l1, rel=1e-4)
    assert logs["markers_vel"].item() == pytest.approx(l1v, rel=1e-4)
    assert logs["contacts"].item() == pytest.approx(bce, rel=1e-5)
    assert logs["loss"].item() == pytest.approx(l1 + 0.5 * l1v + bce, rel=1e-4)
    r = RouteNet().eval().loss(w)
    d = (w["traj_interp"] - w["traj"]).numpy()
    want = np.abs(d).sum((1, 2)).mean() + 0.05 * np.abs(np.diff(d, axis=1)).sum((1, 2)).mean()
    assert r["loss"].item() == pytest.approx(want, rel=1e-4)


def _overfit(model: torch.nn.Module, w: dict[str, torch.Tensor], steps: int, lr: float) -> None:
    torch.manual_seed(0)
    opt = torch.optim.Adam(model.parameters(), lr=lr)
    model.train()
    for _ in range(steps):
        loss = model.loss(w)["loss"]
        opt.zero_grad()
        loss.backward()
        torch.nn.utils.clip_grad_norm_(model.parameters(), 1.0)          # as graspkit.train.fit
        opt.step()
    model.eval()


@pytest.mark.parametrize("make, steps, lr", [(lambda: CNNAE(channels=(8, 8, 8, 8)), 250, 1e-2),
                                             (lambda: PoseNet(hidden=48), 800, 3e-3)], ids=["cnn_ae", "posenet"])
def test_a_tiny_overfit_beats_the_linear_blend(make, steps, lr):
    """PoseNet at 500 steps sat at the bars (error / blend 0.14-0.28, contact accuracy 0.76-0.95 under four
    floating-point kernel sets): 800 steps give 0.06-0.09 and 0.92-0.97."""
    w = _windows(seed=3)
    torch.manual_seed(0)
    m = make().set_stats(_stats(w))
    _overfit(m, w, steps, lr)
    err = torch.stack([m.predict(w["traj_interp"][i], w["local"][i], w["contacts"][i], traj=w["traj"][i])["local"][0]
                       - w["local"][i] for i in range(2)]).norm(dim=-1).mean().item()
    blend = np.linalg.norm(linear_local(w["local"].double().numpy()) - w["local"].numpy(), axis=-1).mean()
    assert err < 0.3 * blend, (err, blend)
    probs = m.predict(w["traj_interp"][0], w["local"][0], w["contacts"][0], traj=w["traj"][0])["contacts"][0]
    assert ((probs > 0.5).float() == w["contacts"][0]).float().mean() > 0.8


def test_routenet_overfit_keeps_its_ends_and_fits_the_curve():
    w = _windows(seed=4)
    torch.manual_seed(0)
    r = RouteNet(hidden=32, embed=16)
    _overfit(r, w, 300, 1e-2)
    g = r.route(w["traj_interp"]).detach()
    torch.testing.assert_close(g[:, 0], w["traj"][:, 0], atol=1e-5, rtol=0)
    torch.testing.assert_close(g[:, 60], w["traj"][:, 60], atol=1e-5, rtol=0)
    err = (g[..., :2] - w["traj"][..., :2]).norm(dim=-1).mean()
    straight = (w["traj_interp"][..., :2] - w["traj"][..., :2]).norm(dim=-1).mean()
    assert err < 0.3 * straight, (err, straight)


def test_state_round_trip_through_a_weights_only_file(tmp_path):
    w = _windows(seed=5)
    for m in (_perturbed(CNNAE(channels=(4, 8, 8, 8)).set_stats(_stats(w))), _perturbed(PoseNet(hidden=16).set_stats(_stats(w))),
              _perturbed(RouteNet(hidden=8, embed=4))):
        path = tmp_path / f"{m.kind}.pt"
        torch.save(m.state(), path)
        again = baseline_from_state(torch.load(path, weights_only=True))
        assert type(again) is type(m) and again.config() == m.config() and not again.training
        a = m.predict(w["traj_interp"][0], w["local"][0], w["contacts"][0], traj=w["traj"][0])
        b = again.predict(w["traj_interp"][0], w["local"][0], w["contacts"][0], traj=w["traj"][0])
        for k in a:
            torch.testing.assert_close(a[k], b[k])
        half = m.state()
        half["model"] = {k: v.half() if "mean" not in k and "std" not in k else v for k, v in half["model"].items()}
        c = baseline_from_state(half).predict(w["traj_interp"][0], w["local"][0], w["contacts"][0], traj=w["traj"][0])
        torch.testing.assert_close(c["traj"], a["traj"], atol=2e-3, rtol=0)


def test_wrong_shapes_and_kinds_are_refused_with_the_argument_named():
    w = _windows()
    m = PoseNet()
    with pytest.raises(ValueError, match="local"):
        m.predict(w["traj_interp"][0], w["local"][0, :60], w["contacts"][0])
    with pytest.raises(ValueError, match="traj_interp"):
        m.predict(w["traj_interp"][0, :61], w["local"][0], w["contacts"][0])
    with pytest.raises(ValueError, match="contacts"):
        CNNAE().predict(w["traj_interp"][0], w["local"][0], w["contacts"][0, :, :3])
    with pytest.raises(ValueError, match="traj"):
        m.predict(w["traj_interp"][0], w["local"][0], w["contacts"][0], traj=w["traj"])      # a batch of two
    with pytest.raises(ValueError, match="traj_interp"):
        RouteNet().predict(w["traj_interp"])
    with pytest.raises(ValueError, match="kind"):
        baseline_from_state({"kind": "lemo", "model": {}, "model_config": {}})


def test_tab3_rows_for_the_baselines():
    """evaluate(..., baselines=...) adds the deterministic rows (APD 0; with zero-initialised outputs the local
    infillers are the linear blend, so their ADE is the linear row's); table() prints them beside the paper's."""
    from graspkit.eval_motionfill import evaluate, table
    from graspkit.models.motionfill import MotionFillVAE

    w = _windows(B=2, seed=6)
    arr = {"traj": w["traj"].numpy(), "local": w["local"].numpy(), "contacts": w["contacts"].numpy().astype(bool),
           "markers": np.stack([global_motion(w["local"][i].double().numpy(), w["traj"][i].double().numpy())
                                for i in range(2)]).astype(np.float32), "clip": np.arange(2)}
    torch.manual_seed(0)
    ours = MotionFillVAE()
    ours.set_stats(_stats(w))
    base = {k: m.set_stats(_stats(w)).eval() for k, m in (("cnn_ae", CNNAE()), ("posenet", PoseNet()),
                                                         ("routenet", RouteNet()))}
    rows = evaluate(ours, arr, np.arange(2), n=2, baselines=base)
    for k in ("CNN-AE (local)", "PoseNet (local)"):
        assert rows[k]["APD"] == 0.0
        assert rows[k]["ADE"] == pytest.approx(rows["Linear (local)"]["ADE"], abs=1e-5)
    assert rows["Route+PoseNet"]["ADE"] == pytest.approx(rows["Linear"]["ADE"], abs=1e-5)   # RouteNet at Gamma_bar
    text = table(rows)
    assert "| CNN-AE (local) | " in text and "CNN-AE (local) (paper only)" not in text and "LEMO (local) (paper only)" in text
    assert "0.219 / 0.575 / 0.955 / 0.884" in text
    assert "Route+PoseNet" not in evaluate(ours, arr, np.arange(2), n=2, baselines={"cnn_ae": base["cnn_ae"]})


def test_train_command_end_to_end_on_the_shipped_approach_clips(tmp_path, monkeypatch):
    """`graspkit train motionfill_baseline --model routenet` on the four shipped approach clips writes a float16
    checkpoint that `load_baselines` reads back; an unknown model is refused."""
    from graspkit.cli import main
    from graspkit.eval_motionfill import load_baselines
    from graspkit.paths import DATA_STUBS

    monkeypatch.setenv("GRASPKIT_CACHE", str(tmp_path / "cache"))
    rc = main(["train", "motionfill_baseline", "--model", "routenet", "--data", str(DATA_STUBS / "approach"),
               "--clips", "4", "--epochs", "2", "--out", str(tmp_path / "motionfill_routenet.pt")])
    assert rc == 0
    state = torch.load(tmp_path / "motionfill_routenet.pt", weights_only=True)
    assert state["model"]["out.weight"].dtype == torch.float16 and state["kind"] == "routenet"
    assert len(list((tmp_path / "cache" / "runs").glob("motionfill_routenet_s0_*.csv"))) == 1
    models = load_baselines(tmp_path)
    assert set(models) == {"routenet"} and isinstance(models["routenet"], RouteNet)
    with pytest.raises(SystemExit):
        main(["train", "motionfill_baseline", "--model", "lemo"])


def test_posenet_reads_start_end_velocity_and_normalised_time_per_frame():
    """PoseNet's per-frame input is [start markers, end markers, root velocity, t/T] (class docstring, Wang et al.):
    read at its input layer with a forward hook."""
    g = torch.Generator().manual_seed(0)
    local = torch.randn(2, NUM_FRAMES, NUM_MARKERS, 3, generator=g)
    vel = torch.randn(2, NUM_FRAMES, 3, generator=g)
    m = PoseNet().eval()                                   # unit statistics: normalisation is the identity
    seen = []
    m.inp[0].register_forward_hook(lambda mod, args, out: seen.append(args[0].detach()))
    m.infill(local, torch.zeros(2, NUM_FRAMES, 4), vel)
    f = seen[0]
    n = NUM_MARKERS * 3
    torch.testing.assert_close(f[..., :n], local[:, :1].flatten(2).expand(-1, NUM_FRAMES, -1))
    torch.testing.assert_close(f[..., n:2 * n], local[:, -1:].flatten(2).expand(-1, NUM_FRAMES, -1))
    torch.testing.assert_close(f[..., 2 * n:2 * n + 3], vel)
    np.testing.assert_allclose(f[0, :, -1].numpy(), np.arange(NUM_FRAMES) / (NUM_FRAMES - 1), atol=1e-6)   # t / T


NR = 62


def _window(seed: int = 0):
    g = np.random.default_rng(seed)
    t = np.arange(NR) / 60.0
    heading = np.pi / 2 + 0.8 * np.sin(np.pi * t)
    xy = np.cumsum(0.03 * np.stack([np.cos(heading), np.sin(heading)], -1), 0)
    traj = np.concatenate([xy - xy[0], np.cos(heading)[:, None], np.sin(heading)[:, None]], -1)[None]
    local, vel = local_motion(g.normal(0, 0.3, (NUM_FRAMES, 79, 3)), traj[0])
    contacts = (g.random((1, NUM_FRAMES, 4)) < 0.5)
    f = lambda x: torch.as_tensor(np.asarray(x)).float()   # noqa: E731
    return {"traj": f(traj), "traj_interp": f(interpolated_trajectory(traj)), "local": f(local[None]),
            "vel": f(vel[None]), "contacts": f(contacts)}


def test_routenet_root_error_is_the_horizontal_root_distance_in_cm():
    """At initialisation RouteNet returns Gamma_bar; its root_error_cm is the mean horizontal (x, y) distance between
    Gamma_bar and Gamma in cm (numpy), the heading's cos/sin not counted."""
    torch.manual_seed(0)
    w = _window()
    logs = RouteNet().eval().loss(w)
    d = w["traj_interp"][0, :, :2].double().numpy() - w["traj"][0, :, :2].double().numpy()
    assert logs["root_error_cm"].item() == pytest.approx(100 * np.linalg.norm(d, axis=-1).mean(), rel=1e-4)


@pytest.mark.parametrize("make", [CNNAE, PoseNet])
def test_baseline_contacts_are_probabilities(make):
    """predict() returns contact probabilities in [0, 1] even when the decoded logits lie far outside it."""
    w = _window()
    torch.manual_seed(0)
    m = make()
    m.set_stats(MotionFillStats.fit({"local": w["local"].numpy(), "vel": w["vel"].numpy()}))
    for name, p in m.named_parameters():
        if name.startswith(("out", "contact_head.")):
            torch.nn.init.normal_(p, std=2.0)
    c = m.eval().predict(w["traj_interp"][0], w["local"][0], w["contacts"][0])["contacts"]
    assert ((c >= 0) & (c <= 1)).all()
    assert ((c > 0.01) & (c < 0.99)).any()
