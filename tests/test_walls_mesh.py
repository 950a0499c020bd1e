"""Triangle-mesh walls against analytic walls and against geometry.

Meshes are generated into tmp_path (numpy + meshio STL, gmsh for .msh).  Every
comparison with an analytic plane runs the same scene twice, once with the
plane and once with a triangulated copy of it, through the public Simulation.
"""
from __future__ import annotations

import math

import meshio
import numpy as np
import pytest

from pdemfem.simulation import Simulation
from pdemfem.walls.base import rotation_matrix
from pdemfem.walls.mesh import TriangleSurface, smooth_patches
from pdemfem.walls.readers import read_surface

RADIUS = 0.005
MATERIALS = {
    "glass": {"density": 2500.0, "youngs_modulus": 1.0e8, "poisson_ratio": 0.25},
    "steel": {"density": 7800.0, "youngs_modulus": 2.0e11, "poisson_ratio": 0.3},
}
# A tilted plane through the origin: exercises round-off in every component (an axis-aligned plane
# would make the face-region normal exact and the comparison trivially bit-identical).
TILT = rotation_matrix([0.3, -0.2, 0.1])
NORMAL = TILT @ np.array([0.0, 0.0, 1.0])


def grid(cells: int, half: float, diagonal_flip: bool = False):
    """A square [-half, half]^2 in z = 0 split into 2 cells^2 triangles (normals +z)."""
    x = np.linspace(-half, half, cells + 1)
    xx, yy = np.meshgrid(x, x, indexing="ij")
    points = np.column_stack([xx.ravel(), yy.ravel(), np.zeros(xx.size)])
    triangles = []
    for i in range(cells):
        for j in range(cells):
            a = i * (cells + 1) + j
            b = a + cells + 1
            if diagonal_flip and (i + j) % 2:
                triangles += [[a, b, a + 1], [b, b + 1, a + 1]]
            else:
                triangles += [[a, b, b + 1], [a, b + 1, a + 1]]
    return points, np.array(triangles)


def write_stl(path, points, triangles):
    meshio.write(str(path), meshio.Mesh(points, [("triangle", np.asarray(triangles))]), binary=True)
    return path.name


def write_mesh(path, points, triangles):
    """A gmsh .msh in double precision (STL stores float32: 0.05 m would move by ~1e-9 m, which is 1e-5 of a
    1e-4 m overlap and would hide round-off comparisons)."""
    meshio.write(str(path), meshio.Mesh(points, [("triangle", np.asarray(triangles))]), file_format="gmsh22",
                 binary=True)
    return path.name


def scene(wall, positions, velocities, angular_velocities=None, gravity=(0.0, 0.0, 0.0), dt=1.0e-6,
          friction=0.5, restitution=0.5, rolling_friction=0.0, extra_walls=()):
    insert = {"kind": "list", "positions": [list(map(float, p)) for p in positions],
              "velocities": [list(map(float, v)) for v in velocities]}
    if angular_velocities is not None:
        insert["angular_velocities"] = [list(map(float, w)) for w in angular_velocities]
    return {
        "time": {"end": 1.0, "dt": dt},
        "gravity": list(gravity),
        "materials": MATERIALS,
        "interactions": {"default": {"restitution": restitution, "friction": friction,
                                     "rolling_friction": rolling_friction}},
        "particles": [{"name": "p", "material": "glass", "radius": RADIUS, "insert": insert}],
        "walls": [wall, *extra_walls],
    }


def tilted_plane_walls(tmp_path, cells=8, half=0.05, velocity=(0.0, 0.0, 0.0)):
    points, triangles = grid(cells, half, diagonal_flip=True)
    name = write_mesh(tmp_path / "plate.msh", points @ TILT.T, triangles)
    plane = {"name": "floor", "kind": "plane", "material": "steel", "point": [0, 0, 0],
             "normal": NORMAL.tolist(), "velocity": list(velocity)}
    mesh = {"name": "floor", "kind": "mesh", "material": "steel", "file": name, "velocity": list(velocity)}
    return plane, mesh


def run_both(tmp_path, plane, mesh, steps, **kwargs):
    """Trajectories (position, velocity, angular velocity, wall force) per step for plane and mesh."""
    out = []
    for wall in (plane, mesh):
        sim = Simulation.from_dict(scene(wall, **kwargs), base_dir=tmp_path, output_dir=tmp_path / "out")
        rows = []
        for _ in range(steps):
            sim.step()
            state = sim.particle_system.state
            rows.append(np.concatenate([state.positions[0], state.velocities[0], state.angular_velocities[0],
                                        sim.wall_force("floor")]))
        out.append(np.array(rows))
    return out


def relative_error(reference, other):
    """Largest difference of each 3-vector (position, velocity, angular velocity, wall force) over all
    steps, relative to the largest magnitude that vector reaches in the reference run."""
    error = 0.0
    for block in range(0, reference.shape[1], 3):
        scale = np.max(np.linalg.norm(reference[:, block:block + 3], axis=1)) + 1e-300
        error = max(error, np.max(np.abs(other[:, block:block + 3] - reference[:, block:block + 3])) / scale)
    return error


def round_off_bound(half: float, overlap: float) -> float:
    """Relative difference allowed between a mesh wall and the analytic plane it triangulates.

    Only round-off differs: the mesh's plane distance (x - a) . n uses a vertex a and a normal from a cross
    product instead of the plane's point and normal, so the overlap differs by a few ulp of the coordinates
    (<= 2 eps |x|, |x| <= the plate's half size) and the Hertz force, ~ overlap^1.5, by 1.5 times that relative
    to the peak overlap; the contact is restoring, so the difference does not grow over the run.  A real edge
    effect (a bump at an edge or vertex) would change the rebound or the normal force at the per-cent level."""
    return 1.5 * 2.0 * np.finfo(float).eps * half / overlap


def test_bounce_on_triangulated_plane_equals_analytic_plane(tmp_path):
    plane, mesh = tilted_plane_walls(tmp_path)
    # Oblique impact with spin, aimed between grid vertices and edges; the contact lasts ~150 steps.
    start = TILT @ np.array([0.0123, 0.0071, RADIUS * 1.02])
    velocity = TILT @ np.array([0.3, 0.2, -1.0])
    reference, meshed = run_both(tmp_path, plane, mesh, 800, positions=[start], velocities=[velocity],
                                 angular_velocities=[[5.0, -3.0, 2.0]])
    assert np.max(np.abs(reference[:, 11])) > 0  # there was a contact
    rebound = reference[-1, 3:6] @ NORMAL
    assert rebound > 0.3  # and it bounced back
    # Peak overlap ~1e-4 m: bound 3.3e-13, measured 3.8e-14.
    error = relative_error(reference, meshed)
    assert error < round_off_bound(0.05, 1.0e-4), error


def test_rolling_across_edges_and_vertices_equals_analytic_plane(tmp_path):
    plane, mesh = tilted_plane_walls(tmp_path, cells=16, half=0.05)
    # Rolling with friction along the grid diagonal: the contact point crosses triangle edges and
    # passes exactly over shared vertices (the path x = y runs through the grid's vertices).
    rest = RADIUS - 2.0e-6
    start = TILT @ np.array([-0.02, -0.02, rest])
    velocity = TILT @ np.array([0.5, 0.5, 0.0])
    spin = TILT @ np.array([-0.5 / RADIUS, 0.5 / RADIUS, 0.0])
    gravity = -9.81 * NORMAL
    reference, meshed = run_both(tmp_path, plane, mesh, 4000, positions=[start], velocities=[velocity],
                                 angular_velocities=[spin], gravity=gravity, dt=2.0e-5)
    travelled = np.linalg.norm(reference[-1, :3] - reference[0, :3])
    assert travelled > 0.02  # over several cells (cell size 6.25 mm): many edges and vertices crossed
    assert np.all(reference[:, 9:12] @ NORMAL < 0)  # in contact throughout
    # A bump at an edge would show as a jump in the normal force.  Overlap 2e-6 m: bound 1.7e-11, measured
    # 3.9e-12 (over 4000 steps).
    error = relative_error(reference, meshed)
    assert error < round_off_bound(0.05, 2.0e-6), error


def test_moving_mesh_drags_like_moving_plane(tmp_path):
    plane, mesh = tilted_plane_walls(tmp_path, cells=8, half=0.2, velocity=(0.05, 0.0, 0.0))
    # A resting particle on a floor sliding under it: friction drags it (relative velocity uses the
    # surface velocity at the contact point).
    start = TILT @ np.array([0.0, 0.0, RADIUS - 1.0e-6])
    reference, meshed = run_both(tmp_path, plane, mesh, 2000, positions=[start], velocities=[[0, 0, 0]],
                                 gravity=-9.81 * NORMAL, dt=1.0e-5)
    assert reference[-1, 3] > 0.01  # dragged along x
    # The vertices move by v t each step (their coordinates stay within the 0.2 m plate).  Overlap 1e-6 m:
    # bound 1.3e-10, measured 1.8e-12.
    error = relative_error(reference, meshed)
    assert error < round_off_bound(0.2, 1.0e-6), error


def box_surface(half=0.05, cells=2):
    """Closed cube [-half, half]^3 with outward normals, each face a cells x cells grid of triangles."""
    points, triangles = grid(cells, half)
    faces = []
    count = 0
    all_points = []
    for rotation in (np.eye(3), rotation_matrix([math.pi, 0, 0]), rotation_matrix([math.pi / 2, 0, 0]),
                     rotation_matrix([-math.pi / 2, 0, 0]), rotation_matrix([0, math.pi / 2, 0]),
                     rotation_matrix([0, -math.pi / 2, 0])):
        face = (points + [0, 0, half]) @ rotation.T
        all_points.append(face)
        faces.append(triangles + count)
        count += len(face)
    from pdemfem.walls.readers import clean_surface
    return clean_surface(np.vstack(all_points), np.vstack(faces))


def one_step_contacts(tmp_path, wall, position, extra_walls=()):
    sim = Simulation.from_dict(scene(wall, positions=[position], velocities=[[0, 0, 0]], extra_walls=extra_walls),
                               base_dir=tmp_path, output_dir=tmp_path / "out")
    return sim, sim.particle_system.state.forces[0].copy()


def test_concave_corner_gives_one_contact_per_face(tmp_path):
    vertices, triangles = box_surface(half=0.05)
    name = write_mesh(tmp_path / "box.msh", vertices, triangles)
    box = {"name": "box", "kind": "mesh", "material": "steel", "file": name}
    # Inside the box, pressed into the floor (z = -0.05) and the wall x = +0.05 near their edge.
    position = [0.05 - RADIUS + 1e-4, 0.013, -0.05 + RADIUS - 2e-4]
    sim, force = one_step_contacts(tmp_path, box, position)
    assert sim.contact_count() == 2
    floor = {"name": "floor", "kind": "plane", "material": "steel", "point": [0, 0, -0.05], "normal": [0, 0, 1]}
    side = {"name": "side", "kind": "plane", "material": "steel", "point": [0.05, 0, 0], "normal": [-1, 0, 0]}
    planes, reference = one_step_contacts(tmp_path, floor, position, extra_walls=[side])
    assert planes.contact_count() == 2
    # Same two contacts as two analytic planes, to round-off (forces ~1e-1 N, round-off ~1e-17 N).
    np.testing.assert_allclose(force, reference, rtol=1e-12, atol=1e-14)


@pytest.mark.parametrize("where, expected_normal", [
    # Over the convex edge between the top (z = h) and the side x = h, in the edge's Voronoi region.
    ("edge", np.array([1.0, 0.0, 1.0]) / math.sqrt(2.0)),
    # Over the top face close to that edge: overlaps the side's edge too, but only the face counts.
    ("face_near_edge", np.array([0.0, 0.0, 1.0])),
    # Over the convex corner (three faces meet), in the vertex's Voronoi region.
    ("vertex", np.array([1.0, 1.0, 1.0]) / math.sqrt(3.0)),
])
def test_convex_edge_and_vertex_give_one_contact(tmp_path, where, expected_normal):
    half = 0.05
    vertices, triangles = box_surface(half=half)
    name = write_mesh(tmp_path / "box.msh", vertices, triangles)
    box = {"name": "box", "kind": "mesh", "material": "steel", "file": name}
    depth = 2.0e-4
    if where == "face_near_edge":
        position = [half - 0.3 * RADIUS, 0.011, half + RADIUS - depth]
        overlap = depth
    else:
        corner = np.array([half, 0.011 if where == "edge" else half, half])
        position = corner + (RADIUS - depth) * expected_normal
        overlap = depth
    sim, force = one_step_contacts(tmp_path, box, list(position))
    assert sim.contact_count() == 1
    # Hertz with R* = r, m* = m at rest: F = 4/3 E* sqrt(r) delta^1.5 along the normal.
    e_star = 1.0 / ((1 - 0.25**2) / 1.0e8 + (1 - 0.3**2) / 2.0e11)
    magnitude = 4.0 / 3.0 * e_star * math.sqrt(RADIUS) * overlap**1.5
    # rtol 1e-9: the overlap is r - |x - q| computed from coordinates of size 0.05 m (round-off ~1e-17 m
    # on 2e-4 m), giving ~1e-13 relative; 1e-9 leaves room without hiding a wrong contact (a second
    # contact would double the force).
    np.testing.assert_allclose(force, magnitude * expected_normal, rtol=1e-9, atol=1e-9 * magnitude)


def test_wall_torque_of_off_centre_contact(tmp_path):
    points, triangles = grid(4, 0.1)
    name = write_mesh(tmp_path / "plate.msh", points, triangles)
    plate = {"name": "plate", "kind": "mesh", "material": "steel", "file": name}
    position = np.array([0.031, -0.047, RADIUS - 1e-4])
    sim = Simulation.from_dict(scene(plate, positions=[position], velocities=[[0, 0, 0]]),
                               base_dir=tmp_path, output_dir=tmp_path / "out")
    force = sim.wall_force("plate")
    assert force[2] < 0 and abs(force[0]) == 0 and abs(force[1]) == 0
    contact_point = np.array([position[0], position[1], 0.0])
    # The torque is q x F exactly (one contact, q the contact point); about q itself it vanishes.
    np.testing.assert_allclose(sim.wall_torque("plate", about=(0, 0, 0)), np.cross(contact_point, force),
                               rtol=1e-12)
    np.testing.assert_allclose(sim.wall_torque("plate", about=contact_point), 0.0, atol=1e-12 * abs(force[2]))
    about = np.array([0.2, 0.1, -0.3])
    np.testing.assert_allclose(sim.wall_torque("plate", about=about), np.cross(contact_point - about, force),
                               rtol=1e-12)


def test_rotating_mesh_surface_velocity_drags_tangentially(tmp_path):
    points, triangles = grid(4, 0.1)
    name = write_mesh(tmp_path / "disk.msh", points, triangles)
    omega = 2.0
    turntable = {"name": "disk", "kind": "mesh", "material": "steel", "file": name,
                 "angular_velocity": [0.0, 0.0, omega], "center": [0.0, 0.0, 0.0]}
    position = [0.05, 0.0, RADIUS - 1e-5]
    sim = Simulation.from_dict(scene(turntable, positions=[position], velocities=[[0, 0, 0]],
                                     gravity=(0, 0, -9.81), dt=1e-5),
                               base_dir=tmp_path, output_dir=tmp_path / "out")
    sim.step(20)
    wall = sim.contributor_walls[0]
    # Vertices follow the exact rotation, velocities w x (x - c).
    rotation = rotation_matrix([0, 0, omega * 20 * 1e-5])
    np.testing.assert_allclose(wall.vertices, points @ rotation.T, atol=1e-15)
    np.testing.assert_allclose(wall.vertex_velocities, np.cross([0, 0, omega], wall.vertices), atol=1e-15)
    # The surface under the particle moves in +y (w x r): friction pushes the particle along +y.
    velocity = sim.particle_system.state.velocities[0]
    assert velocity[1] > 0 and abs(velocity[0]) < 0.1 * velocity[1]


def test_deformable_surface_api_spreads_forces_to_vertices(tmp_path):
    points, triangles = grid(4, 0.1)
    name = write_mesh(tmp_path / "plate.msh", points, triangles)
    plate = {"name": "plate", "kind": "mesh", "material": "steel", "file": name}
    position = [0.0213, -0.0371, RADIUS - 1e-4]
    sim = Simulation.from_dict(scene(plate, positions=[position], velocities=[[0, 0, -0.2]],
                                     angular_velocities=[[3, 1, 0]]),
                               base_dir=tmp_path, output_dir=tmp_path / "out")
    surface = sim.contributor_walls[0]
    assert isinstance(surface, TriangleSurface)
    surface.spread_to_vertices = True
    # Move the vertices from outside (as the FE coupling will): lift the plate by 50 um with a velocity.
    lift = np.array([0.0, 0.0, 5.0e-5])
    surface.set_vertices(surface.vertices + lift, np.tile([0.0, 0.0, 0.01], (len(points), 1)))
    sim.step()
    contacts = surface.contacts
    assert len(contacts.triangle) == 1
    force = sim.wall_force("plate")
    # The contact point is the weighted vertex sum; spreading by the weights keeps force and moment
    # (to round-off of a 3-term sum).
    np.testing.assert_allclose(contacts.weights.sum(axis=1), 1.0, rtol=1e-14)
    np.testing.assert_allclose(surface.vertex_forces.sum(axis=0), force, rtol=1e-13, atol=1e-15)
    moment = np.cross(surface.vertices, surface.vertex_forces).sum(axis=0)
    np.testing.assert_allclose(moment, sim.wall_torque("plate"), rtol=1e-12, atol=1e-12 * np.abs(force).max())
    # The lifted plate is felt: overlap grew by the lift (Hertz force ~ delta^1.5).
    assert -force[2] > 1.5 * (4.0 / 3.0) * 1.0e8 * math.sqrt(RADIUS) * (1e-4) ** 1.5 * 0.9


def test_patches_of_a_cube_and_a_folded_sheet():
    vertices, triangles = box_surface(half=0.05, cells=3)
    patch = smooth_patches(vertices, triangles)
    assert patch.max() + 1 == 6  # six faces, each one coplanar-connected patch
    # A sheet folded by 20 degrees: two patches at the default angle, one at smooth_angle 25.
    points, triangles = grid(4, 0.1)
    folded = points.copy()
    right = folded[:, 0] > 0
    folded[right] = folded[right] @ rotation_matrix([0, math.radians(20), 0]).T
    assert smooth_patches(folded, triangles).max() + 1 == 2
    assert smooth_patches(folded, triangles, smooth_angle=25.0).max() + 1 == 1


def test_readers_stl_and_gmsh(tmp_path):
    vertices, triangles = box_surface(half=0.5, cells=1)
    write_stl(tmp_path / "cube.stl", vertices, triangles)
    points, tris = read_surface(tmp_path / "cube.stl", scale=0.1)
    assert len(points) == 8 and len(tris) == 12  # STL corners welded back into 8 vertices
    np.testing.assert_allclose(np.ptp(points, axis=0), 0.1, rtol=1e-6)  # float32 STL, scaled

    gmsh = pytest.importorskip("gmsh")
    gmsh.initialize()
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add("box")
        gmsh.model.occ.addBox(0, 0, 0, 1, 2, 3)
        gmsh.model.occ.synchronize()
        gmsh.option.setNumber("Mesh.MeshSizeMax", 0.5)
        gmsh.model.mesh.generate(2)
        gmsh.write(str(tmp_path / "box.msh"))
    finally:
        gmsh.finalize()
    points, tris = read_surface(tmp_path / "box.msh")
    assert len(tris) > 12
    # The surface of a closed box: every edge shared by exactly two triangles, 6 flat patches.
    edges = np.sort(np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]]), axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    assert np.all(counts == 2)
    assert smooth_patches(points, tris).max() + 1 == 6


def test_scene_keys_and_tunnelling_warning(tmp_path):
    from pdemfem.errors import SceneError
    from pdemfem.scene import derived
    from pdemfem.scene.loader import load_scene

    points, triangles = grid(2, 0.1)
    name = write_mesh(tmp_path / "plate.msh", points, triangles)
    plate = {"name": "plate", "kind": "mesh", "material": "steel", "file": name}
    fast = scene(plate, positions=[[0, 0, 0.05]], velocities=[[0, 0, -40.0]], dt=2.0e-5)
    loaded, _ = load_scene(fast, base_dir=tmp_path)
    # 40 m/s x 2e-5 s = 0.8 mm = 0.16 radius per step: over the general 0.1 limit, under the mesh's 0.5.
    assert not any("tunnel" in warning for warning in derived.warnings(loaded))
    fast["particles"][0]["insert"]["velocities"] = [[0, 0, -150.0]]  # 3 mm per step = 0.6 radius
    loaded, _ = load_scene(fast, base_dir=tmp_path)
    assert any("mesh wall 'plate'" in warning and "tunnel" in warning for warning in derived.warnings(loaded))
    # Keys of another kind are errors naming the kind's keys; a cylinder needs radius and axis.
    with pytest.raises(SceneError, match="kind mesh does not use normal"):
        load_scene(scene(dict(plate, normal=[0, 0, 1]), positions=[[0, 0, 0.05]], velocities=[[0, 0, 0]]),
                   base_dir=tmp_path)
    with pytest.raises(SceneError, match="kind cylinder needs radius"):
        load_scene(scene({"name": "c", "kind": "cylinder", "material": "steel", "axis": {"direction": [0, 0, 1]}},
                         positions=[[0, 0, 0.05]], velocities=[[0, 0, 0]]), base_dir=tmp_path)
