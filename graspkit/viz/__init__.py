"""Pictures for the workbook, all in the z-up world (metres): static 3D scenes (scene), animations (animate),
mesh export (export) and the shared palette (style).

    fig, axes = viz.figure(views=("front", "side", "top"))
    viz.draw_mesh(axes[0], vertices, faces)                       # (V,3), (F,3); numpy or torch
    fig = viz.show_scene(meshes=[(v, f), (ov, of, viz.OBJECT)], points=p, values=contact, goals=g)
    viz.show_animation(viz.animate(vertex_sequence, faces, goals=g))      # inline in a notebook
    viz.export_scene({"body": (v, f), "mug": (ov, of)}, "scene.glb")

Note: `viz.animate` is the function; import the module's other names with `from graspkit.viz.animate import ...`.
"""
from graspkit.viz.animate import animate, save_animation, show_animation, to_html
from graspkit.viz.export import export_motion, export_scene, export_sequence_glb, load_sequence_glb
from graspkit.viz.scene import (as_array, as_mesh, as_points, bounds_of, draw_arrows, draw_goal, draw_ground,
                                draw_markers, draw_mesh, draw_meshes, draw_path, draw_points, figure, lambert,
                                set_equal, show_scene, sphere, to_numpy, value_colors)
from graspkit.viz.style import (ARROW, CONTACT_CMAP, GOAL, GROUND, MARKER, OBJECT, OBJECT_2, SEQUENCE, SKIN,
                                TRAJECTORY, VIEWS)

__all__ = ["animate", "save_animation", "show_animation", "to_html", "export_motion", "export_scene", "export_sequence_glb",
           "load_sequence_glb", "as_array", "as_mesh", "as_points", "bounds_of", "draw_arrows", "draw_goal",
           "draw_ground", "draw_markers", "draw_mesh", "draw_meshes", "draw_path", "draw_points", "figure", "lambert",
           "set_equal", "show_scene", "sphere", "to_numpy", "value_colors", "ARROW", "CONTACT_CMAP", "GOAL", "GROUND",
           "MARKER", "OBJECT", "OBJECT_2", "SEQUENCE", "SKIN", "TRAJECTORY", "VIEWS"]
