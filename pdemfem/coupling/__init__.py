"""Two-way DEM-FEM coupling through the solids' contact surfaces."""
