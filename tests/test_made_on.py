"""Grasp and approach files made on one body, read with another: `graspkit.data.grab.body_offset` against the smplx
package, and every reader that poses the files' grasps on the body GRASPKIT_MODEL names refuses another body's."""
from __future__ import annotations

import numpy as np
import pytest
import torch

from conftest import PROCEDURAL_MODEL, npz_copy
from graspkit.paths import DATA_STUBS

GRASP = DATA_STUBS / "grasps" / "grasp_000000.npz"
APPROACH = DATA_STUBS / "approach" / "approach_000000.npz"


@pytest.fixture(scope="module")
def big(tmp_path_factory):
    """graspkit's body 8 % larger, as <tmp>/models/smplx/SMPLX_NEUTRAL.npz (smplx.create's layout)."""
    folder = tmp_path_factory.mktemp("big") / "models" / "smplx"
    folder.mkdir(parents=True)
    with np.load(PROCEDURAL_MODEL, allow_pickle=False) as z:
        return npz_copy(PROCEDURAL_MODEL, folder / "SMPLX_NEUTRAL.npz", v_template=z["v_template"] * 1.08,
                        shapedirs=z["shapedirs"] * 1.08)


def _smplx_offset(model, path) -> float:
    """The largest distance between the smplx package's vertices for a file's grasp frame and its goal.vertices."""
    import smplx

    with np.load(path, allow_pickle=False) as z:
        a = {k: z[k] for k in z.files}
    f = int(a.get("grasp.goal_frame", a.get("grasp.frame", 0)))
    p = torch.as_tensor(a["body.params.fullpose"][f:f + 1], dtype=torch.float64)
    ref = smplx.create(str(model.parent.parent), model_type="smplx", gender="neutral", ext="npz", use_pca=False,
                       flat_hand_mean=True, num_betas=10, batch_size=1, dtype=torch.float64)
    v = ref(betas=torch.as_tensor(a["body.betas"][None], dtype=torch.float64), global_orient=p[:, :3],
            body_pose=p[:, 3:66], jaw_pose=p[:, 66:69], leye_pose=p[:, 69:72], reye_pose=p[:, 72:75],
            left_hand_pose=p[:, 75:120], right_hand_pose=p[:, 120:165], expression=torch.zeros(1, 10).double(),
            transl=torch.as_tensor(a["body.params.transl"][f:f + 1], dtype=torch.float64)).vertices[0]
    return float(np.linalg.norm(v[a["goal.vertex_ids"]].numpy() - a["goal.vertices"], axis=1).max())


def test_body_offset_is_what_smplx_measures(big, tmp_path):
    """On graspkit's body (which made the stubs) a grasp or approach file's stored GOAL vertices are its vertices to
    a micrometre; on a body 8 % larger they lie 8-9 cm off, as the smplx package poses that body. A file without GOAL's
    labels gives None, one of another mesh layout infinity."""
    from graspkit.body import BodyModel
    from graspkit.data.grab import MADE_ON_TOL, body_offset

    shipped, other = BodyModel.from_file(PROCEDURAL_MODEL), BodyModel.from_file(big)
    for path in (GRASP, APPROACH):
        assert body_offset(shipped, path) < 1e-5 and _smplx_offset(PROCEDURAL_MODEL, path) < 1e-5
        off = body_offset(other, path)
        assert off == pytest.approx(_smplx_offset(big, path), abs=1e-5) and off > 50 * MADE_ON_TOL
    assert body_offset(shipped, npz_copy(GRASP, tmp_path / "own.npz", **{"goal.vertices": None})) is None
    with np.load(GRASP, allow_pickle=False) as z:
        ids = z["goal.vertex_ids"].copy()
    ids[0] = 10475
    assert body_offset(shipped, npz_copy(GRASP, tmp_path / "far.npz", **{"goal.vertex_ids": ids})) == float("inf")


def test_readers_refuse_grasps_made_on_another_body(big, tmp_path, monkeypatch):
    """With GRASPKIT_MODEL naming another body than the one that made the data, GOAL's readers (training and
    evaluation), SAGA's evaluation and its GrabNet-SMPLX baseline's training, MotionFill's approach windows and
    `eval --all` refuse, naming the folder, before
    anything is written: until 2026-12-07 they posed graspkit's grasps on that body (6-8 cm under the floor, the hand
    9 cm from where it held the object) and measured them there."""
    from graspkit.benchmark import run_all
    from graspkit.body import BodyModel
    from graspkit.eval_goal import evaluate as eval_goal, gnet_data
    from graspkit.eval_motionfill import approach_motions
    from graspkit.eval_saga import evaluate as eval_saga
    from graspkit.models.wholegrasp import train_grabnet_smplx

    folders = [DATA_STUBS / "grasps", DATA_STUBS / "approach"]
    motions, _ = approach_motions(DATA_STUBS / "approach", bm=BodyModel.from_file(PROCEDURAL_MODEL))
    assert motions                                                 # graspkit's own body: read as before
    with pytest.raises(ValueError, match=r"data: .*approach: its approach files were made on another body model"):
        approach_motions(DATA_STUBS / "approach", bm=BodyModel.from_file(big))
    monkeypatch.setenv("GRASPKIT_MODEL", str(big))
    with pytest.raises(ValueError, match=r"folder: .*grasps: its grasp files were made on another body model than "
                                         r".*SMPLX_NEUTRAL.npz \(grasp_000000.npz's stored GOAL vertices lie up to"):
        eval_goal(folders, out=tmp_path / "goal.json", progress=False)
    with pytest.raises(ValueError, match=r"folder: .*approach: its approach files were made on another body model"):
        gnet_data([DATA_STUBS / "approach"])
    with pytest.raises(ValueError, match=r"root: .*grasps: its grasp files were made on another body model"):
        eval_saga(DATA_STUBS / "grasps", out=tmp_path / "saga.json", progress=False)
    with pytest.raises(ValueError, match=r"root: .*grasps: its grasp files were made on another body model"):
        train_grabnet_smplx(DATA_STUBS / "grasps", tmp_path / "grabnet.pt", epochs=1, progress=False)
    with pytest.raises(ValueError, match=r"data: .*grasps: its grasp files were made on another body model"):
        run_all(tmp_path / "report", data=folders, methods=("gt",), quick=True)
    assert not list(tmp_path.iterdir())


def test_clip_readers_refuse_clips_recorded_as_made_on_another_body(big, tmp_path):
    """Motion clips (AMASS's layout) carry nothing of the body that made them: `graspkit data make`'s record
    (graspkit_make_<kind>.json, the body's digest) is the witness. WANDR's clip sets and MotionFill's windows read a
    folder recorded as made on graspkit's body when posing it on that body, and refuse it, naming the folder and
    both digests, on another; a folder without the record (the stubs) is read on any body."""
    import shutil

    from graspkit.body import BodyModel
    from graspkit.data.cli import claim_folder
    from graspkit.data.wandr_dataset import cached_clips
    from graspkit.eval_motionfill import windows

    shipped, other = BodyModel.from_file(PROCEDURAL_MODEL), BodyModel.from_file(big)
    stubs = sorted((DATA_STUBS / "motion" / "locomotion").glob("locomotion_*.npz"))[:2]
    for name in ("plain", "motion"):
        folder = tmp_path / name / "locomotion"
        folder.mkdir(parents=True)
        if name == "motion":                                   # as `data make` records it, before its first file
            claim_folder(folder, "locomotion", {"seed": 0, "model": str(PROCEDURAL_MODEL)})
        for p in stubs:
            shutil.copy(p, folder / p.name)
    assert len(cached_clips(tmp_path / "plain", other, cache=tmp_path / "c", kinds=("locomotion",)).names) == 2
    assert len(cached_clips(tmp_path / "motion", shipped, cache=tmp_path / "c", kinds=("locomotion",)).names) == 2
    want = rf"folder: {folder}'s locomotion clips were made on another body model than {big} \(its " \
           rf"graspkit_make_locomotion.json records body {shipped.digest()}, this one is {other.digest()}"
    with pytest.raises(ValueError, match=want):
        cached_clips(tmp_path / "motion", other, cache=tmp_path / "c", kinds=("locomotion",))
    with pytest.raises(ValueError, match=want):
        windows("locomotion", 2, other, data=folder, progress=False)
    assert windows("locomotion", 2, shipped, data=folder, progress=False)["local"].shape[0] > 0
