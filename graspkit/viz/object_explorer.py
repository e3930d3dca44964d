"""Move an object around a hand and watch distances and contacts update (lesson 02's widget).

The state and the callback are plain Python (tests/test_object_explorer.py checks them against trimesh);
`HandObjectExplorer.widget()` only wires ipywidgets sliders to `update` and redraws a matplotlib figure.
`place_at_palm` and `reaching_body` set up the scene the lesson uses: a body whose right palm rests on an object.
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np
import torch
import trimesh
from matplotlib.figure import Figure

from graspkit.checks import check_int, check_positive, check_seed, check_type
from graspkit.objects import (MARKER_CONTACT_THRESHOLD, OBJECT_CONTACT_THRESHOLD, ObjectPose, apply_pose, list_objects,
                              intersection_volume, make_object, marker_contact, object_contact, sample_surface,
                              signed_distance)
from graspkit.viz.explorers import bounded_value, slider_bounds, slider_value

if TYPE_CHECKING:
    from graspkit.body import BodyModel

# right arm held forward at chest height, palm down, the left arm lowered (SMPL-X canonical frame, see body/poses.py)
REACH_FORWARD: dict[str, tuple[float, float, float]] = {
    "right_shoulder": (0.0, 1.35, 0.25), "right_elbow": (0.0, 0.25, 0.0), "left_shoulder": (0.0, 0.0, -1.2),
}
OFFSET_SLIDERS = ("x", "y", "z")  # object translation in metres, world axes
YAW_SLIDER = "yaw"  # rotation about the world z axis through the object centre, degrees
MARKER_IN_CONTACT = "#2ca02c"  # SAGA Fig. 3 draws markers in contact in green
MAX_OFFSET = 10.0  # m: an offset beyond this is a typo, not a move around a hand (and far off, meshes collapse)


def reaching_body(bm: BodyModel, pose: dict[str, tuple[float, float, float]] | None = None
                  ) -> tuple[np.ndarray, np.ndarray]:
    """The body in `pose` (default REACH_FORWARD), z-up world, facing -y, feet on z = 0: vertices (V,3), faces (F,3)."""
    from graspkit.body.poses import y_up_to_z_up
    from graspkit.body.skeleton import JOINT_INDEX, NUM_BODY_JOINTS

    body_pose = torch.zeros(NUM_BODY_JOINTS + 1, 3, dtype=bm.dtype)
    for joint, aa in (REACH_FORWARD if pose is None else pose).items():
        body_pose[JOINT_INDEX[joint]] = torch.tensor(aa, dtype=bm.dtype)
    with torch.no_grad():
        v = bm(body_pose=body_pose[1:].reshape(1, -1), global_orient=y_up_to_z_up(bm.dtype)).vertices[0]
    v = v.double().numpy()
    v[:, 2] -= v[:, 2].min()
    return v, bm.faces.cpu().numpy().astype(np.int64)


def hand_vertices(bm: BodyModel, side: str = "right") -> np.ndarray:
    """Ids (N,) of the vertices a hand moves: those whose largest skinning weight is the wrist or a finger joint."""
    from graspkit.body.skeleton import FINGERS, JOINT_INDEX

    if side not in ("left", "right"):
        raise ValueError(f"side: expected 'left' or 'right', got {side!r}")
    joints = [JOINT_INDEX[f"{side}_wrist"]] + [JOINT_INDEX[f"{side}_{f}{k}"] for f in FINGERS for k in (1, 2, 3)]
    return np.flatnonzero(np.isin(bm.lbs_weights.argmax(1).cpu().numpy(), joints))


def palm_frame(vertices: np.ndarray, faces: np.ndarray, palm_ids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Centre (3,) of the palm vertices and the unit mean normal (3,) pointing out of the palm."""
    normals = trimesh.Trimesh(vertices, faces, process=False).vertex_normals[palm_ids]
    n = normals.mean(0)
    return vertices[palm_ids].mean(0), n / np.linalg.norm(n)


def place_at_palm(mesh: trimesh.Trimesh, vertices: np.ndarray, faces: np.ndarray, palm_ids: np.ndarray,
                  gap: float = 0.0, tol: float = 1e-5, max_iter: int = 30) -> ObjectPose:
    """Pose (no rotation) putting `mesh` on the palm's normal line, the nearest body vertex `gap` m outside it.

    The object slides along the palm normal until that holds within `tol` m (at most `max_iter` steps).
    """
    centre, n = palm_frame(vertices, faces, palm_ids)
    t = centre + n * (gap + float((-mesh.vertices @ n).max()))  # the object's extreme point along -n meets the palm
    near = vertices[np.linalg.norm(vertices - t, axis=1) < np.linalg.norm(mesh.extents) + 0.1]
    for _ in range(max_iter):  # the palm is curved: slide along n until the closest vertex sits at `gap`
        error = gap - float(signed_distance(near, apply_pose(ObjectPose(t, np.eye(3)), mesh), check=False).min())
        if abs(error) < tol:
            break
        t = t + n * error  # moving by s along n changes the distance by at most s: no overshoot
    return ObjectPose(t, np.eye(3))


def _check_object_name(value: Any, name: str) -> None:
    """A ValueError naming `name` unless value is a catalogue object's name (a str)."""
    if not isinstance(value, str) or value not in list_objects():
        raise ValueError(f"{name}: unknown object {value!r}; expected one of {list_objects()}")


def _ids(ids: Any, name: str, V: int) -> np.ndarray:
    """Vertex ids (N,) as int64, each in 0..V-1, or a ValueError naming them."""
    a = np.asarray(ids)
    if a.ndim != 1 or (len(a) and (a.dtype.kind not in "iu" or a.min() < 0 or a.max() >= V)):
        raise ValueError(f"{name}: expected vertex ids (N,) in 0..{V - 1}, got {a.dtype} of shape {a.shape}"
                         + (f" from {a.min()} to {a.max()}" if a.ndim == 1 and len(a) and a.dtype.kind in "iuf" else ""))
    return a.astype(np.int64)


class HandObjectExplorer:
    """An object near a posed body: slide it by x, y, z offsets (m) and a yaw (deg), read distances and contacts.

    vertices (V,3) and faces (F,3) are the posed body in the world; `base` the object's starting pose;
    hand_ids the vertices whose distance is reported (default all); marker_ids the markers for SAGA's C_M.
    """

    def __init__(self, vertices: Any, faces: Any, object_name: str = "mug", base: ObjectPose | None = None,
                 hand_ids: Any = None, marker_ids: Any = None, num_points: int = 2048, seed: int = 0) -> None:
        self.vertices = np.asarray(vertices, dtype=np.float64)
        if self.vertices.ndim != 2 or self.vertices.shape[1] != 3 or not len(self.vertices) \
                or not np.isfinite(self.vertices).all():
            raise ValueError(f"vertices: expected finite (V, 3) positions in metres, got shape {self.vertices.shape}")
        V = len(self.vertices)
        self.faces = np.asarray(faces, dtype=np.int64)
        if self.faces.ndim != 2 or self.faces.shape[1] != 3 or not len(self.faces) or self.faces.min() < 0 \
                or self.faces.max() >= V:
            raise ValueError(f"faces: expected (F, 3) vertex indices in 0..{V - 1}, got shape {self.faces.shape}")
        self.hand_ids = np.arange(V) if hand_ids is None else _ids(hand_ids, "hand_ids", V)
        if not len(self.hand_ids):
            raise ValueError("hand_ids: expected at least one vertex id (the distance readout is over them)")
        self.marker_ids = np.zeros(0, np.int64) if marker_ids is None else _ids(marker_ids, "marker_ids", V)
        check_type(base, ObjectPose, "base", optional=True, what="graspkit.objects.ObjectPose (ObjectPose.from_yaw)")
        self.base = ObjectPose.identity() if base is None else base
        self.num_points, self.seed = check_int(num_points, "num_points", 1), check_seed(seed)
        _check_object_name(object_name, "object_name")
        self.offset, self.yaw = np.zeros(3), 0.0
        self.body_closed = trimesh.Trimesh(self.vertices, self.faces, process=False).is_watertight
        tri = self.vertices[self.faces]
        self.face_lo, self.face_hi = tri.min(1), tri.max(1)  # (F,3) boxes: which faces can touch the object
        self.set_object(object_name)

    def set_object(self, name: str) -> None:
        """Swap the object (same pose): its canonical mesh and its SAGA surface points (object frame)."""
        self.name, self.mesh = name, make_object(name)
        self.points, self.normals = sample_surface(self.mesh, self.num_points, seed=self.seed)

    def pose(self) -> ObjectPose:
        """The object's current pose: the base pose turned by yaw about the world z through its centre, then offset."""
        yaw = ObjectPose.from_yaw(math.radians(self.yaw), np.zeros(3))
        return ObjectPose(self.base.translation + self.offset, yaw.rotation @ self.base.rotation)

    def object_mesh(self) -> trimesh.Trimesh:
        """The object mesh in the world at the current pose."""
        return apply_pose(self.pose(), self.mesh)

    def object_points(self) -> np.ndarray:
        """The object's surface points (P,3) in the world at the current pose."""
        return apply_pose(self.pose(), self.points)

    def update(self, name: str, value: float | str) -> dict[str, float]:
        """Set one slider ('x', 'y', 'z' in m within ±MAX_OFFSET, 'yaw' in deg, or 'object' = a catalogue name), then
        `measure()`; a refused value changes nothing."""
        if name in OFFSET_SLIDERS:
            self.offset[OFFSET_SLIDERS.index(name)] = bounded_value(name, value, MAX_OFFSET, "an offset", " m",
                                                                    "the sliders span ±0.1 m")
        elif name == YAW_SLIDER:
            self.yaw = slider_value(name, value)
        elif name == "object":
            _check_object_name(value, "object")
            self.set_object(str(value))
        else:
            names = [*OFFSET_SLIDERS, YAW_SLIDER, "object"]
            raise ValueError(f"name: unknown slider {name!r}; expected one of {names}")
        return self.measure()

    def contacts(self) -> tuple[np.ndarray, np.ndarray]:
        """SAGA's contact maps at the current pose: C_M (M,) over the markers, C_O (P,) over the object points."""
        obj = self.object_mesh()
        c_m = marker_contact(self.vertices[self.marker_ids], obj).numpy() if len(self.marker_ids) else np.zeros(0)
        # only faces whose box comes within the threshold of the object's box can hold a contact: same map, faster
        lo, hi = obj.bounds[0] - OBJECT_CONTACT_THRESHOLD, obj.bounds[1] + OBJECT_CONTACT_THRESHOLD
        near = np.all((self.face_hi >= lo) & (self.face_lo <= hi), axis=1)
        if not near.any():
            return c_m, np.zeros(len(self.points))
        return c_m, object_contact(self.object_points(), (self.vertices, self.faces[near])).numpy()

    def measure(self) -> dict[str, float]:
        """Numbers at the current pose: signed min distance of the hand vertices (cm, < 0 = inside), marker and
        object contact counts, penetration depth (cm) of all body vertices and volume (cm³; NaN for an open body)."""
        obj = self.object_mesh()
        c_m, c_o = self.contacts()
        hand = signed_distance(self.vertices[self.hand_ids], obj, check=False)
        lo, hi = obj.bounds
        near = np.all((self.vertices >= lo) & (self.vertices <= hi), axis=1)  # only these can be inside
        inside = signed_distance(self.vertices[near], obj, check=False) if near.any() else torch.zeros(1)
        volume = intersection_volume((self.vertices, self.faces), obj) * 1e6 if self.body_closed else float("nan")
        return {"min_distance_cm": float(hand.min()) * 100.0,
                "marker_contacts": float(c_m.sum()),
                "object_contacts": float(c_o.sum()),
                "penetration_depth_cm": max(0.0, -float(inside.min())) * 100.0,
                "penetration_volume_cm3": float(volume)}

    def figure(self, views: tuple[Any, ...] = ("front", "side"), size: float = 3.2, radius: float = 0.2) -> Figure:
        """The body near the object (faces within `radius` m of it), the object, its contact points (red) and the
        markers in contact (green), in the given views."""
        import matplotlib.pyplot as plt

        from graspkit.viz.scene import draw_markers, draw_meshes, draw_points, figure, set_equal
        from graspkit.viz.style import OBJECT, SKIN

        obj = self.object_mesh()
        c_m, c_o = self.contacts()
        centre = self.pose().translation
        keep = np.linalg.norm(self.vertices[self.faces].mean(1) - centre, axis=1) < radius
        pts = self.object_points()
        fig, axes = figure(views, size)
        plt.close(fig)  # the caller decides where to show it
        for ax in axes:
            draw_meshes(ax, [(self.vertices, self.faces[keep], SKIN), (obj.vertices, obj.faces, OBJECT)], alpha=0.9)
            if c_o.any():
                draw_points(ax, pts[c_o > 0], color="#d7301f", size=3)
            if c_m.any():
                draw_markers(ax, self.vertices[self.marker_ids[c_m > 0]], color=MARKER_IN_CONTACT, size=14)
            set_equal(ax, np.stack([centre - radius / 2, centre + radius / 2]), pad=0.0)
        return fig

    @staticmethod
    def describe(numbers: dict[str, float]) -> str:
        """One line of the numbers for the widget's readout."""
        n, vol = numbers, numbers["penetration_volume_cm3"]
        return (f"hand–object distance {n['min_distance_cm']:+.2f} cm · "
                f"markers in contact (≤ {MARKER_CONTACT_THRESHOLD * 100:.0f} cm) {n['marker_contacts']:.0f} · "
                f"object points in contact (≤ {OBJECT_CONTACT_THRESHOLD * 100:.0f} cm) {n['object_contacts']:.0f} · "
                f"penetration {n['penetration_depth_cm']:.2f} cm deep"
                + ("" if math.isnan(vol) else f", {vol:.1f} cm³"))

    def widget(self, step: float = 0.005, span: float = 0.1, dpi: float = 72.0) -> Any:  # pragma: no cover - UI only
        """An ipywidgets box: object dropdown, x/y/z sliders (±span m), a yaw slider, the figure and the readout."""
        step, span = check_positive(step, "step"), check_positive(span, "span")
        import ipywidgets as w

        from graspkit.viz.export import png_bytes

        # the figure goes into an Image widget (PNG bytes), not an Output widget: it then shows the same in every
        # front end and executor, and no stray display leaks into the notebook cell
        image, readout = w.Image(format="png"), w.HTML()

        def redraw(numbers: dict[str, float]) -> None:
            readout.value = f"<b>{self.name}</b>: {self.describe(numbers)}"
            image.value = png_bytes(self.figure(), dpi)

        controls: list[Any] = [w.Dropdown(options=list_objects(), value=self.name, description="object")]
        controls += [w.FloatSlider(**slider_bounds(self.offset[i], -span, span), step=step, description=f"{a} (m)",
                                   readout_format=".3f", continuous_update=False) for i, a in enumerate(OFFSET_SLIDERS)]
        controls.append(w.FloatSlider(**slider_bounds(self.yaw, -180, 180), step=15, description="yaw (°)",
                                      continuous_update=False))
        for name, c in zip(["object", *OFFSET_SLIDERS, YAW_SLIDER], controls):
            c.observe(lambda ch, name=name: redraw(self.update(name, ch["new"])), names="value")
        redraw(self.measure())
        return w.VBox([w.HBox([w.VBox(controls), image]), readout])
