"""AMD TressFX ``.tfx``: the binary format of TressFX 3 and 4, and the TressFX 2.0 ASCII format.

Binary, TressFX 4 (version 4.x): a 160-byte header (f32 version, u32 strand count, u32 points per
strand, u32 byte offsets of the vertex positions, strand UVs, vertex UVs, strand thickness and vertex
colours, 32 reserved u32), then ``float4`` positions (xyz and inverse mass) at their offset.
TressFX 3 (version 3.x; AMD's ``TressFXFileObject`` in TressFX 3.0's ``TressFXFileFormat.h``): a
296-byte header (f32 version, u32 strand count, u32 points per strand, u32 follow hairs per guide, a
4-byte bool, 31 reserved u32, then at byte 144 the u32 offset of the vertex positions, five more
offsets and 32 reserved u32), then ``float3`` positions. Every strand has the same point count.
ASCII 2.0: ``key value`` header lines, then per strand a line ``strand i numVerts n texcoord u v``
followed by ``n`` lines of ``x y z``.
TressFX assets are y-up (game-engine convention); the format names no units.
"""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np

from ..atomic import atomic_open
from ..strands import Strands
from ._common import StrandFileError, finish, float32, need, offsets_from_counts, positive, read_bytes, warn

HEADER = struct.Struct("<fIIIIIII32I")  # 160 bytes (TressFX 4)
V3_HEADER_SIZE = 296
V3_POSITIONS_OFFSET = 144  # where TressFX 3 stores the byte offset of its float3 positions
SUPPORTED_MAJOR = (3, 4)
MAX_POINTS = 1 << 16


def load(path: str | Path) -> Strands:
    data = read_bytes(path)
    if data[:7] == b"version" or data.lstrip()[:7] == b"version":
        return _load_ascii(path, data)
    return _load_binary(path, data)


def _load_binary(path: str | Path, data: bytes) -> Strands:
    need(path, data, HEADER.size, "the 160-byte TressFX header")
    version, n_strands, n_per, off_pos, off_uv, *_ = HEADER.unpack_from(data)
    if not np.isfinite(version) or int(version) not in SUPPORTED_MAJOR:
        raise StrandFileError(path, f"not a TressFX 3/4 binary file: version field reads {version!r} "
                                    "(TressFX 2 files are ASCII and start with 'version')")
    header, floats = (HEADER.size, 4) if int(version) == 4 else (V3_HEADER_SIZE, 3)
    if header == V3_HEADER_SIZE:
        need(path, data, V3_HEADER_SIZE, "the 296-byte TressFX 3 header")
        off_pos = struct.unpack_from("<I", data, V3_POSITIONS_OFFSET)[0]
    if n_strands == 0 or not 2 <= n_per <= MAX_POINTS:
        raise StrandFileError(path, f"implausible header: {n_strands} strands of {n_per} points")
    if off_pos < header:
        raise StrandFileError(path, f"vertex positions offset {off_pos} points inside the {header}-byte header")
    n = n_strands * n_per
    need(path, data, off_pos + 4 * floats * n, f"the positions of {n_strands} strands x {n_per} points")
    xyz = np.frombuffer(data, "<f4", floats * n, off_pos).reshape(-1, floats)
    points = np.ascontiguousarray(xyz[:, :3], np.float32)
    root_uv = None
    if floats == 4 and off_uv >= HEADER.size and off_uv + 8 * n_strands <= len(data):  # TressFX 4's strand UVs
        root_uv = np.frombuffer(data, "<f4", 2 * n_strands, off_uv).reshape(-1, 2).astype(np.float32)
        if not root_uv.any():  # writers that have no UVs fill zeros
            root_uv = None
    return finish(path, Strands(points, np.arange(n_strands + 1, dtype=np.int64) * n_per, up_axis="Y",
                                root_uv=root_uv), {"root_uv": "strand UVs"})


def _load_ascii(path: str | Path, data: bytes) -> Strands:
    try:
        lines = data.decode("ascii").splitlines()
    except UnicodeDecodeError as exc:
        raise StrandFileError(path, f"TressFX ASCII file has a non-ASCII byte at offset {exc.start}") from exc
    header: dict[str, list[str]] = {}
    i = 0
    while i < len(lines) and not lines[i].startswith("strand "):
        parts = lines[i].split()
        if parts:
            header[parts[0]] = parts[1:]
        i += 1
    try:
        declared = int(header["numStrands"][0])
        scale = positive(path, "header 'scale'", header.get("scale", ["1"])[0])
        translation = np.array([float(v) for v in header.get("translation", ["0", "0", "0"])[:3]])
        rotation = [float(v) for v in header.get("rotation", ["0", "0", "0"])[:3]]
    except (KeyError, IndexError, ValueError) as exc:
        raise StrandFileError(path, f"TressFX ASCII header is missing or garbles {exc}") from exc
    if not np.isfinite(translation).all() or not np.isfinite(rotation).all():
        raise StrandFileError(path, f"header 'translation' {translation.tolist()} or 'rotation' {rotation} is "
                                    "NaN or infinite")
    if any(rotation):
        warn(f"{path}: TressFX header rotation {rotation} is ignored")
    counts, blocks, uvs = [], [], []
    while i < len(lines):
        parts = lines[i].split()
        if not parts:
            i += 1
            continue
        try:
            if parts[0] != "strand" or parts[2] != "numVerts":
                raise ValueError
            c = int(parts[3])
        except (IndexError, ValueError):
            raise StrandFileError(path, f"line {i + 1}: expected 'strand i numVerts n ...', "
                                        f"got {lines[i][:60]!r}") from None
        if not 0 <= c <= MAX_POINTS or i + 1 + c > len(lines):
            raise StrandFileError(path, f"line {i + 1}: strand {parts[1]} declares {c} points, "
                                        f"the file has {len(lines) - i - 1} lines left (truncated?)")
        try:
            block = np.array([ln.split() for ln in lines[i + 1:i + 1 + c]], dtype=np.float64)
        except ValueError:
            raise StrandFileError(path, f"lines {i + 2}..{i + 1 + c}: point lines must hold 3 numbers "
                                        f"(strand {parts[1]})") from None
        if c and block.shape != (c, 3):
            raise StrandFileError(path, f"lines {i + 2}..{i + 1 + c}: point lines must hold 3 numbers")
        counts.append(c)
        blocks.append(block.reshape(-1, 3))
        try:
            uvs.append((float(parts[5]), float(parts[6])) if parts[4:5] == ["texcoord"] else (0.0, 0.0))
        except (IndexError, ValueError):
            raise StrandFileError(path, f"line {i + 1}: 'texcoord' needs two numbers, got {lines[i][:60]!r}") from None
        i += 1 + c
    if len(counts) != declared:
        raise StrandFileError(path, f"header declares {declared} strands, the file holds {len(counts)} "
                                    "(truncated?)")
    points = float32(path, "points (after the header's scale and translation)",
                     np.concatenate(blocks) * scale + translation)
    offsets = offsets_from_counts(np.array(counts))
    root_uv = float32(path, "texcoord", np.array(uvs, np.float64).reshape(-1, 2))
    return finish(path, Strands(points, offsets, up_axis="Y", root_uv=root_uv if root_uv.any() else None),
                  {"root_uv": "texcoord"})


def save(strands: Strands, path: str | Path) -> None:
    """Write a TressFX 4 binary file; every strand must have the same point count. The strand UVs
    are the strands' root UVs where they have them, else zeros."""
    counts = strands.point_counts
    if strands.count == 0 or (counts != counts[0]).any():
        raise StrandFileError(path, "TressFX needs the same point count in every strand: resample first "
                                    "(cgh convert --points N, or cghair_format.strands.resample)")
    n_per = int(counts[0])
    if not 2 <= n_per <= MAX_POINTS:
        raise StrandFileError(path, f"TressFX strands need 2..{MAX_POINTS} points, got {n_per}")
    if n_per < 4 or n_per > 64 or n_per & (n_per - 1):
        warn(f"{path}: TressFX runtimes expect 4, 8, 16, 32 or 64 points per strand, writing {n_per}; "
             "resample with cgh convert --points")
    xyzw = np.ones((len(strands.points), 4), "<f4")
    xyzw[:, :3] = strands.points
    xyzw.reshape(strands.count, n_per, 4)[:, :2, 3] = 0.0  # roots are immovable (zero inverse mass)
    off_pos = HEADER.size
    off_uv = off_pos + xyzw.nbytes
    header = HEADER.pack(4.0, strands.count, n_per, off_pos, off_uv, 0, 0, 0, *([0] * 32))
    with atomic_open(path) as f:
        f.write(header)
        f.write(xyzw.tobytes())
        uv = np.zeros((strands.count, 2), "<f4") if strands.root_uv is None else strands.root_uv.astype("<f4")
        f.write(uv.tobytes())
