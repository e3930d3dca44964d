"""MNet (GOAL §3.4, Eq. 9-13): canonical frames against the body model, invariance, round trips, loss, rollout."""
import math
from pathlib import Path

import pytest
import torch

from graspkit.body import BodyModel
from graspkit.body._proc_correctives import subtree
from graspkit.body.markers import goal_vertices
from graspkit.body.skeleton import JOINT_INDEX as J, PARENTS
from graspkit.models import mnet as M
from graspkit.models.gnet import SparseBody, pose_rotmats
from graspkit.models.mnet import (MNet, MNetConfig, MNetLossWeights, MNetState, apply_changes, canonical_frame,
                                  feet_mask, heading, mnet_inputs, mnet_loss, mnet_targets, rest_root, rollout,
                                  transform_params, transform_points)
from graspkit.objects.bps import bps_basis
from graspkit.objects.contact import IAA_WEIGHT
from graspkit.optim.goal_refine import hand_object_offsets
from graspkit.paths import default_model_path
from graspkit.rotations import axis_angle_to_rot6d, rotation_about_z


@pytest.fixture(scope="module")
def setup():
    bm = BodyModel.from_file(default_model_path(), flat_hand_mean=True)
    gv = goal_vertices(bm)
    return bm, gv, SparseBody(bm, torch.as_tensor(gv.vertex_ids))


def _random_params(B, T, seed):
    g = torch.Generator().manual_seed(seed)
    aa = 0.2 * torch.randn(B, T, 55, 3, generator=g)
    aa[..., 0, :] = torch.tensor([math.pi / 2, 0, 0]) + 0.3 * torch.randn(B, T, 3, generator=g)
    return axis_angle_to_rot6d(aa), torch.randn(B, T, 3, generator=g) * torch.tensor([1.0, 1.0, 0.05]), \
        0.5 * torch.randn(B, 10, generator=g)


def _state(body, rot6d, transl, betas, obj, goal_hand):
    """MNetState at the last of 6 frames (5 past + the previous one for velocities)."""
    B = len(betas)
    v = body(pose_rotmats(rot6d[:, -2:].reshape(-1, 55, 6)), betas.repeat_interleave(2, 0),
             transl[:, -2:].reshape(-1, 3))[0].reshape(B, 2, -1, 3)
    return MNetState(rot6d[:, -5:], transl[:, -5:], betas, v[:, 1], v[:, 0], goal_hand, obj.mean(1),
                     hand_object_offsets(v[:, 1], obj), rest_root(body.bm, betas))


def test_transform_params_moves_the_mesh_rigidly(setup):
    bm, _, _ = setup
    rot6d, transl, betas = _random_params(3, 1, 0)
    rot6d, transl = rot6d[:, 0], transl[:, 0]
    R = rotation_about_z(torch.tensor([0.3, -2.0, 1.1]))
    o = torch.tensor([[0.5, -0.2, 0.0], [1.0, 2.0, 0.0], [-0.3, 0.1, 0.0]])
    before = bm.forward_rotmats(pose_rotmats(rot6d), betas=betas, transl=transl).vertices
    r2, t2 = transform_params(rot6d, transl, rest_root(bm, betas), R, o)
    after = bm.forward_rotmats(pose_rotmats(r2), betas=betas, transl=t2).vertices
    torch.testing.assert_close(after, transform_points(before, R, o), atol=2e-5, rtol=0)


def test_canonical_frame_puts_the_body_at_the_origin_facing_y(setup):
    bm, _, _ = setup
    rot6d, transl, betas = _random_params(4, 1, 1)
    root = rest_root(bm, betas)
    R, o = canonical_frame(pose_rotmats(rot6d[:, 0, 0]), root + transl[:, 0])
    r2, t2 = transform_params(rot6d[:, 0], transl[:, 0], root, R, o)
    torch.testing.assert_close(heading(pose_rotmats(r2[:, 0])), torch.full((4,), math.pi / 2), atol=1e-5, rtol=0)
    pelvis = root + t2
    torch.testing.assert_close(pelvis[:, :2], torch.zeros(4, 2), atol=1e-5, rtol=0)
    torch.testing.assert_close(pelvis[:, 2], (root + transl[:, 0])[:, 2], atol=1e-5, rtol=0)


def test_inputs_do_not_change_when_the_whole_scene_turns_and_moves(setup):
    bm, gv, body = setup
    rot6d, transl, betas = _random_params(2, 6, 2)
    g = torch.Generator().manual_seed(3)
    obj = torch.randn(2, 200, 3, generator=g) * 0.05 + torch.tensor([0.5, 0.5, 0.9])
    goal_hand = torch.randn(2, 99, 3, generator=g) * 0.05 + torch.tensor([0.5, 0.45, 0.9])
    basis = bps_basis()
    f1, _, _ = mnet_inputs(_state(body, rot6d, transl, betas, obj, goal_hand), basis)
    R = rotation_about_z(torch.tensor([0.7, -1.9]))                       # the world turns and shifts (x -> R(x - o))
    o = torch.tensor([[0.3, -1.0, 0.0], [2.0, 0.5, 0.0]])
    r2, t2 = transform_params(rot6d, transl, rest_root(bm, betas), R, o)
    f2, _, _ = mnet_inputs(_state(body, r2, t2, betas, transform_points(obj, R, o),
                                  transform_points(goal_hand, R, o)), basis)
    for k in f1:
        torch.testing.assert_close(f1[k], f2[k], atol=2e-4, rtol=1e-4)


def test_targets_round_trip_to_the_future_frames(setup):
    bm, gv, body = setup
    rot6d, transl, betas = _random_params(2, 16, 4)
    g = torch.Generator().manual_seed(5)
    obj = torch.randn(2, 200, 3, generator=g) * 0.05
    s = _state(body, rot6d[:, :6], transl[:, :6], betas, obj, torch.zeros(2, 99, 3))
    _, R, o = mnet_inputs(s, bps_basis())
    fut_v = body(pose_rotmats(rot6d[:, 6:].reshape(-1, 55, 6)), betas.repeat_interleave(10, 0),
                 transl[:, 6:].reshape(-1, 3))[0].reshape(2, 10, -1, 3)
    tgt = mnet_targets(s, R, o, rot6d[:, 6:], transl[:, 6:], fut_v,
                       hand_object_offsets(fut_v.reshape(20, -1, 3), obj.repeat_interleave(10, 0)).reshape(2, 10, -1, 3))
    r_now, t_now = transform_params(s.rot6d[:, -1], s.transl[:, -1], s.root, R, o)
    r_c, t_c = apply_changes(r_now, t_now, tgt)
    v_c = body(pose_rotmats(r_c.reshape(-1, 55, 6)), betas.repeat_interleave(10, 0), t_c.reshape(-1, 3))[0]
    torch.testing.assert_close(v_c.reshape(2, 10, -1, 3), transform_points(fut_v, R, o), atol=5e-5, rtol=0)
    torch.testing.assert_close(transform_points(s.verts, R, o)[:, None] + tgt["d_verts"], transform_points(fut_v, R, o),
                               atol=1e-5, rtol=0)


def test_network_shapes_variants_and_loss(setup):
    B = 3
    for cfg, keys in ((MNetConfig(), {"d_rot6d", "d_transl", "d_verts", "d_hand_obj"}),
                      (MNetConfig(attention=False, outputs="pose", n_future=1), {"d_rot6d", "d_transl"})):
        net = MNet(cfg)
        iaa = 1600 if cfg.attention else 1200
        feats = {"pose": torch.randn(B, 5 * 333 + 10), "verts": torch.randn(B, 2400), "goal": torch.randn(B, 297 + 1024),
                 "iaa": torch.randn(B, iaa)}
        out = net(feats)
        assert set(out) == keys and out["d_rot6d"].shape == (B, cfg.n_future, 55, 6)
        tgt = {"d_rot6d": torch.randn(B, cfg.n_future, 55, 6), "d_transl": torch.randn(B, cfg.n_future, 3),
               "d_verts": torch.randn(B, cfg.n_future, 400, 3), "d_hand_obj": torch.randn(B, cfg.n_future, 99, 3)}
        net.fit_normalisation(feats, tgt)
        mean = net(feats)                                          # untrained: the mean change of the data
        torch.testing.assert_close(mean["d_transl"], tgt["d_transl"].mean(0).expand(B, -1, -1), atol=1e-5, rtol=1e-5)
        truth = {k: tgt[k] for k in keys}
        assert float(mnet_loss(truth, tgt, feet_mask(torch.zeros(B, cfg.n_future, 400), torch.arange(139, 179)))["loss"]) == 0
        with pytest.raises(ValueError, match=r"feats\['goal'\]: expected shape \(B, 1321\)"):
            net({**feats, "goal": torch.randn(B, 1000)})      # was torch's "size of tensor a (1000) must match"
        with pytest.raises(ValueError, match=r"feats\['iaa'\]: .*got missing"):
            net({k: v for k, v in feats.items() if k != "iaa"})
    with pytest.raises(ValueError, match="outputs"):
        MNet(MNetConfig(outputs="markers"))


def _loss_pair(err_at):
    """MNet outputs equal to their targets but for 1 cm on every coordinate of the vertices `err_at` (B = 2, 10
    frames)."""
    B, F = 2, 10
    tgt = {"d_rot6d": torch.zeros(B, F, 55, 6), "d_transl": torch.zeros(B, F, 3), "d_verts": torch.zeros(B, F, 400, 3),
           "d_hand_obj": torch.zeros(B, F, 99, 3)}
    out = {k: v.clone() for k, v in tgt.items()}
    out["d_verts"][:, :, err_at] += 0.01
    return out, tgt


def test_loss_foot_term_is_over_the_masked_vertices_and_the_hand_term_over_the_first_99():
    """Eq. 11: the foot term is the mean error of the vertices the mask holds on the floor (one vertex in one frame
    here: 1 cm), and L_v^h reads the 99 hand vertices, which come first (1 cm there, 0 for an error elsewhere)."""
    out, tgt = _loss_pair([350])
    foot = torch.zeros(2, 10, 400)
    foot[0, 3, 350] = 1.0
    torch.testing.assert_close(mnet_loss(out, tgt, foot)["feet"], torch.tensor(0.01), atol=1e-7, rtol=0)
    out, tgt = _loss_pair(list(range(99)))
    torch.testing.assert_close(mnet_loss(out, tgt)["v_hand"], torch.tensor(0.01), atol=1e-7, rtol=0)
    out, tgt = _loss_pair(list(range(99, 400)))
    assert float(mnet_loss(out, tgt)["v_hand"]) == 0.0


def test_feet_mask_selects_low_foot_vertices():
    z = torch.tensor([[[0.01, 0.2, 0.03, 0.0]]])
    m = feet_mask(z, torch.tensor([1, 2]))
    assert m.tolist() == [[[0.0, 0.0, 1.0, 0.0]]]


def _bent_elbow_args(body, elbow: float) -> tuple:
    """`rollout`'s positional arguments for an untrained MNet (it predicts no change: the body stands still) whose
    goal is a standing body with the right arm raised and whose start is the same body with the right elbow bent
    `elbow` rad more; the object is a cloud 2 cm beside the goal hand."""
    aa = torch.zeros(55, 3)
    aa[0] = torch.tensor([math.pi / 2, 0, 0])
    aa[J["right_shoulder"]] = torch.tensor([0, 0, 0.9])
    goal = (axis_angle_to_rot6d(aa), torch.zeros(3))
    aa2 = aa.clone()
    aa2[J["right_elbow"]] += torch.tensor([0.0, elbow, 0.0])
    obj = body(pose_rotmats(goal[0][None]), torch.zeros(1, 10), goal[1][None])[0][0, :99] + 0.02
    return MNet(), body, (axis_angle_to_rot6d(aa2), torch.zeros(3)), goal, torch.zeros(10), obj, obj.mean(0), bps_basis()


def test_rollout_reaches_a_nearby_goal_by_the_refinement_alone(setup):
    """An untrained MNet predicts no change (the body stands still); Eq. 12-13 must carry the hand to the goal."""
    out = rollout(*_bent_elbow_args(setup[2], 0.25), max_frames=60, reach_tol=0.01, min_speed=0.004)  # ~5 cm off
    assert out.first_refined == 1 and out.reached
    assert 0.03 < float(out.hand_dist[0]) < 0.1 and float(out.hand_dist[-1]) <= 0.01
    assert len(out.rot6d) < 25                                     # ~4 mm per frame: about 10-15 frames
    torch.testing.assert_close(out.transl[:, :2], torch.zeros(len(out.transl), 2), atol=5e-3, rtol=0)  # body stays


def test_rollout_stall_rule_refines_a_hand_stopped_beyond_10_cm(setup):
    """graspkit's stall rule (not GOAL's): an untrained MNet stands still with the hand 12-20 cm from the goal hand,
    outside Eq. 12-13's 10 cm; without the rule the rollout runs to its maximum there, with it the refinement starts
    once `stall` frames have brought no progress and carries the hand to the goal, the body within 1 cm of where it
    stood. A stall window that is not a whole number of frames >= 1 is refused by name."""
    args = _bent_elbow_args(setup[2], 0.5)
    paper = rollout(*args, max_frames=80, min_speed=0.004)
    assert 0.12 < float(paper.hand_dist[0]) < 0.2 and not paper.reached and paper.first_refined is None
    assert len(paper.rot6d) == 80
    ours = rollout(*args, max_frames=150, min_speed=0.004, stall=10)
    assert ours.first_refined == 11 and ours.reached                   # frames 1-10 stand still, then the refinement
    assert float(ours.hand_dist[-1]) <= 0.01
    assert float(ours.transl[:, :2].norm(dim=-1).max()) < 0.01         # the arm reaches; the body moves < 1 cm
    for bad in (0, -3, 2.5, True):
        with pytest.raises(ValueError, match="stall"):
            rollout(*args, max_frames=20, stall=bad)


def test_rollout_far_from_the_goal_runs_to_the_maximum(setup):
    bm, gv, body = setup
    aa = torch.zeros(55, 3)
    aa[0] = torch.tensor([math.pi / 2, 0, 0])
    start = (axis_angle_to_rot6d(aa), torch.zeros(3))
    goal = (axis_angle_to_rot6d(aa), torch.tensor([0.0, -1.0, 0.0]))
    for stall in (None, 10):               # the stall rule leaves a hand 1 m off alone: it is a start, not a stall
        out = rollout(MNet(), body, start, goal, torch.zeros(10), torch.randn(50, 3) * 0.05, torch.zeros(3),
                      bps_basis(), max_frames=35, stall=stall)
        assert len(out.rot6d) == 35 and not out.reached and out.first_refined is None
        torch.testing.assert_close(out.hand_dist, torch.full((35,), 1.0), atol=1e-4, rtol=0)  # standing still, 1 m away


def test_rollout_floor_step_raises_sinking_frames_onto_the_floor_and_leaves_others(setup):
    """graspkit's floor step (not GOAL's): an untrained MNet keeps the body where it stands; with a floor 3 cm above
    its soles every generated frame is raised until its lowest vertex (the full mesh, read here with the body model)
    is on that floor, and a floor below the soles changes nothing."""
    bm, gv, body = setup
    aa = torch.zeros(55, 3)
    aa[0] = torch.tensor([math.pi / 2, 0, 0])
    start = (axis_angle_to_rot6d(aa), torch.zeros(3))
    goal = (start[0], torch.tensor([0.0, -1.0, 0.0]))
    obj = torch.randn(50, 3, generator=torch.Generator().manual_seed(0)) * 0.05
    low0 = float(bm.forward_rotmats(pose_rotmats(start[0][None]), betas=torch.zeros(1, 10)).vertices[0, :, 2].min())
    args = (MNet(), body, start, goal, torch.zeros(10), obj, torch.zeros(3), bps_basis())
    free = rollout(*args, max_frames=12)
    up = rollout(*args, max_frames=12, floor=low0 + 0.03)
    low = bm.forward_rotmats(pose_rotmats(up.rot6d), betas=torch.zeros(12, 10), transl=up.transl).vertices[..., 2].amin(-1)
    torch.testing.assert_close(low[1:], torch.full((11,), low0 + 0.03), atol=2e-4, rtol=0)   # frame 0 is the start
    torch.testing.assert_close(up.transl[1:, :2], free.transl[1:, :2])
    below = rollout(*args, max_frames=12, floor=low0 - 0.03)
    torch.testing.assert_close(below.transl, free.transl)


def _reach_clips(n=2):
    """Reaching clips from data_stubs as approach clips: a 4 cm ball of points at the reaching goal."""
    from pathlib import Path

    from graspkit.data import load_motion
    from graspkit.models.mnet import ApproachClip
    g = torch.Generator().manual_seed(0)
    out = []
    for p in sorted(Path(default_model_path()).parents[2].joinpath("motion", "reach").glob("*.npz"))[:n]:
        m = load_motion(p)
        ball = torch.nn.functional.normalize(torch.randn(300, 3, generator=g), dim=-1) * 0.04 + torch.as_tensor(m.goal)
        out.append(ApproachClip(axis_angle_to_rot6d(torch.as_tensor(m.poses)), torch.as_tensor(m.trans),
                                torch.as_tensor(m.betas), m.goal_frame, ball, torch.as_tensor(m.goal), p.stem))
    return out


def test_windows_hold_the_clip_and_pad_its_ends(setup):
    from graspkit.models.mnet import MNetWindows
    bm, gv, body = setup
    clips = _reach_clips(2)
    w = MNetWindows(clips, body, bps_basis())
    T0 = len(clips[0].rot6d)
    assert len(w) == T0 + len(clips[1].rot6d)
    feats, tgt, foot = w.batch(torch.tensor([0, T0 - 1, T0 + 5]))
    assert feats["pose"].shape == (3, 5 * 333 + 10) and feats["iaa"].shape == (3, 1600)
    for k in ("d_rot6d", "d_transl", "d_verts", "d_hand_obj"):               # the last frame holds: no change
        assert float(tgt[k][1].abs().max()) == 0.0
    s = w.state(torch.tensor([0, T0 + 5]))
    assert torch.equal(s.rot6d[0], clips[0].rot6d[:1].float().expand(5, -1, -1))   # a static start before frame 0
    assert torch.equal(s.rot6d[1], clips[1].rot6d[1:6].float())
    assert foot.shape == (3, 10, 400) and 0 < float(foot.sum())                  # standing: sampled soles on the floor


def test_window_targets_are_the_next_ten_frames(setup):
    """Eq. 10: a window's targets are frames t+1 .. t+10 as changes from frame t, in frame t's canonical frame (a
    rotation and a shift): the vertex changes have the lengths of the world displacements from t to t + k."""
    from graspkit.models.mnet import MNetWindows
    bm, gv, body = setup
    w = MNetWindows(_reach_clips(1), body, bps_basis())
    t = 40
    _, tgt, _ = w.batch(torch.tensor([t]))
    want = (w.verts[t + 1:t + 11] - w.verts[t]).norm(dim=-1)                 # (10, 400)
    assert float(want[0].max()) > 1e-3                                        # the body moves at frame 40
    torch.testing.assert_close(tgt["d_verts"][0].norm(dim=-1), want, atol=1e-5, rtol=1e-5)


def test_mnet_learns_the_reaching_windows(setup):
    from graspkit.models.mnet import MNetWindows, train_mnet
    from graspkit.train import TrainConfig
    bm, gv, body = setup
    w = MNetWindows(_reach_clips(2), body, bps_basis(), stride=2)
    net, hist = train_mnet(w, None, train_cfg=TrainConfig(epochs=15, batch_size=32, lr=2e-3), progress=False)
    assert hist[-1]["loss"] < 0.5 * hist[0]["loss"] and hist[-1]["v"] < 0.5 * hist[0]["v"]


def test_horizon_prediction_of_a_standing_mnet_is_the_current_pose(setup):
    """A 1-frame MNet that predicts no change, rolled ten steps, repeats frame t: each V2V column is the mean distance
    (mm) the true motion moves since t over its vertices: the whole body; the right hand = the vertices skinned mostly
    to the right wrist or a joint below it (all three finger segments); the feet = to an ankle or below (the toes)."""
    from graspkit.eval_goal import teacher_forced_v2v
    from graspkit.models.mnet import MNetWindows
    bm, gv, body = setup
    w = MNetWindows(_reach_clips(1), body, bps_basis())
    net = MNet(MNetConfig(n_future=1)).train()
    idx = torch.tensor([40])
    got = teacher_forced_v2v(mnet=net, windows=w, bm=bm, index=idx, horizon=10)   # keywords pass the eval wrapper
    assert net.training                                    # it and predict_horizon restore the mode they found
    t = int(w.windows[40])
    now = bm.forward_rotmats(pose_rotmats(w.rot6d[t:t + 1]), betas=w.betas[:1], transl=w.transl[t:t + 1]).vertices
    fut = bm.forward_rotmats(pose_rotmats(w.rot6d[t + 1:t + 11]), betas=w.betas[:1].expand(10, -1),
                             transl=w.transl[t + 1:t + 11]).vertices
    d = (fut - now).norm(dim=-1)                                                  # (10, V) m
    assert bm.parents.tolist() == list(PARENTS)
    part = bm.lbs_weights.argmax(1)
    hand_joints = subtree(J["right_wrist"])
    hand = torch.isin(part, torch.tensor(hand_joints))
    feet = torch.isin(part, torch.tensor(subtree(J["left_ankle"]) + subtree(J["right_ankle"])))
    assert len(hand_joints) == 16 and int(hand.sum()) > 100 and int(feet.sum()) > 100
    assert got.body == pytest.approx(1000 * float(d.mean()), rel=1e-3)
    assert got.hand == pytest.approx(1000 * float(d[:, hand].mean()), rel=1e-3)
    assert got.feet == pytest.approx(1000 * float(d[:, feet].mean()), rel=1e-3)
    assert abs(got.hand - got.feet) > 1.0                     # the columns differ: the reaching hand moves, the feet less


def test_window_features_match_the_direct_computation(setup):
    """Offsets (KD-tree) and goal-hand BPS (turned basis) of the windows equal mnet_inputs' own computation."""
    from graspkit.models.mnet import MNetWindows
    bm, gv, body = setup
    w = MNetWindows(_reach_clips(1), body, bps_basis())
    idx = torch.tensor([0, 17, 50])
    s = w.state(w.windows[idx])
    torch.testing.assert_close(s.obj_offsets, hand_object_offsets(s.verts, w.points[w.clip[w.windows[idx]]]),
                               atol=1e-6, rtol=0)
    direct, _, _ = mnet_inputs(s, bps_basis())
    stored, _ = w.batch(idx)[:2]
    for k in direct:
        torch.testing.assert_close(stored[k], direct[k], atol=1e-5, rtol=1e-5)


def test_goal_repeat_adds_the_windows_near_the_goal_and_vel_noise_moves_only_velocities(setup):
    from graspkit.models.mnet import MNetWindows
    bm, gv, body = setup
    clips = _reach_clips(1)
    w1 = MNetWindows(clips, body, bps_basis())
    w3 = MNetWindows(clips, body, bps_basis(), goal_repeat=3, goal_span=(-30, 5))
    g, T = clips[0].goal_frame, len(clips[0].rot6d)
    near = [t for t in range(T) if -30 <= t - g <= 5]
    assert len(w3) == len(w1) + 2 * len(near)
    assert sorted(w3.windows[len(w1):].tolist()) == sorted(near * 2)
    torch.manual_seed(0)
    clean, _, _ = w1.batch(torch.tensor([10, 20]))
    noisy, _, _ = w1.batch(torch.tensor([10, 20]), vel_noise=0.01)
    for k in ("pose", "goal", "iaa"):                                          # only v̇_t (in 'verts') changes
        torch.testing.assert_close(noisy[k], clean[k])
    assert not torch.allclose(noisy["verts"], clean["verts"])


def test_refinement_starts_the_frame_after_the_hand_enters_10_cm(setup):
    """§3.4: 10 frames a step while far; once the hand comes within 10 cm of the goal hand the rest of that step is
    dropped and the motion goes on one refined frame at a time. A stand-in MNet walking the body 2 cm a frame
    towards a goal 25 cm ahead: the hand enters the 10 cm ball at frame 8, mid-step, and frame 9 is refined."""
    from graspkit.optim.goal_refine import GOAL_HAND_RADIUS

    bm, gv, body = setup
    net = MNet(MNetConfig())
    fd = net.frame_dim
    with torch.no_grad():                       # its decoder's weights are zero: the output is norm_out's mean
        for k in range(10):
            net.norm_out.mean[k * fd + 55 * 6 + 1] = 0.02 * (k + 1)      # d_transl along the canonical heading
    aa = torch.zeros(55, 3)
    aa[0] = torch.tensor([math.pi / 2, 0, 0])                              # standing, facing world -y
    r6 = axis_angle_to_rot6d(aa)
    start, goal = (r6, torch.zeros(3)), (r6, torch.tensor([0.0, -0.25, 0.0]))
    pts = torch.randn(200, 3, generator=torch.Generator().manual_seed(0)) * 0.02 + torch.tensor([0.3, -0.6, 0.9])
    r = rollout(net, body, start, goal, torch.zeros(10), pts, pts.mean(0), bps_basis(), max_frames=16)
    d = r.hand_dist
    torch.testing.assert_close(d[:9], 0.25 - 0.02 * torch.arange(9.0), atol=2e-4, rtol=0)
    first_in = int(torch.nonzero(d < GOAL_HAND_RADIUS)[0, 0])
    assert first_in == 8 and r.first_refined == first_in + 1


def _clip(path, frames: int, g: torch.Generator):
    """The first `frames` frames of a reaching clip as an approach clip (a 4 cm ball of points at its goal)."""
    from graspkit.data import load_motion
    m = load_motion(path)
    ball = torch.nn.functional.normalize(torch.randn(200, 3, generator=g), dim=-1) * 0.04 + torch.as_tensor(m.goal)
    return M.ApproachClip(axis_angle_to_rot6d(torch.as_tensor(m.poses[:frames])), torch.as_tensor(m.trans[:frames]),
                          torch.as_tensor(m.betas), min(m.goal_frame, frames - 1), ball, torch.as_tensor(m.goal))


def test_a_clips_first_window_repeats_its_first_frame_as_the_previous_one(setup):
    """MNetWindows repeats a clip's first frame before its start: frame t-1 of a clip's first window is that first
    frame (no velocity), never the previous clip's last frame."""
    body = setup[2]
    files = sorted(Path(default_model_path()).parents[2].joinpath("motion", "reach").glob("*.npz"))[:2]
    g = torch.Generator().manual_seed(0)
    clips = [_clip(files[0], 20, g), _clip(files[1], 20, g)]
    w = M.MNetWindows(clips, body, bps_basis())
    c = clips[1]
    with torch.no_grad():
        v0 = body(pose_rotmats(c.rot6d[:1].float()), c.betas.reshape(1, -1).float(), c.transl[:1].float())[0][0]
        v_last_of_clip0 = body(pose_rotmats(clips[0].rot6d[-1:].float()), clips[0].betas.reshape(1, -1).float(),
                               clips[0].transl[-1:].float())[0][0]
    assert float((v0 - v_last_of_clip0).norm(dim=-1).max()) > 0.01          # the two clips do not join up
    s = w.state(torch.tensor([20]))                                           # clip 1, frame 0
    torch.testing.assert_close(s.verts[0], v0, atol=1e-5, rtol=0)
    torch.testing.assert_close(s.verts_prev[0], v0, atol=1e-5, rtol=0)         # a static start: no velocity
    feats, _, _ = w.batch(torch.tensor([20]))
    vel = feats["verts"][0, 3 * 400:]                                          # (v_t - v_{t-1}) in the canonical frame
    assert float(vel.abs().max()) < 1e-5


def test_rollout_gives_mnet_the_current_and_the_previous_frames_vertices(setup, monkeypatch):
    """The rollout hands MNet the vertices of frame t as `verts` and of frame t-1 as `verts_prev` (MNetState), here on a
    stand-in MNet that walks 2 cm further per future frame."""
    body = setup[2]
    torch.manual_seed(0)
    net = M.MNet().eval()
    F, D = net.cfg.n_future, net.frame_dim
    mean = torch.zeros(F, D)
    mean[:, 330] = 0.02 * torch.arange(1, F + 1)          # canonical x: 2 cm more per future frame (a steady walk)
    net.norm_out.mean.copy_(mean.reshape(-1))
    seen = []
    real_step = M.mnet_step
    monkeypatch.setattr(M, "mnet_step", lambda mnet, s, basis: (seen.append(s), real_step(mnet, s, basis))[1])
    aa = torch.zeros(55, 3)
    aa[0] = torch.tensor([math.pi / 2, 0, 0])
    start = (axis_angle_to_rot6d(aa), torch.zeros(3))
    betas = torch.zeros(10)
    goal = (start[0], torch.tensor([5.0, 5.0, 0.0]))                    # far away: MNet's 10-frame steps all the way
    obj = torch.tensor([5.0, 5.0, 1.0]) + 0.03 * torch.randn(100, 3)
    r = M.rollout(net, body, start, goal, betas, obj, obj.mean(0), bps_basis(), max_frames=25, refine=False)
    assert len(seen) >= 2
    with torch.no_grad():
        verts = body(pose_rotmats(r.rot6d), betas.expand(len(r.rot6d), -1), r.transl)[0]
    step = (verts[1:] - verts[:-1]).norm(dim=-1).mean(-1)
    assert float(step[1:].min()) > 1e-3                                        # the body moves from frame to frame
    n = 1
    for s in seen:
        torch.testing.assert_close(s.verts[0], verts[n - 1], atol=1e-5, rtol=0)                 # frame t
        torch.testing.assert_close(s.verts_prev[0], verts[max(n - 2, 0)], atol=1e-5, rtol=0)     # frame t - 1
        n += F


def test_floor_attention_reads_each_vertex_height_above_the_floor():
    """Eq. 9's attention inputs end with exp(-w max(h, 0)) of each of the 400 vertices, h its height above the floor
    (z up; the canonical frame turns about z and moves along the floor only). Truth: the world vertices' z."""
    bm = BodyModel.from_file(default_model_path(), flat_hand_mean=True)
    body = SparseBody(bm, torch.as_tensor(goal_vertices(bm).vertex_ids))
    g = torch.Generator().manual_seed(7)
    aa = 0.2 * torch.randn(2, 6, 55, 3, generator=g)
    aa[..., 0, :] = torch.tensor([math.pi / 2, 0, 0]) + 0.3 * torch.randn(2, 6, 3, generator=g)
    rot6d = axis_angle_to_rot6d(aa)
    transl = torch.randn(2, 6, 3, generator=g) * torch.tensor([1.0, 1.0, 0.05])
    betas = 0.5 * torch.randn(2, 10, generator=g)
    v = body(pose_rotmats(rot6d[:, -2:].reshape(-1, 55, 6)), betas.repeat_interleave(2, 0),
             transl[:, -2:].reshape(-1, 3))[0].reshape(2, 2, -1, 3)
    obj = torch.randn(2, 200, 3, generator=g) * 0.05 + torch.tensor([0.5, 0.5, 0.9])
    goal_hand = torch.randn(2, 99, 3, generator=g) * 0.05 + torch.tensor([0.5, 0.45, 0.9])
    s = MNetState(rot6d[:, -5:], transl[:, -5:], betas, v[:, 1], v[:, 0], goal_hand, obj.mean(1),
                  hand_object_offsets(v[:, 1], obj), rest_root(bm, betas))
    feats, _, _ = mnet_inputs(s, bps_basis())
    want = torch.exp(-IAA_WEIGHT * s.verts[..., 2].clamp_min(0))
    assert float(s.verts[..., 2].std()) > 0.1                            # heights vary over the body
    torch.testing.assert_close(feats["iaa"][:, 3 * 400:], want, atol=1e-5, rtol=1e-4)


@pytest.mark.parametrize("w", [None, MNetLossWeights(v=5.0, v_hand=7.0, theta=3.0, d=11.0)])
def test_eq11_loss_is_the_weighted_sum_of_its_terms(w):
    """Eq. 11: L = lambda_theta L_theta + lambda_v L_v + lambda_vh L_v^h + lambda_d L_d (+ feet). Errors: 0.1 on every
    pose entry (L_theta = 0.01, mean squared), 1 cm on every vertex (L_v = L_v^h = 0.01), 2 cm on every hand offset
    (L_d = 0.02); defaults lambda_theta = 10, the others 1 (MNetLossWeights)."""
    B, F = 2, 10
    tgt = {"d_rot6d": torch.zeros(B, F, 55, 6), "d_transl": torch.zeros(B, F, 3), "d_verts": torch.zeros(B, F, 400, 3),
           "d_hand_obj": torch.zeros(B, F, 99, 3)}
    out = {"d_rot6d": tgt["d_rot6d"] + 0.1, "d_transl": tgt["d_transl"] + 0.1, "d_verts": tgt["d_verts"] + 0.01,
           "d_hand_obj": tgt["d_hand_obj"] + 0.02}
    lam = w or MNetLossWeights()
    want = lam.theta * 0.01 + lam.v * 0.01 + lam.v_hand * 0.01 + lam.d * 0.02
    if w is None:
        assert math.isclose(want, 10 * 0.01 + 0.01 + 0.01 + 0.02)
    terms = mnet_loss(out, tgt, None, w)
    assert math.isclose(float(terms["theta"]), 0.01, rel_tol=1e-4)
    assert math.isclose(float(terms["loss"]), want, rel_tol=1e-4)


def test_windows_take_the_goal_hand_at_the_goal_frame():
    """MNetWindows: each clip's goal hand (Eq. 9's goal input and its BPS) is the 99 hand vertices at the clip's goal
    frame (ApproachClip doc: the first frame of the final grasp), not at its last frame. Truth: the SparseBody at the
    goal frame's parameters of a clip that keeps moving after it."""
    from graspkit.models.mnet import ApproachClip, MNetWindows
    bm = BodyModel.from_file(default_model_path(), flat_hand_mean=True)
    body = SparseBody(bm, torch.as_tensor(goal_vertices(bm).vertex_ids))
    g = torch.Generator().manual_seed(11)
    T, gf = 16, 6
    aa = 0.3 * torch.randn(T, 55, 3, generator=g)
    aa[:, 0] = torch.tensor([math.pi / 2, 0, 0])
    transl = torch.stack([torch.linspace(0, 0.6, T), torch.zeros(T), torch.zeros(T)], 1)   # walks on after gf
    betas = 0.5 * torch.randn(10, generator=g)
    pts = torch.randn(300, 3, generator=g) * 0.05 + torch.tensor([0.8, 0.3, 0.9])
    clip = ApproachClip(axis_angle_to_rot6d(aa), transl, betas, gf, pts, pts.mean(0))
    w = MNetWindows([clip], body, bps_basis())
    with torch.no_grad():
        want = body(pose_rotmats(clip.rot6d[gf:gf + 1]), betas[None], transl[gf:gf + 1])[0][0, :99]
    torch.testing.assert_close(w.goal_hand[0], want, atol=1e-5, rtol=0)



def test_rollout_names_a_bad_argument(setup):
    """rollout checked only `stall`: max_frames 0 returned one frame, reach_tol -1 could never be met, a NaN start
    returned NaN frames, and wrong shapes failed in a matrix product. Each is named now, before any frame."""
    args = list(_bent_elbow_args(setup[2], 0.5))
    r6, t = args[2]
    for kw, name in ((dict(max_frames=0), "max_frames"), (dict(max_frames=2.5), "max_frames"),
                     (dict(reach_tol=-1.0), "reach_tol"), (dict(reach_tol=0.0), "reach_tol"),
                     (dict(min_speed=-0.1), "min_speed"), (dict(floor=float("nan")), "floor")):
        with pytest.raises(ValueError, match=f"{name}: expected"):
            rollout(*args, **kw)
    bad = list(args)
    bad[2] = (r6, torch.tensor([float("nan"), 0.0, 0.0]))
    with pytest.raises(ValueError, match="start: contains NaN"):
        rollout(*bad, max_frames=5)
    bad[2] = (r6[:54], t)
    with pytest.raises(ValueError, match=r"start: expected \(rot6d \(55, 6\)"):
        rollout(*bad, max_frames=5)
    bad = list(args)
    bad[3] = (args[3][0], torch.zeros(2))
    with pytest.raises(ValueError, match="goal: expected"):
        rollout(*bad, max_frames=5)
    bad = list(args)
    bad[4] = torch.zeros(16)
    with pytest.raises(ValueError, match="betas: expected 10"):
        rollout(*bad, max_frames=5)
    one = rollout(*args, max_frames=1)
    assert len(one.rot6d) == 1 and not one.rot6d.requires_grad       # inference: frames without a graph



def _walking_in(bm, speed: float) -> tuple:
    """rollout's arguments for an MNet whose mean output walks the body forward `speed` m a frame towards the same body
    20 cm ahead (every hand vertex 20 cm from its goal, closing `speed` a frame)."""
    from graspkit.data.reaching import Start, plan_reach
    from graspkit.rotations import rot6d_to_matrix

    net = MNet().eval()
    with torch.no_grad():
        for k in range(net.cfg.n_future):
            net.norm_out.mean[k * net.frame_dim + 331] = (k + 1) * speed       # root translation, canonical +y
    first = plan_reach(Start(0.0, 0.0, math.pi / 2), (0.0, 1.0, 1.0), 60, seed=0, bm=bm).slice(0, 1)
    r6 = axis_angle_to_rot6d(torch.as_tensor(first.poses[0], dtype=torch.float64)).float()
    t0 = torch.as_tensor(first.trans[0]).float()
    fwd = rot6d_to_matrix(r6[0])[:, 2].clone()
    fwd[2] = 0
    return (net, None, (r6, t0), (r6, t0 + 0.20 * fwd / fwd.norm()), torch.as_tensor(first.betas[:10]).float(),
            torch.randn(256, 3, generator=torch.Generator().manual_seed(0)) * 0.02 + torch.tensor([0.0, 1.0, 1.0]),
            torch.tensor([0.0, 1.0, 1.0]), bps_basis())


def test_the_stall_rule_is_a_speed_below_stall_gain_a_frame_at_an_mnet_step(setup):
    """What the rule measures (docs/goal.md): at each MNet step, the last frame's distance against the closest of the
    `stall` frames before it. A hand closing 1 mm a frame (10 mm per window, but under STALL_GAIN in its last frame)
    is handed to the refinement at the first step within 25 cm, frame 11; one closing 6 mm a frame is left to MNet
    until GOAL's 10 cm, as without the rule."""
    from graspkit.models.mnet import STALL_GAIN

    bm, gv, body = setup
    for speed, stalls in ((0.001, True), (0.006, False)):
        args = list(_walking_in(bm, speed))
        args[1] = body
        paper, ours = rollout(*args, max_frames=140), rollout(*args, max_frames=140, stall=10)
        d = paper.hand_dist
        assert float(d[9] - d[10]) == pytest.approx(speed, abs=2e-4) and (speed < STALL_GAIN) == stalls
        assert paper.first_refined is not None and float(d[paper.first_refined]) < 0.1
        if stalls:
            assert ours.first_refined == 11 and float(ours.hand_dist[11]) > 0.15
        else:
            assert ours.first_refined == paper.first_refined
            torch.testing.assert_close(ours.hand_dist, paper.hand_dist)


def test_features_the_training_clips_held_still_are_held(setup):
    """The shipped MNet's statistics put 354 of its pose inputs (jaw, eyes, left fingers, ...: joints the synthetic
    clips never move) and 852 of its outputs at the 1e-3 std floor. A jaw turned 0.05 rad (50 floored stds) made a
    rollout miss the goal the unturned start reached (an independent check), and MNet's own changes there drifted
    up to 32 stds within a rollout: MNet.forward holds such inputs and outputs at their training values. Any value
    there leaves the output as it was, the held outputs are the training mean change, and a start with its jaw turned
    moves the rest of the body as the unturned start does (with every input read: 0.2 in rot6d, 3.7 cm in 30 frames).
    Frame t's translation x, y (another body's rest pelvis offset) is held with the past frames' moved alike: an
    offset of all five frames leaves the output as it was (held alone, a larger body walked backwards)."""
    from graspkit.data.reaching import Start, plan_reach
    from graspkit.models.gnet import Standardiser
    from graspkit.models.mnet import load_mnet

    st = Standardiser(3)
    st.fit(torch.tensor([[1.0, 2.0, 5.0], [3.0, 2.0, 5.0], [5.0, 2.0, 5.0]]))   # the last two columns never move
    assert st.floored().tolist() == [False, True, True]
    bm, _, body = setup
    net = load_mnet(Path(__file__).resolve().parents[1] / "data_stubs" / "checkpoints" / "mnet.pt")
    g = torch.Generator().manual_seed(0)
    feats = {k: n.mean + n.std * torch.randn(4, n.mean.numel(), generator=g) for k, n in net.norms.items()}
    per, n_past = M.POSE_DIM, net.cfg.n_past
    xy, shift = torch.zeros_like(feats["pose"][0], dtype=torch.bool), torch.zeros_like(feats["pose"][0])
    for f in range(n_past):                                        # every frame's translation x, y
        x = f * per + M.NUM_JOINTS * 6
        xy[x:x + 2] = True
        shift[x:x + 2] = torch.tensor([0.03, -0.05])
    assert net.norms["pose"].floored()[xy].tolist() == [False] * (2 * n_past - 2) + [True, True]   # frame t's only
    moved = {k: x + 100.0 * (net.norms[k].floored() & ~xy if k == "pose" else net.norms[k].floored())
             for k, x in feats.items()}
    offset = {**feats, "pose": feats["pose"] + shift}
    assert int(net.norms["pose"].floored().sum()) == 354
    with torch.no_grad():
        out, out_moved = net.pack_targets(net(feats)), net.pack_targets(net(moved))
        out_offset = net.pack_targets(net(offset))
    assert torch.equal(out, out_moved)
    torch.testing.assert_close(out_offset, out, atol=1e-6, rtol=0)   # another body's rest pelvis offset, all frames
    held = net.norm_out.floored()
    torch.testing.assert_close(out[:, held], net.norm_out.mean[held].expand(4, -1), atol=1e-7, rtol=0)

    first = plan_reach(Start(0.0, 0.0, math.pi / 2), (0.0, 1.0, 1.0), 60, seed=0, bm=bm).slice(0, 1)
    poses = torch.as_tensor(first.poses[0], dtype=torch.float64)
    t0 = torch.as_tensor(first.trans[0]).float()
    betas = torch.as_tensor(first.betas[:10]).float()
    obj = torch.randn(64, 3, generator=torch.Generator().manual_seed(0)) * 0.04 + torch.tensor([0.0, 0.7, 0.9])

    def roll(p):
        r6 = axis_angle_to_rot6d(p).float()
        return rollout(net, body, (r6, t0), (r6, t0 + torch.tensor([0.0, 0.5, 0.0])), betas, obj, obj.mean(0),
                       bps_basis(), max_frames=31, refine=False)

    jaw = poses.clone()
    jaw[J["jaw"], 0] += 0.05
    a, b = roll(poses), roll(jaw)
    rest = [j for j in range(55) if j != J["jaw"]]
    assert len(a.rot6d) == len(b.rot6d) == 31
    assert float((a.rot6d[:, rest] - b.rot6d[:, rest]).abs().max()) < 1e-3        # measured 1.2e-4 (0.2 unheld)
    assert float((a.transl - b.transl).abs().max()) < 1e-4                         # 1.3e-5 m (3.7 cm unheld)
    torch.testing.assert_close(b.rot6d[-1, J["jaw"]], b.rot6d[0, J["jaw"]])       # the turned jaw stays turned


def test_rollout_and_horizon_leave_the_models_mode_as_they_found_it(setup):
    """rollout / predict_horizon ran MNet in eval mode and left a training caller's model in it (an independent
    check): they now restore the mode they found."""
    from graspkit.data.reaching import Start, plan_reach

    bm, _, body = setup
    net = M.MNet(M.MNetConfig()).train()
    first = plan_reach(Start(0.0, 0.0, math.pi / 2), (0.0, 1.0, 1.0), 60, seed=0, bm=bm).slice(0, 1)
    r6 = axis_angle_to_rot6d(torch.as_tensor(first.poses[0], dtype=torch.float64)).float()
    t0 = torch.as_tensor(first.trans[0]).float()
    obj = torch.randn(64, 3, generator=torch.Generator().manual_seed(0)) * 0.04 + torch.tensor([0.0, 0.7, 0.9])
    seen = []
    forward = net.forward
    net.forward = lambda *a, **k: (seen.append(net.training), forward(*a, **k))[1]
    M.rollout(net, body, (r6, t0), (r6, t0 + torch.tensor([0.0, 0.5, 0.0])), torch.as_tensor(first.betas[:10]).float(),
              obj, obj.mean(0), bps_basis(), max_frames=2, refine=False)
    assert seen and not any(seen) and net.training
