"""The hand-object explorer's callback against independent computations (trimesh proximity, closed forms)."""
import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np
import pytest
import trimesh
from scipy.spatial.transform import Rotation

from graspkit.body.skeleton import JOINT_NAMES
from graspkit.objects import MARKER_CONTACT_THRESHOLD, OBJECT_CONTACT_THRESHOLD, ObjectPose, make_object
from graspkit.viz.object_explorer import HandObjectExplorer, hand_vertices, place_at_palm

HAND = (0.06, 0.04, 0.02)  # a flat box "hand" centred at the origin
GAP = 0.015  # the cracker box starts 1.5 cm above the hand's top face: within the marker threshold only


@pytest.fixture()
def explorer() -> HandObjectExplorer:
    hand = trimesh.creation.box(HAND)
    box_half_height = make_object("cracker_box").extents[2] / 2
    base = ObjectPose(np.array([0.0, 0.0, HAND[2] / 2 + GAP + box_half_height]), np.eye(3))
    top = np.flatnonzero(hand.vertices[:, 2] > 0)  # the four top corners act as markers
    return HandObjectExplorer(hand.vertices, hand.faces, "cracker_box", base=base, marker_ids=top, num_points=1024)


def truth(ex: HandObjectExplorer) -> dict[str, float]:
    """The same numbers from trimesh's proximity queries (signed distance is positive inside in trimesh)."""
    obj, body = ex.object_mesh(), trimesh.Trimesh(ex.vertices, ex.faces, process=False)
    hand_sd = -trimesh.proximity.signed_distance(obj, ex.vertices[ex.hand_ids])
    _, marker_d, _ = trimesh.proximity.closest_point(obj, ex.vertices[ex.marker_ids])
    _, point_d, _ = trimesh.proximity.closest_point(body, ex.object_points())
    return {"min_distance_cm": hand_sd.min() * 100,
            "marker_contacts": float((marker_d <= MARKER_CONTACT_THRESHOLD).sum()),
            "object_contacts": float((point_d <= OBJECT_CONTACT_THRESHOLD).sum())}


def test_starting_pose_matches_trimesh_and_the_set_up_gap(explorer):
    got, want = explorer.measure(), truth(explorer)
    assert got["min_distance_cm"] == pytest.approx(GAP * 100, abs=1e-6)
    assert got["min_distance_cm"] == pytest.approx(want["min_distance_cm"], abs=1e-3)
    assert got["marker_contacts"] == want["marker_contacts"] == 4  # 1.5 cm: within 2 cm (C_M), beyond 1 cm (C_O)
    assert got["object_contacts"] == want["object_contacts"] == 0
    assert got["penetration_depth_cm"] == 0 and got["penetration_volume_cm3"] == 0


def test_moving_away_by_one_metre_adds_one_metre_and_removes_all_contacts(explorer):
    before = explorer.measure()["min_distance_cm"]
    after = explorer.update("z", 1.0)
    assert after["min_distance_cm"] == pytest.approx(before + 100.0, abs=1e-6)
    assert after["marker_contacts"] == after["object_contacts"] == 0
    assert after["min_distance_cm"] == pytest.approx(truth(explorer)["min_distance_cm"], abs=1e-3)


@pytest.mark.parametrize("move", [{"z": -0.015}, {"z": -0.009, "x": 0.02}, {"x": 0.1, "z": -0.03},
                                  {"yaw": 45.0, "z": -0.01}, {"y": 0.05, "z": -0.06, "yaw": 30.0}])
def test_contacts_and_distance_match_trimesh_after_moves(explorer, move):
    for name, value in move.items():
        got = explorer.update(name, value)
    want = truth(explorer)
    assert got["min_distance_cm"] == pytest.approx(want["min_distance_cm"], abs=1e-3)
    assert got["marker_contacts"] == want["marker_contacts"]
    assert got["object_contacts"] == want["object_contacts"]


def test_pushing_in_gives_the_closed_form_depth_and_volume(explorer):
    push = GAP + 0.005  # the box's bottom face 5 mm below the hand's top face
    got = explorer.update("z", -push)
    assert got["min_distance_cm"] == pytest.approx(-0.5, abs=1e-6)
    assert got["penetration_depth_cm"] == pytest.approx(0.5, abs=1e-6)  # the top corners, 5 mm under the face
    assert got["penetration_volume_cm3"] == pytest.approx(HAND[0] * HAND[1] * 0.005 * 1e6, rel=1e-6)
    assert got["object_contacts"] > 0  # points on the bottom face inside the hand's footprint are within 1 cm
    want = truth(explorer)
    assert got["object_contacts"] == want["object_contacts"]


def test_object_swap_keeps_the_pose_and_unknown_slider_is_named(explorer):
    explorer.update("x", 0.03)
    got = explorer.update("object", "apple")
    assert explorer.name == "apple" and explorer.points.shape == (1024, 3)
    np.testing.assert_allclose(explorer.pose().translation[0], 0.03)
    assert got["min_distance_cm"] == pytest.approx(truth(explorer)["min_distance_cm"], abs=1e-3)
    with pytest.raises(ValueError, match="wiggle"):
        explorer.update("wiggle", 1.0)
    before = explorer.measure()
    for name in ("z", "yaw"):                               # a NaN is refused by name and not stored
        with pytest.raises(ValueError, match=f"{name}: expected a finite number"):
            explorer.update(name, float("nan"))
    assert explorer.update("x", 0.03) == before
    with pytest.raises(ValueError, match="x: expected a number"):      # float(True) would read as 1 m
        explorer.update("x", True)
    with pytest.raises(ValueError, match="object: unknown object 'nope'"):
        explorer.update("object", "nope")
    assert explorer.update("x", 0.03) == before


def test_the_widget_shows_the_values_the_explorer_holds_even_outside_the_slider_range(explorer):
    pytest.importorskip("ipywidgets")
    explorer.update("x", 0.25)                              # beyond the ±0.1 m range: ipywidgets would clamp to 0.1
    explorer.update("yaw", 200.0)
    sliders = {c.description: c for c in explorer.widget(dpi=20).children[0].children[0].children}
    assert sliders["x (m)"].value == pytest.approx(0.25) and sliders["yaw (°)"].value == pytest.approx(200.0)
    assert sliders["y (m)"].value == 0.0 and (sliders["y (m)"].min, sliders["y (m)"].max) == (-0.1, 0.1)
    sliders["x (m)"].value = -0.05                          # the slider still drives the explorer
    assert explorer.offset[0] == pytest.approx(-0.05)


def test_open_body_reports_no_volume_but_still_depth():
    hand = trimesh.creation.box(HAND)
    ex = HandObjectExplorer(hand.vertices, hand.faces[1:], "apple")  # one face missing: not closed
    got = ex.measure()  # the apple's centre sits at the box centre: every hand vertex is inside
    assert np.isnan(got["penetration_volume_cm3"]) and got["penetration_depth_cm"] > 0


def test_figure_and_readout(explorer):
    explorer.update("z", -GAP)
    fig = explorer.figure(views=("front",), size=2.0)
    assert len(fig.axes) == 1
    line = HandObjectExplorer.describe(explorer.measure())
    assert "markers in contact" in line and "cm³" in line


def test_place_at_palm_touches_at_the_requested_gap():
    palm = trimesh.creation.icosphere(3, 0.04)  # a round "palm": the object is placed on its normal line
    ids = np.flatnonzero(palm.vertices[:, 2] < -0.035)  # the bottom cap, normal about -z
    mug = make_object("mug")
    pose = place_at_palm(mug, palm.vertices, palm.faces, ids, gap=0.003)
    moved = mug.copy()
    moved.apply_transform(pose.matrix())
    d = -trimesh.proximity.signed_distance(moved, palm.vertices)
    assert d.min() == pytest.approx(0.003, abs=2e-5)
    assert pose.translation[2] < -0.04  # below the palm


@pytest.fixture(scope="module")
def body_scene():
    """The lesson's scene: the procedural body reaching forward, a can 2 mm under its right palm."""
    from graspkit.body import BodyModel
    from graspkit.body.markers import palm_vertices, saga_markers
    from graspkit.paths import default_model_path
    from graspkit.viz.object_explorer import hand_vertices, reaching_body

    bm = BodyModel.from_file(default_model_path())
    v, f = reaching_body(bm)
    pose = place_at_palm(make_object("can"), v, f, palm_vertices(bm)["right"], gap=0.002)
    markers = saga_markers(bm)
    ex = HandObjectExplorer(v, f, "can", base=pose, hand_ids=hand_vertices(bm, "right"), marker_ids=markers.vertex_ids)
    return ex, markers


def test_body_scene_touches_with_the_palm_and_matches_trimesh(body_scene):
    ex, markers = body_scene
    got = ex.update("z", 0.0)
    assert got["min_distance_cm"] == pytest.approx(0.2, abs=1e-3)
    assert ex.vertices[:, 2].min() == 0.0 and ex.body_closed
    c_m, _ = ex.contacts()
    touching = [n for n, c in zip(markers.names, c_m) if c]
    assert touching and all(n.startswith("RPALM") for n in touching)  # the right palm, nothing else
    for dz in (0.0, 0.01):  # touching, then pressed 1 cm into the hand
        got, want = ex.update("z", dz), truth(ex)
        assert got["min_distance_cm"] == pytest.approx(want["min_distance_cm"], abs=1e-3)
        assert (got["marker_contacts"], got["object_contacts"]) == (want["marker_contacts"], want["object_contacts"])
    assert got["penetration_depth_cm"] == pytest.approx(-got["min_distance_cm"], abs=1e-9)
    assert got["penetration_volume_cm3"] > 0


def test_body_scene_one_metre_down_has_no_contact(body_scene):
    ex, _ = body_scene
    got = ex.update("z", -1.0)
    want = truth(ex)
    ex.update("z", 0.0)
    assert got["marker_contacts"] == got["object_contacts"] == 0 == want["object_contacts"]
    assert got["min_distance_cm"] == pytest.approx(want["min_distance_cm"], abs=1e-3)
    assert 90.0 < got["min_distance_cm"] <= 100.2  # the palm was 2 mm above; other vertices may come closer


HAND = (0.06, 0.04, 0.02)


def _explorer(gap: float, base_rotation=np.eye(3)) -> HandObjectExplorer:
    hand = trimesh.creation.box(HAND)
    half = make_object("cracker_box").extents[2] / 2
    base = ObjectPose(np.array([0.0, 0.0, HAND[2] / 2 + gap + half]), base_rotation)
    return HandObjectExplorer(hand.vertices, hand.faces, "cracker_box", base=base, num_points=1024)


def test_yaw_slider_is_degrees_about_the_world_z_after_the_base_rotation():
    """The docstring: the base pose turned by `yaw` (degrees) about the world z through the object's centre."""
    base_R = Rotation.from_euler("x", 90, degrees=True).as_matrix()
    ex = _explorer(0.3, base_R)
    ex.update("yaw", 90.0)
    want = Rotation.from_euler("z", 90, degrees=True).as_matrix() @ base_R
    np.testing.assert_allclose(ex.pose().rotation, want, atol=1e-12)
    np.testing.assert_allclose(ex.pose().translation, ex.base.translation, atol=1e-12)   # about its own centre
    # the object's points: world = Rz(90) (Rx(90) p) + t
    want_pts = ex.points @ want.T + ex.base.translation
    np.testing.assert_allclose(ex.object_points(), want_pts, atol=1e-9)


@pytest.mark.parametrize("gap", [0.004, 0.008])
def test_object_contacts_under_the_threshold_match_trimesh(gap):
    """An object hovering `gap` < 1 cm over the hand's top face: its points within 1 cm of the hand count as contacts,
    as trimesh's exact closest-point distance says."""
    ex = _explorer(gap)
    got = ex.measure()
    body = trimesh.Trimesh(ex.vertices, ex.faces, process=False)
    _, d, _ = trimesh.proximity.closest_point(body, ex.object_points())
    want = float((d <= OBJECT_CONTACT_THRESHOLD).sum())
    assert want > 0
    assert got["object_contacts"] == want


def test_hand_vertices_are_those_skinned_mostly_to_the_wrist_or_a_finger_joint(bm):
    names = [n for n in JOINT_NAMES if n.startswith("right_") and
             (n == "right_wrist" or any(f in n for f in ("index", "middle", "ring", "pinky", "thumb")))]
    assert len(names) == 16
    joints = [JOINT_NAMES.index(n) for n in names]
    w = bm.lbs_weights.cpu().numpy()
    want = np.flatnonzero(np.isin(w.argmax(1), joints))
    np.testing.assert_array_equal(hand_vertices(bm, "right"), want)
    tips = [JOINT_NAMES.index(f"right_{f}3") for f in ("index", "middle", "ring", "pinky", "thumb")]
    assert np.isin(w[hand_vertices(bm, "right")].argmax(1), tips).sum() > 0   # the fingertips are part of the hand


@pytest.mark.parametrize("gap", [0.03, 0.06])
def test_place_at_palm_holds_any_requested_gap(gap):
    """The docstring: the nearest body vertex `gap` m outside the object, for any gap (trimesh's signed distance)."""
    palm = trimesh.creation.icosphere(3, 0.04)
    ids = np.flatnonzero(palm.vertices[:, 2] < -0.035)
    mug = make_object("mug")
    pose = place_at_palm(mug, palm.vertices, palm.faces, ids, gap=gap)
    moved = mug.copy()
    moved.apply_transform(pose.matrix())
    d = -trimesh.proximity.signed_distance(moved, palm.vertices)
    assert d.min() == pytest.approx(gap, abs=2e-5)


def test_hand_vertices_refuses_an_unknown_side(bm):
    """side is 'left' or 'right'; anything else is a ValueError naming side."""
    for side in ("both", "middle"):
        with pytest.raises(ValueError, match="side"):
            hand_vertices(bm, side)


def test_min_distance_is_over_the_hand_vertices_only():
    """min_distance_cm is the signed distance of the hand_ids vertices alone (trimesh's, negated: outside positive):
    hand_ids the bottom corners of a slab under the object, the top ones being nearer."""
    slab = trimesh.creation.box((0.3, 0.3, 0.1))
    half = make_object("cracker_box").extents[2] / 2
    base = ObjectPose(np.array([0.0, 0.0, 0.05 + 0.02 + half]), np.eye(3))
    bottom = np.flatnonzero(slab.vertices[:, 2] < 0)
    ex = HandObjectExplorer(slab.vertices, slab.faces, "cracker_box", base=base, hand_ids=bottom, num_points=256)
    got = ex.measure()["min_distance_cm"]
    want = (-trimesh.proximity.signed_distance(ex.object_mesh(), slab.vertices[bottom])).min() * 100
    assert got == pytest.approx(want, abs=1e-4)


def test_figure_draws_the_body_faces_near_the_objects_current_place():
    """figure(radius=r) draws the body faces whose centroid lies within r of the object's current centre (after a
    slider move), recomputed with numpy; the object's own faces follow them."""
    slab = trimesh.creation.box((1.0, 1.0, 0.02)).subdivide().subdivide().subdivide().subdivide()
    ex = HandObjectExplorer(slab.vertices, slab.faces, "cracker_box", base=ObjectPose(np.array([0.0, 0.0, 0.3]),
                                                                                      np.eye(3)), num_points=128)
    ex.update("x", 0.25)
    centre = np.array([0.25, 0.0, 0.3])
    cent = slab.vertices[slab.faces].mean(1)
    want = np.linalg.norm(cent - centre, axis=1) < 0.35
    fig = ex.figure(views=("front",), radius=0.35)
    [pc] = [c for c in fig.axes[0].collections if type(c).__name__ == "Poly3DCollection"]
    tri = np.asarray(pc._faces)
    n_obj = len(ex.object_mesh().faces)
    assert len(tri) == want.sum() + n_obj
    np.testing.assert_allclose(np.sort(tri[:-n_obj].mean(1), axis=0), np.sort(cent[want], axis=0), atol=1e-9)
    plt.close(fig)


def test_bad_arrays_are_named_in_the_constructor():
    """Out-of-range ids failed at measure() with a bare IndexError, (V, 2) vertices were taken until measure() broke,
    NaN vertices were named 'points' (an independent check); the constructor now names each."""
    hand = trimesh.creation.box(HAND)
    V = len(hand.vertices)
    for kwargs, message in (({"hand_ids": [10**6]}, f"^hand_ids: expected vertex ids \\(N,\\) in 0..{V - 1}"),
                            ({"marker_ids": [-1]}, "^marker_ids:"), ({"hand_ids": [0.5]}, "^hand_ids:")):
        with pytest.raises(ValueError, match=message):
            HandObjectExplorer(hand.vertices, hand.faces, "apple", **kwargs)
    with pytest.raises(ValueError, match=r"^vertices: expected finite \(V, 3\)"):
        HandObjectExplorer(hand.vertices[:, :2], hand.faces, "apple")
    bad = hand.vertices.copy()
    bad[0, 0] = np.nan
    with pytest.raises(ValueError, match="^vertices:"):
        HandObjectExplorer(bad, hand.faces, "apple")
    with pytest.raises(ValueError, match=f"^faces: expected \\(F, 3\\) vertex indices in 0..{V - 1}"):
        HandObjectExplorer(hand.vertices, hand.faces + V, "apple")


def test_an_offset_past_its_bound_is_refused_and_the_state_kept(explorer):
    """x = 1e15 m collapsed the mug's float64 mesh (1e17 the cracker box's), was stored, and every later update failed
    naming `mesh_b` (an independent check): refused by the slider's name now, and the explorer measures as before."""
    before = explorer.measure()
    for value in (1e17, 1e15, -10.5):                    # 1e15 passed with the cracker box, a mug failed
        with pytest.raises(ValueError, match="^x: expected an offset within ±10 m"):
            explorer.update("x", value)
    np.testing.assert_array_equal(explorer.offset, np.zeros(3))
    assert explorer.update("z", 0.0) == before
    with pytest.raises(ValueError, match="^object: unknown object"):            # an array is not a name
        explorer.update("object", np.array(["apple"]))
    assert explorer.name == "cracker_box"


def test_constructor_and_widget_arguments_are_named():
    """hand_ids=[] failed at the first measure ('points: empty point set'), a translation as `base` with an
    AttributeError, num_points=0 and an unknown object were named after inner functions' arguments (`n`, `name`),
    a negative span froze the widget's sliders (an independent check): each is named where it is given."""
    hand = trimesh.creation.box(HAND)
    for kwargs, message in (({"hand_ids": []}, "^hand_ids: expected at least one"),
                            ({"base": np.array([0, 0, 0.06])}, "^base: expected a graspkit.objects.ObjectPose"),
                            ({"num_points": 0}, "^num_points: expected an integer >= 1"),
                            ({"object_name": "nope"}, "^object_name: unknown object 'nope'"),
                            ({"seed": -1}, "^seed: expected")):
        with pytest.raises((ValueError, TypeError), match=message):
            HandObjectExplorer(hand.vertices, hand.faces, **{"object_name": "apple", **kwargs})
    ex = HandObjectExplorer(hand.vertices, hand.faces, "apple", num_points=256)
    for kwargs, name in (({"span": -0.1}, "span"), ({"span": float("nan")}, "span"), ({"step": 0.0}, "step")):
        with pytest.raises(ValueError, match=f"^{name}: expected a finite positive number"):
            ex.widget(**kwargs)
