"""Benchmarks of the Python package (BENCHMARKS.md, "From Python"), not
timed tests. Run from the repository's root after scripts/python_test.sh:

    target/python-venv/bin/python python/benchmarks/bench.py

1. compensate from numpy (box mode, in memory) vs the Rust kernel alone on
   the same record, in one run: the bundled measured record tiled to
   N samples per axis, best of R runs each.
2. design from Python vs the CLI (`dynocomp design`, a new process), same
   inputs, no report, best of RD runs each, the two interleaved; and the
   Python layer's own cost around the design call (the call stubbed).
"""

import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import dynocomp

ROOT = Path(__file__).resolve().parents[2]
EX = ROOT / "data" / "example"
CLI = Path(os.environ.get("DYNOCOMP_BIN", ROOT / "target" / "release" / "dynocomp"))
N = int(os.environ.get("BENCH_SAMPLES", 4_000_000))
R = int(os.environ.get("BENCH_RUNS", 5))
RD = int(os.environ.get("BENCH_DESIGN_RUNS", 5))


def best(f, runs=R):
    ts = []
    for _ in range(runs):
        t0 = time.perf_counter()
        f()
        ts.append(time.perf_counter() - t0)
    return min(ts)


def main():
    with tempfile.TemporaryDirectory() as tmp:
        img_path = Path(tmp) / "example.dcimg"
        argv = [str(CLI), "design", "--frf", str(EX / "frf.uff"), "--fs", "51200",
                "--idle", str(EX / "idle.csv"), "--out", str(img_path)]
        subprocess.run(argv, check=True, capture_output=True)
        img = dynocomp.Image.load(img_path)
        x = dynocomp.read_record(EX / "measured.csv").forces
        x = np.asfortranarray(np.tile(x, (N // x.shape[0] + 1, 1))[:N])
        samples = x.size
        t_py = best(lambda: img.compensate(x))
        t_k = min(img._kernel_seconds(x) for _ in range(R))
        print(f"compensate, box mode, {N} samples x 3 axes ({samples / 1e6:.0f} M samples), best of {R}:")
        print(f"  from numpy (float64, F order): {t_py * 1e3:8.1f} ms  {samples / t_py / 1e6:7.1f} M samples/s")
        print(f"  Rust kernel alone:             {t_k * 1e3:8.1f} ms  {samples / t_k / 1e6:7.1f} M samples/s")
        print(f"  ratio numpy / kernel: {t_py / t_k:.2f}")
        xc = np.ascontiguousarray(x)
        t_c = best(lambda: img.compensate(xc))
        print(f"  from numpy (float64, C order): {t_c * 1e3:8.1f} ms  ratio {t_c / t_k:.2f}")

        frf = dynocomp.read_frf(EX / "frf.uff")
        timed = {
            "py": lambda: dynocomp.design(frf, fs=51200, idle=EX / "idle.csv", report=False),
            "cli": lambda: subprocess.run(argv, check=True, capture_output=True),
        }
        # Interleaved, so that a change in the machine's load reaches both;
        # wall time, and CPU time (user + sys of every thread: this process's
        # for Python, the child's for the CLI), which a loaded machine
        # disturbs far less.
        t = {k: [] for k in timed}
        cpu = {k: [] for k in timed}
        who = {"py": resource.RUSAGE_SELF, "cli": resource.RUSAGE_CHILDREN}
        for _ in range(RD):
            for k, f in timed.items():
                c0 = cpu_seconds(who[k])
                t[k].append(best(f, runs=1))
                cpu[k].append(cpu_seconds(who[k]) - c0)
        t_dpy, t_dcli = min(t["py"]), min(t["cli"])
        c_py, c_cli = min(cpu["py"]), min(cpu["cli"])
        print(f"design (bundled example, no report), best of {RD}, interleaved:")
        print(f"  wall: from Python: {t_dpy:.3f} s   CLI: {t_dcli:.3f} s   ratio {t_dpy / t_dcli:.2f}")
        print(f"  CPU:  from Python: {c_py:.3f} s   CLI: {c_cli:.3f} s   ratio {c_py / c_cli:.2f}")
        t_layer = python_layer_seconds(frf, img_path)
        print(f"  the Python layer alone (temporary directory, image and sidecar written and read back, "
              f"JSON parsed; the design call stubbed), best of 20: {t_layer * 1e3:.2f} ms")


def cpu_seconds(who):
    r = resource.getrusage(who)
    return r.ru_utime + r.ru_stime


def python_layer_seconds(frf, img_path):
    """`dynocomp.design`'s own cost around the design call: the extension's
    call replaced by a stub that writes an existing image, sidecar and
    summary where the design would."""
    summary = subprocess.run([str(CLI), "inspect", "--json", str(img_path)], check=True,
                             capture_output=True, text=True).stdout
    side = dynocomp._dynocomp.sidecar_path(str(img_path))
    image, sidecar = img_path.read_bytes(), Path(side).read_bytes()

    def stub(argv):
        out = argv[argv.index("--out") + 1]
        Path(out).write_bytes(image)
        Path(dynocomp._dynocomp.sidecar_path(out)).write_bytes(sidecar)
        return summary

    real = dynocomp._rs.design_cli
    dynocomp._rs.design_cli = stub
    try:
        return best(lambda: dynocomp.design(frf, fs=51200, idle=EX / "idle.csv", report=False), runs=20)
    finally:
        dynocomp._rs.design_cli = real

if __name__ == "__main__":
    sys.exit(main())
