"""Fixtures of the card-builder tests (helpers live in cards_helpers.py, a unique module name)."""

from __future__ import annotations

import pytest

pytest.importorskip("sklearn", reason="the card builder needs scikit-learn (pip install 'cghair[cards]')")
pytest.importorskip("scipy", reason="the card builder needs scipy (pip install 'cghair[cards]')")


@pytest.fixture(scope="session")
def wavy_build():
    """A small build of procedural wavy hair: 300 strands x 40 points on 30 cards of 12 segments."""
    from cards_helpers import synth

    from cghair_format.cards import build_cards

    return build_cards(synth("wavy"), n_cards=30, n_groups=6, segments=12, points=40, progress=False)
