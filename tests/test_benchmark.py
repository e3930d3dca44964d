"""The cross-method benchmark (`graspkit eval --all`): the ground-truth row against smplx + trimesh, the planner
row against the metrics' definitions, the report round trip and the CLI's errors."""
import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import smplx
import torch
import trimesh
from scipy.spatial.transform import Rotation

import graspkit.benchmark as B
from graspkit.benchmark import (PAPER_ROWS, Row, goal_rows, ground_truth_grasps, markdown, paper_rows, planner_motion,
                                read_csv, run_all, saga_motion_rows, wandr_rows, write_report)
from graspkit.body import BodyModel
from graspkit.cli import main
from graspkit.data.grasp import split_of
from graspkit.paths import DATA_STUBS, default_model_path

from conftest import PROCEDURAL_MODEL

STUBS = Path(__file__).resolve().parents[1] / "data_stubs"
PARAMS = ("global_orient", "body_pose", "jaw_pose", "leye_pose", "reye_pose", "left_hand_pose", "right_hand_pose",
          "transl", "expression")


@pytest.fixture(scope="module")
def bm():
    return BodyModel.from_file(PROCEDURAL_MODEL, flat_hand_mean=True)


def _independent(path: Path, model) -> tuple[float, float, float]:
    """(in contact, volume cm^3, depth cm) of a grasp file's last frame, with smplx + trimesh only."""
    z = dict(np.load(path, allow_pickle=False))
    out = model(betas=torch.as_tensor(z["body.betas"][None, :10], dtype=torch.float64),
                **{k: torch.as_tensor(z[f"body.params.{k}"][-1:], dtype=torch.float64) for k in PARAMS})
    v = out.vertices[0].detach().numpy()
    body = trimesh.Trimesh(v, model.faces, process=False)
    obj = trimesh.load(path.parent / str(z["object.object_mesh"]), process=False)
    R = Rotation.from_rotvec(z["object.params.global_orient"][-1]).as_matrix()
    obj.apply_transform(np.block([[R, z["object.params.transl"][-1].astype(np.float64)[:, None]],
                                  [np.zeros((1, 3)), np.ones((1, 1))]]))
    inter = trimesh.boolean.intersection([body, obj], engine="manifold")
    near = np.all((v > obj.bounds[0] - 0.03) & (v < obj.bounds[1] + 0.03), axis=1)
    sd = trimesh.proximity.signed_distance(obj, v[near])                     # > 0 inside
    return float(sd.max() >= -0.002), 0.0 if inter.is_empty else inter.volume * 1e6, max(sd.max(), 0.0) * 100


def test_ground_truth_row_matches_smplx_and_trimesh(bm):
    """The row averages the test-split grasps' last frames; each recomputed with smplx + trimesh alone."""
    files = [p for p in sorted((STUBS / "grasps").glob("grasp_*.npz"))
             if split_of(str(np.load(p, allow_pickle=False)["obj_name"])) == "test"
             and bool(np.load(p, allow_pickle=False).get("grasp.accepted", True))][:3]
    assert files, "the stubs hold test-split grasps (mug)"
    model = smplx.create(str(STUBS / "body_models"), model_type="smplx", gender="neutral", ext="npz", use_pca=False,
                         flat_hand_mean=True, num_betas=10, dtype=torch.float64)
    ref = np.array([_independent(p, model) for p in files])
    row = ground_truth_grasps(bm, [STUBS / "grasps"], n=len(files))
    assert row.table == "grasp" and row.source == "graspkit" and f"{len(files)} grasps" in row.note
    assert row.values["contact_ratio"] == pytest.approx(ref[:, 0].mean())
    assert row.values["volume_cm3"] == pytest.approx(ref[:, 1].mean(), abs=0.05, rel=0.05)
    assert row.values["depth_cm"] == pytest.approx(ref[:, 2].mean(), abs=0.02)


def test_planner_row_recounts_sliding_and_jerk_with_smplx(bm):
    """GOAL's sliding (the lowest vertex moves > 1 cm per frame) and the mean jerk of the body joints on the approach
    clips, recounted from smplx's vertices and joints."""
    files = sorted((STUBS / "approach").glob("approach_*.npz"))
    row = planner_motion(bm, [STUBS / "approach"])
    slid = pairs = 0
    jerks = []
    for p in files:
        z = dict(np.load(p, allow_pickle=False))
        if split_of(str(z["obj_name"])) != "test":
            continue
        T = len(z["body.params.transl"])
        model_t = smplx.create(str(STUBS / "body_models"), model_type="smplx", gender="neutral", ext="npz",
                               use_pca=False, flat_hand_mean=True, num_betas=10, batch_size=T, dtype=torch.float64)
        out = model_t(betas=torch.as_tensor(z["body.betas"][None, :10], dtype=torch.float64).expand(T, -1),
                      **{k: torch.as_tensor(z[f"body.params.{k}"], dtype=torch.float64) for k in PARAMS})
        j = out.joints[:, :22].detach().numpy()
        v = out.vertices.detach().numpy()
        d3 = j[3:] - 3 * j[2:-1] + 3 * j[1:-2] - j[:-3]
        jerks.append(np.linalg.norm(d3, axis=-1).ravel() * 30.0 ** 3)
        low = v[:-1, :, 2].argmin(1)
        move = np.linalg.norm(v[1:, :, :][np.arange(T - 1), low] - v[:-1][np.arange(T - 1), low], axis=1)
        slid, pairs = slid + int((move > 0.01).sum()), pairs + T - 1
    assert pairs > 0
    assert row.values["slide_goal"] == pytest.approx(100 * slid / pairs, abs=1e-6)
    assert row.values["mean_jerk"] == pytest.approx(np.concatenate(jerks).mean(), rel=1e-3)


def test_report_round_trips_and_labels_the_papers(tmp_path):
    ours = [Row("grasp", "ground truth (synthetic)", "graspkit", {"contact_ratio": 1.0, "volume_cm3": 0.25},
                "3 grasps"),
            Row("motion", "WANDR", "graspkit", note="checkpoint missing: x.pt")]
    rows = ours + paper_rows()
    md, cs, png = write_report(rows, tmp_path)
    text = md.read_text()
    assert "| ground truth (synthetic) | graspkit (ours) | 1 | 0.25 |" in text
    assert "| WANDR | paper: WANDR Tab. 1 |" in text and "| GOAL (GNet + refinement) | paper: GOAL Tab. 1 |" in text
    back = read_csv(cs)
    assert [(r.table, r.method, r.source, r.values, r.note) for r in back] == \
        [(r.table, r.method, r.source, r.values, r.note) for r in rows]
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and not list(tmp_path.glob("*.tmp"))
    assert markdown(back) == markdown(rows)


def test_eval_cli_errors_name_what_is_wrong(tmp_path, capsys):
    assert main(["eval"]) == 2
    assert "--all" in capsys.readouterr().err
    with pytest.raises(FileNotFoundError, match="checkpoints: no folder"):
        run_all(tmp_path / "o", checkpoints=tmp_path / "nowhere", methods=("goal",))
    for methods in ("gt,nope", ",", ""):                   # "," ran nothing and wrote the papers' rows alone
        assert main(["eval", "--all", "--methods", methods, "--out", str(tmp_path)]) == 2
        assert "--methods: expected a comma-separated list" in capsys.readouterr().err
    assert not (tmp_path / "benchmark.csv").exists()
    assert main(["eval", "--all", "--data", str(tmp_path / "missing"), "--out", str(tmp_path)]) == 2
    assert "data" in capsys.readouterr().err


def test_a_method_comes_from_its_shipped_evaluation_or_says_what_is_missing(tmp_path):
    """--reuse reads <method>_eval.json (the evaluator's own output format); without it and without weights, a row
    names the missing checkpoint."""
    ck = tmp_path / "ck"
    ck.mkdir()
    saga = {"config": {"objects": ["mug"]}, "rows": {
        "WholeGrasp w/ opt. (Ours)": {"n": 6, "contact_ratio": 0.5, "volume_cm3": 1.25, "depth_cm": 0.5, "apd": 2.0},
        "GrabNet-SMPLX": {"n": 6, "contact_ratio": 0.25, "volume_cm3": 8.0, "depth_cm": 1.0, "apd": 0.5}}}
    (ck / "wholegrasp_eval.json").write_text(json.dumps(saga))
    rows = run_all(tmp_path / "out", data=[STUBS / "grasps"], checkpoints=ck, methods=("saga", "goal"), reuse=True)
    ours = {r.method: r for r in rows if r.source == "graspkit"}
    assert ours["SAGA (WholeGrasp w/ opt.)"].values == {"contact_ratio": 0.5, "volume_cm3": 1.25, "depth_cm": 0.5,
                                                        "apd": 2.0}
    assert ours["GrabNet-SMPLX"].values["volume_cm3"] == 8.0 and "wholegrasp_eval.json" in ours["GrabNet-SMPLX"].note
    assert not ours["GOAL (GNet + refinement)"].values
    assert f"checkpoint missing: {ck / 'gnet.pt'}" in ours["GOAL (GNet + refinement)"].note
    (ck / "gnet.pt").write_bytes(b"")                 # the evaluator loads mnet.pt too: named, not a crash
    rows = run_all(tmp_path / "out", data=[STUBS / "grasps"], checkpoints=ck, methods=("goal",), reuse=False)
    goal = next(r for r in rows if r.method == "GOAL (GNet + refinement)" and r.source == "graspkit")
    assert f"checkpoint missing: {ck / 'mnet.pt'}" in goal.note and not goal.values


def test_saga_motion_rows_from_a_run_equal_those_from_its_saved_evaluation(tmp_path):
    """MotionFill's Tab. 3 on the shipped test-object approach clips: run, saved as JSON, read back with --reuse."""
    ck = tmp_path / "ck"
    ck.mkdir()
    shutil.copy(DATA_STUBS / "checkpoints" / "motionfill.pt", ck / "motionfill.pt")
    run = [r for r in run_all(tmp_path / "a", data=[STUBS / "approach"], quick=True, checkpoints=ck,
                              methods=("saga_motion",)) if r.source == "graspkit"]
    assert {r.method for r in run} == {"SAGA (MotionFill, traj + local)", "SAGA (MotionFill, local, true trajectory)"}
    for r in run:
        assert 0 < r.values["ade"] < 1 and 0 <= r.values["skate_saga"] <= 1 and "min of 3 samples" in r.note
    shutil.copy(tmp_path / "a" / "motionfill_eval.json", ck / "motionfill_eval.json")
    again = [r for r in run_all(tmp_path / "b", data=[STUBS / "approach"], quick=True, checkpoints=ck,
                                methods=("saga_motion",), reuse=True) if r.source == "graspkit"]
    assert [r.values for r in again] == [r.values for r in run]


def test_rows_of_one_method_merge_and_keep_the_first_value():
    from graspkit.benchmark import merge

    a = Row("motion", "GOAL (GNet + MNet)", "graspkit", {"slide_goal": 6.0}, "8 rollouts")
    b = Row("motion", "GOAL (GNet + MNet)", "graspkit", {"slide_goal": 2.0, "mean_jerk": 200.0}, "2 motions")
    c = Row("motion", "GOAL (GNet + MNet)", "GOAL Sec. 4.2", {"slide_goal": 13.7}, "published")
    out = merge([a, c, b])
    assert [(r.source, r.values, r.note) for r in out] == [
        ("graspkit", {"slide_goal": 6.0, "mean_jerk": 200.0}, "8 rollouts; 2 motions"),
        ("GOAL Sec. 4.2", {"slide_goal": 13.7}, "published")]
    assert a.values == {"slide_goal": 6.0}                      # inputs untouched


def test_update_replaces_whole_rows_of_the_methods_run_and_keeps_the_others(tmp_path, capsys):
    """`graspkit eval --all --update`: a saved report keeps its other rows; a reused method's rows are replaced by
    those of its (new) evaluation file, values and note together."""
    from graspkit.benchmark import update

    old = [Row("grasp", "ground truth (synthetic)", "graspkit", {"contact_ratio": 1.0}, "3 grasps"),
           Row("grasp", "SAGA (WholeGrasp w/ opt.)", "graspkit", {"contact_ratio": 0.1, "apd": 9.0}, "old run")]
    new = [Row("grasp", "SAGA (WholeGrasp w/ opt.)", "graspkit", {"contact_ratio": 0.5}, "new run"),
           Row("grasp", "GrabNet-SMPLX", "graspkit", {"contact_ratio": 0.25}, "new run")]
    assert [(r.method, r.values, r.note) for r in update(old, new)] == [
        ("ground truth (synthetic)", {"contact_ratio": 1.0}, "3 grasps"),
        ("SAGA (WholeGrasp w/ opt.)", {"contact_ratio": 0.5}, "new run"), ("GrabNet-SMPLX", {"contact_ratio": 0.25},
                                                                          "new run")]
    out = tmp_path / "report"
    assert main(["eval", "--all", "--update", "--methods", "saga", "--out", str(out)]) == 2
    assert "--update" in capsys.readouterr().err and not out.joinpath("benchmark.csv").exists()
    write_report(old + paper_rows(), out)
    ck = tmp_path / "ck"
    ck.mkdir()
    (ck / "wholegrasp_eval.json").write_text(json.dumps({"config": {"objects": ["mug"]}, "rows": {
        "WholeGrasp w/ opt. (Ours)": {"n": 6, "contact_ratio": 0.5, "volume_cm3": 1.25, "depth_cm": 0.5, "apd": 2.0}}}))

    rows = update(read_csv(out / "benchmark.csv"), run_all(tmp_path / "x", data=[STUBS / "grasps"], checkpoints=ck,
                                                            methods=("saga",), reuse=True))
    ours = {r.method: r for r in rows if r.source == "graspkit"}
    assert ours["ground truth (synthetic)"].values == {"contact_ratio": 1.0}
    assert ours["SAGA (WholeGrasp w/ opt.)"].values == {"contact_ratio": 0.5, "volume_cm3": 1.25, "depth_cm": 0.5,
                                                        "apd": 2.0}
    assert len([r for r in rows if r.source != "graspkit"]) == len(paper_rows())


def test_a_benchmark_csv_cut_short_or_a_damaged_evaluation_to_reuse_is_named(tmp_path):
    """`eval --all --update` took a benchmark.csv cut inside its last number (47.835 read as 47) and wrote the cut
    value into the new report; `--reuse` of a damaged shipped *_eval.json failed after the other methods' work with an
    unnamed JSON error or a KeyError traceback (an independent check). Both are refused, naming the file; the reuse
    check comes before any work (no --out folder made)."""
    rows = [Row("motion", "WANDR", "graspkit", {"mean_jerk": 47.835}, "4 motions")]
    out = tmp_path / "report"
    write_report(rows, out)
    good = (out / "benchmark.csv").read_text()
    assert read_csv(out / "benchmark.csv")[0].values == {"mean_jerk": 47.835}
    (out / "benchmark.csv").write_text(good[:good.index("47.835") + 2])
    with pytest.raises(ValueError, match=r"benchmark.csv is cut short"):
        read_csv(out / "benchmark.csv")
    (out / "benchmark.csv").write_text(good.replace(",4 motions\n", "\n"))          # a line of 5 fields, ended
    with pytest.raises(ValueError, match=r"benchmark.csv, line 2: expected 6 fields"):
        read_csv(out / "benchmark.csv")
    ck = tmp_path / "ck"
    ck.mkdir()
    for text in ('{"config": {"objects": ["mug"]}, "rows": {', "{}", "[]", ""):
        (ck / "wholegrasp_eval.json").write_text(text)
        with pytest.raises(ValueError, match=rf"--reuse: {ck / 'wholegrasp_eval.json'} is damaged or not saga's"):
            run_all(tmp_path / "x", data=[STUBS / "grasps"], checkpoints=ck, methods=("gt", "saga"), reuse=True)
        assert not (tmp_path / "x").exists()


def test_two_updates_at_once_keep_each_others_rows(tmp_path, monkeypatch):
    """Two `eval --all --update` runs into one --out each read benchmark.csv at their start; the later writer dropped
    the rows the other had written meanwhile (an independent check). The file is read again when the rows are merged
    and written, inside `paths.locked` on --out's .benchmark.lock (taken only with --update; `locked` itself is tested
    in test_caches)."""
    import graspkit.paths as P

    taken = []
    real_locked = P.locked
    monkeypatch.setattr(P, "locked", lambda path: taken.append(path) or real_locked(path))
    out = tmp_path / "report"
    write_report([Row("grasp", "ground truth (synthetic)", "graspkit", {"contact_ratio": 0.9}, "old")], out)

    def run_all(out_dir, **kw):                      # while this run works, another update lands in the file
        other = read_csv(out / "benchmark.csv")
        write_report(B.update(other, [Row("motion", "WANDR", "graspkit", {"sr": 0.99}, "the other run")]), out)
        return [Row("grasp", "ground truth (synthetic)", "graspkit", {"contact_ratio": 1.0}, "this run")]

    monkeypatch.setattr(B, "run_all", run_all)
    assert main(["eval", "--all", "--update", "--methods", "gt", "--out", str(out)]) == 0
    rows = {r.method: (r.values, r.note) for r in read_csv(out / "benchmark.csv")}
    assert rows == {"ground truth (synthetic)": ({"contact_ratio": 1.0}, "this run"),
                    "WANDR": ({"sr": 0.99}, "the other run")}
    assert taken == [out / ".benchmark.lock"]
    assert main(["eval", "--all", "--methods", "gt", "--out", str(tmp_path / "fresh")]) == 0
    assert taken == [out / ".benchmark.lock"] and not (tmp_path / "fresh" / ".benchmark.lock").exists()


def test_a_row_holds_one_protocol_the_common_motions_and_goals_saga_clips_get_rows_of_their_own(tmp_path, bm):
    """WANDR's own grid row keeps the grid's FS; its motion on the common goals is a row of its own, measured here
    again with the metrics' definition (the lowest vertex's horizontal step > 0.66 cm); GOAL's evaluation gives
    SAGA's sliding on its clips a row."""
    from graspkit.benchmark import COMMON, common_motion_rows, wandr_motions
    from graspkit.eval_wandr import goal_from_cylinder

    ck = tmp_path / "ck"
    ck.mkdir()
    for name in ("wandr.pt", "wandr_eval.json", "goal_eval.json"):
        shutil.copy(STUBS / "checkpoints" / name, ck / name)
    common = common_motion_rows(bm, [STUBS / "approach"], ck, k=1)          # only WANDR's weights are there
    assert [r.method for r in common if r.values] == ["WANDR · 1 common motion"]
    missing = {r.method: r.note for r in common if not r.values}      # named, not left out without a word
    assert missing == {f"{m} · 1 common motion": f"checkpoint missing: {ck / f}" for m, f in (   # the first file
        ("SAGA (MotionFill + GraspMotion-Opt)", "motionfill.pt"), ("GOAL (GNet + MNet)", "gnet.pt"))}   # each loads
    goal = torch.stack([goal_from_cylinder(0.0, 2.0, 0.9)])
    (m,) = wandr_motions(ck / "wandr.pt", goal, 120)
    v = m.vertices(bm).numpy()
    low = v[:-1, :, 2].argmin(1)                                           # the lowest vertex at t, followed to t+1
    step = np.linalg.norm((v[1:] - v[:-1])[np.arange(len(low)), low, :2], axis=-1)
    (measured,) = [r for r in common if r.values]
    assert measured.values["fs_wandr"] == pytest.approx(100 * np.mean(step > 0.0066), abs=1e-9)
    rows = run_all(tmp_path / "out", data=[STUBS / "approach"], checkpoints=ck, methods=("wandr", "goal"), reuse=True)
    ours = {r.method: r for r in rows if r.source == "graspkit"}
    grid = json.loads((ck / "wandr_eval.json").read_text())["summary"]
    assert ours["WANDR"].values["fs_wandr"] == pytest.approx(grid["FS"])
    assert not any(COMMON in name for name in ours)
    sliding = json.loads((ck / "goal_eval.json").read_text())["sliding"]
    got = {r.method: r.values for r in goal_rows(json.loads((ck / "goal_eval.json").read_text())) if r.table == "motion"}
    assert got["SAGA (MotionFill + GraspMotion-Opt) · GOAL's 12 clips"]["slide_goal"] == pytest.approx(
        100 * sliding["SAGA (WholeGrasp + MotionFill, ours)"])
    quick = {"rollouts": {"clips": 2}, "sliding": sliding}                  # a --quick run's 2 clips are named so
    assert "SAGA (MotionFill + GraspMotion-Opt) · GOAL's 2 clips" in {r.method for r in goal_rows(quick)}


def test_goal_sliding_rows_are_percent():
    """The foot-sliding column is in percent: GOAL's published 13.7 % is eval_goal's 0.137, and a measured share of
    0.137 (GOAL) or 0.25 (SAGA) reads 13.7 and 25.0."""
    from graspkit.eval_goal import PAPER_SLIDING

    paper = [v for t, m, s, v in PAPER_ROWS if s == "GOAL Sec. 4.2" and m.startswith("GOAL")][0]["slide_goal"]
    assert paper == pytest.approx(100 * PAPER_SLIDING["GOAL"])
    rows = goal_rows({"sliding": {"GOAL (GNet + MNet, ours)": 0.137, "SAGA (WholeGrasp + MotionFill, ours)": 0.25},
                      "rollouts": {"clips": 4}})
    got = {r.method: r.values["slide_goal"] for r in rows}
    assert got["GOAL (GNet + MNet)"] == pytest.approx(13.7)
    assert [v for k, v in got.items() if k.startswith("SAGA")][0] == pytest.approx(25.0)


def test_planner_row_gives_goals_sliding_in_percent_on_a_clip_that_slides(tmp_path):
    """A shipped test-object approach clip pushed 2 cm sideways per frame for 20 frames (its object with it, so the
    grasp and its labels still hold): GOAL's sliding (the lowest vertex moves > 1 cm to the next frame, §4.2) counted
    by hand on its meshes, in % as the column says."""
    from graspkit.data.grab import load_grasp_sequence
    from graspkit.data.motion import Motion

    src = DATA_STUBS / "approach" / "approach_000000.npz"            # the mug: a test object
    z = dict(np.load(src, allow_pickle=False))
    tr = z["body.params.transl"].copy()
    k = np.arange(len(tr))
    tr[:, 0] += 0.02 * np.clip(k - 19, 0, 20)
    z["object.params.transl"] = z["object.params.transl"] + tr - z["body.params.transl"]
    z["body.params.transl"] = tr
    np.savez(tmp_path / "approach_000000.npz", **z)
    bm = BodyModel.from_file(default_model_path(), flat_hand_mean=True)
    row = planner_motion(bm, [tmp_path])
    s = load_grasp_sequence(tmp_path / "approach_000000.npz")
    v = Motion(s.poses, s.trans, s.betas[:10], 30.0).vertices(bm).double().numpy()
    T = len(v)
    low = v[:-1, :, 2].argmin(1)
    move = np.linalg.norm(v[1:][np.arange(T - 1), low] - v[:-1][np.arange(T - 1), low], axis=1)
    share = float((move > 0.01).mean())
    assert share > 0.2
    assert row.values["slide_goal"] == pytest.approx(100 * share, abs=1e-6)


def test_motionfill_rows_keep_their_protocols_names():
    """SAGA Tab. 3: 'Ours' is trajectory + local (TrajFill then LocalMotionFill), 'Ours-Local' the local infilling on the
    true trajectory; the benchmark's 'traj + local' row is 'Ours' and sits beside the paper's ADE 0.083 / skating 0.394
    (Tab. 3, 'Ours')."""
    rows = saga_motion_rows({"rows": {"Ours": {"ADE": 0.11, "skating": 0.22}, "Ours-Local": {"ADE": 0.33, "skating": 0.44}},
                             "test_windows": 5})
    by = {r.method: r.values for r in rows}
    assert by["SAGA (MotionFill, traj + local)"] == {"ade": 0.11, "skate_saga": 0.22}
    assert by["SAGA (MotionFill, local, true trajectory)"] == {"ade": 0.33, "skate_saga": 0.44}
    paper = next(v for t, m, s, v in PAPER_ROWS if m == "SAGA (MotionFill, traj + local)")
    assert paper == {"ade": 0.083, "skate_saga": 0.394}


def test_wandr_row_takes_the_mean_distance_to_goal():
    """WANDR §4.3's DTG is the mean closest wrist distance over the rollouts (the summary's 'DTG', not its median)."""
    s = {"SR": 30.0, "FS": 12.0, "DTG": 40.0, "DTG_median": 10.0, "rollouts": 5}
    rows = wandr_rows({"summary": s, "planner": {**s, "DTG": 50.0, "DTG_median": 5.0}})
    assert [r.values for r in rows] == [{"SR": 30.0, "fs_wandr": 12.0, "DTG": 40.0},
                                        {"SR": 30.0, "fs_wandr": 12.0, "DTG": 50.0}]


def test_papers_wandr_row_is_wandr_table_1():
    """WANDR Tab. 1 (full intention): SR 32 %, FS 16 %, DTG 24.8 cm; the same figures as eval_wandr.PAPER's."""
    from graspkit.eval_wandr import PAPER

    row = next(v for t, m, s, v in PAPER_ROWS if m == "WANDR" and s == "WANDR Tab. 1")
    assert row == {"SR": 32.0, "fs_wandr": 16.0, "DTG": 24.8}
    assert (row["SR"], row["fs_wandr"], row["DTG"]) == PAPER["WANDR"]
    goal = next(v for t, m, s, v in PAPER_ROWS if m == "GOAL (on WANDR's grid)")
    assert (goal["SR"], goal["fs_wandr"], goal["DTG"]) == PAPER["GOAL"] == (0.0, 29.0, 149.2)


def test_common_wandr_motions_go_to_k_different_directions(tmp_path, monkeypatch):
    """common_motion_rows: WANDR towards k goals 2 m away, 0.9 m high, in k different directions (every 360/k deg)."""
    from graspkit.data import load_motion

    (tmp_path / "wandr.pt").write_bytes(b"")                   # present; the motions are stubbed
    seen = []

    def fake(ck, goals, t_goal, seed=0, lift=False, bm=None):
        seen.append(goals.clone())
        m = load_motion(DATA_STUBS / "motion" / "reach" / "reach_000002.npz").slice(0, 6)
        return [m] * len(goals)

    monkeypatch.setattr(B, "wandr_motions", fake)
    bm = BodyModel.from_file(default_model_path(), flat_hand_mean=True)
    rows = B.common_motion_rows(bm, [DATA_STUBS / "approach"], tmp_path, k=4)
    assert len(seen) == 1 and any(r.method.startswith("WANDR") and r.values for r in rows)
    g = seen[0].double().numpy()
    assert g.shape == (4, 3) and np.allclose(np.linalg.norm(g[:, :2], axis=1), 2.0) and np.allclose(g[:, 2], 0.9)
    ang = np.sort(np.degrees(np.arctan2(g[:, 1], g[:, 0])) % 360)
    assert np.allclose(ang, [0, 90, 180, 270], atol=1e-4)


def test_motionfill_motions_stand_on_the_floor_z_0(monkeypatch):
    """motionfill_motions returns the fitted bodies with the scene's floor moved to z = 0 (its docstring): a body whose
    soles stand on the scene's floor (z = -0.85 in MotionFill's canonical frame) comes back with its soles at 0, the
    object mesh moved the same way."""
    import graspkit.eval_motionfill as EM
    from graspkit.benchmark import motionfill_motions

    bm = BodyModel.from_file(default_model_path(), flat_hand_mean=True)
    floor, F = -0.85, 3
    with torch.no_grad():
        z0 = float(bm().vertices[0, :, 2].min())
    transl = torch.tensor([[0.1, 0.2, floor - z0]]).expand(F, 3)[None].clone()
    box = trimesh.creation.box((0.1, 0.1, 0.1))
    box.apply_translation([0.5, 0.0, floor + 0.8])
    params = {"poses": torch.zeros(1, F, 165), "transl": transl, "betas": torch.zeros(1, 10)}
    monkeypatch.setattr(EM, "load_motionfill", lambda path: None)
    monkeypatch.setattr(EM, "graspmotion_eval", lambda model, files, **kw: {
        "result": type("R", (), {"params": params})(), "scenes": [{"floor": floor, "mesh": box}]})
    motions, scenes = motionfill_motions([DATA_STUBS / "approach" / "approach_000000.npz"], DATA_STUBS / "checkpoints")
    v = motions[0].vertices(bm)
    assert abs(float(v[:, :, 2].min())) < 1e-5
    assert np.allclose(scenes[0]["mesh"].bounds[:, 2], [0.75, 0.85], atol=1e-6)


def _name(path: Path) -> str:
    """The object name a GRAB-style file stores, read with numpy."""
    with np.load(path, allow_pickle=False) as z:
        return str(z["obj_name"])


def _names(folder: Path, kind: str) -> list[str]:
    """Object names of a folder's `kind` files, in file order."""
    return [_name(f) for f in sorted(folder.glob(f"{kind}_*.npz"))]


def test_goal_grasp_rows_keep_the_refinement_and_the_pen_row_apart():
    """GOAL Tab. 1: eval_goal's 'GNet' row (Eq. 4-8 refinement) is the benchmark's 'GOAL (GNet + refinement)', its
    E_pen row the one named so."""
    from graspkit.eval_goal import PEN_ROW

    rows = goal_rows({"tab1": {"GNet": {"n": 4, "contact_ratio": 0.5, "volume_cm3": 2.0, "depth_cm": 0.25},
                               PEN_ROW: {"n": 4, "contact_ratio": 0.75, "volume_cm3": 1.0, "depth_cm": 0.125}}})
    by = {r.method: r.values for r in rows}
    assert by["GOAL (GNet + refinement)"] == {"contact_ratio": 0.5, "volume_cm3": 2.0, "depth_cm": 0.25}
    assert by["GOAL (GNet + refinement + E_pen, graspkit's)"]["volume_cm3"] == 1.0


def test_run_saga_evaluates_the_test_objects_with_the_quick_protocol(tmp_path, monkeypatch):
    """run_saga: the held-out (test-split) objects of the folder; quick = one placement, three samples, one GT grasp;
    otherwise eval_saga's defaults."""
    import graspkit.eval_saga as ES

    seen = []
    monkeypatch.setattr(ES, "evaluate", lambda root, cfg, **kw: seen.append(cfg) or {"rows": {}})
    want = tuple(sorted({n for n in _names(DATA_STUBS / "grasps", "grasp") if split_of(n) == "test"}))
    assert want == ("mug",)
    B.run_saga(DATA_STUBS / "grasps", tmp_path / "s.json", True, DATA_STUBS / "checkpoints")
    B.run_saga(DATA_STUBS / "grasps", tmp_path / "s.json", False, DATA_STUBS / "checkpoints")
    quick, full = seen
    assert (quick.objects, quick.placements, quick.samples, quick.gt_grasps) == (want, 1, 3, 1)
    assert full == ES.EvalConfig(objects=want)


def test_run_saga_motion_evaluates_the_test_object_clips(tmp_path, monkeypatch):
    """run_saga_motion hands MotionFill's Tab. 3 the windows of the test-object approach clips only (the stubs: two
    mug clips, two bottle clips)."""
    import graspkit.eval_motionfill as EM

    seen = []
    monkeypatch.setattr(EM, "load_motionfill", lambda path: None)
    monkeypatch.setattr(EM, "evaluate", lambda model, arr, clips, n=10: seen.append((arr, clips)) or {})
    res = B.run_saga_motion(DATA_STUBS / "approach", tmp_path / "m.json", True, DATA_STUBS / "checkpoints")
    (arr, clips), = seen
    _, names = EM.approach_motions(DATA_STUBS / "approach")
    assert sorted(names[c] for c in clips) == ["mug", "mug"]
    assert res["test_windows"] == int(np.isin(arr["clip"], clips).sum()) and res["samples"] == 3


def _sliding_motions(k: int) -> list:
    """k short clips pushed 2 cm sideways per frame (they slide in GOAL's sense)."""
    from graspkit.data import load_motion
    from graspkit.data.motion import Motion

    m = load_motion(DATA_STUBS / "motion" / "reach" / "reach_000002.npz").slice(0, 6)
    tr = m.trans + 0.02 * np.arange(len(m.trans))[:, None] * np.array([1.0, 0.0, 0.0])
    return [Motion(m.poses, tr, m.betas, m.fps)] * k


def test_common_wandr_motions_run_four_seconds_and_slide_in_percent(tmp_path, monkeypatch):
    """common_motion_rows: WANDR's goal frame is 4 s at 30 fps (120), and the sliding column is in percent (100 x
    graspkit.metrics.motion_quality's share of the same motions)."""
    from graspkit.metrics import motion_quality

    (tmp_path / "wandr.pt").write_bytes(b"")
    seen = []
    monkeypatch.setattr(B, "wandr_motions", lambda ck, goals, t_goal, seed=0, lift=False, bm=None:
                        seen.append(t_goal) or _sliding_motions(len(goals)))
    bm = BodyModel.from_file(default_model_path(), flat_hand_mean=True)
    rows = B.common_motion_rows(bm, [DATA_STUBS / "approach"], tmp_path, k=2)
    assert seen == [120]
    (w,) = [r for r in rows if r.method.startswith("WANDR")]
    share = motion_quality(bm, _sliding_motions(2))["slide_goal"]
    assert share > 0.2 and w.values["slide_goal"] == pytest.approx(100 * share)


def test_common_saga_and_goal_motions_start_from_test_object_clips(tmp_path, monkeypatch):
    """The common motions of SAGA and GOAL come from the first k test-object approach clips only (the stubs hold two
    mug and two bottle clips; k = 4)."""
    from graspkit.data.grab import load_grasp_sequence

    for f in ("motionfill.pt", "pose_prior.pt", "motionfill_smooth_ae.pt", "gnet.pt", "mnet.pt"):   # all they load
        (tmp_path / f).write_bytes(b"")
    files, seqs = [], []
    monkeypatch.setattr(B, "motionfill_motions", lambda fs, ck: files.extend(fs) or (_sliding_motions(len(fs)), []))
    monkeypatch.setattr(B, "goal_motions", lambda ss, ck: seqs.extend(ss) or _sliding_motions(len(ss)))
    bm = BodyModel.from_file(default_model_path(), flat_hand_mean=True)
    B.common_motion_rows(bm, [DATA_STUBS / "approach"], tmp_path, k=4)
    assert [load_grasp_sequence(f).object_name for f in files] == ["mug", "mug"]
    assert [s.object_name for s in seqs] == ["mug", "mug"]


def test_run_all_runs_each_saga_evaluator_on_its_kind_of_data(tmp_path, monkeypatch):
    """run_all with data = [grasps folder, approach folder]: SAGA's grasp evaluation reads the grasp files, its
    MotionFill evaluation the approach clips."""
    ck = tmp_path / "ck"
    ck.mkdir()
    for f in ("wholegrasp.pt", "pose_prior.pt", "motionfill.pt"):
        (ck / f).write_bytes(b"")
    seen = {}
    monkeypatch.setattr(B, "run_saga", lambda root, o, q, c: seen.setdefault("saga", Path(root)) and {"rows": {}})
    monkeypatch.setattr(B, "run_saga_motion", lambda root, o, q, c: seen.setdefault("motion", Path(root)) and {"rows": {}})
    run_all(tmp_path / "out", data=[DATA_STUBS / "grasps", DATA_STUBS / "approach"], checkpoints=ck,
            methods=("saga", "saga_motion"))
    assert list(seen["saga"].glob("grasp_*.npz")) and list(seen["motion"].glob("approach_*.npz"))


def test_shipped_evaluation_is_read_only_with_reuse(tmp_path):
    """Without --reuse a method runs its evaluator: a shipped <method>_eval.json is not read, and without weights the
    row says the checkpoint is missing."""
    ck = tmp_path / "ck"
    ck.mkdir()
    (ck / "wholegrasp_eval.json").write_text(json.dumps({"config": {"objects": ["mug"]}, "rows": {
        "WholeGrasp w/ opt. (Ours)": {"n": 6, "contact_ratio": 0.5, "volume_cm3": 1.25, "depth_cm": 0.5}}}))
    rows = run_all(tmp_path / "out", data=[DATA_STUBS / "grasps"], checkpoints=ck, methods=("saga",))
    (saga,) = [r for r in rows if r.source == "graspkit"]
    assert not saga.values and f"checkpoint missing: {ck / 'wholegrasp.pt'}" in saga.note


def test_markdown_lists_ours_before_the_papers_rows():
    """Each table lists graspkit's rows first, then the papers' (markdown's docstring), whatever the input order."""
    ours = Row("grasp", "ground truth (synthetic)", "graspkit", {"contact_ratio": 1.0}, "3 grasps")
    lines = [x for x in markdown(paper_rows() + [ours]).splitlines() if x.startswith("| ")]
    grasp = [x for x in lines if "contact ratio" not in x and "foot" not in x][:6]
    assert "graspkit (ours)" in grasp[0] and all("paper:" in x for x in grasp[1:])


def test_markdown_prints_the_papers_figures_as_published_and_ours_to_3_figures():
    """A paper's cell keeps every digit it was published with (14.15 cm³, 149.2 cm); ours are rounded to 3."""
    ours = Row("grasp", "ground truth (synthetic)", "graspkit", {"volume_cm3": 14.15}, "")
    cells = {x.split(" | ")[0] + " | " + x.split(" | ")[1]: x.split(" | ")
             for x in markdown(paper_rows() + [ours]).splitlines() if x.startswith("| ")}
    assert cells["| GrabNet-SMPLX | paper: SAGA Tab. 1"][3] == "14.15"
    assert "149.2" in cells["| GOAL (on WANDR's grid) | paper: WANDR Tab. 1"]
    assert cells["| ground truth (synthetic) | graspkit (ours)"][3] == "14.2"


def test_papers_saga_rows_are_saga_tables_1_and_2():
    """The benchmark's SAGA figures are eval_saga's transcriptions of Tab. 1 (ours, GrabNet-SMPLX) and Tab. 2 (GT)."""
    from graspkit.eval_saga import PAPER_TAB1, PAPER_TAB2

    by = {(m, s): v for t, m, s, v in PAPER_ROWS}
    for name, key in (("SAGA (WholeGrasp w/ opt.)", "WholeGrasp w/ opt. (Ours)"), ("GrabNet-SMPLX", "GrabNet-SMPLX")):
        v = by[(name, "SAGA Tab. 1")]
        assert (v["apd"], v["contact_ratio"], v["volume_cm3"], v["depth_cm"]) == PAPER_TAB1[key]
    gt = by[("ground truth (GRAB)", "SAGA Tab. 2")]
    assert (gt["contact_ratio"], gt["volume_cm3"], gt["depth_cm"]) == tuple(c[0] for c in PAPER_TAB2["GT mesh"])


def test_ground_truth_row_averages_the_grasps_volumes_and_depths(tmp_path):
    """The ground-truth row's volume and depth are the means over its grasps: the row of three grasps equals the
    mean of the three one-grasp rows (each grasp file alone in a folder)."""
    bm = BodyModel.from_file(default_model_path(), flat_hand_mean=True)
    files = [f for f in sorted((DATA_STUBS / "grasps").glob("grasp_*.npz")) if split_of(_name(f)) == "test"][:3]
    one = []
    for i, f in enumerate(files):
        (tmp_path / str(i)).mkdir()
        shutil.copy(f, tmp_path / str(i) / f.name)
        one.append(ground_truth_grasps(bm, [tmp_path / str(i)]).values)
    vols = [r["volume_cm3"] for r in one]
    assert np.ptp(vols) > 1e-3 and abs(np.mean(vols) - np.median(vols)) > 1e-4   # a case where mean != median
    row = ground_truth_grasps(bm, [DATA_STUBS / "grasps"], n=3).values
    for k in ("contact_ratio", "volume_cm3", "depth_cm"):
        assert row[k] == pytest.approx(np.mean([r[k] for r in one]), rel=1e-9, abs=1e-12), k


def test_folders_are_found_by_what_they_hold_and_a_refused_run_writes_nothing(tmp_path, monkeypatch, capsys):
    """--data in either order: SAGA takes the folder with grasp files, MotionFill the one with approach clips (saga
    read only the first folder and saga_motion only the last); a folder without approach clips is named (it failed as
    'motions: no clip gave a window'); a refused run leaves no --out folder; --all's --out is a folder whatever its
    name (x.csv was asked to be a file)."""
    seen = {}
    monkeypatch.setattr(B, "run_saga", lambda folder, o, quick, ck: seen.setdefault("saga", folder) and {"rows": {}})
    monkeypatch.setattr(B, "run_saga_motion", lambda folder, o, quick, ck: seen.setdefault("motion", folder) and {})
    monkeypatch.setattr(B, "_method", lambda ck, out, rows, run, *a: (run(out), [])[1])
    B.run_all(tmp_path / "o", data=[STUBS / "approach", STUBS / "grasps"], methods=("saga", "saga_motion"))
    assert seen == {"saga": STUBS / "grasps", "motion": STUBS / "approach"}
    monkeypatch.undo()
    with pytest.raises(FileNotFoundError, match="data: no approach clips \\(approach_\\*.npz\\) in"):
        B.run_saga_motion(STUBS / "grasps", tmp_path / "m.json", True, DATA_STUBS / "checkpoints")
    with pytest.raises(FileNotFoundError, match="data: no folder"):
        B.run_all(tmp_path / "refused", data=[tmp_path / "missing"], methods=("gt",))
    assert not (tmp_path / "refused").exists()
    folder = tmp_path / "dir.csv"
    folder.mkdir()
    monkeypatch.setattr(B, "run_all", lambda *a, **k: [])
    main(["eval", "--all", "--methods", "gt", "--out", str(folder)])
    assert "expected a file path" not in capsys.readouterr().err
