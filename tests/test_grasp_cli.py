"""`graspkit data make --kind grasp`: files, resumability, atomic writes, the same bytes with two workers."""
import os
import subprocess
import sys

import numpy as np

from graspkit.data.grab import load_grasp_sequence
from graspkit.data.grasp_make import make_grasp_dataset, task_seed


def test_make_resume_and_two_workers_write_the_same_bytes(tmp_path, monkeypatch):
    monkeypatch.setenv("GRASPKIT_CACHE", str(tmp_path / "cache"))           # SDF grids come from data_stubs/sdf
    kw = dict(workers=1, progress=False, chunk=1, objects=("apple", "banana"))
    a = make_grasp_dataset("grasp", 2, 3, tmp_path / "a", **kw)
    assert [p.name for p in a] == ["grasp_000000.npz", "grasp_000001.npz"]
    assert (tmp_path / "a" / "meshes" / "apple.ply").is_file() and (tmp_path / "a" / "meshes" / "banana.ply").is_file()
    stamp = [p.stat().st_mtime_ns for p in a]
    make_grasp_dataset("grasp", 2, 3, tmp_path / "a", **kw)                 # resumes: nothing to do
    assert [p.stat().st_mtime_ns for p in a] == stamp
    assert not [p for p in (tmp_path / "a").rglob("*") if p.name.startswith(".") or p.suffix == ".tmp"]
    s = load_grasp_sequence(a[1])
    assert s.object_name == "banana" and s.num_frames == 1 and s.contacts["object"].shape == (1, 2048)
    assert int(s.extras["grasp.index"]) == 1 and task_seed(3, "grasp", 1) != task_seed(3, "approach", 1)
    env = {**os.environ, "GRASPKIT_CACHE": str(tmp_path / "cache")}
    r = subprocess.run([sys.executable, "-m", "graspkit", "data", "make", "--kind", "grasp", "--n", "2", "--seed", "3",
                        "--out", str(tmp_path / "p"), "--workers", "2", "--chunk", "1", "--objects", "apple,banana"],
                       capture_output=True, text=True, timeout=600, env=env)
    assert r.returncode == 0, r.stderr
    assert "grasp files" in r.stderr                                        # tqdm's progress bar
    for p in a:
        assert p.read_bytes() == (tmp_path / "p" / p.name).read_bytes()


def test_cli_errors_name_the_argument(tmp_path):
    r = subprocess.run([sys.executable, "-m", "graspkit", "data", "make", "--kind", "grasp", "--n", "1",
                        "--objects", "elephant", "--out", str(tmp_path)], capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and "objects" in r.stderr and "elephant" in r.stderr
    assert not list(tmp_path.glob("*.npz"))
    np.testing.assert_equal(len(list(tmp_path.iterdir())), 0)
