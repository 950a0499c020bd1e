"""Counter-forces of sphere-triangle contacts onto FE nodes.

A contact on a surface triangle carries the force the particle exerts on the
surface and the barycentric weights of the contact point.  For P1 faces the
weights go straight to the triangle's three nodes.  A P2 face (a, b, c, ab, bc,
ca) is mirrored as four flat sub-triangles, and the force goes to the three
nodes of the sub-triangle the contact point is on, by the same weights: the
contact's gap is measured on that flat sub-triangle, so these weights are its
derivative with respect to the nodes' positions, and the work the particle does
on the surface is the work the nodal forces do on the solid.  (Spreading by the
quadratic face functions instead, the variationally consistent load of a point
force on a P2 face, is not that derivative: an impact on a free P2 plate left
+2.2e-2 of its energy behind, at any time step.)  The weights sum to one (total
force preserved) and reproduce the contact point (sum w_k x_k = x_c), so the
total moment is preserved as well.
"""
from __future__ import annotations

from numba import njit


@njit(cache=True)
def spread_linear(triangles, contact_triangles, contact_weights, contact_forces, node_forces):
    """node_forces[node] += w_k F for the three nodes of each contact's triangle."""
    for c in range(contact_triangles.shape[0]):
        t = contact_triangles[c]
        for k in range(3):
            node = triangles[t, k]
            for axis in range(3):
                node_forces[node, axis] += contact_weights[c, k] * contact_forces[c, axis]
