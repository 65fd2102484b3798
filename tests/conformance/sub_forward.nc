G0 X0 Y0 Z0
o<square> call [2]
M2
o<square> sub
  G1 X#1 F10
  G1 Y#1
  G1 X0
  G1 Y0
o<square> endsub
