"""Static 3D figures with matplotlib: shaded meshes, point clouds, markers, arrows, goals and a ground grid.

Everything is drawn in the z-up world (metres). Inputs may be numpy arrays, torch tensors or nested lists,
one item at a time (a (V, 3) mesh, not a batch).

Occlusion: meshes drawn in one `draw_meshes` call share one polygon collection, so their faces are
depth-sorted together (a hand around a mug is hidden correctly). Across calls, layers are drawn in a fixed
order (ground, meshes, paths, points, arrows, markers; see LAYERS) so that overlays stay visible even behind
a body; meshes from separate calls are drawn in call order, so draw meshes that overlap in one call.
"""
from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.colors import Colormap, Normalize, to_rgb, to_rgba
from matplotlib.figure import Figure
from mpl_toolkits.mplot3d import Axes3D
from mpl_toolkits.mplot3d.art3d import Line3DCollection, Poly3DCollection

from graspkit.viz.style import AMBIENT, ARROW, CONTACT_CMAP, GOAL, GROUND, MARKER, SKIN, TRAJECTORY, VIEWS

View = str | tuple[float, float]
Mesh = tuple[Any, Any] | tuple[Any, Any, Any]  # (vertices (V,3), faces (F,3)[, color])


def to_numpy(x: Any, dtype: type = np.float64) -> np.ndarray:
    """numpy array, torch tensor (any device, with grad) or nested lists -> numpy array of dtype."""
    if hasattr(x, "detach"):
        x = x.detach().cpu().numpy()
    return np.asarray(x, dtype=dtype)


def as_array(x: Any, name: str, shape: tuple[int | None, ...], dtype: type = np.float64) -> np.ndarray:
    """x -> numpy array of `shape` (None = any size); ValueError naming `name` otherwise."""
    a = to_numpy(x, dtype)
    if a.ndim != len(shape) or any(s is not None and s != d for s, d in zip(shape, a.shape)):
        want = "(" + ", ".join("N" if s is None else str(s) for s in shape) + ")"
        raise ValueError(f"{name}: expected shape {want}, got {tuple(a.shape)}")
    return a


def as_points(x: Any, name: str) -> np.ndarray:
    """x of shape (3,) or (N, 3) -> (N, 3) float array; ValueError naming `name` otherwise."""
    a = to_numpy(x)
    return as_array(a[None] if a.ndim == 1 else a, name, (None, 3))


def as_mesh(vertices: Any, faces: Any, name: str = "mesh") -> tuple[np.ndarray, np.ndarray]:
    """Validated vertices (V, 3) float and faces (F, 3) int with indices in [0, V)."""
    v = as_array(vertices, f"{name} vertices", (None, 3))
    f = as_array(faces, f"{name} faces", (None, 3), dtype=np.int64)
    if f.size and (f.min() < 0 or f.max() >= len(v)):
        raise ValueError(f"{name} faces: indices must lie in [0, {len(v)}), got [{f.min()}, {f.max()}]")
    return v, f


# drawing order: ground under meshes under overlays (paths, points, arrows, markers), so overlays stay visible
# even on the far side of a body; faces within one mesh collection are still depth-sorted
LAYERS = {"ground": 0.0, "mesh": 1.0, "path": 2.0, "points": 3.0, "arrows": 4.0, "markers": 5.0}
MAX_GROUND_LINES = 200      # per axis: a far goal once drew a line every 0.25 m over kilometres (GiBs)


def _layer(ax: Axes3D, artist: Any, layer: str) -> Any:
    """Give artist the z-order of `layer` and make ax draw by z-order instead of by whole-collection depth."""
    ax.computed_zorder = False
    artist.set_zorder(LAYERS[layer])
    return artist


def view_angles(view: View) -> tuple[float, float]:
    """A view name from style.VIEWS or an (elevation, azimuth) pair in degrees -> (elev, azim)."""
    if isinstance(view, str):
        if view not in VIEWS:
            raise ValueError(f"views: unknown view {view!r}; expected one of {list(VIEWS)} or (elev, azim)")
        return VIEWS[view]
    if len(view) != 2:
        raise ValueError(f"views: expected a name or (elev, azim), got {view!r}")
    return float(view[0]), float(view[1])


def camera_light(ax: Axes3D) -> np.ndarray:
    """Unit light direction (3,) for ax: from the camera, raised 30 deg and turned 35 deg, so fronts get a gradient."""
    e, a = np.radians(min(ax.elev + 30.0, 89.0)), np.radians(ax.azim - 35.0)
    return np.array([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)])


def face_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Unit normals (F, 3) of triangles; degenerate faces get a zero normal."""
    tri = vertices[faces]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)


def lambert(normals: np.ndarray, rgb: np.ndarray, light: np.ndarray, ambient: float = AMBIENT) -> np.ndarray:
    """Face colours (F, 3) from normals (F, 3), base colours (F, 3) and a unit light (3,): ambient + diffuse |n.l|."""
    # two-sided (|n.l|) so that meshes with flipped or inconsistent winding are not drawn black
    k = ambient + (1.0 - ambient) * np.abs(normals @ light)
    return np.clip(rgb * k[:, None], 0.0, 1.0)


def value_colors(values: Any, cmap: str | Colormap | None = None, vmin: float = 0.0, vmax: float = 1.0) -> np.ndarray:
    """Scalars (N,) -> RGBA (N, 4) through cmap (default: the contact colormap), clipped to [vmin, vmax]."""
    v = as_array(values, "values", (None,))
    cm = plt.get_cmap(cmap if cmap is not None else CONTACT_CMAP)
    return cm(Normalize(vmin, vmax, clip=True)(v))


def _mesh_polys(mesh: Mesh, name: str, ax: Axes3D, light: bool | Sequence[float],
                values: Any = None, cmap: Any = None) -> tuple[np.ndarray, np.ndarray]:
    """Triangles (F, 3, 3) and lit RGB face colours (F, 3) of one (vertices, faces[, color]) item."""
    if len(mesh) not in (2, 3):
        raise ValueError(f"{name}: expected (vertices, faces) or (vertices, faces, color), got {len(mesh)} items")
    v, f = as_mesh(mesh[0], mesh[1], name)
    if values is not None:
        vals = as_array(values, f"{name} values", (len(v),))
        rgb = value_colors(vals[f].mean(axis=1), cmap)[:, :3]
    else:
        rgb = np.broadcast_to(np.asarray(to_rgb(mesh[2] if len(mesh) == 3 else SKIN)), (len(f), 3))
    if light is not False:
        direction = camera_light(ax) if light is True else as_array(light, "light", (3,))
        rgb = lambert(face_normals(v, f), rgb, direction / np.linalg.norm(direction))
    return v[f], rgb


def draw_meshes(ax: Axes3D, meshes: Sequence[Mesh], alpha: float = 1.0, light: bool | Sequence[float] = True,
                values: Sequence[Any] | None = None, cmap: str | Colormap | None = None) -> Poly3DCollection:
    """Several (vertices (V,3), faces (F,3)[, color]) meshes as one depth-sorted, Lambert-lit collection.

    values: optional per-mesh per-vertex scalars in [0, 1] (None entries keep the mesh colour), e.g. contact maps.
    """
    polys, colors = [], []
    for k, mesh in enumerate(meshes):
        p, c = _mesh_polys(mesh, f"meshes[{k}]", ax, light, None if values is None else values[k], cmap)
        polys.append(p)
        colors.append(c)
    tri = np.concatenate(polys) if polys else np.zeros((0, 3, 3))
    rgb = np.concatenate(colors) if polys else np.zeros((0, 3))
    rgba = np.concatenate([rgb, np.full((len(tri), 1), alpha)], axis=1)
    # no edges and no antialiasing: antialiased edges leave light seams between adjacent faces
    pc = Poly3DCollection(tri, facecolors=rgba, edgecolors="none", linewidths=0.0, antialiased=False)
    ax.add_collection3d(pc)
    return _layer(ax, pc, "mesh")


def draw_mesh(ax: Axes3D, vertices: Any, faces: Any, color: Any = SKIN, alpha: float = 1.0,
              light: bool | Sequence[float] = True, values: Any = None, cmap: str | Colormap | None = None,
              max_faces: int | None = None) -> Poly3DCollection:
    """A triangle mesh: vertices (V,3), faces (F,3); Lambert light from the camera (light=True), a given
    direction (3,), or flat colour (False). values (V,) colours vertices through cmap (contact maps).
    max_faces: quadric-decimate larger meshes first (a 20k-face body draws in ~0.2 s, so rarely needed).
    """
    v, f = as_mesh(vertices, faces, "mesh")
    if max_faces is not None and len(f) > max_faces:
        if values is not None:
            raise ValueError("max_faces: decimation cannot carry per-vertex values; pass max_faces=None")
        import fast_simplification

        v, f = fast_simplification.simplify(v, f, target_reduction=1.0 - max_faces / len(f))
    return draw_meshes(ax, [(v, f, color)], alpha, light, None if values is None else [values], cmap)


def draw_points(ax: Axes3D, points: Any, values: Any = None, cmap: str | Colormap | None = None, size: float = 6.0,
                color: Any = MARKER, vmin: float = 0.0, vmax: float = 1.0, colorbar: bool = True,
                label: str | None = None) -> Any:
    """A point cloud (N,3), coloured by scalars values (N,) in [vmin, vmax] through cmap (default: contact
    colormap) with a colorbar, or in one colour; returns the scatter collection (a ScalarMappable)."""
    p = as_points(points, "points")
    kw: dict[str, Any] = dict(s=size, depthshade=False, linewidths=0)
    if values is not None:
        vals = as_array(values, "values", (len(p),))
        kw.update(c=vals, cmap=plt.get_cmap(cmap if cmap is not None else CONTACT_CMAP), vmin=vmin, vmax=vmax)
    else:
        kw.update(color=to_rgba(color))
    sc = _layer(ax, ax.scatter(p[:, 0], p[:, 1], p[:, 2], **kw), "points")
    if values is not None and colorbar:
        cb = ax.figure.colorbar(sc, ax=ax, shrink=0.6, pad=0.02)
        if label:
            cb.set_label(label)
    return sc


def draw_markers(ax: Axes3D, points: Any, labels: Sequence[str] | None = None, color: Any = MARKER,
                 size: float = 14.0, fontsize: float = 7.0) -> Any:
    """Markers (N,3) as dots, with optional text labels (N,) beside them; returns the scatter collection."""
    p = as_points(points, "points")
    if labels is not None and len(labels) != len(p):
        raise ValueError(f"labels: expected {len(p)} labels for {len(p)} points, got {len(labels)}")
    sc = ax.scatter(p[:, 0], p[:, 1], p[:, 2], s=size, color=to_rgba(color), depthshade=False,
                    edgecolors="white", linewidths=0.4)
    for q, text in zip(p, labels or []):
        _layer(ax, ax.text(q[0], q[1], q[2], f" {text}", fontsize=fontsize, color=color), "markers")
    return _layer(ax, sc, "markers")


def draw_arrows(ax: Axes3D, origins: Any, vectors: Any, color: Any = ARROW, linewidth: float = 1.5,
                head: float = 0.2) -> Line3DCollection:
    """Arrows from origins (N,3) or (3,) along vectors (N,3) or (3,) (true length, metres); head: tip share."""
    o, d = as_points(origins, "origins"), as_points(vectors, "vectors")
    if len(o) != len(d) and 1 not in (len(o), len(d)):
        raise ValueError(f"vectors: {len(d)} vectors for {len(o)} origins")
    o, d = np.broadcast_arrays(o, d)
    return _layer(ax, ax.quiver(o[:, 0], o[:, 1], o[:, 2], d[:, 0], d[:, 1], d[:, 2], color=color,
                                linewidths=linewidth, arrow_length_ratio=head, normalize=False), "arrows")


def sphere(center: Any, radius: float, n: int = 12) -> tuple[np.ndarray, np.ndarray]:
    """A UV sphere around center (3,): vertices ((n-1)*2n + 2, 3), faces (F, 3), outward winding."""
    c = as_array(center, "center", (3,))
    th = np.linspace(0, np.pi, n + 1)[1:-1]
    ph = np.linspace(0, 2 * np.pi, 2 * n, endpoint=False)
    t, p = np.meshgrid(th, ph, indexing="ij")
    ring = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], -1).reshape(-1, 3)
    v = np.concatenate([[[0, 0, 1]], ring, [[0, 0, -1]]]) * radius + c
    m, last = 2 * n, len(v) - 1
    faces = []
    for j in range(m):
        faces.append([0, 1 + j, 1 + (j + 1) % m])
        faces.append([last, 1 + (n - 2) * m + (j + 1) % m, 1 + (n - 2) * m + j])
    for i in range(n - 2):
        for j in range(m):
            a, b = 1 + i * m + j, 1 + i * m + (j + 1) % m
            faces += [[a, a + m, b + m], [a, b + m, b]]
    return v, np.asarray(faces)


def draw_goal(ax: Axes3D, center: Any, radius: float = 0.05, color: Any = GOAL, alpha: float = 0.9,
              light: bool | Sequence[float] = True) -> Poly3DCollection:
    """Goal spheres at center (3,) or (G,3) with the given radius; returns their mesh collection."""
    return draw_meshes(ax, [(*sphere(c, radius), color) for c in as_points(center, "center")], alpha, light)


def draw_path(ax: Axes3D, points: Any, color: Any = TRAJECTORY, linewidth: float = 1.5, dots: bool = False) -> Any:
    """A trajectory (T,3) as a polyline (e.g. pelvis or wrist path), optionally with a dot per sample."""
    p = as_points(points, "points")
    (line,) = ax.plot(p[:, 0], p[:, 1], p[:, 2], color=color, linewidth=linewidth, marker="." if dots else None)
    return _layer(ax, line, "path")


def draw_ground(ax: Axes3D, extent: float | Sequence[float] = 1.0, z: float = 0.0, step: float = 0.25,
                color: Any = GROUND, linewidth: float = 0.6) -> Line3DCollection:
    """A grid on the plane z, lines every `step` metres over extent: half-size (float) or (xmin, xmax, ymin, ymax);
    on a scene wider than MAX_GROUND_LINES steps the step grows to keep that many lines."""
    ext = [-extent, extent, -extent, extent] if np.isscalar(extent) else list(map(float, extent))
    if len(ext) != 4 or not np.isfinite(ext).all() or ext[0] >= ext[1] or ext[2] >= ext[3]:
        raise ValueError(f"extent: expected a half-size or (xmin, xmax, ymin, ymax), got {extent!r}")
    step = max(step, max(ext[1] - ext[0], ext[3] - ext[2]) / MAX_GROUND_LINES)
    xs = np.arange(np.ceil(ext[0] / step), np.floor(ext[1] / step) + 1) * step
    ys = np.arange(np.ceil(ext[2] / step), np.floor(ext[3] / step) + 1) * step
    segs = [[(x, ext[2], z), (x, ext[3], z)] for x in xs] + [[(ext[0], y, z), (ext[1], y, z)] for y in ys]
    lc = Line3DCollection(segs, colors=color, linewidths=linewidth)
    ax.add_collection3d(lc)
    return _layer(ax, lc, "ground")


def bounds_of(*arrays: Any) -> np.ndarray:
    """Bounds (2, 3) = [min, max] over all points of arrays of shape (..., 3)."""
    pts = [to_numpy(a) for a in arrays]
    if not pts or any(p.ndim == 0 or p.shape[-1] != 3 for p in pts):
        raise ValueError(f"points: expected arrays of shape (..., 3), got {[p.shape for p in pts]}")
    allp = np.concatenate([p.reshape(-1, 3) for p in pts])
    if not len(allp):
        raise ValueError("points: no points given")
    return np.stack([allp.min(0), allp.max(0)])


FLOOR_SINK = 0.5   # m: a scene whose lowest point is no deeper than this under z = 0 stands on the floor z = 0


def floor_height(*points: Any) -> float:
    """Where the ground grid goes for a scene of points (..., 3): the floor z = 0 when the scene stands on it (a body
    sinking up to FLOOR_SINK under it is drawn through it, not on it), else just under the lowest point (a scene not
    set on a floor, such as a body centred at its pelvis)."""
    lowest = float(bounds_of(*points)[0][2])
    return 0.0 if lowest >= -FLOOR_SINK else lowest


def set_equal(ax: Axes3D, *points: Any, pad: float = 0.05, zoom: float = 1.0) -> np.ndarray:
    """Equal metric scale on all axes over points (..., 3) (several arrays, or bounds (2,3)): limits get a
    pad (metres) and the box aspect equals the padded ranges; returns the limits (2, 3)."""
    lo, hi = bounds_of(*points)
    # a flat set (e.g. ground points) still gets a visible box
    span = max(float((hi - lo).max()), 1e-3)
    mid, half = (lo + hi) / 2, np.maximum((hi - lo) / 2 + pad, 0.02 * span)
    lo, hi = mid - half, mid + half
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_zlim(lo[2], hi[2])
    ax.set_box_aspect(tuple(hi - lo), zoom=zoom)
    return np.stack([lo, hi])


def figure(views: Sequence[View] = ("front", "side", "top"), size: float = 4.0, title: str | None = None,
           axis: bool = False, proj: str = "ortho", dpi: float | None = None) -> tuple[Figure, list[Axes3D]]:
    """A figure with one 3D axes per view (names from style.VIEWS or (elev, azim) pairs), in a row,
    each size x size inches; axis=False hides panes and ticks (the ground grid gives the scale)."""
    views = [views] if isinstance(views, str) else list(views)
    if not views:
        raise ValueError("views: expected at least one view")
    angles = [view_angles(v) for v in views]
    fig = plt.figure(figsize=(size * len(views), size + (0.3 if title else 0.0)), dpi=dpi)
    axes = []
    for k, (view, (elev, azim)) in enumerate(zip(views, angles)):
        ax = fig.add_subplot(1, len(views), k + 1, projection="3d", proj_type=proj)
        ax.view_init(elev=elev, azim=azim)
        if not axis:
            ax.set_axis_off()
        else:
            ax.set_xlabel("x (m)")
            ax.set_ylabel("y (m)")
            ax.set_zlabel("z (m)")
        if len(views) > 1:
            ax.set_title(view if isinstance(view, str) else f"elev {elev:.0f}, azim {azim:.0f}", fontsize=9, pad=0)
        axes.append(ax)
    if title:
        fig.suptitle(title, fontsize=11)
    # a title above panel titles needs more room, or the two overprint at the small sizes of animations
    top = (0.86 if len(views) > 1 else 0.9) if title else 0.95
    fig.subplots_adjust(left=0.0, right=1.0, bottom=0.0, top=top, wspace=0.0)
    return fig, axes


def show_scene(meshes: Sequence[Mesh] = (), points: Any = None, values: Any = None, markers: Any = None,
               labels: Sequence[str] | None = None, arrows: tuple[Any, Any] | None = None, goals: Any = None,
               goal_radius: float = 0.05, paths: Sequence[Any] = (), ground: bool = True,
               views: Sequence[View] = ("front", "side", "top"), size: float = 4.0, title: str | None = None,
               cmap: str | Colormap | None = None, colorbar_label: str | None = None,
               mesh_values: Sequence[Any] | None = None, axis: bool = False, zoom: float = 1.2) -> Figure:
    """One scene in several views: meshes [(V,3), (F,3)[, color]], points (N,3) coloured by values (N,),
    markers (M,3) with labels, arrows (origins, vectors), goal spheres (G,3), paths [(T,3)], ground grid.
    mesh_values: per-mesh per-vertex scalars (contact maps) or None; returns the Figure, a pyplot one (a notebook shows
    it inline; in a loop, plt.close(fig) after saving it, or pyplot keeps every one open)."""
    meshes = [(*as_mesh(m[0], m[1], f"meshes[{k}]"), *m[2:]) for k, m in enumerate(meshes)]
    extent: list[Any] = [m[0] for m in meshes] + [as_points(p, f"paths[{k}]") for k, p in enumerate(paths)]
    for a, name in ((points, "points"), (markers, "markers"), (goals, "goals")):
        if a is not None:
            extent.append(as_points(a, name))
            if not np.isfinite(extent[-1]).all():
                raise ValueError(f"{name}: contains NaN or Inf (expected positions in metres)")
    things = extent[:-1] if goals is not None else extent          # what stands on the floor: not the goals
    if arrows is not None:
        o, d = np.broadcast_arrays(as_points(arrows[0], "origins"), as_points(arrows[1], "vectors"))
        extent += [o, o + d]
    if not extent:
        raise ValueError("show_scene: nothing to draw")
    fig, axes = figure(views, size, title, axis=axis)
    try:   # a check that fails while drawing (mesh_values, cmap) closes the figure it opened
        lo, hi = bounds_of(*extent)
        if goals is not None:
            lo, hi = lo - goal_radius, hi + goal_radius
        ground_box = None
        if ground:  # a grid a quarter of the scene wider, on the floor (floor_height)
            m, gz = 0.25 * max(float((hi - lo)[:2].max()), 0.4), floor_height(*things or extent)
            ground_box = (lo[0] - m, hi[0] + m, lo[1] - m, hi[1] + m)
            lo = np.minimum(lo, [ground_box[0], ground_box[2], gz])
            hi = np.maximum(hi, [ground_box[1], ground_box[3], gz])
        sc = None
        for ax in axes:
            polys = list(meshes)
            mv = None if mesh_values is None else list(mesh_values)
            if goals is not None:  # goals join the mesh collection so that they are depth-sorted with the body
                polys += [(*sphere(c, goal_radius), GOAL) for c in as_points(goals, "goals")]
                mv = None if mv is None else mv + [None] * (len(polys) - len(mv))
            if ground_box is not None:
                draw_ground(ax, ground_box, z=gz)
            if polys:
                draw_meshes(ax, polys, values=mv, cmap=cmap)
            for p in paths:
                draw_path(ax, p)
            if points is not None:
                sc = draw_points(ax, points, values, cmap=cmap, colorbar=False)
            if markers is not None:
                draw_markers(ax, markers, labels)
            if arrows is not None:
                draw_arrows(ax, *arrows)
            set_equal(ax, np.stack([lo, hi]), pad=0.0, zoom=zoom)
        if (points is not None and values is not None) or mesh_values is not None:
            mappable = sc if sc is not None and values is not None else plt.cm.ScalarMappable(
                Normalize(0, 1), plt.get_cmap(cmap if cmap is not None else CONTACT_CMAP))
            w = fig.get_figwidth()  # keep ~0.9 inch on the right for the bar, its ticks and its label
            fig.subplots_adjust(right=1.0 - 1.0 / w)
            cb = fig.colorbar(mappable, cax=fig.add_axes((1.0 - 0.85 / w, 0.2, 0.12 / w, 0.55)))
            if colorbar_label:
                cb.set_label(colorbar_label)
    except BaseException:
        plt.close(fig)
        raise
    return fig
