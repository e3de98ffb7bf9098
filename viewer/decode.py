"""GPU decode: a :class:`HairAsset` (or plain :class:`Gaussians`) to Gaussians in storage buffers.

Compute shaders rebuild the card strips, the strand points (card triangle + barycentrics +
delta), the segment Gaussians' frames, the strand latents and the appearance MLP, reproducing
:func:`cghair_format.decode_gaussians` in float32. SH coefficients can exceed one storage
block (2.5 M Gaussians x 48 floats is 480 MB; llvmpipe allows 128 MiB per block), so they are
decoded in chunks of whole strands, and each chunk is kept as an image (``sh_texture``) that the
preprocess fetches as texels, each Gaussian's coefficients on whole texels.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from cghair_format import Gaussians, HairAsset
from cghair_format.errors import CghError

from .pipeline import Programs, bind, bind_images, data_image, dispatch, max_texture_size, set_uniforms, use_textures
from .shader_constants import LATENT_LOCAL_SIZE, TEXELS_PER_ROW

DEFAULT_BLOCK_LIMIT = 128 << 20


@dataclass
class ShChunk:
    first: int  # first Gaussian
    count: int  # Gaussians in this chunk
    texture: Any  # RGBA32F data image: Gaussian i's coeffs * 3 floats from texel i * sh_texels(coeffs)


def sh_texels(coeffs: int) -> int:
    """Texels a Gaussian's SH coefficients take in an :class:`ShChunk`'s image."""
    return math.ceil(3 * coeffs / 4)


@dataclass
class GpuScene:
    """Gaussians resident on the GPU, plus what the overlays need."""

    count: int  # G
    sh_coeffs: int  # (deg+1)^2 stored per Gaussian
    segments: int  # Gaussians per strand (P - 1); 1 for plain Gaussians
    means: Any  # data image (RGBA32F, texel g): xyz, opacity
    rotations: Any  # data image: wxyz
    scales: Any  # data image: xyz, 0
    sh: list[ShChunk]
    strand_card: Any  # [S] uint
    card_group: Any  # [C] uint
    bounds: tuple[np.ndarray, np.ndarray]  # world-space min and max of the means (for framing)
    points: Any | None = None  # [S * P] vec4 strand points
    strand_group: Any | None = None  # [S] uint
    mesh_pos: Any | None = None  # [C * 2(M+1)] vec4 card strip vertices
    mesh_triangles: Any | None = None  # index buffer of the strips
    card_vertices: int = 0  # 2(M+1)
    n_strands: int = 0
    geometry: CardGeometry | None = None  # an animated scene's geometry decode inputs

    @property
    def sh_degree(self) -> int:
        return int(round(self.sh_coeffs ** 0.5)) - 1

    def release(self) -> None:
        for buf in (self.means, self.rotations, self.scales, self.strand_card, self.card_group,
                    self.points, self.strand_group, self.mesh_pos, self.mesh_triangles):
            if buf is not None:
                buf.release()
        for chunk in self.sh:
            chunk.texture.release()
        self.sh = []
        if self.geometry is not None:
            self.geometry.release()
            self.geometry = None


def block_limit(ctx: Any) -> int:
    """Largest storage block the context allows, in bytes."""
    limit = ctx.info.get("GL_MAX_SHADER_STORAGE_BLOCK_SIZE") or DEFAULT_BLOCK_LIMIT
    return int(min(limit, 1 << 31))


def sh_chunk_bytes(ctx: Any) -> int:
    """Size limit of one SH (and MLP activation) chunk buffer."""
    return block_limit(ctx)


def sh_chunk_gaussians(ctx: Any, coeffs: int) -> int:
    """Most Gaussians one SH chunk's image holds (GL_MAX_TEXTURE_SIZE rows)."""
    return TEXELS_PER_ROW * max_texture_size(ctx) // sh_texels(coeffs)


def _sh_image(ctx: Any, programs: Programs, sh: Any, count: int, coeffs: int) -> Any:
    """The SH chunk buffer ``sh`` (``count`` Gaussians) copied into its image; releases ``sh``."""
    texels = count * sh_texels(coeffs)
    image = data_image(ctx, texels, 4, "f4")
    prog = programs.compute("sh_texture")
    bind(prog, Sh=sh)
    bind_images(prog, u_image=image)
    set_uniforms(prog, u_count=texels, u_floats=3 * coeffs, u_stride=sh_texels(coeffs))
    dispatch(ctx, prog, texels)
    sh.release()
    return image


class SceneTooLargeError(CghError):
    """The asset has more Gaussians than one storage block of this OpenGL can address."""


def check_capacity(ctx: Any, gaussians: int) -> None:
    """Per-Gaussian vec4 buffers must fit one storage block (128 MiB on llvmpipe: 8.4 M Gaussians)."""
    most = block_limit(ctx) // 16
    if gaussians > most:
        raise SceneTooLargeError(
            f"the asset has {gaussians:,} Gaussians; this OpenGL driver addresses at most {most:,} per "
            "storage block (GL_MAX_SHADER_STORAGE_BLOCK_SIZE). Use fewer strands or points per strand.")


def _vec4(a: np.ndarray, w: float = 0.0) -> np.ndarray:
    out = np.full((len(a), 4), w, np.float32)
    out[:, :a.shape[1]] = a
    return out


def _buffer(ctx: Any, data: np.ndarray | None = None, nbytes: int = 0) -> Any:
    """A storage buffer from ``data``, or an uninitialised one of ``nbytes`` (at least 16 bytes)."""
    if data is not None:
        raw = np.ascontiguousarray(data).tobytes()
        return ctx.buffer(raw if raw else bytes(16))
    return ctx.buffer(reserve=max(int(nbytes), 16))


@dataclass
class CardGeometry:
    """What the geometry decode reads, kept on the GPU for an animated scene: per frame only the cards'
    spines and normals are written (:meth:`upload_cards`), then :meth:`decode` rebuilds the card
    strips, strand points and segment frames; the appearance (latents, MLP, SH) is decoded once.

    With ``turn`` (:class:`SegmentTurns`), :meth:`decode` also writes each segment's rotation from rest
    (:func:`cghair_format.animation.shading.segment_rotations`), with which the preprocess turns its SH.
    """

    spine: Any  # [C * (M+1)] vec4
    normal: Any  # [C * (M+1)] vec4
    half_width: Any  # [C * (M+1)] float
    mesh_nrm: Any  # [C * 2(M+1)] vec4
    uvd: Any  # [S * P * 3] float
    opacity: Any  # [G] float
    cards: int  # C
    card_points: int  # M + 1
    thickness: float
    turn: SegmentTurns | None = None

    def upload_cards(self, spine: np.ndarray, normal: np.ndarray) -> None:
        """Write new card spines and normals (``[C, M+1, 3]`` each)."""
        self.spine.write(_vec4(np.asarray(spine, np.float32).reshape(-1, 3), 1.0).tobytes())
        self.normal.write(_vec4(np.asarray(normal, np.float32).reshape(-1, 3)).tobytes())

    def decode(self, ctx: Any, programs: Programs, scene: GpuScene, lod: tuple[Any, tuple] | None = None) -> None:
        """Card strips, then strand points and the Gaussians' means, rotations and scales, into ``scene``:
        every strand's, or with ``lod`` (the priority lists' buffer and a plan's chunks, viewer/lod.py)
        only the strands a splat budget draws."""
        c, m1, turn = self.cards, self.card_points, self.turn
        prog = programs.compute("card_mesh")
        bind(prog, Spine=self.spine, Normal=self.normal, HalfWidth=self.half_width, MeshPos=scene.mesh_pos,
             MeshNrm=self.mesh_nrm)
        if turn is not None:
            bind(prog, RestFrame=turn.rest_frame)
            bind_images(prog, u_card_turns=turn.card_turns)
        set_uniforms(prog, u_count=c * m1, u_points=m1, u_turn=turn is not None)
        dispatch(ctx, prog, c * m1)
        prog = programs.compute("decode_geometry")
        # without lod, LodStrands is bound to any buffer: the shader does not read it
        lists, chunks = lod if lod is not None else (scene.strand_card, ((0, scene.count),))
        bind(prog, MeshPos=scene.mesh_pos, MeshNrm=self.mesh_nrm, StrandCard=scene.strand_card, Uvd=self.uvd,
             Opacity=self.opacity, Points=scene.points, LodStrands=lists)
        bind_images(prog, u_means=scene.means, u_rotations=scene.rotations, u_scales=scene.scales)
        if turn is not None:
            bind_images(prog, u_turns=turn.turns)
            use_textures(prog, u_rest=turn.rest, u_card_turns=turn.card_turns)
        set_uniforms(prog, u_points=scene.segments + 1, u_segments=m1 - 1, u_thickness=self.thickness,
                     u_indexed=lod is not None, u_turn=turn is not None)
        for list_base, count, *_ in chunks:
            set_uniforms(prog, u_count=count, u_list_base=list_base)
            dispatch(ctx, prog, count)

    def release(self) -> None:
        for buf in (self.spine, self.normal, self.half_width, self.mesh_nrm, self.uvd, self.opacity):
            buf.release()
        if self.turn is not None:
            self.turn.release()


@dataclass
class SegmentTurns:
    """What turning an animated scene's SH with its segments takes (issue 34, "Appearance follows"), as
    :func:`cghair_format.animation.shading.segment_rotations` does on the CPU. Fixed at load: the rest
    card frames and each segment's rest direction and spine sample; per frame the geometry decode writes
    the card frames' turns, then each segment's rotation from rest, which the preprocess reads."""

    rest_frame: Any  # [C * (M+1) * 3] vec4: the rest frame's columns t, n, n x t (shading.spine_frames)
    card_turns: Any  # data image, texel c (M+1) + k: F_now F_rest^T as a quaternion (wxyz), written per frame
    rest: Any  # data image, texel g: the segment's rest direction (xyz) and its spine sample k (w)
    turns: Any  # data image, texel g: the segment's rotation from rest (wxyz), written per frame

    @classmethod
    def of(cls, ctx: Any, asset: HairAsset) -> SegmentTurns:
        from cghair_format.animation.shading import segment_directions, segment_samples, spine_frames
        from cghair_format.geometry import strand_points

        cards = asset.cards
        frames = spine_frames(cards).swapaxes(-1, -2).reshape(-1, 3)  # each sample's columns, in order
        directions = segment_directions(strand_points(cards, asset.strand_card, asset.uvd))
        rest = np.concatenate([directions, segment_samples(asset)[..., None]], axis=-1)
        return cls(rest_frame=_buffer(ctx, _vec4(frames)), card_turns=data_image(ctx, frames.shape[0] // 3, 4, "f4"),
                   rest=_image_of(ctx, rest), turns=data_image(ctx, rest.shape[0] * rest.shape[1], 4, "f4"))

    def release(self) -> None:
        for obj in (self.rest_frame, self.card_turns, self.rest, self.turns):
            obj.release()


def _card_geometry(ctx: Any, asset: HairAsset, turn_sh: bool = False) -> CardGeometry:
    cards = asset.cards
    c, m1 = cards.spine.shape[:2]
    # placeholder segments (spec 3) get opacity 0: they are decoded with the others, and never seen
    opacity = (asset.opacity * asset.real_segments()).astype(np.float32).reshape(-1)
    return CardGeometry(
        spine=_buffer(ctx, _vec4(cards.spine.reshape(-1, 3), 1.0)),
        normal=_buffer(ctx, _vec4(cards.normal.reshape(-1, 3))),
        half_width=_buffer(ctx, cards.half_width.astype(np.float32).reshape(-1)),
        mesh_nrm=_buffer(ctx, nbytes=c * 2 * m1 * 16), uvd=_buffer(ctx, asset.uvd.astype(np.float32).reshape(-1)),
        opacity=_buffer(ctx, opacity), cards=c, card_points=m1, thickness=float(asset.thickness),
        turn=SegmentTurns.of(ctx, asset) if turn_sh else None)


def upload_asset(ctx: Any, programs: Programs, asset: HairAsset, animated: bool = False,
                 turn_sh: bool = True) -> GpuScene:
    """Upload an asset's compact data and decode it on the GPU. ``animated`` keeps the geometry
    decode's inputs (:attr:`GpuScene.geometry`) so that its cards can move
    (:meth:`viewer.renderer.Renderer.move_cards`); with ``turn_sh`` (the default) each frame's SH turn
    with their segments (:class:`SegmentTurns`), ``False`` leaves them as at rest (for comparison)."""
    asset.validate()
    cards = asset.cards
    c, m1 = cards.spine.shape[:2]
    s, p = asset.n_strands, asset.points_per_strand
    g = s * (p - 1)  # the shaders index Gaussians s (P-1) + i: a variable-count asset's placeholders too
    check_capacity(ctx, g)
    from cghair_format.geometry import card_mesh

    strand_card = _buffer(ctx, asset.strand_card.astype(np.uint32))
    card_group = _buffer(ctx, cards.group.astype(np.uint32))
    lo = cards.spine.reshape(-1, 3).min(axis=0) - cards.half_width.max()
    hi = cards.spine.reshape(-1, 3).max(axis=0) + cards.half_width.max()
    scene = GpuScene(
        count=g, sh_coeffs=asset.appearance.sh_coeffs, segments=p - 1,
        means=data_image(ctx, g, 4, "f4"), rotations=data_image(ctx, g, 4, "f4"), scales=data_image(ctx, g, 4, "f4"),
        sh=[], strand_card=strand_card, card_group=card_group, bounds=(lo, hi),
        points=_buffer(ctx, nbytes=s * p * 16),
        strand_group=_buffer(ctx, cards.group.astype(np.uint32)[asset.strand_card]),
        mesh_pos=_buffer(ctx, nbytes=c * 2 * m1 * 16),
        mesh_triangles=ctx.buffer(card_mesh(cards).triangles.astype(np.uint32).tobytes()), card_vertices=2 * m1,
        n_strands=s)
    geometry = _card_geometry(ctx, asset, animated and turn_sh)
    geometry.decode(ctx, programs, scene)
    scene.sh = _decode_appearance(ctx, programs, asset, strand_card, card_group)
    if animated:
        scene.geometry = geometry
    else:
        geometry.release()
    return scene


def _pad4(a: np.ndarray) -> np.ndarray:
    """Pad the first axis to a multiple of 4 with zeros."""
    pad = -len(a) % 4
    return np.concatenate([a, np.zeros((pad, *a.shape[1:]), a.dtype)]) if pad else a


def _weights_vec4(weight: np.ndarray) -> np.ndarray:
    """``[out, in]`` weights as the shader's vec4 layout ``[in, ceil(out / 4), 4]``."""
    w = _pad4(weight.astype(np.float32))  # [out4 * 4, in]
    return np.ascontiguousarray(w.T.reshape(w.shape[1], -1, 4))


def _decode_appearance(ctx: Any, programs: Programs, asset: HairAsset, strand_card: Any,
                       card_group: Any) -> list[ShChunk]:
    """Latents and MLP per chunk of strands; each chunk's output is its Gaussians' SH."""
    app = asset.appearance
    s, segs = asset.n_strands, asset.points_per_strand - 1
    widths = [layer.weight.shape[0] for layer in app.mlp]
    out_width = widths[-1]
    widest = max([app.latent_dim, *widths])
    per_chunk = max(1, sh_chunk_bytes(ctx) // (4 * widest))
    per_chunk = min(per_chunk, s, max(1, sh_chunk_gaussians(ctx, app.sh_coeffs) // segs))
    logits = _buffer(ctx, app.logits.astype(np.float32).reshape(-1))
    codebooks = _buffer(ctx, app.codebooks.astype(np.float32).reshape(-1))
    layers = [(_buffer(ctx, _weights_vec4(layer.weight)), _buffer(ctx, _pad4(layer.bias.astype(np.float32))),
               layer.activation == "relu", layer.weight.shape[1], layer.weight.shape[0]) for layer in app.mlp]
    hidden = [_buffer(ctx, nbytes=per_chunk * widest * 4) for _ in range(2)]
    latent_prog = programs.compute("latent")
    layer_prog = programs.compute("mlp_layer")
    chunks = []
    for first in range(0, s, per_chunk):
        n = min(per_chunk, s - first)
        bind(latent_prog, Logits=logits, Codebooks=codebooks, StrandCard=strand_card, CardGroup=card_group,
             Latents=hidden[0])
        set_uniforms(latent_prog, u_first=first, u_count=n, u_k=app.k, u_d=app.latent_dim,
                     u_temperature=float(app.temperature), u_hard=app.weight_mode == "hard")
        dispatch(ctx, latent_prog, n, local_size=LATENT_LOCAL_SIZE)
        src = 0
        out = None
        for i, (w, b, relu, n_in, n_out) in enumerate(layers):
            last = i == len(layers) - 1
            out = _buffer(ctx, nbytes=n * out_width * 4) if last else hidden[1 - src]
            bind(layer_prog, Input=hidden[src], Weight=w, Bias=b, Output=out)
            out4 = -(-n_out // 4)
            count = -(-n // 4) * out4
            set_uniforms(layer_prog, u_strands=n, u_count=count, u_in=n_in, u_out=n_out, u_out4=out4,
                         u_relu=relu)
            dispatch(ctx, layer_prog, count)
            src = 1 - src
        chunks.append(ShChunk(first * segs, n * segs, _sh_image(ctx, programs, out, n * segs, app.sh_coeffs)))
    for buf in (logits, codebooks, *hidden):
        buf.release()
    for w, b, *_ in layers:
        w.release()
        b.release()
    return chunks


def _image_of(ctx: Any, data: np.ndarray) -> Any:
    """A data image holding ``data``'s float32 values, 4 a texel, in order (the tail zero)."""
    flat = np.ascontiguousarray(data, np.float32).reshape(-1)
    image = data_image(ctx, -(-flat.size // 4), 4, "f4")
    texels = np.zeros(image.width * image.height * 4, np.float32)
    texels[:flat.size] = flat
    image.write(texels.tobytes())
    return image


def _read_image(image: Any, count: int) -> np.ndarray:
    """The first ``count`` texels of a data image, ``[count, 4]`` float32."""
    return np.frombuffer(image.read(), np.float32).reshape(-1, 4)[:count]


def upload_gaussians(ctx: Any, gaussians: Gaussians) -> GpuScene:
    """Upload a plain Gaussian set (no strands or cards: overlays and group colours unavailable)."""
    g = gaussians.count
    check_capacity(ctx, g)
    coeffs = gaussians.sh.shape[1]
    per_chunk = max(1, min(sh_chunk_bytes(ctx) // (coeffs * 3 * 4), sh_chunk_gaussians(ctx, coeffs)))
    sh = np.zeros((g, 4 * sh_texels(coeffs)), np.float32)  # each Gaussian on whole texels
    sh[:, :3 * coeffs] = gaussians.sh.reshape(g, -1)
    chunks = [ShChunk(first, len(sh[first:first + per_chunk]), _image_of(ctx, sh[first:first + per_chunk]))
              for first in range(0, g, per_chunk)]
    means = np.concatenate([gaussians.means, gaussians.opacities[:, None]], axis=1).astype(np.float32)
    return GpuScene(
        count=g, sh_coeffs=coeffs, segments=1, means=_image_of(ctx, means),
        rotations=_image_of(ctx, gaussians.rotations.astype(np.float32)),
        scales=_image_of(ctx, _vec4(gaussians.scales.astype(np.float32))), sh=chunks,
        strand_card=_buffer(ctx, np.zeros(max(g, 1), np.uint32)),
        card_group=_buffer(ctx, np.zeros(1, np.uint32)),
        bounds=(gaussians.means.min(axis=0), gaussians.means.max(axis=0)), n_strands=g)


def read_gaussians(scene: GpuScene) -> Gaussians:
    """Read the decoded Gaussians back from the GPU (for tests and exports)."""
    g = scene.count
    means, rotations, scales = (_read_image(image, g) for image in (scene.means, scene.rotations, scene.scales))
    texels = sh_texels(scene.sh_coeffs)
    sh = np.concatenate([_read_image(c.texture, c.count * texels).reshape(c.count, 4 * texels) for c in scene.sh])
    sh = sh[:, :3 * scene.sh_coeffs].reshape(g, -1, 3)
    return Gaussians(means[:, :3].copy(), rotations.copy(), scales[:, :3].copy(), means[:, 3].copy(), sh)


def read_points(scene: GpuScene) -> np.ndarray:
    """Strand points ``[S, P, 3]`` decoded on the GPU."""
    if scene.points is None:
        raise ValueError("this scene was uploaded as plain Gaussians: it has no strand points")
    pts = np.frombuffer(scene.points.read(), np.float32).reshape(-1, 4)[:, :3]
    return pts.reshape(scene.n_strands, scene.segments + 1, 3).copy()
