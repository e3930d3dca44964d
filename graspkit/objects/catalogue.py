"""Procedural catalogue of graspable objects named after GRAB / HO3D (YCB) objects.

Every object is ONE watertight, consistently outward-oriented triangle mesh (at most a few thousand
faces), in metres, z up when the object stands (or lies) in its natural resting pose, with the
object-frame origin at the centre of its axis-aligned bounding box. Shapes are built by constructive
solid geometry in manifold3d (revolved profiles, extrusions, convex hulls, exact boolean unions),
which guarantees 2-manifold, watertight output. Sizes are realistic approximations of the real
objects; they are listed in `SPECS` and in docs/objects.md.

GRAB's six test objects (mug, camera, toothpaste, wine glass, frying pan, binoculars; SAGA App. A.3,
GrabNet's split; GOAL withholds five objects without naming them) are all present. The YCB / HO3D
look-alikes are training objects here (graspkit.data.grasp.SPLITS); SAGA uses HO3D only for testing.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from typing import Callable

import manifold3d as m3d
import numpy as np
import trimesh

SEG = 40  # circular segments for round parts: enough for ~0.3 mm chord error on a 4 cm radius
VARIATION = 0.1  # seeded shape variation: independent scales in [1 - v, 1 + v] for x/y (shared) and z


@dataclass(frozen=True)
class ObjectSpec:
    """A catalogue entry: the source data set, nominal bounding-box size (x, y, z) in metres, a builder."""

    name: str
    source: str
    size: tuple[float, float, float]
    description: str
    build: Callable[[], m3d.Manifold]


# ---------------------------------------------------------------------------------------------- primitives

def _revolve(profile: list[tuple[float, float]], segments: int = SEG) -> m3d.Manifold:
    """Solid of revolution about z of a closed (radius, z) polygon, counter-clockwise in the (r, z) plane."""
    return m3d.CrossSection([np.asarray(profile, dtype=np.float64)]).revolve(segments)


def _cylinder(radius: float, height: float, z0: float = 0.0, segments: int = SEG) -> m3d.Manifold:
    """Cylinder along z from z0 to z0 + height."""
    return m3d.Manifold.cylinder(height, radius, radius, segments).translate((0.0, 0.0, z0))


def _box(size: tuple[float, float, float], centre: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> m3d.Manifold:
    """Axis-aligned box of the given size centred at `centre`."""
    return m3d.Manifold.cube(size, True).translate(centre)


def _rounded_box(size: tuple[float, float, float], radius: float, segments: int = 16) -> m3d.Manifold:
    """Box centred at the origin with rounded vertical edges (hull of four vertical cylinders)."""
    x, y, z = size[0] / 2 - radius, size[1] / 2 - radius, size[2]
    posts = [_cylinder(radius, z, -z / 2, segments).translate((sx * x, sy * y, 0.0))
             for sx in (-1, 1) for sy in (-1, 1)]
    return m3d.Manifold.batch_hull(posts)


def _handle(major: float, minor: float, degrees: float = 180.0, segments: int = 24) -> m3d.Manifold:
    """Arc of a torus (a ring handle) in the xz-plane on the +x side, centred at the origin, spanning z in ±major."""
    ring = m3d.CrossSection.circle(minor, 16).translate((major, 0.0)).revolve(segments, degrees)
    return ring.rotate((0.0, 0.0, -degrees / 2)).rotate((90.0, 0.0, 0.0))


def _capsule_chain(points: np.ndarray, radii: np.ndarray, segments: int = 16) -> m3d.Manifold:
    """Union of convex hulls of consecutive spheres: a swept tube with varying radius along a polyline."""
    spheres = [m3d.Manifold.sphere(float(r), segments).translate(tuple(map(float, p))) for p, r in zip(points, radii)]
    hulls = [m3d.Manifold.batch_hull([a, b]) for a, b in zip(spheres[:-1], spheres[1:])]
    return m3d.Manifold.batch_boolean(hulls, m3d.OpType.Add)


def _union(*parts: m3d.Manifold) -> m3d.Manifold:
    """Exact boolean union (manifold3d keeps the result watertight)."""
    return m3d.Manifold.batch_boolean(list(parts), m3d.OpType.Add)


# ---------------------------------------------------------------------------------------------- builders

def _mug() -> m3d.Manifold:
    r, h, t = 0.041, 0.095, 0.004
    cup = _revolve([(0, 0), (r, 0), (r, h), (r - t, h), (r - t, 0.006), (0, 0.006)])
    handle = _handle(0.027, 0.0055).scale((0.9, 1.0, 1.0)).translate((r - 0.006, 0.0, 0.05))
    return _union(cup, handle)


def _wine_glass() -> m3d.Manifold:
    bowl = [(0.0, 0.085), (0.025, 0.095), (0.037, 0.115), (0.040, 0.14), (0.038, 0.17), (0.036, 0.21),
            (0.0335, 0.21), (0.0355, 0.17), (0.0375, 0.14), (0.0345, 0.117), (0.023, 0.099), (0.0, 0.092)]
    stem_and_foot = [(0.0, 0.0), (0.035, 0.0), (0.035, 0.003), (0.012, 0.006), (0.0045, 0.012), (0.0045, 0.086),
                     (0.0, 0.086)]
    return _union(_revolve(bowl), _revolve(stem_and_foot))


def _bottle() -> m3d.Manifold:
    return _revolve([(0, 0), (0.031, 0), (0.033, 0.004), (0.033, 0.15), (0.028, 0.175), (0.016, 0.195),
                     (0.0135, 0.2), (0.0135, 0.23), (0, 0.23)])


def _can() -> m3d.Manifold:
    return _revolve([(0, 0), (0.026, 0), (0.033, 0.008), (0.033, 0.112), (0.027, 0.12), (0.027, 0.122),
                     (0, 0.122)])


def _cracker_box() -> m3d.Manifold:
    return _box((0.16, 0.06, 0.21))


def _toothpaste() -> m3d.Manifold:
    # a tube standing on its cap: convex hull of neck disc, elliptic shoulder and a flat crimp at the top
    neck = _cylinder(0.011, 0.002, 0.017, 32)
    shoulder = _cylinder(0.02, 0.004, 0.03).scale((1.0, 0.8, 1.0))
    crimp = _box((0.048, 0.006, 0.012), (0.0, 0.0, 0.184))
    cap = _cylinder(0.012, 0.02, 0.0, 32)
    return _union(m3d.Manifold.batch_hull([neck, shoulder, crimp]), cap)


def _toothbrush() -> m3d.Manifold:
    handle = m3d.Manifold.batch_hull([_rounded_box((0.014, 0.010, 0.001), 0.004).translate((0, 0, z))
                                      for z in (0.0, 0.12, 0.15)]).scale((1.0, 1.0, 1.0))
    neck = m3d.Manifold.batch_hull([_rounded_box((0.010, 0.006, 0.001), 0.0025).translate((0, 0.001, 0.12)),
                                    _rounded_box((0.010, 0.006, 0.001), 0.0025).translate((0, 0.001, 0.165))])
    head = _rounded_box((0.012, 0.006, 0.026), 0.003).translate((0.0, 0.001, 0.178))
    bristles = _box((0.010, 0.011, 0.024), (0.0, 0.0095, 0.178))
    return _union(handle, neck, head, bristles)


def _apple() -> m3d.Manifold:
    z = np.linspace(0.0, 1.0, 13)
    r = 0.04 * np.sin(np.pi * (0.08 + 0.84 * z)) ** 0.7 * (1.0 + 0.08 * z)
    profile = [(0.0, 0.004)] + [(float(ri), float(0.075 * zi)) for ri, zi in zip(r, z)] + [(0.0, 0.069)]
    stem = _cylinder(0.0022, 0.016, 0.062, 12)
    return _union(_revolve(profile, 36), stem)


def _banana() -> m3d.Manifold:
    a = np.linspace(-0.85, 0.85, 9)  # angles along an arc of radius 0.13 m in the xy-plane
    # the C library's sine and cosine, not numpy's: numpy 1.x and 2.x round them differently in the last bit, and
    # the hulls below then split some flat quads along the other diagonal (another mesh than the shipped files')
    sin, cos = np.array([math.sin(x) for x in a]), np.array([math.cos(x) for x in a])
    pts = np.stack([0.13 * sin, 0.13 * (1 - cos), np.zeros_like(a)], axis=1)
    radii = 0.018 * np.sqrt(np.clip(1.0 - (a / 0.95) ** 2, 0.06, 1.0))
    return _capsule_chain(pts, radii, 16)


def _camera() -> m3d.Manifold:
    body = _rounded_box((0.12, 0.065, 0.08), 0.008)
    lens = _cylinder(0.032, 0.05, 0.0, SEG).rotate((90.0, 0.0, 0.0)).translate((0.015, -0.03, 0.0))
    grip = _rounded_box((0.025, 0.02, 0.07), 0.008).translate((-0.045, -0.035, -0.003))
    button = _cylinder(0.006, 0.008, 0.038, 16).translate((-0.04, 0.0, 0.0))
    return _union(body, lens, grip, button)


def _binoculars() -> m3d.Manifold:
    parts = []
    for sx in (-1.0, 1.0):
        barrel = _revolve([(0, 0), (0.024, 0), (0.024, 0.09), (0.019, 0.1), (0.019, 0.14), (0, 0.14)], 32)
        parts.append(barrel.rotate((-90.0, 0.0, 0.0)).translate((sx * 0.035, -0.07, 0.0)))
    bridge = _cylinder(0.012, 0.09, 0.0, 24).rotate((-90.0, 0.0, 0.0)).translate((0.0, -0.02, 0.0))
    hinge = _box((0.07, 0.05, 0.014), (0.0, 0.02, 0.0))
    return _union(*parts, bridge, hinge)


def _frying_pan() -> m3d.Manifold:
    pan = _revolve([(0, 0), (0.1, 0), (0.122, 0.045), (0.118, 0.045), (0.097, 0.004), (0, 0.004)], 48)
    handle = m3d.Manifold.batch_hull([_rounded_box((0.03, 0.022, 0.012), 0.008).translate((0.0, 0.0, z))
                                      for z in (0.0, 0.17)])
    handle = handle.rotate((0.0, 80.0, 0.0)).translate((0.112, 0.0, 0.035))
    return _union(pan, handle)


def _pitcher() -> m3d.Manifold:
    t = 0.004
    outer = [(0.06, 0.0), (0.07, 0.05), (0.072, 0.12), (0.062, 0.19), (0.058, 0.235)]
    inner = [(r - t, z) for r, z in outer[::-1]]
    profile = [(0.0, 0.0)] + outer + inner[:-1] + [(0.06 - t, 0.006), (0.0, 0.006)]
    body = _revolve(profile, 48)
    handle = _handle(0.065, 0.009, 180.0, 24).scale((0.8, 1.0, 1.0)).translate((0.06, 0.0, 0.13))
    return _union(body, handle)


def _bowl() -> m3d.Manifold:
    a = np.linspace(0.0, np.pi / 2, 8)
    outer = [(0.05 + 0.03 * np.sin(x), 0.055 * (1 - np.cos(x))) for x in a]
    inner = [(r - 0.004, z + 0.004) for r, z in outer[::-1]]
    return _revolve([(0.0, 0.0)] + outer + inner + [(0.0, 0.004)], 48)


def _power_drill() -> m3d.Manifold:
    body = _cylinder(0.03, 0.14, 0.0, 32).rotate((0.0, 90.0, 0.0)).translate((-0.07, 0.0, 0.065))
    motor = m3d.Manifold.sphere(0.034, 24).scale((1.0, 0.9, 1.0)).translate((-0.07, 0.0, 0.065))
    chuck = _revolve([(0, 0), (0.016, 0), (0.012, 0.04), (0, 0.04)], 24).rotate((0.0, 90.0, 0.0)) \
        .translate((0.07, 0.0, 0.065))
    grip = m3d.Manifold.batch_hull([_rounded_box((0.045, 0.035, 0.002), 0.012).translate((-0.055, 0.0, 0.04)),
                                    _rounded_box((0.04, 0.03, 0.002), 0.012).translate((-0.035, 0.0, -0.06))])
    battery = _rounded_box((0.09, 0.07, 0.035), 0.01).translate((-0.04, 0.0, -0.075))
    return _union(body, motor, chuck, grip, battery)


def _flashlight() -> m3d.Manifold:
    profile = [(0, 0), (0.014, 0), (0.015, 0.002), (0.015, 0.13), (0.022, 0.17), (0.022, 0.19), (0, 0.19)]
    return _revolve(profile, 32).rotate((0.0, 90.0, 0.0))


def _sugar_box() -> m3d.Manifold:
    return _box((0.09, 0.045, 0.175))


SPECS: dict[str, ObjectSpec] = {s.name: s for s in [
    ObjectSpec("mug", "GRAB", (0.1053, 0.082, 0.095), "cup with a ring handle, open top", _mug),
    ObjectSpec("wine_glass", "GRAB", (0.08, 0.08, 0.21), "hollow bowl on a stem and foot", _wine_glass),
    ObjectSpec("bottle", "GRAB (water bottle)", (0.066, 0.066, 0.23), "solid bottle with shoulder and neck", _bottle),
    ObjectSpec("can", "YCB / HO3D (tomato soup can)", (0.066, 0.066, 0.122), "cylinder with chamfered rims", _can),
    ObjectSpec("cracker_box", "YCB / HO3D", (0.16, 0.06, 0.21), "box", _cracker_box),
    ObjectSpec("toothpaste", "GRAB", (0.048, 0.032, 0.19), "tube standing on its cap, crimped top", _toothpaste),
    ObjectSpec("toothbrush", "GRAB", (0.014, 0.02, 0.1915), "handle, neck, head with a bristle block", _toothbrush),
    ObjectSpec("apple", "GRAB", (0.0832, 0.0832, 0.078), "lathe-profile apple with a stem", _apple),
    ObjectSpec("banana", "YCB / HO3D", (0.2114, 0.0702, 0.036), "curved, tapered tube lying in the xy-plane",
               _banana),
    ObjectSpec("camera", "GRAB", (0.12, 0.1125, 0.086), "rounded body, lens along -y, grip, button", _camera),
    ObjectSpec("binoculars", "GRAB", (0.118, 0.14, 0.048), "two barrels along y, bridge and hinge", _binoculars),
    ObjectSpec("frying_pan", "GRAB", (0.4099, 0.244, 0.0803), "pan with sloped walls and a long handle",
               _frying_pan),
    ObjectSpec("pitcher", "YCB / HO3D (pitcher base)", (0.1912, 0.144, 0.235), "hollow jug with a handle",
               _pitcher),
    ObjectSpec("bowl", "YCB", (0.16, 0.16, 0.059), "hollow hemispherical bowl", _bowl),
    ObjectSpec("power_drill", "YCB / HO3D", (0.214, 0.07, 0.1915), "body, chuck, pistol grip, battery", _power_drill),
    ObjectSpec("flashlight", "GRAB", (0.19, 0.044, 0.044), "torch lying along x, wider head", _flashlight),
    ObjectSpec("sugar_box", "YCB / HO3D", (0.09, 0.045, 0.175), "box", _sugar_box),
]}

TEST_OBJECTS: tuple[str, ...] = ("mug", "camera", "toothpaste", "wine_glass", "frying_pan", "binoculars")


def list_objects() -> list[str]:
    """Names of the catalogue objects, sorted."""
    return sorted(SPECS)


def _to_trimesh(man: m3d.Manifold) -> trimesh.Trimesh:
    """manifold3d solid -> trimesh (float64), origin moved to the bounding-box centre."""
    mesh = man.to_mesh()
    verts = np.asarray(mesh.vert_properties, dtype=np.float64)[:, :3]
    out = trimesh.Trimesh(verts, np.asarray(mesh.tri_verts, dtype=np.int64), process=True)  # merges coincident verts
    out.apply_translation(-out.bounds.mean(axis=0))
    return out


@lru_cache(maxsize=None)
def _canonical(name: str) -> trimesh.Trimesh:
    """Build (once) the canonical mesh of a catalogue object."""
    mesh = _to_trimesh(SPECS[name].build())
    if not (mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0):
        raise RuntimeError(f"catalogue object {name!r} did not build into a closed, outward-oriented mesh")
    return mesh


def make_object(name: str, seed: int | None = None) -> trimesh.Trimesh:
    """The mesh of catalogue object `name`; seed=None gives the canonical shape, an int a seeded size variation.

    The variation scales x and y by one factor and z by another, both uniform in [0.9, 1.1], about the
    bounding-box centre (which stays the origin). The result is a fresh copy the caller may modify.
    """
    if name not in SPECS:
        raise ValueError(f"name: unknown object {name!r}; valid names are {list_objects()}")
    if seed is not None and (isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0):
        raise ValueError(f"seed: expected None or an integer >= 0, got {seed!r}")
    mesh = _canonical(name).copy()
    if seed is not None:
        sxy, sz = np.random.default_rng(seed).uniform(1.0 - VARIATION, 1.0 + VARIATION, size=2)
        mesh.apply_transform(np.diag([sxy, sxy, sz, 1.0]))
    return mesh
