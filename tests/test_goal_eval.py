"""GOAL data adapters, labels and the `graspkit train gnet|mnet` commands on small GRAB-style files."""
from pathlib import Path

import numpy as np
import pytest
import torch
import trimesh
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from graspkit.body.markers import goal_vertices
from graspkit.data import load_motion
from graspkit.data.grab import GraspSequence, save_grasp_sequence
from graspkit.data.grasp import object_points
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


def test_train_commands_write_loadable_half_precision_weights(tmp_path):
    from graspkit.cli import main
    from graspkit.models.gnet import load_gnet
    from graspkit.models.mnet import load_mnet

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
    assert np.allclose(r.start.poses[0], seq.poses[0]) and np.allclose(r.start.trans[0], seq.trans[0])
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


def test_rollout_sliding_is_pooled_over_frame_pairs(monkeypatch):
    """GOAL's foot sliding over the rollouts is the share of all frame pairs that slide (as the other rows pool
    theirs), not a mean of per-clip shares: a 5-frame clip standing still and a 21-frame one sliding 2 cm a frame
    give 20 / 24, not 1 / 2."""
    import math

    import graspkit.models.mnet as mnet_mod
    from graspkit.eval_goal import rollout_eval
    from graspkit.models.mnet import ApproachClip, Rollout
    from graspkit.rotations import axis_angle_to_rot6d

    aa = torch.zeros(55, 3)
    aa[0] = torch.tensor([math.pi / 2, 0, 0])
    r6 = axis_angle_to_rot6d(aa)

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
