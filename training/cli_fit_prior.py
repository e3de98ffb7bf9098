"""``cgh fit-strand-prior MODEL... -o prior.npz [--exclude NAME...]``: a PCA basis of strand shapes
fitted on strand models, for ``cgh reconstruct --prior``. It is written where ``-o`` says: a basis
fitted on other people's models stays out of the package (the package ships one fitted on the
built-in synthetic styles)."""

from __future__ import annotations

import argparse

from cghair_format.cli.argtypes import int_at_least, positive_float


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("models", metavar="MODEL", nargs="+", help="strand files (any format cgh convert reads)")
    p.add_argument("-o", "--output", required=True, help="output .npz")
    p.add_argument("--exclude", metavar="NAME", nargs="*", default=[],
                   help="file names to leave out (the held-out models of an evaluation)")
    p.add_argument("--units", type=positive_float, nargs="*", default=None,
                   help="metres per unit of each model, in order (default: what each file states)")
    p.add_argument("--components", type=int_at_least(1), default=16, help="basis size (default: 16)")


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from cghair_format.exchange import load_strands

    from .reconstruct.hull import ReconstructError
    from .reconstruct.prior import fit_prior

    if args.units is not None and len(args.units) != len(args.models):
        raise ReconstructError(f"--units needs one value per model ({len(args.models)}), got {len(args.units)}")
    models = []
    for i, path in enumerate(args.models):
        if Path(path).name in args.exclude:
            print(f"left out {path}")
            continue
        units = args.units[i] if args.units else None
        models.append((Path(path).name, load_strands(path, units=units)))
    if not models:
        raise ReconstructError("every model was excluded; nothing to fit")
    prior = fit_prior(models, components=args.components)
    prior.save(args.output)
    print(f"wrote {args.output}: {len(prior.stddev)} components from {', '.join(prior.sources)}; "
          f"spread of the first {prior.stddev[0]:.4g} m")
    return 0
