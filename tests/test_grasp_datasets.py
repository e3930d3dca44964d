"""The grasp-file datasets (SAGA A.3, GOAL §3.3; graspkit.data.grasp_datasets): splits and acceptance, array checks,
GNet items against the `smplx` package, the approach windows' padding and bounds."""
from pathlib import Path

import numpy as np
import pytest
import smplx
import torch

from graspkit.data.grasp import SPLITS
from graspkit.data.grasp_datasets import ApproachDataset, GNetDataset, check_arrays, grasp_files
from graspkit.paths import DATA_STUBS

from conftest import npz_copy

STUBS = DATA_STUBS


def _copy(dst: Path, name: str, kind: str = "grasp", **replace) -> Path:
    """Shipped file `name` copied into `dst` with arrays replaced (None drops a key)."""
    return npz_copy(STUBS / ("grasps" if kind == "grasp" else "approach") / name, dst / name, **replace)


def _smplx_vertices(item: dict) -> np.ndarray:
    """The `smplx` package's vertices (10475, 3), float64, of a GNetDataset item's fullpose, transl and betas on the
    shipped procedural model (flat hand mean: the hand poses are absolute)."""
    model = smplx.create(str(STUBS / "body_models"), model_type="smplx", gender="neutral", ext="npz", use_pca=False,
                         flat_hand_mean=True, num_betas=10, dtype=torch.float64)
    p = item["fullpose"].double()
    with torch.no_grad():
        return model(betas=item["betas"].double()[None], global_orient=p[None, 0],
                     body_pose=p[None, 1:22].reshape(1, -1), jaw_pose=p[None, 22], leye_pose=p[None, 23],
                     reye_pose=p[None, 24], left_hand_pose=p[None, 25:40].reshape(1, -1),
                     right_hand_pose=p[None, 40:55].reshape(1, -1), transl=item["transl"].double()[None],
                     expression=torch.zeros(1, 10, dtype=torch.float64)).vertices[0].numpy()


def test_grasp_files_by_split_and_acceptance(tmp_path):
    """grasp_files: mug grasps are SPLITS' test split and pitcher grasps its train split; a rejected grasp
    (grasp.accepted False) is left out unless accepted_only=False, a file without the flag counts as accepted; an
    unknown split name and a missing folder are errors, not an empty list."""
    assert "mug" in SPLITS["test"] and "pitcher" in SPLITS["train"]
    mug, mug_bad = _copy(tmp_path, "grasp_000000.npz"), _copy(tmp_path, "grasp_000001.npz", **{"grasp.accepted": np.array(False)})
    pit, pit_noflag = _copy(tmp_path, "grasp_000008.npz"), _copy(tmp_path, "grasp_000009.npz", **{"grasp.accepted": None})
    assert grasp_files(tmp_path, split="test") == [mug]
    assert grasp_files(tmp_path, split="train") == [pit, pit_noflag]
    assert grasp_files(tmp_path, split="val") == []
    assert grasp_files(tmp_path, split=None, accepted_only=False) == [mug, mug_bad, pit, pit_noflag]
    with pytest.raises(ValueError, match="split"):
        grasp_files(tmp_path, split="training")
    with pytest.raises(FileNotFoundError):
        grasp_files(tmp_path / "nope")


def test_check_arrays_refuses_extra_dims_other_frame_counts_infinities_and_foreign_hand_rows():
    """check_arrays (its doc: another shape than SHAPES gives, a NaN or an inf; goal.right_hand are rows of the 400
    GOAL vertices, so in [0, 400)): each bad copy of a shipped grasp is refused, the original passes."""
    from graspkit.data.grasp_datasets import WholeGraspDataset
    with np.load(STUBS / "grasps" / "grasp_000000.npz", allow_pickle=False) as z:
        good = {k: z[k] for k in z.files}
    keys = tuple(dict.fromkeys(WholeGraspDataset.keys + GNetDataset.keys))
    check_arrays(good, keys, Path("ok.npz"))
    bad = {"saga.markers": good["saga.markers"][..., None],                       # (143, 3, 1)
           "contact.markers": np.repeat(good["contact.markers"], 2, 0),           # 2 frames in a 1-frame file
           "object.points": np.where(np.arange(len(good["object.points"]))[:, None] == 7, np.inf, good["object.points"])}
    rh = good["goal.right_hand"].copy()
    for v in (400, -1):
        r = rh.copy()
        r[3] = v
        bad[f"goal.right_hand={v}"] = r
    for k, v in bad.items():
        with pytest.raises(ValueError, match=r"bad\.npz"):
            check_arrays({**good, k.split("=")[0]: v}, keys, Path("bad.npz"))


def test_gnet_items_rebuild_their_vertices_with_smplx():
    """GNetDataset's fullpose, transl and betas are the body's parameters (GOAL Eq. 2): fed to the `smplx` package
    (procedural model, flat hand mean) they give the item's 400 verts, and hand_offsets are the right-hand rows of
    offsets."""
    ds = GNetDataset(STUBS / "grasps", split=None)
    for i in (0, len(ds) - 1):
        it = ds[i]
        np.testing.assert_allclose(_smplx_vertices(it)[ds.vertex_ids], it["verts"].numpy(), atol=1e-4)
        np.testing.assert_allclose(it["hand_offsets"].numpy(), it["offsets"][ds.right_hand].numpy(), atol=0)


def test_approach_window_and_goal_frame_are_checked(tmp_path):
    """ApproachDataset: a window under 2 frames ('None or >= 2'), a goal frame past the clip's last frame and a window
    that starts after the goal frame (goal_frame is an index within the item) are refused with a ValueError."""
    for w in (0, 1, 62.0, 2.5, True, "62"):      # 62.0 was a bare IndexError, "62" a TypeError (an independent check)
        with pytest.raises(ValueError, match="^window: expected None or a whole number >= 2 frames"):
            ApproachDataset(STUBS / "approach", split=None, window=w)
    with np.load(STUBS / "approach" / "approach_000000.npz", allow_pickle=False) as z:
        T = len(z["body.params.fullpose"])
    _copy(tmp_path, "approach_000000.npz", "approach", **{"grasp.goal_frame": np.array(T)})
    with pytest.raises(ValueError, match="goal_frame"):
        ApproachDataset(tmp_path, split=None)
    with pytest.raises(ValueError, match="window: the last 10 frames .* start after its goal frame"):
        ApproachDataset(STUBS / "approach", split=None, window=10)   # the goal frame would be a negative index


def test_a_window_longer_than_the_clip_repeats_its_first_frame_in_front():
    """A window of 120 frames over clips of 66..108: the clip's first frame repeated in front (SAGA's padding),
    valid False exactly on those padded frames (pose, translation and foot contacts alike), and goal_frame still the file's goal pose, shifted by the padding."""
    W = 120
    ds = ApproachDataset(STUBS / "approach", split=None, window=W)
    for i, f in enumerate(ds.files):
        with np.load(f, allow_pickle=False) as z:
            pose, g = z["body.params.fullpose"].reshape(-1, 55, 3), int(z["grasp.goal_frame"])
            transl, feet = z["body.params.transl"], z["contact.feet"].astype(bool)
        T = len(pose)
        pad = W - T
        it = ds[i]
        assert pad > 0 and it["fullpose"].shape == (W, 55, 3)
        np.testing.assert_array_equal(it["valid"].numpy(), np.arange(W) >= pad)
        np.testing.assert_allclose(it["fullpose"][:pad].numpy(), np.repeat(pose[:1], pad, 0), atol=0)
        np.testing.assert_allclose(it["fullpose"][pad:].numpy(), pose, atol=0)
        assert int(it["goal_frame"]) == g + pad
        for key, arr in (("transl", transl), ("foot_contacts", feet)):             # padded the same way
            np.testing.assert_array_equal(it[key].numpy(), np.concatenate([np.repeat(arr[:1], pad, 0), arr]))


def test_a_scene_moved_along_the_floor_keeps_its_labels_on_its_body(tmp_path):
    """Grasp and approach files moved as a whole, body and object, by (0.5, -1, 0) m (which `body_offset` takes as
    the same body's): the world-frame labels follow the move (`moved_since_labels`), so SAGA's object-centred markers
    (dataset and evaluation) and an approach clip's hand-to-goal offsets are the unmoved files', the hand-to-goal
    offset is zero at the goal frame, and GNet's 400 vertices are the `smplx` package's for the moved parameters
    (all were off by the move)."""
    from graspkit.body import BodyModel
    from graspkit.data.grasp_datasets import WholeGraspDataset
    from graspkit.eval_saga import load_placements
    from graspkit.paths import default_model_path

    d = np.array([0.5, -1.0, 0.0], np.float32)
    for kind, folder in (("grasp", "grasps"), ("approach", "approach")):
        (tmp_path / folder).mkdir()
        for p in sorted((STUBS / folder).glob(f"{kind}_*.npz")):
            with np.load(p, allow_pickle=False) as z:
                moved = {k: z[k] + d for k in ("body.params.transl", "object.params.transl")}
            npz_copy(p, tmp_path / folder / p.name, **moved)
    old, new = WholeGraspDataset(STUBS / "grasps", split=None), WholeGraspDataset(tmp_path / "grasps", split=None)
    np.testing.assert_allclose(new.data["markers"].numpy(), old.data["markers"].numpy(), atol=1e-5)
    name = old.object_names[0]
    for a, b in zip(load_placements(STUBS / "grasps", name, 3, split=_split_of(name)),
                    load_placements(tmp_path / "grasps", name, 3, split=_split_of(name))):
        np.testing.assert_allclose(b.markers.numpy(), a.markers.numpy(), atol=1e-5)
    bm = BodyModel.from_file(default_model_path())
    old, new = (ApproachDataset(f, split=None, bm=bm) for f in (STUBS / "approach", tmp_path / "approach"))
    for a, b in zip(old, new):
        np.testing.assert_allclose(b["hand_to_goal"].numpy(), a["hand_to_goal"].numpy(), atol=1e-5)
        assert float(b["hand_to_goal"][int(b["goal_frame"])].abs().max()) < 1e-5
    ds = GNetDataset(tmp_path / "grasps", split=None)
    np.testing.assert_allclose(_smplx_vertices(ds[0])[ds.vertex_ids], ds[0]["verts"].numpy(), atol=1e-4)


def _split_of(name: str) -> str:
    """The split an object's grasps belong to (SPLITS)."""
    return next(s for s, names in SPLITS.items() if name in names)
