"""The ``cgh`` verb the batch package owns (named by its ``cgh.verbs`` entry point in pyproject.toml)."""

from cghair_format.cli.registry import Verb

VERBS = {
    "batch": Verb("batch.cli", "convert, encode and check a library of strand files on Dask, with a report"),
}
