// The blank holder's clamping surface (section 4.1): the plane z = 0 outside the circular
// opening of holder_opening_mm (170 mm), out to outer_radius_mm (default 0.75 sheet_mm,
// beyond the sheet's corners). A node is under the holder when its closest point on this
// annulus is not on its edges (MeshedTool.covers): r > 85 mm on the sheet's plane, as the
// closed-form holder (fenicsx_drape.forming.holder). It does not move.
DefineConstant[
  holder_opening_mm = 170.0,
  sheet_mm = 240.0,
  outer_radius_mm = 0.75 * sheet_mm,
  mesh_mm = 4.0
];
SetFactory("OpenCASCADE");
Disk(1) = {0, 0, 0, outer_radius_mm};
Disk(2) = {0, 0, 0, 0.5 * holder_opening_mm};
BooleanDifference{ Surface{1}; Delete; }{ Surface{2}; Delete; }
Mesh.MeshSizeMax = mesh_mm;
