"""Geometry training that moves each strand by a smooth correction.

Adam moves every strand point on its own, and the images' gradients differ from point to point, so the
moved strands come out rough; the strand coder predicts each point from its neighbours (spec 4.3) and
pays for that roughness in every point. With ``TrainConfig.geometry_controls`` = N, after each optimiser
step a strand's change since the start of the run, in card coordinates (u, v, delta), is replaced by its
least-squares fit by a clamped cubic B-spline of N coefficients over the strand's points
(:func:`cghair_format.cards.guide.bspline_basis`): the strand can shift, tilt and bend as a whole, as a
misplaced strand needs, but not zigzag. Within a knot span a cubic is exactly what the coder's 4-tap
interpolation predicts, so a smooth correction adds next to nothing to the bytes of the strands it moves.
The children that follow their guides (:mod:`training.children`) are left to their own projection.
"""

from __future__ import annotations

import numpy as np
import torch

from cghair_format.asset import HairAsset
from cghair_format.cards.guide import bspline_basis


class SmoothMoves:
    """The strands whose moves are kept smooth, by point count, and each count's projection."""

    def __init__(self, base: HairAsset, controls: int, skip: torch.Tensor | None = None,
                 device: torch.device | str = "cpu"):
        counts = np.asarray(base.counts)
        moving = np.ones(base.n_strands, bool)
        if skip is not None:
            moving[skip.cpu().numpy()] = False
        start = base.uvd.astype(np.float32)  # [S, P, 3] the run's start
        # per point count: the rows (None: every strand), the count, the orthonormal basis q [count, k] (the
        # fit is q q^T) and those rows' starting coordinates [n, count, 3]
        self.groups: list[tuple[torch.Tensor | None, int, torch.Tensor, torch.Tensor]] = []
        for count in np.unique(counts[moving]):
            count = int(count)
            rows = np.flatnonzero(moving & (counts == count))
            q, _ = np.linalg.qr(bspline_basis(np.linspace(0.0, 1.0, count), min(controls, count)))
            index = None if len(rows) == base.n_strands else torch.as_tensor(rows, device=device)
            self.groups.append((index, count, torch.as_tensor(q.astype(np.float32), device=device),
                                torch.as_tensor(start[rows, :count], device=device)))

    @torch.no_grad()
    def project(self, uv: torch.Tensor, delta: torch.Tensor) -> None:
        """Set each moving strand's coordinates ``uv [S, P, 2]``, ``delta [S, P]`` to its start plus the
        smooth fit of its change since then."""
        for index, count, q, start in self.groups:
            rows = slice(None) if index is None else index
            change = torch.cat([uv[rows, :count], delta[rows, :count, None]], -1) - start  # [n, count, 3]
            across = change.transpose(1, 2).reshape(-1, count)  # one row per strand and coordinate
            smooth = start + ((across @ q) @ q.T).reshape(-1, 3, count).transpose(1, 2)
            uv[rows, :count] = smooth[..., :2]
            delta[rows, :count] = smooth[..., 2]
