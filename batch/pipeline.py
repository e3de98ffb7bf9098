"""One file's pipeline, run on a worker: import, cards, a .cgh per profile, the round-trip check, the
baseline coder, exports and (with a dataset) training. It returns the file's report row.

Every output is written atomically (:mod:`cghair_format.atomic`) and the file's record last
(:mod:`.records`), so a file is done when its record is there and never half-written.
"""

from __future__ import annotations

import functools
import resource
import time
from contextlib import contextmanager
from pathlib import Path

import cghair_format as cgh
from cghair_format.atomic import write_bytes
from cghair_format.cards import build_cards
from cghair_format.exchange import load_strands
from cghair_format.profiles import get_profile

from . import baseline_coder, records
from .manifest import Job


@contextmanager
def timed(row: dict, key: str):
    start = time.perf_counter()
    yield
    row[key] = round(time.perf_counter() - start, 4)


@functools.cache
def warm_up() -> None:
    """Import and run once what the pipeline imports lazily (scikit-learn's k-means: about 4 s here), in
    the worker, so that every file's forked process starts with it done."""
    from cghair_format.synth import synthesize

    build = build_cards(synthesize("wavy", 16, 8, seed=0), n_cards=2, n_groups=1, progress=False)
    cgh.decode(cgh.encode(build.asset, "compact")[0])


def run_file(job: Job, out_dir: Path) -> dict:
    """Do ``job`` and return its row (:mod:`.report` says what each column is)."""
    start = time.perf_counter()
    opts = job.options
    row: dict = {"input": str(job.rel), "status": "ok", "run": "this", "error": ""}
    fingerprint = records.fingerprint(job.input)
    with timed(row, "import_s"):
        strands = load_strands(job.input)
    counts = strands.point_counts
    row.update(strands=strands.count, points=int(counts.sum()), min_points=int(counts.min()),
               max_points=int(counts.max()), bbox_diagonal=float(strands.bbox_diagonal()))
    cards, groups = opts.card_counts(strands.count)
    with timed(row, "cards_s"):
        build = build_cards(strands, n_cards=cards, n_groups=groups, points=opts.points, seed=opts.seed,
                            progress=False)
    # the builder's own error before quantization, against the points it kept (the input's own, unless resampled)
    row.update(cards=build.info["cards"], groups=build.info["groups"],
               cards_error=_relative(build.error.max_abs, row["bbox_diagonal"]))
    outputs = []
    for profile in opts.profiles:
        outputs.append(_profile(row, build, strands, profile, job.output(out_dir, f".{profile}.cgh"), opts.check))
    for ext in opts.exports:
        with timed(row, f"export{ext.replace('.', '_')}_s"):
            outputs.append(_export(outputs[0], job.output(out_dir, ext)))
    if opts.dataset is not None:
        with timed(row, "train_s"):
            outputs.append(_train(build, opts, job.output(out_dir, ".trained.cgh")))
    usage = resource.getrusage(resource.RUSAGE_SELF)  # of this file's process (forked: counted from zero)
    row["total_s"] = round(time.perf_counter() - start, 4)
    row["cpu_s"] = round(usage.ru_utime + usage.ru_stime, 3)  # what the file costs a core, whatever the load
    row["peak_rss_mb"] = round(usage.ru_maxrss / 1024, 1)
    row["outputs"] = ";".join(str(p.relative_to(out_dir)) for p in outputs)
    records.write(out_dir, job, fingerprint, row)
    return row


def _relative(distance: float, diagonal: float) -> float:
    """A distance over the bounding-box diagonal, to 4 digits (the distance itself where the points coincide)."""
    return float(f"{distance / diagonal if diagonal > 0 else distance:.4g}")


def _profile(row: dict, build, strands, profile: str, path: Path, check: bool) -> Path:
    """Encode ``build`` with ``profile`` to ``path``; its sizes, times and (``check``) round-trip error."""
    with timed(row, f"encode_s_{profile}"):
        data, report = cgh.encode(build.asset, profile)
    geometry = sum(report.chunk_sizes.get(c, 0) for c in baseline_coder.GEOMETRY_CHUNKS)
    row[f"bytes_{profile}"] = len(data)
    row[f"bits_per_point_{profile}"] = round(8 * len(data) / row["points"], 3)
    row[f"geometry_bytes_{profile}"] = geometry
    prof = get_profile(profile)
    if not prof.lossless:  # the baseline at this profile's bound, on the same points
        bound = prof.position_tolerance * report.bbox_diagonal
        with timed(row, f"baseline_s_{profile}"):
            row[f"baseline_bytes_{profile}"], _ = baseline_coder.encode(strands.points, strands.offsets, bound)
        row[f"ratio_{profile}"] = round(geometry / row[f"baseline_bytes_{profile}"], 4)
    if check:
        with timed(row, f"decode_s_{profile}"):
            decoded = cgh.decode(data)
        error = build.error_of(decoded, report)  # against the points the build kept: the input's own ...
        row[f"max_error_{profile}"] = _relative(error.max_abs, row["bbox_diagonal"])
        if build.resampling is not None:  # ... unless --points resampled them: how far that moved them
            row["resampling_error"] = float(f"{build.resampling.shape_error:.4g}")
    path.parent.mkdir(parents=True, exist_ok=True)
    write_bytes(path, data)
    return path


def _export(src: Path, out: Path) -> Path:
    """``src`` (a .cgh) as ``out``: a 3DGS PLY, USD with curves, cards and Gaussians, or an Alembic groom."""
    ext = out.suffix
    if ext == ".ply":
        from cghair_format.exchange.ply_3dgs import write_3dgs_ply

        asset, g = cgh.read_with_gaussians(src)
        write_3dgs_ply(g, out, source_up=asset.up_axis, meters_per_unit=asset.meters_per_unit)
    elif ext == ".abc":
        from cghair_format.exchange.alembic import export_groom

        export_groom(out, asset=cgh.read(src), cards=True)
    else:
        from cghair_format.exchange.usd_export import export_usd

        export_usd(out, asset=cgh.read(src), curves=True, cards=True, gaussians=True)
    return out


def _train(build, opts, out: Path) -> Path:
    from training.config import TrainConfig
    from training.train import train

    train(opts.dataset, cards=build.asset, out=out, config=TrainConfig(iterations=opts.iters), progress=False,
          threads=1)
    return out
