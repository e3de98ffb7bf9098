"""Helpers of the training tests: a small procedural hair cap (no data files needed)."""

from __future__ import annotations

import numpy as np

from cghair_format.strands import Strands


def hair_cap(n_strands: int = 120, n_points: int = 12, seed: int = 0) -> Strands:
    """Strands rooted on the upper half of a unit sphere, falling down and outwards with a wave."""
    rng = np.random.default_rng(seed)
    theta = rng.uniform(0, 2 * np.pi, n_strands)
    phi = rng.uniform(0.0, 1.1, n_strands)  # from the top of the head
    root = np.stack([np.sin(phi) * np.cos(theta), np.cos(phi), np.sin(phi) * np.sin(theta)], -1)
    t = np.linspace(0, 1, n_points)[None, :, None]
    out = root * np.array([1.0, 0.0, 1.0])
    out /= np.maximum(np.linalg.norm(out, axis=-1, keepdims=True), 1e-6)
    wave = 0.05 * np.sin(6 * t + theta[:, None, None])
    pts = root[:, None] * (1 + 0.15 * t) + out[:, None] * (0.3 * t + wave) + np.array([0, -1.0, 0]) * 1.2 * t ** 2
    return Strands.from_array(pts.astype(np.float32))


def nerf_to_colmap(src, dst, text: bool = False, haircut: bool = False, scale: int = 1) -> None:
    """Rewrite the NeRF-synthetic dataset ``src`` as a capture in ``dst``: the same cameras as a
    COLMAP sparse model written by pycolmap (binary, or text), the same pixels as RGB images and
    greyscale hair masks (the alpha). ``haircut`` writes GaussianHaircut's ``images_2/`` and
    ``masks_2/hair/`` with cameras at ``scale`` times the images' size, else ``images/`` and ``masks/``."""
    from pathlib import Path

    import pycolmap
    from PIL import Image

    from training.datasets.read import read_dataset

    src, dst = Path(src), Path(dst)
    ds = read_dataset(src)
    views = sorted(ds.train + ds.val + ds.test, key=lambda v: v.name)
    images, masks = (dst / "images_2", dst / "masks_2" / "hair") if haircut else (dst / "images", dst / "masks")
    images.mkdir(parents=True)
    masks.mkdir(parents=True)
    rec = pycolmap.Reconstruction()
    cam = views[0].camera
    rec.add_camera_with_trivial_rig(pycolmap.Camera(
        model="PINHOLE", width=cam.width * scale, height=cam.height * scale, camera_id=1,
        params=[cam.fx * scale, cam.fy * scale, cam.cx * scale, cam.cy * scale]))
    for k, v in enumerate(views, 1):
        c = v.camera
        assert (c.width, c.height, c.fx, c.fy, c.cx, c.cy) == (cam.width, cam.height, cam.fx, cam.fy, cam.cx, cam.cy)
        pose = pycolmap.Rigid3d(pycolmap.Rotation3d(c.world_to_camera[:3, :3]), c.world_to_camera[:3, 3])
        rec.add_image_with_trivial_frame(pycolmap.Image(name=f"{v.name}.png", camera_id=1, image_id=k), pose)
        rgba = np.rint(v.image * 255).astype(np.uint8)  # the PNG's own bytes: v.image is u8 / 255
        Image.fromarray(rgba[..., :3], "RGB").save(images / f"{v.name}.png")
        Image.fromarray(rgba[..., 3], "L").save(masks / f"{v.name}.png")
    sparse = dst / "sparse" / "0"
    sparse.mkdir(parents=True)
    rec.write_text(str(sparse)) if text else rec.write(str(sparse))
