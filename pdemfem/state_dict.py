"""What a component's state_dict() returns: named entries, each with a declared kind.

Every piece of simulation state (particle state, Verlet list, decomposition, each
wall, each solid, the coupling) owns its state: it returns a nested dict from
`state_dict()` and takes the same shape back in `load_state_dict()`.  A leaf is an
`Entry`: a value and the *kind* that tells the checkpoint how to store it.  The
checkpoint code only serialises these dicts; it knows the kinds, never the
components.

    {"positions": Entry(PARTICLE_ROWS, positions[:owned]),
     "ids": Entry(PARTICLE_IDS, ids[:owned]),
     "work": Entry(SCALAR, 0.25),
     "contacts": {"pairs": Entry(CONTACT_KEYS, pairs), "history": Entry(CONTACT_ROWS, xi)}}

load_state_dict() receives the plain values (arrays, scalars) at the same places.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

# One row per owned particle, in the rows of the PARTICLE_IDS entry.  Stored sorted by particle
# id (the file does not depend on the rank count); read back as an even share of the id-sorted
# rows, the same share for every particle entry, so the particles then migrate by position.
PARTICLE_ROWS = "particle_rows"
# The particles' global ids (int64): the key of every PARTICLE_ROWS entry (exactly one per state).
PARTICLE_IDS = "particle_ids"
# Rows keyed by the CONTACT_KEYS entry (int64 (K, 2): owner id, partner id), this rank's rows;
# stored sorted by the keys, read back as an even share (the reader routes them to their owners).
CONTACT_ROWS = "contact_rows"
CONTACT_KEYS = "contact_keys"
# An array identical on every rank (rank 0's copy is written); read back whole on every rank.
GLOBAL = "global"
# This rank's rows of a table in a rank-count independent numbering (the FE vectors by input
# node number): either rows [first, first + n), or rows in any order with their global row
# numbers (`keys`; the checkpoint sorts them across ranks).  The rows of all ranks tile the
# table.  Read back whole on every rank.
SLAB = "slab"
# A JSON value (number, string, list, dict) identical on every rank.
SCALAR = "scalar"

KINDS = (PARTICLE_ROWS, PARTICLE_IDS, CONTACT_ROWS, CONTACT_KEYS, GLOBAL, SLAB, SCALAR)


@dataclass(frozen=True)
class Entry:
    kind: str
    value: Any
    first: int = 0  # SLAB only: the global row of this rank's first row
    keys: Any = None  # SLAB only, instead of first: the global row number of each row

    def __post_init__(self):
        if self.kind not in KINDS:
            raise ValueError(f"unknown state entry kind {self.kind!r} (kinds: {', '.join(KINDS)})")


def scalar(value) -> Entry:
    return Entry(SCALAR, value)


def global_array(values) -> Entry:
    return Entry(GLOBAL, np.ascontiguousarray(values))


def particle_rows(values) -> Entry:
    return Entry(PARTICLE_ROWS, np.ascontiguousarray(values))


def slab(values, first: int) -> Entry:
    return Entry(SLAB, np.ascontiguousarray(values), int(first))


def keyed_slab(values, keys) -> Entry:
    return Entry(SLAB, np.ascontiguousarray(values), keys=np.asarray(keys, dtype=np.int64))


class StateMismatch(ValueError):
    """load_state_dict: the stored state does not fit this component (another scene wrote it).

    The message names what differs; the caller names the file and the fix."""


class StateComponent:
    """The protocol (and its defaults) of a component that owns checkpointed state.

    state_dict()        collective: nested dict of Entry leaves (see the module docstring)
    load_state_dict(s)  collective: the plain values back (same nesting); raise StateMismatch
                        when they cannot belong to this component
    canonicalize()      collective: put the component into the state a restart rebuilds from
                        the file (rebuild derived data from the stored state alone); called
                        right after a checkpoint is written and after load_state_dict
    """

    def state_dict(self) -> dict:
        return {}

    def load_state_dict(self, state: dict) -> None:
        pass

    def canonicalize(self) -> None:
        pass


def flatten(state: dict, prefix: tuple = ()) -> list:
    """[(path tuple, Entry)] of a nested state dict, in insertion order."""
    leaves = []
    for name, value in state.items():
        if not isinstance(name, str) or not name:
            raise ValueError(f"state dict key {name!r} at {'/'.join(prefix) or '<root>'}: names must be non-empty "
                             f"strings")
        path = prefix + (name,)
        if isinstance(value, dict):
            leaves += flatten(value, path)
        elif isinstance(value, Entry):
            leaves.append((path, value))
        else:
            raise TypeError(f"state dict entry {'/'.join(path)}: expected an Entry or a dict, got "
                            f"{type(value).__name__}")
    return leaves


def nest(leaves) -> dict:
    """The nested dict of plain values from [(path, value)] (the inverse of flatten)."""
    root: dict = {}
    for path, value in leaves:
        node = root
        for name in path[:-1]:
            node = node.setdefault(name, {})
        node[path[-1]] = value
    return root
