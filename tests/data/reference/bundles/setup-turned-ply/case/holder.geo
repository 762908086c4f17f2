// The double dome's blank holder: the plane z = 0 outside a rounded-rectangle opening
// (opening_length_mm x opening_width_mm, corner radius corner_mm) around the domes' footprint
// (double_dome.py: |x| <= dome_centre + dome_radius = 100 mm, |y| <= 60 mm), out beyond the
// blank. A node is under the holder when its closest point is not on the plate's edges.
DefineConstant[
  opening_length_mm = 230.0,
  opening_width_mm = 150.0,
  corner_mm = 15.0,
  outer_length_mm = 340.0,
  outer_width_mm = 240.0,
  mesh_mm = 5.0
];
SetFactory("OpenCASCADE");
Rectangle(1) = {-outer_length_mm / 2, -outer_width_mm / 2, 0, outer_length_mm, outer_width_mm};
Rectangle(2) = {-opening_length_mm / 2, -opening_width_mm / 2, 0, opening_length_mm,
                opening_width_mm, corner_mm};
BooleanDifference{ Surface{1}; Delete; }{ Surface{2}; Delete; }
Mesh.MeshSizeMax = mesh_mm;
