#!/usr/bin/env bash
# Same-run comparison of two dynocomp builds on the 1-minute record (issue #14).
# usage: bench_io.sh OLD NEW   (run in a folder holding ex.dcimg, min1.csv, min1.tdms):
#   B=target/release/dynocomp
#   $B design --frf data/example/frf.uff --fs 51200 --idle data/example/idle.csv --out ex.dcimg
#   python3 scripts/gen_record.py 3072000 > min1.csv
#   $B compensate --coeffs ex.dcimg --input min1.csv --output min1.tdms --output-format tdms
#     (min1.tdms is then a compensated record; as an input it costs the same)
# Prints: build, path, wall s, user s, sys s, peak RSS KB.
O=$1; N=$2; out=/dev/shm
for i in 1 2 3; do
  for b in old new; do
    if [ $b = old ]; then B=$O; else B=$N; fi
    /usr/bin/time -f "$b csv->csv  %e %U %S %M" $B compensate --coeffs ex.dcimg --input min1.csv --output $out/o.csv 2>&1 | tail -1
    /usr/bin/time -f "$b csv->tdms %e %U %S %M" $B compensate --coeffs ex.dcimg --input min1.csv --output $out/o.tdms --output-format tdms 2>&1 | tail -1
    /usr/bin/time -f "$b tdms->tdms %e %U %S %M" $B compensate --coeffs ex.dcimg --input min1.tdms --output $out/o2.tdms 2>&1 | tail -1
  done
done
rm -f $out/o.csv $out/o.tdms $out/o2.tdms
