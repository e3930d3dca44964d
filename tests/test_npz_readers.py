"""The .npz readers of the datasets (clip sets, MotionFill windows, grasp folders) name the file they cannot read."""
import numpy as np
import pytest

from graspkit.data import motionfill_dataset as mf
from graspkit.data import wandr_dataset as W
from graspkit.data.grasp_datasets import grasp_files


def _bad_files(tmp_path, stem: str) -> list:
    """An empty file, a single array renamed .npz, a truncated archive and an archive holding a pickled object."""
    empty = tmp_path / f"{stem}_empty.npz"
    empty.write_bytes(b"")
    single = tmp_path / f"{stem}_single.npz"
    with open(single, "wb") as f:
        np.save(f, np.zeros(3))
    good = tmp_path / f"{stem}_good.npz"
    np.savez(good, obj_name=np.array("mug"))
    cut = tmp_path / f"{stem}_cut.npz"
    cut.write_bytes(good.read_bytes()[:40])
    pickled = tmp_path / f"{stem}_pickled.npz"
    np.savez(pickled, obj_name=np.array([{"a": 1}], dtype=object))
    good.unlink()
    return [empty, single, cut, pickled]


@pytest.mark.parametrize("reader", [W.load_clipset, mf.load_windows])
def test_a_bad_file_is_named(tmp_path, reader):
    for path in _bad_files(tmp_path, "x"):
        with pytest.raises(ValueError, match=path.name):
            reader(path)
    with pytest.raises((ValueError, FileNotFoundError), match="nope.npz"):
        reader(tmp_path / "nope.npz")


def test_a_bad_file_in_a_grasp_folder_is_named(tmp_path):
    for k, path in enumerate(_bad_files(tmp_path, "grasp")):
        folder = tmp_path / f"set{k}"
        folder.mkdir()
        path.rename(folder / path.name)
        with pytest.raises(ValueError, match=path.name):
            grasp_files(folder)
