# t_s plus three sines with noise, %.6f: a 3-axis force record at 51.2 kHz.
import sys, math, random
n = int(sys.argv[1]); fs = 51200.0
random.seed(1)
w = sys.stdout.write
w("t_s,fx,fy,fz\n")
for k in range(n):
    t = k / fs
    w("%.9f,%.6f,%.6f,%.6f\n" % (t, 100*math.sin(2*math.pi*1100*t) + random.gauss(0, .3), 50*math.sin(2*math.pi*2200*t) + random.gauss(0, .3), 200 + 80*math.sin(2*math.pi*1100*t+1) + random.gauss(0, .3)))
