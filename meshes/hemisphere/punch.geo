// The paper's hemisphere punch (section 4.1) at its start position: apex at z = 0 on the
// z axis, the shoulder (base plane) at z = -(R + Rf), moving +z by travel_mm (case.toml).
// Same numbers and construction as fenicsx_drape.forming.tools.HemisphereTools: a spherical
// cap of radius R whose centre is Rf above the base plane, a concave fillet of radius Rf to
// the flat shoulder, the shoulder out to shoulder_radius_mm where an edge round of radius
// edge_radius_mm turns into the cylindrical side wall (side_wall_mm deep; the closed form's
// wall is endless, the sheet never reaches below the shoulder). Only the outer surface is
// meshed (an open surface; its normals are turned towards the sheet by the loader).
// Numbers can be set from outside: gmsh -setnumber punch_radius_mm 50, or the case file's
// parameters (fenicsx_drape.forming.surfaces.load_surface).
DefineConstant[
  punch_radius_mm = 60.0,      // R: radius of the cap
  fillet_radius_mm = 20.0,     // Rf: radius of the concave fillet
  shoulder_radius_mm = 84.0,   // outer radius of the flat shoulder (inside the opening)
  edge_radius_mm = 1.0,        // round between the shoulder and the side wall
  side_wall_mm = 10.0,         // depth of the cylindrical side wall below the shoulder
  mesh_mm = 2.0                // largest triangle (load_surface's mesh_size_mm overrides it)
];
SetFactory("OpenCASCADE");
R = punch_radius_mm; Rf = fillet_radius_mm; rs = shoulder_radius_mm; re = edge_radius_mm;
H = R + Rf;                    // apex-to-base height
zb = -H;                       // the base plane at the start
Point(1) = {0, 0, zb + Rf + R};          // apex
Point(2) = {0, 0, zb + Rf};              // centre of the cap
Point(3) = {R, 0, zb + Rf};              // cap -> fillet (vertical tangent)
Point(4) = {R + Rf, 0, zb + Rf};         // centre of the fillet
Point(5) = {R + Rf, 0, zb};              // fillet -> shoulder
Point(6) = {rs - re, 0, zb};             // shoulder -> edge round
Point(7) = {rs - re, 0, zb - re};        // centre of the edge round
Point(8) = {rs, 0, zb - re};             // edge round -> side wall
Point(9) = {rs, 0, zb - side_wall_mm};   // bottom of the side wall
Circle(1) = {1, 2, 3};
Circle(2) = {3, 4, 5};
Line(3) = {5, 6};
Circle(4) = {6, 7, 8};
Line(5) = {8, 9};
Extrude {{0, 0, 1}, {0, 0, 0}, 2 * Pi} { Curve{1:5}; }
Mesh.MeshSizeMax = mesh_mm;
Mesh.MeshSizeFromCurvature = 16;         // the 1 mm edge round gets ~0.4 mm triangles
