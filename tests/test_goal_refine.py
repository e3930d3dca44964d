"""GOAL's refinements (Eq. 4-8 for GNet, Eq. 12-13 for MNet) on cases with a known answer."""
import functools
import math

import numpy as np
import pytest
import torch
from scipy.spatial import cKDTree

from graspkit.body import BodyModel
from graspkit.body.markers import goal_vertices
from graspkit.body.skeleton import JOINT_INDEX as J
from graspkit.models.gnet import SparseBody, pose_rotmats
from graspkit.optim.goal_refine import (GraspRefiner, GraspRefineWeights, MotionRefineWeights, hand_object_offsets,
                                        hand_step_targets, refine_frame)
from graspkit.paths import default_model_path
from graspkit.rotations import axis_angle_to_rot6d


@pytest.fixture(scope="module")
def setup():
    bm = BodyModel.from_file(default_model_path(), flat_hand_mean=True)
    gv = goal_vertices(bm)
    return bm, gv, GraspRefiner(bm, gv)


def _sphere(centre, radius, n=3000):
    i = torch.arange(n) + 0.5
    phi, th = torch.acos(1 - 2 * i / n), math.pi * (1 + 5 ** 0.5) * i
    return torch.stack([torch.cos(th) * torch.sin(phi), torch.sin(th) * torch.sin(phi), torch.cos(phi)], 1) * radius + centre


def _grasp_pose():
    """A standing body (z up) with the right arm lowered and the fingers curled."""
    aa = torch.zeros(1, 55, 3, dtype=torch.float64)
    aa[0, 0] = torch.tensor([math.pi / 2, 0, 0])
    aa[0, J["right_shoulder"]] = torch.tensor([0, 0, 0.9])
    aa[0, 40:55, 2] = 0.3
    return aa


def test_offsets_match_a_kd_tree():
    g = torch.Generator().manual_seed(0)
    pts, obj = torch.randn(2, 50, 3, generator=g), torch.randn(2, 300, 3, generator=g)
    d = hand_object_offsets(pts, obj)
    for b in range(2):
        _, idx = cKDTree(obj[b].numpy()).query(pts[b].numpy())
        np.testing.assert_allclose(d[b].numpy(), obj[b].numpy()[idx] - pts[b].numpy(), atol=1e-6)


def test_grasp_refinement_recovers_a_known_grasp(setup):
    bm, gv, ref = setup
    aa, betas = _grasp_pose(), torch.zeros(1, 10)
    rot6d, transl = axis_angle_to_rot6d(aa).float(), torch.zeros(1, 3)
    transl[0, 2] -= ref.vertices(rot6d, transl, betas)[0, :, 2].min()            # standing on z = 0
    v = ref.vertices(rot6d, transl, betas)
    hand = v[:, :99]
    obj = _sphere(hand[0].mean(0) + torch.tensor([0, 0, -0.05]), 0.045)       # a ball under the palm
    q = torch.nn.functional.normalize(v[:, 401] - v[:, 400], dim=-1)
    wrong = aa.clone()                                                          # GNet's "prediction": wrist, elbow,
    wrong[0, J["right_wrist"]] += torch.tensor([0.25, 0.1, -0.1], dtype=torch.float64)   # fingers and root off
    wrong[0, J["right_elbow"]] += torch.tensor([0.0, 0.15, 0.0], dtype=torch.float64)
    wrong[0, 40:55, 2] += 0.2
    hat = {"rot6d": axis_angle_to_rot6d(wrong).float(), "transl": transl + torch.tensor([[0.02, -0.015, 0.01]]),
           "head_dir": q, "hand_offsets": hand_object_offsets(hand, obj[None])}
    before = (ref.vertices(hat["rot6d"], hat["transl"], betas)[:, :99] - hand).norm(dim=-1).mean()
    out = ref(hat, betas, obj, GraspRefineWeights(steps=200))
    after_v = ref.vertices(out.rot6d, out.transl, betas)
    after = (after_v[:, :99] - hand).norm(dim=-1).mean()
    assert before > 0.05 and after < 0.005                                     # 7 cm -> a few mm
    assert abs(float(after_v[0, :, 2].min())) < 1e-3                            # Eq. 7: on the ground
    assert out.history[-1]["d"] < 0.1 * out.history[0]["d"]


def test_foot_term_alone_puts_the_lowest_vertex_on_the_ground(setup):
    bm, gv, ref = setup
    rot6d, betas = axis_angle_to_rot6d(_grasp_pose()).float(), torch.zeros(1, 10)
    transl = torch.zeros(1, 3)
    transl[0, 2] += 0.04 - ref.vertices(rot6d, transl, betas)[0, :, 2].min()     # floating 4 cm above the floor
    v = ref.vertices(rot6d, transl, betas)
    hat = {"rot6d": rot6d, "transl": transl, "head_dir": torch.nn.functional.normalize(v[:, 401] - v[:, 400], dim=-1),
           "hand_offsets": torch.zeros(1, 99, 3)}
    out = ref(hat, betas, torch.zeros(1, 3), GraspRefineWeights(d=0.0, q=0.0, gamma=0.0, steps=150, lr=2e-3))
    full = bm.forward_rotmats(pose_rotmats(out.rot6d), betas=betas, transl=out.transl).vertices
    assert abs(float(full[0, :, 2].min())) < 1.5e-3                              # the full mesh's lowest vertex too
    assert -0.045 < float(out.transl[0, 2] - transl[0, 2]) < -0.03               # mostly by moving down


def test_refiner_names_a_missing_prediction(setup):
    _, _, ref = setup
    with pytest.raises(ValueError, match="hand_offsets"):
        ref({"rot6d": torch.zeros(1, 55, 6), "transl": torch.zeros(1, 3), "head_dir": torch.zeros(1, 3)},
            torch.zeros(1, 10), torch.zeros(5, 3))


def test_refiner_names_nan_predictions_mismatched_betas_and_bad_steps(setup):
    """All-NaN offsets were taken (E_d then added nothing), steps -5 returned GNet's prediction unrefined, betas of
    another batch failed in an expand: each is named."""
    from graspkit.optim.goal_refine import GraspRefineWeights

    _, _, ref = setup
    hat = {"rot6d": torch.zeros(2, 55, 6), "transl": torch.zeros(2, 3), "head_dir": torch.zeros(2, 3),
           "hand_offsets": torch.zeros(2, 99, 3)}
    pts = torch.zeros(5, 3)
    with pytest.raises(ValueError, match="hat\\['hand_offsets'\\]: expected 2 finite rows"):
        ref({**hat, "hand_offsets": torch.full((2, 99, 3), float("nan"))}, torch.zeros(2, 10), pts)
    with pytest.raises(ValueError, match="hat\\['transl'\\]: expected 2 finite rows"):
        ref({**hat, "transl": torch.zeros(3, 3)}, torch.zeros(2, 10), pts)
    with pytest.raises(ValueError, match="betas: expected finite shape coefficients \\(1 or B = 2"):
        ref(hat, torch.zeros(3, 10), pts)
    with pytest.raises(ValueError, match="object_points: expected finite points"):
        ref(hat, torch.zeros(2, 10), torch.full((5, 3), float("nan")))
    with pytest.raises(ValueError, match="weights.steps: expected an integer >= 0"):
        ref(hat, torch.zeros(2, 10), pts, GraspRefineWeights(steps=-5))
    with pytest.raises(ValueError, match="weights.lr: expected a learning rate > 0"):
        ref(hat, torch.zeros(2, 10), pts, GraspRefineWeights(lr=0.0))


def test_refiner_names_empty_batches_a_nan_floor_and_bad_weights(setup):
    """B = 0 failed in a reshape, an empty object was called "target", a NaN floor ran with E_f silently dropped (its
    gradient is 0 at NaN), a NaN λ failed after a step as "query", a negative λ was taken: each is named up front."""
    from graspkit.optim.goal_refine import PosedSDF
    from graspkit.objects.sdf import SDFGrid

    _, _, ref = setup
    hat = {"rot6d": torch.zeros(2, 55, 6), "transl": torch.zeros(2, 3), "head_dir": torch.zeros(2, 3),
           "hand_offsets": torch.zeros(2, 99, 3)}
    pts = torch.zeros(5, 3)
    with pytest.raises(ValueError, match="^hat: expected at least one sample"):
        ref({k: v[:0] for k, v in hat.items()}, torch.zeros(1, 10), pts)
    with pytest.raises(ValueError, match="^object_points: expected at least one point"):
        ref(hat, torch.zeros(2, 10), torch.zeros(2, 0, 3))
    for ground in (float("nan"), float("inf")):
        with pytest.raises(ValueError, match="^ground: expected a finite floor height"):
            ref(hat, torch.zeros(2, 10), pts, ground=ground)
    for bad in ({"d": float("nan")}, {"f": float("inf")}, {"theta": -1.0}, {"pen_object": -0.1}):
        with pytest.raises(ValueError, match=f"^{next(iter(bad))}: expected a finite number >= 0"):
            GraspRefineWeights(**bad)
    grid = SDFGrid(torch.zeros(3, 3, 3), torch.full((3,), -1.0), torch.ones(3))
    for R, t, name in ((2 * torch.eye(3)[None], torch.zeros(1, 3), "R"), (torch.diag(torch.tensor([1.0, 1, -1]))[None],
                       torch.zeros(1, 3), "R"), (torch.full((1, 3, 3), float("nan")), torch.zeros(1, 3), "R"),
                       (torch.eye(3)[None], torch.full((1, 3), float("nan")), "t")):
        with pytest.raises(ValueError, match=f"^{name}: "):
            PosedSDF([grid], R, t)


def test_eq12_and_eq13_helpers_name_bad_inputs(setup):
    """hand_step_targets and refine_frame checked nothing: a negative speed moved the hand away from its goal, a NaN
    target vertex silently dropped out of the fit (|NaN|'s gradient is 0), steps -1 returned MNet's pose unrefined."""
    bm, gv, _ = setup
    now, goal = torch.zeros(1, 2, 3), torch.ones(1, 2, 3)
    with pytest.raises(ValueError, match="^speed: expected speeds >= 0"):
        hand_step_targets(now, goal, torch.tensor([-0.03]))
    with pytest.raises(ValueError, match="^speed: contains NaN or Inf"):
        hand_step_targets(now, goal, torch.tensor([float("nan")]))
    with pytest.raises(ValueError, match="^hand_now, hand_goal: expected the same shape"):
        hand_step_targets(now, goal[:, :1], torch.tensor([0.01]))
    hand_body = SparseBody(bm, torch.as_tensor(gv.vertex_ids[gv.right_hand]))
    r6, t, betas = axis_angle_to_rot6d(_grasp_pose()).float(), torch.zeros(1, 3), torch.zeros(1, 10)
    target = hand_body(pose_rotmats(r6), betas, t)[0]
    bad_target = target.clone()
    bad_target[0, 0, 0] = float("nan")
    with pytest.raises(ValueError, match="^hand_target: contains NaN or Inf"):
        refine_frame(hand_body, r6, t, betas, bad_target)
    with pytest.raises(ValueError, match="^hand_target: expected shape \\(1, "):
        refine_frame(hand_body, r6, t, betas, target[:, :10])
    with pytest.raises(ValueError, match="^rot6d_hat: expected shape"):
        refine_frame(hand_body, r6[:0], t[:0], betas, target[:0])
    with pytest.raises(ValueError, match="^weights.steps: expected an integer >= 0"):
        refine_frame(hand_body, r6, t, betas, target, MotionRefineWeights(steps=-1))
    with pytest.raises(ValueError, match="^weights.hand: expected a finite number >= 0"):
        refine_frame(hand_body, r6, t, betas, target, MotionRefineWeights(hand=-1.0))


def test_hand_step_targets_is_eq12_without_overshoot():
    now = torch.zeros(2, 1, 3)
    goal = torch.tensor([[[0.1, 0.0, 0.0]], [[0.0, 0.0, 0.02]]])
    out = hand_step_targets(now, goal, torch.tensor([0.03, 0.03]))
    torch.testing.assert_close(out, torch.tensor([[[0.03, 0.0, 0.0]], [[0.0, 0.0, 0.02]]]))


def test_motion_frame_refinement_meets_the_hand_targets(setup):
    bm, gv, _ = setup
    hand_body = SparseBody(bm, torch.as_tensor(gv.vertex_ids[gv.right_hand]))
    aa, betas = _grasp_pose(), torch.zeros(1, 10)
    rot6d, transl = axis_angle_to_rot6d(aa).float(), torch.zeros(1, 3)
    target = hand_body(pose_rotmats(rot6d), betas, transl)[0]
    wrong = aa.clone()
    wrong[0, J["right_wrist"]] += torch.tensor([0.0, 0.2, 0.1], dtype=torch.float64)
    wrong[0, J["right_elbow"]] += torch.tensor([0.0, -0.1, 0.0], dtype=torch.float64)
    r6, t = refine_frame(hand_body, axis_angle_to_rot6d(wrong).float(), transl, betas, target,
                         MotionRefineWeights())
    before = (hand_body(pose_rotmats(axis_angle_to_rot6d(wrong).float()), betas, transl)[0] - target).norm(dim=-1).mean()
    after = (hand_body(pose_rotmats(r6), betas, t)[0] - target).norm(dim=-1).mean()
    assert before > 0.015 and after < 0.003


# ------------------------------------------------------------------------------- graspkit's E_pen (not in GOAL)

@functools.lru_cache(maxsize=None)
def _ball_grid(radius: float):
    """An icosphere of `radius` at the origin and the ball's signed-distance grid, the closed form |x| - r at nodes
    2 mm apart over the ball's box and 3 cm around it (the exact mesh distance of so many nodes takes ~20 s)."""
    import trimesh

    from graspkit.objects.sdf import SDFGrid

    ball = trimesh.creation.icosphere(4, radius)
    n = int(2 * (radius + 0.03) / 0.002) + 1
    axis = -(radius + 0.03) + 0.002 * torch.arange(n, dtype=torch.float64)
    zz, yy, xx = torch.meshgrid(axis, axis, axis, indexing="ij")
    values = (xx ** 2 + yy ** 2 + zz ** 2).sqrt() - radius
    return ball, SDFGrid(values.float(), axis[0].repeat(3).float(), axis[-1].repeat(3).float())


def test_posed_sdf_matches_trimesh_for_two_posed_objects():
    """Each sample's object placed by its own R, t: the grid lookup of a point equals trimesh's exact signed distance
    of the mesh moved there (within the grid's interpolation error), and the gradient reaches the points."""
    import trimesh
    from scipy.spatial.transform import Rotation

    from graspkit.objects.sdf import SDFGrid
    from graspkit.optim.goal_refine import PosedSDF

    box = trimesh.creation.box((0.10, 0.06, 0.04))
    _, ball_grid = _ball_grid(0.04)
    ball = trimesh.creation.icosphere(4, 0.04)
    box_grid = SDFGrid.from_mesh(box, resolution=96)
    R = torch.tensor(Rotation.from_euler("zyx", [[0.7, 0.2, -0.3], [-1.2, 0.0, 0.5]]).as_matrix()).float()
    t = torch.tensor([[0.3, -0.2, 0.9], [-0.5, 0.4, 1.1]])
    sdf = PosedSDF([box_grid, ball_grid], R, t)
    g = torch.Generator().manual_seed(0)
    x = (t[:, None] + 0.06 * torch.randn(2, 400, 3, generator=g)).requires_grad_(True)
    got = sdf(x)
    for b, mesh in enumerate((box, ball)):
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = R[b].double().numpy(), t[b].double().numpy()
        m = mesh.copy()
        m.apply_transform(T)
        want = -trimesh.proximity.signed_distance(m, x[b].detach().double().numpy())   # trimesh: positive inside
        near = np.abs(want) < 0.02
        np.testing.assert_allclose(got[b].detach().numpy()[near], want[near], atol=1.5e-3)
        assert (np.sign(got[b].detach().numpy()) == np.sign(want))[np.abs(want) > 3e-3].all()
    got.sum().backward()
    assert torch.isfinite(x.grad).all() and x.grad.abs().sum() > 0
    with pytest.raises(ValueError, match="x: expected shape"):
        sdf(torch.zeros(3, 5, 3))
    with pytest.raises(ValueError, match="grids, R, t"):
        PosedSDF([box_grid], R, t)


def test_pen_term_is_the_summed_depth_of_hands_inner_points_and_forearms(setup):
    """E_pen at a hand sunk into a ball equals the depth past the ball's surface, computed here from the full mesh
    (hand and forearm vertices by their dominant joint, vertex normals by trimesh over the hand's own faces) and the
    ball's closed-form distance |x - c| - r."""
    import trimesh

    from graspkit.optim.goal_refine import PosedSDF
    from graspkit.optim.grasppose import forearm_vertex_ids, hand_vertex_ids

    bm, gv, ref = setup
    rot6d, betas, transl = axis_angle_to_rot6d(_grasp_pose()).float(), torch.zeros(1, 10), torch.zeros(1, 3)
    full = bm.forward_rotmats(pose_rotmats(rot6d), betas=betas, transl=transl).vertices[0].double()
    hands, arms = hand_vertex_ids(bm), forearm_vertex_ids(bm)
    r = 0.04
    right = hand_vertex_ids(bm, ("right",))
    c = full[right].mean(0) + torch.tensor([0.0, 0.0, -0.03], dtype=torch.float64)    # the ball through the palm
    _, grid = _ball_grid(r)
    sdf = PosedSDF([grid], torch.eye(3)[None], c[None].float())
    e = ref.energy(rot6d, transl, betas, {"rot6d": rot6d, "transl": transl, "head_dir": torch.zeros(1, 3),
                                          "hand_offsets": torch.zeros(1, 99, 3)}, c[None, None].float(), sdf=sdf)
    pos = -np.ones(len(full), dtype=np.int64)
    pos[hands] = np.arange(len(hands))
    f = pos[bm.faces.numpy()]
    normals = trimesh.Trimesh(full[hands].numpy(), f[(f >= 0).all(1)], process=False).vertex_normals
    h = full[hands].numpy()
    pts = np.concatenate([h, h - 0.005 * normals, h - 0.01 * normals, full[arms].numpy()])
    want = np.maximum(r - np.linalg.norm(pts - c.numpy(), axis=1), 0).sum()
    assert want > 0.5                                                           # metres summed: well inside
    assert float(e["pen"][0]) == pytest.approx(want, rel=0.02)
    assert "pen" not in ref.energy(rot6d, transl, betas, {"rot6d": rot6d, "transl": transl,
                                   "head_dir": torch.zeros(1, 3), "hand_offsets": torch.zeros(1, 99, 3)},
                                   c[None, None].float())


def test_pen_term_keeps_the_hand_out_of_the_ball_the_offsets_pull_it_into(setup):
    """GNet's offsets put the hand 2 cm into a ball under the palm. Eq. 4-8 pull it in; with E_pen (PEN_WEIGHTS, 150
    of its 400 steps) the hand stops at the surface and still touches it (closed-form ball distance of the full
    mesh's hand vertices)."""
    from dataclasses import replace

    from graspkit.optim.goal_refine import PEN_WEIGHTS, PosedSDF
    from graspkit.optim.grasppose import hand_vertex_ids

    bm, gv, ref = setup
    aa, betas = _grasp_pose(), torch.zeros(1, 10)
    rot6d, transl = axis_angle_to_rot6d(aa).float(), torch.zeros(1, 3)
    transl[0, 2] -= ref.vertices(rot6d, transl, betas)[0, :, 2].min()
    v = ref.vertices(rot6d, transl, betas)
    r = 0.045
    c = v[0, :99].mean(0) + torch.tensor([0.0, 0.0, -r - 0.005])                 # the palm 5 mm above the ball
    obj = _sphere(c, r)
    sunk = v[:, :99] - torch.tensor([0.0, 0.0, 0.02])                            # where the offsets put the hand
    q = torch.nn.functional.normalize(v[:, 401] - v[:, 400], dim=-1)
    hat = {"rot6d": rot6d, "transl": transl, "head_dir": q, "hand_offsets": hand_object_offsets(sunk, obj[None])}
    _, grid = _ball_grid(r)
    hands = hand_vertex_ids(bm)

    def depth_and_gap(out):
        full = bm.forward_rotmats(pose_rotmats(out.rot6d), betas=betas, transl=out.transl).vertices[0, hands]
        d = (full - c).norm(dim=-1) - r
        return float(-d.min()), float(d.abs().min())

    w = replace(PEN_WEIGHTS, steps=150)
    plain = depth_and_gap(ref(hat, betas, obj, replace(w, pen=0.0)))
    pen = depth_and_gap(ref(hat, betas, obj, w, sdf=PosedSDF([grid], torch.eye(3)[None], c[None])))
    assert plain[0] > 0.008                                                     # Eq. 4-8: the hand sinks in
    assert pen[0] < 0.4 * plain[0] and pen[1] < 0.002                            # E_pen: out, and touching
    with pytest.raises(ValueError, match="inner_depths"):
        ref(hat, betas, obj, replace(PEN_WEIGHTS, inner_depths=(-0.01,)),
            sdf=PosedSDF([grid], torch.eye(3)[None], c[None]))
    with pytest.raises(ValueError, match="sdf: expected one object per sample"):
        ref(hat, betas, obj, PEN_WEIGHTS, sdf=PosedSDF([grid, grid], torch.eye(3).expand(2, 3, 3), c.expand(2, 3)))


def _hand_surface(bm, ref, rot6d, betas, transl):
    """Both hands' vertices (N,3) as the refiner poses them and their trimesh vertex normals over the hands' own
    faces of the full mesh."""
    import trimesh

    from graspkit.optim.grasppose import hand_vertex_ids

    hands = hand_vertex_ids(bm)
    pos = -np.ones(bm.lbs_weights.shape[0], dtype=np.int64)
    pos[hands] = np.arange(len(hands))
    f = pos[bm.faces.numpy()]
    h = ref.vertices(rot6d, transl, betas, pen=True)[0, ref.sl_hands].double().numpy()
    return h, trimesh.Trimesh(h, f[(f >= 0).all(1)], process=False).vertex_normals


def test_pen_object_term_is_the_summed_depth_of_object_points_inside_the_hands(setup):
    """E_pen's other way: object points 1 mm inside the hands (moved along trimesh's normals) count their distance to
    the nearest hand vertex (a k-d tree), points 2 mm outside count nothing; near_object_points are the k points
    nearest the hands (the k-d tree again)."""
    from graspkit.optim.goal_refine import PosedSDF

    bm, gv, ref = setup
    rot6d, betas, transl = axis_angle_to_rot6d(_grasp_pose()).float(), torch.zeros(1, 10), torch.zeros(1, 3)
    h, n = _hand_surface(bm, ref, rot6d, betas, transl)
    pick = np.random.default_rng(0).choice(len(h), 300, replace=False)
    inside, outside = h[pick[:200]] - 0.001 * n[pick[:200]], h[pick[200:]] + 0.002 * n[pick[200:]]
    pts = torch.tensor(np.concatenate([inside, outside]))[None].float()
    _, grid = _ball_grid(0.02)
    far = PosedSDF([grid], torch.eye(3)[None], torch.tensor([[5.0, 5.0, 5.0]]))   # an object E^B_colli does not see
    hat = {"rot6d": rot6d, "transl": transl, "head_dir": torch.zeros(1, 3), "hand_offsets": torch.zeros(1, 99, 3)}
    near = torch.arange(300)[None]
    e = ref.energy(rot6d, transl, betas, hat, pts, sdf=far, near=near)
    want = cKDTree(h).query(inside)[0].sum()
    assert want == pytest.approx(0.2, rel=0.1)                                   # about 1 mm each
    assert float(e["pen_object"][0]) == pytest.approx(want, rel=0.01)
    assert float(e["pen"][0]) == 0.0
    only_out = ref.energy(rot6d, transl, betas, hat, pts, sdf=far, near=near[:, 200:])
    assert float(only_out["pen_object"][0]) == 0.0
    assert "pen_object" not in ref.energy(rot6d, transl, betas, hat, pts, sdf=far)
    v = ref.vertices(rot6d, transl, betas, pen=True)
    cloud = torch.tensor(h.mean(0) + 0.08 * np.random.default_rng(1).standard_normal((400, 3)))[None].float()
    got = ref.near_object_points(v, cloud, 50)[0].numpy()
    d = cKDTree(h).query(cloud[0].numpy())[0]
    assert set(got.tolist()) == set(np.argsort(d)[:50].tolist())


def test_restart_frees_a_hand_that_one_run_leaves_in_a_power_drill_handle(setup):
    """tests/data/goal_restart_case.npz (tools/goal_restart_case.py): a GNet grasp of the power drill whose hand one
    run with E_pen leaves > 2 cm inside the handle. With restart_sunk the sample is run again from a shifted start
    and keeps that run, whose full energy is lower; its hand is out of the drill (trimesh's signed distance of the
    full mesh's hand vertices) and still touching it."""
    from dataclasses import replace
    from pathlib import Path

    import trimesh

    from graspkit.objects.catalogue import make_object
    from graspkit.objects.sdf import SDFGrid
    from graspkit.optim.goal_refine import PEN_WEIGHTS, PosedSDF
    from graspkit.optim.grasppose import hand_vertex_ids

    bm, gv, ref = setup
    case = np.load(Path(__file__).parent / "data" / "goal_restart_case.npz", allow_pickle=False)
    hat = {k[4:]: torch.as_tensor(case[k])[None] for k in case.files if k.startswith("hat_")}
    betas, points = torch.as_tensor(case["betas"])[None], torch.as_tensor(case["points"])[None]
    R, t = torch.as_tensor(case["R"]), torch.as_tensor(case["t"])
    mesh = make_object(str(case["object_name"]))
    sdf = PosedSDF([SDFGrid.from_mesh(mesh, resolution=96)], R[None], t[None])
    posed = mesh.copy()
    posed.apply_transform(np.block([[R.double().numpy(), t.double().numpy()[:, None]], [np.zeros((1, 3)), 1.0]]))
    hands = hand_vertex_ids(bm)

    def hand_depth(out) -> tuple[float, float]:
        """Deepest hand vertex inside the drill and the nearest one's distance to it (m; trimesh, full mesh)."""
        v = bm.forward_rotmats(pose_rotmats(out.rot6d), betas=betas, transl=out.transl).vertices[0, hands]
        s = trimesh.proximity.signed_distance(posed, v.double().numpy())        # positive inside
        return float(s.max()), float(np.abs(s).min())

    one = ref(hat, betas, points, replace(PEN_WEIGHTS, restart_sunk=None), sdf=sdf)
    two = ref(hat, betas, points, replace(PEN_WEIGHTS, restart_sunk=0.002), sdf=sdf)
    e_one = ref.full_energy(one.rot6d, one.transl, betas, hat, points, PEN_WEIGHTS, 0.0, sdf)[0]
    e_two = ref.full_energy(two.rot6d, two.transl, betas, hat, points, PEN_WEIGHTS, 0.0, sdf)[0]
    assert one.restarted is None and two.restarted.tolist() == [True]
    assert hand_depth(one)[0] > 0.02                                             # one run: stuck in the handle
    depth, gap = hand_depth(two)
    assert depth < 0.003 and gap < 0.002                                         # restart: out, and touching
    assert float(e_two) < 0.5 * float(e_one)
    with pytest.raises(ValueError, match="restart_sunk"):
        ref(hat, betas, points, replace(PEN_WEIGHTS, restart_sunk=0.0), sdf=sdf)


def test_pen_terms_and_their_gradient_equal_a_from_scratch_evaluation_bit_for_bit(setup):
    """E_pen's two sums with a hand sunk 2 cm into a ball, as `energy` computes them (the hand normals once, shared by
    both sums) and as written out here from their parts (grasppose.collision_points with its own normals; SAGA's
    signed distance to the hand cloud with the normals computed again): equal values and equal gradients on θ and γ,
    to the bit."""
    from graspkit.body.markers import vertex_normals
    from graspkit.optim.goal_refine import PEN_WEIGHTS, PosedSDF
    from graspkit.optim.grasppose import _signed_to_cloud, collision_points

    bm, gv, ref = setup
    aa, betas = _grasp_pose(), torch.zeros(1, 10)
    rot6d, transl = axis_angle_to_rot6d(aa).float(), torch.zeros(1, 3)
    transl[0, 2] -= ref.vertices(rot6d, transl, betas)[0, :, 2].min()
    r = 0.045
    c = ref.vertices(rot6d, transl, betas)[0, :99].mean(0) + torch.tensor([0.0, 0.0, -r + 0.015])  # palm 1.5 cm in
    obj = _sphere(c, r)[None]
    sdf = PosedSDF([_ball_grid(r)[1]], torch.eye(3)[None], c[None])
    hat = {"rot6d": rot6d, "transl": transl, "head_dir": torch.tensor([[0.0, 1.0, 0.0]]),
           "hand_offsets": torch.zeros(1, 99, 3)}
    w = PEN_WEIGHTS

    def grads(pen_terms):
        x, t = rot6d.clone().requires_grad_(True), transl.clone().requires_grad_(True)
        pen, pen_object = pen_terms(x, t)
        (w.pen * pen + w.pen_object * pen_object).sum().backward()
        return pen.detach(), pen_object.detach(), x.grad, t.grad

    def shared(x, t):
        v = ref.vertices(x, t, betas, pen=True)
        near = ref.near_object_points(v, obj, w.object_near)
        e = ref.energy(x, t, betas, hat, obj, 0.0, sdf, w.inner_depths, w.pen_floor, near, v)
        return e["pen"], e["pen_object"]

    def from_scratch(x, t):
        v = ref.vertices(x, t, betas, pen=True)
        near = ref.near_object_points(v, obj, w.object_near)
        hands = v[:, ref.sl_hands]
        pts = collision_points(hands, ref.hand_faces, w.inner_depths, v[:, ref.sl_arms])
        pen = torch.relu(-sdf(pts) - w.pen_floor).sum(-1)
        cloud = v[:, ref.sl_hands]
        o = torch.gather(obj, 1, near[..., None].expand(-1, -1, 3))
        so, _ = _signed_to_cloud(o, cloud, vertex_normals(cloud, ref.hand_faces))
        return pen, torch.relu(-so).sum(-1)

    a, b = grads(shared), grads(from_scratch)
    assert float(a[0]) > 0.01 and float(a[1]) > 0.01                  # both sums see the hand in the ball
    assert all(torch.equal(x, y) for x, y in zip(a, b))


def test_head_term_is_zero_at_the_predicted_pose_and_q_points_where_the_body_faces(setup):
    """Eq. 6's q is the unit vector from the back of the head to the nose: a standing body (root R_x(90)) faces world
    -y, and with q^ taken from the same body, E_q is zero at GNet's pose (a reversed q would make it largest)."""
    bm, gv, ref = setup
    aa = torch.zeros(1, 55, 3)
    aa[0, 0] = torch.tensor([math.pi / 2, 0, 0])
    aa[0, J["head"]] = torch.tensor([0.2, 0.3, 0.0])                      # the head turned a little
    rot6d, transl, betas = axis_angle_to_rot6d(aa), torch.zeros(1, 3), torch.zeros(1, 10)
    V = bm.forward_rotmats(pose_rotmats(rot6d), betas=betas, transl=transl).vertices
    q = gv.head_direction(V)
    assert float(q[0, 1]) < -0.8
    hat = {"rot6d": rot6d, "transl": transl, "head_dir": q, "hand_offsets": torch.zeros(1, 99, 3)}
    assert float(ref.energy(rot6d, transl, betas, hat, torch.zeros(1, 10, 3))["q"][0]) < 1e-5


def test_restart_starts_from_the_lowest_energy_shift(setup, monkeypatch):
    """The restart begins at gamma^ plus the RESTART_SHIFTS entry of the lowest full energy: the second run's start
    equals the brute-force argmin over the candidate starts (which differ in energy, so the choice matters)."""
    from dataclasses import replace
    from pathlib import Path

    from graspkit.objects.catalogue import make_object
    from graspkit.objects.sdf import SDFGrid
    from graspkit.optim.goal_refine import PEN_WEIGHTS, RESTART_SHIFTS, PosedSDF

    bm, gv, _ = setup
    ref = GraspRefiner(bm, gv)                                           # its own: _descend is spied on
    case = np.load(Path(__file__).parent / "data" / "goal_restart_case.npz", allow_pickle=False)
    hat = {k[4:]: torch.as_tensor(case[k])[None] for k in case.files if k.startswith("hat_")}
    betas, points = torch.as_tensor(case["betas"])[None], torch.as_tensor(case["points"])[None]
    R, t = torch.as_tensor(case["R"]), torch.as_tensor(case["t"])
    sdf = PosedSDF([SDFGrid.from_mesh(make_object(str(case["object_name"])), resolution=96)], R[None], t[None])
    w = replace(PEN_WEIGHTS, steps=30, restart_sunk=0.002)
    starts = []
    descend = ref._descend

    def spy(hat_, betas_, pts_, w_, ground, sdf_, transl0):
        starts.append(transl0.clone())
        return descend(hat_, betas_, pts_, w_, ground, sdf_, transl0)

    monkeypatch.setattr(ref, "_descend", spy)
    out = ref(hat, betas, points, w, sdf=sdf)
    assert len(starts) == 2 and out.restarted is not None
    e = torch.stack([ref.full_energy(hat["rot6d"], hat["transl"] + d, betas, hat, points, w, 0.0, sdf)[0]
                     for d in RESTART_SHIFTS])[:, 0]
    assert float(e.max() - e.min()) > 1e-3
    torch.testing.assert_close(starts[1], hat["transl"] + RESTART_SHIFTS[int(e.argmin())])


def _case(ref):
    aa = torch.zeros(1, 55, 3)
    aa[0, 0] = torch.tensor([math.pi / 2, 0, 0])
    rot6d, transl, betas = axis_angle_to_rot6d(aa), torch.zeros(1, 3), torch.zeros(1, 10)
    v = ref.vertices(rot6d, transl, betas)
    q = torch.nn.functional.normalize(v[:, 401] - v[:, 400], dim=-1)
    hat = {"rot6d": rot6d + 0.1, "transl": transl + torch.tensor([[0.01, -0.02, 0.03]]), "head_dir": q,
           "hand_offsets": torch.zeros(1, 99, 3)}
    return rot6d, transl, betas, hat, v


def test_theta_and_gamma_terms_are_eq5s_norms(setup):
    """Eq. 5: E_gamma = ||gamma - gamma^||_1 (here per coordinate, averaged: the offset 1, -2, 3 cm reads 2 cm, an L2
    would read 0.047 cm^2), E_theta the (squared, averaged) 2-norm of the 6D pose offset (0.1 everywhere: 0.01)."""
    ref = setup[2]
    rot6d, transl, betas, hat, v = _case(ref)
    obj = v[0, :99] + torch.tensor([0.0, 0.0, 0.01])       # object points 1 cm above the hand vertices
    e = ref.energy(rot6d, transl, betas, hat, obj)
    assert float(e["gamma"][0]) == pytest.approx(0.02, rel=1e-5)
    assert float(e["theta"][0]) == pytest.approx(0.01, rel=1e-4)


def test_the_energy_weighs_each_term_by_its_own_lambda(setup):
    """Eq. 8: E = lambda_d E_d + lambda_theta E_theta + lambda_gamma E_gamma + lambda_q E_q + lambda_f E_f, each lambda
    by its name in GraspRefineWeights; after one Adam step (theta and gamma off GNet's prediction) the history's E is
    that sum of its terms."""
    ref = setup[2]
    rot6d, transl, betas, hat, v = _case(ref)
    obj = v[0, :99] + torch.tensor([0.0, 0.0, 0.01])
    w = GraspRefineWeights(d=1.0, theta=0.7, gamma=0.03, q=0.2, f=0.5, steps=1)
    out = ref(hat, betas, obj, w)
    h = out.history[-1]
    want = w.d * h["d"] + w.theta * h["theta"] + w.gamma * h["gamma"] + w.q * h["q"] + w.f * h["f"]
    assert h["theta"] > 0 and h["gamma"] > 0
    assert h["E"] == pytest.approx(want, rel=1e-5)


def test_eq13_holds_the_body_translation_with_its_weight(setup):
    """Eq. 13's E_Theta couples gamma to MNet's with weight MotionRefineWeights.transl (1000: "so the body does not
    slide to help the hand"). A hand target 3 cm to the side of the hand, reachable by sliding the whole body: with
    the coupling the body moves under 2 mm; with transl=0 (no coupling of gamma) it slides several times as far."""
    bm, gv, _ = setup
    hand_body = SparseBody(bm, torch.as_tensor(gv.vertex_ids[gv.right_hand]))
    aa = torch.zeros(1, 55, 3)
    aa[0, 0] = torch.tensor([math.pi / 2, 0, 0])
    rot6d, transl, betas = axis_angle_to_rot6d(aa), torch.zeros(1, 3), torch.zeros(1, 10)
    target = hand_body(pose_rotmats(rot6d), betas, transl)[0] + torch.tensor([0.03, 0.0, 0.0])
    _, t_held = refine_frame(hand_body, rot6d, transl, betas, target, MotionRefineWeights())
    _, t_free = refine_frame(hand_body, rot6d, transl, betas, target, MotionRefineWeights(transl=0.0))
    held, free = float(t_held.norm()), float(t_free.norm())
    assert held < 0.002 and free > 4 * held, (held, free)
