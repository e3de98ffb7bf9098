"""Debug output of a card build, for a person to look at: strand textures as PNGs, card meshes as OBJ."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..atomic import atomic_open, atomic_path
from ..errors import require
from ..geometry import card_mesh
from .build import CardBuild

ATLAS_COLUMNS = 40
TEXEL_SCALE = 4  # each texel as a 4x4 block in the per-card PNGs


def texture_atlas(textures: np.ndarray, groups: np.ndarray, columns: int = ATLAS_COLUMNS) -> np.ndarray:
    """All textures ``[C, T, T]`` in one RGB image (8-bit), sorted by group, a 1-texel gap between.

    Strands are white on a background tinted by the card's group, so groups read as bands.
    """
    c, t, _ = textures.shape
    order = np.argsort(groups, kind="stable")
    rows = -(-c // columns)
    cell = t + 1
    atlas = np.zeros((rows * cell, columns * cell, 3))
    hue = np.random.default_rng(0).uniform(0.05, 0.3, (int(groups.max()) + 1, 3))
    for i, card in enumerate(order):
        y, x = divmod(i, columns)
        tex = textures[card][..., None]
        atlas[y * cell: y * cell + t, x * cell: x * cell + t] = tex + (1 - tex) * hue[groups[card]]
    return (atlas.clip(0, 1) * 255).round().astype(np.uint8)


def write_obj(build: CardBuild, path: Path) -> None:
    """The card strip meshes as a Wavefront OBJ: one object per card, named with its group."""
    cards = build.asset.cards
    mesh = card_mesh(cards)
    tris_per_card = 2 * cards.segments
    with atomic_open(path, "w", encoding="ascii") as f:
        f.write(f"# {cards.count} hair cards of {cards.segments} segments, written by cgh cards --debug-dir\n")
        np.savetxt(f, mesh.vertices, fmt="v %.7g %.7g %.7g")
        np.savetxt(f, mesh.uvs, fmt="vt %.7g %.7g")
        np.savetxt(f, mesh.normals, fmt="vn %.7g %.7g %.7g")
        tri = mesh.triangles.astype(np.int64) + 1
        for card in range(cards.count):
            f.write(f"o card_{card:05d}_group_{int(cards.group[card]):03d}\n")
            block = tri[card * tris_per_card:(card + 1) * tris_per_card]
            rows = np.repeat(block, 3, axis=1).reshape(-1, 9)
            np.savetxt(f, rows, fmt="f %d/%d/%d %d/%d/%d %d/%d/%d")


def write_debug(build: CardBuild, directory: str | Path, per_card_limit: int = 10000) -> list[Path]:
    """Write ``textures.png`` (atlas), ``textures/card_NNNNN.png`` and ``cards.obj``; return the paths."""
    image = require("PIL.Image", "cards", "card debug images", package="pillow")
    out = Path(directory)
    (out / "textures").mkdir(parents=True, exist_ok=True)
    groups = build.asset.cards.group
    written = []
    atlas = out / "textures.png"
    with atomic_path(atlas) as tmp:
        image.fromarray(texture_atlas(build.textures, groups)).save(tmp)
    written.append(atlas)
    for card, tex in enumerate(build.textures[:per_card_limit]):
        big = np.kron(tex, np.ones((TEXEL_SCALE, TEXEL_SCALE)))
        p = out / "textures" / f"card_{card:05d}_group_{int(groups[card]):03d}.png"
        with atomic_path(p) as tmp:
            image.fromarray((big.clip(0, 1) * 255).round().astype(np.uint8)).save(tmp)
    written.append(out / "textures")
    obj = out / "cards.obj"
    write_obj(build, obj)
    written.append(obj)
    return written
