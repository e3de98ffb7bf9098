"""Blender worker: ``python groom.py OP SRC DST``, converting a groom through Blender (bpy 5.0).

- ``abc_to_usd``: import an Alembic file, write a y-up USD stage (read back by :mod:`..usd_curves`).
- ``abc_frames_to_usd``: the same with every frame of the scene's range (which the import sets to the
  file's) as time samples (read back by :mod:`..usd_cache`).
- ``abc_xforms_to_usd``: the same for an Alembic file of transforms only (a head's track, read back by
  :mod:`..xform_track`): no curves needed.
- ``usd_to_blend``: import our USD stage, give the curves Blender's Principled Hair BSDF (colour
  from the ``displayColor`` attribute) and save a .blend file.

Runs in its own process (see :mod:`cghair_format.exchange.alembic`); it imports only bpy. Prints
``CGH_DONE`` on success; any failure exits non-zero with Blender's message.
"""

from __future__ import annotations

import sys


def hair_material(bpy):
    """Principled Hair BSDF, coloured directly by the ``displayColor`` point attribute (linear)."""
    mat = bpy.data.materials.new("StrandHair")
    mat.use_nodes = True
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    nodes.clear()
    out = nodes.new("ShaderNodeOutputMaterial")
    bsdf = nodes.new("ShaderNodeBsdfHairPrincipled")
    bsdf.parametrization = "COLOR"
    attr = nodes.new("ShaderNodeAttribute")
    attr.attribute_name = "displayColor"
    links.new(attr.outputs["Color"], bsdf.inputs["Color"])
    links.new(bsdf.outputs[0], out.inputs["Surface"])
    return mat


def main(op: str, src: str, dst: str) -> None:
    import bpy

    bpy.ops.wm.read_factory_settings(use_empty=True)
    if op == "usd_to_blend":
        if bpy.ops.wm.usd_import(filepath=src) != {"FINISHED"}:
            raise SystemExit(f"Blender could not import {src}")
    elif op in ("abc_to_usd", "abc_frames_to_usd", "abc_xforms_to_usd"):
        if bpy.ops.wm.alembic_import(filepath=src) != {"FINISHED"}:
            raise SystemExit(f"Blender could not import {src}")
        if op != "abc_xforms_to_usd" and not any(o.type == "CURVES" for o in bpy.data.objects):
            raise SystemExit(f"{src}: the Alembic file has no curves")
    else:
        raise SystemExit(f"unknown operation {op!r}")
    if op != "usd_to_blend":
        result = bpy.ops.wm.usd_export(filepath=dst, convert_orientation=True, export_global_up_selection="Y",
                                       export_global_forward_selection="NEGATIVE_Z", export_materials=False,
                                       export_animation=op != "abc_to_usd")
    else:
        material = hair_material(bpy)
        for obj in bpy.data.objects:
            if obj.type == "CURVES":
                obj.data.materials.clear()
                obj.data.materials.append(material)
        bpy.ops.file.pack_all()  # the card texture lives in a temporary folder
        result = bpy.ops.wm.save_as_mainfile(filepath=dst, compress=True)
    if result != {"FINISHED"}:
        raise SystemExit(f"Blender could not write {dst}")
    print("CGH_DONE")


if __name__ == "__main__":
    main(*sys.argv[1:4])
