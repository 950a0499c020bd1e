// Strip 7 of the hopper's measured wall at x = 60 mm: z = 70 .. 80 mm.
// Written by benchmarks/hopper_discharge.py (write_example_meshes); pdemfem meshes it when a scene
// names it (walls[].file).  To look at it: gmsh hopper_strip_7.geo -2
Point(1) = {0.06, 0, 0.07};
Point(2) = {0.06, 0.03, 0.07};
Point(3) = {0.06, 0.03, 0.08};
Point(4) = {0.06, 0, 0.08};
Line(1) = {1, 2};
Line(2) = {2, 3};
Line(3) = {3, 4};
Line(4) = {4, 1};
Curve Loop(1) = {1, 2, 3, 4};
Plane Surface(1) = {1};
Transfinite Curve{1, 2, 3, 4} = 2;
Transfinite Surface{1};
