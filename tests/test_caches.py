"""graspkit's caches (SDF grids, WANDR clip sets, MotionFill windows): a cache file damaged after it was written (cut
short, a changed byte) is made again, with a warning, to the same arrays; a damaged shipped grid is left alone."""
import warnings
from pathlib import Path

import numpy as np
import pytest

from graspkit.paths import DATA_STUBS, read_cache


def damage(path: Path, how: str) -> None:
    """Cut the file to half its length, or flip one byte inside its first entry's data."""
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2] if how == "cut" else data[:120] + bytes([data[120] ^ 0xFF]) + data[121:])


def test_read_cache_gives_none_for_a_missing_or_damaged_file_and_removes_the_damaged_one(tmp_path):
    p = tmp_path / "c.npz"
    assert read_cache(p, np.load) is None
    np.savez(p, a=np.arange(3))
    assert read_cache(p, lambda q: int(np.load(q)["a"].sum())) == 3
    damage(p, "cut")
    with pytest.warns(UserWarning, match="c.npz: a damaged cache file, made again"):
        assert read_cache(p, lambda q: np.load(q)["a"]) is None
    assert not p.exists()


@pytest.mark.parametrize("how", ["cut", "flip"])
def test_a_damaged_sdf_grid_is_built_again(tmp_path, how):
    from graspkit.data.grasp_io import cached_sdf_grid

    first = cached_sdf_grid("apple", 16, folder=tmp_path)
    [path] = tmp_path.glob("apple_r16_*.npz")
    damage(path, how)
    with pytest.warns(UserWarning, match="damaged cache file"):
        again = cached_sdf_grid("apple", 16, folder=tmp_path)
    assert np.array_equal(again.values.numpy(), first.values.numpy())
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        cached_sdf_grid("apple", 16, folder=tmp_path)                 # whole again: read, no warning


def test_a_damaged_clip_set_is_made_again(tmp_path):
    import graspkit.data.wandr_dataset as W
    from graspkit.body import BodyModel
    from graspkit.paths import default_model_path

    bm = BodyModel.from_file(default_model_path())
    first = W.cached_clips(DATA_STUBS / "motion", bm, limit=1, cache=tmp_path)
    [path] = tmp_path.glob("clips_*.npz")
    damage(path, "cut")
    with pytest.warns(UserWarning, match="damaged cache file"):
        again = W.cached_clips(DATA_STUBS / "motion", bm, limit=1, cache=tmp_path)
    assert again.names == first.names and np.array_equal(again.p.numpy(), first.p.numpy())


def test_damaged_motionfill_windows_are_made_again(tmp_path, monkeypatch):
    from graspkit.eval_motionfill import windows

    monkeypatch.setenv("GRASPKIT_CACHE", str(tmp_path))
    first = windows("approach", 2, data=DATA_STUBS / "approach", progress=False)
    [path] = (tmp_path / "motionfill").glob("approach_2_*.npz")
    damage(path, "flip")
    with pytest.warns(UserWarning, match="damaged cache file"):
        again = windows("approach", 2, data=DATA_STUBS / "approach", progress=False)
    assert first.keys() == again.keys() and all(np.array_equal(first[k], again[k]) for k in first)
