"""Rigid clumps of spheres: mass properties, sphere filling of a closed surface, rigid-body integration,
and their place in the particle system (docs/shapes.md).

    quaternion   unit-quaternion helpers (w, x, y, z), numba kernels
    shape        mass, centre of mass, inertia and principal axes of a union of spheres
    fill         N spheres filling a closed triangulated surface
    rigid_body   kick-drift-kick rigid-body step with the symplectic free-rotor splitting;
                 member-sphere state from the body state; member loads summed to the body
    template     a clump group's shape: members about the centre of mass, mass shares, bounds
    insert       placing clump groups (list, lattice, random) without overlap
    bodies       the bodies of a particle system: step, loads, energies, removal, checkpoint state
"""
