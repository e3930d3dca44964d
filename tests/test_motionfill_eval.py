"""MotionFill evaluation (SAGA Tab. 3) and training command: PSKL, skating, the approach scene, `graspkit train motionfill`."""
import json
import re
from pathlib import Path

import numpy as np
import pytest
import torch

from graspkit.body import BodyModel
from graspkit.body.markers import saga_sparse_markers
from graspkit.eval_motionfill import (approach_scene, heel_columns, linear_local, load_motionfill, pskl, pskl_still_share,
                                      skating)
from graspkit.paths import DATA_STUBS, default_model_path
from graspkit.rotations import axis_angle_to_matrix

STUB = DATA_STUBS / "approach" / "approach_000000.npz"


def test_pskl_is_zero_for_equal_motions_and_positive_otherwise():
    g = np.random.default_rng(0)
    x = np.cumsum(g.normal(0, 0.01, (2, 30, 5, 3)), 1)
    assert pskl(x, x) == pytest.approx((0.0, 0.0), abs=1e-9)
    y = x + g.normal(0, 0.01, x.shape)                       # white noise on top: a flatter acceleration spectrum
    a, b = pskl(y, x)
    assert a > 0 and b > 0 and a != pytest.approx(b)
    assert pskl(np.stack([y, y], 1), x) == pytest.approx((a, b))   # (N, K, ...) samples against (N, ...)


def test_pskl_matches_scipy_kl_per_coordinate_and_leaves_out_coordinates_that_never_accelerate():
    from scipy.stats import entropy

    g = np.random.default_rng(1)
    x = np.cumsum(g.normal(0, 0.01, (3, 40, 4, 3)), 1)
    y = np.cumsum(g.normal(0, 0.01, x.shape), 1)
    y[..., 2] = np.linspace(0.0, 0.3, 40)[None, :, None]     # z: a straight line in time, no acceleration at all

    def kl(a, b):                                           # scipy's KL of the normalised spectra, per coordinate
        pa, pb = (np.abs(np.fft.rfft(np.diff(v, 2, axis=1), axis=1)) ** 2 for v in (a, b))
        return np.mean([entropy(pa[n, :, j, c], pb[n, :, j, c]) for n in range(3) for j in range(4) for c in range(2)])

    got = pskl(y, x)
    assert got == pytest.approx((kl(y, x), kl(x, y)), rel=1e-5)          # x and y coordinates only
    assert pskl(y[..., :2], x[..., :2]) == pytest.approx(got)
    assert pskl_still_share(y) == pytest.approx(1 / 3) and pskl_still_share(x) == 0.0


def test_skating_counts_frames_where_both_heels_slide_near_the_ground():
    heels = heel_columns()
    T = 11
    m = np.zeros((T, 79, 3))
    m[:, heels, 0] = np.arange(T)[:, None] * 0.01            # 0.3 m/s, both heels, on the ground
    assert skating(m, np.array(0.0), heels) == 1.0
    m[:, heels[0], 0] = 0.0                                  # one heel planted
    assert skating(m, np.array(0.0), heels) == 0.0
    m[:, heels[0], 0] = m[:, heels[1], 0]
    assert skating(m, np.array(-0.2), heels) == 0.0          # both 20 cm above the ground: stepping, not skating


def test_linear_local_keeps_the_known_frames():
    x = np.random.default_rng(1).normal(size=(2, 61, 79, 3))
    y = linear_local(x)
    np.testing.assert_allclose(y[:, [0, -1]], x[:, [0, -1]])
    np.testing.assert_allclose(y[:, 30], 0.5 * (x[:, 0] + x[:, -1]))


def test_approach_scene_puts_the_object_in_the_window_frame():
    torch.set_num_threads(1)
    bm = BodyModel.from_file(default_model_path())
    s = approach_scene(STUB, bm)
    assert s["markers"].shape == (61, 79, 3) and s["traj"].shape == (62, 4)
    d = np.linalg.norm(s["markers"][-1][:, None] - s["points"][None], axis=-1).min()
    assert d < 0.02                                          # the grasping hand touches the object at frame T
    assert abs(s["markers"][..., 2].min() - s["floor"]) < 0.03
    # the mesh and the sampled points are the same object in the same frame
    near = np.abs(s["mesh"].nearest.signed_distance(s["points"][:200])).max()
    assert near < 2e-3
    np.testing.assert_allclose(np.linalg.norm(s["normals"], axis=-1), 1.0, atol=1e-5)


def test_shipped_model_beats_linear_interpolation_on_the_shipped_approach_clips():
    """Tab. 3's ADE (min of 10 samples) on the four shipped approach clips (mug: a held-out object; bottle)."""
    from graspkit.data.motionfill_dataset import make_windows
    from graspkit.eval_motionfill import approach_motions, evaluate

    torch.set_num_threads(1)
    bm = BodyModel.from_file(default_model_path())
    motions, names = approach_motions(DATA_STUBS / "approach")
    arr = make_windows(motions, bm, align_end=True, progress=False)
    rows = evaluate(load_motionfill(), arr, np.arange(len(motions)), n=10, seed=0)
    assert rows["Ours-Local"]["ADE"] < rows["Linear (local)"]["ADE"]
    assert rows["Ours"]["ADE"] < rows["Linear"]["ADE"]
    assert rows["Ours"]["APD"] > 0 and rows["Ground truth"]["skating"] < 0.1


def test_train_command_end_to_end_on_the_shipped_approach_clips(tmp_path, monkeypatch, capsys):
    """`graspkit train motionfill --stage traj` on the four shipped clips (bottle: train, mug: test) writes a
    float16 checkpoint that loads and says where the run's log and loss plot are; the windows are cached; an unknown
    stage is refused."""
    from graspkit.cli import main

    monkeypatch.setenv("GRASPKIT_CACHE", str(tmp_path / "cache"))
    out = tmp_path / "mf.pt"
    rc = main(["train", "motionfill", "--stage", "traj", "--data", str(DATA_STUBS / "approach"), "--clips", "4",
               "--epochs", "2", "--out", str(out)])
    assert rc == 0 and out.is_file()
    assert len(list((tmp_path / "cache" / "motionfill").glob("approach_4_*.npz"))) == 1
    said = re.findall(r"training state (\S+); per-epoch log (\S+), loss plot (\S+) beside it", capsys.readouterr().out)
    assert len(said) == 1
    run = Path(said[0][0])
    assert run.is_file() and (run.parent / said[0][1]).is_file() and (run.parent / said[0][2]).is_file()
    # another epoch count is another run: it trains its own epoch instead of resuming the 2-epoch run's file
    rc = main(["train", "motionfill", "--stage", "traj", "--data", str(DATA_STUBS / "approach"), "--clips", "4",
               "--epochs", "1", "--out", str(tmp_path / "mf1.pt")])
    logs = sorted((tmp_path / "cache" / "runs").glob("motionfill_traj_s0_*.csv"), key=lambda f: f.stat().st_mtime)
    assert rc == 0 and len(logs) == 2
    assert [len(f.read_text().strip().splitlines()) - 1 for f in logs] == [2, 1]      # header + one row per epoch
    state = torch.load(out, weights_only=True)
    assert state["model"]["traj.out.weight"].dtype == torch.float16
    model = load_motionfill(out)
    assert not model.training and model.cfg.traj_latent == 512                  # the shipped config (A.2)
    with pytest.raises(SystemExit):
        main(["train", "motionfill", "--stage", "nope"])


def test_held_out_clips_are_each_test_objects_first_accepted_clips(tmp_path):
    from graspkit.eval_motionfill import held_out_clips, main

    for i, (name, ok) in enumerate([("apple", True), ("mug", False), ("mug", True), ("camera", True), ("mug", True)]):
        np.savez(tmp_path / f"approach_{i:06d}.npz", obj_name=np.array(name), **{"grasp.accepted": np.array(ok)})
    assert [f.name for f in held_out_clips(tmp_path)] == ["approach_000002.npz", "approach_000003.npz"]
    assert [f.name for f in held_out_clips(tmp_path, 2)] == ["approach_000002.npz", "approach_000003.npz",
                                                             "approach_000004.npz"]
    with pytest.raises(ValueError, match="per_object"):
        held_out_clips(tmp_path, 0)
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(FileNotFoundError, match="folder"):
        held_out_clips(empty)
    with pytest.raises(SystemExit):
        main(["nothing"])


def test_graspmotion_eval_measures_the_last_frame_against_the_clips_posed_mesh():
    """GraspMotion-Opt on a shipped approach clip (few steps, with the posed collision grid): the row's end-grasp
    distance is trimesh's signed distance of the last fitted frame to the scene's mesh (the deepest vertex inside,
    negative, or the gap)."""
    import trimesh

    from graspkit.eval_motionfill import graspmotion_eval
    from graspkit.optim.graspmotion import GraspMotionOpt
    from graspkit.models.pose_prior import load_pose_prior

    bm = BodyModel.from_file(default_model_path())
    ev = graspmotion_eval(load_motionfill(), [DATA_STUBS / "approach" / "approach_000000.npz"], steps=(10, 10),
                          progress=False)
    s, row = ev["scenes"][0], ev["rows"][0]
    v = GraspMotionOpt(bm, load_pose_prior()).vertices(ev["result"], 0)[-1].double().numpy()
    sd = trimesh.proximity.signed_distance(s["mesh"], v)                     # positive inside
    want = -sd.max() if sd.max() > 0 else np.abs(sd).min()                   # deepest inside, else the gap
    assert row["contact_mm"] == pytest.approx(1000 * want, abs=0.5)
    # the floor columns from every frame's full mesh against the scene's floor height (numpy, not the row's code)
    low = GraspMotionOpt(bm, load_pose_prior()).vertices(ev["result"], 0).double().numpy()[..., 2].min(-1)
    dip = np.maximum(s["floor"] - low, 0.0)
    assert row["below_floor_max_cm"] == pytest.approx(100 * dip.max(), abs=1e-3)
    assert row["below_floor_mean_cm"] == pytest.approx(100 * dip.mean(), abs=1e-3)
    assert row["floating_opt"] == pytest.approx(float(np.mean(low - s["floor"] > 0.01)))     # more than 1 cm up
    # start_cm: the fitted frame 0's markers, read off its full mesh, from the clip's first frame
    frame0 = GraspMotionOpt(bm, load_pose_prior()).vertices(ev["result"], 0)[0]
    first = saga_sparse_markers(bm).select(frame0).double().numpy()
    assert row["start_cm"] == pytest.approx(100 * np.linalg.norm(first - s["markers"][0], axis=-1).mean(), abs=1e-3)


def test_window_cache_is_keyed_by_the_body_and_the_window_version(tmp_path, monkeypatch):
    """`windows` reads back its own set, and builds another (never reads across) for another body model or another
    WINDOWS_VERSION: a body whose template is moved 1 cm along x gives windows of its own, as make_windows makes
    them (moved further, or up, the clips' goals or floor would no longer hold on it: `made_on`, refused)."""
    from graspkit import eval_motionfill as E
    from graspkit.body.model import load_model_arrays
    from graspkit.data import load_motion
    from graspkit.data.motionfill_dataset import make_windows

    monkeypatch.setenv("GRASPKIT_CACHE", str(tmp_path / "cache"))
    data = DATA_STUBS / "motion" / "reach"
    bm = BodyModel.from_file(default_model_path())
    arrays = dict(load_model_arrays(default_model_path()))
    arrays["v_template"] = arrays["v_template"] + np.array([0.01, 0.0, 0.0], arrays["v_template"].dtype)
    tall = BodyModel(arrays)
    a = E.windows("reach", 2, bm, data=data, progress=False)
    for k, v in E.windows("reach", 2, bm, data=data, progress=False).items():
        np.testing.assert_array_equal(v, a[k])
    b = E.windows("reach", 2, tall, data=data, progress=False)
    motions = [m.slice(0, m.goal_frame + 1) for m in (load_motion(f) for f in sorted(data.glob("reach_*.npz"))[:2])]
    truth = make_windows(motions, tall, stride=30, align_end=True, progress=False)
    assert set(b) == set(truth) and any(not np.array_equal(b[k], a[k]) for k in a)
    for k in truth:
        np.testing.assert_allclose(b[k], truth[k], atol=1e-6)
    cache = tmp_path / "cache" / "motionfill"
    assert len(list(cache.glob("reach_2_*.npz"))) == 2
    monkeypatch.setattr(E, "WINDOWS_VERSION", E.WINDOWS_VERSION + 1)
    E.windows("reach", 2, bm, data=data, progress=False)
    assert len(list(cache.glob("reach_2_*.npz"))) == 3
    assert E.windows_source("reach", 2, data)[0] != E.windows_source("reach", 2, data, tall.digest())[0]


def test_the_evaluation_command_checks_out_and_the_baselines_before_any_work(tmp_path, monkeypatch, capsys):
    import graspkit.eval_motionfill as E

    def no_work(*a, **k):
        raise AssertionError("the work started")

    monkeypatch.setattr(E, "windows", no_work)
    monkeypatch.setattr(E, "graspmotion_eval", no_work)
    (tmp_path / "notes.json").write_bytes(b"\x89PNG not json")
    (tmp_path / "afile").write_text("x")
    for argv, message in ((["tab3", "--out", str(tmp_path / "notes.json")], "--out: .*not a JSON file"),
                          (["graspmotion", "--out", str(tmp_path / "afile" / "eval.json")], "--out: .*afile is a file"),
                          (["example", "--out", str(tmp_path / "afile" / "ex")], "--out: .*afile is a file"),
                          (["tab3", "--checkpoints", str(tmp_path), "--out", str(tmp_path / "e.json")],
                           "--checkpoints: the Tab. 3 baselines are missing")):
        assert E.main(argv) == 2
        assert re.search(message, capsys.readouterr().err), argv
    got = {}                                                 # example: --out is where the pair goes
    monkeypatch.setattr(E, "held_out_clips", lambda data, per_object: [STUB])
    def write_example(files, out, seed):
        got["out"] = out
        return {"rows": [{}]}

    monkeypatch.setattr(E, "write_example", write_example)
    assert E.main(["example", "--out", str(tmp_path / "mine.npz")]) == 0
    assert got["out"] == tmp_path / "mine"


def test_approach_scene_names_a_file_that_is_not_an_approach_clip(tmp_path):
    bm = BodyModel.from_file(default_model_path())
    np.savez(tmp_path / "other.npz", poses=np.zeros((3, 165)))
    with pytest.raises(ValueError, match="other.npz is not an approach clip.*missing"):
        approach_scene(tmp_path / "other.npz", bm)


def test_load_motionfill_names_the_file_once_for_a_foreign_or_truncated_checkpoint(tmp_path):
    """Another model's checkpoint (GNet's) and a truncated copy of MotionFill's: each a ValueError that names the file
    once and says what is wrong with it."""
    import shutil

    foreign = tmp_path / "gnet.pt"
    shutil.copy(DATA_STUBS / "checkpoints" / "gnet.pt", foreign)
    with pytest.raises(ValueError, match="not a MotionFill-VAE checkpoint") as e:
        load_motionfill(foreign)
    assert str(e.value).count(str(foreign)) == 1 and "state:" not in str(e.value)
    cut = tmp_path / "cut.pt"
    data = (DATA_STUBS / "checkpoints" / "motionfill.pt").read_bytes()
    cut.write_bytes(data[: len(data) // 2])
    with pytest.raises(ValueError, match="not a torch checkpoint|damaged") as e:
        load_motionfill(cut)
    assert str(e.value).count(str(cut)) == 1


def test_ade_is_the_best_of_the_samples():
    """Tab. 3's ADE is the smallest of the n samples' mean marker errors per window (SAGA §4.2), then the mean over
    windows: a stand-in model whose sample k is the truth moved k cm gives 0 (sample 0 is exact), not 4.5 cm."""
    from graspkit.data.motionfill_dataset import make_windows
    from graspkit.eval_motionfill import approach_motions, evaluate

    bm = BodyModel.from_file(default_model_path())
    motions, _ = approach_motions(DATA_STUBS / "approach")
    arr = make_windows(motions, bm, align_end=True, progress=False)
    gt = torch.as_tensor(arr["markers"]).float()
    calls = []

    class Shifted:
        def sample(self, ti, local, contacts, n, g, traj=None):
            i = len(calls) // 2                                    # two calls (local, full) per window
            calls.append(i)
            shift = torch.zeros(n, 1, 1, 3)
            shift[:, 0, 0, 0] = 0.01 * torch.arange(n)
            return {"markers": gt[i][None] + shift}

    rows = evaluate(Shifted(), arr, np.unique(arr["clip"]), n=10, seed=0)
    assert rows["Ours"]["ADE"] < 1e-6 and rows["Ours-Local"]["ADE"] < 1e-6


def test_tab3_skating_floor_is_the_lowest_heel_of_the_window():
    """SAGA §4.2's skating needs both heels within 5 cm of the ground (the lowest heel marker of the ground-truth
    window): a stand-in model whose motion is the truth raised 8 cm and sliding 1 cm per frame has its heels 8+ cm
    above the ground on every frame, so it never skates, however fast it slides; the same slide on the ground skates."""
    from graspkit.data.motionfill_dataset import make_windows
    from graspkit.eval_motionfill import approach_motions, evaluate

    bm = BodyModel.from_file(default_model_path())
    motions, _ = approach_motions(DATA_STUBS / "approach")
    arr = make_windows(motions, bm, align_end=True, progress=False)
    gt = torch.as_tensor(arr["markers"]).float()
    heels = heel_columns()
    z = gt[:, :, heels, 2]
    assert float((z.amax((1, 2)) - z.amin((1, 2))).max()) > 0.05          # a window lifts a heel > 5 cm
    for lift, skates in ((0.08, False), (0.0, True)):
        calls = []

        class Sliding:
            def sample(self, ti, local, contacts, n, g, traj=None):
                i = len(calls) // 2                                    # two calls (local, full) per window
                calls.append(i)
                m = gt[i].clone()
                m[..., 0] += 0.01 * torch.arange(len(m))[:, None]      # 1 cm per frame: 0.3 m/s > 75 mm/s
                m[..., 2] += lift
                return {"markers": m[None].expand(n, -1, -1, -1)}

        rows = evaluate(Sliding(), arr, np.unique(arr["clip"]), n=1, seed=0)
        assert (rows["Ours"]["skating"] > 0.05) == skates and (rows["Ours-Local"]["skating"] > 0.05) == skates
        if not skates:
            assert rows["Ours"]["skating"] == 0.0


def test_heel_jerkiness_is_in_metres_per_second_and_per_second_squared():
    """heel_jerkiness: a heel marker at constant acceleration a = 2 m/s^2 from rest (x = a t^2 / 2 at 30 fps) has
    largest speed a (T-1)/fps minus half a frame, and every acceleration a (m/s^2), the 99th percentile too."""
    from graspkit.eval_motionfill import heel_jerkiness

    T, fps, a = 31, 30.0, 2.0
    t = np.arange(T) / fps
    m = np.zeros((T, 4, 3))
    m[:, 1, 0] = m[:, 3, 0] = 0.5 * a * t ** 2
    m[:, 3, 1] = 0.2                                              # the other heel beside it, same motion
    r = heel_jerkiness(m, [1, 3], fps)
    assert abs(r["heel_acc_p99"] - a) < 1e-6
    assert abs(r["heel_speed_max"] - a * (T - 1.5) / fps) < 1e-6   # the last frame pair's mean speed


def test_tab3_rows_give_the_model_and_the_linear_baseline_the_same_trajectory():
    """Tab. 3 (SAGA §4.2): 'Ours-Local' infills with the true trajectory (the window's traj), 'Ours' without it (TrajFill
    from the interpolated start-to-end trajectory it is given); the linear rows are the same two protocols with a
    linear local motion: a stand-in model that answers the linear blend along the trajectory it is told gives exactly
    the linear rows."""
    from graspkit.data.motionfill_dataset import global_motion, make_windows
    from graspkit.eval_motionfill import approach_motions, evaluate

    bm = BodyModel.from_file(default_model_path())
    motions, _ = approach_motions(DATA_STUBS / "approach")
    arr = make_windows(motions, bm, align_end=True, progress=False)
    seen = []

    class Linear:
        def sample(self, ti, local, contacts, n, g, traj=None):
            i = len(seen) // 2                                     # two calls (local, full) per window
            seen.append(None if traj is None else np.asarray(traj))
            lin = linear_local(np.asarray(local, np.float64)[None])
            if traj is not None:
                assert np.array_equal(np.asarray(traj), arr["traj"][i])   # the window's true trajectory
                m = global_motion(lin, np.asarray(traj, np.float64)[None])
            else:
                g0, gT = arr["traj"][i][0], arr["traj"][i][60]      # told only the start and the end
                assert np.allclose(np.asarray(ti)[[0, 60]], [g0, gT], atol=1e-6)
                m = global_motion(lin, np.asarray(ti, np.float64)[None])
            return {"markers": torch.as_tensor(m).expand(n, -1, -1, -1)}

    rows = evaluate(Linear(), arr, np.unique(arr["clip"]), n=1, seed=0)
    assert [s is None for s in seen] == [False, True] * (len(seen) // 2)   # Ours-Local told the truth, Ours not
    for ours, lin in (("Ours-Local", "Linear (local)"), ("Ours", "Linear")):
        assert abs(rows[ours]["ADE"] - rows[lin]["ADE"]) < 1e-6
    assert abs(rows["Linear"]["ADE"] - rows["Linear (local)"]["ADE"]) > 1e-3     # the two protocols differ here


def test_tab3_table_shows_the_papers_figures_beside_the_rows_they_belong_to():
    """SAGA Tab. 3: Ours-Local (true trajectory) ADE 0.079, skating 0.137; Ours (trajectory + local) ADE 0.083,
    skating 0.394: each printed beside our row of the same name."""
    from graspkit.eval_motionfill import table

    row = {"ADE": 0.5, "skating": 0.5, "PSKL (P, GT)": 0.5, "PSKL (GT, P)": 0.5, "APD": 0.5}
    lines = table({"Ours-Local": row, "Ours": row}).splitlines()
    local = next(x for x in lines if x.startswith("| Ours-Local |"))
    full = next(x for x in lines if x.startswith("| Ours |"))
    assert local.rstrip(" |").endswith("0.079 / 0.137 / 0.377 / 0.327")
    assert full.rstrip(" |").endswith("0.083 / 0.394 / 0.772 / 0.609")


STUB_UNPADDED = DATA_STUBS / "approach" / "approach_000002.npz"    # 91 frames up to the grasp: no front padding


def _rigid(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Kabsch: R, t with b ~ a @ R.T + t."""
    ca, cb = a.mean(0), b.mean(0)
    u, _, vt = np.linalg.svd((a - ca).T @ (b - cb))
    d = np.sign(np.linalg.det(vt.T @ u.T))
    R = vt.T @ np.diag([1.0, 1.0, d]) @ u.T
    return R, cb - ca @ R.T


def test_approach_scene_object_is_in_the_frame_of_the_window_markers():
    """The scene's object points are the clip's world object points moved by the same rigid map that takes the
    clip's last 61 frames of world markers (saga_sparse_markers on the posed body) to the window's markers (Kabsch)."""
    bm = BodyModel.from_file(default_model_path())
    s = approach_scene(STUB_UNPADDED, bm)
    with np.load(STUB_UNPADDED) as a:
        g = int(a["grasp.goal_frame"])
        R_o = axis_angle_to_matrix(torch.as_tensor(a["object.params.global_orient"][g]).double()).numpy()
        world_pts = a["object.points"].astype(np.float64) @ R_o.T + a["object.params.transl"][g]
    m = s["motion"]                                             # the clip's last 61 frames up to the grasp
    assert m.num_frames == 61 and g + 1 > 62
    mark = saga_sparse_markers(bm).select(m.vertices(bm)).numpy().astype(np.float64)
    R, t = _rigid(mark.reshape(-1, 3), s["markers"].astype(np.float64).reshape(-1, 3))
    assert np.abs(mark.reshape(-1, 3) @ R.T + t - s["markers"].reshape(-1, 3)).max() < 1e-4   # rigid, exactly
    assert np.abs(world_pts @ R.T + t - s["points"]).max() < 1e-4


def test_approach_motions_end_at_the_grasp_frame():
    """approach_motions cuts each clip at its goal frame: frames 0..goal_frame of the file, so the window's frame T is
    the grasp (SAGA A.3)."""
    from graspkit.eval_motionfill import approach_motions

    motions, names = approach_motions(DATA_STUBS / "approach")
    files = sorted((DATA_STUBS / "approach").glob("approach_*.npz"))
    assert len(motions) == len(files) == 4
    for m, name, f in zip(motions, names, files):
        with np.load(f) as a:
            g = int(a["grasp.goal_frame"])
            assert m.num_frames == g + 1 and name == str(a["obj_name"])
            np.testing.assert_allclose(m.poses[-1].reshape(-1), a["body.params.fullpose"][g].reshape(-1), atol=1e-6)
            np.testing.assert_allclose(m.trans[-1], a["body.params.transl"][g], atol=1e-6)


def test_approach_windows_are_split_by_grabs_held_out_objects(tmp_path, monkeypatch):
    """windows('approach') tags each window with its object's split (0 train, 1 val, 2 test; GRAB's split: mug test,
    bottle train) and clip_split gives the mug clips as the test set."""
    from graspkit.data.grasp import split_of
    from graspkit.eval_motionfill import approach_motions, clip_split, windows

    monkeypatch.setenv("GRASPKIT_CACHE", str(tmp_path / "cache"))
    arr = windows("approach", 4, data=DATA_STUBS / "approach", progress=False)
    _, names = approach_motions(DATA_STUBS / "approach")
    assert split_of("mug") == "test" and split_of("bottle") == "train"
    want = {"mug": 2, "bottle": 0}
    assert [int(s) for s in arr["split"]] == [want[names[c]] for c in arr["clip"]]
    sp = clip_split(arr)
    assert sorted(sp["test"].tolist()) == [c for c, n in enumerate(names) if n == "mug"]
    assert sorted(sp["train"].tolist()) == [c for c, n in enumerate(names) if n == "bottle"] and len(sp["val"]) == 0


def test_clip_split_puts_every_clip_in_exactly_one_split():
    """clip_split of windows without object tags: every clip id is in exactly one of train / val / test."""
    from graspkit.eval_motionfill import clip_split

    for n in (1, 7, 10):
        sp = clip_split({"clip": np.repeat(np.arange(n), 3)})
        got = np.concatenate([sp["train"], sp["val"], sp["test"]])
        assert sorted(got.tolist()) == list(range(n))


def test_shipped_state_round_trips_the_normalisation_statistics_exactly():
    """shipped_state: weights in float16, but the normalisation means and stds stay float32: a model rebuilt from it
    normalises exactly as the trained one."""
    from graspkit.eval_motionfill import shipped_state
    from graspkit.models.motionfill import MotionFillVAE

    torch.manual_seed(0)
    model = MotionFillVAE()
    g = torch.Generator().manual_seed(1)
    for k in ("marker_mean", "marker_std", "vel_mean", "vel_std"):
        b = getattr(model, k)
        b.copy_(0.3 + torch.rand(b.shape, generator=g) * 1.234567)
    back = MotionFillVAE.from_state(shipped_state(model))
    for k in ("marker_mean", "marker_std", "vel_mean", "vel_std"):
        assert torch.equal(getattr(back, k), getattr(model, k)), k


def test_pskl_counts_a_slowly_accelerating_coordinate():
    """PSKL leaves out only coordinates that do not accelerate at all (rounding): a heel drifting at 9 mm/s^2
    (1e-5 m per frame^2 at 30 fps) is motion and is counted."""
    t = np.arange(40, dtype=np.float64)
    x = np.zeros((1, 40, 1, 3))
    x[0, :, 0, 0] = 0.5e-5 * t ** 2 + 1e-6 * np.sin(t)
    x[0, :, 0, 1] = 1e-5 * np.cos(0.3 * t)
    x[0, :, 0, 2] = 0.2 * t                                      # constant velocity: no acceleration
    assert pskl_still_share(x) == pytest.approx(1 / 3)


def test_heel_columns_are_the_rearmost_markers_of_each_foot():
    """heel_columns: [left heel, right heel] are, on the rest body (SMPL-X: y up, z forward, +x the body's left), the
    rearmost markers among those within 8 cm of the sole on the left and the right side."""
    bm = BodyModel.from_file(default_model_path())
    with torch.no_grad():
        v = bm().vertices[0]
    mk = saga_sparse_markers(bm).select(v[None])[0].double().numpy()
    sole = float(v[:, 1].min())
    low = np.flatnonzero(mk[:, 1] < sole + 0.08)
    want = [int(low[mk[low, 0] > 0][np.argmin(mk[low[mk[low, 0] > 0], 2])]),
            int(low[mk[low, 0] < 0][np.argmin(mk[low[mk[low, 0] < 0], 2])])]
    assert heel_columns() == want


def test_heel_acceleration_is_the_99th_percentile_in_metres_per_second_squared():
    """heel_jerkiness: two heel markers built by integrating hand-made accelerations (m/s^2, 30 fps) twice, 199 each
    (the right heel's half the left's), give the 99th percentile of all 398 back."""
    from graspkit.eval_motionfill import heel_jerkiness

    fps = 30.0
    acc = np.random.default_rng(3).permutation(np.linspace(0.0, 19.8, 199))   # m/s^2, |a| along x
    m = np.zeros((201, 3, 3))
    for col, a in ((0, acc), (2, 0.5 * acc)):
        m[2:, col, 0] = np.cumsum(np.cumsum(a / fps ** 2))                   # x[t+2] - 2 x[t+1] + x[t] = a_t / fps^2
    r = heel_jerkiness(m, [0, 2], fps)
    assert r["heel_acc_p99"] == pytest.approx(np.percentile(np.r_[acc, 0.5 * acc], 99), abs=1e-6)


def _stub_windows():
    from graspkit.data.motionfill_dataset import make_windows
    from graspkit.eval_motionfill import approach_motions

    bm = BodyModel.from_file(default_model_path())
    motions, _ = approach_motions(DATA_STUBS / "approach")
    return make_windows(motions, bm, align_end=True, progress=False)


def test_tab3_models_are_given_the_linear_start_to_end_trajectory():
    """Tab. 3: the model's Gamma_bar is the straight blend of the window's true trajectory from frame 0 to frame T
    (one step past it at T+1: SAGA §3.3), for both rows, never the true trajectory in between."""
    from graspkit.eval_motionfill import evaluate

    arr = _stub_windows()
    seen = []

    class Recorder:
        def sample(self, ti, local, contacts, n, g, traj=None):
            i = len(seen) // 2
            seen.append(i)
            g0, gT = arr["traj"][i][0].astype(np.float64), arr["traj"][i][60].astype(np.float64)
            s = np.arange(62)[:, None] / 60.0
            np.testing.assert_allclose(np.asarray(ti, np.float64), g0 + s * (gT - g0), atol=1e-5)
            return {"markers": torch.as_tensor(arr["markers"][i])[None].expand(n, -1, -1, -1)}

    evaluate(Recorder(), arr, np.unique(arr["clip"]), n=1, seed=0)
    assert len(seen) == 2 * len(arr["clip"])


def test_ade_takes_the_best_sample_of_each_window_as_a_whole():
    """Tab. 3's ADE: per window, the sample with the smallest mean marker error (not the best sample per marker):
    two samples, each 10 cm off on a different half of the markers (40 and 39 of 79), give 10 cm x 39/79."""
    from graspkit.eval_motionfill import evaluate

    arr = _stub_windows()
    calls = []

    class Halves:
        def sample(self, ti, local, contacts, n, g, traj=None):
            i = len(calls) // 2
            calls.append(i)
            m = torch.as_tensor(arr["markers"][i]).double()[None].repeat(2, 1, 1, 1)
            m[0, :, :40, 0] += 0.1
            m[1, :, 40:, 0] += 0.1
            return {"markers": m}

    rows = evaluate(Halves(), arr, np.unique(arr["clip"]), n=2, seed=0)
    for name in ("Ours", "Ours-Local"):
        assert rows[name]["ADE"] == pytest.approx(0.1 * 39 / 79, abs=1e-6)


def test_approach_scene_of_a_short_clip_is_the_world_clip_moved_rigidly():
    """A clip shorter than a window (50 frames up to the grasp, padded in front): the rigid map that takes its world
    markers to the window's last 50 frames of markers also takes the world object points, normals and catalogue mesh
    to the scene's; the scene's mesh pose is x = mesh_rotation x_mesh + mesh_origin."""
    from graspkit.objects.catalogue import make_object

    bm = BodyModel.from_file(default_model_path())
    s = approach_scene(STUB, bm)
    with np.load(STUB) as a:
        g = int(a["grasp.goal_frame"])
        R_o = axis_angle_to_matrix(torch.as_tensor(a["object.params.global_orient"][g]).double()).numpy()
        t_o = a["object.params.transl"][g].astype(np.float64)
        pts, nrm = a["object.points"].astype(np.float64), a["object.normals"].astype(np.float64)
    m = s["motion"]
    assert m.num_frames == g + 1 < 61
    mark = saga_sparse_markers(bm).select(m.vertices(bm)).numpy().astype(np.float64).reshape(-1, 3)
    win = s["markers"][61 - m.num_frames:].astype(np.float64).reshape(-1, 3)
    R, t = _rigid(mark, win)
    assert np.abs(mark @ R.T + t - win).max() < 1e-4
    assert np.abs((pts @ R_o.T + t_o) @ R.T + t - s["points"]).max() < 1e-4
    assert np.abs(nrm @ R_o.T @ R.T - s["normals"]).max() < 1e-4
    cat = np.asarray(make_object(s["name"]).vertices, np.float64)
    assert np.abs((cat @ R_o.T + t_o) @ R.T + t - s["mesh"].vertices).max() < 1e-4
    assert np.abs(cat @ s["mesh_rotation"].T + s["mesh_origin"] - s["mesh"].vertices).max() < 1e-4


def test_tab3_command_evaluates_the_test_objects_windows(tmp_path, monkeypatch):
    """`python -m graspkit.eval_motionfill tab3` evaluates the windows of the held-out test objects (split code 2),
    and reports their number."""
    import graspkit.eval_motionfill as E

    arr = {"clip": np.array([0, 0, 1, 2, 2, 3]), "split": np.array([0, 0, 2, 1, 1, 2])}
    got = {}

    def fake_evaluate(model, a, clips, **kw):
        got["clips"] = sorted(np.asarray(clips).tolist())
        return {"Ours": {"ADE": 0.0, "skating": 0.0, "PSKL (P, GT)": 0.0, "PSKL (GT, P)": 0.0, "APD": 0.0}}

    monkeypatch.setattr(E, "windows", lambda kind, n, data=None: arr)
    monkeypatch.setattr(E, "evaluate", fake_evaluate)
    monkeypatch.setattr(E, "load_motionfill", lambda path=None: None)
    monkeypatch.setattr(E, "load_baselines", lambda folder=None: {})
    out = tmp_path / "e.json"
    assert E.main(["tab3", "--out", str(out), "--clips", "4"]) == 0
    assert got["clips"] == [1, 3]
    assert json.loads(out.read_text())["test_windows"] == 2


def test_graspmotion_rows_measure_the_floor_of_the_scene():
    """graspmotion_eval's per-clip figures stand on the scene's floor (the window's canonical frame puts it at
    s['floor'], not z = 0): the non-collision score is the share of the fitted mesh's vertices at or above that
    floor (SAGA §4.2), and a stand-in sample that is the clip's window raised 8 cm and sliding 1 cm a frame never
    skates (both heels must be within 5 cm of the floor). (~10 s: one GraspMotion-Opt fit of 2 + 2 steps.)"""
    from graspkit.eval_motionfill import graspmotion_eval
    from graspkit.models.pose_prior import load_pose_prior
    from graspkit.optim.graspmotion import GraspMotionOpt

    bm = BodyModel.from_file(default_model_path())
    window = torch.as_tensor(approach_scene(STUB, bm)["markers"]).float()

    class Raised:
        def sample(self, ti, local, contacts, n, g, traj=None):
            m = window.clone()
            m[..., 0] += 0.01 * torch.arange(len(m))[:, None]
            m[..., 2] += 0.08
            return {"markers": m[None], "contacts": torch.zeros(1, len(m), 4)}

    ev = graspmotion_eval(Raised(), [STUB], steps=(2, 2), progress=False)
    s, row = ev["scenes"][0], ev["rows"][0]
    assert abs(s["floor"]) > 0.3                                         # the floor is not z = 0 in this frame
    v = GraspMotionOpt(bm, load_pose_prior()).vertices(ev["result"], 0).double().numpy()
    assert row["noncollision_opt"] == pytest.approx(float((v[..., 2] >= s["floor"]).mean()), abs=1e-9)
    names = saga_sparse_markers(bm).names
    h = ev["markers"][0].double().numpy()[:, [names.index("LHEE"), names.index("RHEE")]]
    assert (h[..., 2] - s["floor"]).min() > 0.05 and row["skating_sample"] == 0.0


def test_finetune_stage_trains_both_cvaes(tmp_path, monkeypatch):
    """A.4's third run (`finetune`) trains TrajFill and LocalMotionFill together: from the shipped checkpoint, one
    epoch on the four shipped approach clips changes the weights of both."""
    from graspkit.eval_motionfill import CHECKPOINT, train_stage

    monkeypatch.setenv("GRASPKIT_CACHE", str(tmp_path / "cache"))
    init = load_motionfill(CHECKPOINT)
    model, _ = train_stage("finetune", 1, tmp_path / "mf.pt", init=CHECKPOINT, clips={"approach": 4},
                           data=DATA_STUBS / "approach", progress=False, lr=1e-2)
    for part in ("local", "traj"):
        a, b = getattr(init, part).state_dict(), getattr(model, part).state_dict()
        assert any(not torch.equal(a[k], b[k]) for k in a), part


def test_approach_scene_mesh_pose_holds_for_a_tilted_object(tmp_path):
    """approach_scene's mesh pose x = mesh_rotation x_mesh + mesh_origin holds for an object tilted off the vertical
    (the shipped clip with its object turned about x and y as well: rotations about z alone commute and hide the
    order of the product)."""
    from graspkit.objects.catalogue import make_object

    with np.load(DATA_STUBS / "approach" / "approach_000000.npz") as a:
        arrays = {k: a[k] for k in a.files}
    arrays["object.params.global_orient"] = (arrays["object.params.global_orient"]
                                             + np.array([0.4, -0.3, 0.0], arrays["object.params.global_orient"].dtype))
    np.savez(tmp_path / "approach_tilted.npz", **arrays)
    s = approach_scene(tmp_path / "approach_tilted.npz", BodyModel.from_file(default_model_path()))
    cat = np.asarray(make_object(s["name"]).vertices, np.float64)
    assert np.abs(cat @ s["mesh_rotation"].T + s["mesh_origin"] - s["mesh"].vertices).max() < 1e-4


def test_heel_jerkiness_names_short_or_non_finite_markers():
    """One or two frames have no acceleration (an IndexError / ValueError from numpy before), NaN gave NaN figures."""
    from graspkit.eval_motionfill import heel_jerkiness

    for T in (1, 2):
        with pytest.raises(ValueError, match="markers: expected .*T >= 3"):
            heel_jerkiness(np.zeros((T, 4, 3)), [0, 1])
    bad = np.zeros((5, 4, 3))
    bad[2, 1, 0] = np.nan
    with pytest.raises(ValueError, match="markers: contains NaN"):
        heel_jerkiness(bad, [0, 1])
    assert heel_jerkiness(np.zeros((3, 4, 3)), [0, 1]) == {"heel_speed_max": 0.0, "heel_acc_p99": 0.0}


def test_approach_windows_are_read_from_the_clips_their_cache_is_named_by(tmp_path, monkeypatch):
    """A clip of one's own naming, approach_000000_old.npz, in the folder: approach_motions read it as the second clip
    while the windows' cache key listed approach_000001.npz, so a cached set outlived the file's removal. Every reader
    of the folder and the key now take the same files (`formats.clip_files`: approach_*.npz, not another kind's)."""
    import shutil

    from graspkit.benchmark import split_sequences
    from graspkit.data.formats import clip_files
    from graspkit.data.grab import load_grasp_sequence
    from graspkit.data.grasp_datasets import grasp_files
    from graspkit.eval_goal import _files
    from graspkit.eval_motionfill import approach_motions, held_out_clips, windows_source

    monkeypatch.setenv("GRASPKIT_CACHE", str(tmp_path / "cache"))
    folder = tmp_path / "approach"
    folder.mkdir()
    for i in (0, 1):
        shutil.copy(DATA_STUBS / "approach" / f"approach_00000{i}.npz", folder)
    shutil.copy(DATA_STUBS / "approach" / "approach_000002.npz", folder / "approach_000000_old.npz")
    shutil.copy(DATA_STUBS / "grasps" / "grasp_000000.npz", folder)          # another kind's file: no approach clip
    listed = ["approach_000000.npz", "approach_000000_old.npz", "approach_000001.npz"]
    assert [f.name for f in clip_files(folder, "approach")] == listed
    _, _, files = windows_source("approach", 2, folder)
    assert [f.name for f in files] == listed[:2]
    motions, names = approach_motions(folder, 2)
    assert len(motions) == 2
    for m, f in zip(motions, files):                  # the files the key lists, cut at their goal frames
        full = load_grasp_sequence(f)
        np.testing.assert_allclose(m.poses, full.poses[:m.num_frames], atol=1e-6)
    assert [f.name for f in grasp_files(folder, "approach")] == listed
    assert len(_files(folder, "approach", None)) == 3
    assert {f.name for f in held_out_clips(folder, 5)} <= set(listed)
    assert sum(len(split_sequences([folder], "approach", s)) for s in ("train", "val", "test")) == 3
