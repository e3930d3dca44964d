"""Static grasp synthesis end to end, checked with independent geometry (trimesh) and the motion of the approach."""
import dataclasses
import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import torch
import trimesh
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from graspkit import metrics as M
from graspkit.body import BodyModel
from graspkit.body.markers import palm_vertices
from graspkit.body.skeleton import JOINT_INDEX as J
from graspkit.data import Motion
from graspkit.data import grasp as G
from graspkit.data import grasp_make as gm
from graspkit.data.approach import GRASP_CLOSE_S, TPOSE_S, _continuous, _rate_limited, approach_motion
from graspkit.data.grasp import (GRASP_PARTS, SPLITS, GraspFitter, grasp_candidates, grasp_types, object_points,
                                 object_points_world, object_radius, sample_grasp_task, split_of)
from graspkit.data.grasp_make import accepted, fit_chunk
from graspkit.data.rig import build_rig
from graspkit.objects import TEST_OBJECTS, apply_pose, list_objects, make_object, signed_distance
from graspkit.objects.bps import bps_basis
from graspkit.objects.placement import ObjectPose
from graspkit.optim.grasppose import hand_vertex_ids
from graspkit.rotations import axis_angle_to_matrix

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
    from graspkit.body.markers import goal_vertices
    from graspkit.data.grasp_make import frame_labels

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


# The approach clip's helpers against analytic cases: the axis-angle unwrapping keeps each rotation (scipy), the
# elbow's rate-limited swivel turns towards its target, and a T-pose start lowers the arms over TPOSE_S seconds.
def test_continuous_axis_angles_keep_their_rotations_across_pi():
    n = np.array([0.0, 0.6, 0.8])
    angles = np.linspace(2.6, 3.7, 12)                           # through pi: the plain log flips the axis there
    aa = Rotation.from_rotvec(angles[:, None] * n).as_rotvec()    # scipy's principal axis-angles (|aa| <= pi)
    out = _continuous(aa[:, None])[:, 0]
    same = Rotation.from_rotvec(out) * Rotation.from_rotvec(aa).inv()
    assert np.abs(same.magnitude()).max() < 1e-9                  # every frame is still its own rotation
    np.testing.assert_allclose(out, angles[:, None] * n, atol=1e-9)   # and the sequence runs on past pi


def test_rate_limited_swivel_turns_towards_the_wanted_side_at_most_max_step_per_frame():
    T, step = 6, np.deg2rad(8.0)
    axis = np.tile([0.0, 0.0, 1.0], (T, 1))
    dirs = np.tile([0.0, 1.0, 0.0], (T, 1))
    dirs[0] = [1.0, 0.0, 0.0]                                     # wanted: +x, then +y (90 deg counter-clockwise)
    out = _rate_limited(dirs, axis, step)
    ang = np.arctan2(out[:, 1], out[:, 0])
    np.testing.assert_allclose(ang, step * np.arange(T), atol=1e-12)


def test_a_t_pose_start_lowers_the_arms_over_tpose_s():
    T, fps = 60, 30.0
    poses = np.zeros((T, 55, 3))
    poses[:, J["left_shoulder"]] = [0.0, 0.0, -1.1]               # the plan's arm, down from the T-pose
    poses[:, J["left_elbow"]] = [0.0, 0.4, 0.0]
    plan = Motion(poses, np.zeros((T, 3)), np.zeros(10), fps)
    m = approach_motion(plan, T - 1, poses[0], np.zeros((15, 3)), start_pose="t_pose")
    for j in ("left_shoulder", "left_elbow"):
        a = m.poses[:, J[j]]
        np.testing.assert_allclose(a[0], 0.0, atol=1e-9)                                  # T-pose at the start
        np.testing.assert_allclose(a[int(round(0.5 * TPOSE_S * fps))], 0.5 * poses[0, J[j]], atol=1e-6)   # halfway
        np.testing.assert_allclose(a[int(round(TPOSE_S * fps))], poses[0, J[j]], atol=1e-6)              # lowered


# fit_chunk keeps the attempt of lowest badness when every attempt fails ("lower is better", badness's docstring),
# write_chunk writes only the missing items with index < n, and accepted() follows its docstring's thresholds.
GOOD = {"contact": True, "depth_cm": 0.2, "volume_cm3": 1.0, "feet_cm": 0.3, "arm_residual_deg": 20.0,
        "regions_mm": [2.0, 1.0, 1.5, 2.5, 9.0, 12.0]}


def test_accepted_follows_its_docstring_thresholds():
    assert gm.accepted(GOOD, "power")
    for key, bad in (("depth_cm", 0.6), ("volume_cm3", 4.5), ("feet_cm", 1.2), ("arm_residual_deg", 80.0),
                     ("contact", False)):
        assert not gm.accepted({**GOOD, key: bad}, "power"), key


def test_fit_chunk_keeps_the_least_bad_of_failed_attempts():
    depths = iter([3.0, 1.0, 4.0, 2.0])                         # attempt 0..3 all fail (depth > 0.5 cm); 1 is best

    class Fitter:
        def fit(self, tasks):
            d = next(depths)
            return [SimpleNamespace(task=t, quality={**GOOD, "depth_cm": d}) for t in tasks]

        def evaluate(self, res):
            pass

    best = gm.fit_chunk(Fitter(), "grasp", 0, 0, size=1)
    (r, attempt, ok), = best
    assert not ok and attempt == 1 and r.quality["depth_cm"] == 1.0
    assert gm.badness(r.quality) == min(gm.badness({**GOOD, "depth_cm": d}) for d in (3.0, 1.0, 4.0, 2.0))


def test_write_chunk_writes_only_the_missing_indices_below_n(tmp_path, monkeypatch):
    """n = 3, chunks of 4: chunk 0 writes items 0, 1, 2 (index < n, write_chunk's docstring), never item 3."""
    monkeypatch.setattr(gm, "export_object_ply", lambda name, folder: None)
    monkeypatch.setattr(gm, "fit_chunk", lambda fitter, kind, seed, chunk, size, objects: [(None, 0, True)] * size)
    monkeypatch.setattr(gm, "grasp_sequence", lambda *a: None)
    monkeypatch.setattr(gm, "model_name", lambda bm: "stub")

    def save(path, seq, model):
        Path(path).write_bytes(b"")
        return Path(path)
    monkeypatch.setattr(gm, "save_grasp_sequence", save)
    fitter = SimpleNamespace(bm=None, vertices=lambda results: [None] * len(results))
    gm.file_path(tmp_path, "grasp", 1).write_bytes(b"")                         # item 1 is there already
    written = gm.write_chunk(fitter, "grasp", 0, 0, tmp_path, n=3, size=4)
    assert sorted(Path(p).name for p in written) == ["grasp_000000.npz", "grasp_000002.npz"]
    assert not gm.file_path(tmp_path, "grasp", 3).exists()


def test_world_points_lie_on_the_placed_object():
    """object_points_world puts the surface points on the object as placed (x = R x + t), checked with trimesh."""
    pose = ObjectPose.from_yaw(1.1, (0.8, -0.3, 0.9))
    mesh = make_object("mug").copy()
    mesh.apply_transform(pose.matrix())
    pts = object_points_world("mug", pose)
    _, dist, _ = trimesh.proximity.closest_point(mesh, pts[::16])
    assert float(dist.max()) < 1e-5


def test_object_radius_is_horizontal():
    """object_radius is the largest horizontal distance of the canonical vertices from the centre, not the 3D one."""
    for name in ("mug", "bottle"):      # both taller than wide
        v = np.asarray(make_object(name).vertices)
        r = object_radius(name)
        np.testing.assert_allclose(r, np.hypot(v[:, 0], v[:, 1]).max(), rtol=0, atol=1e-9)
        assert r < np.linalg.norm(v, axis=1).max() - 1e-3          # not the 3D distance


def test_a_parts_facing_cone_is_in_degrees():
    """Part.facing = (direction, max angle in DEGREES) (Part's docstring): 30 deg off the direction is inside a
    40-deg cone, 50 deg is not."""
    from graspkit.data.grasp import Part, _allowed
    part = Part("test", "sphere", (0.0, 0.0, 0.0), (0.05,), ("power",), facing=((1.0, 0.0, 0.0), 40.0))
    a = np.deg2rad([0.0, 30.0, 50.0, 150.0])
    s = np.stack([np.cos(a), np.sin(a), np.zeros_like(a)], 1)
    assert _allowed(part, s).tolist() == [True, True, False, False]


def _q(regions: list[float]) -> dict:
    """A quality record that passes every rule but the pads' contact (`regions_mm`: per pad region, mm)."""
    return {"regions_mm": regions, "contact": True, "depth_cm": 0.1, "volume_cm3": 0.5, "feet_cm": 0.2,
            "arm_residual_deg": 10.0}


def test_a_pinch_needs_the_thumb_and_the_index_or_middle_pad():
    """A pinch is accepted with the thumb AND the index or middle pad in contact (`accepted`'s docstring)."""
    far = 20.0
    assert gm.accepted(_q([far, 1.0, 1.0, far, far, far]), "pinch")           # thumb + index
    assert gm.accepted(_q([far, 1.0, far, 1.0, far, far]), "pinch")           # thumb + middle
    assert not gm.accepted(_q([far, far, 1.0, 1.0, far, far]), "pinch")      # index + middle, no thumb
    assert not gm.accepted(_q([far, 1.0, far, far, 1.0, far]), "pinch")      # thumb + ring only


class _NeverFitter:
    """Records the tasks of every fit call; every result fails acceptance (no contact)."""

    def __init__(self):
        self.calls = []

    def fit(self, tasks):
        self.calls.append(list(tasks))
        return [SimpleNamespace(task=t, quality={**_q([20.0] * 6), "contact": False, "depth_cm": 0.0}) for t in tasks]

    def evaluate(self, res):
        pass


def test_fit_chunk_tries_max_attempts_times_with_new_tasks(monkeypatch):
    """fit_chunk makes MAX_ATTEMPTS attempts in all for a fitter that never succeeds, each retry a newly drawn task."""
    monkeypatch.setattr(gm, "badness", lambda q: 1.0)
    f = _NeverFitter()
    best = gm.fit_chunk(f, "grasp", 0, 0, size=2)
    assert len(f.calls) == gm.MAX_ATTEMPTS                                  # the first attempt + MAX_ATTEMPTS - 1 retries
    assert [len(c) for c in f.calls] == [2] * gm.MAX_ATTEMPTS and not any(ok for _, _, ok in best)
    for k in range(2):                                                       # item k's task in every attempt
        tasks = [c[k] for c in f.calls]
        keys = {(float(t.choice), tuple(np.round(t.betas, 9)), float(t.start.x), float(t.start.y)) for t in tasks}
        assert len(keys) == gm.MAX_ATTEMPTS                                  # each retry draws another task


def test_the_approach_clip_opens_the_right_hand_into_its_grasp_types_pre_shape(fitted):
    """graspkit.data.approach: before closing, the fingers take the grasp type's open pre-shape (the hand path at zero
    curl, with the task's noise, grasp_opt.hand_path). In the saved approach clip, the frame just before the closing
    starts (8 frames before the grasp frame, the pre-shape blend at 99 %) holds the RIGHT hand within 0.05 rad of that
    pre-shape, built here from the grasp type and the hand axes."""
    from graspkit.data import grasp_opt as go

    bm, fitter, res, ok = fitted
    for r in res:
        t = r.task
        pre = go.hand_path(go.HAND_SHAPES[t.grasp_type], fitter.hm.axes(t.betas), np.zeros((1, 5)), t.hand_noise)[0]
        seq = gm.approach_sequence(fitter, r, fitter.vertices([r])[0], 0, 0, 0, True, "apple.ply")
        f = r.grasp_frame - 8
        assert f > 0
        got = Rotation.from_rotvec(seq.poses[f, 40:55].astype(np.float64))
        err = (got.inv() * Rotation.from_rotvec(np.asarray(pre, np.float64))).magnitude()
        assert err.max() < 0.05, err
        left = Rotation.from_rotvec(np.asarray(r.init_poses[25:40], np.float64))
        assert (left.inv() * Rotation.from_rotvec(np.asarray(pre, np.float64))).magnitude().max() > 0.2  # the case


def test_fingers_close_over_grasp_close_s_and_arrive_at_the_grasp_frame():
    """approach_motion: the fingers go plan -> open pre-shape -> grasp, starting to close GRASP_CLOSE_S before the
    grasp frame (module constants), so they arrive there: one frame before it they are within 5 % of the way, and no
    frame-to-frame change near the grasp is a snap (each < 25 % of the open -> grasp angle). Angles by scipy."""
    T, fps, g = 60, 30.0, 45
    plan = Motion(np.zeros((T, 55, 3)), np.zeros((T, 3)), np.zeros(10), fps)
    grasp = np.zeros((55, 3))
    grasp[40:55] = [0.0, 0.0, 0.9]                 # every right finger joint flexed 0.9 rad about z
    open_hand = np.tile([0.0, 0.0, -0.2], (15, 1))
    m = approach_motion(plan, g, grasp, open_hand)
    R = Rotation.from_rotvec(m.poses[:, 40:55].reshape(-1, 3).astype(np.float64)).as_matrix().reshape(T, 15, 3, 3)
    Rg = Rotation.from_rotvec(grasp[40:55]).as_matrix()

    def ang(a, b):
        return Rotation.from_matrix(np.swapaxes(a, -1, -2) @ b).magnitude()

    total = ang(Rotation.from_rotvec(open_hand).as_matrix(), Rg).max()        # 1.1 rad
    assert ang(R[g], Rg).max() < 1e-6
    assert ang(R[g - 1], Rg).max() < 0.05 * total
    k0 = g - int(round(GRASP_CLOSE_S * fps)) - 2
    steps = [ang(R[k], R[k + 1]).max() for k in range(k0, g)]
    assert max(steps) < 0.25 * total, np.round(steps, 3)


@pytest.fixture(scope="module")
def scene():
    """A standing body (flat hand mean, z up) and a mug turned about a tilted axis, its centre 2 cm from the right
    palm's centre: some of its points touch the hand; the one-frame grasp file built from them (grasp_sequence with
    stand-ins for the fitter and its result)."""
    bm = BodyModel.from_file(PROCEDURAL_MODEL, flat_hand_mean=True)
    aa = torch.zeros(1, 55, 3, dtype=bm.dtype)
    aa[0, 0] = torch.tensor([math.pi / 2, 0, 0])
    with torch.no_grad():
        V = bm.forward_rotmats(axis_angle_to_matrix(aa)).vertices[0].double()
    palm = V[palm_vertices(bm)["right"]].mean(0).numpy()
    c, s = math.cos(0.8), math.sin(0.8)
    R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]]) @ np.array([[1.0, 0, 0], [0, math.cos(0.3), -math.sin(0.3)],
                                                                  [0, math.sin(0.3), math.cos(0.3)]])
    pose = ObjectPose(palm + np.array([0.0, -0.02, 0.0]), R)
    hand_ids = hand_vertex_ids(bm)
    task = dataclasses.replace(sample_grasp_task(np.random.default_rng(0), "mug", grasp_type="power"),
                               object_pose=pose, candidate=0)
    q = {"min_distance": 0.001, "volume_cm3": 0.5, "depth_cm": 0.2, "feet_cm": 0.3,
         "regions_mm": [1.0, 1.0, 1.0, 5.0, 5.0, 5.0], "arm_residual_deg": 10.0}
    r = SimpleNamespace(task=task, poses=aa[0].numpy().astype(np.float32), trans=np.zeros(3, np.float32),
                        betas=np.zeros(10, np.float32), curls=np.full(5, 0.5), quality=q)
    fitter = SimpleNamespace(bm=bm, hm=SimpleNamespace(hand_ids=hand_ids))
    seq = gm.grasp_sequence(fitter, r, V, 0, 0, 0, True, "meshes/mug.ply")
    lab = gm.frame_labels(bm, V, "mug", pose, hand_ids)
    return dict(bm=bm, V=V.numpy(), pose=pose, hand_ids=hand_ids, seq=seq, lab=lab)


def test_grasp_file_object_orientation_is_the_object_pose(scene):
    """The file's object orientation (axis-angle, GRAB's object.params.global_orient) turns into the object pose's
    rotation, and its translation is the pose's (x_world = R x_obj + t)."""
    seq, pose = scene["seq"], scene["pose"]
    np.testing.assert_allclose(seq.object_rotation()[0], pose.rotation, atol=1e-6)
    np.testing.assert_allclose(seq.object_transl[0], pose.translation, atol=1e-6)


def test_static_grasp_file_has_both_feet_planted(scene):
    """A static grasp's file labels all four foot contacts (heels and toes) 1 on its one frame: graspkit's convention,
    not measured from the mesh (the acceptance rule keeps a static grasp's feet within 1 cm of the ground)."""
    assert scene["seq"].contacts["feet"].tolist() == [[1, 1, 1, 1]]


def test_object_height_is_the_objects_z(scene):
    """SAGA's t_O (A.3, the object's height): the z of the object's world translation (z up; the generated grasps
    stand on the floor z = 0)."""
    assert float(scene["lab"]["object.height"]) == pytest.approx(scene["pose"].translation[2], abs=1e-6)


def test_hand_bps_is_centred_on_the_object_translation(scene):
    """GOAL's hand BPS uses the object's basis: the distance from each basis point to the nearest hand vertex minus the
    object translation (scipy's KD-tree), like b^o."""
    hand = scene["V"][scene["hand_ids"]] - scene["pose"].translation
    want = cKDTree(hand).query(bps_basis().double().numpy())[0]
    np.testing.assert_allclose(scene["lab"]["goal.bps_hand"], want, atol=1e-5)


def test_object_contacts_are_the_points_within_1_cm_of_the_body(scene):
    """C_O (SAGA Sec. 3.2, graspkit's 1 cm): an object point is in contact when trimesh's distance from it to the body
    mesh is at most 1 cm (points within 0.1 mm of the threshold are not judged)."""
    pts = object_points("mug")[0] @ scene["pose"].rotation.T + scene["pose"].translation
    body = trimesh.Trimesh(scene["V"], scene["bm"].faces.numpy(), process=False)
    d = trimesh.proximity.closest_point(body, pts)[1]
    c = scene["lab"]["contact.object"].astype(bool)
    sure = np.abs(d - 0.01) > 1e-4
    assert c.sum() > 20 and ((d > 0.01) & (d < 0.02)).sum() > 20
    assert (c[sure] == (d[sure] <= 0.01)).all()


def test_badness_prefers_an_attempt_in_contact():
    """badness (lower is better): of two attempts that differ only in contact, the one touching the object scores
    lower, as the acceptance rule asks for contact."""
    q = {"depth_cm": 0.3, "volume_cm3": 1.0, "feet_cm": 0.5, "regions_mm": [2.0, 4.0, 4.0, 9.0, 9.0, 9.0]}
    assert gm.badness({**q, "contact": 1.0}) < gm.badness({**q, "contact": 0.0})
    assert gm.badness({**q, "contact": True}) < gm.badness({**q, "contact": False})


class _Recorder:
    """A fitter stand-in that records the tasks it is given; every result is accepted."""

    def __init__(self) -> None:
        self.tasks = []

    def fit(self, tasks):
        self.tasks += tasks
        q = {"contact": 1.0, "depth_cm": 0.1, "volume_cm3": 0.1, "feet_cm": 0.1, "arm_residual_deg": 5.0,
             "regions_mm": [1.0] * 6}
        return [SimpleNamespace(task=t, quality=q) for t in tasks]

    def evaluate(self, res):
        pass


def test_chunk_c_draws_the_tasks_of_items_c_size_onwards():
    """fit_chunk: chunk c of `size` grasps holds items c*size .. (c+1)*size - 1, each drawn from its own task seed
    (module docstring: grasp i's task derives from (seed, kind, i, attempt)): chunk 2 of 3 draws items 6, 7, 8."""
    rec = _Recorder()
    gm.fit_chunk(rec, "grasp", 5, 2, size=3, objects=("apple", "mug"))
    want = [sample_grasp_task(np.random.default_rng(gm.task_seed(5, "grasp", i, 0)), "apple") for i in (6, 7, 8)]
    assert [t.plan_seed for t in rec.tasks] == [t.plan_seed for t in want]
    assert [t.choice for t in rec.tasks] == [t.choice for t in want]


def test_grasp_and_approach_sets_draw_different_tasks():
    """The module docstring: a task seed derives from (seed, kind, index, attempt), so item i of the grasp set and of
    the approach set (same --seed) are different draws."""
    seeds = {k: [gm.task_seed(0, k, i) for i in range(20)] for k in gm.KINDS}
    assert not set(seeds["grasp"]) & set(seeds["approach"])


def test_solid_profiles_span_the_objects_height():
    """solid_profiles are in the object frame: the mug's profile spans the mesh's z extent and the wine glass's
    bowl profile tops out at the mesh's top (trimesh bounds of the catalogue mesh)."""
    for name, lo in (("mug", True), ("wine_glass", False)):
        z = np.array(make_object(name).bounds)[:, 2]
        prof = G.solid_profiles(name)[0]
        assert abs(prof[:, 1].max() - z[1]) < 2e-3, name
        if lo:
            assert abs(prof[:, 1].min() - z[0]) < 2e-3, name


def test_a_facing_direction_need_not_be_unit():
    """Part.facing's direction is a direction: (3, 0, 0) allows the same cone as (1, 0, 0)."""
    part = G.Part("t", "sphere", (0.0, 0.0, 0.0), (0.05,), ("power",), facing=((3.0, 0.0, 0.0), 40.0))
    a = np.deg2rad([0.0, 30.0, 50.0, 150.0])
    s = np.stack([np.cos(a), np.sin(a), np.zeros_like(a)], 1)
    assert G._allowed(part, s).tolist() == [True, True, False, False]


def test_palm_frames_approach_from_outside_and_pinch_axes_cross_the_part():
    """Palm frames: s is the outward direction at the anchor (trimesh's signed distance, > 0 inside, is lower 3 mm
    out along s than 3 mm in); cylinder pinches: the pinch axis y is across the part (perpendicular to its axis
    and to s); box power grasps: y runs along the face's long side (the fingers wrap the thin one, as round a
    cylinder's axis). The probe skips the wine glass (3 mm in crosses its thin bowl wall into the cup), the
    toothbrush (thinner than the 6 mm probe) and the binoculars (the barrel's ends run into the body)."""
    for name in sorted(G.GRASP_PARTS):
        mesh = make_object(name)
        for t in G.grasp_types(name):
            c = G.grasp_candidates(name, t)
            parts = G.GRASP_PARTS[name]
            if t != "pinch" and name not in ("wine_glass", "toothbrush", "binoculars"):
                out = trimesh.proximity.signed_distance(mesh, c.p + 0.003 * c.s)
                inn = trimesh.proximity.signed_distance(mesh, c.p - 0.003 * c.s)
                assert (out < inn).all(), f"{name} {t}: {(out >= inn).sum()} frames approach from inside"
            for k in range(len(c.p)):
                part = parts[c.part[k]]
                if t == "pinch" and part.shape == "cylinder":
                    ax = np.asarray(part.axis, float) / np.linalg.norm(part.axis)
                    assert abs(c.y[k] @ ax) < 1e-9 and abs(c.y[k] @ c.s[k]) < 1e-9, (name, k)
                if t == "power" and part.shape == "box":
                    n = int(np.argmax(np.abs(c.s[k])))
                    tang = [i for i in range(3) if i != n]
                    long_ = tang[int(np.argmax(np.asarray(part.size)[tang]))]
                    assert abs(abs(c.y[k][long_]) - 1) < 1e-9, (name, k, c.y[k])


def test_natural_hand_rotation_points_the_fingers_at_the_object_palm_to_the_left():
    """natural_hand_rotation (docstring): a rotation whose finger column points horizontally at the object and down,
    more for a low object, and whose palm normal faces the person's left (z x facing direction)."""
    for u in ([0.0, 1.0, 0.0], [0.6, -0.8, 0.0]):
        u = np.array(u)
        Rs = {}
        for h in (0.5, 1.0, 1.3):
            R = G.natural_hand_rotation(u, h)
            np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-12)
            assert np.linalg.det(R) > 0
            f, n = R[:, 0], R[:, 1]
            assert f[2] < 0
            fh = f[:2] / np.linalg.norm(f[:2])
            np.testing.assert_allclose(fh, -u[:2], atol=1e-12)
            left = np.cross([0, 0, 1.0], -u)
            assert n @ left > 0.5
            Rs[h] = f[2]
        assert Rs[0.5] < Rs[1.0] < Rs[1.3]


def _rand_unit(rng, n=None):
    v = rng.normal(size=(3,) if n is None else (n, 3))
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def test_hand_rotation_puts_the_palm_on_minus_s_and_the_pinch_axis_on_y():
    """hand_rotation (docstring): palm grasps map the palm normal exactly onto -s and the hand axis onto y made
    perpendicular to s; pinches map the pinch axis exactly onto y and pinch_from onto -s (y perpendicular to s)."""
    rng = np.random.default_rng(5)
    for _ in range(20):
        Rb = Rotation.random(random_state=rng).as_matrix()
        hf = SimpleNamespace(normal=Rb[:, 0], thumb=Rb[:, 1])
        s, y = _rand_unit(rng), _rand_unit(rng)
        R = G.hand_rotation(hf, Rb[:, 1], s, y)
        np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
        assert np.linalg.det(R) > 0
        np.testing.assert_allclose(R @ Rb[:, 0], -s, atol=1e-12)
        yp = y - (y @ s) * s
        np.testing.assert_allclose(R @ Rb[:, 1], yp / np.linalg.norm(yp), atol=1e-12)
        y2 = yp / np.linalg.norm(yp)
        R2 = G.hand_rotation(hf, Rb[:, 1], s, y2, pinch_from=Rb[:, 2])
        np.testing.assert_allclose(R2 @ Rb[:, 1], y2, atol=1e-12)
        np.testing.assert_allclose(R2 @ Rb[:, 2], -s, atol=1e-12)


def _start_distance(task):
    return float(np.hypot(task.start.x - task.object_pose.translation[0], task.start.y - task.object_pose.translation[1]))


def test_sampled_tasks_keep_the_start_clear_of_the_object_and_face_it():
    """sample_grasp_task (module docstring, START_*): the start is between radius + START_CLEARANCE and 1.5 m from the
    object centre; a drawn object lies within +-10 deg of -y from the origin; with a given placement the person
    faces the object within +-10 deg."""
    lo = G.object_radius("mug") + G.START_CLEARANCE
    rng = np.random.default_rng(6)
    pose = ObjectPose(np.array([0.4, -0.7, 0.9]), np.eye(3))
    for _ in range(40):
        t = G.sample_grasp_task(rng, "mug", "power")
        d = _start_distance(t)
        assert lo - 1e-9 <= d <= 1.5 + 1e-9
        bearing = np.degrees(np.arctan2(t.object_pose.translation[1], t.object_pose.translation[0]))
        assert abs(bearing + 90.0) <= 10.0 + 1e-9
        t = G.sample_grasp_task(rng, "mug", "power", object_pose=pose)
        d = _start_distance(t)
        assert lo - 1e-9 <= d <= 1.5 + 1e-9
        to = pose.translation[:2] - [t.start.x, t.start.y]
        off = np.degrees(np.arccos(np.clip(np.dot(to / d, [np.cos(t.start.heading), np.sin(t.start.heading)]), -1, 1)))
        assert off <= 10.0 + 1e-6


def test_a_start_range_below_the_clearance_starts_at_the_clearance():
    """start_distance (0.05, 0.1) is below the mug's radius + START_CLEARANCE: the start is at that clearance (the
    start is always at least that far), not an error about a distance_range the caller never passed."""
    lo = G.object_radius("mug") + G.START_CLEARANCE
    rng = np.random.default_rng(7)
    pose = ObjectPose(np.array([0.4, -0.7, 0.9]), np.eye(3))
    for op in (None, pose):
        t = G.sample_grasp_task(rng, "mug", "power", object_pose=op, start_distance=(0.05, 0.1))
        assert abs(_start_distance(t) - lo) < 1e-9


@pytest.fixture(scope="module")
def fitter(bm):
    return G.GraspFitter(bm)


@pytest.mark.parametrize("name, gtype", [("apple", "power"), ("cracker_box", "side")])
def test_world_frames_are_the_candidates_moved_by_the_object_pose(fitter, name, gtype):
    """GraspFitter._frames: every candidate not approached from below (world s_z >= -0.35) appears twice (both
    flips); the palm target is the candidate anchor moved by the pose matrix plus PALM_GAP along the world s (the
    pose's rotation of the object-frame s); the rest hand rotated by R puts its palm normal on -s and, placed at the
    wrist target, its anchor on the target; the two flips turn the hand axis to opposite sides."""
    rot = Rotation.from_euler("zx", [50.0, 35.0], degrees=True).as_matrix()
    pose = ObjectPose(np.array([0.3, -0.6, 1.0]), rot)
    task = G.sample_grasp_task(np.random.default_rng(8), name, gtype, object_pose=pose)
    T, S, R, Wr, rows = fitter._frames(task)
    cand = G.grasp_candidates(name, gtype)
    M = pose.matrix()
    s_world = cand.s @ M[:3, :3].T
    keep = np.flatnonzero(s_world[:, 2] >= -0.35)
    assert len(keep) < len(cand.p)              # the tilt puts some frames below
    assert sorted(rows[:, 0].tolist()) == sorted(np.repeat(keep, 2).tolist())
    p_world = trimesh.transform_points(cand.p, M)
    np.testing.assert_allclose(S, s_world[rows[:, 0]], atol=1e-12)
    np.testing.assert_allclose(T, p_world[rows[:, 0]] + G.PALM_GAP * S, atol=1e-12)
    anchor, _, hf = G.hand_anchor(fitter.hm, task.betas, gtype)
    np.testing.assert_allclose(np.einsum("mij,j->mi", R, hf.normal), -S, atol=1e-9)
    np.testing.assert_allclose(Wr + np.einsum("mij,j->mi", R, anchor - hf.wrist), T, atol=1e-9)
    axis = G._hand_axis(hf, cand.kind[0], None)
    a = np.einsum("mij,j->mi", R, axis)
    for i in keep[:10]:
        m0, m1 = (np.flatnonzero((rows[:, 0] == i) & (rows[:, 1] == f))[0] for f in (0, 1))
        assert a[m0] @ a[m1] < 0


def test_evaluate_measures_each_grasp_on_its_own_object(fitted):
    """evaluate measured every result on the first result's object: a cracker-box grasp listed after an apple one
    read 10.7 mm off instead of -1.7 mm (an independent check). A result's figures no longer depend on its company."""
    import copy
    import dataclasses

    bm, fitter, res, _ = fitted
    alone = copy.deepcopy(res[0])
    fitter.evaluate([alone])
    other = dataclasses.replace(copy.deepcopy(res[0]), task=dataclasses.replace(res[0].task, object_name="cracker_box"),
                                quality={})
    mixed = copy.deepcopy(res[0])
    fitter.evaluate([other, mixed])
    for k, v in alone.quality.items():                   # equal up to a batch's float rounding (1e-7 m)
        assert mixed.quality[k] == pytest.approx(v, rel=1e-5, abs=1e-4), k
    assert other.quality["min_distance"] != alone.quality["min_distance"]     # the box is measured as the box
