// Strip 1 of the hopper's measured wall at x = 60 mm: z = 10 .. 20 mm.
// Written by benchmarks/hopper_discharge.py (write_example_meshes); pdemfem meshes it when a scene
// names it (walls[].file).  To look at it: gmsh hopper_strip_1.geo -2
Point(1) = {0.06, 0, 0.01};
Point(2) = {0.06, 0.03, 0.01};
Point(3) = {0.06, 0.03, 0.02};
Point(4) = {0.06, 0, 0.02};
Line(1) = {1, 2};
Line(2) = {2, 3};
Line(3) = {3, 4};
Line(4) = {4, 1};
Curve Loop(1) = {1, 2, 3, 4};
Plane Surface(1) = {1};
Transfinite Curve{1, 2, 3, 4} = 2;
Transfinite Surface{1};
