// The matched die of the hemisphere (not in the paper; HemisphereTools.die): the punch's
// part surface offset outwards by the ply thickness, fixed at the punch's final position
// (base plane at z = travel_mm - (R + Rf), i.e. z = 0 for the paper's 80 mm), its material
// above. The offset cap (radius R + t), the offset fillet (radius Rf - t: the die's convex
// lip, the entry radius the sheet is drawn over) and the flat face z = t out to
// outer_radius_mm (the closed form's face is endless; beyond the holder's opening the sheet
// is clamped at z = 0, below the face, so 15 mm past the opening is enough and keeps the
// distance field's grid small). An open surface: the loader turns its normals towards the
// sheet (-z).
DefineConstant[
  punch_radius_mm = 60.0,
  fillet_radius_mm = 20.0,
  ply_thickness_mm = 0.3,      // t: the gap between punch and die when closed
  travel_mm = 80.0,            // punch travel: the die sits at the punch's final position
  holder_opening_mm = 170.0,   // diameter of the blank holder's opening
  outer_radius_mm = 0.5 * holder_opening_mm + 15.0,
  mesh_mm = 2.0
];
SetFactory("OpenCASCADE");
R = punch_radius_mm; Rf = fillet_radius_mm; t = ply_thickness_mm;
zb = travel_mm - (R + Rf);     // the punch's base plane at the end
Point(1) = {0, 0, zb + Rf + R + t};      // apex of the offset cap
Point(2) = {0, 0, zb + Rf};
Point(3) = {R + t, 0, zb + Rf};
Point(4) = {R + Rf, 0, zb + Rf};
Point(5) = {R + Rf, 0, zb + t};
Point(6) = {outer_radius_mm, 0, zb + t};
Circle(1) = {1, 2, 3};
Circle(2) = {3, 4, 5};
Line(3) = {5, 6};
Extrude {{0, 0, 1}, {0, 0, 0}, 2 * Pi} { Curve{1:3}; }
Mesh.MeshSizeMax = mesh_mm;
Mesh.MeshSizeFromCurvature = 16;
