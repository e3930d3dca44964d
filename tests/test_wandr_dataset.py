"""WANDR's dataset (§3.2, §4.1, Sup. B.2) on the shipped sample clips: windows, real and hindsight goals, filter, splits."""
from dataclasses import replace

import numpy as np
import pytest
import torch

from graspkit import intention as I
from graspkit.data import heading_of, load_motion
from graspkit.data import wandr_dataset as W
from graspkit.paths import DATA_STUBS

from conftest import PROCEDURAL_MODEL

STUBS = DATA_STUBS / "motion"


@pytest.fixture(scope="module")
def clips(bm):
    return W.load_clips(W.list_clips(STUBS), bm)


def test_sample_clips_load_with_goals_where_labelled(clips):
    files = W.list_clips(STUBS)
    assert len(clips) == 20 and clips.names[0] == "locomotion/locomotion_000000.npz"
    for k, f in enumerate(files):
        m = load_motion(f)
        assert clips.lengths[k] == m.num_frames
        assert torch.allclose(clips.clip(k)[:, :3], torch.as_tensor(m.trans))
        if m.goal is None:
            assert clips.goal_frame[k] == -1 and clips.kind[k] == 0
        else:
            assert clips.goal_frame[k] == m.goal_frame and clips.kind[k] == 1
            assert torch.allclose(clips.goal[k], torch.as_tensor(m.goal))
    assert len(clips.of_kind("reach")) == 10


def test_feet_filter_drops_clips_with_feet_above_20_cm(bm):
    m = load_motion(STUBS / "locomotion" / "locomotion_000001.npz")
    lifted = replace(m, trans=m.trans + np.array([0, 0, 0.30], np.float32))
    low = replace(m, trans=m.trans + np.array([0, 0, 0.05], np.float32))
    jump = m.trans.copy()
    jump[50:60, 2] += 0.35                                   # a short jump: 10 frames with the feet high
    cs = W.clips_from_motions([m, lifted, low, replace(m, trans=jump)], ["a", "b", "c", "d"], bm)
    assert cs.names == ["a", "c"]
    feet = W.feet_height(cs.clip(0), cs.rest[0])
    joints = m.joint_positions(bm)[:, W.FOOT_JOINTS, 2].min(1)
    assert np.allclose(feet.numpy(), joints, atol=1e-5)      # the filter measures the ankle/foot joints
    assert W.clips_from_motions([lifted], ["b"], bm, max_foot_height=None).names == ["b"]


def test_splits_are_deterministic_disjoint_and_80_10_10():
    names = [f"locomotion/locomotion_{k:06d}.npz" for k in range(3000)]
    a = W.split_clips(names)
    b = W.split_clips(list(reversed(names))[:1500] + ["reach/extra.npz"])   # order and other names do not matter
    for split, members in b.items():
        assert set(m for m in members if m != "reach/extra.npz") <= set(a[split])
    assert sorted(sum(a.values(), [])) == sorted(names)
    frac = {k: len(v) / len(names) for k, v in a.items()}
    assert abs(frac["train"] - 0.8) < 0.03 and abs(frac["val"] - 0.1) < 0.02 and abs(frac["test"] - 0.1) < 0.02
    assert W.split_clips(names, seed=1)["test"] != a["test"]
    with pytest.raises(ValueError, match="fractions"):
        W.split_clips(names, fractions=(0.5, 0.2, 0.2))


def test_windows_fit_in_their_clips(clips):
    ds = W.WindowDataset(clips, max_steps=10)
    expected = sum(max(0, int(T) - 12) for T in clips.lengths)
    assert len(ds) == expected
    c, i = ds.items[:, 0], ds.items[:, 1]
    assert (i >= 1).all() and (i + 11 <= clips.lengths[c] - 1).all()


def test_batches_hold_the_clip_frames_and_real_goals(clips):
    ds = W.WindowDataset(clips, max_steps=3)
    reach = (clips.kind[ds.items[:, 0]] == 1).nonzero()[:, 0]
    items = ds.items[reach[::7]]
    b = W.make_batch(clips, items, steps=3, generator=torch.Generator().manual_seed(0))
    for k, (c, i) in enumerate(items.tolist()):
        assert torch.equal(b["p"][k], clips.clip(c)[i - 1:i + 5])
        assert torch.equal(b["goal"][k], clips.goal[c])
        assert b["t_goal"][k] == clips.goal_frame[c] - i
        assert not b["hindsight"][k]


def test_goal_frame_hold_labels_the_end_of_the_hold(clips, bm):
    ds = W.WindowDataset(clips, max_steps=3)
    reach = (clips.kind[ds.items[:, 0]] == 1).nonzero()[:, 0]
    items = ds.items[reach[::7]]
    b = W.make_batch(clips, items, steps=3, goal_frame="hold")
    files = {f"{f.parent.name}/{f.name}": f for f in W.list_clips(STUBS)}
    motions = {c: load_motion(files[clips.names[c]]) for c in set(items[:, 0].tolist())}
    for c, m in motions.items():                                          # the wrist stays on the goal to the end
        held = np.linalg.norm(m.joint_positions(bm)[int(clips.goal_frame[c]):, 21] - m.goal, axis=-1)
        assert held.max() < 1e-3
    for k, (c, i) in enumerate(items.tolist()):
        T, g, m = int(clips.lengths[c]), int(clips.goal_frame[c]), motions[c]
        assert b["t_goal"][k] == T - 1 - i and T - 1 > g                  # the clip's last frame, after its reach
        assert torch.equal(b["goal"][k], clips.goal[c])
        assert b["goal_heading"][k].item() == pytest.approx(float(heading_of(m.poses[T - 1, 0])), abs=1e-5)
    with pytest.raises(ValueError, match="goal_frame"):
        W.make_batch(clips, items, steps=3, goal_frame="arrival")


def test_hindsight_goal_is_the_future_right_wrist(clips, bm):
    ds = W.WindowDataset(clips, max_steps=4)
    loco = (clips.kind[ds.items[:, 0]] == 0).nonzero()[:, 0]
    items = ds.items[loco[::37]]
    b = W.make_batch(clips, items, steps=4, generator=torch.Generator().manual_seed(1))
    files = W.list_clips(STUBS)
    motions = {c: load_motion(files[c]) for c in set(items[:, 0].tolist())}
    wrists = {c: m.joint_positions(bm)[:, 21] for c, m in motions.items()}
    for k, (c, i) in enumerate(items.tolist()):
        tg = i + int(b["t_goal"][k])
        T = int(clips.lengths[c])
        assert 5 <= b["t_goal"][k] <= min(240, T - 1 - i)             # beyond the window, within the 8 s horizon
        m, wrist = motions[c], wrists[c][tg]
        assert np.allclose(b["goal"][k].numpy(), wrist, atol=1e-5)
        assert b["goal_heading"][k].item() == pytest.approx(float(heading_of(m.poses[tg, 0])), abs=1e-5)
        assert b["hindsight"][k]
    again = W.make_batch(clips, items, steps=4, generator=torch.Generator().manual_seed(1))
    other = W.make_batch(clips, items, steps=4, generator=torch.Generator().manual_seed(2))
    assert torch.equal(again["t_goal"], b["t_goal"]) and not torch.equal(other["t_goal"], b["t_goal"])


def test_hindsight_offsets_cover_their_whole_range_uniformly():
    """t_G - i of a locomotion window is uniform over [steps + 1, min(horizon, T - 1 - i)], both ends included: on a
    6-frame clip from frame 1, the offsets 1..4 come equally often (chi-square) and nothing else."""
    from scipy import stats

    T = 6
    p = I.pose_from_rotmats(torch.zeros(T, 3), torch.eye(3).expand(T, 22, 3, 3)).float()
    clips = W.ClipSet(p, torch.tensor([0, T]), torch.zeros(1, 22, 3), torch.zeros(1, 10), torch.zeros(1, 3),
                      torch.tensor([-1]), torch.tensor([0]), ["locomotion/a.npz"])
    b = W.make_batch(clips, torch.tensor([[0, 1]]).expand(4000, 2), steps=0, generator=torch.Generator().manual_seed(0))
    counts = np.bincount(b["t_goal"].numpy(), minlength=6)
    assert counts[0] == 0 and counts[5] == 0 and (counts[1:5] > 0).all()
    assert stats.chisquare(counts[1:5]).pvalue > 1e-3


def test_hindsight_horizons_cover_the_test_horizon(clips):
    ds = W.WindowDataset(clips.of_kind("locomotion"), max_steps=0)
    loco = clips.of_kind("locomotion")
    first = ds.items[ds.items[:, 1] == 1]
    g = torch.Generator().manual_seed(0)
    t = torch.cat([W.make_batch(loco, first, steps=0, generator=g)["t_goal"] for _ in range(50)])
    assert t.min() <= 5 and t.max() >= 200                     # short and long horizons both drawn


def test_intention_is_zero_after_the_real_goal_frame(clips):
    c = int((clips.kind == 1).nonzero()[0])
    i = int(clips.goal_frame[c]) + 2
    b = W.make_batch(clips, torch.tensor([[c, i]]), steps=0)
    p0, p1 = b["p"][:, 0], b["p"][:, 1]
    _, inten = W.window_condition(p1, I.pose_to_delta(p0, p1), b["rest"], b["goal"], b["t_goal"], b["goal_heading"])
    assert torch.equal(inten, torch.zeros(1, 7))
    b = W.make_batch(clips, torch.tensor([[c, 3]]), steps=0)
    _, inten = W.window_condition(b["p"][:, 1], I.pose_to_delta(b["p"][:, 0], b["p"][:, 1]), b["rest"], b["goal"],
                                  b["t_goal"], b["goal_heading"])
    assert inten.abs().sum() > 0


def test_stats_match_the_walking_speed_measured_independently(clips):
    loco = clips.of_kind("locomotion")
    stats = W.compute_stats(loco, samples=2000)
    fwd = []
    for f in W.list_clips(STUBS, kinds=("locomotion",)):
        m = load_motion(f)
        h = heading_of(m.poses[:, 0])
        v = np.diff(m.trans[:, :2], axis=0)
        fwd.append((v[:, 0] * np.cos(h[:-1]) + v[:, 1] * np.sin(h[:-1]))[1:])   # forward step in the heading frame
    fwd = np.concatenate(fwd)
    assert stats["delta_mean"][0].item() == pytest.approx(fwd.mean(), abs=1e-5)
    assert stats["delta_std"][0].item() == pytest.approx(fwd.std(ddof=1), rel=1e-3)
    assert (stats["state_std"] >= W.STD_FLOOR).all() and stats["intention_std"].shape == (7,)
    assert stats["state_mean"][7:133].abs().max() <= 1.0                  # 6D entries of rotations


def test_stats_of_every_delta_and_state_column_match_numpy_over_every_frame(clips):
    stats = W.compute_stats(clips, samples=300)
    d, st = [], []
    for c in range(len(clips)):                               # clip by clip: frames with a frame before and after
        p = clips.p[clips.offsets[c]:clips.offsets[c + 1]]
        d.append(I.pose_to_delta(p[1:-1], p[2:]).numpy())
        st.append(I.state_features(p[1:-1], I.pose_to_delta(p[:-2], p[1:-1])).numpy())
    for name, x in (("delta", np.concatenate(d).astype(np.float64)), ("state", np.concatenate(st).astype(np.float64))):
        assert stats[f"{name}_mean"].shape == (x.shape[1],)          # 135 and 268 columns, several blocks of 64
        np.testing.assert_allclose(stats[f"{name}_mean"].numpy(), x.mean(0), rtol=1e-6, atol=1e-7)
        np.testing.assert_allclose(stats[f"{name}_std"].numpy(), np.maximum(x.std(0, ddof=1), W.STD_FLOOR),
                                   rtol=1e-5, atol=1e-7)


def test_held_out_starts_are_test_split_and_canonical(bm):
    names = W.test_start_names(STUBS, n=2, seed=3)
    assert all(W.split_of(n, 3) == "test" for n in names)
    assert [n.split("/")[0] for n in names] == ["locomotion", "reach"]
    ms = [load_motion(STUBS / n) for n in names]
    starts = W.held_out_starts(ms, names, bm, n=2, frame=5)
    for s, m in zip(starts, ms):
        pelvis = I.body_joints(s.p, s.rest)[0]
        assert pelvis[:2].abs().max() < 1e-5 and abs(I.heading_of_pose(s.p).item()) < 1e-5
        orig = I.pose_from_axis_angle(torch.as_tensor(m.trans[4:6]), torch.as_tensor(m.poses[4:6]))
        assert torch.allclose(I.pose_to_delta(s.p_prev, s.p), I.pose_to_delta(orig[0], orig[1]), atol=1e-5)
        assert abs(pelvis[2].item() - m.joint_positions(bm)[5, 0, 2]) < 1e-5
        assert s.source.endswith("#5")


def test_clipset_cache_round_trip(clips, tmp_path):
    path = W.save_clipset(tmp_path / "c.npz", clips)
    back = W.load_clipset(path)
    assert back.names == clips.names and torch.equal(back.p, clips.p) and torch.equal(back.offsets, clips.offsets)
    with np.load(path, allow_pickle=False) as z:
        assert z["names"].dtype.kind == "U"


def test_errors_name_the_argument(clips):
    with pytest.raises(ValueError, match="names"):
        clips.subset(["nope.npz"])
    with pytest.raises(ValueError, match="kind"):
        clips.of_kind("dance")
    with pytest.raises(ValueError, match="items"):
        W.make_batch(clips, torch.tensor([[0, 0]]), steps=1)
    with pytest.raises(FileNotFoundError, match="folder"):
        W.list_clips(STUBS / "nothing")


def test_cached_clips_are_keyed_by_the_clips_and_the_body(bm, tmp_path):
    """The ClipSet cache reads back what it wrote for the same files and body, and is rebuilt (a second file) for
    another body model or another CLIPSET_VERSION, never read across them: a body whose template is moved 1 cm along
    x has its rest joints there (moved further, or up, the clips' goals or floor would not hold on it: refused)."""
    from graspkit.body import BodyModel
    from graspkit.body.model import load_model_arrays
    from graspkit.data import wandr_dataset

    a = W.cached_clips(STUBS, bm, limit=1, cache=tmp_path)
    again = W.cached_clips(STUBS, bm, limit=1, cache=tmp_path)
    torch.testing.assert_close(again.rest, a.rest)
    assert len(list(tmp_path.glob("clips_*.npz"))) == 1
    arrays = dict(load_model_arrays(PROCEDURAL_MODEL))
    arrays["v_template"] = arrays["v_template"] + np.array([0.01, 0.0, 0.0], arrays["v_template"].dtype)
    b = W.cached_clips(STUBS, BodyModel(arrays), limit=1, cache=tmp_path)
    torch.testing.assert_close(b.rest[..., 0] - a.rest[..., 0], torch.full_like(a.rest[..., 0], 0.01))
    assert len(list(tmp_path.glob("clips_*.npz"))) == 2
    mp = pytest.MonkeyPatch()
    mp.setattr(wandr_dataset, "CLIPSET_VERSION", wandr_dataset.CLIPSET_VERSION + 1)
    W.cached_clips(STUBS, bm, limit=1, cache=tmp_path)
    mp.undo()
    assert len(list(tmp_path.glob("clips_*.npz"))) == 3


def test_a_clip_remade_in_place_at_the_same_size_rebuilds_the_cache(bm, tmp_path):
    """The cache was keyed on names and sizes only: a clip rewritten with one beta's sign flipped (the same bytes
    long) returned the stale ClipSet (an independent check). The key now holds each npz member's CRC-32."""
    src = sorted((STUBS / "reach").glob("*.npz"))[0]
    (tmp_path / "d" / "reach").mkdir(parents=True)
    clip = tmp_path / "d" / "reach" / src.name
    with np.load(src, allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    np.savez(clip, **arrays)                              # uncompressed: a changed value keeps the size
    a = W.cached_clips(tmp_path / "d", bm, cache=tmp_path / "c", kinds=("reach",))
    size = clip.stat().st_size
    arrays["betas"] = arrays["betas"].copy()
    arrays["betas"][9] = 0.5 if arrays["betas"][9] != 0.5 else -0.5
    np.savez(clip, **arrays)
    assert clip.stat().st_size == size
    b = W.cached_clips(tmp_path / "d", bm, cache=tmp_path / "c", kinds=("reach",))
    assert len(list((tmp_path / "c").glob("clips_*.npz"))) == 2
    assert float(b.betas[0, 9]) == pytest.approx(float(arrays["betas"][9])) != float(a.betas[0, 9])


def test_intention_stats_are_taken_at_frame_i_with_t_goal_minus_i_frames_left(bm):
    clips = W.load_clips(W.list_clips(DATA_STUBS / "motion", kinds=("reach",), limit=1), bm)
    k = 0
    p_all, g = clips.clip(k), int(clips.goal_frame[k])
    assert g >= 2
    p = p_all[g - 2:g + 1]                           # three frames: the only window (i = 1) has t_G = i + 1
    one = W.ClipSet(p, torch.tensor([0, 3]), clips.rest[k:k + 1], clips.betas[k:k + 1], clips.goal[k:k + 1],
                    torch.tensor([2]), torch.tensor([1]), ["reach/one.npz"])
    assert len(W.WindowDataset(one, max_steps=0)) == 1
    stats = W.compute_stats(one, samples=50)
    # closed form at frame i = 1: I^w = R_z(-psi)(G - W) / (1/30 s), I^r = (cos, sin)(psi_G - psi) - (1, 0),
    # I^p = 2 (1 - e^{-|D|}) D / |D| with D = R_z(-psi)(G - P)^xy
    J = I.body_joints(p[1], clips.rest[k])
    psi, psi_g = I.heading_of_pose(p[1]).double(), I.heading_of_pose(p[2]).double()
    c, s = torch.cos(psi), torch.sin(psi)
    R = torch.tensor([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]], dtype=torch.float64)
    goal = clips.goal[k].double()
    iw = R @ (goal - J[I.WRIST].double()) * 30.0
    D = (R @ (goal - J[I.PELVIS].double()))[:2]
    ip = 2 * (1 - torch.exp(-D.norm())) * D / D.norm()
    ir = torch.stack([torch.cos(psi_g - psi) - 1, torch.sin(psi_g - psi)])
    want = torch.cat([iw, ir, ip]).float()
    torch.testing.assert_close(stats["intention_mean"], want, rtol=1e-4, atol=1e-4)
    # one window and one frame with a frame on each side: no spread, so every std is the documented floor (not NaN)
    for k in ("delta_std", "state_std", "intention_std"):
        torch.testing.assert_close(stats[k], torch.full_like(stats[k], W.STD_FLOOR), rtol=0, atol=0)


def test_a_dropped_clip_does_not_shift_the_rest_joints_of_those_kept(bm):
    """clips_from_motions keeps each clip's own shaped rest joints when the foot filter drops a clip before it: the FK
    of the kept clip matches Motion.joint_positions (the body model's joints-only forward pass) for its own betas."""
    from dataclasses import replace

    import numpy as np

    m = load_motion(sorted((DATA_STUBS / "motion" / "locomotion").glob("*.npz"))[1])
    b1 = np.zeros(10, np.float32)
    b1[0] = 2.0                                               # another body than the kept clip's
    assert not np.allclose(b1, np.asarray(m.betas[:10]))
    lifted = replace(m, trans=m.trans + np.array([0, 0, 1.0], np.float32), betas=b1)   # dropped (feet > 20 cm)
    kept = m
    cs = W.clips_from_motions([lifted, kept], ["lifted", "kept"], bm)
    assert cs.names == ["kept"]
    J = I.body_joints(cs.clip(0)[:3], cs.rest[0]).double().numpy()
    np.testing.assert_allclose(J, kept.joint_positions(bm)[:3, :22], atol=1e-4)


def test_clips_shorter_than_three_frames_are_dropped(bm):
    """clips_from_motions' docstring: Motion objects of >= 3 frames (one frame before and after a state); shorter
    clips are left out."""
    from dataclasses import replace

    m = load_motion(sorted((DATA_STUBS / "motion" / "locomotion").glob("*.npz"))[0])
    short = [replace(m, poses=m.poses[:n], trans=m.trans[:n], contacts=None) for n in (1, 2, 3)]
    cs = W.clips_from_motions(short, ["one", "two", "three"], bm)
    assert cs.names == ["three"] and cs.lengths.tolist() == [3]
