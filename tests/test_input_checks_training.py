"""Bad training data, checkpoints and command-line counts give a clear error naming the file, key or flag (exit 2 on
the command line), and nothing is trained or written from them."""
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch

from graspkit.data.grasp_datasets import ApproachDataset, GNetDataset, WholeGraspDataset
from graspkit.train import load_checkpoint

from conftest import npz_copy

STUBS = Path(__file__).resolve().parents[1] / "data_stubs"
CK = STUBS / "checkpoints"


def _copy_with(tmp_path: Path, kind: str, first: int = 0, **replace) -> Path:
    """A folder holding two shipped `kind` files from number `first` on, the first one's arrays updated with
    `replace` (a value None drops the key)."""
    src = sorted((STUBS / ("grasps" if kind == "grasp" else "approach")).glob(f"{kind}_*.npz"))[first:first + 2]
    for p in src[1:]:
        shutil.copy(p, tmp_path / p.name)
    npz_copy(src[0], tmp_path / src[0].name, **replace)
    return tmp_path


def _nan_at(kind: str, key: str) -> np.ndarray:
    """The first shipped `kind` file's array `key` with one NaN in it."""
    p = sorted((STUBS / ("grasps" if kind == "grasp" else "approach")).glob(f"{kind}_*.npz"))[0]
    with np.load(p, allow_pickle=False) as z:
        a = z[key].astype(np.float32).copy()
    a.reshape(-1)[a.size // 2] = np.nan
    return a


# ------------------------------------------------------------------------------------------------ datasets
@pytest.mark.parametrize("dataset, kind, key", [(WholeGraspDataset, "grasp", "saga.markers"),
                                                (WholeGraspDataset, "grasp", "contact.object"),
                                                (GNetDataset, "grasp", "goal.bps_object"),
                                                (ApproachDataset, "approach", "body.params.fullpose")])
def test_a_nan_in_the_data_is_refused_naming_file_and_key(tmp_path, dataset, kind, key):
    root = _copy_with(tmp_path, kind, **{key: _nan_at(kind, key)})
    with pytest.raises(ValueError, match=rf"{kind}_000000\.npz: key '{key}' holds 1 NaN or infinite values"):
        dataset(root, split=None)
    _copy_with(tmp_path, kind)                                              # the same files without the NaN load
    assert len(dataset(root, split=None)) == 2


@pytest.mark.parametrize("dataset, kind, key", [(WholeGraspDataset, "grasp", "saga.markers"),
                                                (GNetDataset, "grasp", "goal.vertex_ids"),
                                                (ApproachDataset, "approach", "grasp.goal_frame")])
def test_a_missing_key_is_named_with_its_file(tmp_path, dataset, kind, key):
    root = _copy_with(tmp_path, kind, **{key: None})
    with pytest.raises(ValueError, match=rf"{kind}_000000\.npz: missing key '{key}'"):
        dataset(root, split=None)


@pytest.mark.parametrize("dataset, kind, key, value, shown", [
    (WholeGraspDataset, "grasp", "saga.markers", np.zeros((100, 3), np.float32), r"\(143, 3\)"),
    (WholeGraspDataset, "grasp", "contact.markers", np.zeros((1, 5), np.uint8), r"\(1, 143\)"),
    (GNetDataset, "grasp", "goal.vertices", np.zeros((10, 3), np.float32), r"\(400, 3\)"),
    (ApproachDataset, "approach", "contact.feet", np.zeros((10, 4), np.uint8), r"\(\d+, 4\)"),
    (ApproachDataset, "approach", "goal.bps_object", np.zeros(100, np.float32), r"\(1024,\)")])
def test_a_key_of_another_shape_is_named_with_its_file(tmp_path, dataset, kind, key, value, shown):
    """A key of the wrong shape is refused when the files are read, naming file, key and the shape expected (it used
    to fail in numpy's stacking without either, or to load and break the batching later)."""
    root = _copy_with(tmp_path, kind, **{key: value})
    with pytest.raises(ValueError, match=rf"{kind}_000000\.npz: key '{key}' has shape .*, expected {shown}"):
        dataset(root, split=None)


def test_an_unknown_object_and_a_goal_frame_outside_the_clip_are_named(tmp_path):
    (tmp_path / "a").mkdir()
    root = _copy_with(tmp_path / "a", "grasp", obj_name=np.array("spaceship"))
    with pytest.raises(ValueError, match=r"grasp_000000\.npz: key 'obj_name' is 'spaceship', not an object"):
        WholeGraspDataset(root, split=None)
    (tmp_path / "b").mkdir()
    root = _copy_with(tmp_path / "b", "approach", **{"grasp.goal_frame": np.array(-3)})
    with pytest.raises(ValueError, match=r"approach_000000\.npz: key 'grasp.goal_frame' is -3, expected a whole frame number in \[0, 80\)"):
        ApproachDataset(root, split=None)


def test_training_on_nan_data_exits_2_and_writes_no_weights(tmp_path, capsys):
    from graspkit.cli import main

    root = _copy_with(tmp_path, "grasp", 8, **{"saga.markers": _nan_at("grasp", "saga.markers")})   # pitcher: train
    out = tmp_path / "out" / "wholegrasp.pt"
    code = main(["train", "wholegrasp", "--data", str(root), "--epochs", "1", "--out", str(out)])
    assert code == 2 and not out.exists()
    assert "grasp_000008.npz: key 'saga.markers' holds 1 NaN" in capsys.readouterr().err


# ------------------------------------------------------------------------------------------------ checkpoints
def test_a_checkpoint_with_nan_weights_is_refused(tmp_path):
    state = torch.load(CK / "gnet.pt", weights_only=True)
    name = next(k for k, v in state["model"].items() if v.is_floating_point())
    state["model"][name] = state["model"][name].clone()
    state["model"][name].view(-1)[0] = float("inf")
    torch.save(state, tmp_path / "diverged.pt")
    with pytest.raises(ValueError, match=rf"diverged\.pt: 1 weight tensors hold NaN or infinite values \({name}"):
        load_checkpoint(tmp_path / "diverged.pt")


def test_each_loader_names_the_file_of_weights_of_another_size(tmp_path):
    from graspkit.models.gnet import load_gnet
    from graspkit.models.mnet import load_mnet
    from graspkit.models.wandr import load_wandr
    from graspkit.optim.graspmotion import load_smooth_ae

    for name, load in (("gnet", load_gnet), ("mnet", load_mnet), ("wandr", load_wandr),
                       ("motionfill_smooth_ae", load_smooth_ae)):
        state = torch.load(CK / f"{name}.pt", weights_only=True)
        key = next(k for k, v in state["model"].items() if v.ndim >= 1 and v.is_floating_point())
        state["model"][key] = state["model"][key][:-1].clone()               # one row short
        torch.save(state, tmp_path / f"short_{name}.pt")
        with pytest.raises(ValueError, match=rf"short_{name}\.pt: not .*(size|shape)"):
            load(tmp_path / f"short_{name}.pt")
        load(CK / f"{name}.pt")                                               # the shipped file still loads
    with pytest.raises(ValueError, match=r"mnet\.pt: not a marker-difference autoencoder \(no 'sizes'"):
        load_smooth_ae(CK / "mnet.pt")


# ------------------------------------------------------------------------------------------------ command lines
@pytest.mark.parametrize("module, argv, message", [
    ("eval_saga", ["--finish", "{tmp}/none.partial.json"], "partial: no file"),
    ("eval_saga", ["--finish", str(STUBS.parent / "README.md")], "README.md is not JSON"),
    ("eval_saga", ["--data", "{tmp}/nosuchdir"], "--data: {tmp}/nosuchdir: no such folder"),
    ("eval_saga", ["--data", "{tmp}", "--placements", "0"], "--placements: expected an integer >= 1, got 0"),
    ("eval_saga", ["--data", "{tmp}", "--objects", "mugg"], "--objects: 'mugg' is not one of the held-out test objects"),
    ("eval_goal", ["--n-grasps", "-1"], "--n-grasps: expected an integer >= 0, got -1"),
    ("eval_goal", ["--tab1-only", "--out", "{tmp}/none.json"], "--out: no evaluation at"),
    ("eval_motionfill", ["tab3", "--clips", "-3"], "--clips: expected an integer >= 1, got -3"),
    ("eval_motionfill", ["tab3", "--data", "{tmp}/nosuchdir"], "data: no folder"),
])
def test_module_commands_report_bad_input_without_a_traceback(tmp_path, capsys, module, argv, message):
    import importlib

    main = importlib.import_module(f"graspkit.{module}").main
    assert main([a.format(tmp=tmp_path) for a in argv]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"python -m graspkit.{module}: error: ") and "Traceback" not in err
    assert message.format(tmp=tmp_path) in err


@pytest.mark.parametrize("argv, message", [
    (["train", "motionfill", "--stage", "local", "--clips", "-2"], "--clips: expected an integer >= 1, got -2"),
    (["train", "motionfill_baseline", "--model", "cnn_ae", "--clips", "0"], "--clips: expected an integer >= 1"),
    (["demo", "--stages", ",", "--out", "{tmp}/demo"], "--stages: expected one or more stage names"),
    (["demo", "--out", "{tmp}/demo", "--model", "{tmp}/none.npz"], "--model: "),
    (["saga", "--object", "mug", "--out", "{tmp}/demo", "--model", "{tmp}/none.npz"], "--model: "),
    (["goal", "--object", "mug", "--out", "{tmp}/demo", "--model", "{tmp}/none.npz"], "--model: "),
    (["data", "make", "--kind", "grasp", "--n", "1", "--objects", "", "--out", "{tmp}/demo"], "--objects: expected"),
    (["data", "make", "--kind", "grasp", "--n", "1", "--objects", "teapot", "--out", "{tmp}/demo"], "got 'teapot'"),
    (["eval", "wandr", "--checkpoint", str(CK / "wandr.pt"), "--clips", "{tmp}/nosuchdir"], "--clips: {tmp}/nosuchdir: no such"),
    (["train", "wholegrasp", "--data", "{tmp}/nosuchdir", "--out", "{tmp}/demo/w.pt"], "nosuchdir: no such folder"),
    (["train", "gnet", "--data", str(STUBS / "grasps"), "--data", str(CK / "gnet.pt")], "gnet.pt: is a file"),
    (["eval", "wandr", "--checkpoint", "{tmp}"], "--checkpoint: {tmp} is a folder, expected a checkpoint file"),
    (["wandr", "--goal", "1", "0", "1", "--checkpoint", "{tmp}", "--out", "{tmp}/demo"], "--checkpoint: "),
    # loss weights and schedules below zero once trained (a logged loss of -131366 with --foot-weight -5)
    (["train", "gnet", "--kl", "-1", "--out", "{tmp}/demo/g.pt"], "argument --kl: expected a finite number >= 0"),
    (["train", "wandr", "--foot-weight", "-5", "--out", "{tmp}/demo/w.pt"], "argument --foot-weight: expected"),
    (["train", "wandr", "--alpha-kl", "nan", "--out", "{tmp}/demo/w.pt"], "argument --alpha-kl: expected"),
    (["train", "wandr", "--ramp-epochs", "-1", "--out", "{tmp}/demo/w.pt"], "argument --ramp-epochs: expected an "
                                                                           "integer >= 0"),
    (["train", "mnet", "--goal-repeat", "0", "--out", "{tmp}/demo/m.pt"], "argument --goal-repeat: expected an "
                                                                         "integer >= 1"),
    (["train", "mnet", "--vel-noise", "-1", "--out", "{tmp}/demo/m.pt"], "argument --vel-noise: expected"),
    (["train", "wholegrasp", "--time-limit", "-1", "--out", "{tmp}/demo/w.pt"], "argument --time-limit: expected a "
                                                                               "finite number > 0, got -1"),
    (["train", "motionfill", "--stage", "smooth_ae", "--lr", "0.1", "--out", "{tmp}/demo/s.pt"],
     "--lr: --stage smooth_ae trains"),
    # options smooth_ae does not use were ignored: --clips 3 trained on the default 160 clips without a word
    (["train", "motionfill", "--stage", "smooth_ae", "--clips", "3", "--init", str(CK / "motionfill.pt"), "--out",
      "{tmp}/demo/s.pt"], "--init, --clips: --stage smooth_ae trains"),
    # an existing folder as --out passed the check, trained, then failed on renaming a temporary file onto it
    (["train", "motionfill", "--stage", "local", "--out", "{tmp}"], "--out: "),
    (["train", "wandr", "--lr", "-1", "--out", "{tmp}/demo/w.pt"], "argument --lr: expected a finite number > 0"),
    (["train", "motionfill_baseline", "--model", "cnn_ae", "--lr", "0", "--out", "{tmp}/demo/b.pt"],
     "argument --lr: expected a finite number > 0"),
])
def test_graspkit_counts_and_folders_are_checked_before_work(tmp_path, capsys, argv, message):
    from graspkit.cli import main

    try:
        code = main([a.format(tmp=tmp_path) for a in argv])
    except SystemExit as e:                 # argparse's own "argument --flag: ..." exits from parse_args
        code = e.code
    assert code == 2
    assert message.format(tmp=tmp_path) in capsys.readouterr().err
    assert not (tmp_path / "demo").exists()


def test_argument_checks_at_their_documented_bounds():
    """check_int refuses bools, check_positive takes `most` itself ((0, most]), seeded_rng refuses None (an OS seed is
    not repeatable), check_type refuses None unless optional, check_steps refuses bools; the argparse types take
    their bound itself when not strict (>= 0, >= 1)."""
    import argparse

    from graspkit.checks import (check_int, check_positive, check_steps, check_type, count_type, nonneg_float,
                                 seeded_rng)

    with pytest.raises(ValueError, match="n: expected an integer >= 0"):
        check_int(True, "n")
    assert check_positive(2.0, "d", most=2.0) == 2.0
    with pytest.raises(ValueError, match="seed"):
        seeded_rng(None)
    assert seeded_rng(5).random() == np.random.default_rng(5).random()
    with pytest.raises(TypeError, match="g: expected a torch.Generator, got NoneType"):
        check_type(None, torch.Generator, "g", what="torch.Generator")
    check_type(None, torch.Generator, "g", optional=True)
    with pytest.raises(ValueError, match="steps"):
        check_steps((True, 1, 1), "steps", 3)
    assert count_type(1)("1") == 1 and count_type(0)("0") == 0
    with pytest.raises(argparse.ArgumentTypeError):
        count_type(1)("0")
    assert nonneg_float("0") == 0.0
