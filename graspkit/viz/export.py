"""Meshes to files other tools open (Blender, MeshLab, three.js / glTF viewers): GLB, OBJ, PLY; and a body
sequence as an animated GLB (morph targets).

Axes: the world is z up; glTF is y up by specification, so GLB files are written rotated -90 deg about x,
(x, y, z) -> (x, z, -y), which keeps the world's up pointing up in every glTF viewer. OBJ and PLY have no
up-axis convention and are written in world coordinates unless y_up=True. All files are written atomically.

Per format:
- .glb: a trimesh.Scene, one named node (and mesh) per entry, colours as PBR base colours;
- .obj: one `o <name>` group per entry, colours as per-vertex RGB after each `v` (MeshLab / Blender read them);
- .ply: one mesh (entries concatenated, names lost), colours as vertex colours.
"""
from __future__ import annotations

import json
import os
import struct
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import trimesh
from matplotlib.colors import to_rgba
from trimesh.visual import TextureVisuals
from trimesh.visual.material import PBRMaterial

from graspkit.paths import check_suffix, publish, temp_beside, write_atomic  # noqa: F401 (re-exported: callers import them here)
from graspkit.viz.scene import as_array, as_mesh
from graspkit.viz.style import OBJECT, SEQUENCE, SKIN

if TYPE_CHECKING:
    from graspkit.body import BodyModel
    from graspkit.data.motion import Motion

FORMATS = (".glb", ".obj", ".ply")
Z_UP_TO_Y_UP = np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]])  # rotation of -90 deg about x: (x, y, z) -> (x, z, -y)


def _default_color(name: str, k: int) -> Any:
    """Skin for the first entry or names containing 'body', else the object colour, then the sequence palette."""
    if "body" in name or "human" in name or (k == 0 and "obj" not in name):
        return SKIN
    return OBJECT if k <= 1 else SEQUENCE[k % len(SEQUENCE)]


def _as_trimesh(item: Any, name: str) -> tuple[np.ndarray, np.ndarray]:
    """(vertices (V,3), faces (F,3)) from a (vertices, faces) pair or a trimesh.Trimesh."""
    if isinstance(item, trimesh.Trimesh):
        v, f = np.asarray(item.vertices, float), np.asarray(item.faces, np.int64)
    elif not isinstance(item, (tuple, list)) or len(item) != 2:
        raise ValueError(f"meshes[{name!r}]: expected (vertices, faces) or a trimesh.Trimesh, "
                         f"got {type(item).__name__}")
    else:
        v, f = as_mesh(item[0], item[1], f"meshes[{name!r}]")
    if not np.isfinite(v).all():
        raise ValueError(f"meshes[{name!r}] vertices: contain NaN or Inf")
    return v, f


def _check_objects(objects: Any, body: str = "body") -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Validated static objects {name: (vertices, faces) or Trimesh} (None: none) as {name: (V,3), (F,3)}; no object
    may take the body mesh's name `body` (it would replace or shadow the body in the scene)."""
    if objects is None:
        return {}
    if not isinstance(objects, Mapping):
        raise TypeError(f"objects: expected a mapping {{name: (vertices, faces) or Trimesh}}, "
                        f"got {type(objects).__name__}")
    if body in map(str, objects):
        raise ValueError(f"objects: {body!r} is the body mesh's name; give the object another")
    return {str(k): _as_trimesh(item, str(k)) for k, item in objects.items()}


def _check_stride_fps(stride: Any, fps: Any) -> None:
    """ValueError / TypeError unless stride is an integer >= 1 and fps a finite number > 0."""
    if isinstance(stride, bool) or not isinstance(stride, (int, np.integer)):
        raise TypeError(f"stride: expected an integer >= 1, got {type(stride).__name__}")
    if stride < 1:
        raise ValueError(f"stride: expected an integer >= 1, got {stride}")
    from graspkit.data.motion import check_fps

    check_fps(fps)


def png_bytes(fig: Any, dpi: float | None = None) -> bytes:
    """A matplotlib figure as PNG bytes; the figure is closed (widgets and reports draw a fresh one each time)."""
    import io

    import matplotlib.pyplot as plt

    buf = io.BytesIO()
    try:
        fig.savefig(buf, format="png", dpi=dpi)
    finally:
        plt.close(fig)
    return buf.getvalue()


def save_png(fig: Any, path: str | os.PathLike, dpi: float | None = None) -> Path:
    """Write a matplotlib figure as a PNG atomically (rendered in memory, then a temporary file renamed); closes it."""
    check_suffix(path, ".png")
    return write_atomic(Path(path), png_bytes(fig, dpi))



def export_scene(meshes: Mapping[str, Any], path: str | os.PathLike, colors: Mapping[str, Any] | None = None,
                 y_up: bool | None = None) -> Path:
    """Write named meshes {name: (vertices (V,3), faces (F,3)) or trimesh.Trimesh} (z-up world) to path
    (.glb / .obj / .ply, from the suffix); colors {name: matplotlib colour}; y_up defaults to True for .glb
    only (see module doc). Vertices keep their order and count (no merging). Returns the path."""
    path = Path(path)
    fmt = path.suffix.lower()
    if fmt not in FORMATS:
        raise ValueError(f"path: expected a file ending in one of {FORMATS}, got {path.name!r}")
    if not meshes:
        raise ValueError("meshes: nothing to export")
    rot = Z_UP_TO_Y_UP if (fmt == ".glb" if y_up is None else y_up) else np.eye(3)
    scene = trimesh.Scene()
    for k, (name, item) in enumerate(meshes.items()):
        v, f = _as_trimesh(item, name)
        rgba = np.round(np.asarray(to_rgba((colors or {}).get(name, _default_color(name, k)))) * 255).astype(np.uint8)
        mesh = trimesh.Trimesh(v @ rot.T, f, process=False)
        if fmt == ".glb":
            mesh.visual = TextureVisuals(material=PBRMaterial(name=name, baseColorFactor=rgba, metallicFactor=0.0,
                                                              roughnessFactor=0.8, doubleSided=True))
        else:
            mesh.visual.vertex_colors = rgba
        scene.add_geometry(mesh, node_name=name, geom_name=name)
    if fmt == ".ply":
        data = trimesh.util.concatenate(list(scene.geometry.values())).export(file_type="ply")
    else:
        data = scene.export(file_type=fmt[1:])
    return write_atomic(path, data)


# ---- animated GLB: one mesh whose morph targets are the frames, played by a weights animation ----

_FLOAT, _UINT = 5126, 5125  # glTF componentType
_ARRAY_BUFFER, _ELEMENT_ARRAY_BUFFER = 34962, 34963


class _GLBBuilder:
    """Accumulates one binary buffer and the glTF JSON that describes its accessors."""

    def __init__(self) -> None:
        self.blob = bytearray()
        self.gltf: dict[str, Any] = {"asset": {"version": "2.0", "generator": "graspkit.viz.export"},
                                     "buffers": [], "bufferViews": [], "accessors": [], "meshes": [], "nodes": [],
                                     "materials": [], "scenes": [{"nodes": []}], "scene": 0}

    def accessor(self, a: np.ndarray, kind: str, target: int | None = None) -> int:
        """Append a (float32 VEC3 / SCALAR, or uint32 SCALAR) array; returns its accessor index."""
        while len(self.blob) % 4:
            self.blob.append(0)
        view: dict[str, Any] = {"buffer": 0, "byteOffset": len(self.blob), "byteLength": a.nbytes}
        if target is not None:
            view["target"] = target
        self.blob += a.tobytes()
        self.gltf["bufferViews"].append(view)
        acc: dict[str, Any] = {"bufferView": len(self.gltf["bufferViews"]) - 1, "count": len(a), "type": kind,
                               "componentType": _UINT if a.dtype == np.uint32 else _FLOAT}
        if a.dtype == np.float32:  # POSITION (also in morph targets) and animation inputs need min / max
            acc["min"] = np.atleast_1d(a.min(0)).astype(float).tolist()
            acc["max"] = np.atleast_1d(a.max(0)).astype(float).tolist()
        self.gltf["accessors"].append(acc)
        return len(self.gltf["accessors"]) - 1

    def mesh_node(self, name: str, v: np.ndarray, f: np.ndarray, color: Any, targets: np.ndarray | None = None) -> int:
        """Add a mesh (V,3) / (F,3), its material and node, and optional morph targets (K,V,3); returns the mesh."""
        g = self.gltf
        g["materials"].append({"name": name, "doubleSided": True, "pbrMetallicRoughness": {
            "baseColorFactor": list(map(float, to_rgba(color))), "metallicFactor": 0.0, "roughnessFactor": 0.8}})
        prim: dict[str, Any] = {"attributes": {"POSITION": self.accessor(v.astype(np.float32), "VEC3", _ARRAY_BUFFER)},
                                "indices": self.accessor(f.astype(np.uint32).reshape(-1), "SCALAR",
                                                         _ELEMENT_ARRAY_BUFFER),
                                "material": len(g["materials"]) - 1, "mode": 4}
        mesh: dict[str, Any] = {"name": name, "primitives": [prim]}
        if targets is not None and len(targets):
            prim["targets"] = [{"POSITION": self.accessor(t.astype(np.float32), "VEC3", _ARRAY_BUFFER)}
                               for t in targets]
            mesh["weights"] = [0.0] * len(targets)
            mesh["extras"] = {"targetNames": [f"frame_{k + 1:04d}" for k in range(len(targets))]}
        g["meshes"].append(mesh)
        g["nodes"].append({"name": name, "mesh": len(g["meshes"]) - 1})
        g["scenes"][0]["nodes"].append(len(g["nodes"]) - 1)
        return len(g["meshes"]) - 1

    def to_bytes(self) -> bytes:
        """The GLB container: 12-byte header, JSON chunk (space-padded), BIN chunk (zero-padded)."""
        self.gltf["buffers"] = [{"byteLength": len(self.blob)}]
        js = json.dumps(self.gltf, separators=(",", ":")).encode()
        js += b" " * (-len(js) % 4)
        bin_ = bytes(self.blob) + b"\0" * (-len(self.blob) % 4)
        total = 12 + 8 + len(js) + 8 + len(bin_)
        return (struct.pack("<III", 0x46546C67, 2, total) + struct.pack("<II", len(js), 0x4E4F534A) + js
                + struct.pack("<II", len(bin_), 0x004E4942) + bin_)


def drawn_frames(total: int, stride: int) -> list[int]:
    """The frames of a clip of `total` that an animation or an animated GLB shows: every `stride`-th and the last
    (a reach or grasp ends there)."""
    ticks = list(range(0, total, stride))
    return ticks if ticks[-1] == total - 1 else ticks + [total - 1]


def export_sequence_glb(vertices: Any, faces: Any, path: str | os.PathLike, fps: float = 30.0,
                        objects: Mapping[str, Any] | None = None, color: Any = SKIN,
                        colors: Mapping[str, Any] | None = None, stride: int = 1, y_up: bool = True,
                        name: str = "body") -> Path:
    """An animated GLB of a body sequence vertices (T,V,3) with faces (F,3) at fps, plus static objects
    {name: (vertices, faces)}. Frame 0 is the mesh, frames 1..T-1 are morph targets (offsets from frame 0),
    and an animation drives their weights with LINEAR interpolation at t = k / fps for the kept frames k (every
    `stride`-th, and always the last, so the clip ends where the motion ends), so viewers (Blender: shape keys;
    three.js, gltf viewers) play it. Size ~ 12 * T * V bytes (10k vertices, 300 frames: 36 MB): use stride.
    trimesh loads the file as the static frame 0. Returns the path."""
    check_suffix(path, ".glb")          # a .gltf is JSON text by the glTF 2.0 specification
    verts = as_array(vertices, "vertices", (None, None, 3))
    f = as_array(faces, "faces", (None, 3), dtype=np.int64)
    _check_stride_fps(stride, fps)
    if len(verts) == 0:
        raise ValueError("vertices: need at least one frame, got 0")
    if not np.isfinite(verts).all():
        raise ValueError("vertices: contain NaN or Inf")
    objs = _check_objects(objects, name)
    kept = np.asarray(drawn_frames(len(verts), stride))
    verts = verts[kept]
    if f.size and (f.min() < 0 or f.max() >= verts.shape[1]):
        raise ValueError(f"faces: indices must lie in [0, {verts.shape[1]}), got [{f.min()}, {f.max()}]")
    rot = Z_UP_TO_Y_UP if y_up else np.eye(3)
    verts = verts @ rot.T
    glb = _GLBBuilder()
    mesh = glb.mesh_node(name, verts[0], f, color, verts[1:] - verts[0])
    for k, (oname, (ov, of)) in enumerate(objs.items()):
        glb.mesh_node(oname, ov @ rot.T, of, (colors or {}).get(oname, _default_color(oname, k + 1)))
    if len(verts) > 1:
        n = len(verts)
        times = (kept / fps).astype(np.float32)
        weights = np.zeros((n, n - 1), np.float32)
        weights[np.arange(1, n), np.arange(n - 1)] = 1.0  # frame k shows target k - 1 fully; frame 0 shows none
        sampler = {"input": glb.accessor(times, "SCALAR"), "output": glb.accessor(weights.reshape(-1), "SCALAR"),
                   "interpolation": "LINEAR"}
        glb.gltf["animations"] = [{"name": f"{name}_motion", "samplers": [sampler],
                                   "channels": [{"sampler": 0, "target": {"node": mesh, "path": "weights"}}]}]
    return write_atomic(path, glb.to_bytes())


def read_glb(path: str | os.PathLike) -> tuple[dict[str, Any], bytes]:
    """The JSON document and binary chunk of a GLB file; ValueError naming the file when it is not one, or is cut
    short (the header's total length against the file's)."""
    data = Path(path).read_bytes()
    if len(data) < 20:
        raise ValueError(f"path: {path} is not a glTF 2.0 binary file (only {len(data)} bytes)")
    magic, version, total = struct.unpack_from("<III", data, 0)
    if magic != 0x46546C67 or version != 2:
        raise ValueError(f"path: {path} is not a glTF 2.0 binary file")
    if total != len(data):
        raise ValueError(f"path: {path} is cut short or padded ({len(data)} bytes; its header says {total})")
    n_json, _ = struct.unpack_from("<II", data, 12)
    off = 20 + n_json
    try:
        gltf = json.loads(data[20:off])
        blob = None
        while off < len(data):                          # chunks of unknown type are skipped, as glTF 2.0 asks
            n, kind = struct.unpack_from("<II", data, off)
            chunk = data[off + 8:off + 8 + n]
            if len(chunk) != n:
                raise ValueError(f"a chunk holds {len(chunk)} of its {n} bytes")
            if kind == 0x004E4942 and blob is None:     # "BIN\0"
                blob = chunk
            off += 8 + n
        blob = blob or b""
    except (ValueError, struct.error) as e:
        raise ValueError(f"path: {path} is a damaged glTF binary file ({e})") from None
    return gltf, blob


def load_sequence_glb(path: str | os.PathLike, name: str = "body",
                      y_up: bool = True) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Read back a file from export_sequence_glb: vertices (T,V,3) in the z-up world, faces (F,3), times (T,) s."""
    gltf, blob = read_glb(path)

    def arr(i: int) -> np.ndarray:
        acc = gltf["accessors"][i]
        view = gltf["bufferViews"][acc["bufferView"]]
        if acc.get("componentType") not in _COMPONENTS or acc.get("type") not in _WIDTH:
            raise ValueError(f"accessor {i} holds {acc.get('type')} of component type {acc.get('componentType')}, "
                             f"expected SCALAR or VEC3 of {sorted(_COMPONENTS)}")
        dtype = np.dtype(_COMPONENTS[acc["componentType"]])
        n = acc["count"] * _WIDTH[acc["type"]]
        if "sparse" in acc or view.get("byteStride") not in (None, _WIDTH[acc["type"]] * dtype.itemsize):
            raise ValueError(f"accessor {i} is sparse or interleaved, which this reader does not take")
        start = view.get("byteOffset", 0) + acc.get("byteOffset", 0)
        if start + n * dtype.itemsize > view.get("byteOffset", 0) + view["byteLength"]:
            raise ValueError(f"accessor {i} reaches past its buffer view")
        a = np.frombuffer(blob, dtype, n, start)
        return a.reshape(-1, 3) if acc["type"] == "VEC3" else a

    try:
        k = next((i for i, m in enumerate(gltf.get("meshes", [])) if m.get("name") == name), None)
        if k is None:
            raise LookupError(f"name: no mesh {name!r} in {path}")
        prim = gltf["meshes"][k]["primitives"][0]
        base = arr(prim["attributes"]["POSITION"]).astype(np.float64)
        frames = [base] + [base + arr(t["POSITION"]) for t in prim.get("targets", [])]
        times = np.zeros(1)
        for anim in gltf.get("animations", []):
            times = arr(anim["samplers"][0]["input"]).astype(np.float64)
        faces = arr(prim["indices"]).reshape(-1, 3).astype(np.int64)
    except LookupError as e:
        if str(e).startswith("name:"):
            raise ValueError(str(e)) from None
        raise ValueError(f"path: {path} is not a sequence GLB as export_sequence_glb writes it (missing {e})") from None
    except (ValueError, TypeError) as e:
        raise ValueError(f"path: {path} is not a sequence GLB as export_sequence_glb writes it ({e})") from None
    rot = Z_UP_TO_Y_UP if y_up else np.eye(3)
    return np.stack(frames) @ rot, faces, times


# glTF 2.0 accessor component types (5121 unsigned byte, 5123 unsigned short, 5125 unsigned int, 5126 float) and the
# number of components in an item of each accessor type this reader takes
_COMPONENTS = {5121: np.uint8, 5123: np.uint16, 5125: np.uint32, 5126: np.float32}
_WIDTH = {"SCALAR": 1, "VEC3": 3}


def export_motion(motion: Motion, bm: BodyModel, folder: str | os.PathLike, name: str,
                  objects: Mapping[str, Any] | None = None, stride: int = 2) -> dict[str, Path]:
    """A whole sequence (graspkit.data.Motion) for other tools: `<name>.npz` (AMASS-style SMPL-X parameters with
    AMASS's per-part keys too, loads in the smplx package), `<name>.glb` (animated: morph targets every `stride`
    frames and the last) and `<name>_final.glb`
    (the last frame with the static `objects` {name: (vertices, faces) or Trimesh}, through trimesh). Returns
    {'npz', 'glb', 'final_glb'} paths; every file is written atomically."""
    from graspkit.data.formats import check_motion, save_motion

    folder = Path(folder)
    if not isinstance(name, str) or not name or Path(name).name != name:
        raise ValueError(f"name: expected a plain file stem, got {name!r}")
    check_motion(motion)                     # everything is checked before the first file is written
    _check_stride_fps(stride, motion.fps)
    _check_objects(objects)
    v = motion_vertices(motion, bm)
    if not np.isfinite(v).all():
        raise ValueError("motion: its mesh vertices on bm contain NaN or Inf")
    faces = np.asarray(bm.faces, np.int64)
    for target in (folder / f"{name}.npz", folder / f"{name}.glb", folder / f"{name}_final.glb"):
        if target.is_dir():
            raise ValueError(f"name: {target} is a folder; expected a file there (or none)")
    out = {"npz": save_motion(folder / f"{name}.npz", motion, amass_keys=True),
           "glb": export_sequence_glb(v, faces, folder / f"{name}.glb", fps=motion.fps, objects=objects,
                                      stride=stride),
           "final_glb": export_scene({"body": (v[-1], faces), **dict(objects or {})}, folder / f"{name}_final.glb")}
    return out


def motion_vertices(motion: Motion, bm: BodyModel, chunk: int = 64) -> np.ndarray:
    """Mesh vertices (T,V,3) of a Motion on body model bm as a float32 numpy array."""
    if motion.num_frames == 0:
        raise ValueError("motion: has no frames, expected at least one")
    return np.concatenate([v.numpy().astype(np.float32) for _, v in motion.iter_vertices(bm, chunk=chunk)])
