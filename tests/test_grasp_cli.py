"""`graspkit data make --kind grasp`: files, resumability, atomic writes, the same bytes with two workers."""
import subprocess
import sys

import numpy as np

from graspkit.data.grab import load_grasp_sequence
from graspkit.data.grasp_make import make_grasp_dataset, task_seed


def test_two_workers_then_resume_in_process_give_the_same_bytes(tmp_path, monkeypatch):
    """The CLI with two workers writes two grasps (two objects, one chunk each); deleting one and resuming in
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
    files[0].unlink()
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
