"""META's schema (cghair_format/codec/schema.py): one table that the reader checks and the writer
writes from. Every field of it, pushed out of its range or given the wrong type in a real file, is
refused by the reader naming the field, chunk META and its byte offset; the writer refuses the same."""

import json
import re

import pytest
from hostile import small_file, with_meta

import cghair_format as cgh
from cghair_format import container
from cghair_format.codec import schema
from cghair_format.errors import AssetError, InvalidContentError


def _meta(data: bytes) -> dict:
    return json.loads(container.unpack(data, set(cgh.codec.KNOWN_CHUNKS), {"META"})[2]["META"])


def _bad_values(meta: dict, f: schema.Field) -> list:
    """Values ``f`` must refuse: the wrong type, and just outside each bound (or a value not allowed)."""
    lo, hi = (b(meta) if callable(b) else b for b in (f.lo, f.hi))
    wrong_type = {schema.INTEGER: 1.5, schema.NUMBER: "1", schema.BOOLEAN: 1, schema.STRING: 1, schema.LIST: {},
                  schema.OBJECT: []}[f.kind]
    bad = [wrong_type, None]
    if f.kind == schema.LIST:
        good = meta[f.key] if f.key in meta else None
        item = good[0] if good else 1
        bad += [[item] * (lo - 1)] if lo else []
        bad += [[item] * (hi + 1)] if hi is not None else []
    elif f.one_of:
        bad.append(-1 if f.kind == schema.INTEGER else "no such value")
    elif f.kind in (schema.INTEGER, schema.NUMBER):
        def past(bound: float, sign: int) -> float:
            return bound + sign * (1 if f.kind == schema.INTEGER else max(abs(bound) * 1e-3, 1e-300))

        bad += [past(lo, -1)] if lo is not None else []
        bad += [past(hi, 1)] if hi is not None else []
    return bad


DATA = small_file()


def _cases():
    meta = _meta(DATA)
    for f in schema.FIELDS:
        if f.kind == schema.OBJECT:
            continue
        for v in _bad_values(meta, f):
            yield (f.key,), v
    for f in schema.QUANT_FIELDS:
        if f.key in meta["quant"] or f.optional:
            for v in _bad_values(meta, f):
                yield ("quant", f.key), v
    for f in schema.MLP_LAYER:
        for v in _bad_values(meta, f):
            yield ("mlp", 0, f.key), v


CASES = list(_cases())


@pytest.mark.parametrize(("path", "value"), CASES, ids=[f"{'.'.join(map(str, p))}={v!r}"[:60] for p, v in CASES])
def test_every_field_out_of_range_is_refused_by_name(path, value):
    def edit(text: str) -> str:
        meta = json.loads(text)
        node = meta
        for key in path[:-1]:
            node = node[key]
        node[path[-1]] = value
        return json.dumps(meta)

    with pytest.raises(InvalidContentError) as refused:
        cgh.decode(with_meta(DATA, edit))
    name = "".join(f"[{p}]" if isinstance(p, int) else f".{p}" for p in path)[1:]  # as in mlp[0].out
    assert refused.value.chunk == "META" and refused.value.offset is not None
    assert f"META field '{name}" in str(refused.value), str(refused.value)
    with pytest.raises(AssetError, match=f"META field '{re.escape(name)}"):  # the writer would not store it either
        schema.dump(json.loads(edit(json.dumps(_meta(DATA)))))


def test_the_schema_covers_every_field_the_writer_stores():
    for profile in ("lossless", "compact"):
        meta = _meta(small_file(profile))
        assert schema.parse(schema.dump(meta)) == meta
        quant = {f.key for f in schema.QUANT_FIELDS}
        assert set(meta) == {f.key for f in schema.FIELDS if not f.optional} and set(meta["quant"]) <= quant
    with pytest.raises(KeyError, match="not in the schema"):
        schema.dump(meta | {"colour": 1})


def test_unknown_fields_are_read_past():
    """A later minor version may add fields: a reader ignores those it does not know."""
    data = with_meta(small_file(), lambda text: json.dumps(json.loads(text) | {"colour": [1, 2]}))
    assert cgh.decode(data).n_strands == 24


def test_the_writer_refuses_what_meta_cannot_hold_before_the_long_work(monkeypatch):
    from cghair_format.codec import writer
    from cghair_format.examples import example_asset

    monkeypatch.setattr(writer, "_search_step", lambda *_: pytest.fail("the step search ran"))
    asset = example_asset(11, strands=4, points=4097, cards=2, segments=5)  # META holds up to 4096 points
    with pytest.raises(AssetError, match="META field 'points' is out of range: 4097"):
        cgh.encode(asset, "compact")


def test_an_opacity_budget_without_the_lowered_count_is_refused():
    """``quant.opacity_budget`` describes ``quant.opacity_lowered`` (spec 4.4): alone it is refused, with it read."""
    def record(**fields):
        return lambda text: json.dumps((lambda m: m | {"quant": m["quant"] | fields})(json.loads(text)))

    with pytest.raises(InvalidContentError, match="META field 'quant.opacity_budget' .* opacity_lowered, which is "
                                                  "missing"):
        cgh.decode(with_meta(DATA, record(opacity_budget=0.1)))
    info = cgh.read_info(with_meta(DATA, record(opacity_lowered=3, opacity_budget=0.1)))
    assert info["opacities"]["lowered"] == 3 and info["opacities"]["budget"] == 0.1
