"""graspkit: a workbook that teaches and implements whole-body motion synthesis towards objects and goals.

SAGA (ECCV 2022), GOAL (CVPR 2022) and WANDR (CVPR 2024) at small scale, on synthetic procedural data.
"""
__version__ = "0.1.0"
