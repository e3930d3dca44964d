# %% [markdown]
# # 04 · Synthetic grasps: whole-body grasps with contact, and the approach that ends in one
#
# SAGA's WholeGrasp-VAE and GOAL's GNet learn **static whole-body grasps** with fine hand–object contact from GRAB;
# SAGA's MotionFill-VAE and GOAL's MNet learn the **approach** that ends in one. graspkit makes that data itself,
# on its procedural body and object catalogue, in GRAB's file layout. The grasps are the "ground truth" every grasp
# metric is compared with, so they have to be physically plausible: palm and fingers on the surface, nothing inside
# the object, both feet on the ground, the head towards the object.
#
# | step | module | what happens | paper |
# |---|---|---|---|
# | task | `graspkit.data.grasp` | object at SAGA's placement (0.5–1.7 m high, any yaw), a person 0.05–1.5 m away (at least the object's radius + 15 cm) facing it, a shape, a grasp type, a frame on a part | SAGA §4.3, GOAL §3 |
# | reach | `graspkit.data.plan_reach` | walk to a stand-off, wrist onto the frame's wrist target: feet on the floor, pelvis over them, gaze on the object | lesson 03 |
# | arm | `grasp_opt.solve_arm` | two-bone IK over 24 elbow swivels, forearm twist into the elbow: the hand also *turns* to the frame | — |
# | fingers | `grasp_opt.close_fingers` | each digit closes from the open pre-shape until it touches | "closed until contact" |
# | polish | `grasp_opt.polish` | Adam on the SMPL-X pose: collision, contact, anchor, head, coupling terms | after SAGA Eq. 6–7, GOAL Eq. 4–6 |
# | labels, files | `grasp_make`, `grab` | SAGA's C_M / C_O, GOAL's vertices, offsets, q, BPS; GRAB-style `.npz` + PLY | SAGA §3.2, GOAL Eq. 2, 9 |

# %%
%matplotlib inline
import matplotlib.pyplot as plt
import numpy as np
import torch

from graspkit import metrics as M
from graspkit import viz
from graspkit.body import BodyModel
from graspkit.body.markers import saga_markers
from graspkit.data.approach import approach_motion
from graspkit.data.grab import load_grasp_sequence, read_arrays
from graspkit.data.grasp import GRASP_PARTS, SPLITS, GraspFitter, grasp_candidates, grasp_types, sample_grasp_task
from graspkit.data.grasp_datasets import ApproachDataset, GNetDataset, WholeGraspDataset
from graspkit.data.motion import Motion
from graspkit.objects import ObjectPose, apply_pose, make_object
from graspkit.paths import DATA_STUBS, default_model_path
from graspkit.rotations import axis_angle_to_matrix

torch.set_num_threads(1)
plt.rcParams["figure.dpi"] = 72
bm = BodyModel.from_file(default_model_path())
faces = bm.faces.numpy()
fitter = GraspFitter(bm, steps=40)
hand_faces = faces[np.isin(faces, np.concatenate([fitter.hm.hand_ids, fitter.hm.arm_ids])).all(1)]


def body(poses, trans, betas):
    """Vertices (V,3) of one absolute SMPL-X pose (55,3)."""
    rot = axis_angle_to_matrix(torch.as_tensor(np.asarray(poses, np.float32)))[None]
    with torch.no_grad():
        return bm.forward_rotmats(rot, betas=torch.as_tensor(np.asarray(betas, np.float32))[None],
                                  transl=torch.as_tensor(np.asarray(trans, np.float32))[None]).vertices[0].numpy()


def closeup(ax, v, obj, values=None, half=0.11):
    """The hand and forearm of body v with the object mesh, framed around the object."""
    viz.draw_meshes(ax, [(v, hand_faces), (obj.vertices, obj.faces, viz.OBJECT)],
                    values=None if values is None else [values, None])
    c = obj.bounding_box.centroid
    viz.set_equal(ax, np.stack([c - half, c + half]), pad=0.0)


print("grasp types per object:", {n: grasp_types(n) for n in ("mug", "frying_pan", "pitcher", "power_drill", "bottle")})
print("splits:", {k: list(v) for k, v in SPLITS.items()})

# %% [markdown]
# ## 1 · Where a hand can go
#
# Each catalogue object lists its graspable **parts** (a cylinder, box, sphere) and the grasp types each allows:
# `power` (the hand wraps the part), `side` (the palm flat on a face), `pinch` (thumb and index pads on either side
# of a thin part), `handle` (a power grasp of a handle: mug, frying pan, pitcher, power drill). Frames are sampled
# on the parts — an anchor point, the direction the palm comes from, and an axis the thumb (power, handle), the
# fingers (side) or the pinch must follow — and kept only where they are on the real surface (exact signed
# distance). Here the mug's power frames (on the cup) and handle frames (outside the handle's bar):

# %%
mug = make_object("mug")
fig, axes = viz.figure(("front", "top"), size=3.4, title="mug: power frames (blue arrows) and handle frames (red)")
for ax in axes:
    viz.draw_meshes(ax, [(mug.vertices, mug.faces, viz.OBJECT)], alpha=0.5)
    for t, color in (("power", "#3b6ea8"), ("handle", "#c0504d")):
        c = grasp_candidates("mug", t)
        viz.draw_arrows(ax, c.p, 0.025 * c.s, color=color, linewidth=0.8)
    viz.set_equal(ax, mug.vertices, pad=0.03)
plt.show()

# %% [markdown]
# ## 2 · Fitting one grasp: the energy terms, before and after
#
# The planner puts the wrist where the palm must be; `solve_arm` also turns the hand onto the frame; the fingers
# close until they touch; then a short Adam **polish** of the SMPL-X pose (spine, neck, head, right arm, fingers —
# the legs keep the planner's stance, so the feet stay planted) minimises
#
# | term | what | from |
# |---|---|---|
# | $E_{colli}$ | $\sum_{b \in V^h_B} \max(-S(b, O), 0)^2$: hand/arm vertices inside the object (SDF grid) | after SAGA Eq. 7, 1st term (squared; the paper's is a hinge) |
# | $E_{colli,O}$ | object points inside the hand: $S(o, V^h_B)$ from the nearest hand vertex and its normal | after SAGA Eq. 7, 2nd term |
# | $E_{cont}$ | the closest vertex of each contact region (palm, five pads) on the surface | after SAGA Eq. 6 |
# | $E_{anchor}$, facing | palm centre on its target, palm normal against the surface normal | after GOAL Eq. 4 (offsets) |
# | $E_q$ | $1 - \cos(q, \text{object} - \text{head})$ | after GOAL Eq. 6 (whose target is GNet's predicted $\hat q$, an L1 norm) |
# | $E_\theta$ | squared change of every rotation from its initial value (the arm is freer) | after GOAL Eq. 5 (squared; the paper's norm is not) |
#
# (SAGA's foot–ground term $E^g_{cont}$ and GOAL's $E_f$, Eq. 7, hold by construction: the lower body is the
# planner's standing pose, both feet flat on $z = 0$.)
#
# What is minimised is the weighted **total** (black in the plot); the terms are drawn unweighted, and they trade
# against each other. The first steps overshoot (Adam's first moves are a full learning rate in every coordinate),
# then the total settles several times below where it started. Along the way the polish brings the contact regions
# (thumb, palm) onto the surface and pays for it with a little penetration, so $E_{colli}$ and the printed volume
# and depth can end higher than after closing the fingers: compare the two lines printed under the figure.

# %%
task = sample_grasp_task(np.random.default_rng(3), "mug", grasp_type="handle",
                         object_pose=ObjectPose.from_yaw(2.2, (0.1, -0.8, 1.05)))
[closed] = fitter.fit([task], polish_steps=0)
history = []
[res] = fitter.fit([task], history=history)
fitter.evaluate([closed, res])
obj = apply_pose(task.object_pose, mug)
stages = [("planned reach, open hand", res.init_poses), ("fingers closed", closed.poses), ("polished", res.poses)]
fig = plt.figure(figsize=(11, 3.6))
for k, (title, pose) in enumerate(stages):
    ax = fig.add_subplot(1, 4, k + 1, projection="3d")
    ax.view_init(*viz.scene.view_angles("top"))
    closeup(ax, body(pose, res.trans, res.betas), obj)
    ax.set_axis_off(); ax.set_title(title, fontsize=9)
ax = fig.add_subplot(1, 4, 4)
ax.semilogy([h["total"] for h in history], color="k", lw=2, label="total (weighted)")
for key in ("colli", "colli_obj", "contact", "anchor", "prior"):
    ax.semilogy([max(h[key], 1e-3) for h in history], label=key)
ax.set_xlabel("Adam step"); ax.set_ylabel("energy"); ax.set_title("energy: total and terms (unweighted)", fontsize=9); ax.legend(fontsize=7)
plt.tight_layout(); plt.show()
for name, r in (("closed", closed), ("polished", res)):
    q = r.quality
    print(f"{name:9s} contact {q['min_distance'] * 1000:5.1f} mm, volume {q['volume_cm3']:.2f} cm3, depth {q['depth_cm']:.2f} cm,"
          f" regions (palm, thumb, index, middle, ring, pinky) {np.round(q['regions_mm'], 1)} mm")

# %% [markdown]
# ## 3 · Contact maps on the hand and on the object (SAGA Fig. 3)
#
# SAGA's WholeGrasp-VAE learns, with the markers, two binary contact maps: $C_M$ on the 143 markers (within 2 cm
# of the object surface) and $C_O$ on the 2048 object points (within 1 cm of the body surface). Both are stored in
# every file. Left: the hand coloured by closeness to the object, markers in contact in green; right: the object
# points coloured by $C_O$. (A shipped sample file, `data_stubs/grasps/`.)

# %%
files = sorted((DATA_STUBS / "grasps").glob("grasp_*.npz"))
seq = load_grasp_sequence(files[0])
a = read_arrays(files[0])
v = body(seq.poses[0], seq.trans[0], seq.betas)
R = seq.object_rotation()[0]
o = apply_pose(ObjectPose(seq.object_transl[0], R), make_object(seq.object_name))
d = M.grasp_contact_distance(v[fitter.hm.hand_ids], o)
from graspkit.objects import point_mesh_distance  # noqa: E402

dist = point_mesh_distance(torch.as_tensor(v), o).distance.numpy()
closeness = np.clip(1 - dist / 0.01, 0, 1)
markers = a["saga.markers"]
cm = a["contact.markers"][0].astype(bool)
pts = a["object.points"] @ R.T + seq.object_transl[0]
fig = plt.figure(figsize=(9, 4))
ax = fig.add_subplot(1, 2, 1, projection="3d")
closeup(ax, v, o, values=closeness)
viz.draw_markers(ax, markers[cm], color="#2ca02c")
ax.set_axis_off(); ax.set_title(f"{seq.object_name}: hand contact, C_M (green, {cm.sum()} of 143)", fontsize=9)
cb = fig.colorbar(plt.cm.ScalarMappable(plt.Normalize(0, 1), plt.get_cmap(viz.CONTACT_CMAP)), ax=ax, shrink=0.6,
                  pad=0.02)
cb.set_label("closeness 1 − d / 1 cm", fontsize=8)
ax = fig.add_subplot(1, 2, 2, projection="3d")
viz.draw_points(ax, pts, a["contact.object"][0].astype(float), size=4)
viz.set_equal(ax, pts, pad=0.01); ax.set_axis_off()
ax.set_title(f"C_O: {a['contact.object'][0].sum()} of 2048 object points in contact", fontsize=9)
plt.show()

# %% [markdown]
# ## 4 · Diversity at one placement
#
# For one object placement, grasps differ in the person's shape, where they come from (the start is anywhere
# 0.05–1.5 m away, and at least the object's radius + 15 cm, facing the object), the grasp type and the frame. SAGA measures diversity with the **APD**
# (average pairwise L2 distance of samples, after DLow): here over the 143 markers of five grasps of the same mug
# at the same placement, centred at the object.

# %%
pose = ObjectPose.from_yaw(0.8, (0.0, -0.9, 1.0))
rng = np.random.default_rng(11)
fast = GraspFitter(bm, steps=20)
tasks = [sample_grasp_task(rng, "mug", object_pose=pose) for _ in range(5)]
res6 = fast.fit(tasks)
fast.evaluate(res6)
V6 = fast.vertices(res6).numpy()
ms = saga_markers(bm).select(torch.as_tensor(V6)).numpy() - pose.translation
print(f"APD of the markers over {len(res6)} grasps: {M.apd(ms):.2f} m (the person may come from any side here; SAGA Tab. 1 "
      "reports 2.92-2.94 for WholeGrasp samples, 0.33 for GrabNet-SMPLX)")
print("types:", [r.task.grasp_type for r in res6], "| contact:", [bool(r.quality["contact"]) for r in res6])
omesh = apply_pose(pose, mug)
colors = plt.get_cmap("tab10").colors
fig, axes = viz.figure(("top", (25, -100), (60, -100)), size=3.8, title="five grasps of one placement (one colour each)")
for ax in axes[:2]:
    viz.draw_meshes(ax, [(v, faces, colors[k]) for k, v in enumerate(V6)] + [(omesh.vertices, omesh.faces, viz.OBJECT)])
    viz.set_equal(ax, np.concatenate([v[::10] for v in V6]), pad=0.02)
centre = omesh.vertices.mean(0)                  # the close-up keeps only faces near the mug, or the bodies hide it
near = [(v, faces[np.linalg.norm(v[faces].mean(1) - centre, axis=1) < 0.13], colors[k]) for k, v in enumerate(V6)]
viz.draw_meshes(axes[2], near + [(omesh.vertices, omesh.faces, viz.OBJECT)])
viz.set_equal(axes[2], omesh.vertices, pad=0.06)
axes[2].set_title("close-up: the mug and the body within 13 cm of it", fontsize=9)
plt.show()

# %% [markdown]
# ## 5 · Approach and grasp
#
# The grasp is the end of a reach plan, so the approach comes with it: the person starts 0.05–1.5 m away (at least the object's radius + 15 cm; GRAB's
# T-pose or an idle stance), walks, reaches; half a second before the grasp frame the upper body turns into the
# fitted pose, the fingers take the pre-shape and close, and the grasp is held to the end (GOAL's *goal frame* is
# the first held frame). The lower body is the planner's, so foot contacts and skating are those of the motion
# data. A shipped approach clip, every third frame and the last:

# %%
afile = sorted((DATA_STUBS / "approach").glob("approach_*.npz"))[0]
aseq = load_grasp_sequence(afile)
clip = Motion(aseq.poses, aseq.trans, aseq.betas, aseq.fps, contacts=aseq.contacts["feet"].astype(bool))
g = int(aseq.extras["grasp.goal_frame"])
ao = apply_pose(ObjectPose(aseq.object_transl[0], aseq.object_rotation()[0]), make_object(aseq.object_name))
verts = clip.vertices(bm).numpy()
q = M.motion_quality(bm, [clip])
print(f"{aseq.num_frames} frames, goal frame {g}, start: {aseq.extras['grasp.start_pose']}; FS (WANDR) "
      f"{100 * q['fs_wandr']:.1f} %, GOAL sliding {100 * q['slide_goal']:.1f} %, ground penetration max "
      f"{100 * q['penetration_max']:.2f} cm")
fig, ax = plt.subplots(figsize=(7, 1.6))
ax.imshow(clip.contacts.T, aspect="auto", cmap="Greys", interpolation="nearest")
ax.axvline(g, color="#c0504d"); ax.set_yticks(range(4), ["l heel", "l toe", "r heel", "r toe"], fontsize=7)
ax.set_xlabel("frame (red: goal frame)"); ax.set_title("foot contact labels (black: in contact)", fontsize=9)
plt.show()

# %%
# NBVAL_IGNORE_OUTPUT
anim = viz.animate(verts, faces, objects=[(ao.vertices, ao.faces)], views=("side", "top"), stride=3, max_frames=36,
                   size=2.4, title=f"{aseq.object_name}: approach and grasp")
viz.show_animation(anim)

# %% [markdown]
# ## 6 · Files and datasets
#
# Each file is GRAB's tree without pickle (`body.params.*`, `object.params.*`, `contact.*`, ...) plus graspkit's
# labels (`saga.*`, `goal.*`, `grasp.*`); the object's PLY lies beside it, so the `smplx` package and `trimesh`
# alone rebuild the scene (tested). The torch datasets read them; splits are by object (GRAB's, as SAGA uses it).

# %%
for k in ("body.params.fullpose", "body.betas", "object.params.transl", "object.points", "contact.object",
          "contact.markers", "saga.markers", "goal.vertices", "goal.offsets", "goal.hand_offsets", "goal.head_direction",
          "goal.bps_object", "object.height", "grasp.type"):
    print(f"{k:24s} {str(a[k].shape):12s} {a[k].dtype}")
wg = WholeGraspDataset(DATA_STUBS / "grasps", split=None)
gn = GNetDataset(DATA_STUBS / "grasps", split=None)
ap = ApproachDataset(DATA_STUBS / "approach", split=None, bm=bm)
for ds in (wg, gn, ap):
    print(type(ds).__name__, len(ds), {k: tuple(t.shape) for k, t in list(ds[0].items())[:6]})

# %% [markdown]
# ## 7 · Quality, measured with `graspkit.metrics`
#
# Contact ratio (SAGA §4.1, GOAL Tab. 1; the body within 2 mm of the object, graspkit's threshold: neither paper gives
# one), interpenetration volume and depth (exact ray casting and signed distance), the feet's distance to the floor —
# here over the shipped samples; the table over 272 grasps of all 17 objects is in docs/grasps.md (GRAB's captured
# grasps, GOAL Tab. 1: 1.95 cm³; SAGA Tab. 2's ground-truth meshes: contact 0.99, 2.04 cm³, 0.45 cm).

# %%
part = bm.lbs_weights.argmax(1).numpy()
feet = [np.flatnonzero(np.isin(part, js)) for js in ((7, 10), (8, 11))]   # left / right ankle + foot vertices
rows = []
for f in files:
    s = load_grasp_sequence(f)
    vb = body(s.poses[0], s.trans[0], s.betas)
    ob = apply_pose(ObjectPose(s.object_transl[0], s.object_rotation()[0]), make_object(s.object_name))
    r = M.grasp_metrics(vb, faces, ob)
    r["feet_cm"] = 100 * max(abs(vb[ids, 2].min()) for ids in feet)              # the higher of the two feet
    rows.append(r)
t = M.grasp_quality_table(rows)
print(f"{t['grasps']} grasps: contact ratio {t['contact_ratio']:.2f}, volume mean {t['volume_mean_cm3']:.2f} cm3 "
      f"(max {t['volume_max_cm3']:.2f}), depth mean {t['depth_mean_cm']:.2f} cm (max {t['depth_max_cm']:.2f}), "
      f"feet within 1 cm {100 * t['feet_within_1cm']:.0f} %")

# %% [markdown]
# ## Exercise
# 1. The papers give no contact threshold; graspkit uses 2 mm (`GRASP_CONTACT_THRESHOLD`). Recompute the table of
#    section 7 with `M.grasp_metrics(vb, faces, ob, threshold=...)` (in metres: 0.5 mm is `threshold=0.0005`) at 10,
#    1, 0.5 and 0.1 mm: how low must the threshold go before the contact ratio falls, why does a grasp that penetrates
#    the object count as contact at any threshold, and what does that say about how tightly the synthetic hands close?
# 2. Each grasp's volume comes from fingertips sinking a little into the object. Take the grasp with the largest
#    volume and draw the body vertices inside the object (`graspkit.objects.signed_distance(vb, ob) < 0`): which
#    fingers are they on, and would the hand have to open or close by a millimetre or two to remove them?
# 3. GOAL Tab. 1 reports GRAB's captured grasps at 1.95 cm³ and SAGA Tab. 2 at 2.04 cm³; the synthetic grasps are
#    far shallower. Which of graspkit's two penetration targets (set in its issues, after the papers' figures, not by
#    the papers: GOAL's relative "≤ 1.15× the ground truth", docs/goal.md, against SAGA's absolute ≤ 0.5 cm³) becomes
#    harder to meet because of that?
