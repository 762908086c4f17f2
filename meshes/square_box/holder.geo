// The square box's blank holder: the plane z = 0 outside a rounded-square opening
// (opening_mm x opening_mm, corner radius corner_mm) around the punch (square_box.py: a 100 mm
// square with 20 mm corners, 5 mm foot radius), 20 mm clear of its wall all round (the corner
// radius concentric with the punch's), out beyond the blank. A node is under the holder when
// its closest point is not on the plate's edges.
DefineConstant[
  opening_mm = 140.0,
  corner_mm = 40.0,
  outer_mm = 280.0,
  mesh_mm = 5.0
];
SetFactory("OpenCASCADE");
Rectangle(1) = {-outer_mm / 2, -outer_mm / 2, 0, outer_mm, outer_mm};
Rectangle(2) = {-opening_mm / 2, -opening_mm / 2, 0, opening_mm, opening_mm, corner_mm};
BooleanDifference{ Surface{1}; Delete; }{ Surface{2}; Delete; }
Mesh.MeshSizeMax = mesh_mm;
