"""Where ``cgh`` finds its verbs: the format's own (below) and those each package above it registers.

A package above the format (``training``, ``viewer``) owns its verbs: a table like :data:`VERBS` in a small
module of its own (``training/verbs.py``), named by an entry point of the ``cgh.verbs`` group in
pyproject.toml. So the format never imports a higher package, and a new verb is one line in its
package's table. Steps a higher package lends to a format verb (``cgh encode --views``, which renders a
dataset's views) are entry points too, found with :func:`registered`.
"""

from __future__ import annotations

from importlib.metadata import entry_points
from typing import NamedTuple


class Verb(NamedTuple):
    """A ``cgh`` verb. Its module defines ``add_arguments(parser)`` and ``run(args) -> int`` and is imported
    to build the parser, so it imports nothing heavy at its top: torch, GL and scikit-learn only in ``run``
    (``cgh info`` never loads them)."""

    module: str
    help: str  # one line, for ``cgh --help``
    output_folder: bool = False  # --output names a folder (made as needed); else a file
    make_parents: bool = False  # --output's missing folders are made


VERBS: dict[str, Verb] = {
    "info": Verb("cghair_format.cli.info", "show counts, chunk sizes and bits per Gaussian of a .cgh"),
    "validate": Verb("cghair_format.cli.validate", "check a .cgh file; exit 0 if valid, 1 with the reason"),
    "encode": Verb("cghair_format.cli.encode", "re-encode a .cgh with another precision profile"),
    "synth": Verb("cghair_format.cli.synth", "grow a built-in procedural hairstyle"),
    "convert": Verb("cghair_format.cli.convert", "convert strands between formats (.cgh accepted as input)"),
    "export": Verb("cghair_format.cli.export", "export a .cgh or strands to USD, 3DGS PLY, Alembic or .blend"),
    "cards": Verb("cghair_format.cli.cards", "build hair cards from strands and write a .cgh"),
    "animate": Verb("cghair_format.cli.animate", "move a .cgh's cards by a simulated head motion (built in, or a "
                    "head track from USD or Alembic) or an animated strand file"),
}
VERB_GROUP = "cgh.verbs"  # entry points: a package's name -> its table of verbs ("training.verbs:VERBS")


def verbs() -> dict[str, Verb]:
    """Every verb: the format's, then each registered package's, in the order of the packages' names."""
    found = dict(VERBS)
    for entry in sorted(entry_points(group=VERB_GROUP), key=lambda e: e.name):
        try:
            found.update(entry.load())
        except ImportError:  # a registered package that is not there: its verbs are unknown, so absent
            continue
    return found


def registered(group: str, name: str):
    """The object the entry point ``name`` of ``group`` names, loaded; None when no package registers it."""
    for entry in entry_points(group=group, name=name):
        return entry.load()
    return None
