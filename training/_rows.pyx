# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True, initializedcheck=False
"""Compiled kernel of :func:`training.model.segment_rows`: chosen rows of a linear layer whose
output is a strand's per-segment blocks, forward and backward, each in one parallel loop (OpenMP).

Row ``i`` is block ``block[i]`` of strand ``strand[i]``: ``out[i] = W_b h_s + bias_b`` with ``W_b``
the ``width x hidden`` slice of the layer. A hundred small matrix products (one per block) would
cost a hundred thread hand-overs each way; here each row is one short loop.
"""

from cython.parallel import prange

from libc.stdint cimport int64_t


cdef void row_forward(const float* h, const float* wt, const float* bias, int n_hidden, int width,
                      float* out) noexcept nogil:
    """out = bias + sum_k h[k] wt[k, :] (``wt`` the block's transpose, ``hidden x width``)."""
    cdef int k, o
    cdef float hk
    cdef const float* wk
    for o in range(width):
        out[o] = bias[o]
    for k in range(n_hidden):
        hk = h[k]
        wk = wt + k * width
        for o in range(width):
            out[o] += hk * wk[o]


def forward(const float[:, ::1] hidden, const float[:, :, ::1] weight_t, const float[:, ::1] bias,
            const int64_t[::1] strand, const int64_t[::1] block, const int64_t[::1] by_block, float[:, ::1] out):
    """``out[i] = hidden[strand[i]] @ weight_t[block[i]] + bias[block[i]]``; ``weight_t`` is
    ``[blocks, hidden, width]``. Rows are visited in ``by_block`` order (the rows block by block),
    so that consecutive rows share their block's weights in the cache."""
    cdef Py_ssize_t n = strand.shape[0], t, i
    cdef int n_hidden = hidden.shape[1], width = out.shape[1]
    for t in prange(n, nogil=True, schedule="static"):
        i = by_block[t]
        row_forward(&hidden[strand[i], 0], &weight_t[block[i], 0, 0], &bias[block[i], 0], n_hidden, width,
                    &out[i, 0])


cdef void row_grad_hidden(const float* g, const float* w, int n_hidden, int width, float* gh) noexcept nogil:
    """gh = sum_o g[o] w[o, :] (``w`` the block, ``width x hidden``)."""
    cdef int k, o
    cdef float go
    cdef const float* wo
    for k in range(n_hidden):
        gh[k] = 0
    for o in range(width):
        go = g[o]
        wo = w + o * n_hidden
        for k in range(n_hidden):
            gh[k] += go * wo[k]


cdef void block_grad(const float* hidden, const float* grad, const int64_t* strand, const int64_t* rows,
                     int64_t count, int n_hidden, int width, float* gw, float* gb) noexcept nogil:
    """gw += sum over the block's rows r of grad[r] (x) hidden[strand[r]], gb += grad[r]."""
    cdef int64_t j
    cdef int o, k
    cdef float go
    cdef const float* h
    cdef const float* g
    cdef float* gwo
    for j in range(count):
        g = grad + rows[j] * width
        h = hidden + strand[rows[j]] * n_hidden
        for o in range(width):
            go = g[o]
            gb[o] += go
            gwo = gw + o * n_hidden
            for k in range(n_hidden):
                gwo[k] += go * h[k]


def backward(const float[:, ::1] hidden, const float[:, :, ::1] weight, const int64_t[::1] strand,
             const int64_t[::1] block, const int64_t[::1] by_block, const int64_t[::1] block_start,
             const float[:, ::1] grad, float[:, ::1] grad_rows_hidden, float[:, :, ::1] grad_weight,
             float[:, ::1] grad_bias):
    """Gradients: per row the hidden vector's (summed per strand by the caller), and per block the
    weight's and bias's (``grad_weight`` and ``grad_bias`` zeroed by the caller). ``weight`` is
    ``[blocks, width, hidden]``; ``by_block`` lists the rows block by block, block b's from
    ``block_start[b]`` to ``block_start[b + 1]``."""
    cdef Py_ssize_t n = strand.shape[0], t, i, b
    cdef int n_hidden = hidden.shape[1], width = grad.shape[1], blocks = weight.shape[0]
    if n == 0:
        return
    for t in prange(n, nogil=True, schedule="static"):
        i = by_block[t]
        row_grad_hidden(&grad[i, 0], &weight[block[i], 0, 0], n_hidden, width, &grad_rows_hidden[i, 0])
    for b in prange(blocks, nogil=True, schedule="dynamic"):
        block_grad(&hidden[0, 0], &grad[0, 0], &strand[0], &by_block[0] + block_start[b],
                   block_start[b + 1] - block_start[b], n_hidden, width, &grad_weight[b, 0, 0], &grad_bias[b, 0])
