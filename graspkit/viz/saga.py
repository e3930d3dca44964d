"""SAGA stage-1 pictures: the WholeGrasp-VAE diagram and a walk through its latent space (lesson 05).

`LatentWalk` holds the object and a latent z (16-D); `update(name, value)` changes one latent coordinate (or draws
a new z from a seed) and decodes the grasp: markers, marker contacts, object contacts (SAGA §3.2, inference). It is
plain Python, tested in tests/test_wholegrasp_explorer.py; `widget()` wires sliders to it and shows the figure as a
PNG in an ipywidgets Image (as graspkit.viz.object_explorer).
"""
from __future__ import annotations

from typing import Any

import numpy as np
import torch
from matplotlib.figure import Figure
from torch import Tensor

from graspkit.checks import check_int, check_seed, check_type
from graspkit.models.blocks import evaluating
from graspkit.viz.explorers import bounded_value, slider_bounds, slider_value

_BOXES = [  # (x, y, w, h, text, colour) of the WholeGrasp-VAE diagram (SAGA Fig. 3)
    (0.0, 2.6, 1.9, 0.7, "markers M (143x3)\n+ contacts C_M", "#3b6ea8"),
    (0.0, 1.4, 1.9, 0.7, "object O (2048 pts,\nxyz + normal) + C_O", "#c0504d"),
    (2.3, 2.6, 1.6, 0.7, "ResBlocks\n(body branch)", "#3b6ea8"),
    (2.3, 1.4, 1.6, 0.7, "PointNet++ (enc)\nSA 256/128/all", "#c0504d"),
    (4.3, 2.0, 1.3, 0.7, "[F_B, F_O, t_O]\n-> mu, sigma", "#6a3d9a"),
    (6.0, 2.0, 1.0, 0.7, "z (16-D)", "#6a3d9a"),
    (6.0, 0.5, 2.0, 0.7, "object O\n(xyz + normal), t_O", "#c0504d"),
    (7.4, 2.0, 1.6, 0.7, "ResBlocks\n(decoder)", "#2ca02c"),
    (8.4, 0.5, 1.6, 0.7, "PointNet++ (dec)\n+ feature prop.", "#c0504d"),
    (9.4, 2.9, 1.6, 0.6, "markers M^", "#2ca02c"),
    (9.4, 2.1, 1.6, 0.6, "sigmoid C^_M", "#2ca02c"),
    (10.4, 1.2, 1.5, 0.6, "sigmoid C^_O\n(per point)", "#2ca02c"),
]
_ARROWS = [(0, 2), (1, 3), (2, 4), (3, 4), (4, 5), (5, 7), (6, 8), (8, 7), (7, 9), (7, 10), (8, 11), (7, 11)]


def wholegrasp_diagram(width: float = 11.0) -> Figure:
    """WholeGrasp-VAE as boxes and arrows (SAGA Fig. 3; encoder used in training only)."""
    from matplotlib.patches import FancyArrowPatch, FancyBboxPatch

    fig = Figure(figsize=(width, width * 0.32), dpi=72)
    ax = fig.add_subplot(1, 1, 1)
    ax.set_xlim(-0.1, 12.0)
    ax.set_ylim(0.2, 3.7)
    ax.axis("off")
    for x, y, w, h, text, c in _BOXES:
        ax.add_patch(FancyBboxPatch((x, y), w, h, boxstyle="round,pad=0.03", fc=c, alpha=0.25, ec=c))
        ax.text(x + w / 2, y + h / 2, text, ha="center", va="center", fontsize=7.5)
    for a, b in _ARROWS:
        xa, ya, wa, ha = _BOXES[a][:4]
        xb, yb, wb, hb = _BOXES[b][:4]
        up = yb > ya + ha                     # the target sits above: leave from the top, enter at the bottom
        start = (xa + wa / 2, ya + ha) if up and xb < xa + wa else (xa + wa, ya + ha / 2)
        end = (xb + wb / 2, yb) if up and xb < xa + wa else (xb, yb + hb / 2)
        ax.add_patch(FancyArrowPatch(start, end, arrowstyle="-|>", mutation_scale=10, color="0.35",
                                     shrinkA=2, shrinkB=2))
    ax.text(2.6, 3.55, "encoder q(z | M, C_M, C_O, t_O, O): training only", fontsize=8, color="0.3")
    ax.text(7.2, 3.55, "decoder p(M, C_M, C_O | z, t_O, O): sampling", fontsize=8, color="0.3")
    ax.axvline(5.8, color="0.8", lw=0.8, ls="--")
    return fig


SEED_SLIDER = "seed"
MARKER_IN_CONTACT = "#2ca02c"     # SAGA Fig. 3: markers in contact in green
CONTACT_LEVEL = 0.5               # probability above which a marker / point is drawn as in contact
MAX_LATENT = 100.0                # a latent coordinate beyond this is a typo, not a walk (z ~ N(0, 1))


class LatentWalk:
    """A WholeGrasp-VAE, one object (points, normals (P,3) in the object frame, height t_O) and a latent z."""

    def __init__(self, model: Any, points: Tensor, normals: Tensor, height: float, dims: int = 4,
                 seed: int = 0) -> None:
        """model: the multi-task WholeGrasp-VAE (the walk shows its contact maps); points, normals (P,3) tensors or
        arrays in the object frame, centred at the object (SAGA A.3; `WholeGraspVAE.sample` takes world points and
        centres them itself, this walk decodes them as given), height t_O in metres."""
        from graspkit.models.wholegrasp import WholeGraspVAE, check_sample_inputs

        check_type(model, WholeGraspVAE, "model", what="graspkit.models.wholegrasp.WholeGraspVAE")
        if not model.cfg.multitask:
            raise ValueError("model: expected the multi-task WholeGrasp-VAE (cfg.multitask=True); WholeGrasp-single "
                             "has no contact maps to show")
        dims = check_int(dims, "dims", 1)
        if dims > model.cfg.latent:
            raise ValueError(f"dims: expected 1..{model.cfg.latent} latent sliders, got {dims}")
        points, normals = (torch.as_tensor(x) if isinstance(x, np.ndarray) else x for x in (points, normals))
        height = slider_value("height", height)
        check_sample_inputs(points, normals, 1, model.obj_dec.sa[0].npoint, ("points", "normals"), height=height)
        self.model, self.points, self.normals = model, points.float(), normals.float()
        self.height = height
        self.dims = dims
        self.seed = check_seed(seed)
        self.z = self._draw(seed)
        self.grasp: dict[str, Tensor] = {}
        self.decode()

    def _draw(self, seed: int) -> Tensor:
        """z ~ N(0, I) (1, latent) from a seeded generator."""
        return torch.randn(1, self.model.cfg.latent, generator=torch.Generator().manual_seed(int(seed)))

    @property
    def names(self) -> list[str]:
        """Slider names: z0 .. z{dims-1}, then the seed."""
        return [f"z{i}" for i in range(self.dims)] + [SEED_SLIDER]

    @torch.no_grad()
    def decode(self) -> dict[str, Tensor]:
        """Markers (143,3), marker contacts (143,), object contacts (P,) for the current z."""
        with evaluating(self.model):                    # the caller's model keeps its mode
            out = self.model.decode(self.z, self.points[None], self.normals[None], torch.tensor([[float(self.height)]]))
        self.grasp = {k: v[0] for k, v in out.items()}
        return self.grasp

    def update(self, name: str, value: float | int) -> dict[str, float]:
        """Set latent coordinate `name` ('z0'...) or draw a new z (`seed`); decode; return `measure()`."""
        if name == SEED_SLIDER:
            self.z = self._draw(check_seed(value))       # drawn first: a refused seed changes nothing
            self.seed = int(value)
        elif name in self.names:
            self.z[0, int(name[1:])] = bounded_value(name, value, MAX_LATENT, "a latent coordinate",
                                                     note="the prior is N(0, 1); the sliders span ±3")
        else:
            raise ValueError(f"name: expected one of {self.names}, got {name!r}")
        self.decode()
        return self.measure()

    def measure(self) -> dict[str, float]:
        """Numbers for the caption: markers and object points in contact (p > CONTACT_LEVEL), the object contacts'
        soft count (the sum of C_O, what GraspPose-Opt weighs by) and largest probability, the right palm's distance
        to the object."""
        g = self.grasp
        m, co = g["markers"], g["object_contact"]
        d = torch.cdist(m[None], self.points[None])[0].min(1).values
        palm = slice(121, 143)                                   # the right palm's 22 markers (saga_markers order)
        return {"markers_in_contact": int((g["marker_contact"] > CONTACT_LEVEL).sum()),
                "points_in_contact": int((co > CONTACT_LEVEL).sum()), "points_soft": float(co.sum()),
                "points_max": float(co.max()),
                "palm_to_object_cm": float(d[palm].min()) * 100, "z_norm": float(self.z.norm())}

    def figure(self, size: float = 3.0) -> Figure:
        """Two panels: the markers around the object (contact markers green), the object coloured by C_O."""
        from graspkit.viz import scene

        fig = Figure(figsize=(2 * size, size), dpi=72)
        g = self.grasp
        m, cm, co = g["markers"].numpy(), g["marker_contact"].numpy(), g["object_contact"].numpy()
        p = self.points.numpy()
        ax = fig.add_subplot(1, 2, 1, projection="3d", proj_type="ortho")
        ax.view_init(15, -60)
        ax.set_axis_off()
        scene.draw_points(ax, p, size=1.0, color="0.6", colorbar=False)
        ax.scatter(*m[cm <= CONTACT_LEVEL].T, s=4, c="#3b6ea8")
        ax.scatter(*m[cm > CONTACT_LEVEL].T, s=10, c=MARKER_IN_CONTACT)
        scene.set_equal(ax, m, p)
        ax.set_title("markers (green: in contact)", fontsize=8)
        ax = fig.add_subplot(1, 2, 2, projection="3d", proj_type="ortho")
        ax.view_init(15, -60)
        ax.set_axis_off()
        scene.draw_points(ax, p, values=co, cmap="Reds", size=3.0, colorbar=False)
        hand, hc = m[63:143], cm[63:143]                          # hand, finger and palm markers of both hands
        near = np.linalg.norm(hand[:, None] - p[None], axis=-1).min(1) < 0.1
        ax.scatter(*hand[near & (hc <= CONTACT_LEVEL)].T, s=4, c="#3b6ea8")
        ax.scatter(*hand[near & (hc > CONTACT_LEVEL)].T, s=6, c=MARKER_IN_CONTACT)
        scene.set_equal(ax, p)
        ax.set_title("object contacts C_O (red); hand markers within 10 cm", fontsize=8)
        fig.tight_layout()
        return fig

    @staticmethod
    def describe(numbers: dict[str, float]) -> str:
        """One caption line."""
        return (f"{numbers['markers_in_contact']} markers and {numbers['points_in_contact']} object points above "
                f"p = {CONTACT_LEVEL:g} (C_O: soft count {numbers['points_soft']:.0f} points, largest p "
                f"{numbers['points_max']:.2f}); right palm {numbers['palm_to_object_cm']:.1f} cm from the object; "
                f"|z| = {numbers['z_norm']:.2f}")

    def png(self) -> bytes:
        """The current figure as PNG bytes."""
        from graspkit.viz.export import png_bytes

        return png_bytes(self.figure())

    def widget(self) -> Any:  # pragma: no cover - UI only
        """Sliders for z0..z{dims-1} and the seed, an Image with the figure and a caption."""
        import ipywidgets as w

        img = w.Image(value=self.png(), format="png")
        caption = w.Label(self.describe(self.measure()))
        sliders = [w.FloatSlider(**slider_bounds(self.z[0, i], -3, 3), step=0.1, description=f"z{i}")
                   for i in range(self.dims)]
        seed = w.IntSlider(value=self.seed, min=0, max=max(50, self.seed), description=SEED_SLIDER)

        def changed(change: dict, name: str) -> None:
            numbers = self.update(name, change["new"])
            if name == SEED_SLIDER:
                for i, s in enumerate(sliders):
                    s.unobserve_all()
                    b = slider_bounds(self.z[0, i], s.min, s.max)     # widen first: a value outside is clamped
                    s.min, s.max, s.value = b["min"], b["max"], b["value"]
                    s.observe(lambda c, n=f"z{i}": changed(c, n), names="value")
            img.value, caption.value = self.png(), self.describe(numbers)

        for i, s in enumerate(sliders):
            s.observe(lambda c, n=f"z{i}": changed(c, n), names="value")
        seed.observe(lambda c: changed(c, SEED_SLIDER), names="value")
        return w.VBox([w.HBox([w.VBox(sliders + [seed]), img]), caption])
