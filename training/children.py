"""Interpolated strands that follow their guides while the geometry trains.

A groom's children are blends of guide strands (Houdini, XGen, Blender), and densified hair is made the
same way; the writer stores such a strand as its parents and weights, a few bytes instead of its points
(spec 4.5, :mod:`cghair_format.children`). Geometry training moves every point on its own, so after it no
strand is a blend any more and each is coded in full. Here the strands the writer would store as children
(:func:`cghair_format.children.find_children` on the untrained points, at the profile's tolerance) keep
no gradient of their own, and every :data:`PROJECT_EVERY` iterations, and at the end, their card
coordinates are set to those of the blend of their parents' current points: they move as their guides
move, as a DCC's children do, and the written file keeps them as children.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import torch

from cghair_format.asset import Cards, HairAsset
from cghair_format.cards.inverse import points_on_cards
from cghair_format.children import blend, find_children
from cghair_format.codec.writer import MIN_CHILD_SHARE
from cghair_format.geometry import CardMap, bounding_diagonal, strand_points
from cghair_format.profiles import get_profile

PROJECT_EVERY = 50  # iterations between two projections (1.4-1.8 s at the paper's scale at load 6, against about
# 60 s for the 50 iterations); Adam moves a guide about its learning rate an iteration, so a child lags its blend
# by at most 50 such steps
REACH = 1e-3  # x the profile's position tolerance: where Newton steps leave a child point farther than this
# from its blend, the point is solved exactly (cghair_format.cards.inverse.points_on_cards)


class FollowingChildren(NamedTuple):
    """The children of a card-built asset and how to put them back on their parents' blend."""

    child: torch.Tensor  # [C] int64 strand indices
    parents: np.ndarray  # [C, 3] int64 strand indices (guides)
    weights: np.ndarray  # [C, 3] int64, summing to cghair_format.children.WEIGHT_ONE
    respaced: np.ndarray  # [C] bool: the blend resampled at even arc length
    cards: Cards  # the (frozen) cards ...
    cmap: CardMap  # ... and their map, to carry a blend back to card coordinates
    all_cards: np.ndarray  # [S] every strand's card
    reach: float  # REACH x the profile's position tolerance, in scene units

    def hold(self, uv: torch.Tensor, delta: torch.Tensor) -> None:
        """Clear the children's rows of the coordinates' gradients (before the optimiser's step), so that
        only the projection moves them."""
        for p in (uv, delta):
            if p.grad is not None:
                p.grad.index_fill_(0, self.child.to(p.grad.device), 0.0)

    @torch.no_grad()
    def project(self, uv: torch.Tensor, delta: torch.Tensor) -> float:
        """Set the children's coordinates ``uv [S, P, 2]``, ``delta [S, P]`` to those of the blend of their
        parents' points (as the writer gets them: float32, :meth:`~cghair_format.geometry.CardMap.strand_points`);
        returns the largest distance left between a child point and the blend
        (:func:`~cghair_format.cards.inverse.points_on_cards`, from their coordinates before)."""
        uvd = torch.cat([uv, delta[..., None]], -1).cpu().numpy()
        world = self.cmap.strand_points(self.all_cards, uvd)
        target = blend(world, self.parents, self.weights, self.respaced)
        child = self.child.numpy()
        moved, miss = points_on_cards(self.cards, self.cmap, self.all_cards[child], uvd[child], target, self.reach)
        moved = torch.as_tensor(moved, dtype=uv.dtype, device=uv.device)
        index = self.child.to(uv.device)
        uv[index] = moved[..., :2]
        delta[index] = moved[..., 2]
        return miss


def following_children(base: HairAsset, profile: str) -> FollowingChildren | None:
    """The children of ``base`` that the writer of ``profile`` would find, where there are as many as it
    stores (None: too few, a lossless profile, which keeps every strand's points, or strands of their own
    point counts, which it never stores as children)."""
    prof = get_profile(profile)
    if prof.lossless or base.variable:
        return None
    points = strand_points(base.cards, base.strand_card, base.uvd).astype(np.float64)
    tol = prof.position_tolerance * bounding_diagonal(points)
    kids = find_children(points, tol)
    child = np.flatnonzero(kids.child)
    if len(child) < MIN_CHILD_SHARE * base.n_strands:
        return None
    return FollowingChildren(torch.as_tensor(child), kids.parents[child], kids.weights[child], kids.respaced[child],
                             base.cards, CardMap(base.cards), base.strand_card, REACH * tol)
