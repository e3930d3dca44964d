"""Grasp and approach files made on one body, read with another: `graspkit.data.grab.body_offset` against the smplx
package, and every reader that poses the files' grasps on the body GRASPKIT_MODEL names refuses another body's."""
from __future__ import annotations

import numpy as np
import pytest

from conftest import PROCEDURAL_MODEL, npz_copy, relabelled, smplx_posed
from graspkit.paths import DATA_STUBS

GRASP = DATA_STUBS / "grasps" / "grasp_000000.npz"
APPROACH = DATA_STUBS / "approach" / "approach_000000.npz"


def _smplx_offset(model, path) -> float:
    """body_offset's figure with the smplx package's vertices: the largest distance between GOAL's stored vertices and
    the file's grasp-frame vertices taken back by the object's move since the labels, at the best of 11 points on each
    segment to a neighbouring frame."""
    with np.load(path, allow_pickle=False) as z:
        a = {k: z[k] for k in z.files}
    f = int(a.get("grasp.goal_frame", a.get("grasp.frame", 0)))
    lo, hi = max(f - 1, 0), min(f + 2, len(a["body.params.fullpose"]))
    n = hi - lo
    v, _ = smplx_posed(model, a["body.params.fullpose"][lo:hi], a["body.params.transl"][lo:hi], a["body.betas"])
    v = v[:, a["goal.vertex_ids"]] - (a["object.params.transl"][lo:hi] - a["goal.object_transl"])[:, None]
    pairs = [(k, k + 1) for k in range(n - 1)] or [(0, 0)]             # a one-frame grasp file: that frame
    return min(float(np.linalg.norm((1 - w) * v[i] + w * v[j] - a["goal.vertices"], axis=1).max())
               for i, j in pairs for w in np.linspace(0, 1, 11))


def test_body_offset_is_what_smplx_measures(big, tmp_path):
    """On graspkit's body (which made the stubs) a grasp or approach file's stored GOAL vertices are its vertices to
    a micrometre, also with the whole clip (body and object) moved; with the body alone moved, by the move; on a body
    8 % larger they lie 8-9 cm off, as the smplx package poses that body. A file without GOAL's labels gives None, one
    of another mesh layout infinity."""
    from graspkit.body import BodyModel
    from graspkit.data.grab import MADE_ON_TOL, body_offset

    shipped, other = BodyModel.from_file(PROCEDURAL_MODEL), BodyModel.from_file(big)
    for path in (GRASP, APPROACH):
        assert body_offset(shipped, path) < 1e-5 and _smplx_offset(PROCEDURAL_MODEL, path) < 1e-5
        off = body_offset(other, path)
        assert off == pytest.approx(_smplx_offset(big, path), abs=1e-5) and off > 50 * MADE_ON_TOL
    with np.load(APPROACH, allow_pickle=False) as z:
        transl, obj = z["body.params.transl"], z["object.params.transl"]
    d = np.array([0.5, -1.0, 0.02])
    moved = npz_copy(APPROACH, tmp_path / "moved.npz", **{"body.params.transl": transl + d,     # body and object
                                                           "object.params.transl": obj + d})
    assert body_offset(shipped, moved) < 1e-5 and _smplx_offset(PROCEDURAL_MODEL, moved) < 1e-5
    apart = npz_copy(APPROACH, tmp_path / "apart.npz", **{"body.params.transl": transl + d})    # the body alone
    assert body_offset(shipped, apart) == pytest.approx(np.linalg.norm(d), abs=1e-5)
    assert _smplx_offset(PROCEDURAL_MODEL, apart) == pytest.approx(np.linalg.norm(d), abs=1e-5)
    with np.load(PROCEDURAL_MODEL, allow_pickle=False) as z:            # the template 5 cm aside (re-centred)
        side = BodyModel.from_file(npz_copy(PROCEDURAL_MODEL, tmp_path / "side.npz",
                                            v_template=z["v_template"] + 0.05 * np.eye(3)[0]))
    assert body_offset(side, APPROACH) == pytest.approx(0.05, abs=1e-4)
    assert body_offset(shipped, npz_copy(GRASP, tmp_path / "own.npz", **{"goal.vertices": None})) is None
    with np.load(GRASP, allow_pickle=False) as z:
        ids = z["goal.vertex_ids"].copy()
    ids[0] = 10475
    assert body_offset(shipped, npz_copy(GRASP, tmp_path / "far.npz", **{"goal.vertex_ids": ids})) == float("inf")


def test_readers_refuse_grasps_made_on_another_body(big, tmp_path, monkeypatch):
    """With GRASPKIT_MODEL naming another body than the one that made the data, GOAL's readers (training and
    evaluation), SAGA's evaluation and its GrabNet-SMPLX baseline's training, MotionFill's approach windows and
    `eval --all` refuse, naming the folder, before anything is written: until 2026-12-07 they posed graspkit's grasps
    on that body (6-8 cm under the floor, the hand 9 cm from where it held the object) and measured them there."""
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


def test_every_folder_and_every_reader_of_the_benchmark_is_checked(big, tmp_path):
    """`eval --all` checks every --data folder (its ground-truth and motion rows read them all; until 2026-12-07 only
    the first grasp and approach folders were), and the rows' own readers (the ground truth's grasps, the planner's
    clips) and GraspMotion-Opt's approach scenes refuse another body's files when called alone (lesson 10 calls the
    first two): the ground truth of graspkit's stubs measured on a body 5 % larger had contact 0.75 and 3.6 cm³."""
    from graspkit.benchmark import ground_truth_grasps, planner_motion, run_all
    from graspkit.body import BodyModel
    from graspkit.eval_motionfill import approach_scene

    shipped, other = BodyModel.from_file(PROCEDURAL_MODEL), BodyModel.from_file(big)
    theirs = relabelled(DATA_STUBS / "grasps", tmp_path / "theirs", other)
    with pytest.raises(ValueError, match=rf"data: {theirs}: its grasp files were made on another body model"):
        run_all(tmp_path / "report", data=[DATA_STUBS / "grasps", DATA_STUBS / "approach", theirs], methods=("gt",),
                quick=True)
    assert not (tmp_path / "report").exists()
    assert ground_truth_grasps(other, [theirs], n=2).values["contact_ratio"] > 0      # on the body that made them
    with pytest.raises(ValueError, match=r"data: .*grasps: its grasp files were made on another body model"):
        ground_truth_grasps(other, [DATA_STUBS / "grasps"], n=2)
    with pytest.raises(ValueError, match=r"data: .*approach: its approach files were made on another body model"):
        planner_motion(other, [DATA_STUBS / "approach"], n=1)
    clip = DATA_STUBS / "approach" / "approach_000000.npz"
    assert approach_scene(clip, shipped)["markers"].shape == (61, 79, 3)
    with pytest.raises(ValueError, match=r"path: .*approach_000000.npz: its approach files were made on another"):
        approach_scene(clip, other)


@pytest.mark.parametrize("fps", [15.0, 20.0, 60.0])
def test_a_clip_resampled_on_its_own_body_is_still_its_own(fps, tmp_path):
    """An approach clip read at another frame rate (slerp, its goal frame rescaled and rounded) and saved again holds
    the labelled instant between two frames: body_offset interpolates there and finds the body that made it (a
    micrometre; at the rounded frame alone 1.3-4.6 mm, refused by the 1 mm rule), and the readers take it."""
    from graspkit.body import BodyModel
    from graspkit.data.grab import MADE_ON_TOL, body_offset, load_grasp_sequence, save_grasp_sequence
    from graspkit.eval_goal import _files

    path = save_grasp_sequence(tmp_path / "approach_000000.npz", load_grasp_sequence(APPROACH, fps=fps))
    assert body_offset(BodyModel.from_file(PROCEDURAL_MODEL), path) < MADE_ON_TOL / 10
    assert len(_files(tmp_path, "approach", None)) == 1
