// An arch bridge: a 200 x 50 x 40 mm aluminium block with a half-cylinder arch (radius 28 mm) cut from below.
// Physical groups (names the scene uses):
//   "abutments" : the two end faces (x = 0 and x = 0.2), clamped      -> solids[].fixed
//   "deck"      : the top face (z = 0.04), which the particles touch   -> solids[].contact
//   "bridge"    : the volume (a 3-D physical group is needed for the tetrahedra to be saved)
// Mesh it with gmsh (the shipped bridge.msh was made so):  gmsh bridge.geo -3 -format msh4 -o bridge.msh
SetFactory("OpenCASCADE");
Mesh.CharacteristicLengthMax = 0.012;   // m: ~12 mm tetrahedra (coarse: a demo; see docs/fem.md for refinement)
Mesh.CharacteristicLengthMin = 0.006;

Box(1) = {0, 0, 0, 0.2, 0.05, 0.04};
Cylinder(2) = {0.1, -0.01, 0, 0, 0.07, 0, 0.028};   // axis along y through (0.1, ., 0), radius 28 mm: a 12 mm deck over the arch
bridge() = BooleanDifference{ Volume{1}; Delete; }{ Volume{2}; Delete; };

eps = 1e-6;
Physical Surface("abutments") = {Surface In BoundingBox{-eps, -eps, -eps, eps, 0.05 + eps, 0.04 + eps},
                                 Surface In BoundingBox{0.2 - eps, -eps, -eps, 0.2 + eps, 0.05 + eps, 0.04 + eps}};
Physical Surface("deck") = {Surface In BoundingBox{-eps, -eps, 0.04 - eps, 0.2 + eps, 0.05 + eps, 0.04 + eps}};
Physical Volume("bridge") = {bridge()};
