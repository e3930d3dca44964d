"""Static grasp synthesis end to end, checked with independent geometry (trimesh) and the motion of the approach."""
import numpy as np
import pytest
import torch
import trimesh

from graspkit import metrics as M
from graspkit.body import BodyModel
from graspkit.body.skeleton import JOINT_INDEX as J
from graspkit.data.approach import approach_motion
from graspkit.data.grasp import GRASP_PARTS, SPLITS, GraspFitter, grasp_candidates, grasp_types, split_of
from graspkit.data.grasp_make import accepted, fit_chunk
from graspkit.data.rig import build_rig
from graspkit.objects import TEST_OBJECTS, apply_pose, list_objects, make_object, signed_distance

from conftest import PROCEDURAL_MODEL


def test_splits_follow_grab_and_cover_the_catalogue():
    names = [n for s in SPLITS.values() for n in s]
    assert sorted(names) == list_objects() and len(set(names)) == len(names)
    assert set(SPLITS["test"]) == set(TEST_OBJECTS) and set(SPLITS["val"]) == {"apple", "toothbrush"}
    assert split_of("mug") == "test" and split_of("pitcher") == "train"
    with pytest.raises(ValueError, match="name"):
        split_of("elephant")
    for name in ("mug", "frying_pan", "pitcher", "power_drill"):
        assert "handle" in grasp_types(name)


def test_grasp_frames_lie_on_the_object():
    """Palm frames sit on the surface, pinch points inside or at it (trimesh's signed distance), axes as declared."""
    for name in sorted(GRASP_PARTS):
        mesh = make_object(name)
        for t in grasp_types(name):
            c = grasp_candidates(name, t)
            d = -trimesh.proximity.signed_distance(mesh, c.p)                    # trimesh: > 0 inside
            if t == "pinch":
                assert d.max() <= 0.0051, f"{name} {t}: a pinch point {d.max() * 100:.1f} cm outside"
            else:
                assert np.abs(d).max() <= 0.0101, f"{name} {t}: a palm point {np.abs(d).max() * 100:.1f} cm off the surface"
            assert np.allclose(np.linalg.norm(c.s, axis=1), 1) and np.allclose(np.linalg.norm(c.y, axis=1), 1)
            thumb = np.array([k == "thumb" for k in c.kind])
            assert np.abs((c.s * c.y).sum(1))[thumb].max(initial=0.0) < 1e-9


@pytest.fixture(scope="module")
def fitted(tmp_path_factory):
    """A chunk of two apple grasps as the generator makes them (fit, evaluate, retry failures); the SDF grid comes from
    data_stubs/sdf and nothing is written to the user's cache."""
    mp = pytest.MonkeyPatch()
    mp.setenv("GRASPKIT_CACHE", str(tmp_path_factory.mktemp("cache")))
    torch.set_num_threads(1)
    bm = BodyModel.from_file(PROCEDURAL_MODEL)
    fitter = GraspFitter(bm, steps=40)
    best = fit_chunk(fitter, "grasp", 0, 0, size=2, objects=("apple",))
    mp.undo()
    return bm, fitter, [b[0] for b in best], [b[2] for b in best]


def test_quality_figures_agree_with_trimesh_and_manifold(fitted):
    """evaluate()'s depth and volume against trimesh's signed distance and manifold3d's exact intersection; the
    accepted grasps touch (2 mm), are at most 5 mm deep and stand on both feet."""
    bm, fitter, res, ok = fitted
    assert any(ok)
    V = fitter.vertices(res).double().numpy()
    faces = bm.faces.numpy()
    for r, v, good in zip(res, V, ok):
        obj = apply_pose(r.task.object_pose, make_object("apple"))
        sd = trimesh.proximity.signed_distance(obj, v[fitter.hm.hand_ids])          # trimesh: > 0 inside
        assert abs(max(sd.max(), 0) * 100 - r.quality["depth_cm"]) < 0.05
        inter = trimesh.boolean.intersection([trimesh.Trimesh(v, faces, process=False), obj], engine="manifold")
        vol = 0.0 if inter.is_empty else inter.volume * 1e6
        assert abs(vol - r.quality["volume_cm3"]) < 0.05 + 0.05 * vol
        assert good == accepted(r.quality, r.task.grasp_type)
        if good:
            assert -0.002 <= sd.max() < 0.005, "the hand touches the apple, at most 5 mm deep"
            for foot in ("left_ankle", "right_ankle"):                               # both feet on the ground
                ids = np.flatnonzero(bm.lbs_weights.argmax(1).numpy() == J[foot])
                assert abs(v[ids, 2].min()) < 0.01


def test_pelvis_over_the_feet_and_head_towards_the_object(fitted):
    bm, fitter, res, _ = fitted
    from graspkit.rotations import axis_angle_to_matrix
    for r in res:
        out = bm.forward_rotmats(axis_angle_to_matrix(torch.as_tensor(r.poses))[None], betas=torch.as_tensor(r.betas[None]),
                                 transl=torch.as_tensor(r.trans[None]))
        j = out.joints[0].detach().numpy()
        feet = j[[J["left_ankle"], J["right_ankle"], J["left_foot"], J["right_foot"]], :2]
        lo, hi = feet.min(0) - 0.08, feet.max(0) + 0.08
        assert np.all(j[0, :2] >= lo) and np.all(j[0, :2] <= hi), "pelvis over the support area"
        from graspkit.body.markers import goal_vertices
        q = goal_vertices(bm).head_direction(out.vertices)[0].detach().numpy()
        to = r.task.object_pose.translation - j[J["head"]]
        assert q @ to / np.linalg.norm(to) > np.cos(np.deg2rad(45)), "the head looks at the object"


def test_the_approach_clip_walks_in_and_holds_the_grasp(fitted):
    bm, fitter, res, _ = fitted
    r = res[0]
    m = approach_motion(r.plan, r.grasp_frame, r.poses, r.init_poses[40:55], "t_pose", r.approach_dir,
                        build_rig(bm, r.task.betas))
    g = r.grasp_frame
    assert m.num_frames == r.plan.num_frames and np.allclose(m.poses[g:], r.poses, atol=1e-5)
    arms = [J[n] for n in ("left_shoulder", "right_shoulder", "left_elbow", "right_elbow")]
    assert np.abs(m.poses[0, arms]).max() < 1e-6, "GRAB's T-pose start"
    w = m.joint_positions(bm)[:, J["right_wrist"]]
    assert np.linalg.norm(np.diff(w, axis=0), axis=1).max() < 0.085, "no jumps (wrist < 2.5 m/s)"
    va, vp = m.vertices(bm), r.plan.vertices(bm)
    assert M.foot_skating_wandr(va).mean() == M.foot_skating_wandr(vp).mean()   # the planner's feet
    obj = apply_pose(r.task.object_pose, make_object("apple"))
    hand = va[g - 15:g, fitter.hm.hand_ids].double()                              # the open hand comes in from outside
    depth = max(0.0, -float(min(signed_distance(h, obj).min() for h in hand)))
    assert depth < 0.005, f"the approaching hand is {depth * 100:.1f} cm inside the apple"


def test_goal_labels_against_kd_trees():
    """GOAL's labels of a grasp frame (Eq. 2): b^o is the BPS of the object points minus the object translation, and
    the offsets go from each of the 400 vertices to its closest object point (scipy KD-trees on the object's own
    sampled points)."""
    import math

    from scipy.spatial import cKDTree

    from graspkit.body.markers import goal_vertices
    from graspkit.data.grasp import object_points
    from graspkit.data.grasp_make import frame_labels
    from graspkit.objects.bps import bps_basis
    from graspkit.objects.placement import ObjectPose
    from graspkit.optim.grasppose import hand_vertex_ids
    from graspkit.rotations import axis_angle_to_matrix

    bm = BodyModel.from_file(PROCEDURAL_MODEL, flat_hand_mean=True)
    aa = torch.zeros(1, 55, 3, dtype=bm.dtype)
    aa[0, 0] = torch.tensor([math.pi / 2, 0, 0])
    V = bm.forward_rotmats(axis_angle_to_matrix(aa), betas=torch.zeros(1, 10, dtype=bm.dtype),
                           transl=torch.zeros(1, 3, dtype=bm.dtype)).vertices[0].double()
    pose = ObjectPose.from_yaw(0.7, (0.25, -0.55, 0.95))
    lab = frame_labels(bm, V, "mug", pose, hand_vertex_ids(bm))
    centred = object_points("mug")[0] @ pose.rotation.T                  # = world points - translation
    np.testing.assert_allclose(lab["goal.bps_object"], cKDTree(centred).query(bps_basis().double().numpy())[0],
                               atol=1e-5)
    world = centred + pose.translation
    v400 = V[torch.as_tensor(goal_vertices(bm).vertex_ids)].numpy()
    _, idx = cKDTree(world).query(v400)
    np.testing.assert_allclose(lab["goal.offsets"], world[idx] - v400, atol=1e-5)


def test_two_touching_regions_are_not_a_grasp():
    """The acceptance rule: a non-pinch grasp needs at least three regions (palm, pads) within 3 mm."""
    base = {"contact": 1.0, "depth_cm": 0.1, "volume_cm3": 0.5, "feet_cm": 0.2, "arm_residual_deg": 10.0}
    assert not accepted({**base, "regions_mm": [2.0, 2.0, 9.0, 9.0, 9.0, 9.0]}, "power")
    assert accepted({**base, "regions_mm": [2.0, 2.0, 2.0, 9.0, 9.0, 9.0]}, "power")


def test_builder_centre_maps_the_builder_mesh_onto_the_catalogue_mesh():
    """builder_centre is the builder mesh's bounding-box centre: moved by it, the builder's mesh has the catalogue
    mesh's bounds (make_object puts the origin at the box centre)."""
    from graspkit.data.grasp import builder_centre
    from graspkit.objects.catalogue import SPECS

    for name in sorted(GRASP_PARTS):
        v = np.asarray(SPECS[name].build().to_mesh().vert_properties, np.float64)[:, :3]
        canon = make_object(name)
        np.testing.assert_allclose(v.min(0) - builder_centre(name), canon.bounds[0], atol=1e-6, err_msg=name)
        np.testing.assert_allclose(v.max(0) - builder_centre(name), canon.bounds[1], atol=1e-6, err_msg=name)
