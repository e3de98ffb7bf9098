"""Blender script (run with the bpy interpreter): ``render_colours.py SCENE OUT_DIR RES``.

Opens a .blend (or imports a USD stage), frames the curves and meshes from the front with an
orthographic camera and renders them with Cycles at RES x RES: lit by a uniform white world
(``*_lit``), then with every material's colour input re-wired into an emission shader
(``*_colour``: the colour Cycles sees, texture and colour attribute included, without lighting).
Prints ``CGH_REPORT`` with the objects, their materials and, per render, the coverage and the
mean linear colour (premultiplied sum over alpha sum).
"""

import json
import sys

import bpy
import numpy as np
from mathutils import Vector

GEOMETRY = ("CURVES", "MESH")


def load(path: str) -> None:
    if path.endswith(".blend"):
        bpy.ops.wm.open_mainfile(filepath=path)
    else:
        bpy.ops.wm.read_factory_settings(use_empty=True)
        assert bpy.ops.wm.usd_import(filepath=path) == {"FINISHED"}


def setup(res: int):
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = 16
    scene.render.resolution_x = scene.render.resolution_y = res
    scene.render.film_transparent = True
    scene.view_settings.view_transform = "Standard"
    scene.render.image_settings.file_format = "OPEN_EXR"
    scene.render.image_settings.color_depth = "32"
    world = bpy.data.worlds.new("white")
    scene.world = world
    world.use_nodes = True
    background = world.node_tree.nodes["Background"]
    background.inputs["Color"].default_value = (1, 1, 1, 1)
    corners = [tuple(o.matrix_world @ Vector(c)) for o in bpy.data.objects if o.type in GEOMETRY
               for c in o.bound_box]
    lo, hi = np.min(corners, 0), np.max(corners, 0)
    size = float(max(hi - lo))
    cam = bpy.data.objects.new("cam", bpy.data.cameras.new("cam"))
    cam.data.type = "ORTHO"
    cam.data.ortho_scale = 1.1 * size
    cam.data.clip_end = 10 * size + 10
    centre = (lo + hi) / 2
    cam.location = (centre[0], lo[1] - 2 * size, centre[2])  # in front (Blender's -y), looking along +y
    cam.rotation_euler = (np.pi / 2, 0, 0)
    scene.collection.objects.link(cam)
    scene.camera = cam
    return scene, background


def emission_only() -> None:
    """Every material shows its colour input (and alpha) unlit."""
    for mat in bpy.data.materials:
        if not mat.use_nodes:
            continue
        nodes, links = mat.node_tree.nodes, mat.node_tree.links
        bsdf = next((n for n in nodes if n.type in ("BSDF_PRINCIPLED", "BSDF_HAIR_PRINCIPLED")), None)
        out = next((n for n in nodes if n.type == "OUTPUT_MATERIAL"), None)
        if bsdf is None or out is None:
            continue
        emission = nodes.new("ShaderNodeEmission")
        transparent = nodes.new("ShaderNodeBsdfTransparent")
        mix = nodes.new("ShaderNodeMixShader")
        principled = bsdf.type == "BSDF_PRINCIPLED"
        base = bsdf.inputs["Base Color" if principled else "Color"]
        if base.is_linked:
            links.new(base.links[0].from_socket, emission.inputs["Color"])
        else:
            emission.inputs["Color"].default_value = base.default_value
        alpha = bsdf.inputs["Alpha"] if principled else None
        if alpha is not None and alpha.is_linked:
            links.new(alpha.links[0].from_socket, mix.inputs["Fac"])
        else:
            mix.inputs["Fac"].default_value = 1.0 if alpha is None else alpha.default_value
        links.new(transparent.outputs[0], mix.inputs[1])
        links.new(emission.outputs[0], mix.inputs[2])
        links.new(mix.outputs[0], out.inputs["Surface"])


def render(scene, out_dir: str, tag: str, show: list[str]) -> dict:
    for o in bpy.data.objects:
        if o.type in GEOMETRY + ("POINTCLOUD",):
            o.hide_render = o.name not in show
    scene.render.filepath = f"{out_dir}/{tag}.exr"
    bpy.ops.render.render(write_still=True)
    px = np.array(bpy.data.images.load(scene.render.filepath).pixels[:], np.float64).reshape(-1, 4)
    alpha = px[:, 3].sum()
    return {"alpha": alpha / len(px), "mean": (px[:, :3].sum(0) / max(alpha, 1e-9)).tolist()}


def main(path: str, out_dir: str, res: int) -> None:
    load(path)
    report = {"objects": {o.name: o.type for o in bpy.data.objects},
              "materials": {o.name: [m.name for m in o.data.materials] for o in bpy.data.objects
                            if o.type in GEOMETRY}}
    scene, background = setup(res)
    curves = [o.name for o in bpy.data.objects if o.type == "CURVES"]
    meshes = [o.name for o in bpy.data.objects if o.type == "MESH"]
    background.inputs["Strength"].default_value = 1.0  # a uniform white world, no lights
    report["cards_lit"] = render(scene, out_dir, "cards_lit", meshes)
    report["curves_lit"] = render(scene, out_dir, "curves_lit", curves)
    background.inputs["Strength"].default_value = 0.0
    emission_only()
    report["cards_colour"] = render(scene, out_dir, "cards_colour", meshes)
    report["curves_colour"] = render(scene, out_dir, "curves_colour", curves)
    print("CGH_REPORT " + json.dumps(report))


if __name__ == "__main__":
    main(sys.argv[-3], sys.argv[-2], int(sys.argv[-1]))
