"""GRAB-style grasp files: round trips, byte determinism, real-GRAB layout behind the pickle opt-in."""
import numpy as np
import pytest

from graspkit.data.formats import SequenceFileError
from graspkit.data.grab import GraspSequence, load_grasp_sequence, save_grasp_sequence


def _sequence(T=5, seed=0):
    rng = np.random.default_rng(seed)
    return GraspSequence(rng.normal(scale=0.3, size=(T, 55, 3)), rng.normal(size=(T, 3)), rng.normal(size=10), 30.0,
                         "mug", rng.normal(size=(T, 3)), rng.normal(size=(T, 3)), "meshes/mug.ply",
                         {"object": rng.random((T, 2048)) < 0.1, "markers": rng.random((T, 143)) < 0.2},
                         {"grasp.type": np.array("handle"), "goal.offsets": rng.normal(size=(400, 3)).astype(np.float32)},
                         rng.normal(size=(2048, 3)), rng.normal(size=(2048, 3)))


def test_round_trip_without_pickle_and_equal_bytes(tmp_path):
    s = _sequence()
    a, b = save_grasp_sequence(tmp_path / "a.npz", s), save_grasp_sequence(tmp_path / "b.npz", s)
    assert a.read_bytes() == b.read_bytes()
    with np.load(a, allow_pickle=False) as z:                      # every key is a plain array
        assert z["body.params.right_hand_pose"].shape == (5, 45) and z["contact.object"].dtype == np.uint8
        assert bool(z["body.flat_hand_mean"]) and str(z["obj_name"]) == "mug"
    r = load_grasp_sequence(a, hands_mean=np.ones(90))            # flat_hand_mean files are never shifted
    assert np.array_equal(r.poses, s.poses) and np.array_equal(r.trans, s.trans) and np.array_equal(r.betas, s.betas)
    assert np.array_equal(r.object_orient, s.object_orient) and r.object_mesh == "meshes/mug.ply"
    assert np.array_equal(r.contacts["object"], s.contacts["object"].astype(np.uint8))
    assert str(r.extras["grasp.type"]) == "handle" and np.array_equal(r.extras["goal.offsets"], s.extras["goal.offsets"])
    assert not list(tmp_path.glob("*.tmp")) and not list(tmp_path.glob(".*"))


def _grab_like(path, T=9, fullpose=True):
    """A file laid out as GRAB's: pickled nested dictionaries, 120 fps, a subject template mesh instead of betas, and
    smplx's full_pose (absolute hand poses) or, without it, 45-D per-part hand poses relative to the hand mean."""
    rng = np.random.default_rng(4)
    full = rng.normal(scale=0.2, size=(T, 165))
    params = {"global_orient": full[:, :3], "body_pose": full[:, 3:66], "jaw_pose": full[:, 66:69],
              "leye_pose": full[:, 69:72], "reye_pose": full[:, 72:75], "transl": rng.normal(size=(T, 3)),
              "expression": np.zeros((T, 10))}
    if fullpose:
        params.update(fullpose=full, left_hand_pose=rng.normal(size=(T, 24)), right_hand_pose=rng.normal(size=(T, 24)))
    else:
        params.update(left_hand_pose=full[:, 75:120], right_hand_pose=full[:, 120:])
    np.savez(path, body={"params": params, "vtemp": "tools/subject_meshes/male/s1.ply"},
             object={"params": {"transl": rng.normal(size=(T, 3)), "global_orient": rng.normal(size=(T, 3))},
                     "object_mesh": "tools/object_meshes/contact_meshes/mug.ply"},
             contact={"body": rng.integers(0, 2, (T, 10475)), "object": rng.integers(0, 2, (T, 48))},
             framerate=np.array(120.0), obj_name="mug", gender="male", sbj_id="s1", motion_intent="lift", n_frames=T)
    return full


def test_real_grab_layout_needs_the_pickle_opt_in(tmp_path):
    """GRAB's fullpose (smplx's full_pose: the hand mean already in it) is read as it is and refuses hands_mean;
    per-part hand poses relative to the mean get it added; the template-mesh shape is named in a warning."""
    full = _grab_like(tmp_path / "mug_lift.npz")
    with pytest.raises(SequenceFileError, match="allow_pickle"):
        load_grasp_sequence(tmp_path / "mug_lift.npz")
    mean = np.linspace(-0.1, 0.1, 90)
    with pytest.raises(ValueError, match="hands_mean: .*mug_lift.npz has 'body.params.fullpose'.*already holds"):
        load_grasp_sequence(tmp_path / "mug_lift.npz", allow_pickle=True, hands_mean=mean)
    with pytest.warns(UserWarning, match="body.vtemp.*betas 0"):
        s = load_grasp_sequence(tmp_path / "mug_lift.npz", allow_pickle=True)
    assert s.fps == 30.0 and s.num_frames == 3                     # 9 frames at 120 Hz -> frames 0, 4, 8 at 30 Hz
    assert np.allclose(s.poses[0], full[0].reshape(55, 3), atol=1e-6)
    assert np.allclose(s.poses[1, :1], full[4, :3], atol=1e-5)
    assert s.object_name == "mug" and s.gender == "male" and s.contacts["object"].shape == (3, 48)
    assert not s.betas.any() and str(s.extras["body.vtemp"]).endswith("s1.ply")
    parts = _grab_like(tmp_path / "mug_parts.npz", fullpose=False)
    with pytest.warns(UserWarning, match="body.vtemp"):
        p = load_grasp_sequence(tmp_path / "mug_parts.npz", allow_pickle=True, hands_mean=mean)
    assert np.allclose(p.poses[0, :25], parts[0, :75].reshape(25, 3), atol=1e-6)
    assert np.allclose(p.poses[0, 25:], (parts[0, 75:] + mean).reshape(30, 3), atol=1e-6)


def test_errors_name_the_file_and_key(tmp_path):
    with pytest.raises(SequenceFileError, match="no such"):
        load_grasp_sequence(tmp_path / "missing.npz")
    s = _sequence()
    a = {k: v for k, v in np.load(save_grasp_sequence(tmp_path / "x.npz", s)).items() if k != "object.params.transl"}
    np.savez(tmp_path / "y.npz", **a)
    with pytest.raises(SequenceFileError, match="object.params.transl"):
        load_grasp_sequence(tmp_path / "y.npz")


def _joint_valued_seq(T: int, fps: float) -> GraspSequence:
    """A sequence whose every joint carries its own value (0.01 j about x), with a per-frame contact count."""
    poses = np.zeros((T, 55, 3), np.float32)
    poses[:, :, 0] = 0.01 * np.arange(55)
    return GraspSequence(poses, np.zeros((T, 3)), np.zeros(10), fps, "mug", np.zeros((T, 3)), np.zeros((T, 3)),
                         contacts={"object": (np.arange(T) % 251)[:, None].astype(np.uint8)})


def test_per_part_keys_follow_smplx_joint_order():
    """GRAB's per-part keys in smplx's joint order (smplx.joint_names: 22 jaw, 23 left eye, 24 right eye)."""
    import smplx.joint_names as jn

    from graspkit.data.grab import to_arrays

    a = to_arrays(_joint_valued_seq(2, 30.0))
    for key, name in (("jaw_pose", "jaw"), ("leye_pose", "left_eye_smplhf"), ("reye_pose", "right_eye_smplhf")):
        j = jn.JOINT_NAMES.index(name)
        np.testing.assert_allclose(a[f"body.params.{key}"][0], [0.01 * j, 0, 0], atol=1e-7, err_msg=key)


def test_contacts_are_resampled_with_the_poses(tmp_path):
    """A 120 fps file read at 30 fps keeps every fourth frame, its contacts included."""
    s = load_grasp_sequence(save_grasp_sequence(tmp_path / "s.npz", _joint_valued_seq(121, 120.0)), fps=30.0)
    assert s.num_frames == 31
    np.testing.assert_array_equal(s.contacts["object"][:, 0], 4 * np.arange(31))
