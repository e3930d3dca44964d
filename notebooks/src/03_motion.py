# %% [markdown]
# # 03 · Procedural motion: walking, reaching, and the data every motion model learns from
#
# WANDR learns navigation from **AMASS** (goal-less motion: walking, turning, starting, stopping) and reaching from
# **CIRCLE** (short clips that end with a hand on a target), WANDR §3.1 and §4.1. SAGA pre-trains its motion infilling
# on AMASS (App. A.3). Neither dataset can be shipped, so graspkit **generates** the equivalent with its own body
# model — and everything learnt later can only be as natural as this data. It has to move like a person: feet planted
# while they carry weight, nothing through the floor, smooth, human timing, bending and stretching to reach.
#
# | stage | module | idea |
# |---|---|---|
# | root plan | `graspkit.data.trajectory` | smoothed speed / turn controls, integrated: where the body goes |
# | footsteps | `graspkit.data.footsteps` | a foot steps when its footprint drifts too far from where it stands; cadence from speed |
# | foot motion, contacts | `graspkit.data.footsteps` | heel rocker, flat foot, heel rise about the ball, swing; labels from the same phases |
# | whole body | `graspkit.data.posing` | pelvis sway and bob, two-bone leg IK, counter-rotating spine, arm swing, gaze |
# | reaching | `graspkit.data.reaching` | posture family (bend, squat, stretch), stand-off, right-arm IK timed to $t_G$ |
# | files | `graspkit.data.formats` | AMASS-style `.npz` (z up, 30 fps) and CIRCLE-style clips with goal, goal frame, hand |
#
# The metrics come from the papers (`graspkit.metrics`): WANDR's foot skating, SAGA's skating, GOAL's sliding.

# %%
%matplotlib inline
import matplotlib.pyplot as plt
import numpy as np
import torch
from scipy.spatial import ConvexHull

from graspkit import metrics as M
from graspkit import viz
from graspkit.body import BodyModel
from graspkit.body.skeleton import JOINT_INDEX
from graspkit.data import Start, generate_locomotion, generate_reach, load_motion, plan_reach, save_motion
from graspkit.data.footsteps import GaitStyle, foot_tracks, plan_footsteps
from graspkit.data.ik import two_bone_ik
from graspkit.data.motion import Motion, heading_of
from graspkit.data.posing import Style, pose_body
from graspkit.data.rig import build_rig
from graspkit.data.trajectory import integrate_controls, smooth_controls
from graspkit.paths import default_model_path

torch.set_num_threads(1)
plt.rcParams["figure.dpi"] = 72
bm = BodyModel.from_file(default_model_path())
faces = bm.faces.numpy()
rig = build_rig(bm)
print(f"body {rig.height:.2f} m, leg {rig.leg_length:.3f} m, arm {rig.arm_length:.3f} m, pelvis {rig.pelvis_height:.3f} m")

# %% [markdown]
# ## 1 · A root plan and its footsteps, seen from above
#
# A walk is planned as controls — forward speed, sideways speed, turning rate — smoothed (people take about a second
# to reach speed or stop) and integrated. Here: stand, accelerate to 1.2 m/s, curve left, slow down, stop.
# Footsteps follow one rule (as a walking controller): a foot steps when the footprint it would need a little later
# (where the root will be half a step after landing, half a stance width to its side) is more than 5 cm or 9° away
# from where it stands. Cadence follows speed; step length = speed / cadence.

# %%
T, fps = 210, 30.0
v = np.r_[np.zeros(25), np.full(125, 1.2), np.zeros(60)]
turn = np.r_[np.zeros(70), np.full(60, 0.55), np.zeros(80)]
plan = integrate_controls(smooth_controls(v, 0.3), np.zeros(T), smooth_controls(turn * v, 0.15))
gait, style = GaitStyle(), Style()
steps = plan_footsteps(plan, rig, gait)
tracks = foot_tracks(steps, plan, rig, gait)
aa, root, extra = pose_body(rig, plan, tracks, style)
walk = Motion(aa, root - rig.joints[0], np.zeros(10), contacts=tracks.contacts)
print(f"{len(steps)} steps; first lifts at {steps[0].t_lift:.2f} s, last lands at {steps[-1].t_land:.2f} s")

fig, (ax, ax2) = plt.subplots(1, 2, figsize=(11, 4.2), gridspec_kw={"width_ratios": [1.6, 1]})
sole = {s: rig.feet[s].sole for s in ("left", "right")}
for st in steps:
    side = ("left", "right")[st.side]
    R = np.array([[np.cos(st.yaw), -np.sin(st.yaw)], [np.sin(st.yaw), np.cos(st.yaw)]])
    pts = (sole[side][:, [2, 0]] - rig.feet[side].ref[[2, 0]]) @ R.T + st.xy   # canonical (z fwd, x left) -> world
    ax.fill(*pts[ConvexHull(pts).vertices].T, color="#3b6ea8" if st.side == 0 else "#c0504d", alpha=0.6)
    ax.annotate(f"{st.t_land:.1f}", st.xy, fontsize=7, ha="center", va="bottom" if st.side == 0 else "top",
                xytext=(0, 7 if st.side == 0 else -7), textcoords="offset points")
ax.plot(*plan.xy.T, "k-", lw=1, label="root plan")
ax.plot(*root[:, :2].T, color="#6a3d9a", lw=1, label="pelvis (with sway)")
ax.set_aspect("equal"); ax.legend(fontsize=8); ax.set_title("footprints (blue left, red right; landing time in s)")
ax.set_xlabel("x (m)"); ax.set_ylabel("y (m)")
speeds = np.linspace(0.5, 1.6, 12)
f = gait.cadence(speeds)
ax2.plot(speeds, f, "o-", label="cadence (steps/s)")
ax2.plot(speeds, speeds / f, "s-", label="step length (m)")
ax2.set_xlabel("speed (m/s)"); ax2.legend(fontsize=8); ax2.set_title("gait from speed")
fig.tight_layout()

# %% [markdown]
# ## 2 · Feet: four phases, exact contact labels
#
# Each foot is a rigid ankle segment plus a toe segment. It lands toes-up and rotates down about the **heel point**
# (heel rocker: the heel does not move), stays **flat**, then rotates heels-up about the **ball joint** while the toes
# stay flat (heel rise), then **swings** on Hermite curves with a clearance bump checked on sole points. The contact
# labels (left heel, left toe, right heel, right toe) come from the same phases. The pelvis shifts towards the
# stance foot (sway) and is lowest in double support (bob): it is held as high as both legs can reach.

# %%
t = np.arange(T) / fps
fig, axs = plt.subplots(3, 1, figsize=(10, 5.6), sharex=True)
for k, (name, c) in enumerate(zip(("left heel", "left toe", "right heel", "right toe"), ("#3b6ea8", "#7ea6d8", "#c0504d", "#e39a98"))):
    axs[0].fill_between(t, k, k + 0.8 * tracks.contacts[:, k], color=c, step="mid", label=name)
axs[0].set_yticks([]); axs[0].legend(ncol=4, fontsize=7, loc="upper right"); axs[0].set_title("contact labels")
axs[1].plot(t, tracks.ankle[0, :, 2], color="#3b6ea8", label="left ankle height")
axs[1].plot(t, tracks.ankle[1, :, 2], color="#c0504d", label="right ankle height")
axs[1].legend(fontsize=7); axs[1].set_ylabel("m")
axs[2].plot(t, root[:, 2], "k", label="pelvis height (bob)")
left = np.stack([-np.sin(plan.heading), np.cos(plan.heading)], 1)
axs[2].plot(t, 0.85 + 2 * ((root[:, :2] - plan.xy) * left).sum(1), color="#6a3d9a", label="0.85 + 2 x sideways pelvis offset (sway)")
axs[2].legend(fontsize=7); axs[2].set_xlabel("time (s)")
fig.tight_layout()

# %% [markdown]
# ## 3 · Two-bone leg IK
#
# Given the hip and the planned ankle, the knee is found in closed form (`graspkit.data.ik.two_bone_ik`): the law of
# cosines gives the angle at the hip, the **pole** (the direction the knee should point: over the toes) picks the plane.
# Each bone's global rotation maps its rest frame (bone, bend direction) onto the solved one, so the knee's local
# rotation is a pure hinge. Below: one hip, five ankle targets, the pole forward (+x).

# %%
b1, b2 = rig.bone("left_hip", "left_knee"), rig.bone("left_knee", "left_ankle")
l1, l2 = np.linalg.norm(b1), np.linalg.norm(b2)
hip = np.array([0.0, 0.0, 0.85])
fig, ax = plt.subplots(figsize=(5, 4))
for k, (x, z) in enumerate([(0.0, 0.1), (0.2, 0.12), (-0.25, 0.15), (0.1, 0.45), (0.35, 0.35)]):
    target = np.array([x, 0.0, z])
    R1, R2, knee = two_bone_ik(hip, target, np.array([1.0, 0, 0]), b1, b2, np.array([0, 0, 1.0]))
    ax.plot([hip[0], knee[0], target[0]], [hip[2], knee[2], target[2]], "o-", color=plt.cm.viridis(k / 5))
    print(f"target {target[[0, 2]]}: knee flexion {np.degrees(np.arccos(np.clip(((knee - hip) @ (target - knee)) / (l1 * l2), -1, 1))):5.1f} deg,"
          f" ankle on target: {np.linalg.norm(knee + R2 @ b2 - target) < 1e-9}")
ax.plot(*hip[[0, 2]], "ks", ms=9)
ax.set_aspect("equal"); ax.set_xlabel("forward (m)"); ax.set_ylabel("up (m)"); ax.set_title("hip (square), knee, ankle targets")
fig.tight_layout()

# %% [markdown]
# ## 4 · The walk, animated
#
# Arms swing in counter-phase with the legs (elbows bend on the forward swing), the thorax counter-rotates against
# the pelvis, the head looks along the path. (Every 5th frame is drawn, and the last.)

# %%
# NBVAL_IGNORE_OUTPUT
walk_vertices = walk.vertices(bm).numpy()
anim = viz.animate(walk_vertices, faces, views=("side", "top"), stride=5, max_frames=42, size=2.4,
                   paths=[np.c_[plan.xy, np.zeros(T)]], title="curved walk")
viz.show_animation(anim)

# %% [markdown]
# ## 5 · Reaching low, middle and high goals
#
# `plan_reach(start, goal, t_goal_frames, betas, seed)` is graspkit's **procedural planner**: walk to a stand-off point,
# turn to face the goal, slow down, and bring the right wrist onto the goal exactly at frame $t_G$ (WANDR's time
# control, §3.2). The posture comes from a one-parameter family: stretch (collar up, spine extended) for high goals,
# bend the trunk and knees, then squat and stoop, for low ones; the level is the smallest one from which the
# shoulder reaches the goal. Floor goals put the hand flat on the floor, the wrist 7 cm above it.

# %%
goals = {"low (0.05 m)": (1.5, -0.6, 0.05), "middle (1.0 m)": (1.6, 0.2, 1.0), "high (1.75 m)": (1.3, 0.9, 1.75)}
reaches = {k: plan_reach(Start(0, 0, 0), g, 90, seed=1, bm=bm, hold_frames=0) for k, g in goals.items()}
fig, axes = plt.subplots(1, 3, figsize=(11, 4), subplot_kw={"projection": "3d", "proj_type": "ortho"})
for ax, (name, m) in zip(axes, reaches.items()):
    vv = m.vertices(bm, 90, 91).numpy()[0]
    ax.view_init(8, -70); ax.set_axis_off()
    viz.draw_mesh(ax, vv, faces)
    viz.draw_goal(ax, m.goal, radius=0.04)
    w = m.joint_positions(bm)[90, JOINT_INDEX["right_wrist"]]
    viz.set_equal(ax, vv, m.goal[None])
    ax.set_title(f"{name}: wrist {100 * np.linalg.norm(w - m.goal):.1f} cm from the goal", fontsize=9)
fig.tight_layout()

# %% [markdown]
# **Time control.** The same goal, asked for at different frames: the person waits, walks and reaches so that the
# wrist arrives just then, slowing down onto the goal (WANDR Sup. C.1).

# %%
fig, ax = plt.subplots(figsize=(7, 3))
goal = np.array([2.5, 0.8, 1.2])
for t_goal in (75, 120, 180):
    m = plan_reach(Start(0, 0, 0), goal, t_goal, seed=0, bm=bm, hold_frames=20)
    d = np.linalg.norm(m.joint_positions(bm)[:, JOINT_INDEX["right_wrist"]] - goal, axis=1)
    ax.plot(np.arange(m.num_frames) / fps, d, label=f"$t_G$ = {t_goal / fps:.1f} s (error at $t_G$: {100 * d[t_goal]:.2f} cm)")
    ax.axvline(t_goal / fps, color="0.8", lw=0.8)
ax.set_xlabel("time (s)"); ax.set_ylabel("wrist to goal (m)"); ax.legend(fontsize=8)
fig.tight_layout()

# %% [markdown]
# ## 6 · The planner on WANDR's evaluation grid
#
# WANDR §4.2 evaluates on goals around the start: 5 angles 72° apart × 5 heights 0–1.8 m × 5 distances 0.5–5 m,
# 8 s each; success = the right wrist within 10 cm (SR), DTG = its closest distance. Here one slice, the goals
# 144° away (behind and to the left): every one needs a turn first. The full grid and its table are in `docs/data.md`
# (`python benchmarks/motion_throughput.py --grid`).

# %%
from graspkit.data.reaching import EVAL_DISTANCES, EVAL_HEIGHTS, evaluation_goals

grid = evaluation_goals()
slice_ = grid[grid[:, 0] == 144.0]
dtg = np.zeros((5, 5))
for a, h, d, x, y in slice_:
    m = plan_reach(Start(), (x, y, h), 239, seed=0, bm=bm, hold_frames=0)
    dtg[EVAL_HEIGHTS.index(h), EVAL_DISTANCES.index(d)] = M.distance_to_goal(m.joint_positions(bm)[:, JOINT_INDEX["right_wrist"]], (x, y, h))
print("DTG (cm), rows: height (m), columns: distance (m)")
print("        " + "".join(f"{d:8.3g}" for d in EVAL_DISTANCES))
for i, h in enumerate(EVAL_HEIGHTS):
    print(f"{h:6.2f}  " + "".join(f"{100 * x:8.1f}" for x in dtg[i]))
print(f"success rate on this slice: {100 * np.mean(dtg <= M.WANDR_SUCCESS_RADIUS):.0f} %")

# %% [markdown]
# ## 7 · The training data: what WANDR would see
#
# Two kinds of clips, as WANDR's premise asks (`graspkit data make --kind {locomotion,reach}`):
# **AMASS-style** locomotion without goals (speeds 0.5–1.6 m/s, curves, turns in place, side steps, starts, stops,
# idling; 4–10 s) and **CIRCLE-style** reaching (a few short steps at most, then a right-hand reach; goal, goal frame and
# hand stored). Below, as WANDR's Fig. S.4: the training goals in cylindrical coordinates around the start pose
# (distance, angle from the facing direction, height) — CIRCLE-style goals and AMASS-style *hindsight* goals
# (the wrist at a random future frame up to 8 s ahead, WANDR §3.2, drawn as the training windows draw them:
# `HINDSIGHT_HORIZON`, capped by the clip's end) — with the evaluation goals as ×. Only the default reach tasks are
# drawn; the room-scale sets (reach_far, reach_near, reach_chain: docs/data.md) add goals out to 5 m. Like WANDR's,
# many evaluation goals lie where this training data is thin.

# %%
from graspkit.data.reaching import sample_reach_task
from graspkit.data.wandr_dataset import HINDSIGHT_HORIZON


def cylindrical(goal, start_xy, heading):
    """(distance, angle in degrees from the facing direction, height) of goals (N,3) around a start."""
    d = goal[:, :2] - start_xy
    ang = np.degrees(np.angle(np.exp(1j * (np.arctan2(d[:, 1], d[:, 0]) - heading)))) % 360
    return np.stack([np.linalg.norm(d, axis=1), ang, goal[:, 2]], 1)


tasks = [sample_reach_task(np.random.default_rng(s)) for s in range(600)]
circle = np.concatenate([cylindrical(t.goal[None], np.array([t.start.x, t.start.y]), t.start.heading) for t in tasks])
rng = np.random.default_rng(0)
hindsight = []
for s in range(12):
    m = generate_locomotion(1000 + s, bm)
    j = m.joint_positions(bm)
    h = heading_of(m.poses[:, 0])
    for _ in range(25):
        i = int(rng.integers(0, m.num_frames - 2))
        tg = i + int(rng.integers(1, min(HINDSIGHT_HORIZON, m.num_frames - 1 - i) + 1))   # the dataset's rule
        hindsight.append(cylindrical(j[tg, JOINT_INDEX["right_wrist"]][None], j[i, 0, :2], h[i])[0])
hindsight = np.array(hindsight)
evalg = np.stack([grid[:, 2], grid[:, 0], grid[:, 1]], 1)
names = ["distance (m)", "angle (deg)", "height (m)"]
fig, axes = plt.subplots(1, 3, figsize=(12, 3.6))
for ax, (i, j) in zip(axes, [(0, 1), (0, 2), (1, 2)]):
    *_, im = ax.hist2d(np.r_[circle[:, i], hindsight[:, i]], np.r_[circle[:, j], hindsight[:, j]], bins=30,
                       cmap="Blues", range=[[0, 5.2] if i == 0 else [0, 360], [0, 360] if j == 1 else [0, 1.9]])
    fig.colorbar(im, ax=ax, pad=0.02).set_label("goals per bin", fontsize=8)
    ax.scatter(evalg[:, i], evalg[:, j], marker="x", color="#d62728", s=18)
    ax.set_xlabel(names[i]); ax.set_ylabel(names[j])
fig.suptitle("training goals (density: CIRCLE-style goals + AMASS-style hindsight goals) and WANDR's evaluation goals (x)")
fig.tight_layout()

# %% [markdown]
# ## 8 · Is it skating? The metrics on the meshes
#
# WANDR counts a frame as foot skating when the mesh's **lowest vertex** moves more than 0.66 cm to the next frame
# (the paper's words; graspkit measures the move horizontally, as the authors' evaluation code does, `docs/wandr.md`);
# GOAL counts "sliding" above 1 cm per frame (GRAB's captured motion: 6.7 %); SAGA counts frames where
# both heels are within 5 cm of the ground and both move faster than 75 mm/s. The histogram shows the lowest
# vertex's motion per frame over a few clips of each kind. None of these looks above the feet: graspkit also reports
# how fast any joint's rotation turns (a head that snapped round in one frame once passed every foot metric).

# %%
clips = [generate_locomotion(s, bm) for s in range(5)] + [generate_reach(s, bm) for s in range(5)]
moves = np.concatenate([M.lowest_vertex_motion(c.vertices(bm))[0] for c in clips])
q = M.motion_quality(bm, clips)
fig, ax = plt.subplots(figsize=(7, 3))
ax.hist(100 * moves, bins=np.linspace(0, 1.2, 49), color="#3b6ea8")
ax.axvline(100 * M.WANDR_SKATE_THRESHOLD, color="#d62728", label="WANDR threshold 0.66 cm")
ax.set_yscale("log"); ax.set_ylabel("frame pairs"); ax.set_xlabel("lowest vertex, horizontal motion per frame (cm)"); ax.legend(fontsize=8)
fig.tight_layout()
print(f"{q['clips']} clips, {q['frames']} frames: FS (WANDR) {100 * q['fs_wandr']:.2f} %, SAGA skating "
      f"{100 * q['skate_saga']:.2f} %, GOAL sliding {100 * q['slide_goal']:.2f} %, max penetration "
      f"{100 * q['penetration_max']:.2f} cm, joint-limit violations {q['joint_limit_max']:.1f} deg, fastest joint "
      f"turn {q['max_joint_turn']:.0f} deg/s ({q['max_joint_turn_at']})")

# %% [markdown]
# ## 9 · Files
#
# A clip is saved as an AMASS-style `.npz`: `poses` (T, 165) axis-angle in SMPL-X order, `trans`, `betas`, `gender`,
# `mocap_frame_rate`, `surface_model_type`, plus `contacts` and, for reaching clips, `goal`, `goal_frame`, `hand`.
# `load_motion` also reads real AMASS SMPL-X and SMPL-H files and resamples them to 30 fps.

# %%
import tempfile
from pathlib import Path

with tempfile.TemporaryDirectory() as d:
    path = save_motion(Path(d) / "reach.npz", clips[5])
    with np.load(path, allow_pickle=False) as z:
        for k in z.files:
            print(f"{k:20s} {str(z[k].shape):10s} {z[k].dtype}")
    back = load_motion(path)
print("round trip exact:", np.array_equal(back.poses, clips[5].poses), "| goal frame", back.goal_frame, "| hand", back.hand)

# %% [markdown]
# The file names no body model: `poses`, `trans` and `betas` mean something only on the body that made them. Its labels
# remember what that body did — a foot on the floor at every frame labelled in contact, the wrist on the goal at the
# goal frame — so `graspkit.data.made_on.clip_offsets` can tell. Posed on a body only 2 % larger, the same parameters
# put the feet about 2 cm under the floor; WANDR's and MotionFill's readers refuse such a folder rather than learn from
# it (`check_clips_made_on`: the feet more than 1 cm off the floor, or the wrist more than 2 cm off its goal).

# %%
from graspkit.body.model import load_model_arrays
from graspkit.data.made_on import clip_offsets

arrays = dict(load_model_arrays(default_model_path()))
arrays["v_template"], arrays["shapedirs"] = arrays["v_template"] * 1.02, arrays["shapedirs"] * 1.02
bigger = BodyModel(arrays)
offs = {name: clip_offsets(body, back) for name, body in (("the body that made it", bm), ("a body 2 % larger", bigger))}
for name, off in offs.items():
    print(f"{name:22s} lowest vertex at the contact frames {100 * off['floor']:+.2f} cm | "
          f"wrist to goal {100 * off['goal']:.2f} cm")
assert abs(offs["the body that made it"]["floor"]) < 0.01 < abs(offs["a body 2 % larger"]["floor"])

# %% [markdown]
# ## Exercise
# 1. Make the person walk backwards (`integrate_controls` with a negative forward speed): which parts of the footstep
#    and foot-phase rules still make sense? Look at the heel-strike angle (`Step.strike`) of backward steps.
# 2. Change the gait's `lead` from 0.45 to 0.8 (`gait = GaitStyle(lead=0.8)`: a GaitStyle is frozen, so build a new
#    one rather than setting `gait.lead`) and re-run section 1: where do the footprints land, and what happens to
#    the pelvis height (the legs must still reach both feet)?
# 3. Raise the goal of section 5 to 2.1 m. Which posture level does `choose_posture` pick, and why does the wrist
#    stop short? What would a person do (tiptoe, a step closer)?
