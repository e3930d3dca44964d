"""Objects and the shared geometry layer: procedural catalogue, placement, surface sampling, BPS,
exact distances, signed distance (exact and grid), SAGA contact maps, GOAL attention, interpenetration.

Conventions: z-up world, metres; signed distances are negative inside; torch in, torch out.
"""
from graspkit.objects.bps import bps_basis, bps_encode
from graspkit.objects.catalogue import SPECS, TEST_OBJECTS, ObjectSpec, list_objects, make_object
from graspkit.objects.contact import (IAA_WEIGHT, MARKER_CONTACT_THRESHOLD, OBJECT_CONTACT_THRESHOLD,
                                      body_object_attention, distance_to, interaction_attention, marker_contact,
                                      object_contact)
from graspkit.objects.distance import (MeshDistance, closest_point_on_triangle, nearest_neighbours,
                                       point_mesh_distance)
from graspkit.objects.penetration import Penetration, interpenetration, intersection_volume, penetration_depth
from graspkit.objects.placement import ObjectPose, apply_pose, sample_object_pose
from graspkit.objects.sampling import sample_surface
from graspkit.objects.sdf import (SDFGrid, contains, object_sdf_grid, signed_distance, signed_distance_to_points,
                                 winding_number)

__all__ = [
    "SPECS", "TEST_OBJECTS", "ObjectSpec", "list_objects", "make_object",
    "ObjectPose", "apply_pose", "sample_object_pose",
    "sample_surface", "bps_basis", "bps_encode",
    "MeshDistance", "closest_point_on_triangle", "nearest_neighbours", "point_mesh_distance",
    "SDFGrid", "contains", "object_sdf_grid", "signed_distance", "signed_distance_to_points", "winding_number",
    "IAA_WEIGHT", "MARKER_CONTACT_THRESHOLD", "OBJECT_CONTACT_THRESHOLD", "body_object_attention", "distance_to",
    "interaction_attention", "marker_contact", "object_contact",
    "Penetration", "interpenetration", "intersection_volume", "penetration_depth",
]
