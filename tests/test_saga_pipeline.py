"""SAGA end to end (graspkit.saga): the world-frame conversion against moved vertices, and one call from an object
of one's own to an approach-and-grasp motion, checked with trimesh against the object and the floor."""
import numpy as np
import pytest
import torch
import trimesh

from graspkit.body.markers import saga_sparse_markers
from graspkit.data import Start
from graspkit.data.motion import Motion, heading_of
from graspkit.objects.placement import ObjectPose
from graspkit.optim import graspmotion
from graspkit.saga import default_start, rigid_params, synthesize


def test_rigid_params_equals_moving_every_vertex(bm):
    """Parameters moved by x -> R x + o give the vertices R v + o (the global rotation turns about the rest pelvis)."""
    g = torch.Generator().manual_seed(0)
    poses = (torch.randn(3, 55, 3, generator=g) * 0.3).double().numpy()
    transl = torch.randn(3, 3, generator=g).double().numpy()
    betas = (torch.randn(10, generator=g) * 0.8).double().numpy()
    a = 0.7
    R = np.array([[np.cos(a), -np.sin(a), 0.0], [np.sin(a), np.cos(a), 0.0], [0.0, 0.0, 1.0]])
    R = R @ np.array([[1.0, 0.0, 0.0], [0.0, np.cos(0.3), -np.sin(0.3)], [0.0, np.sin(0.3), np.cos(0.3)]])
    o = np.array([0.4, -1.2, 0.25])
    p2, t2 = rigid_params(poses, transl, betas, R, o, bm)
    v1 = Motion(poses, transl, betas, 30.0).vertices(bm).double().numpy()
    v2 = Motion(p2, t2, betas, 30.0).vertices(bm).double().numpy()
    np.testing.assert_allclose(v2, v1 @ R.T + o, atol=1e-4)


def test_the_same_seed_gives_the_same_motion_and_polish_steps_are_checked(bm, monkeypatch):
    """Two calls with one seed give bit-identical grasps and motions (a few steps of each stage, no polish); a third
    seed another motion; polish_steps takes two counts >= 0; free_joints reaches both optimisers; GraspMotion-Opt gets
    the start body's 79 markers unless hold_start=False."""
    from graspkit.objects.placement import ObjectPose
    from graspkit.optim import grasppose, graspmotion

    seen = []
    for cls in (grasppose.GraspPoseOpt, graspmotion.GraspMotionOpt):
        def init(self, *a, _orig=cls.__init__, **k):
            _orig(self, *a, **k)
            seen.append((type(self).__name__, self.cfg.free_joints))
        monkeypatch.setattr(cls, "__init__", init)
    starts = []

    def fit(self, *a, _orig=graspmotion.GraspMotionOpt.fit, **k):
        starts.append(None if k.get("start") is None else tuple(k["start"].shape))
        return _orig(self, *a, **k)
    monkeypatch.setattr(graspmotion.GraspMotionOpt, "fit", fit)

    kw = dict(object_pose=ObjectPose.from_yaw(0.8, np.array([0.3, -0.6, 0.85])), grasp_steps=(5, 5, 5),
              motion_steps=(5, 5), polish_steps=(0, 0), progress=False)
    a, b, c = (synthesize("camera", bm, seed=s, **kw) for s in (3, 3, 4))
    np.testing.assert_array_equal(a.motion.poses, b.motion.poses)
    np.testing.assert_array_equal(a.grasp.vertices.numpy(), b.grasp.vertices.numpy())
    assert np.abs(a.motion.poses - c.motion.poses).max() > 1e-3
    assert set(seen) == {("GraspPoseOpt", grasppose.ARM_JOINTS), ("GraspMotionOpt", grasppose.ARM_JOINTS)}
    seen.clear()
    d = synthesize("camera", bm, seed=3, free_joints=(), **kw)          # Alg. 1 and Alg. 2: the prior latent alone
    assert seen == [("GraspPoseOpt", ()), ("GraspMotionOpt", ())]
    assert np.abs(a.motion.poses - d.motion.poses).max() > 1e-3
    synthesize("camera", bm, seed=3, hold_start=False, **kw)
    assert starts == [(1, 79, 3)] * 4 + [None]
    with pytest.raises(ValueError, match="polish_steps"):
        synthesize("camera", bm, polish_steps=(10, -1))
    with pytest.raises(ValueError, match="name"):
        synthesize("teapot", bm)
    with pytest.raises(ValueError, match="start_distance: .*at most 3"):      # 1e6 m ran, 31 km under the floor
        synthesize("camera", bm, start_distance=1e6)
    with pytest.raises(ValueError, match="^poses: expected at least one frame"):       # refused by Motion itself
        Motion(np.zeros((0, 55, 3)), np.zeros((0, 3)), np.zeros(10), 30.0)
    emptied = Motion(np.zeros((1, 55, 3)), np.zeros((1, 3)), np.zeros(10), 30.0)
    emptied.poses, emptied.trans = emptied.poses[:0], emptied.trans[:0]              # emptied after it was made
    with pytest.raises(ValueError, match="start: expected a Motion with at least one frame"):
        synthesize("camera", bm, start=emptied)


def test_saga_command_names_a_bad_object(capsys):
    from graspkit.cli import main

    assert main(["saga", "--object", "teapot", "--out", "unused"]) == 2
    assert "--object: unknown object 'teapot'" in capsys.readouterr().err


def test_one_call_for_an_object_of_ones_own(bm, tmp_path, monkeypatch):
    """synthesize(): WholeGrasp-VAE -> GraspPose-Opt -> MotionFill-VAE -> GraspMotion-Opt for a mesh the catalogue does
    not have (a box, given as a file) at a placement of our choosing: the grasp body touches it, the motion starts at
    the start body, ends with the right hand on the box (trimesh's exact distance) and stays on the floor; the grid is
    built in a fresh cache. (Fewer steps than Alg. 1-2; a catalogue name goes the same way: the seeded test above.)"""
    import trimesh

    from graspkit.body.markers import palm_vertices
    from graspkit.objects.placement import ObjectPose
    from graspkit.optim.grasppose import hand_vertex_ids

    monkeypatch.setenv("GRASPKIT_CACHE", str(tmp_path / "cache"))
    path = tmp_path / "parcel.ply"
    trimesh.creation.box((0.05, 0.07, 0.10)).export(path)
    pose = ObjectPose.from_yaw(-0.4, np.array([0.1, -0.7, 0.9]))
    r = synthesize(path, bm, object_pose=pose, seed=0, grasp_steps=(100, 120, 150), motion_steps=(60, 80),
                   progress=False)
    assert r.name == "parcel"
    assert list((tmp_path / "cache" / "sdf").glob("mesh_r*.npz"))
    np.testing.assert_allclose(np.asarray(r.mesh.vertices).mean(0), pose.translation, atol=1e-9)
    assert np.isclose(r.mesh.volume, 0.05 * 0.07 * 0.10)
    q = trimesh.proximity.ProximityQuery(r.mesh)
    assert np.abs(q.signed_distance(r.grasp.vertices[0].double().numpy())).min() < 0.005   # the grasp touches it
    palm = torch.as_tensor(palm_vertices(bm)["right"])
    hand = torch.as_tensor(hand_vertex_ids(bm, ("right",)))
    near = lambda v, ids: np.abs(q.signed_distance(v[ids].double().numpy())).min()  # noqa: E731
    # the grasp's right palm is at the box (its fingers touch it); the motion ends with the right hand on the box and
    # no vertex more than 3 mm inside it (trimesh: positive inside)
    assert near(r.grasp.vertices[0], palm) < 0.03
    v = r.motion.vertices(bm)
    assert near(v[-1], hand) < 0.005 and q.signed_distance(v[-1].double().numpy()).max() < 0.003
    assert r.motion.num_frames == 61 and r.markers.shape == (61, 79, 3) and r.foot_contact.shape == (61, 4)
    start_off = float((v[0] - r.start.vertices(bm)[0]).norm(dim=-1).mean())
    # starts at the start body: 2 cm after these 60 stage-1 steps (frame 0's lr 0.1 decays at step 60), 2-3 mm after
    # Alg. 2's 100; 8-12 cm off when Alg. 2 does not hold frame 0 (docs/saga_motion.md, "The start frame")
    assert start_off < 0.03, start_off
    feet = v[:, :, 2].min(1).values
    assert feet.abs().max() < 0.08                                                  # on the floor (z = 0)
    assert set(r.metrics) >= {"grasp_contact", "end_contact", "end_volume_cm3", "skating_opt"}
    assert r.metrics["floor_deepest_cm"] == pytest.approx(100 * max(0.0, -float(feet.min())), abs=1e-4)   # reported
    low = float(r.grasp.vertices[0, :, 2].min())                    # the grasp body on the floor too (its floor term)
    assert r.metrics["grasp_floor_cm"] == pytest.approx(100 * low, abs=1e-4) and -0.002 < low < 0.02


def test_saga_command_names_a_bad_mesh_file(tmp_path, capsys):
    import trimesh

    from graspkit.cli import main

    path = tmp_path / "huge.stl"
    trimesh.creation.box((50.0, 70.0, 100.0)).export(path)      # millimetres
    assert main(["saga", "--object", str(path), "--out", str(tmp_path)]) == 2
    assert "in metres" in capsys.readouterr().err


def test_default_start_stands_away_from_the_object_and_faces_it(bm):
    """saga.default_start puts the standing body `distance` m from the grasp pelvis on the side AWAY from the object
    centre, facing the object (docstring)."""
    centre = np.array([0.4, 0.3, 0.9])
    grasp_pelvis = np.array([0.4 + 0.36, 0.3 - 0.48, 0.95])        # 0.6 m from the centre in the plane, along (0.6, -0.8)
    d = np.array([0.6, -0.8])
    st = default_start(grasp_pelvis, centre, np.zeros(10), 1.0, bm, seed=0)
    assert st.num_frames == 1
    pelvis = st.joint_positions(bm)[0, 0]
    np.testing.assert_allclose(pelvis[:2], grasp_pelvis[:2] + 1.0 * d, atol=0.05)     # 1.6 m from the centre
    h = float(heading_of(st.poses[:1, 0])[0])
    to_obj = centre[:2] - pelvis[:2]
    assert np.cos(h - np.arctan2(to_obj[1], to_obj[0])) > np.cos(np.deg2rad(20))      # facing the object


def test_sample_markers_are_in_the_world_frame_of_the_start_body(bm):
    """SagaResult.markers (MotionFill's sample, taken back to the world) starts at the start body's markers, where the
    sample's known first frame is, and ends near the fitted motion's last markers. (A few optimiser steps only;
    about 4 s, most of it synthesize.)"""
    # a start facing -x (towards the object): the canonical frame is turned well away from the world's
    r = synthesize("camera", bm, object_pose=ObjectPose.from_yaw(0.8, np.array([0.3, -0.6, 0.85])), seed=3,
                   start=Start(1.4, -0.3, 3.3), grasp_steps=(5, 5, 5), motion_steps=(5, 5), polish_steps=(0, 0),
                   progress=False)
    start = saga_sparse_markers(bm).select(r.start.vertices(bm))[0].double().numpy()
    first = r.markers[0].double().numpy()
    assert np.linalg.norm(first - start, axis=1).mean() < 0.05                 # the known first frame, in the world
    fitted = saga_sparse_markers(bm).select(r.motion.vertices(bm, 60, 61))[0].double().numpy()
    assert np.linalg.norm(r.markers[-1].double().numpy() - fitted, axis=1).mean() < 0.25


class _Stop(Exception):
    """Raised by a stand-in to stop a pipeline once it has seen what the test needs."""


def test_motion_opt_gets_normals_in_the_points_frame(bm, monkeypatch):
    """GraspMotion-Opt gets the object's points and normals in one frame: for a capsule the normals are its own
    outward normals at the points, R n_mesh (against the analytic capsule)."""
    seen = {}

    def fit(self, markers, betas, contacts, obj, *a, **k):
        seen["obj"] = obj
        raise _Stop

    monkeypatch.setattr(graspmotion.GraspMotionOpt, "fit", fit)
    radius, height = 0.035, 0.14
    mesh = trimesh.creation.capsule(height=height, radius=radius)             # axis z, centred at the origin
    with pytest.raises(_Stop):
        synthesize(mesh, bm, object_pose=ObjectPose.from_yaw(0.8, np.array([0.3, -0.6, 0.85])), seed=3,
                   grasp_steps=(5, 5, 5), motion_steps=(5, 5), polish_steps=(0, 0), progress=False)
    o = seen["obj"]
    R = o.rotation.double().reshape(3, 3).numpy()
    origin = o.origin.double().reshape(3).numpy()
    p = o.points.double().reshape(-1, 3).numpy()
    n = o.normals.double().reshape(-1, 3).numpy()
    q = (p - origin) @ R                                                       # back in the mesh frame: R^T (p - origin)
    axis = np.zeros_like(q)
    axis[:, 2] = np.clip(q[:, 2], -height / 2, height / 2)
    n_mesh = (q - axis) / np.linalg.norm(q - axis, axis=1, keepdims=True)
    assert np.abs(np.linalg.norm(q - axis, axis=1) - radius).max() < 2e-3       # the points are on the capsule
    cos = np.sum((n_mesh @ R.T) * n, axis=1)
    assert np.quantile(cos, 0.05) > 0.95, np.quantile(cos, [0.0, 0.05, 0.5])


def test_end_figures_and_skating_are_of_the_returned_motion(bm, monkeypatch):
    """SagaResult.metrics: the end_* figures are of the motion's last frame (frame 60) and skating_opt is SAGA's
    skating of the fitted markers in the world. Truth: the returned motion itself -- its last frame's vertices and its
    sparse markers (r.motion is the fitted body moved to the world; a few optimiser steps only)."""
    import graspkit.eval_motionfill as emf
    import graspkit.metrics as gm
    seen = {}
    real_fig, real_sk = gm.grasp_and_end_figures, emf.skating

    def fig(grasp_vertices, end_vertices, faces, obj):
        seen["end"] = torch.as_tensor(end_vertices).detach().double().clone()
        return real_fig(grasp_vertices, end_vertices, faces, obj)

    def sk(markers, floor, heels):
        seen.setdefault("skating", []).append(np.array(markers, np.float64))
        return real_sk(markers, floor, heels)

    monkeypatch.setattr(gm, "grasp_and_end_figures", fig)
    monkeypatch.setattr(emf, "skating", sk)
    r = synthesize("camera", bm, object_pose=ObjectPose.from_yaw(0.8, np.array([0.3, -0.6, 0.85])), seed=3,
                   start=Start(1.4, -0.3, 3.3), grasp_steps=(2, 2, 2), motion_steps=(2, 2), polish_steps=(0, 0),
                   progress=False)
    v = r.motion.vertices(bm).double()
    assert r.motion.num_frames == 61
    torch.testing.assert_close(seen["end"], v[-1], atol=1e-4, rtol=0)
    assert float((v[-1] - v[-2]).norm(dim=-1).max()) > 1e-3           # the last two frames differ
    fitted = seen["skating"][1][0]                                      # skating_opt's markers (61, 79, 3)
    want = saga_sparse_markers(bm).select(v).numpy()
    np.testing.assert_allclose(fitted, want, atol=1e-3)
    assert r.metrics["skating_opt"] == pytest.approx(real_sk(want[None], np.zeros(1), emf.heel_columns()), abs=0.02)


def _standing(bm, betas: np.ndarray) -> Motion:
    """A standing body (the planner's first frame) of shape `betas` at (0.5, -0.2), facing +y, on the floor."""
    from graspkit.data.reaching import plan_reach

    return plan_reach(Start(0.5, -0.2, np.pi / 2), np.array([0.5, 0.6, 0.9]), 60, betas=betas, seed=0,
                      bm=bm).slice(0, 1)


def test_a_given_body_is_reshaped_where_it_stands(bm):
    """saga.reshaped_in_place: the given pose in another shape keeps its pelvis joint's x, y and stands on the floor
    (lowest vertex at z = 0, as the given body's); keeping the translation instead floats a shorter body and sinks a
    taller one by centimetres (the truth: the given body's own joints and vertices)."""
    from graspkit.saga import reshaped_in_place

    given = _standing(bm, np.r_[1.5, -1.0, np.zeros(8)])
    assert abs(float(given.vertices(bm)[0, :, 2].min())) < 2e-3                  # the planner's body stands on z = 0
    for b0 in (-2.0, 2.0):
        betas = np.r_[b0, 0.8, np.zeros(8)]
        kept = Motion(given.poses, given.trans, betas, 30.0)
        assert abs(float(kept.vertices(bm)[0, :, 2].min())) > 0.01                # the case is not trivial
        new = reshaped_in_place(given, betas, bm)
        np.testing.assert_array_equal(new.poses, given.poses)
        np.testing.assert_allclose(new.betas, betas, atol=1e-6)
        np.testing.assert_allclose(new.joint_positions(bm)[0, 0, :2], given.joint_positions(bm)[0, 0, :2], atol=1e-5)
        assert float(new.vertices(bm)[0, :, 2].min()) == pytest.approx(float(given.vertices(bm)[0, :, 2].min()),
                                                                       abs=1e-5)


def test_a_given_start_body_stands_where_it_was_given(bm):
    """synthesize(start=Motion) with a body of another shape than the grasp's: SagaResult.start is that pose in the
    grasp's shape with its pelvis at the given x, y and its feet on the floor (before 2026-12-07 it kept the given
    translation and stood centimetres above or below the floor, and the held frame 0 with it)."""
    given = _standing(bm, np.r_[2.0, -1.5, np.zeros(8)])
    r = synthesize("camera", bm, object_pose=ObjectPose.from_yaw(np.pi / 2, np.array([0.5, 0.6, 0.85])), seed=3,
                   start=given, grasp_steps=(2, 2, 2), motion_steps=(2, 2), polish_steps=(0, 0), progress=False)
    np.testing.assert_array_equal(r.start.betas, r.grasp.params["betas"][0].detach().double().numpy())
    np.testing.assert_array_equal(r.start.poses, given.poses)
    np.testing.assert_allclose(r.start.joint_positions(bm)[0, 0, :2], given.joint_positions(bm)[0, 0, :2], atol=1e-5)
    assert abs(float(r.start.vertices(bm)[0, :, 2].min())) < 2e-3
