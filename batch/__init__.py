"""cgh batch: a library of strand files through the pipeline on a distributed engine (batch/README in docs/batch.md)."""
