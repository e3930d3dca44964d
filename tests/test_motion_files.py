"""AMASS-style motion files and the Motion class (graspkit.data.formats, graspkit.data.motion): resampling against
scipy's Slerp and read-back round trips, the readers' and writers' checks, atomic writes, slicing, heading, SAGA's
canonical frame and rest-pose joints by hand."""
import os

import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation, Slerp

from graspkit.data import Motion, SequenceFileError, load_motion, save_motion
from graspkit.data.formats import write_npz_atomic
from graspkit.data.motion import canonicalize, heading_of


def _big_turn_motion(T=9, seed=3):
    """Poses whose frames differ by large rotations (many consecutive quaternion pairs with a negative dot)."""
    rng = np.random.default_rng(seed)
    rv = Rotation.random(T * 55, random_state=seed).as_rotvec().reshape(T, 55, 3)
    return Motion(rv, rng.normal(size=(T, 3)), rng.normal(size=10), 30.0)


def test_reading_at_twice_the_rate_slerps_like_scipy_and_reading_back_restores_the_frames(tmp_path):
    """Upsampling 30->60 fps gives 2T-1 frames equal to scipy's Slerp (short way) and linear trans; reading that at
    30 fps again returns the original frames (round trip)."""
    m = _big_turn_motion()
    T = m.num_frames
    up = load_motion(save_motion(tmp_path / "a.npz", m), fps=60)
    assert up.fps == 60.0 and up.num_frames == 2 * T - 1
    f = np.arange(2 * T - 1) / 2.0
    for j in (0, 5, 40):
        ref = Slerp(np.arange(T), Rotation.from_rotvec(m.poses[:, j].astype(np.float64)))(f).as_matrix()
        got = Rotation.from_rotvec(up.poses[:, j].astype(np.float64)).as_matrix()
        np.testing.assert_allclose(got, ref, atol=2e-5)
    ref_tr = np.stack([np.interp(f, np.arange(T), m.trans[:, k]) for k in range(3)], 1)
    np.testing.assert_allclose(up.trans, ref_tr, atol=1e-5)
    back = load_motion(save_motion(tmp_path / "b.npz", up), fps=30)
    assert back.num_frames == T
    np.testing.assert_allclose(Rotation.from_rotvec(back.poses.reshape(-1, 3)).as_matrix(),
                               Rotation.from_rotvec(m.poses.reshape(-1, 3)).as_matrix(), atol=2e-5)


def test_a_goal_on_the_last_frame_stays_on_the_last_frame_at_a_lower_rate(tmp_path):
    """A 30 fps clip of 5 frames due at frame 4 (0.133 s) read at 20 fps has 3 frames (0, 0.05, 0.1 s): the goal
    falls on the nearest existing frame, the last one (hand-computed)."""
    m = Motion(np.zeros((5, 55, 3)), np.zeros((5, 3)), np.zeros(10), 30.0, goal=np.ones(3), goal_frame=4, hand="left")
    r = load_motion(save_motion(tmp_path / "g.npz", m), fps=20)
    assert r.num_frames == 3 and r.goal_frame == 2 and r.hand == "left"


def _base(T=4):
    rng = np.random.default_rng(0)
    return dict(poses=rng.normal(scale=0.2, size=(T, 165)), trans=rng.normal(size=(T, 3)),
                mocap_frame_rate=np.array(30.0))


@pytest.mark.parametrize("extra, key", [
    (dict(contacts=np.full((4, 4), 2, np.uint8)), "contacts"),
    (dict(goal=np.zeros(3), goal_frame=np.array(2.5), hand=np.array("right")), "goal_frame"),
    (dict(mocap_frame_rate=np.array(0.0)), "mocap_frame_rate"),
])
def test_malformed_values_are_refused_naming_the_key(tmp_path, extra, key):
    """Documented reader checks: contacts must be 0/1, goal_frame a whole number, the frame rate positive; the
    SequenceFileError names the file and the key."""
    p = tmp_path / "bad.npz"
    np.savez(p, **{**_base(), **extra})
    with pytest.raises(SequenceFileError, match=key) as e:
        load_motion(p)
    assert "bad.npz" in str(e.value)


def test_any_number_of_betas_keeps_the_first_ten(tmp_path):
    """The module docstring: a file's betas may have any length; the first 10 are kept."""
    p = tmp_path / "b.npz"
    b = np.arange(16, dtype=np.float64)
    np.savez(p, **_base(), betas=b)
    np.testing.assert_array_equal(load_motion(p).betas, b[:10])


def test_a_failed_write_leaves_no_temporary_file_and_keeps_the_old_file(tmp_path):
    """write_npz_atomic's contract: a write that fails (an object array cannot be stored without pickle) leaves
    the folder as it was."""
    p = tmp_path / "x.npz"
    write_npz_atomic(p, {"a": np.arange(3)})
    with pytest.raises(ValueError):
        write_npz_atomic(p, {"a": np.arange(3), "b": np.array([object()], dtype=object)})
    assert sorted(os.listdir(tmp_path)) == ["x.npz"]
    with np.load(p) as z:
        assert z.files == ["a"]


def test_saving_a_motion_with_nan_translation_names_the_field(tmp_path):
    """check_motion's docstring: a ValueError naming the field for non-finite values (here trans)."""
    m = Motion(np.zeros((3, 55, 3)), np.zeros((3, 3)), np.zeros(10))
    m.trans[1, 0] = np.nan                              # the constructor refuses it too: here it came in later
    with pytest.raises(ValueError, match="trans"):
        save_motion(tmp_path / "n.npz", m)
    assert not list(tmp_path.iterdir())


def test_motion_checks_goal_frame_range_fps_type_and_duration():
    """Motion's contract: goal_frame in [0, T), fps a number (a bool is not a frame rate); duration is first to
    last frame, (T-1)/fps (31 frames at 30 fps = 1 s)."""
    z = (np.zeros((4, 55, 3)), np.zeros((4, 3)), np.zeros(10))
    with pytest.raises(ValueError, match="goal_frame"):
        Motion(*z, goal=np.zeros(3), goal_frame=4, hand="right")
    with pytest.raises(TypeError, match="fps"):
        Motion(*z, fps=True)
    assert Motion(np.zeros((31, 55, 3)), np.zeros((31, 3)), np.zeros(10), 30.0).duration == pytest.approx(1.0)


def test_heading_of_a_turned_amass_root():
    """Hand-computed: the AMASS standing root Rx(+90deg) sends the body's +z to world -y (heading -90deg); turning it
    by psi about world z adds psi."""
    psi = np.array([0.0, 0.4, 1.3, -2.0])
    rv = np.stack([(Rotation.from_euler("z", p) * Rotation.from_euler("x", np.pi / 2)).as_rotvec() for p in psi])
    expect = np.angle(np.exp(1j * (psi - np.pi / 2)))
    np.testing.assert_allclose(heading_of(rv), expect, atol=1e-9)


def test_canonical_frame_of_tilted_shoulders_is_a_right_handed_turn_about_z():
    """SAGA A.3, hand-computed: shoulders left (0, .2, 1.4) and right (0, -.2, 1.5) give x = -y_world (horizontal
    part only), y = z cross x = +x_world, z up: R is a -90deg turn about z (det +1), origin the pelvis."""
    j = np.zeros((2, 55, 3))
    from graspkit.body.skeleton import JOINT_INDEX as J
    j[0, J["pelvis"]] = (0.1, 0.2, 0.9)
    j[0, J["left_shoulder"]] = (0.0, 0.2, 1.4)
    j[0, J["right_shoulder"]] = (0.0, -0.2, 1.5)
    R, o = canonicalize(j)
    np.testing.assert_allclose(R, [[0, -1, 0], [1, 0, 0], [0, 0, 1]], atol=1e-12)
    np.testing.assert_allclose(o, (0.1, 0.2, 0.9))


def test_rest_pose_joint_positions_are_the_regressed_shaped_mesh_plus_translation(bm):
    """SMPL-X: at the zero pose the joints are J_regressor applied to the shaped mesh (betas included), moved by trans;
    the mesh comes from Motion.vertices (the full forward pass)."""
    rng = np.random.default_rng(1)
    m = Motion(np.zeros((2, 55, 3)), rng.normal(size=(2, 3)), rng.normal(scale=1.5, size=10))
    v = m.vertices(bm).double()
    ref = torch.einsum("jv,tvc->tjc", bm.J_regressor.double(), v).numpy()
    np.testing.assert_allclose(m.joint_positions(bm), ref, atol=1e-4)


def test_motion_refuses_layouts_it_would_scramble():
    """A (3, T) translation and (55, 3, T) poses were reshaped into scrambled frames (frame 0's translation became the
    first three x values), SMPL-H-width poses were blamed on `trans`, NaN poses were taken and then named `rot_mats`,
    and slice(50, 20) or 0-frame arrays gave a 0-frame clip, whose duration was -1/fps (independent checks). Each is
    refused by name; (T, 165) poses still read as (T, 55, 3)."""
    T = 30
    poses, trans = np.zeros((T, 55, 3), np.float32), np.stack([np.linspace(0, 1, T), np.zeros(T), np.full(T, 0.9)], 1)
    for kw, message in (({"trans": trans.T}, r"^trans: expected \(T, 3\)"),
                        ({"poses": np.moveaxis(poses, 0, -1)}, r"^poses: expected \(T, 55, 3\) or \(T, 165\)"),
                        ({"poses": np.zeros((T, 156))}, "^poses: expected"),
                        ({"poses": np.zeros((T, 63))}, "^poses: expected"),
                        ({"poses": np.full((T, 55, 3), np.nan)}, "^poses: contains NaN"),
                        ({"trans": np.full((T, 3), np.inf)}, "^trans: contains NaN"),
                        ({"poses": poses[:0], "trans": trans[:0]}, r"^poses: expected at least one frame"),
                        ({"poses": poses[:1], "trans": trans[0]}, r"^trans: expected \(T, 3\)"),     # not trans[None]
                        ({"trans": trans[:, :, None]}, r"^trans: expected \(T, 3\)"),
                        ({"poses": np.zeros((T // 2, 55, 6))}, r"^poses: expected \(T, 55, 3\)")):  # 6D, not axis-angle
        with pytest.raises(ValueError, match=message):
            Motion(**{"poses": poses, "trans": trans, "betas": np.zeros(10), **kw})
    m = Motion(poses.reshape(T, 165), trans, np.zeros(10))
    assert m.poses.shape == (T, 55, 3)
    np.testing.assert_allclose(m.trans[0], [0.0, 0.0, 0.9])
    with pytest.raises(ValueError, match=r"^start, stop: frames \[50, 20\) of 30 hold no frame"):
        m.slice(50, 20)
