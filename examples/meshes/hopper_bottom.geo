// The hopper's floor at z = 0: two plates leaving a 20 mm slot across the bin's depth,
// centred at x = 30 mm.
// Written by benchmarks/hopper_discharge.py (write_example_meshes); pdemfem meshes it when a scene
// names it (walls[].file).  To look at it: gmsh hopper_bottom.geo -2
Point(1) = {0, 0, 0};
Point(2) = {0.02, 0, 0};
Point(3) = {0.02, 0.03, 0};
Point(4) = {0, 0.03, 0};
Line(1) = {1, 2};
Line(2) = {2, 3};
Line(3) = {3, 4};
Line(4) = {4, 1};
Curve Loop(1) = {1, 2, 3, 4};
Plane Surface(1) = {1};
Transfinite Curve{1, 2, 3, 4} = 2;
Transfinite Surface{1};
Point(5) = {0.04, 0, 0};
Point(6) = {0.06, 0, 0};
Point(7) = {0.06, 0.03, 0};
Point(8) = {0.04, 0.03, 0};
Line(5) = {5, 6};
Line(6) = {6, 7};
Line(7) = {7, 8};
Line(8) = {8, 5};
Curve Loop(2) = {5, 6, 7, 8};
Plane Surface(2) = {2};
Transfinite Curve{5, 6, 7, 8} = 2;
Transfinite Surface{2};
