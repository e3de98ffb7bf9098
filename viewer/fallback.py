"""The viewer without compute shaders (OpenGL 3.3, e.g. macOS): the CPU sort path.

Decode (:func:`cghair_format.decode_gaussians`), projection, colour, culling and the depth sort
run in numpy; each frame's sorted splat records are uploaded as per-instance attributes and
drawn with the same fragment shader and blending as the GPU path. Overlays need storage
buffers and are not drawn here; there are no splat budgets.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from cghair_format import Gaussians, HairAsset, decode_gaussians
from cghair_format.camera import Camera
from cghair_format.gaussians import eval_sh

from .frame import SplatRenderer, Stage, ViewSettings, run_stage
from .pipeline import Programs
from .sort import stable_order

NEAR_PLANE = 0.01
DILATION = 0.3
SIGMA_SUPPORT = 3.0
ALPHA_MIN = 1.0 / 255.0
FALLBACK_GLSL = "330 core"


def _quat_matrices(q: np.ndarray) -> np.ndarray:
    q = q / np.maximum(np.linalg.norm(q, axis=1, keepdims=True), 1e-12)
    w, x, y, z = q.T
    return np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
                     2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
                     2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1).reshape(-1, 3, 3)


def group_colors(groups: np.ndarray) -> np.ndarray:
    """The shaders' colour of each card group (a multiplicative hash spread over RGB)."""
    h = (groups.astype(np.uint64) * 2654435761) & 0xFFFFFFFF
    rgb = np.stack([(h >> 8) & 255, (h >> 16) & 255, (h >> 24) & 255], -1).astype(np.float64)
    return rgb / 255.0 * 0.8 + 0.2


def splat_records(g: Gaussians, camera: Camera, settings: ViewSettings,
                  groups: np.ndarray | None = None) -> np.ndarray:
    """Records ``[V, 16]`` float32 of the visible splats, front to back (contract steps 1-5)."""
    rot = np.asarray(camera.world_to_camera, np.float64)[:3, :3]
    t = g.means.astype(np.float64) @ rot.T + np.asarray(camera.world_to_camera, np.float64)[:3, 3]
    idx = np.nonzero(t[:, 2] > NEAR_PLANE)[0]
    t = t[idx]
    x, y, z = t.T
    fx, fy = float(camera.fx), float(camera.fy)
    jac = np.zeros((len(idx), 2, 3))
    jac[:, 0, 0], jac[:, 0, 2] = fx / z, -fx * x / (z * z)
    jac[:, 1, 1], jac[:, 1, 2] = fy / z, -fy * y / (z * z)
    m = _quat_matrices(g.rotations[idx].astype(np.float64)) * (g.scales[idx].astype(np.float64)
                                                               * settings.splat_scale)[:, None, :]
    a = jac @ (rot @ m)
    cov = a @ a.transpose(0, 2, 1)
    ca, cb, cc = cov[:, 0, 0] + DILATION, cov[:, 0, 1], cov[:, 1, 1] + DILATION
    det = ca * cc - cb * cb
    mid = 0.5 * (ca + cc)
    lam = mid + np.sqrt(np.maximum(mid * mid - det, 0.0))  # the reference's formula, for the radius
    radius = np.ceil(SIGMA_SUPPORT * np.sqrt(lam))
    m2 = np.stack([fx * x / z + camera.cx, fy * y / z + camera.cy], -1)
    opacity = g.opacities[idx].astype(np.float64)
    onscreen = ((m2[:, 0] + radius >= 0) & (m2[:, 0] - radius <= camera.width)
                & (m2[:, 1] + radius >= 0) & (m2[:, 1] - radius <= camera.height))
    keep = onscreen & (det > 0) & (opacity >= ALPHA_MIN)
    order = stable_order(z[keep].astype(np.float32).view(np.uint32))
    sel = np.nonzero(keep)[0][order]
    idx, z, m2, radius, opacity = idx[sel], z[sel], m2[sel], radius[sel], opacity[sel]
    ca, cb, cc, det, mid = ca[sel], cb[sel], cc[sel], det[sel], mid[sel]
    con_a, con_b, con_c = cc / det, -cb / det, ca / det
    # primitive half-axes, as preprocess.comp.glsl: the alpha >= 1/255 ellipse or the disc
    # around the support square, whichever is smaller
    q = 2.0 * np.log(opacity / ALPHA_MIN) * 1.0001 + 1e-4
    lam1 = mid + np.sqrt(0.25 * (ca - cc) ** 2 + cb * cb)
    lam2 = det / lam1
    v1 = np.where((ca >= cc)[:, None], np.stack([lam1 - cc, cb], -1), np.stack([cb, lam1 - ca], -1))
    n1 = np.linalg.norm(v1, axis=1, keepdims=True)
    v1 = np.where(n1 > 0, v1 / np.maximum(n1, 1e-300), [[1.0, 0.0]])
    e1, e2 = np.sqrt(q * lam1) * 1.0001 + 0.01, np.sqrt(q * lam2) * 1.0001 + 0.01
    disc = np.sqrt(2.0) * (radius + 0.5)
    ellipse = e1 * e2 < disc * disc
    ax = np.where(ellipse[:, None], np.concatenate([v1 * e1[:, None], np.stack([-v1[:, 1], v1[:, 0]], -1)
                                                    * e2[:, None]], 1),
                  np.stack([disc, 0 * disc, 0 * disc, disc], -1))
    if settings.color_by_group and groups is not None:
        rgb = group_colors(groups[idx])
    else:
        deg = g.sh_degree if settings.sh_degree is None else max(0, min(int(settings.sh_degree), g.sh_degree))
        dirs = g.means[idx].astype(np.float64) - camera.center
        dirs /= np.maximum(np.linalg.norm(dirs, axis=1, keepdims=True), 1e-12)
        rgb = eval_sh(g.sh[idx, :(deg + 1) ** 2].astype(np.float64), dirs)
    rec = np.zeros((len(idx), 16), np.float32)
    rec[:, 0:2], rec[:, 2], rec[:, 3] = m2, 1.0 / radius, opacity
    rec[:, 4:8], rec[:, 8], rec[:, 9], rec[:, 10], rec[:, 12:15] = ax, con_a, con_b, con_c, rgb
    return rec


class FallbackRenderer(SplatRenderer):
    """A :class:`viewer.frame.SplatRenderer` on OpenGL 3.3: numpy projection and sort, instanced draw."""

    sort_mode = "cpu"

    def __init__(self, ctx: Any, gaussians: Gaussians, groups: np.ndarray | None = None):
        super().__init__(ctx, Programs(ctx, version=FALLBACK_GLSL))
        self.gaussians = gaussians
        self.groups = groups  # card group of each Gaussian, for colour by group
        self.visible = 0
        self._bounds = (gaussians.means.min(axis=0), gaussians.means.max(axis=0))
        self._buffer = None
        self._vao_records = None

    @classmethod
    def from_asset(cls, ctx: Any, asset: HairAsset) -> FallbackRenderer:
        groups = np.repeat(asset.cards.group[asset.strand_card], asset.counts - 1)  # per real segment
        return cls(ctx, decode_gaussians(asset), groups)

    @classmethod
    def from_gaussians(cls, ctx: Any, gaussians: Gaussians) -> FallbackRenderer:
        return cls(ctx, gaussians)

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        return self._bounds

    @property
    def count(self) -> int:
        return self.gaussians.count

    @property
    def drawn(self) -> int:
        return self.visible

    def describe(self) -> str:
        return f"raster (OpenGL 3.3) | {self.gaussians.count:,} Gaussians"

    def frame(self, camera: Camera, settings: ViewSettings | None = None, stage: Stage = run_stage) -> None:
        """Project, colour, cull and sort in numpy (the records come out in draw order), upload the
        records as per-instance attributes and draw them."""
        s = settings or ViewSettings()
        records = stage("preprocess", lambda: splat_records(self.gaussians, camera, s, self.groups))
        self.visible = len(records)
        stage("gather", lambda: self._upload(records))
        stage("draw", lambda: self._draw(camera.width, camera.height))

    def overlays(self, camera: Camera, settings: ViewSettings, flip_y: bool) -> None:
        """None: the overlays read strand points from storage buffers, which OpenGL 3.3 lacks."""

    def _upload(self, records: np.ndarray) -> None:
        data = records.tobytes() or bytes(64)
        if self._buffer is None or self._buffer.size < len(data):
            if self._buffer is not None:
                self._buffer.release()
                self._vao_records.release()
            self._buffer = self.ctx.buffer(reserve=max(len(data), 64))
            prog = self.programs.render("splat_attr", "splat")
            self._vao_records = self.ctx.vertex_array(
                prog, [(self._buffer, "4f 4f 4f 4f/i", "a_r0", "a_r1", "a_r2", "a_r3")])
        self._buffer.write(data)

    def _draw(self, width: int, height: int) -> None:
        accum_fbo = self.accum(width, height).framebuffer
        accum_fbo.use()
        accum_fbo.clear(0.0, 0.0, 0.0, 0.0)
        if self.visible == 0:
            return
        prog = self.programs.render("splat_attr", "splat")
        prog["u_viewport"].value = (float(width), float(height))
        self.ctx.enable_only(self.ctx.BLEND)
        self.ctx.blend_func = self.ctx.ONE_MINUS_DST_ALPHA, self.ctx.ONE
        self._vao_records.render(mode=self.ctx.TRIANGLES, vertices=3, instances=self.visible)
        self.ctx.blend_func = self.ctx.SRC_ALPHA, self.ctx.ONE_MINUS_SRC_ALPHA

    def release(self) -> None:
        if self._buffer is not None:
            self._vao_records.release()
            self._buffer.release()
        super().release()
