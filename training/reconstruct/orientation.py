"""2D orientation maps of hair images: a bank of Gabor filters, per pixel the dominant line
orientation and a confidence, within the hair mask.

Angles are those of the line in the image, in ``[0, pi)``, measured from the +x axis (right)
towards +y (down), as :meth:`cghair_format.camera.Camera.project` lays out pixels.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

DEFAULT_ORIENTATIONS = 32
# Gabor parameters in pixels for strands one or two pixels wide: wavelength across the line,
# (4 px biases angles within 10 deg of the axes by up to 6 deg: the pixel grid aliases it),
# widths of the envelope along and across it; the kernel reaches 3 envelope widths
WAVELENGTH = 5.0
SIGMA_ALONG = 4.0
SIGMA_ACROSS = 2.0
MASK_MIN = 0.5  # alpha above which a pixel is hair
MIN_RESPONSE = 1e-3  # strongest response (image units, kernels of unit L1 norm) below which a pixel is flat


@dataclass
class OrientationMap:
    angle: np.ndarray  # [H, W] float32 radians in [0, pi)
    confidence: np.ndarray  # [H, W] float32 in [0, 1], 0 outside the mask
    mask: np.ndarray  # [H, W] bool


def gabor_bank(n: int = DEFAULT_ORIENTATIONS, wavelength: float = WAVELENGTH, sigma_along: float = SIGMA_ALONG,
               sigma_across: float = SIGMA_ACROSS) -> np.ndarray:
    """``[2n, k, k]`` zero-mean Gabor kernels for line angles ``pi * i / n``: the ``n`` even (cosine)
    ones, then the ``n`` odd (sine) ones; the energy of each pair does not depend on where the line
    falls under the kernel."""
    r = int(math.ceil(3 * max(sigma_along, sigma_across)))
    y, x = np.mgrid[-r:r + 1, -r:r + 1].astype(np.float64)
    kernels = []
    for wave in (np.cos, np.sin):
        for theta in np.pi * np.arange(n) / n:
            u = x * math.cos(theta) + y * math.sin(theta)  # along the line
            v = -x * math.sin(theta) + y * math.cos(theta)  # across it
            k = np.exp(-0.5 * (u / sigma_along) ** 2 - 0.5 * (v / sigma_across) ** 2) * wave(2 * np.pi * v / wavelength)
            k -= k.mean()  # no response to flat regions
            kernels.append(k / np.abs(k).sum())
    return np.stack(kernels).astype(np.float32)


def orientation_map(image: np.ndarray, n: int = DEFAULT_ORIENTATIONS, mask: np.ndarray | None = None) -> OrientationMap:
    """Orientation of ``image`` (``[H, W]`` grey, ``[H, W, 3]`` RGB or ``[H, W, 4]`` straight RGBA whose
    alpha is the mask): the angle of the strongest filter pair, refined between neighbouring angles by a
    parabola, and the confidence ``1 - mean / max`` of the responses (0 when all agree, near 1 for one
    clear line)."""
    import torch

    img = np.asarray(image, np.float32)
    if img.ndim == 3 and img.shape[2] == 4:
        if mask is None:
            mask = img[..., 3] > MASK_MIN
        img = img[..., :3] * img[..., 3:4]
    if img.ndim == 3:
        img = img @ np.float32([0.299, 0.587, 0.114])
    if mask is None:
        mask = np.ones(img.shape, bool)
    bank = torch.from_numpy(gabor_bank(n))
    pad = bank.shape[-1] // 2
    with torch.no_grad():
        x = torch.nn.functional.pad(torch.from_numpy(img)[None, None], (pad,) * 4, mode="reflect")
        pair = torch.nn.functional.conv2d(x, bank[:, None])[0]
        resp = torch.sqrt(pair[:n] ** 2 + pair[n:] ** 2).numpy()  # [n, H, W] energy
    best = resp.argmax(0)
    f0 = np.take_along_axis(resp, best[None], 0)[0]
    fm = np.take_along_axis(resp, ((best - 1) % n)[None], 0)[0]
    fp = np.take_along_axis(resp, ((best + 1) % n)[None], 0)[0]
    denom = fm - 2 * f0 + fp
    shift = np.where(np.abs(denom) > 1e-12, 0.5 * (fm - fp) / np.where(denom == 0, 1, denom), 0.0)
    angle = (np.pi * (best + np.clip(shift, -0.5, 0.5)) / n) % np.pi
    conf = np.where(f0 > MIN_RESPONSE, 1.0 - resp.mean(0) / np.maximum(f0, 1e-8), 0.0)
    conf = np.where(mask, np.clip(conf, 0, 1), 0.0)
    return OrientationMap(angle.astype(np.float32), conf.astype(np.float32), np.asarray(mask, bool))


def angle_difference(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Difference of undirected line angles, in ``[0, pi/2]``."""
    d = np.abs(a - b) % np.pi
    return np.minimum(d, np.pi - d)


def orientation_rgb(m: OrientationMap) -> np.ndarray:
    """``[H, W, 3]`` uint8: hue = angle (a full hue turn over 180 degrees), brightness = confidence."""
    h = m.angle / np.pi * 6.0
    i = np.floor(h).astype(int) % 6
    f = h - np.floor(h)
    v = m.confidence
    q, t = v * (1 - f), v * f
    z = np.zeros_like(v)
    table = [(v, t, z), (q, v, z), (z, v, t), (z, q, v), (t, z, v), (v, z, q)]
    rgb = np.zeros((*v.shape, 3), np.float32)
    for k, (r, g, b) in enumerate(table):
        sel = i == k
        rgb[sel] = np.stack([r[sel], g[sel], b[sel]], -1)
    return (np.clip(rgb, 0, 1) * 255 + 0.5).astype(np.uint8)


def save_debug(m: OrientationMap, path: str | Path) -> None:
    from PIL import Image

    Image.fromarray(orientation_rgb(m), "RGB").save(path)
