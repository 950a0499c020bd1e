// The conveyor belt of examples/belt.yaml: a 0.6 m x 8 cm x 6 mm rubber strip, its carrying side at z = 0.
// Structured: 24 x 2 x 1 cells (2.5 cm along the belt, 4 cm across, the whole thickness), each hexahedral
// cell split into 6 tetrahedra: the same mesh as the scene's `mesh: {box: [[0, -0.04, -0.006],
// [0.6, 0.04, 0]], cells: [24, 2, 1]}` (pdemfem builds that box the same way).
// Physical groups (names the scene uses):
//   "carrying_side" : the top face (z = 0), which the gravel touches     -> solids[].contact
//   "belt"          : the volume
// pdemfem meshes this file itself when a scene names it (solids[].mesh: meshes/belt.geo); to look at it:
//   gmsh belt.geo -3
SetFactory("OpenCASCADE");
length = 0.6; width = 0.08; thickness = 0.006;
cells_along = 24; cells_across = 2; cells_through = 1;

Box(1) = {0, -width / 2, -thickness, length, width, thickness};

// Every edge gets the cell count of the axis it runs along.
edges() = Curve{:};
For i In {0 : #edges() - 1}
  bounds() = BoundingBox Curve{edges(i)};
  span_x = bounds(3) - bounds(0); span_y = bounds(4) - bounds(1); span_z = bounds(5) - bounds(2);
  If (span_x > span_y && span_x > span_z)
    Transfinite Curve{edges(i)} = cells_along + 1;
  ElseIf (span_y > span_z)
    Transfinite Curve{edges(i)} = cells_across + 1;
  Else
    Transfinite Curve{edges(i)} = cells_through + 1;
  EndIf
EndFor
Transfinite Surface{:};
Transfinite Volume{1};

eps = 1e-6;
Physical Surface("carrying_side") = {Surface In BoundingBox{-eps, -width / 2 - eps, -eps, length + eps, width / 2 + eps, eps}};
Physical Volume("belt") = {1};
