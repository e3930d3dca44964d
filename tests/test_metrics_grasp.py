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
