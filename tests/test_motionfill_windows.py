"""MotionFill's training windows (SAGA §3.3, A.3; graspkit.data.motionfill_dataset): padding, slicing, frame rate,
rest starts, splits, normalisation statistics and the dataset's clip filter, against clips padded and sliced by hand
and numpy's statistics."""
import numpy as np
import pytest
import torch

from graspkit.data import load_motion
from graspkit.data import motionfill_dataset as mf
from graspkit.data.motion import Motion
from graspkit.paths import DATA_STUBS

CLIP = DATA_STUBS / "motion" / "locomotion" / "locomotion_000000.npz"
KEYS = ("traj", "markers", "local", "vel", "contacts")


@pytest.fixture(scope="module")
def clip():
    return load_motion(CLIP)


def _front_padded(m: Motion, k: int) -> Motion:
    """`m` with its first frame written out k more times in front (poses, translation and contact labels)."""
    rep = lambda a: np.concatenate([np.repeat(a[:1], k, 0), a])  # noqa: E731
    return Motion(poses=rep(m.poses), trans=rep(m.trans), betas=m.betas, fps=m.fps, contacts=rep(m.contacts))


def _same(a, b, atol=1e-5):
    for k in KEYS:
        assert a[k].shape == b[k].shape, k
        np.testing.assert_allclose(a[k].astype(np.float64), b[k].astype(np.float64), atol=atol, err_msg=k)


def test_a_short_clip_gives_the_window_of_the_clip_padded_by_hand(bm, clip):
    """A.3: a clip shorter than 62 frames is padded at the front with its first frame; so a 40-frame and a 61-frame
    clip give exactly the window of the same clip with that frame written out 22 (resp. 1) more times in front."""
    for n in (40, 61):
        short = clip.slice(0, n)
        got = mf.make_windows([short], bm, progress=False)
        want = mf.make_windows([_front_padded(short, mf.NUM_ROOT - n)], bm, progress=False)
        assert len(got["traj"]) == 1
        _same(got, want)


def test_windows_every_stride_frames_are_the_clip_sliced_there(bm, clip):
    """Windows every `stride` frames: a clip of 62 + 2*15 frames gives 3 windows (starts 0, 15, 30, counted by hand),
    window k is the window of the clip cut to frames [15k, 15k+62), and its contacts are the clip's own gait labels
    of frames 15k .. 15k+60 (the module doc: the generator's phases where the clip carries them)."""
    m = clip.slice(0, mf.NUM_ROOT + 30)
    w = mf.make_windows([m], bm, stride=15, progress=False)
    assert len(w["traj"]) == 3 and (w["clip"] == 0).all()
    for k in range(3):
        one = mf.make_windows([m.slice(15 * k, 15 * k + mf.NUM_ROOT)], bm, progress=False)
        _same({x: w[x][k:k + 1] for x in KEYS}, one)
        np.testing.assert_array_equal(w["contacts"][k], m.contacts[15 * k:15 * k + mf.NUM_FRAMES])


def test_a_clip_at_another_frame_rate_is_refused(bm, clip):
    """The windows are 2 s at 30 fps (A.3): a 60-fps clip would silently give 1-s windows, so it is refused."""
    fast = Motion(poses=clip.poses, trans=clip.trans, betas=clip.betas, fps=60.0)
    with pytest.raises(ValueError, match="30 fps"):
        mf.make_windows([fast], bm, progress=False)


def test_start_at_rest_gives_the_first_frame_of_a_jump_its_ground_contacts(bm, clip):
    """start_at_rest (a start pose at rest joined to a later pose): a clip whose frame 0 stands 1 m behind the rest
    of it, without labels. Without the flag frame 0 moves at 30 m/s, so no foot is in contact; with it frame 0 is at
    rest and a walking body has at least one foot on the floor; later frames are the same either way."""
    poses = np.concatenate([clip.poses[:1], clip.poses[1:mf.NUM_ROOT]])
    trans = np.concatenate([clip.trans[:1] - [1.0, 0.0, 0.0], clip.trans[1:mf.NUM_ROOT]]).astype(np.float32)
    m = Motion(poses=poses, trans=trans, betas=clip.betas)
    moving = mf.make_windows([m], bm, progress=False)["contacts"][0]
    rest = mf.make_windows([m], bm, progress=False, start_at_rest=True)["contacts"][0]
    assert not moving[0].any() and rest[0].any()
    np.testing.assert_array_equal(moving[1:], rest[1:])


def test_split_sizes_are_the_nearest_counts_and_the_seed_matters():
    """split_clips: each split holds the nearest whole number of clips to its fraction (19 clips at 0.8 / 0.1:
    15.2 -> 15 train, 1.9 -> 2 val, the 2 left test; 30 at 0.6 / 0.3: 18, 9, 3), the three are disjoint and cover
    all clips, and another seed deals another split (50 clips: the chance two permutations give the same is ~0)."""
    for n, fr, sizes in ((19, (0.8, 0.1), (15, 2, 2)), (30, (0.6, 0.3), (18, 9, 3))):
        s = mf.split_clips(n, seed=0, fractions=fr)
        assert tuple(len(s[k]) for k in ("train", "val", "test")) == sizes
        assert sorted(np.concatenate(list(s.values())).tolist()) == list(range(n))
    a, b = mf.split_clips(50, seed=0), mf.split_clips(50, seed=1)
    assert not np.array_equal(a["train"], b["train"])


@pytest.fixture(scope="module")
def windows(bm, clip):
    return mf.make_windows([clip, load_motion(DATA_STUBS / "motion" / "locomotion" / "locomotion_000001.npz")], bm,
                           stride=30, progress=False)


def test_stats_are_the_mean_and_std_over_all_training_frames(windows):
    """MotionFillStats: mean / std per marker coordinate and per velocity component over every frame of every
    window (numpy over the flattened (N*61, .) arrays); the images' velocity channels are then zero-mean, unit-std."""
    st = mf.MotionFillStats.fit(windows)
    loc = windows["local"].reshape(-1, 79 * 3).astype(np.float64)
    vel = windows["vel"].reshape(-1, 3).astype(np.float64)
    np.testing.assert_allclose(st.marker_mean.numpy(), loc.mean(0), atol=1e-5)
    np.testing.assert_allclose(st.marker_std.numpy(), np.maximum(loc.std(0, ddof=1), 1e-3), rtol=1e-4, atol=1e-6)
    np.testing.assert_allclose(st.vel_mean.numpy(), vel.mean(0), atol=1e-6)
    np.testing.assert_allclose(st.vel_std.numpy(), np.maximum(vel.std(0, ddof=1), 1e-3), rtol=1e-4, atol=1e-7)
    ds = mf.MotionFillDataset(windows, st)
    v = torch.stack([ds[i]["image"][1:, :, 0] for i in range(len(ds))]).permute(1, 0, 2).reshape(3, -1)
    np.testing.assert_allclose(v.mean(1).numpy(), 0, atol=1e-4)
    np.testing.assert_allclose(v.std(1).numpy(), 1, atol=1e-3)


def test_a_constant_coordinate_gets_the_floor_std_and_a_finite_image():
    """'std floored at 1e-3': a marker coordinate that never changes (e.g. a foot marker's height on flat ground in
    a toy set) gets std 1e-3, not 0, so its normalised image is 0 there and finite everywhere."""
    rng = np.random.default_rng(0)
    local = rng.normal(size=(3, mf.NUM_FRAMES, 79, 3)).astype(np.float32)
    local[:, :, 5, 2] = 0.25
    vel = rng.normal(size=(3, mf.NUM_FRAMES, 3)).astype(np.float32)
    vel[..., 2] = 0.0
    st = mf.MotionFillStats.fit({"local": local, "vel": vel})
    assert float(st.marker_std[5 * 3 + 2]) == pytest.approx(1e-3) and float(st.vel_std[2]) == pytest.approx(1e-3)
    img = mf.motion_image(torch.as_tensor(local), torch.zeros(3, mf.NUM_FRAMES, 4), torch.as_tensor(vel), st)
    assert torch.isfinite(img).all() and img[:, 0, :, 5 * 3 + 2].abs().max() < 1e-3


def test_dataset_of_some_clips_holds_their_windows_and_their_linear_trajectories(windows):
    """MotionFillDataset(clips=[1]): exactly the windows of clip 1, each with Γ̄ = Γ_0 + t/60 (Γ_60 - Γ_0) for
    t = 0..61 computed here by hand (§3.3)."""
    st = mf.MotionFillStats.fit(windows)
    ds = mf.MotionFillDataset(windows, st, clips=np.array([1]))
    idx = np.flatnonzero(windows["clip"] == 1)
    assert len(ds) == len(idx) > 0 and (windows["clip"] == 0).any()
    t = np.arange(mf.NUM_ROOT)[:, None] / 60.0
    for i, j in enumerate(idx):
        tr = windows["traj"][j].astype(np.float64)
        np.testing.assert_allclose(ds[i]["traj"].numpy(), tr, atol=0)
        np.testing.assert_allclose(ds[i]["traj_interp"].numpy(), tr[0] + t * (tr[60] - tr[0]), atol=1e-5)


def test_a_windows_file_without_contacts_is_refused(tmp_path, windows):
    """load_windows: a file lacking one of the six keys (here 'contacts') is not a windows file; the error names it."""
    np.savez(tmp_path / "nocontacts.npz", **{k: v for k, v in windows.items() if k != "contacts"})
    with pytest.raises(ValueError, match=r"nocontacts\.npz.*contacts"):
        mf.load_windows(tmp_path / "nocontacts.npz")


def test_a_stride_that_is_not_a_whole_number_of_frames_is_named(bm, clip):
    """stride 0 used to mean 62 (read as None), a negative one blamed the clips, True meant 1."""
    for bad in (0, -5, 2.5, True):
        with pytest.raises(ValueError, match="stride: expected an integer >= 1"):
            mf.make_windows([clip], bm, stride=bad, progress=False)
