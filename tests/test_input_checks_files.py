"""Damaged or foreign files through graspkit's readers: each is refused naming the file (and the key), before any
work, and nothing graspkit writes holds NaN (strict JSON)."""
import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch

from conftest import npz_copy
from graspkit.paths import DATA_STUBS

REACH = DATA_STUBS / "motion" / "reach" / "reach_000000.npz"
APPROACH = DATA_STUBS / "approach" / "approach_000000.npz"
CKPT = DATA_STUBS / "checkpoints"


@pytest.mark.parametrize("rate", [1 / 30, 0.001, 1e-300, 50_000.0])
def test_a_capture_rate_no_camera_has_is_refused_before_resampling(tmp_path, rate):
    """A frame period stored as the rate (1/30) would resample a 3 s clip to 48 minutes, 0.001 fills the memory:
    the rate must lie in SOURCE_FPS_RANGE, the file and key named."""
    from graspkit.data.formats import load_motion
    from graspkit.data.grab import load_grasp_sequence

    with pytest.raises(ValueError, match=r"reach_000000\.npz: key 'mocap_frame_rate' is .*between 1 and 10000"):
        load_motion(npz_copy(REACH, tmp_path / "reach_000000.npz", mocap_frame_rate=np.array(rate)))
    with pytest.raises(ValueError, match=r"approach_000000\.npz: key 'framerate' is .*between 1 and 10000"):
        load_grasp_sequence(npz_copy(APPROACH, tmp_path / "approach_000000.npz", framerate=np.array(rate)))


@pytest.mark.parametrize("key, value, said", [
    ("body.params.transl", np.array([["a", "b", "c"]] * 80), "holds <U1 values, expected numbers"),
    ("body.params.fullpose", np.zeros((80, 165), np.complex64), "holds complex64 values, expected numbers"),
    ("body.betas", np.array(["x"] * 10), "holds <U1 values, expected numbers"),
    ("body.flat_hand_mean", np.array([True, False]), "holds 2 bool value"),
    ("contact.feet", np.array(3), r"holds \(\) int64, expected a number per frame"),
    ("grasp.goal_frame", np.array(np.nan), "is nan, expected a whole frame number in"),
    ("grasp.goal_frame", np.array(-5), r"is -5, expected a whole frame number in \[0, 80\)"),
    ("grasp.goal_frame", np.array(80), r"is 80, expected a whole frame number in \[0, 80\)"),
])
def test_a_grasp_sequence_key_of_the_wrong_kind_is_named(tmp_path, key, value, said):
    """load_grasp_sequence refuses keys that hold no numbers, a flag of two values, a contact key without frames and
    a goal frame outside the clip (which GOAL's evaluation would read as another frame: -5 is frame 75)."""
    from graspkit.data.grab import load_grasp_sequence

    path = npz_copy(APPROACH, tmp_path / "approach_000000.npz", **{key: value})
    with pytest.raises(ValueError, match=rf"approach_000000\.npz: key '{key}' {said}"):
        load_grasp_sequence(path)


@pytest.mark.parametrize("key", ["gender", "hand"])
def test_a_motion_string_key_that_is_empty_or_a_number_is_named(tmp_path, key):
    from graspkit.data.formats import load_motion

    for value in (np.array([], dtype=np.str_), np.array(3.0)):
        with pytest.raises(ValueError, match=rf"reach_000000\.npz: key '{key}' holds .*expected one string"):
            load_motion(npz_copy(REACH, tmp_path / "reach_000000.npz", **{key: value}))


def test_a_text_file_named_npz_is_not_called_a_pickle(tmp_path):
    """numpy calls every file that is no zip a pickle and suggests unpickling it: graspkit says what it is."""
    from graspkit.data.formats import load_motion, open_npz

    text = tmp_path / "notes.npz"
    text.write_text("a,b\n1,2\n")
    for read in (load_motion, open_npz):
        with pytest.raises(ValueError, match=r"notes\.npz: .*not an \.npz archive \(it starts with b'a,b\\n'\)") as e:
            read(text)
        assert "pickle" not in str(e.value)
    pickled = tmp_path / "pickled.npz"
    pickled.write_bytes(b"\x80\x04K\x01.")
    with pytest.raises(ValueError, match=r"pickled\.npz: .*a pickle, which graspkit does not read"):
        load_motion(pickled)


def _grasp_folder(tmp_path: Path, first_replaced: dict | None = None) -> Path:
    """A copy of the shipped grasp folder, its first mug (test split) file's arrays replaced."""
    folder = tmp_path / "grasps"
    shutil.copytree(DATA_STUBS / "grasps", folder)
    if first_replaced:
        mug = next(p for p in sorted(folder.glob("grasp_*.npz")) if str(np.load(p)["obj_name"]) == "mug")
        npz_copy(mug, mug, **first_replaced)
    return folder


@pytest.mark.parametrize("replace, said", [
    ({"saga.markers": np.full((143, 3), np.nan, np.float32)}, "key 'saga.markers' holds 429 NaN"),
    ({"saga.markers": np.zeros((100, 3), np.float32)}, "key 'saga.markers' has shape"),
    ({"contact.markers": np.full((1, 143), 7, np.uint8)}, "key 'contact.markers' holds values other than 0 and 1"),
    ({"object.points": None}, "missing key 'object.points'"),
    ({"object.height": np.array("x")}, "key 'object.height' holds <U1 values, expected numbers"),
])
def test_the_saga_evaluation_reads_its_grasps_checked(tmp_path, replace, said):
    """load_placements (the SAGA evaluation's ground truth) refuses what the training sets refuse, naming the file."""
    from graspkit.eval_saga import load_placements

    folder = _grasp_folder(tmp_path, replace)
    with pytest.raises(ValueError, match=rf"grasp_\d+\.npz: {said}"):
        load_placements(folder, "mug", 5, split="test")


def test_save_examples_names_a_damaged_file_rather_than_finding_no_grasps(tmp_path):
    """A damaged file of another split was reported as 'no test grasps in <folder>'."""
    from graspkit.eval_saga import save_examples

    folder = _grasp_folder(tmp_path)
    pitcher = next(p for p in sorted(folder.glob("grasp_*.npz")) if str(np.load(p)["obj_name"]) == "pitcher")
    pitcher.write_bytes(pitcher.read_bytes()[:100])
    with pytest.raises(ValueError, match=rf"{pitcher.name}: not a readable \.npz file"):
        save_examples(folder, tmp_path / "ex.pt", per_object=1, split="test")
    assert not (tmp_path / "ex.pt").exists()


@pytest.mark.parametrize("goal_frame", [-5, 80, 10**6])
def test_an_approach_clip_with_its_goal_frame_outside_it_is_named(tmp_path, goal_frame):
    """approach_motions cut the MotionFill window at an unchecked goal frame ([:g + 1]: -5 kept 76 frames)."""
    from graspkit.eval_motionfill import approach_motions, held_out_clips

    folder = tmp_path / "approach"
    folder.mkdir()
    npz_copy(APPROACH, folder / APPROACH.name, **{"grasp.goal_frame": np.array(goal_frame)})
    with pytest.raises(ValueError, match=rf"approach_000000\.npz: key 'grasp.goal_frame' is {goal_frame}, expected"):
        approach_motions(folder)
    npz_copy(APPROACH, folder / APPROACH.name, **{"object.points": None, "object.normals": None})
    assert len(approach_motions(folder)[0]) == 1                # only what it reads is required
    (folder / APPROACH.name).write_bytes(APPROACH.read_bytes()[:1000])
    for read in (approach_motions, held_out_clips):
        with pytest.raises(ValueError, match=r"approach_000000\.npz: not a readable \.npz file"):
            read(folder)


@pytest.mark.parametrize("reader, name", [("load_grabnet_smplx", "gnet.pt"), ("load_examples", "mnet.pt"),
                                          ("load_baselines", "gnet.pt")])
def test_another_models_checkpoint_is_named_by_every_reader(tmp_path, reader, name):
    """The SAGA evaluation's baselines, the lesson examples and MotionFill's baselines name a foreign checkpoint."""
    from graspkit import eval_motionfill, eval_saga
    from graspkit.models import wholegrasp

    if reader == "load_baselines":
        path = tmp_path / "motionfill_posenet.pt"
        shutil.copy(CKPT / name, path)
        call = lambda: eval_motionfill.load_baselines(tmp_path)  # noqa: E731
    else:
        path = tmp_path / "x.pt"
        shutil.copy(CKPT / name, path)
        fn = getattr(wholegrasp, reader, None) or getattr(eval_saga, reader)
        call = lambda: fn(path)  # noqa: E731
    with pytest.raises(ValueError, match=rf"{path.name}:? .*not a"):
        call()


@pytest.mark.parametrize("loader, ck, key, value", [("load_wandr", "wandr.pt", "latent", "32"),
                                                     ("load_gnet", "gnet.pt", "latent", 16.5)])
def test_a_config_value_of_the_wrong_type_in_a_checkpoint_is_named(tmp_path, loader, ck, key, value):
    """A config value torch cannot build from failed inside torch.nn.Linear with no file named."""
    from graspkit.models import gnet, wandr

    state = torch.load(CKPT / ck, weights_only=True)
    cfg = state.get("wandr_config") if ck == "wandr.pt" else state["config"]
    cfg[key] = value
    path = tmp_path / ck
    torch.save(state, path)
    with pytest.raises(ValueError, match=rf"checkpoint {path}: not a"):
        getattr(wandr if ck == "wandr.pt" else gnet, loader)(path)


def test_saga_results_that_are_not_json_or_not_an_evaluation_are_named(tmp_path):
    from graspkit.eval_saga import load_results

    for text, said in (("", "is not JSON"), ('{"rows": {', "is not JSON"), ("[1, 2]", "is not a SAGA evaluation"),
                       ('{"rows": {}}', "is not a SAGA evaluation")):
        path = tmp_path / "r.json"
        path.write_text(text)
        with pytest.raises(ValueError, match=rf"path: {path} {said}"):
            load_results(path)
    assert load_results(CKPT / "wholegrasp_eval.json")["rows"]


def test_a_json_to_update_that_is_no_object_is_refused(tmp_path):
    from graspkit.eval_motionfill import main, update_json

    path = tmp_path / "mf.json"
    path.write_text("[]")
    with pytest.raises(ValueError, match=rf"path: {path} holds a JSON list, expected an object"):
        update_json(path, rows={})
    assert path.read_text() == "[]"
    # refused before the run (which took 47 s before failing), as the command's other checks are
    assert main(["graspmotion", "--data", str(DATA_STUBS / "approach"), "--out", str(path)]) == 2


def test_finishing_a_partial_of_another_layout_is_refused_and_no_json_holds_nan(tmp_path):
    """finish_partial wrote `"seconds": NaN` (no strict JSON reader takes it) and crashed in table1 after."""
    from graspkit.eval_saga import finish_partial
    from graspkit.paths import write_json

    part = tmp_path / "x.partial.json"
    part.write_text(json.dumps({"config": {}, "per_object": {"mug": {"WholeGrasp w/ opt. (Ours)": {"n": 4,
                                                                                                    "contact": 0.5}}}}))
    with pytest.raises(ValueError, match=r"the row of 'WholeGrasp w/ opt\. \(Ours\)' on 'mug' is not one"):
        finish_partial(part, tmp_path / "out.json")
    assert not (tmp_path / "out.json").exists()
    row = {"n": 4, "contact_ratio": 0.5, "volume_cm3": 1.0, "depth_cm": 0.1}
    part.write_text(json.dumps({"config": {}, "per_object": {"mug": {"WholeGrasp w/ opt. (Ours)": row}}}))
    finish_partial(part, tmp_path / "out.json")
    doc = json.loads((tmp_path / "out.json").read_text(), parse_constant=lambda c: pytest.fail(f"{c} in the JSON"))
    assert doc["seconds"] is None and doc["rows"]["WholeGrasp w/ opt. (Ours)"]["contact_ratio"] == 0.5
    write_json(tmp_path / "nan.json", {"a": [float("nan"), 1.0], "b": float("inf")})
    assert json.loads((tmp_path / "nan.json").read_text()) == {"a": [None, 1.0], "b": None}


def test_fit_refuses_a_folder_as_its_checkpoint_before_training(tmp_path):
    from graspkit.train import TrainConfig, fit

    (tmp_path / "run.pt").mkdir()
    calls = []

    def step(model, batch, epoch):
        calls.append(epoch)
        return {"loss": model(batch).pow(2).mean()}

    with pytest.raises(ValueError, match=r"checkpoint: .*run\.pt is a folder"):
        fit(torch.nn.Linear(3, 1), step, torch.zeros(8, 3), TrainConfig(epochs=1, batch_size=4),
            checkpoint=tmp_path / "run.pt", progress=False)
    assert calls == []


def test_a_bad_model_file_from_graspkit_model_is_named_as_such(tmp_path, monkeypatch, capsys):
    """The error said '--model: ...' for a path that came from the GRASPKIT_MODEL variable."""
    from graspkit.cli import main

    bad = tmp_path / "half.npz"
    bad.write_bytes(b"PK\x03\x04 cut")
    monkeypatch.setenv("GRASPKIT_MODEL", str(bad))
    assert main(["goal", "--object", "mug", "--out", str(tmp_path / "out")]) == 2
    assert f"graspkit: error: GRASPKIT_MODEL: {bad}: not a readable .npz file" in capsys.readouterr().err
    assert main(["goal", "--object", "mug", "--model", str(bad), "--out", str(tmp_path / "out")]) == 2
    assert f"graspkit: error: --model: {bad}: not a readable .npz file" in capsys.readouterr().err


def test_a_clip_set_or_window_file_that_does_not_add_up_is_refused(tmp_path):
    """The caches' readers checked keys only: NaN poses, offsets past the frames, a name twice loaded silently."""
    from graspkit.data import motionfill_dataset as mf
    from graspkit.data import wandr_dataset as W

    n = 3
    clips = W.ClipSet(p=torch.zeros(10, 135), offsets=torch.tensor([0, 4, 10]), rest=torch.zeros(2, 22, 3),
                      betas=torch.zeros(2, 10), goal=torch.zeros(2, 3), goal_frame=torch.tensor([-1, 5]),
                      kind=torch.tensor([0, 1]), names=["a", "b"])
    good = W.save_clipset(tmp_path / "c.npz", clips)
    assert len(W.load_clipset(good)) == 2
    with np.load(good) as z:
        arrays = {k: z[k] for k in z.files}
    for k, v, said in (("p", np.full((10, 135), np.nan, np.float32), "key 'p'"),
                       ("offsets", np.array([0, 4, 100]), "key 'offsets'"),
                       ("names", np.array(["a"]), "key 'names' is <U1 of shape"),
                       ("goal_frame", np.array([-1, 6]), r"key 'goal_frame' is 6 for clip 1 \(b\), expected -1 \(no "
                        r"goal\) or a frame in \[0, 6\)"),
                       ("kind", np.array([0, 2]), r"key 'kind' is 2 for clip 1 \(b\), expected 0")):
        bad = tmp_path / f"bad_{k}.npz"
        np.savez(bad, **{**arrays, k: v})
        with pytest.raises(ValueError, match=rf"{bad.name}: {said}"):
            W.load_clipset(bad)
    windows = {"traj": np.zeros((n, 62, 4)), "markers": np.zeros((n, 61, 79, 3)), "local": np.zeros((n, 61, 79, 3)),
               "vel": np.zeros((n, 61, 3)), "contacts": np.zeros((n, 61, 4)), "clip": np.arange(n)}
    assert len(mf.load_windows(mf.save_windows(tmp_path / "w.npz", windows))["clip"]) == n
    for k, v in (("markers", np.full((n, 61, 79, 3), np.nan)), ("vel", np.zeros(3))):
        bad = mf.save_windows(tmp_path / f"w_{k}.npz", {**windows, k: v})
        with pytest.raises(ValueError, match=rf"w_{k}\.npz: key '{k}'"):
            mf.load_windows(bad)


def _glb(gltf: dict, blob: bytes) -> bytes:
    """A GLB file's bytes: header, JSON chunk, BIN chunk (each padded to 4 bytes), as glTF 2.0 lays them out."""
    import struct

    js = json.dumps(gltf).encode()
    js += b" " * (-len(js) % 4)
    blob += b"\0" * (-len(blob) % 4)
    body = struct.pack("<II", len(js), 0x4E4F534A) + js + struct.pack("<II", len(blob), 0x004E4942) + blob
    return struct.pack("<III", 0x46546C67, 2, 12 + len(body)) + body


def test_a_glb_written_by_trimesh_or_by_hand_reads_back_with_its_offsets_and_index_types(tmp_path):
    """load_sequence_glb read only its own layout: a valid accessor byteOffset was ignored (vertices 9 m off), a view
    without byteOffset failed, 16-bit indices were read as floats. trimesh's GLB of a box, and a triangle laid out by
    hand (12 bytes before its positions in their view, uint16 indices), are the independent truths."""
    import trimesh

    from graspkit.viz.export import load_sequence_glb

    box = trimesh.creation.box((0.1, 0.12, 0.15))
    path = tmp_path / "box.glb"
    trimesh.Scene({"body": box}).export(path)
    verts, faces, _ = load_sequence_glb(path, y_up=False)
    assert np.abs(verts[0][faces] - box.vertices[box.faces]).max() < 1e-6
    tri = np.array([[0.1, 0.2, 0.3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], np.float32)
    blob = b"\x09" * 12 + tri.tobytes() + np.array([0, 2, 1], np.uint16).tobytes()
    gltf = {"asset": {"version": "2.0"}, "buffers": [{"byteLength": len(blob)}],
            "bufferViews": [{"buffer": 0, "byteLength": 48}, {"buffer": 0, "byteOffset": 48, "byteLength": 6}],
            "accessors": [{"bufferView": 0, "byteOffset": 12, "componentType": 5126, "count": 3, "type": "VEC3"},
                          {"bufferView": 1, "componentType": 5123, "count": 3, "type": "SCALAR"}],
            "meshes": [{"name": "body", "primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}]}
    path.write_bytes(_glb(gltf, blob))
    verts, faces, times = load_sequence_glb(path, y_up=False)
    assert np.array_equal(verts[0], tri) and faces.tolist() == [[0, 2, 1]] and times.tolist() == [0.0]
    gltf["accessors"][0]["count"] = 4                       # past its view
    path.write_bytes(_glb(gltf, blob))
    with pytest.raises(ValueError, match=rf"path: {path} is not a sequence GLB .*accessor 0 reaches past its buffer"):
        load_sequence_glb(path)
    del gltf["meshes"]
    path.write_bytes(_glb(gltf, blob))
    with pytest.raises(ValueError, match=rf"name: no mesh 'body' in {path}"):
        load_sequence_glb(path)
    gltf["meshes"] = [{"name": "body", "primitives": [{"attributes": {}}]}]
    path.write_bytes(_glb(gltf, blob))
    with pytest.raises(ValueError, match=rf"path: {path} is not a sequence GLB .*missing 'POSITION'"):
        load_sequence_glb(path)
