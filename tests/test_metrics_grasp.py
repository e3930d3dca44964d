"""graspkit.metrics' grasp distance against trimesh's closest points over every vertex."""
import numpy as np
import pytest
import trimesh

from graspkit import metrics as M
from graspkit.objects import make_object


def _truth(points: np.ndarray, mesh: trimesh.Trimesh) -> float:
    """Smallest signed distance (negative inside) of points to the mesh (trimesh, every point; its sign is + inside)."""
    return float(-trimesh.proximity.signed_distance(mesh, points).max())


def test_contact_distance_of_a_vertex_inside_the_padded_box_but_far_from_a_thin_diagonal_rod():
    """A diagonal rod's bounding box holds points far from it: the nearest vertex can lie outside that box."""
    rod = trimesh.creation.cylinder(0.005, segment=[[0, 0, 0], [0.3, 0.3, 0]], sections=32)
    pts = np.array([[0.3, 0.0, 0.0], [-0.06, -0.06, 0.0]])
    assert M.grasp_contact_distance(pts, rod) == pytest.approx(_truth(pts, rod), abs=1e-6)
    assert M.grasp_contact_distance(pts, rod) < 0.09                    # the skipped vertex is the closer one


@pytest.mark.parametrize("offset", [0.02, 0.2, 1.5])
def test_contact_distance_is_exact_near_and_far(offset):
    """A cloud of vertices at `offset` beside the mug (some inside it, within the margin, beyond it, far away)."""
    mug = make_object("mug")
    rng = np.random.default_rng(2)
    pts = rng.normal(scale=0.05, size=(300, 3)) + mug.vertices.max(0) + offset
    assert M.grasp_contact_distance(pts, mug) == pytest.approx(_truth(pts, mug), abs=1e-6)


def test_contact_distance_rejects_empty_or_nan_vertices():
    mug = make_object("mug")
    with pytest.raises(ValueError, match="vertices"):
        M.grasp_contact_distance(np.zeros((0, 3)), mug)
    with pytest.raises(ValueError, match="vertices"):
        M.grasp_contact_distance(np.full((2, 3), np.nan), mug)
    with pytest.raises(ValueError, match="one body"):                   # a batch of bodies is not one point set
        M.grasp_contact_distance(np.zeros((2, 5, 3)), mug)
    with pytest.raises(ValueError, match="vertices"):
        M.grasp_contact_distance(np.zeros((6, 2)), mug)                 # (V, 2) would reshape into 4 points


def _box_body(size: float) -> tuple[np.ndarray, np.ndarray]:
    """A closed coarse 'body' mesh: a box of `size` m centred at the origin, 8 vertices, 12 triangles."""
    b = trimesh.creation.box(extents=[size] * 3)
    return np.asarray(b.vertices), np.asarray(b.faces)


def test_an_object_inside_the_body_or_through_it_between_vertices_is_in_contact():
    """The vertices' distance misses an object that lies between them: a 2 cm cube wholly inside a 20 cm box body,
    and a rod of radius 5 mm through its middle. Both overlap the body (volume: the cube's 8 cm^3, the rod's
    a third of its 60 cm inside the box, ~1.57 cm^3), so both are in contact, though every body vertex is > 8 cm away."""
    v, f = _box_body(0.2)
    cube = trimesh.creation.box(extents=[0.02] * 3)
    rod = trimesh.creation.cylinder(0.005, segment=[[-0.3, 0, 0], [0.3, 0, 0]], sections=64)
    far = trimesh.creation.box(extents=[0.02] * 3, transform=trimesh.transformations.translation_matrix([0.5, 0, 0]))
    for obj, vol in ((cube, 8.0), (rod, 1e6 * rod.volume / 3)):
        m = M.grasp_metrics(v, f, obj)
        assert m["min_distance"] == pytest.approx(_truth(v, obj), abs=1e-6) and m["min_distance"] > 0.08
        assert m["volume_cm3"] == pytest.approx(vol, rel=0.03)
        assert m["contact"] == 1.0
    m = M.grasp_metrics(v, f, far)                       # beside the body, 39 cm from its nearest vertex: no contact
    assert m["contact"] == 0.0 and m["volume_cm3"] == 0.0


def test_contact_distance_refuses_a_mesh_whose_sign_would_be_wrong():
    """Inside an inward-wound sphere the signed distance would read +5 cm (outside): refused, as an open mesh is."""
    s = trimesh.creation.icosphere(3, radius=0.05)
    assert M.grasp_contact_distance(np.zeros((1, 3)), s) == pytest.approx(-0.05, abs=2e-3)   # the inscribed facets
    inverted, open_ = s.copy(), s.copy()
    inverted.invert()
    open_.update_faces(np.arange(len(s.faces)) > 0)
    for bad in (inverted, open_):
        with pytest.raises(ValueError, match="obj: "):
            M.grasp_contact_distance(np.zeros((1, 3)), bad)


def test_grasp_metrics_contact_threshold_is_checked_and_applied():
    v, f = _box_body(0.2)
    near = trimesh.creation.box(extents=[0.02] * 3, transform=trimesh.transformations.translation_matrix([0.115, 0.1, 0.1]))
    d = _truth(v, near)                                   # the body's corner (0.1, 0.1, 0.1) is 5 mm off the cube's face
    assert d == pytest.approx(0.005, abs=1e-9) and M.grasp_metrics(v, f, near)["contact"] == 0.0   # default 2 mm
    assert M.grasp_metrics(v, f, near, threshold=d + 1e-4)["contact"] == 1.0
    assert M.grasp_metrics(v, f, near, threshold=d - 1e-4)["contact"] == 0.0
    for bad in (np.nan, np.inf, "2mm", None):
        with pytest.raises(ValueError, match="threshold: expected a finite distance"):
            M.grasp_metrics(v, f, near, threshold=bad)


def test_grasp_quality_table_median_and_feet_share_on_known_rows():
    """Three grasps with volumes 0, 1, 11 cm^3 (median 1, mean 4) and feet 0.5, 2, 0.9 cm above the ground (two of
    three within 1 cm: the key and the docstring say cm)."""
    rows = [{"contact": 1.0, "volume_cm3": 0.0, "depth_cm": 0.0, "feet_cm": 0.5},
            {"contact": 0.0, "volume_cm3": 1.0, "depth_cm": 0.2, "feet_cm": 2.0},
            {"contact": 1.0, "volume_cm3": 11.0, "depth_cm": 1.0, "feet_cm": 0.9}]
    t = M.grasp_quality_table(rows)
    assert t["volume_median_cm3"] == pytest.approx(1.0) and t["volume_mean_cm3"] == pytest.approx(4.0)
    assert t["feet_within_1cm"] == pytest.approx(2 / 3) and t["feet_max_cm"] == pytest.approx(2.0)
    assert t["contact_ratio"] == pytest.approx(2 / 3) and t["depth_max_cm"] == pytest.approx(1.0)


def test_grasp_quality_table_means_and_maxima_by_hand():
    """Three grasps, volumes 0, 1, 11 cm^3 (max 11) and depths 0, 0.2, 1.0 cm (mean 0.4, median 0.2)."""
    rows = [{"contact": 1.0, "volume_cm3": 0.0, "depth_cm": 0.0},
            {"contact": 0.0, "volume_cm3": 1.0, "depth_cm": 0.2},
            {"contact": 1.0, "volume_cm3": 11.0, "depth_cm": 1.0}]
    t = M.grasp_quality_table(rows)
    assert t["volume_max_cm3"] == pytest.approx(11.0) and t["depth_mean_cm"] == pytest.approx(0.4)
    assert "feet_within_1cm" not in t


def test_contact_ratio_counts_a_volume_only_when_it_is_positive():
    """Two grasps 10 cm from the object, one overlapping it by 0.3 cm^3: one of two in contact (a zero volume is none)."""
    assert M.contact_ratio([0.1, 0.1], volumes_cm3=[0.0, 0.3]) == 0.5


def test_contact_ratio_compares_in_the_distances_own_precision():
    """float32 0.002 read as float64 is 0.0020000000949949 > 2 mm: contact_ratio counted it out for float32 input and
    in for float64 or a list (an independent check); it compares in the input's precision now, as numpy does and as
    the contact maps do (marker_contact of a point at that distance), so every form gives 2 of 3."""
    import torch

    d = [0.001, M.GRASP_CONTACT_THRESHOLD, 0.5]
    want = float(np.mean(np.array(d, np.float32) <= np.float32(M.GRASP_CONTACT_THRESHOLD)))
    assert want == pytest.approx(2 / 3)
    for x in (d, np.array(d), np.array(d, np.float32), torch.tensor(d), torch.tensor(d, dtype=torch.float64)):
        assert M.contact_ratio(x) == pytest.approx(want), type(x)


def test_contact_distance_finds_a_closer_vertex_outside_the_padded_box():
    """A 10 cm sphere: a vertex off its bounding-box corner (inside the 5 cm padded box) is ~9 cm from the surface,
    one 6 cm off its +x pole (outside the padded box) is 6 cm away: the answer is trimesh's 6 cm."""
    s = trimesh.creation.icosphere(4, radius=0.1)
    pts = np.array([[0.11, 0.11, 0.11], [0.16, 0.0, 0.0]])
    truth = float(-trimesh.proximity.signed_distance(s, pts).max())
    assert truth == pytest.approx(0.06, abs=1e-3)
    assert M.grasp_contact_distance(pts, s) == pytest.approx(truth, abs=1e-6)


def test_grasp_contact_at_exactly_the_threshold_and_grasp_and_end_figures_measure_each_body():
    """grasp_metrics' rule "min_distance <= threshold" holds at equality; grasp_and_end_figures measures the grasp
    body and the end body each (a box body half-overlapping a 2 cm cube, then the same body 50 cm away: contact 1 then 0)."""
    b = trimesh.creation.box(extents=[0.2] * 3)
    v, f = np.asarray(b.vertices), np.asarray(b.faces)
    near = trimesh.creation.box(extents=[0.02] * 3, transform=trimesh.transformations.translation_matrix([0.115, 0.1, 0.1]))
    d = M.grasp_metrics(v, f, near)["min_distance"]
    assert d == pytest.approx(0.005, abs=1e-6)
    assert M.grasp_metrics(v, f, near, threshold=d)["contact"] == 1.0
    touch = trimesh.creation.box(extents=[0.02] * 3, transform=trimesh.transformations.translation_matrix([0.1, 0.0, 0.0]))
    g = M.grasp_and_end_figures(v, v + [0.5, 0.0, 0.0], f, touch)
    assert g["grasp_contact"] == 1.0 and g["end_contact"] == 0.0
