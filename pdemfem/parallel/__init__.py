"""MPI spatial decomposition of the particles: RCB boxes, migration, ghosts."""
