"""The shipped samples (data_stubs/grasps, data_stubs/approach, made by `graspkit data make`): a third party rebuilds a
scene with smplx + trimesh alone, the labels agree with the body model, the datasets read them."""
from pathlib import Path

import numpy as np
import pytest
import smplx
import torch
import trimesh
from scipy.spatial.transform import Rotation

from graspkit.body import BodyModel
from graspkit.body.markers import saga_sparse_markers
from graspkit.body.skeleton import SMPLX_LANDMARK_VERTEX_IDS
from graspkit.data.grab import load_grasp_sequence
from graspkit.data.grasp_datasets import ApproachDataset, GNetDataset, WholeGraspDataset
from graspkit.eval_goal import _body
from graspkit.objects.contact import MARKER_CONTACT_THRESHOLD

from conftest import PROCEDURAL_MODEL

STUBS = Path(__file__).resolve().parents[1] / "data_stubs"
GRASPS = sorted((STUBS / "grasps").glob("grasp_*.npz"))
APPROACH = sorted((STUBS / "approach").glob("approach_*.npz"))
PARAMS = ("global_orient", "body_pose", "jaw_pose", "leye_pose", "reye_pose", "left_hand_pose", "right_hand_pose",
          "transl", "expression")


def test_samples_are_shipped():
    assert len(GRASPS) >= 8 and len(APPROACH) >= 2
    assert sum(p.stat().st_size for p in (STUBS / "grasps").rglob("*") if p.is_file()) < 3e6


@pytest.mark.parametrize("path", GRASPS[:1] + GRASPS[-1:], ids=lambda p: p.stem)
def test_a_scene_rebuilt_with_smplx_and_trimesh_alone(path):
    """Grasp file + procedural body file + PLY: contact, penetration and the contact labels recomputed independently."""
    z = dict(np.load(path, allow_pickle=False))
    model = smplx.create(str(STUBS / "body_models"), model_type="smplx", gender="neutral", ext="npz", use_pca=False,
                         flat_hand_mean=True, num_betas=10, dtype=torch.float64)
    out = model(betas=torch.as_tensor(z["body.betas"][None], dtype=torch.float64),
                **{k: torch.as_tensor(z[f"body.params.{k}"], dtype=torch.float64) for k in PARAMS})
    v = out.vertices[0].detach().numpy()
    body = trimesh.Trimesh(v, model.faces, process=False)
    obj = trimesh.load(path.parent / str(z["object.object_mesh"]), process=False)
    R = Rotation.from_rotvec(z["object.params.global_orient"][0]).as_matrix()
    t = z["object.params.transl"][0].astype(np.float64)
    obj.apply_transform(np.block([[R, t[:, None]], [np.zeros((1, 3)), np.ones((1, 1))]]))
    inter = trimesh.boolean.intersection([body, obj], engine="manifold")
    vol = 0.0 if inter.is_empty else inter.volume * 1e6
    assert abs(vol - float(z["grasp.quality.volume_cm3"])) < 0.05 + 0.05 * vol
    near = np.all((v > obj.bounds[0] - 0.03) & (v < obj.bounds[1] + 0.03), axis=1)
    sd = trimesh.proximity.signed_distance(obj, v[near])                       # > 0 inside
    assert abs(max(sd.max(), 0.0) * 100 - float(z["grasp.quality.depth_cm"])) < 0.02
    assert sd.max() > -0.002 and sd.max() < 0.005                              # in contact, at most 5 mm deep
    pts = z["object.points"].astype(np.float64) @ R.T + t                      # C_O: object points within 1 cm of the body
    _, dist, _ = trimesh.proximity.closest_point(body, pts)
    assert np.mean((dist <= 0.01) == z["contact.object"][0].astype(bool)) > 0.995
    markers = v[z["saga.marker_ids"]]                                          # C_M: markers within 2 cm of the object
    assert np.abs(markers - z["saga.markers"]).max() < 1e-5
    _, dm, _ = trimesh.proximity.closest_point(obj, markers)
    assert np.mean((dm <= 0.02) == z["contact.markers"][0].astype(bool)) > 0.99


def test_goal_labels_agree_with_the_body_model():
    bm = BodyModel.from_file(PROCEDURAL_MODEL, dtype=torch.float64)
    for path in GRASPS[:4]:
        s = load_grasp_sequence(path)
        assert bool(s.extras["grasp.accepted"]) and (path.parent / s.object_mesh).is_file()
        v = torch.as_tensor(s.poses, dtype=torch.float64)
        from graspkit.rotations import axis_angle_to_matrix
        V = bm.forward_rotmats(axis_angle_to_matrix(v), betas=torch.as_tensor(s.betas[None], dtype=torch.float64),
                               transl=torch.as_tensor(s.trans, dtype=torch.float64)).vertices[0].numpy()
        e = s.extras
        # the files' 400 vertices are the ones GOAL's networks use (eval_goal builds a flat-hand model)
        np.testing.assert_array_equal(e["goal.vertex_ids"], _body()[1].vertex_ids)
        verts = V[e["goal.vertex_ids"]]
        assert np.abs(verts - e["goal.vertices"]).max() < 1e-5
        pts = s.object_points.astype(np.float64) @ s.object_rotation()[0].T + s.object_transl[0]
        nearest = pts[np.argmin(((verts[:, None] - pts[None]) ** 2).sum(-1), axis=1)]
        assert np.abs(nearest - verts - e["goal.offsets"]).max() < 1e-4
        assert np.array_equal(e["goal.hand_offsets"], e["goal.offsets"][e["goal.right_hand"]])
        assert abs(float(e["object.height"]) - s.object_transl[0, 2]) < 1e-6
        q, to = e["goal.head_direction"], s.object_transl[0] - V[SMPLX_LANDMARK_VERTEX_IDS["nose"]]
        assert abs(np.linalg.norm(q) - 1) < 1e-5 and q @ to / np.linalg.norm(to) > np.cos(np.deg2rad(45))


def test_the_datasets_read_the_samples():
    wg = WholeGraspDataset(STUBS / "grasps", split=None)
    a = dict(np.load(GRASPS[0], allow_pickle=False))
    assert np.allclose(wg[0]["markers"].numpy() + a["object.params.transl"][0], a["saga.markers"], atol=1e-6)
    assert wg[0]["object_points"].shape == (2048, 3) and wg[0]["object_contacts"].shape == (2048,)
    with pytest.raises(ValueError, match="root"):
        WholeGraspDataset(STUBS / "grasps", split="val")                     # mug (test) and pitcher (train) only
    gn = GNetDataset(STUBS / "grasps", split=None)
    assert gn[0]["fullpose_6d"].shape == (55, 6) and gn[0]["bps_object"].shape == (1024,)
    bm = BodyModel.from_file(PROCEDURAL_MODEL)
    ap = ApproachDataset(STUBS / "approach", split=None, bm=bm)
    item = ap[0]
    g = int(item["goal_frame"])
    assert item["fullpose"].shape == (62, 55, 3) and 0 <= g < 62
    assert item["hand_to_goal"][g:].abs().max() < 1e-4                      # the grasp is held from the goal frame on
    assert item["foot_contacts"][g:].all()
    whole = ApproachDataset(STUBS / "approach", split=None, window=None)
    assert whole[0]["fullpose"].shape[0] == len(load_grasp_sequence(APPROACH[0]).poses)


def test_approach_window_goal_frame_and_hand_to_goal():
    """In a window that holds the clip's goal frame as its 21st frame, goal_frame is 20 (the file's pose there),
    and hand_to_goal is the goal hand minus the current hand (GOAL's d^h): at frame 0, rebuilt by smplx, the current
    right hand plus hand_to_goal is the goal hand."""
    z = dict(np.load(APPROACH[0], allow_pickle=False))
    T, g = len(z["body.params.transl"]), int(z["grasp.goal_frame"])
    window = T - g + 20
    assert window < T
    item = ApproachDataset(STUBS / "approach", split=None, window=window, bm=BodyModel.from_file(PROCEDURAL_MODEL))[0]
    assert int(item["goal_frame"]) == 20
    np.testing.assert_allclose(item["fullpose"][20].numpy().reshape(-1), z["body.params.fullpose"][g], atol=1e-6)
    k = T - window                                               # the window's frame 0 in the clip
    model = smplx.create(str(STUBS / "body_models"), model_type="smplx", gender="neutral", ext="npz", use_pca=False,
                         flat_hand_mean=True, num_betas=10, dtype=torch.float64)
    with torch.no_grad():
        v = model(betas=torch.as_tensor(z["body.betas"][None], dtype=torch.float64),
                  **{p: torch.as_tensor(z[f"body.params.{p}"][k:k + 1], dtype=torch.float64) for p in PARAMS}
                  ).vertices[0].numpy()
    rh = z["goal.right_hand"]
    hand_now, goal_hand = v[z["goal.vertex_ids"]][rh], z["goal.vertices"][rh]
    assert np.linalg.norm(goal_hand - hand_now, axis=1).mean() > 0.02      # the hand is still on its way
    np.testing.assert_allclose(hand_now + item["hand_to_goal"][0].numpy(), goal_hand, atol=1e-4)


def test_object_points_are_turned_by_the_object_pose():
    """WholeGraspDataset's object points and normals are world-oriented ('the object is rotated by its pose'): the stored
    object-frame points turned by the object's axis-angle orientation (scipy), so the in-contact markers lie on them."""
    ds = WholeGraspDataset(STUBS / "grasps", split=None)
    for i, f in enumerate(ds.files[:2]):
        a = np.load(f, allow_pickle=False)
        R = Rotation.from_rotvec(a["object.params.global_orient"][0].astype(np.float64))
        assert R.magnitude() > 0.5                                  # a turned object: R and R^T differ
        np.testing.assert_allclose(ds[i]["object_points"].numpy(), R.apply(a["object.points"]), atol=1e-5)
        np.testing.assert_allclose(ds[i]["object_normals"].numpy(), R.apply(a["object.normals"]), atol=1e-5)
        touching = ds[i]["marker_contacts"].numpy() > 0.5
        assert touching.sum() > 0
        d = np.linalg.norm(ds[i]["markers"].numpy()[touching][:, None] - ds[i]["object_points"].numpy()[None], axis=-1)
        assert d.min(1).max() < MARKER_CONTACT_THRESHOLD + 0.01    # in contact: within 2 cm of the surface (+ spacing)


def test_approach_markers_are_the_mesh_at_the_saga_marker_ids():
    """ApproachDataset(bm=...)['markers'] (T,79,3): SAGA's stage-2 markers, i.e. the posed mesh (smplx, flat hand mean,
    as the file's parameters) at saga_sparse_markers' vertex ids, on the first and the last frame of the clip."""
    bm = BodyModel.from_file(PROCEDURAL_MODEL)
    item = ApproachDataset(STUBS / "approach", split=None, window=None, bm=bm)[0]
    z = dict(np.load(APPROACH[0], allow_pickle=False))
    T = len(z["body.params.transl"])
    ids = saga_sparse_markers(bm).vertex_ids
    assert item["markers"].shape == (T, len(ids), 3)
    model = smplx.create(str(STUBS / "body_models"), model_type="smplx", gender="neutral", ext="npz", use_pca=False,
                         flat_hand_mean=True, num_betas=10, dtype=torch.float64)
    for k in (0, T - 1):
        with torch.no_grad():
            v = model(betas=torch.as_tensor(z["body.betas"][None], dtype=torch.float64),
                      **{p: torch.as_tensor(z[f"body.params.{p}"][k:k + 1], dtype=torch.float64) for p in PARAMS}
                      ).vertices[0].numpy()
        np.testing.assert_allclose(item["markers"][k].numpy(), v[ids], atol=1e-4)
