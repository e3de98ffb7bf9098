"""A coverage-guided fuzz target (atheris, libFuzzer) for the .cgh reader.

The seeds are small valid files of every profile, with optional chunks and an unknown one, re-packed with
every chunk stored raw (codec 0), so that libFuzzer's byte mutations land in the payloads themselves; each
input is re-sealed (every chunk's and the header's CRC recomputed) before it is decoded, so that mutations
get past the checksums into the decoders (tests/format/test_hostile.py and the byte-flip sweeps cover the
checksums). An input fails when decoding, or decoding to Gaussians, raises anything but a
CghFormatError with a byte offset (a warning, turned into an error, included: validating untrusted
values must not warn), returns non-finite Gaussians, runs over 1 s (``-timeout=1``) or
takes 256 MB above the resident memory before it (the peak, ``VmHWM``, reset for each input).

    PYTHONPATH=. python tests/fuzz/fuzz_decode.py [CORPUS_DIR] -max_total_time=600   # make fuzz
"""

from __future__ import annotations

import inspect
import resource
import struct
import sys
import tempfile
import warnings
import zlib
from pathlib import Path

import atheris
import numpy as np

import cghair_format as cgh
from cghair_format import container
from cghair_format.codec import KNOWN_CHUNKS
from cghair_format.limits import ReadLimits

# tighter than the defaults, so that a valid but large decode cannot pass for a leak
LIMITS = ReadLimits(max_gaussians=1 << 16, max_decoded_bytes=64 << 20)
PEAK_MB = 256
# Left uninstrumented: atheris's comparison hook keeps the numpy arrays these modules compare (their rANS
# table checks), 230 KB a decode with rans.py instrumented, 6.6 KB with residual_coder.py; the others take
# under 1.2 KB together (measured over 200 decodes of a small compact file)
UNINSTRUMENTED = ("cghair_format.rans", "cghair_format.residual_coder")


def instrument() -> int:
    """Instrument, in place, every function and method of the loaded cghair_format modules for coverage
    (``atheris.instrument_imports`` would also instrument the modules it imports, and leaks as above)."""
    count = 0
    for name, module in sorted(sys.modules.items()):
        if not name.startswith("cghair_format") or name in UNINSTRUMENTED or module is None:
            continue
        for obj in list(vars(module).values()):
            funcs = [obj] if inspect.isfunction(obj) else \
                [v for v in vars(obj).values() if inspect.isfunction(v)] if inspect.isclass(obj) else []
            for fn in funcs:
                if fn.__module__ == name:
                    fn.__code__ = atheris.instrument_func(fn).__code__
                    count += 1
    return count


def seeds() -> list[bytes]:
    """Small valid files, every chunk raw: compact, high (hard weights), lossless, one with every
    optional chunk and an unknown one, and one of strands of their own point counts (PCNT)."""
    from cghair_format.examples import example_asset, with_point_counts

    plain = example_asset(11, strands=24, points=12, cards=4, segments=5)
    full = example_asset(5, strands=16, points=9, cards=3, segments=4)
    full.strand_ids = np.arange(16, dtype=np.uint32) * 3
    full.root_uv = np.linspace(0, 1, 32, dtype=np.float32).reshape(16, 2)
    full.source_color = np.full((16, 9, 3), 0.5, np.float32)
    full.metadata = {"source": "fuzz seed"}
    out = []
    for asset, profile in ((plain, "compact"), (plain, "high"), (plain, "lossless"), (full, "compact"),
                           (with_point_counts(plain, seed=1), "compact")):
        data = cgh.encode(asset, profile)[0]
        _, infos, payloads = container.unpack(data, set(KNOWN_CHUNKS))
        chunks = [container.Stored(container.Chunk(i.type, payloads[i.type], i.required), container.CODEC_RAW,
                                   payloads[i.type]) for i in infos]
        if profile == "compact" and asset is full:
            blob = bytes(range(64))
            chunks.append(container.Stored(container.Chunk("XTRA", blob, False), container.CODEC_RAW, blob))
        out.append(container.assemble(chunks))
    return out


def reseal(data: bytes) -> bytes:
    """``data`` with every CRC that can be located recomputed (chunks within the file, then the header)."""
    head, entry = container.HEADER, container.ENTRY
    if len(data) < head.size:
        return data
    out = bytearray(data)
    count = min(struct.unpack_from("<I", out, 24)[0], container.MAX_CHUNKS)
    table_end = head.size + entry.size * count
    if table_end > len(out):
        return data
    for i in range(count):
        pos = head.size + entry.size * i
        offset, stored = struct.unpack_from("<QQ", out, pos + 8)
        if offset + stored <= len(out):
            struct.pack_into("<I", out, pos + 32, zlib.crc32(out[offset:offset + stored]) & 0xFFFFFFFF)
    crc = zlib.crc32(bytes(out[:head.size - 4]) + bytes(out[head.size:table_end])) & 0xFFFFFFFF
    struct.pack_into("<I", out, head.size - 4, crc)
    return bytes(out)


def _rss_mb(field: str) -> float:
    with open("/proc/self/status") as f:
        return next(int(line.split()[1]) for line in f if line.startswith(field)) / 1024


def test_one_input(data: bytes) -> None:
    with open("/proc/self/clear_refs", "w") as f:
        f.write("5")  # reset the peak (VmHWM) to the present resident memory
    before = _rss_mb("VmRSS:")
    try:
        asset, gaussians = cgh.read_with_gaussians(reseal(data), LIMITS)
    except cgh.CghFormatError as exc:
        if exc.offset is None:
            raise AssertionError(f"a refusal names no byte offset: {exc}") from exc
        return
    finally:
        peak = _rss_mb("VmHWM:") - before
        if peak > PEAK_MB:
            raise AssertionError(f"decoding took {peak:.0f} MB above the resident memory before it")
    for name in ("means", "rotations", "scales", "opacities", "sh"):
        if not np.isfinite(getattr(gaussians, name)).all():
            raise AssertionError(f"a decoded file gives non-finite Gaussian {name}")
    asset.validate()


def main(argv: list[str]) -> None:
    args = [a for a in argv[1:] if a.startswith("-")]
    dirs = [a for a in argv[1:] if not a.startswith("-")]
    if not dirs:
        dirs = [tempfile.mkdtemp(prefix="cgh_fuzz_")]
    corpus = Path(dirs[0])
    if not any(corpus.iterdir()):
        for i, seed in enumerate(seeds()):
            (corpus / f"seed{i}.cgh").write_bytes(seed)
    if not any(a.startswith("-rss_limit_mb") for a in args):  # a guard for the process; inputs: test_one_input
        # libFuzzer compares the limit with getrusage's peak, which Linux carries over an exec from the
        # parent (a large pytest process): start from that peak, not from this process's own memory
        start = max(_rss_mb("VmRSS:"), resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024)
        args.append(f"-rss_limit_mb={int(start) + 4 * PEAK_MB}")
    if not any(a.startswith("-timeout") for a in args):
        args.append("-timeout=1")
    instrument()
    warnings.simplefilter("error")
    atheris.Setup([argv[0], *args, *dirs], test_one_input)
    atheris.Fuzz()


if __name__ == "__main__":
    main(sys.argv)
