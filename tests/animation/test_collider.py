"""A head mesh as the collider: its distance field against the analytic one, the mesh files read and
refused, and strands that drape over the mesh instead of falling into it."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from head_helpers import sphere_mesh, write_obj

from cghair_format.animation import Scene, SolverSettings, mesh_field, simulate
from cghair_format.animation.collider import collider_field, depth_inside, mesh_in_asset
from cghair_format.animation.tracks import HeadTrack
from cghair_format.errors import CghError
from cghair_format.examples import example_asset
from cghair_format.exchange import meshes
from cghair_format.exchange.meshes import TriangleMesh, load_mesh

RINGS = 24
CHORD = 1 - np.cos(np.pi / RINGS)  # how far the facets lie inside the unit sphere, at most


def _nodes(field) -> np.ndarray:
    return field.origin + field.cell * np.stack(np.indices(field.distance.shape), -1)


def test_a_sphere_meshs_field_matches_the_analytic_distance():
    field = mesh_field(*sphere_mesh(1.0, rings=RINGS), np.full(3, -1.6), np.full(3, 1.6), 40)
    exact = np.linalg.norm(_nodes(field), axis=-1) - 1
    error = np.abs(field.distance - exact)
    near = np.abs(exact) < 2 * field.cell - CHORD  # the band: exact distances to the facets
    assert error[near].max() < CHORD + 1e-9
    # beyond the band: the distance to the nearest band node's nearest point, not the node's own (a third
    # of a cell off at most here, where it matters least: collisions happen in the band)
    assert error.max() < 0.35 * field.cell
    off_facets = np.abs(exact) > CHORD
    assert np.array_equal(field.distance[off_facets] < 0, exact[off_facets] < 0)  # inside is negative
    points = np.random.default_rng(0).uniform(-1.3, 1.3, (2000, 3))
    d, g = field.sample(points)
    r = np.linalg.norm(points, axis=-1)
    shell = np.abs(r - 1) < 0.25 * field.cell  # where collisions happen: interpolated from band nodes
    assert shell.sum() > 20
    # the facets, and trilinear interpolation of a sphere's distance (3 cell^2 / 8 over its radius)
    assert np.abs(d - (r - 1))[shell].max() < CHORD + 3 * field.cell**2 / 8
    cosine = (g * points).sum(-1) / np.linalg.norm(g, axis=-1) / r
    assert cosine[shell].min() > 0.99  # the gradient points away from the centre
    assert np.isinf(field.sample(np.array([[5.0, 0, 0]]))[0]).all()  # off the grid: nothing to hit
    near_d, near_g = field.sample(points, within=0.05)  # what lies within 0.05 is sampled as before
    assert np.array_equal(near_d[d < 0.05], d[d < 0.05]) and np.array_equal(near_g[d < 0.05], g[d < 0.05])
    assert np.isinf(near_d[d > 0.05 + 2 * np.sqrt(3) * field.cell]).all()  # surely far: one lookup


def test_an_open_scalp_cap_is_signed_by_its_pseudo_normals():
    vertices, triangles = sphere_mesh(1.0, rings=RINGS)
    cap = triangles[vertices[triangles][:, :, 2].mean(1) > 0]  # the upper half: an open scalp
    field = mesh_field(vertices, cap, np.full(3, -1.6), np.full(3, 1.6), 40)
    nodes = _nodes(field)
    exact = np.linalg.norm(nodes, axis=-1) - 1
    over = (nodes[..., 2] > 0.3) & (np.abs(exact) > CHORD) & (np.abs(exact) < 0.5)
    assert np.array_equal(field.distance[over] < 0, exact[over] < 0)
    assert np.abs(field.distance - exact)[over & (np.abs(exact) < 2 * field.cell - CHORD)].max() < CHORD + 1e-9


def test_obj_ply_and_usd_meshes_read_to_the_same_triangles(tmp_path):
    vertices, triangles = sphere_mesh(0.5, rings=8)
    write_obj(tmp_path / "head.obj", vertices, triangles)
    mesh = load_mesh(tmp_path / "head.obj")
    assert np.allclose(mesh.vertices, vertices) and np.array_equal(mesh.triangles, triangles)
    (tmp_path / "quad.ply").write_text("ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n"
                                       "property float z\nelement face 1\nproperty list uchar int vertex_indices\n"
                                       "end_header\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n")
    assert np.array_equal(load_mesh(tmp_path / "quad.ply").triangles, [[0, 1, 2], [0, 2, 3]])  # a fan
    (tmp_path / "back.obj").write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf -4 -3 -2 -1\n")
    assert np.array_equal(load_mesh(tmp_path / "back.obj").triangles, [[0, 1, 2], [0, 2, 3]])  # negatives
    pytest.importorskip("pxr", reason="needs usd-core: pip install -e '.[usd]'")
    from pxr import Gf, Usd, UsdGeom

    stage = Usd.Stage.CreateNew(str(tmp_path / "head.usda"))
    UsdGeom.SetStageMetersPerUnit(stage, 0.01)
    UsdGeom.SetStageUpAxis(stage, "Z")
    UsdGeom.Xform.Define(stage, "/body").AddTranslateOp().Set(Gf.Vec3d(0, 0, 100))
    usd = UsdGeom.Mesh.Define(stage, "/body/head")
    usd.CreatePointsAttr([Gf.Vec3f(*map(float, p)) for p in vertices * 100])
    usd.CreateFaceVertexCountsAttr([3] * len(triangles))
    usd.CreateFaceVertexIndicesAttr([int(i) for i in triangles.reshape(-1)])
    stage.GetRootLayer().Save()
    mesh = load_mesh(tmp_path / "head.usda")
    assert mesh.meters_per_unit == pytest.approx(0.01) and mesh.up_axis == "Z"
    assert np.allclose(mesh.vertices, vertices * 100 + [0, 0, 100], atol=1e-4)  # world space
    in_asset = mesh_in_asset(mesh, example_asset())  # y up, metres
    assert np.allclose(in_asset, (vertices + [0, 0, 1]) @ np.array([[1, 0, 0], [0, 0, 1], [0, -1, 0]]).T, atol=1e-6)


@pytest.mark.parametrize("text, message", [
    ("", "the mesh is empty"),
    ("v 0 0 0\nv 1 0 0\nv nan 1 0\nf 1 2 3\n", "vertex 2 holds NaN"),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 7\n", "a face refers to vertex 6"),
    ("v 0 0 0\nv 1 zero 0\n", "OBJ line 2 is malformed"),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2 3\nf 1 2 3\n", "over 2 faces"),
])
def test_hostile_meshes_are_refused_in_one_line(tmp_path, monkeypatch, text, message):
    monkeypatch.setattr(meshes, "MAX_TRIANGLES", 2)
    path = tmp_path / "bad.obj"
    path.write_text(text)
    with pytest.raises(CghError, match=message) as err:
        load_mesh(path)
    assert "\n" not in str(err.value) and "bad.obj" in str(err.value)


def test_a_mesh_far_from_the_hair_is_refused():
    asset = example_asset()
    far = TriangleMesh(*sphere_mesh(0.1, centre=(100.0, 0.0, 0.0)))
    with pytest.raises(CghError, match="nowhere near the hair .*: give it in the groom's units"):
        collider_field(asset, far)


def _draping(field) -> list[np.ndarray]:
    """Limp strands rooted on top of a 0.1 m head, sticking out sideways: gravity folds them onto the head."""
    angle = np.linspace(0, 2 * np.pi, 6, endpoint=False)
    root = np.stack([0.03 * np.cos(angle), np.full(6, np.sqrt(0.1**2 - 0.03**2)), 0.03 * np.sin(angle)], -1)
    out = np.stack([np.cos(angle), np.zeros(6), np.sin(angle)], -1)
    rest = root[:, None] + out[:, None] * np.linspace(0, 0.2, 11)[None, :, None]
    track = HeadTrack(np.eye(3)[None].repeat(8, 0), np.zeros((8, 3)), 30.0)
    scene = Scene(track, None, 1.0, np.array([0.0, 1.0, 0.0]), field=field)
    settings = SolverSettings(global_stiffness=0.0, local_stiffness=0.0, settle=0.3)
    return list(simulate(rest, scene, replace(settings, substeps=4)))


def test_strands_drape_over_the_mesh_instead_of_falling_into_it():
    field = mesh_field(*sphere_mesh(0.1, rings=RINGS), np.full(3, -0.35), np.full(3, 0.35), 40, margin=0.001)
    still = np.eye(3), np.zeros(3)
    fallen = _draping(None)  # no collider: the strands fall through the head
    assert depth_inside(field, fallen[-1][:, 1:], *still) > 0.02
    draped = _draping(field)
    assert max(depth_inside(field, x[:, 1:], *still) for x in draped) < 0.1 * CHORD + 2e-3
    assert (draped[-1][:, -1, 1] < 0.05).all()  # yet they fell: the tips hang down the sides
