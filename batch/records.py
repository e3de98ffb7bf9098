"""What makes a rerun resume: one record per finished file, ``OUT/.batch/<rel>.json``.

A worker writes a file's record after all its outputs, atomically, with the input's size, modification
time and SHA-256 and the options' key. A rerun skips a file whose record matches: same options, and the
same size and time or, where those changed, the same SHA-256; and whose outputs are all still there.
A failed file has no record, so a rerun tries it again.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

from cghair_format.atomic import write_text

from .manifest import Job

FOLDER = ".batch"
VERSION = 1


def fingerprint(path: Path) -> dict:
    """The input's size, modification time (ns) and SHA-256."""
    stat = path.stat()
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        while chunk := f.read(1 << 20):
            digest.update(chunk)
    return {"size": stat.st_size, "mtime_ns": stat.st_mtime_ns, "sha256": digest.hexdigest()}


def path_of(out_dir: Path, job: Job) -> Path:
    return out_dir / FOLDER / f"{job.rel}.json"


def write(out_dir: Path, job: Job, fingerprint: dict, row: dict) -> None:
    """Record ``job`` as done with ``row`` (after its outputs are written)."""
    path = path_of(out_dir, job)
    path.parent.mkdir(parents=True, exist_ok=True)
    write_text(path, json.dumps({"version": VERSION, "options": job.options.key(), "input": fingerprint,
                                 "row": row}, indent=1))


def finished(out_dir: Path, job: Job) -> dict | None:
    """The row of ``job`` from an earlier run, if that run did it as it would be done now; else None."""
    try:
        record = json.loads(path_of(out_dir, job).read_text(encoding="utf-8"))
        row, known, options = record["row"], record["input"], record["options"]
        stat = job.input.stat()
    except (OSError, ValueError, KeyError, TypeError):
        return None  # none, unreadable or of another version: do the file again
    if record.get("version") != VERSION or options != job.options.key() or stat.st_size != known["size"]:
        return None
    if stat.st_mtime_ns != known["mtime_ns"] and fingerprint(job.input)["sha256"] != known["sha256"]:
        return None
    if not all((out_dir / p).is_file() for p in str(row.get("outputs", "")).split(";") if p):
        return None
    return row | {"run": "earlier"}
