"""Rigid clumps of spheres: mass properties, sphere filling of a closed surface, rigid-body integration.

Building blocks only: the particle system does not use clumps yet (docs/shapes.md).

    quaternion   unit-quaternion helpers (w, x, y, z), numba kernels
    shape        mass, centre of mass, inertia and principal axes of a union of spheres
    fill         N spheres filling a closed triangulated surface
    rigid_body   kick-drift-kick rigid-body step with the symplectic free-rotor splitting;
                 member-sphere state from the body state; member loads summed to the body
"""
