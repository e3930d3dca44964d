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


def test_a_cache_that_cannot_be_written_still_gives_the_grid_and_names_itself(tmp_path, monkeypatch):
    """With a read-only cache, `cached_sdf_grid` of a user's mesh built the grid and then threw it away with a bare
    "[Errno 30] Read-only file system: '<cache>/sdf'" (an independent check): `graspkit saga --object box.obj` failed.
    Now it warns and returns the grid it built (the same values as a fresh build); and a cache write that cannot be
    made names the folder and GRASPKIT_CACHE. (Under a regular file no folder can be made, even by root.)"""
    import trimesh

    from graspkit.data.formats import write_npz_atomic
    from graspkit.data.grasp_io import SDF_PADDING, cached_sdf_grid
    from graspkit.objects.sdf import SDFGrid

    blocker = tmp_path / "a_file"
    blocker.write_text("")
    monkeypatch.setenv("GRASPKIT_CACHE", str(blocker / "cache"))
    box = trimesh.creation.box((0.07, 0.05, 0.12))
    with pytest.warns(UserWarning, match=r"not kept for next time: .*cannot write in .*set GRASPKIT_CACHE"):
        grid = cached_sdf_grid(box, 16)
    want = SDFGrid.from_mesh(box, 16, SDF_PADDING)
    assert np.array_equal(grid.values.numpy(), want.values.numpy()) and grid.values.shape == want.values.shape
    with pytest.raises(OSError, match=rf"cannot write in {blocker / 'cache' / 'x'}: .*set GRASPKIT_CACHE"):
        write_npz_atomic(blocker / "cache" / "x" / "y.npz", {"a": np.ones(2)})
    with pytest.raises(OSError, match=r"cannot write in .*out: ") as e:
        write_npz_atomic(blocker / "out" / "y.npz", {"a": np.ones(2)})      # not in the cache: no cache hint
    assert "GRASPKIT_CACHE" not in str(e.value)


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


def test_write_atomic_clears_killed_writers_temporary_files(tmp_path):
    """JSON, CSV, PNG and GLB files go through write_atomic, which swept nothing: a writer killed there left its
    .<name>.<random>.tmp for ever (an independent check). A write now removes those of the same type of file in the
    folder older than STALE_TMP_S, and no younger one."""
    import time

    from graspkit.paths import STALE_TMP_S, write_atomic

    stale, young, png = (tmp_path / ".a_eval.json.k2j4h5g6.tmp", tmp_path / ".b.json.k2j4h5g7.tmp",
                         tmp_path / ".p.png.k2j4h5g8.tmp")
    for f, age in ((stale, STALE_TMP_S + 1), (young, STALE_TMP_S - 60), (png, STALE_TMP_S + 1)):
        f.write_bytes(b"{")
        os.utime(f, (time.time() - age, time.time() - age))
    write_atomic(tmp_path / "c.json", "{}")
    assert not stale.exists() and young.exists() and png.exists() and (tmp_path / "c.json").read_text() == "{}"


def test_a_body_build_writes_through_a_temporary_that_is_no_model_and_is_swept(tmp_path, monkeypatch):
    """`graspkit body build` killed while writing left `.<name>.<pid>.tmp.npz` for ever, and `--model <folder>`
    listed it among the folder's models (an independent check). Its temporary file is now a .tmp, and a build sweeps
    a killed build's."""
    import time

    from graspkit.body.procedural import save_model_npz
    from graspkit.paths import STALE_TMP_S

    stale = tmp_path / ".b.npz.a1b2c3d4.tmp"
    stale.write_bytes(b"half")
    os.utime(stale, (time.time() - STALE_TMP_S - 5, time.time() - STALE_TMP_S - 5))
    seen = []
    real = np.savez_compressed

    def savez(fh, **arrays):
        seen.extend(sorted(p.name for p in tmp_path.glob("*.npz")))         # what a folder listing shows meanwhile
        return real(fh, **arrays)

    monkeypatch.setattr(np, "savez_compressed", savez)
    save_model_npz({"x": np.arange(3)}, tmp_path / "b.npz")
    assert seen == [] and sorted(p.name for p in tmp_path.iterdir()) == ["b.npz"]
    assert np.load(tmp_path / "b.npz")["x"].tolist() == [0, 1, 2]


def test_locked_blocks_run_one_after_another(tmp_path):
    """`paths.locked` (around `eval --all --update`'s read-merge-write): blocks holding the same lock file never
    overlap, whichever starts first."""
    import threading
    import time

    from graspkit.paths import locked

    pytest.importorskip("fcntl")                        # elsewhere `locked` takes no lock, by design

    events: list[tuple[str, int]] = []

    def hold(k: int) -> None:
        with locked(tmp_path / ".lock"):
            events.append(("in", k))
            time.sleep(0.2)
            events.append(("out", k))

    threads = [threading.Thread(target=hold, args=(k,)) for k in range(3)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert [e[0] for e in events] == ["in", "out"] * 3
    assert all(events[2 * i][1] == events[2 * i + 1][1] for i in range(3))


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
    from graspkit.paths import DATA_STUBS, default_model_path

    monkeypatch.setenv("GRASPKIT_MODEL", str(tmp_path / "m.npz"))
    assert default_model_path() == tmp_path / "m.npz"
    monkeypatch.delenv("GRASPKIT_MODEL")
    assert default_model_path() == DATA_STUBS / "body_models" / "smplx" / "SMPLX_NEUTRAL.npz"


def test_window_and_wandr_run_keys_see_content_not_only_sizes(tmp_path):
    """The MotionFill window cache was named by the clips' names and sizes: a clip rewritten at the same size (one
    joint's sign flipped: save_motion kept the size 19 times in 50) read the old windows; the WANDR run key hashed the
    clips' names and a 7-digit sum of their poses, so moved goals resumed the old run (an independent check). Both
    keys change now with a clip's content at the same size, and with one goal moved."""
    import shutil

    import torch

    from graspkit.data.wandr_dataset import ClipSet
    from graspkit.eval_motionfill import windows_source
    from graspkit.eval_wandr import clipset_key

    src = sorted((DATA_STUBS / "motion" / "locomotion").glob("locomotion_*.npz"))[0]
    folder = tmp_path / "loco"
    folder.mkdir()
    clip = folder / src.name
    shutil.copy(src, clip)
    before = windows_source("locomotion", 1, folder, body="b")[0]
    with np.load(clip, allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    poses = arrays["poses"].copy()
    poses[12, 48:51] *= -1                                       # same dtype and shape: stored at the same size
    with zipfile.ZipFile(clip) as zf:
        compressed = zf.infolist()[0].compress_type == zipfile.ZIP_DEFLATED
    (np.savez_compressed if compressed else np.savez)(clip, **{**arrays, "poses": poses})
    if clip.stat().st_size == src.stat().st_size:                # the case the sizes alone missed
        assert windows_source("locomotion", 1, folder, body="b")[0] != before
    assert windows_source("locomotion", 1, folder, body="b")[0] != before     # content, whatever the size
    cs = ClipSet(torch.zeros(10, 135), torch.tensor([0, 5, 10]), torch.zeros(2, 22, 3), torch.zeros(2, 10),
                 torch.zeros(2, 3), torch.tensor([4, -1]), torch.tensor([1, 0]), ["r", "l"])
    moved = ClipSet(cs.p, cs.offsets, cs.rest, cs.betas, cs.goal + torch.tensor([0.3, 0.0, 0.0]), cs.goal_frame,
                    cs.kind, cs.names)
    same = ClipSet(*(t.clone() for t in (cs.p, cs.offsets, cs.rest, cs.betas, cs.goal, cs.goal_frame, cs.kind)),
                   list(cs.names))
    assert clipset_key(cs) != clipset_key(moved) and clipset_key(cs) == clipset_key(same)
    fields = ("p", "offsets", "rest", "betas", "goal", "goal_frame", "kind")      # each one changes the training
    changed = {"p": lambda t: t.index_put((torch.tensor([3]), torch.tensor([7])), torch.tensor(1e-4)),
               "rest": lambda t: t + 0.01, "betas": lambda t: t.index_fill(1, torch.tensor([0]), 0.5),
               "goal_frame": lambda t: torch.full_like(t, 5), "kind": lambda t: t.flip(0)}
    keys = {clipset_key(cs)} | {clipset_key(ClipSet(*(changed[k](getattr(cs, k)) if k == f else getattr(cs, k)
                                                      for k in fields), cs.names)) for f in changed}
    keys.add(clipset_key(ClipSet(*(getattr(cs, k) for k in fields), ["a", "b"])))
    assert len(keys) == 7                                    # the base, five arrays, the names: all distinct


def test_window_sources_take_only_the_kinds_own_numbered_clips(tmp_path):
    """`reach_*.npz` also matches reach_far_* and reach_near_* clips; the window set of "reach" counts and reads only
    reach_<digits>.npz, so a folder short of them says so instead of filling up with far clips."""
    import shutil

    from graspkit.eval_motionfill import windows_source

    src = sorted((DATA_STUBS / "motion" / "reach").glob("reach_0*.npz"))[0]
    shutil.copy(src, tmp_path / "reach_000000.npz")
    shutil.copy(src, tmp_path / "reach_far_000000.npz")
    with pytest.raises(FileNotFoundError, match="holds 1 reach clips, 2 wanted"):
        windows_source("reach", 2, tmp_path, body="b")
    assert [f.name for f in windows_source("reach", 1, tmp_path, body="b")[2]] == ["reach_000000.npz"]


@pytest.mark.parametrize("bad", ["one_node", "corners_equal", "nan", "corner_shape"])
def test_a_grid_that_is_no_sdf_grid_is_refused_by_name(tmp_path, bad):
    """A grid file is read only when SDFGrid can use it: 3-D values with at least 2 nodes a side (the cell is
    (upper - lower) / (nodes - 1)), lower < upper, both (3,), all finite; otherwise ValueError naming the file."""
    from graspkit.data import grasp_io
    from graspkit.data.formats import write_npz_atomic

    good = {"values": np.zeros((4, 4, 4), np.float32), "lower": -np.ones(3, np.float32),
            "upper": np.ones(3, np.float32)}
    write_npz_atomic(tmp_path / "ok.npz", good)
    assert grasp_io._read_grid(tmp_path / "ok.npz").values.shape == (4, 4, 4)
    bad_arrays = {"one_node": {"values": np.zeros((1, 4, 4), np.float32)}, "corners_equal": {"upper": -np.ones(3)},
                  "nan": {"values": np.where(np.arange(64).reshape(4, 4, 4) == 21, np.nan, 0.0)},
                  "corner_shape": {"lower": -np.ones(2, np.float32)}}[bad]
    write_npz_atomic(tmp_path / "g.npz", {**good, **bad_arrays})
    with pytest.raises(ValueError, match="g.npz: not an SDF grid"):
        grasp_io._read_grid(tmp_path / "g.npz")


def test_ship_sdf_grid_builds_from_the_mesh_whatever_the_cache_holds(tmp_path, monkeypatch):
    """`ship_sdf_grid` writes a grid built from the mesh (compared with SDFGrid.from_mesh run here), not one of that
    name that a cache holds (planted with values 1 cm off)."""
    from graspkit.data import grasp_io
    from graspkit.data.formats import write_npz_atomic
    from graspkit.objects.sdf import SDFGrid

    monkeypatch.setenv("GRASPKIT_CACHE", str(tmp_path / "cache"))
    built = SDFGrid.from_mesh(grasp_io._mesh("apple"), 16, grasp_io.SDF_PADDING)
    write_npz_atomic(tmp_path / "cache" / "sdf" / grasp_io._grid_filename("apple", 16),
                     {"values": built.values.numpy() + 0.01, "lower": built.lower.numpy(),
                      "upper": built.upper.numpy()})
    with np.load(grasp_io.ship_sdf_grid("apple", 16, tmp_path / "ship"), allow_pickle=False) as z:
        np.testing.assert_allclose(z["values"].astype(np.float32), built.values.numpy(), atol=3e-5)


def test_foreign_shipped_and_run_files_are_named(tmp_path, monkeypatch):
    """A cache grid of the right keys but a 1-D `values` was used and failed in grid_sample; an unreadable shipped grid
    fell back to the cache silently (today's lesson-05 bug again); a damaged run file stopped every rerun with 'not a
    torch checkpoint' and no way out; GRASPKIT_CACHE='' put the cache in the working folder and '~' was not
    expanded (an independent check)."""
    import torch

    from graspkit.data import grasp_io
    from graspkit.data.formats import write_npz_atomic
    from graspkit.paths import cache_dir
    from graspkit.train import TrainConfig, fit

    foreign = tmp_path / "g.npz"
    write_npz_atomic(foreign, {"values": np.zeros(8, np.float32), "lower": np.zeros(3), "upper": np.ones(3)})
    with pytest.raises(ValueError, match="g.npz: not an SDF grid"):
        grasp_io._read_grid(foreign)
    stubs = tmp_path / "stubs"
    (stubs / "sdf").mkdir(parents=True)
    name = grasp_io._grid_filename("apple", 16)
    (stubs / "sdf" / name).write_text("version https://git-lfs.github.com/spec/v1\n")
    monkeypatch.setattr(grasp_io, "DATA_STUBS", stubs)
    with pytest.warns(UserWarning, match=f"{name}: the shipped grid cannot be read"):
        grasp_io.cached_sdf_grid("apple", 16, folder=tmp_path / "cache")
    run = tmp_path / "run.pt"
    run.write_bytes(b"cut short")
    net = torch.nn.Linear(2, 1)
    data = torch.utils.data.TensorDataset(torch.zeros(4, 2))
    with pytest.raises(ValueError, match="run.pt: .*; delete it \\(graspkit's run file\\)"):
        fit(net, lambda m, b, e: {"loss": m(b[0]).sum()}, data, TrainConfig(epochs=1, batch_size=2), checkpoint=run,
            progress=False)
    monkeypatch.setenv("GRASPKIT_CACHE", "")
    assert cache_dir() == Path.home() / ".cache" / "graspkit"
    monkeypatch.setenv("GRASPKIT_CACHE", "~/gk")
    assert cache_dir() == Path.home() / "gk"


def test_the_default_body_follows_graspkit_model_within_a_process(tmp_path, monkeypatch):
    """MotionFill's window key and GOAL's `_body()` kept the first default body of the process (an lru_cache without
    the path), so a notebook that set GRASPKIT_MODEL later keyed runs by windows of another body (an independent
    check); both follow the file GRASPKIT_MODEL names now, as BodyModel.digest() of that file."""
    from graspkit.body import BodyModel
    from graspkit.eval_goal import _body
    from graspkit.eval_motionfill import default_body_digest
    from graspkit.paths import default_model_path

    from graspkit.data.reaching import _default_model
    from graspkit.eval_goal import _head_body

    first, bm0 = default_body_digest(), _body()[0]
    head0, planner0 = _head_body().bm.digest(), _default_model().digest()      # the first of the process, cached
    with np.load(default_model_path(), allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    tall = tmp_path / "tall.npz"
    np.savez(tall, **{**arrays, "v_template": arrays["v_template"] * 1.2})
    monkeypatch.setenv("GRASPKIT_MODEL", str(tall))
    want = BodyModel.from_file(tall).digest()
    assert default_body_digest() == want != first
    assert _body()[0].digest() == BodyModel.from_file(tall, flat_hand_mean=True).digest() != bm0.digest()
    assert _head_body().bm.digest() == _body()[0].digest() != head0          # GOAL's head labels and the planner's
    assert _default_model().digest() == BodyModel.from_file(tall).digest() != planner0      # body followed too
    size = tall.stat().st_size                        # rewritten in place at the same size: only the mtime tells
    np.savez(tall, **{**arrays, "v_template": arrays["v_template"] * 0.9})
    st = tall.stat()
    os.utime(tall, ns=(st.st_atime_ns, st.st_mtime_ns + 1_000_000))     # a later mtime, whatever the file system's tick
    assert tall.stat().st_size == size
    assert default_body_digest() == BodyModel.from_file(tall).digest() != want
    assert _body()[0].digest() == BodyModel.from_file(tall, flat_hand_mean=True).digest()
    monkeypatch.setenv("GRASPKIT_MODEL", str(tmp_path / "nope.npz"))            # named by the reader, not by stat()
    with pytest.raises(ValueError, match="nope.npz: no such body-model file"):
        default_body_digest()


def test_file_stamp_sees_size_and_one_file_by_any_name(tmp_path, monkeypatch):
    """paths.file_stamp (the body caches' key): (resolved path, mtime ns, size); a size change counts at the same
    mtime (coarse-mtime file systems), a relative name is the same file, a missing file is (path, 0, 0)."""
    from graspkit.paths import file_stamp

    f = tmp_path / "m.npz"
    f.write_bytes(b"a" * 10)
    st, a = f.stat(), file_stamp(f)
    f.write_bytes(b"a" * 11)
    os.utime(f, ns=(st.st_atime_ns, st.st_mtime_ns))
    assert file_stamp(f) != a and file_stamp(f) == (str(f.resolve()), st.st_mtime_ns, 11)
    monkeypatch.chdir(tmp_path)
    assert file_stamp("m.npz") == file_stamp(tmp_path / "m.npz")
    assert file_stamp("gone.npz") == (str((tmp_path / "gone.npz").resolve()), 0, 0)


def test_an_npz_write_clears_a_killed_writers_temporary_files(tmp_path):
    """A process killed while writing a cache .npz left `.<name>.<random>.tmp` for ever (a 240 MB one in an independent
    check); the next write of that entry removes such files older than STALE_TMP_S, and leaves a fresh one (another
    writer at work now) alone, as checkpoints do. Folder-wide: a resumed `data make` rewrote the killed clip at once,
    while its temporary file was young, and never again (another check), so a later write of *any* .npz there sweeps
    it; other kinds of file and names that are not a temporary file's are left alone."""
    import time

    from graspkit.data.formats import write_npz_atomic
    from graspkit.paths import STALE_TMP_S

    target = tmp_path / "c.npz"
    stale, fresh = tmp_path / ".c.npz.abc01234.tmp", tmp_path / ".c.npz.def01234.tmp"
    other = tmp_path / ".reach[1]_000001.npz.09v_eynp.tmp"   # another clip's (glob characters in its name), as mkstemp
    kept = [tmp_path / ".notes.txt.abc01234.tmp", tmp_path / ".c.npz.backup.tmp", tmp_path / "c.npz.abc01234.tmp"]
    for f, age in [(stale, STALE_TMP_S + 60), (fresh, 1), (other, STALE_TMP_S + 60)] + [(k, 10 * STALE_TMP_S)
                                                                                       for k in kept]:
        f.write_bytes(b"half")
        os.utime(f, (time.time() - age, time.time() - age))
    write_npz_atomic(target, {"a": np.arange(3)})
    assert not stale.exists() and not other.exists() and fresh.exists() and np.load(target)["a"].tolist() == [0, 1, 2]
    assert all(k.exists() for k in kept)


def test_create_exclusive_claims_once_also_without_hard_links(tmp_path, monkeypatch):
    """create_exclusive writes a file whole unless it exists (False then, the file untouched); where the filesystem
    has no hard links (vfat: os.link raises PermissionError) it falls back to O_EXCL instead of failing (a review)."""
    from graspkit.paths import create_exclusive

    a = tmp_path / "a.json"
    assert create_exclusive(a, "one") and not create_exclusive(a, "two") and a.read_text() == "one"

    def no_links(src, dst):
        raise PermissionError(1, "Operation not permitted")

    monkeypatch.setattr(os, "link", no_links)
    b = tmp_path / "b.json"
    assert create_exclusive(b, "one") and not create_exclusive(b, "two") and b.read_text() == "one"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.json", "b.json"]          # no temporary left
    plain = tmp_path / "plain.json"                  # the mode a plain open() gives, not mkstemp's owner-only 0600
    plain.write_text("x")
    assert a.stat().st_mode & 0o777 == b.stat().st_mode & 0o777 == plain.stat().st_mode & 0o777


def test_an_undeletable_stale_temporary_does_not_fail_a_finished_write(tmp_path, monkeypatch):
    """In a shared cache another user's stale temporary file cannot be removed (EPERM): the sweep after a published
    write raised it, and a grid that was written was reported as failed (an independent check). It is skipped."""
    import time

    from graspkit.data.formats import write_npz_atomic
    from graspkit.paths import STALE_TMP_S

    theirs = tmp_path / ".other.npz.abcd1234.tmp"
    theirs.write_bytes(b"half")
    os.utime(theirs, (time.time() - STALE_TMP_S - 60,) * 2)
    real = Path.unlink

    def unlink(self, missing_ok=False):
        if self.name == theirs.name:
            raise PermissionError(1, "Operation not permitted", str(self))
        return real(self, missing_ok=missing_ok)

    monkeypatch.setattr(Path, "unlink", unlink)
    write_npz_atomic(tmp_path / "mine.npz", {"a": np.arange(2)})
    assert np.load(tmp_path / "mine.npz")["a"].tolist() == [0, 1] and theirs.exists()


@pytest.mark.parametrize("umask", [0o077, 0o002])
def test_npz_files_follow_the_umask_as_every_other_file(tmp_path, umask):
    """write_npz_atomic set 0644 whatever the umask (world-readable under umask 077, not group-writable in a shared
    cache under 002), while every other writer follows it (an independent check)."""
    from graspkit.data.formats import write_npz_atomic
    from graspkit.paths import write_atomic

    old = os.umask(umask)
    try:
        write_npz_atomic(tmp_path / "a.npz", {"a": np.ones(2)})
        write_atomic(tmp_path / "b.json", "{}")
        (tmp_path / "c.txt").write_text("plain open()")
    finally:
        os.umask(old)
    modes = {p.name: p.stat().st_mode & 0o777 for p in tmp_path.iterdir()}
    assert modes == dict.fromkeys(("a.npz", "b.json", "c.txt"), 0o666 & ~umask)


def test_a_full_disk_names_the_file_and_leaves_nothing_half_written(tmp_path, monkeypatch):
    """A full disk: torch's zip writer raised "RuntimeError: [enforce fail at inline_container.cc] unexpected pos"
    (a traceback through the CLI, which reports OSErrors), other writes "[Errno 28] No space left on device" with no
    path, and create_exclusive left a 0-byte run record that refused the folder as damaged once space was back (an
    independent check, on a 120 kB tmpfs). Each names the file now, and no record is left."""
    import errno

    import torch

    from graspkit.paths import create_exclusive, write_atomic
    from graspkit.train import save_checkpoint

    def full(*a, **k):
        raise OSError(errno.ENOSPC, "No space left on device")

    def torch_full(obj, f, *a, **k):
        raise RuntimeError("[enforce fail at inline_container.cc:672] . unexpected pos 68736 vs 68688")

    monkeypatch.setattr(torch, "save", torch_full)
    with pytest.raises(OSError, match=r"^\[Errno 5\] the checkpoint could not be written .* bytes free there: is the "
                                      "disk full") as e:
        save_checkpoint(tmp_path / "c.pt", {"w": torch.ones(2)})
    assert e.value.filename == str(tmp_path / "c.pt") and isinstance(e.value.__cause__, RuntimeError)
    monkeypatch.setattr(Path, "write_bytes", full)
    with pytest.raises(OSError, match=r"^\[Errno 28\] No space left on device: ") as e:
        write_atomic(tmp_path / "r.json", "{}")
    assert e.value.filename == str(tmp_path / "r.json")
    class FullFile:                                   # a file whose data never fit: write() raises ENOSPC
        def __init__(self, f):
            self.f = f

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            self.f.close()

        def write(self, data):
            full()

    real_open, real_fdopen = open, os.fdopen
    monkeypatch.setattr("graspkit.paths.open", lambda *a, **k: FullFile(real_open(*a, **k)), raising=False)
    for links in (True, False):
        if not links:             # the O_EXCL fallback (vfat): the temporary file fits, the record's own write fails
            monkeypatch.undo()
            monkeypatch.setattr(os, "link", lambda a, b: (_ for _ in ()).throw(PermissionError(1, "no links")))
            monkeypatch.setattr(os, "fdopen", lambda *a, **k: FullFile(real_fdopen(*a, **k)))
        with pytest.raises(OSError, match="No space left on device") as e:
            create_exclusive(tmp_path / "record.json", "{}")
        assert e.value.filename == str(tmp_path / "record.json") and not (tmp_path / "record.json").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == []


def test_a_long_file_name_and_a_symbolic_link_are_written_as_open_would(tmp_path, monkeypatch):
    """A legal 249-byte --out name failed after the work ("File name too long": the temporary file's name is 14 bytes
    longer), and --out naming a symbolic link replaced the link by a file and left its target as it was (an
    independent check). The temporary name is shortened (and still swept); a link is written through."""
    import time

    import torch

    import graspkit.paths as paths
    from graspkit.data.formats import write_npz_atomic
    from graspkit.paths import STALE_TMP_S, write_atomic
    from graspkit.train import load_checkpoint, save_checkpoint

    long = tmp_path / ("a" * 246 + ".pt")
    save_checkpoint(long, {"w": torch.arange(3.0)})
    assert load_checkpoint(long)["w"].tolist() == [0.0, 1.0, 2.0]
    assert [p.name for p in tmp_path.iterdir()] == [long.name]
    stale = tmp_path / (".a" + "a" * 196 + ".pt.abcd1234.tmp")              # a killed writer's, shortened the same way
    stale.write_bytes(b"half")
    os.utime(stale, (time.time() - STALE_TMP_S - 60,) * 2)
    monkeypatch.setattr(paths, "_SWEPT", {})                  # the folder was swept a moment ago: once a minute
    save_checkpoint(long, {"w": torch.arange(2.0)})
    assert not stale.exists()
    store = tmp_path / "store"
    store.mkdir()
    for name, write, read in (("m.npz", lambda p: write_npz_atomic(p, {"a": np.arange(4)}),
                               lambda p: np.load(p)["a"].tolist() == [0, 1, 2, 3]),
                              ("r.json", lambda p: write_atomic(p, "{}"), lambda p: p.read_text() == "{}"),
                              ("w.pt", lambda p: save_checkpoint(p, {"w": torch.ones(1)}),
                               lambda p: load_checkpoint(p)["w"].tolist() == [1.0])):
        (store / name).write_text("old")
        link = tmp_path / f"link_{name}"
        link.symlink_to(store / name)
        write(link)
        assert link.is_symlink() and read(store / name) and read(link), name
    assert sorted(p.name for p in store.iterdir()) == ["m.npz", "r.json", "w.pt"]          # no temporary left


def test_a_damaged_entry_of_a_read_only_cache_is_made_again_not_a_crash(tmp_path, monkeypatch):
    """read_cache removed a damaged entry before making it again; in a read-only cache the removal raised a bare
    OSError (an independent check). It warns, naming the folder and GRASPKIT_CACHE, and the caller makes it again."""
    from graspkit.paths import read_cache

    monkeypatch.setenv("GRASPKIT_CACHE", str(tmp_path))
    bad = tmp_path / "sdf" / "g.npz"
    bad.parent.mkdir()
    bad.write_bytes(b"PK cut")
    real = Path.unlink

    def unlink(self, missing_ok=False):
        if self == bad:
            raise OSError(30, "Read-only file system")
        return real(self, missing_ok=missing_ok)

    monkeypatch.setattr(Path, "unlink", unlink)
    with pytest.warns(UserWarning) as got:
        assert read_cache(bad, lambda p: np.load(p, allow_pickle=False)["a"]) is None
    text = [str(w.message) for w in got]
    assert any("a damaged cache file, made again" in t for t in text)
    assert any(f"cannot write in {bad.parent}: Read-only file system" in t and "GRASPKIT_CACHE" in t for t in text)


def test_naming_errors_names_only_plain_errors_that_name_no_file(tmp_path):
    """A full disk's plain OSError gets the path as its filename; an error without an errno (Pillow's "encoder
    error -2"), a subclass (io.UnsupportedOperation is a ValueError too) or one that names its file passes unchanged
    (the first version turned them into "[Errno None] ..." plain OSErrors, a review)."""
    import io

    from graspkit.paths import naming_errors

    for raised in (OSError("encoder error -2"), io.UnsupportedOperation("not writable"),
                   FileNotFoundError(2, "No such file or directory", "/elsewhere")):
        with pytest.raises(type(raised)) as e:
            with naming_errors(tmp_path / "x.gif"):
                raise raised
        assert e.value is raised
    for raised in (OSError(28, "No space left on device"), PermissionError(13, "Permission denied")):
        with pytest.raises(OSError) as e:
            with naming_errors(tmp_path / "x.gif"):
                raise raised
        assert type(e.value) is type(raised) and e.value.errno == raised.errno
        assert e.value.filename == str(tmp_path / "x.gif")


def test_a_folder_is_swept_once_a_minute_per_file_type_and_suffixless_names_by_their_own(tmp_path, monkeypatch):
    """The folder-wide sweep runs at most once a minute per (folder, file type) in a process (writing n files there
    stays linear in n); the next one after that minute sweeps again. Files without a suffix are swept by their own
    (shortened) name, each under its own key (one name's write once skipped another's stale file, a review)."""
    import time

    import graspkit.paths as paths

    clock = [1000.0]
    monkeypatch.setattr(time, "monotonic", lambda: clock[0])
    monkeypatch.setattr(paths, "_SWEPT", {})

    def stale(name: str) -> Path:
        f = tmp_path / name
        f.write_bytes(b"half")
        os.utime(f, (time.time() - paths.STALE_TMP_S - 60,) * 2)
        return f

    first = stale(".a.npz.abcd1234.tmp")
    paths.sweep_stale_temps(tmp_path / "x.npz")
    second = stale(".b.npz.abcd1234.tmp")
    clock[0] += 30.0
    paths.sweep_stale_temps(tmp_path / "x.npz")                      # within the minute: not again
    assert not first.exists() and second.exists()
    clock[0] += 31.0
    paths.sweep_stale_temps(tmp_path / "x.npz")
    assert not second.exists()
    long = "b" * 230                                                 # no suffix, shortened in its temporary name
    for name in ("A", long):
        f = stale(f".{paths.temp_stem(tmp_path / name)}.abcd1234.tmp")
        paths.sweep_stale_temps(tmp_path / name)
        assert not f.exists(), name
