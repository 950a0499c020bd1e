"""Components own their state: the checkpoint only serialises state dicts, the particle field
registry decides what migrates, what ghosts carry and what is checkpointed."""
from __future__ import annotations

import sys
import tracemalloc
from pathlib import Path

import numpy as np
import pytest
from mpi4py import MPI

from mpi_harness import run_under_mpi
from pdemfem import state_dict as kinds
from pdemfem.errors import CheckpointError
from pdemfem.io.checkpoint import read_state, write_checkpoint, write_state
from pdemfem.parallel.decomposition import Decomposition
from pdemfem.parallel.exchange import GhostExchange
from pdemfem.particles.state import ParticleState

sys.path.insert(0, str(Path(__file__).parent / "mpi_cases"))


@pytest.mark.mpi
@pytest.mark.parametrize("ranks", [1, 2])
def test_new_wall_kind_and_particle_fields_restart_bit_identical(tmp_path, ranks):
    """A wall kind and per-particle fields unknown to io/checkpoint.py and io/simulation_io.py
    come back bit-identical from a restart (tests/mpi_cases/state_extension.py)."""
    completed = run_under_mpi(ranks, "state_extension.py", tmp_path)
    line = next(line for line in completed.stdout.splitlines() if line.startswith("OK "))
    _, size, checked, checked_after_restart = line.split()
    assert int(size) == ranks
    if ranks > 1:  # the ghost_step field was checked on real ghost rows, before and after the restart
        assert int(checked) > 0 and int(checked_after_restart) > 0


def nested_state(ids, comm) -> dict:
    rows = len(ids)
    return {"component": {"ids": kinds.Entry(kinds.PARTICLE_IDS, ids),
                          "values": kinds.particle_rows(np.column_stack([ids * 0.5, ids + 0.25])),
                          "clock": kinds.scalar(1.5),
                          "deep": {"walls": kinds.global_array(np.arange(6.0).reshape(2, 3))}},
            "solid": {"u": kinds.keyed_slab(np.arange(rows, dtype=float)[::-1, None] * [1.0, 2.0, 3.0],
                                            ids[::-1]),
                      "count": kinds.scalar({"a": 3})},
            "contacts": {"pairs": kinds.Entry(kinds.CONTACT_KEYS, np.column_stack([ids, ids[::-1]])),
                         "history": kinds.Entry(kinds.CONTACT_ROWS, np.zeros((rows, 0)))}}


def test_state_dict_round_trip(tmp_path):
    ids = np.random.default_rng(1).permutation(50).astype(np.int64)
    path = write_state(tmp_path / "s.h5", MPI.COMM_SELF, nested_state(ids, MPI.COMM_SELF), attributes={"step": 1})
    _, state = read_state(path, MPI.COMM_SELF)
    order = np.argsort(ids)
    assert np.array_equal(state["component"]["ids"], ids[order])
    assert np.array_equal(state["component"]["values"], np.column_stack([ids * 0.5, ids + 0.25])[order])
    assert state["component"]["clock"] == 1.5 and state["solid"]["count"] == {"a": 3}
    assert np.array_equal(state["component"]["deep"]["walls"], np.arange(6.0).reshape(2, 3))
    # keyed slab rows come back in global row order
    assert np.array_equal(state["solid"]["u"], np.arange(50.0)[::-1][np.argsort(ids[::-1])][:, None] * [1, 2, 3])
    assert state["contacts"]["history"].shape == (50, 0)  # history widths come from the arrays


def test_older_format_is_refused_clearly(tmp_path):
    path = write_checkpoint(tmp_path / "old.h5", MPI.COMM_SELF, {"ids": np.arange(3)},
                            attributes={"step": 1, "format_version": 1})
    with pytest.raises(CheckpointError, match="older pdemfem") as error:
        read_state(path, MPI.COMM_SELF)
    assert "start the run anew" in error.value.fix


def test_a_checkpoint_without_state_manifest_is_refused(tmp_path):
    path = write_checkpoint(tmp_path / "raw.h5", MPI.COMM_SELF, {"ids": np.arange(3)}, attributes={"step": 1})
    with pytest.raises(CheckpointError, match="no simulation state"):
        read_state(path, MPI.COMM_SELF)


def particles(count: int) -> ParticleState:
    rng = np.random.default_rng(2)
    return ParticleState(ids=np.arange(count), material_index=np.zeros(count), radii=np.full(count, 0.01),
                         densities=np.ones(count), positions=rng.random((count, 3)),
                         velocities=rng.random((count, 3)), angular_velocities=rng.random((count, 3)),
                         temperatures=np.zeros(count))


def test_field_flags_are_checked():
    state = particles(4)
    with pytest.raises(ValueError, match="ghost_rebuild"):
        state.add_field("a", (3,), ghost_step=True)
    with pytest.raises(ValueError, match="float64"):
        state.add_field("b", (), np.int32, ghost_rebuild=True, ghost_step=True)
    with pytest.raises(ValueError, match="twice"):
        state.add_field("positions", (3,))


def test_particle_state_round_trip_registers_added_fields():
    state = particles(6)
    state.add_field("extra", (2,), np.int32, fill=7, ghost_rebuild=True)
    state.add_field("scratch", (), checkpoint=False)
    stored = state.state_dict()
    assert "scratch" not in stored["rows"] and "positions_at_build" not in stored["rows"]
    assert stored["rows"]["ids"].kind == kinds.PARTICLE_IDS and stored["rows"]["extra"].kind == kinds.PARTICLE_ROWS
    plain = {"rows": {name: entry.value for name, entry in stored["rows"].items()},
             "added_fields": stored["added_fields"].value}
    fresh = particles(6)
    fresh.load_state_dict(plain)
    assert fresh.registry["extra"] == state.registry["extra"]
    assert np.array_equal(fresh.fields["extra"], np.full((6, 2), 7))
    assert np.array_equal(fresh.positions, state.positions) and fresh.owned_count == 6
    del plain["rows"]["angular_velocities"]
    with pytest.raises(kinds.StateMismatch, match="angular_velocities"):
        particles(6).load_state_dict(plain)


def periodic_ghosts(count: int = 400):
    """One rank, periodic in x: the ghosts are this rank's own particles shifted by the period."""
    state = particles(count)
    state.add_field("colour", (), ghost_rebuild=True, ghost_step=True)
    state.fields["colour"][:] = np.arange(count)
    lengths = np.array([1.0, 0.0, 0.0])
    decomposition = Decomposition.single(np.array([0.0, -np.inf, -np.inf]), np.array([1.0, np.inf, np.inf]))
    ghosts = GhostExchange(MPI.COMM_SELF, decomposition, 0.2, lengths)
    ghosts.plan_and_send(state)
    return state, ghosts, lengths


def test_ghost_update_carries_the_registered_step_fields():
    state, ghosts, lengths = periodic_ghosts()
    index_map = ghosts.index_map
    first, stop = index_map.ghost_ranges[0]
    assert (first, stop) == (state.owned_count, state.count) and stop > first
    sources = index_map.send_rows[0]
    state.velocities[:state.owned_count] += 1.0
    state.fields["colour"][:state.owned_count] *= 3.0
    state.radii[:state.owned_count] = 0.02  # ghost_rebuild only: not refreshed between rebuilds
    ghosts.update(state)
    assert np.array_equal(state.velocities[first:stop], state.velocities[sources])
    assert np.array_equal(state.fields["colour"][first:stop], 3.0 * sources)
    assert np.array_equal(state.positions[first:stop], state.positions[sources] + index_map.send_shifts[0])
    assert np.all(state.radii[first:stop] == 0.01)


def test_ghost_update_allocates_no_arrays():
    state, ghosts, _ = periodic_ghosts(4000)
    ghosts.update(state)  # first call: compiles the pack/unpack kernels
    buffer_bytes = sum(block.nbytes for block in ghosts.step_scatter.send_blocks[0])
    tracemalloc.start()
    ghosts.update(state)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    # Python bookkeeping (dicts, MPI request objects) is a few hundred bytes; a per-step copy of the
    # ghost rows (what the update did before its buffers were preallocated) is buffer_bytes or more.
    assert buffer_bytes > 20000 and peak < buffer_bytes / 4, (peak, buffer_bytes)


def test_ghosts_appended_again_reuse_the_arrays_and_equal_a_fresh_append():
    """Every rebuild drops the ghosts and appends the new ones: the second append writes into the spare rows
    the first one left (no copy of the owned rows), and every field holds what a fresh state's append gives."""
    state, ghosts, _ = periodic_ghosts()
    positions_buffer = state.positions.base
    state.velocities[:state.owned_count] += 2.0  # the owned rows change between the rebuilds
    state.drop_ghosts()
    ghosts.plan_and_send(state)
    assert state.ghost_count > 0 and state.positions.base is positions_buffer
    fresh, fresh_ghosts, _ = periodic_ghosts()
    fresh.velocities[:fresh.owned_count] += 2.0
    fresh.drop_ghosts()
    fresh = _copy_of(fresh)
    fresh_ghosts.plan_and_send(fresh)
    for name in state.registry:
        assert np.array_equal(state.array(name), fresh.array(name)), name


def test_a_selection_renumbered_through_a_reorder_is_the_selection_of_the_reordered_rows():
    """A rebuild selects the ghosts to send before its cell sort and renumbers them through the reorder instead
    of selecting again: the same rows, in the same (ascending) order, so the same ghosts arrive."""
    state, ghosts, _ = periodic_ghosts(600)
    state.drop_ghosts()
    selection = ghosts.select(state.positions[:state.owned_count])
    assert sum(len(rows) for rows in selection) > 0
    permutation = np.random.default_rng(3).permutation(state.owned_count)
    state.reorder(permutation)
    renumbered = ghosts.renumber(selection, permutation)
    again = ghosts.select(state.positions[:state.owned_count])
    assert len(renumbered) == len(again)
    for given, expected in zip(renumbered, again):
        assert np.array_equal(given, expected)
    mask = ghosts.sent_rows_mask(renumbered, state.owned_count)
    assert np.array_equal(np.flatnonzero(mask), np.unique(np.concatenate(again)))
    ghosts.plan_and_send(state, renumbered)
    fresh, fresh_ghosts, _ = periodic_ghosts(600)  # the same rows, reordered alike and selected afresh
    fresh.drop_ghosts()
    fresh.reorder(permutation)
    fresh_ghosts.plan_and_send(fresh)
    for name in state.registry:
        assert np.array_equal(state.array(name), fresh.array(name)), name


def test_reorder_permutes_every_field_and_leaves_spare_rows_for_the_ghosts():
    """The cell sort's reorder gathers every field by the permutation into a buffer with spare rows: every
    field of each particle stays together, and the ghosts appended next write into those rows (the arrays
    stay views of the buffers the reorder made: no owned row is copied a second time)."""
    state, _, _ = periodic_ghosts()
    state.drop_ghosts()
    before = {name: state.array(name).copy() for name in state.registry}
    permutation = np.random.default_rng(3).permutation(state.owned_count)
    state.reorder(permutation)
    for name in state.registry:
        assert np.array_equal(state.array(name), before[name][permutation]), name
    buffers = {name: state.array(name).base for name in state.registry}
    layout, width = state.ghost_layout()
    spare = state.owned_count // 5  # the ghost count may drift up to a fifth of the owned rows without a copy
    state.append_rows(state.pack_rows(np.arange(spare), layout, width), layout, as_ghosts=True)
    assert state.ghost_count == spare
    for name in state.registry:
        assert state.array(name).base is buffers[name], name
        assert np.array_equal(state.array(name)[:state.owned_count], before[name][permutation]), name


def test_remove_fills_the_holes_with_the_last_rows_and_keeps_every_field_of_each_particle():
    """Migration removes the leaving rows by moving the last staying rows into their holes: every field of
    every staying particle stays together (by id), the removed ones are gone, only O(removed) rows move
    (rows before the first hole are untouched), the arrays stay views of their buffers, and a removal
    that takes the tail (no holes) or every row works."""
    state = particles(12)
    state.add_field("extra", (2,), np.int32, fill=0)
    state.fields["extra"][:] = np.arange(12)[:, None] * [1, 10]
    positions_buffer = state.positions.base
    before = {name: state.array(name).copy() for name in state.registry}
    leaving = np.array([3, 7, 10, 11])
    state.remove(leaving)
    assert state.owned_count == state.count == 8
    assert state.positions.base is positions_buffer
    assert sorted(state.ids) == sorted(set(range(12)) - {3, 7, 10, 11})
    source = [list(before["ids"]).index(particle) for particle in state.ids]
    for name in state.registry:
        assert np.array_equal(state.array(name), before[name][source]), name
    assert np.array_equal(state.ids[:3], before["ids"][:3]) and np.array_equal(state.ids[4:7], before["ids"][4:7])
    state.remove(np.array([6, 7]))  # the tail only
    assert list(state.ids) == list(before["ids"][source][:6])
    state.remove(np.arange(6))
    assert state.owned_count == state.count == 0


def test_packed_rows_append_every_field_exactly_whatever_its_dtype():
    """Migration and the ghost exchange pack fields of several dtypes into float64 rows and append them on the
    other side (compiled loops for float64, int64 and int32; numpy for the rest): every value comes back
    exactly, ids up to 2^53 included, and the fields outside the layout get zeros."""
    state = particles(40)
    state.ids[:] = 2**53 - np.arange(40)  # the largest ids float64 holds exactly
    state.add_field("flag", (), bool, fill=True, ghost_rebuild=True)
    state.add_field("pair", (2,), np.int32, fill=-7, ghost_rebuild=True)
    state.add_field("scratch", (3,), checkpoint=False, migrate=False)
    state.fields["pair"][::3] = [2**31 - 1, -2**31]
    state.fields["flag"][::2] = False
    state.fields["scratch"][:] = 5.0
    before = {name: state.array(name).copy() for name in state.registry}
    rows = np.array([39, 0, 17, 3, 3])
    layout, width = state.ghost_layout()
    state.append_rows(state.pack_rows(rows, layout, width), layout, as_ghosts=True)
    assert state.ghost_count == len(rows)
    for name in state.registry:
        expected = before[name][rows] if name in {entry[0] for entry in layout} else np.zeros_like(before[name][rows])
        assert state.array(name).dtype == before[name].dtype, name
        assert np.array_equal(state.array(name)[40:], expected), name
        assert np.array_equal(state.array(name)[:40], before[name]), name


def _page_offsets_apart(state: ParticleState, names) -> float:
    """The smallest distance, in bytes around a 4 KiB page, between the page offsets of the fields' first rows."""
    offsets = sorted(state.array(name).ctypes.data % 4096 for name in names)
    return min((later - earlier) % 4096 for earlier, later in zip(offsets, offsets[1:] + offsets[:1]))


def test_every_field_starts_at_a_place_of_its_own_in_a_page():
    """Arrays walked in one loop whose addresses agree in their low 12 bits stall each other (4K aliasing);
    malloc puts every large array at the same 16 bytes into a page.  Each field's buffer starts at its own
    offset, through construction, an added field, reorder, ghost appends, removal and the list build's copy
    of the positions, so the eight arrays kick_drift walks are at least 5 cache lines apart (the golden-ratio
    sequence over 64 lines: 320 B for the core fields)."""
    from pdemfem.particles.state import page_offset, staggered_empty

    for shape, dtype, slot in (((0, 3), np.float64, 3), ((7,), np.int32, 5), ((1000, 2), np.float64, 40)):
        array = staggered_empty(shape, dtype, slot)
        assert array.shape == shape and array.dtype == dtype and array.flags.c_contiguous
        assert array.ctypes.data % 4096 == page_offset(slot) or array.size == 0
    walked = ("positions", "velocities", "angular_velocities", "forces", "torques", "positions_at_build",
              "inverse_mass", "inverse_inertia")
    state = particles(30000)  # rows of 240 kB: malloc maps each array on its own page, 16 B in
    state.add_field("extra", (3,))
    layout, width = state.ghost_layout()
    steps = [lambda: None, lambda: state.reorder(np.random.default_rng(1).permutation(state.owned_count)),
             lambda: state.append_rows(state.pack_rows(np.arange(500), layout, width), layout, as_ghosts=True),
             state.record_build_positions, state.drop_ghosts, lambda: state.remove(np.arange(0, 3000, 7))]
    for step in steps:
        step()
        offsets = [state.array(name).ctypes.data % 4096 for name in state.registry]
        assert len(set(offsets)) == len(offsets), offsets
        assert _page_offsets_apart(state, walked) >= 320
        if step is state.record_build_positions:
            assert np.array_equal(state.positions_at_build, state.positions)
            assert not np.shares_memory(state.positions_at_build, state.positions)


def _copy_of(state: ParticleState) -> ParticleState:
    """The same rows in arrays of their own (no spare rows)."""
    for name in state.registry:
        state._set(name, state.array(name).copy())
    state._buffers.clear()
    return state


# ------------------------------------------------------------------ guards



@pytest.mark.parametrize("id_stride", [1, 10**9])
def test_migration_splits_each_record_to_its_owners_destination(id_stride):
    """migrate's one-pass split of the contact records: a record whose owner leaves goes with its owner's
    destination, every other record stays, both in their order (against numpy's search and masks).  Ids
    spread far apart (stride 10^9: streams number particles as they come) take the binary search instead of
    the table over the leaving ids' span."""
    from pdemfem.parallel.exchange import _split_records

    rng = np.random.default_rng(3)
    records = np.column_stack([rng.integers(0, 500, 4000) * id_stride, rng.integers(0, 500, 4000),
                               rng.random((4000, 3))])
    leaving_ids = np.sort(rng.choice(500, 12, replace=False)) * id_stride
    leaving_destinations = rng.integers(1, 4, 12)
    kept_records, moving_records = np.empty_like(records), np.empty_like(records)
    moving_destinations = np.empty(len(records), dtype=np.int64)
    kept, moving = _split_records(records, leaving_ids, leaving_destinations, kept_records, moving_records,
                                  moving_destinations, False)
    leaves = np.isin(records[:, 0].astype(np.int64), leaving_ids)
    assert 0 < moving == np.count_nonzero(leaves) and kept == len(records) - moving
    assert np.array_equal(kept_records[:kept], records[~leaves])
    assert np.array_equal(moving_records[:moving], records[leaves])
    owners = records[leaves, 0].astype(np.int64)
    assert np.array_equal(moving_destinations[:moving], leaving_destinations[np.searchsorted(leaving_ids, owners)])
    # In place (the records lead a longer buffer, as the list's collected records do): the same split, the kept
    # records moved up over the leaving ones' rows.
    buffer = np.full((len(records) + 100, records.shape[1]), np.nan)
    buffer[:len(records)] = records
    in_place_moving = np.empty_like(records)
    in_place_destinations = np.empty(len(records), dtype=np.int64)
    assert _split_records(buffer[:len(records)], leaving_ids, leaving_destinations, buffer, in_place_moving,
                          in_place_destinations, True) == (kept, moving)
    assert np.array_equal(buffer[:kept], records[~leaves])
    assert np.array_equal(in_place_moving[:moving], records[leaves])
    assert np.array_equal(in_place_destinations[:moving], moving_destinations[:moving])


def test_entry_and_state_dict_shape_are_checked(tmp_path):
    with pytest.raises(ValueError, match="unknown state entry kind"):
        kinds.Entry("rows", np.zeros(3))
    with pytest.raises(TypeError, match="expected an Entry or a dict"):
        kinds.flatten({"a": {"b": np.zeros(3)}})
    ids = np.arange(4, dtype=np.int64)
    two_keys = {"a": {"ids": kinds.Entry(kinds.PARTICLE_IDS, ids)}, "b": {"ids": kinds.Entry(kinds.PARTICLE_IDS, ids)}}
    with pytest.raises(ValueError, match="more than one particle_ids"):
        write_state(tmp_path / "a.h5", MPI.COMM_SELF, two_keys)
    with pytest.raises(ValueError, match="without a particle_ids"):
        write_state(tmp_path / "b.h5", MPI.COMM_SELF, {"a": {"x": kinds.particle_rows(np.zeros(4))}})
    with pytest.raises(ValueError, match="two entries"):
        write_state(tmp_path / "c.h5", MPI.COMM_SELF,
                    {"a|b": kinds.global_array(ids), "a": {"b": kinds.global_array(ids)}})
    with pytest.raises(ValueError, match="not contiguous"):
        write_state(tmp_path / "d.h5", MPI.COMM_SELF, {"u": kinds.keyed_slab(np.zeros(2), [0, 2])})


def test_a_triangle_surface_refuses_another_vertex_count():
    from pdemfem.walls.mesh import TriangleSurface

    square = TriangleSurface("lid", [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], [[0, 1, 2], [0, 2, 3]], 0)
    triangle = TriangleSurface("lid", [[0, 0, 0], [1, 0, 0], [1, 1, 0]], [[0, 1, 2]], 0)
    stored = {name: entry.value for name, entry in triangle.state_dict().items()}
    with pytest.raises(kinds.StateMismatch, match="3 vertices in the checkpoint, 4 in this scene"):
        square.load_state_dict(stored)


def small_scene(out, walls=()) -> dict:
    import restart_scenes

    scene = restart_scenes.pile_scene(out, 10, 5, 5, count=8)
    del scene["solids"], scene["coupling"]
    scene["walls"] += list(walls)
    return scene


def test_a_restart_names_the_state_the_checkpoint_lacks(tmp_path):
    from pdemfem.simulation import Simulation

    Simulation.from_dict(small_scene(tmp_path), comm=MPI.COMM_WORLD, base_dir=tmp_path).run(progress=False)
    path = tmp_path / "checkpoints" / "checkpoint_000000000005.h5"
    drum = {"name": "drum", "kind": "cylinder", "material": "grain", "radius": 0.2,
            "axis": {"point": [0.1, 0.1, 0.0], "direction": [0, 0, 1]}}
    with pytest.raises(CheckpointError, match="lacks the state of wall:drum"):
        Simulation.from_dict(small_scene(tmp_path / "b", [drum]), comm=MPI.COMM_WORLD, base_dir=tmp_path,
                             restart=path, force=True)
    floor = {"name": "floor", "kind": "plane", "point": [0, 0, 0], "normal": [0, 0, 1], "material": "grain"}
    # The plane walls' positions are restored by their place in the list: another list is refused, named.
    with pytest.raises(CheckpointError, match=r"was written with other walls \(walls \['side_0', 'side_1', "
                                              r"'side_2', 'side_3'\] -> \[.*'floor'\]\)"):
        Simulation.from_dict(small_scene(tmp_path / "c", [floor]), comm=MPI.COMM_WORLD, base_dir=tmp_path,
                             restart=path, force=True)
