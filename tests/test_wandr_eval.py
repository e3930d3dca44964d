"""WANDR's goal-grid evaluation (§4.2-4.3): the grid, SR / DTG on hand-made motions, FS on the fly against full meshes."""
import dataclasses
import warnings

import numpy as np
import pytest
import torch
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import shortest_path

from graspkit import eval_wandr as E
from graspkit import intention as I
from graspkit import metrics
from graspkit.body import BodyModel
from graspkit.body.random_model import random_smplx_arrays
from graspkit.data import load_motion
from graspkit.data.wandr_dataset import FOOT_JOINTS, held_out_starts, list_clips, load_clips, rest_joints
from graspkit.paths import DATA_STUBS
from graspkit.rotations import axis_angle_to_matrix


def _clip(bm, name="locomotion/locomotion_000003.npz"):
    m = load_motion(DATA_STUBS / "motion" / name)
    p = I.pose_from_axis_angle(torch.as_tensor(m.trans), torch.as_tensor(m.poses))
    return m, p, rest_joints(bm, m.betas[None])[0]


def _reach_frames(bm):
    """Frames 30-59 of a reach clip as 30 "bodies", each with its frame's finger pose: LowVertices, the body
    transforms, the body index per frame and the body model's full mesh of those frames."""
    m, p, rest = _clip(bm, "reach/reach_000002.npz")
    frames = slice(30, 60)
    low = E.LowVertices(bm, torch.as_tensor(m.betas)[None].expand(30, -1), torch.as_tensor(m.poses[frames]))
    Rg, pos = I.body_transforms(p[frames], rest)
    return low, Rg, pos, torch.arange(30), m.vertices(bm, 30, 60)


def test_the_grid_is_the_papers():
    goals, cells = E.grid_goals()
    assert goals.shape == (125, 3) and cells.shape == (125, 3)
    assert sorted(set(cells[:, 0])) == [0, 72, 144, 216, 288]
    assert np.allclose(sorted(set(cells[:, 1])), [0, 0.45, 0.9, 1.35, 1.8])
    assert np.allclose(sorted(set(cells[:, 2])), [0.5, 1.625, 2.75, 3.875, 5.0])
    for g, (a, h, d) in zip(goals.numpy(), cells):
        assert np.allclose(g, [d * np.cos(np.radians(a)), d * np.sin(np.radians(a)), h], atol=1e-6)
    assert E.T_GOAL == 239 and 5 * 5 * 5 * 6 * 5 == 3750


def test_foot_and_hand_vertices_are_posed_exactly_as_the_body_model_does(bm):
    low, Rg, pos, body, full = _reach_frames(bm)
    assert torch.allclose(low.feet.points(Rg, pos, body), full[:, low.feet.ids], atol=1e-5)
    assert torch.allclose(low.feet.heights(Rg, pos, body), full[:, low.feet.ids, 2], atol=1e-5)
    one = torch.randint(len(low.feet.ids), (30,), generator=torch.Generator().manual_seed(0))
    assert torch.allclose(low.feet.points(Rg, pos, body, one), full[torch.arange(30), low.feet.ids[one]], atol=1e-5)
    RgF, posF = low.with_fingers(Rg, pos, body)
    for hand, wrist, reach in zip(low.hands, E.WRISTS, low.reach):
        x = hand.points(RgF, posF, body)
        assert torch.allclose(x, full[:, hand.ids], atol=1e-5)
        assert torch.allclose(hand.heights(RgF, posF, body), full[:, hand.ids, 2], atol=1e-5)
        assert ((x - pos[:, None, wrist]).norm(dim=-1).amax(1) <= reach).all()      # the bound holds
    assert len(low.feet.ids) > 400 and set(low.feet.joints.tolist()) <= {4, 5, 7, 8, 10, 11}
    assert min(len(h.ids) for h in low.hands) > 300


def test_feet_and_hands_with_pose_correctives_are_posed_exactly(tmp_path):
    """A body model whose every vertex carries pose correctives (the shipped one's arrays with random posedirs, as a
    real SMPL-X file has them): the feet and hands, their lowest vertex and the FS still match the full mesh."""
    from graspkit.body import BodyModel
    from graspkit.paths import default_model_path

    with np.load(default_model_path(), allow_pickle=False) as f:
        arrays = {k: f[k] for k in f.files}
    arrays["posedirs"] = np.random.default_rng(3).normal(0, 2e-3, arrays["posedirs"].shape)
    np.savez(tmp_path / "SMPLX_NEUTRAL.npz", **arrays)
    bmc = BodyModel.from_file(tmp_path / "SMPLX_NEUTRAL.npz")
    m, p, rest = _clip(bmc, "reach/reach_000002.npz")
    frames = slice(20, 80)
    low = E.LowVertices(bmc, torch.as_tensor(m.betas)[None], torch.as_tensor(m.poses[50]))
    assert low.correctives
    q = p[frames]
    start = I.StartPose(p[49], p[50], rest, torch.as_tensor(m.betas), torch.as_tensor(m.poses[50]))
    full = E.body_vertices(bmc, q, start)                                       # every vertex, correctives included
    Rg, pos = I.body_transforms(q, rest)
    body = torch.zeros(len(q), dtype=torch.long)
    local = I.pose_rotmats(q)[1]
    f = low.feature(local)
    RgF, posF = low.with_fingers(Rg, pos, body)
    assert torch.allclose(low.feet.points(Rg, pos, body, feature=f), full[:, low.feet.ids], atol=1e-5)
    for hand, wrist, reach in zip(low.hands, E.WRISTS, low.reach):
        x = full[:, hand.ids]
        assert torch.allclose(hand.heights(RgF, posF, body, f), x[..., 2], atol=1e-5)
        assert ((x - pos[:, None, wrist]).norm(dim=-1).amax(1) <= reach).all()
    lowest, at, _, _ = low.lowest(Rg, pos, body, local=local)
    inside = torch.isin(full[..., 2].argmin(1), low.ids)                          # frames whose lowest is a foot's
    assert inside.any() and torch.equal(low.ids[lowest][inside], full[..., 2].argmin(1)[inside])
    with pytest.raises(ValueError, match="local"):
        low.lowest(Rg, pos, body)
    res = E.evaluate_motions(q[None], rest[None], torch.zeros(1, 3), torch.as_tensor(m.betas)[None], bmc,
                             full_pose=torch.as_tensor(m.poses[50]))
    assert res.fs[0] == pytest.approx(metrics.foot_skating_wandr(full).mean(), abs=1e-6)


def test_the_lowest_vertex_is_the_whole_meshs_also_when_a_hand_reaches_the_floor(bm):
    from graspkit.models.wandr import generate, load_wandr

    model = load_wandr(DATA_STUBS / "checkpoints" / "wandr.pt")
    start = E.starts_from_meta(model.meta)[0]
    goals = torch.stack([E.goal_from_cylinder(a, d, 0.0) for a, d in ((0, 0.5), (72, 1.625), (288, 0.5))])
    out = generate(model, start, goals, t_goal=90, n=2, generator=torch.Generator().manual_seed(0), frames=120)
    B, T = out.p.shape[:2]
    low = E.LowVertices(bm, start.betas[None], start.full_pose)
    hand_frames = 0
    previous = None
    for k in range(T):
        Rg, pos = I.body_transforms(out.p[:, k], out.rest)
        lowest, at, _, _ = low.lowest(Rg, pos, torch.zeros(B, dtype=torch.long), previous)
        full = torch.stack([E.body_vertices(bm, out.p[b, k:k + 1], start)[0] for b in range(B)])
        truth = full[..., 2].argmin(1)
        assert torch.equal(low.ids[lowest], truth)
        assert torch.allclose(at, full[torch.arange(B), truth], atol=1e-5)
        hand_frames += int((lowest >= low.offsets[1]).sum())
        previous = lowest
    assert hand_frames > 0                                  # a hand was the lowest vertex in some frames
    res = E.evaluate_motions(out.p, out.rest, out.goal[:, 0], start.betas[None].expand(B, -1), bm,
                             full_pose=start.full_pose)
    full = [E.body_vertices(bm, out.p[b], start) for b in range(B)]
    truth = np.array([metrics.foot_skating_wandr(v).mean() for v in full])
    # the same frames skate, but for a step within float32 rounding of the threshold (the two paths sum in another
    # order; with other CPU kernels one such step of these 714 landed on the other side)
    ties = np.array([(np.abs(metrics.lowest_vertex_motion(v)[0] - metrics.WANDR_SKATE_THRESHOLD) < 1e-6).mean()
                     for v in full])
    assert np.all(np.abs(res.fs - truth) <= ties + 1e-6), (res.fs, truth, ties)


@pytest.mark.parametrize("name", ["locomotion/locomotion_000003.npz", "locomotion/locomotion_000007.npz",
                                  "reach/reach_000002.npz"])
def test_fs_on_the_fly_equals_wandrs_metric_on_full_meshes(bm, name):
    m, p, rest = _clip(bm, name)
    slid = p.clone()
    slid[:, 0] += 0.04 * torch.sin(torch.arange(len(p)) / 3.0)       # a slide in x: some frames skate, some not
    for q in (p, slid):
        res = E.evaluate_motions(q[None], rest[None], torch.zeros(1, 3), torch.as_tensor(m.betas)[None], bm)
        verts = torch.cat([bm.forward_rotmats(
            torch.cat([I.pose_rotmats(q[a:a + 64])[1], m.rotmats()[a:a + 64, 22:]], 1),
            betas=torch.as_tensor(m.betas)[None], transl=q[a:a + 64, :3]).vertices for a in range(0, len(q), 64)])
        truth = metrics.foot_skating_wandr(verts).mean()
        assert res.fs[0] == pytest.approx(truth, abs=1e-6)          # the same frames skate
    assert res.fs[0] > 0.2                                              # the slid clip does skate


def test_success_and_distance_to_goal_on_a_hand_made_motion(bm):
    m, p, rest = _clip(bm, "reach/reach_000002.npz")
    wrist = I.body_joints(p, rest)[:, I.WRIST]
    k = 40
    goals = torch.stack([wrist[k] + torch.tensor([0.05, 0.0, 0.0]), wrist[k] + torch.tensor([0.0, 0.0, 3.0])])
    res = E.evaluate_motions(p[None].expand(2, -1, -1), rest[None].expand(2, -1, -1), goals,
                             torch.as_tensor(m.betas)[None].expand(2, -1), bm, t_goal=k)
    d = (wrist[None] - goals[:, None]).norm(dim=-1)
    assert np.allclose(res.dtg, d.min(1).values.numpy(), atol=1e-6)
    assert res.success.tolist() == [True, False]
    assert res.reach_frame[0] == int((d[0] <= 0.10).nonzero()[0]) and res.reach_frame[1] == -1
    assert res.error_at_goal[0] == pytest.approx(0.05, abs=1e-5)


def test_a_wrist_reached_with_both_feet_off_the_floor_is_not_a_grounded_success(bm):
    """The same clip lifted 20 cm from frame 30 on (full meshes: its lowest vertex then 20 cm up): the goal at frame
    40's wrist is reached (SR) but not with a foot on the floor (SR_grounded); the floating share is the lifted frames'
    share, and the clip as made (on the floor throughout) floats in none."""
    m, p, rest = _clip(bm, "reach/reach_000002.npz")
    lifted = p.clone()
    lifted[30:, 2] += 0.20
    goal = torch.stack([I.body_joints(q, rest)[40, I.WRIST] for q in (p, lifted)])     # each clip's wrist at 40
    res = E.evaluate_motions(torch.stack([p, lifted]), rest[None].expand(2, -1, -1), goal,
                             torch.as_tensor(m.betas)[None].expand(2, -1), bm, t_goal=40)
    low = m.vertices(bm)[..., 2].min(-1).values                # the clip's full meshes: on the floor throughout
    assert float(low.max()) < 0.01 and float(low[30:].min()) + 0.20 > 0.15   # lifted: both feet 19+ cm up
    assert res.success.tolist() == [True, True] and res.grounded.tolist() == [True, False]
    assert res.floating[0] == 0.0 and res.floating[1] == pytest.approx((len(p) - 30) / len(p))
    s = E.summary(res)
    assert s["SR"] == 100.0 and s["SR_grounded"] == 50.0


def test_a_body_sunk_into_the_floor_counts_its_sunk_frames(bm):
    """The same clip lowered 3 cm from frame 30 on: the frames after it count as sunk (lowest foot vertex > 1 cm
    below the floor, from the full meshes: 2+ cm under it), the clip as made none; a foot there still touches
    (SR_grounded), but its wrist, on the goal only at frame 40 (and a few frames around), is not reached unsunk."""
    m, p, rest = _clip(bm, "reach/reach_000002.npz")
    sunk = p.clone()
    sunk[30:, 2] -= 0.03
    goal = torch.stack([I.body_joints(q, rest)[40, I.WRIST] for q in (p, sunk)])
    res = E.evaluate_motions(torch.stack([p, sunk]), rest[None].expand(2, -1, -1), goal,
                             torch.as_tensor(m.betas)[None].expand(2, -1), bm, t_goal=40)
    low = m.vertices(bm)[..., 2].min(-1).values
    truth = [float(((low - d) < -E.SUNK_DEPTH).double().mean()) for d in (torch.zeros(len(p)),
                                                                        torch.tensor([0.0] * 30 + [0.03] * (len(p) - 30)))]
    assert truth[0] == 0.0 and truth[1] == pytest.approx((len(p) - 30) / len(p))
    assert res.sunk.tolist() == pytest.approx(truth)
    assert res.grounded.tolist() == [True, True] and res.unsunk.tolist() == [True, False]   # reached at 40: sunk
    s = E.summary(res)
    assert s["sunk"] == pytest.approx(50 * truth[1]) and s["SR"] == 100.0 and s["SR_not_sunk"] == 50.0


def test_summary_and_breakdown():
    cells = np.array([[0, 0.0, 0.5], [72, 0.0, 5.0], [0, 1.8, 0.5], [72, 1.8, 5.0]])
    r = E.GridResult(np.zeros(4, int), np.arange(4), np.zeros(4, int), cells, np.array([0.05, 0.5, 0.09, 0.2]),
                     np.array([3, -1, 7, -1]), np.array([0.1, 0.0, 0.2, 0.1]), np.array([0.05, 0.6, 0.1, 0.3]))
    s = E.summary(r)
    assert s["SR"] == 50 and s["FS"] == pytest.approx(10) and s["DTG"] == pytest.approx(21)
    assert s["time_to_goal_s"] == pytest.approx(5 / 30)              # frames 3 and 7 at 30 fps
    assert E.breakdown(r, "angle") == {0.0: 100.0, 72.0: 0.0}
    assert E.breakdown(r, "height") == {0.0: 50.0, 1.8: 50.0}
    with pytest.raises(ValueError, match="by"):
        E.breakdown(r, "colour")
    assert "| WANDR | 50.0 | 10.0 | 21.0 | 32 | 16 | 24.8 |" in E.table({"WANDR": s})
    r.error_at_goal = np.full(4, np.nan)                              # motions that end before t_G: no error there
    with warnings.catch_warnings():
        warnings.simplefilter("error")                                # and no "Mean of empty slice" either
        assert np.isnan(E.summary(r)["error_at_goal"])


def test_body_vertices_are_the_body_models(bm):
    m, p, rest = _clip(bm, "reach/reach_000002.npz")
    k = 50
    start = I.StartPose(p[k - 1], p[k], rest, torch.as_tensor(m.betas), torch.as_tensor(m.poses[k]))
    v = E.body_vertices(bm, p[k:k + 1], start)
    assert torch.allclose(v, m.vertices(bm, k, k + 1), atol=1e-5)


def test_goal_from_cylinder_matches_the_grid():
    goals, cells = E.grid_goals()
    for g, (a, h, d) in zip(goals[::17], cells[::17]):
        assert torch.allclose(E.goal_from_cylinder(a, d, h), g, atol=1e-6)


def test_goal_reacher_callback(bm):
    from graspkit.data.wandr_dataset import held_out_starts
    from graspkit.models.wandr import WandrConfig, WandrCVAE, generate

    m = load_motion(DATA_STUBS / "motion" / "reach" / "reach_000001.npz")
    start = held_out_starts([m], ["reach_000001"], bm, n=1)[0]
    torch.manual_seed(0)
    model = WandrCVAE(WandrConfig(latent=4, hidden=32, enc_layers=1, dec_layers=1, dropout=0.0)).eval()
    r = E.GoalReacher(model, start, seed=3, angle=0.0, distance=1.0, height=1.0, seconds=1.0)
    for bad in (2.5, True, -1, "3"):                 # was torch's manual_seed error at run(), naming nothing
        with pytest.raises(ValueError, match="^seed: expected a non-negative integer"):
            E.GoalReacher(model, start, seed=bad)
    out = r.update("angle", 90.0)
    assert torch.allclose(r.goal, torch.tensor([0.0, 1.0, 1.0]), atol=1e-6) and r.t_goal == 30
    ref = generate(model, start, r.goal[None], 30, generator=torch.Generator().manual_seed(3))
    d = (ref.joints[0, :, I.WRIST] - r.goal).norm(dim=-1)
    assert out["dtg_cm"] == pytest.approx(100 * float(d.min()), abs=1e-4)
    assert out["closest_frame"] == int(d.argmin()) and out["reached"] == bool(d.min() <= 0.1)
    low = I.body_joints(ref.p[0], start.rest)[:, [7, 8, 10, 11], 2].amin(-1)     # ankles and feet
    assert out["lift_cm"] == pytest.approx(100 * float((low - low[0]).max()), abs=1e-4)
    with torch.no_grad():                       # the floor constraint reaches the generation
        model.decoder[-1].bias[2] += 0.02 / model.delta_std[2]
    lifted = E.GoalReacher(model, start, seed=3, seconds=1.0).run()["lift_cm"]
    held = E.GoalReacher(model, start, seed=3, seconds=1.0, floor=0.01).run()["lift_cm"]
    assert lifted > 20 and held == pytest.approx(1.0, abs=1e-3)
    assert r.update("seconds", 2.0) and r.t_goal == 60 and len(r.joints) == 61
    assert r.png()[:8] == b"\x89PNG\r\n\x1a\n"
    with pytest.raises(ValueError, match="height"):
        r.update("height", 3.0)
    with pytest.raises(ValueError, match="name"):
        r.update("colour", 1.0)


def test_goal_reacher_moves_any_start_to_where_its_sliders_measure_from(bm):
    """A start from StartPose.from_motion (pelvis at (-1.0, -1.7) m, facing -113°) took the goal at angle 0, 1 m as
    world (1, 0): 2.6 m from the pelvis at 152° (an independent check). The reacher moves such a start onto the
    origin facing +x, body pose unchanged, so the goal lies 1 m straight ahead of the pelvis; floor=True is refused
    when built (it failed in torch at the first run), and figure() leaves no pyplot figure open."""
    import matplotlib.pyplot as plt

    from graspkit.models.wandr import WandrConfig, WandrCVAE

    m = load_motion(DATA_STUBS / "motion" / "locomotion" / "locomotion_000003.npz")
    start = I.StartPose.from_motion(m, 40, bm)
    pelvis0 = start.p[:2] + start.rest[0, :2]
    assert float(pelvis0.norm()) > 0.5 and abs(float(I.heading_of_pose(start.p))) > 0.5       # not canonical
    torch.manual_seed(0)
    model = WandrCVAE(WandrConfig(latent=4, hidden=32, enc_layers=1, dec_layers=1, dropout=0.0)).eval()
    r = E.GoalReacher(model, start, seed=1, angle=0.0, distance=1.0, height=1.0, seconds=1.0)
    J = I.body_joints(r.start.p[None], r.start.rest)[0]                 # (22, 3) at the start
    fwd = J[I.PELVIS, :2] + torch.stack([torch.cos(I.heading_of_pose(r.start.p)),
                                          torch.sin(I.heading_of_pose(r.start.p))])
    torch.testing.assert_close(r.goal[:2], fwd.float(), atol=1e-4, rtol=0)   # 1 m ahead of the pelvis
    torch.testing.assert_close(r.start.p[9:], start.p[9:])                  # the body's pose is the start's
    assert J[:, 2].min() == pytest.approx(float(I.body_joints(start.p[None], start.rest)[0, :, 2].min()), abs=1e-5)
    figs = plt.get_fignums()
    r.figure()
    assert plt.get_fignums() == figs
    # each half of "canonical" alone: over the origin but facing -113°, and facing +x but 1 m away
    c = start.canonical()
    turned = dataclasses.replace(start, p_prev=start.p_prev.clone(), p=start.p.clone())
    turned.p_prev[:2] -= pelvis0
    turned.p[:2] -= pelvis0
    moved = dataclasses.replace(c, p_prev=c.p_prev.clone(), p=c.p.clone())
    moved.p_prev[0] += 1.0
    moved.p[0] += 1.0
    assert c.is_canonical() and not turned.is_canonical() and not moved.is_canonical()
    for s in (turned, moved):
        rs = E.GoalReacher(model, s, angle=0.0, distance=1.0, height=1.0, seconds=1.0)
        Js = I.body_joints(rs.start.p[None], rs.start.rest)[0]
        assert rs.start.is_canonical() and float(Js[I.PELVIS, :2].norm()) < 1e-4
        torch.testing.assert_close(rs.goal[:2], torch.tensor([1.0, 0.0]) + Js[I.PELVIS, :2].float(), atol=1e-4, rtol=0)
    for ok in (np.float32(0.01), np.int64(0), 0.02):                 # numpy scalars, from an array or a widget
        E.GoalReacher(model, start, floor=ok)
    for bad in (True, -0.1, float("nan"), float("inf"), "1cm"):
        with pytest.raises(ValueError, match="^floor: expected None or a finite tolerance"):
            E.GoalReacher(model, start, floor=bad)
    with pytest.raises(TypeError, match="^start: expected a graspkit.intention.StartPose"):
        E.GoalReacher(model, start.p)


def test_an_evaluation_on_another_body_than_its_starts_is_refused(tmp_path, monkeypatch):
    """run_eval_wandr with GRASPKIT_MODEL naming a body 8 % larger than graspkit's: the checkpoint's held-out starts
    carry graspkit's rest joints, so the rollout would move graspkit's body while FS, SR and DTG were read on the other;
    it is refused before any rollout, naming the checkpoint, and `eval --all` refuses before any method runs. On
    graspkit's body every start is its own."""
    from conftest import PROCEDURAL_MODEL, npz_copy

    from graspkit.body import BodyModel
    from graspkit.eval_wandr import run_eval_wandr, starts_from_meta
    from graspkit.models.wandr import load_wandr
    from graspkit.paths import DATA_STUBS

    ck = DATA_STUBS / "checkpoints" / "wandr.pt"
    starts = starts_from_meta(load_wandr(ck).meta)
    assert all(s.made_on(BodyModel.from_file(PROCEDURAL_MODEL)) for s in starts)
    with np.load(PROCEDURAL_MODEL, allow_pickle=False) as z:
        big = npz_copy(PROCEDURAL_MODEL, tmp_path / "big.npz", v_template=z["v_template"] * 1.08,
                       shapedirs=z["shapedirs"] * 1.08)
    assert not any(s.made_on(BodyModel.from_file(big)) for s in starts)
    monkeypatch.setenv("GRASPKIT_MODEL", str(big))
    with pytest.raises(ValueError, match=r"checkpoint: .*wandr.pt's held-out starts were made on another body model"):
        run_eval_wandr(str(ck), n=1, threads=1)
    from graspkit.benchmark import run_all                     # eval --all says so before the other methods' hours
    with pytest.raises(ValueError, match=r"held-out starts were made on another body model"):
        run_all(tmp_path / "report", data=[DATA_STUBS / "grasps"], methods=("gt", "wandr"), quick=True)
    assert not (tmp_path / "report").exists()


def test_train_command_parses_the_schedule_flags():
    import argparse

    ap = argparse.ArgumentParser()
    sub = ap.add_subparsers(dest="cmd")
    E.add_wandr_commands(sub.add_parser("train").add_subparsers(dest="what"),
                         sub.add_parser("eval").add_subparsers(dest="what"))
    a = ap.parse_args(["train", "wandr", "--epochs", "5", "--batch-size", "256", "--lr", "2e-3", "--max-steps", "5",
                       "--ramp-epochs", "1", "--stride-scale", "2"])
    assert (a.epochs, a.batch_size, a.lr, a.max_steps, a.ramp_epochs, a.stride_scale) == (5, 256, 2e-3, 5, 1, 2)
    assert a.func is E._cmd_train
    with pytest.raises(ValueError, match="stride_scale"):
        E.run_train_wandr(stride_scale=0, folder="/nonexistent")
    a = ap.parse_args(["train", "wandr", "--kinds", "reach", "--reach-far", "--select-val"])
    assert (a.kinds, a.reach_far, a.select_val, a.window_stride, a.init) == ("reach", True, True, None, None)
    assert not a.reach_chain and ap.parse_args(["train", "wandr", "--reach-chain"]).reach_chain
    assert not a.reach_near and ap.parse_args(["train", "wandr", "--reach-near"]).reach_near
    a = ap.parse_args(["train", "wandr", "--window-stride", "1", "--init", "x.pt"])
    assert (a.window_stride, str(a.init)) == (1, "x.pt")
    with pytest.raises(ValueError, match="window_stride"):
        E.run_train_wandr(window_stride=0, folder="/nonexistent")
    with pytest.raises(ValueError, match="time_limit"):
        E.run_train_wandr(select_val=True, time_limit=60.0, folder="/nonexistent")
    for bad in ((), ("walk",), ("reach", "walk")):
        with pytest.raises(ValueError, match="kinds"):
            E.run_train_wandr(kinds=bad, folder="/nonexistent")


class _Replay:
    """A stand-in model whose decoder returns each clip's true next delta: its rollouts are the clips themselves."""

    def __init__(self, deltas):
        self.deltas, self.k = deltas, 0
        self.cfg = type("Cfg", (), {"latent": 2})()
        self.dtype = torch.float32 if deltas is None else deltas.dtype

    def eval(self):
        return self

    def condition(self, state, inten):
        return state

    def untrained_features(self, state):
        return []                                          # no training statistics: nothing to warn about

    def decode(self, z, cond):
        self.k += 1
        return self.deltas[:, self.k]


def test_evaluate_clips_times_goals_as_the_data_does(bm):
    from graspkit.data.wandr_dataset import list_clips, load_clips

    clips = load_clips(list_clips(DATA_STUBS / "motion", kinds=("reach",)), bm)
    L = int(clips.lengths.max()) + 40
    p = torch.stack([torch.cat([clips.clip(c), clips.clip(c)[-1:].expand(L - len(clips.clip(c)), -1)])
                     for c in range(len(clips))])
    r = E.evaluate_clips(_Replay(I.poses_to_deltas(p)), clips)      # replayed clips put the wrist on their goals
    assert r["clips"] == len(clips) and r["SR"] == 100.0 and r["error_at_goal"] < 2.0
    late = E.evaluate_clips(_Replay(I.poses_to_deltas(p[:, :1].expand(-1, L, -1))), clips)   # standing still: misses
    assert late["SR"] < 50 and late["DTG"] > 20
    with pytest.raises(ValueError, match="clips"):
        E.evaluate_clips(_Replay(None), load_clips(list_clips(DATA_STUBS / "motion", kinds=("locomotion",)), bm))


def test_validation_goals_lie_on_the_grids_cylinder_but_off_its_points():
    goals, cells = E.validation_goals()
    g, _ = E.grid_goals()
    assert goals.shape == (250, 3) and cells.shape == (250, 3)
    assert torch.allclose(goals[:, :2].norm(dim=1), torch.as_tensor(cells[:, 2], dtype=torch.float32), atol=1e-5)
    assert float(goals[:, 2].min()) >= 0.0 and float(goals[:, 2].max()) <= 1.8
    assert float(torch.cdist(goals, g).min()) > 0.01                 # none is a grid goal
    assert torch.equal(E.validation_goals()[0], goals)               # fixed by its seed


def test_select_val_keeps_the_best_epochs_weights_and_resumes(bm, tmp_path, monkeypatch):
    # the selection logic with a scripted validation score: epoch 2 is best; a second call (a resumed run) trains
    # nothing and gives the same weights
    from graspkit.data import wandr_dataset as W
    from graspkit.models import wandr as M
    from graspkit.paths import DATA_STUBS
    from graspkit.train import TrainConfig, load_checkpoint

    stubs = DATA_STUBS / "motion"
    clips = W.load_clips(W.list_clips(stubs, limit=3), bm)
    stats = W.compute_stats(clips, samples=500)
    tiny = dict(latent=4, hidden=32, enc_layers=1, dec_layers=2, dropout=0.0, max_steps=1, ramp_epochs=1)
    names = ["locomotion/locomotion_000000.npz", "reach/reach_000001.npz"]
    monkeypatch.setattr(W, "test_start_names", lambda folder, n=6, seed=0, split="test": names)
    script = iter([{"SR": 10.0, "FS": 1.0, "DTG": 30.0}, {"SR": 50.0, "FS": 1.0, "DTG": 20.0},
                   {"SR": 50.0, "FS": 1.0, "DTG": 25.0}])
    monkeypatch.setattr(E, "validation_score", lambda model, starts, bm: next(script))
    cfg = TrainConfig(epochs=3, batch_size=256, lr=1e-3, seed=0)
    kw = dict(stride={"locomotion": 8, "reach": 8}, progress=False)
    torch.manual_seed(0)
    model = M.WandrCVAE(M.WandrConfig(**tiny), stats)
    hist, val = E._train_selecting(model, clips, cfg, tmp_path / "ck.pt", kw["stride"], False, stubs, bm)
    assert len(hist) == 3 and val["best"] == 2 and [v["epoch"] for v in val["scores"]] == [1, 2, 3]
    torch.manual_seed(0)
    ref = M.WandrCVAE(M.WandrConfig(**tiny), stats)
    M.train_wandr(ref, clips, cfg, checkpoint=tmp_path / "ref.pt", stop_at=2, **kw)   # epoch 2 of the same run
    assert all(torch.equal(a, b) for a, b in zip(ref.state_dict().values(), model.state_dict().values()))
    assert load_checkpoint(tmp_path / "ck.pt")["epoch"] == 3                        # trained to the end
    torch.manual_seed(1)
    again = M.WandrCVAE(M.WandrConfig(**tiny), stats)
    hist2, val2 = E._train_selecting(again, clips, cfg, tmp_path / "ck.pt", kw["stride"], False, stubs, bm)
    assert val2 == val and len(hist2) == 3
    assert all(torch.equal(a, b) for a, b in zip(again.state_dict().values(), model.state_dict().values()))


def test_train_from_init_starts_from_its_weights_and_statistics(bm, tmp_path, monkeypatch):
    # at learning rate 0 a run from --init gives back the init's weights exactly (both float16 on disk); a fresh run
    # does not; a checkpoint of another network is refused by name
    from graspkit.data import wandr_dataset as W
    from graspkit.train import load_checkpoint, save_checkpoint

    names = ["locomotion/locomotion_000000.npz", "reach/reach_000001.npz"] * 3
    monkeypatch.setattr(W, "test_start_names", lambda folder, n=6, seed=0, split="test": names)
    monkeypatch.setenv("GRASPKIT_CACHE", str(tmp_path / "cache"))
    kw = dict(folder=str(DATA_STUBS / "motion"), epochs=1, threads=1, max_steps=1, ramp_epochs=1, progress=False)
    E.run_train_wandr(out=str(tmp_path / "a.pt"), lr=1e-3, **kw)
    E.run_train_wandr(out=str(tmp_path / "b.pt"), lr=0.0, init=str(tmp_path / "a.pt"), **kw)
    E.run_train_wandr(out=str(tmp_path / "c.pt"), lr=0.0, seed=1, **kw)
    a, b, c = (load_checkpoint(tmp_path / f"{x}.pt") for x in "abc")
    assert all(torch.equal(a["model"][k], b["model"][k]) for k in a["model"])
    assert not torch.equal(a["model"]["decoder.0.weight"], c["model"]["decoder.0.weight"])
    assert b["meta"]["init_command"] == a["meta"]["command"] and "--init" in b["meta"]["command"]
    assert [st["command"] for st in b["meta"]["stages"]] == [a["meta"]["command"], b["meta"]["command"]]
    assert b["meta"]["stages"][0]["history"] == a["history"] and b["meta"]["stages"][1]["history"] == b["history"]
    E.run_train_wandr(out=str(tmp_path / "b2.pt"), lr=0.0, init=str(tmp_path / "b.pt"), **kw)   # a third stage
    assert len(load_checkpoint(tmp_path / "b2.pt")["meta"]["stages"]) == 3
    old = dict(a, meta={k: v for k, v in a["meta"].items() if k != "stages"})      # a file from before the chain
    save_checkpoint(tmp_path / "old.pt", old)
    E.run_train_wandr(out=str(tmp_path / "b3.pt"), lr=0.0, init=str(tmp_path / "old.pt"), **kw)
    first = load_checkpoint(tmp_path / "b3.pt")["meta"]["stages"][0]
    assert first["command"] == a["meta"]["command"] and first["history"] == a["history"]
    with pytest.raises(ValueError, match="init: .* another network"):
        E.run_train_wandr("wandr_iw", out=str(tmp_path / "d.pt"), init=str(tmp_path / "a.pt"), **kw)


def test_full_mesh_fs_scores_a_body_that_is_not_upright(bm):
    """A body in the rest pose lying on its back (root rotation 0 in the z-up world) and turning 1° a frame about
    the pelvis's vertical: its lowest vertex (the buttock) barely moves, while a heel swings round; full_mesh=True
    follows the whole mesh, the default only the feet and hands."""
    from graspkit.rotations import axis_angle_to_matrix

    m, _, rest = _clip(bm)
    T = 40
    Rs = torch.eye(3).expand(T, I.NUM_BODY, 3, 3).clone()
    Rs[:, 0] = axis_angle_to_matrix(torch.stack([torch.zeros(T), torch.zeros(T), torch.arange(T) * np.pi / 180], 1))
    ts = torch.tensor([0.3, -0.2, 0.1]).expand(T, 3)
    q = I.pose_from_rotmats(ts, Rs)
    betas = torch.as_tensor(m.betas)[None]
    verts = bm.forward_rotmats(torch.cat([Rs, torch.eye(3).expand(T, 33, 3, 3)], 1), betas=betas,
                               transl=ts).vertices.numpy()
    low = verts[..., 2].argmin(1)                                                     # numpy: the lowest vertex's move
    move = np.linalg.norm(verts[np.arange(1, T), low[:-1], :2] - verts[np.arange(T - 1), low[:-1], :2], axis=1)
    truth = float((move > 0.0066).mean())
    assert not np.isin(low, E.LowVertices(bm, betas).ids.numpy()).any()               # neither a foot nor a hand
    full = E.evaluate_motions(q[None], rest[None], torch.zeros(1, 3), betas, bm, full_mesh=True)
    assert full.fs[0] == pytest.approx(truth, abs=1e-6) and truth < 0.5
    part = E.evaluate_motions(q[None], rest[None], torch.zeros(1, 3), betas, bm)
    assert part.fs[0] > truth + 0.5                               # the default follows a heel round the turn
    with pytest.raises(ValueError, match="T >= 2"):
        E.evaluate_motions(q[None, :1], rest[None], torch.zeros(1, 3), betas, bm)


def test_goal_row_schedules_space_their_goals_as_asked():
    g = E.goal_row_schedules(50, legs=3, seed=4)
    assert g.shape == (50, 3, 3) and torch.equal(g, E.goal_row_schedules(50, legs=3, seed=4))
    xy = np.concatenate([np.zeros((50, 1, 2)), g[:, :, :2].numpy()], 1)
    step = np.linalg.norm(np.diff(xy, axis=1), axis=-1)                    # start -> goal 1 -> goal 2 -> goal 3
    assert step.min() >= 0.8 - 1e-5 and step.max() <= 2.5 + 1e-5
    assert float(g[..., 2].min()) >= 0.3 and float(g[..., 2].max()) <= 1.6
    with pytest.raises(ValueError, match="legs"):
        E.goal_row_schedules(3, legs=0)


def test_goals_in_a_row_are_scored_in_their_own_windows():
    from graspkit.models.wandr import goal_schedule, load_wandr, rollout

    model = load_wandr(DATA_STUBS / "checkpoints" / "wandr.pt")
    starts = E.starts_from_meta(model.meta)[:2]
    r = E.evaluate_goal_rows(model, starts, per_start=3, legs=3, leg_frames=60, seed=5)
    assert r["rollouts"] == 6 and r["closest"].shape == (6, 3)
    # one of them again by hand: the same rollout (its own batch of one draws other z, so compare the batch's row 4
    # against a batch built the same way) and each goal's closest distance within its window
    goals = E.goal_row_schedules(6, 3, seed=5)
    g, tg = map(torch.stack, zip(*[goal_schedule(row, [60, 120, 180], 180) for row in goals]))
    st = [starts[0]] * 3 + [starts[1]] * 3
    with torch.no_grad():
        out = rollout(model, torch.stack([s.p_prev for s in st]), torch.stack([s.p for s in st]),
                      torch.stack([s.rest for s in st]), g, tg, 180, generator=torch.Generator().manual_seed(5))
    w = out.joints[4, :, I.WRIST].numpy()
    want = [np.linalg.norm(w[a:b + 1] - goals[4, k].numpy(), axis=1).min()
            for k, (a, b) in enumerate([(0, 60), (61, 120), (121, 180)])]
    assert np.allclose(r["closest"][4].numpy(), want, atol=1e-6)
    ok = r["closest"] <= 0.10
    assert r["SR_per_goal"] == pytest.approx((100 * ok.float().mean(0)).tolist())
    assert r["SR_all"] == pytest.approx(100 * float(ok.all(1).float().mean()))
    with pytest.raises(ValueError, match="starts"):
        E.evaluate_goal_rows(model, [], per_start=1)


def test_the_shipped_model_reaches_goals_one_after_another():
    # the shipped checkpoint's stage 4 trained on clips that start from a finished reach (docs/wandr.md, "Reaches in
    # a row"); the stage-3 model reached the third of three goals in about 10 % of such schedules
    from graspkit.models.wandr import load_wandr

    model = load_wandr(DATA_STUBS / "checkpoints" / "wandr.pt")
    r = E.evaluate_goal_rows(model, E.starts_from_meta(model.meta), per_start=10, seed=1)
    assert r["SR_per_goal"][2] >= 60.0 and r["SR_all"] >= 60.0


def test_evaluate_clips_reads_the_wrist_at_the_clips_own_goal_frame(bm):
    """A clip's goal frame g counts from its first frame (the rollout starts at frame 1): with the goal put on the
    replayed clip's wrist at frame g, the frame its wrist moves fastest, the error at t_G is 0 and the wrist at frame g + 1
    (a frame late) is centimetres away."""
    from graspkit.data.wandr_dataset import list_clips, load_clips

    clips = load_clips(list_clips(DATA_STUBS / "motion", kinds=("reach",)), bm)
    wrists = [I.body_joints(clips.clip(c), clips.rest[c])[:, I.WRIST] for c in range(len(clips))]
    speed = [(w[1:] - w[:-1]).norm(dim=-1) for w in wrists]                # speed[k]: frame k -> k + 1
    g = torch.tensor([2 + int(s[2:len(s) - 1].argmax()) for s in speed])   # the fastest wrist frame of each clip
    goal = torch.stack([w[k] for w, k in zip(wrists, g.tolist())])
    late = torch.stack([s[k] for s, k in zip(speed, g.tolist())])
    assert float(late.min()) > 0.005                                   # the wrist moves > 5 mm from g to g + 1
    cs = dataclasses.replace(clips, goal=goal, goal_frame=g)
    L = int(cs.lengths.max()) + 40
    p = torch.stack([torch.cat([cs.clip(c), cs.clip(c)[-1:].expand(L - len(cs.clip(c)), -1)]) for c in range(len(cs))])
    r = E.evaluate_clips(_Replay(I.poses_to_deltas(p)), cs)
    assert r["error_at_goal"] == pytest.approx(0.0, abs=0.05)         # cm
    assert r["SR"] == 100.0 and r["DTG"] == pytest.approx(0.0, abs=0.05)


def test_a_foot_within_5_cm_of_the_floor_is_on_it(bm):
    """SAGA's 5 cm heel height is the floor contact (FOOT_ON_FLOOR): a clip lifted 3 cm (its lowest vertex 2-4 cm up,
    full meshes) never floats and its reach is a grounded success; lifted 8 cm it floats on every lifted frame."""
    m = load_motion(DATA_STUBS / "motion" / "reach" / "reach_000002.npz")
    p = I.pose_from_axis_angle(torch.as_tensor(m.trans), torch.as_tensor(m.poses))
    rest = rest_joints(bm, m.betas[None])[0]
    low = m.vertices(bm)[..., 2].min(-1).values
    assert float(low.abs().max()) < 0.01                               # the clip as made stands on the floor
    up3, up8 = p.clone(), p.clone()
    up3[:, 2] += 0.03
    up8[:, 2] += 0.08
    assert float((low + 0.03).max()) < 0.05 and float((low + 0.08).min()) > 0.05
    goal = torch.stack([I.body_joints(q, rest)[40, I.WRIST] for q in (up3, up8)])
    res = E.evaluate_motions(torch.stack([up3, up8]), rest[None].expand(2, -1, -1), goal,
                             torch.as_tensor(m.betas)[None].expand(2, -1), bm, t_goal=40)
    assert res.success.tolist() == [True, True]
    assert res.floating.tolist() == pytest.approx([0.0, 1.0])
    assert res.grounded.tolist() == [True, False]


def test_corrective_bound_is_attained_by_a_half_turn():
    """Pose features are entries of R - I, which reach -2 on the diagonal of a half turn: correctives aligned with
    those entries give |delta_v| = 2 sum |pd| exactly, so the bound must be (at least) that."""
    V, c = 3, 0.3
    weights = torch.zeros(V, 55)
    weights[:, 0] = 1.0
    posedirs = torch.zeros(486, 3, V)
    posedirs[0, 0], posedirs[4, 0] = -c, -c           # joint 1's (0,0) and (1,1) entries push along -x ... 
    v, J = torch.randn(1, V, 3, generator=torch.Generator().manual_seed(0)), torch.zeros(1, 55, 3)
    s = E.Skinned(weights, torch.arange(V), v, J, posedirs, torch.zeros(1, 486))
    R = torch.eye(3).repeat(21, 1, 1)
    R[0] = torch.diag(torch.tensor([-1.0, -1.0, 1.0]))   # joint 1 turned by pi about z: R - I = diag(-2, -2, 0)
    feature = (R - torch.eye(3)).reshape(1, 189)
    d = s.delta(feature)[0]                             # (V, 3): ... so a half turn moves them by 4c along +x
    torch.testing.assert_close(d, torch.tensor([4 * c, 0.0, 0.0]).expand(V, 3))
    assert (d.norm(dim=-1) <= s.bound + 1e-6).all()
    # and no rotation exceeds it (random rotations of every body joint)
    from graspkit.rotations import axis_angle_to_matrix
    g = torch.Generator().manual_seed(1)
    for _ in range(20):
        Rr = axis_angle_to_matrix(torch.randn(21, 3, generator=g, dtype=torch.float64) * 2).float()
        f = (Rr - torch.eye(3)).reshape(1, 189)
        assert (s.delta(f)[0].norm(dim=-1) <= s.bound + 1e-6).all()


def test_hand_reach_is_the_docstrings_bound():
    """reach = max_v sum_k w_vk (|x_v - J_k| + tree path from joint k to the wrist), on a model whose hand vertices
    are skinned to joints all over the tree (the path is computed here by scipy on the bone-length tree)."""
    arr = random_smplx_arrays(seed=3)
    w = np.abs(np.asarray(arr["weights"], np.float64))
    w[:, 22:25] = 0.0                                   # LowVertices refuses feet or hands skinned to jaw or eyes
    w = np.where(w < np.quantile(w, 0.8, axis=1, keepdims=True), 0.0, w)      # sparse-ish, many joints per vertex
    part = np.argmax(arr["weights"], 1)
    w[np.arange(len(w)), part] += 1.0                  # each vertex still dominated by its part
    w[:, 22:25] = 0.0
    arr = {**arr, "weights": w / w.sum(1, keepdims=True), "posedirs": np.zeros_like(arr["posedirs"])}
    bm = BodyModel(arr, dtype=torch.float64)
    betas = torch.zeros(1, 10, dtype=torch.float64)
    low = E.LowVertices(bm, betas)
    v, J = bm.shaped(torch.zeros(1, bm.num_betas + bm.num_expression, dtype=torch.float64))
    v, J = v[0].numpy(), J[0].numpy()
    par = bm.parents.numpy()
    bone = np.linalg.norm(J[1:] - J[par[1:]], axis=1)
    tree = csr_matrix((bone, (np.arange(1, 55), par[1:])), shape=(55, 55))
    dist = shortest_path(tree, directed=False)
    for hand, wrist, reach in zip(low.hands, E.WRISTS, low.reach):
        ids = hand.ids.numpy()
        W = arr["weights"][ids]
        r = (W * (np.linalg.norm(v[ids, None] - J[None], axis=-1) + dist[None, :, wrist])).sum(1)
        np.testing.assert_allclose(float(reach[0]), r.max(), rtol=1e-5)


def test_where_the_previous_lowest_vertex_is_now_at_the_foot_hand_boundary(bm):
    """`lowest(previous=...)` returns where the given vertices are now: the last foot vertex, the first vertex of
    each hand (indices at the offsets' boundaries) and a random one, against the body model's full mesh."""
    low, Rg, pos, body, full = _reach_frames(bm)
    o = low.offsets
    prev = torch.tensor([o[1] - 1, o[1], o[2] - 1, o[2], o[3] - 1, 0] * 5)
    _, _, _, was = low.lowest(Rg, pos, body, prev)
    torch.testing.assert_close(was, full[torch.arange(30), low.ids[prev]], atol=1e-5, rtol=0)


def test_full_mesh_fs_is_the_share_of_frame_pairs_whose_lowest_vertex_slides(bm):
    """A body lying on its back that slides 1 cm along x on every other frame: the lowest vertex of the whole mesh
    moves > 0.66 cm in about half the frame pairs; full_mesh=True's FS is that share (numpy on the posed vertices)."""
    m = load_motion(DATA_STUBS / "motion" / "locomotion/locomotion_000003.npz")
    rest = rest_joints(bm, m.betas[None])[0]
    T = 21
    Rs = torch.eye(3).expand(T, I.NUM_BODY, 3, 3).clone()
    x = 0.01 * torch.tensor([(k + 1) // 2 for k in range(T)], dtype=torch.float32)     # +1 cm at every odd frame
    ts = torch.stack([0.3 + x, torch.full((T,), -0.2), torch.full((T,), 0.1)], 1)
    q = I.pose_from_rotmats(ts, Rs)
    betas = torch.as_tensor(m.betas)[None]
    verts = bm.forward_rotmats(torch.cat([Rs, torch.eye(3).expand(T, 33, 3, 3)], 1), betas=betas,
                               transl=ts).vertices.numpy()
    low = verts[..., 2].argmin(1)
    move = np.linalg.norm(verts[np.arange(1, T), low[:-1], :2] - verts[np.arange(T - 1), low[:-1], :2], axis=1)
    truth = float((move > 0.0066).mean())
    assert 0.4 < truth < 0.6
    full = E.evaluate_motions(q[None], rest[None], torch.zeros(1, 3), betas, bm, full_mesh=True)
    assert full.fs[0] == pytest.approx(truth, abs=1e-6)


def test_evaluate_clips_window_includes_its_last_frame(bm):
    """after_s=0: the window ends at the clip's goal frame g itself; with the goal put on the replayed wrist at g (a
    frame it moves into fast), SR is 100 % and DTG 0 cm: frame g is in the window."""
    clips = load_clips(list_clips(DATA_STUBS / "motion", kinds=("reach",)), bm)
    wrists = [I.body_joints(clips.clip(c), clips.rest[c])[:, I.WRIST] for c in range(len(clips))]
    speed = [(w[1:] - w[:-1]).norm(dim=-1) for w in wrists]                # speed[k]: frame k -> k + 1
    g = torch.tensor([2 + int(s[1:len(s) - 1].argmax()) for s in speed])   # the wrist moves fast from g - 1 into g
    assert float(torch.stack([s[k - 1] for s, k in zip(speed, g.tolist())]).min()) > 0.005
    goal = torch.stack([w[k] for w, k in zip(wrists, g.tolist())])
    cs = dataclasses.replace(clips, goal=goal, goal_frame=g)
    L = int(cs.lengths.max()) + 40
    p = torch.stack([torch.cat([cs.clip(c), cs.clip(c)[-1:].expand(L - len(cs.clip(c)), -1)]) for c in range(len(cs))])
    r = E.evaluate_clips(_Replay(I.poses_to_deltas(p)), cs, after_s=0.0)
    assert r["SR"] == 100.0 and r["DTG"] == pytest.approx(0.0, abs=0.05)


def test_summary_dtg_median_is_the_median():
    """summary's DTG_median (cm) is the median of the closest distances: 5, 9, 20, 50 cm and 4 m give 20 cm (the
    mean would be 96.8 cm)."""
    d = np.array([0.05, 0.09, 0.2, 0.5, 4.0])
    n = len(d)
    r = E.GridResult(np.zeros(n, int), np.arange(n), np.zeros(n, int), np.zeros((n, 3)), d, np.full(n, -1),
                     np.zeros(n), np.full(n, 0.3))
    s = E.summary(r)
    assert s["DTG_median"] == pytest.approx(100 * np.median(d)) and s["DTG"] == pytest.approx(96.8)


def _tiny(dropout=0.0):
    from graspkit.models.wandr import WandrConfig, WandrCVAE

    torch.manual_seed(0)
    return WandrCVAE(WandrConfig(latent=4, hidden=32, enc_layers=1, dec_layers=1, dropout=dropout))


def test_validation_goals_cover_the_whole_cylinder_with_their_angles_in_degrees():
    """250 uniform goals: each row's angle (deg) is the goal's counter-clockwise direction atan2(y, x), every quarter
    of the circle holds about a quarter of them, and the heights and distances fill 0-1.8 m and 0.5-5 m."""
    goals, cells = E.validation_goals()
    g = goals.double().numpy()
    ang = np.degrees(np.arctan2(g[:, 1], g[:, 0])) % 360
    diff = (cells[:, 0] - ang + 180) % 360 - 180
    assert np.abs(diff).max() < 1e-3
    quarter = np.bincount((ang // 90).astype(int), minlength=4)
    assert quarter.min() > 40                                          # 62.5 expected per quarter
    assert np.allclose(cells[:, 1], g[:, 2], atol=1e-6)
    assert cells[:, 1].max() > 1.6 and cells[:, 1].min() < 0.2
    assert cells[:, 2].max() > 4.6 and cells[:, 2].min() < 0.9


def test_goal_row_schedules_step_in_every_direction():
    """Each leg's direction is uniform on the circle: of 150 legs every quarter gets a fair share."""
    g = E.goal_row_schedules(50, legs=3, seed=4).double().numpy()
    xy = np.concatenate([np.zeros((50, 1, 2)), g[:, :, :2]], 1)
    step = np.diff(xy, axis=1).reshape(-1, 2)
    ang = np.degrees(np.arctan2(step[:, 1], step[:, 0])) % 360
    assert np.bincount((ang // 90).astype(int), minlength=4).min() > 20      # 37.5 expected per quarter


def test_breakdown_by_distance_groups_by_the_distance_column():
    """SR per distance on a hand-made result: the rows at 0.5 m reach 2 of 2, at 5 m 1 of 3, whatever their height."""
    cells = np.array([[0, 0.0, 0.5], [72, 1.8, 0.5], [0, 0.0, 5.0], [144, 0.45, 5.0], [0, 1.8, 5.0]])
    n = len(cells)
    r = E.GridResult(np.zeros(n, int), np.arange(n), np.zeros(n, int), cells, np.array([0.05, 0.02, 0.5, 0.08, 0.3]),
                     np.array([3, 1, -1, 9, -1]), np.zeros(n), np.full(n, 0.3))
    assert E.breakdown(r, "distance") == pytest.approx({0.5: 100.0, 5.0: 100 / 3})
    assert E.breakdown(r, "height") == pytest.approx({0.0: 50.0, 0.45: 100.0, 1.8: 50.0})


def test_variants_match_their_tables_rows_and_the_papers_figures():
    """Tab. 1/2 (WANDR paper): each variant's row names the intention parts it keeps (I^w wrist, I^p pelvis, I^r
    orientation; full intention otherwise, none for VAE + opt) and the data it learns from; PAPER holds the paper's
    SR / FS / DTG of each row."""
    parts = {"I^w": "wrist", "I^p": "pelvis", "I^r": "orientation"}
    for name, v in E.VARIANTS.items():
        row = v["row"]
        named = {p for tag, p in parts.items() if tag in row}
        want = set() if row == "VAE + opt" else named or {"wrist", "pelvis", "orientation"}
        assert set(v["intention"]) == want, name
        kinds = ("locomotion",) if "AMASS" in row else ("reach",) if "Circle" in row else ("locomotion", "reach")
        assert tuple(v["kinds"]) == kinds, name
        assert row in E.PAPER
    paper = {"WANDR / reaching only (Circle)": (0, 56, 205.4), "WANDR / locomotion only (AMASS)": (16, 19, 48.0),
             "WANDR": (32, 16, 24.8), "GOAL": (0, 29, 149.2), "WANDR (I^w)": (15, 13, 62.9),
             "WANDR (I^w + I^p)": (18, 17, 44.9), "WANDR (I^w + I^r)": (19, 19, 36.0), "VAE + opt": (3, 4, 217.0)}
    assert E.PAPER == paper


def test_table_puts_the_papers_figures_beside_a_variants_row_with_graspkits_suffixes():
    """A row named by `--kinds` ("[reach clips]") or by the floor / lift constraints gets its variant's paper figures
    and says which paper row they are; a row the paper does not have gets dashes."""
    s = {"SR": 99.5, "FS": 6.5, "DTG": 2.2}
    lines = {ln.split(" | ")[0]: ln for ln in E.table({"WANDR [reach clips]": s, "WANDR (I^w + I^p) [reach clips] + lift "
                                                        "(not the paper's)": s, "WANDR": s, "mine": s}).splitlines()}
    assert lines["| WANDR [reach clips] (paper: WANDR)"].endswith("| 32 | 16 | 24.8 |")
    assert lines["| WANDR (I^w + I^p) [reach clips] + lift (not the paper's) (paper: WANDR (I^w + I^p))"].endswith(
        "| 18 | 17 | 44.9 |")
    assert lines["| WANDR"].endswith("| 32 | 16 | 24.8 |")
    assert lines["| mine"].endswith("| — | — | — |")


def test_start_poses_round_trip_through_a_checkpoints_meta(bm):
    """starts_to_meta then starts_from_meta gives the same start poses back (p_prev before p); a meta without them
    is refused by name."""
    names = ["reach/reach_000001.npz", "locomotion/locomotion_000003.npz"]
    starts = held_out_starts([load_motion(DATA_STUBS / "motion" / n) for n in names], names, bm, n=2)
    back = E.starts_from_meta({"starts": E.starts_to_meta(starts)})
    assert len(back) == 2
    for a, b in zip(starts, back):
        for k in ("p_prev", "p", "rest", "betas", "full_pose"):
            assert torch.equal(getattr(a, k), getattr(b, k)), k
        assert a.source == b.source
    assert not torch.equal(starts[0].p_prev, starts[0].p)
    with pytest.raises(ValueError, match="no held-out start poses"):
        E.starts_from_meta({})


def test_goal_reacher_reads_the_error_at_its_goal_frame_and_the_time_of_the_closest_frame(bm):
    """The readout's error at t_G is the wrist's distance at frame t_G of the same motion (generate, same seed), and
    closest_s the closest frame's time at 30 fps (frame 0 at 0 s)."""
    from graspkit.models.wandr import generate

    start = held_out_starts([load_motion(DATA_STUBS / "motion" / "reach" / "reach_000001.npz")], ["r1"], bm, n=1)[0]
    model = _tiny().eval()
    r = E.GoalReacher(model, start, seed=2, angle=30.0, distance=0.6, height=1.2, seconds=1.5)
    out = r.run()
    ref = generate(model, start, r.goal[None], 45, generator=torch.Generator().manual_seed(2))
    d = (ref.joints[0, :, I.WRIST] - r.goal).norm(dim=-1)
    assert len(d) == 46
    assert out["error_at_goal_cm"] == pytest.approx(100 * float(d[45]), abs=1e-4)
    k = int(d.argmin())
    assert out["closest_s"] == pytest.approx(k / 30.0) and out["closest_frame"] == k
    assert float((d[45] - d[44]).abs()) > 1e-4                         # the two frames differ


def _posed_bodies(bm, frames=(30, 45, 60, 75)):
    """Frames of a reach clip, each on a body of its own shape (random betas) with its own finger pose: LowVertices,
    body transforms, body index and the body model's full meshes."""
    m, p, _ = _clip(bm, "reach/reach_000002.npz")
    n = len(frames)
    betas = torch.as_tensor(np.random.default_rng(5).normal(0, 2.0, (n, 10)), dtype=torch.float32)
    rest = rest_joints(bm, betas)
    q = p[list(frames)]
    hands = torch.as_tensor(m.poses[list(frames)], dtype=torch.float32)
    low = E.LowVertices(bm, betas, hands)
    Rg, pos = I.body_transforms(q, rest)
    rot = torch.cat([I.pose_rotmats(q)[1], axis_angle_to_matrix(hands[:, 22:].double()).float()], 1)
    full = torch.cat([bm.forward_rotmats(rot[b:b + 1], betas=betas[b:b + 1], transl=q[b:b + 1, :3]).vertices
                      for b in range(n)])
    return low, Rg, pos, torch.arange(n), full, rest


def test_feet_and_hands_of_bodies_of_different_shapes_are_each_bodys_own(bm):
    """Several bodies of different betas in one batch: every foot and hand vertex (points and heights) and the hand
    reach bound match each body's own full mesh (the body model), not the first body's."""
    low, Rg, pos, body, full, rest = _posed_bodies(bm)
    assert float((rest[1:] - rest[:1]).abs().max()) > 0.02            # the shapes differ by centimetres
    torch.testing.assert_close(low.feet.points(Rg, pos, body), full[:, low.feet.ids], atol=1e-5, rtol=0)
    torch.testing.assert_close(low.feet.heights(Rg, pos, body), full[:, low.feet.ids, 2], atol=1e-5, rtol=0)
    RgF, posF = low.with_fingers(Rg, pos, body)
    for hand, wrist, reach in zip(low.hands, E.WRISTS, low.reach):
        torch.testing.assert_close(hand.points(RgF, posF, body), full[:, hand.ids], atol=1e-5, rtol=0)
        torch.testing.assert_close(hand.heights(RgF, posF, body), full[:, hand.ids, 2], atol=1e-5, rtol=0)
        assert ((full[:, hand.ids] - pos[:, None, wrist]).norm(dim=-1).amax(1) <= reach).all()
    lowest, at, foot_low, _ = low.lowest(Rg, pos, body)
    truth = full[:, low.ids, 2].min(1)
    torch.testing.assert_close(at[:, 2], truth.values, atol=1e-5, rtol=0)
    torch.testing.assert_close(foot_low, full[:, low.feet.ids, 2].amin(1), atol=1e-5, rtol=0)


def test_an_upside_down_body_with_a_hand_below_the_floor_has_its_feet_in_the_air(bm):
    """A body turned upside down (a half turn about x), a hand 5 cm under the floor: the lowest vertex searched is
    that hand's, but the lowest foot vertex (full mesh: > 50 cm up) decides floating and sunk: it floats on every
    frame and never sinks."""
    m, p, rest = _clip(bm, "reach/reach_000002.npz")
    betas = torch.as_tensor(m.betas)[None]
    T = 4
    Rs = torch.eye(3).expand(T, I.NUM_BODY, 3, 3).clone()
    Rs[:, 0] = torch.diag(torch.tensor([1.0, -1.0, -1.0])) @ I.pose_rotmats(p[:1])[1][0, 0]   # standing, turned
    fingers = torch.eye(3).expand(T, 33, 3, 3)
    v0 = bm.forward_rotmats(torch.cat([Rs[:1], fingers[:1]], 1), betas=betas, transl=torch.zeros(1, 3)).vertices[0]
    part = bm.lbs_weights.argmax(1)
    feet = torch.isin(part, torch.tensor(list(FOOT_JOINTS)))
    hands = torch.isin(part, torch.tensor([20, 21] + list(range(25, 55))))
    ts = torch.tensor([0.0, 0.0, -0.05 - float(v0[hands, 2].min())]).expand(T, 3)
    v = bm.forward_rotmats(torch.cat([Rs, fingers], 1), betas=betas, transl=ts).vertices
    assert float(v[:, feet, 2].min()) > 0.5 and float(v[:, hands, 2].min()) == pytest.approx(-0.05, abs=1e-5)
    q = I.pose_from_rotmats(ts, Rs)
    res = E.evaluate_motions(q[None], rest[None], torch.zeros(1, 3), betas, bm)
    assert res.floating[0] == 1.0 and res.sunk[0] == 0.0


def test_evaluate_grid_scores_the_motions_it_generates(bm):
    """evaluate_grid on 2 starts x 3 goals x 2 samples (t_G = 6, 9 frames) of a tiny model left in training mode with
    dropout: start-major rows, each goal's own cell, and SR / DTG / error at t_G / FS equal those measured on the
    same motions from `generate` (same seed; wrist distances, and FS on the body model's full meshes)."""
    from graspkit.models.wandr import generate

    names = ["reach/reach_000001.npz", "locomotion/locomotion_000003.npz"]
    starts = held_out_starts([load_motion(DATA_STUBS / "motion" / n) for n in names], names, bm, n=2)
    gg, cc = E.grid_goals()
    pick = [7, 61, 118]
    goals, cells = gg[pick], cc[pick]
    model = _tiny(dropout=0.5).train()
    res = E.evaluate_grid(model, starts, bm, n=2, seed=3, goals=goals, cells=cells, t_goal=6, frames=9)
    assert model.training                            # the caller's mode comes back
    assert res.start.tolist() == [0] * 6 + [1] * 6
    assert res.goal_index.tolist() == [0, 0, 1, 1, 2, 2] * 2 and res.sample.tolist() == [0, 1] * 6
    assert np.array_equal(res.cell, cells[res.goal_index])
    out = generate(model.eval(), starts, goals, 6, n=2, generator=torch.Generator().manual_seed(3), frames=9)
    assert out.joints.shape[1] == 10
    d = (out.joints[:, :, I.WRIST] - out.goal[:, :1]).norm(dim=-1).double().numpy()
    assert np.allclose(res.dtg, d.min(1), atol=1e-6) and np.allclose(res.error_at_goal, d[:, 6], atol=1e-6)
    first = np.array([int(np.flatnonzero(r <= 0.1)[0]) if (r <= 0.1).any() else -1 for r in d])
    assert np.array_equal(res.reach_frame, first)
    fs = [metrics.foot_skating_wandr(E.body_vertices(bm, out.p[b], starts[int(res.start[b])])).mean()
          for b in range(12)]
    assert np.allclose(res.fs, fs, atol=1e-6)
    assert not np.allclose(res.dtg, E.evaluate_grid(model, starts, bm, n=2, seed=4, goals=goals, cells=cells,
                                                     t_goal=6, frames=9).dtg)   # another seed, other motions
    short = E.evaluate_grid(model, starts[:1], bm, n=2, seed=3, goals=goals[:1], cells=cells[:1], t_goal=8, frames=4)
    out = generate(model, starts[:1], goals[:1], 8, n=2, generator=torch.Generator().manual_seed(3), frames=4)
    d = (out.joints[:, :, I.WRIST] - goals[:1]).norm(dim=-1).double().numpy()
    assert d.shape == (2, 5) and np.allclose(short.dtg, d.min(1), atol=1e-6)
    assert np.isnan(short.error_at_goal).all()                         # the motions end before t_G


def test_validation_score_is_one_rollout_per_start_and_goal_and_keeps_the_training_mode(bm, monkeypatch):
    """validation_score: SR / DTG of one 8 s rollout per start and validation goal (as measured on `generate`'s
    motions, same seed), and a model in training mode comes back in it (training goes on after the score)."""
    from graspkit.models.wandr import generate

    goals = torch.stack([E.goal_from_cylinder(40.0, 1.0, 0.9), E.goal_from_cylinder(200.0, 2.0, 0.3)])
    monkeypatch.setattr(E, "validation_goals", lambda: (goals, np.array([[40.0, 0.9, 1.0], [200.0, 0.3, 2.0]])))
    start = held_out_starts([load_motion(DATA_STUBS / "motion" / "reach" / "reach_000001.npz")], ["r1"], bm, n=1)
    model = _tiny().train()
    s = E.validation_score(model, start, bm, seed=2)
    assert model.training
    out = generate(model, start, goals, E.T_GOAL, n=1, generator=torch.Generator().manual_seed(2))
    d = (out.joints[:, :, I.WRIST] - out.goal[:, :1]).norm(dim=-1).min(1).values
    assert out.joints.shape[:2] == (2, 240)
    assert s["DTG"] == pytest.approx(100 * float(d.mean()), abs=1e-4)
    assert s["SR"] == pytest.approx(100 * float((d <= 0.1).float().mean()))


def test_goals_in_a_row_count_each_goal_in_its_own_window_only(bm):
    """A replayed motion that teleports its wrist: rollout 0 puts it on goal 2 at goal 1's frame only (before goal 2's
    window), rollout 1 on each goal exactly at that goal's own frame. Goal 2 of rollout 0 is missed (closest: the
    far frames), every goal of rollout 1 is reached at distance 0; closest_cm is the closest distance in cm."""
    L, legs = 8, 3
    start = held_out_starts([load_motion(DATA_STUBS / "motion" / "reach" / "reach_000001.npz")], ["r1"], bm, n=1)[0]
    goals = E.goal_row_schedules(2, legs, seed=7)                     # the schedules evaluate_goal_rows draws
    T = legs * L + 1
    wrist0 = I.body_joints(start.p[None], start.rest)[0, I.WRIST]
    far = torch.tensor([0.0, 0.0, 3.0]) + 0.01 * torch.arange(T)[:, None]    # 3 m up: far from every goal
    want = far[None].repeat(2, 1, 1)
    want[:, 0] = wrist0                                                # frame 0: the start itself
    want[0, L] = goals[0, 1]
    for k in range(legs):
        want[1, (k + 1) * L] = goals[1, k]
    p = start.p.expand(2, T + 1, -1).clone()
    p[:, 0] = start.p_prev
    p[:, 1:, :3] += want - wrist0                                      # move the body so the wrist is where wanted
    wr = I.body_joints(p[:, 1:].reshape(-1, I.POSE_DIM), start.rest.expand(2 * T, -1, -1)).reshape(2, T, 22, 3)
    torch.testing.assert_close(wr[:, :, I.WRIST], want, atol=1e-5, rtol=0)
    r = E.evaluate_goal_rows(_Replay(I.poses_to_deltas(p)), [start], per_start=2, legs=legs, leg_frames=L, seed=7)
    w = want.double().numpy()
    truth = np.array([[np.linalg.norm(w[b, lo:hi + 1] - goals[b, k].double().numpy(), axis=1).min()
                       for k, (lo, hi) in enumerate([(0, L), (L + 1, 2 * L), (2 * L + 1, 3 * L)])] for b in range(2)])
    assert truth[0, 1] > 1.0 and np.allclose(truth[1], 0.0, atol=1e-5)
    assert np.allclose(r["closest"].double().numpy(), truth, atol=1e-4)
    assert r["SR_per_goal"] == pytest.approx((100 * (truth <= 0.1).mean(0)).tolist())
    assert r["closest_cm"] == pytest.approx((100 * truth.mean(0)).tolist(), abs=1e-2)


def test_evaluate_clips_counts_a_late_arrival_within_after_s_and_reports_centimetres(bm):
    """Replayed reaching clips whose goal frame g is set 15 frames (0.5 s) before the wrist arrives on the goal: with
    after_s=1 the window holds that frame (SR 100 %, DTG 0); with after_s=0.2 (6 frames) the DTG is the mean over clips
    of the closest wrist distance in clip frames 1..g+6 (cm), and the error at t_G is the wrist's distance at g (cm)."""
    clips = load_clips(list_clips(DATA_STUBS / "motion", kinds=("reach",)), bm)
    wrists = [I.body_joints(clips.clip(c), clips.rest[c])[:, I.WRIST] for c in range(len(clips))]
    g = clips.goal_frame - 15                                          # the wrist arrives 15 frames after g
    goal = torch.stack([w[k + 15] for w, k in zip(wrists, g.tolist())])
    cs = dataclasses.replace(clips, goal=goal, goal_frame=g)
    L = int(cs.lengths.max()) + 40
    p = torch.stack([torch.cat([cs.clip(c), cs.clip(c)[-1:].expand(L - len(cs.clip(c)), -1)]) for c in range(len(cs))])
    on = E.evaluate_clips(_Replay(I.poses_to_deltas(p)), cs, after_s=1.0)
    assert on["SR"] == 100.0 and on["DTG"] == pytest.approx(0.0, abs=0.01)
    short = E.evaluate_clips(_Replay(I.poses_to_deltas(p)), cs, after_s=0.2)
    dmin = np.array([float((w[1:k + 7] - gl).norm(dim=-1).min()) for w, k, gl in zip(wrists, g.tolist(), goal)])
    err = np.array([float((w[k] - gl).norm()) for w, k, gl in zip(wrists, g.tolist(), goal)])
    assert dmin.max() > 0.02 and abs(np.mean(dmin) - np.median(dmin)) > 0.005
    assert short["DTG"] == pytest.approx(100 * dmin.mean(), abs=0.01)
    assert short["error_at_goal"] == pytest.approx(100 * err.mean(), abs=0.01) and err.mean() > 0.02


def test_vae_opt_cells_are_their_goals_whatever_the_chunk_and_samples(bm, monkeypatch):
    """evaluate_vae_opt's rows carry their own goal's grid cell (Fig. 5 groups by it) and the goals per optimisation
    batch (`chunk`) change nothing: chunk 50 crashed on its second chunk, and n = 2 gave 248 of 250 rows another
    goal's cell (here chunk 5 on a 12-goal grid; iters = 0: the decoded random draws, scored as they are)."""
    from graspkit.optim.latent import evaluate_vae_opt

    goals, cells = E.grid_goals()
    sub = torch.arange(0, 125, 11)                            # 12 goals of the grid, to keep it short
    monkeypatch.setattr(E, "grid_goals", lambda: (goals[sub], cells[sub.numpy()]))
    start = held_out_starts([load_motion(DATA_STUBS / "motion" / "reach" / "reach_000001.npz")], ["r1"], bm, n=1)
    model = _tiny()
    whole = evaluate_vae_opt(model, start, bm, n_starts=1, iters=0)
    for chunk, n in ((5, 1), (12, 2)):
        res = evaluate_vae_opt(model, start, bm, n_starts=1, iters=0, chunk=chunk, n=n)
        assert len(res.dtg) == 12 * n
        np.testing.assert_array_equal(res.cell, cells[sub.numpy()][res.goal_index])
    res = evaluate_vae_opt(model, start, bm, n_starts=1, iters=0, chunk=5)
    np.testing.assert_array_equal(res.goal_index, whole.goal_index)
    assert np.isfinite(res.dtg).all() and (res.dtg > 0).all()


def test_goal_reacher_refuses_start_values_outside_its_sliders(bm):
    """The constructor's values obey the sliders' ranges, as update() does: seconds 0 used to run a 1-frame goal, a
    negative distance put the goal behind, NaN failed as 'cannot convert float NaN to integer'."""
    for kw in (dict(seconds=0.0), dict(seconds=-3.0), dict(seconds=float("nan")), dict(distance=-2.0),
               dict(height=5.0), dict(angle=float("nan")), dict(seconds=True)):
        name = next(iter(kw))
        with pytest.raises(ValueError, match=f"{name}: expected a (value|number) in"):
            E.GoalReacher(None, None, **kw)
    from graspkit.data.wandr_dataset import held_out_starts

    start = held_out_starts([load_motion(DATA_STUBS / "motion" / "reach" / "reach_000001.npz")], ["r"], bm, n=1)[0]
    r = E.GoalReacher(None, start, angle=360.0, distance=0.3, height=0.0, seconds=8.0)      # the ends are fine
    assert r.t_goal == 240


def test_goal_rows_name_a_bad_schedule():
    """spacing (2.5, 0.8) failed in numpy ('high - low < 0'), a NaN height overflowed, per_start 0 was blamed on `n`
    and a fractional leg length failed in torch.empty."""
    for kw, name in ((dict(spacing=(2.5, 0.8)), "spacing"), (dict(spacing=(-1.0, -0.5)), "spacing"),
                     (dict(heights=(float("nan"), 1.0)), "heights"), (dict(legs=0), "legs")):
        with pytest.raises(ValueError, match=f"{name}: expected"):
            E.goal_row_schedules(2, **kw)
    start = [object()]
    for kw, name in ((dict(per_start=0), "per_start"), (dict(leg_frames=2.5), "leg_frames"),
                     (dict(leg_frames=1), "leg_frames")):
        with pytest.raises(ValueError, match=f"{name}: expected an integer"):
            E.evaluate_goal_rows(None, start, **kw)


def test_eval_wandr_keeps_a_row_per_checkpoint_of_one_variant(tmp_path, monkeypatch, capsys):
    """Two checkpoints of one variant (two seeds) shared the row name their meta gives: the table kept the last one's
    figures alone. Each gets its row; the second ('#2') still stands beside the paper's figures for the variant."""
    import graspkit.eval_wandr as EW
    from graspkit.cli import main

    sr = iter([99.5, 4.9])

    def fake(ck, *a, **k):
        s = {"SR": next(sr), "FS": 50.0, "DTG": 60.0, "rollouts": 10}
        return {"row": "WANDR [reach clips]", "summary": s, "breakdown": {}, "seconds": 1.0}
    monkeypatch.setattr(EW, "run_eval_wandr", fake)
    cks = []
    for name in ("a.pt", "b.pt"):
        (tmp_path / name).write_bytes(b"x")
        cks += ["--checkpoint", str(tmp_path / name)]
    assert main(["eval", "wandr", *cks, "--clips", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    table = out[out.index("|"):]
    assert "99.5" in table and "4.9" in table and "WANDR [reach clips] #2" in table
    assert EW.paper_row("WANDR [reach clips] #2") == EW.paper_row("WANDR [reach clips]") == "WANDR"
