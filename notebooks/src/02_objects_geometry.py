# %% [markdown]
# # 02 · Objects and contact geometry
#
# SAGA and GOAL never look at an object as a mesh inside their networks. They look at it through a few
# geometric *measurements*, and this lesson builds each of them on graspkit's procedural objects:
#
# | measurement | paper | used for |
# |---|---|---|
# | 2,048 surface points with normals | SAGA Sec. 3 ("Preliminaries") | the object input of WholeGrasp-VAE |
# | Basis Point Set code $\mathbf{b}^o \in \mathbb{R}^{1024}$ | GOAL Sec. 3.3, Eq. 2 | the object input of GNet (and the hand code $\mathbf{b}^h_g$ of MNet, Sec. 3.4, Eq. 9) |
# | nearest distance $d(x, \mathcal{Y})$ and signed distance $S(x, \mathcal{Y})$ | SAGA Eq. 3, 6, 7 | consistency, contact and collision terms |
# | contact maps $C_M$ (markers) and $C_O$ (object points) | SAGA Sec. 3.2 | what WholeGrasp-VAE predicts, what GraspPose-Opt pulls together |
# | interpenetration volume and depth | SAGA Sec. 4 (Tab. 1: both), GOAL Sec. 4 (Tab. 1: the volume) | the physical-plausibility metrics |
# | interaction-aware attention $I_w(\mathbf{d}) = e^{-w\mathbf{d}}$ | GOAL Sec. 3.2, Eq. 1 | weighting body-to-object distances (ablated for MNet in Tab. 2) |
#
# Everything lives in `graspkit.objects` (reference: `docs/objects.md`). World frame: **z up, metres**;
# signed distances are **negative inside**.

# %%
%matplotlib inline
import matplotlib.pyplot as plt
import numpy as np
import torch
import trimesh

from graspkit import viz
from graspkit.data.grasp import SPLITS
from graspkit.objects import (IAA_WEIGHT, MARKER_CONTACT_THRESHOLD, OBJECT_CONTACT_THRESHOLD, SPECS, TEST_OBJECTS,
                              ObjectPose, SDFGrid, apply_pose, bps_basis, bps_encode, interaction_attention,
                              interpenetration, list_objects, make_object, sample_surface, signed_distance,
                              signed_distance_to_points, winding_number)

torch.manual_seed(0)
torch.set_num_threads(1)  # these small queries gain little from more; one thread keeps run times steady on busy cores
plt.rcParams["figure.dpi"] = 72  # small pictures keep the notebook small

# %% [markdown]
# ## 1 · The catalogue
#
# The papers train and test on GRAB's objects (SAGA Sec. 4, GOAL Sec. 4) and SAGA also tests on unseen HO3D
# (YCB) objects. Those scans cannot be shipped, so graspkit builds **17 procedural look-alikes** by exact
# constructive solid geometry: every object is one watertight, outward-oriented triangle mesh, z up in its
# resting pose, with its origin at the centre of its bounding box. GRAB's held-out **test objects** (mug,
# camera, toothpaste, wine glass, frying pan, binoculars: SAGA App. A.3, GrabNet's split; GOAL withholds five
# objects without naming them) are drawn in green below. One deviation: with only 17 objects, graspkit *trains*
# on its YCB / HO3D look-alikes (banana, bowl, can, ...), which SAGA keeps as unseen test objects only.

# %%
names = list_objects()
fig = plt.figure(figsize=(10.5, 5.6))
for k, name in enumerate(names):
    mesh = make_object(name)
    test = name in TEST_OBJECTS
    ax = fig.add_subplot(3, 6, k + 1, projection="3d", proj_type="ortho")
    ax.view_init(22, -55)
    ax.set_axis_off()
    viz.draw_mesh(ax, mesh.vertices, mesh.faces, color=viz.OBJECT_2 if test else viz.OBJECT)
    viz.set_equal(ax, mesh.vertices, pad=0.0)
    x, y, z = mesh.extents * 100
    ax.set_title(f"{name}{' (test)' if test else ''}\n{x:.0f} × {y:.0f} × {z:.0f} cm", fontsize=8, pad=0,
                 color="#3a7d44" if test else "black")
fig.subplots_adjust(left=0, right=1, bottom=0, top=0.93, wspace=0, hspace=0.15)

# %% [markdown]
# Each panel has its own scale, so here are the sizes (bounding box), face counts and volumes. `make_object(name,
# seed=s)` gives a seeded variant scaled by U(0.9, 1.1) in x, y and independently in z, for training-set variety.

# %%
print(f"{'object':<12} {'split':<6} {'source':<30} {'x × y × z (cm)':<20} {'faces':>6} {'volume (cm³)':>13}")
for name in names:
    mesh = make_object(name)
    size = " × ".join(f"{s:.1f}" for s in mesh.extents * 100)
    split = next(s for s, members in SPLITS.items() if name in members)
    print(f"{name:<12} {split:<6} {SPECS[name].source:<30} {size:<20} {len(mesh.faces):>6} {mesh.volume * 1e6:>13.0f}")
variant = make_object("mug", seed=3)
print("\nmug, seed 3:", " × ".join(f"{s:.1f}" for s in variant.extents * 100), "cm")

# %% [markdown]
# ## 2 · Surface points and normals
#
# SAGA represents an object by **2,048 points sampled on its surface, each with its normal** (Sec. 3,
# "Preliminaries": 3 coordinates + 3 normal features). `sample_surface` picks a face with probability
# proportional to its area, then a uniform point in it (square-root barycentric warp), so the points are
# uniform over the surface whatever the triangulation. The normal is the face's outward normal.

# %%
mug = make_object("mug")
points, normals = sample_surface(mug, 2048, seed=0)
unit = np.allclose(np.linalg.norm(normals, axis=1), 1.0)
print("points", points.shape, "normals", normals.shape, "| unit normals:", unit)
# outward means: a step of 1 mm along the normal leaves the solid, a step against it enters it
out = (signed_distance(points + 1e-3 * normals, mug) > 0).float().mean()
inn = (signed_distance(points - 1e-3 * normals, mug) < 0).float().mean()
print(f"1 mm along the normal is outside for {out:.1%}, against it inside for {inn:.1%}")

# %% [markdown]
# Left: every point, and the normals of a random tenth as 1.2 cm arrows. Right: a 1 cm thick slice through
# the handle (|y| < 5 mm) seen from the front. The normals on the *inner* wall of the cup point into the
# cavity: outward from the solid, which is what a hand touching the inside would need.

# %%
fig = plt.figure(figsize=(8.5, 3.8))
ax = fig.add_subplot(1, 2, 1, projection="3d", proj_type="ortho")
ax.view_init(22, -55)
ax.set_axis_off()
some = np.random.default_rng(0).choice(len(points), 200, replace=False)
viz.draw_mesh(ax, mug.vertices, mug.faces, color=viz.OBJECT, alpha=0.25)
viz.draw_points(ax, points, size=1.5)
viz.draw_arrows(ax, points[some], 0.012 * normals[some], linewidth=0.8, head=0.3)
viz.set_equal(ax, mug.vertices, pad=0.0)
ax.set_title("2,048 points, 200 normals", fontsize=9)
ax = fig.add_subplot(1, 2, 2)
band = np.abs(points[:, 1]) < 0.005
ax.scatter(points[band, 0] * 100, points[band, 2] * 100, s=4, color=viz.MARKER)
ax.quiver(points[band, 0] * 100, points[band, 2] * 100, normals[band, 0], normals[band, 2], color=viz.ARROW,
          scale=25, width=0.004)
ax.set_aspect("equal")
ax.set_xlabel("x (cm)")
ax.set_ylabel("z (cm)")
ax.set_title("slice |y| < 5 mm", fontsize=9)
fig.tight_layout()

# %% [markdown]
# ## 3 · Basis Point Set (BPS)
#
# GOAL feeds GNet the object as a **BPS code** $\mathbf{b}^o \in \mathbb{R}^{1024}$ (Sec. 3.3, Eq. 2; Prokudin et
# al., ICCV 2019): fix $K = 1024$ basis points once, uniformly in a ball around the object centre, and record for
# each the distance to the nearest object point. Every object becomes a fixed-length vector in a fixed order,
# which a plain MLP can read. The ball radius is not in GOAL's text; graspkit uses 0.15 m, enough for
# hand-held objects. MNet encodes the *hand* in the goal frame with the **same** basis (Sec. 3.4, Eq. 9), so
# the two codes share one frame and together say where the hand is relative to the object.

# %%
basis = bps_basis(1024, radius=0.15, seed=0)
cloud = torch.as_tensor(points)
code, offsets = bps_encode(cloud, basis, return_deltas=True)  # (1024,), (1024, 3) nearest point - basis point
print("basis", tuple(basis.shape), f"| radius of the farthest basis point {basis.norm(dim=1).max():.3f} m")
print("code", tuple(code.shape), f"| min {code.min():.4f} m, mean {code.mean():.4f} m, max {code.max():.4f} m")
print("first 6 entries:", np.round(code[:6].numpy(), 4))
# the code is a function of the point cloud only: the nearest point = basis point + offset
print("offsets consistent with distances:", bool(torch.allclose(offsets.norm(dim=1), code)))

# %%
fig = plt.figure(figsize=(11, 3.6))
ax = fig.add_subplot(1, 3, 1, projection="3d", proj_type="ortho")
ax.view_init(22, -55)
ax.set_axis_off()
viz.draw_mesh(ax, mug.vertices, mug.faces, color=viz.OBJECT, alpha=0.6)
viz.draw_points(ax, basis, values=code, cmap="viridis", vmax=0.12, size=3, label="distance (m)")
viz.set_equal(ax, basis, pad=0.0, zoom=1.3)
ax.set_title("1,024 basis points, coloured by the code", fontsize=9)
ax = fig.add_subplot(1, 3, 2)
slab = basis[:, 2].abs() < 0.01
b, o = basis[slab].numpy() * 100, offsets[slab].numpy() * 100
ax.plot(*(points[np.abs(points[:, 2]) < 0.01][:, :2] * 100).T, ".", ms=2, color=viz.OBJECT)
ax.plot(b[:, 0], b[:, 1], ".", ms=3, color=viz.MARKER)
ax.quiver(b[:, 0], b[:, 1], o[:, 0], o[:, 1], angles="xy", scale_units="xy", scale=1, width=0.003, color=viz.ARROW)
ax.set_aspect("equal")
ax.set_xlabel("x (cm)")
ax.set_ylabel("y (cm)")
ax.set_title("slab |z| < 1 cm: basis point → nearest point", fontsize=9)
ax = fig.add_subplot(1, 3, 3)
for label, shape in [("mug", mug), ("mug, seed 5", make_object("mug", seed=5)), ("camera", make_object("camera"))]:
    c = bps_encode(torch.as_tensor(sample_surface(shape, 2048, seed=0)[0]), basis)
    ax.plot(c[:64].numpy() * 100, lw=1, label=label)
ax.set_xlabel("basis point k")
ax.set_ylabel("code (cm)")
ax.legend(fontsize=8)
ax.set_title("the code as a vector (first 64 entries)", fontsize=9)
fig.tight_layout()

# %% [markdown]
# Similar shapes give similar codes, different shapes different ones, which is what lets GNet condition on
# the code. Distances between whole codes (L2, in metres):

# %%
codes = {}
for label, name, seed in [("mug", "mug", None), ("mug, seed 5", "mug", 5), ("mug, 2nd sample", "mug", None),
                          ("camera", "camera", None), ("wine_glass", "wine_glass", None)]:
    pts = sample_surface(make_object(name, seed=seed), 2048, seed=1 if label == "mug, 2nd sample" else 0)[0]
    codes[label] = bps_encode(torch.as_tensor(pts), basis)
for label, c in list(codes.items())[1:]:
    print(f"|code(mug) - code({label})| = {(codes['mug'] - c).norm():.3f}")

# %% [markdown]
# ## 4 · Nearest distance and signed distance
#
# SAGA measures body–object proximity in two ways:
# - the **unsigned** distance $d(x, \mathcal{Y}) = \min_{y \in \mathcal{Y}} \lVert x - y \rVert_2^2$ from a point to a
#   point cloud (Eq. 3, the consistency loss; Eq. 6, the contact loss), and
# - the **signed** distance $S(x, \mathcal{Y})$ (Eq. 7, the collision loss), negative inside, so
#   $\max(-S, \sigma)$ penalises only points that went in.
#
# Against a point cloud, $d$ is a nearest-neighbour search (`nearest_neighbours`, `squared=True` for Eq. 3's squared
# form). Against a mesh graspkit computes both exactly: `point_mesh_distance` (closest point on any triangle) and
# `signed_distance` (that distance, signed by the pseudo-normal of the closest feature; Bærentzen & Aanæs 2005).
# For speed in optimisation loops, `SDFGrid` samples the exact SDF once on a regular grid and interpolates
# trilinearly. Below: a vertical slice through the mug and its handle (the plane y = 0). The black line is
# the zero level set (the surface), the dashed lines are 1 cm and 2 cm out, graspkit's two contact thresholds.

# %%
xs, zs = np.linspace(-0.075, 0.075, 101), np.linspace(-0.065, 0.065, 88)
X, Z = np.meshgrid(xs, zs)
plane = np.stack([X.ravel(), np.zeros(X.size), Z.ravel()], axis=1)
sdf_exact = signed_distance(plane, mug).reshape(X.shape).numpy()
grid = SDFGrid.from_mesh(mug, resolution=48)  # 48 nodes along the longest side (object_sdf_grid: 64, cached)
sdf_grid = grid(torch.as_tensor(plane)).reshape(X.shape).numpy()
print(f"grid: {tuple(grid.values.shape[::-1])} nodes (x, y, z), cell {grid.cell[0] * 1000:.2f} mm")

# %%
fig, axes = plt.subplots(1, 3, figsize=(11, 3.3), layout="constrained")
extent = (xs[0] * 100, xs[-1] * 100, zs[0] * 100, zs[-1] * 100)
for ax, values, title in [(axes[0], sdf_exact, "exact signed distance"), (axes[1], sdf_grid, "grid (trilinear)")]:
    im = ax.imshow(np.clip(values * 100, -3, 3), origin="lower", extent=extent, cmap="RdBu", vmin=-3, vmax=3)
    ax.contour(xs * 100, zs * 100, values * 100, levels=[0], colors="black", linewidths=1.5)
    ax.contour(xs * 100, zs * 100, values * 100, levels=[1, 2], colors=viz.ARROW, linewidths=0.8, linestyles="--")
    ax.set_title(title, fontsize=9)
    ax.set_xlabel("x (cm)")
axes[0].set_ylabel("z (cm)")
fig.colorbar(im, ax=axes[:2], label="cm (< 0 inside)", shrink=0.9, pad=0.02)
im = axes[2].imshow(np.abs(sdf_grid - sdf_exact) * 1000, origin="lower", extent=extent, cmap="magma", vmax=1.0)
axes[2].contour(xs * 100, zs * 100, sdf_exact, levels=[0], colors="white", linewidths=0.6)
axes[2].set_title("|grid − exact|", fontsize=9)
axes[2].set_xlabel("x (cm)")
fig.colorbar(im, ax=axes[2], label="mm", shrink=0.9)
plt.show()

# %% [markdown]
# The grid's error lives where the distance field has a kink that trilinear interpolation cannot follow: at the
# thin walls and rims, and along the *medial axis* (the bright lines inside the cup and below it), where the
# nearest surface point jumps from one wall to another. The walls are 4 mm thick, so inside them the field is
# negative by at most 2 mm: too little to see on this colour scale.
#
# Numbers on 5,000 random points in the mug's bounding box padded by 2 cm, against two independent references:
# trimesh's signed distance (which is *positive inside*, so we flip it) and the generalized winding number
# (≈ 1 inside, 0 outside; Jacobson et al. 2013).

# %%
rng = np.random.default_rng(0)
query = rng.uniform(mug.bounds[0] - 0.02, mug.bounds[1] + 0.02, size=(5000, 3))
exact = signed_distance(query, mug).numpy()
reference = -trimesh.proximity.signed_distance(mug, query)
fast = grid(torch.as_tensor(query)).numpy()
inside_wn = winding_number(query[:2000], mug).numpy() > 0.5  # slow (all faces per point): a subset
far = np.abs(exact) > float(grid.cell.max())
print(f"inside the mug: {(exact < 0).mean():.1%} of the points")
print(f"exact vs trimesh:  sign agrees {np.mean(np.sign(exact) == np.sign(reference)):.2%}, "
      f"max |difference| {np.abs(exact - reference).max() * 1000:.2f} mm")
print(f"exact vs winding number (2,000 points): inside agrees {np.mean((exact[:2000] < 0) == inside_wn):.2%}")
print(f"grid vs exact: sign agrees {np.mean(np.sign(fast) == np.sign(exact)):.2%} (all), "
      f"{np.mean(np.sign(fast[far]) == np.sign(exact[far])):.2%} (farther than one cell from the surface); "
      f"median |error| {np.median(np.abs(fast - exact)) * 1000:.3f} mm, max {np.abs(fast - exact).max() * 1000:.2f} mm")

# %% [markdown]
# SAGA's Eq. 7 defines $S(x, \mathcal{Y})$ against a **point cloud**: "the signed distance from point $x$ to point cloud
# $\mathcal{Y}$", without saying how it is signed; graspkit signs the distance to the nearest point by that point's
# normal (`signed_distance_to_points`), and it is only as good as the cloud is dense: against the mesh-exact value on
# the same query points,

# %%
for n in (2048, 8192):
    cloud_pts, cloud_nrm = sample_surface(mug, n, seed=0)
    approx = signed_distance_to_points(query, cloud_pts, cloud_nrm).numpy()
    print(f"{n:>6} points: sign agrees {np.mean(np.sign(approx) == np.sign(exact)):.2%}, "
          f"median |error| {np.median(np.abs(approx - exact)) * 1000:.2f} mm")

# %% [markdown]
# ## 5 · Contact maps on the body and on the object
#
# SAGA's WholeGrasp-VAE (Sec. 3.2, Fig. 3) describes a grasp by the body **markers** $M$ *and* two binary
# contact maps: $C_M \in \{0,1\}^N$, which markers touch the object, and $C_O \in \{0,1\}^{2048}$, which object
# points touch the body. GraspPose-Opt then pulls the contacting markers onto the object and the contacting
# object points onto the body (Eq. 6). The paper gives no distance threshold; graspkit labels
#
# - a marker as touching when it is within **2 cm** of the object *surface* (markers are sparse skin points a few
#   cm apart, so 2 cm accepts the markers of a palm or finger that wraps the object but not the back of the hand);
# - an object point as touching when it is within **1 cm** of the body *surface* (the body is dense, so a tighter
#   band marks the patch under the palm and fingers, not the gaps between them).
#
# To see them we need a body touching an object. Lesson 01 built the body; here we pose it with the right arm held
# forward, palm down (`reaching_body`), find the palm's centre and outward normal from the palm vertices, and put
# an object on that normal line so that the nearest body vertex is 2 mm from its surface (`place_at_palm`).

# %%
from graspkit.body import BodyModel
from graspkit.body.markers import goal_vertices, palm_vertices, saga_markers
from graspkit.objects import body_object_attention, distance_to, marker_contact, object_contact
from graspkit.paths import default_model_path
from graspkit.viz.object_explorer import (MARKER_IN_CONTACT, HandObjectExplorer, hand_vertices, palm_frame,
                                          place_at_palm, reaching_body)

bm = BodyModel.from_file(default_model_path())
body_v, body_f = reaching_body(bm)  # (V, 3) world, feet on z = 0, facing -y; (F, 3)
markers = saga_markers(bm)
palm = palm_vertices(bm)["right"]
centre, normal = palm_frame(body_v, body_f, palm)
print(f"body: {len(body_v)} vertices, {len(body_f)} faces; {len(markers)} SAGA markers; "
      f"{len(palm)} right-palm vertices")
print("palm centre (m):", np.round(centre, 3), " palm normal:", np.round(normal, 2))

obj_name = "can"
can = make_object(obj_name)  # object frame
obj_pose = place_at_palm(can, body_v, body_f, palm, gap=0.002)
obj = apply_pose(obj_pose, can)  # world
obj_points = apply_pose(obj_pose, sample_surface(can, 2048, seed=0)[0])
marker_pos = body_v[markers.vertex_ids]
c_m = marker_contact(marker_pos, obj).numpy()  # SAGA's C_M, (143,)
c_o = object_contact(obj_points, (body_v, body_f)).numpy()  # SAGA's C_O, (2048,)
print(f"thresholds: marker {MARKER_CONTACT_THRESHOLD * 100:.0f} cm, "
      f"object point {OBJECT_CONTACT_THRESHOLD * 100:.0f} cm")
print(f"C_M: {int(c_m.sum())} of {len(c_m)} markers touch the {obj_name}:",
      ", ".join(n for n, c in zip(markers.names, c_m) if c))
print(f"C_O: {int(c_o.sum())} of {len(c_o)} object points touch the body")

# %% [markdown]
# Left: the whole scene. Middle: the markers, green where $C_M = 1$ (SAGA Fig. 3 colours them the same way).
# Right: the object's 2,048 points, red where $C_O = 1$: the patch under the palm.

# %%
fig = plt.figure(figsize=(10.5, 3.8))
lo, hi = centre - 0.11, centre + 0.11
ax = fig.add_subplot(1, 3, 1, projection="3d", proj_type="ortho")
viz.draw_meshes(ax, [(body_v, body_f, viz.SKIN), (obj.vertices, obj.faces, viz.OBJECT)])
viz.set_equal(ax, body_v, obj.vertices, pad=0.0)
ax.set_title("reaching body and a can", fontsize=9)
ax = fig.add_subplot(1, 3, 2, projection="3d", proj_type="ortho")
near = np.linalg.norm(body_v[body_f].mean(1) - centre, axis=1) < 0.16
viz.draw_meshes(ax, [(body_v, body_f[near], viz.SKIN), (obj.vertices, obj.faces, viz.OBJECT)], alpha=0.35)
close = np.all((marker_pos > lo) & (marker_pos < hi), axis=1)
viz.draw_markers(ax, marker_pos[close & (c_m == 0)], size=10)
viz.draw_markers(ax, marker_pos[c_m > 0], color=MARKER_IN_CONTACT, size=18)
viz.set_equal(ax, np.stack([lo, hi]), pad=0.0)
ax.set_title(f"markers: C_M = 1 in green ({int(c_m.sum())})", fontsize=9)
ax = fig.add_subplot(1, 3, 3, projection="3d", proj_type="ortho")
viz.draw_points(ax, obj_points, values=c_o, size=3, colorbar=False)
viz.draw_meshes(ax, [(body_v, body_f[near], viz.SKIN)], alpha=0.25)
viz.set_equal(ax, np.stack([lo, hi]), pad=0.0)
ax.set_title(f"object points: C_O = 1 in red ({int(c_o.sum())})", fontsize=9)
for ax in fig.axes:
    ax.view_init(25, -60)
    ax.set_axis_off()
fig.subplots_adjust(left=0, right=1, bottom=0, top=0.92, wspace=0)

# %% [markdown]
# The maps are what SAGA's losses need. GraspPose-Opt's contact term (Eq. 6) sums, over the object points with
# $C_o = 1$, their distance to the body, $d(o, V_B)$, and over the markers with $C_m = 1$ their distance to the
# object, $d(m, O)$ (here plain distances, without the weights $\alpha$). With the maps of the touching pose it is
# small; lower the object away from the palm and it grows, which is the pull that brings the hand back:

# %%
def contact_distances(offset: np.ndarray) -> tuple[torch.Tensor, torch.Tensor]:
    """Eq. 6's distances, object moved by offset (3,) m: d(o, V_B) where C_O = 1 (P,), d(m, O) where C_M = 1 (M,)."""
    moved = apply_pose(ObjectPose(obj_pose.translation + offset, np.eye(3)), can)
    return distance_to(obj_points[c_o > 0] + offset, (body_v, body_f)), distance_to(marker_pos[c_m > 0], moved)


print(f"{'lowered by':>10} | {'sum d(o, V_B) (m)':>17} {'mean (cm)':>9} | {'sum d(m, O) (m)':>15} {'mean (cm)':>9}")
for drop in (0.0, 0.01, 0.05):
    d_o, d_m = contact_distances(np.array([0.0, 0.0, -drop]))
    print(f"{drop * 100:>7.0f} cm | {d_o.sum():>17.3f} {d_o.mean() * 100:>9.2f} | "
          f"{d_m.sum():>15.3f} {d_m.mean() * 100:>9.2f}")

# %% [markdown]
# ## 6 · Interpenetration volume and depth
#
# SAGA (Sec. 4, Tab. 1) reports how much body and object overlap by the **volume** of their intersection (cm³) and
# the **depth**, the farthest a body vertex went inside the object (cm); GOAL (Sec. 4, Tab. 1) by the volume alone.
# graspkit's `interpenetration(body, obj)` casts vertical rays on a 1 mm grid over the overlap of the two bounding
# boxes, finds each mesh's inside intervals along every ray exactly (a running winding number over the signed
# crossings: +1 entering, -1 leaving), and sums the length of their intersection; the depth is the most negative signed distance of a body vertex.
#
# Two spheres have a closed form. Radii $r_1, r_2$ at centre distance $d$ overlap in a lens of volume
# $$V = \frac{\pi (r_1 + r_2 - d)^2 \left(d^2 + 2d(r_1 + r_2) - 3(r_1 - r_2)^2\right)}{12\, d},$$
# and if the second sphere's centre lies on the ray through a body vertex, that vertex is the deepest, at
# depth $r_2 - |d - r_1|$. The meshes are icospheres (5,120 faces), which lie slightly inside the true spheres.

# %%
def lens_volume(r1: float, r2: float, d: float) -> float:
    """Volume (m³) of the intersection of two balls of radii r1, r2 whose centres are d apart."""
    return np.pi * (r1 + r2 - d) ** 2 * (d * d + 2 * d * (r1 + r2) - 3 * (r1 - r2) ** 2) / (12 * d)


print(f"{'r1 (cm)':>7} {'r2 (cm)':>7} {'d (cm)':>6} | {'V exact':>8} {'V ours':>8} {'error':>7} | "
      f"{'depth exact':>11} {'ours':>6} (cm)")
for r1, r2, d in [(0.05, 0.05, 0.07), (0.06, 0.03, 0.075), (0.04, 0.05, 0.06), (0.05, 0.04, 0.03)]:
    ball_1 = trimesh.creation.icosphere(subdivisions=4, radius=r1)  # the "body"
    ray = ball_1.vertices[0] / np.linalg.norm(ball_1.vertices[0])  # put the "object" on a vertex's ray
    ball_2 = apply_pose(ObjectPose(d * ray, np.eye(3)), trimesh.creation.icosphere(subdivisions=4, radius=r2))
    pen = interpenetration(ball_1, ball_2)
    v = lens_volume(r1, r2, d) * 1e6
    print(f"{r1 * 100:>7.0f} {r2 * 100:>7.0f} {d * 100:>6.1f} | {v:>8.2f} {pen.volume_cm3:>8.2f} "
          f"{(pen.volume_cm3 - v) / v:>+7.2%} | {(r2 - abs(d - r1)) * 100:>11.3f} {pen.depth_cm:>6.3f}")

# %% [markdown]
# The volume is a few tenths of a percent low, which is the icospheres' faceting, not the integration: against
# the exact boolean intersection of the same two meshes these volumes read +0.04 to +0.20 % high (the default refined
# ray casting; one ray per column, `refine=1`, reads −0.08 to +0.06 % on the same meshes, docs/objects.md).

# %% [markdown]
# ## 7 · Interaction-aware attention
#
# GOAL feeds its networks body-to-object distances, but a distance of 2 m at the knee says nothing about a grasp.
# Its **interaction-aware attention** (Sec. 3.2, Eq. 1) reweights each vertex's distance $d$ (metres) by
# $$I_w(d) = e^{-w d}, \qquad w = 5,$$
# so vertices near the object count most: 2 cm away → 0.90, 10 cm → 0.61, 50 cm → 0.08. GOAL Fig. 4 draws the
# body coloured by $I_w$; here is the same picture for the reaching body and the can (exact surface distances).

# %%
attention = body_object_attention(body_v, obj, w=IAA_WEIGHT).numpy()  # (V,)
goal = goal_vertices(bm)
rest = np.setdiff1d(np.arange(len(goal.vertex_ids)), goal.right_hand)
print(f"w = {IAA_WEIGHT}: attention on all vertices from {attention.min():.3f} to {attention.max():.3f}")
print(f"GOAL's 400 vertices: right hand (99) mean {attention[goal.vertex_ids[goal.right_hand]].mean():.3f}, "
      f"the other 301 mean {attention[goal.vertex_ids[rest]].mean():.3f}")

fig = plt.figure(figsize=(10.5, 3.8))
grid_spec = fig.add_gridspec(1, 5, width_ratios=[1, 1, 0.04, 0.5, 1.3], wspace=0.05)
arm = np.linalg.norm(body_v[body_f].mean(1) - centre, axis=1) < 0.35  # faces near the hand, for the close-up
for k, (faces, view, title) in enumerate([(body_f, (10, -90), "whole body"), (body_f[arm], (15, -30), "close-up")]):
    ax = fig.add_subplot(grid_spec[k], projection="3d", proj_type="ortho")
    viz.draw_meshes(ax, [(body_v, faces), (obj.vertices, obj.faces, "#f2c14e")], values=[attention, None],
                    cmap="coolwarm")
    viz.set_equal(ax, body_v[np.unique(faces)], obj.vertices, pad=0.0, zoom=1.1)
    ax.view_init(*view)
    ax.set_axis_off()
    ax.set_title(title, fontsize=9)
fig.colorbar(plt.cm.ScalarMappable(cmap="coolwarm"), cax=fig.add_subplot(grid_spec[2]), label=f"attention $e^{{-{IAA_WEIGHT:g}d}}$")
ax = fig.add_subplot(grid_spec[4])
d = np.linspace(0, 1, 200)
for w in (1.0, IAA_WEIGHT, 20.0):
    ax.plot(d, interaction_attention(torch.as_tensor(d), w=w).numpy(), lw=2.5 if w == IAA_WEIGHT else 1,
            label=f"w = {w:g}")
ax.set_xlabel("distance to the object d (m)")
ax.set_ylabel("attention $e^{-wd}$")
ax.legend(fontsize=8)
fig.subplots_adjust(left=0, right=0.98, bottom=0.15, top=0.97)

# %% [markdown]
# ## 8 · Explore: move the object around the hand
#
# `HandObjectExplorer` (in `graspkit/viz/object_explorer.py`) holds the scene above and recomputes, for any object
# position, the signed distance from the right hand to the object (negative once the hand is inside), the two
# contact maps and the penetration depth and volume. Its callback `update(name, value)` is plain Python, so here
# it is without any widget: the can pushed up into the palm (z > 0) and lowered away from it (z < 0).

# %%
explorer = HandObjectExplorer(body_v, body_f, obj_name, base=obj_pose, hand_ids=hand_vertices(bm, "right"),
                              marker_ids=markers.vertex_ids)
print(f"{'z (cm)':>6} | {'distance (cm)':>13} {'C_M':>4} {'C_O':>5} {'depth (cm)':>10} {'volume (cm³)':>12}")
for dz in (0.03, 0.01, 0.0, -0.01, -0.02):
    r = explorer.update("z", dz)
    print(f"{dz * 100:>+6.0f} | {r['min_distance_cm']:>+13.2f} {r['marker_contacts']:>4.0f} "
          f"{r['object_contacts']:>5.0f} {r['penetration_depth_cm']:>10.2f} {r['penetration_volume_cm3']:>12.2f}")
_ = explorer.update("z", 0.0)  # back to the touching pose

# %% [markdown]
# The widget wires sliders to the same callback and redraws the hand, the object, its contact points (red) and the
# markers in contact (green). Drag the sliders (in a live notebook; a static page shows only the controls).

# %%
explorer.widget()

# %% [markdown]
# ## Exercise
#
# 1. Rotate the mug by 90° about z (`ObjectPose.from_yaw(np.pi / 2, np.zeros(3))`, `apply_pose` on its surface
#    points) and compare its BPS
#    code with the unrotated one, using the distances of section 3 as a yardstick. Is the code rotation-invariant?
#    What must a network conditioned on $\mathbf{b}^o$ therefore see during training?
# 2. Rebuild the mug's grid with `SDFGrid.from_mesh(mug, resolution=128)` and re-run the numbers of section 4. How
#    do the median and maximum errors scale with the cell size, and why does the sign near the wall improve?
# 3. In the widget (or with `explorer.update`), find an object position with marker contacts but no object contacts.
#    What does that say about the two thresholds (2 cm vs 1 cm)? Then set `w = 20` in section 7: which body parts
#    still get attention, and what would GOAL's networks lose?
