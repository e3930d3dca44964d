# %% [markdown]
# # 01 · The body model, step by step
#
# SAGA, GOAL and WANDR all move an **SMPL-X** body (Pavlakos et al., CVPR 2019): a mesh of 10,475 vertices
# driven by shape coefficients $\beta$, facial expression $\psi$ and the rotations $\theta$ of 55 joints.
# GOAL §3.1 and WANDR §3.2 describe their inputs in SMPL-X terms; SAGA (§3.2, App. A.1) fits SMPL-X to markers.
# This lesson builds a body the way SMPL-X does, one stage at a time:
#
# $$T(\beta,\psi,\theta) = \bar T + B_S(\beta) + B_E(\psi) + B_P(\theta), \qquad J(\beta) = \mathcal{J}\,(\bar T + B_S(\beta) + B_E(\psi)),$$
# $$v_i = \sum_k w_{ik}\, G_k(\theta, J)\, G_k(0, J)^{-1}\, T_i \qquad \text{(linear blend skinning)}.$$
#
# graspkit's body is a **procedural humanoid** saved in the SMPL-X file format (the licensed model cannot be
# shipped): same keys, same array layouts, same joint order, the same landmark vertex ids. Everything below runs
# unchanged on a real `SMPLX_NEUTRAL.npz`.

# %%
%matplotlib inline
import matplotlib.pyplot as plt
import numpy as np
import torch

from graspkit import viz
from graspkit.body import JOINT_NAMES, PARENTS, BodyModel
from graspkit.body.model import load_model_arrays
from graspkit.paths import default_model_path
from graspkit.viz.explorers import canonical_to_world

torch.manual_seed(0)
arrays = load_model_arrays(default_model_path())
bm = BodyModel.from_file(default_model_path())
faces = bm.faces.numpy()
print(str(arrays["procedural"]))
for key in ("v_template", "f", "shapedirs", "posedirs", "J_regressor", "weights", "kintree_table", "hands_componentsl"):
    print(f"{key:18s} {str(arrays[key].shape):16s} {arrays[key].dtype}")

# %% [markdown]
# ## 1. The template $\bar T$
# The rest pose: arms out, palms down, y up, facing +z (SMPL-X's canonical frame). We draw it in the workbook's
# z-up world (a +90° turn about x, exactly what an AMASS `root_orient` of $(\pi/2, 0, 0)$ does).

# %%
v0 = arrays["v_template"]
print(f"stature {v0[:, 1].max() - v0[:, 1].min():.3f} m, arm span {v0[:, 0].max() - v0[:, 0].min():.3f} m")
fig = viz.show_scene(meshes=[(canonical_to_world(v0), faces)], views=("front", "side", "top"), size=3.2,
                     title="template mesh (10,475 vertices)")

# %% [markdown]
# ## 2. Shape blend shapes $B_S(\beta) = \sum_n \beta_n S_n$
# Each coefficient moves every vertex along a fixed direction. The procedural model's first components are
# stature, girth and proportions; $\beta$ is in units of standard deviations, as in SMPL-X.

# %%
def stature(betas: torch.Tensor) -> np.ndarray:
    """Stature (m) of bodies with the given betas (N, 10) in the rest pose."""
    with torch.no_grad():
        v = bm(betas=betas).vertices
    return (v[..., 1].amax(1) - v[..., 1].amin(1)).numpy()


b = torch.zeros(5, 10)
b[:, 0] = torch.tensor([-2.0, -1.0, 0.0, 1.0, 2.0])
print("stature for beta0 = -2..2:", np.round(stature(b), 3))
meshes = []
for k, (i, val) in enumerate([(0, -2), (0, 2), (1, -2), (1, 2)]):
    beta = torch.zeros(1, 10)
    beta[0, i] = val
    with torch.no_grad():
        v = canonical_to_world(bm(betas=beta).vertices[0].numpy())
    v[:, 0] += 1.9 * k
    meshes.append((v, faces))
fig = viz.show_scene(meshes=meshes, views=("front",), size=7, title="beta0 = -2, +2 (stature); beta1 = -2, +2")

# %% [markdown]
# ## 3. Joints from the shaped mesh: $J = \mathcal{J}\,T_{\text{shaped}}$
# The joint regressor $\mathcal{J}$ (55 × 10,475) averages vertices around each joint, so the skeleton follows the
# shape. graspkit folds $\mathcal{J}$ into the template and the shape basis once at load time
# ($J = \mathcal{J}\bar T + \beta\,(\mathcal{J} S)$), so a forward pass never touches the big matrix.

# %%
J = bm().joints[0].detach().numpy()
Jw, vw = canonical_to_world(J), canonical_to_world(v0)
bones = [(Jw[p], Jw[c] - Jw[p]) for c, p in enumerate(PARENTS) if p >= 0]
o, d = map(np.array, zip(*bones))
fig = viz.show_scene(meshes=[(vw, faces, (0.85, 0.85, 0.85))], arrows=(o, d), markers=Jw, views=("front",), size=5,
                     title="55 SMPL-X joints and the kinematic tree")
print("children of the right wrist:", [JOINT_NAMES[c] for c, p in enumerate(PARENTS) if p == 21][:5])

# %% [markdown]
# ## 4. Pose correctives $B_P(\theta) = \sum_k (R_k(\theta) - I)\,P_k$
# SMPL-X learns 486 corrective directions (9 entries of each of 54 joint rotations minus the identity) that fix
# skinning artefacts such as a collapsing elbow. The procedural humanoid computes its own: for elbows, knees
# and hips, graspkit poses the body's *implicit* (signed-distance) anatomy, fits the offset between
# where LBS puts each vertex and where the posed anatomy's surface is, and stores it as the linear corrective basis
# (`docs/body_model.md`). The term is one matrix product; switching it off shows what it does:

# %%
pose = torch.zeros(1, 63)
pose[0, 3 * 17 + 1] = -np.pi / 2  # left elbow (joint 18 -> index 17 of body_pose), bent 90 degrees
with torch.no_grad():
    with_c = bm(body_pose=pose).vertices
    plain = BodyModel({**arrays, "posedirs": np.zeros_like(arrays["posedirs"])})(body_pose=pose).vertices
print("the procedural model has pose correctives:", bm.has_posedirs)
print(f"at 90 deg of elbow flexion they move vertices by up to {(with_c - plain).norm(dim=-1).max().item() * 100:.2f} cm")

# %% [markdown]
# ## 5. Skinning weights and linear blend skinning
# Each vertex follows a weighted blend of its joints' rigid transforms. Below: vertices coloured by their dominant
# joint, and the same body in a few poses (`graspkit.body.poses`: every rotation is an axis-angle in the parent's
# rest frame).

# %%
part = arrays["weights"].argmax(1)
fig, axes = viz.figure(views=("front",), size=5, title="dominant skinning joint per vertex")
viz.draw_points(axes[0], vw, values=(part % 11) / 10, cmap="tab20", size=1.5, colorbar=False)  # colour: joint id mod 11
_ = viz.set_equal(axes[0], vw)

# %%
from graspkit.body.poses import POSES, body_pose, y_up_to_z_up

names = ["a_pose", "walk", "squat", "bend_pick", "reach_high"]
with torch.no_grad():
    out = bm(body_pose=torch.cat([body_pose(n) for n in names]), global_orient=y_up_to_z_up().expand(len(names), 3))
meshes = []
for k in range(len(names)):
    v = out.vertices[k].numpy().copy()
    v[:, 2] -= v[:, 2].min()
    v[:, 0] += 1.0 * k
    meshes.append((v, faces))
fig = viz.show_scene(meshes=meshes, views=("front",), size=8, title="  ·  ".join(names))

# %% [markdown]
# ### How well does it bend?
# Linear blend skinning loses volume where weights blend (the "candy wrapper" and the collapsing elbow). We bend
# the elbow and knee to 90° and measure the volume of the skin near the joint: the cones from the joint to every
# face within 12 cm (elbow) / 15 cm (knee) of it at rest, before and after, with and without the correctives.

# %%
from graspkit.body.skeleton import JOINT_INDEX

plain_bm = BodyModel({**arrays, "posedirs": np.zeros_like(arrays["posedirs"])})


def local_volume_change(model: BodyModel, joint: str, axis: tuple[float, float, float], radius: float) -> float:
    """Relative change of the cone volume (joint -> faces within `radius` m at rest) at 90 degrees about `axis`."""
    p = torch.zeros(1, 22, 3)
    p[0, JOINT_INDEX[joint]] = torch.tensor(axis) * np.pi / 2
    c = JOINT_INDEX[joint]
    with torch.no_grad():
        rest, bent = model(), model(body_pose=p[:, 1:].reshape(1, -1))
    near = (np.linalg.norm(rest.vertices[0].numpy() - rest.joints[0, c].numpy(), axis=1) < radius)[faces].all(1)

    def cone_volume(out) -> float:
        t = out.vertices[0].numpy()[faces[near]] - out.joints[0, c].numpy()
        return float(np.einsum("ij,ij->i", t[:, 0], np.cross(t[:, 1], t[:, 2])).sum() / 6)

    return cone_volume(bent) / cone_volume(rest) - 1


for joint, axis, radius in [("left_elbow", (0, -1, 0), 0.12), ("right_knee", (1, 0, 0), 0.15)]:
    print(f"{joint:11s} at 90 deg: local volume change {100 * local_volume_change(bm, joint, axis, radius):+5.1f} % "
          f"with correctives, {100 * local_volume_change(plain_bm, joint, axis, radius):+5.1f} % plain LBS")

# %%
with torch.no_grad():
    bent = [canonical_to_world(m(body_pose=pose).vertices[0].numpy()) for m in (plain_bm, bm)]
ew = canonical_to_world(J[JOINT_INDEX["left_elbow"]])
arm = faces[(np.linalg.norm(vw - ew, axis=1) < 0.2)[faces].all(1)]  # the skin around the elbow
fig, axes = viz.figure(views=("top", "top"), size=4.5, title="left elbow at 90 deg: plain LBS (left), with correctives (right)")
for ax, v in zip(axes, bent):
    viz.draw_mesh(ax, v, arm)
    viz.set_equal(ax, v[np.unique(arm)])

# %% [markdown]
# ## 6. Rotations in networks: 6D
# Files store axis-angle; LBS needs matrices; networks predict **6D** (Zhou et al. 2019): the first two columns of
# the rotation matrix, turned back into a rotation by Gram–Schmidt. GOAL (§3.1, $\theta \in \mathbb{R}^{55\times 6}$)
# and WANDR (§3.2, $p_i \in \mathbb{R}^{135}$) both use it, because it is continuous: nearby rotations have nearby
# codes, which is not true of axis-angle near $\pi$ or of quaternions' double cover.

# %%
from graspkit.rotations import axis_angle_to_matrix, matrix_to_axis_angle, matrix_to_rot6d, rot6d_to_matrix

angles = torch.linspace(0, 2 * np.pi, 400, dtype=torch.float64)
aa = torch.stack([torch.zeros_like(angles), torch.zeros_like(angles), angles], -1)
R = axis_angle_to_matrix(aa)
back_aa, six = matrix_to_axis_angle(R), matrix_to_rot6d(R)
fig, ax = plt.subplots(1, 2, figsize=(9, 2.6))
ax[0].plot(angles, back_aa[:, 2])
ax[0].set_title("axis-angle (z) of a rotation turning once: jumps at pi")
ax[0].set_ylabel("axis-angle z (rad)")
ax[1].plot(angles, six, label=[f"r{k + 1}" for k in range(6)])
ax[1].legend(fontsize=6, ncol=2, title="component (r1, r4 = cos; r2 = sin, r3 = r6 = 0)", title_fontsize=6)
ax[1].set_title("6D code of the same rotations: continuous")
ax[1].set_ylabel("6D components (unitless)")
for a in ax:
    a.set_xlabel("angle (rad)")
fig.tight_layout()
print("round trip error of 6D:", float((rot6d_to_matrix(six) - R).abs().max()))

# %% [markdown]
# ## 7. Markers and vertex sets
# SAGA represents a body by **143 markers** on its surface (App. A.1: 49 body, 14 face, 6 hand, 30 finger, 44 palm,
# after GRAB's mocap layout); its motion stage uses a sparse hand (10 fingertips instead of fingers and palms, 79 in
# all). GOAL samples **400 body vertices** with 99 on the right hand, and a head direction. graspkit places all of them
# by anatomical rules (`graspkit.body.markers`), so they fit any SMPL-X-format mesh. The layout depends on the file
# only: SAGA's markers are placed on the rest body with the mean (relaxed) hands, GOAL's vertices on flat hands, whether
# the model was built with `flat_hand_mean` or not.

# %%
from graspkit.body.markers import goal_vertices, saga_markers

m = saga_markers(bm)
print({g: b - a for g, (a, b) in m.groups.items()}, "total", len(m))
gv = goal_vertices(bm)
fig, axes = viz.figure(views=("front", "back"), size=4.2, title="SAGA's 143 markers (red) and GOAL's 400 vertices (blue)")
for ax in axes:
    viz.draw_mesh(ax, vw, faces, alpha=0.35)
    viz.draw_points(ax, vw[gv.vertex_ids], size=3, color="tab:blue")
    viz.draw_markers(ax, vw[m.vertex_ids], size=10, color="tab:red")
    viz.set_equal(ax, vw)

# %% [markdown]
# ## 8. Explore
# Move the sliders: the first three shape coefficients and a few joints. The callback logic lives in
# `graspkit.viz.explorers.BodyExplorer` (unit-tested); the widget only wires sliders to it.

# %%
from graspkit.viz.explorers import BodyExplorer

explorer = BodyExplorer(bm)
print(f"stature at the start: {explorer.stature():.3f} m")
explorer.widget()

# %% [markdown]
# ## Exercise
# 1. With `BodyExplorer.update("left_elbow", ...)` (radians; `update` takes angles past the slider's 1.6), find the
#    elbow angle at which the forearm first touches the upper arm. Hint: take the forearm and upper-arm vertices by
#    their dominant joint (`part` of section 5), leave out those within 6 cm of the elbow joint (they sit on the
#    crease and touch at any angle), and step the angle until the smallest distance between the two sets
#    (`graspkit.objects.nearest_neighbours`) falls under 5 mm. Vertex-to-vertex distances cannot see two surfaces
#    cross, so a small gap stands in for touching, and the answer moves with the exclusion radius: try 4 and 8 cm.
# 2. The GOAL vertex budget gives the right hand 99 of 400 vertices. Set `GOAL_BUDGET["right_hand"] = 20` (a dict in
#    `graspkit.body.markers`; `goal_vertices(bm)` reads it on every call, and the other parts keep theirs, so the total
#    falls to 321) and look at the picture: what would a network conditioned on these vertices lose?
