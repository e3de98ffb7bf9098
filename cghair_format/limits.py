"""What a reader accepts before it allocates (spec 1.4): the caller's limits, and the chunk sizes that META's
counts imply.

Every size the decoder will allocate follows from META's counts, which are parsed (META is at most 1 MiB)
before any other chunk is decompressed. Two checks then run on the chunk table alone:

- the decoded arrays (the asset, and the Gaussians where they are wanted) and the decompressed chunks must fit
  :class:`ReadLimits`, so that a small file cannot ask for gigabytes (a zstd chunk of zeros expands 32,000
  times);
- each chunk's ``raw_size`` must hold at least one byte per value META says it stores, so that counts
  inconsistent with the payloads are refused before anything is sized by them.
"""

from __future__ import annotations

from dataclasses import dataclass

from .errors import LimitError

FLOAT = 4
GAUSSIAN_FLOATS = 3 + 4 + 3 + 1  # mean, rotation, scale, opacity; plus 3 per SH coefficient


@dataclass(frozen=True)
class ReadLimits:
    """The largest file a reader decodes without being asked to (``cgh --max-gaussians N
    --max-decoded-mb M VERB ...``, or ``read(path, limits=ReadLimits(...))``). The defaults leave room
    for several times the paper's largest asset (docs/format.md, "Profiles and storage")."""

    max_gaussians: int = 1 << 24
    max_decoded_bytes: int = 1 << 31
    max_frames: int = 1 << 17  # an animation's (spec 4.6): over an hour at 30 fps

    def __post_init__(self) -> None:
        if self.max_gaussians < 1 or self.max_decoded_bytes < 1 or self.max_frames < 1:
            raise ValueError(f"read limits must be positive, got {self}")


_default = ReadLimits()


def default_limits() -> ReadLimits:
    return _default


def set_default_limits(limits: ReadLimits) -> None:
    """The limits of every later read that names none (the CLI's ``--max-gaussians``)."""
    global _default
    _default = limits


def decoded_bytes(meta: dict, gaussians: bool) -> int:
    """The bytes of the arrays a decoder returns for this META: the asset's, and with ``gaussians`` the
    Gaussians' (:func:`.gaussians.decode_gaussians`) too."""
    s, p, c, m, nt, k, d = (meta[key] for key in ("strands", "points", "cards", "segments", "groups", "k",
                                                  "latent_dim"))
    widths = [d] + [layer["out"] for layer in meta["mlp"]]
    weights = sum(i * o + o for i, o in zip(widths[:-1], widths[1:], strict=True))
    total = FLOAT * (c * (m + 1) * 7 + c + s * (1 + p * 3 + (p - 1) + k) + nt * k * d + weights)
    if gaussians:
        total += FLOAT * s * (p - 1) * (GAUSSIAN_FLOATS + 3 * (meta["sh_degree"] + 1) ** 2)
    return total


def min_payloads(meta: dict) -> dict[str, int]:
    """Per chunk, the fewest decompressed bytes that can hold the values META declares: one byte per
    integer (the narrowest array type) and four per float32 (spec 2, 4)."""
    s, p, c, m, nt, k, d = (meta[key] for key in ("strands", "points", "cards", "segments", "groups", "k",
                                                  "latent_dim"))
    widths = [d] + [layer["out"] for layer in meta["mlp"]]
    weights = sum(i * o + o for i, o in zip(widths[:-1], widths[1:], strict=True))
    optional = {"SIDS": s, "ROOT": FLOAT * 2 * s, "SCOL": 3 * s * p, "PCNT": s}
    if meta["quant"]["lossless"]:
        return optional | {"CARD": FLOAT * c * (m + 1) * 7 + 2 * c, "STRD": s + FLOAT * s * p * 3,
                           "OPAC": FLOAT * s * (p - 1), "LOGT": FLOAT * s * k, "CBKS": FLOAT * nt * k * d,
                           "MLPW": FLOAT * weights}
    logits = s if meta["weight_mode"] == "hard" else s * k
    return optional | {"CARD": c * (m + 1) * 5 + 2 * c, "STRD": s, "OPAC": s * (p - 1), "LOGT": logits,
                       "CBKS": nt * k * d, "MLPW": weights, "CHLD": 6 * meta["quant"].get("children", 0)}


def animation_bytes(frames: int, cards: int, segments: int) -> int:
    """The bytes of ``frames`` decoded animation frames (spec 4.6): float32 spines and normals, and the
    int64 integers a quantized block decodes through."""
    return frames * cards * (segments + 1) * (6 * FLOAT + 4 * 8)


# bytes of the arrays decoded from each optional chunk present, per strand (SCOL: per point)
OPTIONAL_DECODED = {"SIDS": 4, "ROOT": 2 * FLOAT, "SCOL": 3 * FLOAT}


def check(meta: dict, chunks: list, limits: ReadLimits, gaussians: bool) -> None:
    """Refuse, before decompressing anything but META, a file beyond ``limits`` or whose chunks (their
    ``type``, ``offset``, ``raw``) are too small for META's counts. The Gaussians counted are ``S (P-1)``,
    the decoder's arrays with a variable-count file's placeholders (spec 1.4)."""
    count = meta["strands"] * (meta["points"] - 1)
    if count > limits.max_gaussians:
        raise LimitError(f"the file holds {count:,} Gaussians, more than this reader's limit of "
                         f"{limits.max_gaussians:,} (raise it with cgh --max-gaussians N, or "
                         "read(..., limits=ReadLimits(max_gaussians=N)))", chunk="META")
    per_point = {"SCOL": meta["points"]}
    need = decoded_bytes(meta, gaussians) + sum(info.raw for info in chunks) + sum(
        meta["strands"] * per_point.get(info.type, 1) * OPTIONAL_DECODED.get(info.type, 0) for info in chunks)
    if need > limits.max_decoded_bytes:
        raise LimitError(f"decoding the file takes {need:,} bytes, more than this reader's limit of "
                         f"{limits.max_decoded_bytes:,} (raise it with cgh --max-decoded-mb M, or "
                         "read(..., limits=ReadLimits(max_decoded_bytes=N)))", chunk="META")
    least = min_payloads(meta)
    for info in chunks:
        if info.raw < least.get(info.type, 0):
            raise LimitError(f"the chunk's {info.raw:,} bytes cannot hold the {least[info.type]:,} bytes of values "
                             "META's counts declare", chunk=info.type, offset=info.offset)
