"""AMASS-style / CIRCLE-style files: round trips, smplx parity, SMPL-H mapping, resampling, clear errors."""
import numpy as np
import pytest
import smplx
import torch
from scipy.spatial.transform import Rotation, Slerp

from graspkit.body import BodyModel
from graspkit.data import Motion, SequenceFileError, load_motion, save_motion
from graspkit.data.formats import resample, to_smplx_poses
from graspkit.data.wandr_dataset import motion_kind

from conftest import PROCEDURAL_MODEL


def _random_motion(T=12, seed=0, goal=False):
    rng = np.random.default_rng(seed)
    kw = dict(goal=rng.normal(size=3), goal_frame=T - 3, hand="right") if goal else {}
    return Motion(rng.normal(scale=0.3, size=(T, 55, 3)), rng.normal(size=(T, 3)), rng.normal(size=10), 30.0,
                  contacts=rng.random((T, 4)) < 0.5, **kw)


def test_round_trip_keeps_every_array_and_the_goal(tmp_path):
    m = _random_motion(goal=True)
    p = save_motion(tmp_path / "clip.npz", m)
    with np.load(p, allow_pickle=False) as z:          # AMASS keys, plain arrays
        assert z["poses"].shape == (12, 165) and z["trans"].shape == (12, 3) and z["betas"].shape == (10,)
        assert str(z["surface_model_type"]) == "smplx" and float(z["mocap_frame_rate"]) == 30.0
        assert str(z["gender"]) == "neutral"
    r = load_motion(p)
    for k in ("poses", "trans", "betas", "contacts", "goal"):
        assert np.array_equal(getattr(r, k), getattr(m, k)), k
    assert (r.goal_frame, r.hand, r.fps) == (m.goal_frame, "right", 30.0)
    assert not list(tmp_path.glob("*.tmp"))


def test_writes_are_byte_deterministic(tmp_path):
    m = _random_motion(seed=3)
    a, b = save_motion(tmp_path / "a.npz", m), save_motion(tmp_path / "b.npz", m)
    assert a.read_bytes() == b.read_bytes()


def test_file_through_smplx_gives_graspkit_vertices(tmp_path):
    """A written file, loaded into the smplx package with the procedural model, matches graspkit to 1e-5 m."""
    m = _random_motion(T=6, seed=1)
    m.trans[:] = 0.1 * m.trans
    m = load_motion(save_motion(tmp_path / "clip.npz", m))
    with np.load(tmp_path / "clip.npz", allow_pickle=False) as z:
        poses, trans, betas = (torch.as_tensor(z[k], dtype=torch.float64) for k in ("poses", "trans", "betas"))
    T = len(poses)
    ref = smplx.create(str(PROCEDURAL_MODEL.parents[1]), model_type="smplx", gender="neutral", ext="npz",
                       use_pca=False, flat_hand_mean=True, num_betas=10, batch_size=T, dtype=torch.float64)
    out = ref(betas=betas[None].expand(T, -1), global_orient=poses[:, :3], body_pose=poses[:, 3:66],
              jaw_pose=poses[:, 66:69], leye_pose=poses[:, 69:72], reye_pose=poses[:, 72:75],
              left_hand_pose=poses[:, 75:120], right_hand_pose=poses[:, 120:165], transl=trans,
              expression=torch.zeros(T, 10, dtype=torch.float64))
    bm = BodyModel.from_file(PROCEDURAL_MODEL, dtype=torch.float64)
    ours = m.vertices(bm)
    assert (ours - out.vertices).abs().max() < 1e-5


def test_smplh_poses_map_body_and_hands_and_zero_jaw_and_eyes(tmp_path):
    rng = np.random.default_rng(2)
    p156 = rng.normal(size=(5, 156))
    np.savez(tmp_path / "h.npz", poses=p156, trans=rng.normal(size=(5, 3)), betas=rng.normal(size=16),
             mocap_framerate=np.array(30.0), gender=np.array(b"female"))
    with pytest.warns(UserWarning, match="SMPL\\+H file's betas are read as SMPL-X betas"):
        m = load_motion(tmp_path / "h.npz")
    p = p156.reshape(5, 52, 3)
    assert np.allclose(m.poses[:, :22], p[:, :22], atol=1e-6) and np.allclose(m.poses[:, 25:], p[:, 22:], atol=1e-6)
    assert np.all(m.poses[:, 22:25] == 0)
    assert m.betas.shape == (10,) and m.gender == "female"
    assert to_smplx_poses(np.zeros((2, 165))).shape == (2, 55, 3)


def test_resampling_120_to_30_keeps_every_fourth_frame_and_50_to_30_slerps_like_scipy(tmp_path):
    rng = np.random.default_rng(4)
    T = 41
    poses, trans = rng.normal(scale=0.8, size=(T, 55, 3)), rng.normal(size=(T, 3))
    np.savez(tmp_path / "a.npz", poses=poses.reshape(T, -1), trans=trans, mocap_frame_rate=np.array(120.0))
    m = load_motion(tmp_path / "a.npz")
    assert m.num_frames == 11 and m.fps == 30.0
    R = Rotation.from_rotvec(m.poses.reshape(-1, 3).astype(np.float64)).as_matrix()
    assert np.allclose(R, Rotation.from_rotvec(poses[::4].reshape(-1, 3)).as_matrix(), atol=1e-5)
    assert np.allclose(m.trans, trans[::4], atol=1e-6)
    out, tr, _, _ = resample(poses, trans, 50.0, 30.0)
    f = np.arange(len(out)) * 50.0 / 30.0
    assert len(out) == int((T - 1) * 30 / 50) + 1
    for j in (0, 7, 30):
        ref = Slerp(np.arange(T), Rotation.from_rotvec(poses[:, j]))(f).as_matrix()
        assert np.allclose(Rotation.from_rotvec(out[:, j]).as_matrix(), ref, atol=1e-9)
    assert np.allclose(tr, np.stack([np.interp(f, np.arange(T), trans[:, k]) for k in range(3)], 1))


def test_a_reaching_clip_read_at_another_rate_keeps_its_goal_frame_in_time(tmp_path):
    """A 120 fps clip due at frame 100 (0.833 s) is due at frame 25 when read at 30 fps, the frame whose
    translation is the source's frame 100."""
    T = 121
    trans = np.stack([np.arange(T) / 120.0, np.zeros(T), np.ones(T)], 1)
    m = Motion(np.zeros((T, 55, 3)), trans, np.zeros(10), 120.0, goal=np.array([1.0, 0.0, 1.0]), goal_frame=100,
               hand="right")
    r = load_motion(save_motion(tmp_path / "c.npz", m), fps=30)
    assert r.fps == 30.0 and r.goal_frame == 25
    np.testing.assert_allclose(r.trans[r.goal_frame], trans[100], atol=1e-6)


def test_amass_per_part_keys_are_the_slices_of_poses(tmp_path):
    """AMASS's per-part copies (root_orient | pose_body | pose_jaw | pose_eye | pose_hand) put back together are
    `poses`, joint by joint: every joint carries its own value here, so a slice shifted by a joint shows."""
    T = 3
    poses = np.zeros((T, 55, 3))
    poses[:, :, 0] = 0.01 * np.arange(55)
    poses[:, :, 1] = 0.001 * np.arange(T)[:, None]
    p = save_motion(tmp_path / "c.npz", Motion(poses, np.zeros((T, 3)), np.zeros(10), 30.0), amass_keys=True)
    with np.load(p, allow_pickle=False) as z:
        parts = [z[k] for k in ("root_orient", "pose_body", "pose_jaw", "pose_eye", "pose_hand")]
        assert [x.shape[1] for x in parts] == [3, 63, 3, 6, 90]
        np.testing.assert_array_equal(np.concatenate(parts, 1), z["poses"])
        np.testing.assert_allclose(z["pose_eye"].reshape(T, 2, 3), poses[:, 23:25], atol=1e-7)
        np.testing.assert_allclose(z["pose_jaw"], poses[:, 22], atol=1e-7)


def test_errors_name_the_file_and_key(tmp_path):
    with pytest.raises(SequenceFileError, match="nope.npz: no such"):
        load_motion(tmp_path / "nope.npz")
    np.savez(tmp_path / "no_trans.npz", poses=np.zeros((3, 165)), mocap_frame_rate=np.array(30.0))
    with pytest.raises(SequenceFileError, match="no_trans.npz: missing key 'trans'"):
        load_motion(tmp_path / "no_trans.npz")
    np.savez(tmp_path / "bad.npz", poses=np.zeros((3, 100)), trans=np.zeros((3, 3)), mocap_frame_rate=np.array(30.0))
    with pytest.raises(SequenceFileError, match="bad.npz: key 'poses' has shape"):
        load_motion(tmp_path / "bad.npz")
    np.savez(tmp_path / "pickled.npz", poses=np.zeros((3, 165)), trans=np.zeros((3, 3)),
             mocap_frame_rate=np.array(30.0), gender=np.array([{"a": 1}], dtype=object))
    with pytest.raises(SequenceFileError, match="pickled.npz: key 'gender' cannot be read without pickle"):
        load_motion(tmp_path / "pickled.npz")
    np.savez(tmp_path / "nan.npz", poses=np.full((3, 165), np.nan), trans=np.zeros((3, 3)), mocap_frame_rate=np.array(30.0))
    with pytest.raises(SequenceFileError, match="nan.npz: key 'poses' contains NaN"):
        load_motion(tmp_path / "nan.npz")


@pytest.mark.parametrize("change, message", [
    ({"poses": np.full((3, 165), "x")}, "key 'poses' holds <U1 values, expected numbers"),
    ({"mocap_frame_rate": np.array([30.0, 30.0])}, "key 'mocap_frame_rate' has shape \\(2,\\), expected a single"),
    ({"mocap_frame_rate": np.array("30")}, "key 'mocap_frame_rate' holds <U2 values"),
    ({"goal_frame": np.array(1.5)}, "key 'goal_frame' is 1.5, expected a whole frame number"),
    ({"goal_frame": np.array([1, 2])}, "key 'goal_frame' has shape \\(2,\\)"),
    ({"contacts": np.full((3, 4), 7)}, "key 'contacts' holds int64 values other than 0 and 1"),
])
def test_a_damaged_key_is_named_with_its_file(tmp_path, change, message):
    good = {"poses": np.zeros((3, 165)), "trans": np.zeros((3, 3)), "mocap_frame_rate": np.array(30.0),
            "goal": np.zeros(3), "goal_frame": np.array(1), "contacts": np.zeros((3, 4), bool)}
    np.savez(tmp_path / "ok.npz", **good)
    m = load_motion(tmp_path / "ok.npz")
    assert m.goal_frame == 1 and m.contacts.dtype == bool
    np.savez(tmp_path / "odd.npz", **{**good, **change})
    with pytest.raises(SequenceFileError, match="odd.npz: " + message):
        load_motion(tmp_path / "odd.npz")


def test_a_folder_or_a_file_without_a_frame_rate_is_named(tmp_path):
    with pytest.raises(SequenceFileError, match="is a folder, expected a sequence .npz"):
        load_motion(tmp_path)
    np.savez(tmp_path / "norate.npz", poses=np.zeros((3, 165)), trans=np.zeros((3, 3)))
    with pytest.raises(SequenceFileError, match="norate.npz: no frame rate: expected a key 'mocap_frame_rate'.*"
                                                "'mocap_framerate'"):
        load_motion(tmp_path / "norate.npz")
    np.savez(tmp_path / "ints.npz", poses=np.zeros((3, 165)), trans=np.zeros((3, 3)), mocap_frame_rate=np.array(30),
             contacts=np.ones((3, 4), np.int8))          # whole-number rate and 0/1 contacts are fine
    m = load_motion(tmp_path / "ints.npz")
    assert m.fps == 30.0 and m.contacts.all()


def test_resampled_contacts_come_from_the_nearest_source_frame():
    """`resample` takes each new frame's contacts from the nearest source frame (50 -> 30 fps: nearest and floor differ)."""
    T, src, fps = 11, 50.0, 30.0
    contacts = np.zeros((T, 4), bool)
    contacts[np.arange(T), np.arange(T) % 4] = True                 # a different pattern on every source frame
    poses, trans = np.zeros((T, 55, 3)), np.zeros((T, 3))
    _, _, c, _ = resample(poses, trans, src, fps, contacts)
    t = np.arange(len(c)) / fps                                     # the new frames' times (s)
    nearest = np.array([int(np.argmin(np.abs(np.arange(T) / src - x))) for x in t])
    assert len(set((nearest * fps / src) % 1)) > 1                  # not an integer ratio: nearest != floor somewhere
    assert np.array_equal(c, contacts[nearest])


def test_a_goal_without_a_hand_key_is_a_right_hand_reach(tmp_path):
    """A CIRCLE-style clip without a 'hand' key is a right-hand reach (docs/data.md; WANDR puts the right wrist on the goal)."""
    T = 5
    path = tmp_path / "circle_style.npz"
    np.savez(path, poses=np.zeros((T, 165), np.float32), trans=np.zeros((T, 3), np.float32),
             mocap_frame_rate=np.array(30.0), goal=np.array([1.0, 0.5, 1.2], np.float32), goal_frame=np.array(3))
    m = load_motion(path)
    assert m.hand == "right" and m.goal_frame == 3
    assert motion_kind(m) == "reach"
