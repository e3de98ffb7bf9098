"""Which EGL device a headless context should use, and what to say when the NVIDIA one is missing.

With libglvnd, EGL lists one device per driver (EGL_EXT_device_enumeration): NVIDIA's GPUs
(``libEGL_nvidia``; device extension ``EGL_NV_device_cuda``), Mesa's GPUs (``EGL_EXT_device_drm``)
and Mesa's software renderer llvmpipe (``EGL_MESA_device_software``), in an order that depends on
the installed vendor libraries. moderngl's EGL backend opens device ``device_index`` of that list
(glcontext, EGL_EXT_platform_device; 0 by default, or ``GLCONTEXT_DEVICE_INDEX``), so the viewer
lists the devices itself and asks for an NVIDIA one first, then another GPU, then software.

A container started without the NVIDIA graphics capability (``NVIDIA_DRIVER_CAPABILITIES``
without ``graphics``) has the GPU but not ``libEGL_nvidia``: EGL then offers only llvmpipe, and
:func:`graphics_hint` says how to get the GPU.
"""

from __future__ import annotations

import ctypes
import os
from ctypes.util import find_library
from dataclasses import asdict, dataclass
from pathlib import Path

EGL_EXTENSIONS = 0x3055
EGL_VENDOR = 0x3053
EGL_DRM_DEVICE_FILE_EXT = 0x3233
EGL_RENDERER_EXT = 0x335F  # EGL_EXT_device_query_name
MAX_DEVICES = 32
PREFERENCE = ("nvidia", "gpu", "software")  # device kinds, best first
INDEX_ENV = "GLCONTEXT_DEVICE_INDEX"  # glcontext's own override of the device index
NVIDIA_PRESENT = ("/proc/driver/nvidia/version", "/dev/nvidia0")  # files the NVIDIA kernel driver provides


@dataclass(frozen=True)
class EglDevice:
    """One EGL device: its index in EGL's list and what it says about itself."""

    index: int
    extensions: str = ""
    drm_file: str | None = None  # /dev/dri/cardN (EGL_EXT_device_drm)
    vendor: str | None = None  # where the driver offers EGL_EXT_device_query_name
    renderer: str | None = None

    @property
    def kind(self) -> str:
        """``nvidia``, ``software`` or ``gpu`` (any other)."""
        names = set(self.extensions.split())
        if "EGL_NV_device_cuda" in names or "nvidia" in str(self.vendor or "").lower():
            return "nvidia"
        if "EGL_MESA_device_software" in names:
            return "software"
        return "gpu"

    def record(self) -> dict:
        return {**asdict(self), "kind": self.kind}


def device_order(devices: list[EglDevice]) -> list[int]:
    """Device indices to try, best kind first (:data:`PREFERENCE`), EGL's order within a kind."""
    return [d.index for d in sorted(devices, key=lambda d: (PREFERENCE.index(d.kind), d.index))]


def egl_devices() -> list[EglDevice]:
    """The EGL devices of this machine; empty where libEGL or device enumeration is missing."""
    try:
        lib = ctypes.CDLL(find_library("EGL") or "libEGL.so.1")
    except OSError:
        return []
    get_proc = lib.eglGetProcAddress
    get_proc.restype, get_proc.argtypes = ctypes.c_void_p, [ctypes.c_char_p]
    query_devices, query_string = get_proc(b"eglQueryDevicesEXT"), get_proc(b"eglQueryDeviceStringEXT")
    if not query_devices or not query_string:
        return []
    query_devices = ctypes.CFUNCTYPE(ctypes.c_uint, ctypes.c_int, ctypes.POINTER(ctypes.c_void_p),
                                     ctypes.POINTER(ctypes.c_int))(query_devices)
    query_string = ctypes.CFUNCTYPE(ctypes.c_char_p, ctypes.c_void_p, ctypes.c_int)(query_string)
    handles, count = (ctypes.c_void_p * MAX_DEVICES)(), ctypes.c_int(0)
    if not query_devices(MAX_DEVICES, handles, ctypes.byref(count)):
        return []

    def text(handle: int, name: int) -> str | None:
        value = query_string(handle, name)
        return value.decode("utf-8", "replace") if value else None

    devices = []
    for index in range(count.value):
        handle = handles[index]
        ext = text(handle, EGL_EXTENSIONS) or ""
        names = set(ext.split())  # query only what the device offers: anything else is an EGL error
        named = "EGL_EXT_device_query_name" in names
        devices.append(EglDevice(index, ext, text(handle, EGL_DRM_DEVICE_FILE_EXT) if "EGL_EXT_device_drm" in names
                                 else None, text(handle, EGL_VENDOR) if named else None,
                                 text(handle, EGL_RENDERER_EXT) if named else None))
    return devices


def forced_index() -> int | None:
    """The device index ``GLCONTEXT_DEVICE_INDEX`` forces on glcontext, if set."""
    value = os.environ.get(INDEX_ENV, "").strip()
    return int(value) if value.isdigit() else None


def nvidia_gpu_present() -> bool:
    """Whether the NVIDIA kernel driver is loaded here (whatever EGL offers)."""
    return any(Path(p).exists() for p in NVIDIA_PRESENT)


def graphics_hint(gl_renderer: str | None, gpu_present: bool | None = None) -> str | None:
    """One line for a machine whose NVIDIA GPU is not the one OpenGL runs on, else ``None``."""
    if "nvidia" in str(gl_renderer or "").lower() or not (nvidia_gpu_present() if gpu_present is None
                                                          else gpu_present):
        return None
    caps = os.environ.get("NVIDIA_DRIVER_CAPABILITIES")
    said = f" (NVIDIA_DRIVER_CAPABILITIES={caps})" if caps is not None else ""
    return (f"an NVIDIA GPU is present but OpenGL runs on {gl_renderer or 'another device'}: NVIDIA's EGL "
            f"library (libEGL_nvidia.so.0) is missing{said}; in a container, set "
            "NVIDIA_DRIVER_CAPABILITIES=all (or compute,graphics,utility)")
