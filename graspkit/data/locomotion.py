"""Goal-less locomotion clips in the spirit of AMASS (WANDR Sec. 3.1, 4.1; SAGA A.3 pre-training data).

A clip is a random program of segments (walk at 0.5-1.6 m/s on straight or curved paths, stand,
turn in place, side steps, a few steps backwards), turned into smooth per-frame controls, integrated
into a RootPlan, stepped by the footstep planner and posed (`posing.py`). Clips may start mid-walk
(a pre-roll is generated and cut away), so the data holds starts, stops and steady gait, as AMASS does.
Every draw comes from one np.random.Generator seeded per clip: the same seed gives the same clip.
"""
from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from graspkit.checks import check_betas, check_int, seeded_rng
from graspkit.data.footsteps import GaitStyle, foot_tracks, plan_footsteps
from graspkit.data.motion import Motion
from graspkit.data.posing import Controls, Style, pose_body
from graspkit.data.rig import Rig, build_rig, check_rig
from graspkit.data.trajectory import RootPlan, integrate_controls, smooth_controls

if TYPE_CHECKING:
    from graspkit.body import BodyModel

PROGRAMS = {"walk": 0.24, "curve": 0.2, "start_stop": 0.18, "turn": 0.14, "side": 0.1, "idle": 0.08, "backward": 0.06}
SPEED_RANGE = (0.5, 1.6)


def sample_betas(rng: np.random.Generator, scale: float = 0.8) -> np.ndarray:
    """Shape coefficients (10,) ~ N(0, scale^2), clipped to +-2."""
    return np.clip(rng.normal(0, scale, 10), -2, 2)


def sample_gait_style(rng: np.random.Generator) -> GaitStyle:
    """A person's gait: stance width, toe-out, cadence, foot angles and clearance varied around the defaults."""
    g = GaitStyle()
    return replace(g, half_width=g.half_width * rng.uniform(0.8, 1.2), toe_out=rng.uniform(0.02, 0.14),
                   lead=rng.uniform(0.4, 0.5), duty=rng.uniform(0.59, 0.63), cadence_gain=g.cadence_gain * rng.uniform(0.9, 1.1),
                   clearance=g.clearance * rng.uniform(0.8, 1.25), toeoff_gain=g.toeoff_gain * rng.uniform(0.85, 1.1))


def sample_style(rng: np.random.Generator) -> Style:
    """A person's upper-body style: arm carriage and swing, sway, pelvic motion, lean, gaze."""
    s = Style()
    return replace(s, arm_lower=rng.uniform(1.36, 1.46), arm_abduct=rng.uniform(0.0, 0.08), arm_swing=rng.uniform(0.2, 0.4),
                   elbow_bend=rng.uniform(0.15, 0.5), sway=rng.uniform(0.3, 0.45), pelvic_rotation=rng.uniform(0.1, 0.18),
                   obliquity=rng.uniform(0.03, 0.07), lean=rng.uniform(0.02, 0.08), head_pitch=rng.uniform(0.05, 0.25),
                   finger_curl=rng.uniform(0.7, 1.2))


def _segments(kind: str, rng: np.random.Generator, duration: float) -> list[tuple[str, float, dict]]:
    """A program: (segment, seconds, parameters) covering at least `duration` s."""
    v = lambda: rng.uniform(*SPEED_RANGE)  # noqa: E731
    stand = lambda lo=0.6, hi=2.0: ("stand", rng.uniform(lo, hi), {})  # noqa: E731
    out: list[tuple[str, float, dict]] = []
    while sum(d for _, d, _ in out) < duration:
        if kind == "walk":
            out.append(("walk", rng.uniform(2.0, 5.0), {"v": v(), "k": rng.normal(0, 0.08)}))
        elif kind == "curve":
            out.append(("walk", rng.uniform(1.5, 3.5), {"v": rng.uniform(0.5, 1.4), "k": rng.uniform(-0.8, 0.8)}))
        elif kind == "start_stop":
            out += [stand(), ("walk", rng.uniform(1.5, 4.0), {"v": v(), "k": rng.normal(0, 0.15)})]
        elif kind == "turn":
            ang = rng.choice([-1, 1]) * rng.uniform(np.pi / 3, np.pi)
            rate = rng.uniform(1.6, 2.6)
            out += [stand(0.4, 1.5), ("turn", abs(ang) / rate, {"w": np.sign(ang) * rate})]
            if rng.random() < 0.4:
                out.append(("walk", rng.uniform(1.5, 3.0), {"v": rng.uniform(0.5, 1.3), "k": 0.0}))
        elif kind == "side":
            out += [stand(0.4, 1.5), ("side", rng.uniform(0.8, 2.0), {"u": rng.choice([-1, 1]) * rng.uniform(0.15, 0.35)})]
        elif kind == "backward":
            out += [stand(0.5, 1.5), ("walk", rng.uniform(1.0, 2.5), {"v": -rng.uniform(0.3, 0.6), "k": 0.0})]
        else:  # idle
            out.append(stand(duration, duration + 0.1))
    return out


def locomotion_plan(kind: str, rng: np.random.Generator, num_frames: int, fps: float = 30.0,
                    preroll: float = 0.0, postroll: float = 0.0) -> tuple[RootPlan, np.ndarray]:
    """A RootPlan of num_frames + preroll + postroll frames for a program kind, and the planned speed (T,)."""
    T = num_frames + int(round(preroll * fps)) + int(round(postroll * fps))
    segs = _segments(kind, rng, T / fps)
    v, u, w = np.zeros(T), np.zeros(T), np.zeros(T)
    k = 0
    for name, dur, p in segs:
        n = int(round(dur * fps))
        sl = slice(k, min(k + n, T))
        if name == "walk":
            v[sl], w[sl] = p["v"], p["k"] * p["v"]
        elif name == "turn":
            w[sl] = p["w"]
        elif name == "side":
            u[sl] = p["u"]
        k += n
        if k >= T:
            break
    # every plan starts slow with the feet at their footprints (the controls are zero for 0.25 s; after smoothing,
    # frame 0 already moves at about a fifth of the walking speed); a clip that should begin in motion gets a
    # pre-roll that is cut later. Smoothing makes ramps of about a second.
    rest = int(0.25 * fps)
    v[:rest], u[:rest], w[:rest] = 0.0, 0.0, 0.0
    v = smooth_controls(v, 0.3, fps)
    u = smooth_controls(u, 0.25, fps)
    w = smooth_controls(w, 0.15, fps)
    return integrate_controls(v, u, w, (0.0, 0.0), rng.uniform(-np.pi, np.pi), fps), v


def generate_locomotion(seed: int, bm: BodyModel, num_frames: int | None = None, kind: str | None = None,
                        betas: np.ndarray | None = None, rig: Rig | None = None) -> Motion:
    """One AMASS-style clip (4-10 s unless num_frames) from a seed; kind one of PROGRAMS (None: drawn)."""
    rng = seeded_rng(seed)
    fps = 30.0
    kind = kind or str(rng.choice(list(PROGRAMS), p=np.array(list(PROGRAMS.values())) / sum(PROGRAMS.values())))
    if kind not in PROGRAMS:
        raise ValueError(f"kind: expected one of {sorted(PROGRAMS)}, got {kind!r}")
    T = int(rng.integers(120, 301)) if num_frames is None else check_int(num_frames, "num_frames", 1)
    betas = sample_betas(rng) if betas is None else check_betas(betas, bm.num_betas)
    if rig is None:
        rig = build_rig(bm, betas)
    else:
        check_rig(rig, bm, betas)
    gait, style = sample_gait_style(rng), sample_style(rng)
    preroll = 2.5 if kind in ("walk", "curve") and rng.random() < 0.6 else 0.0
    post = 1.0   # planned past the end, so the last steps are taken as if the motion went on, then cut
    plan, _ = locomotion_plan(kind, rng, T, fps, preroll, post)
    P = plan.num_frames
    c = Controls.zeros(P)
    tt = np.arange(P) / fps
    c.weight_shift = 0.25 * np.sin(2 * np.pi * tt / rng.uniform(3, 6) + rng.uniform(0, 6.3)) * rng.uniform(0.3, 1.0)
    c.look_yaw = 0.5 * np.sin(2 * np.pi * tt / rng.uniform(4, 9) + rng.uniform(0, 6.3)) * rng.uniform(0.0, 1.0)
    steps = plan_footsteps(plan, rig, gait)
    tracks = foot_tracks(steps, plan, rig, gait)
    aa, root, _ = pose_body(rig, plan, tracks, style, c)
    m = Motion(aa, root - rig.joints[0], betas, fps, contacts=tracks.contacts)
    end = P - int(round(post * fps))
    m = m.slice(end - T, end)
    m.trans[:, :2] -= m.trans[0, :2] - rng.uniform(-0.5, 0.5, 2)  # each clip starts near the origin
    return m
