"""The viewer package's ``cgh`` verbs, registered by the ``cgh.verbs`` entry point ``viewer``
(pyproject.toml; :mod:`cghair_format.cli.registry`). ``demo`` is here because it is the highest package
the demo needs: it trains (training) and renders a picture (viewer)."""

from cghair_format.cli.registry import Verb

VERBS: dict[str, Verb] = {
    "view": Verb("viewer.cli", "open a .cgh in an interactive window"),
    "render": Verb("viewer.cli_render", "render a .cgh to a PNG, GIF or MP4 without a display"),
    "bench-viewer": Verb("viewer.cli_bench", "measure the viewer's load and frame times"),
    "demo": Verb("viewer.cli_demo", "run the main job end to end on built-in data", output_folder=True),
}
