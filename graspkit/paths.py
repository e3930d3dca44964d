"""Where graspkit finds its shipped files (data_stubs/) and writes caches."""
from __future__ import annotations

import math
import os
import tempfile
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

REPO_ROOT = Path(__file__).resolve().parents[1]
DATA_STUBS = REPO_ROOT / "data_stubs"


def shipped() -> bool:
    """Whether graspkit runs from a clone with its data_stubs/ (not from a plain `pip install`, which has none)."""
    return (DATA_STUBS / "checkpoints").is_dir()


def stub_hint(path: Path) -> str:
    """What to add to a "missing" message about `path`: where data_stubs/ went when graspkit runs without it, or how
    the default body is made then."""
    env = os.environ.get("GRASPKIT_MODEL")
    if env and Path(env).expanduser().resolve() == Path(path).resolve():
        return " (the file GRASPKIT_MODEL names)"
    if shipped():
        return ""
    if Path(path).resolve().is_relative_to(DATA_STUBS.resolve()):
        there = "does not exist" if not DATA_STUBS.is_dir() else "holds no shipped checkpoints"
        return (f"; {DATA_STUBS} {there}: the shipped checkpoints and samples come with a clone of graspkit's "
                "repository, installed there with `pip install -e .`, not with a plain `pip install`")
    if Path(path).resolve() == built_model_path().resolve():
        return ("; without data_stubs/ (a plain `pip install`) graspkit's default body is built there by `graspkit "
                "body build` (or set GRASPKIT_MODEL to an SMPL-X .npz)")
    return ""


def require_checkpoints(folder: str | os.PathLike, names: Sequence[str], docs: str) -> Path:
    """`folder` as a Path once each file of `names` is in it, else a FileNotFoundError naming the first missing and the
    docs that say how it is made."""
    ck = Path(folder)
    for f in names:
        if not (ck / f).is_file():
            raise FileNotFoundError(f"checkpoints: {ck / f} is missing (see {docs}){stub_hint(ck / f)}")
    return ck


def built_model_path() -> Path:
    """Where the procedural humanoid is built and kept when no data_stubs/ ships with graspkit: in the cache."""
    return cache_dir() / "body_models" / "smplx" / "SMPLX_NEUTRAL.npz"


def default_model_path() -> Path:
    """The SMPL-X-format model to use: $GRASPKIT_MODEL if set (`~` expanded), else procedural_model_path(): the shipped
    procedural humanoid (in a plain `pip install`, without data_stubs/, the one built in the cache; nothing is written
    into the installed package)."""
    env = os.environ.get("GRASPKIT_MODEL")
    return _expanded(env, "GRASPKIT_MODEL") if env else procedural_model_path()


def procedural_model_path() -> Path:
    """graspkit's procedural humanoid, whatever GRASPKIT_MODEL says: the shipped file, or in a plain `pip install`
    the one built in the cache (built_model_path()); where `graspkit body build` writes by default."""
    return DATA_STUBS / "body_models" / "smplx" / "SMPLX_NEUTRAL.npz" if shipped() else built_model_path()


def cache_dir() -> Path:
    """Folder for generated training sets and outputs of long jobs: $GRASPKIT_CACHE (`~` expanded; set but empty
    counts as unset, not as the working folder) or ~/.cache/graspkit."""
    env = os.environ.get("GRASPKIT_CACHE")
    if env:
        return _expanded(env, "GRASPKIT_CACHE")
    try:
        return Path.home() / ".cache" / "graspkit"
    except RuntimeError:                 # no HOME and no passwd entry (a container's uid)
        raise ValueError("GRASPKIT_CACHE: not set, and this user has no home folder for the default "
                         "~/.cache/graspkit; set GRASPKIT_CACHE to a writable folder") from None


def _expanded(value: str, variable: str) -> Path:
    """The path an environment variable names, `~` and `~user` expanded; ValueError naming the variable when they
    cannot be (an unknown user: pathlib's RuntimeError)."""
    try:
        return expand_home(value)
    except RuntimeError as e:
        raise ValueError(f"{variable}: {value}: {e} (`~` or `~user` names no home folder here)") from None


def expand_home(path: str | os.PathLike) -> Path:
    """`path` with a leading `~` or `~user` expanded as a shell would (`--out=~/x`: the shell leaves a `~` after `=`),
    unless its first part is a file or folder here whose name starts with `~` (`./~res/x.obj`: Path drops the `./`);
    RuntimeError (pathlib's) for `~user` of no one."""
    p = Path(path)
    if not p.parts or not p.parts[0].startswith("~") or (p.parts[0] != "~" and Path(p.parts[0]).exists()):
        return p
    return p.expanduser()


def check_suffix(path: str | os.PathLike, *suffixes: str) -> None:
    """ValueError naming `path` unless its file name ends in one of `suffixes` (any case): a writer's bytes are that
    format, and a file named for another (seq.gltf holding binary GLB, clip.json an npz) is read by nothing."""
    if Path(path).suffix.lower() not in suffixes:
        raise ValueError(f"path: expected a file ending in {' or '.join(suffixes)} (the format written), got "
                         f"{Path(path).name!r}")


def cannot_write(folder: Path, e: OSError) -> OSError:
    """The OSError to raise when a file cannot be created in `folder`: it names the folder, and the cache's variable
    when the folder is in graspkit's cache (a bare "[Errno 30] Read-only file system: '<cache>/sdf'" said neither)."""
    hint = ""
    try:
        if Path(folder).resolve().is_relative_to(cache_dir().resolve()):
            hint = f"; it is in graspkit's cache {cache_dir()}: set GRASPKIT_CACHE to a writable folder"
    except OSError:
        pass
    return OSError(e.errno, f"cannot write in {folder}: {e.strerror or e}{hint}")


def writes_to(path: str | os.PathLike) -> Path:
    """The file that writing `path` replaces: a symbolic link's target (the link stays, as open() writes through
    it; a rename onto the link replaced it by a file and left the target as it was), else path itself."""
    p = Path(path)
    return Path(os.path.realpath(p)) if p.is_symlink() else p


TEMP_NAME_BYTES = 200        # the target's name in a temporary file's, at most: with ".", ".", 8 random characters
                             # and a suffix of up to 40 bytes it stays within NAME_MAX (255)


def temp_stem(path: Path) -> str:
    """The part of path's name that its temporary files carry: the name, shortened before its extension to
    TEMP_NAME_BYTES (a 249-byte name is legal, its temporary file's name was not)."""
    name, ext = path.name, path.suffix
    while len(name.encode()) > TEMP_NAME_BYTES:
        name = name[:-len(ext) - 1] + ext if len(name) > len(ext) + 1 else name[:-1]
    return name


def make_temp(path: Path, suffix: str = ".tmp") -> tuple[int, str]:
    """tempfile.mkstemp's (fd, name) of a new temporary file .<temp_stem>.<8 random><suffix> beside `path` (or its
    link's target: `writes_to`), its folder made first; an OSError naming the folder (`cannot_write`) when it cannot
    be made."""
    path = writes_to(path)
    name = temp_stem(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        return tempfile.mkstemp(dir=path.parent, prefix=f".{name}.", suffix=suffix)
    except OSError as e:
        raise cannot_write(path.parent, e) from None


@contextmanager
def naming_errors(path: Path) -> Iterator[None]:
    """Re-raise a plain OSError of the block that names no file (a full disk's "[Errno 28] No space left on device"
    from write()) with `path` as its file, so that one knows which disk filled up; other errors (a subclass, no
    errno: Pillow's encoder errors, io.UnsupportedOperation; one naming its file) pass unchanged."""
    try:
        yield
    except OSError as e:
        if e.errno is not None and e.filename is None and type(e).__module__ == "builtins":   # (errno, strerror, file)
            raise type(e)(e.errno, e.strerror, str(path)) from e
        raise


def temp_beside(path: Path, suffix: str = ".tmp") -> Path:
    """An empty temporary file of a unique name in path's folder (created), for writing before `publish`: two
    processes writing the same path never share a temporary file."""
    fd, tmp = make_temp(path, suffix)
    os.close(fd)
    return Path(tmp)


def sync_rename(tmp: str | os.PathLike, path: str | os.PathLike) -> None:
    """Flush tmp's bytes to disk, rename it onto path and flush the folder: after a power cut path holds the old
    file or the new one, never a renamed file whose data had not reached the disk."""
    path = writes_to(path)
    fd = os.open(tmp, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)
    os.replace(tmp, path)
    try:                                    # the rename itself; some file systems cannot sync a folder
        fd = os.open(Path(path).parent, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def _umask() -> int:
    """The process's umask, read where Linux shows it; elsewhere set and put back (os.umask is the only other way), with
    0o022 meanwhile, not 0, so that a file another thread makes in that instant is not world-writable."""
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def _warn(message: str) -> None:
    """A GraspkitWarning pointing at the first line outside graspkit (graspkit.checks imported here, when needed:
    this module stays free of torch)."""
    import warnings

    from graspkit.checks import GraspkitWarning, user_stacklevel

    warnings.warn(message, GraspkitWarning, stacklevel=user_stacklevel())


def usual_mode(tmp: Path) -> None:
    """Give tmp the permissions a plain open() would (mkstemp makes it owner-only)."""
    os.chmod(tmp, 0o666 & ~_umask())


def publish(tmp: Path, path: Path) -> Path:
    """Give tmp the usual permissions and rename it onto path (a link's target) atomically (synced)."""
    usual_mode(tmp)
    sync_rename(tmp, path)
    return path


def file_stamp(path: str | os.PathLike) -> tuple[str, int, int]:
    """(resolved path, mtime ns, size) of a file — (resolved path, 0, 0) when it is missing — a cache key that sees
    the file rewritten in place or named by another relative path."""
    p = Path(path).resolve()
    st = p.stat() if p.is_file() else None
    return str(p), st.st_mtime_ns if st else 0, st.st_size if st else 0


def write_atomic(path: str | os.PathLike, data: bytes | str) -> Path:
    """Write data to path (a link's target) through a temporary file beside it, synced and renamed, with the umask's
    permissions; a killed writer's stale temporary files there are swept after; returns the path."""
    path = Path(path)
    tmp = temp_beside(path)
    try:
        with naming_errors(path):
            tmp.write_bytes(data.encode() if isinstance(data, str) else data)
            publish(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    sweep_stale_temps(path)
    return path


def write_json(path: str | os.PathLike, obj: Any) -> Path:
    """obj as indented strict JSON at path, atomically: NaN and infinities become null (readers such as jq refuse
    them), numpy numbers plain numbers."""
    import json

    return write_atomic(path, json.dumps(_finite_or_null(obj), indent=1, allow_nan=False))


def _finite_or_null(obj: Any) -> Any:
    """obj with numpy numbers as Python ones and every NaN or infinite float as None."""
    if hasattr(obj, "item") and getattr(obj, "shape", None) == ():      # a numpy scalar or 0-d array
        obj = obj.item()
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: _finite_or_null(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_finite_or_null(v) for v in obj]
    return obj


STALE_TMP_S = 600.0          # s: a temporary file older than this beside its target was left by a killed writer
_SWEPT: dict[tuple[str, str], float] = {}      # (folder, file type) -> time.monotonic() of this process's last sweep


def sweep_stale_temps(path: Path) -> None:
    """Remove the temporary files (`temp_beside`'s .<name><ext>.<8 random>.tmp, or .<name><ext>.<8 random><ext> for
    writers that need the suffix) of any file of path's type in path's folder that are older than STALE_TMP_S: left
    by a process killed while writing (kill -9). Folder-wide, since a killed writer's own file may never be written
    again (a resumed run rewrites it at once, while the temporary file is still young). A writer at work is told by
    its file's age: npz, checkpoint and JSON writers write as they go, and a GIF's file is made again by name at its
    end; an .mp4 render slower than ~12 s a frame leaves its file untouched for 10 minutes (ffmpeg's lookahead) and
    could lose it to another process's write there. A folder is swept at most once a minute per process and file
    type, so writing n files there stays linear in n."""
    import glob
    import time

    path = writes_to(path)
    key = (str(path.parent.absolute()), path.suffix or temp_stem(path))
    if time.monotonic() - _SWEPT.get(key, -math.inf) < 60.0:
        return
    _SWEPT[key] = time.monotonic()
    now = time.time()
    ext, rand = glob.escape(path.suffix), "?" * 8            # tempfile's random part: 8 characters
    patterns = ([f".*{ext}.{rand}.tmp", f".*{ext}.{rand}{ext}"] if path.suffix
                else [f".{glob.escape(temp_stem(path))}.{rand}.tmp"])
    for pattern in patterns:
        for stale in path.parent.glob(pattern):
            try:
                if stale.is_file() and now - stale.stat().st_mtime > STALE_TMP_S:
                    stale.unlink()
            except OSError:          # gone meanwhile, or another user's in a shared folder: housekeeping, not our write
                pass


def create_exclusive(path: str | os.PathLike, data: bytes | str) -> bool:
    """Write data to path whole (a temporary file, the usual permissions, synced, then hard-linked) unless path exists;
    False when it did (another process created it first, even a moment before)."""
    path = Path(path)
    payload = data.encode() if isinstance(data, str) else data
    tmp = temp_beside(path)
    try:
        with naming_errors(path), open(tmp, "wb") as f:     # a full disk fails here, before path exists
            f.write(payload)
            f.flush()
            os.fsync(f.fileno())
        usual_mode(tmp)
        try:
            os.link(tmp, path)
            return True
        except FileExistsError:
            return False
        except OSError:          # no hard links here (vfat: EPERM, Windows' FAT: EINVAL, some CIFS mounts: EACCES)
            pass
        # O_EXCL instead, and no half-written file left behind
        try:
            fd = os.open(path, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o666)
        except FileExistsError:
            return False
        try:
            with naming_errors(path), os.fdopen(fd, "wb") as f:
                f.write(payload)
        except BaseException:
            path.unlink(missing_ok=True)
            raise
        return True
    finally:
        tmp.unlink(missing_ok=True)


@contextmanager
def locked(path: Path) -> Iterator[None]:
    """Hold an exclusive lock on the file `path` (made if missing) for the block: processes that lock the same path
    run their blocks one after another (fcntl.flock; where there is none, or a mount refuses it, the block runs
    without a lock, with a warning in the latter case)."""
    try:
        import fcntl
    except ImportError:                                 # not POSIX
        yield
        return

    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "a") as fh:
        try:
            fcntl.flock(fh, fcntl.LOCK_EX)
            held = True
        except OSError as e:                            # some network mounts take no locks: go on without one
            _warn(f"{path}: no lock could be taken ({e.strerror}); going on without it")
            held = False
        try:
            yield
        finally:
            if held:
                fcntl.flock(fh, fcntl.LOCK_UN)


def drop_damaged(paths: Sequence[Path], what: str = "files") -> list[Path]:
    """Remove those of `paths` (.npz files; missing ones are skipped) that are not intact zip archives (truncated, or
    an entry failing its checksum), warning on stderr, so that a resumed run makes them again; returns the removed
    paths. Files are written atomically, so only damage from outside (a copy cut short, a bad disk) is caught here."""
    import sys
    import zipfile

    bad = []
    for p in paths:
        if not Path(p).exists():
            continue
        try:
            with zipfile.ZipFile(p) as zf:
                ok = zf.testzip() is None
        except Exception:  # noqa: BLE001 - BadZipFile, zlib.error, OSError, EOFError: any of them is damage
            ok = False
        if not ok:
            bad.append(Path(p))
    if bad:
        names = ", ".join(p.name for p in bad[:3]) + (", ..." if len(bad) > 3 else "")
        print(f"warning: {len(bad)} damaged {what} made again ({names})", file=sys.stderr)
        for p in bad:
            p.unlink(missing_ok=True)
    return bad


def read_cache(path: Path, load: Callable[[Path], Any]) -> Any | None:
    """load(path) for a cache file; None when there is none, or when it is damaged (a copy cut short, a changed byte:
    `load` raises ValueError, OSError or a zip / zlib error), which is then removed with a warning so that the caller
    makes it again."""
    import zipfile
    import zlib

    path = Path(path)
    if not path.is_file():
        return None
    try:
        return load(path)
    except (ValueError, OSError, EOFError, zipfile.BadZipFile, zlib.error) as e:
        _warn(f"{path}: a damaged cache file, made again ({str(e)[:200]})")
        try:
            path.unlink(missing_ok=True)
        except OSError as err:                          # a read-only cache: the caller's write will fail, named
            _warn(str(cannot_write(path.parent, err)))
        return None


class _Stopped(BaseException):
    """Raised in a pool worker's call by the parent's SIGTERM: the call's own cleanup runs (a writer removes its
    temporary file), then the worker exits."""


_IN_CALL = False                                        # a pool worker: whether it is running a call now


def _on_sigterm(signum: int, frame: Any) -> None:
    """A pool worker's SIGTERM: stop the running call through its cleanup, or exit at once when idle."""
    if _IN_CALL:
        raise _Stopped
    os._exit(143)


def _pool_worker_init(initializer: Callable[..., None] | None, initargs: tuple) -> None:
    """A pool worker ignores Ctrl-C (the terminal sends it to the whole process group: the parent handles it) and
    stops on the parent's SIGTERM through the running call's cleanup."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, _on_sigterm)
    if initializer is not None:
        initializer(*initargs)


def _pool_call(fn: Callable[..., Any], args: tuple) -> Any:
    """fn(*args) in a pool worker; stopped by SIGTERM, the worker exits once the call's cleanup has run."""
    global _IN_CALL
    try:
        _IN_CALL = True
        try:
            return fn(*args)
        finally:
            _IN_CALL = False
    except _Stopped:                                    # also when the signal lands in the finally above
        os._exit(143)


def pool_results(calls: Sequence[tuple[Callable[..., Any], tuple]], workers: int,
                 initializer: Callable[..., None] | None = None, initargs: tuple = ()) -> Iterator[Any]:
    """Results of calls [(fn, args), ...] run on a pool of `workers` processes, in the order they complete. On any
    error, Ctrl-C included, the workers are stopped before the error is raised, their running calls through their
    cleanup (no temporary file left), the queued calls not started (a pool in a plain `with` block runs every queued
    call first, and a worker that took Ctrl-C as its call's error went on with the next: `data make` wrote files for
    a minute after Ctrl-C)."""
    from concurrent.futures import ProcessPoolExecutor, as_completed

    # never more processes than calls: `--workers 500` for 3 clips starts 3 (each process loads torch and a body)
    ex = ProcessPoolExecutor(max_workers=max(1, min(workers, len(calls))), initializer=_pool_worker_init,
                             initargs=(initializer, initargs))
    try:
        futures = [ex.submit(_pool_call, fn, args) for fn, args in calls]
        for f in as_completed(futures):
            yield f.result()
    except BaseException:
        # stop the workers and let the pool fail the calls left: cancelling them here as well races the pool's own
        # failing of them on Python 3.11 (an InvalidStateError traceback from its thread)
        for p in list((getattr(ex, "_processes", None) or {}).values()):
            p.terminate()
        ex.shutdown(wait=True)
        raise
    ex.shutdown(wait=True)


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
