"""`graspkit data make --kind grasp`: files, resumability, atomic writes, the same bytes with two workers."""
import subprocess
import sys

import numpy as np
import pytest

from graspkit.data.grab import load_grasp_sequence
from graspkit.data.grasp_make import make_grasp_dataset, task_seed


def test_two_workers_then_resume_in_process_give_the_same_bytes(tmp_path, monkeypatch):
    """The CLI with two workers writes two grasps (two objects, one chunk each); cutting one short and resuming in
    process with one worker rewrites exactly the same bytes and leaves the other file alone."""
    monkeypatch.setenv("GRASPKIT_CACHE", str(tmp_path / "cache"))           # SDF grids come from data_stubs/sdf
    r = subprocess.run([sys.executable, "-m", "graspkit", "data", "make", "--kind", "grasp", "--n", "2", "--seed", "3",
                        "--out", str(tmp_path / "p"), "--workers", "2", "--chunk", "1", "--objects", "apple,banana"],
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    assert "grasp files" in r.stderr                                        # tqdm's progress bar
    files = sorted((tmp_path / "p").glob("grasp_*.npz"))
    assert [p.name for p in files] == ["grasp_000000.npz", "grasp_000001.npz"]
    assert (tmp_path / "p" / "meshes" / "apple.ply").is_file() and (tmp_path / "p" / "meshes" / "banana.ply").is_file()
    assert not [p for p in (tmp_path / "p").rglob("*") if p.name.startswith(".") or p.suffix == ".tmp"]
    first = files[0].read_bytes()
    stamp = files[1].stat().st_mtime_ns
    files[0].write_bytes(first[: len(first) // 3])                           # cut short: made again on resume
    make_grasp_dataset("grasp", 2, 3, tmp_path / "p", workers=1, progress=False, chunk=1, objects=("apple", "banana"))
    assert files[0].read_bytes() == first and files[1].stat().st_mtime_ns == stamp
    s = load_grasp_sequence(files[1])
    assert s.object_name == "banana" and s.num_frames == 1 and s.contacts["object"].shape == (1, 2048)
    assert int(s.extras["grasp.index"]) == 1 and task_seed(3, "grasp", 1) != task_seed(3, "approach", 1)


def test_cli_errors_name_the_argument(tmp_path):
    r = subprocess.run([sys.executable, "-m", "graspkit", "data", "make", "--kind", "grasp", "--n", "1",
                        "--objects", "elephant", "--out", str(tmp_path)], capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and "objects" in r.stderr and "elephant" in r.stderr
    assert not list(tmp_path.glob("*.npz"))
    np.testing.assert_equal(len(list(tmp_path.iterdir())), 0)


def test_a_file_names_the_body_model_it_was_made_with(tmp_path, monkeypatch):
    """`body.model` is graspkit's name for the shipped body and the model file itself for --model (it always said the
    shipped body's name, so a file made with another model named a body 5 cm off)."""
    from graspkit.data.grab import DEFAULT_MODEL_NAME
    from graspkit.paths import default_model_path

    monkeypatch.setenv("GRASPKIT_CACHE", str(tmp_path / "cache"))
    other = tmp_path / "other" / "SMPLX_NEUTRAL.npz"
    other.parent.mkdir()
    arrays = dict(np.load(default_model_path(), allow_pickle=False))
    np.savez(other, **dict(arrays, v_template=arrays["v_template"] * 1.02))
    for model, want in ((None, DEFAULT_MODEL_NAME), (str(other), str(other))):
        out = tmp_path / ("own" if model else "shipped")
        make_grasp_dataset("grasp", 1, 3, out, workers=1, progress=False, chunk=1, objects=("apple",), model=model)
        assert str(np.load(out / "grasp_000000.npz", allow_pickle=False)["body.model"]) == want


def test_approach_contacts_are_labelled_on_every_frame_the_body_touches(tmp_path):
    """Per-frame body contacts of an approach clip against trimesh's distances on the smplx body: every frame before
    the goal frame with a body vertex within 1 cm of the object is labelled, with the same vertices (this clip's hand
    passes through the bottle 29-37 frames before the goal frame, which only the 20 frames before it used to be);
    the goal frame itself holds the goal grasp's labels."""
    import smplx
    import torch
    import trimesh

    from graspkit.body import BodyModel
    from graspkit.data.grasp import GraspFitter
    from graspkit.data.grasp_make import write_chunk
    from graspkit.paths import default_model_path

    [path, _] = write_chunk(GraspFitter(BodyModel.from_file(default_model_path())), "approach", 3, 3, tmp_path,
                            n=8, size=2)
    z = np.load(path, allow_pickle=False)
    g, P = int(z["grasp.goal_frame"]), z["body.params.fullpose"].reshape(-1, 55, 3)
    ref = smplx.create(str(default_model_path().parent.parent), model_type="smplx", gender="neutral", ext="npz",
                       use_pca=False, flat_hand_mean=True, batch_size=g + 1)
    t = lambda x: torch.as_tensor(np.asarray(x[:g + 1]), dtype=torch.float32)  # noqa: E731
    with torch.no_grad():
        V = ref(betas=t(np.repeat(z["body.betas"][None], g + 1, 0)), global_orient=t(P[:, 0]), body_pose=t(P[:, 1:22]),
                jaw_pose=t(P[:, 22]), leye_pose=t(P[:, 23]), reye_pose=t(P[:, 24]), left_hand_pose=t(P[:, 25:40]),
                right_hand_pose=t(P[:, 40:55]), transl=t(z["body.params.transl"])).vertices.numpy()
    mesh = trimesh.load(tmp_path / str(z["object.object_mesh"]), process=False)
    R = trimesh.transformations.rotation_matrix(np.linalg.norm(z["object.params.global_orient"][0]),
                                                z["object.params.global_orient"][0])
    mesh.apply_transform(R)
    mesh.apply_translation(z["object.params.transl"][0])
    touching, agree, early = 0, [], 0
    for f in range(g + 1):
        near = np.flatnonzero(((V[f] > mesh.bounds[0] - 0.011) & (V[f] < mesh.bounds[1] + 0.011)).all(1))
        within = np.zeros(len(V[f]), bool)
        if len(near):
            within[near] = trimesh.proximity.closest_point(mesh, V[f][near])[1] <= 0.01
        if within.any():
            touching += 1
            early += f < g - 20
            assert z["contact.body"][f].any(), f"frame {f} of {g}: the body touches the object, labelled 0"
            agree.append(np.mean(within == z["contact.body"][f].astype(bool)))
    assert early >= 5 and touching >= early and min(agree) > 0.999
    assert z["contact.body"][g].any() and z["contact.object"][g].any() and z["contact.markers"][g].any()


def test_the_library_call_names_a_bad_seed_or_count_before_touching_the_folder(tmp_path):
    """make_grasp_dataset(seed=-1) failed in numpy without naming the seed and left the folder claimed for seed -1,
    so the corrected call was refused (an independent check); now nothing is created."""
    for kwargs, message in (({"seed": -1}, "^seed: expected a non-negative integer"),
                            ({"seed": 1.5}, "^seed:"), ({"seed": True}, "^seed:"),
                            ({"chunk": 2.5}, "^chunk: expected an integer >= 1"), ({"n": True}, "^n:")):
        args = {"kind": "grasp", "n": 1, "seed": 0, "out": tmp_path / "p", "workers": 1, "progress": False,
                "chunk": 1, "objects": ("mug",), **kwargs}
        with pytest.raises(ValueError, match=message):
            make_grasp_dataset(**args)
        assert not (tmp_path / "p").exists()


def test_sample_grasp_task_names_a_bad_argument():
    """A start pose of 'sitting', a grasp type the object does not afford, a reversed or negative start distance and
    an int for rng were taken (or failed with an AttributeError) before (an independent check)."""
    from graspkit.data.grasp import sample_grasp_task

    rng = np.random.default_rng(0)
    for kwargs, message in (({"start_pose": "sitting"}, "^start_pose:"), ({"grasp_type": "fist"}, "^grasp_type: mug affords"),
                            ({"start_distance": (1.5, 0.05)}, "^start_distance:"),
                            ({"start_distance": (-1, -0.5)}, "^start_distance:")):
        with pytest.raises(ValueError, match=message):
            sample_grasp_task(rng, "mug", **kwargs)
    with pytest.raises(ValueError, match="^rng: expected a numpy Generator"):
        sample_grasp_task(5, "mug")
