"""What ``cgh batch`` does to one file: :class:`FileOptions`, the defaults any manifest entry overrides.

A manifest's per-file options are the fields below, by name (a CSV column or a JSON key); the command
line's options give every file's defaults. :meth:`FileOptions.key` names the options a file was done
with, so that a rerun redoes a file whose options changed.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import asdict, dataclass, fields

from cghair_format.errors import CghError
from cghair_format.profiles import PROFILES

EXPORTS = (".ply", ".usda", ".usdc", ".abc")  # 3DGS PLY, USD (curves, cards, Gaussians), Alembic groom
CARDS_PER_STRANDS = 30  # the default card count: one card per this many strands (at most MAX_CARDS) ...
MAX_CARDS = 800  # ... as cgh cards' default
MAX_GROUPS = 64


@dataclass(frozen=True)
class FileOptions:
    """One file's pipeline: import, cards, one .cgh per profile, the round-trip check, exports, training."""

    profiles: tuple[str, ...] = ("compact",)
    cards: int | None = None  # None: strands // CARDS_PER_STRANDS, in [1, MAX_CARDS]
    groups: int | None = None  # None: min(cards, MAX_GROUPS)
    points: int | None = None  # None: every strand keeps its own points
    seed: int = 0
    check: bool = True  # decode each file and measure its error against the input's own points
    exports: tuple[str, ...] = ()  # extensions from EXPORTS, written from the first profile's file
    dataset: str | None = None  # a training dataset folder: train the appearance on it, write <stem>.trained.cgh
    iters: int = 300  # training iterations (with a dataset)

    def __post_init__(self) -> None:
        bad = [p for p in self.profiles if p not in PROFILES]
        if not self.profiles or bad:
            raise CghError(f"unknown profile {', '.join(bad) or '(none given)'}: choose from {', '.join(PROFILES)}")
        wrong = [e for e in self.exports if e not in EXPORTS]
        if wrong:
            raise CghError(f"cannot export {', '.join(wrong)}: choose from {', '.join(EXPORTS)}")
        for name, low in (("cards", 1), ("groups", 1), ("points", 4), ("iters", 1)):
            value = getattr(self, name)
            if value is not None and value < low:
                raise CghError(f"{name} must be at least {low}, got {value}")

    def key(self) -> str:
        """A short hash of the options: a file done with other options is done again."""
        return hashlib.sha256(json.dumps(asdict(self), sort_keys=True).encode()).hexdigest()[:16]

    def card_counts(self, strands: int) -> tuple[int, int]:
        cards = self.cards or min(max(strands // CARDS_PER_STRANDS, 1), MAX_CARDS)
        return cards, self.groups or min(cards, MAX_GROUPS)

    def override(self, entry: dict, where: str) -> FileOptions:
        """These options with a manifest entry's (strings from a CSV, or JSON values) in their place."""
        known = {f.name: f for f in fields(self)}
        changes = {}
        for name, value in entry.items():
            if name not in known:
                raise CghError(f"{where}: unknown option {name!r}; known: input, {', '.join(known)}")
            if value is None or value == "":
                continue
            changes[name] = _parse(name, value, where)
        try:
            return type(self)(**{**asdict(self), **changes})
        except CghError as exc:
            raise CghError(f"{where}: {exc}") from None


def _parse(name: str, value, where: str):
    """A manifest value as the field ``name`` holds it: lists may be ``a;b`` strings (CSV) or JSON lists."""
    try:
        if name in ("profiles", "exports"):
            items = value.split(";") if isinstance(value, str) else list(value)
            return tuple(str(v).strip() for v in items if str(v).strip())
        if name == "check":
            if isinstance(value, str) and value.strip().lower() in ("0", "1", "true", "false", "yes", "no"):
                return value.strip().lower() in ("1", "true", "yes")
            if isinstance(value, bool):
                return value
            raise ValueError(value)
        if name == "dataset":
            return str(value)
        if isinstance(value, bool) or (isinstance(value, float) and not value.is_integer()):
            raise ValueError(value)
        return int(value)
    except (TypeError, ValueError):
        raise CghError(f"{where}: option {name} cannot be {value!r}") from None
