// The elastic side panel of examples/hopper_discharge.yaml: a 4 mm plate at x = -4 .. 0 mm, 30 mm along y,
// 130 mm high, the grains on its x = 0 face.  Structured: 1 x 3 x 13 cells (the whole thickness, 10 mm
// squares over the face), each hexahedral cell split into 6 tetrahedra: the same mesh as the scene's
// `mesh: {box: [[-0.004, 0, 0], [0, 0.03, 0.13]], cells: [1, 3, 13]}` (pdemfem builds that box the same way).
// Physical groups (names the scene uses):
//   "edges"      : the four edge faces (y = 0, y = 30 mm, z = 0, z = 130 mm), clamped  -> solids[].fixed
//   "grain_side" : the x = 0 face, which the grains touch                              -> solids[].contact
//   "panel"      : the volume
// pdemfem meshes this file itself when a scene names it (solids[].mesh: meshes/hopper_panel.geo); to look
// at it: gmsh hopper_panel.geo -3
SetFactory("OpenCASCADE");
thickness = 0.004; depth = 0.03; height = 0.13;
cells_through = 1; cells_across = 3; cells_up = 13;

Box(1) = {-thickness, 0, 0, thickness, depth, height};

// Every edge gets the cell count of the axis it runs along.
edges() = Curve{:};
For i In {0 : #edges() - 1}
  bounds() = BoundingBox Curve{edges(i)};
  span_x = bounds(3) - bounds(0); span_y = bounds(4) - bounds(1); span_z = bounds(5) - bounds(2);
  If (span_x > span_y && span_x > span_z)
    Transfinite Curve{edges(i)} = cells_through + 1;
  ElseIf (span_y > span_z)
    Transfinite Curve{edges(i)} = cells_across + 1;
  Else
    Transfinite Curve{edges(i)} = cells_up + 1;
  EndIf
EndFor
Transfinite Surface{:};
Transfinite Volume{1};

eps = 1e-6;
Physical Surface("edges") = {Surface In BoundingBox{-thickness - eps, -eps, -eps, eps, eps, height + eps},
                             Surface In BoundingBox{-thickness - eps, depth - eps, -eps, eps, depth + eps, height + eps},
                             Surface In BoundingBox{-thickness - eps, -eps, -eps, eps, depth + eps, eps},
                             Surface In BoundingBox{-thickness - eps, -eps, height - eps, eps, depth + eps, height + eps}};
Physical Surface("grain_side") = {Surface In BoundingBox{-eps, -eps, -eps, eps, depth + eps, height + eps}};
Physical Volume("panel") = {1};
