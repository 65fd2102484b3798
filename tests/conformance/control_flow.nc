o100 sub
  G1 X#1 Y#2 F100
  o100 return [#1 + #2]
o100 endsub
G0 X0 Y0 Z0
o100 call [1] [2]
G1 X#<_value> F100
#1 = 0
o200 while [#1 LT 3]
  #1 = [#1 + 1]
  G1 Y#1
o200 endwhile
o300 if [#1 EQ 2]
  G1 Z-1
o300 elseif [#1 EQ 3]
  G1 Z-2
o300 else
  G1 Z-3
o300 endif
o400 repeat [2]
  G91 G1 X1
  G90
o400 endrepeat
#2 = 0
o500 do
  #2 = [#2 + 1]
  o600 if [#2 EQ 2]
    o500 continue
  o600 endif
  G1 X[10 + #2]
  o700 if [#2 GE 3]
    o500 break
  o700 endif
o500 while [#2 LT 5]
G0 Z5
M30
G0 X99
