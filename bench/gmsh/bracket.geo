// An L-shaped steel bracket for the unstructured FEM peer case (bench/README.md, case tet10):
// a base plate 200 x 100 x 20 mm with three bolt holes, an upright 20 x 100 x 150 mm with a
// cable hole, clamped on its back face x = 0, a pressure on the base's top face. Meshed by
// Gmsh in 10-node tetrahedra; both codes read the same nodes (compare.sh):
//   gmsh -3 -order 2 -setnumber h 0.004 -format msh41 bracket.geo -o bracket.msh
// Physical groups: volume "part", surfaces "fixed" (x = 0) and "loaded" (z = 20 mm, x > 20 mm).
SetFactory("OpenCASCADE");
If (!Exists(h))
  h = 0.004;
EndIf
Box(1) = {0, 0, 0, 0.2, 0.1, 0.02};
Box(2) = {0, 0, 0, 0.02, 0.1, 0.15};
Cylinder(3) = {0.08, 0.03, -0.01, 0, 0, 0.04, 0.008};
Cylinder(4) = {0.08, 0.07, -0.01, 0, 0, 0.04, 0.008};
Cylinder(5) = {0.15, 0.05, -0.01, 0, 0, 0.04, 0.008};
Cylinder(6) = {-0.01, 0.05, 0.1, 0.04, 0, 0, 0.015};
BooleanUnion(7) = { Volume{1}; Delete; }{ Volume{2}; Delete; };
BooleanDifference(8) = { Volume{7}; Delete; }{ Volume{3, 4, 5, 6}; Delete; };
eps = 1e-6;
fixed() = Surface In BoundingBox {-eps, -eps, -eps, eps, 0.1 + eps, 0.15 + eps};
loaded() = Surface In BoundingBox {0.02 - eps, -eps, 0.02 - eps, 0.2 + eps, 0.1 + eps, 0.02 + eps};
Physical Volume("part") = {8};
Physical Surface("fixed") = {fixed()};
Physical Surface("loaded") = {loaded()};
Mesh.CharacteristicLengthMax = h;
Mesh.CharacteristicLengthMin = h / 2;
Mesh.ElementOrder = 2;
Mesh.Optimize = 1;
