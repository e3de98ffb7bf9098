"""From multi-view images to strands: strand metrics, 2D orientation maps, scalp, growth, refinement."""
