"""Caches for grasp synthesis: per-object SDF grids stored in graspkit's cache folder (built once per machine;
a few are shipped in data_stubs/sdf for the tests and lesson 04)."""
from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np
import torch

from graspkit.objects.catalogue import make_object
from graspkit.paths import DATA_STUBS
from graspkit.objects.sdf import SDFGrid

SDF_PADDING = 0.03


def mesh_digest(name: str) -> str:
    """A short hash of the canonical mesh of object `name` (a cached grid is rebuilt when the mesh changes)."""
    m = make_object(name)
    h = hashlib.sha256(np.ascontiguousarray(m.vertices, np.float64).tobytes())
    h.update(np.ascontiguousarray(m.faces, np.int64).tobytes())
    return h.hexdigest()[:12]


def cached_sdf_grid(name: str, resolution: int = 64, folder: Path | None = None) -> SDFGrid:
    """The SDF grid of catalogue object `name`, read from `<cache>/sdf/` or built (seconds) and stored atomically."""
    from graspkit.data.formats import write_npz_atomic
    from graspkit.paths import cache_dir

    folder = Path(folder) if folder is not None else cache_dir() / "sdf"
    fname = f"{name}_r{resolution}_{mesh_digest(name)}.npz"
    path = folder / fname
    for p in (path, DATA_STUBS / "sdf" / fname):     # the cache, then the few grids shipped in data_stubs/sdf
        if p.is_file():
            try:
                with np.load(p, allow_pickle=False) as z:
                    return SDFGrid(torch.as_tensor(z["values"]).float(), torch.as_tensor(z["lower"]).float(),
                                   torch.as_tensor(z["upper"]).float())
            except (OSError, ValueError, KeyError):
                pass   # a damaged cache file is rebuilt below
    grid = SDFGrid.from_mesh(make_object(name), resolution, SDF_PADDING)
    write_npz_atomic(path, {"values": grid.values.numpy(), "lower": grid.lower.numpy(), "upper": grid.upper.numpy()})
    return grid
