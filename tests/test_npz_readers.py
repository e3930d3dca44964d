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


def _damaged(tmp_path, arrays: dict, name: str):
    """A compressed archive of `arrays` whose largest member's stored bytes are overwritten: its zip directory still
    reads, the member does not (a CRC or inflate error on reading it)."""
    import zipfile
    path = tmp_path / name
    np.savez_compressed(path, **arrays)
    with zipfile.ZipFile(path) as z:
        info = max(z.infolist(), key=lambda i: i.compress_size)
    raw = bytearray(path.read_bytes())
    start = info.header_offset + 30 + len(info.filename) + len(info.extra) + info.compress_size // 2
    raw[start:start + 64] = bytes(64)
    path.write_bytes(bytes(raw))
    return path


def test_a_damaged_member_is_named_with_its_file(tmp_path):
    """A body model, a motion and a grasp file whose zip directory reads but one member is corrupt: each reader
    raises its ValueError naming the file and the key (numpy raises BadZipFile or zlib.error, which the CLI did not
    report as bad input)."""
    from graspkit.body.model import load_model_arrays
    from graspkit.data.formats import load_motion
    from graspkit.data.grab import read_arrays
    from graspkit.paths import default_model_path

    rng = np.random.default_rng(0)
    body = _damaged(tmp_path, dict(np.load(default_model_path(), allow_pickle=False)), "body.npz")
    motion = _damaged(tmp_path, {"poses": rng.normal(size=(300, 165)), "trans": rng.normal(size=(300, 3)),
                                 "mocap_frame_rate": np.array(30.0)}, "motion.npz")
    grasp = _damaged(tmp_path, {"obj_name": np.array("mug"), "body.params.transl": rng.normal(size=(300, 3)),
                                "contact.object": rng.integers(0, 2, (300, 2048)).astype(np.uint8)}, "grasp.npz")
    for reader, path in ((load_model_arrays, body), (load_motion, motion), (read_arrays, grasp)):
        with pytest.raises(ValueError, match=rf"{path.name}: key '.*' .*corrupt"):
            reader(path)
