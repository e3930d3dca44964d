"""MotionFill-VAE's windows (SAGA §3.3, A.3): canonical frame, root states, local motion round trip, images."""
from pathlib import Path

import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

from graspkit.body.markers import saga_sparse_markers
from graspkit.data import load_motion
from graspkit.data import motionfill_dataset as mf
from graspkit.data.motion import Motion
from graspkit.data.motionfill_dataset import CONTACT_HEIGHT, CONTACT_SPEED, geometric_contacts

STUBS = Path(__file__).resolve().parents[1] / "data_stubs" / "motion"


@pytest.fixture(scope="module")
def clips():
    return [load_motion(p) for p in sorted((STUBS / "locomotion").glob("*.npz"))[:3]]


@pytest.fixture(scope="module")
def windows(bm, clips):
    return mf.make_windows(clips, bm, stride=60, progress=False)


def test_window_shapes_and_canonical_frame(windows, bm):
    n = len(windows["traj"])
    assert n >= 3 and windows["traj"].shape == (n, 62, 4) and windows["markers"].shape == (n, 61, 79, 3)
    assert windows["vel"].shape == (n, 61, 3) and windows["contacts"].shape == (n, 61, 4)
    names = saga_sparse_markers(bm).names
    m0 = windows["markers"][:, 0]
    # first pelvis at the origin, heading along +y (gamma = 90 deg), left shoulder at -x of the right one
    np.testing.assert_allclose(windows["traj"][:, 0, :2], 0, atol=1e-5)
    assert (m0[:, names.index("RSHO"), 0] > m0[:, names.index("LSHO"), 0]).all()
    assert (windows["traj"][:, 0, 3] > 0.95).all()
    np.testing.assert_allclose(np.linalg.norm(windows["traj"][..., 2:], axis=-1), 1, atol=1e-5)


def test_local_motion_round_trips_to_the_canonical_markers(windows):
    back = mf.global_motion(windows["local"].astype(np.float64), windows["traj"].astype(np.float64))
    np.testing.assert_allclose(back, windows["markers"], atol=1e-5)


def test_root_velocity_integrates_back_to_the_trajectory(windows):
    traj, vel = windows["traj"][0].astype(np.float64), windows["vel"][0].astype(np.float64)
    g = np.arctan2(traj[:, 3], traj[:, 2])
    p = traj[0, :2].copy()
    for t in range(61):
        c, s = np.cos(g[t]), np.sin(g[t])
        p = p + np.array([c * vel[t, 0] - s * vel[t, 1], s * vel[t, 0] + c * vel[t, 1]])
    np.testing.assert_allclose(p, traj[61, :2], atol=1e-4)
    np.testing.assert_allclose(g[0] + vel[:, 2].sum(), np.unwrap(g)[61], atol=1e-4)


def test_interpolated_trajectory_is_linear_with_one_step_extrapolation():
    traj = np.zeros((62, 4))
    traj[0] = [0, 0, 1, 0]
    traj[60] = [3, -1.5, 0, 1]
    bar = mf.interpolated_trajectory(traj)
    np.testing.assert_allclose(bar[30], [1.5, -0.75, 0.5, 0.5])
    np.testing.assert_allclose(bar[61], traj[60] + (traj[60] - traj[0]) / 60)


def test_windows_are_invariant_to_where_the_clip_happens(bm, clips, windows):
    m = clips[0]
    R = Rotation.from_euler("z", 2.1)
    moved = Motion(poses=m.poses.copy(), trans=m.trans.copy(), betas=m.betas, contacts=m.contacts)
    # turn the whole clip about the world z axis through the origin and shift it
    J0 = m.joint_positions(bm)[:, 0] - m.trans                    # root joint offset (rest), per frame the same
    root = Rotation.from_rotvec(m.poses[:, 0].astype(np.float64))
    moved.poses[:, 0] = (R * root).as_rotvec()
    moved.trans = (R.apply(m.trans + J0) - J0 + np.array([5.0, -3.0, 0.0])).astype(np.float32)
    w = mf.make_windows([moved], bm, stride=60, progress=False)
    k = windows["clip"] == 0
    np.testing.assert_allclose(w["markers"], windows["markers"][k], atol=2e-4)
    np.testing.assert_allclose(w["traj"], windows["traj"][k], atol=2e-4)


def test_short_clip_is_padded_at_the_front_and_approach_windows_end_at_the_last_frame(bm, clips):
    short = clips[0].slice(0, 40)
    w = mf.make_windows([short], bm, progress=False)
    assert len(w["traj"]) == 1
    np.testing.assert_allclose(w["markers"][0, :22], np.repeat(w["markers"][0, :1], 22, 0), atol=1e-6)
    end = mf.make_windows([clips[1]], bm, align_end=True, progress=False)
    full = mf.make_windows([clips[1].slice(clips[1].num_frames - 61)], bm, align_end=True, progress=False)
    np.testing.assert_allclose(end["markers"], full["markers"], atol=1e-6)
    np.testing.assert_allclose(end["traj"][0, 61], end["traj"][0, 60], atol=1e-6)


def test_images_condition_and_normalisation_round_trip(windows):
    stats = mf.MotionFillStats.fit(windows)
    ds = mf.MotionFillDataset(windows, stats)
    item = ds[0]
    assert item["image"].shape == (4, 61, 79 * 3 + 4) and item["cond"].shape == item["image"].shape
    assert (item["cond"][0, 1:60] == 0).all() and torch.equal(item["cond"][0, [0, 60]], item["image"][0, [0, 60]])
    assert torch.equal(item["cond"][1:], item["image"][1:])
    local, contacts, vel = mf.split_image(item["image"][None], stats)
    torch.testing.assert_close(local[0], item["local"], atol=1e-4, rtol=0)
    torch.testing.assert_close(vel[0], item["vel"], atol=1e-5, rtol=0)
    assert torch.equal(contacts[0], item["contacts"])
    x = torch.stack([ds[i]["image"][0, :, :-4] for i in range(len(ds))])
    assert abs(float(x.mean())) < 0.05 and abs(float(x.std()) - 1) < 0.1     # normalised on this (training) set


def test_split_is_deterministic_and_disjoint():
    a, b = mf.split_clips(50, seed=3), mf.split_clips(50, seed=3)
    assert all(np.array_equal(a[k], b[k]) for k in a)
    allc = np.concatenate(list(a.values()))
    assert sorted(allc.tolist()) == list(range(50)) and len(a["train"]) == 40


def test_geometric_contacts_on_a_planted_and_a_lifted_foot():
    t = np.arange(30)[:, None]
    planted = np.zeros((30, 3)) + [0, 0, 0.03]
    swing = np.concatenate([t * 0.05, 0 * t, 0.03 + 0.1 * (t > 5)], 1)
    foot = np.stack([planted, planted, swing, swing], 1)
    c = mf.geometric_contacts(foot)
    assert c[:, :2].all() and not c[10:, 2:].any()
    # a standing start joined to a pose 1 m away (graspkit.saga.synthesize's window): the jump is not a motion
    jump = np.concatenate([np.full((1, 4, 3), [0, 0, 0.03]), np.full((5, 4, 3), [1.0, 0, 0.03])])
    moving, at_rest = mf.geometric_contacts(jump), mf.geometric_contacts(jump, first_at_rest=True)
    assert not moving[0].any() and at_rest[0].all() and np.array_equal(moving[1:], at_rest[1:])


def test_files_round_trip_and_bad_file_is_named(tmp_path, windows):
    p = mf.save_windows(tmp_path / "w.npz", windows)
    back = mf.load_windows(p)
    assert all(np.array_equal(back[k], windows[k]) for k in windows)
    np.savez(tmp_path / "bad.npz", traj=np.zeros(3))
    with pytest.raises(ValueError, match="bad.npz"):
        mf.load_windows(tmp_path / "bad.npz")


def test_yaw_velocity_is_wrapped_across_pi():
    """The root's yaw velocity is wrap(g_t+1 - g_t): a body turning steadily through +-pi has the same yaw velocity
    on every frame, and its ground step is expressed in the heading frame."""
    t = np.arange(mf.NUM_ROOT)
    h = 3.0 + 0.01 * t                                   # crosses pi near t = 14
    traj = np.stack([0.02 * t, np.zeros_like(h), np.cos(h), np.sin(h)], 1)
    _, vel = mf.local_motion(np.zeros((mf.NUM_FRAMES, 79, 3)), traj)
    np.testing.assert_allclose(vel[:, 2], 0.01, atol=1e-9)
    np.testing.assert_allclose(vel[:, 0], 0.02 * np.cos(h[:-1]), atol=1e-9)     # 2 cm along x, turned by -h
    np.testing.assert_allclose(vel[:, 1], -0.02 * np.sin(h[:-1]), atol=1e-9)


def test_a_still_foot_held_above_the_floor_is_not_in_contact():
    """Contacts: 'near the clip's lowest foot height and slow'. The left foot stands on the floor (z = 0); the right
    heel stands there too, the right toe is held still 20 cm up (> CONTACT_HEIGHT above the clip's lowest marker):
    not a contact, however still."""
    n = 20
    foot = np.zeros((n, 4, 3))
    foot[:, :, 0] = [0.0, 0.2, 0.3, 0.5]
    foot[:, 3, 2] = 0.2
    c = geometric_contacts(foot, 30.0)
    assert CONTACT_HEIGHT < 0.2
    assert c[:, :3].all() and not c[:, 3].any()


def test_contact_speed_is_in_metres_per_second():
    """CONTACT_SPEED = 0.2 m/s: a foot marker on the floor sliding at 1 m/s (3.3 cm per frame at 30 fps) is not in
    contact; one creeping at 0.1 m/s is; at 120 fps the same 1 m/s slide is still not a contact."""
    assert CONTACT_SPEED == 0.2
    for fps in (30.0, 120.0):
        n = 30
        t = np.arange(n) / fps
        foot = np.zeros((n, 4, 3))
        foot[:, 0, 0] = 1.0 * t            # sliding at 1 m/s
        foot[:, 1, 0] = 0.1 * t            # creeping at 0.1 m/s
        c = geometric_contacts(foot, fps)
        assert not c[:, 0].any(), fps
        assert c[:, 1].all() and c[:, 2:].all(), fps
