"""Finding a Python that has Blender as a module (bpy), to run Blender work in a subprocess.

bpy 5.0 pins numpy < 2, so the project keeps it in its own environment (``make blender`` creates
``.venv/blender``) and talks to it through a subprocess, which also keeps a Blender crash from
taking the caller down.
"""

from __future__ import annotations

import importlib.util
import os
import sys
from pathlib import Path

from ..errors import CghError

ENV_VAR = "CGH_BLENDER_PYTHON"
REPO_ROOT = Path(__file__).resolve().parents[2]


class BlenderNotFoundError(CghError):
    """No interpreter with bpy was found; the message says how to install one."""


def find_blender_python() -> str:
    """Path of a Python interpreter that can ``import bpy``.

    Looks at ``$CGH_BLENDER_PYTHON``, then ``.venv/blender/bin/python`` beside the package's
    checkout, then the running interpreter.
    """
    env = os.environ.get(ENV_VAR)
    if env:
        if not Path(env).exists():
            raise BlenderNotFoundError(f"{ENV_VAR}={env} does not exist")
        return env
    local = REPO_ROOT / ".venv" / "blender" / "bin" / "python"
    if local.exists():
        return str(local)
    if importlib.util.find_spec("bpy") is not None:
        return sys.executable
    raise BlenderNotFoundError(
        "Blender as a Python module (bpy 5.0, Python 3.11) is not installed: run `make blender` "
        f"(creates .venv/blender with bpy==5.0.*) or set {ENV_VAR} to a Python that has bpy")
