#!/usr/bin/env python3
"""The last L samples of a latency-removed output against the simulator's
true force (BENCHMARKS.md, "The last L samples of a latency-removed output").

For simulate seeds 11 and 12 at 10.24, 25.6 and 102.4 kHz: simulate, design,
then cut measured.csv at 12 places and compensate each prefix; the RMS error
of its last L outputs is compared with the body's, and with the last value
held as the look-ahead (the control: L copies appended, --raw-timing).
Needs numpy and `cargo build --release -p dynocomp`. Work files: /tmp/tail.
"""
import os
import re
import subprocess

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
B = os.path.join(ROOT, "target", "release", "dynocomp")
WORK = "/tmp/tail"


def load(p):
    return np.loadtxt(p, delimiter=",", skiprows=1)


def comp(img, arr, raw):
    inp, out = os.path.join(WORK, "in.csv"), os.path.join(WORK, "o.csv")
    np.savetxt(inp, arr, delimiter=",", header="t_s,fx,fy,fz", comments="", fmt="%.9g")
    args = [B, "compensate", "--coeffs", img, "--input", inp, "--output", out]
    subprocess.run(args + (["--raw-timing"] if raw else []), check=True, capture_output=True)
    return load(out)


def setup(fs, seed):
    d = os.path.join(WORK, f"s{fs}_{seed}")
    img = os.path.join(d, "c.dcimg")
    if not os.path.exists(img):
        sim = [B, "simulate", "--dyno", "diagonal", "--out", d, "--fs", str(fs), "--seed", str(seed), "--duration", "0.5"]
        subprocess.run(sim, check=True, capture_output=True)
        des = [B, "design", "--frf", f"{d}/frf.uff", "--fs", str(fs), "--idle", f"{d}/idle.csv", "--out", img]
        subprocess.run(des, check=True, capture_output=True)
    return d, img


def main():
    os.makedirs(WORK, exist_ok=True)
    for fs in (10240, 25600, 102400):
        for seed in (11, 12):
            d, img = setup(fs, seed)
            text = subprocess.run([B, "inspect", img], capture_output=True, text=True).stdout
            lat = int(re.search(r"latency (\d+)", text).group(1))
            m, t = load(f"{d}/measured.csv"), load(f"{d}/true_force.csv")
            n = len(m)
            ends = [int(n * 0.4) + int(i * n * 0.55 / 12) for i in range(12)]
            tp, th = np.zeros(3), np.zeros(3)
            for e in ends:
                y = comp(img, m[:e], False)
                tp += ((y[e - lat:e, 1:] - t[e - lat:e, 1:]) ** 2).sum(0)
                h = np.vstack([m[:e]] + [m[e - 1:e]] * lat)
                h[:, 0] = np.arange(len(h)) * (m[1, 0] - m[0, 0])
                yh = comp(img, h, True)[lat:]
                th += ((yh[e - lat:e, 1:] - t[e - lat:e, 1:]) ** 2).sum(0)
            body = np.sqrt(((y[n // 5:ends[-1] - lat, 1:] - t[n // 5:ends[-1] - lat, 1:]) ** 2).mean(0))
            pred, held = np.sqrt(tp / 12 / lat), np.sqrt(th / 12 / lat)
            print(f"{fs} Hz seed {seed} L {lat}: body {np.round(body, 2)} N, last L predicted "
                  f"{np.round(pred, 2)} N ({np.round(pred / body, 2)}x), held {np.round(held, 2)} N")


if __name__ == "__main__":
    main()
