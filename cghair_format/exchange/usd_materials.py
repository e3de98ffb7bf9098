"""Materials of the USD export: UsdPreviewSurface networks that DCCs (Blender, usdview, Omniverse) read.

- Curves: ``diffuseColor`` from the ``displayColor`` primvar (linear) through a
  ``UsdPrimvarReader_float3``, ``opacity`` from ``displayOpacity``.
- Cards: each card's strand texture (coverage of its strands, :func:`~cghair_format.cards.textures.strand_textures`)
  as opacity and the mean colour of its strands as colour, packed into one RGBA atlas PNG written
  beside the USD file; the Mesh's ``st`` point into the atlas, read through ``UsdUVTexture``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..asset import HairAsset
from ..errors import require

MATERIALS = "/Hair/Materials"
TILE_BORDER = 1  # texels copied from the tile's edge around each card's texture, against bleeding


def card_atlas(asset: HairAsset, size: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The cards' texture atlas ``[H, W, 4]`` uint8 (sRGB colour, linear alpha = strand coverage)
    and each card vertex's atlas coordinate ``st`` ``[C * 2(M+1), 2]`` (origin bottom left)."""
    from ..cards.textures import TEXTURE_SIZE, strand_textures
    from ._common import linear_to_srgb, srgb_to_linear
    from .cgh_strands import strand_colors

    size = size or TEXTURE_SIZE
    c, m1 = asset.cards.count, asset.cards.spine.shape[1]
    coverage = strand_textures(asset.uvd[..., :2], asset.strand_card, c, size, asset.counts)  # rows along u
    real = asset.real_points()[..., None]
    strand_rgb = (srgb_to_linear(strand_colors(asset)) * real).sum(1) / real.sum(1)  # [S, 3], in linear light
    n = np.bincount(asset.strand_card, minlength=c).astype(np.float64)
    card_rgb = np.stack([np.bincount(asset.strand_card, strand_rgb[:, i], c) for i in range(3)], 1)
    card_rgb = linear_to_srgb(np.where(n[:, None] > 0, card_rgb / np.maximum(n, 1)[:, None], 0.2))
    tile = size + 2 * TILE_BORDER
    cols = int(np.ceil(np.sqrt(c)))
    rows = -(-c // cols)
    rgba = np.concatenate([np.broadcast_to(card_rgb[:, None, None, :], (c, size, size, 3)), coverage[..., None]], -1)
    padded = np.pad(rgba, ((0, rows * cols - c), (TILE_BORDER,) * 2, (TILE_BORDER,) * 2, (0, 0)), mode="edge")
    atlas = padded.reshape(rows, cols, tile, tile, 4).transpose(0, 2, 1, 3, 4).reshape(rows * tile, cols * tile, 4)
    card = np.arange(c * 2 * m1) // (2 * m1)
    k = np.arange(c * 2 * m1) % (2 * m1)
    u, v = (k // 2) / (m1 - 1), (k % 2).astype(np.float64)
    x = (card % cols) * tile + TILE_BORDER + v * (size - 1) + 0.5  # texel centres, in pixels
    y = (card // cols) * tile + TILE_BORDER + u * (size - 1) + 0.5
    st = np.stack([x / atlas.shape[1], 1 - y / atlas.shape[0]], 1).astype(np.float32)
    return (np.clip(atlas, 0, 1) * 255).round().astype(np.uint8), st


def _surface(stage, name: str):
    from pxr import Sdf, UsdShade

    material = UsdShade.Material.Define(stage, f"{MATERIALS}/{name}")
    shader = UsdShade.Shader.Define(stage, f"{MATERIALS}/{name}/Surface")
    shader.CreateIdAttr("UsdPreviewSurface")
    shader.CreateInput("roughness", Sdf.ValueTypeNames.Float).Set(0.45)
    shader.CreateInput("specularColor", Sdf.ValueTypeNames.Color3f).Set((0.04, 0.04, 0.04))
    shader.CreateInput("useSpecularWorkflow", Sdf.ValueTypeNames.Int).Set(1)
    material.CreateSurfaceOutput().ConnectToSource(shader.ConnectableAPI(), "surface")
    return material, shader


def _bind(prim, material) -> None:
    from pxr import UsdShade

    UsdShade.MaterialBindingAPI.Apply(prim).Bind(material)


def bind_curve_material(stage, curves_prim, has_opacity: bool) -> None:
    """``displayColor`` (and ``displayOpacity``) through primvar readers into a preview surface."""
    from pxr import Sdf, UsdShade

    material, surface = _surface(stage, "StrandMaterial")
    reader = UsdShade.Shader.Define(stage, f"{MATERIALS}/StrandMaterial/DisplayColor")
    reader.CreateIdAttr("UsdPrimvarReader_float3")
    reader.CreateInput("varname", Sdf.ValueTypeNames.Token).Set("displayColor")
    surface.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).ConnectToSource(
        reader.CreateOutput("result", Sdf.ValueTypeNames.Float3))
    if has_opacity:
        alpha = UsdShade.Shader.Define(stage, f"{MATERIALS}/StrandMaterial/DisplayOpacity")
        alpha.CreateIdAttr("UsdPrimvarReader_float")
        alpha.CreateInput("varname", Sdf.ValueTypeNames.Token).Set("displayOpacity")
        surface.CreateInput("opacity", Sdf.ValueTypeNames.Float).ConnectToSource(
            alpha.CreateOutput("result", Sdf.ValueTypeNames.Float))
    _bind(curves_prim, material)


def bind_card_material(stage, mesh_prim, png: Path, usd_path: Path) -> None:
    """The card atlas ``png`` (beside ``usd_path``) as colour and opacity, read at the ``st`` primvar."""
    from pxr import Sdf, UsdShade

    material, surface = _surface(stage, "CardMaterial")
    st = UsdShade.Shader.Define(stage, f"{MATERIALS}/CardMaterial/UV")
    st.CreateIdAttr("UsdPrimvarReader_float2")
    st.CreateInput("varname", Sdf.ValueTypeNames.Token).Set("st")
    tex = UsdShade.Shader.Define(stage, f"{MATERIALS}/CardMaterial/StrandTexture")
    tex.CreateIdAttr("UsdUVTexture")
    tex.CreateInput("file", Sdf.ValueTypeNames.Asset).Set(f"./{png.relative_to(usd_path.parent).as_posix()}")
    tex.CreateInput("sourceColorSpace", Sdf.ValueTypeNames.Token).Set("sRGB")
    tex.CreateInput("wrapS", Sdf.ValueTypeNames.Token).Set("clamp")
    tex.CreateInput("wrapT", Sdf.ValueTypeNames.Token).Set("clamp")
    tex.CreateInput("st", Sdf.ValueTypeNames.Float2).ConnectToSource(
        st.CreateOutput("result", Sdf.ValueTypeNames.Float2))
    surface.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).ConnectToSource(
        tex.CreateOutput("rgb", Sdf.ValueTypeNames.Float3))
    surface.CreateInput("opacity", Sdf.ValueTypeNames.Float).ConnectToSource(
        tex.CreateOutput("a", Sdf.ValueTypeNames.Float))
    _bind(mesh_prim, material)


def write_png(path: Path, rgba: np.ndarray) -> None:
    image = require("PIL.Image", "cards", "the card texture PNG of a USD export", package="pillow")
    image.fromarray(rgba, "RGBA").save(path)
