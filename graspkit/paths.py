"""Where graspkit finds its shipped files (data_stubs/) and writes caches."""
from __future__ import annotations

import os
import tempfile
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[1]
DATA_STUBS = REPO_ROOT / "data_stubs"
BODY_MODELS = DATA_STUBS / "body_models"


def default_model_path() -> Path:
    """The SMPL-X-format model to use: $GRASPKIT_MODEL if set, else the shipped procedural humanoid."""
    env = os.environ.get("GRASPKIT_MODEL")
    return Path(env) if env else BODY_MODELS / "smplx" / "SMPLX_NEUTRAL.npz"


def cache_dir() -> Path:
    """Folder for generated training sets and outputs of long jobs: $GRASPKIT_CACHE or ~/.cache/graspkit."""
    return Path(os.environ.get("GRASPKIT_CACHE", Path.home() / ".cache" / "graspkit"))


def temp_beside(path: Path, suffix: str = ".tmp") -> Path:
    """An empty temporary file of a unique name in path's folder (created), for writing before `publish`: two
    processes writing the same path never share a temporary file."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=suffix)
    os.close(fd)
    return Path(tmp)


def publish(tmp: Path, path: Path) -> Path:
    """Give tmp the usual permissions (mkstemp makes it owner-only) and rename it onto path atomically."""
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)
    os.replace(tmp, path)
    return path


def write_atomic(path: str | os.PathLike, data: bytes | str) -> Path:
    """Write data to path through a temporary file in the same folder and os.replace; returns the path."""
    path = Path(path)
    tmp = temp_beside(path)
    try:
        tmp.write_bytes(data.encode() if isinstance(data, str) else data)
        return publish(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def exit_with_parent(parent: int) -> None:
    """In a worker process: exit as soon as the process `parent` is gone (a parent killed with kill -9 cannot close its
    pool, whose idle workers would otherwise wait for work forever)."""
    import threading
    import time

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(0.5)
        os._exit(1)

    threading.Thread(target=watch, daemon=True, name="exit-with-parent").start()
