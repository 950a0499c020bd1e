// A treaded wheel for the tyre-tread application: a ring about the y axis (through the origin), inner
// radius 60 mm, outer radius 80 mm, 40 mm wide (y = -20 .. 20 mm), with 10 lugs evenly spaced on its
// outer surface: radial bars across the whole width, 8 mm high (to r = 88 mm at their centre line) and
// 10 mm thick along the circumference (flat flanks parallel to the lug's centre plane).
// Tetrahedra of ~6 mm (about 2900 nodes).
// Physical groups (names the scene uses):
//   "rim"   : the inner cylindrical surface r = 60 mm (where the hub holds the wheel) -> solids[].fixed
//   "tread" : the whole outer surface: the ring between the lugs and the lugs' tops and flanks
//                                                                                    -> solids[].contact
//   "sides" : the two flat faces y = -20 mm and y = 20 mm
//   "wheel" : the volume
// pdemfem meshes this file itself when a scene names it (solids[].mesh: meshes/tread_wheel.geo); to look
// at it: gmsh tread_wheel.geo -3
SetFactory("OpenCASCADE");
inner_radius = 0.06; outer_radius = 0.08; width = 0.04;
lug_count = 10; lug_height = 0.008; lug_thickness = 0.01;
Mesh.CharacteristicLengthMax = 0.0063;   // m: 2939 nodes, 10368 tetrahedra (gmsh 4.15)

// The ring: a cylinder along y minus its bore.
Cylinder(1) = {0, -width / 2, 0, 0, width, 0, outer_radius};
Cylinder(2) = {0, -width / 2, 0, 0, width, 0, inner_radius};
ring() = BooleanDifference{ Volume{1}; Delete; }{ Volume{2}; Delete; };

// A lug along +x, sunk 1 mm into the ring so the union is clean (its inner corners, at
// r = sqrt(0.079^2 + 0.005^2) = 79.2 mm, lie inside the ring), then copies turned about the y axis.
sunk = 0.001;
lugs() = {};
For k In {0 : lug_count - 1}
  lug = newv;
  Box(lug) = {outer_radius - sunk, -width / 2, -lug_thickness / 2, lug_height + sunk, width, lug_thickness};
  Rotate {{0, 1, 0}, {0, 0, 0}, 2 * Pi * k / lug_count} { Volume{lug}; }
  lugs() += lug;
EndFor
wheel() = BooleanUnion{ Volume{ring()}; Delete; }{ Volume{lugs()}; Delete; };

eps = 1e-6;
rim() = Surface In BoundingBox{-inner_radius - eps, -width / 2 - eps, -inner_radius - eps,
                               inner_radius + eps, width / 2 + eps, inner_radius + eps};
reach = outer_radius + lug_height + 0.01;   // beyond every lug's corner
sides() = {Surface In BoundingBox{-reach, -width / 2 - eps, -reach, reach, -width / 2 + eps, reach},
           Surface In BoundingBox{-reach, width / 2 - eps, -reach, reach, width / 2 + eps, reach}};
tread() = Surface{:};
tread() -= {rim(), sides()};

Physical Surface("rim") = {rim()};
Physical Surface("tread") = {tread()};
Physical Surface("sides") = {sides()};
Physical Volume("wheel") = {wheel()};
