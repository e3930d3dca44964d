"""Objects the catalogue does not have: a user's mesh (a trimesh.Trimesh or a mesh file) made ready for the methods.

The methods see an object the way they see a catalogue object: a closed, outward-oriented triangle mesh in metres
whose frame has its origin at the bounding-box centre, z up (`make_object`'s convention). `as_object` checks a mesh
against that and moves it there, so that `graspkit.saga.synthesize`, the samplers and the SDF caches take it like
any catalogue name. A mesh that is not closed, is inside out, has faces without area, is made of overlapping parts or
has a part turned inside out, or whose size says millimetres gets an error naming the argument and what was expected,
never a silent fix (vertices that no face uses are dropped: they are not part of the surface; one with NaN
coordinates is still refused, as a sign of a damaged file). One smaller or larger than every catalogue object (8-41 cm;
the methods are trained on 12-24 cm and evaluated on the rest) is taken with a UserWarning.
"""
from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import torch
import trimesh

from graspkit.checks import GraspkitWarning, user_stacklevel
from graspkit.objects.catalogue import list_objects, make_object
from graspkit.objects.distance import require_closed, require_face_areas
from graspkit.objects.sampling import sample_surface
from graspkit.objects.sdf import winding_number
from graspkit.paths import expand_home

# m: the largest side a hand-held object may have. The grasp models were trained on objects of 8-41 cm (the
# catalogue); 0.6 m leaves room for larger ones and still tells metres from millimetres or centimetres.
MAX_SIDE = 0.6
MIN_SIDE = 0.01
# m: the catalogue's largest sides, apple to frying pan: the objects the methods are trained (12-24 cm, the train
# split) and evaluated on (the held-out test objects span 10-41 cm)
CATALOGUE_SIDES = (0.08, 0.41)
SOLID_SAMPLES = 512      # surface points of the one-solid check (solid_problem)
SOLID_OFFSET = 1e-5      # how far behind / in front of the surface it looks, as a share of the largest side
MIN_BAD = 2              # samples that must disagree before a mesh is refused
PART_SAMPLES = 64        # more samples on each connected part of a mesh of several (down to 4 * MIN_BAD when many)
SOLID_PAIRS = 10_000_000  # at most this many (sample, face) pairs: fewer samples on meshes of over 20,000 faces
MANY_FACES = 20_000      # above this a user mesh gets a note: its collision grid takes minutes (docs/objects.md)
Y_UP_SUFFIXES = (".glb", ".gltf")   # glTF 2.0 is +y up by specification: turned to z up on reading
Y_UP_TO_Z_UP = np.array([[1.0, 0, 0, 0], [0, 0, -1, 0], [0, 1, 0, 0], [0, 0, 0, 1]])   # +90 deg about x: y -> z


def as_object(obj: str | Path | trimesh.Trimesh, argument: str = "obj") -> tuple[str, trimesh.Trimesh]:
    """A catalogue name, a mesh file (.obj, .ply, .stl, .glb, ...) or a trimesh.Trimesh -> (name, mesh).

    The mesh comes back as a copy in the object frame: closed and outward-oriented, metres, origin at its
    bounding-box centre (axes kept as given: z is up; a .glb / .gltf file is y up by the glTF specification and
    is turned +90 deg about x, so that its up becomes z, as graspkit's own GLB exports expect). The name is the
    catalogue name, the file's stem, or the mesh's `metadata["name"]` (else "object"). A str naming a catalogue
    object is that object even when a file of that name lies in the working folder; pass a Path (or "./mug") for
    the file.
    """
    if isinstance(obj, trimesh.Trimesh):
        return str(obj.metadata.get("name") or "object"), _noted(_checked(obj.copy(), argument), "the mesh")
    if isinstance(obj, (str, Path)):
        path = Path(obj)       # a catalogue name as a str is the catalogue object, even beside a file of that name
        try:
            path = expand_home(path)                     # `--object=~/cup.obj`: the shell leaves that `~` alone
            found = path.is_file()
        except (OSError, RuntimeError) as e:             # a name past 255 bytes; `~user` of no one
            raise ValueError(f"{argument}: {obj}: {getattr(e, 'strerror', None) or e}") from None
        if str(obj) in list_objects() and (isinstance(obj, str) or not found):
            return str(obj), make_object(str(obj))
        if found:
            try:            # unprocessed first: processing would drop NaN vertices and their faces without a word
                mesh = trimesh.load(path, force="mesh", process=False)
            except Exception as e:   # trimesh raises many kinds for unreadable files
                raise ValueError(f"{argument}: could not read a mesh from {path}: {e}") from e
            if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
                raise ValueError(f"{argument}: {path} holds no triangle mesh")
            if not np.isfinite(mesh.vertices).all():
                raise ValueError(f"{argument} ({path}): the mesh has NaN or infinite vertex coordinates")
            mesh.process()
            if path.suffix.lower() in Y_UP_SUFFIXES:
                mesh.apply_transform(Y_UP_TO_Z_UP)
            return path.stem, _noted(_checked(mesh, f"{argument} ({path})"), str(path))
        if path.suffix or len(path.parts) > 1:
            raise ValueError(f"{argument}: no such mesh file {str(path)!r} (nor a catalogue name {list_objects()})")
        raise ValueError(f"{argument}: unknown object {str(obj)!r}; expected a catalogue name {list_objects()}, "
                         "a mesh file, or a trimesh.Trimesh")
    raise ValueError(f"{argument}: expected a catalogue name, a mesh file or a trimesh.Trimesh, "
                     f"got {type(obj).__name__}")


def size_note(mesh: trimesh.Trimesh) -> str:
    """'' when the mesh's largest side lies within the catalogue's (CATALOGUE_SIDES: the objects the methods are
    trained and evaluated on), else a sentence saying how far outside."""
    side, (lo, hi) = float((mesh.bounds[1] - mesh.bounds[0]).max()), CATALOGUE_SIDES
    if lo <= side <= hi:
        return ""
    return (f"its largest side is {100 * side:.1f} cm, {'below' if side < lo else 'above'} the "
            f"{100 * lo:g}-{100 * hi:g} cm of the catalogue objects the methods are trained and evaluated on; "
            "expect the grasp to miss or penetrate it")


def _noted(mesh: trimesh.Trimesh, what: str) -> trimesh.Trimesh:
    """`mesh` (`what`: its file, or 'the mesh'), after a UserWarning when its size is outside the trained range
    (`size_note`; attributed to as_object, so that the same mesh checked twice in one run warns once)."""
    note = size_note(mesh)
    if note:
        warnings.warn(f"{what}: {note}", GraspkitWarning, stacklevel=user_stacklevel())
    if len(mesh.faces) > MANY_FACES:
        warnings.warn(f"{what}: {len(mesh.faces):,} faces: the exact distances and the 2 mm collision grid that SAGA "
                      "and GOAL build for it grow with the faces (about 1.5 min at 20,000, minutes more at 80,000; the "
                      "grid is kept in the cache); a decimated copy (trimesh's simplify_quadric_decimation) runs as "
                      "well", GraspkitWarning, stacklevel=user_stacklevel())
    return mesh


def _checked(mesh: trimesh.Trimesh, argument: str) -> trimesh.Trimesh:
    """The mesh checked (finite, closed, outward, no zero-area faces, solids that do not overlap, metres) and moved to its
    bounding-box centre; vertices no face uses are dropped (they do not change the surface)."""
    if not np.isfinite(mesh.vertices).all():
        raise ValueError(f"{argument}: the mesh has NaN or infinite vertex coordinates")
    mesh.remove_unreferenced_vertices()
    require_face_areas(torch.as_tensor(mesh.vertices), torch.as_tensor(mesh.faces), argument)   # before the
    if not mesh.is_watertight:                                  # closure test, which such faces fail with a wrong hint
        merged = mesh.copy()
        merged.merge_vertices()
        many = int((np.unique(merged.edges_sorted, axis=0, return_counts=True)[1] > 2).sum())
        hint = ("its faces do not share vertices where they meet: trimesh's merge_vertices() joins them" if
                merged.is_watertight else
                f"{many} edges are used by more than two faces: parts that meet along an edge or a face, or a fin; "
                "parts that overlap or share a face become one surface by a boolean union (trimesh.boolean.union), "
                "parts that touch along an edge alone must first be moved apart or into each other" if many else
                "trimesh's fill_holes() or a remesh may fix it")
        raise ValueError(f"{argument}: the mesh is not closed (watertight); signed distances, contact and "
                         f"penetration need a closed surface ({hint})")
    if not mesh.is_winding_consistent:
        raise ValueError(f"{argument}: the mesh's faces are not consistently wound (trimesh's fix_winding())")
    if not mesh.volume > 0:
        raise ValueError(f"{argument}: the mesh is inside out (negative volume {mesh.volume:.3g}); "
                         "its normals must point outward (trimesh's invert())")
    require_closed(torch.as_tensor(mesh.vertices), torch.as_tensor(mesh.faces), argument)
    side = float((mesh.bounds[1] - mesh.bounds[0]).max())
    if not MIN_SIDE <= side <= MAX_SIDE:
        hint = ("; in metres that is larger than a hand-held object: a mesh in millimetres needs apply_scale(0.001), "
                "one in centimetres apply_scale(0.01)" if side > MAX_SIDE else
                "; in metres that is smaller than a hand-held object")
        raise ValueError(f"{argument}: expected a hand-held object in metres (largest side {MIN_SIDE}-{MAX_SIDE} m), "
                         f"got {side:.4g}{hint}")
    problem = solid_problem(mesh)
    if problem:
        raise ValueError(f"{argument}: {problem}")
    mesh.apply_translation(-(mesh.bounds[0] + mesh.bounds[1]) / 2.0)
    return mesh


def solid_problem(mesh: trimesh.Trimesh, samples: int = SOLID_SAMPLES) -> str:
    """'' if the closed mesh bounds solids that do not overlap (separate pieces are fine), else what is wrong: the
    generalized winding number just behind and just in front of `samples` surface points (area-uniform, seed 0, and
    up to PART_SAMPLES more on each connected part) must be 1 and 0. Parts that overlap (2 behind the surface), parts
    that touch along a shared face (1 in front) or a part turned inside out (-1 in front) pass the closed-and-outward
    checks (the total volume is positive) but give signed distances of the wrong sign; a cavity (an inner surface
    facing inwards) is fine."""
    samples = min(samples, max(64, SOLID_PAIRS // len(mesh.faces)))      # bounded time on large meshes
    labels = trimesh.graph.connected_component_labels(mesh.face_adjacency, node_count=len(mesh.faces))
    pts, nrm = sample_surface(mesh, samples, seed=0)
    pts, nrm = _part_samples(mesh, labels, samples, pts, nrm)
    eps = SOLID_OFFSET * float((mesh.bounds[1] - mesh.bounds[0]).max())
    w = _winding_by_part(np.concatenate([pts - eps * nrm, pts + eps * nrm]), mesh, labels, 2 * eps)
    behind, front = w[:len(pts)], w[len(pts):]
    overlap, inverted = behind > 1.5, (behind < 0.5) | (front < -0.5)
    inner = (front > 0.5) & ~overlap           # solid on both sides: parts that touch along a shared face
    if max(overlap.sum(), inverted.sum(), inner.sum()) < MIN_BAD:   # a lone sample at a sharp edge is not a part
        return ""
    share = lambda m: (f"{100 * m[:samples].mean():.1f} % of the surface" if m[:samples].any()  # noqa: E731
                       else "a small part of the surface")
    union = ("signed distances and volumes need one closed surface around the solid: a boolean union of the parts "
             "(trimesh.boolean.union, manifold3d) makes one")
    if overlap.sum() >= MIN_BAD:
        return f"parts of the mesh overlap or intersect themselves ({share(overlap)} lies inside another part); {union}"
    if inner.sum() >= MIN_BAD:
        return (f"parts of the mesh touch along shared faces ({share(inner)} has solid on both sides, so the "
                f"distance to it is not a distance to the solid's surface); {union}")
    return (f"a part of the mesh is inside out ({share(inverted)} faces inwards with no solid behind it); "
            "its normals must point outward (that part's invert())")


def _winding_by_part(q: np.ndarray, mesh: trimesh.Trimesh, labels: np.ndarray, pad: float) -> np.ndarray:
    """Winding number (n,) of the closed mesh at points q (n,3), summed over its connected parts (`labels` per face),
    each part only at the points within `pad` of its box: outside, a closed part adds 0 (to rounding), and a scan of
    hundreds of fragments took minutes against every face."""
    parts = np.unique(labels)
    if len(parts) < 2:
        return winding_number(q, mesh).numpy()
    w = np.zeros(len(q))
    for k in parts:
        faces = mesh.faces[labels == k]
        corners = mesh.vertices[faces].reshape(-1, 3)
        near = np.all((q >= corners.min(0) - pad) & (q <= corners.max(0) + pad), axis=1)
        if near.any():
            w[near] += winding_number(q[near], (mesh.vertices, faces)).numpy()
    return w


def _part_samples(mesh: trimesh.Trimesh, labels: np.ndarray, samples: int, pts: np.ndarray, nrm: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray]:
    """The area-uniform samples (n,3) and normals, with PART_SAMPLES more on each connected part (`labels` per face) of
    a mesh of several (seed 1): a small part (a knob sunk into a ball) gets too few area-uniform samples to be seen
    overlapping."""
    parts = np.unique(labels)
    if len(parts) < 2:
        return pts, nrm
    per = max(MIN_BAD * 4, min(PART_SAMPLES, samples // len(parts)))
    extra = [sample_surface(mesh.submesh([np.flatnonzero(labels == k)], append=True), per, seed=1) for k in parts]
    return np.concatenate([pts] + [e[0] for e in extra]), np.concatenate([nrm] + [e[1] for e in extra])


__all__ = ["MAX_SIDE", "MIN_SIDE", "as_object", "solid_problem"]
