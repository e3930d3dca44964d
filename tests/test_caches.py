"""graspkit's caches (SDF grids, WANDR clip sets, MotionFill windows): a cache file damaged after it was written (cut
short, a changed byte) is made again, with a warning, to the same arrays; a damaged shipped grid is left alone."""
import os
import warnings
import zipfile
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


def test_write_atomic_replaces_not_rewrites_and_leaves_no_temporary(tmp_path):
    """write_atomic replaces the file by a rename: a hard link to the old file keeps the old bytes (an in-place write
    would change both), the new file gets the mode a plain open() gives, and a failed write leaves no temporary."""
    from graspkit.paths import write_atomic

    p = tmp_path / "out.txt"
    p.write_text("old")
    os.link(p, tmp_path / "link.txt")
    write_atomic(p, "new")
    assert p.read_text() == "new" and (tmp_path / "link.txt").read_text() == "old"
    plain = tmp_path / "plain.txt"
    plain.write_text("x")
    assert (p.stat().st_mode & 0o777) == (plain.stat().st_mode & 0o777)
    before = sorted(q.name for q in tmp_path.iterdir())
    with pytest.raises(TypeError):
        write_atomic(tmp_path / "bad.txt", 123)
    assert sorted(q.name for q in tmp_path.iterdir()) == before


def test_drop_damaged_removes_only_archives_failing_their_checksums(tmp_path, capsys):
    """drop_damaged: an .npz with a changed data byte (zipfile's CRC check fails) is removed, an intact one kept, a
    missing one skipped (not reported as removed)."""
    from graspkit.paths import drop_damaged

    good, bad, gone = tmp_path / "good.npz", tmp_path / "bad.npz", tmp_path / "gone.npz"
    np.savez(good, a=np.arange(100.0))
    np.savez(bad, a=np.arange(100.0))
    raw = bytearray(bad.read_bytes())
    with zipfile.ZipFile(bad) as z:
        info = z.infolist()[0]
    raw[info.header_offset + 30 + len(info.filename) + len(info.extra) + 200] ^= 0xFF
    bad.write_bytes(bytes(raw))
    assert drop_damaged([good, bad, gone]) == [bad]
    assert good.exists() and not bad.exists()
    assert "1 damaged files" in capsys.readouterr().err


def test_default_model_path_follows_graspkit_model(monkeypatch, tmp_path):
    """$GRASPKIT_MODEL names the model to use (default_model_path's docstring); unset, the shipped humanoid."""
    from graspkit.paths import BODY_MODELS, default_model_path

    monkeypatch.setenv("GRASPKIT_MODEL", str(tmp_path / "m.npz"))
    assert default_model_path() == tmp_path / "m.npz"
    monkeypatch.delenv("GRASPKIT_MODEL")
    assert default_model_path() == BODY_MODELS / "smplx" / "SMPLX_NEUTRAL.npz"
