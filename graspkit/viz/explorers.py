"""Interactive explorers for the lessons: the state and callback logic are plain Python (unit-tested);
the ipywidgets layer only wires sliders to them and redraws a matplotlib figure.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
import torch

from graspkit.body.model import BodyModel
from graspkit.body.skeleton import JOINT_INDEX, NUM_BODY_JOINTS
from graspkit.checks import check_int

if TYPE_CHECKING:
    from matplotlib.figure import Figure

# joints the body explorer exposes, with the axis (canonical frame) that bends them naturally
EXPLORER_JOINTS: dict[str, tuple[float, float, float]] = {
    "left_shoulder": (0, 0, -1), "right_shoulder": (0, 0, 1),
    "left_elbow": (0, -1, 0), "right_elbow": (0, 1, 0),
    "left_hip": (-1, 0, 0), "right_hip": (-1, 0, 0),
    "left_knee": (1, 0, 0), "right_knee": (1, 0, 0),
    "spine1": (1, 0, 0), "neck": (1, 0, 0),
}


def slider_value(name: str, value: float) -> float:
    """`value` as a float, or a ValueError naming the slider when it is not a finite number (stored, a NaN would
    break every later update)."""
    if isinstance(value, (bool, np.bool_)):      # float(True) is 1.0: a flag is not a slider position
        raise ValueError(f"{name}: expected a number, got {value!r}")
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: expected a number, got {value!r}") from None
    if not np.isfinite(v):
        raise ValueError(f"{name}: expected a finite number, got {value!r}")
    return v


MAX_BETA = 10.0            # stds: a shape coefficient beyond this is a typo (the sliders span ±2)
MAX_ANGLE = 2 * np.pi      # rad: every bend is within a full turn (the sliders span ±1.6)


def bounded_value(name: str, value: Any, most: float, what: str, unit: str = "", note: str = "") -> float:
    """slider_value(name, value) within ±most (a stored absurd value would break every later update), else a
    ValueError naming the slider and saying what it expected."""
    v = slider_value(name, value)
    if abs(v) > most:
        raise ValueError(f"{name}: expected {what} within ±{most:g}{unit}{f' ({note})' if note else ''}, got {value!r}")
    return v


def slider_bounds(value: float | torch.Tensor, low: float, high: float) -> dict[str, float]:
    """A slider's value, min and max: the range [low, high] widened to hold `value` (ipywidgets clamps a value
    outside its range, and the slider would then show a number the explorer does not hold)."""
    v = float(value)
    return {"value": v, "min": min(low, v), "max": max(high, v)}


@dataclass
class BodyExplorerState:
    """Slider values of the body explorer: shape coefficients and one bend angle (radians) per exposed joint."""

    betas: np.ndarray = field(default_factory=lambda: np.zeros(10))
    angles: dict[str, float] = field(default_factory=lambda: {j: 0.0 for j in EXPLORER_JOINTS})

    def set(self, name: str, value: float) -> None:
        """Set one slider: 'beta0'..'beta9' (|value| <= MAX_BETA) or a joint name from EXPLORER_JOINTS (radians,
        |value| <= MAX_ANGLE); unknown name or value out of bounds -> ValueError, the state unchanged."""
        if name.startswith("beta") and name[4:].isdigit() and name == f"beta{int(name[4:])}" \
                and int(name[4:]) < len(self.betas):
            self.betas[int(name[4:])] = bounded_value(name, value, MAX_BETA, "a shape coefficient", note="in stds")
        elif name in self.angles:
            self.angles[name] = bounded_value(name, value, MAX_ANGLE, "an angle in radians")
        else:
            raise ValueError(f"name: unknown slider {name!r}; expected beta0..beta{len(self.betas) - 1} "
                             f"or one of {list(self.angles)}")

    def body_pose(self) -> torch.Tensor:
        """SMPL-X body_pose (1, 63) from the joint sliders."""
        pose = torch.zeros(NUM_BODY_JOINTS + 1, 3)
        for j, a in self.angles.items():
            pose[JOINT_INDEX[j]] = a * torch.tensor(EXPLORER_JOINTS[j], dtype=torch.float32)
        return pose[1:].reshape(1, -1)


def canonical_to_world(points: np.ndarray) -> np.ndarray:
    """Canonical SMPL-X points (..., 3), y up and facing +z, -> z-up world (rotation of +90 deg about x; faces -y)."""
    return np.stack([points[..., 0], -points[..., 2], points[..., 1]], axis=-1)


class BodyExplorer:
    """Shape and a few joints of a body model: `update(name, value)` returns the new vertices and joints."""

    def __init__(self, bm: BodyModel) -> None:
        self.bm, self.state = bm, BodyExplorerState(np.zeros(bm.num_betas))

    def mesh(self) -> tuple[np.ndarray, np.ndarray]:
        """Vertices (V,3) and joints (55,3) for the current state (canonical frame)."""
        with torch.no_grad():
            out = self.bm(betas=torch.as_tensor(self.state.betas, dtype=self.bm.dtype)[None],
                          body_pose=self.state.body_pose().to(self.bm.dtype))
        return out.vertices[0].numpy(), out.joints[0].numpy()

    def update(self, name: str, value: float) -> tuple[np.ndarray, np.ndarray]:
        """Apply one slider change (refused by name, the state unchanged, beyond MAX_BETA / MAX_ANGLE), then return
        (vertices, joints)."""
        self.state.set(name, value)
        return self.mesh()

    def stature(self) -> float:
        """Height of the current body in metres (vertical extent in the canonical y-up frame)."""
        v, _ = self.mesh()
        return float(v[:, 1].max() - v[:, 1].min())

    def figure(self) -> Figure:
        """A matplotlib figure of the current body: front and side views in the z-up world."""
        import matplotlib.pyplot as plt

        from graspkit.viz import draw_mesh, set_equal

        v, _ = self.mesh()
        vz = canonical_to_world(v)
        fig = plt.figure(figsize=(6, 4))
        for k, azim in enumerate((-90, 0)):  # front and side
            ax = fig.add_subplot(1, 2, k + 1, projection="3d")
            draw_mesh(ax, vz, self.bm.faces.numpy())
            set_equal(ax, vz)
            ax.view_init(elev=5, azim=azim)
            ax.set_axis_off()
        fig.suptitle(f"stature {float(v[:, 1].max() - v[:, 1].min()):.2f} m")
        plt.close(fig)
        return fig

    def widget(self, betas_shown: int = 3, dpi: float = 72.0) -> Any:  # pragma: no cover - needs a browser; logic is tested
        """An ipywidgets box: sliders for the first betas and the exposed joints, and the redrawn front/side view."""
        betas_shown = check_int(betas_shown, "betas_shown", 0)
        if betas_shown > len(self.state.betas):
            raise ValueError(f"betas_shown: expected at most the model's {len(self.state.betas)} shape coefficients, "
                             f"got {betas_shown}")
        import ipywidgets as w

        from graspkit.viz.export import png_bytes

        # an Image widget (PNG bytes) rather than an Output widget: no stray display leaks into the notebook cell
        image = w.Image(format="png")

        def redraw() -> None:
            image.value = png_bytes(self.figure(), dpi)

        # the sliders start at the explorer's current state (after any `update`), their range widened to hold it
        sliders = [w.FloatSlider(**slider_bounds(self.state.betas[i], -2, 2), step=0.25, description=f"beta{i}",
                                 continuous_update=False) for i in range(betas_shown)]
        sliders += [w.FloatSlider(**slider_bounds(self.state.angles[j], -1.6, 1.6), step=0.1, description=j,
                                  continuous_update=False) for j in EXPLORER_JOINTS]
        for s in sliders:
            s.observe(lambda ch, s=s: (self.state.set(s.description, ch["new"]), redraw()), names="value")
        redraw()
        return w.HBox([w.VBox(sliders), image])
