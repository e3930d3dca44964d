"""Objects the catalogue does not have: a user's mesh (a trimesh.Trimesh or a mesh file) made ready for the methods.

The methods see an object the way they see a catalogue object: a closed, outward-oriented triangle mesh in metres
whose frame has its origin at the bounding-box centre, z up (`make_object`'s convention). `as_object` checks a mesh
against that and moves it there, so that `graspkit.saga.synthesize`, the samplers and the SDF caches take it like
any catalogue name. A mesh that is not closed, is inside out, or whose size says millimetres gets an error naming the
argument and what was expected, never a silent fix.
"""
from __future__ import annotations

from pathlib import Path

import trimesh

from graspkit.objects.catalogue import list_objects, make_object

# m: the largest side a hand-held object may have. The grasp models were trained on objects of 8-41 cm (the
# catalogue); 0.6 m leaves room for larger ones and still tells metres from millimetres or centimetres.
MAX_SIDE = 0.6
MIN_SIDE = 0.01


def as_object(obj: str | Path | trimesh.Trimesh, argument: str = "obj") -> tuple[str, trimesh.Trimesh]:
    """A catalogue name, a mesh file (.obj, .ply, .stl, .glb, ...) or a trimesh.Trimesh -> (name, mesh).

    The mesh comes back as a copy in the object frame: closed and outward-oriented, metres, origin at its
    bounding-box centre (axes kept as given: z is up). The name is the catalogue name, the file's stem, or the
    mesh's `metadata["name"]` (else "object").
    """
    if isinstance(obj, trimesh.Trimesh):
        return str(obj.metadata.get("name") or "object"), _checked(obj.copy(), argument)
    if isinstance(obj, (str, Path)):
        if isinstance(obj, str) and obj in list_objects():
            return obj, make_object(obj)
        path = Path(obj)
        if path.is_file():
            try:
                mesh = trimesh.load(path, force="mesh", process=True)
            except Exception as e:   # trimesh raises many kinds for unreadable files
                raise ValueError(f"{argument}: could not read a mesh from {path}: {e}") from e
            if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
                raise ValueError(f"{argument}: {path} holds no triangle mesh")
            return path.stem, _checked(mesh, f"{argument} ({path})")
        if path.suffix or len(path.parts) > 1:
            raise ValueError(f"{argument}: no such mesh file {str(path)!r} (nor a catalogue name {list_objects()})")
        raise ValueError(f"{argument}: unknown object {str(obj)!r}; expected a catalogue name {list_objects()}, "
                         "a mesh file, or a trimesh.Trimesh")
    raise ValueError(f"{argument}: expected a catalogue name, a mesh file or a trimesh.Trimesh, "
                     f"got {type(obj).__name__}")


def _checked(mesh: trimesh.Trimesh, argument: str) -> trimesh.Trimesh:
    """The mesh checked (closed, outward, metres) and moved to its bounding-box centre."""
    if not mesh.is_watertight:
        raise ValueError(f"{argument}: the mesh is not closed (watertight); signed distances, contact and "
                         "penetration need a closed surface (trimesh's fill_holes() or a remesh may fix it)")
    if not mesh.is_winding_consistent:
        raise ValueError(f"{argument}: the mesh's faces are not consistently wound (trimesh's fix_winding())")
    if not mesh.volume > 0:
        raise ValueError(f"{argument}: the mesh is inside out (negative volume {mesh.volume:.3g}); "
                         "its normals must point outward (trimesh's invert())")
    side = float((mesh.bounds[1] - mesh.bounds[0]).max())
    if not MIN_SIDE <= side <= MAX_SIDE:
        hint = ("; in metres that is larger than a hand-held object: a mesh in millimetres needs apply_scale(0.001), "
                "one in centimetres apply_scale(0.01)" if side > MAX_SIDE else
                "; in metres that is smaller than a hand-held object")
        raise ValueError(f"{argument}: expected a hand-held object in metres (largest side {MIN_SIDE}-{MAX_SIDE} m), "
                         f"got {side:.4g}{hint}")
    mesh.apply_translation(-(mesh.bounds[0] + mesh.bounds[1]) / 2.0)
    return mesh


__all__ = ["MAX_SIDE", "MIN_SIDE", "as_object"]
