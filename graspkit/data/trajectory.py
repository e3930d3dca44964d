"""Root plans: where the body is meant to be and which way it faces, frame by frame (z-up world).

A plan is built from per-frame controls (forward speed, sideways speed, turning rate) that are
smoothed (people need about a second to reach walking speed or to stop) and integrated. Footsteps
(`footsteps.py`) are then placed along the plan, and the pelvis follows it with sway and bob.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.ndimage import gaussian_filter1d

from graspkit.data.ik import smoothstep, wrap_angle


@dataclass
class RootPlan:
    """Ground position xy (T,2) and heading (T,) (radians from +x, counter-clockwise) of the body, at fps."""

    xy: np.ndarray
    heading: np.ndarray
    fps: float = 30.0

    @property
    def num_frames(self) -> int:
        return len(self.xy)

    def at(self, t: float | np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Position (...,2) and heading (...) at time(s) t in seconds (linear interpolation, held at the ends)."""
        f = np.clip(np.asarray(t, np.float64) * self.fps, 0, self.num_frames - 1)
        i0 = np.minimum(np.floor(f).astype(int), self.num_frames - 2) if self.num_frames > 1 else np.zeros_like(f, int)
        i1 = np.minimum(i0 + 1, self.num_frames - 1)
        a = (f - i0)[..., None]
        xy = (1 - a) * self.xy[i0] + a * self.xy[i1]
        dh = wrap_angle(self.heading[i1] - self.heading[i0])
        return xy, self.heading[i0] + a[..., 0] * dh

    def speed(self) -> np.ndarray:
        """Ground speed (T,) in m/s (central differences; 0 for a one-frame plan)."""
        if self.num_frames < 2:
            return np.zeros(self.num_frames)
        return np.linalg.norm(np.gradient(self.xy, axis=0), axis=1) * self.fps

    def turn_rate(self) -> np.ndarray:
        """Heading rate (T,) in rad/s (0 for a one-frame plan)."""
        if self.num_frames < 2:
            return np.zeros(self.num_frames)
        return np.gradient(np.unwrap(self.heading)) * self.fps


def integrate_controls(v_fwd: np.ndarray, v_side: np.ndarray, yaw_rate: np.ndarray,
                       xy0: tuple[float, float] | np.ndarray = (0.0, 0.0),
                       heading0: float = 0.0, fps: float = 30.0) -> RootPlan:
    """Integrate per-frame forward / leftward speed (m/s) and yaw rate (rad/s), all (T,), into a RootPlan."""
    heading = heading0 + np.concatenate([[0.0], np.cumsum(0.5 * (yaw_rate[1:] + yaw_rate[:-1]))]) / fps
    c, s = np.cos(heading), np.sin(heading)
    vel = np.stack([v_fwd * c - v_side * s, v_fwd * s + v_side * c], 1)
    xy = np.asarray(xy0, np.float64) + np.concatenate([np.zeros((1, 2)), np.cumsum(0.5 * (vel[1:] + vel[:-1]), 0)]) / fps
    return RootPlan(xy, heading, fps)


def smooth_controls(x: np.ndarray, sigma_s: float, fps: float = 30.0) -> np.ndarray:
    """Gaussian-smoothed control signal (T,) with sigma in seconds (edges held)."""
    return gaussian_filter1d(np.asarray(x, np.float64), sigma_s * fps, mode="nearest")


def ramp(T: int, t0: float, t1: float, fps: float = 30.0) -> np.ndarray:
    """Minimum-jerk ramp (T,) from 0 before t0 (s) to 1 after t1."""
    t = np.arange(T) / fps
    return smoothstep((t - t0) / max(t1 - t0, 1e-6))


def straight_walk(T: int, start_xy: tuple[float, float] | np.ndarray, heading: float, distance: float,
                  t_start: float, t_stop: float, accel_time: float = 0.9,
                  fps: float = 30.0) -> tuple[np.ndarray, np.ndarray]:
    """Ground positions (T,2) walking `distance` m along `heading` between t_start and t_stop (s), and speeds (T,).

    The speed profile rises and falls with minimum-jerk ramps of `accel_time`, then is scaled so that the
    walked distance is exact.
    """
    t = np.arange(T) / fps
    dur = max(t_stop - t_start, 1e-3)
    a = min(accel_time, 0.45 * dur)
    prof = smoothstep((t - t_start) / a) * (1 - smoothstep((t - (t_stop - a)) / a))
    s = np.concatenate([[0.0], np.cumsum(0.5 * (prof[1:] + prof[:-1]))]) / fps
    s = s * (distance / s[-1]) if s[-1] > 0 else s
    d = np.array([np.cos(heading), np.sin(heading)])
    return np.asarray(start_xy, np.float64) + s[:, None] * d, np.gradient(s) * fps


def heading_profile(T: int, h0: float, h1: float, t0: float, t1: float, fps: float = 30.0) -> np.ndarray:
    """Headings (T,) turning from h0 to h1 (the short way) with a minimum-jerk profile over [t0, t1]."""
    return h0 + wrap_angle(h1 - h0) * ramp(T, t0, t1, fps)
