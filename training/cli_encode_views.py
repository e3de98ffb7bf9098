"""``cgh encode --views DATASET``'s step: which Gaussians the dataset's training views hardly use
(:mod:`training.visibility`), registered for the format's ``encode`` verb by the ``cgh.negligible``
entry point ``views`` (pyproject.toml), since measuring them renders the views."""

from __future__ import annotations

from cghair_format.errors import MissingDependencyError


def negligible_from_views(asset, dataset: str, budget: float):
    """The segments of ``asset`` (bool ``[S, P-1]``) whose Gaussians together carry at most ``budget`` of
    the blend weight of ``dataset``'s training views (:func:`training.visibility.negligible_segments`)."""
    try:
        from .datasets.read import read_dataset
        from .visibility import negligible_segments
    except ImportError as exc:
        raise MissingDependencyError(exc.name or "torch", "training", "cgh encode --views") from None
    return negligible_segments(asset, read_dataset(dataset).train, budget)
