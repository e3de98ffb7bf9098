"""META, the file's JSON chunk (spec 3), as one table of fields: each one's JSON type and range.

The reader checks META with :func:`parse` and the writer serialises it with :func:`dump`, both from
:data:`FIELDS`: a field has one definition, the writer cannot store a value the reader would refuse,
and every refusal says which field and what it may hold. A range that depends on another field
(``quant.children`` below the strand count, one ``quant.level_taps`` width per refinement level) is a
function of META, evaluated on the fields before it, which :func:`parse` has already checked.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from ..asset import ACTIVATIONS, MAX_LENGTH, UP_AXES, WEIGHT_MODES
from ..errors import AssetError, InvalidContentError, LimitError
from ..quantize import TAPS, level_plan
from ..residual_coder import MAX_NEIGHBOUR_CLASSES

MAX_LATENT_DIM = 4096  # META latent_dim's range (2.1); also bounds a multi-sh codebook entry

MAX_META_BYTES = 1 << 20
POSITIVE = math.ulp(0.0)  # the smallest float above 0: a lower bound of POSITIVE means "> 0"
TINY = 1e-30

# the JSON types, as the refusals name them
INTEGER, NUMBER, BOOLEAN, STRING = "an integer", "a number", "true or false", "a string"
LIST, OBJECT = "a list", "an object"

Bound = float | int | Callable[[dict], float | int] | None


@dataclass(frozen=True)
class Field:
    """One META value. ``lo``/``hi``: the range of a number, or the item count of a list (a function of
    META where it depends on other fields); ``one_of``: the values allowed; ``item``: what a list holds;
    ``fields``: what an object holds; ``when``: the field exists only where this holds of META
    (absent: always); ``optional``: it may be left out; ``rule``: a check across fields, returning what
    is wrong or None."""

    key: str
    kind: str
    lo: Bound = None
    hi: Bound = None
    one_of: tuple = ()
    item: Field | None = None
    fields: tuple[Field, ...] = ()
    when: Callable[[dict], bool] | None = None
    optional: bool = False
    rule: Callable[[dict, Any], str | None] | None = None


def _levels(meta: dict) -> int:
    """The refinement levels of the strands' points (spec 4.1): one interpolation width each."""
    return len(level_plan(meta["points"], meta["quant"]["base_stride"])[1])


def _quantized(meta: dict) -> bool:
    return not meta["quant"]["lossless"]


def _sh_outputs(meta: dict, layers: list) -> str | None:
    want = (meta["points"] - 1) * (meta["sh_degree"] + 1) ** 2 * 3
    if layers[-1]["out"] != want:  # the quantized last layer's rows are colour triples (spec 4.4)
        return f"its last layer must output (points - 1) x (sh_degree + 1)^2 x 3 = {want} values"
    return None


def _power_of_two(_meta: dict, stride: int) -> str | None:
    return "it must be a power of two" if stride & (stride - 1) else None


def _plain_levels(meta: dict, masks: list) -> str | None:
    if meta["quant"]["level_guide"] and any(masks[1:]):
        return ("the refinement levels' masks must be 0 with level_guide (they are differences from their "
                "references' already)")
    return None


def _with_lowered(meta: dict, _budget: float) -> str | None:
    return None if "opacity_lowered" in meta["quant"] else "it describes opacity_lowered, which is missing"


def _count(key: str, lo: int, hi: int) -> Field:
    return Field(key, INTEGER, lo, hi)


QUANT_FIELDS = (
    Field("lossless", BOOLEAN),
    Field("step", NUMBER, TINY, MAX_LENGTH, when=_quantized),  # strand points' step, scene units
    Field("card_step", NUMBER, TINY, MAX_LENGTH, when=_quantized),
    Field("normal_bits", INTEGER, 8, 24, when=_quantized),
    Field("base_stride", INTEGER, 1, 256, when=_quantized, rule=_power_of_two),
    Field("newton_halvings", INTEGER, 0, 8, when=_quantized),
    Field("stretch_max", NUMBER, 1, 16, when=_quantized),
    Field("base_order", LIST, 3, 3, item=Field("", INTEGER, one_of=(1, 2)), when=_quantized),  # u, v, delta
    Field("base_guide", INTEGER, 0, 3, when=_quantized),
    Field("newton_steps", INTEGER, 0, 8, when=_quantized),
    Field("level_taps", LIST, _levels, _levels, item=Field("", INTEGER, one_of=TAPS), when=_quantized),
    Field("level_guide", INTEGER, 0, 1, when=_quantized),
    Field("opacity_scale", NUMBER, TINY, when=_quantized),
    Field("logit_levels", INTEGER, 1, 1 << 24, when=_quantized),
    Field("logit_floor", NUMBER, -1e6, 0, when=_quantized),
    # the codebooks' step, then each MLP layer's
    Field("weight_steps", LIST, lambda m: len(m["mlp"]) + 1, lambda m: len(m["mlp"]) + 1,
          item=Field("", NUMBER, POSITIVE), when=_quantized),
    Field("children", INTEGER, 0, lambda m: m["strands"] - 1, when=_quantized, optional=True),  # spec 4.5
    # per residual array (the base, then each level), the channels stored as differences (bits u, v, delta)
    Field("neighbour", LIST, lambda m: _levels(m) + 1, lambda m: _levels(m) + 1,
          item=Field("", INTEGER, 0, 7), when=_quantized, rule=_plain_levels),
    Field("neighbour_classes", INTEGER, 1, MAX_NEIGHBOUR_CLASSES, when=_quantized),
    # spec 4.4, "Lowered opacities": how many opacities lie below the profile's bound, and the share of the
    # blend weight their Gaussians carry (both only where the writer stored some so)
    Field("opacity_lowered", INTEGER, 0, lambda m: m["strands"] * (m["points"] - 1), when=_quantized,
          optional=True),
    Field("opacity_budget", NUMBER, 0, 1, when=_quantized, optional=True, rule=_with_lowered),
    # the points' bound as a fraction of bbox_diagonal, where the profile's name does not tell it (spec 7)
    Field("position_tolerance", NUMBER, TINY, 1, when=_quantized, optional=True),
)

ANIMATION_FIELDS = (  # spec 2.1 and 4.6: the animation part
    Field("frames", INTEGER, 1, 1 << 20),
    Field("fps", NUMBER, TINY, 1000),
    Field("start", NUMBER, -MAX_LENGTH, MAX_LENGTH),  # seconds
    Field("keyframe_interval", INTEGER, 1, lambda m: min(m["animation"]["frames"], 4096)),
    Field("step", NUMBER, TINY, MAX_LENGTH, when=_quantized),  # spine step qa, scene units
    Field("normal_bits", INTEGER, 8, 24, when=_quantized),
    Field("source", STRING, optional=True),
)

MLP_LAYER = (Field("out", INTEGER, 1, 1 << 20), Field("activation", STRING, one_of=ACTIVATIONS))

FIELDS = (
    _count("strands", 1, 1 << 24),
    _count("points", 2, 4096),
    _count("cards", 1, 1 << 20),
    _count("segments", 1, 1024),
    _count("groups", 1, 1 << 16),
    _count("k", 1, 256),
    _count("latent_dim", 1, MAX_LATENT_DIM),
    Field("sh_degree", INTEGER, 0, 3),
    Field("weight_mode", STRING, one_of=WEIGHT_MODES),
    Field("temperature", NUMBER, TINY),
    Field("mlp", LIST, 1, 16, item=Field("", OBJECT, fields=MLP_LAYER), rule=_sh_outputs),
    Field("thickness", NUMBER, TINY, MAX_LENGTH),
    Field("meters_per_unit", NUMBER, TINY),
    Field("up_axis", STRING, one_of=UP_AXES),
    Field("generator", STRING),
    Field("attribution", STRING),
    Field("bbox_diagonal", NUMBER, 0),
    Field("profile", STRING),
    Field("quant", OBJECT, fields=QUANT_FIELDS),
    Field("animation", OBJECT, fields=ANIMATION_FIELDS, optional=True),
)

# fields that every quantized file of this format version has: a file without them was written by a draft
_DRAFT_MISSING = ("newton_halvings", "stretch_max", "neighbour_classes", "base_guide", "weight_steps", "level_guide")


def parse(raw: bytes) -> dict:
    """META from its bytes, every field checked against :data:`FIELDS` (unknown fields are ignored:
    a later minor version may add some); raises ``InvalidContentError`` or ``LimitError`` naming META."""
    if len(raw) > MAX_META_BYTES:
        raise LimitError(f"META of {len(raw)} bytes exceeds {MAX_META_BYTES}", chunk="META")
    try:
        meta = load_json(raw)
    except (UnicodeDecodeError, ValueError, RecursionError) as exc:
        raise InvalidContentError(f"META is not valid UTF-8 JSON: {exc}", chunk="META") from None
    if not isinstance(meta, dict):
        raise InvalidContentError("META must be a JSON object", chunk="META")
    quant = meta.get("quant")
    if isinstance(quant, dict) and (("logit_step" in quant and "logit_levels" not in quant) or (
            quant.get("lossless") is False and any(key not in quant for key in _DRAFT_MISSING))):
        raise InvalidContentError("written by a pre-release draft of .cgh 1.0 (before the rANS strand coder, "
                                  "searched Newton steps, stretched residual steps, neighbour token contexts, "
                                  "guided base samples, weights on steps, card normals as angles or level "
                                  "references), which this reader cannot decode: write the asset again from its "
                                  "source (cgh encode, or cgh train --resume CHECKPOINT)", chunk="META")
    problem = _check_object(meta, meta, FIELDS, "")
    if problem:
        raise InvalidContentError(problem, chunk="META")
    return meta


def check_writable(meta: dict) -> None:
    """Raise ``AssetError`` where META holds a value the format cannot (one :func:`parse` would refuse)."""
    problem = _check_object(meta, meta, FIELDS, "")
    if problem:
        raise AssetError(f"the asset cannot be written: {problem}")


def dump(meta: dict) -> bytes:
    """META's bytes as the writer stores them: the fields in :data:`FIELDS`' order, each checked as
    :func:`parse` will (:func:`check_writable`; ``KeyError`` for a field the schema does not define: a
    writer's mistake)."""
    check_writable(meta)
    return json.dumps(_ordered(meta, FIELDS), separators=(",", ":"), allow_nan=False).encode("utf-8")


def _ordered(obj: dict, fields: tuple[Field, ...]) -> dict:
    defined = {f.key: f for f in fields}
    unknown = set(obj) - set(defined)
    if unknown:
        raise KeyError(f"META fields {sorted(unknown)} are not in the schema")
    out = {}
    for key, f in defined.items():
        if key in obj:
            v = obj[key]
            if f.kind == OBJECT:
                v = _ordered(v, f.fields)
            elif f.kind == LIST and f.item.kind == OBJECT:
                v = [_ordered(x, f.item.fields) for x in v]
            out[key] = v
    return out


def _check_object(meta: dict, obj: dict, fields: tuple[Field, ...], path: str) -> str | None:
    """What is wrong with the JSON object ``obj`` (at ``path`` in ``meta``), or None."""
    for f in fields:
        if f.when is not None and not f.when(meta):
            continue
        name = path + f.key
        if f.key not in obj:
            if f.optional:
                continue
            return f"META field {name!r} is missing (it must be {_describe(meta, f)})"
        problem = _check_value(meta, obj[f.key], f, name)
        if problem:
            return problem
    return None


def _check_value(meta: dict, v: Any, f: Field, name: str) -> str | None:
    if not _fits(meta, v, f):
        return f"META field {name!r} is out of range: {_shown(v)} (it must be {_describe(meta, f)})"
    if f.kind == OBJECT:
        problem = _check_object(meta, v, f.fields, name + ".")
        if problem:
            return problem
    elif f.kind == LIST:
        for i, x in enumerate(v):
            problem = _check_value(meta, x, f.item, f"{name}[{i}]")
            if problem:
                return problem
    why = f.rule(meta, v) if f.rule is not None else None
    return f"META field {name!r} is out of range: {_shown(v)} ({why})" if why else None


def _fits(meta: dict, v: Any, f: Field) -> bool:
    """Whether ``v`` has ``f``'s type and lies in its range (a list: its item count; items apart)."""
    lo, hi = (b(meta) if callable(b) else b for b in (f.lo, f.hi))
    if f.kind == BOOLEAN:
        return isinstance(v, bool)
    if isinstance(v, bool):
        return False
    if f.kind == STRING:
        return isinstance(v, str) and (not f.one_of or v in f.one_of)
    if f.kind == OBJECT:
        return isinstance(v, dict)
    if f.kind == LIST:
        return isinstance(v, list) and (lo is None or len(v) >= lo) and (hi is None or len(v) <= hi)
    number = isinstance(v, int) or (f.kind == NUMBER and isinstance(v, float) and math.isfinite(v))
    return (number and (lo is None or v >= lo) and (hi is None or v <= hi)
            and (not f.one_of or v in f.one_of))


def _describe(meta: dict, f: Field) -> str:
    """What ``f`` may hold, in words (for the refusals)."""
    lo, hi = (b(meta) if callable(b) else b for b in (f.lo, f.hi))
    if f.kind == LIST:
        count = f"{lo}" if lo == hi else f"{lo} to {hi}" if hi is not None else f"at least {lo}"
        return f"a list of {count} items, each {_describe(meta, f.item)}"
    if f.kind == OBJECT:
        return "an object with " + ", ".join(x.key for x in f.fields)
    if f.one_of:
        return "one of " + ", ".join(map(str, f.one_of))
    if lo == POSITIVE:
        return f"{f.kind} above 0"
    if lo is not None and hi is not None:
        return f"{f.kind} in [{_number(lo)}, {_number(hi)}]"
    if lo is not None:
        return f"{f.kind} of at least {_number(lo)}"
    return f.kind


def _number(x: float) -> str:
    return str(x) if isinstance(x, int) else f"{x:g}"


def _shown(v: Any) -> str:
    text = repr(v)
    return text if len(text) <= 80 else text[:77] + "..."


def load_json(raw: bytes):
    """JSON from UTF-8 bytes with only finite numbers in float64's range (``ValueError`` otherwise), so that
    no field escapes as an ``OverflowError`` or a NaN later."""
    def number(text: str) -> float:
        v = float(text)
        if not math.isfinite(v):
            raise ValueError(f"number {text[:40]} is out of range")
        return v

    def integer(text: str) -> int:
        if len(text.lstrip("-")) > 18:
            raise ValueError(f"integer {text[:40]} is out of range")
        return int(text)

    def constant(text: str):
        raise ValueError(f"{text} is not a JSON number")

    return json.loads(raw.decode("utf-8"), parse_float=number, parse_int=integer, parse_constant=constant)
