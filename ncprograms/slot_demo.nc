(Demo for the comparison picture: the target's slot, 2 mm wide, 0.1 mm deep)
(cut with a 2 mm flat end mill 5 um too deep up to X3, 5 um too shallow)
(from X4.5: overcut red, undercut blue, in tolerance grey)
G21 G90 G17
G0 X-2 Y0 Z1
G1 Z-0.105 F100
G1 X3
G1 Z-0.1
G1 X4.5
G1 Z-0.095
G1 X8
G0 Z1
M30
