"""A small PLY reader and writer (ascii, binary little- and big-endian) for the strand and 3DGS layouts.

Reading returns each element as a dict of property name -> numpy array (list properties as a
Python list of arrays). Sizes are checked against the file length before anything is allocated.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..atomic import atomic_open
from ._common import StrandFileError, need, read_bytes

TYPES = {"char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2", "int16": "i2",
         "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
         "float": "f4", "float32": "f4", "double": "f8", "float64": "f8"}
FORMATS = {"ascii": None, "binary_little_endian": "<", "binary_big_endian": ">"}
MAX_HEADER = 1 << 20


@dataclass
class Element:
    name: str
    count: int
    props: list[tuple[str, str, str | None]] = field(default_factory=list)  # (name, type, list count type)
    data: dict[str, np.ndarray | list] = field(default_factory=dict)


@dataclass
class PlyFile:
    fmt: str
    elements: dict[str, Element]
    comments: list[str]


def read_ply(path: str | Path) -> PlyFile:
    data = read_bytes(path)
    if not data.startswith(b"ply"):
        raise StrandFileError(path, f"not a PLY file: it starts with {data[:8]!r}, expected b'ply'")
    end = data.find(b"end_header", 0, MAX_HEADER)
    if end < 0:
        raise StrandFileError(path, "PLY header has no 'end_header' line (truncated or not PLY)")
    body = data.find(b"\n", end) + 1
    if body == 0:
        raise StrandFileError(path, "PLY file ends right after 'end_header'")
    fmt, elements, comments = None, {}, []
    current = None
    for n, raw in enumerate(data[:end].decode("ascii", "replace").splitlines()[1:], start=2):
        parts = raw.split()
        if not parts:
            continue
        try:
            if parts[0] == "format":
                if parts[1] not in FORMATS:
                    raise StrandFileError(path, f"PLY header line {n}: unknown format {parts[1]!r}")
                fmt = parts[1]
            elif parts[0] in ("comment", "obj_info"):
                comments.append(raw.split(None, 1)[1] if len(parts) > 1 else "")
            elif parts[0] == "element":
                count = int(parts[2])
                if count < 0:
                    raise ValueError
                current = Element(parts[1], count)
                elements[current.name] = current
            elif parts[0] == "property":
                if current is None:
                    raise StrandFileError(path, f"PLY header line {n}: property before any element")
                if parts[1] == "list":
                    current.props.append((parts[4], TYPES[parts[3]], TYPES[parts[2]]))
                else:
                    current.props.append((parts[2], TYPES[parts[1]], None))
            else:
                raise StrandFileError(path, f"PLY header line {n}: unexpected keyword {parts[0]!r}")
        except (IndexError, ValueError, KeyError):
            raise StrandFileError(path, f"PLY header line {n} is malformed: {raw[:80]!r}") from None
    if fmt is None:
        raise StrandFileError(path, "PLY header has no 'format' line")
    if fmt == "ascii":
        _read_ascii(path, data[body:], elements)
    else:
        _read_binary(path, data, body, FORMATS[fmt], elements)
    return PlyFile(fmt, elements, comments)


def _read_binary(path, data: bytes, pos: int, endian: str, elements: dict[str, Element]) -> None:
    for el in elements.values():
        if all(p[2] is None for p in el.props):
            dt = np.dtype([(name, endian + t) for name, t, _ in el.props])
            need(path, data, pos + dt.itemsize * el.count, f"PLY element {el.name!r} ({el.count} rows)")
            rows = np.frombuffer(data, dt, el.count, pos)
            pos += dt.itemsize * el.count
            el.data = {name: np.ascontiguousarray(rows[name]).astype(rows[name].dtype.newbyteorder("="))
                       for name, _, _ in el.props}
            continue
        cols: dict[str, list] = {name: [] for name, _, _ in el.props}
        for row in range(el.count):  # list properties make rows variable-sized: walk them
            for name, t, ct in el.props:
                if ct is None:
                    size = np.dtype(t).itemsize
                    need(path, data, pos + size, f"PLY element {el.name!r} row {row}")
                    cols[name].append(np.frombuffer(data, endian + t, 1, pos)[0])
                    pos += size
                else:
                    csize = np.dtype(ct).itemsize
                    need(path, data, pos + csize, f"PLY element {el.name!r} row {row}")
                    k = int(np.frombuffer(data, endian + ct, 1, pos)[0])
                    pos += csize
                    size = np.dtype(t).itemsize * k
                    need(path, data, pos + size, f"PLY element {el.name!r} row {row}")
                    cols[name].append(np.frombuffer(data, endian + t, k, pos).astype(t))
                    pos += size
        el.data = {name: (np.array(v, t) if ct is None else v)
                   for (name, t, ct), v in zip(el.props, cols.values(), strict=True)}


def _read_ascii(path, body: bytes, elements: dict[str, Element]) -> None:
    lines = body.decode("ascii", "replace").splitlines()
    i = 0
    for el in elements.values():
        if i + el.count > len(lines):
            raise StrandFileError(path, f"truncated: PLY element {el.name!r} needs {el.count} lines, "
                                        f"{len(lines) - i} are left")
        chunk = lines[i:i + el.count]
        i += el.count
        if all(p[2] is None for p in el.props):
            k = len(el.props)
            try:
                table = np.array(" ".join(chunk).split(), np.float64)
            except ValueError:
                raise StrandFileError(path, f"PLY element {el.name!r} has a non-numeric value") from None
            if table.size != k * el.count:
                raise StrandFileError(path, f"PLY element {el.name!r}: expected {k} values on each of "
                                            f"{el.count} lines, found {table.size} values in all")
            table = table.reshape(el.count, k)
            el.data = {name: table[:, j].astype(t) for j, (name, t, _) in enumerate(el.props)}
            continue
        cols = {name: [] for name, _, _ in el.props}
        for n, line in enumerate(chunk):
            tok = line.split()
            j = 0
            try:
                for name, t, ct in el.props:
                    if ct is None:
                        cols[name].append(float(tok[j]))
                        j += 1
                    else:
                        k = int(tok[j])
                        cols[name].append(np.array(tok[j + 1:j + 1 + k], t))
                        if len(cols[name][-1]) != k:
                            raise IndexError
                        j += 1 + k
            except (IndexError, ValueError):
                raise StrandFileError(path, f"PLY element {el.name!r} line {n} is malformed") from None
        el.data = {name: (np.array(v, t) if ct is None else v)
                   for (name, t, ct), v in zip(el.props, cols.values(), strict=True)}


def write_ply(path: str | Path, elements: list[tuple[str, dict[str, np.ndarray]]],
              comments: list[str] = ()) -> None:
    """Write scalar-property elements as binary little-endian PLY; arrays keep their dtypes."""
    names = {np.dtype(v).str[1:]: k for k, v in TYPES.items() if k in
             ("char", "uchar", "short", "ushort", "int", "uint", "float", "double")}
    head = ["ply", "format binary_little_endian 1.0", *(f"comment {c}" for c in comments)]
    blobs = []
    for name, cols in elements:
        count = len(next(iter(cols.values())))
        head.append(f"element {name} {count}")
        dt = []
        for prop, arr in cols.items():
            head.append(f"property {names[arr.dtype.str[1:]]} {prop}")
            dt.append((prop, "<" + arr.dtype.str[1:]))
        rec = np.empty(count, dt)
        for prop, arr in cols.items():
            rec[prop] = arr
        blobs.append(rec.tobytes())
    head.append("end_header")
    with atomic_open(path) as f:
        f.write(("\n".join(head) + "\n").encode("ascii"))
        for b in blobs:
            f.write(b)
