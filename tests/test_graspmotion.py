"""GraspMotion-Opt (SAGA §3.4, Alg. 2): recovery of a known body sequence from its markers; S.2 and Eq. 11 on
hand-made cases."""
import numpy as np
import pytest
import torch
import trimesh
from scipy.spatial import cKDTree

from graspkit.body import BodyModel
from graspkit.body.markers import foot_vertices, palm_vertices, saga_sparse_markers
from graspkit.data import load_motion
from graspkit.eval_motionfill import heel_columns
from graspkit.models.pose_prior import load_pose_prior
from graspkit.objects.sdf import SDFGrid
from graspkit.optim.graspmotion import (GraspMotionConfig, GraspMotionOpt, GraspMotionWeights, MarkerDiffAE, in_box,
                                       load_smooth_ae, train_smooth_ae)
from graspkit.optim.grasppose import GraspObject, hand_vertex_ids
from graspkit.paths import DATA_STUBS, default_model_path
from graspkit.rotations import matrix_to_axis_angle, matrix_to_rot6d

from conftest import PROCEDURAL_MODEL


@pytest.fixture(scope="module")
def clip(bm):
    """12 frames of a shipped locomotion clip: markers, joints and betas of the known body."""
    m = load_motion(DATA_STUBS / "motion" / "locomotion" / "locomotion_000001.npz").slice(30, 42)
    flat = BodyModel.from_file(default_model_path(), flat_hand_mean=True)
    markers = saga_sparse_markers(bm).select(m.vertices(flat)).float()
    return markers, torch.as_tensor(m.joint_positions(flat)).float(), torch.as_tensor(m.betas).float(), m


def test_markers_of_a_known_sequence_give_the_sequence_back(bm, clip):
    markers, joints, betas, m = clip
    opt = GraspMotionOpt(bm, load_pose_prior(), None, GraspMotionConfig(terms=("smooth",)))
    res = opt.fit(markers[None], betas[None, :10], progress=False)
    err_m = (res.markers[0] - markers).norm(dim=-1).mean()
    err_j = (res.joints[0, :, :22] - joints[:, :22]).norm(dim=-1).mean()
    assert err_m < 0.015 and err_j < 0.03, (float(err_m), float(err_j))
    assert res.params["poses"].shape == (1, 12, 165) and res.energies["stage2"]["fit"] <= res.energies["stage1"]["fit"] * 1.5
    # the full mesh of the fitted parameters carries the fitted markers
    v = opt.vertices(res)
    torch.testing.assert_close(saga_sparse_markers(bm).select(v), res.markers[0], atol=1e-4, rtol=0)


def test_polish_removes_adams_frame_to_frame_jitter_on_a_body_standing_still(bm, clip):
    """A body standing still (one frame repeated): after Alg. 2's 300 steps at lr 0.005 Adam leaves every frame's
    parameters jittering, so the heel markers move between frames; the polish at lr 0.001 holds them far below
    SAGA's 75 mm/s skating threshold (the median over frames; the first frame has its own learning rate). Measured:
    13 mm/s against 34 without the polish (torch 2.13; 14 / 31 with other kernels, 20 / 48 on torch 2.3)."""
    markers, _, betas, _ = clip
    still = markers[:1].expand(len(markers), -1, -1)[None].clone()
    speeds = {}
    for polish in ((100, 1e-3), (0, 0.0)):
        opt = GraspMotionOpt(bm, load_pose_prior(), None, GraspMotionConfig(terms=("smooth",), polish=polish))
        h = opt.fit(still, betas[None, :10], progress=False).markers[0][:, heel_columns()]
        speeds[polish[0]] = float(((h[1:] - h[:-1]).norm(dim=-1) * 30).median())
    assert speeds[100] < 0.025 and speeds[100] < 0.5 * speeds[0], speeds          # a third of 75 mm/s; half
    with pytest.raises(ValueError, match="polish"):
        GraspMotionConfig(polish=(10, 0.0))


def test_sequences_of_a_batch_are_fitted_independently(bm, clip):
    """A sequence fitted alone and beside another (the same body 1 m away and 30 cm lower, walking backwards) gets
    the same bodies and energies, up to floating-point summation order (every term is a per-sequence sum; Adam is per
    parameter)."""
    markers, _, betas, _ = clip
    shift = torch.tensor([1.0, 0.0, -0.3])                # 30 cm lower: its own floor too
    other = markers.flip(0) + shift
    cfg = GraspMotionConfig(steps=(20, 20), polish=(10, 1e-3), terms=("smooth", "skate", "heel"))
    opt = GraspMotionOpt(bm, load_pose_prior(), None, cfg)
    feet = torch.full((len(markers), 4), 0.6)
    alone = opt.fit(markers[None], betas[None, :10], feet[None], progress=False)
    both = opt.fit(torch.stack([markers, other]), betas[None, :10].expand(2, -1), feet[None].expand(2, -1, -1),
                   progress=False)
    torch.testing.assert_close(both.markers[0], alone.markers[0], atol=1e-3, rtol=0)
    for k, e in alone.energies["stage2"].items():
        assert float(both.energies["stage2"][k][0]) == pytest.approx(float(e[0]), rel=0.05, abs=1e-3), k
    assert (both.markers[1] - both.markers[0] - shift).norm(dim=-1).mean() > 0.01


def test_foot_skating_term_is_analytic_for_a_sliding_body(bm):
    """A body translated by a constant 2 cm per frame: S.2 = a (|v| - sigma) per sole vertex and contact frame."""
    opt = GraspMotionOpt(bm, load_pose_prior(), None, GraspMotionConfig(terms=("skate",)))
    F = 5
    p = opt.init_params(torch.zeros(F, 79, 3), torch.zeros(F, 10))
    p = {k: torch.zeros_like(v) if k != "orient6d" else v for k, v in p.items()}
    p["transl"] = torch.arange(F, dtype=torch.float32)[:, None] * torch.tensor([0.02, 0.0, 0.0])
    contact = torch.zeros(1, F, 4)
    contact[:, :, 0] = 1.0                                       # left heel in contact on every frame
    e = opt.energy(p, torch.zeros(1, F, 79, 3), torch.zeros(F, 10), 2, contact, None, None)
    w = opt.cfg.weights
    n_heel = int((opt.foot_part == 0).sum())
    assert e["skate"].item() == pytest.approx(w.skate * n_heel * (F - 1) * (0.02 - w.skate_sigma), rel=1e-4)
    paper = GraspMotionOpt(bm, load_pose_prior(), None, GraspMotionConfig(terms=("skate",), one_foot_down=False))
    assert paper.energy(p, torch.zeros(1, F, 79, 3), torch.zeros(F, 10), 2, torch.zeros(1, F, 4), None,
                        None)["skate"].item() == 0.0
    # one_foot_down: with every probability below 0.5, the most probable part (here the right toe) still counts
    low = torch.full((1, F, 4), 0.1)
    low[:, :, 3] = 0.3
    n_toe = int((opt.foot_part == 3).sum())
    e = opt.energy(p, torch.zeros(1, F, 79, 3), torch.zeros(F, 10), 2, low, None, None)
    assert e["skate"].item() == pytest.approx(w.skate * n_toe * (F - 1) * (0.02 - w.skate_sigma), rel=1e-4)


def _sliding(opt, F: int, transl) -> dict:
    """Frame parameters of the prior's mean pose translated by `transl` (F, 3)."""
    p = opt.init_params(torch.zeros(F, 79, 3), torch.zeros(F, 10))
    p = {k: torch.zeros_like(v) if k != "orient6d" else v for k, v in p.items()}
    p["transl"] = transl
    return p


def test_planted_heel_term_is_analytic_and_off_when_a_heel_is_lifted(bm):
    """graspkit's planted-heel term on a body sliding 2 cm per frame: both heel markers move 2 cm, so it is
    a_heel (0.02 - sigma) per frame while both heels are within heel_height of the floor, and 0 above it."""
    opt = GraspMotionOpt(bm, load_pose_prior(), None, GraspMotionConfig(terms=("heel",)))
    F, w = 5, opt.cfg.weights
    p = _sliding(opt, F, torch.arange(F, dtype=torch.float32)[:, None] * torch.tensor([0.02, 0.0, 0.0]))
    heel_z = opt.body(p, torch.zeros(F, 10))[0][0, opt.sl_m][heel_columns(), 2]
    target = torch.zeros(1, F, 79, 3)
    on_floor = heel_z.min().reshape(1) - 0.01              # heels 1 cm (and a few mm) above the floor
    e = opt.energy(p, target, torch.zeros(F, 10), 2, None, None, None, on_floor)["heel"].item()
    assert e == pytest.approx(w.heel * (F - 1) * (0.02 - w.skate_sigma), rel=1e-4)
    held = opt.energy(p, target, torch.zeros(F, 10), 2, None, None, None, on_floor, held=True)["heel"].item()
    assert held == pytest.approx(w.heel_held * (F - 1) * (0.02 - w.skate_sigma), rel=1e-4)   # frame 0 held
    lifted = heel_z.max().reshape(1) - w.heel_height - 0.01    # both heels higher than heel_height: off
    assert opt.energy(p, target, torch.zeros(F, 10), 2, None, None, None, lifted)["heel"].item() == 0.0
    # a body standing still costs nothing
    still = _sliding(opt, F, torch.zeros(F, 3))
    assert opt.energy(still, target, torch.zeros(F, 10), 2, None, None, None, on_floor)["heel"].item() < 1e-3


def test_floor_term_is_the_sole_vertices_depth_below_a_given_floor_and_off_without_one(bm):
    """graspkit's floor term: w_floor times the summed depth below the floor given to `fit` of each frame's lowest sole
    vertex (`foot_vertices`), read here off the full mesh of the same parameters; 0 with the floor below the feet, and
    absent when no floor is given (the heel markers' default floor is not the ground)."""
    opt = GraspMotionOpt(bm, load_pose_prior(), None, GraspMotionConfig(terms=("floor",)))
    F, w = 3, opt.cfg.weights
    p = _sliding(opt, F, torch.arange(F, dtype=torch.float32)[:, None] * torch.tensor([0.0, 0.0, -0.01]))
    with torch.no_grad():
        v = bm.forward_rotmats(opt.rotmats(p), betas=torch.zeros(F, 10), transl=p["transl"]).vertices
    sole = v[:, np.concatenate(list(foot_vertices(bm).values())), 2]             # (F, n) heights
    args = (torch.zeros(1, F, 79, 3), torch.zeros(F, 10), 2, None, None, None)
    floor = sole.min() + 0.015                              # the first frame's lowest soles under it, later frames deeper
    e = opt.energy(p, *args, floor.reshape(1))["floor"].item()
    assert e == pytest.approx(w.floor * float(torch.relu(floor - sole.amin(1)).sum()), rel=1e-4) and e > 0
    assert opt.energy(p, *args, (sole.min() - 0.001).reshape(1))["floor"].item() == 0.0
    assert "floor" not in opt.energy(p, *args, None)


def test_fit_with_the_floor_keeps_the_body_on_it_where_the_markers_sink(bm, clip):
    """Markers of a walking clip lowered 2 cm into the floor z = 0: fitted without the floor term the soles follow
    them under it; with it at a_floor = 1000 (the floor given to `fit`, no foot contacts) the lowest vertex of every
    frame's full mesh stays above the floor (at most 2 mm under), and the markers are fitted within the 2 cm they
    sank (plus 5 mm) of the fit without it. (The default 3000 goes with the stand term, which needs the contacts:
    without them it throws this body up to 2.6 cm above the floor, docs/saga_motion.md, "The floor term".)"""
    markers, _, betas, _ = clip
    sunk = (markers - torch.tensor([0.0, 0.0, 0.02]))[None]
    low, err = {}, {}
    for terms in (("smooth",), ("smooth", "floor")):
        opt = GraspMotionOpt(bm, load_pose_prior(), None, GraspMotionConfig(steps=(60, 120), polish=(40, 1e-3),
                                                                            terms=terms,
                                                                            weights=GraspMotionWeights(floor=1000.0)))
        res = opt.fit(sunk, betas[None, :10], progress=False, floor=torch.zeros(1))
        low[terms[-1]] = float(opt.vertices(res)[..., 2].amin(-1).min())
        err[terms[-1]] = float((res.markers[0] - sunk[0]).norm(dim=-1).mean())
    assert low["smooth"] < -0.012 and low["floor"] > -0.002, low
    assert err["floor"] < err["smooth"] + 0.025, err


def test_stand_term_is_the_lowest_sole_vertex_above_the_floor_on_frames_with_a_foot_part_in_contact(bm):
    """graspkit's stand term: on each frame where a foot part is in contact (T_c of S.2), w_stand times how far the
    lowest sole vertex (the floor term's) stands above the floor plus stand_height, read here off the full mesh of the
    same parameters (a body rising 1 cm a frame); the same whichever part is in contact; 0 on frames with none
    (one_foot_down off); absent without a floor or without contacts."""
    opt = GraspMotionOpt(bm, load_pose_prior(), None, GraspMotionConfig(terms=("stand",), one_foot_down=False))
    F, w = 4, opt.cfg.weights
    p = _sliding(opt, F, torch.arange(F, dtype=torch.float32)[:, None] * torch.tensor([0.0, 0.0, 0.01]))
    with torch.no_grad():
        v = bm.forward_rotmats(opt.rotmats(p), betas=torch.zeros(F, 10), transl=p["transl"]).vertices
    sole = v[:, np.concatenate(list(foot_vertices(bm).values())), 2].amin(1)         # (F,) the lowest sole vertex
    floor = sole[0] - 0.002                                    # frame 0 stands within stand_height, the others above
    expected = w.stand * float(torch.relu(sole - floor - w.stand_height).sum())
    for part in range(4):                                      # FOOT_PARTS: left heel, left toe, right heel, right toe
        contact = torch.zeros(1, F, 4)
        contact[:, :, part] = 0.9
        args = (torch.zeros(1, F, 79, 3), torch.zeros(F, 10), 2, contact, None, None)
        e = opt.energy(p, *args, floor.reshape(1))["stand"].item()
        assert e == pytest.approx(expected, rel=1e-4) and e > 0
    contact[:, 2:, part] = 0.4                                 # no part down on frames 2-3: only frame 1 counts
    assert opt.energy(p, *args, floor.reshape(1))["stand"].item() == pytest.approx(
        w.stand * float(torch.relu(sole[1] - floor - w.stand_height)), rel=1e-4)
    assert "stand" not in opt.energy(p, *args, None)
    assert "stand" not in opt.energy(p, *args[:3], None, None, None, floor.reshape(1))
    # one_foot_down (the default): each frame's most probable part is down, so every frame counts
    always = GraspMotionOpt(bm, load_pose_prior(), None, GraspMotionConfig(terms=("stand",)))
    assert always.energy(p, *args, floor.reshape(1))["stand"].item() == pytest.approx(expected, rel=1e-4)


def test_fit_with_feet_in_contact_puts_them_on_the_floor_where_the_markers_float(bm, clip):
    """Markers of a walking clip lifted 3 cm above the floor z = 0, every foot part in contact: fitted with the
    floor term alone (it only pushes up) the body floats with them; with the stand term each frame's lowest vertex
    ends within stand_height (plus 2 mm) of the floor, the markers fitted within the 3 cm they rose (plus 5 mm)."""
    markers, _, betas, _ = clip
    lifted = (markers + torch.tensor([0.0, 0.0, 0.03]))[None]
    F = lifted.shape[1]
    low, err = {}, {}
    for terms in (("smooth", "floor"), ("smooth", "floor", "stand")):
        opt = GraspMotionOpt(bm, load_pose_prior(), None, GraspMotionConfig(steps=(60, 120), polish=(40, 1e-3),
                                                                            terms=terms))
        res = opt.fit(lifted, betas[None, :10], foot_contact=torch.ones(1, F, 4), progress=False,
                      floor=torch.zeros(1))
        low[terms[-1]] = opt.vertices(res)[..., 2].amin(-1)                     # (F,) each frame's lowest vertex
        err[terms[-1]] = float((res.markers[0] - lifted[0]).norm(dim=-1).mean())
    w = GraspMotionWeights()
    assert float(low["floor"].min()) > 0.015, low["floor"]
    assert float(low["stand"].max()) < w.stand_height + 0.002 and float(low["stand"].min()) > -0.002, low["stand"]
    assert err["stand"] < err["floor"] + 0.035, err


def test_foot_acceleration_term_is_zero_at_constant_velocity_and_analytic_at_constant_acceleration(bm):
    """The foot term graspkit adds beside S.2: sum over frames of the mean squared second difference of the foot
    vertices; a body at constant velocity gives 0, one at constant acceleration a (m/frame^2) gives w a^2 (F - 2)."""
    opt = GraspMotionOpt(bm, load_pose_prior(), None, GraspMotionConfig(terms=("skate",)))
    F, w, a = 6, opt.cfg.weights, 0.004
    t = torch.arange(F, dtype=torch.float32)[:, None]
    args = (torch.zeros(1, F, 79, 3), torch.zeros(F, 10), 2, None, None, None)
    assert opt.energy(_sliding(opt, F, t * torch.tensor([0.03, 0.01, 0.0])), *args)["foot_acc"].item() < 1e-3
    e = opt.energy(_sliding(opt, F, 0.5 * a * t ** 2 * torch.tensor([1.0, 0.0, 0.0])), *args)["foot_acc"].item()
    assert e == pytest.approx(w.foot_acc * a ** 2 * (F - 2), rel=1e-3)


def test_cloud_collision_hinge_is_analytic_inside_a_sphere_and_zero_outside_its_box(bm):
    """E^o_colli against a point cloud: queries inside a sphere of radius 5 cm get (r - |q| - sigma_b)_+ (SAGA's
    S(x, O) from the nearest point's normal); a query 3 cm outside the sphere's box gets 0 even where the nearest
    cloud point's normal is flipped (a thin wall's far side), which the normal's sign alone would call inside."""
    opt = GraspMotionOpt(bm, load_pose_prior())
    g = torch.Generator().manual_seed(0)
    n = torch.nn.functional.normalize(torch.randn(1, 4000, 3, generator=g), dim=-1)
    r, sig = 0.05, opt.cfg.weights.sigma_b
    q = torch.tensor([[[0.01, 0.0, -0.01], [0.02, 0.0, 0.0], [0.0, -0.03, 0.0], [0.0, 0.0, r + 0.03]]])
    flipped = n.clone()
    flipped[0, (r * n[0] - q[0, 3]).norm(dim=-1).argmin()] *= -1          # the far query's nearest point
    lo, hi = (r * n).min(1).values[:, None], (r * n).max(1).values[:, None]
    pen = opt.cloud_penetration(q, r * n, flipped, lo, hi)
    want = torch.relu(r - q[0, :3].norm(dim=-1) - sig)
    torch.testing.assert_close(pen[0, :3], want, atol=2e-3, rtol=0)      # the cloud's sampling: < 2 mm here
    assert pen[0, 3] == 0 and (pen[0, :3] > 0.01).all()
    from graspkit.optim.grasppose import _signed_to_cloud

    assert _signed_to_cloud(q[:, 3:], r * n, flipped)[0].item() < -0.02   # what the sign alone would say


def test_object_in_hand_hinge_measures_points_pushed_into_the_palm_and_ignores_points_outside(bm):
    """Eq. 7's second sum in GraspMotion-Opt: object points 4 mm inside the palm (along trimesh's vertex normals of
    the full body mesh) are 2-4 mm deep less sigma_o (the nearest hand vertex decides); points 4 mm outside and a
    point far from the hand's box are 0."""
    opt = GraspMotionOpt(bm, load_pose_prior())
    p = {"transl": torch.zeros(1, 3), "orient6d": torch.tensor([[1.0, 0, 0, 0, 1, 0]]), "z": torch.zeros(1, 32),
         "left_pca": torch.zeros(1, 24), "right_pca": torch.zeros(1, 24)}             # the prior's mean pose
    with torch.no_grad():
        full = bm.forward_rotmats(opt.rotmats(p), betas=torch.zeros(1, 10), transl=p["transl"]).vertices[0].double()
        hands = opt.body(p, torch.zeros(1, 10))[0][:, opt.sl_h].float()
    mesh = trimesh.Trimesh(full.numpy(), bm.faces.numpy(), process=False)
    ids = palm_vertices(bm)["right"]
    n = torch.as_tensor(mesh.vertex_normals[ids]).float()
    base = full[ids].float()
    d, sig = 0.004, opt.cfg.weights.sigma_o
    far = hands.max(1).values + 0.03
    pts = torch.cat([base - d * n, base + d * n, far])[None]
    pen = opt.object_in_hand(hands, pts)[0]
    k = len(ids)
    inside, outside = pen[:k], pen[k:2 * k]
    assert (inside > 0).float().mean() > 0.9 and (outside == 0).float().mean() > 0.9, (inside, outside)
    assert inside.max() <= d - sig + 1e-4 and abs(inside.median() - (d - sig)) < 5e-4
    assert pen[-1] == 0


def test_approach_scene_poses_the_collision_grid_where_its_mesh_is(bm):
    """The object of an approach clip in MotionFill's canonical frame: the catalogue collision grid read through
    GraspObject's rotation and origin gives trimesh's signed distance to the scene's mesh (opposite sign), also as a
    one-grid-per-sample list."""
    from graspkit.data.grasp_io import collision_sdf_grid
    from graspkit.eval_motionfill import approach_scene

    s = approach_scene(DATA_STUBS / "approach" / "approach_000000.npz", bm)
    pts = torch.as_tensor(s["points"]).float()
    obj = GraspObject(pts[None], torch.as_tensor(s["normals"]).float()[None], 0.0, [collision_sdf_grid(s["name"])],
                      torch.as_tensor(s["mesh_rotation"]).float()[None], torch.as_tensor(s["mesh_origin"]).float()[None])
    g = torch.Generator().manual_seed(0)
    q = pts[torch.randint(len(pts), (300,), generator=g)] + 0.01 * torch.randn(300, 3, generator=g)
    want = -trimesh.proximity.signed_distance(s["mesh"], q.double().numpy())        # trimesh: positive inside
    got = obj.signed_distance(q[None])[0].numpy()
    assert np.abs(got - want).max() < 1.5e-3 and (want < -1e-3).sum() > 30, np.abs(got - want).max()
    with pytest.raises(ValueError, match="sdf: 1 grids for a batch of 2"):
        obj.signed_distance(q[None].expand(2, -1, -1))
    # an object no frame comes near: both collision sums are 0 (the grid is not asked about zero points)
    opt = GraspMotionOpt(bm, load_pose_prior())
    p = _sliding(opt, 3, torch.zeros(3, 3))
    far = GraspObject(pts[None] + 10.0, obj.normals, 0.0, obj.sdf, obj.rotation, obj.origin + 10.0)
    e = opt.energy(p, torch.zeros(1, 3, 79, 3), torch.zeros(3, 10), 2, None, far, None)
    assert e["colli"].item() == 0.0


def test_palm_term_is_small_for_a_palm_facing_a_wall_and_large_for_a_wall_behind_it(bm):
    """Eq. 11 with the rest hand (palm facing -y) and a plane of points 3 mm below the palm (cos gamma ~ 1) or 3 mm
    past its highest palm vertex (the vector to the plane points against the palm normal: cos gamma ~ -1); only palm
    vertices within sigma of the object count."""
    opt = GraspMotionOpt(bm, load_pose_prior())
    rot = torch.eye(3).expand(1, 55, 3, 3)
    v, _ = opt.sparse(rot, torch.zeros(1, 10), torch.zeros(1, 3))
    hands = v[:, opt.sl_h].float()[:, None].expand(1, 3, -1, -1)              # three frames of the same hand
    palm = hands[0, 0, opt.palm]
    lo, hi = palm.min(0).values, palm.max(0).values
    xs = torch.arange(float(lo[0]) - 0.03, float(hi[0]) + 0.03, 0.002)
    zs = torch.arange(float(lo[2]) - 0.03, float(hi[2]) + 0.03, 0.002)
    grid = torch.stack(torch.meshgrid(xs, zs, indexing="ij"), -1).reshape(-1, 2)

    def plane(y: float) -> torch.Tensor:
        return torch.stack([grid[:, 0], torch.full((len(grid),), y), grid[:, 1]], -1)[None]

    facing = opt.palm_term(hands, plane(float(lo[1]) - 0.003)).item()
    behind = opt.palm_term(hands, plane(float(hi[1]) + 0.003)).item()
    assert behind > 1.0 and facing < 0.1 * behind, (facing, behind)
    # alpha_t = 1 - (t/T)^2 over frames 0, 1, 2 of 3: 1, 3/4 and 0 of the same hand's term
    one = [opt.palm_term(hands[:, :1], plane(float(hi[1]) + 0.003), torch.tensor([t]), total=3).item()
           for t in range(3)]
    assert one[0] > 0 and one[1] == pytest.approx(0.75 * one[0], rel=1e-5) and one[2] == 0.0
    assert behind == pytest.approx(1.75 * one[0], rel=1e-5)
    # the indicator 1(d < sigma), sigma = 1 cm: the same plane 3 cm past the palm (every palm vertex >= 3 cm away) is 0
    assert opt.cfg.weights.palm_sigma == pytest.approx(0.01)
    assert opt.palm_term(hands, plane(float(hi[1]) + 0.03)).item() == 0.0
    assert opt.palm_term(hands, plane(float(hi[1]) + 0.5)).item() == 0.0


def test_smoothness_autoencoder_trains_and_round_trips_its_checkpoint(tmp_path):
    g = np.random.default_rng(0)
    t = np.linspace(0, 2, 21)[None, :, None, None]
    markers = g.normal(0, 0.3, (16, 1, 79, 3)) + 0.2 * np.sin(t * g.uniform(1, 3, (16, 1, 1, 1)))
    ae, hist = train_smooth_ae(markers.astype(np.float32), epochs=25, out=tmp_path / "ae.pt")
    assert hist[-1] < 0.6 * hist[0]
    again = load_smooth_ae(tmp_path / "ae.pt")
    x = torch.as_tensor(np.diff(markers, axis=1)).float().flatten(2)
    torch.testing.assert_close(again.encode(x), ae.encode(x), atol=2e-2, rtol=2e-2)        # float16 weights
    assert isinstance(again, MarkerDiffAE)


def test_free_arm_joints_fit_a_wrist_the_prior_cannot_and_are_the_prior_at_zero(bm, clip):
    """GraspMotionConfig.free_joints (graspkit's, GraspPose-Opt's arm joints): at zero offsets the bodies are the
    prior's; a walking clip with its right wrist turned 50 degrees in every frame is refitted far closer on the
    right hand's markers with the arms free than through Alg. 2's prior latent alone."""
    from dataclasses import replace

    from scipy.spatial.transform import Rotation

    from graspkit.body.skeleton import JOINT_INDEX
    from graspkit.data.motion import Motion
    from graspkit.optim.grasppose import ARM_JOINTS

    _, _, betas, m = clip
    poses = m.poses.copy()
    w = JOINT_INDEX["right_wrist"]
    poses[:, w] = (Rotation.from_rotvec(poses[:, w]) * Rotation.from_rotvec([0.0, 0.0, 0.87])).as_rotvec()
    flat = BodyModel.from_file(default_model_path(), flat_hand_mean=True)
    ms = saga_sparse_markers(bm)
    markers = ms.select(Motion(poses, m.trans, m.betas, m.fps).vertices(flat)).float()
    cfg = GraspMotionConfig(terms=("smooth",), steps=(100, 150), polish=(0, 0.0))
    assert GraspMotionConfig().free_joints == ARM_JOINTS                                   # the arms by default
    plain, free = (GraspMotionOpt(bm, load_pose_prior(), None, replace(cfg, free_joints=j)) for j in ((), ARM_JOINTS))
    p = plain.init_params(markers, betas[None, :10].expand(len(markers), -1))
    q = {**p, "joint6d": torch.zeros(len(markers), len(ARM_JOINTS), 6)}
    torch.testing.assert_close(free.rotmats(q), plain.rotmats(p))
    right = torch.as_tensor(np.isin(ms.vertex_ids, hand_vertex_ids(bm, ("right",))))
    assert right.sum() >= 3
    err = {}
    for name, opt in (("plain", plain), ("free", free)):
        res = opt.fit(markers[None], betas[None, :10], progress=False)
        err[name] = float((res.markers[0] - markers)[:, right].norm(dim=-1).mean())
        assert "limits" in res.energies["stage2"] if name == "free" else "limits" not in res.energies["stage2"]
    assert err["free"] < 0.5 * err["plain"], err


def test_a_given_start_holds_frame_0_where_planted_feet_would_drag_it(bm, clip):
    """Markers of a walking clip with every foot part marked planted: S.2 fights the walk, and without a start body
    Alg. 2 moves frame 0 along the walk, off its markers; given start markers 3 cm behind the clip's first frame,
    stage 1 fits frame 0 to them and stage 2 leaves it there (frame 0's markers within 1 cm of the start), and the
    other frames fit the walk about as well as without it (within 1 cm on average)."""
    markers, _, betas, _ = clip
    feet = torch.ones(1, len(markers), 4)
    start = markers[0] - torch.tensor([0.03, 0.0, 0.0])
    opt = GraspMotionOpt(bm, load_pose_prior(), None, GraspMotionConfig(steps=(100, 120), polish=(40, 1e-3),
                                                                        terms=("smooth", "skate")))
    free = opt.fit(markers[None], betas[None, :10], feet, progress=False)
    held = opt.fit(markers[None], betas[None, :10], feet, progress=False, start=start[None])
    off = lambda res, ref: float((res.markers[0, 0] - ref).norm(dim=-1).mean())      # noqa: E731
    assert off(held, start) < 0.01 and off(free, markers[0]) > 2 * off(held, start), (off(held, start),
                                                                                       off(free, markers[0]))
    rest = lambda res: float((res.markers[0, 1:] - markers[1:]).norm(dim=-1).mean())  # noqa: E731
    assert rest(held) < rest(free) + 0.01, (rest(held), rest(free))
    with pytest.raises(ValueError, match="start"):
        opt.fit(markers[None], betas[None, :10], progress=False, start=start)


def test_a_held_start_fits_with_heel_held_and_a_free_one_with_heel(bm, clip):
    """fit(start=...) weighs the planted heel by weights.heel_held, fit without a start by weights.heel: each result
    is bit for bit the one whose other weight is set equal, and differs when the weight it uses changes."""
    markers, _, betas, _ = clip
    feet = torch.ones(1, len(markers), 4)
    start = markers[0] - torch.tensor([0.03, 0.0, 0.0])

    def fit(heel: float, heel_held: float, held: bool) -> torch.Tensor:
        cfg = GraspMotionConfig(steps=(20, 30), polish=(0, 1e-3), terms=("skate", "heel"),
                                weights=GraspMotionWeights(heel=heel, heel_held=heel_held))
        res = GraspMotionOpt(bm, load_pose_prior(), None, cfg).fit(
            markers[None], betas[None, :10], feet, progress=False, start=start[None] if held else None)
        return res.markers

    both = fit(1e4, 3e4, True)
    assert torch.equal(both, fit(3e4, 3e4, True)) and not torch.equal(both, fit(1e4, 1e4, True))
    free = fit(1e4, 3e4, False)
    assert torch.equal(free, fit(1e4, 1e4, False)) and not torch.equal(free, fit(3e4, 3e4, False))


def test_errors_name_the_argument(bm):
    opt = GraspMotionOpt(bm, load_pose_prior())
    with pytest.raises(ValueError, match="markers"):
        opt.fit(torch.zeros(1, 5, 80, 3), torch.zeros(1, 10))
    with pytest.raises(ValueError, match="foot_contact"):
        opt.fit(torch.zeros(1, 5, 79, 3), torch.zeros(1, 10), foot_contact=torch.zeros(1, 5, 2))
    for bad in (torch.tensor(0.0), torch.zeros(2), torch.tensor([float("nan")]), 0.0):
        with pytest.raises(ValueError, match="floor"):
            opt.fit(torch.zeros(1, 5, 79, 3), torch.zeros(1, 10), floor=bad)
    with pytest.raises(ValueError, match="flat_hand_mean"):
        GraspMotionOpt(BodyModel.from_file(default_model_path(), flat_hand_mean=True), load_pose_prior())
    nan = torch.zeros(1, 5, 79, 3)
    nan[0, 2, 7, 0] = float("nan")                                # an SVD error deep inside, before
    with pytest.raises(ValueError, match="markers: contains NaN"):
        opt.fit(nan, torch.zeros(1, 10))
    with pytest.raises(ValueError, match="betas: contains NaN"):
        opt.fit(torch.zeros(1, 5, 79, 3), torch.full((1, 10), float("nan")))
    with pytest.raises(ValueError, match="at least 2 frames"):
        opt.fit(torch.zeros(1, 1, 79, 3), torch.zeros(1, 10))
    with pytest.raises(ValueError, match="betas: expected a tensor"):
        opt.fit(torch.zeros(1, 5, 79, 3), torch.zeros(10))
    for steps in ((-1, 5), (1.5, 5), (5,)):                        # (-1, 5) skipped stage 1 silently
        with pytest.raises(ValueError, match="steps: expected"):
            GraspMotionConfig(steps=steps)


def test_marker_contact_term_is_eq6s_marker_side_on_the_last_five_frames(bm):
    """E^o_cont's marker side (Eq. 6 in Eq. 10): w_m sum over the last 5 frames and the 143 SAGA markers of C^_M times
    the squared distance to the nearest object point, the markers read off the full mesh and the distances from
    scipy's KD-tree; frames before the last five do not count, and C^_M = 0 gives 0."""
    from graspkit.body.markers import saga_markers

    opt = GraspMotionOpt(bm, load_pose_prior(), None, GraspMotionConfig(terms=("contact",)))
    F, w = 7, opt.cfg.weights
    p = _sliding(opt, F, torch.arange(F, dtype=torch.float32)[:, None] * torch.tensor([0.05, 0.0, 0.0]))
    g = torch.Generator().manual_seed(0)
    with torch.no_grad():
        full = bm.forward_rotmats(opt.rotmats(p), betas=torch.zeros(F, 10), transl=p["transl"]).vertices.double()
    pts = full[-1, 5000] + 0.05 * torch.nn.functional.normalize(torch.randn(500, 3, generator=g, dtype=torch.float64))
    up = torch.tensor([0.0, 0.0, 1.0]).expand(1, 500, 3)            # the contact term reads no normals
    obj = GraspObject(pts.float()[None], up, 0.0)
    c_m = torch.rand(1, 143, generator=g)
    args = (torch.zeros(1, F, 79, 3), torch.zeros(F, 10), 2, None, obj, None)
    e = opt.energy(p, *args, None, c_m)["contact"].item()
    d, _ = cKDTree(pts.numpy()).query(full[-5:, saga_markers(bm).vertex_ids].reshape(-1, 3).numpy())
    want = w.contact_marker * float((c_m.double().repeat(5, 1).reshape(-1) * torch.as_tensor(d) ** 2).sum())
    assert e == pytest.approx(want, rel=1e-3) and e > 0
    assert opt.energy(p, *args, None, torch.zeros(1, 143))["contact"].item() == 0.0
    assert "contact" not in opt.energy(p, *args, None, None)
    with pytest.raises(ValueError, match=r"marker_contact: expected shape \(1, 143\)"):
        opt.fit(torch.zeros(1, F, 79, 3), torch.zeros(1, 10), obj=obj, marker_contact=torch.zeros(1, 79),
                progress=False)


def test_marker_contact_brings_the_contact_markers_onto_an_object_the_markers_miss(bm, clip):
    """A walking clip's markers and a ball 2 cm past the right hand's palm markers at the last frame: fitted with
    C^_M = 1 on those markers (0 elsewhere) they end at least 5 mm closer to the ball (scipy's KD-tree on its points)
    than fitted without it, which leaves them where the markers put them, over 2 cm off. (The L1 marker fit holds
    them back: the squared distance's pull is 2 w_m d, 0.6 per marker at 2 cm.)"""
    from graspkit.body.markers import saga_markers

    markers, _, betas, m = clip
    ms = saga_markers(bm)
    flat = BodyModel.from_file(default_model_path(), flat_hand_mean=True)
    palm = [i for i, n in enumerate(ms.names) if i >= ms.groups["palm"][0] and n.startswith("R")]
    hand = torch.as_tensor(m.vertices(flat)[-1][ms.vertex_ids[palm]]).float()            # (k, 3)
    centre = hand.mean(0)
    out = torch.nn.functional.normalize(centre - torch.as_tensor(m.joint_positions(flat)[-1, 0]).float(), dim=0)
    g = torch.Generator().manual_seed(0)
    ball = torch.nn.functional.normalize(torch.randn(800, 3, generator=g), dim=-1)
    r = 0.04
    pts = centre + (r + 0.02) * out + r * ball
    obj = GraspObject(pts[None], ball[None], 0.0)
    c_m = torch.zeros(1, 143)
    c_m[0, palm] = 1.0
    cfg = GraspMotionConfig(steps=(40, 100), polish=(0, 1e-3), terms=("contact",))
    opt = GraspMotionOpt(bm, load_pose_prior(), None, cfg)
    gap = {}
    for name, c in (("without", None), ("with", c_m)):
        res = opt.fit(markers[None], betas[None, :10], obj=obj, progress=False, marker_contact=c)
        v = opt.vertices(res)[-1].double().numpy()
        gap[name] = float(cKDTree(pts.numpy()).query(v[ms.vertex_ids[palm]])[0].mean())
    assert gap["without"] > 0.02 and gap["with"] < gap["without"] - 0.005, gap


def test_object_contact_term_is_eq6s_object_side_on_the_last_five_frames_and_the_most_likely_points(bm):
    """E^o_cont's object side: w_o sum over the last 5 frames and the 256 object points of highest C^_O of C^_O times
    the squared distance to the nearest right-hand vertex (the right hand and palm vertices read off the full mesh,
    distances from scipy's KD-tree). The body slides 5 cm a frame, so the first frames are farther from the object."""
    opt = GraspMotionOpt(bm, load_pose_prior(), None, GraspMotionConfig(terms=("contact",)))
    F, w = 7, opt.cfg.weights
    p = opt.init_params(torch.zeros(F, 79, 3), torch.zeros(F, 10))
    p = {k: torch.zeros_like(v) if k != "orient6d" else v for k, v in p.items()}
    p["transl"] = torch.arange(F, dtype=torch.float32)[:, None] * torch.tensor([0.05, 0.0, 0.0])
    with torch.no_grad():
        full = bm.forward_rotmats(opt.rotmats(p), betas=torch.zeros(F, 10), transl=p["transl"]).vertices.double()
    hand_ids = np.union1d(hand_vertex_ids(bm, ("right",)), palm_vertices(bm)["right"])
    g = torch.Generator().manual_seed(0)
    centre = full[-1, hand_ids].mean(0)
    pts = centre + 0.06 * torch.nn.functional.normalize(torch.randn(500, 3, generator=g, dtype=torch.float64))
    up = torch.tensor([0.0, 0.0, 1.0]).expand(1, 500, 3)            # the contact term reads no normals
    obj = GraspObject(pts.float()[None], up, 0.0)
    c_o = torch.rand(1, 500, generator=g)
    e = opt.energy(p, torch.zeros(1, F, 79, 3), torch.zeros(F, 10), 2, None, obj, c_o)["contact"].item()
    top = np.argsort(-c_o[0].numpy())[:256]
    want = 0.0
    for t in range(F - 5, F):
        d, _ = cKDTree(full[t, hand_ids].numpy()).query(pts[top].numpy())
        want += float((c_o[0, top].double().numpy() * d ** 2).sum())
    assert e == pytest.approx(w.contact * want, rel=1e-3) and e > 0


def _schedule(bm, monkeypatch, start):
    """The learning rates of every Adam step of GraspMotionOpt.fit on 3 frames of the rest body's markers (the energy
    replaced by a constant: only the schedule is read), as (stage, i, [lr of each parameter group])."""
    import graspkit.optim.graspmotion as GM

    seen = []
    monkeypatch.setattr(GM, "energy_step", lambda opt, e, log, i, step, stage, every: seen.append(
        (stage, i, [(g["lr"], sum(p.numel() for p in g["params"])) for g in opt.param_groups])))
    opt = GraspMotionOpt(bm, load_pose_prior(), None, GraspMotionConfig(terms=("smooth",)))
    monkeypatch.setattr(opt, "energy", lambda *a, **k: {"fit": torch.zeros(1, requires_grad=True)})
    with torch.no_grad():
        m = saga_sparse_markers(bm).select(bm().vertices).float()            # (1, 79, 3)
    markers = m[:, None].expand(1, 3, -1, -1).clone()
    opt.fit(markers, torch.zeros(1, 10), progress=False, start=m.clone() if start else None)
    return seen


def test_alg2_learning_rate_schedule_is_the_papers(bm, monkeypatch):
    """SAGA appendix (GraspMotion-Opt): stage 1, 100 steps, lr 0.1 for the first frame and 0.01 for the others, 0.01
    after step 60 and 0.003 after step 80; stage 2, 300 steps at 0.01 decaying to 0.005 after step 150 (then
    graspkit's polish, 100 steps at 0.001). The first frame's group holds a third of the parameters of 3 frames."""
    seen = _schedule(bm, monkeypatch, start=False)
    s1 = [x for x in seen if x[0] == 1]
    s2 = [x for x in seen if x[0] == 2]
    assert len(s1) == 100 and len(s2) == 400
    for _, i, groups in s1:
        lrs = [g[0] for g in groups]
        assert lrs == ([0.1, 0.01] if i < 60 else [0.01, 0.01] if i < 80 else [0.003, 0.003]), (i, lrs)
        assert 2 * groups[0][1] == groups[1][1]                               # frame 0 vs frames 1-2
    for _, i, groups in s2:
        want = 0.01 if i < 150 else 0.005 if i < 300 else 1e-3
        assert [g[0] for g in groups] == [want, want], (i, groups)


def test_a_given_start_frame_is_fitted_in_stage_1_and_held_in_stage_2(bm, monkeypatch):
    """fit's docstring: with `start`, stage 1 fits frame 0 to the start body's markers and stage 2 holds it there: stage
    1 optimises both groups (frame 0 at lr 0.1), stage 2 only the other frames'."""
    seen = _schedule(bm, monkeypatch, start=True)
    assert all(len(g) == 2 and g[0][0] in (0.1, 0.01, 0.003) for s, _, g in seen if s == 1)
    assert [g[0][0] for s, i, g in seen if s == 1 and i == 0] == [0.1]
    assert all(len(g) == 1 for s, _, g in seen if s == 2)


def test_skating_term_counts_the_displacement_from_a_frame_in_contact(bm):
    """Module docstring: T_c are the frames whose contact is above 0.5 and v^foot a sole vertex's displacement to the
    next frame. A body sliding 2 cm a frame over 4 frames with the left heel in contact at frame 1 only (S.2 alone,
    one_foot_down off): one displacement (frame 1 -> 2) of each left-heel vertex counts; in contact at the last frame
    only, none does (no next frame)."""
    opt = GraspMotionOpt(bm, load_pose_prior(), None, GraspMotionConfig(terms=("skate",), one_foot_down=False))
    w, F = opt.cfg.weights, 4
    p = opt.init_params(torch.zeros(F, 79, 3), torch.zeros(F, 10))
    p = {k: torch.zeros_like(v) if k != "orient6d" else v for k, v in p.items()}
    p["transl"] = torch.arange(F, dtype=torch.float32)[:, None] * torch.tensor([0.02, 0.0, 0.0])
    n_heel = int((opt.foot_part == 0).sum())
    args = (torch.zeros(1, F, 79, 3), torch.zeros(F, 10), 2)
    c = torch.zeros(1, F, 4)
    c[0, 1, 0] = 1.0
    e = opt.energy(p, *args, c, None, None)["skate"].item()
    assert e == pytest.approx(w.skate * n_heel * (0.02 - w.skate_sigma), rel=1e-4)
    c = torch.zeros(1, F, 4)
    c[0, F - 1, 0] = 1.0
    assert opt.energy(p, *args, c, None, None)["skate"].item() == 0.0


def _params(opt: GraspMotionOpt, orient: torch.Tensor, transl: torch.Tensor) -> dict[str, torch.Tensor]:
    """Frame parameters of the prior's mean pose (zero latent, zero hand codes) with global rotations orient (F,3,3)
    and translations transl (F,3)."""
    F = len(transl)
    p = {"transl": transl.float(), "orient6d": matrix_to_rot6d(orient.float()), "z": torch.zeros(F, 32),
         "left_pca": torch.zeros(F, opt.cfg.n_pca), "right_pca": torch.zeros(F, opt.cfg.n_pca)}
    if len(opt.free_ids):
        p["joint6d"] = torch.zeros(F, len(opt.free_ids), 6)
    return p


def _still(opt: GraspMotionOpt, F: int, transl=None) -> dict[str, torch.Tensor]:
    """The mean pose, unrotated, at translations transl (F,3) (default 0)."""
    t = torch.zeros(F, 3) if transl is None else transl
    return _params(opt, torch.eye(3).expand(F, 3, 3), t)


def _rz(a: float) -> torch.Tensor:
    c, s = np.cos(a), np.sin(a)
    return torch.tensor([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]], dtype=torch.float32)


def _right_hand_ids(bm) -> np.ndarray:
    """The vertices of GraspMotion-Opt's hand slice: the right hand and its palm."""
    return np.union1d(hand_vertex_ids(bm, ("right",)), palm_vertices(bm)["right"])


def test_hand_codes_are_pca_about_each_hands_own_mean(bm):
    """rotmats: each hand's pose is its own 24 PCA coefficients times the model's components plus that hand's mean
    (flat_hand_mean=False), as BodyModel.forward with use_pca=True builds the same named SMPL-X parameters."""
    opt = GraspMotionOpt(bm, load_pose_prior(), None, GraspMotionConfig())
    g = torch.Generator().manual_seed(0)
    p = _still(opt, 2)
    p["left_pca"] = 0.8 * torch.randn(2, 24, generator=g)
    p["right_pca"] = 0.8 * torch.randn(2, 24, generator=g)
    rot = opt.rotmats(p)
    pca = BodyModel.from_file(PROCEDURAL_MODEL, use_pca=True, num_pca_comps=24)
    with torch.no_grad():
        out = pca(global_orient=matrix_to_axis_angle(rot[:, 0]), body_pose=matrix_to_axis_angle(rot[:, 1:22]).reshape(2, 63),
                  left_hand_pose=p["left_pca"], right_hand_pose=p["right_pca"], transl=p["transl"]).vertices
        got = opt.body(p, torch.zeros(2, 10))[0]
    torch.testing.assert_close(got[:, opt.sl_h], out[:, _right_hand_ids(bm)], atol=1e-4, rtol=0)
    torch.testing.assert_close(got[:, opt.sl_m], saga_sparse_markers(bm).select(out), atol=1e-4, rtol=0)


def test_init_params_put_the_mean_pose_exactly_on_rigidly_moved_markers(bm):
    """init_params (the prior's mean pose Kabsch-aligned to the markers): markers of the mean pose turned by 1 rad about
    z and 0.4 rad about x and moved by (0.5, -1.2, 0.9) m are met exactly (a rigid motion about the pelvis joint)."""
    opt = GraspMotionOpt(bm, load_pose_prior(), None, GraspMotionConfig())
    with torch.no_grad():
        m0 = opt.body(_still(opt, 1), torch.zeros(1, 10))[0][:, opt.sl_m]
    c, s = float(np.cos(0.4)), float(np.sin(0.4))
    R = _rz(1.0) @ torch.tensor([[1.0, 0, 0], [0, c, -s], [0, s, c]])
    target = m0 @ R.T + torch.tensor([0.5, -1.2, 0.9])
    p = opt.init_params(target, torch.zeros(1, 10))
    with torch.no_grad():
        got = opt.body(p, torch.zeros(1, 10))[0][:, opt.sl_m]
    torch.testing.assert_close(got, target, atol=2e-4, rtol=0)


def test_marker_fit_term_is_the_l1_distance(bm):
    """E_fit (Eq. 5 as GraspPose-Opt: L1 marker distance): every marker 1 cm, 2 cm and 5 mm off along x, y, z over 3
    frames gives 3 x 79 x 0.035."""
    opt = GraspMotionOpt(bm, load_pose_prior(), None, GraspMotionConfig(terms=()))
    F = 3
    p = _still(opt, F, torch.arange(F, dtype=torch.float32)[:, None] * torch.tensor([0.02, 0.0, 0.0]))
    with torch.no_grad():
        m = opt.body(p, torch.zeros(F, 10))[0][:, opt.sl_m]
        target = (m + torch.tensor([0.01, -0.02, 0.005]))[None]
        e = opt.energy(p, target, torch.zeros(F, 10), 2, None, None, None)["fit"].item()
    assert e == pytest.approx(F * 79 * 0.035, rel=1e-3)


def test_grid_collision_term_is_the_hand_depth_past_sigma_b(bm):
    """E^o_colli with the object's grid (Eq. 7's first sum, sigma_b = 1 mm): a box through the right hand gives
    w_colli sum over the hand vertices of (depth - sigma_b)_+, the depth from the analytic box SDF (the grid's
    trilinear values are exact near a face); the object-points sum is switched off."""
    cfg = GraspMotionConfig(terms=("colli",), weights=GraspMotionWeights(colli_object=0.0))
    opt = GraspMotionOpt(bm, load_pose_prior(), None, cfg)
    p = _still(opt, 2)
    with torch.no_grad():
        hands = opt.body(p, torch.zeros(2, 10))[0][0, opt.sl_h].double().numpy()
    centre = hands.mean(0)
    ext = np.array([0.3, 0.3, 0.3])
    box = trimesh.creation.box(extents=ext)
    origin = np.array([centre[0], centre[1], np.quantile(hands[:, 2], 0.3) - 0.15])   # its top face 30 % into the hand
    grid = SDFGrid.from_mesh(box, resolution=24)
    pts, fid = trimesh.sample.sample_surface_even(box, 2000, seed=0)
    obj = GraspObject(torch.as_tensor(pts + origin).float()[None], torch.as_tensor(box.face_normals[fid]).float()[None],
                      0.0, grid, torch.eye(3)[None], torch.as_tensor(origin).float()[None])
    q = np.abs(hands - origin) - ext / 2
    sdf = np.linalg.norm(np.maximum(q, 0), axis=1) + np.minimum(q.max(1), 0)
    w = opt.cfg.weights
    want = 2 * w.colli * np.maximum(-sdf - w.sigma_b, 0).sum()          # both frames
    assert (sdf < -0.005).sum() > 20
    with torch.no_grad():
        e = opt.energy(p, torch.zeros(1, 2, 79, 3), torch.zeros(2, 10), 2, None, obj, None)["colli"].item()
    assert e == pytest.approx(want, rel=0.03)


def test_palm_term_weighs_the_near_frames_by_their_place_in_the_sequence(bm):
    """Eq. 11's alpha_t = 1 - (t/T)^2 counts t over the whole sequence: of 3 frames, frame 0 far from the object and
    frames 1, 2 at a plane behind the palm, the energy is w_g (3/4 E(frame 1) + 0 E(frame 2))."""
    opt = GraspMotionOpt(bm, load_pose_prior(), None, GraspMotionConfig(terms=("palm",), point_stride=1))
    p = _still(opt, 3, torch.tensor([[-1.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]]))
    with torch.no_grad():
        hands = opt.body(p, torch.zeros(3, 10))[0][:, opt.sl_h].float()
    palm = hands[1, opt.palm]
    lo, hi = palm.min(0).values, palm.max(0).values
    xs = torch.arange(float(lo[0]) - 0.02, float(hi[0]) + 0.02, 0.003)
    zs = torch.arange(float(lo[2]) - 0.02, float(hi[2]) + 0.02, 0.003)
    grid = torch.stack(torch.meshgrid(xs, zs, indexing="ij"), -1).reshape(-1, 2)
    pts = torch.stack([grid[:, 0], torch.full((len(grid),), float(hi[1]) + 0.003), grid[:, 1]], -1)[None]
    obj = GraspObject(pts, torch.tensor([0.0, 1.0, 0.0]).expand_as(pts), 0.0)      # E_g reads no normals
    with torch.no_grad():
        e = opt.energy(p, torch.zeros(1, 3, 79, 3), torch.zeros(3, 10), 2, None, obj, None)["palm"].item()
        one = opt.palm_term(hands[1:2][None], pts, torch.tensor([0]), total=3).item()     # alpha = 1
    assert one > 0.5
    assert e == pytest.approx(opt.cfg.weights.palm * 0.75 * one, rel=1e-4)


def test_latent_smoothness_depends_on_marker_differences_only(bm):
    """S.1: S = AE(M_{1:T} - M_{0:T-1}) encodes marker differences, so E_smooth (shipped autoencoder) is the same for a
    walking body and the same body moved by (1, 2, 0.5) m on every frame."""
    opt = GraspMotionOpt(bm, load_pose_prior(), load_smooth_ae(), GraspMotionConfig(terms=("smooth",)))
    F = 6
    t = torch.arange(F, dtype=torch.float32)[:, None]
    walk = 0.03 * t * torch.tensor([1.0, 0.0, 0.0]) + 0.01 * t ** 2 * torch.tensor([0.0, 0.0, 1.0])
    args = (torch.zeros(1, F, 79, 3), torch.zeros(F, 10), 2, None, None, None)
    with torch.no_grad():
        e = opt.energy(_still(opt, F, walk), *args)["smooth"].item()
        moved = opt.energy(_still(opt, F, walk + torch.tensor([1.0, 2.0, 0.5])), *args)["smooth"].item()
    assert e > 0 and moved == pytest.approx(e, rel=1e-3)


UP = torch.tensor([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])    # canonical y up -> world z up


def test_default_floor_is_the_lowest_heel_marker_height_and_heels_10cm_up_are_lifted(bm):
    """graspkit's planted heel (module docstring): the floor defaults to the lowest heel marker of the target (its z, z
    up), and the term counts frames with both heel markers within 6 cm of it. A body sliding 2 cm a frame: target heels
    1 cm under the body's gives a_heel (0.02 - sigma) per frame; the right heel's target 1 m lower (the lowest) puts
    the floor 1 m down: 0; target heels 10 cm under the body's: 0 (lifted)."""
    opt = GraspMotionOpt(bm, load_pose_prior(), None, GraspMotionConfig(terms=("heel",)))
    F, w = 5, opt.cfg.weights
    p = _params(opt, UP.expand(F, 3, 3), torch.arange(F, dtype=torch.float32)[:, None] * torch.tensor([0.02, 0.0, 0.0]))
    hl, hr = heel_columns()
    with torch.no_grad():
        hz = opt.body(p, torch.zeros(F, 10))[0][:, opt.sl_m][:, [hl, hr], 2]
    low = float(hz.min())

    def energy(zl: float, zr: float) -> float:
        target = torch.zeros(1, F, 79, 3)
        target[..., 1] = -5.0                                           # far along y: not a height
        target[0, :, hl, 2], target[0, :, hr, 2] = zl, zr
        with torch.no_grad():
            return opt.energy(p, target, torch.zeros(F, 10), 2, None, None, None)["heel"].item()

    assert energy(low - 0.01, low - 0.01) == pytest.approx(w.heel * (F - 1) * (0.02 - w.skate_sigma), rel=1e-4)
    assert energy(low - 0.01, low - 1.0) == 0.0
    assert energy(low - 0.10, low - 0.10) == 0.0


def test_planted_heel_term_is_zero_while_one_heel_stands_still(bm):
    """The planted-heel term takes the slower heel marker (min(|v^LHEE|, |v^RHEE|) - sigma)_+: a z-up body turning
    0.1 rad a frame about a vertical axis through its left heel marker costs nothing (that heel stands still); the
    same turn about the pelvis moves both heels and costs a_heel (v_min - sigma) per frame."""
    opt = GraspMotionOpt(bm, load_pose_prior(), None, GraspMotionConfig(terms=("heel",)))
    F, w = 4, opt.cfg.weights
    hl, hr = heel_columns()
    with torch.no_grad():
        v, J = opt.body(_params(opt, UP[None], torch.zeros(1, 3)), torch.zeros(1, 10))
    J0 = J[0, 0].float()
    heel_l = v[0, opt.sl_m][hl].float()                                  # its place with orientation UP
    x_l = UP.T @ (heel_l - J0)                                           # the heel about J0 in the canonical frame
    R = torch.stack([_rz(0.1 * k) @ UP for k in range(F)])
    about_heel = torch.stack([UP @ x_l - R[k] @ x_l for k in range(F)])
    floor = (heel_l[2] - 0.01).reshape(1)
    e = {}
    for name, transl in (("heel", about_heel), ("pelvis", torch.zeros(F, 3))):
        p = _params(opt, R, transl)
        with torch.no_grad():
            m = opt.body(p, torch.zeros(F, 10))[0][:, opt.sl_m]
            e[name] = opt.energy(p, torch.zeros(1, F, 79, 3), torch.zeros(F, 10), 2, None, None, None, floor)["heel"].item()
        speed = (m[1:, [hl, hr]] - m[:-1, [hl, hr]]).norm(dim=-1)
        assert float((m[:, [hl, hr], 2] - floor).abs().max()) < 0.06
    assert float(speed.min()) > 2 * w.skate_sigma                       # (the pelvis turn: both heels move)
    assert e["heel"] < 1e-3
    want = w.heel * float((speed.min(-1).values - w.skate_sigma).clamp(min=0).sum())
    assert e["pelvis"] == pytest.approx(want, rel=1e-3)


def test_foot_contact_columns_are_left_heel_left_toe_right_heel_right_toe(bm):
    """S.2's contact probabilities come in the order of the module docstring (left heel, left toe, right heel, right
    toe): a body sliding 2 cm a frame with only column k in contact skates with the sole vertices of that part
    (foot_vertices), a (0.02 - sigma) per vertex and frame."""
    opt = GraspMotionOpt(bm, load_pose_prior(), None, GraspMotionConfig(terms=("skate",), one_foot_down=False))
    F, w = 4, opt.cfg.weights
    p = _still(opt, F, torch.arange(F, dtype=torch.float32)[:, None] * torch.tensor([0.02, 0.0, 0.0]))
    feet = foot_vertices(bm)
    for k, part in enumerate(("left_heel", "left_toe", "right_heel", "right_toe")):
        c = torch.zeros(1, F, 4)
        c[:, :, k] = 1.0
        with torch.no_grad():
            e = opt.energy(p, torch.zeros(1, F, 79, 3), torch.zeros(F, 10), 2, c, None, None)["skate"].item()
        assert e == pytest.approx(w.skate * len(feet[part]) * (F - 1) * (0.02 - w.skate_sigma), rel=1e-4), part


def test_in_box_widens_the_box_by_the_margin_on_both_sides():
    """in_box's docstring: inside [lo - margin, hi + margin] on every axis."""
    lo, hi = torch.zeros(1, 1, 3), torch.ones(1, 1, 3)
    x = torch.tensor([[[-0.01, 0.5, 0.5], [0.5, 1.01, 0.5], [0.5, 0.5, -0.03], [1.03, 0.5, 0.5], [0.5, 0.5, 0.5]]])
    assert in_box(x, lo, hi, 0.02).tolist() == [[True, True, False, False, True]]


@pytest.fixture(scope="module")
def pair(bm):
    """Two still bodies of different shapes (betas 0 and beta_0 = 2) fitted in one batch (1 + 1 steps)."""
    opt = GraspMotionOpt(bm, load_pose_prior(), None, GraspMotionConfig(steps=(1, 1), polish=(0, 0.0),
                                                                        terms=("smooth",)))
    betas = torch.zeros(2, 10)
    betas[1, 0] = 2.0
    with torch.no_grad():
        m = [saga_sparse_markers(bm).select(bm(betas=betas[b:b + 1]).vertices) for b in range(2)]
    markers = torch.stack([x.expand(3, -1, -1) for x in m]).float()
    return opt, opt.fit(markers, betas, progress=False), betas


def test_result_parameters_follow_the_smplx_layout(bm, pair):
    """The result's named parameters are the SMPL-X slices of `poses` (global_orient 0:3, body_pose 3:66, left hand
    75:120, right hand 120:165; absolute, hand mean included): a flat-hand-mean BodyModel fed those named parameters
    and each sequence's own betas gives the fitted markers back (two sequences of different shapes fitted together in
    one batch)."""
    _, res, betas = pair
    pr = res.params
    flat = BodyModel.from_file(PROCEDURAL_MODEL, flat_hand_mean=True)
    for b in range(2):
        with torch.no_grad():
            out = flat(betas=betas[b:b + 1].expand(3, -1), global_orient=pr["global_orient"][b],
                       body_pose=pr["body_pose"][b], left_hand_pose=pr["left_hand_pose"][b],
                       right_hand_pose=pr["right_hand_pose"][b], transl=pr["transl"][b])
        torch.testing.assert_close(saga_sparse_markers(bm).select(out.vertices), res.markers[b], atol=1e-4, rtol=0)
    torch.testing.assert_close(pr["body_pose"], pr["poses"][..., 3:66])


def test_contact_frames_0_means_no_object_contact_and_bad_settings_are_named(bm):
    """contact_frames = k puts E^o_cont on the last k frames: 0 is none (Python's x[-0:] had put it on every frame),
    k past the sequence is all of it; GraspMotionConfig / GraspMotionWeights name a bad setting before any work."""
    F = 6
    energies = {}
    for k in (0, 1, F, F + 3):
        opt = GraspMotionOpt(bm, load_pose_prior(), None, GraspMotionConfig(terms=("contact",), contact_frames=k))
        p = opt.init_params(torch.zeros(F, 79, 3), torch.zeros(F, 10))
        p = {n: torch.zeros_like(v) if n != "orient6d" else v for n, v in p.items()}
        p["transl"] = torch.arange(F, dtype=torch.float32)[:, None] * torch.tensor([0.05, 0.0, 0.0])
        pts = 0.3 + 0.05 * torch.nn.functional.normalize(torch.randn(200, 3, generator=torch.Generator().manual_seed(0)))
        obj = GraspObject(pts[None], torch.nn.functional.normalize(pts - 0.3)[None], 0.0)
        e = opt.energy(p, torch.zeros(1, F, 79, 3), torch.zeros(F, 10), 2, None, obj, torch.ones(1, 200))
        energies[k] = float(e.get("contact", torch.zeros(1)).sum())
    assert energies[0] == 0.0 and 0 < energies[1] < energies[F]
    assert energies[F + 3] == pytest.approx(energies[F], rel=1e-6)
    for kw, name in ((dict(contact_frames=-1), "contact_frames"), (dict(point_stride=0), "point_stride"),
                     (dict(n_pca=100), "n_pca"), (dict(n_pca=0), "n_pca"), (dict(one_foot_down="no"), "one_foot_down"),
                     (dict(terms=("colli", "contcat")), "terms"), (dict(terms="colli"), "terms")):
        with pytest.raises(ValueError, match=name):
            GraspMotionConfig(**kw)
    for kw, name in ((dict(skate=-300.0), "skate"), (dict(skate_sigma=float("nan")), "skate_sigma"),
                     (dict(palm_sigma=0.0), "palm_sigma"), (dict(colli=True), "colli")):
        with pytest.raises(ValueError, match=name):
            GraspMotionWeights(**kw)
    GraspMotionWeights(sigma_b=0.0, sigma_o=0.0)                  # the hinge floors may be 0 (GraspPose-Opt's are)


def test_fit_names_contact_maps_outside_0_1_and_too_many_betas(bm):
    """NaN contact maps used to give NaN bodies without a word, a negative C_O pushed the hand away, and 300 betas
    failed inside the body model."""
    opt = GraspMotionOpt(bm, load_pose_prior())
    m, b = torch.zeros(1, 5, 79, 3), torch.zeros(1, 10)
    pts = torch.nn.functional.normalize(torch.randn(50, 3, generator=torch.Generator().manual_seed(0)))
    obj = GraspObject(0.05 * pts[None], pts[None], 1.0)
    with pytest.raises(ValueError, match="object_contact: expected contact probabilities in"):
        opt.fit(m, b, obj=obj, object_contact=torch.full((1, 50), float("nan")))
    with pytest.raises(ValueError, match="object_contact: expected contact probabilities in"):
        opt.fit(m, b, obj=obj, object_contact=-torch.ones(1, 50))
    with pytest.raises(ValueError, match="marker_contact: expected contact probabilities in"):
        opt.fit(m, b, obj=obj, marker_contact=torch.full((1, 143), float("nan")))
    with pytest.raises(ValueError, match="foot_contact: expected contact probabilities in"):
        opt.fit(m, b, foot_contact=torch.full((1, 5, 4), 7.0))
    with pytest.raises(ValueError, match="betas: expected at most the body model's 10"):
        opt.fit(m, torch.zeros(1, 300))
    with pytest.raises(ValueError, match=r"^markers: expected at least one sequence \(B >= 1\)"):    # a reshape error
        opt.fit(torch.zeros(0, 5, 79, 3), torch.zeros(0, 10))


def test_touch_term_is_the_closest_hand_vertex_past_the_gap_on_the_last_frames(bm):
    """graspkit's touch term (stage 2's polish) with the object's grid: a box under the right hand, its top face 8 mm
    below the lowest hand vertex, gives w_touch (min over the hand vertices of the analytic box SDF - touch_gap) on
    each of the last contact_frames frames (F = 7 still frames: 5 of them); absent outside the polish; 0 with the top
    face 0.5 mm below (within the gap) or cutting into the hand; without a grid it reads the nearest object point (SAGA's S(x, Y), of every 4th point), at
    most the points' spacing (3 mm here) farther than the face."""
    cfg = GraspMotionConfig(terms=("touch",))
    opt = GraspMotionOpt(bm, load_pose_prior(), None, cfg)
    F, w = 7, opt.cfg.weights
    p = _still(opt, F)
    with torch.no_grad():
        hands = opt.body(p, torch.zeros(F, 10))[0][0, opt.sl_h].double().numpy()
    ext = np.array([0.3, 0.3, 0.3])
    box = trimesh.creation.box(extents=ext)
    grid = SDFGrid.from_mesh(box, resolution=24)
    pts, fid = trimesh.sample.sample_surface_even(box, 20000, seed=0)
    args = (torch.zeros(1, F, 79, 3), torch.zeros(F, 10), 2, None)
    for below, want_on in ((0.008, True), (0.0005, False), (-0.01, False)):
        origin = np.array([*hands[:, :2].mean(0), hands[:, 2].min() - below - ext[2] / 2])
        q = np.abs(hands - origin) - ext / 2
        sdf = np.linalg.norm(np.maximum(q, 0), axis=1) + np.minimum(q.max(1), 0)
        want = 5 * w.touch * max(sdf.min() - w.touch_gap, 0.0)
        assert (want > 0) == want_on
        for g in (grid, None):
            obj = GraspObject(torch.as_tensor(pts + origin).float()[None],
                              torch.as_tensor(box.face_normals[fid]).float()[None], 0.0, g, torch.eye(3)[None],
                              torch.as_tensor(origin).float()[None])
            with torch.no_grad():
                e = opt.energy(p, *args, obj, None, polish=True)["touch"].item()
                assert "touch" not in opt.energy(p, *args, obj, None)          # only in stage 2's polish
            if g is not None:
                assert e == pytest.approx(want, rel=0.02, abs=1e-3), below
            else:                     # the nearest of every 4th point: farther than the face by up to its spacing
                assert want - 1e-3 <= e <= want + 5 * w.touch * 0.003, (below, e, want)


def test_touch_brings_the_hand_onto_an_object_the_markers_miss(bm, clip):
    """A walking clip's markers and a ball 8 mm past the right hand's closest vertex at the last frame (its grid
    from trimesh's icosphere): fitted with the touch term (100 polish steps at lr 1e-3) the hand ends within 2 mm of
    the ball (the exact signed distance, `objects.sdf.signed_distance`) and not more than 2 mm into it (-1.0 mm
    measured: the collision hinge lets it 1 mm in); without it over 6 mm off (18.9 mm measured: the fit stands the
    hand a little farther off than the clip)."""
    from graspkit.objects.sdf import signed_distance

    markers, _, betas, m = clip
    flat = BodyModel.from_file(default_model_path(), flat_hand_mean=True)
    hand = torch.as_tensor(m.vertices(flat)[-1][_right_hand_ids(bm)]).double()           # (H, 3)
    centre = hand.mean(0)
    out = torch.nn.functional.normalize(centre - torch.as_tensor(m.joint_positions(flat)[-1, 0]).double(), dim=0)
    r = 0.05
    ball = trimesh.creation.icosphere(subdivisions=4, radius=r)
    s = r + 0.05                                     # the centre along `out`, moved until the gap is 8 mm
    for _ in range(20):
        s += 0.008 - (float((hand - (centre + s * out)).norm(dim=-1).min()) - r)
    c = centre + s * out
    mesh = trimesh.Trimesh(ball.vertices + c.numpy(), ball.faces)
    pts, fid = trimesh.sample.sample_surface_even(ball, 2048, seed=0)
    obj = GraspObject(torch.as_tensor(pts + c.numpy()).float()[None],
                      torch.as_tensor(ball.face_normals[fid]).float()[None], 0.0, SDFGrid.from_mesh(ball, resolution=32),
                      torch.eye(3)[None], c.float()[None])
    end = {}
    for terms in (("colli",), ("colli", "touch")):
        cfg = GraspMotionConfig(steps=(40, 60), polish=(100, 1e-3), terms=terms)
        opt = GraspMotionOpt(bm, load_pose_prior(), None, cfg)
        res = opt.fit(markers[None], betas[None, :10], obj=obj, progress=False)
        v = opt.vertices(res)[-1].double()[_right_hand_ids(bm)]
        end[terms[-1]] = float(signed_distance(v, mesh).min())
    assert end["colli"] > 0.006 and -0.002 < end["touch"] < 0.002, end
