"""GraspPose-Opt (SAGA Eq. 4-7, Alg. 1): a known body refitted from its markers, each energy term against an
independent computation (scipy KD-tree, trimesh-free exact signed distance, closed-form heights)."""
from dataclasses import replace

import numpy as np
import pytest
import torch
import trimesh
from scipy.spatial import cKDTree

from graspkit.body.markers import foot_vertices, palm_vertices, saga_markers
from graspkit.body.skeleton import JOINT_INDEX
from graspkit.metrics import joint_limit_violation
from graspkit.models.pose_prior import load_pose_prior
from graspkit.objects.sdf import SDFGrid, signed_distance
from graspkit.optim.grasppose import (ARM_JOINTS, GraspObject, GraspPoseConfig, GraspPoseOpt, GraspPoseResult,
                                      GraspPoseWeights, body_joint_ids, energies_table, expand_free_joints,
                                      forearm_vertex_ids, hand_vertex_ids, kabsch, valid_body_joints)
from graspkit.rotations import axis_angle_to_matrix, matrix_to_axis_angle, matrix_to_rot6d


@pytest.fixture(scope="module")
def prior():
    torch.manual_seed(0)
    return load_pose_prior()


def _truth(bm, prior, B: int = 2, seed: int = 0):
    """A known body: prior latent, shape, hand PCA, upright in the z-up world with a yaw; posed by BodyModel.forward."""
    g = torch.Generator().manual_seed(seed)
    z = 0.5 * torch.randn(B, 32, generator=g)
    betas = 0.5 * torch.randn(B, 10, generator=g)
    pca = {s: 0.5 * torch.randn(B, 24, generator=g) for s in ("left", "right")}
    yaw = torch.rand(B, generator=g) * 6.28
    up = axis_angle_to_matrix(torch.tensor([np.pi / 2, 0.0, 0.0])).expand(B, 3, 3)
    R = axis_angle_to_matrix(torch.stack([torch.zeros(B), torch.zeros(B), yaw], -1)) @ up
    transl = torch.randn(B, 3, generator=g) * 0.3
    with torch.no_grad():
        out = bm(betas=betas, global_orient=matrix_to_axis_angle(R), body_pose=prior.decode(z),
                 left_hand_pose=pca["left"] @ bm.left_hand_components[:24],
                 right_hand_pose=pca["right"] @ bm.right_hand_components[:24], transl=transl)
    return out.vertices, dict(z=z, betas=betas, pca=pca, R=R, transl=transl)


def _dummy_object() -> GraspObject:
    pts = torch.tensor(trimesh.creation.icosphere(2, 0.05).vertices, dtype=torch.float32)
    return GraspObject(pts, torch.nn.functional.normalize(pts, dim=-1), height=1.0)


def _ball(centre, radius: float, n: int = 800):
    """An icosphere (trimesh) of `radius` at `centre` (3,) and its GraspObject: n surface points with normals and a
    32-node signed-distance grid."""
    ball = trimesh.creation.icosphere(3, radius)
    ball.apply_translation(torch.as_tensor(centre).double().numpy())
    pts_np, face = trimesh.sample.sample_surface_even(ball, n, seed=0)
    obj = GraspObject(torch.tensor(pts_np, dtype=torch.float32), torch.tensor(ball.face_normals[face]).float(),
                      height=1.0, sdf=SDFGrid.from_mesh(ball, resolution=32, padding=0.02))
    return ball, obj


def test_kabsch_recovers_a_rigid_motion():
    g = torch.Generator().manual_seed(0)
    x = torch.randn(3, 40, 3, generator=g)
    R = axis_angle_to_matrix(torch.randn(3, 3, generator=g))
    c = torch.randn(3, 3, generator=g)
    R2, c2 = kabsch(x, x @ R.transpose(1, 2) + c[:, None])
    torch.testing.assert_close(R2, R, atol=1e-5, rtol=0)
    torch.testing.assert_close(c2, c, atol=1e-5, rtol=0)


def test_kabsch_of_a_mirror_image_is_still_a_rotation():
    """Mirrored (or nearly flat) markers make the SVD's best orthogonal map a reflection; the fit must return the best
    proper rotation instead, scipy's `Rotation.align_vectors` on the centred points."""
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(0)
    src = rng.normal(size=(30, 3))
    tgt = src * np.array([-1.0, 1.0, 1.0]) + 0.01 * rng.normal(size=src.shape)
    R, _ = kabsch(torch.tensor(src)[None], torch.tensor(tgt)[None])
    assert torch.det(R[0]).item() == pytest.approx(1.0, abs=1e-9)
    want = Rotation.align_vectors(tgt - tgt.mean(0), src - src.mean(0))[0].as_matrix()
    np.testing.assert_allclose(R[0].numpy(), want, atol=1e-6)


def test_weights_are_the_papers():
    """SAGA A.4's weights of Eq. 5-7 and S.3's heuristic thresholds."""
    w = GraspPoseWeights()
    assert (w.prior, w.contact_object, w.contact_marker, w.colli_object, w.colli_body) == (5e-4, 15.0, 15.0, 100.0,
                                                                                          200.0)
    assert (w.heuristic_prior, w.heuristic_radius) == (0.7, 0.02)


def test_markers_of_a_known_body_are_refitted_to_within_a_centimetre(bm, prior):
    verts, _ = _truth(bm, prior)
    opt = GraspPoseOpt(bm, prior, GraspPoseConfig(steps=(60, 200, 200), collision=False, contact=False,
                                                  ground=False))
    markers = verts[:, opt.marker_ids]
    res = opt.fit(markers, _dummy_object(), progress=False)
    err = (res.markers - markers).norm(dim=-1)
    assert err.mean() < 0.01, f"mean marker error {err.mean():.4f} m"
    assert (res.vertices - verts).norm(dim=-1).mean() < 0.015       # the whole mesh follows, not just the markers
    # energies fall in every stage, and the result re-poses with BodyModel.forward from its axis-angle parameters
    for e in res.energies:
        assert e["after"]["fit"].sum() < e["before"]["fit"].sum()
    p = res.params
    again = bm(betas=p["betas"], global_orient=p["global_orient"], body_pose=p["body_pose"],
               left_hand_pose=p["left_hand_pose"] - bm.pose_mean[75:120],
               right_hand_pose=p["right_hand_pose"] - bm.pose_mean[120:165], leye_pose=p["leye_pose"],
               reye_pose=p["reye_pose"], transl=p["transl"]).vertices
    torch.testing.assert_close(again, res.vertices, atol=2e-4, rtol=0)


def _params_of(opt, truth):
    B = truth["z"].shape[0]
    p = {"transl": truth["transl"], "orient6d": matrix_to_rot6d(truth["R"]), "betas": truth["betas"],
         "z": truth["z"], "left_pca": truth["pca"]["left"], "right_pca": truth["pca"]["right"],
         "eyes": torch.zeros(B, 6)}
    if len(opt.free_ids):                                   # the free joints at zero residual: the prior's pose
        p["joint6d"] = torch.zeros(B, len(opt.free_ids), 6)
    return p


def test_energy_terms_against_independent_computations(bm, prior):
    verts, truth = _truth(bm, prior, B=1, seed=3)
    w = GraspPoseConfig().weights
    # the object: a box around the right palm, so that some hand vertices are inside it
    hand = hand_vertex_ids(bm, ("right",))
    centre = verts[0, hand].mean(0).double()
    box = trimesh.creation.box((0.06, 0.06, 0.06))
    box.apply_translation(centre.numpy())
    pts_np, face = trimesh.sample.sample_surface_even(box, 800, seed=0)
    pts = torch.tensor(pts_np, dtype=torch.float32)
    nrm = torch.tensor(box.face_normals[face], dtype=torch.float32)
    height = 0.7
    obj = GraspObject(pts, nrm, height=height, sdf=SDFGrid.from_mesh(box, resolution=40, padding=0.02))
    # E^B_colli on the hand vertices alone (Alg. 1's points; the extra points are checked below)
    opt = GraspPoseOpt(bm, prior, GraspPoseConfig(contact_points=800, collision_points=800, inner_depths=(),
                                                  forearms=False))
    p = _params_of(opt, truth)
    cm = torch.zeros(1, 143)
    cm[0, 100] = 1.0
    co = torch.zeros(1, len(pts))
    co[0, :5] = 1.0
    cache = opt._stage3_cache(p, obj, co)
    target = verts[:, opt.marker_ids]
    e = opt.energy(p, target, obj, 3, cm, co, cache)
    v = verts[0].double().numpy()
    # E_fit at the truth is the prior term only
    assert e["fit"].item() < 1e-3
    # ground: alpha_g sum |z + t_O - h0| over the sole vertices, h0 each one's height above its foot's lowest vertex
    # in the rest mesh (y up there); ground_rest=False: the paper's |z + t_O|
    f = foot_vertices(bm)
    feet = np.concatenate(list(f.values()))
    with torch.no_grad():
        rest_y = bm().vertices[0, :, 1].double().numpy()
    h0 = np.concatenate([rest_y[f[k]] - rest_y[np.concatenate([f[s + "_heel"], f[s + "_toe"]])].min()
                         for s in ("left", "right") for k in (s + "_heel", s + "_toe")])
    # + the floor term: a_floor times how far the lowest sole vertex is under the floor (0 when on or above it)
    under = max(0.0, -(v[feet, 2].min() + height))
    assert under > 0.01                                           # this body's soles are under the floor z = -t_O
    assert e["ground"].item() == pytest.approx(w.ground * np.abs(v[feet, 2] + height - h0).sum() + w.floor * under,
                                               rel=1e-3)
    paper = opt.with_config(ground_rest=False).energy(p, target, obj, 3, cm, co, cache)
    assert paper["ground"].item() == pytest.approx(w.ground * np.abs(v[feet, 2] + height).sum() + w.floor * under,
                                                   rel=1e-3)
    lifted = replace(obj, height=height + 1.0)                    # a metre lower floor: no floor term
    assert opt.energy(p, target, lifted, 3, cm, co, cache)["ground"].item() == pytest.approx(
        w.ground * np.abs(v[feet, 2] + height + 1.0 - h0).sum(), rel=1e-3)
    # marker contact: 15 * squared distance of marker 100 to its nearest object point
    d, _ = cKDTree(pts_np).query(v[opt.marker_ids[100]])
    assert e["contact_marker"].item() == pytest.approx(w.contact_marker * d ** 2, rel=1e-3)
    # object contact: 15 * sum over the 5 contact points of the squared distance to the nearest hand vertex
    both = hand_vertex_ids(bm)
    d, _ = cKDTree(v[both]).query(pts_np[:5])
    assert e["contact_object"].item() == pytest.approx(w.contact_object * (d ** 2).sum(), rel=1e-3)
    # hand in the box: alpha^B sum relu(-S - sigma) with the exact signed distance
    sd = signed_distance(torch.tensor(v[both]), box).numpy()
    want = w.colli_body * np.maximum(-sd - w.sigma_b, 0).sum()
    assert want > 0.5
    assert e["colli_body"].item() == pytest.approx(want, rel=0.05)
    assert e["colli_object"].item() > 0                                     # box points inside the closed hand too
    # a hinge floor lets penetration up to sigma go free: 3 mm subtracted from every depth, shallower ones cost 0
    floored = opt.with_config(weights=replace(w, sigma_b=3e-3)).energy(p, target, obj, 3, cm, co, cache)
    want3 = w.colli_body * np.maximum(-sd - 3e-3, 0).sum()
    assert 0 < want3 < want and floored["colli_body"].item() == pytest.approx(want3, rel=0.05)
    # graspkit's extra E^B points (the defaults): the hand vertices moved 5 and 10 mm inward along the normals of
    # the hand surface (here trimesh's, of the hand's own faces), and the forearm vertices
    full = opt.with_config(inner_depths=(0.005, 0.01), forearms=True).energy(p, target, obj, 3, cm, co, cache)
    f = bm.faces.numpy()
    pos = np.full(len(v), -1)
    pos[both] = np.arange(len(both))
    hf = pos[f][(pos[f] >= 0).all(1)]
    n = trimesh.Trimesh(v[both], hf, process=False).vertex_normals
    arm = forearm_vertex_ids(bm)
    q = np.concatenate([v[both] - 0.005 * n, v[both] - 0.01 * n, v[arm]])
    extra = w.colli_body * np.maximum(-signed_distance(torch.tensor(q), box).numpy(), 0).sum()
    assert extra > 0.5 * want                                               # the inner points are deeper still
    assert full["colli_body"].item() == pytest.approx(want + extra, rel=0.05)
    # stage 2 has the same points when stage2_collision, and the ground term when stage2_ground (nothing else)
    e2 = opt.with_config(inner_depths=(0.005, 0.01), forearms=True).energy(p, target, obj, 2, cm, co, cache)
    assert set(e2) == {"fit", "prior", "colli_body", "limits", "ground"}
    assert e2["colli_body"].item() == pytest.approx(want + extra, rel=0.05)
    assert e2["ground"].item() == pytest.approx(w.ground * np.abs(v[feet, 2] + height - h0).sum() + w.floor * under,
                                              rel=1e-3)
    assert "ground" not in opt.with_config(stage2_ground=False).energy(p, target, obj, 2, cm, co, cache)
    assert "ground" not in opt.with_config(ground=False).energy(p, target, obj, 2, cm, co, cache)
    assert "colli_body" not in opt.with_config(stage2_collision=False).energy(p, target, obj, 2, cm, co, cache)
    assert "colli_body" not in opt.with_config(collision=False).energy(p, target, obj, 2, cm, co, cache)
    # sunk_depth: E^O is switched off exactly while some hand vertex is deeper than it inside the box
    deepest = float(-sd.min())
    for depth, on in ((deepest + 2e-3, True), (deepest - 2e-3, False)):
        g = opt.with_config(sunk_depth=depth).energy(p, target, obj, 3, cm, co, cache)
        assert g["colli_object"].item() == (pytest.approx(e["colli_object"].item()) if on else 0.0)
        assert g["colli_body"].item() == pytest.approx(e["colli_body"].item())


def test_collision_stage_pushes_the_hand_out_of_the_object(bm, prior):
    verts, truth = _truth(bm, prior, B=1, seed=3)
    palm = torch.as_tensor(palm_vertices(bm)["right"])
    hand = hand_vertex_ids(bm, ("right",))
    # a ball pressed 1 cm into the palm, from the palm side
    out = verts[0, palm].mean(0) - verts[0, hand].mean(0)
    out = out / out.norm()
    r = 0.04
    ball, obj = _ball(verts[0, palm].mean(0) + out * (r - 0.01), r, 1000)
    opt = GraspPoseOpt(bm, prior, GraspPoseConfig(steps=(0, 0, 60), contact=False, ground=False))
    markers = verts[:, opt.marker_ids]
    res = opt.fit(markers, obj, init=_params_of(opt, truth), stages=(3,), progress=False)
    e = res.energies[0]
    assert e["before"]["colli_body"].item() > 1.0
    assert e["after"]["colli_body"].item() < 0.1 * e["before"]["colli_body"].item()
    depth = lambda vv: max(0.0, -signed_distance(vv[0, hand].double(), ball).min().item())  # noqa: E731
    assert depth(verts) > 0.008 and depth(res.vertices) < 0.25 * depth(verts)


def test_stage3_moves_only_its_variables(bm, prior):
    """Alg. 1's stage 3 frees the pose latent, hand PCA and eyes only; `stage3_free` adds the global translation."""
    verts, truth = _truth(bm, prior, B=1, seed=3)
    hand = hand_vertex_ids(bm, ("right",))
    _, obj = _ball(verts[0, hand].mean(0), 0.04)                        # the ball swallows the right hand
    cfg = GraspPoseConfig(steps=(0, 0, 20), contact=False, ground=False)
    opt = GraspPoseOpt(bm, prior, cfg)
    init = _params_of(opt, truth)
    markers = verts[:, opt.marker_ids]
    fixed = opt.fit(markers, obj, init=init, stages=(3,), progress=False)
    for k in ("transl", "orient6d", "betas"):
        assert torch.equal(fixed.state[k], init[k]), k
    assert not torch.equal(fixed.state["z"], init["z"])
    moved = opt.with_config(stage3_free=("transl",) + cfg.stage3_free).fit(markers, obj, init=init, stages=(3,),
                                                                            progress=False)
    assert (moved.state["transl"] - init["transl"]).norm() > 1e-3
    assert torch.equal(moved.state["betas"], init["betas"])
    with pytest.raises(ValueError, match="stage3_free"):
        opt.with_config(stage3_free=("wrist",)).fit(markers, obj, init=init, stages=(3,), progress=False)


def test_bad_inputs_are_named(bm, prior):
    opt = GraspPoseOpt(bm, prior)
    with pytest.raises(ValueError, match="markers"):
        opt.fit(torch.zeros(2, 100, 3), _dummy_object())
    with pytest.raises(ValueError, match="object_contact"):
        opt.fit(torch.zeros(2, 143, 3), _dummy_object(), torch.zeros(2, 143), torch.zeros(2, 7))
    with pytest.raises(ValueError, match="normals"):
        GraspObject(torch.zeros(10, 3), torch.zeros(9, 3), 1.0)
    with pytest.raises(ValueError, match="hand_contact_prior"):
        GraspPoseOpt(bm, prior, GraspPoseConfig(heuristic=True)).fit(torch.zeros(1, 143, 3), _dummy_object())
    with pytest.raises(ValueError, match=r"markers: expected at least one marker set \(B >= 1\), got 0"):
        opt.fit(torch.zeros(0, 143, 3), _dummy_object())
    obj = _dummy_object()                  # NaN points ran every stage, then failed naming rot_mats, betas, transl
    pts = obj.points.clone()
    pts[3, 1] = float("nan")
    with pytest.raises(ValueError, match="^points: contains NaN or Inf"):
        GraspObject(pts, obj.normals, 1.0)
    with pytest.raises(ValueError, match="^points: expected at least one point"):
        GraspObject(torch.zeros(0, 3), torch.zeros(0, 3), 1.0)
    with pytest.raises(ValueError, match="^height: nan, expected an object-centre height"):       # an IndexError
        GraspObject(obj.points, obj.normals, float("nan"))
    with pytest.raises(ValueError, match="^origin: contains NaN or Inf"):
        GraspObject(obj.points, obj.normals, 1.0, origin=torch.full((3,), float("nan")))
    for steps in ((-1, 2, 2), (1, 2), (1, 2.5, 3), (True, 2, 2)):
        with pytest.raises(ValueError, match=r"steps: expected three step counts >= 0"):
            GraspPoseOpt(bm, prior, GraspPoseConfig(steps=steps)).fit(torch.zeros(1, 143, 3), _dummy_object())


def test_contact_maps_markers_and_settings_are_checked_before_any_step(bm, prior):
    """A contact map of -1 made E^m_cont negative (the optimiser rewarded for leaving the object), NaN markers failed in
    the Kabsch SVD, markers in millimetres ran, one contact map alone dropped both contact terms, and nn_every 0,
    two learning rates or 50 hand components failed deep inside (an independent check): each is named."""
    opt = GraspPoseOpt(bm, prior)
    m, obj = torch.zeros(2, 143, 3), _dummy_object()
    mc, oc = torch.full((2, 143), 0.5), torch.full((2, obj.num_points), 0.5)
    for bad_mc, bad_oc, name in ((-mc, oc, "marker_contact"), (mc, 5 * oc, "object_contact"),
                                 (mc * float("nan"), oc, "marker_contact")):
        with pytest.raises(ValueError, match=f"{name}: expected contact probabilities in"):
            opt.fit(m, obj, bad_mc, bad_oc)
    with pytest.raises(ValueError, match="marker_contact, object_contact: .* need both"):
        opt.fit(m, obj, mc, None)
    nan = m.clone()
    nan[0, 3, 1] = float("nan")
    with pytest.raises(ValueError, match="markers: contains NaN"):
        opt.fit(nan, obj)
    with pytest.raises(ValueError, match="markers: largest side .* millimetres"):
        opt.fit(torch.randn(2, 143, 3, generator=torch.Generator().manual_seed(0)) * 300.0, obj)
    for kw, name in ((dict(nn_every=0), "nn_every"), (dict(log_every=0), "log_every"),
                     (dict(contact_points=0), "contact_points"), (dict(n_pca=50), "n_pca"),
                     (dict(lrs=(0.01, 0.01)), "lrs"), (dict(lrs=(0.01, -1.0, 0.01)), "lrs"),
                     (dict(collision="no"), "collision")):
        with pytest.raises(ValueError, match=f"{name}: expected"):
            GraspPoseConfig(**kw)
    for kw in (dict(colli_body=-200.0), dict(sigma_b=-0.01), dict(floor=float("nan"))):
        with pytest.raises(ValueError, match=f"{next(iter(kw))}: expected a finite number >= 0"):
            GraspPoseWeights(**kw)


def test_rotated_object_grid_matches_the_exact_signed_distance_of_the_turned_mesh():
    from graspkit.data.grasp_io import cached_sdf_grid
    from graspkit.objects import make_object
    R = axis_angle_to_matrix(torch.tensor([0.0, 0.0, 2.2]))
    mesh = make_object("mug")
    T = np.eye(4)
    T[:3, :3] = R.double().numpy()
    turned = mesh.copy().apply_transform(T)
    g = torch.Generator().manual_seed(0)
    q = (torch.rand(2, 300, 3, generator=g) - 0.5) * torch.tensor([0.16, 0.16, 0.14])
    obj = GraspObject(torch.zeros(2, 10, 3), torch.tensor([0.0, 0.0, 1.0]).expand(2, 10, 3),
                      torch.tensor([0.8, 0.9]), sdf=cached_sdf_grid("mug"), rotation=R.expand(2, 3, 3))
    want = signed_distance(q.double(), turned).float()
    got = obj.signed_distance(q)
    far = want.abs() > 0.004                      # beyond a cell of the 64-node grid the sign is exact
    assert (torch.sign(got[far]) == torch.sign(want[far])).all()
    assert (got - want).abs().median() < 5e-4
    pts, _, h = obj.batch(2)
    assert pts.shape == (2, 10, 3) and h[:, 0].tolist() == pytest.approx([0.8, 0.9])


def test_polish_continues_stage3_at_its_learning_rate(bm, prior):
    """`polish=(n, lr)` runs n more stage-3 steps on the same Adam state at lr. From a body that already fits its
    markers (the object far away), stage 3 at 0.008 only jitters: the polish at 1e-3 ends with a lower energy than
    as many more steps at 0.008; at a vanishing lr the result is stage 3's own; bad values are named."""
    verts, truth = _truth(bm, prior, B=1, seed=3)
    _, obj = _ball(verts[0].mean(0) + torch.tensor([2.0, 0.0, 0.0]), 0.04, 400)
    cfg = GraspPoseConfig(steps=(0, 0, 40), contact=False, ground=False, polish=(0, 0.0))
    opt = GraspPoseOpt(bm, prior, cfg)
    markers = verts[:, opt.marker_ids]
    init = _params_of(opt, truth)

    def run(polish):
        r = opt.with_config(polish=polish).fit(markers, obj, init=init, stages=(3,), progress=False)
        return r, sum(v.item() for v in r.energies[0]["after"].values())

    plain, e_plain = run((0, 0.0))
    still, _ = run((30, 1e-12))
    for k in plain.state:
        torch.testing.assert_close(still.state[k], plain.state[k], atol=1e-6, rtol=0)
    assert still.log[-1]["step"] > plain.log[-1]["step"]                    # the extra steps ran
    _, e_polish = run((30, 1e-3))
    _, e_longer = run((30, cfg.lrs[2]))                                      # as many steps at stage 3's own lr
    assert e_polish < e_longer and e_polish < e_plain, (e_polish, e_longer, e_plain)
    with pytest.raises(ValueError, match="polish"):
        run((10, 0.0))


def test_free_joints_reach_a_wrist_the_prior_cannot(bm, prior):
    """free_joints (docs/saga.md): at zero residual the body is the prior's; a wrist turned 50 degrees off the
    prior's pose is refitted far better with that wrist free than through the latent alone."""
    _, truth = _truth(bm, prior, B=2, seed=3)
    turn = axis_angle_to_matrix(torch.tensor([[0.0, 0.0, 0.87], [0.87, 0.0, 0.0]]))     # 50 degrees, per sample
    body = prior.decode_rotmats(truth["z"]).clone()
    body[:, 20] = body[:, 20] @ turn
    B = 2
    with torch.no_grad():
        verts = bm(betas=truth["betas"], global_orient=matrix_to_axis_angle(truth["R"]),
                   body_pose=matrix_to_axis_angle(body).reshape(B, 63),
                   left_hand_pose=truth["pca"]["left"] @ bm.left_hand_components[:24],
                   right_hand_pose=truth["pca"]["right"] @ bm.right_hand_components[:24],
                   transl=truth["transl"]).vertices
    cfg = GraspPoseConfig(steps=(60, 300, 300), collision=False, contact=False, ground=False, polish=(0, 0.0),
                          free_joints=())                                    # Alg. 1: the prior's latent alone
    plain, free = GraspPoseOpt(bm, prior, cfg), GraspPoseOpt(bm, prior, replace(cfg, free_joints=("right_wrist",)))
    p = {**_params_of(free, truth), "joint6d": torch.zeros(B, 1, 6)}
    torch.testing.assert_close(free.rotmats(p), plain.rotmats(_params_of(plain, truth)))
    markers = verts[:, plain.marker_ids]
    right = torch.as_tensor(np.isin(plain.marker_ids.numpy(), hand_vertex_ids(bm, ("right",))))  # right-hand markers
    errs = {}
    for name, opt in (("plain", plain), ("free", free)):
        res = opt.fit(markers, _dummy_object(), progress=False)
        errs[name] = float((res.markers - markers)[:, right].norm(dim=-1).mean())
    assert errs["free"] < 0.5 * errs["plain"], errs
    with pytest.raises(ValueError, match="free_joints"):
        GraspPoseOpt(bm, prior, GraspPoseConfig(free_joints=("right_hand",)))
    with pytest.raises(ValueError, match="free_joints"):
        plain.with_config(free_joints=("right_wrist", "right_wrist"))
    assert expand_free_joints(["neck", "arms"]) == ("neck",) + ARM_JOINTS        # the command line's shorthand
    assert expand_free_joints(["none"]) == () and GraspPoseConfig().free_joints == ARM_JOINTS   # the default
    # the rule the command line checks too: distinct SMPL-X body joints (indices into the 21 after the pelvis)
    assert body_joint_ids(("left_knee", "right_wrist")).tolist() == [JOINT_INDEX["left_knee"] - 1,
                                                                     JOINT_INDEX["right_wrist"] - 1]
    assert valid_body_joints(("left_knee", "head")) and not valid_body_joints(("jaw",))
    assert not valid_body_joints(("pelvis",)) and not valid_body_joints(("neck", "neck"))
    # weights.limits: the free joints' degrees past the human range, as metrics.joint_limit_violation counts them
    lim = GraspPoseOpt(bm, prior, replace(cfg, free_joints=("right_wrist", "right_collar"),
                                          weights=GraspPoseWeights(limits=0.05)))
    q = {**_params_of(lim, truth), "joint6d": torch.zeros(B, 2, 6)}
    q["joint6d"][:, 0] = matrix_to_rot6d(axis_angle_to_matrix(torch.tensor([0.0, 2.4, 0.0]))) - matrix_to_rot6d(
        torch.eye(3))                                                          # the wrist turned a further 137 deg
    e = lim.energy(q, markers, _dummy_object(), 1, None, None, {})
    aa = matrix_to_axis_angle(lim.rotmats(q).detach().double())
    want = joint_limit_violation(aa.numpy())[:, [21, 14]].sum(-1)              # SMPL-X joints right_wrist, right_collar
    assert want.min() > 10.0
    np.testing.assert_allclose(e["limits"].detach().numpy(), 0.05 * want, rtol=1e-3)
    GraspPoseOpt(bm, prior, GraspPoseConfig(free_joints=expand_free_joints(["arms"])))   # every arm joint is valid


def test_restart_keeps_the_lower_energy_run_per_sample(bm, prior):
    """restart_sunk: stage 3 also runs with E^O_colli gated while the hand is sunk; each sample keeps whichever of
    the two separately-run fits has the lower full energy, and for a hand swallowed by a ball that is the gated run,
    which lifts the hand out (less E^B_colli)."""
    verts, truth = _truth(bm, prior, B=2, seed=3)
    hand = hand_vertex_ids(bm, ("right",))
    _, obj = _ball(verts[0, hand].mean(0), 0.04)                        # swallows sample 0's right hand only
    # E^B_colli on the hand vertices alone (Alg. 1's): with the inner points the single run lifts this hand out too
    cfg = GraspPoseConfig(steps=(0, 0, 40), contact=False, ground=False, polish=(0, 0.0), restart_sunk=0.005,
                          inner_depths=(), forearms=False)
    opt = GraspPoseOpt(bm, prior, cfg)
    init = _params_of(opt, truth)
    markers = verts[:, opt.marker_ids]

    def run(o):
        return o.fit(markers, obj, init={k: v.clone() for k, v in init.items()}, stages=(3,), progress=False)

    both = run(opt)
    plain = run(opt.with_config(restart_sunk=None))
    gated = run(opt.with_config(sunk_depth=0.005, restart_sunk=None))
    cache = opt._stage3_cache({k: v.clone() for k, v in init.items()}, obj, None)
    with torch.no_grad():
        e = {n: sum(opt.energy(r.state, markers, obj, 3, None, None, cache).values()) for n, r in
             (("plain", plain), ("gated", gated), ("both", both))}
    want = e["gated"] < e["plain"]
    assert torch.equal(both.energies[0]["restarted"], want)
    torch.testing.assert_close(e["both"], torch.minimum(e["plain"], e["gated"]), rtol=1e-5, atol=1e-6)
    assert bool(want[0]), e                                                 # the sunk hand: the gated run wins ...
    assert float(gated.energies[0]["after"]["colli_body"][0]) < float(plain.energies[0]["after"]["colli_body"][0])
    for k in ("z", "right_pca", "joint6d"):                                 # ... and its state is kept as it was
        torch.testing.assert_close(both.state[k][0], gated.state[k][0])
    with pytest.raises(ValueError, match="restart_sunk"):
        run(opt.with_config(restart_sunk=-1.0))
    with pytest.raises(ValueError, match="inner_depths"):
        run(opt.with_config(inner_depths=(0.005, -0.01)))


def test_forearm_vertices_lie_between_elbow_and_wrist(bm):
    """forearm_vertex_ids: the vertices skinned mostly to the elbows, on the elbow-wrist segment, apart from the hands."""
    arm, hands = forearm_vertex_ids(bm), hand_vertex_ids(bm)
    assert len(arm) > 400 and not set(arm) & set(hands)
    with torch.no_grad():
        out = bm(betas=torch.zeros(1, 10))
    J, v = out.joints[0].double().numpy(), out.vertices[0].double().numpy()
    for side in ("left", "right"):
        ids = arm[(v[arm, 0] > 0) == (side == "left")]                         # the left arm is at +x at rest
        a, b = J[JOINT_INDEX[f"{side}_elbow"]], J[JOINT_INDEX[f"{side}_wrist"]]
        t = (v[ids] - a) @ (b - a) / np.dot(b - a, b - a)
        assert len(ids) > 200 and t.min() > -0.25 and t.max() < 1.25, (side, t.min(), t.max())


def test_stage2_collision_keeps_the_hand_out_of_an_object_the_markers_are_in(bm, prior):
    """stage2_collision: where the markers put the hand inside the object, E_fit alone follows them in during
    stage 2; with E^B_colli in stage 2 the body reaches them from outside and the hand stays (nearly) out."""
    verts, truth = _truth(bm, prior, B=1, seed=3)
    hand = hand_vertex_ids(bm, ("right",))
    ball, obj = _ball(verts[0, hand].mean(0), 0.03)                        # the ball swallows the right palm
    opt = GraspPoseOpt(bm, prior, GraspPoseConfig(steps=(100, 250, 0)))
    markers = verts[:, opt.marker_ids]
    depth = lambda r: max(0.0, -signed_distance(r.vertices[0, hand].double(), ball).min().item())  # noqa: E731
    s1 = opt.fit(markers, obj, stages=(1,), progress=False).state            # stage 1 is the same for both
    plain = opt.with_config(stage2_collision=False).fit(markers, obj, stages=(2,), init=s1, progress=False)
    kept = opt.fit(markers, obj, stages=(2,), init=s1, progress=False)
    assert depth(plain) > 0.015                                              # E_fit alone: into the ball
    # kept: 0 mm here and under two other sets of floating-point kernels, 3.1 mm under a third (plain 23-27 mm)
    assert depth(kept) < 0.005, depth(kept)
    assert "colli_body" in kept.energies[0]["after"] and "colli_body" not in plain.energies[0]["after"]


def test_stage2_ground_brings_the_soles_to_the_floor_with_the_markers_above_it(bm, prior):
    """stage2_ground: E_g acts in stage 2, where t is free. Markers of a body standing 3 cm above the floor: with
    E_g (202 sole vertices at weight 1 against E_fit's 143 L1 markers) stage 2 sets the soles on the floor; without
    it, stage 2 follows the markers and the soles stay 3 cm up."""
    verts, truth = _truth(bm, prior, B=1, seed=3)
    feet = torch.as_tensor(np.concatenate(list(foot_vertices(bm).values())))
    opt = GraspPoseOpt(bm, prior, GraspPoseConfig(steps=(100, 250, 0)))
    obj = _dummy_object()
    # the floor z = -height, 3 cm under where E_g would put the true soles (each at its rest height h0 above it)
    obj.height = 0.03 - float((verts[0, feet, 2] - opt.sole_rest).mean())
    markers = verts[:, opt.marker_ids]
    off = lambda r: float((r.vertices[0, feet, 2] + obj.height - opt.sole_rest).mean())  # noqa: E731  m
    s1 = opt.fit(markers, obj, stages=(1,), progress=False).state            # stage 1 is the same for both
    held = opt.fit(markers, obj, stages=(2,), init=s1, progress=False)
    free = opt.with_config(stage2_ground=False).fit(markers, obj, stages=(2,), init=s1, progress=False)
    assert "ground" in held.energies[0]["after"] and "ground" not in free.energies[0]["after"]
    assert abs(off(held)) < 0.005, off(held)
    assert off(free) > 0.025, off(free)


def test_floor_term_holds_the_lowest_sole_vertex_on_the_floor_under_sunk_markers(bm, prior):
    """weights.floor (graspkit's): markers of a rest body sunk 2 cm into the floor, E_g's L1 off (alpha_g = 0) so
    that only the one-sided floor term holds the body up: without it the lowest sole vertex follows the markers under
    the floor; with it (the default weight) it ends on the floor or just above, and the markers are still met within 2.5 cm."""
    up = axis_angle_to_matrix(torch.tensor([np.pi / 2, 0.0, 0.0]))
    with torch.no_grad():
        verts = bm(global_orient=matrix_to_axis_angle(up)[None]).vertices
    feet = torch.as_tensor(np.concatenate(list(foot_vertices(bm).values())))
    obj = _dummy_object()
    obj.height = -float(verts[0, :, 2].min()) - 0.02                 # the lowest vertex 2 cm under the floor
    default = GraspPoseWeights().floor
    assert default > 0
    low = {}
    for w in (0.0, default):
        opt = GraspPoseOpt(bm, prior, GraspPoseConfig(steps=(100, 150, 0), weights=GraspPoseWeights(ground=0.0, floor=w)))
        markers = verts[:, opt.marker_ids]
        r = opt.fit(markers, obj, progress=False)
        low[w] = float(r.vertices[0, feet, 2].min() + obj.height)
        err = float((r.markers - markers).norm(dim=-1).mean())
    assert low[0.0] < -0.015, low
    assert -0.001 < low[default] < 0.01, low            # one-sided: it may lift a little (Adam), not sink
    assert err < 0.025, err


def test_ground_from_the_rest_heights_stands_a_flat_footed_body_on_the_floor(bm, prior):
    """ground_rest: markers of a body in the rest pose (feet flat) whose lowest vertex is on the floor. E_g from
    each sole vertex's rest height keeps the lowest vertex on the floor; the paper's |h| (an L1 over each foot's
    lowest 2 cm, median 0.8 cm above the sole's bottom) sinks it under (both without the floor term, which would hold
    the paper's up as well: checked last)."""
    up = axis_angle_to_matrix(torch.tensor([np.pi / 2, 0.0, 0.0]))
    with torch.no_grad():
        verts = bm(global_orient=matrix_to_axis_angle(up)[None]).vertices
    feet = torch.as_tensor(np.concatenate(list(foot_vertices(bm).values())))
    obj = _dummy_object()
    obj.height = -float(verts[0, :, 2].min())                      # the lowest vertex on the floor
    opt = GraspPoseOpt(bm, prior, GraspPoseConfig(steps=(100, 150, 0), weights=GraspPoseWeights(floor=0.0)))
    markers = verts[:, opt.marker_ids]
    low = lambda r: float(r.vertices[0, feet, 2].min() + obj.height)  # noqa: E731  lowest sole vertex, m
    s1 = opt.fit(markers, obj, stages=(1,), progress=False).state            # stage 1 has no E_g: the same for both
    rest = opt.fit(markers, obj, stages=(2,), init=s1, progress=False)
    paper = opt.with_config(ground_rest=False).fit(markers, obj, stages=(2,), init=s1, progress=False)
    assert abs(low(rest)) < 0.002, low(rest)
    assert low(paper) < -0.004, low(paper)
    floored = opt.with_config(ground_rest=False, weights=GraspPoseWeights()).fit(markers, obj, stages=(2,), init=s1,
                                                                                 progress=False)
    assert low(floored) > -0.001, low(floored)


def _object(centre, n=300):
    pts = torch.tensor(trimesh.creation.icosphere(2, 0.05).vertices[:n], dtype=torch.float32)
    return GraspObject(pts + centre, torch.nn.functional.normalize(pts, dim=-1), height=1.0)


def test_alg1_frees_the_papers_variables_at_the_papers_learning_rates(bm, prior, monkeypatch):
    """SAGA appendix: Adam at 0.016, 0.012, 0.008 for stages 1-3; Alg. 1: stage 1 the global translation and
    rotation, stage 2 these with shape and the body pose latent (+ graspkit's free arm joints), stage 3 the pose
    latent, hand PCA and eyes (+ the arm joints); the polish goes on in stage 3 at its own lr. The energy is replaced
    by a constant: only the schedule is read, as (stage, i, lr, shapes of the optimised tensors)."""
    import graspkit.optim.grasppose as GP

    seen = []
    monkeypatch.setattr(GP, "energy_step", lambda opt, e, log, i, step, stage, every: seen.append(
        (stage, i, [g["lr"] for g in opt.param_groups], [tuple(p.shape) for g in opt.param_groups for p in g["params"]])))
    cfg = GraspPoseConfig(steps=(3, 4, 5), polish=(2, 1e-3), restart_sunk=None)
    assert GraspPoseConfig().lrs == (0.016, 0.012, 0.008) and GraspPoseConfig().steps == (300, 400, 500)
    opt = GraspPoseOpt(bm, prior, cfg)
    monkeypatch.setattr(opt, "energy", lambda *a, **k: {"fit": torch.zeros(1, requires_grad=True)})
    with torch.no_grad():
        markers = bm().vertices[:, saga_markers(bm).vertex_ids].float()
    opt.fit(markers, _object(markers[0].mean(0)), progress=False)
    L, A = prior.cfg.latent, len(cfg.free_joints)
    want = {1: [(1, 3), (1, 6)], 2: [(1, 3), (1, 6), (1, 10), (1, L), (1, A, 6)],
            3: [(1, L), (1, 24), (1, 24), (1, 6), (1, A, 6)]}
    assert [(s, i) for s, i, _, _ in seen] == [(1, i) for i in range(3)] + [(2, i) for i in range(4)] + \
        [(3, i) for i in range(7)]
    for stage, i, lrs, shapes in seen:
        assert shapes == want[stage], (stage, shapes)
        lr = (0.016, 0.012, 0.008)[stage - 1] if not (stage == 3 and i >= 5) else 1e-3
        assert lrs == [pytest.approx(lr)], (stage, i, lrs)


def test_object_contact_term_uses_the_points_of_highest_contact_probability(bm, prior):
    """Eq. 6's object side over cfg.contact_points object points: the ones of HIGHEST C^_O. 300 object points, C^_O
    random, contact_points = 20: alpha^o sum over the 20 most probable points of C^_O times the squared distance to the
    nearest hand vertex (scipy's KD-tree over both hands' vertices of the full mesh)."""
    opt = GraspPoseOpt(bm, prior, GraspPoseConfig(contact_points=20, collision=False, ground=False))
    with torch.no_grad():
        markers = bm().vertices[:, saga_markers(bm).vertex_ids].float()
        p = opt.init_params(markers)
        v = bm.forward_rotmats(opt.rotmats(p), betas=p["betas"], transl=p["transl"]).vertices[0].double().numpy()
    hand = hand_vertex_ids(bm)
    obj = _object(torch.as_tensor(v[hand].mean(0), dtype=torch.float32))
    g = torch.Generator().manual_seed(0)
    co = torch.rand(1, obj.num_points, generator=g)
    cm = torch.zeros(1, 143)
    cache = opt._stage3_cache(p, obj, co)
    e = opt.energy(p, markers, obj, 3, cm, co, cache)["contact_object"].item()
    top = np.argsort(-co[0].numpy())[:20]
    d, _ = cKDTree(v[hand]).query(obj.points.numpy()[top])
    want = opt.cfg.weights.contact_object * float((co[0].numpy()[top] * d ** 2).sum())
    assert want > 0 and e == pytest.approx(want, rel=1e-3)


def test_heuristic_contact_pulls_only_likely_hand_vertices_within_its_radius(bm, prior):
    """S.3 (WholeGrasp-single's heuristic contact): alpha^h sum of C_h d^2 over the hand vertices whose prior contact
    probability C_h is above 0.7 and whose nearest object point is closer than heuristic_radius (2 cm). A ball of 300
    points around the right hand: the truth from scipy's KD-tree over the full mesh's hand vertices."""
    hand = hand_vertex_ids(bm)
    g = torch.Generator().manual_seed(1)
    ch = torch.rand(len(hand), generator=g)
    opt = GraspPoseOpt(bm, prior, GraspPoseConfig(heuristic=True, contact=False, collision=False, ground=False),
                       hand_contact_prior=ch)
    with torch.no_grad():
        markers = bm().vertices[:, saga_markers(bm).vertex_ids].float()
        p = opt.init_params(markers)
        v = bm.forward_rotmats(opt.rotmats(p), betas=p["betas"], transl=p["transl"]).vertices[0].double().numpy()
    right = hand_vertex_ids(bm, ("right",))
    obj = _object(torch.as_tensor(v[right].mean(0), dtype=torch.float32))
    e = opt.energy(p, markers, obj, 3, None, None, opt._stage3_cache(p, obj, None))["heuristic"].item()
    d, _ = cKDTree(obj.points.numpy()).query(v[hand])
    w = opt.cfg.weights
    on = (ch.numpy() > 0.7) & (d < 0.02)
    assert on.any() and ((ch.numpy() > 0.7) & (d >= 0.02) & (d < 0.1)).any()   # both kinds of likely vertex
    assert e == pytest.approx(w.heuristic * float((on * ch.numpy() * d ** 2).sum()), rel=1e-3)


def test_fit_term_is_eq5s_l1_distance_to_the_markers(bm, prior):
    """SAGA Eq. 5: E_fit = |M^ - M(Theta)| (L1, summed over the 143 markers' coordinates), the markers read off the
    full mesh at SAGA's marker vertices; targets moved 0-3 cm from the body's markers."""
    opt = GraspPoseOpt(bm, prior, GraspPoseConfig(collision=False, ground=False, contact=False))
    ids = saga_markers(bm).vertex_ids
    with torch.no_grad():
        markers = bm().vertices[:, ids].float()
        p = opt.init_params(markers)
        v = bm.forward_rotmats(opt.rotmats(p), betas=p["betas"], transl=p["transl"]).vertices[0].double().numpy()
    g = torch.Generator().manual_seed(2)
    target = markers + 0.03 * torch.rand(markers.shape, generator=g)
    e = opt.energy(p, target, _object(markers[0].mean(0)), 1, None, None, {})["fit"].item()
    want = float(np.abs(v[ids] - target[0].double().numpy()).sum())
    assert want > 1.0 and e == pytest.approx(want, rel=1e-4)


def _box_cloud(n: int = 600, size: float = 0.06):
    """n points (seeded) on a cube of side `size` centred at 0, with its outward face normals."""
    box = trimesh.creation.box((size, size, size))
    pts, face = trimesh.sample.sample_surface(box, n, seed=0)
    return np.asarray(pts), box.face_normals[face]


def _cloud_sd(q, pts, nrm):
    """SAGA's S(x, Y) to a point cloud with outward normals: the distance to the nearest point, signed by its normal."""
    d, i = cKDTree(pts).query(q)
    return d * np.sign(((q - pts[i]) * nrm[i]).sum(-1))


def _cube_sd(x, c, half: float = 0.03):
    """Closed-form signed distance (> 0 outside) of points x (N,3) to the axis-aligned cube of half-side `half` at c."""
    q = np.abs(x - c) - half
    return np.linalg.norm(np.maximum(q, 0), axis=-1) + np.minimum(q.max(-1), 0)


def _hand_normals(bm, v):
    """trimesh's vertex normals of the hand surface (the body's faces whose vertices are all hand vertices)."""
    both = hand_vertex_ids(bm)
    f = bm.faces.numpy()
    pos = np.full(len(v), -1)
    pos[both] = np.arange(len(both))
    return both, trimesh.Trimesh(v[both], pos[f][(pos[f] >= 0).all(1)], process=False).vertex_normals


def test_energy_of_a_batch_is_each_samples_energy_alone(bm, prior):
    """Module doc: the samples of a batch are independent (energies per sample, summed only by the optimiser). Two
    bodies, each with its own object pose (a cube through sample 0's right hand, one shifted off sample 1's),
    floor height (sample 1's soles 1 cm under its floor, sample 0's above) and contacts, sunk_depth between the two
    hands' depths: every stage-2 and stage-3 term of the batch equals that sample's term computed alone."""
    _, truth = _truth(bm, prior, B=2, seed=3)
    opt0 = GraspPoseOpt(bm, prior)
    g = torch.Generator().manual_seed(4)
    p = _params_of(opt0, truth)
    p["eyes"] = 0.1 * torch.randn(2, 6, generator=g)
    p["joint6d"] = 0.05 * torch.randn(2, len(opt0.free_ids), 6, generator=g)
    with torch.no_grad():
        verts = bm.forward_rotmats(opt0.rotmats(p), betas=p["betas"], transl=p["transl"]).vertices
    hands = hand_vertex_ids(bm, ("right",))
    local, nrm = _box_cloud()
    centres = verts[:, hands].mean(1).double().numpy() + np.array([[0.0, 0, 0], [0.0, 0.0, 0.035]])
    pts = torch.tensor(local[None] + centres[:, None], dtype=torch.float32)
    nrms = torch.tensor(nrm, dtype=torch.float32).expand(2, -1, -1).contiguous()
    feet = np.concatenate(list(foot_vertices(bm).values()))
    low = verts[:, feet, 2].min(1).values
    height = torch.stack([-low[0] + 0.05, -low[1] - 0.01])

    # the hands' depths in their cubes (the cube's closed-form signed distance) and a sunk_depth between them
    depth = [max(0.0, -_cube_sd(verts[b, hand_vertex_ids(bm)].double().numpy(), centres[b]).min()) for b in range(2)]
    assert depth[0] > depth[1] + 2e-3 and depth[1] > 0, depth
    opt = opt0.with_config(sunk_depth=0.5 * (depth[0] + depth[1]), collision_points=200, contact_points=100)
    target = verts[:, opt.marker_ids] + 0.01 * torch.randn(2, 143, 3, generator=g)
    cm, co = torch.rand(2, 143, generator=g), torch.rand(2, pts.shape[1], generator=g)
    grid = SDFGrid.from_mesh(trimesh.creation.box((0.06, 0.06, 0.06)), resolution=32, padding=0.02)
    origin = torch.tensor(centres, dtype=torch.float32)
    obj = GraspObject(pts, nrms, height, sdf=grid, origin=origin)
    with torch.no_grad():
        full = {s: opt.energy(p, target, obj, s, cm, co, opt._stage3_cache(p, obj, co)) for s in (2, 3)}
        for b in range(2):
            one = {k: v[b:b + 1] for k, v in p.items()}
            ob = GraspObject(pts[b], nrms[b], float(height[b]), sdf=grid, origin=origin[b])
            for s in (2, 3):
                e = opt.energy(one, target[b:b + 1], ob, s, cm[b:b + 1], co[b:b + 1], opt._stage3_cache(one, ob, co[b:b + 1]))
                assert set(e) == set(full[s])
                for k in e:
                    torch.testing.assert_close(full[s][k][b:b + 1], e[k], rtol=1e-5, atol=1e-6, msg=f"{s} {k} {b}")
    # the set-up exercises what it should: E^O on for sample 1 (sample 0's hand is sunk), E^B for both
    assert full[3]["colli_object"][1] > 0 and full[3]["colli_object"][0] == 0 and (full[3]["colli_body"] > 0).all()


def test_energy_terms_take_their_own_weights_and_hinge_floors(bm, prior):
    """Eq. 5-7 with every weight distinct (A.4's equal ones would hide a swap): alpha_theta (|z|^2 + |theta_h|^2 +
    |theta_e|^2) + the free joints' weight |6D offsets|^2; alpha^m_cont sum C_m d(m, O) (scipy KD-tree); E^O_colli
    over the collision_points object points nearest the hand, alpha^O sum max(-S(o, V^h) - sigma_o, 0) with S signed
    by trimesh's hand vertex normals; stage 2's E^B_colli over the hand, its 5 / 10 mm inner copies and the forearms,
    alpha^B sum max(-S(b, O) - sigma_b, 0) with S the cube's closed form (read from its grid)."""
    verts, truth = _truth(bm, prior, B=1, seed=3)
    local, nrm = _box_cloud()
    right = hand_vertex_ids(bm, ("right",))
    c = verts[0, right].mean(0).double().numpy()
    pts_np = local + c
    grid = SDFGrid.from_mesh(trimesh.creation.box((0.06, 0.06, 0.06)), resolution=32, padding=0.02)
    obj = GraspObject(torch.tensor(pts_np, dtype=torch.float32), torch.tensor(nrm, dtype=torch.float32), 1.0,
                      sdf=grid, origin=torch.tensor(c, dtype=torch.float32))
    w = GraspPoseWeights(prior=2e-3, free_joints=7e-3, contact_marker=3.0, contact_object=7.0, colli_object=70.0,
                         colli_body=200.0, sigma_o=2e-3, sigma_b=3e-3)
    opt = GraspPoseOpt(bm, prior, GraspPoseConfig(collision_points=150, weights=w))
    g = torch.Generator().manual_seed(5)
    p = _params_of(opt, truth)
    p["eyes"] = 0.3 * torch.randn(1, 6, generator=g)
    p["joint6d"] = 0.05 * torch.randn(1, len(opt.free_ids), 6, generator=g)
    cm, co = torch.rand(1, 143, generator=g), torch.rand(1, len(pts_np), generator=g)
    cache = opt._stage3_cache(p, obj, co)
    target = verts[:, opt.marker_ids]
    with torch.no_grad():
        v = bm.forward_rotmats(opt.rotmats(p), betas=p["betas"], transl=p["transl"]).vertices[0].double().numpy()
        e3 = opt.energy(p, target, obj, 3, cm, co, cache)
        e2 = opt.energy(p, target, obj, 2, cm, co, cache)
    sq = lambda k: float(p[k].double().pow(2).sum())  # noqa: E731
    assert e3["prior"].item() == pytest.approx(2e-3 * (sq("z") + sq("left_pca") + sq("right_pca") + sq("eyes"))
                                               + 7e-3 * sq("joint6d"), rel=1e-5)
    d, _ = cKDTree(pts_np).query(v[opt.marker_ids])
    assert e3["contact_marker"].item() == pytest.approx(3.0 * float((cm[0].double().numpy() * d ** 2).sum()), rel=1e-3)
    # E^O_colli: the 150 object points nearest the hand vertices (both hands), inside the hand past sigma_o
    both, hn = _hand_normals(bm, v)
    dh, _ = cKDTree(v[both]).query(pts_np)
    near = np.argsort(dh)[:150]
    assert set(cache["collision_idx"][0].tolist()) == set(near.tolist())
    dd, j = cKDTree(v[both]).query(pts_np[near])
    so = dd * np.sign(((pts_np[near] - v[both][j]) * hn[j]).sum(-1))
    want_o = 70.0 * np.maximum(-so - 2e-3, 0).sum()
    assert want_o > 0.05 and np.maximum(-so, 0).sum() > 1.2 * np.maximum(-so - 2e-3, 0).sum()
    assert e3["colli_object"].item() == pytest.approx(want_o, rel=0.02)
    # stage 2's E^B_colli: hand vertices, their inner copies and the forearms, each past sigma_b
    q = np.concatenate([v[both], v[both] - 0.005 * hn, v[both] - 0.01 * hn, v[forearm_vertex_ids(bm)]])
    sb = _cube_sd(q, c)                                                         # the cube's closed-form S
    want_b = 200.0 * np.maximum(-sb - 3e-3, 0).sum()
    assert want_b > 1.0 and np.maximum(-sb, 0).sum() > 1.2 * np.maximum(-sb - 3e-3, 0).sum()
    assert e2["colli_body"].item() == pytest.approx(want_b, rel=0.05)


def test_result_in_the_world_reposes_with_smplx_parameters_and_carries_its_markers(bm, prior):
    """GraspPoseResult: its SMPL-X parameters (eyes, absolute hands) re-pose its vertices through BodyModel.forward;
    to_world(t) moves vertices, markers and transl by t, and the moved parameters re-pose the moved vertices, whose
    marker vertices are the moved markers (a rigid translation of everything)."""
    _, truth = _truth(bm, prior, B=2, seed=1)
    opt = GraspPoseOpt(bm, prior)
    p = _params_of(opt, truth)
    p["eyes"] = torch.tensor([[0.0, 0.6, 0.0, 0.0, -0.2, 0.3], [0.4, 0.0, 0.0, 0.0, 0.0, -0.5]])
    res = opt._result(p, [], [])
    t = torch.tensor([0.4, -1.2, 0.9])
    moved = res.to_world(t)
    for r in (res, moved):
        q = r.params
        again = bm(betas=q["betas"], global_orient=q["global_orient"], body_pose=q["body_pose"],
                   left_hand_pose=q["left_hand_pose"] - bm.pose_mean[75:120],
                   right_hand_pose=q["right_hand_pose"] - bm.pose_mean[120:165], leye_pose=q["leye_pose"],
                   reye_pose=q["reye_pose"], jaw_pose=q["jaw_pose"], transl=q["transl"]).vertices
        torch.testing.assert_close(again, r.vertices, atol=2e-4, rtol=0)
        torch.testing.assert_close(r.markers, r.vertices[:, opt.marker_ids])
    torch.testing.assert_close(moved.vertices, res.vertices + t)


def test_energies_table_sums_each_term_over_the_batch():
    """energies_table's docstring: one row per stage and term, before and after each summed over the batch."""
    e = [{"stage": 1, "before": {"fit": torch.tensor([1.0, 2.0])}, "after": {"fit": torch.tensor([0.5, 0.25])}},
         {"stage": 3, "before": {"fit": torch.tensor([0.5, 0.25]), "ground": torch.tensor([4.0, 0.0])},
          "after": {"fit": torch.tensor([0.1, 0.2]), "ground": torch.tensor([1.0, 1.0])}}]
    r = GraspPoseResult({}, torch.zeros(2, 1, 3), torch.zeros(2, 143, 3), e, [])
    rows = energies_table(r)
    assert [(x["stage"], x["term"]) for x in rows] == [(1, "fit"), (3, "fit"), (3, "ground")]
    assert [x["before"] for x in rows] == pytest.approx([3.0, 0.75, 4.0])
    assert [x["after"] for x in rows] == pytest.approx([0.75, 0.3, 2.0])


def test_inner_depths_must_be_strictly_positive(bm, prior):
    """fit's check (its message: depths in metres in (0, 0.05)): a depth of 0 would only repeat the hand vertices."""
    opt = GraspPoseOpt(bm, prior, GraspPoseConfig(inner_depths=(0.0, 0.01), steps=(1, 0, 0)))
    with pytest.raises(ValueError, match="inner_depths"):
        opt.fit(torch.zeros(1, 143, 3), _dummy_object(), progress=False)


def test_grid_signed_distance_takes_each_samples_own_origin():
    """GraspObject (B,3) origins, one per sample: S(x) from a ball's grid is |x - origin_b| - r for sample b's queries
    (the analytic distance of the 5 cm ball, within the 32-node grid's error)."""
    ball = trimesh.creation.icosphere(3, 0.05)
    grid = SDFGrid.from_mesh(ball, resolution=32, padding=0.02)
    origin = torch.tensor([[0.3, 0.0, 0.0], [-0.2, 0.1, 0.4]])
    g = torch.Generator().manual_seed(0)
    d = torch.nn.functional.normalize(torch.randn(2, 50, 3, generator=g), dim=-1)
    x = origin[:, None] + d * (0.02 + 0.05 * torch.rand(2, 50, 1, generator=g))
    obj = GraspObject(torch.zeros(2, 10, 3), torch.tensor([0.0, 0.0, 1.0]).expand(2, 10, 3),
                      torch.tensor([0.8, 0.9]), sdf=grid, origin=origin)
    want = (x - origin[:, None]).norm(dim=-1) - 0.05
    assert (obj.signed_distance(x) - want).abs().max() < 3e-3


def test_restart_reports_the_full_energy_of_the_run_it_keeps(bm, prior):
    """restart_sunk (module doc): each sample keeps the run with the lower FULL (ungated) energy, and stage 3's
    'after' energies are those of the kept parameters. A hand swallowed by a ball stays sunk through 3 steps, so its
    gated run still has E^O_colli > 0 in the full energy: the reported terms equal the full energy recomputed from
    the returned state, and the choice is the lower of the two runs' full energies."""
    verts, truth = _truth(bm, prior, B=1, seed=3)
    hand = hand_vertex_ids(bm, ("right",))
    _, obj = _ball(verts[0, hand].mean(0), 0.04)
    cfg = GraspPoseConfig(steps=(0, 0, 3), contact=False, ground=False, polish=(0, 0.0), restart_sunk=0.005,
                          inner_depths=(), forearms=False)
    opt = GraspPoseOpt(bm, prior, cfg)
    init = _params_of(opt, truth)
    markers = verts[:, opt.marker_ids]
    run = lambda o: o.fit(markers, obj, init={k: v.clone() for k, v in init.items()}, stages=(3,),  # noqa: E731
                          progress=False)
    both, plain = run(opt), run(opt.with_config(restart_sunk=None))
    gated = run(opt.with_config(sunk_depth=0.005, restart_sunk=None))
    cache = opt._stage3_cache({k: v.clone() for k, v in init.items()}, obj, None)
    with torch.no_grad():
        full = {n: opt.energy(r.state, markers, obj, 3, None, None, cache) for n, r in
                (("both", both), ("plain", plain), ("gated", gated))}
    assert full["gated"]["colli_object"][0] > 0                     # sample 0 still sunk: the gate matters here
    rep = both.energies[0]["after"]
    for k in full["both"]:
        torch.testing.assert_close(rep[k], full["both"][k], rtol=1e-4, atol=1e-5, msg=k)
    tot = {n: sum(e.values()) for n, e in full.items()}
    torch.testing.assert_close(both.energies[0]["restarted"], tot["gated"] < tot["plain"])
