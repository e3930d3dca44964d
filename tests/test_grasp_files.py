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


def test_a_copy_saved_elsewhere_still_points_at_the_mesh(tmp_path):
    """object_mesh is stored relative to the file: a file loaded from one folder and saved in another names the same
    PLY (trimesh reads identical vertices through both), and saving it back beside the mesh gives the first bytes."""
    import trimesh

    from graspkit.data.grab import export_object_ply
    a_dir, b_dir = tmp_path / "a", tmp_path / "b" / "deeper"
    export_object_ply("mug", a_dir / "meshes")
    first = save_grasp_sequence(a_dir / "s.npz", _sequence())
    r = load_grasp_sequence(first)
    assert r.object_mesh == str((a_dir / "meshes" / "mug.ply").absolute())
    copy = save_grasp_sequence(b_dir / "s.npz", r)
    with np.load(copy, allow_pickle=False) as z:
        stored = str(z["object.object_mesh"])
    assert not stored.startswith("/") and (b_dir / stored).resolve() == (a_dir / "meshes" / "mug.ply").resolve()
    want = trimesh.load(a_dir / "meshes" / "mug.ply", process=False).vertices
    assert np.array_equal(trimesh.load(b_dir / stored, process=False).vertices, want)
    assert load_grasp_sequence(copy).object_mesh == r.object_mesh
    assert save_grasp_sequence(a_dir / "t.npz", load_grasp_sequence(copy)).read_bytes() == first.read_bytes()


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


def _small_sequence(T=4, fps=30.0, extras=None):
    """_sequence's layout with 16 object points, at a chosen rate and with chosen extras."""
    rng = np.random.default_rng(0)
    return GraspSequence(rng.normal(scale=0.3, size=(T, 55, 3)), rng.normal(size=(T, 3)), rng.normal(size=10), fps,
                         "mug", rng.normal(size=(T, 3)), rng.normal(size=(T, 3)), "meshes/mug.ply",
                         {"object": rng.random((T, 16)) < 0.3}, dict(extras or {}),
                         rng.normal(size=(16, 3)), rng.normal(size=(16, 3)))


def _rewrite(tmp_path, name, drop=(), **replace):
    """A saved sequence's arrays with keys replaced or dropped, written again with np.savez."""
    good = save_grasp_sequence(tmp_path / "good.npz", _small_sequence())
    with np.load(good) as z:
        arrays = {k: v for k, v in dict(z).items() if k not in drop}
    arrays.update(replace)
    np.savez(tmp_path / name, **arrays)
    return tmp_path / name


def test_grab_malformed_keys_are_refused_naming_file_and_key(tmp_path):
    """Per-frame keys transposed to (3, T), points of 2 columns, points without normals and a NaN in a float contact
    map are malformed files: each read raises SequenceFileError naming the file and the key (module docstring's
    table of shapes)."""
    s = _small_sequence()
    cases = [("transposed.npz", {}, {"object.params.transl": s.object_transl.T.copy()}, "object.params.transl"),
             ("flat.npz", {}, {"object.points": np.zeros((16, 2), np.float32),
                               "object.normals": np.zeros((16, 2), np.float32)}, "object.points"),
             ("alone.npz", ("object.normals",), {}, "object.points"),
             ("nancontact.npz", {}, {"contact.object": np.where(np.eye(4, 16) > 0, np.nan, 0.5)}, "contact.object")]
    for name, drop, replace, key in cases:
        p = _rewrite(tmp_path, name, drop, **replace)
        with pytest.raises(SequenceFileError, match=rf"{name}.*'{key}'"):
            load_grasp_sequence(p)


def test_saving_a_bad_sequence_writes_nothing(tmp_path):
    """save_grasp_sequence refuses a NaN translation, an infinite object orientation and a zero frame rate before
    writing: the folder stays empty (a NaN file would only fail later, when read)."""
    for attr, index, value in (("trans", (1, 2), np.nan), ("object_orient", (0, 0), np.inf)):
        s = _small_sequence()
        getattr(s, attr)[index] = value
        with pytest.raises(ValueError, match="NaN or Inf"):
            save_grasp_sequence(tmp_path / f"{attr}.npz", s)
    with pytest.raises(ValueError, match="fps"):
        save_grasp_sequence(tmp_path / "rate.npz", _small_sequence(fps=0.0))
    assert not list(tmp_path.iterdir())


def test_grab_round_trip_keeps_exactly_the_extras_and_reads_old_style_strings(tmp_path):
    """extras read back are exactly those written (GRAB's own keys, body.model included, are not extras); an integer
    framerate and byte-string (numpy 'S') names, which `_str` decodes, read as 120 Hz and 'mug' / 'male'."""
    s = _small_sequence(extras={"grasp.type": np.array("handle"), "goal.frame": np.array(3)})
    r = load_grasp_sequence(save_grasp_sequence(tmp_path / "a.npz", s))
    assert set(r.extras) == set(s.extras)
    p = _rewrite(tmp_path, "old.npz", framerate=np.array(120), obj_name=np.array(b"mug"), gender=np.array(b"male"))
    old = load_grasp_sequence(p, fps=None)
    assert old.fps == 120.0 and old.object_name == "mug" and old.gender == "male"


def test_contacts_are_resampled_to_the_nearest_source_frame(tmp_path):
    """Read 120 -> 50 fps (a non-integer ratio 2.4), new frame k lies at source frame 2.4 k: its contacts are those of
    the nearest source frame; the body translation (linear) marks the source position, so |contact - x| <= 0.5."""
    T = 25
    poses = np.zeros((T, 55, 3))
    trans = np.zeros((T, 3))
    trans[:, 0] = np.arange(T)
    s = GraspSequence(poses, trans, np.zeros(10), 120.0, "mug", np.zeros((T, 3)), np.zeros((T, 3)),
                      contacts={"object": np.arange(T, dtype=np.uint8)[:, None]})
    r = load_grasp_sequence(save_grasp_sequence(tmp_path / "s.npz", s), fps=50.0)
    np.testing.assert_allclose(r.trans[:, 0], 2.4 * np.arange(r.num_frames), atol=1e-5)
    assert np.abs(r.contacts["object"][:, 0].astype(float) - r.trans[:, 0]).max() <= 0.5 + 1e-6


def test_a_one_frame_file_is_returned_at_the_rate_asked_for(tmp_path):
    """A one-frame file has nothing to resample, but load_grasp_sequence(fps=30) still returns it at 30 fps as its
    docstring says (not at the 120 fps it was stored at); fps=None keeps the stored rate."""
    s = _small_sequence(T=1, fps=120.0)
    p = save_grasp_sequence(tmp_path / "one.npz", s)
    assert load_grasp_sequence(p, fps=30.0).fps == 30.0 and load_grasp_sequence(p, fps=None).fps == 120.0


def test_resampling_moves_the_goal_frame_with_the_frames(tmp_path):
    """An approach clip read at another rate kept grasp.goal_frame at the file's rate: at 15 fps past the clip's end,
    at 60 fps on the wrong frame (an independent check). It now follows the frames, as formats.resample moves a
    motion's goal frame (frame g at src -> round(g fps / src))."""
    seq = _joint_valued_seq(81, 30.0)
    seq.extras["grasp.goal_frame"] = np.array(46)
    path = save_grasp_sequence(tmp_path / "a.npz", seq)
    for fps, want in ((15.0, 23), (60.0, 92), (30.0, 46)):
        s = load_grasp_sequence(path, fps=fps)
        g = int(s.extras["grasp.goal_frame"])
        assert g == want and g < s.num_frames
        np.testing.assert_allclose(s.poses[g], seq.poses[46], atol=1e-5)      # the same instant of the clip


def test_a_clip_of_an_object_outside_the_catalogue_is_named_by_its_file(tmp_path):
    """The splits are by catalogue object: a clip whose obj_name is 'teapot' failed with "name: unknown object" (split_of's
    parameter), naming neither the file nor the key, among hundreds of clips; every reader that splits names both."""
    import shutil

    from graspkit.data.grasp_datasets import grasp_files
    from graspkit.eval_goal import _files
    from graspkit.eval_motionfill import approach_motions
    from graspkit.paths import DATA_STUBS

    for i in range(2):
        shutil.copy(DATA_STUBS / "approach" / f"approach_00000{i}.npz", tmp_path)
    bad = tmp_path / "approach_000001.npz"
    with np.load(bad, allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    arrays["obj_name"] = np.array("teapot")
    np.savez(bad, **arrays)
    for read in (lambda: grasp_files(tmp_path, "approach", split="train"), lambda: _files(tmp_path, "approach", "test"),
                 lambda: approach_motions(tmp_path)):
        with pytest.raises(SequenceFileError, match=r"approach_000001\.npz: key 'obj_name' is 'teapot', expected a catalogue"):
            read()
    assert len(grasp_files(tmp_path, "approach")) == 2                  # no split asked: no object needed
