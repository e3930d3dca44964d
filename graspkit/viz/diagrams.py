"""Block diagrams drawn with matplotlib: the workbook's pipeline picture."""
from __future__ import annotations

import matplotlib.pyplot as plt
from matplotlib.figure import Figure
from matplotlib.patches import FancyArrowPatch, FancyBboxPatch

_ROWS = [
    ("SAGA (ECCV 2022)", ["object\n(points + normals)", "WholeGrasp-VAE\nmarkers + contacts", "GraspPose-Opt\nSMPL-X grasp",
                          "MotionFill-VAE\ntrajectory + local", "GraspMotion-Opt\napproach motion"], "#4C72B0"),
    ("GOAL (CVPR 2022)", ["object\n(BPS code)", "GNet\nbody + offsets", "refinement\n(offsets, feet)",
                          "MNet\n10 frames at a time", "approach motion\n+ grasp"], "#DD8452"),
    ("WANDR (CVPR 2024)", ["3D goal\n+ time t_G", "intention features\nwrist / orient. / pelvis",
                           "CVAE on pose\ndeltas (per frame)", "rollout\n(autoregressive)", "walk-and-reach\nmotion"], "#55A868"),
]


def pipeline_diagram(width: float = 12.0) -> Figure:
    """The three methods as rows of boxes (input -> model -> optimiser -> output); returns the Figure (a pyplot one,
    shown inline in a notebook; plt.close(fig) when done with it outside one)."""
    fig, ax = plt.subplots(figsize=(width, width * 0.36))
    ax.set_xlim(0, 10.4)
    ax.set_ylim(0, 3.3)
    ax.axis("off")
    for r, (name, boxes, color) in enumerate(_ROWS):
        y = 2.55 - r * 1.05
        ax.text(0.05, y + 0.47, name, fontsize=10, fontweight="bold", color=color)
        for i, label in enumerate(boxes):
            x = 0.1 + i * 2.07
            ax.add_patch(FancyBboxPatch((x, y - 0.3), 1.75, 0.62, boxstyle="round,pad=0.03",
                                        fc=color, alpha=0.18 if i in (0, len(boxes) - 1) else 0.4, ec=color))
            ax.text(x + 0.875, y, label, ha="center", va="center", fontsize=8)
            if i:
                ax.add_patch(FancyArrowPatch((x - 0.3, y), (x - 0.02, y), arrowstyle="-|>", mutation_scale=12, color="0.3"))
    ax.text(5.2, 0.02, "shared: SMPL-X body model · objects & contact geometry · synthetic data · metrics",
            ha="center", fontsize=9, style="italic", color="0.35")
    return fig
