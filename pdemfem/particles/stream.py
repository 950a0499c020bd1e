"""Insertion over time: particle groups with `insert: {kind: stream}` (docs/streams.md).

A stream inserts particles into its region box in *events*, at t_k = start + k * interval.  Event k
brings the stream's running total up to what the rate asks for at the end of its interval:

    rate:       floor(rate * (t_k + interval - start)) particles
    mass_rate:  mass_rate * (t_k + interval - start) kg, to the nearest particle

(capped at `stop` and at `count`).  A candidate that would overlap a particle or a wall is not
inserted; the running target makes the next event try again, so a blocked region only delays
the stream.

Determinism, independent of the rank count.  Every rank generates the same candidates: radii and
positions come from the group's seed, the group's index and the event index, and the candidates
are tested against the same particles (the owned particles near the region, gathered from every
rank) and the same walls, so every rank accepts the same ones.  Ids continue after the largest id
so far in candidate order; each rank appends the accepted candidates that lie in its own box
(pdemfem.parallel.decomposition) and the list is rebuilt (ParticleSystem.add_particles).

The stream's counters (last event, particles and mass inserted, next id, energy brought in) are
checkpointed scalars: no random state survives an event, so a restart continues bit-identically.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from pdemfem import state_dict as kinds
from pdemfem.errors import SceneError
from pdemfem.parallel.exchange import allgather_rows
from pdemfem.particles.energy import NO_CLUMP_BODIES, particle_energy_sums
from pdemfem.particles.insert import _random_place
from pdemfem.particles.periodic_images import PeriodicBox
from pdemfem.particles.state import ParticleState
from pdemfem.scene.derived import group_radius_range
from pdemfem.walls.triangle_contact import point_triangle_distance_squared

# Events are due at the first step whose time reaches t_k; this slack keeps a t_k that is a whole
# number of steps (up to round-off in start + k * interval) on that step.
_STEP_SLACK = 1e-9


@dataclass
class Stream:
    """One group's stream: its fixed parameters and its running counters."""

    group: str
    key: str  # the scene key of its insert entry, for messages
    index: int  # the group's index in the scene: part of every event's seed
    material_index: int
    density: float
    temperature: float
    radius_range: tuple
    lower: np.ndarray
    upper: np.ndarray
    velocity: np.ndarray
    rate: float | None
    mass_rate: float | None
    start: float
    stop: float
    interval: float
    count: int | None
    seed: int
    max_attempts: int
    last_event: int = -1
    inserted: int = 0
    mass: float = 0.0

    def event_step(self, event: int, dt: float) -> int:
        return int(math.ceil((self.start + event * self.interval) / dt - _STEP_SLACK))

    def latest_due_event(self, step: int, dt: float) -> int:
        """The last event k (t_k < stop) due at or before `step`, or -1."""
        event = int(math.floor((step * dt - self.start) / self.interval))
        while self.event_step(event + 1, dt) <= step:
            event += 1
        while event >= 0 and self.event_step(event, dt) > step:
            event -= 1
        while event >= 0 and self.start + event * self.interval >= self.stop:
            event -= 1
        return event

    def interval_end(self, event: int) -> float:
        return min(self.start + (event + 1) * self.interval, self.stop)

    def candidate_radii(self, event: int, random) -> np.ndarray:
        """Radii of the candidates of `event`: as many as bring the total up to the event's target."""
        smallest, largest = self.radius_range
        duration = self.interval_end(event) - self.start
        if self.rate is not None:
            # The relative slack keeps rate * duration that is a whole number up to round-off on it.
            target = int(math.floor(self.rate * duration * (1.0 + 1e-12) + 1e-12))
            if self.count is not None:
                target = min(target, self.count)
            wanted = max(target - self.inserted, 0)
            return random.uniform(smallest, largest, size=wanted) if largest > smallest else np.full(wanted, largest)
        target_mass = self.mass_rate * duration
        radii = []
        planned = self.mass
        limit = (self.count - self.inserted) if self.count is not None else math.inf
        while len(radii) < limit:
            radius = random.uniform(smallest, largest) if largest > smallest else largest
            mass = 4.0 / 3.0 * math.pi * radius**3 * self.density
            # Nearest particle: add it while that leaves the total at most half a particle above the target.
            if planned + 0.5 * mass > target_mass:
                break
            radii.append(radius)
            planned += mass
        return np.array(radii, dtype=float)

    def state_dict(self) -> dict:
        return {"last_event": kinds.scalar(int(self.last_event)), "inserted": kinds.scalar(int(self.inserted)),
                "mass": kinds.scalar(float(self.mass))}

    def load_state_dict(self, state: dict) -> None:
        self.last_event = int(state["last_event"])
        self.inserted = int(state["inserted"])
        self.mass = float(state["mass"])


class ParticleStreams(kinds.StateComponent):
    """The scene's streams (a checkpointed component); `insert_due(simulation)` at each step's start."""

    def __init__(self, streams: list, next_id: int, gravity, dt: float):
        self.streams = streams
        self.next_id = int(next_id)
        self.gravity = np.asarray(gravity, dtype=float)
        self.dt = float(dt)
        # Kinetic + rotational + potential (-m g.x) energy the inserted particles brought in [J].
        self.energy_in = 0.0
        self._next_due_step = 0  # no event is due before this step (recomputed after each event)

    @classmethod
    def from_scene(cls, scene, material_names, next_id: int, dt: float):
        """The streams of `scene` (None when it has none); SceneError for a region that cannot work."""
        validate_streams(scene)
        streams = []
        end = scene.time.end
        for index, group in enumerate(scene.particles):
            insert = group.insert
            if insert.kind != "stream":
                continue
            key = f"particles[{index}].insert"
            smallest, largest = group_radius_range(group)
            lower, upper = (np.array(corner, dtype=float) for corner in insert.region.box)
            stop = insert.stop if insert.stop is not None else math.inf
            velocity = np.array(insert.velocity, dtype=float)
            interval = insert.interval or default_interval(lower, upper, velocity, scene.gravity,
                                                           min(stop, end) - insert.start, dt)
            streams.append(Stream(
                group=group.name, key=key, index=index, material_index=list(material_names).index(group.material),
                density=scene.materials[group.material].density, temperature=(group.initial_temperature if group.initial_temperature is not None
                             else scene.heat.default_temperature),
                radius_range=(smallest, largest), lower=lower, upper=upper, velocity=velocity,
                rate=insert.rate, mass_rate=insert.mass_rate, start=insert.start, stop=stop, interval=interval,
                count=insert.count, seed=insert.seed, max_attempts=insert.max_attempts))
        return cls(streams, next_id, scene.gravity, dt) if streams else None

    @property
    def inserted(self) -> int:
        return sum(stream.inserted for stream in self.streams)

    @property
    def mass_in(self) -> float:
        return sum(stream.mass for stream in self.streams)

    # ------------------------------------------------------------ insertion
    def insert_due(self, simulation) -> None:
        """Collective: run the events due at the start of this step (every rank, the same decisions)."""
        step = simulation.step_count
        if step < self._next_due_step:
            return
        simulation.particle_system.finish_step_sum()  # the last step's sums in place before the insertion
        simulation.particle_system.finish_clump_step()  # and the clumps' second half (the rebuild moves their rows)
        try:
            self._insert_events(simulation, step)
        finally:
            self._next_due_step = min((stream.event_step(stream.last_event + 1, self.dt) for stream in self.streams
                                       if stream.start + (stream.last_event + 1) * stream.interval < stream.stop),
                                      default=math.inf)

    def _insert_events(self, simulation, step: int) -> None:
        due = [(stream, stream.latest_due_event(step, self.dt)) for stream in self.streams]
        due = [(stream, event) for stream, event in due if event > stream.last_event]
        if not due:
            return
        system = simulation.particle_system
        fixed_positions, fixed_radii = self._gather_near(system, [stream for stream, _ in due])
        batches = []
        for stream, event in due:
            stream.last_event = event  # an event's candidates are drawn once; what fails waits for the next
            random = np.random.default_rng([stream.seed & (2**64 - 1), stream.index, event])
            radii = stream.candidate_radii(event, random)
            if not len(radii):
                continue
            positions = self._place(stream, radii, fixed_positions, fixed_radii, int(random.integers(2**31 - 1)))
            radii = radii[:len(positions)]
            clear = ~_touches_walls(positions, radii, system.walls, simulation.contributor_walls)
            positions, radii = positions[clear], radii[clear]
            if not len(radii):
                continue
            fixed_positions = np.concatenate([fixed_positions, positions])
            fixed_radii = np.concatenate([fixed_radii, radii])
            batches.append(self._new_particles(stream, positions, radii, system.state))
        if not batches:
            return
        new = batches[0]
        for batch in batches[1:]:
            new.append_particles(batch)
        kinetic, rotational, potential, _ = particle_energy_sums(
            new.count, new.mass, new.velocities, new.angular_velocities, new.inverse_inertia, new.positions,
            self.gravity, NO_CLUMP_BODIES)
        self.energy_in += kinetic + rotational + potential
        # Each rank keeps the particles in its own box; the others are another rank's.
        new.keep(np.flatnonzero(system.decomposition.owners(new.positions) == system.comm.rank))
        system.add_particles(new)

    def _gather_near(self, system, streams):
        """(positions, radii) of every rank's owned particles that could touch a candidate of `streams`
        (within the largest radius of a region), the same rows on every rank."""
        state = system.state
        owned = state.owned_count
        positions = state.positions[:owned]
        radii = state.radii[:owned]
        margin = 2.0 * system.largest_radius
        periodic_box = PeriodicBox.from_lengths(system.domain_lower, system.periodic_lengths)
        if periodic_box is not None:
            # A particle near a periodic face stands beyond the opposite one too: a region along that face (a
            # chute's inlet across its periodic width) must keep clear of it there.
            positions, radii, _ = periodic_box.with_images(positions, radii, margin)
        near = np.zeros(len(positions), dtype=bool)
        for stream in streams:
            near |= np.all((positions >= stream.lower - margin) & (positions <= stream.upper + margin), axis=1)
        rows = np.column_stack([positions[near], radii[near]])
        gathered = allgather_rows(system.comm, rows, 4)
        return np.ascontiguousarray(gathered[:, :3]), np.ascontiguousarray(gathered[:, 3])

    @staticmethod
    def _place(stream, radii, fixed_positions, fixed_radii, seed: int) -> np.ndarray:
        """Random sequential addition in the region, clear of the fixed particles and of each other; the
        candidates from the first one that finds no place within max_attempts on are dropped."""
        largest = float(max(radii.max(), fixed_radii.max() if len(fixed_radii) else 0.0))
        grid_lower = np.minimum(stream.lower, fixed_positions.min(axis=0)) if len(fixed_radii) else stream.lower
        grid_upper = np.maximum(stream.upper, fixed_positions.max(axis=0)) if len(fixed_radii) else stream.upper
        cell_size = 2.0 * largest
        dimensions = np.floor((grid_upper - grid_lower) / cell_size).astype(np.int64) + 1
        positions, placed = _random_place(stream.lower, stream.upper, radii, fixed_positions, fixed_radii, cell_size,
                                          dimensions, grid_lower, stream.max_attempts, seed)
        return positions[:placed]

    def _new_particles(self, stream, positions, radii, state) -> ParticleState:
        count = len(radii)
        ids = np.arange(self.next_id, self.next_id + count, dtype=np.int64)
        self.next_id += count
        new = ParticleState(ids=ids, material_index=np.full(count, stream.material_index, dtype=np.int32), radii=radii,
                            densities=np.full(count, stream.density), positions=positions,
                            velocities=np.tile(stream.velocity, (count, 1)), angular_velocities=np.zeros((count, 3)),
                            temperatures=np.full(count, stream.temperature) if state.temperatures is not None else None)
        stream.inserted += count
        stream.mass += float(np.sum(new.mass))
        return new

    # ------------------------------------------------------------ checkpoints
    def state_dict(self) -> dict:
        state = {"next_id": kinds.scalar(int(self.next_id)), "energy_in": kinds.scalar(float(self.energy_in))}
        state["groups"] = {stream.group: stream.state_dict() for stream in self.streams}
        return state

    def load_state_dict(self, state: dict) -> None:
        groups = state["groups"]
        if sorted(groups) != sorted(stream.group for stream in self.streams):
            raise kinds.StateMismatch(f"holds the streams {sorted(groups)}, the scene has "
                                      f"{sorted(stream.group for stream in self.streams)}")
        for stream in self.streams:
            stream.load_state_dict(groups[stream.group])
        self.next_id = int(state["next_id"])
        self.energy_in = float(state["energy_in"])
        self._next_due_step = 0


def stream_radius_range(scene):
    """(smallest, largest) radius of the scene's stream groups, or None when it has none."""
    ranges = [group_radius_range(group) for group in scene.particles if group.insert.kind == "stream"]
    if not ranges:
        return None
    return min(low for low, _ in ranges), max(high for _, high in ranges)


def default_interval(lower, upper, velocity, gravity, duration: float, dt: float) -> float:
    """The time a particle inserted at `velocity` takes to cross the region along its motion
    (the velocity's direction, else gravity's): by then one event's particles have left the region.
    Without motion (no velocity, no gravity), 1 % of the stream's duration.  Never below dt."""
    velocity = np.asarray(velocity, dtype=float)
    gravity = np.asarray(gravity, dtype=float)
    speed = float(np.linalg.norm(velocity))
    direction = velocity / speed if speed > 0 else (gravity / np.linalg.norm(gravity) if np.any(gravity) else None)
    if direction is None:
        return max(0.01 * duration if math.isfinite(duration) else 100.0 * dt, dt)
    length = float(np.sum(np.abs(direction) * (upper - lower)))
    acceleration = float(gravity @ direction)
    if abs(acceleration) < 1e-12 * max(speed, 1.0):
        time = length / speed
    else:
        discriminant = speed * speed + 2.0 * acceleration * length
        # Thrown against gravity and turning back before it crosses: it leaves by the side it came in.
        time = (-speed + math.sqrt(discriminant)) / acceleration if discriminant > 0 else 2.0 * speed / -acceleration
    return max(time, dt)


def validate_streams(scene) -> None:
    """SceneError for a stream region that cannot work: thinner than a particle, or reaching
    outside domain.box (`pdemfem check` and `run`)."""
    for index, group in enumerate(scene.particles):
        if group.insert.kind != "stream":
            continue
        key = f"particles[{index}].insert.region.box"
        lower, upper = (np.array(corner, dtype=float) for corner in group.insert.region.box)
        largest = group_radius_range(group)[1]
        if np.any(upper - lower < 2.0 * largest):
            raise SceneError(key, f"the region is thinner than the largest particle diameter {2 * largest:g} m",
                             "enlarge region.box")
        if scene.domain.box is None:
            continue
        low, high = (np.asarray(corner, dtype=float) for corner in scene.domain.box)
        bounded = np.array(["xyz"[axis] not in scene.domain.periodic for axis in range(3)])
        if np.any(((lower < low) | (upper > high)) & bounded):
            raise SceneError(key, "the region reaches outside domain.box: particles inserted there would be removed "
                                  "as lost", "move the region inside domain.box")


# ---------------------------------------------------------------- walls


def _touches_walls(positions, radii, plane_walls, contributor_walls) -> np.ndarray:
    """Candidates closer to a wall than their radius (plane, mesh, cylinder walls and the solids' surfaces)."""
    touching = np.zeros(len(radii), dtype=bool)
    if not len(radii):
        return touching
    for point, normal in zip(plane_walls.points, plane_walls.normals):
        touching |= (positions - point) @ normal < radii
    for wall in contributor_walls:
        if hasattr(wall, "triangles"):
            # Every triangle (an event has few candidates): the wall's search tree may wait for a refit.
            touching |= _near_triangles(positions, radii, wall.vertices, wall.triangles)
        elif hasattr(wall, "direction"):  # an analytic cylinder
            relative = positions - wall.point
            axial = relative @ wall.direction
            distance = np.linalg.norm(relative - axial[:, None] * wall.direction, axis=1)
            touching |= (distance > wall.radius - radii) if wall.inside else (distance < wall.radius + radii)
    return touching


@njit(cache=True)
def _near_triangles(positions, radii, vertices, triangles):
    touching = np.zeros(positions.shape[0], dtype=np.bool_)
    for i in range(positions.shape[0]):
        for t in range(triangles.shape[0]):
            if point_triangle_distance_squared(positions[i, 0], positions[i, 1], positions[i, 2], vertices, triangles,
                                               t) < radii[i] * radii[i]:
                touching[i] = True
                break
    return touching
