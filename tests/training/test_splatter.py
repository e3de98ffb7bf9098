"""The reference splatter against a brute-force dense renderer, and its gradients."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from cghair_format.camera import Camera
from training import splatter

# real SH constants of degrees 0..3 in closed form (the 3DGS basis and signs), written out here so that the
# oracle shares no code with the splatter's SH (cghair_format.gaussians.sh_polynomial)
SH0 = 1 / (2 * math.sqrt(math.pi))
SH1 = math.sqrt(3 / (4 * math.pi))
SH2 = (math.sqrt(15 / math.pi) / 2, -math.sqrt(15 / math.pi) / 2, math.sqrt(5 / math.pi) / 4,
       -math.sqrt(15 / math.pi) / 2, math.sqrt(15 / math.pi) / 4)
SH3 = (-math.sqrt(35 / (2 * math.pi)) / 4, math.sqrt(105 / math.pi) / 2, -math.sqrt(21 / (2 * math.pi)) / 4,
       math.sqrt(7 / math.pi) / 4, -math.sqrt(21 / (2 * math.pi)) / 4, math.sqrt(105 / math.pi) / 4,
       -math.sqrt(35 / (2 * math.pi)) / 4)


def oracle_colour(coeffs, d):
    """RGB of one Gaussian's SH ``[K, 3]`` seen along the unit direction ``d``: the basis functions one by
    one, + 0.5, clamped at 0."""
    x, y, z = d
    basis = [SH0 + 0 * x]
    if len(coeffs) > 1:
        basis += [-SH1 * y, SH1 * z, -SH1 * x]
    if len(coeffs) > 4:
        basis += [SH2[0] * x * y, SH2[1] * y * z, SH2[2] * (2 * z * z - x * x - y * y), SH2[3] * x * z,
                  SH2[4] * (x * x - y * y)]
    if len(coeffs) > 9:
        basis += [SH3[0] * y * (3 * x * x - y * y), SH3[1] * x * y * z, SH3[2] * y * (4 * z * z - x * x - y * y),
                  SH3[3] * z * (2 * z * z - 3 * x * x - 3 * y * y), SH3[4] * x * (4 * z * z - x * x - y * y),
                  SH3[5] * z * (x * x - y * y), SH3[6] * x * (x * x - 3 * y * y)]
    return torch.clamp_min(sum(b * c for b, c in zip(basis, coeffs, strict=True)) + 0.5, 0.0)


def _hamilton(a, b):
    """The quaternion product ``a b`` of (w, x, y, z) quaternions."""
    w1, v1, w2, v2 = a[0], a[1:], b[0], b[1:]
    return torch.cat([(w1 * w2 - v1 @ v2)[None], w1 * v2 + w2 * v1 + torch.linalg.cross(v1, v2)])


def oracle_rotation(q):
    """The rotation matrix of a (w, x, y, z) quaternion, normalised: its columns are the axes turned by the
    sandwich product ``q (0, e) q*`` (not the closed-form matrix the splatter uses)."""
    q = q / q.norm()
    conj = q * torch.tensor([1.0, -1.0, -1.0, -1.0], dtype=q.dtype)
    axes = torch.eye(3, dtype=q.dtype)
    return torch.stack([_hamilton(_hamilton(q, torch.cat([q.new_zeros(1), e])), conj)[1:] for e in axes], 1)


def dense_render(means, quats, scales, opacities, sh, camera, background=(0.0, 0.0, 0.0)):
    """Every pixel against every Gaussian, written from the contract (float64 oracle; its SH and rotations
    are its own, above)."""
    w2c = torch.as_tensor(camera.world_to_camera, dtype=torch.float64)
    rot, trans = w2c[:3, :3], w2c[:3, 3]
    t = means @ rot.T + trans
    out_rgb = torch.zeros(camera.height, camera.width, 3, dtype=torch.float64)
    out_a = torch.zeros(camera.height, camera.width, dtype=torch.float64)
    out_d = torch.zeros(camera.height, camera.width, dtype=torch.float64)
    order = [int(i) for i in torch.argsort(t[:, 2], stable=True) if t[i, 2] > splatter.NEAR_PLANE]
    cen = torch.as_tensor(camera.center, dtype=torch.float64)
    rq = [oracle_rotation(q) for q in quats]
    for j in range(camera.height):
        for i in range(camera.width):
            p = torch.tensor([i + 0.5, j + 0.5], dtype=torch.float64)
            trans_t = torch.tensor(1.0, dtype=torch.float64)
            c = torch.zeros(3, dtype=torch.float64)
            dep = torch.tensor(0.0, dtype=torch.float64)
            for g in order:
                x, y, z = t[g]
                jac = torch.stack([torch.stack([camera.fx / z, z * 0, -camera.fx * x / z**2]),
                                   torch.stack([z * 0, camera.fy / z, -camera.fy * y / z**2])])
                sig = rq[g] @ torch.diag(scales[g] ** 2) @ rq[g].T
                s2 = jac @ rot @ sig @ rot.T @ jac.T + 0.3 * torch.eye(2, dtype=torch.float64)
                m = torch.stack([camera.fx * x / z + camera.cx, camera.fy * y / z + camera.cy])
                r = math.ceil(3 * math.sqrt(float(torch.linalg.eigvalsh(s2.detach()).max())))
                if abs(float(p[0] - m[0])) > r or abs(float(p[1] - m[1])) > r:
                    continue
                dd = p - m
                a = torch.clamp_max(opacities[g] * torch.exp(-0.5 * dd @ torch.linalg.inv(s2) @ dd), 0.99)
                if float(a) < 1 / 255:
                    continue
                dirs = means[g] - cen
                col = oracle_colour(sh[g], dirs / dirs.norm())
                c = c + col * a * trans_t
                dep = dep + z * a * trans_t
                trans_t = trans_t * (1 - a)
            out_rgb[j, i] = c + trans_t * torch.as_tensor(background, dtype=torch.float64)
            out_a[j, i] = 1 - trans_t
            out_d[j, i] = dep
    return out_rgb, out_a, out_d


def random_scene(n: int, deg: int, seed: int, dtype=torch.float64):
    gen = torch.Generator().manual_seed(seed)
    means = (torch.rand(n, 3, generator=gen, dtype=dtype) - 0.5) * 1.2
    quats = torch.randn(n, 4, generator=gen, dtype=dtype)
    scales = 0.02 + 0.12 * torch.rand(n, 3, generator=gen, dtype=dtype)
    opac = 0.3 + 0.6 * torch.rand(n, generator=gen, dtype=dtype)
    sh = 0.5 * torch.randn(n, (deg + 1) ** 2, 3, generator=gen, dtype=dtype)
    return means, quats, scales, opac, sh


def small_camera(w=14, h=11, az=30.0):
    return Camera.orbit((0, 0, 0), 3.0, az, 15.0, w, h, fov_y_deg=35.0)


@pytest.mark.parametrize("deg", [0, 1, 3])
def test_matches_dense_renderer(deg):
    scene = random_scene(24, deg, seed=deg)
    cam = small_camera()
    out = splatter.render(*scene, cam, background=(0.2, 0.1, 0.3))
    rgb, a, d = dense_render(*scene, cam, background=(0.2, 0.1, 0.3))
    assert float(a.max()) > 0.5  # the scene is actually visible
    assert torch.max(torch.abs(out.rgb - rgb)) <= 1e-5
    assert torch.max(torch.abs(out.alpha - a)) <= 1e-5
    assert torch.max(torch.abs(out.depth - d)) <= 1e-5


def test_matches_dense_in_float32_with_culling():
    means, quats, scales, opac, sh = random_scene(20, 2, seed=7)
    cam = small_camera(az=-60.0)
    means = means.clone()
    means[0] = torch.as_tensor(cam.center) * 1.5  # behind the camera: culled
    args32 = [x.float() for x in (means, quats, scales, opac, sh)]
    out = splatter.render(*args32, cam)
    rgb, a, _ = dense_render(means, quats, scales, opac, sh, cam)
    assert out.rgb.dtype == torch.float32
    # float32 arithmetic: a few ulps on values of order 1
    assert float(torch.max(torch.abs(out.rgb.double() - rgb))) <= 1e-5
    assert float(torch.max(torch.abs(out.alpha.double() - a))) <= 1e-5


def test_empty_and_offscreen_scene_renders_background():
    means = torch.tensor([[0.0, 0.0, 50.0]], dtype=torch.float64)  # far outside the view
    cam = small_camera()
    one = torch.ones(1, dtype=torch.float64)
    out = splatter.render(means, torch.tensor([[1.0, 0, 0, 0]], dtype=torch.float64),
                          torch.full((1, 3), 0.01, dtype=torch.float64), 0.5 * one,
                          torch.zeros(1, 1, 3, dtype=torch.float64), cam, background=(1.0, 0.5, 0.0))
    assert torch.allclose(out.rgb, torch.tensor([1.0, 0.5, 0.0], dtype=torch.float64).expand(11, 14, 3))
    assert float(out.alpha.abs().max()) == 0.0


def test_gradcheck_float64():
    means, quats, scales, opac, sh = random_scene(5, 1, seed=3)
    cam = small_camera(w=8, h=7)
    inputs = [x.clone().requires_grad_(True) for x in (means, quats, scales, opac, sh)]

    def f(*xs):
        out = splatter.render(*xs, cam, background=(0.1, 0.2, 0.3))
        return out.rgb, out.alpha, out.depth

    # thresholds (alpha >= 1/255, the 3-sigma square, the 0.99 clamp) are discontinuities:
    # the seed keeps every pair away from them by more than eps
    assert torch.autograd.gradcheck(f, inputs, eps=1e-6, atol=1e-5, rtol=1e-4)


def test_render_gaussians_numpy_and_batch():
    from cghair_format.gaussians import Gaussians

    means, quats, scales, opac, sh = (x.float().numpy() for x in random_scene(10, 0, seed=1))
    g = Gaussians(means, quats / np.linalg.norm(quats, axis=1, keepdims=True), scales, opac, sh)
    cams = [small_camera(az=a) for a in (0.0, 90.0)]
    out = splatter.render_gaussians(g, cams[0])
    assert out["rgb"].shape == (11, 14, 3) and out["alpha"].dtype == np.float32
    batch = splatter.render_batch(*(torch.as_tensor(x) for x in (means, quats, scales, opac, sh)), cams)
    assert batch.rgb.shape == (2, 11, 14, 3)
    assert np.allclose(batch.rgb[0].numpy(), out["rgb"], atol=1e-6)


def test_bad_shapes_raise():
    means, quats, scales, opac, sh = random_scene(3, 0, seed=0)
    with pytest.raises(ValueError, match="shape mismatch"):
        splatter.render(means, quats[:2], scales, opac, sh, small_camera())
    with pytest.raises(ValueError, match="sh must be"):
        splatter.render(means, quats, scales, opac, sh[:, :, :2], small_camera())


@pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device here")
def test_cuda_matches_cpu():
    scene = [x.float() for x in random_scene(30, 2, seed=11)]
    cam = small_camera()
    cpu = splatter.render(*scene, cam)
    gpu = splatter.render(*(x.cuda() for x in scene), cam)
    assert gpu.rgb.is_cuda
    assert torch.max(torch.abs(gpu.rgb.cpu() - cpu.rgb)) <= 1e-5


@pytest.mark.parametrize("name", ["gpu9", "cuda:99"])
def test_a_device_this_torch_cannot_use_gets_a_clear_error(name):
    """Without CUDA both names fail the first check; with it, cuda:99 names a device that isn't there."""
    with pytest.raises(splatter.DeviceError, match=f"{name}'"):
        splatter.torch_device(name)
    assert splatter.torch_device("cpu") == torch.device("cpu")
