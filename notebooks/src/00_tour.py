# %% [markdown]
# # 00 · A tour of graspkit
#
# **graspkit** is a workbook: eleven executable lessons and a small library that implement, at a scale
# that trains on a laptop CPU, three published methods for synthesising *whole-body* human motion
# towards objects and goals:
#
# | method | question it answers | lessons |
# |---|---|---|
# | **SAGA** (Wu et al., ECCV 2022) | given an object, how does a whole body grasp it, and how does it walk there? | 05, 06 |
# | **GOAL** (Taheri et al., CVPR 2022) | the same, with a CVAE over body parameters and an autoregressive motion net | 07 |
# | **WANDR** (Diomataris et al., CVPR 2024) | given a 3D goal for the wrist (and a time), walk to it and reach it | 08, 09 |
#
# All three move an **SMPL-X** body. The licensed SMPL-X model and the motion-capture sets the papers train on
# (AMASS, GRAB, CIRCLE) cannot be shipped, so graspkit builds its own *procedural humanoid in the SMPL-X file
# format* and its own *synthetic procedural data*. The same code reads the real files when you have them.

# %%
%matplotlib inline
from graspkit.viz.diagrams import pipeline_diagram

fig = pipeline_diagram()

# %% [markdown]
# ## The road through the lessons
#
# | lesson | topic |
# |---|---|
# | 01 | the SMPL-X body model step by step: template, shape, joints, pose correctives, skinning; 6D rotations; markers |
# | 02 | objects and contact geometry: surface points, BPS, signed distance, contact maps, penetration, attention |
# | 03 | synthetic motion: footsteps, leg IK, locomotion and goal reaching; AMASS/CIRCLE-style files |
# | 04 | synthetic grasps: whole-body grasp optimisation, contact labels, approach-and-grasp clips |
# | 05 | SAGA stage 1: WholeGrasp-VAE and GraspPose-Opt |
# | 06 | SAGA stage 2: MotionFill-VAE and GraspMotion-Opt |
# | 07 | GOAL: GNet, refinement and MNet |
# | 08, 09 | WANDR: intention features, the CVAE and its rollout; the goal-grid evaluation, time control, waypoints |
# | 10 | one benchmark for all methods |
#
# Conventions used everywhere (the design notes are in `docs/`): the world is **z up, in metres, at 30 fps**;
# the body model's own space is SMPL-X's (y up, facing +z), and the root orientation turns it into the world, as in AMASS.

# %% [markdown]
# ## Running the workbook
#
# From a fresh clone, with Python 3.11 and pip:
#
# ```bash
# bash workbook.sh demo   # sets up .venv, runs the main job, writes figures to outputs/demo
# bash workbook.sh test   # sets up .venv, runs the tests and every lesson under nbval
# ```
#
# The lessons are built from `notebooks/src/*.py` by `python tools/notebooks.py`, which executes them and stores
# their outputs; nbval re-runs each lesson and compares. Every random draw is seeded, so on one machine, with one
# torch thread count, the numbers you see are the numbers you get; another CPU's floating-point kernels can move
# the last digits, and an optimisation or a rollout can carry them further (README, "Other CPUs": those cells are
# the ones nbval does not compare).

# %% [markdown]
# ## Environment check
# The cell below checks that the pieces the lessons need are importable and that the body model loads.

# %%
import importlib

import torch

needed = ["numpy", "scipy", "torch", "trimesh", "matplotlib", "ipywidgets", "tqdm", "skimage"]
missing = [m for m in needed if importlib.util.find_spec(m) is None]
print("missing packages:", missing or "none")
print("torch", torch.__version__.split("+")[0], "| CUDA available:", torch.cuda.is_available())

# %%
from graspkit.body import BodyModel
from graspkit.paths import default_model_path

bm = BodyModel.from_file(default_model_path())
out = bm()
print(f"procedural humanoid: {bm.is_procedural}; vertices {tuple(out.vertices.shape)}, joints {tuple(out.joints.shape)}")

# %% [markdown]
# ## Exercise
# Open `graspkit/body/model.py` and find where the joints are computed. Why can graspkit fold the joint regressor
# into the shape basis once, at load time, instead of applying the (55 × 10,475) regressor on every forward pass?
