"""Blender worker: ``python render_cycles.py JOB_DIR``. Reads JOB_DIR/job.npz and job.json, renders
every camera with Cycles (CPU), and writes JOB_DIR/r_000.png ... (RGBA, transparent background).

Runs in its own process (see :mod:`training.datasets.cycles`); it imports only numpy and bpy.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

KEY, FILL, RIM = 3.5, 1.2, 2.5  # sun strengths of the light rig
AMBIENT = 0.25  # world background strength (lights the hair; the film is transparent)
RANDOM_COLOR = 0.15  # per-strand melanin variation of the preset
# the strands' colours as a point attribute; Cycles reads an attribute named "color" as zeros
COLOR_ATTRIBUTE = "hair_rgb"


def _hair_object(bpy, points, offsets, radius, colors):
    counts = np.diff(offsets)
    curves = bpy.data.hair_curves.new("hair")
    curves.add_curves([int(c) for c in counts])
    curves.position_data.foreach_set("vector", points.reshape(-1).astype(np.float32))
    if "radius" not in curves.attributes:
        curves.attributes.new("radius", "FLOAT", "POINT")
    curves.attributes["radius"].data.foreach_set("value", radius.astype(np.float32))
    if colors is not None:
        attr = curves.attributes.new(COLOR_ATTRIBUTE, "FLOAT_COLOR", "POINT")
        rgba = np.concatenate([colors, np.ones((len(colors), 1), np.float32)], 1)
        attr.data.foreach_set("color", rgba.reshape(-1))
    obj = bpy.data.objects.new("hair", curves)
    bpy.context.scene.collection.objects.link(obj)
    return obj


def _material(bpy, has_colors: bool, melanin: float, redness: float):
    mat = bpy.data.materials.new("hair")
    mat.use_nodes = True
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    nodes.clear()
    out = nodes.new("ShaderNodeOutputMaterial")
    bsdf = nodes.new("ShaderNodeBsdfHairPrincipled")
    if has_colors:
        bsdf.parametrization = "COLOR"
        attr = nodes.new("ShaderNodeAttribute")
        attr.attribute_name = COLOR_ATTRIBUTE
        links.new(attr.outputs["Color"], bsdf.inputs["Color"])
    else:
        bsdf.parametrization = "MELANIN"
        bsdf.inputs["Melanin"].default_value = melanin
        bsdf.inputs["Melanin Redness"].default_value = redness
        bsdf.inputs["Random Color"].default_value = RANDOM_COLOR
    links.new(bsdf.outputs[0], out.inputs["Surface"])
    return mat


def _lights(bpy, up: np.ndarray, side: np.ndarray, front: np.ndarray):
    from mathutils import Vector

    for name, strength, towards in (("key", KEY, -(0.8 * up + 0.6 * side + 0.6 * front)),
                                    ("fill", FILL, -(0.3 * up - 0.8 * side + 0.5 * front)),
                                    ("rim", RIM, -(0.7 * up - 0.9 * front))):
        light = bpy.data.lights.new(name, "SUN")
        light.energy = strength
        obj = bpy.data.objects.new(name, light)
        obj.rotation_mode = "QUATERNION"
        obj.rotation_quaternion = Vector(towards.tolist()).to_track_quat("-Z", "Y")
        bpy.context.scene.collection.objects.link(obj)


def main(job: Path) -> None:
    import bpy
    from mathutils import Matrix

    data = np.load(job / "job.npz")
    cfg = json.loads((job / "job.json").read_text())
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = cfg["samples"]
    scene.cycles.seed = cfg["seed"]
    scene.cycles.use_denoising = bool(cfg.get("denoise"))
    if scene.cycles.use_denoising:  # OpenImageDenoise on the CPU, guided by albedo and normals
        scene.cycles.denoiser = "OPENIMAGEDENOISE"
        scene.cycles.denoising_input_passes = "RGB_ALBEDO_NORMAL"
    scene.cycles_curves.shape = "THICK"
    scene.render.film_transparent = True
    scene.render.resolution_x, scene.render.resolution_y = cfg["width"], cfg["height"]
    scene.render.resolution_percentage = 100
    scene.render.image_settings.file_format = "PNG"
    scene.render.image_settings.color_mode = "RGBA"
    scene.render.image_settings.color_depth = "8"
    scene.view_settings.view_transform = "Standard"
    world = bpy.data.worlds.new("world")
    world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)
    world.node_tree.nodes["Background"].inputs["Strength"].default_value = AMBIENT
    scene.world = world

    colors = data["colors"] if "colors" in data.files else None
    obj = _hair_object(bpy, data["points"], data["offsets"], data["radius"], colors)
    obj.data.materials.append(_material(bpy, colors is not None, cfg["melanin"], cfg["redness"]))
    up = np.array([0.0, 1.0, 0.0]) if cfg["up_axis"] == "Y" else np.array([0.0, 0.0, 1.0])
    front = np.array([0.0, 0.0, 1.0]) if cfg["up_axis"] == "Y" else np.array([0.0, -1.0, 0.0])
    _lights(bpy, up, np.cross(up, front), front)

    cam_data = bpy.data.cameras.new("cam")
    cam_data.sensor_fit = "HORIZONTAL"
    cam_data.angle = cfg["fov_x"]
    pts = data["points"]
    extent = float(np.linalg.norm(pts.max(0) - pts.min(0))) or 1.0
    cam_data.clip_start = 1e-3 * extent
    cam_data.clip_end = 1e3 * extent
    cam = bpy.data.objects.new("cam", cam_data)
    scene.collection.objects.link(cam)
    scene.camera = cam
    for i, c2w in enumerate(data["c2w"]):
        cam.matrix_world = Matrix(c2w.tolist())
        scene.render.filepath = str(job / f"r_{i:03d}.png")
        bpy.ops.render.render(write_still=True)
        if cfg.get("progress"):
            print(f"cycles: view {i + 1}/{len(data['c2w'])}", file=sys.stderr, flush=True)


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit("usage: render_cycles.py JOB_DIR")
    main(Path(sys.argv[1]))
