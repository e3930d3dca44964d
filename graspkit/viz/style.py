"""The workbook's palette and named camera views, so every figure looks alike."""
from __future__ import annotations

from matplotlib.colors import LinearSegmentedColormap

SKIN = "#e0b49a"        # body
OBJECT = "#5b8db8"      # manipulated object
OBJECT_2 = "#8cb369"    # a second object / support surface
GOAL = "#d62728"        # goal spheres
MARKER = "#2b2d42"      # body markers
ARROW = "#e07a1f"       # offsets, intention vectors
GROUND = "#b8b8b8"      # ground grid lines
TRAJECTORY = "#6a4c93"  # root / wrist paths
SEQUENCE = ["#4c72b0", "#dd8452", "#55a868", "#c44e52", "#8172b3", "#937860"]  # methods, in lesson order

# contact probability in [0, 1]: light grey (no contact) through orange to dark red (certain contact)
CONTACT_CMAP = LinearSegmentedColormap.from_list("graspkit_contact", ["#d9d9d9", "#fdae61", "#d7301f", "#7f0000"])

# camera (elevation, azimuth) in degrees for the z-up world, where a body at rest faces -y
VIEWS: dict[str, tuple[float, float]] = {
    "front": (12.0, -90.0),
    "back": (12.0, 90.0),
    "side": (12.0, 0.0),      # from +x, the body's left
    "left": (12.0, 0.0),
    "right": (12.0, 180.0),
    "top": (90.0, -90.0),     # x to the right, y up the page
    "iso": (22.0, -55.0),
}

AMBIENT = 0.35  # share of light that reaches faces turned away from the light
