"""Caches for grasp synthesis: per-object SDF grids stored in graspkit's cache folder (built once per machine;
a few are shipped in data_stubs/sdf for the tests and lessons 04-05). The grasp generator uses 64 nodes along the
longest side; GraspPose-Opt's collision terms use `collision_sdf_grid` (cells of at most 2 mm)."""
from __future__ import annotations

import hashlib
import math
import warnings
from pathlib import Path

import numpy as np
import torch
import trimesh

from graspkit.checks import GraspkitWarning, user_stacklevel
from graspkit.objects.catalogue import make_object
from graspkit.objects.sdf import SDFGrid
from graspkit.paths import DATA_STUBS, read_cache

SDF_PADDING = 0.03
# The grid algorithm's version, part of every cached grid's file name: raise it whenever SDFGrid.from_mesh or
# signed_distance would give other values for the same mesh, so that no cache built by an earlier version is read.
SDF_VERSION = 1
# m: the largest cell of the grids the optimisers' collision terms use (GraspPose-Opt's E_colli). A fixed 64 nodes
# gives cells of 2.9-7.5 mm on the larger objects and misses most points 1-2 mm inside their thin walls (frying pan,
# wine glass, pitcher): E_colli cannot see a finger there. Measured in docs/objects.md.
COLLISION_CELL = 0.002


def _mesh(obj: str | trimesh.Trimesh) -> trimesh.Trimesh:
    """A catalogue object's canonical mesh, or the mesh itself (a user's object, see graspkit.objects.user)."""
    return make_object(obj) if isinstance(obj, str) else obj


def mesh_digest(obj: str | trimesh.Trimesh) -> str:
    """A short hash of catalogue object `obj`'s canonical mesh, or of a given mesh, with the grid's padding and
    SDF_VERSION (a cached grid is rebuilt when the mesh, the padding or the grid algorithm changes)."""
    m = _mesh(obj)
    h = hashlib.sha256(np.ascontiguousarray(m.vertices, np.float64).tobytes())
    h.update(np.ascontiguousarray(m.faces, np.int64).tobytes())
    h.update(f"padding={SDF_PADDING!r};version={SDF_VERSION}".encode())
    return h.hexdigest()[:12]


def cached_sdf_grid(name: str | trimesh.Trimesh, resolution: int = 64, folder: Path | None = None,
                    progress: bool = True) -> SDFGrid:
    """The SDF grid of catalogue object `name` (or of a mesh in its object frame): the grid shipped in
    data_stubs/sdf when there is one (then `folder` is not read), else read from `folder` (default `<cache>/sdf/`) or
    built (seconds; minutes for a scan, with a bar unless `progress` is False) and stored there atomically (where the
    folder cannot be written, a warning says so and the grid is returned all the same)."""
    from graspkit.paths import cache_dir

    fname = _grid_filename(name, resolution)
    stub = DATA_STUBS / "sdf" / fname
    if stub.is_file():
        # the shipped grid first, whatever the cache holds: mug_r84 ships as float16, and a float32 grid of the same
        # name in the cache (one built where data_stubs was missing) took lesson 05's fit to other energies
        try:
            return _read_grid(stub)
        except ValueError as e:
            warnings.warn(f"{stub}: the shipped grid cannot be read ({str(e)[:200]}; a Git LFS pointer?); the cache's or "
                          "a new build is used, whose last bits differ (restore data_stubs: git checkout)",
                          GraspkitWarning, stacklevel=user_stacklevel())
    path = (Path(folder) if folder is not None else cache_dir() / "sdf") / fname
    grid = read_cache(path, _read_grid)               # a damaged cache file is removed and rebuilt
    if grid is not None:
        return grid
    grid = SDFGrid.from_mesh(_mesh(name), resolution, SDF_PADDING, progress=progress)     # minutes for a scan
    try:
        _write_grid(path, grid)
    except OSError as e:                              # a read-only cache: the grid is what the caller needs
        warnings.warn(f"the SDF grid is not kept for next time: {e}", GraspkitWarning, stacklevel=user_stacklevel())
    return grid


def _read_grid(path: Path) -> SDFGrid:
    """A grid file of `_write_grid`; ValueError naming the file when it is damaged or lacks a key."""
    from graspkit.data.formats import npz_arrays, open_npz

    with open_npz(path, "an SDF grid (values, lower, upper)") as z:
        a = npz_arrays(z, ("values", "lower", "upper"), path)
    v, lo, hi = a["values"], a["lower"], a["upper"]
    if v.ndim != 3 or min(v.shape) < 2 or lo.shape != (3,) or hi.shape != (3,) or not (lo < hi).all() \
            or not all(np.isfinite(x).all() for x in (v, lo, hi)):
        raise ValueError(f"{path}: not an SDF grid (expected finite values (X, Y, Z) of at least 2 nodes a side and "
                         f"corners lower < upper (3,), got values {v.shape}, lower {lo.shape}, upper {hi.shape})")
    return SDFGrid(*(torch.as_tensor(x).float() for x in (v, lo, hi)))


def _grid_filename(name: str | trimesh.Trimesh, resolution: int) -> str:
    """The cache (and data_stubs/sdf) file name of object `name`'s grid: resolution and the hash of mesh, padding and
    SDF_VERSION in it."""
    return f"{name if isinstance(name, str) else 'mesh'}_r{resolution}_{mesh_digest(name)}.npz"


def _write_grid(path: Path, grid: SDFGrid, dtype: type = np.float32) -> None:
    """Write a grid atomically (values in `dtype`; the box corners in float32)."""
    from graspkit.data.formats import write_npz_atomic

    write_npz_atomic(path, {"values": grid.values.numpy().astype(dtype), "lower": grid.lower.numpy(),
                            "upper": grid.upper.numpy()})


def resolution_for(name: str | trimesh.Trimesh, cell: float, minimum: int = 64) -> int:
    """Nodes along the longest side of object `name`'s (or a mesh's) padded box for cells of at most `cell` m (at
    least `minimum`)."""
    if cell <= 0:
        raise ValueError(f"cell: expected a positive size in metres, got {cell}")
    m = _mesh(name)
    longest = float((m.bounds[1] - m.bounds[0]).max()) + 2 * SDF_PADDING
    return max(minimum, math.ceil(longest / cell - 1e-9) + 1)


def collision_sdf_grid(name: str | trimesh.Trimesh, folder: Path | None = None, progress: bool = True) -> SDFGrid:
    """The SDF grid of object `name` (or of a mesh in its object frame) that GraspPose-Opt's collision terms use:
    cells of at most COLLISION_CELL."""
    return cached_sdf_grid(name, resolution_for(name, COLLISION_CELL), folder, progress)


def object_collision_grid(obj: object, mesh: trimesh.Trimesh, progress: bool = True) -> SDFGrid:
    """The collision grid for an object as a user gave it (`obj`: what objects.user.as_object took, `mesh`: the mesh
    it returned): a catalogue name keeps its name's grid (cached, or shipped in data_stubs/sdf), anything else the
    mesh's own."""
    from graspkit.objects.catalogue import list_objects

    return collision_sdf_grid(obj if isinstance(obj, str) and obj in list_objects() else mesh, progress=progress)


def ship_sdf_grid(name: str, resolution: int, folder: Path = DATA_STUBS / "sdf") -> Path:
    """Write object `name`'s grid at `resolution` into `folder` with float16 values (within 0.03 mm of float32) for
    shipping in data_stubs/sdf, e.g. `ship_sdf_grid("mug", resolution_for("mug", COLLISION_CELL))` (lesson 05)."""
    path = Path(folder) / _grid_filename(name, resolution)
    _write_grid(path, SDFGrid.from_mesh(_mesh(name), resolution, SDF_PADDING), np.float16)   # built, not a read
    return path
