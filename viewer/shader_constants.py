"""Constants shared by the Python side and the GLSL, defined once here and handed to every shader
as ``#define`` lines after its ``#version`` line (:mod:`viewer.pipeline`), and the work-group
sizes chosen per OpenGL driver.

Work-group sizes: NVIDIA runs invocations in warps of 32 and AMD in waves of 32 or 64, so a
work group that is not a multiple of 32 leaves lanes idle; llvmpipe compiles a work group into
8-wide SIMD loops and prefers few invocations with much work each (the tile blend at 16 rows per
invocation took about half the time of 4 rows; docs/viewer.md). Only the tile blend's shape
differs between the two; every other size is a multiple of 32 on all drivers.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

TILE = 16  # pixels per tile side of the compute rasterizer
RUN = 16  # consecutive sorted splats per tile-binning invocation
TEXELS_PER_ROW = 4096  # width of the data images (a power of two: texel k is at (k % W, k / W))
RECORD_VEC4S = 4  # a splat record: 4 vec4s (storage buffer) or 4 RGBA32F texels (record image)
LOCAL_SIZE = 256  # work-group size of the one-invocation-per-item compute shaders
LATENT_LOCAL_SIZE = 64  # the strand-latent pass (one invocation per strand, heavier each)
RADIX_BITS = 4  # key bits per radix-sort pass
RADIX_THREADS = 256  # invocations per radix-sort work group
RADIX_ITEMS = 16  # consecutive keys per radix-sort invocation
RADIX_SCAN_THREADS = 1024  # the one work group that scans the block histograms (and the tile runs)
# Tile entries one tile_blend dispatch blends per tile: Mesa's gallivm (llvmpipe) ends a shader
# invocation after 65,535 loop iterations (LP_MAX_TGSI_LOOP_ITERATIONS, all its loops together),
# so a denser tile is blended over several dispatches (viewer/tiles.py). The blend's per-row loops
# have constant trip counts and are unrolled (the limit was measured to fall at the 65,535th
# entry); the margin covers them if not. Near the limit, so that a paper-scale 1080p frame (60,997
# entries in its longest tile, docs/viewer.md) still takes one dispatch.
BLEND_CHUNK = 65_000
# Tile entries one tile_emit dispatch writes per run of RUN splats (the same limit): besides these,
# an invocation loops over its splats and their rows of tiles (RUN x 270 rows at 8K).
EMIT_CHUNK = 1 << 15

SOFTWARE_RENDERERS = ("llvmpipe", "softpipe", "swrast")  # GL_RENDERER names of CPU renderers


@dataclass(frozen=True)
class Workgroups:
    """The driver-dependent work-group shapes (recorded in ``cgh bench-viewer``'s JSON)."""

    profile: str  # the table entry: "llvmpipe", "NVIDIA", "AMD" or "gpu" (any other driver)
    blend: tuple[int, int]  # tile_blend's (local_size_x, local_size_y): TILE columns x row groups

    @property
    def blend_rows(self) -> int:
        """Pixels each tile_blend invocation blends (a column of the tile, split by row groups)."""
        return TILE // self.blend[1]

    def record(self) -> dict:
        """Every work-group size the viewer dispatches, for the benchmark's JSON."""
        return {**asdict(self), "blend": list(self.blend), "blend_rows": self.blend_rows, "items": LOCAL_SIZE,
                "latent": LATENT_LOCAL_SIZE, "radix": RADIX_THREADS,
                "scan": RADIX_SCAN_THREADS}


# keyed by a word of GL_VENDOR; software renderers are recognised by GL_RENDERER (Mesa's vendor
# string is the same for its hardware drivers on some systems)
WORKGROUPS = {
    "llvmpipe": Workgroups("llvmpipe", (TILE, 1)),  # 16 invocations, a 16-pixel column each
    "NVIDIA": Workgroups("NVIDIA", (TILE, TILE)),  # 256 invocations (8 warps), a pixel each
    "AMD": Workgroups("AMD", (TILE, TILE)),  # 256 invocations (4 waves of 64), a pixel each
    "gpu": Workgroups("gpu", (TILE, TILE)),
}
VENDOR_WORDS = {"NVIDIA": "NVIDIA", "AMD": "AMD", "ATI": "AMD"}


def workgroups_for(vendor: str | None, renderer: str | None) -> Workgroups:
    """The table entry for a driver, from its ``GL_VENDOR`` and ``GL_RENDERER`` strings."""
    if any(s in str(renderer or "").lower() for s in SOFTWARE_RENDERERS):
        return WORKGROUPS["llvmpipe"]
    for word, profile in VENDOR_WORDS.items():
        if word in str(vendor or ""):
            return WORKGROUPS[profile]
    return WORKGROUPS["gpu"]


def glsl_defines(workgroups: Workgroups) -> str:
    """The ``#define`` lines every shader is compiled with (plain integers: they also size
    ``layout(local_size_x = ...)``, which GLSL 4.30 wants as integer constants)."""
    row_shift = TEXELS_PER_ROW.bit_length() - 1
    if TEXELS_PER_ROW != 1 << row_shift or TILE % workgroups.blend[1]:
        raise ValueError("TEXELS_PER_ROW must be a power of two and the blend's row groups divide TILE")
    values = {"TILE": TILE, "RUN": RUN, "TEXEL_ROW_SHIFT": row_shift, "RECORD_VEC4S": RECORD_VEC4S,
              "LOCAL_SIZE": LOCAL_SIZE, "LATENT_LOCAL_SIZE": LATENT_LOCAL_SIZE,
              "RADIX_DIGITS": 1 << RADIX_BITS, "RADIX_THREADS": RADIX_THREADS, "RADIX_ITEMS": RADIX_ITEMS,
              "RADIX_SCAN_THREADS": RADIX_SCAN_THREADS, "BLEND_CHUNK": BLEND_CHUNK, "EMIT_CHUNK": EMIT_CHUNK,
              "BLEND_GROUP_X": workgroups.blend[0], "BLEND_GROUP_Y": workgroups.blend[1],
              "BLEND_ROWS": workgroups.blend_rows}
    return "".join(f"#define {name} {value}\n" for name, value in values.items())
