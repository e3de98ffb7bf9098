""".cgh files crafted to break a reader (issue 21), and a runner that measures what refusing each costs.

Each case is a small valid file with one thing changed and its checksums re-sealed, so that the change
reaches the part of the reader it aims at. ``python tests/hostile.py`` decodes every case in this
process, with every warning turned into an error (validating untrusted values must not warn), and
prints one line per case: the error, the seconds, and the peak resident memory above what the process
held before (Linux ``VmHWM``, reset per case through ``/proc/self/clear_refs``), which counts zstd's
and numpy's C allocations that tracemalloc misses.
"""

from __future__ import annotations

import json
import struct
import sys
import time
import warnings
from collections.abc import Callable

import numpy as np
import zstandard

import cghair_format as cgh
from cghair_format import codec, container
from cghair_format.examples import example_animation, example_asset
from cghair_format.limits import ReadLimits
from cghair_format.streams import StreamReader, StreamWriter


def small_file(profile: str = "compact", frames: int = 0) -> bytes:
    """A small asset's file; with ``frames``, animated (spec 4.6)."""
    asset = example_asset(11, strands=24, points=12, cards=4, segments=5)
    return cgh.encode(asset, profile, animation=example_animation(asset.cards, frames) if frames else None)[0]


ANIM_CASE = "ANIM "  # cases so named are read as an animation (read_animation), the others as an asset


def with_anim(data: bytes, payload: bytes) -> bytes:
    """``data`` with ANIM's payload replaced (stored raw, as spec 4.6 has it)."""
    return reseal(data, bodies={"ANIM": (container.CODEC_RAW, payload, len(payload))})


def anim_block_bomb() -> bytes:
    """A block whose table says 2^31 - 1 raw bytes, its body a zstd frame of zeros declaring no size."""
    data = small_file(frames=40)
    bomb = zstd_frame(None, 64)
    return with_anim(data, struct.pack("<IIIB3xIIB3x", 2, len(bomb), (1 << 31) - 1, 1, 1, 1, 0) + bomb + b"\0")


def anim_table(edit: Callable[[bytes], bytes], frames: int = 40, profile: str = "compact") -> bytes:
    data = small_file(profile, frames)
    return with_anim(data, edit(container.unpack(data, set(codec.KNOWN_CHUNKS))[2]["ANIM"]))


def reseal(data: bytes, payloads: dict[str, bytes] | None = None,
           bodies: dict[str, tuple[int, bytes, int]] | None = None, extra: list[container.Chunk] = ()) -> bytes:
    """``data`` with some chunks' payloads replaced (``payloads``), or their stored bytes (``bodies``:
    ``type -> (codec, stored bytes, raw size)``), ``extra`` chunks appended, every checksum recomputed."""
    _, infos, old = container.unpack(data, set(codec.KNOWN_CHUNKS))
    stored = []
    for info in infos:
        chunk = container.Chunk(info.type, (payloads or {}).get(info.type, old[info.type]), info.required)
        if bodies and info.type in bodies:
            kind, body, raw = bodies[info.type]
            chunk.payload = bytes(raw)  # only its length goes into the table
            stored.append(container.Stored(chunk, kind, body))
        else:
            stored.append(container.compress(chunk, 3))
    stored += [container.compress(c, 3) for c in extra]
    return container.assemble(stored)


def with_meta(data: bytes, edit: Callable[[str], str]) -> bytes:
    """``data`` with META's JSON text edited by ``edit``."""
    meta = container.unpack(data, set(codec.KNOWN_CHUNKS), {"META"})[2]["META"].decode()
    return reseal(data, {"META": edit(meta).encode()})


def set_field(data: bytes, path: tuple[str, ...], text: str) -> bytes:
    """META field ``path`` set to the raw JSON ``text`` (which may be beyond what json.dumps writes)."""
    def edit(meta: str) -> str:
        obj = json.loads(meta)
        node = obj
        for key in path[:-1]:
            node = node[key]
        node[path[-1]] = "@@"
        return json.dumps(obj).replace('"@@"', text)
    return with_meta(data, edit)


def zstd_frame(declared: int | None, blocks: int, block: int = 1 << 17) -> bytes:
    """A zstd frame of ``blocks`` RLE blocks of ``block`` zero bytes whose header declares ``declared``
    bytes (None: no size), written by hand as no compressor declares a size it does not write."""
    if declared is None:
        head = bytes([0x00, 0x58])  # no content size, not single-segment; window 2^(10 + 11) ...
    else:
        head = bytes([0xC0, 0x58]) + struct.pack("<Q", declared)  # ... 8-byte content size
    body = b""
    for i in range(blocks):
        last = 1 if i == blocks - 1 else 0
        body += ((block << 3) | (1 << 1) | last).to_bytes(3, "little") + b"\0"  # RLE block of zeros
    return b"\x28\xb5\x2f\xfd" + head + body


def lossless_card(field: int, value: float) -> bytes:
    """A lossless file whose CARD array ``field`` (0: spine, 1: normal) has ``value`` at its first entry."""
    data = small_file("lossless")
    payload = container.unpack(data, set(codec.KNOWN_CHUNKS))[2]["CARD"]
    r = StreamReader(payload, "CARD")
    arrays = [r.array((None, None, 3), "spine"), r.array((None, None, 3), "normal"), r.array((None, None), "hw"),
              r.array((None,), "group")]
    arrays[field] = arrays[field].copy()
    arrays[field][0, 0, 0] = value
    w = StreamWriter()
    for a in arrays:
        w.array(a, shuffle=True)
    return reseal(data, {"CARD": w.getvalue()})


def meta_bomb(raw: int) -> bytes:
    """META stored as a zstd stream of ``raw`` zero bytes (64 KB of it make 2 GB)."""
    z = zstandard.ZstdCompressor(level=1).compressobj()
    body = b"".join(z.compress(bytes(1 << 20)) for _ in range(raw >> 20)) + z.flush()
    return reseal(small_file(), bodies={"META": (container.CODEC_ZSTD, body, raw)})


def flipped_unknown_chunk() -> bytes:
    data = bytearray(reseal(small_file(), extra=[container.Chunk("XTRA", bytes(range(256)) * 4, required=False)]))
    _, infos = container.read_table(bytes(data))
    xtra = next(i for i in infos if i.type == "XTRA")
    data[xtra.offset + 10] ^= 0x01
    return bytes(data)


def cases() -> dict[str, tuple[Callable[[], bytes], ReadLimits | None]]:
    """Name -> (the file's builder, the limits to read it with; None: the defaults)."""
    huge = "1" + "0" * 400
    out = {
        "zstd frame declaring 2^40 bytes": (lambda: _frame_in_card(1 << 40), None),
        "zstd frame of unknown size beyond raw_size": (lambda: _frame_in_card(None), None),
        "META zstd bomb (2047 MiB in 64 KB)": (lambda: meta_bomb(2047 << 20), None),
        "META strands 2^24 - 1": (lambda: set_field(small_file(), ("strands",), str((1 << 24) - 1)), None),
        "META strands 2^20 (payloads too small)": (lambda: set_field(small_file(), ("strands",), str(1 << 20)), None),
        "META points 4096, strands 2^20": (
            lambda: set_field(set_field(small_file(), ("points",), "4096"), ("strands",), str(1 << 20)), None),
        "more Gaussians than the limit": (small_file, ReadLimits(max_gaussians=100)),
        "more decoded bytes than the limit": (small_file, ReadLimits(max_decoded_bytes=10_000)),
        "base_stride 3": (lambda: set_field(small_file(), ("quant", "base_stride"), "3"), None),
        "thickness 1e308": (lambda: set_field(small_file(), ("thickness",), "1e308"), None),
        "thickness 1e400": (lambda: set_field(small_file(), ("thickness",), "1e400"), None),
        "lossless spine at 3e38": (lambda: lossless_card(0, 3e38), None),
        "lossless spine at inf": (lambda: lossless_card(0, np.inf), None),
        "lossless card normal at 3e38": (lambda: lossless_card(1, 3e38), None),
        "XMET with NaN": (lambda: reseal(small_file(), extra=[container.Chunk("XMET", b'{"a": NaN}', False)]),
                          None),
        "flipped byte in an unknown optional chunk": (flipped_unknown_chunk, None),
        "ANIM block zstd bomb (2 GiB declared)": (anim_block_bomb, None),
        "ANIM block count 2^32 - 1": (lambda: anim_table(lambda a: struct.pack("<I", (1 << 32) - 1) + a[4:]), None),
        "ANIM block pointing outside": (lambda: anim_table(lambda a: a[:4] + struct.pack("<I", 1 << 31) + a[8:]),
                                        None),
        "ANIM table cut short": (lambda: anim_table(lambda a: a[:10]), None),
        "ANIM frames over the limit": (lambda: small_file(frames=40), ReadLimits(max_frames=39)),
        "ANIM frames' bytes over the limit": (lambda: small_file(frames=40), ReadLimits(max_decoded_bytes=50_000)),
        "ANIM frame count 2^20": (lambda: set_field(small_file(frames=40), ("animation", "frames"), str(1 << 20)),
                                  None),
    }
    for path in (("thickness",), ("temperature",), ("quant", "step"), ("quant", "card_step"),
                 ("quant", "opacity_scale"), ("quant", "weight_steps")):
        text = f"[{huge}, 1, 1, 1]" if path[-1] == "weight_steps" else huge
        out[f"{'.'.join(path)} = 10^400"] = (lambda p=path, t=text: set_field(small_file(), p, t), None)
    return out


def _frame_in_card(declared: int | None) -> bytes:
    data = small_file()
    raw = next(i.raw for i in container.read_table(data)[1] if i.type == "CARD")
    return reseal(data, bodies={"CARD": (container.CODEC_ZSTD, zstd_frame(declared, 64), raw)})


def _rss(field: str) -> int:
    with open("/proc/self/status") as f:
        return next(int(line.split()[1]) * 1024 for line in f if line.startswith(field))


def measure(name: str, data: bytes, limits: ReadLimits | None) -> tuple[str, float, int]:
    """Decode ``data`` (to Gaussians, as a viewer does; a case named ``ANIM ...``: its animation): the
    outcome, seconds, and peak RSS bytes above the RSS before."""
    with open("/proc/self/clear_refs", "w") as f:
        f.write("5")  # reset VmHWM to the current RSS
    before = _rss("VmRSS:")
    start = time.perf_counter()
    try:
        if name.startswith(ANIM_CASE):
            cgh.read_animation(data, limits)
        else:
            cgh.read_with_gaussians(data, limits)
        outcome = "decoded"
    except cgh.CghFormatError as exc:
        outcome = f"{type(exc).__name__}|{exc.chunk}|{exc.offset}|{exc}"
    except Exception as exc:  # noqa: BLE001 - what the test reports as an escape
        outcome = f"ESCAPE {type(exc).__name__}: {exc}"
    seconds = time.perf_counter() - start
    return outcome, seconds, _rss("VmHWM:") - before


def main() -> None:
    warnings.simplefilter("error")  # a warning on untrusted values is a defect: it reports as an ESCAPE
    built = {name: (build(), limits) for name, (build, limits) in cases().items()}
    for name, (data, limits) in built.items():
        outcome, seconds, peak = measure(name, data, limits)
        print(json.dumps({"case": name, "bytes": len(data), "outcome": outcome, "seconds": seconds, "peak": peak}),
              flush=True)


if __name__ == "__main__":
    sys.exit(main())
