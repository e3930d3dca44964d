"""Whole-sequence exports (graspkit.viz.export_motion): the AMASS-style npz read back by the smplx package and the
GLB files read back by trimesh give the same bodies as graspkit."""
from pathlib import Path

import numpy as np
import pytest
import smplx
import torch
import trimesh

from graspkit.body import BodyModel
from graspkit.data import load_motion
from graspkit.viz.export import Z_UP_TO_Y_UP, export_motion, load_sequence_glb

from conftest import PROCEDURAL_MODEL

CLIP = sorted((Path(__file__).resolve().parents[1] / "data_stubs" / "motion" / "reach").glob("*.npz"))[0]


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    bm = BodyModel.from_file(PROCEDURAL_MODEL, flat_hand_mean=True)
    full = load_motion(CLIP)
    m = full.slice(max(0, full.goal_frame - 20), full.goal_frame + 1)          # the last 21 frames of the reach
    box = trimesh.creation.box((0.1, 0.1, 0.1))
    box.apply_translation(full.goal)
    folder = tmp_path_factory.mktemp("export")
    return m, bm, box, export_motion(m, bm, folder, "reach", objects={"box": box}, stride=5)


def test_npz_in_smplx_gives_graspkit_vertices(exported):
    m, bm, _, paths = exported
    with np.load(paths["npz"], allow_pickle=False) as z:
        poses, trans, betas = (torch.as_tensor(z[k], dtype=torch.float64) for k in ("poses", "trans", "betas"))
    T = len(poses)
    ref = smplx.create(str(PROCEDURAL_MODEL.parents[1]), model_type="smplx", gender="neutral", ext="npz", use_pca=False,
                       flat_hand_mean=True, num_betas=10, batch_size=T, dtype=torch.float64)
    out = ref(betas=betas[None].expand(T, -1), global_orient=poses[:, :3], body_pose=poses[:, 3:66],
              jaw_pose=poses[:, 66:69], leye_pose=poses[:, 69:72], reye_pose=poses[:, 72:75],
              left_hand_pose=poses[:, 75:120], right_hand_pose=poses[:, 120:165], transl=trans,
              expression=torch.zeros(T, 10, dtype=torch.float64))
    ours = m.vertices(bm).double()
    assert T == m.num_frames and (ours - out.vertices).abs().max() < 1e-4


def test_npz_per_part_keys_pose_the_same_body_in_smplx(exported):
    """A loader that reads AMASS's per-part keys (root_orient, pose_body, pose_jaw, pose_eye, pose_hand) instead of
    `poses` gets the same vertices from smplx as graspkit's own; the keys carry the file's length and shape size."""
    m, bm, _, paths = exported
    with np.load(paths["npz"], allow_pickle=False) as z:
        k = {n: torch.as_tensor(z[n], dtype=torch.float64) for n in
             ("root_orient", "pose_body", "pose_jaw", "pose_eye", "pose_hand", "trans", "betas")}
        assert int(z["num_betas"]) == 10 and abs(float(z["mocap_time_length"]) - m.num_frames / m.fps) < 1e-9
    T = len(k["trans"])
    ref = smplx.create(str(PROCEDURAL_MODEL.parents[1]), model_type="smplx", gender="neutral", ext="npz", use_pca=False,
                       flat_hand_mean=True, num_betas=10, batch_size=T, dtype=torch.float64)
    out = ref(betas=k["betas"][None].expand(T, -1), global_orient=k["root_orient"], body_pose=k["pose_body"],
              jaw_pose=k["pose_jaw"], leye_pose=k["pose_eye"][:, :3], reye_pose=k["pose_eye"][:, 3:],
              left_hand_pose=k["pose_hand"][:, :45], right_hand_pose=k["pose_hand"][:, 45:], transl=k["trans"],
              expression=torch.zeros(T, 10, dtype=torch.float64))
    assert (m.vertices(bm).double() - out.vertices).abs().max() < 1e-4
    assert load_motion(paths["npz"]).num_frames == m.num_frames          # the reader still takes the file


def test_glb_files_read_back_with_trimesh(exported):
    m, bm, box, paths = exported
    v = m.vertices(bm).numpy()
    frames, faces, times = load_sequence_glb(paths["glb"])
    assert np.array_equal(faces, bm.faces.numpy())
    kept = sorted(set(range(0, m.num_frames, 5)) | {m.num_frames - 1})     # every 5th frame and the last
    assert len(frames) == len(kept) and np.abs(frames - v[kept]).max() < 1e-4
    assert np.allclose(times, np.array(kept) / m.fps)
    scene = trimesh.load(paths["final_glb"])
    geoms = dict(scene.geometry)
    assert set(geoms) == {"body", "box"}
    body = geoms["body"]
    assert len(body.vertices) == v.shape[1]
    assert np.abs(np.asarray(body.vertices) - v[-1] @ Z_UP_TO_Y_UP.T).max() < 1e-4
    assert np.abs(np.asarray(geoms["box"].vertices) - box.vertices @ Z_UP_TO_Y_UP.T).max() < 1e-5
    static = trimesh.load(paths["glb"])                      # a viewer without animation shows frame 0
    assert np.abs(np.asarray(next(iter(static.geometry.values())).vertices) - v[0] @ Z_UP_TO_Y_UP.T).max() < 1e-4


def test_bad_name_is_refused(exported, tmp_path):
    m, bm, _, _ = exported
    with pytest.raises(ValueError, match="name"):
        export_motion(m, bm, tmp_path, "../escape")
