"""The `graspkit` console command: help, version and the body-model subcommands."""
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import pytest
import torch

from graspkit import __version__
from graspkit.body.random_model import random_smplx_arrays


def _run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "graspkit", *args], capture_output=True, text=True, timeout=120)


def test_help_and_version():
    r = _run("--help")
    assert r.returncode == 0 and "demo" in r.stdout and "body" in r.stdout
    r = _run("--version")
    assert r.returncode == 0 and r.stdout.strip() == f"graspkit {__version__}"


def test_top_level_help_loads_no_torch_and_each_heavy_command_gets_its_subcommands():
    import subprocess
    import sys

    from graspkit.cli import build_parser

    code = ("import sys; from graspkit.cli import build_parser; p = build_parser(['--help']); "
            "print(sorted(p._subparsers._group_actions[0].choices), 'torch' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.split("]")[1].strip() == "False"
    assert all(c in out for c in ("body", "demo", "saga", "goal", "wandr", "data", "train", "eval"))
    # named on the command line, a heavy command has its subcommands, and each parses
    assert build_parser(["data"]).parse_args(["data", "make", "--kind", "reach"]).kind == "reach"
    def commands(parser):
        return parser._subparsers._group_actions[0].choices

    train_help = next(a for a in build_parser(["--help"])._subparsers._group_actions[0]._choices_actions
                      if a.dest == "train").help
    models = sorted(commands(commands(build_parser(["train"]))["train"]))
    assert models == sorted(("wholegrasp", "wholegrasp_single", "grabnet_smplx", "pose_prior", "motionfill",
                             "motionfill_baseline", "gnet", "mnet", "wandr"))
    assert all(m in train_help.replace(",", " ").split() for m in models)   # the top-level help lists them all
    assert build_parser(["train"]).parse_args(["train", "wandr"]).train_command == "wandr"
    assert build_parser(["eval"]).parse_args(["eval", "wandr", "--checkpoint", "c.pt"]).eval_command == "wandr"


def test_body_info_reads_a_file_and_reports_a_bad_one(tmp_path):
    arr = random_smplx_arrays(num_vertices=100, num_faces=40, seed=0)
    np.savez(tmp_path / "m.npz", **arr)
    r = _run("body", "info", "--model", str(tmp_path / "m.npz"))
    assert r.returncode == 0 and "V=100" in r.stdout
    del arr["weights"]
    np.savez(tmp_path / "bad.npz", **arr)
    r = _run("body", "info", "--model", str(tmp_path / "bad.npz"))
    assert r.returncode == 2 and "bad.npz: missing key 'weights'" in r.stderr


def test_demo_writes_a_figure_and_a_glb_that_trimesh_reads(tmp_path):
    import trimesh
    from PIL import Image

    from graspkit.demo import DEMO_BODIES, run_demo

    files = run_demo(tmp_path, stages=("body",))
    png, glb = sorted(files, key=lambda p: p.suffix)[::-1]
    assert png.suffix == ".png" and Image.open(png).size[0] > 1000
    scene = trimesh.load(glb)
    assert len(scene.geometry) == len(DEMO_BODIES)
    heights = sorted(float(np.ptp(g.vertices[:, 1])) for g in scene.geometry.values())
    assert 1.45 < heights[-1] < 2.0          # a standing adult; glTF is y up
    x = sorted(float(g.bounds[:, 0].mean()) for g in scene.geometry.values())
    np.testing.assert_allclose(np.diff(x), 1.0, atol=0.15)             # side by side, as in the picture


def test_demo_planner_stage_writes_clip_files_that_read_back(tmp_path):
    """The planner stage: a GIF, a still, and exports whose npz is the shipped clip's motion."""
    from PIL import Image

    from graspkit.benchmark import sequence_motion, split_sequences
    from graspkit.data import load_motion
    from graspkit.demo import run_demo
    from graspkit.paths import DATA_STUBS

    files = {p.name: p for p in run_demo(tmp_path, stages=("planner",))}
    assert set(files) == {f"planner_approach{s}" for s in (".gif", ".png", ".npz", ".glb", "_final.glb")} | {
        "pipeline_overview.png"}
    gif = Image.open(files["planner_approach.gif"])
    assert gif.n_frames >= 20
    seq = split_sequences([DATA_STUBS / "approach"], "approach", "test")[0]
    m = load_motion(files["planner_approach.npz"])
    assert np.allclose(m.poses, sequence_motion(seq).poses, atol=1e-6) and np.allclose(m.trans, seq.trans, atol=1e-6)


def test_a_clip_stopped_part_way_leaves_no_earlier_runs_files_beside_its_own(tmp_path, monkeypatch):
    """`graspkit wandr` killed while writing left its new GIF and PNG beside the previous run's npz and GLBs, all valid
    and of two goals (an independent check). An earlier run's files of the clip's name go before the first write."""
    import graspkit.viz as V
    from graspkit.body import BodyModel
    from graspkit.data import load_motion
    from graspkit.demo import _write_clip
    from graspkit.paths import DATA_STUBS, default_model_path

    names = [f"wandr_s0{s}" for s in (".gif", ".png", ".npz", ".glb", "_final.glb")]
    for n in names[1:] + ["wandr_s1.gif"]:
        (tmp_path / n).write_text("an earlier run's")
    store = tmp_path / "store"                                # the GIF name a link into a store: the link stays
    store.mkdir()
    (store / "shared.gif").write_text("an earlier run's")
    (tmp_path / names[0]).symlink_to(store / "shared.gif")

    def killed(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr(V, "save_animation", killed)
    m = load_motion(sorted((DATA_STUBS / "motion" / "reach").glob("reach_0*.npz"))[0]).slice(0, 3)
    import gc
    import warnings

    import matplotlib.pyplot as plt

    figures = plt.get_fignums()
    with warnings.catch_warnings():       # the interrupted animation was never drawn: matplotlib says so when it goes,
        warnings.simplefilter("ignore")   # here and not in a later test
        with pytest.raises(KeyboardInterrupt):
            _write_clip(BodyModel.from_file(default_model_path()), m, tmp_path, "wandr_s0", {}, "t")
        gc.collect()
    assert plt.get_fignums() == figures                                 # its figure closed although the save failed
    assert sorted(p.name for p in tmp_path.iterdir()) == ["store", "wandr_s0.gif", "wandr_s1.gif"]   # another clip's
    assert (tmp_path / "wandr_s0.gif").is_symlink() and not list(store.iterdir())        # file is kept, the link too


def test_demo_stages_stand_on_the_floor_of_another_model(tmp_path):
    """`graspkit demo --model F` with F 8 % larger than graspkit's body: the planner clip (made on graspkit's body)
    and WANDR's motion (its start rebuilt on F) begin with F's lowest vertex on the floor, the same poses as on the
    shipped body. Until 2026-12-07 both kept the shipped body's translations and sank 7.3-7.5 cm."""
    from conftest import PROCEDURAL_MODEL, npz_copy

    from graspkit.body import BodyModel
    from graspkit.data import load_motion
    from graspkit.demo import run_demo

    with np.load(PROCEDURAL_MODEL, allow_pickle=False) as z:
        big = npz_copy(PROCEDURAL_MODEL, tmp_path / "big.npz", v_template=z["v_template"] * 1.08,
                       shapedirs=z["shapedirs"] * 1.08)
    bm = BodyModel.from_file(big)
    for model, out in ((None, tmp_path / "shipped"), (big, tmp_path / "big")):
        run_demo(out, model_path=model, stages=("planner", "wandr"))
    for name in ("planner_approach", "wandr_reach"):
        a, b = load_motion(tmp_path / "shipped" / f"{name}.npz"), load_motion(tmp_path / "big" / f"{name}.npz")
        np.testing.assert_allclose(b.poses[0, :22], a.poses[0, :22], atol=1e-5)
        assert abs(float(b.vertices(bm, 0, 1)[0, :, 2].min())) < 0.002, name
        assert abs(float(a.vertices(bm, 0, 1)[0, :, 2].min())) > 0.03, name     # kept, F's body would not stand


def test_demo_goal_stage_stands_on_the_floor_of_the_graspkit_model_body(tmp_path, monkeypatch):
    """Under GRASPKIT_MODEL naming a body 8 % larger, the demo's GOAL stage runs MNet on that body (eval_goal's) from
    the shipped clip's start restood on it: frame 0's lowest vertex on the floor, no frame under it. Until 2026-12-07
    the start kept the translation of graspkit's body and the whole approach sank 7.3 cm."""
    from conftest import PROCEDURAL_MODEL, npz_copy

    from graspkit.body import BodyModel
    from graspkit.data import load_motion
    from graspkit.demo import run_demo

    with np.load(PROCEDURAL_MODEL, allow_pickle=False) as z:
        big = npz_copy(PROCEDURAL_MODEL, tmp_path / "big.npz", v_template=z["v_template"] * 1.08,
                       shapedirs=z["shapedirs"] * 1.08)
    monkeypatch.setenv("GRASPKIT_MODEL", str(big))
    run_demo(tmp_path / "out", stages=("goal",))
    low = load_motion(tmp_path / "out" / "goal_approach.npz").vertices(BodyModel.from_file(big))[:, :, 2].amin(1)
    assert abs(float(low[0])) < 0.002 and float(low.min()) > -0.01


def test_demo_refuses_unknown_stages(tmp_path, capsys):
    from graspkit.cli import main

    assert main(["demo", "--out", str(tmp_path), "--stages", "body,saga2"]) == 2
    err = capsys.readouterr().err
    assert "--stages" in err and "saga2" in err and not list(tmp_path.iterdir())


def test_demo_skips_a_stage_for_any_checkpoint_it_loads(tmp_path, monkeypatch, capsys):
    """Each method stage is skipped, with the file named, when any checkpoint it loads is missing (only one per stage
    was checked: without gnet.pt the goal stage ended the demo with 'checkpoint: no file', an independent check);
    the stages that can run still do."""
    import graspkit.demo as D

    ck = tmp_path / "ck"
    ck.mkdir()
    for f in ("mnet.pt", "wholegrasp.pt", "motionfill.pt"):        # each stage's first-named file, not the others
        (ck / f).write_bytes(b"")
    monkeypatch.setattr(D, "CHECKPOINTS", ck)
    ran = []
    for name, (fn, needs) in list(D.METHOD_STAGES.items()):
        monkeypatch.setitem(D.METHOD_STAGES, name, (lambda bm, out, n=name: ran.append(n) or ([], None), needs))
    monkeypatch.setattr(D, "overview", lambda panels, faces: None)
    monkeypatch.setattr(D, "save_png", lambda fig, path, dpi=None: path)
    D.run_demo(tmp_path / "out", stages=("planner", "saga", "saga_motion", "goal", "wandr"))
    out, err = capsys.readouterr()
    assert "skipping" not in out                                 # notices on stderr: stdout keeps the written files
    assert ran == ["planner"]
    for stage, f in (("saga", "pose_prior.pt"), ("saga_motion", "pose_prior.pt"), ("goal", "gnet.pt"),
                     ("wandr", "wandr.pt")):
        assert f"skipping {stage}: its checkpoint {ck / f} is missing" in err


def test_out_paths_that_cannot_be_written_and_bad_seeds_fail_before_any_work(tmp_path, capsys):
    """A file where a folder is wanted (or the reverse), a path under a file, a negative seed and a time shorter than
    a frame are named in one line, exit code 2, no traceback (in process: an exception would fail the test; the
    process-level exit codes are test_help_and_version's and test_body_info_reads_a_file_and_reports_a_bad_one's)."""
    from graspkit.cli import main

    (tmp_path / "f").write_text("x")
    for args, message in ((("wandr", "--goal", "1", "0", "1", "--out", str(tmp_path / "f")), "is a file; expected a folder"),
                          (("wandr", "--goal", "1", "0", "1", "--out", str(tmp_path / "f" / "sub")), "is a file, so"),
                          (("body", "build", "--out", str(tmp_path)), "is a folder; expected a file path"),
                          (("data", "make", "--kind", "reach", "--n", "1", "--seed", "-1", "--out", str(tmp_path / "d")),
                           "--seed: expected a non-negative integer"),
                          (("wandr", "--goal", "1", "0", "1", "--seconds", "0.01", "--out", str(tmp_path / "w")),
                           "--seconds: expected at least one frame"),
                          (("wandr", "--goal", "1e9", "0", "1", "--out", str(tmp_path / "w")),   # once: 44.7 GiB
                           "--goal: expected coordinates within 50 m")):
        assert main(list(args)) == 2, args
        err = capsys.readouterr().err
        assert message in err and "Traceback" not in err, (args, err)
    assert not (tmp_path / "d").exists() and not (tmp_path / "w").exists()


def test_bad_counts_seeds_and_folder_outs_are_named_before_any_work(tmp_path, capsys):
    """Thread, epoch, batch, clip and chunk counts below one, grasp-only options for a motion kind, a bad body-model
    file, a seed past 2^63 and an --out that is a file where a command writes a folder: exit code 2 and the option
    named, nothing written (a training run with --epochs 0 used to write an untrained checkpoint over --out)."""
    from graspkit.cli import main

    (tmp_path / "clip.pt").write_text("x")
    for args, message in ((("wandr", "--goal", "1", "0", "1", "--seed", str(10**23), "--out", str(tmp_path / "w")),
                           "--seed: expected a non-negative integer below 2^63"),
                          (("eval", "wandr", "--checkpoint", "x.pt", "--threads", "0"), "--threads: expected an integer >= 1"),
                          (("train", "wandr", "--epochs", "0", "--out", str(tmp_path / "w.pt")),
                           "--epochs: expected an integer >= 1"),
                          (("train", "wandr", "--batch-size", "0", "--out", str(tmp_path / "w.pt")),
                           "--batch-size: expected an integer >= 1"),
                          (("wandr", "--goal", "1", "0", "1", "--out", str(tmp_path / "clip.pt")),
                           "clip.pt is a file; expected a folder"),
                          (("data", "make", "--kind", "reach", "--n", "0", "--out", str(tmp_path / "d")),
                           "--n: expected an integer >= 1"),
                          (("data", "make", "--kind", "grasp", "--chunk", "0", "--out", str(tmp_path / "d")),
                           "--chunk: expected an integer >= 1"),
                          (("data", "make", "--kind", "reach", "--chunk", "4", "--objects", "apple", "--out",
                            str(tmp_path / "d")),
                           "--chunk and --objects: only for --kind grasp or approach, not reach"),
                          (("data", "make", "--kind", "reach", "--model", str(tmp_path / "clip.pt"), "--out",
                            str(tmp_path / "d")), "--model: ")):
        assert main(list(args)) == 2, args
        assert message in capsys.readouterr().err, args
    assert sorted(p.name for p in tmp_path.iterdir()) == ["clip.pt"]


@pytest.mark.parametrize("command", ["saga", "goal"])
def test_a_bad_object_file_is_named_as_the_option(tmp_path, capsys, command):
    from graspkit.cli import main

    (tmp_path / "cup.obj").write_text("not a mesh\n")
    for obj, message in ((tmp_path / "nope.obj", "no such mesh file"), (tmp_path / "cup.obj", "cup.obj")):
        assert main([command, "--object", str(obj), "--out", str(tmp_path / "o")]) == 2
        err = capsys.readouterr().err
        assert err.count("--object") >= 1 and message in err and "name:" not in err, err
    assert not (tmp_path / "o").exists()


def test_object_notes_say_when_an_object_is_placed_outside_the_training_heights():
    """--at heights against the range the grasp and approach data draw from (sample_object_pose's default)."""
    import inspect

    from graspkit.cli import _object_pose, object_range_notes
    from graspkit.objects.placement import sample_object_pose

    lo, hi = inspect.signature(sample_object_pose).parameters["height_range"].default
    assert (lo, hi) == (0.5, 1.7)
    assert object_range_notes(None) == [] and object_range_notes(_object_pose([0, 0.6, 0.9, 0])) == []
    assert object_range_notes(_object_pose([0, 0.6, 0.5, 0])) == [] == object_range_notes(_object_pose([0, 0.6, 1.7, 0]))
    assert "0.25 m high, below the 0.5-1.7 m" in object_range_notes(_object_pose([0.3, 0.5, 0.25, -60]))[0]
    assert "1.90 m high, above" in object_range_notes(_object_pose([0, 0.6, 1.9, 0]))[0]


def test_wandr_notes_say_when_a_goal_leaves_the_trained_range():
    from graspkit.cli import wandr_range_notes

    assert wandr_range_notes((1.5, 0.5, 1.0), 3.0) == []                       # 1.6 m in 3 s: a walk
    assert any("past the 8 s" in n for n in wandr_range_notes((1.5, 0.5, 1.0), 10.0))
    assert any("8.0 m away: 2.0 m/s" in n for n in wandr_range_notes((8.0, 0.0, 1.0), 4.0))
    assert any("below the floor" in n for n in wandr_range_notes((1.0, 0.0, -0.5), 4.0))
    assert any("4.50 m high" in n for n in wandr_range_notes((0.3, 0.0, 4.5), 4.0))    # above every training goal
    assert wandr_range_notes((0.3, 0.0, 1.9), 4.0) == []                        # the highest training goals


def test_wandr_command_moves_the_body_of_its_model_file(tmp_path, capsys):
    """`graspkit wandr --model F` with F 8 % larger than graspkit's body (the body WANDR was trained on): the motion
    starts standing on the floor of F's body and the wrist distance it prints is F's, both read back through the smplx
    package on F. Until 2026-12-07 the rollout ran on graspkit's body and was drawn on F's, 7.5 cm under the floor."""
    import re

    import smplx
    import torch

    from graspkit.cli import main
    from conftest import PROCEDURAL_MODEL, npz_copy

    folder = tmp_path / "models" / "smplx"
    folder.mkdir(parents=True)
    with np.load(PROCEDURAL_MODEL, allow_pickle=False) as z:
        tall = npz_copy(PROCEDURAL_MODEL, folder / "SMPLX_NEUTRAL.npz", v_template=z["v_template"] * 1.08,
                        shapedirs=z["shapedirs"] * 1.08)
    goal = np.array([1.5, 0.5, 1.0])
    assert main(["wandr", "--goal", *map(str, goal), "--seconds", "2", "--model", str(tall),
                 "--out", str(tmp_path / "w")]) == 0
    text = capsys.readouterr().out
    with np.load(tmp_path / "w" / "wandr_s0.npz", allow_pickle=False) as z:
        poses, trans, betas = (torch.as_tensor(z[k], dtype=torch.float64) for k in ("poses", "trans", "betas"))
    T = len(poses)
    ref = smplx.create(str(folder.parent), model_type="smplx", gender="neutral", ext="npz", use_pca=False,
                       flat_hand_mean=True, num_betas=10, batch_size=T, dtype=torch.float64)
    body = ref(betas=betas[None].expand(T, -1), global_orient=poses[:, :3], body_pose=poses[:, 3:66],
               jaw_pose=poses[:, 66:69], leye_pose=poses[:, 69:72], reye_pose=poses[:, 72:75],
               left_hand_pose=poses[:, 75:120], right_hand_pose=poses[:, 120:165], transl=trans,
               expression=torch.zeros(T, 10, dtype=torch.float64))
    assert abs(float(body.vertices[0, :, 2].min())) < 0.002                  # frame 0 stands on F's floor
    assert float(body.vertices[:, :, 2].amin(1).min()) > -0.01                 # and no frame sinks (the lift)
    closest = float(re.search(r"goal ([\d.]+) cm at", text).group(1))
    assert closest == pytest.approx(100 * np.linalg.norm(body.joints[:, 21].numpy() - goal, axis=1).min(), abs=0.06)
    assert closest < 10                                                      # F's wrist reaches the goal


def test_wandr_command_reports_what_smplx_measures_on_its_file(tmp_path, capsys):
    """`graspkit wandr` (with its default lift and with --no-lift): the closest wrist distance and the floor figures it prints are those
    of the .npz it writes, read back through the smplx package (flat_hand_mean=True: absolute hand poses); --lift keeps
    the body out of the floor (a foot at most 1 cm under it)."""
    import re

    import smplx
    import torch

    from graspkit.cli import main
    from conftest import PROCEDURAL_MODEL

    goal = np.array([1.1, -0.9, 0.45])
    ref = None
    for lift in (False, True):
        out = tmp_path / ("lift" if lift else "paper")
        assert main(["wandr", "--goal", *map(str, goal), "--seconds", "2", "--out", str(out)]
                    + ([] if lift else ["--no-lift"])) == 0                 # lift is the command's default
        text = capsys.readouterr().out
        with np.load(out / "wandr_s0.npz", allow_pickle=False) as z:
            poses, trans, betas = (torch.as_tensor(z[k], dtype=torch.float64) for k in ("poses", "trans", "betas"))
        T = len(poses)
        if ref is None:
            ref = smplx.create(str(PROCEDURAL_MODEL.parents[1]), model_type="smplx", gender="neutral", ext="npz",
                               use_pca=False, flat_hand_mean=True, num_betas=10, batch_size=T, dtype=torch.float64)
        body = ref(betas=betas[None].expand(T, -1), global_orient=poses[:, :3], body_pose=poses[:, 3:66],
                   jaw_pose=poses[:, 66:69], leye_pose=poses[:, 69:72], reye_pose=poses[:, 72:75],
                   left_hand_pose=poses[:, 75:120], right_hand_pose=poses[:, 120:165], transl=trans,
                   expression=torch.zeros(T, 10, dtype=torch.float64))
        d = (body.joints[:, 21].numpy() - goal)                            # smplx joint 21: the right wrist
        closest = float(re.search(r"goal ([\d.]+) cm at", text).group(1))
        assert closest == pytest.approx(100 * np.linalg.norm(d, axis=1).min(), abs=0.06)
        low = body.vertices[:, :, 2].amin(1).numpy()
        deepest, share = (float(x) for x in re.search(r"the body ([\d.]+) cm below .*, (\d+) % of the frames", text).groups())
        assert deepest == pytest.approx(100 * max(0.0, -low.min()), abs=0.06)
        assert share == pytest.approx(100 * np.mean(low < -0.01), abs=0.6)
        floating = float(re.search(r"cm of the floor \(floating\) in (\d+) % of the frames", text).group(1))
        assert floating == pytest.approx(100 * np.mean(low > 0.05), abs=0.6)
        if lift:
            assert low.min() > -0.01 and "--no-lift" not in text


@pytest.mark.skipif(not Path("/proc/self").exists(), reason="needs Linux's /proc")
def test_an_out_in_a_folder_that_takes_no_files_is_named_before_any_work():
    """/proc takes no new files, even for root, to whom os.access says every folder is writable (the command used to
    fail after its work with a bare OSError)."""
    from graspkit.cli import check_out

    with pytest.raises(ValueError, match="--out: /proc is not writable .*, so /proc/graspkit_x/y cannot be made"):
        check_out(Path("/proc/graspkit_x/y"))
    check_out(Path(tempfile.gettempdir()) / "graspkit_x")          # a writable folder passes (nothing is created)
    assert not (Path(tempfile.gettempdir()) / "graspkit_x").exists()


def test_a_cache_or_out_that_cannot_be_written_is_named_before_the_work(tmp_path, monkeypatch, capsys):
    """An independent check: with a read-only cache, `train pose_prior` built its data and trained an epoch before a
    bare "[Errno 30] Read-only file system: '<cache>/runs'"; a dangling symbolic link as --out passed the check and
    `saga` failed after its minute of work with "File exists". Both are refused up front, naming GRASPKIT_CACHE or
    the link. (A cache under a regular file cannot take files even for root, to whom chmod means nothing.)"""
    from graspkit.cli import main

    blocker = tmp_path / "a_file"
    blocker.write_text("")
    monkeypatch.setenv("GRASPKIT_CACHE", str(blocker / "cache"))
    for argv in (["train", "pose_prior", "--epochs", "1"], ["data", "make", "--kind", "reach", "--n", "1"]):
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert f"GRASPKIT_CACHE: {blocker} is a file" in err and "set GRASPKIT_CACHE to a writable folder" in err
    assert not list(tmp_path.rglob("*.pt")) and sorted(p.name for p in tmp_path.iterdir()) == ["a_file"]
    monkeypatch.setenv("GRASPKIT_CACHE", str(tmp_path / "cache"))
    dangling = tmp_path / "dangling"
    dangling.symlink_to(tmp_path / "nowhere")
    assert main(["data", "make", "--kind", "reach", "--n", "1", "--out", str(dangling)]) == 2
    err = capsys.readouterr().err
    assert f"--out: {dangling} is a symbolic link to {tmp_path / 'nowhere'}, which does not exist" in err
    assert not (tmp_path / "cache").exists() and not (tmp_path / "nowhere").exists()
    from graspkit.cli import check_out

    lost, new = tmp_path / "lost.pt", tmp_path / "new.pt"          # a file --out is written through its link
    lost.symlink_to(tmp_path / "gone" / "w.pt")
    new.symlink_to(tmp_path / "w.pt")
    with pytest.raises(ValueError, match=f"^--out: {lost} is a symbolic link to .*gone/w.pt, whose folder does not"):
        check_out(lost, is_file=True)
    check_out(new, is_file=True)                                       # its target's folder is there: fine
    folder = tmp_path / "adir.pt"                                      # a link to a folder: the link is named
    (tmp_path / "dir").mkdir()
    folder.symlink_to(tmp_path / "dir")
    with pytest.raises(ValueError, match=f"^--out {folder} -> {tmp_path / 'dir'}: .* is a folder; expected a file"):
        check_out(folder, is_file=True)


def test_a_missing_shipped_checkpoint_says_when_data_stubs_is_not_there(tmp_path, monkeypatch, capsys):
    """Run from a plain (non-editable) install, data_stubs/ is not beside the package: the missing-checkpoint errors
    say so; a checkpoint of one's own, or a data_stubs/ that is there, gets the plain message."""
    import importlib
    import pkgutil

    import graspkit
    import graspkit.paths as paths
    from graspkit.cli import main
    from graspkit.goal import synthesize as goal_synthesize
    from graspkit.saga import synthesize as saga_synthesize

    # every module first imported now, not while DATA_STUBS is patched: one imported then (pose_prior, by saga's
    # synthesize) kept the gone folder in its path constants for the rest of the worker's tests
    for m in pkgutil.walk_packages(graspkit.__path__, "graspkit."):
        if not m.name.endswith("__main__"):
            importlib.import_module(m.name)
    gone = tmp_path / "site" / "data_stubs"
    monkeypatch.setattr(paths, "DATA_STUBS", gone)
    for synth, ck in ((goal_synthesize, "gnet.pt"), (saga_synthesize, "wholegrasp.pt")):
        with pytest.raises(FileNotFoundError) as e:
            synth("mug", checkpoints=gone / "checkpoints")
        assert f"{gone / 'checkpoints' / ck} is missing" in str(e.value) and "pip install -e ." in str(e.value)
    assert main(["wandr", "--goal", "1", "0", "1", "--checkpoint", str(gone / "w.pt"), "--out", str(tmp_path)]) == 2
    assert f"{gone} does not exist" in capsys.readouterr().err
    assert paths.stub_hint(tmp_path / "mine.pt") == ""
    gone.mkdir(parents=True)                    # a data_stubs/ folder alone (once made by a default `body build`)
    assert "pip install -e ." in paths.stub_hint(gone / "checkpoints" / "w.pt")
    (gone / "checkpoints").mkdir()
    assert paths.stub_hint(gone / "checkpoints" / "w.pt") == ""


def test_a_plain_install_builds_the_default_body_in_the_cache_not_the_package(tmp_path, monkeypatch, capsys):
    """Without data_stubs/ (a plain `pip install`), the default body is the one built in the cache: `body build`
    writes it there, `body info` and the library's loaders name `graspkit body build` when it is missing, the
    commands build it there (never in the installed package), and `saga` / `goal` refuse missing checkpoints before
    building anything."""
    import graspkit.body.procedural as procedural
    import graspkit.goal as goal
    import graspkit.paths as paths
    import graspkit.saga as saga
    from graspkit.body import BodyModel
    from graspkit.cli import build_parser, main
    from graspkit.demo import load_or_build_body

    shipped_model = paths.default_model_path()
    gone, cache = tmp_path / "site" / "data_stubs", tmp_path / "cache"
    monkeypatch.setattr(paths, "DATA_STUBS", gone)
    monkeypatch.setattr(saga, "CHECKPOINTS", gone / "checkpoints")     # as they are read at import
    monkeypatch.setattr(goal, "CHECKPOINTS", gone / "checkpoints")
    monkeypatch.setenv("GRASPKIT_CACHE", str(cache))
    monkeypatch.delenv("GRASPKIT_MODEL", raising=False)
    built = cache / "body_models" / "smplx" / "SMPLX_NEUTRAL.npz"
    assert paths.default_model_path() == built
    assert build_parser(["body", "build"]).parse_args(["body", "build"]).out == built
    with pytest.raises(ValueError, match="graspkit body build"):
        BodyModel.from_file(paths.default_model_path())
    assert main(["body", "info"]) == 2 and "graspkit body build" in capsys.readouterr().err
    for method in ("saga", "goal"):
        assert main([method, "--object", "mug", "--out", str(tmp_path / "out")]) == 2
        assert "pip install -e ." in capsys.readouterr().err
    for model in ("wandr", "gnet"):                       # their default --out is in data_stubs/checkpoints
        assert main(["train", model]) == 2 and "--out: required here" in capsys.readouterr().err
    assert not cache.exists() and not (tmp_path / "site").exists() and not (tmp_path / "out").exists()
    made = []                                   # the build itself (15 s) stood in for by the shipped file
    monkeypatch.setattr(procedural, "build_procedural_smplx", lambda seed: seed)
    monkeypatch.setattr(procedural, "save_model_npz",
                        lambda model, path: made.append(path) or Path(path).parent.mkdir(parents=True, exist_ok=True) or
                        Path(path).write_bytes(shipped_model.read_bytes()))
    assert load_or_build_body().num_betas > 0 and made == [built] and not (tmp_path / "site").exists()


def _mark_worker(folder: str) -> None:
    """A pool initializer: leaves one file per worker process started."""
    import os

    Path(folder, f"worker_{os.getpid()}").touch()


def test_a_pool_starts_no_more_processes_than_calls(tmp_path):
    """pool_results with 16 workers for 2 calls starts at most 2 processes (`data make --workers 500` for 3 clips
    started 500, each loading torch, and ended in a BrokenProcessPool)."""
    from graspkit.paths import pool_results

    got = sorted(pool_results([(abs, (-1,)), (abs, (-2,))], 16, _mark_worker, (str(tmp_path),)))
    assert got == [1, 2] and 1 <= len(list(tmp_path.glob("worker_*"))) <= 2


def _slow_write(i: int, folder: str) -> int:
    """A pool call: fails after 0.5 s for i = 0, else writes its file as graspkit's writers do, through a temporary
    file it removes when stopped, the write taking 10 s (a slack that a loaded machine needs to stop it first)."""
    import time

    if i == 0:
        time.sleep(0.5)
        raise ValueError("call 0 failed")
    tmp = Path(folder, f".call_{i}.tmp")
    try:                               # made inside the try: a stop landing just after the touch still removes it
        tmp.touch()
        time.sleep(10.0)
        tmp.rename(Path(folder, f"call_{i}"))
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return i


def _sigint_handler() -> bool:
    """A pool call: whether this worker ignores Ctrl-C."""
    import signal

    return signal.getsignal(signal.SIGINT) == signal.SIG_IGN


def test_a_pool_stops_its_workers_on_an_error_and_leaves_ctrl_c_to_the_parent(tmp_path, monkeypatch):
    """An error (Ctrl-C reaches the parent the same way) stops the workers, the running call through its cleanup (no
    temporary file left), and starts no queued call: the workers had taken Ctrl-C as one call's error and gone on
    with the queued calls, writing files for a minute. The pool has returned only once its workers are gone, so
    nothing can be written after; and no thread of the pool prints a traceback (cancelling the calls by hand as
    well had raced the pool's own failing of them: InvalidStateError)."""
    import threading

    from graspkit.paths import pool_results

    assert list(pool_results([(_sigint_handler, ())], 1)) == [True]
    thread_errors = []
    monkeypatch.setattr(threading, "excepthook", lambda a: thread_errors.append(a.exc_type.__name__))
    for k in range(3):
        folder = tmp_path / str(k)
        folder.mkdir()
        with pytest.raises(ValueError, match="call 0 failed"):
            list(pool_results([(_slow_write, (i, str(folder))) for i in range(8)], 2))
        assert list(folder.iterdir()) == []
    assert thread_errors == []


def test_the_evaluators_check_out_before_any_work(tmp_path, capsys):
    """python -m graspkit.eval_saga / eval_goal: an --out that cannot be written is refused at once, naming --out
    (it had run the whole evaluation first, then failed on a temporary file, once leaving one at /)."""
    from graspkit import eval_goal, eval_saga
    from graspkit.paths import DATA_STUBS

    (tmp_path / "afile").touch()
    assert eval_saga.main(["--data", str(DATA_STUBS / "grasps"), "--out", str(tmp_path)]) == 2
    assert f"--out: {tmp_path} is a folder; expected a file path" in capsys.readouterr().err
    assert eval_goal.main(["--data", str(DATA_STUBS / "grasps"), "--out", str(tmp_path / "afile" / "x.json")]) == 2
    assert "--out: " in capsys.readouterr().err and list(tmp_path.iterdir()) == [tmp_path / "afile"]


@pytest.mark.parametrize("at", [["0", "0", "1e6", "0"], ["1e6", "0", "1", "0"], ["0", "-60", "1", "0"]])
def test_saga_and_goal_refuse_an_object_out_of_any_reach(at, tmp_path, capsys):
    from graspkit.cli import main

    for method in ("saga", "goal"):
        assert main([method, "--object", "mug", "--at", *at, "--out", str(tmp_path / method)]) == 2
        assert "--at: expected the object within 50 m" in capsys.readouterr().err
    assert not list(tmp_path.iterdir())


def test_wandr_train_and_eval_name_the_flag_before_any_work(tmp_path, capsys):
    """Errors that a library function raised under its parameter's name (floor:, clips_folder:, checkpoint:,
    stride_scale:) name the flag the user typed, and the counts are checked before the clips load."""
    from graspkit.cli import as_flags, main
    from graspkit.paths import DATA_STUBS

    ck = str(DATA_STUBS / "checkpoints" / "wandr.pt")
    (tmp_path / "no_clips").mkdir()
    cases = [(["eval", "wandr", "--checkpoint", ck, "--floor", "nan"], "--floor: expected a finite tolerance >= 0"),
             (["eval", "wandr", "--checkpoint", str(tmp_path / "no.pt")], "--checkpoint: {} is missing".format(tmp_path / "no.pt")),
             (["eval", "wandr", "--checkpoint", ck, "--clips", str(tmp_path / "no_clips")],
              "--clips: no reaching clips"),
             (["train", "wandr", "--init", str(tmp_path / "no.pt"), "--out", str(tmp_path / "w.pt")],
              "--init: {} is missing".format(tmp_path / "no.pt")),
             (["train", "wandr", "--stride-scale", "0", "--out", str(tmp_path / "w.pt")], "--stride-scale: expected"),
             (["train", "wandr", "--data", str(tmp_path / "no_clips"), "--out", str(tmp_path / "w.pt")],
              "--data: no clips under")]
    for argv, message in cases:
        assert main(argv) == 2, argv
        assert message in capsys.readouterr().err, argv
    assert sorted(p.name for p in tmp_path.iterdir()) == ["no_clips"]            # nothing written
    with pytest.raises(FileNotFoundError, match="^--x: gone$"), as_flags(x="--x"):
        raise FileNotFoundError("x: gone")
    with pytest.raises(ValueError, match="^xy: kept$"), as_flags(x="--x"):    # only a whole leading name
        raise ValueError("xy: kept")


def test_the_wandr_command_fixes_its_thread_count(monkeypatch, tmp_path):
    """`graspkit wandr` rolls out on --threads (default 1) whatever torch's thread count was before, so that its file
    does not depend on the machine's cores (larger rollouts' sums round differently on another count: 3e-6 m measured
    on WANDR's generate). The rollout is replaced by a probe of the thread count it would run on."""
    import torch

    import graspkit.benchmark
    from graspkit.cli import main

    seen = []

    def probe(*a, **k):
        seen.append(torch.get_num_threads())
        raise ValueError("probe: stopped")

    monkeypatch.setattr(graspkit.benchmark, "wandr_motions", probe)
    before = torch.get_num_threads()
    try:
        for ambient, flag in ((2, []), (1, ["--threads", "2"])):
            torch.set_num_threads(ambient)
            assert main(["wandr", "--goal", "1.2", "0.4", "1.0", "--out", str(tmp_path), *flag]) == 2
    finally:
        torch.set_num_threads(before)
    assert seen == [1, 2]


def test_saga_stage_draws_the_object_at_the_first_test_grasps_pose(tmp_path, monkeypatch):
    """The saga stage shows the WholeGrasp sample on 'the placement of the first shipped test grasp' (module doc): the
    object mesh in the world is the catalogue mesh at that grasp file's object pose (rotation, then translation)."""
    import torch

    import graspkit.demo as D
    import graspkit.eval_saga as ES
    from graspkit.body import BodyModel
    from graspkit.data.grasp_datasets import grasp_files
    from graspkit.objects.catalogue import make_object
    from graspkit.objects.placement import ObjectPose, apply_pose
    from graspkit.paths import DATA_STUBS, default_model_path
    from graspkit.rotations import axis_angle_to_matrix

    seen = {}
    zero = {k: torch.zeros(1, n) for k, n in (("global_orient", 3), ("body_pose", 63), ("jaw_pose", 3),
                                               ("leye_pose", 3), ("reye_pose", 3), ("left_hand_pose", 45),
                                               ("right_hand_pose", 45), ("transl", 3), ("betas", 10))}
    monkeypatch.setattr(ES, "fit_variants", lambda *a, **k: {"full": type("R", (), {"params": zero})()})
    monkeypatch.setattr(D, "_write_clip", lambda bm, motion, out, name, objects, title: seen.update(objects) or ([], None))
    D.saga_stage(BodyModel.from_file(default_model_path()), tmp_path)
    (name, mesh), = seen.items()
    first = next(f for f in grasp_files(DATA_STUBS / "grasps", "grasp", split="test")
                 if str(np.load(f, allow_pickle=False)["obj_name"]) == name)
    z = np.load(first, allow_pickle=False)
    R = axis_angle_to_matrix(torch.as_tensor(z["object.params.global_orient"][0], dtype=torch.float64)).numpy()
    assert np.linalg.norm(R - R.T) > 0.1                        # a turn that R and R^T tell apart
    want = apply_pose(ObjectPose(z["object.params.transl"][0].astype(np.float64), R), make_object(name))
    assert np.allclose(mesh.vertices, want.vertices, atol=1e-5)


@pytest.fixture
def probe(monkeypatch):
    """`saga.synthesize` and `goal.synthesize` replaced by a probe that records its keyword arguments and stops."""
    import graspkit.goal
    import graspkit.saga
    seen = []

    def fake(*a, **k):
        seen.append(k)
        raise ValueError("probe: stopped")

    monkeypatch.setattr(graspkit.saga, "synthesize", fake)
    monkeypatch.setattr(graspkit.goal, "synthesize", fake)
    return seen


def test_saga_passes_hold_start_on(probe, tmp_path):
    """`graspkit saga` passes --hold-start / --no-hold-start on to synthesize."""
    from graspkit.cli import main

    for flag in ([], ["--no-hold-start"]):
        assert main(["saga", "--object", "mug", "--out", str(tmp_path), *flag]) == 2
    assert [k.get("hold_start") for k in probe] == [True, False]


def test_goal_passes_max_frames_and_stall_on(probe, tmp_path):
    """`graspkit goal` passes --max-frames and --stall on to synthesize (defaults 150 frames and STALL_FRAMES)."""
    from graspkit.cli import main
    from graspkit.models.mnet import STALL_FRAMES

    for flag in ([], ["--max-frames", "37", "--stall", "0"]):
        assert main(["goal", "--object", "mug", "--out", str(tmp_path), *flag]) == 2
    assert [k.get("max_frames") for k in probe] == [150, 37]
    assert [k.get("stall") for k in probe] == [STALL_FRAMES, None]


@pytest.fixture
def probe_args(monkeypatch):
    """saga/goal.synthesize and benchmark.wandr_motions replaced by a probe that records its arguments and stops."""
    import graspkit.benchmark
    import graspkit.goal
    import graspkit.saga
    seen = []

    def fake(*a, **k):
        seen.append((a, k))
        raise ValueError("probe: stopped")

    monkeypatch.setattr(graspkit.saga, "synthesize", fake)
    monkeypatch.setattr(graspkit.goal, "synthesize", fake)
    monkeypatch.setattr(graspkit.benchmark, "wandr_motions", fake)
    return seen


def test_at_yaw_is_in_degrees(probe_args, tmp_path):
    """`--at X Y Z YAW_DEG`: YAW_DEG = 90 turns the object a quarter turn about z (x -> y), placed at X Y Z."""
    from graspkit.cli import main

    assert main(["saga", "--object", "mug", "--at", "0.3", "-0.6", "0.8", "90", "--out", str(tmp_path)]) == 2
    pose = probe_args[0][1]["object_pose"]
    np.testing.assert_allclose(pose.rotation @ [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(pose.translation, [0.3, -0.6, 0.8])


@pytest.mark.parametrize("seconds, frames", [("0.999", 30), ("1.99", 60), ("2", 60)])
def test_wandr_seconds_are_rounded_to_frames_at_30_fps(probe_args, tmp_path, seconds, frames):
    """`graspkit wandr --seconds S` generates round(30 S) frames (t_G at 30 fps)."""
    from graspkit.cli import main

    assert main(["wandr", "--goal", "1", "0", "1", "--seconds", seconds, "--out", str(tmp_path)]) == 2
    a, k = probe_args[0]
    assert a[2] == frames


def test_object_pose_yaw_is_in_degrees_and_the_floor_is_allowed():
    """--at X Y Z YAW_DEG: yaw 90 is a quarter turn about z (scipy's rotation), and Z = 0 (documented 0 <= Z) is
    taken."""
    from scipy.spatial.transform import Rotation

    from graspkit.cli import _object_pose

    pose = _object_pose([1.0, 2.0, 0.8, 90.0])
    np.testing.assert_allclose(pose.rotation, Rotation.from_euler("z", 90, degrees=True).as_matrix(), atol=1e-12)
    np.testing.assert_allclose(pose.translation, [1.0, 2.0, 0.8])
    assert _object_pose([0.0, 0.0, 0.0, 0.0]).translation[2] == 0.0


def test_wandr_speed_note_uses_the_ground_distance():
    """The speed note compares the distance on the ground (x, y) over the time with 1.5 m/s (docstring: 'faster than
    1.5 m/s on the ground'): 5.8 m in 4 s is 1.45 m/s however high the goal."""
    from graspkit.cli import wandr_range_notes

    assert not any("m/s" in n for n in wandr_range_notes((5.8, 0.0, 1.8), 4.0))
    assert any("m/s" in n for n in wandr_range_notes((6.2, 0.0, 0.2), 4.0))


def test_cli_check_helpers_accept_an_existing_file_and_name_one_missing_folder(tmp_path):
    """check_out takes an existing file as --out (it is replaced); check_folders checks a single path too; a
    reports_errors main turns an OSError into exit status 2 with `prog: error:`."""
    from graspkit.cli import check_folders, check_out, reports_errors

    (tmp_path / "w.pt").write_text("x")
    check_out(tmp_path / "w.pt", True)
    with pytest.raises(FileNotFoundError, match="--data: .*nope: no such folder"):
        check_folders(tmp_path / "nope")
    check_folders(tmp_path)

    @reports_errors("prog")
    def main(argv=None):
        raise FileNotFoundError("data: gone")

    assert main([]) == 2


def test_body_gallery_stands_each_body_on_the_ground_with_its_own_height(bm):
    """Each gallery body stands on z = 0 and is centred above the origin, and its height is that of the body model
    posed with its (pose, beta0): a standing pose with beta0 +2 and -2 gets the model's heights for those shapes."""
    from graspkit.body.poses import body_pose, y_up_to_z_up
    from graspkit.demo import body_gallery

    bodies = [("a_pose", -2.0), ("squat", 0.0), ("a_pose", 2.0)]
    fig, v = body_gallery(bm, bodies)
    plt.close(fig)
    np.testing.assert_allclose(v[..., 2].amin(1).numpy(), 0.0, atol=1e-6)
    np.testing.assert_allclose(v[..., :2].mean(1).numpy(), 0.0, atol=1e-5)
    with torch.no_grad():
        for k, (pose, beta) in enumerate(bodies):
            b = torch.zeros(1, bm.num_betas)
            b[0, 0] = beta
            ref = bm(betas=b, body_pose=body_pose(pose), global_orient=y_up_to_z_up()).vertices[0]
            h = float(ref[:, 2].max() - ref[:, 2].min())
            assert float(v[k, :, 2].max()) == pytest.approx(h, abs=1e-5)


def test_a_missing_model_file_given_by_name_is_not_built(tmp_path):
    """load_or_build_body builds only the default model when it is missing; a named file that is not there is an error
    and nothing is written in its place."""
    from graspkit.demo import load_or_build_body

    with pytest.raises((ValueError, OSError)):
        load_or_build_body(tmp_path / "none.npz")
    assert not list(tmp_path.iterdir())


def test_a_demo_that_can_write_nothing_fails_and_leaves_no_folder(tmp_path, monkeypatch, capsys):
    """Every named stage skipped for its missing checkpoint exited 0 with an empty --out; a planner stage without its
    sample clips left an empty folder behind: both are errors now, named before the folder is made."""
    import graspkit.demo as D

    monkeypatch.setattr(D, "CHECKPOINTS", tmp_path / "none")
    with pytest.raises(FileNotFoundError, match="^stages \\(--stages\\): none of saga, wandr can run: .*wholegrasp.pt"):
        D.run_demo(tmp_path / "out", stages=("saga", "wandr"))
    monkeypatch.setattr(D, "DATA_STUBS", tmp_path / "gone")
    D._test_clip.cache_clear()
    try:
        with pytest.raises(FileNotFoundError, match="none of planner can run: .*/approach is missing \\(its sample"):
            D.run_demo(tmp_path / "out", stages=("planner",))
        assert not (tmp_path / "out").exists()
        monkeypatch.setattr(D, "body_gallery", lambda bm: (plt.figure(), torch.zeros(0, 3)))
        monkeypatch.setattr("graspkit.viz.export.export_scene", lambda scene, path: path)
        D.run_demo(tmp_path / "out", stages=("body", "planner"))          # the planner skipped, as a checkpoint is
        assert "demo: skipping planner: no test-split approach clip" in capsys.readouterr().err
    finally:
        D._test_clip.cache_clear()
    with pytest.raises(ValueError, match="^stages \\(--stages\\): expected at least one"):
        D.run_demo(tmp_path / "out2", stages=())


def test_graspkit_model_is_never_built_over_or_written_by_body_build(tmp_path, monkeypatch, capsys):
    """GRASPKIT_MODEL naming a missing file (a typo) built the procedural body there and ran on it; `body build`
    without --out replaced the file GRASPKIT_MODEL names (a user's own SMPL-X model); a `~` in it was taken as a
    folder named "~"; an unwritable default cache was reported as "GRASPKIT_CACHE: <home>", a variable not set."""
    import graspkit.paths as paths
    from graspkit.cli import build_parser, check_cache
    from graspkit.demo import load_or_build_body

    typo = tmp_path / "models" / "SMPLX_NEUTRL.npz"
    monkeypatch.setenv("GRASPKIT_MODEL", str(typo))
    with pytest.raises(FileNotFoundError, match=f"^GRASPKIT_MODEL: {typo}: no such body-model file"):
        load_or_build_body()
    assert not typo.parent.exists()
    assert build_parser(["body", "build"]).parse_args(["body", "build"]).out == paths.procedural_model_path() != typo
    monkeypatch.setenv("GRASPKIT_MODEL", "~/m/SMPLX_NEUTRAL.npz")
    assert paths.default_model_path() == Path.home() / "m" / "SMPLX_NEUTRAL.npz"
    monkeypatch.delenv("GRASPKIT_CACHE", raising=False)
    home = tmp_path / "home"
    home.mkdir()
    home.chmod(0o500)
    monkeypatch.setenv("HOME", str(home))
    try:
        if os.access(home, os.W_OK):                                   # root writes anywhere: the try-write decides
            monkeypatch.setattr("graspkit.cli.tempfile.TemporaryFile", lambda dir: (_ for _ in ()).throw(
                PermissionError(13, "Permission denied")))
        with pytest.raises(ValueError, match="^graspkit's cache .*/home/.cache/graspkit \\(the default: GRASPKIT_CACHE "
                                             "is not set\\): .* is not writable"):
            check_cache()
    finally:
        home.chmod(0o700)



def test_data_make_gets_its_body_before_making_its_folder(tmp_path, monkeypatch, capsys):
    """In a plain `pip install` (no data_stubs/), `data make` failed on the missing default body only inside the
    maker, leaving the new --out folder behind, empty: the body is now built (in the cache) or named first."""
    import graspkit.body.procedural as procedural
    import graspkit.paths as paths
    from graspkit.cli import main

    monkeypatch.setattr(paths, "DATA_STUBS", tmp_path / "site" / "data_stubs")
    monkeypatch.setenv("GRASPKIT_CACHE", str(tmp_path / "cache"))
    monkeypatch.delenv("GRASPKIT_MODEL", raising=False)

    def build(seed):
        raise RuntimeError("the default body is built first")

    monkeypatch.setattr(procedural, "build_procedural_smplx", build)
    out = tmp_path / "dm"
    with pytest.raises(RuntimeError, match="the default body is built first"):
        main(["data", "make", "--kind", "locomotion", "--n", "1", "--out", str(out)])
    assert not out.exists()
    assert main(["data", "make", "--kind", "locomotion", "--n", "1", "--model", str(tmp_path / "none.npz"),
                 "--out", str(out)]) == 2
    assert "--model: " in capsys.readouterr().err and not out.exists()


def test_a_cache_that_cannot_keep_the_default_body_is_named_before_the_build(tmp_path, monkeypatch):
    """In a plain `pip install` with an unwritable cache, the default body was built for 20-40 s and then failed."""
    import graspkit.body.procedural as procedural
    import graspkit.paths as paths
    from graspkit.demo import load_or_build_body

    monkeypatch.setattr(paths, "DATA_STUBS", tmp_path / "site" / "data_stubs")
    (tmp_path / "afile").write_text("")
    monkeypatch.setenv("GRASPKIT_CACHE", str(tmp_path / "afile"))           # a file: nothing can be made under it
    monkeypatch.delenv("GRASPKIT_MODEL", raising=False)
    monkeypatch.setattr(procedural, "build_procedural_smplx", lambda seed: pytest.fail("built before the check"))
    with pytest.raises(OSError, match="cannot write in .*afile/body_models/smplx.*set GRASPKIT_CACHE"):
        load_or_build_body()


def test_module_commands_end_ctrl_c_with_one_line(capsys):
    """python -m graspkit.eval_goal (eval_saga, eval_motionfill) printed a 40-line KeyboardInterrupt traceback on
    Ctrl-C where `graspkit ...` prints one line."""
    from graspkit.cli import reports_errors

    @reports_errors("python -m graspkit.eval_x")
    def main(argv=None):
        raise KeyboardInterrupt

    assert main([]) == 130
    assert capsys.readouterr().err == "\npython -m graspkit.eval_x: interrupted\n"

    @reports_errors("python -m graspkit.eval_x")
    def noting(argv=None):                            # graspkit's warnings as notes, as `graspkit ...` shows them
        import warnings
        from graspkit.checks import GraspkitWarning
        warnings.warn_explicit("checkpoints: no x.pt", GraspkitWarning, "<frozen runpy>", 1)   # where they point
        return 0

    assert noting([]) == 0
    assert capsys.readouterr().err == "python -m graspkit.eval_x: note: checkpoints: no x.pt\n"


def test_goal_on_a_mesh_file_named_body_writes_the_whole_set(tmp_path, monkeypatch, capsys):
    """A mesh file body.obj (stem 'body', the body mesh's name in the exports) ran the whole pipeline and then
    stopped with 'objects: ...' after the GIF and PNG, a half-written set; a stem too long for the outputs' names
    failed with a bare ENAMETOOLONG after the run: it is refused up front, naming --object."""
    import types

    import numpy as np
    import trimesh

    import graspkit.goal
    from graspkit.cli import main
    from graspkit.data.motion import Motion

    box = trimesh.creation.box((0.08, 0.08, 0.12))
    box.export(tmp_path / "body.obj")
    calls = []

    def fake(obj, **k):
        calls.append(obj)
        trans = np.tile([0.0, 0.0, 0.9], (3, 1))
        return types.SimpleNamespace(name="body", mesh=box, motion=Motion(np.zeros((3, 55, 3)), trans, np.zeros(10), 30.0),
                                     reached=True, metrics={})
    monkeypatch.setattr(graspkit.goal, "synthesize", fake)
    out = tmp_path / "out"
    assert main(["goal", "--object", str(tmp_path / "body.obj"), "--out", str(out)]) == 0
    names = sorted(p.name for p in out.iterdir())
    assert [n for n in names if n.endswith((".gif", ".png", ".npz", ".glb"))] == [
        "goal_body_s0.gif", "goal_body_s0.glb", "goal_body_s0.npz", "goal_body_s0.png", "goal_body_s0_final.glb"]
    long = tmp_path / ("b" * 240 + ".obj")
    box.export(long)
    capsys.readouterr()
    assert main(["goal", "--object", str(long), "--out", str(out)]) == 2
    assert "--object" in capsys.readouterr().err and len(calls) == 1


@pytest.mark.parametrize("argv, env, message", [
    # argparse's Path dropped the slash: a 2.6 MB body file named `newdir` was written
    (["body", "build", "--out", "{tmp}/newdir/"], {}, "--out: {tmp}/newdir/ names a folder; this command writes one"),
    (["train", "pose_prior", "--out={tmp}/runs/"], {}, "--out: {tmp}/runs/ names a folder"),
    (["body", "build", "--ou", "{tmp}/newdir/"], {}, "--out: {tmp}/newdir/ names a folder"),   # argparse's prefix
    (["train", "pose_prior", "--data", "{tmp}/" + "d" * 300, "--out", "{tmp}/p.pt"], {}, "--data: {tmp}/ddd"),
    (["saga", "--object", "mug", "--model", "{tmp}/" + "m" * 300 + ".npz", "--out", "{tmp}/o"], {}, "--model: "),
    # a name past 255 bytes: a bare "[Errno 36] File name too long" that named no option
    (["wandr", "--goal", "1", "0", "1", "--out", "{tmp}/" + "a" * 300], {}, "--out: {tmp}/aaa"),
    (["wandr", "--goal", "1", "0", "1", "--checkpoint", "{tmp}/" + "c" * 300 + ".pt", "--out", "{tmp}/o"], {},
     "--checkpoint: {tmp}/ccc"),
    (["goal", "--object", "{tmp}/" + "m" * 300 + ".obj", "--out", "{tmp}/o"], {}, "--object: {tmp}/mmm"),
    # `~user` of no one: a RuntimeError traceback, even for --version with GRASPKIT_MODEL
    (["body", "info"], {"GRASPKIT_MODEL": "~nosuchuser_gk/x.npz"}, "GRASPKIT_MODEL: ~nosuchuser_gk/x.npz: "),
    (["data", "make", "--kind", "locomotion", "--n", "1"], {"GRASPKIT_CACHE": "~nosuchuser_gk/c"},
     "GRASPKIT_CACHE: ~nosuchuser_gk/c: "),
    (["wandr", "--goal", "1", "0", "1", "--out=~nosuchuser_gk/o"], {}, "--out: ~nosuchuser_gk/o: "),
    # body info's own --model named
    (["body", "info", "--model", "{tmp}/none.npz"], {}, "--model: {tmp}/none.npz"),
])
def test_path_arguments_are_refused_by_name(tmp_path, monkeypatch, capsys, argv, env, message):
    from graspkit.cli import main

    for k, v in env.items():
        monkeypatch.setenv(k, v)
    assert main([a.format(tmp=tmp_path) for a in argv]) == 2
    err = capsys.readouterr().err
    assert message.format(tmp=tmp_path) in err and "Traceback" not in err
    assert sorted(p.name for p in tmp_path.iterdir()) == []                   # nothing written


def test_version_and_help_survive_a_bad_model_variable(monkeypatch, capsys):
    from graspkit.cli import main

    monkeypatch.setenv("GRASPKIT_MODEL", "~nosuchuser_gk/x.npz")
    with pytest.raises(SystemExit) as e:
        main(["--version"])
    assert e.value.code == 0 and "graspkit" in capsys.readouterr().out


def test_a_tilde_in_a_path_argument_is_the_home_folder(tmp_path, monkeypatch):
    """`--out=~/x` (the shell leaves `~` after `=` alone) wrote into a folder named `~` in the working folder."""
    import argparse

    from graspkit.cli import expand_user_paths

    monkeypatch.setenv("HOME", str(tmp_path))
    args = argparse.Namespace(out=Path("~/x"), data=[Path("~/d"), Path("rel/~y")], seed=3, name="~z")
    expand_user_paths(args)
    assert args.out == tmp_path / "x" and args.data == [tmp_path / "d", Path("rel/~y")] and args.name == "~z"


def test_module_commands_refuse_a_folder_out_and_expand_a_tilde(tmp_path, monkeypatch, capsys):
    """`python -m graspkit.eval_goal --out DIR/` wrote its JSON as a file named DIR after the whole evaluation; a mesh
    file given as --object=~/cup.obj (the shell leaves that `~` alone) was not found."""
    import trimesh

    from graspkit import eval_goal, eval_saga
    from graspkit.objects.user import as_object

    for main in (eval_goal.main, eval_saga.main):
        assert main(["--out", f"{tmp_path}/res/"]) == 2
        assert f"--out: {tmp_path}/res/ names a folder" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []
    monkeypatch.setenv("HOME", str(tmp_path))
    trimesh.creation.box((0.08, 0.06, 0.1)).export(tmp_path / "cup.obj")
    assert as_object("~/cup.obj", "--object")[0] == "cup"
    (tmp_path / "~res").mkdir()                   # a folder whose name starts with `~` is that folder, not a home
    trimesh.creation.box((0.08, 0.06, 0.1)).export(tmp_path / "~res" / "box.obj")
    monkeypatch.chdir(tmp_path)
    assert as_object("./~res/box.obj", "--object")[0] == "box"


def test_eval_wandr_clips_without_a_clip_and_a_sunk_task_are_told_first(tmp_path, capsys):
    """`eval wandr --clips DIR` whose reach/ held no reach clip but another .npz ran the whole grid, then failed naming
    `folder`; sample_grasp_task on a mug centred on the floor fitted a half-buried object without a word."""
    import shutil
    import warnings

    import numpy as np

    from graspkit.checks import GraspkitWarning
    from graspkit.cli import main
    from graspkit.data.grasp import sample_grasp_task
    from graspkit.objects.placement import ObjectPose
    from graspkit.paths import DATA_STUBS

    (tmp_path / "reach").mkdir()
    shutil.copy(DATA_STUBS / "motion" / "locomotion" / "locomotion_000000.npz", tmp_path / "reach")
    assert main(["eval", "wandr", "--checkpoint", str(DATA_STUBS / "checkpoints" / "wandr.pt"), "--clips",
                 str(tmp_path)]) == 2
    assert "--clips" in capsys.readouterr().err
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        sample_grasp_task(np.random.default_rng(0), "mug", object_pose=ObjectPose.from_yaw(0.0, np.array([0, -0.6, 0.0])))
    assert any(issubclass(w.category, GraspkitWarning) and "under the floor" in str(w.message) for w in caught)
