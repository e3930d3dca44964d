"""GOAL data adapters, labels and the `graspkit train gnet|mnet` commands on small GRAB-style files."""
import argparse
import math
from pathlib import Path

import numpy as np
import pytest
import torch
import trimesh
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from graspkit.body.markers import goal_vertices
from graspkit.data import load_motion
from graspkit.data.grab import GraspSequence, load_grasp_sequence, save_grasp_sequence
from graspkit.data.grasp import object_points
from graspkit.data.motion import Motion
from graspkit.eval_goal import _body, approach_clips, gnet_samples
from graspkit.models.mnet import ApproachClip
from graspkit.paths import DATA_STUBS
from graspkit.rotations import axis_angle_to_rot6d

REACH = sorted((DATA_STUBS / "motion" / "reach").glob("*.npz"))


REACH_START = (0.3, -0.2)


def _sequence(k: int, name: str) -> GraspSequence:
    """A reaching clip of data_stubs as an approach clip: the object sits at the goal, turned about z."""
    m = load_motion(REACH[k])
    T = m.num_frames
    orient = np.array([0.0, 0.0, 0.4 + k], np.float32)
    pts, nrm = object_points(name)
    return GraspSequence(m.poses, m.trans, m.betas, 30.0, name, np.broadcast_to(m.goal, (T, 3)),
                         np.broadcast_to(orient, (T, 3)), f"meshes/{name}.ply", {},
                         {"grasp.goal_frame": np.array(m.goal_frame), "grasp.start": np.array([*REACH_START, 0.0])},
                         pts, nrm)


def test_labels_are_those_of_the_full_body_and_a_kd_tree():
    seqs = [_sequence(0, "bottle"), _sequence(1, "mug")]
    s = gnet_samples(seqs)
    bm, gv, _ = _body()
    for b, seq in enumerate(seqs):
        f = int(seq.extras["grasp.goal_frame"])
        p = torch.as_tensor(seq.poses[f]).reshape(1, -1)
        full = bm(betas=torch.as_tensor(seq.betas[None]), global_orient=p[:, :3], body_pose=p[:, 3:66],
                  jaw_pose=p[:, 66:69], leye_pose=p[:, 69:72], reye_pose=p[:, 72:75], left_hand_pose=p[:, 75:120],
                  right_hand_pose=p[:, 120:], transl=torch.as_tensor(seq.trans[f:f + 1])).vertices[0]
        R, o = s["R"][b].double().numpy(), s["o"][b].double().numpy()     # GNet's frame: x' = R (x - o)
        start = np.asarray(REACH_START)
        d = seq.object_transl[f, :2] - start
        np.testing.assert_allclose(R @ np.r_[d / np.linalg.norm(d), 0], [0, -1, 0], atol=1e-6)   # start -> object: -y
        np.testing.assert_allclose(o, np.r_[seq.object_transl[f, :2], 0], atol=1e-6)
        full = (full.double().numpy() - o) @ R.T
        np.testing.assert_allclose(s["verts"][b].numpy(), full[gv.vertex_ids], atol=2e-5)
        pts = (Rotation.from_rotvec(seq.object_orient[f]).apply(seq.object_points) + seq.object_transl[f] - o) @ R.T
        _, idx = cKDTree(pts).query(s["verts"][b].numpy())
        np.testing.assert_allclose(s["offsets"][b].numpy(), pts[idx] - s["verts"][b].numpy(), atol=2e-5)
        q = goal_vertices(bm).head_direction(torch.as_tensor(full))
        np.testing.assert_allclose(s["head_dir"][b].numpy(), q.numpy(), atol=1e-5)
        np.testing.assert_allclose(s["obj_transl"][b].numpy(), [0, 0, seq.object_transl[f, 2]], atol=1e-6)
    assert s["bps"].shape == (2, 1024) and float(s["bps"].min()) >= 0


def test_approach_clips_place_the_object_in_the_world():
    seq = _sequence(2, "can")
    c = approach_clips([seq])[0]
    want = Rotation.from_rotvec(seq.object_orient[0]).apply(seq.object_points) + seq.object_transl[0]
    np.testing.assert_allclose(c.object_points.numpy(), want, atol=1e-5)
    assert c.goal_frame == int(seq.extras["grasp.goal_frame"]) and c.rot6d.shape == (seq.num_frames, 55, 6)


def test_train_commands_write_loadable_half_precision_weights(tmp_path, monkeypatch):
    from graspkit.cli import main
    from graspkit.models.gnet import load_gnet
    from graspkit.models.mnet import load_mnet

    monkeypatch.setenv("GRASPKIT_CACHE", str(tmp_path / "cache"))    # the run states of data made here: not kept

    for k, name in enumerate(("bottle", "can", "apple")):                # train, train, validation objects
        save_grasp_sequence(tmp_path / f"approach_{k:06d}.npz", _sequence(k, name))
    for net in ("gnet", "mnet"):
        out = tmp_path / f"{net}.pt"
        assert main(["train", net, "--data", str(tmp_path), "--epochs", "1", "--out", str(out), "--threads", "1"]) == 0
        raw = torch.load(out, weights_only=True)
        assert raw["kind"] == net and all(v.dtype == torch.float16 for v in raw["model"].values() if v.is_floating_point())
        model = (load_gnet if net == "gnet" else load_mnet)(out)
        assert not model.training and all(p.dtype == torch.float32 for p in model.parameters())
    assert Path(tmp_path / "gnet.pt").stat().st_size < 2.5e6


def test_run_paths_differ_when_anything_that_shapes_the_run_differs(tmp_path):
    from graspkit.train import run_path

    a = run_path("gnet_gnet", 0, tmp_path, cfg={"hidden": 128}, epochs=60, data=["/x"])
    assert a == run_path("gnet_gnet", 0, tmp_path, epochs=60, data=["/x"], cfg={"hidden": 128})    # order-free
    others = [run_path("gnet_gnet", 0, tmp_path, cfg={"hidden": 192}, epochs=60, data=["/x"]),
              run_path("gnet_gnet", 0, tmp_path, cfg={"hidden": 128}, epochs=61, data=["/x"]),
              run_path("gnet_gnet", 0, tmp_path, cfg={"hidden": 128}, epochs=60, data=["/y"]),
              run_path("gnet_gnet", 1, tmp_path, cfg={"hidden": 128}, epochs=60, data=["/x"])]
    assert len({a, *others}) == 5 and all(p.parent == tmp_path for p in others)


def test_saga_sliding_starts_from_the_sequence_and_counts_goals_sliding_frames():
    from graspkit.eval_goal import saga_sliding

    seq = _sequence(0, "mug")
    out = saga_sliding([seq], grasp_steps=(3, 3, 3), motion_steps=(3, 3), polish_steps=(0, 0))
    r = out["results"][0]
    bm, _, _ = _body()
    m = r.motion
    assert m.num_frames == 61 and out["per_clip"][0]["frames"] == 61
    given = Motion(np.asarray(seq.poses[:1], np.float64), np.asarray(seq.trans[:1], np.float64),
                   np.asarray(seq.betas[:10], np.float64), 30.0)
    assert np.allclose(r.start.poses[0], seq.poses[0])        # the sequence's first body in the grasp's shape, where
    np.testing.assert_allclose(r.start.joint_positions(bm)[0, 0, :2], given.joint_positions(bm)[0, 0, :2], atol=1e-5)
    assert float(r.start.vertices(bm)[0, :, 2].min()) == pytest.approx(float(given.vertices(bm)[0, :, 2].min()),
                                                                       abs=1e-5)   # it stands (saga.reshaped_in_place)
    pelvis = m.joint_positions(bm)[:, 0]                                      # begins near that body, ends elsewhere
    assert np.linalg.norm(pelvis[0] - r.start.joint_positions(bm)[0, 0]) < 0.15
    v = m.vertices(bm).double().numpy()                                       # GOAL §4.2 by hand, numpy
    low, ar = v[:-1, :, 2].argmin(1), np.arange(60)
    step = np.linalg.norm(v[1:][ar, low] - v[:-1][ar, low], axis=1)
    assert abs(out["sliding"] - float((step > 0.01).mean())) < 1e-9


def test_tab1_only_recomputes_table_1_and_keeps_the_rest(tmp_path, monkeypatch, capsys):
    """`python -m graspkit.eval_goal --tab1-only`: Tab. 1 over every test grasp (n_grasps 0), its medians, 90th
    percentiles and paired counts the numpy statistics of the per-grasp rows of the `gnet_table` call it makes (caught
    on the way); the rest of the JSON kept; with --tab1-row, that row alone again."""
    import json
    from dataclasses import replace

    import graspkit.eval_goal as eg
    from graspkit.eval_goal import PEN_ROW, main, tab1_results
    from graspkit.optim.goal_refine import PEN_WEIGHTS, GraspRefineWeights

    for k in range(3):                                                  # the mug is a test object
        save_grasp_sequence(tmp_path / f"approach_{k:06d}.npz", _sequence(k, "mug"))
    out = tmp_path / "goal_eval.json"
    args = ["--tab1-only", "--data", str(tmp_path), "--n-grasps", "0", "--out", str(out), "--threads", "1"]
    assert main(args) == 2 and "--out: no evaluation at" in capsys.readouterr().err      # nothing to update yet
    out.write_text(json.dumps({"tab2": {"MNet": {"body": 1.0}}, "tab1": {"old": {}}}))
    real, calls = eg.gnet_table, []

    def caught(*a, **k):                        # a few refinement steps: the statistics, not the optimum, are tested
        k.update(refine_weights=GraspRefineWeights(steps=10), pen_weights=replace(PEN_WEIGHTS, steps=10))
        calls.append(real(*a, **k))
        return calls[-1]

    monkeypatch.setattr(eg, "gnet_table", caught)
    assert main(args) == 0
    r = json.loads(out.read_text())
    assert r["tab2"] == {"MNet": {"body": 1.0}} and set(r["tab1"]) == {"GNet w/o opt", "GNet", PEN_ROW, "synthetic GT"}
    assert len(calls) == 1
    t = calls[0]
    for name, rows in t["samples"].items():
        v = np.array([x["volume_cm3"] for x in rows["rows"]])
        row = r["tab1"][name]
        assert row["n"] == 3 and row["volume_cm3"] == pytest.approx(v.mean(), abs=1e-9)
        assert row["volume_median_cm3"] == pytest.approx(np.median(v), abs=1e-9)
        assert row["volume_p90_cm3"] == pytest.approx(np.percentile(v, 90), abs=1e-9)
    ref, raw = (np.array([x["volume_cm3"] for x in t["samples"][k]["rows"]]) for k in ("GNet", "GNet w/o opt"))
    pen = np.array([x["volume_cm3"] for x in t["samples"][PEN_ROW]["rows"]])
    assert r["tab1_paired"] == {"refined_lower": int((ref < raw).sum()), "refined_higher": int((ref > raw).sum()), "n": 3,
                                "pen_lower": int((pen < raw).sum()), "pen_higher": int((pen > raw).sum())}
    # --tab1-row: only that row (and the paired counts' reference) measured again, the same numbers for the same seed;
    # the other rows, paired counts and refinement energies kept as they are in the file
    r["tab1"]["GNet"]["volume_cm3"], r["tab1_paired"]["refined_lower"] = -1.0, -1
    out.write_text(json.dumps(r))
    assert main(args + ["--tab1-row", PEN_ROW]) == 0
    r2 = json.loads(out.read_text())
    assert len(calls) == 2 and set(calls[1]["samples"]) == {"GNet w/o opt", PEN_ROW}
    assert r2["tab1"][PEN_ROW] == r["tab1"][PEN_ROW] and r2["tab1"]["GNet w/o opt"] == r["tab1"]["GNet w/o opt"]
    assert r2["tab1"]["GNet"]["volume_cm3"] == -1.0 and r2["tab1_paired"]["refined_lower"] == -1
    assert r2["tab1_paired"]["pen_lower"] == r["tab1_paired"]["pen_lower"]
    assert r2["tab1_refine_energy"] == r["tab1_refine_energy"] and r2["tab1_seconds"] == r["tab1_seconds"]
    assert main(["--tab1-row", PEN_ROW, "--out", str(out)]) == 2 and "only with --tab1-only" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(args + ["--tab1-row", "GNet + nothing"])
    assert "invalid choice" in capsys.readouterr().err
    with pytest.raises(ValueError, match="rows: expected names in"):
        eg.gnet_table(None, None, [], rows=("GNet + nothing",))
    with pytest.raises(ValueError, match="folders"):
        tab1_results([tmp_path / "empty"], DATA_STUBS / "checkpoints")


def test_rollouts_only_recomputes_the_rollouts_on_the_floor_and_keeps_sagas_row(tmp_path, capsys):
    """`python -m graspkit.eval_goal --rollouts-only`: MNet's rollouts (to the true goal and to GNet's) and GOAL's
    sliding rows recomputed with the floor step, so that no frame's full mesh is under the floor z = 0; SAGA's sliding
    row and the other parts of the JSON kept."""
    import json

    from graspkit.eval_goal import main

    for k in range(2):
        save_grasp_sequence(tmp_path / f"approach_{k:06d}.npz", _sequence(k, "mug"))
    out = tmp_path / "goal_eval.json"
    saga = "SAGA (WholeGrasp + MotionFill, ours)"
    out.write_text(json.dumps({"tab2": {"MNet": {"body": 1.0}}, "sliding": {saga: 0.5, "GOAL (GNet + MNet, ours)": 9.0}}))
    assert main(["--rollouts-only", "--data", str(tmp_path), "--n-rollouts", "2", "--out", str(out), "--threads", "1",
                 "--max-frames", "60"]) == 0
    r = json.loads(out.read_text())
    assert r["rollouts"]["max_frames"] == 60
    assert r["tab2"] == {"MNet": {"body": 1.0}} and r["sliding"][saga] == 0.5
    assert r["rollouts"]["clips"] >= 1 and 0.0 <= r["sliding"]["GOAL (GNet + MNet, ours)"] <= 1.0
    rows = r["rollouts"]["per_clip_true_goal"] + r["rollouts"]["per_clip_pipeline"]
    assert len(rows) == 2 * r["rollouts"]["clips"] and all(x["below_floor_max_cm"] < 0.01 for x in rows)
    assert all(x["frames"] <= 60 for x in rows)
    assert main(["--rollouts-only", "--data", str(tmp_path), "--out", str(out), "--max-frames", "1"]) == 2
    assert "--max-frames: expected an integer >= 2, got 1" in capsys.readouterr().err


def test_an_update_of_a_damaged_evaluation_is_refused_before_the_work(tmp_path, capsys, monkeypatch):
    """`--saga-only` / `--tab1-only` / `--rollouts-only` read --out's JSON after their work: a file cut short gave an
    unnamed "Expecting value", `{}` a KeyError traceback after SAGA's minutes-long row (an independent check). The
    file is read first, and a bad one named."""
    import graspkit.eval_goal as E

    def no_work(*a, **k):
        raise AssertionError("the work started")

    for name in ("saga_sliding", "tab1_results", "rollout_results", "rollout_sequences"):
        monkeypatch.setattr(E, name, no_work)
    out = tmp_path / "goal_eval.json"
    for text, flag, message in (('{"sliding": {"a": 0.5}, "tab1": {', "--saga-only", "is not a JSON file to update"),
                                ("", "--tab1-only", "is not a JSON file to update"),
                                ("{}", "--saga-only", "is not a GOAL evaluation to update with --saga-only"),
                                ("[]", "--tab1-only", "is not a GOAL evaluation to update with --tab1-only"),
                                ("[]", "--rollouts-only", "is not a GOAL evaluation"),
                                ('{"sliding": [0.5]}', "--rollouts-only", "is not a GOAL evaluation"),
                                ('{"tab1": [1]}', "--tab1-only", "is not a GOAL evaluation"),
                                ('{"sliding": {}, "updates": {}}', "--saga-only", "is not a GOAL evaluation")):
        out.write_text(text)
        assert E.main([flag, "--data", str(tmp_path), "--out", str(out)]) == 2, (text, flag)
        err = capsys.readouterr().err
        assert f"--out: {out} {message}" in err, (text, flag, err)
        assert out.read_text() == text


def _standing_r6() -> torch.Tensor:
    """The rest pose stood up in a z-up world (55, 6): the root turned +90 deg about x."""
    aa = torch.zeros(55, 3)
    aa[0] = torch.tensor([math.pi / 2, 0, 0])                                       # y up -> z up: standing
    return axis_angle_to_rot6d(aa)


def test_rollout_sliding_is_pooled_over_frame_pairs(monkeypatch):
    """GOAL's foot sliding over the rollouts is the share of all frame pairs that slide (as the other rows pool
    theirs), not a mean of per-clip shares: a 5-frame clip standing still and a 21-frame one sliding 2 cm a frame
    give 20 / 24, not 1 / 2."""
    import graspkit.models.mnet as mnet_mod
    from graspkit.eval_goal import rollout_eval
    from graspkit.models.mnet import Rollout

    r6 = _standing_r6()

    def fake_rollout(mnet, body, start, goal, betas, points, centre, basis, **kw):
        T, step = (5, 0.0) if float(start[1][0]) == 0.0 else (21, 0.02)
        tr = start[1][None].repeat(T, 1) + torch.arange(T)[:, None] * torch.tensor([step, 0.0, 0.0])
        return Rollout(r6[None].repeat(T, 1, 1), tr, torch.ones(T), False, None)

    monkeypatch.setattr(mnet_mod, "rollout", fake_rollout)
    clips = [ApproachClip(r6[None].repeat(3, 1, 1), torch.tensor([[x, 0.0, 0.0]] * 3), torch.zeros(10), 2,
                          torch.zeros(10, 3), torch.zeros(3)) for x in (0.0, 3.0)]
    res = rollout_eval(None, clips, refine=False)
    assert [c["sliding"] for c in res["clips"]] == [0.0, 1.0]
    assert res["sliding"] == pytest.approx(20 / 24)


def test_tab1_object_meshes_are_in_gnets_frame_with_the_object_points():
    """gnet_table measures every body against its object mesh in GNet's frame x' = R (x - o): the mesh there is the
    world mesh moved so, and the object's sample points in GNet's frame (gt['points']) lie on its surface."""
    from graspkit.eval_goal import gnet_table, object_mesh_world
    from graspkit.models.gnet import load_gnet

    seqs = [_sequence(k, "mug") for k in (0, 1)]
    t = gnet_table(load_gnet(DATA_STUBS / "checkpoints" / "gnet.pt"), None, seqs, rows=("GNet w/o opt",))
    for b, s in enumerate(seqs):
        R, o = t["gt"]["R"][b].double().numpy(), t["gt"]["o"][b].double().numpy()
        assert abs(np.linalg.det(R) - 1) < 1e-5 and np.linalg.norm(o) > 0.1          # a real move
        world = object_mesh_world(s, int(s.extras["grasp.goal_frame"]))
        assert np.allclose(t["meshes"][b].vertices, (world.vertices - o) @ R.T, atol=1e-5)
        _, dist, _ = trimesh.proximity.closest_point(t["meshes"][b], t["gt"]["points"][b].double().numpy())
        assert dist.max() < 2e-3


def _still_clip(T, goal_frame, transl, obj_centre):
    """A body standing still at rest pose (T frames), translations `transl` (T, 3)."""
    rot6d = axis_angle_to_rot6d(torch.zeros(T, 55, 3, dtype=torch.float64)).float()
    return ApproachClip(rot6d, torch.as_tensor(transl, dtype=torch.float32), torch.zeros(10), goal_frame,
                        torch.zeros(5, 3), torch.as_tensor(obj_centre, dtype=torch.float32), "mug")


def test_ground_truth_sliding_counts_the_frame_pairs_up_to_and_including_the_goal_frame():
    """clip_sliding: frames 0..goal_frame (the docstring's 'up to the goal frame'), i.e. goal_frame frame pairs; a body
    that stands still and jumps 5 cm sideways into the goal frame slides on 1 of its 10 pairs (GOAL §4.2: the vertex
    closest to the ground moves more than 1 cm)."""
    from graspkit.eval_goal import clip_sliding

    tr = np.zeros((13, 3))
    tr[10:, 0] = 0.05                                        # the step into the goal frame 10 (and stays there)
    c = _still_clip(13, 10, tr, [1.0, 0.0, 0.8])
    assert clip_sliding([c]) == pytest.approx(1 / 10)
    assert clip_sliding([c], until_goal=False) == pytest.approx(1 / 12)
    tr[10:, 0] = 0.0
    tr[11:, 0] = 0.05                                        # the step after the goal frame: not counted
    assert clip_sliding([_still_clip(13, 10, tr, [1.0, 0.0, 0.8])]) == 0.0


def test_start_distance_is_measured_on_the_floor_plane():
    """start_distance: the horizontal distance from the first frame's pelvis (the posed body's joint 0) to the object
    centre, whatever the object's height (a 1.4 m high shelf 1 m away is 1 m away)."""
    from graspkit.eval_goal import start_distance

    bm, _, _ = _body()
    tr = np.tile([0.2, -0.1, 0.0], (3, 1))
    with torch.no_grad():
        pelvis = bm(transl=torch.as_tensor(tr[:1], dtype=bm.dtype)).joints[0, 0].double().numpy()
    for z in (0.0, 1.4):
        c = _still_clip(3, 2, tr, [pelvis[0] + 0.6, pelvis[1] + 0.8, z])
        assert start_distance(c) == pytest.approx(1.0, abs=1e-5)


def _full_mesh(bm, seq: GraspSequence, f: int) -> np.ndarray:
    """The body model's full mesh (V,3) of a sequence's stored absolute pose at frame f."""
    p = torch.as_tensor(seq.poses[f]).reshape(1, -1)
    with torch.no_grad():
        return bm(betas=torch.as_tensor(seq.betas[None]), global_orient=p[:, :3], body_pose=p[:, 3:66],
                  jaw_pose=p[:, 66:69], leye_pose=p[:, 69:72], reye_pose=p[:, 72:75], left_hand_pose=p[:, 75:120],
                  right_hand_pose=p[:, 120:], transl=torch.as_tensor(seq.trans[f:f + 1])).vertices[0].double().numpy()


def _pelvis(bm, betas: np.ndarray, transl: np.ndarray) -> np.ndarray:
    """The posed body's joint 0 (the pelvis: the root joint does not depend on the pose)."""
    with torch.no_grad():
        return bm(betas=torch.as_tensor(betas[None, :10]).float(),
                  transl=torch.as_tensor(transl[None]).float()).joints[0, 0].double().numpy()


# ----------------------------------------------------------------------------------------------------------- Tab. 2


def test_teacher_forced_v2v_does_not_depend_on_how_the_windows_are_batched():
    """Tab. 2's V2V is a mean over predicted frames: windows of two clips with different body shapes measured in one
    batch (or in chunks of 2) give the mean of the windows measured one at a time."""
    from graspkit.eval_goal import teacher_forced_v2v
    from graspkit.models.mnet import MNet, MNetConfig, MNetWindows
    from graspkit.objects.bps import bps_basis

    bm, _, body = _body()
    clips = approach_clips([_sequence(0, "mug"), _sequence(5, "mug")])
    assert not torch.equal(clips[0].betas, clips[1].betas)
    w = MNetWindows(clips, body, bps_basis(), stride=7)
    of_clip = w.clip[w.windows]
    idx = torch.cat([torch.nonzero(of_clip == 0)[3:5, 0], torch.nonzero(of_clip == 1)[2:3, 0]])   # 2 + 1 windows
    torch.manual_seed(0)
    net = MNet(MNetConfig())
    one = [teacher_forced_v2v(net, w, bm, idx[i:i + 1], horizon=3) for i in range(3)]
    want = [np.mean([getattr(e, k) for e in one]) for k in ("body", "hand", "feet")]
    for chunk in (32, 2):
        got = teacher_forced_v2v(net, w, bm, idx, horizon=3, chunk=chunk)
        assert [got.body, got.hand, got.feet] == pytest.approx(want, rel=1e-4)


# ----------------------------------------------------------------------------------------------------------- labels


def test_object_points_follow_the_object_pose_of_the_requested_frame():
    """object_points_world(seq, f): the object's points moved by its rotation and translation at frame f (scipy),
    for an object that turns and moves during the sequence."""
    from graspkit.eval_goal import object_points_world

    seq = _sequence(1, "mug")
    T = seq.num_frames
    seq.object_orient = np.stack([[0.1 * f, -0.05 * f, 0.3 + 0.02 * f] for f in range(T)]).astype(np.float32)
    seq.object_transl = (seq.object_transl + np.arange(T)[:, None] * np.float32([0.01, 0.0, 0.002])).astype(np.float32)
    for f in (0, 7, T - 1):
        want = Rotation.from_rotvec(seq.object_orient[f]).apply(seq.object_points) + seq.object_transl[f]
        np.testing.assert_allclose(object_points_world(seq, f).numpy(), want, atol=1e-5)


def test_gnet_frame_without_a_stored_start_looks_from_the_first_frames_pelvis():
    """GNet's frame (x' = R (x - o)) for a sequence that stores no task start: the horizontal direction from the first
    frame's pelvis (the posed body's joint 0) to the object is -y."""
    bm, _, _ = _body()
    seq = _sequence(3, "mug")
    del seq.extras["grasp.start"]
    s = gnet_samples([seq])
    f = int(seq.extras["grasp.goal_frame"])
    pelvis = _pelvis(bm, seq.betas, seq.trans[0])
    d = seq.object_transl[f, :2] - pelvis[:2]
    assert abs(np.linalg.norm(seq.trans[0, :2] - pelvis[:2])) > 0.01               # trans is not the pelvis here
    R = s["R"][0].double().numpy()
    np.testing.assert_allclose(R @ np.r_[d / np.linalg.norm(d), 0], [0, -1, 0], atol=1e-5)


# ----------------------------------------------------------------------------------------------------------- training


def test_gnet_validation_samples_are_the_validation_objects(tmp_path):
    """gnet_data: training samples from the training objects, validation samples from the validation objects
    (GRAB's split: bottle train, apple val, mug test); the held-out test objects are in neither."""
    from graspkit.eval_goal import gnet_data

    for k, (i, name) in enumerate([(0, "bottle"), (1, "apple"), (2, "mug"), (3, "mug")]):
        save_grasp_sequence(tmp_path / f"approach_{k:06d}.npz", _sequence(i, name))
    train, val = gnet_data([tmp_path])
    files = sorted(tmp_path.glob("approach_*.npz"))
    for got, f in ((train, files[0]), (val, files[1])):
        want = gnet_samples([load_grasp_sequence(f)])
        assert len(got["bps"]) == 1
        torch.testing.assert_close(got["bps"], want["bps"])


def _train_args(data: Path, variant: str, **extra) -> argparse.Namespace:
    return argparse.Namespace(data=[data], variant=variant, out=None, epochs=1, time_limit=60.0, seed=0, threads=1,
                              **extra)


def test_mnet_ablation_trains_on_train_validates_on_val_and_ships_its_own_checkpoint(tmp_path, monkeypatch):
    """`graspkit train mnet --variant no_iaa` (GOAL Tab. 2's MNet-w/o-IAA): windows of the training objects, validation
    on the validation objects, weights to <checkpoints>/mnet_no_iaa.pt (mnet.pt untouched) with attention off."""
    import graspkit.eval_goal as eg
    from graspkit.models.mnet import load_mnet

    data = tmp_path / "data"
    data.mkdir()
    for k, name in enumerate(("bottle", "apple", "mug")):
        save_grasp_sequence(data / f"approach_{k:06d}.npz", _sequence(k, name))
    splits, real = [], eg.mnet_windows

    def spy(folders, split, *a, **k):
        splits.append(split)
        return real(folders, split, *a, **k)

    monkeypatch.setattr(eg, "mnet_windows", spy)
    monkeypatch.setenv("GRASPKIT_CACHE", str(tmp_path / "cache"))    # the run states of data made here: not kept
    stubs = tmp_path / "stubs"
    stubs.mkdir()
    assert eg._cmd_train(_train_args(data, "no_iaa", goal_repeat=1, vel_noise=0.0), "mnet", stubs) == 0
    assert sorted(splits) == ["train", "val"]
    assert sorted(p.name for p in stubs.iterdir()) == ["mnet_no_iaa.pt"]
    assert load_mnet(stubs / "mnet_no_iaa.pt").cfg.attention is False


def test_grabnet_smplx_baseline_ships_without_offsets(tmp_path, monkeypatch):
    """`graspkit train gnet --variant smplx` (Tab. 1's GrabNet-SMPL-X: a decoder of SMPL-X parameters only, no offsets)
    ships <checkpoints>/gnet_smplx.pt whose config has no offsets (gnet.pt untouched)."""
    import graspkit.eval_goal as eg
    from graspkit.models.gnet import load_gnet

    monkeypatch.setenv("GRASPKIT_CACHE", str(tmp_path / "cache"))    # the run states of data made here: not kept

    data = tmp_path / "data"
    data.mkdir()
    for k, name in enumerate(("bottle", "can")):
        save_grasp_sequence(data / f"approach_{k:06d}.npz", _sequence(k, name))
    stubs = tmp_path / "stubs"
    stubs.mkdir()
    assert eg._cmd_train(_train_args(data, "smplx", kl=None), "gnet", stubs) == 0
    assert sorted(p.name for p in stubs.iterdir()) == ["gnet_smplx.pt"]
    assert load_gnet(stubs / "gnet_smplx.pt").cfg.offsets is False


# ----------------------------------------------------------------------------------------------------------- Tab. 1


def _shifted(k: int, body_dz: float, object_dx: float) -> GraspSequence:
    """A mug sequence with the body (and the object with it) moved `body_dz` up and then the object `object_dx`
    along x."""
    s = _sequence(k, "mug")
    s.trans = (s.trans + np.float32([0, 0, body_dz])).astype(np.float32)
    s.object_transl = (s.object_transl + np.float32([object_dx, 0, body_dz])).astype(np.float32)
    return s


def test_tab1_rows_are_the_means_over_grasps_of_the_measured_bodies():
    """Tab. 1's synthetic-GT row measures the stored grasps (the full mesh of the stored pose, in GNet's frame,
    against the object mesh there: graspkit.metrics.grasp_metrics), and each column is the mean over the grasps:
    contact ratio = share in contact, depth = mean depth, lowest vertex to the floor = mean |height| in cm (one
    body sunk 3 cm, one lifted 2 cm, one whose object is 0.6 m away)."""
    from graspkit.eval_goal import gnet_table
    from graspkit.metrics import grasp_metrics
    from graspkit.models.gnet import load_gnet

    bm, _, _ = _body()
    seqs = [_shifted(0, -0.03, 0.0), _shifted(1, 0.0, 0.6), _shifted(2, 0.02, 0.0)]
    t = gnet_table(load_gnet(DATA_STUBS / "checkpoints" / "gnet.pt"), None, seqs, rows=("synthetic GT",))
    truth = []
    for b, s in enumerate(seqs):
        R, o = t["gt"]["R"][b].double().numpy(), t["gt"]["o"][b].double().numpy()
        v = (_full_mesh(bm, s, int(s.extras["grasp.goal_frame"])) - o) @ R.T
        m = grasp_metrics(torch.as_tensor(v), bm.faces, t["meshes"][b])
        truth.append({**m, "feet_cm": 100 * v[:, 2].min()})
    contact = [r["contact"] for r in truth]
    feet = [r["feet_cm"] for r in truth]
    assert 0 < sum(contact) < 3 and min(feet) < -1 and max(feet) > 1              # the case is what it says
    row = t["table"]["synthetic GT"]
    assert row["n"] == 3
    assert row["volume_cm3"] == pytest.approx(np.mean([r["volume_cm3"] for r in truth]), abs=1e-3)
    assert row["contact_ratio"] == pytest.approx(np.mean(contact))
    assert row["depth_cm"] == pytest.approx(np.mean([r["depth_cm"] for r in truth]), abs=1e-3)
    assert row["feet_cm"] == pytest.approx(np.mean(np.abs(feet)), abs=1e-3)


def test_tab1_takes_the_static_grasps_of_the_test_objects_only(tmp_path):
    """tab1_results: one sample per accepted grasp of a held-out test object (mug); a validation object's grasp
    (apple) is not in Tab. 1."""
    from graspkit.eval_goal import tab1_results

    for k, (i, name) in enumerate([(0, "mug"), (1, "mug"), (2, "apple")]):
        save_grasp_sequence(tmp_path / f"grasp_{k:06d}.npz", _sequence(i, name))
    r = tab1_results([tmp_path], DATA_STUBS / "checkpoints", n_grasps=0, penetration=False, rows=("GNet w/o opt",))
    assert r["tab1"]["GNet w/o opt"]["n"] == 2


# ----------------------------------------------------------------------------------------------------------- rollouts


def test_rollout_rows_measure_the_rollout_from_the_goal_frame(monkeypatch):
    """rollout_eval with a stand-in MNet rollout: it is asked for the clip's goal-frame pose; the row's final hand
    distance is the rollout's last frame's (cm), the ground truth has goal_frame + 1 frames (0..goal), and the
    deepest the lowest vertex goes under z = 0 is the deepest frame's (2 cm), not a mean over frames."""
    import graspkit.models.mnet as mnet_mod
    from graspkit.eval_goal import full_vertices, rollout_eval
    from graspkit.models.mnet import Rollout

    bm, _, _ = _body()
    r6 = _standing_r6()
    low = float(full_vertices(bm, r6[None], torch.zeros(1, 3), torch.zeros(10))[0, :, 2].min())
    heights = torch.tensor([0.01, 0.0, -0.02, -0.005, 0.0, 0.0])                  # the lowest vertex's height per frame
    asked = []

    def fake_rollout(mnet, body, start, goal, betas, points, centre, basis, **kw):
        asked.append(goal)
        T = len(heights)
        tr = torch.zeros(T, 3)
        tr[:, 2] = heights - low
        return Rollout(r6[None].repeat(T, 1, 1), tr, torch.linspace(0.5, 0.03, T), False, None)

    monkeypatch.setattr(mnet_mod, "rollout", fake_rollout)
    transl = torch.tensor([[0.1 * k, 0.0, 0.0] for k in range(7)])
    rot6d = axis_angle_to_rot6d(0.01 * torch.arange(7 * 55 * 3, dtype=torch.float32).reshape(7, 55, 3) % 0.5)
    clip = ApproachClip(rot6d, transl, torch.zeros(10), 4, torch.zeros(10, 3), torch.zeros(3))
    row = rollout_eval(None, [clip], refine=False)["clips"][0]
    torch.testing.assert_close(asked[0][0], rot6d[4])
    torch.testing.assert_close(asked[0][1], transl[4])
    assert row["final_hand_cm"] == pytest.approx(3.0, abs=1e-4)
    assert row["gt_frames"] == 5
    assert row["below_floor_max_cm"] == pytest.approx(2.0, abs=1e-3)


def test_rollout_sequences_start_half_to_one_and_a_half_metres_away_and_take_the_test_objects_in_turn(tmp_path):
    """rollout_sequences: accepted approach clips of the test objects whose first pelvis is 0.5-1.5 m (horizontally)
    from the object, taken in turn from each object in file order: mug 0.7, camera 1.0, mug 1.2 (a mug at 0.3 m and
    one at 1.8 m, a rejected mug and a validation object's clip left out)."""
    from graspkit.eval_goal import rollout_sequences

    bm, _, _ = _body()
    made = []
    for k, (name, d, ok) in enumerate([("mug", 0.3, True), ("mug", 0.7, True), ("mug", 1.0, False), ("camera", 1.0, True),
                                       ("mug", 1.8, True), ("apple", 1.0, True), ("mug", 1.2, True)]):
        s = _sequence(k % 3, name)
        pelvis = _pelvis(bm, s.betas, s.trans[0])
        centre = np.float32([pelvis[0] + 0.6 * d, pelvis[1] - 0.8 * d, 0.9])
        s.object_transl = np.broadcast_to(centre, s.object_transl.shape).astype(np.float32)
        s.extras["grasp.accepted"] = np.array(ok)
        save_grasp_sequence(tmp_path / f"approach_{k:06d}.npz", s)
        made.append((name, d))
    got = rollout_sequences([tmp_path], 10)
    dist = []
    for s in got:
        p = _pelvis(bm, s.betas, s.trans[0])
        dist.append((s.object_name, round(float(np.linalg.norm(s.object_transl[0, :2] - p[:2])), 3)))
    assert dist == [("mug", 0.7), ("camera", 1.0), ("mug", 1.2)]
    assert [s.object_name for s in rollout_sequences([tmp_path], 2)] == ["mug", "camera"]


# ----------------------------------------------------------------------------------------------------------- gnet_goal


def test_gnet_goal_samples_in_the_frame_from_the_start_pelvis_with_the_object_centred_bps(monkeypatch):
    """gnet_goal: GNet's frame looks from the start body's pelvis (joint 0, not trans) to the object centre along -y,
    and GNet is given the object's BPS code relative to the object centre in that frame (brute-force distances from
    the 1024 basis points)."""
    from graspkit.eval_goal import gnet_goal
    from graspkit.models.gnet import load_gnet
    from graspkit.objects.bps import bps_basis
    from graspkit.optim.goal_refine import GraspRefineWeights

    bm, _, _ = _body()
    seq = _sequence(4, "mug")
    betas = torch.as_tensor(seq.betas[:10]).float()
    start = (axis_angle_to_rot6d(torch.as_tensor(seq.poses[0]).double()).float(), torch.as_tensor(seq.trans[0]).float())
    centre = torch.tensor([0.9, 1.4, 0.85])
    pts = torch.as_tensor(seq.object_points).float() + centre
    gnet = load_gnet(DATA_STUBS / "checkpoints" / "gnet.pt")
    seen = {}
    real = gnet.sample

    def spy(bps, obj_transl, b, **kw):
        seen["bps"], seen["c"] = bps.clone(), obj_transl.clone()
        return real(bps, obj_transl, b, **kw)

    monkeypatch.setattr(gnet, "sample", spy)
    _, _, info = gnet_goal(gnet, start, betas, pts, centre, z=torch.zeros(1, gnet.cfg.latent),
                           refine_weights=GraspRefineWeights(steps=1))
    R, o = info["R"][0].double().numpy(), info["o"][0].double().numpy()
    pelvis = _pelvis(bm, seq.betas, seq.trans[0])
    d = centre.double().numpy()[:2] - pelvis[:2]
    np.testing.assert_allclose(R @ np.r_[d / np.linalg.norm(d), 0], [0, -1, 0], atol=1e-5)
    c = R @ (centre.double().numpy() - o)
    np.testing.assert_allclose(seen["c"][0].double().numpy(), c, atol=1e-5)
    local = (pts.double().numpy() - o) @ R.T - c
    basis = bps_basis().double().numpy()
    want = np.sqrt(((basis[:, None] - local[None]) ** 2).sum(-1)).min(1)
    np.testing.assert_allclose(seen["bps"][0].double().numpy(), want, atol=1e-5)


# ----------------------------------------------------------------------------------------------------------- SAGA row


def test_saga_sliding_measures_algorithm_2s_fit_with_one_seed_per_sequence(monkeypatch):
    """saga_sliding (the shipped SAGA row) runs synthesize with hold_start=False (Alg. 2's fit, unless asked
    otherwise), each sequence with its own seed (seed + k) and its first frame as the start body."""
    import graspkit.saga as saga_mod
    from graspkit.data.motion import Motion
    from graspkit.eval_goal import saga_sliding

    calls = []

    class Fake:
        def __init__(self, sq):
            trans = np.asarray(sq.trans[:3], np.float64) + [[0, 0, 0], [0, 0, 0.05], [0, 0, 0]]   # frame 1 in the air
            self.motion = Motion(np.asarray(sq.poses[:3], np.float64), trans, np.asarray(sq.betas[:10], np.float64), 30.0)
            self.metrics = {"end_contact": 1.0, "end_volume_cm3": 0.0}

    seqs = [_sequence(0, "mug"), _sequence(1, "camera")]

    def fake(name, bm, pose, start, seed=0, progress=True, **kw):
        calls.append({"name": name, "seed": seed, "start": start, **kw})
        return Fake(seqs[(len(calls) - 1) % 2])

    monkeypatch.setattr(saga_mod, "synthesize", fake)
    out = saga_sliding(seqs, seed=5)
    assert [c["seed"] for c in calls] == [5, 6] and [c["hold_start"] for c in calls] == [False, False]
    for c, sq in zip(calls, seqs):
        np.testing.assert_allclose(c["start"].poses[0], sq.poses[0], atol=1e-6)
    assert out["per_clip"][0]["frames"] == 3
    for row, sq in zip(out["per_clip"], seqs):          # frames whose lowest vertex is more than 1 cm up
        low = Fake(sq).motion.vertices(_body()[0])[..., 2].amin(-1).numpy()
        assert row["floating"] == pytest.approx(float(np.mean(low > 0.01))) and row["floating"] > 0
    assert out["floating"] == pytest.approx(np.mean([row["floating"] for row in out["per_clip"]]))
    saga_sliding(seqs[:1], hold_start=True)
    assert calls[-1]["hold_start"] is True


# ----------------------------------------------------------------------------------------------------------- the whole evaluation


def test_tab1_subset_is_drawn_with_the_seed(tmp_path, monkeypatch):
    """tab1_results with n_grasps < the test grasps: the seed draws which grasps are measured (seeds 0-5 do not all
    pick the same one of three), and the same seed the same ones."""
    import graspkit.eval_goal as eg

    for k in range(3):
        save_grasp_sequence(tmp_path / f"grasp_{k:06d}.npz", _sequence(k, "mug"))
    picked = []

    def fake_table(gnet, base, seqs, seed=0, **kw):
        picked.append(tuple(int(s.poses.shape[0]) for s in seqs))     # the reach clips differ in length
        return {"table": {}, "paired": {}, "refine_history": []}

    monkeypatch.setattr(eg, "gnet_table", fake_table)
    for seed in (0, 1, 2, 3, 4, 5, 3):
        eg.tab1_results([tmp_path], DATA_STUBS / "checkpoints", n_grasps=1, seed=seed)
    assert len(set(picked)) > 1 and picked[3] == picked[6] and all(len(p) == 1 for p in picked)


def test_tab2_rows_come_from_their_own_checkpoints(tmp_path, monkeypatch):
    """evaluate's Tab. 2: row 'MNet' from mnet.pt, 'MNet-w/o-IAA' from mnet_no_iaa.pt, 'MNet-Pose' from mnet_pose.pt,
    '1 output frame' from mnet_1frame.pt (GOAL Tab. 2's ablations; stand-ins tag each row with its file)."""
    import graspkit.eval_goal as eg
    import graspkit.models.gnet as gnet_mod
    import graspkit.models.mnet as mnet_mod
    from graspkit.eval_goal import V2V

    files = {"mnet.pt": 1.0, "mnet_no_iaa.pt": 2.0, "mnet_pose.pt": 3.0, "mnet_1frame.pt": 4.0}
    for f in files:
        (tmp_path / f).write_bytes(b"")
    monkeypatch.setattr(mnet_mod, "load_mnet", lambda p: Path(p).name)
    monkeypatch.setattr(gnet_mod, "load_gnet", lambda p: None)
    monkeypatch.setattr(eg, "tab1_results", lambda *a, **k: {})
    monkeypatch.setattr(eg, "mnet_windows", lambda *a, **k: [0, 1, 2])
    monkeypatch.setattr(eg, "teacher_forced_v2v", lambda net, w, bm, idx: V2V(files[net], files[net], files[net]))
    monkeypatch.setattr(eg, "rollout_sequences", lambda folders, n: [])
    monkeypatch.setattr(eg, "rollout_results", lambda *a, **k: {"sliding": {}})
    monkeypatch.setattr(eg, "add_saga_rows", lambda res, seqs, seed=0: res)
    res = eg.evaluate([tmp_path], tmp_path, out=tmp_path / "goal_eval.json")
    got = {k: v["body"] for k, v in res["tab2"].items()}
    assert got == {"MNet": 1.0, "MNet-w/o-IAA": 2.0, "MNet-Pose": 3.0, "1 output frame": 4.0}


def test_tab2_only_recomputes_table_2_from_the_checkpoints_and_keeps_the_rest(tmp_path, monkeypatch, capsys):
    """`python -m graspkit.eval_goal --tab2-only`: Tab. 2's rows measured again from the MNet checkpoints in
    --checkpoints (stand-ins tag each row with its file), the row of a variant without a file and every other part of
    the JSON kept, the update logged with its window stride; a folder with no MNet checkpoint is refused, the JSON
    untouched (it had written an empty table, and dropped the rows of the ablations, which are not shipped)."""
    import json

    import graspkit.eval_goal as eg
    import graspkit.models.mnet as mnet_mod
    from graspkit.eval_goal import V2V

    files = {"mnet.pt": 1.0, "mnet_pose.pt": 3.0}
    for f in files:
        (tmp_path / f).write_bytes(b"")
    monkeypatch.setattr(mnet_mod, "load_mnet", lambda p: Path(p).name)
    monkeypatch.setattr(eg, "mnet_windows", lambda folders, split, cfg, stride: list(range(7 * stride)))
    monkeypatch.setattr(eg, "teacher_forced_v2v", lambda net, w, bm, idx: V2V(files[net], 10 * files[net], 0.0))
    out = tmp_path / "goal_eval.json"
    kept = {"tab1": {"GNet": {"volume": 2.0}}, "sliding": {"GOAL (GNet + MNet, ours)": 0.05},
            "rollouts": {"clips": 12}, "tab2": {"MNet-w/o-IAA": {"body": 9.0}}}
    out.write_text(json.dumps(kept))
    assert eg.main(["--tab2-only", "--data", str(tmp_path), "--checkpoints", str(tmp_path), "--out", str(out),
                    "--window-stride", "2", "--threads", "1"]) == 0
    r = json.loads(out.read_text())
    assert r["tab2"] == {"MNet-w/o-IAA": {"body": 9.0}, "MNet": {"body": 1.0, "hand": 10.0, "feet": 0.0},
                         "MNet-Pose": {"body": 3.0, "hand": 30.0, "feet": 0.0}}
    assert r["tab2_windows"] == 14 and all(r[k] == v for k, v in kept.items() if k != "tab2")
    assert r["updates"][-1]["flag"] == "--tab2-only" and r["updates"][-1]["window_stride"] == 2
    assert json.loads(capsys.readouterr().out)["tab2"] == r["tab2"]
    before = out.read_text()
    (tmp_path / "none").mkdir()
    assert eg.main(["--tab2-only", "--data", str(tmp_path), "--checkpoints", str(tmp_path / "none"), "--out",
                    str(out)]) == 2
    assert "--checkpoints: none of ['mnet.pt'" in capsys.readouterr().err and out.read_text() == before


@pytest.mark.parametrize("trainer", ["gnet", "mnet", "grabnet_smplx"])
def test_a_training_run_is_keyed_by_the_body_it_is_trained_on(tmp_path, monkeypatch, trainer):
    """GNet's, MNet's and the GrabNet-SMPLX baseline's labels are computed on the body GRASPKIT_MODEL names, so a run
    started under one body must never resume under another: each run key holds that body's digest (compared here
    with BodyModel.from_file of the file), and a taller body gives another key. The spy stops before any training.
    The taller body trains on the stub grasps relabelled as its own (GOAL's stored vertices recomputed on it: grasps
    of another body are refused, tests/test_made_on.py)."""
    from conftest import relabelled

    import graspkit.models.wholegrasp as W
    import graspkit.train as T
    from graspkit.body import BodyModel
    from graspkit.eval_goal import run_train_gnet, run_train_mnet
    from graspkit.paths import default_model_path

    approach = tmp_path / "approach"                                   # clips of train- and val-split objects
    for k, name in enumerate(("bottle", "can", "apple")):
        save_grasp_sequence(approach / f"approach_{k:06d}.npz", _sequence(k, name))
    sets = W.GrabNetTrainingSet                          # the stub grasps are all of training objects: "val" reads them
    monkeypatch.setattr(W, "GrabNetTrainingSet", lambda root, split, *a, **k: sets(root, "train", *a, **k))

    class Stop(Exception):
        pass

    seen = []

    def spy(*args, **settings):
        seen.append(settings["body"])
        raise Stop

    monkeypatch.setattr(T, "run_path", spy)
    with np.load(default_model_path(), allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    tall = tmp_path / "tall.npz"
    np.savez_compressed(tall, **{**arrays, "v_template": arrays["v_template"] * 1.2})
    grasps = {None: DATA_STUBS / "grasps",
              tall: relabelled(DATA_STUBS / "grasps", tmp_path / "tall_grasps", BodyModel.from_file(tall))}
    run = {"gnet": lambda g: run_train_gnet([g], tmp_path / "o.pt", epochs=1, threads=1, progress=False),
           "mnet": lambda g: run_train_mnet([approach], tmp_path / "o.pt", epochs=1, threads=1, progress=False),
           "grabnet_smplx": lambda g: W.train_grabnet_smplx(g, tmp_path / "o.pt", epochs=1, progress=False)}[trainer]
    for model in (None, tall):
        if model is not None:
            monkeypatch.setenv("GRASPKIT_MODEL", str(model))
        with pytest.raises(Stop):
            run(grasps[model])
        want = BodyModel.from_file(default_model_path(), flat_hand_mean=trainer != "grabnet_smplx").digest()
        assert seen[-1] == want
    assert seen[0] != seen[1]
