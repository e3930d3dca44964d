"""Footsteps: where and when each foot steps, and the foot's rigid motion through stance and swing.

Footsteps are placed reactively along a RootPlan (as a walking controller does): when the footprint a
foot would need a little ahead in time (where the root will be `lead` step periods after landing,
offset sideways by half the stance width) is farther than a threshold from where that foot stands, it
steps there, alternating feet. Walking, curves, turning in place, side steps, starting and stopping
all come out of this one rule. Cadence follows speed (steps/s from `GaitStyle.cadence`), stance is
`duty` of the stride, so double support is (2 duty - 1) of a step period.

Each foot then moves as a rigid body with a toe segment (the foot joint at the ball) through four
phases (Perry's gait phases): heel rocker (lands toes up and rotates down about the heel point, which
stays fixed), flat foot, heel rise (rotates heels up about the ball joint while the toes stay flat), and
swing (Hermite curves between the toe-off and heel-strike states plus a clearance bump checked on sole
points). Contact labels come from the same phases, so they are exact by construction.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from graspkit.data.ik import rot_x, rot_z, smoothstep, wrap_angle
from graspkit.data.rig import R_BASE, SIDES, FootGeometry, Rig
from graspkit.data.trajectory import RootPlan


@dataclass(frozen=True)
class GaitStyle:
    """Gait parameters of one person (sampled per clip); lengths in m for a 1.70 m body, angles in rad."""

    half_width: float = 0.085      # lateral offset of each footprint from the path at 1 m/s ...
    width_gain: float = 0.12       # ... times 1 + width_gain (1 - v): a wider stance when slow, narrower when fast
    toe_out: float = 0.08          # each foot turned outwards
    lead: float = 0.45             # footprint = root position `lead` step periods after landing
    duty: float = 0.61             # stance fraction of the stride
    cadence_gain: float = 0.72     # steps/s = 1.0 + gain * v^0.8 (v in m/s), at least cadence_min
    cadence_min: float = 1.5
    strike_gain: float = 0.22      # heel-strike toes-up angle per m of foot travel
    strike_max: float = 0.32
    toeoff_gain: float = 0.65      # toe-off heel-up angle per m of foot travel
    toeoff_max: float = 0.9
    clearance: float = 0.035       # swing bump of the ankle (m) plus clearance_gain per m of travel
    clearance_gain: float = 0.025
    step_threshold: float = 0.05   # a foot steps when its footprint is this far (m) ...
    yaw_threshold: float = 0.16    # ... or turned this much (rad) from where it stands
    max_step: float = 0.95         # longest footprint distance ahead/behind the stance foot
    min_separation: float = 0.09   # footprints never closer sideways than this (no crossing)
    first_step: float = 0.4        # earliest lift-off (s) when starting from rest: time to shift the weight first

    def cadence(self, speed: np.ndarray | float, scale: float = 1.0) -> np.ndarray:
        """Steps per second at a root speed (m/s) for a body `scale` times 1.70 m (taller: slower cadence; dynamic
        similarity: a body s times the size walks at 1/sqrt(s) the cadence at s times the speed)."""
        v = np.maximum(np.asarray(speed, np.float64), 0.0) / scale
        return np.maximum(1.0 + self.cadence_gain * v**0.8, self.cadence_min) / np.sqrt(scale)


@dataclass
class Step:
    """One footstep: side 0 left / 1 right, lift and landing times (s), footprint xy (2,) and yaw, pitch angles."""

    side: int
    t_lift: float
    t_land: float
    xy: np.ndarray
    yaw: float
    strike: float = 0.0   # toes-up angle at heel strike
    toeoff: float = 0.0   # heels-up angle at toe off
    period: float = 0.6   # step period 1/cadence (s)


@dataclass
class FootTracks:
    """Per-frame feet: rotations R_foot, R_toe (2,T,3,3) (global, canonical->world), ankle positions (2,T,3),
    footprint positions (2,T,2) and yaws (2,T), contacts (T,4) [l heel, l toe, r heel, r toe], weight on the left foot (T,)."""

    R_foot: np.ndarray
    R_toe: np.ndarray
    ankle: np.ndarray
    xy: np.ndarray
    yaw: np.ndarray
    contacts: np.ndarray
    weight_left: np.ndarray
    steps: list[Step] = field(default_factory=list)


def footprint_target(plan: RootPlan, rig: Rig, style: GaitStyle, side: int, t: float | np.ndarray,
                     speed: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Footprint xy (...,2) and yaw (...) of foot `side` for the root pose at time t (s), walking at `speed` m/s."""
    xy, h = plan.at(t)
    sgn = 1.0 if side == 0 else -1.0
    f_off = rig.feet[SIDES[side]].ref[2] - rig.joints[0, 2]       # ankle sits a little behind the pelvis
    fwd = np.stack([np.cos(h), np.sin(h)], -1)
    left = np.stack([-np.sin(h), np.cos(h)], -1)
    hw = style.half_width * rig.scale * (1 + style.width_gain * (1 - min(float(speed), 1.6)))
    return xy + f_off * fwd + sgn * hw * left, h + sgn * style.toe_out


def plan_footsteps(plan: RootPlan, rig: Rig, style: GaitStyle, t_begin: float = 0.0) -> list[Step]:
    """Alternating footsteps (see the module docstring) that follow the plan; feet start at their footprints."""
    fps, t_end = plan.fps, (plan.num_frames - 1) / plan.fps
    speed, turn = plan.speed(), np.abs(plan.turn_rate())
    pos = [footprint_target(plan, rig, style, s, 0.0, speed[0]) for s in (0, 1)]
    thr, max_step = style.step_threshold * rig.scale, style.max_step * rig.scale
    steps: list[Step] = []
    at_rest = speed[0] < 0.05 and turn[0] < 0.05
    last, t = None, t_begin + (style.first_step if at_rest else 0.0)
    while t <= t_end:
        k = min(int(round(t * fps)), plan.num_frames - 1)
        k2 = min(k + int(0.6 * fps), plan.num_frames - 1)
        f = float(style.cadence(speed[k:k2 + 1].max() + 0.25 * turn[k:k2 + 1].max(), rig.scale))
        P = 1.0 / f
        t_land = t + 2 * (1 - style.duty) * P
        tau = t_land + style.lead * P
        v_tau = speed[min(int(round(tau * fps)), plan.num_frames - 1)]
        # the farther foot first; on a symmetric start (a straight walk) the two distances tie and rounding picks
        # the foot, so the first foot can differ between headings (kept: changing it would remake the shipped data)
        order = [1 - last, last] if last is not None else sorted((0, 1), key=lambda s: -_distance(
            footprint_target(plan, rig, style, s, tau, v_tau), pos[s]))
        chosen = None
        for s in order:
            txy, tyaw = footprint_target(plan, rig, style, s, tau, v_tau)
            if (np.linalg.norm(txy - pos[s][0]) > thr or abs(wrap_angle(tyaw - pos[s][1])) > style.yaw_threshold):
                chosen = s
                break
        if chosen is None:
            t += 1.0 / fps
            continue
        _, h = plan.at(tau)
        txy = _clamp_footprint(txy, pos[1 - chosen][0], h, chosen, max_step, style.min_separation * rig.scale)
        travel = txy - pos[chosen][0]
        ahead = max(0.0, float(travel @ np.array([np.cos(tyaw), np.sin(tyaw)])))
        dist = float(np.linalg.norm(travel))
        steps.append(Step(chosen, t, t_land, txy, float(tyaw),
                          strike=min(style.strike_gain * ahead, style.strike_max),
                          toeoff=min(style.toeoff_gain * (0.4 * dist + 0.6 * ahead), style.toeoff_max), period=P))
        pos[chosen] = (txy, float(tyaw))
        last = chosen
        t = t_land + (2 * style.duty - 1) * P
    return steps


def _distance(a: tuple[np.ndarray, np.ndarray], b: tuple[np.ndarray, float]) -> float:
    """Footprint mismatch: metres plus 0.3 m per radian of yaw."""
    return float(np.linalg.norm(a[0] - b[0]) + 0.3 * abs(wrap_angle(a[1] - b[1])))


def _clamp_footprint(xy: np.ndarray, other: np.ndarray, heading: float, side: int, max_step: float,
                     min_sep: float) -> np.ndarray:
    """Keep a footprint within max_step ahead/behind of the stance foot and on its own side of it."""
    fwd, left = np.array([np.cos(heading), np.sin(heading)]), np.array([-np.sin(heading), np.cos(heading)])
    r = xy - other
    a, b = float(r @ fwd), float(r @ left)
    a = float(np.clip(a, -max_step, max_step))
    b = max(b, min_sep) if side == 0 else min(b, -min_sep)
    return other + a * fwd + b * left


# ----------------------------------------------------------------------------- rigid foot motion
def _flat(yaw: np.ndarray) -> np.ndarray:
    """Foot rotations (...,3,3) of flat feet with yaws (...)."""
    return rot_z(yaw) @ R_BASE


def _place(R_flat: np.ndarray, xy: np.ndarray, foot: FootGeometry, point: np.ndarray) -> np.ndarray:
    """World position (...,3) of canonical foot point `point` for a flat foot at footprint xy (...,2)."""
    ground = np.concatenate([xy, np.zeros(xy.shape[:-1] + (1,))], -1)
    return (R_flat @ (point - foot.ref)) + ground


def _pivot_state(xy, yaw, foot: FootGeometry, pitch):
    """Foot rotation and ankle position (...,3,3), (...,3) for pitch (...) (>0 heel up about the ball, <0 toes up about the heel)."""
    pitch = np.asarray(pitch, np.float64)
    R_flat = _flat(yaw)
    R = R_flat @ rot_x(pitch)
    heel_up = (pitch > 0)[..., None]
    pivot = np.where(heel_up, foot.ball, foot.heel)
    pivot_w = np.where(heel_up, _place(R_flat, xy, foot, foot.ball), _place(R_flat, xy, foot, foot.heel))
    ankle = (R @ (foot.ankle - pivot)[..., None])[..., 0] + pivot_w
    return R, ankle, R_flat


def _hermite(p0, v0, p1, v1, u, D):
    """Cubic Hermite curve (...,d) at u (N,) between p0, p1 with end velocities v0, v1 (per second) over duration D."""
    u = u[:, None]
    h00, h10, h01, h11 = 2 * u**3 - 3 * u**2 + 1, u**3 - 2 * u**2 + u, -2 * u**3 + 3 * u**2, u**3 - u**2
    return h00 * p0 + h10 * D * v0 + h01 * p1 + h11 * D * v1


def foot_tracks(steps: list[Step], plan: RootPlan, rig: Rig, style: GaitStyle) -> FootTracks:
    """Per-frame rigid motion, contact labels and support weights of both feet for the footsteps."""
    T, fps = plan.num_frames, plan.fps
    t = np.arange(T) / fps
    R_foot, R_toe = np.zeros((2, T, 3, 3)), np.zeros((2, T, 3, 3))
    ankle, fxy, fyaw = np.zeros((2, T, 3)), np.zeros((2, T, 2)), np.zeros((2, T))
    contacts = np.zeros((T, 4), bool)
    for s in (0, 1):
        foot = rig.feet[SIDES[s]]
        xy0, yaw0 = footprint_target(plan, rig, style, s, 0.0, plan.speed()[0])
        mine = [st for st in steps if st.side == s]
        # stance k: footprint k (k=0 the initial one), from landing k to lift k (of the next step of this foot)
        prints = [(xy0, float(yaw0), 0.0, -np.inf, None)] + [(st.xy, st.yaw, st.strike, st.t_land, st) for st in mine]
        for k, (pxy, pyaw, strike, t_land, st_in) in enumerate(prints):
            nxt = mine[k] if k < len(mine) else None
            t_lift = nxt.t_lift if nxt is not None else np.inf
            # ---- stance
            sel = (t >= t_land) & (t < t_lift)
            P_in = st_in.period if st_in is not None else 0.6
            stance = t_lift - t_land
            T_load = min(0.2 * P_in, 0.45 * stance)
            T_rise = min(0.5 * nxt.period, 0.45 * stance) if nxt is not None else 0.0
            tt = t[sel]
            pitch = np.zeros_like(tt)
            if strike > 0 and np.isfinite(t_land):
                u = (tt - t_land) / T_load
                pitch = np.where(u < 1, -strike * (1 - smoothstep(u)), pitch)
            if nxt is not None and nxt.toeoff > 0:
                u = (tt - (t_lift - T_rise)) / T_rise
                pitch = np.where(u > 0, nxt.toeoff * np.clip(u, 0, 1) ** 2, pitch)
            R, a, R_flat = _pivot_state(np.broadcast_to(pxy, (len(tt), 2)), np.full(len(tt), pyaw), foot, pitch)
            R_foot[s, sel], ankle[s, sel] = R, a
            R_toe[s, sel] = np.where((pitch > 0)[:, None, None], R_flat, R)
            fxy[s, sel], fyaw[s, sel] = pxy, pyaw
            heel_on = tt < (t_lift - T_rise) if nxt is not None else np.ones_like(tt, bool)
            toe_on = tt >= t_land + (T_load if strike > 0 else 0.0)
            contacts[sel, 2 * s] = heel_on
            contacts[sel, 2 * s + 1] = toe_on
            # ---- swing to the next footprint
            if nxt is None:
                continue
            sel = (t >= nxt.t_lift) & (t < nxt.t_land)
            if not sel.any():
                continue
            D = nxt.t_land - nxt.t_lift
            u = (t[sel] - nxt.t_lift) / D
            # states and velocities at the two ends (finite differences of the stance formulas)
            dt = 1e-4
            R0, a0, _ = _pivot_state(pxy, pyaw, foot, nxt.toeoff)
            _, a0m, _ = _pivot_state(pxy, pyaw, foot, nxt.toeoff * (1 - dt / T_rise) ** 2 if T_rise > 0 else 0.0)
            v0 = (a0 - a0m) / dt
            w0 = 2 * nxt.toeoff / T_rise if T_rise > 0 else 0.0
            R1, a1, _ = _pivot_state(nxt.xy, nxt.yaw, foot, -nxt.strike)
            yaw_u = pyaw + wrap_angle(nxt.yaw - pyaw) * smoothstep(u)
            pitch_u = _hermite(np.array([nxt.toeoff]), np.array([w0]), np.array([-nxt.strike]), np.zeros(1), u, D)[:, 0]
            pos = _hermite(a0, v0, a1, np.zeros(3), u, D)
            bump = 16 * u**2 * (1 - u) ** 2
            travel = float(np.linalg.norm(nxt.xy - pxy))
            pos[:, 2] += (style.clearance + style.clearance_gain * travel) * rig.scale * bump
            Rs = rot_z(yaw_u) @ R_BASE @ rot_x(pitch_u)
            # the toes stay level while the foot leaves the ground, then follow the foot by mid-swing
            toe_flex = -pitch_u * (1 - smoothstep(u / 0.6))
            # raise the middle of the swing if a sole point would come closer to the ground than 1.5 cm x bump
            pts = np.einsum("tij,kj->tki", Rs, foot.sole - foot.ankle) + pos[:, None]
            low = pts[..., 2].min(1)
            mid = (u > 0.2) & (u < 0.8)
            need = np.where(mid, (0.015 * bump - low) / np.maximum(bump, 1e-3), 0.0)
            pos[:, 2] += max(0.0, float(need.max(initial=0.0))) * bump
            R_foot[s, sel], ankle[s, sel] = Rs, pos
            R_toe[s, sel] = Rs @ rot_x(toe_flex)
            fxy[s, sel] = pxy + (nxt.xy - pxy) * smoothstep(u)[:, None]
            fyaw[s, sel] = yaw_u
    return FootTracks(R_foot, R_toe, ankle, fxy, fyaw, contacts, support_weight(contacts, fps), steps)


def support_weight(contacts: np.ndarray, fps: float, shift_time: float = 0.35) -> np.ndarray:
    """Fraction of body weight on the left foot (T,): 1/0 in single support, shifting over double support.

    A double-support interval hands the weight from the foot that was carrying it to the foot that will
    carry it after the next lift; a long one (standing) rests at 0.5 in between (weight shifts of
    `shift_time` s at its ends, so the body moves over the stance foot before a first step).
    """
    T = len(contacts)
    on = np.stack([contacts[:, 0] | contacts[:, 1], contacts[:, 2] | contacts[:, 3]], 1)
    w = np.where(on[:, 0] & ~on[:, 1], 1.0, np.where(on[:, 1] & ~on[:, 0], 0.0, 0.5))
    both = on[:, 0] & on[:, 1]
    k = 0
    while k < T:
        if not both[k]:
            k += 1
            continue
        a = k
        while k < T and both[k]:
            k += 1
        b = k  # frames [a, b) are double support
        wa = 0.5 if a == 0 else (1.0 if on[a - 1, 0] else 0.0)
        wb = 0.5 if b >= T else (1.0 if on[b, 0] else 0.0)
        n = b - a
        tt = (np.arange(n) + 0.5) / fps
        dur = n / fps
        if dur <= 2 * shift_time:
            w[a:b] = wa + (wb - wa) * smoothstep(tt / dur)
        else:
            w[a:b] = 0.5 + (wa - 0.5) * (1 - smoothstep(tt / shift_time)) + (wb - 0.5) * smoothstep((tt - dur + shift_time) / shift_time)
    return w
