#1 = 2
#2 = [#1 * 3 + 1]
#<len> = [#2 - #1]
G0 X#1 Y#2 Z#<len>
#1 = 3 #4 = #1
G1 X#4 Y[#1 ** 2] F[10*10]
G1 X[ATAN[1]/[1]] Y[SQRT[16] + ABS[-1]] Z[FIX[2.7] + FUP[0.2] + ROUND[1.5]]
G1 X[SIN[30]*2] Y[COS[60]] Z[-7 MOD 3]
G1 X[1 EQ 1] Y[2 GT 3] Z[[1 LT 2] AND [0 OR 1]]
#5 = 2
G1 X#[1+1] Y##5 Z[2 + 3 * 4 - 6 / 2]
G1 X[-#1] Y-#1 Z[2 ** 3 ** 2]
G1 X[EXISTS[#<len>]] Y[EXISTS[#<nope>]] Z[1 XOR 1]
