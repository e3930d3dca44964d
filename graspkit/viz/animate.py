"""Mesh sequences as matplotlib animations: inline JSHTML for notebooks, GIF / MP4 files.

Notebook outputs stay small by default: about `max_frames` frames (the stride grows to fit; the last frame is
added), small panels, low dpi; `to_html` refuses to embed more than `max_mb` megabytes.
"""
from __future__ import annotations

import math
import os
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import matplotlib as mpl
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.animation import FFMpegWriter, FuncAnimation, PillowWriter, writers
from tqdm.auto import tqdm

from graspkit.paths import naming_errors, sweep_stale_temps
from graspkit.progress import hidden
from graspkit.viz.export import drawn_frames, publish, temp_beside
from graspkit.viz.scene import (View, _mesh_polys, as_array, as_mesh, as_points, bounds_of, draw_ground, draw_meshes,
                                draw_path, figure, floor_height, set_equal, sphere, to_numpy)
from graspkit.viz.style import GOAL, OBJECT, SKIN


def _frames_array(frames: Any, num_frames: int | None) -> tuple[int, Callable[[int], np.ndarray]]:
    """(T, frame getter) for an array (T,V,3), a list of (V,3) arrays, or a callable t -> (V,3) with num_frames."""
    if callable(frames):
        if num_frames is None:
            raise ValueError("num_frames: required when frames is a function t -> vertices (V, 3)")
        return num_frames, lambda t: as_array(frames(t), f"frames({t})", (None, 3))
    if isinstance(frames, (list, tuple)):
        return len(frames), lambda t: as_array(frames[t], f"frames[{t}]", (None, 3))
    arr = as_array(frames, "frames", (None, None, 3))
    return len(arr), lambda t: arr[t]


def decimate_sequence(frames: list[np.ndarray], faces: np.ndarray,
                      max_faces: int) -> tuple[list[np.ndarray], np.ndarray]:
    """Quadric-decimate frame 0 (V,3) to ~max_faces faces and replay the same edge collapses on every frame,
    so all frames share one topology; returns the frames (V',3) and faces (F',3)."""
    import fast_simplification

    _, low, collapses = fast_simplification.simplify(frames[0], faces, target_reduction=1.0 - max_faces / len(faces),
                                                     return_collapses=True)
    # float32 in: fast-simplification < 0.2 takes nothing else, and 0.2 returns float32 whatever it is given
    return [fast_simplification.replay_simplification(points=np.asarray(v, np.float32), triangles=faces,
                                                      collapses=collapses)[0] for v in frames], low


def animate(frames: Any, faces: Any, objects: Sequence[tuple[Any, ...]] = (), goals: Any = None,
            goal_radius: float = 0.05, paths: Sequence[Any] = (), fps: float = 30.0,
            views: Sequence[View] = ("front", "side"), stride: int = 1, max_frames: int | None = 60,
            size: float = 3.0, dpi: float = 72.0, color: Any = SKIN, title: str | None = None, ground: bool = True,
            num_frames: int | None = None, max_faces: int | None = 8000, close: bool = True) -> FuncAnimation:
    """A body moving over time: frames (T,V,3) array / list of (V,3) / function t -> (V,3) (with num_frames),
    faces (F,3); objects [(vertices (V,3) static or (T,V,3) moving, faces[, color])]; static goals (G,3),
    paths [(N,3)]. Every `stride`-th frame, stride raised so at most max_frames are drawn, plus the last frame (a reach
    or grasp ends there; so up to max_frames + 1); each drawn frame shows for stride / fps s, real time, except that
    the step into an added last frame is shorter in the clip than on screen (it shows up to stride - 1 frames late).
    max_faces: larger bodies are decimated (same topology every frame): matplotlib's time per frame grows with
    the face count, and a few thousand faces already fill a small panel. close=True closes the figure so a
    notebook shows only the animation, not a still of its last frame.
    """
    total, get = _frames_array(frames, num_frames)
    if total < 1:
        raise ValueError("frames: expected at least one frame")
    if stride < 1:
        raise ValueError(f"stride: expected >= 1, got {stride}")
    if max_frames is not None:
        stride = max(stride, math.ceil(total / max_frames))
    ticks = drawn_frames(total, stride)
    body = [get(t) for t in ticks]
    _, f = as_mesh(body[0], faces, "frames")
    if max_faces is not None and len(f) > max_faces:
        body, f = decimate_sequence(body, f, max_faces)
    objs = []
    for k, item in enumerate(objects):
        ov = to_numpy(item[0])
        if ov.ndim == 3 and len(ov) != total:
            raise ValueError(f"objects[{k}]: {len(ov)} frames of vertices for {total} body frames")
        objs.append((ov[ticks] if ov.ndim == 3 else ov[None], item[1], item[2] if len(item) > 2 else OBJECT))
    goal_meshes = [(*sphere(c, goal_radius), GOAL) for c in as_points(goals, "goals")] if goals is not None else []

    things = [np.stack(body)] + [o[0] for o in objs] + [to_numpy(p) for p in paths]     # what stands on the floor
    lo, hi = bounds_of(*things, *[m[0] for m in goal_meshes])
    gz = floor_height(*things)
    fig, axes = figure(views, size, title=title or " ", dpi=dpi)
    if ground:
        m = 0.25 * max(float((hi - lo)[:2].max()), 0.4)
        box = (lo[0] - m, hi[0] + m, lo[1] - m, hi[1] + m)
        lo = np.minimum(lo, [box[0], box[2], gz])
        hi = np.maximum(hi, [box[1], box[3], gz])
    colls = []
    for ax in axes:
        if ground:
            draw_ground(ax, box, z=gz)
        for p in paths:
            draw_path(ax, p)
        colls.append(draw_meshes(ax, []))
        set_equal(ax, np.stack([lo, hi]), pad=0.0, zoom=1.15)
    stamp = fig.texts[0]  # the suptitle that figure(title=" ") made: it shows the time

    def meshes_at(i: int) -> list[tuple[Any, ...]]:
        moving = [(ov[min(i, len(ov) - 1)], of, oc) for ov, of, oc in objs]  # static objects hold one frame
        return [(body[i], f, color), *moving, *goal_meshes]

    def update(i: int) -> list[Any]:
        items = meshes_at(i)
        for ax, pc in zip(axes, colls):
            polys = [_mesh_polys(mi, f"frame {ticks[i]}", ax, True) for mi in items]
            pc.set_verts(np.concatenate([p for p, _ in polys]))
            pc.set_facecolor(np.concatenate([np.concatenate([c, np.ones((len(c), 1))], 1) for _, c in polys]))
        stamp.set_text(f"{title + '   ' if title else ''}t = {ticks[i] / fps:.2f} s")
        return colls

    anim = FuncAnimation(fig, update, frames=len(ticks), interval=1000.0 * stride / fps, blit=False)
    anim.graspkit_fps = fps / stride  # frames per second of the drawn frames, for writers
    if close:
        plt.close(fig)
    return anim


def to_html(anim: FuncAnimation, max_mb: float = 3.0) -> str:
    """The animation as self-contained JavaScript HTML (looping player); ValueError above max_mb megabytes."""
    with mpl.rc_context({"animation.embed_limit": 1e4}):  # never truncate silently; the check below decides
        html = anim.to_jshtml(default_mode="loop")
    mb = len(html.encode()) / 2**20
    if mb > max_mb:
        raise ValueError(f"max_mb: the animation is {mb:.1f} MB (> {max_mb} MB); draw fewer frames (max_frames, "
                         "stride), smaller panels (size, dpi) or fewer views, or raise max_mb")
    return html


def show_animation(anim: FuncAnimation, max_mb: float = 3.0) -> Any:
    """An IPython HTML object that plays the animation inline in a notebook (see to_html)."""
    from IPython.display import HTML

    return HTML(to_html(anim, max_mb))


def _ffmpeg_path() -> str | None:
    """matplotlib's configured ffmpeg if it runs, else the binary bundled by imageio-ffmpeg, else None."""
    if writers.is_available("ffmpeg"):
        return mpl.rcParams["animation.ffmpeg_path"]
    try:
        import imageio_ffmpeg
    except ImportError:
        return None
    return imageio_ffmpeg.get_ffmpeg_exe()


class RealTimeGif(PillowWriter):
    """Pillow's GIF writer with frame delays that add up to real time: a GIF stores delays in 1/100 s, and one
    delay of int(1000 / fps) ms per frame (Pillow's) plays 30 fps 10 % fast; here 30, 40, 30 ms ... at 30 fps."""

    def finish(self) -> None:
        edges = np.round(np.arange(len(self._frames) + 1) * 100.0 / self.fps).astype(int) * 10   # ms, 10 ms steps
        self._frames[0].save(self.outfile, save_all=True, append_images=self._frames[1:],
                             duration=np.maximum(np.diff(edges), 10).tolist(), loop=0)


def save_animation(anim: FuncAnimation, path: str | os.PathLike, fps: float | None = None, dpi: float | None = None,
                   progress: bool | None = None) -> Path:
    """Write anim to path (.gif with Pillow, .mp4 with ffmpeg) atomically; a progress bar over frames is shown
    when progress=True, or by default for 100 frames or more. Returns the path."""
    path = Path(path)
    suffix = path.suffix.lower()
    fps = fps or getattr(anim, "graspkit_fps", None) or 1000.0 / anim._interval
    rc: dict[str, Any] = {}
    if suffix == ".gif":
        writer: Any = RealTimeGif(fps=fps)
    elif suffix == ".mp4":
        exe = _ffmpeg_path()
        if exe is None:
            raise RuntimeError("path: writing .mp4 needs ffmpeg, which was not found; save as .gif instead, "
                               "or install ffmpeg (e.g. `pip install imageio-ffmpeg`)")
        rc["animation.ffmpeg_path"] = exe
        writer = FFMpegWriter(fps=fps, codec="h264")
    else:
        raise ValueError(f"path: expected a .gif or .mp4 file, got {path.name!r}")
    n = anim._save_count or 0
    show = progress if progress is not None else n >= 100
    tmp = temp_beside(path, suffix)  # writers pick the format from the suffix
    try:
        with naming_errors(path), tqdm(total=n, unit="frame", desc=path.name, disable=hidden(show), leave=False) as bar, \
                mpl.rc_context(rc):
            anim.save(tmp, writer=writer, dpi=dpi, progress_callback=lambda i, total: bar.update(1))
            publish(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    sweep_stale_temps(path)
    return path
