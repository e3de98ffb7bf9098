"""Hair that moves: a strand solver for the card guides, head motion, and cards driven frame by frame.

The rest pose is the asset as stored; motion moves its cards, and every strand point and Gaussian
follows through the format's own decoding (spec 6.1, 6.2). Reading from files is in submodules that
import the exchange package: :mod:`.fit` (animated strands), :mod:`.track_file` (a head track) and
:mod:`.collider` (a head mesh).
"""

from .clip import Animation, frame_asset, frame_points
from .drive import Scene, card_frames, carried_normals, settle, simulate, simulated_animation, tracked_animation
from .sdf import DistanceField, mesh_field
from .shading import frame_gaussians, rotate_sh, segment_rotations
from .solver import Capsules, SolverSettings, StrandState, UnstableSimulation
from .tracks import MOTIONS, Head, HeadTrack, builtin_track, fit_head

__all__ = ["MOTIONS", "Animation", "Capsules", "DistanceField", "Head", "HeadTrack", "Scene", "SolverSettings",
           "StrandState", "UnstableSimulation", "builtin_track", "card_frames", "carried_normals", "fit_head",
           "frame_asset", "frame_gaussians", "frame_points", "mesh_field", "rotate_sh", "segment_rotations", "settle",
           "simulate", "simulated_animation", "tracked_animation"]
