"""The GPU radix sort and the numpy fallback sort stably, like numpy.argsort(kind="stable")."""

from __future__ import annotations

import numpy as np
import pytest

from viewer.pipeline import Programs
from viewer.sort import BLOCK, GpuRadixSort, cpu_sort

pytestmark = pytest.mark.gl


def _run(ctx, keys, sorter=None, count=None):
    count = len(keys) if count is None else count
    kb = ctx.buffer(keys.astype(np.uint32).tobytes())
    vb = ctx.buffer(np.arange(len(keys), dtype=np.uint32).tobytes())
    try:
        if sorter is None:
            cpu_sort(kb, vb, count)
        else:
            sorter.sort(kb, vb, count)
        return np.frombuffer(kb.read(), np.uint32).copy(), np.frombuffer(vb.read(), np.uint32).copy()
    finally:
        kb.release()
        vb.release()


@pytest.mark.parametrize("n", [1, 2, 255, BLOCK - 1, BLOCK, BLOCK + 1, 3 * BLOCK + 17, 70_000])
@pytest.mark.parametrize("use_gpu", [True, False])
def test_sort_matches_stable_argsort(gl_ctx, n, use_gpu):
    rng = np.random.default_rng(n)
    keys = rng.integers(0, 2**32, n, dtype=np.uint64).astype(np.uint32)
    keys[rng.random(n) < 0.3] = 0xFFFFFFFF  # culled splats: many equal maximal keys
    keys[rng.random(n) < 0.2] = 7  # more ties: stability is visible in the values
    sorter = GpuRadixSort(gl_ctx, Programs(gl_ctx), n) if use_gpu else None
    got_k, got_v = _run(gl_ctx, keys, sorter)
    order = np.argsort(keys, kind="stable")
    np.testing.assert_array_equal(got_k, keys[order])
    np.testing.assert_array_equal(got_v, order)
    if sorter:
        sorter.release()


def test_gpu_sort_of_depth_keys(gl_ctx):
    """Float bit patterns of positive depths sort like the depths."""
    depth = np.random.default_rng(0).uniform(0.011, 50.0, 20_000).astype(np.float32)
    sorter = GpuRadixSort(gl_ctx, Programs(gl_ctx), len(depth))
    _, order = _run(gl_ctx, depth.view(np.uint32), sorter)
    np.testing.assert_array_equal(order, np.argsort(depth, kind="stable"))
    sorter.release()


def test_sort_prefix_only_and_capacity(gl_ctx):
    keys = np.arange(1000, 0, -1, dtype=np.uint32)
    sorter = GpuRadixSort(gl_ctx, Programs(gl_ctx), 1000)
    got_k, _ = _run(gl_ctx, keys, sorter, count=600)
    np.testing.assert_array_equal(got_k[:600], np.sort(keys[:600]))
    np.testing.assert_array_equal(got_k[600:], keys[600:])  # untouched beyond count
    with pytest.raises(ValueError, match="capacity"):
        sorter.sort(None, None, 1001)
    sorter.release()
