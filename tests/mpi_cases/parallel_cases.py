"""MPI cases of the spatial decomposition (tests/test_parallel_decomposition.py).

usage: parallel_cases.py OUTDIR SCENARIO[,SCENARIO...]

Each scenario builds a small scene, runs it on the communicator and writes (rank 0)
OUTDIR/<scenario>_<ranks>.npz.  Several scenarios share one mpiexec launch, because
starting the interpreters and loading the numba cache costs more than the stepping.

  gas, gas_ulp          dense granular gas in a closed box (walls), 200 steps; "_ulp" (serial
                        reference) shifts particle 0 by one unit in the last place first
  pgas, pgas_ulp        the same gas, periodic in x and y (floor and lid only)
  shear                 plug + shear flow along a periodic x channel: every particle crosses
                        rank boundaries many times; ids and count checked every step
  slide, slide_drop,    two spheres sliding in a wall corner across an RCB cut (pair and wall
                        springs in the slip regime); "_drop" discards the contact records that
  slide_ulp             migrate (a negative control: what losing the history looks like);
                        "_ulp": particle 0 shifted by one ulp (serial reference)
  pile                  particles thrown into one corner: the decomposition must rebalance
  lost                  particles leave a bounded domain (and one goes NaN): removed and counted;
                        runs Simulation.run so history.csv is written
"""
from __future__ import annotations

import logging
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
import pdemfem  # noqa: F401,E402  (environment first)
from mpi4py import MPI  # noqa: E402

from pdemfem import Simulation  # noqa: E402

GLASS = {"density": 2500.0, "youngs_modulus": 1.0e7, "poisson_ratio": 0.3}
SOFT = {"density": 2500.0, "youngs_modulus": 1.0e6, "poisson_ratio": 0.3}
RADIUS = 1.0e-3


def rayleigh_step(material: dict, radius: float) -> float:
    """0.2 Rayleigh times of the sphere, explicit: these cases test decomposition and agreement across
    rank counts over fixed step counts, not the restitution, so they keep the step dt auto had before
    it resolved contacts (docs/stability.md)."""
    shear = material["youngs_modulus"] / (2.0 * (1.0 + material["poisson_ratio"]))
    return 0.2 * np.pi * radius * np.sqrt(material["density"] / shear) / (0.1631 * material["poisson_ratio"] + 0.8766)

GAS_STEPS = 200
GAS_SITES = (6, 6, 8)      # 288 particles
GAS_SPACING = 2.3e-3
SHEAR_STEPS = 400
PILE_STEPS = 800
SLIDE_STEPS = 400


# ----------------------------------------------------------------------------- scenes
def _plane(name, point, normal, material="glass", velocity=(0.0, 0.0, 0.0)):
    return {"name": name, "kind": "plane", "point": list(point), "normal": list(normal), "material": material,
            "velocity": list(velocity)}


def _lattice(sites, spacing, rng, jitter):
    grid = np.stack(np.meshgrid(*[np.arange(n) for n in sites], indexing="ij"), axis=-1).reshape(-1, 3)
    # x fastest, then y, then z
    grid = grid[np.lexsort((grid[:, 0], grid[:, 1], grid[:, 2]))]
    return (grid + 0.5) * spacing + rng.uniform(-jitter, jitter, size=grid.shape)


def gas_scene(periodic: bool) -> dict:
    """288 glass spheres (r = 0.9..1.1 mm) on a jittered lattice (gaps 0.1-0.5 mm) with random
    velocities (sigma 0.7 m/s per component) under gravity: collisions from the first steps,
    list rebuilds every ~15 steps, particles crossing the RCB cuts."""
    rng = np.random.default_rng(11)
    size = np.array(GAS_SITES) * GAS_SPACING
    positions = _lattice(GAS_SITES, GAS_SPACING, rng, 0.05e-3)
    count = len(positions)
    radii = rng.uniform(0.9e-3, 1.1e-3, count)
    velocities = rng.normal(0.0, 0.7, size=(count, 3))
    walls = [_plane("floor", (0, 0, 0), (0, 0, 1)), _plane("lid", (0, 0, size[2]), (0, 0, -1))]
    scene = {
        "time": {"end": 1.0, "dt": rayleigh_step(GLASS, 0.9e-3)},
        "gravity": [0.0, 0.0, -9.81],
        "materials": {"glass": dict(GLASS)},
        "interactions": {"default": {"model": "hertz_mindlin", "restitution": 0.6, "friction": 0.4}},
        "particles": [{"name": "gas", "material": "glass", "radius": {"min": 0.9e-3, "max": 1.1e-3},
                       "insert": {"kind": "list", "positions": positions.tolist(), "radii": radii.tolist(),
                                  "velocities": velocities.tolist()}}],
        "walls": walls,
    }
    if periodic:
        scene["domain"] = {"box": [[0.0, 0.0, -0.01], size.tolist()[:2] + [size[2] + 0.01]],
                           "periodic": ["x", "y"]}
    else:
        walls += [_plane("x0", (0, 0, 0), (1, 0, 0)), _plane("x1", (size[0], 0, 0), (-1, 0, 0)),
                  _plane("y0", (0, 0, 0), (0, 1, 0)), _plane("y1", (0, size[1], 0), (0, -1, 0))]
    return scene


SHEAR_SITES = (10, 4, 4)   # 160 particles in a 23 x 9.2 x 9.2 mm periodic channel


def shear_scene() -> dict:
    """Soft spheres (E = 1 MPa, dt 5.5e-5 s) in a channel periodic along x and y, between a floor
    and a lid, without gravity: v_x = 3 m/s + 1 m/s * (2 z/H - 1) + noise.  In SHEAR_STEPS steps a
    particle travels ~66 mm, three periods, so it crosses every x cut of the RCB ~3 times."""
    rng = np.random.default_rng(5)
    size = np.array(SHEAR_SITES) * GAS_SPACING
    positions = _lattice(SHEAR_SITES, GAS_SPACING, rng, 0.05e-3)
    count = len(positions)
    velocities = rng.normal(0.0, 0.2, size=(count, 3))
    velocities[:, 0] += 3.0 + 1.0 * (2.0 * positions[:, 2] / size[2] - 1.0)
    return {
        "time": {"end": 1.0, "dt": rayleigh_step(SOFT, RADIUS)},
        "gravity": [0.0, 0.0, 0.0],
        "materials": {"soft": dict(SOFT)},
        "interactions": {"default": {"model": "hertz_mindlin", "restitution": 0.8, "friction": 0.3}},
        "particles": [{"name": "flow", "material": "soft", "radius": RADIUS,
                       "insert": {"kind": "list", "positions": positions.tolist(),
                                  "velocities": velocities.tolist()}}],
        "walls": [_plane("floor", (0, 0, 0), (0, 0, 1), "soft"),
                  _plane("lid", (0, 0, size[2]), (0, 0, -1), "soft")],
        "domain": {"box": [[0.0, 0.0, -0.01], [size[0], size[1], size[2] + 0.01]], "periodic": ["x", "y"]},
        "neighbors": {"skin": 0.4e-3},
    }


# Sliding pair: A in the corner of the floor (z = 0) and the side wall (y = 0), B beside it (B's
# centre SLIDE_LEAD ahead in x), gravity (0, -g_y, -g_z) pressing B onto A and A onto the wall.
# A starts at -0.4 m/s along x, B at -0.3 m/s: every contact (A-B, A-wall, A-floor, B-floor)
# slips.  Two spectators rest in the corner far behind (in -x) and place the cuts: the first
# partition has unit costs, and with the x order (S, S, A, B) the weighted median on 2 ranks,
# and the second cut on 3 ranks, fall at A's x (the first cut on 4 ranks too).  A is on either
# side (the cut converges onto its coordinate); B starts on the right and crosses one or two
# rebuilds later, in contact and sliding, while the pair straddles the cut.
SLIDE_LEAD = 0.2e-3
SLIDE_SPECTATORS = (-20e-3, -10e-3)
SLIDE_GRAVITY = (0.0, -100.0, -30.0)
SLIDE_FRICTION = 0.3


def slide_scene() -> dict:
    r = RADIUS
    a = [0.0, r, r]
    b = [SLIDE_LEAD, r + np.sqrt((2 * r) ** 2 - SLIDE_LEAD ** 2), r]
    spectators = [[x, r, r] for x in SLIDE_SPECTATORS]
    positions = [a, b] + spectators
    velocities = [[-0.4, 0, 0], [-0.4, 0, 0]] + [[0, 0, 0]] * len(spectators)
    return {
        "time": {"end": 1.0, "dt": rayleigh_step(GLASS, r)},
        "gravity": list(SLIDE_GRAVITY),
        "materials": {"glass": dict(GLASS)},
        "interactions": {"default": {"model": "hertz_mindlin", "restitution": 0.5, "friction": SLIDE_FRICTION}},
        "particles": [{"name": "pair", "material": "glass", "radius": r,
                       "insert": {"kind": "list", "positions": positions, "velocities": velocities}}],
        "walls": [_plane("floor", (0, 0, 0), (0, 0, 1)), _plane("side", (0, 0, 0), (0, 1, 0))],
        # Keep the first partition: the pair must cross a fixed cut, not a moving one.
        "parallel": {"rebalance_threshold": 1000.0},
    }


PILE_SITES = (8, 8, 5)     # 320 particles spread over a 24 x 24 x 15 mm box


def pile_scene(threshold: float) -> dict:
    """Soft, very dissipative spheres spread over a box, thrown towards the corner (0, 0, 0) by
    gravity (-150, -150, -150) m/s^2 with walls x = 0, y = 0, z = 0: they end heaped in that corner,
    so the boxes of the first partition end up holding very different loads."""
    rng = np.random.default_rng(2)
    positions = _lattice(PILE_SITES, 3.0e-3, rng, 0.3e-3)
    return {
        "time": {"end": 1.0, "dt": rayleigh_step(SOFT, RADIUS)},
        "gravity": [-150.0, -150.0, -150.0],
        "materials": {"soft": dict(SOFT)},
        "interactions": {"default": {"model": "hertz_mindlin", "restitution": 0.2, "friction": 0.5}},
        "particles": [{"name": "heap", "material": "soft", "radius": RADIUS,
                       "insert": {"kind": "list", "positions": positions.tolist()}}],
        "walls": [_plane("floor", (0, 0, 0), (0, 0, 1), "soft"), _plane("x0", (0, 0, 0), (1, 0, 0), "soft"),
                  _plane("y0", (0, 0, 0), (0, 1, 0), "soft")],
        "parallel": {"rebalance_threshold": threshold},
    }


LOST_RESTING = 40          # on the floor, at rest
LOST_ESCAPING = 12         # moving at +1 m/s along x out of the domain
LOST_LENGTH = 20e-3


def lost_scene(output_dir: str) -> dict:
    """A bounded domain 20 mm long in x with a floor and no side walls: LOST_ESCAPING spheres
    start at x in [10, 18] mm moving +x at 1 m/s and leave through x = 20 mm within 10 ms."""
    r = RADIUS
    resting = [[2.2e-3 * (i % 4) + 1.5e-3, 2.2e-3 * (i // 4) + 1.5e-3, r] for i in range(LOST_RESTING)]
    resting = [[x, y, z] for x, y, z in resting]  # 4 x 10 sites: x <= 8.1 mm, y <= 21.3 mm
    escaping = [[10e-3 + 0.7e-3 * i, 23e-3 + 2.2e-3 * (i % 4), r + 0.5e-3] for i in range(LOST_ESCAPING)]
    positions = resting + escaping
    velocities = [[0, 0, 0]] * LOST_RESTING + [[1.0, 0, 0]] * LOST_ESCAPING
    return {
        "time": {"end": 0.015, "dt": rayleigh_step(GLASS, r)},
        "gravity": [0.0, 0.0, -9.81],
        "materials": {"glass": dict(GLASS)},
        "interactions": {"default": {"model": "hertz_mindlin", "restitution": 0.5, "friction": 0.3}},
        "particles": [{"name": "grains", "material": "glass", "radius": r,
                       "insert": {"kind": "list", "positions": positions, "velocities": velocities}}],
        "walls": [_plane("floor", (0, 0, 0), (0, 0, 1))],
        "domain": {"box": [[0.0, 0.0, -1e-3], [LOST_LENGTH, 40e-3, 10e-3]]},
        "output": {"dir": output_dir, "every": 0.001},
    }


# ----------------------------------------------------------------------------- helpers
def gathered(comm, values):
    """Rank 0: the concatenation of every rank's `values` (small arrays only: test helper)."""
    parts = comm.gather(values, root=0)
    return np.concatenate(parts) if comm.rank == 0 else None


def by_id(comm, sim, name):
    p = sim.particles
    ids = gathered(comm, p.ids)
    values = gathered(comm, getattr(p, name))
    if comm.rank != 0:
        return None
    return values[np.argsort(ids)]


def owners(comm, sim, total):
    """Rank 0: owner rank of every id (-1 when no rank owns it), plus the number of owned copies."""
    p = sim.particles
    ids = gathered(comm, p.ids)
    ranks = gathered(comm, np.full(len(p.ids), comm.rank))
    if comm.rank != 0:
        return None, None
    owner = np.full(total, -1)
    owner[ids] = ranks
    copies = np.bincount(ids, minlength=total)
    return owner, copies


def build(comm, scene, out):
    return Simulation.from_dict(scene, comm=comm, output_dir=str(Path(out) / "unused"))


# ----------------------------------------------------------------------------- scenarios
def run_gas(comm, out, periodic, perturb):
    sim = build(comm, gas_scene(periodic), out)
    total = sim.particle_count()
    state = sim.particle_system.state
    if perturb:
        row = np.flatnonzero(state.ids == 0)
        state.positions[row, 0] += np.spacing(state.positions[row, 0])
    energy_names = ("kinetic_energy", "rotational_energy", "potential_energy", "elastic_energy",
                    "dissipated_energy", "wall_work")
    contacts, energies, owner_changes = [], [], 0
    previous, _ = owners(comm, sim, total)
    for _ in range(GAS_STEPS):
        sim.step(1)
        contacts.append(sim.contact_count())
        e = sim.energies()
        energies.append([e[name] for name in energy_names])
        owner, copies = owners(comm, sim, total)
        if comm.rank == 0:
            owner_changes += int(np.count_nonzero(owner != previous))
            assert np.all(copies == 1), "a particle is owned by no rank or by two"
            previous = owner
    positions = by_id(comm, sim, "positions")
    velocities = by_id(comm, sim, "velocities")
    walls = sim.particle_system.walls.names
    wall_forces = np.array([sim.wall_force(name) for name in walls])
    builds = sim.particle_system.neighbors.builds
    if comm.rank == 0:
        return dict(positions=positions, velocities=velocities, contacts=np.array(contacts),
                    energies=np.array(energies), energy_names=np.array(energy_names), wall_forces=wall_forces,
                    builds=builds, owner_changes=owner_changes, count=total, dt=sim.dt,
                    box=np.array(GAS_SITES) * GAS_SPACING)


def run_shear(comm, out):
    sim = build(comm, shear_scene(), out)
    total = sim.particle_count()
    previous, _ = owners(comm, sim, total)
    changes = np.zeros(total, dtype=np.int64)
    counts, duplicates = [], 0
    for _ in range(SHEAR_STEPS):
        sim.step(1)  # sampled every step: no crossing is missed
        owner, copies = owners(comm, sim, total)
        counts.append(sim.particle_count())
        if comm.rank == 0:
            changes += owner != previous
            duplicates += int(np.count_nonzero(copies != 1))
            previous = owner
    velocities = by_id(comm, sim, "velocities")
    positions = by_id(comm, sim, "positions")
    if comm.rank == 0:
        travelled = 3.0 * SHEAR_STEPS * sim.dt
        return dict(changes=changes, counts=np.array(counts), duplicates=duplicates, total=total,
                    lost=sim.particle_system.lost_particles, rebuilds=sim.particle_system.neighbors.builds,
                    finite=bool(np.all(np.isfinite(positions)) and np.all(np.isfinite(velocities))),
                    mean_velocity_x=float(velocities[:, 0].mean()), travelled=travelled,
                    period=SHEAR_SITES[0] * GAS_SPACING)


def run_slide(comm, out, drop_history, perturb=False):
    import pdemfem.particles.system as system_module

    if drop_history:
        original = system_module.migrate

        def wrapped(comm_, state, destinations, records, *buffers):
            # Keep only the records of particles that stay: the migrated ones arrive without history
            # (of their pairs and of the plane walls alike).
            ids_before = state.ids[:state.owned_count].copy()
            result = original(comm_, state, destinations, records, *buffers)
            stayed = ids_before[destinations == comm_.rank]
            return result[np.isin(result[:, 0].astype(np.int64), stayed)]

        system_module.migrate = wrapped
    sim = build(comm, slide_scene(), out)
    total = sim.particle_count()
    if perturb:
        state = sim.particle_system.state
        row = np.flatnonzero(state.ids[:state.owned_count] == 0)
        state.positions[row, 1] += np.spacing(state.positions[row, 1])  # y = 1 mm (x = 0 has tiny ulps)
    forces_a, forces_b, floor, side, owner_a, owner_b, velocity_a, velocity_b = [], [], [], [], [], [], [], []
    gaps = []
    for _ in range(SLIDE_STEPS):
        sim.step(1)
        forces = by_id(comm, sim, "forces")
        velocities = by_id(comm, sim, "velocities")
        positions = by_id(comm, sim, "positions")
        owner, _ = owners(comm, sim, total)
        floor.append(sim.wall_force("floor"))
        side.append(sim.wall_force("side"))
        if comm.rank == 0:
            gaps.append(np.linalg.norm(positions[1] - positions[0]) - 2 * RADIUS)
            forces_a.append(forces[0])
            forces_b.append(forces[1])
            velocity_a.append(velocities[0])
            velocity_b.append(velocities[1])
            owner_a.append(owner[0])
            owner_b.append(owner[1])
    if comm.rank == 0:
        return dict(forces_a=np.array(forces_a), forces_b=np.array(forces_b), floor=np.array(floor),
                    side=np.array(side), owner_a=np.array(owner_a), owner_b=np.array(owner_b),
                    velocity_a=np.array(velocity_a), velocity_b=np.array(velocity_b), gaps=np.array(gaps),
                    dt=sim.dt, mass=4.0 / 3.0 * np.pi * RADIUS ** 3 * GLASS["density"],
                    gravity=np.array(SLIDE_GRAVITY), friction=SLIDE_FRICTION)


class _Records(logging.Handler):
    def __init__(self):
        super().__init__(logging.INFO)
        self.messages = []

    def emit(self, record):
        self.messages.append(record.getMessage())


def run_pile(comm, out, threshold=1.2):
    handler = _Records()
    logger = logging.getLogger("pdemfem")
    logger.addHandler(handler)
    previous_level = logger.level
    logger.setLevel(logging.INFO)
    try:
        sim = build(comm, pile_scene(threshold), out)
        system = sim.particle_system
        total = sim.particle_count()
        initial_boxes = system.decomposition.boxes.copy()
        history = []
        for _ in range(PILE_STEPS // 20):
            sim.step(20)
            owned = np.array([system.state.owned_count], dtype=float)
            loads = np.empty(comm.size)
            comm.Allgather(owned, loads)
            history.append([system.rebalances, loads.max() / loads.mean()])
        positions = by_id(comm, sim, "positions")
        # The measured cost imbalance right now (max/mean of 1 + listed pairs per rank).
        current = system._imbalance(system._particle_costs())
        count = sim.particle_count()
        # The balance check's rank totals (from pair and contact counts) against the per-particle costs' sum: equal
        # once the contacts are counted on the list (a canonical rebuild does), on every rank.
        system.canonical_rebuild()
        cost_totals = np.array(comm.gather((float(np.sum(system._particle_costs())), system._cost_total()), root=0))
    finally:
        logger.removeHandler(handler)
        logger.setLevel(previous_level)
    if comm.rank == 0:
        return dict(rebalances=system.rebalances, last_imbalance=np.array(getattr(system, "last_imbalance",
                                                                                   (np.nan, np.nan))),
                    current_imbalance=current, messages=np.array(handler.messages or [""]), cost_totals=cost_totals,
                    history=np.array(history), threshold=threshold, count=count, total=total,
                    initial_boxes=initial_boxes, final_boxes=system.decomposition.boxes,
                    centroid=positions.mean(axis=0), positions=positions)


def run_lost(comm, out):
    """Escaping particles are removed and counted during a run.  A NaN particle (as after a numerical
    blow-up) stops the run (pdemfem.monitor: exit 3 on every rank); stepping on without the monitor,
    the next rebuild removes and counts it."""
    from pdemfem.errors import SolverError

    output_dir = str(Path(out) / f"lost_{comm.size}")
    sim = Simulation.from_dict(lost_scene(output_dir), comm=comm, output_dir=output_dir)
    total = sim.particle_count()
    sim.run(progress=False)
    positions = by_id(comm, sim, "positions")
    velocities = by_id(comm, sim, "velocities")
    ids = gathered(comm, sim.particles.ids)
    energies = sim.energies()
    count = sim.particle_count()

    blown_dir = str(Path(out) / f"lost_nan_{comm.size}")
    blown = Simulation.from_dict(lost_scene(blown_dir), comm=comm, output_dir=blown_dir)
    state = blown.particle_system.state
    state.velocities[np.flatnonzero(state.ids[:state.owned_count] == 0)] = np.nan
    try:
        blown.run(progress=False)
        stopped = ""
    except SolverError as error:
        stopped = str(error)
    blown.step(1)  # the drift makes the position NaN, the rebuild it forces removes the particle
    blown_ids = gathered(comm, blown.particles.ids)
    blown_positions = by_id(comm, blown, "positions")
    if comm.rank == 0:
        return dict(total=total, count=count, lost=sim.particle_system.lost_particles,
                    ids=np.sort(ids), finite=bool(np.all(np.isfinite(positions)) and np.all(np.isfinite(velocities))),
                    kinetic=energies["kinetic_energy"], history=str(Path(output_dir) / "history.csv"),
                    escaping=LOST_ESCAPING, stopped=np.array(stopped), blown_ids=np.sort(blown_ids),
                    blown_lost=blown.particle_system.lost_particles,
                    blown_nonfinite=blown.particle_system.nonfinite_particles,
                    blown_finite=bool(np.all(np.isfinite(blown_positions))))


def _abort_on_error(kind, value, traceback):
    # One failing rank must not leave the others waiting in a collective until the test's timeout.
    sys.__excepthook__(kind, value, traceback)
    sys.stderr.flush()
    MPI.COMM_WORLD.Abort(1)


def main():
    sys.excepthook = _abort_on_error
    out, scenarios = sys.argv[1], sys.argv[2].split(",")
    comm = MPI.COMM_WORLD
    for scenario in scenarios:
        if scenario in ("gas", "gas_ulp", "pgas", "pgas_ulp"):
            result = run_gas(comm, out, periodic=scenario.startswith("p"), perturb=scenario.endswith("ulp"))
        elif scenario == "shear":
            result = run_shear(comm, out)
        elif scenario in ("slide", "slide_drop", "slide_ulp"):
            result = run_slide(comm, out, drop_history=scenario == "slide_drop", perturb=scenario == "slide_ulp")
        elif scenario == "pile":
            result = run_pile(comm, out)
        elif scenario == "lost":
            result = run_lost(comm, out)
        else:
            raise SystemExit(f"unknown scenario {scenario}")
        if comm.rank == 0:
            np.savez(Path(out) / f"{scenario}_{comm.size}.npz", **result)


if __name__ == "__main__":
    main()
