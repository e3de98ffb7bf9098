"""A small Alembic (Ogawa) reader for tests: an independent reading of the layout that
``cghair_format.exchange._ogawa`` writes (AbcCoreOgawa's, as its reader parses it), to check a
file's structure. Numeric properties only, every stored sample, each frame's sample found as
Alembic's reader finds it (constant, first and last changed sample); not part of the package."""

from __future__ import annotations

import struct
from dataclasses import dataclass, field

import numpy as np

DATA_BIT = 1 << 63
DTYPES = {0: np.bool_, 1: np.uint8, 2: np.int8, 3: np.uint16, 4: np.int16, 5: np.uint32, 6: np.int32,
          7: np.uint64, 8: np.int64, 9: np.float16, 10: np.float32, 11: np.float64}


@dataclass
class Prop:
    kind: str  # "compound", "scalar" or "array"
    metadata: dict
    values: np.ndarray | None = None  # sample 0, [n, extent] (scalar: [1, extent])
    props: dict = field(default_factory=dict)
    samples: int = 0  # the header's sample count
    stored: list = field(default_factory=list)  # the stored samples, [n, extent] each
    time_sampling: int = 0
    changed: tuple = (0, 0)  # first and last changed sample (0, 0: constant)

    def sample(self, i: int) -> np.ndarray:
        """Sample ``i`` (0 <= i < samples), mapped onto the stored ones as AbcCoreOgawa's reader does."""
        assert 0 <= i < self.samples
        first, last = self.changed
        if (first, last) == (0, 0) or i < first:
            return self.stored[0]
        return self.stored[min(i, last) - first + 1]


@dataclass
class TimeSampling:
    max_samples: int
    time_per_cycle: float
    times: tuple  # the stored times (one: uniform)


@dataclass
class Obj:
    metadata: dict
    props: dict
    children: dict
    hashes: bytes


def parse_md(text: bytes) -> dict:
    return dict(kv.split("=", 1) for kv in text.decode().split(";")) if text else {}


class Archive:
    def __init__(self, path):
        self.buf = open(path, "rb").read()
        assert self.buf[:5] == b"Ogawa", "not an Ogawa file"
        self.frozen = self.buf[5] == 0xFF
        self.version = struct.unpack(">H", self.buf[6:8])[0]
        root = self.group(struct.unpack_from("<Q", self.buf, 8)[0])
        assert len(root) >= 6 and all(root[i] & DATA_BIT for i in (0, 1, 3, 4, 5)) and not root[2] & DATA_BIT
        self.abc_version = struct.unpack("<i", self.data(root[0]))[0]
        self.library_version = struct.unpack("<i", self.data(root[1]))[0]
        self.metadata = parse_md(self.data(root[3]))
        self.time_samplings_raw = self.data(root[4])
        self.time_samplings, pos, raw = [], 0, self.time_samplings_raw
        while pos < len(raw):
            most, tpc, n = struct.unpack_from("<IdI", raw, pos)
            self.time_samplings.append(TimeSampling(most, tpc, struct.unpack_from(f"<{n}d", raw, pos + 16)))
            pos += 16 + 8 * n
        assert pos == len(raw)
        table, self.md_table, pos = self.data(root[5]), [], 0
        while pos < len(table):
            n = table[pos]
            self.md_table.append(parse_md(table[pos + 1:pos + 1 + n]))
            pos += 1 + n
        self.top = self.object(root[2])

    def group(self, pos: int) -> list[int]:
        if pos == 0:
            return []
        n = struct.unpack_from("<Q", self.buf, pos)[0]
        return list(struct.unpack_from(f"<{n}Q", self.buf, pos + 8))

    def data(self, child: int) -> bytes:
        assert child & DATA_BIT, "expected data, found a group"
        pos = child & ~DATA_BIT
        if pos == 0:
            return b""
        n = struct.unpack_from("<Q", self.buf, pos)[0]
        return self.buf[pos + 8:pos + 8 + n]

    def md(self, index: int, inline: bytes) -> dict:
        return parse_md(inline) if index == 255 else {} if index == 0 else self.md_table[index - 1]

    def object(self, pos: int) -> Obj:
        kids = self.group(pos)
        heads = self.data(kids[-1])
        props = self.compound(kids[0])
        children, p = {}, 0
        body, hashes = heads[:-32], heads[-32:]
        for child in kids[1:-1]:
            (n,) = struct.unpack_from("<I", body, p)
            name = body[p + 4:p + 4 + n].decode()
            index = body[p + 4 + n]
            p += 5 + n
            inline = b""
            if index == 255:
                (m,) = struct.unpack_from("<I", body, p)
                inline = body[p + 4:p + 4 + m]
                p += 4 + m
            o = self.object(child)
            o.metadata = self.md(index, inline)
            children[name] = o
        assert p == len(body)
        return Obj({}, props, children, hashes)

    def compound(self, pos: int) -> dict:
        kids = self.group(pos)
        if not kids:
            return {}
        heads, props, p = self.data(kids[-1]), {}, 0
        for child in kids[:-1]:
            (info,) = struct.unpack_from("<I", heads, p)
            p += 4
            fmt = ("<B", "<H", "<I")[(info >> 2) & 3]

            def uint(fmt=fmt):
                nonlocal p
                (v,) = struct.unpack_from(fmt, heads, p)
                p += struct.calcsize(fmt)
                return v

            ptype, pod, extent = info & 3, (info >> 4) & 0xF, (info >> 12) & 0xFF
            samples, changed, ts = 0, (0, 0), 0
            if ptype:
                samples = uint()
                changed = (1, samples - 1)
                if info & 0x200:
                    changed = (uint(), uint())
                if info & 0x800:  # constant
                    changed = (0, 0)
                if info & 0x100:
                    ts = uint()
            n = uint()
            name = heads[p:p + n].decode()
            p += n
            index, inline = (info >> 20) & 0xFF, b""
            if index == 255:
                m = uint()
                inline = heads[p:p + m]
                p += m
            md = self.md(index, inline)
            if ptype == 0:
                props[name] = Prop("compound", md, props=self.compound(child))
                continue
            entries = self.group(child)[::1 if ptype == 1 else 2]  # arrays: each sample's data, then dims
            stored = [np.frombuffer(self.data(e)[16:], DTYPES[pod]).reshape(-1, extent)  # 16-byte key, values
                      for e in entries]
            want = 1 if changed == (0, 0) else changed[1] - changed[0] + 2
            assert len(stored) == want, f"{name}: {len(stored)} samples stored, the header implies {want}"
            props[name] = Prop("scalar" if ptype == 1 else "array", md, stored[0], samples=samples, stored=stored,
                               time_sampling=ts, changed=changed)
        assert p == len(heads)
        return props
