"""The files of a batch: a folder and a glob, or a CSV or JSON manifest with per-file options.

A CSV has a header with an ``input`` column and any of :class:`.options.FileOptions`' fields as further
columns (lists as ``compact;high``); a JSON manifest is a list of objects with the same keys. Relative
inputs are relative to the manifest's folder. Each file's outputs go to the output folder at the file's
path relative to the inputs' common folder (:attr:`Job.rel`), so the output tree mirrors the inputs.
"""

from __future__ import annotations

import csv
import json
import os
from dataclasses import dataclass
from pathlib import Path

from cghair_format.errors import CghError
from cghair_format.exchange import readable_extensions

from .options import FileOptions

DEFAULT_GLOB = "**/*"  # with a folder: every file whose extension a strand loader reads
MANIFEST_LIMIT = 64 << 20  # a manifest is a list of paths: larger than this is not one


@dataclass(frozen=True)
class Job:
    """One input file, its options, and where its outputs go (``rel``: its path below the inputs' folder)."""

    input: Path
    rel: Path
    options: FileOptions

    def output(self, out_dir: Path, suffix: str) -> Path:
        """``OUT/<rel's folder>/<stem><suffix>``: ``suffix`` as ``.compact.cgh`` or ``.ply``."""
        return out_dir / self.rel.parent / (self.rel.stem + suffix)


def read_manifest(source: str | os.PathLike, defaults: FileOptions | None = None, glob: str = DEFAULT_GLOB,
                  exclude: str | os.PathLike | None = None) -> list[Job]:
    """The jobs of a folder (its files matching ``glob`` that a loader reads, less any under ``exclude``:
    the output folder) or of a .csv / .json manifest, each with ``defaults`` overridden by its entry."""
    source = Path(source)
    if source.is_dir():
        entries = _folder(source, glob, exclude)
    elif not source.exists():
        raise CghError(f"{source}: no such folder or manifest; give a folder of strand files or a .csv / .json list")
    elif source.suffix.lower() in (".csv", ".json"):
        if source.stat().st_size > MANIFEST_LIMIT:
            raise CghError(f"{source}: a manifest of over {MANIFEST_LIMIT >> 20} MiB is not a list of files")
        entries = _csv(source) if source.suffix.lower() == ".csv" else _json(source)
    else:
        raise CghError(f"{source}: a manifest is a folder, a .csv or a .json file, not {source.suffix or 'this'}")
    if not entries:
        raise CghError(f"{source}: no input files (a folder's files must have one of the extensions "
                       f"{' '.join(readable_extensions())}; --glob chooses which)")
    return _jobs(entries, defaults or FileOptions())


def _folder(folder: Path, glob: str, exclude) -> list[tuple[Path, dict, str]]:
    readable = set(readable_extensions())
    skip = Path(exclude).resolve() if exclude is not None else None
    paths = sorted(p for p in folder.glob(glob) if p.is_file() and p.suffix.lower() in readable
                   and not p.name.startswith(".") and not (skip and p.resolve().is_relative_to(skip)))
    return [(p, {}, str(p)) for p in paths]


def _csv(path: Path) -> list[tuple[Path, dict, str]]:
    try:
        with open(path, newline="", encoding="utf-8") as f:
            rows = list(csv.DictReader(f))
    except (UnicodeDecodeError, csv.Error) as exc:
        raise CghError(f"{path}: not a CSV manifest ({exc})") from None
    return [_entry(path, row, f"{path}:{i + 2}") for i, row in enumerate(rows)]


def _json(path: Path) -> list[tuple[Path, dict, str]]:
    try:
        items = json.loads(path.read_text(encoding="utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise CghError(f"{path}: not a JSON manifest ({exc})") from None
    if not isinstance(items, list) or not all(isinstance(i, dict) for i in items):
        raise CghError(f"{path}: a JSON manifest is a list of objects, each with an \"input\" path")
    return [_entry(path, item, f"{path}: entry {i}") for i, item in enumerate(items)]


def _entry(manifest: Path, entry: dict, where: str) -> tuple[Path, dict, str]:
    entry = {k.strip() if isinstance(k, str) else k: v for k, v in entry.items()}
    name = entry.pop("input", None)
    if not isinstance(name, str) or not name.strip():
        raise CghError(f"{where}: no input path (each entry needs an \"input\")")
    path = Path(name.strip())
    return (path if path.is_absolute() else manifest.parent / path), entry, where


def _jobs(entries: list[tuple[Path, dict, str]], defaults: FileOptions) -> list[Job]:
    paths = [Path(os.path.abspath(p)) for p, _, _ in entries]
    root = Path(os.path.commonpath([p.parent for p in paths]))
    jobs, seen = [], {}
    for path, (_, entry, where) in zip(paths, entries, strict=True):
        rel = path.relative_to(root)
        stem = rel.parent / rel.stem
        if stem in seen:
            raise CghError(f"{where}: {path} and {seen[stem]} would write the same outputs ({stem}.*); "
                           "rename one or put it in its own folder")
        seen[stem] = path
        jobs.append(Job(path, rel, defaults.override(entry, where)))
    return jobs
