(Reference case 5, seeds/003: assembly error of a 4-axis machine)
(Side milling with a 6 mm flat end mill on the xyza machine: a face cut)
(at A0 with the tool at Y-25, then one at A180 with the tool at Y+25,)
(each on its own stretch of X. With dy_AY = -0.50 mm in the job the two)
(faces end up 2 |dy| = 1.00 mm apart; without it they line up.)
G21 G90 G94
G0 X-4 Y-25 Z20 A0
G0 Z-5
G1 X9 F300
G0 Z20
G0 A180
G0 X11 Y25 Z20
G1 Z-5 F300
G1 X24
G0 Z20
M30
