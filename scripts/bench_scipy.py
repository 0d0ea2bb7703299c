"""scipy reference of the offline compensator (run by scripts/bench_scipy.sh).

usage: bench_scipy.py FILTERS.json MEASURED.csv COMPENSATED_RAW.csv OURS.txt

FILTERS.json comes from `host-tools/examples/sos_export.rs`: per axis the
kernel's filter y = d*u + sum_i H_i(z) u + sum_j h_j u[k-j], with each 2x2
section H_i as a second-order transfer function (parallel form), and the
block-diagonal state space (A, B, C) of the sections.

1. Cross-check (an independent f64 computation of the same filter): scipy's
   parallel form (sosfilt per section + lfilter for the FIR) must agree with
   `dynocomp compensate --raw-timing` (the f32 kernel) to f32 rounding: at
   every sample within 16 f32 ulps (2^-24) of the sum of the magnitudes of
   the terms the kernel adds (|d u|, each section's output, each FIR
   product); exits 1 otherwise. The error is also shown relative to the
   output's peak-to-peak: where terms cancel, f32 rounding of the terms is
   large against the output.
2. Timing, best of 20 (dlsim: best of 2), all three axes of the 0.5 s record:
   - sosfilt, parallel form (the same filter: one sosfilt per section),
   - sosfilt, the sections alone as one cascade (no FIR; timing only: the
     cost of one sosfilt call over that many biquads),
   - sosfilt of the true cascade (zeros of the whole filter from the
     Rosenbrock pencil, zpk2sos), and its error, to show whether the cascade
     of this filter is well-conditioned,
   - dlsim of the state space (one axis, extrapolated),
   and the ratios against our compensate throughput from OURS.txt (and the
   kernel's per-sample `step`, the box's path, on the three axes).
"""

import json
import sys
import time

import numpy as np
import scipy
import scipy.linalg
import scipy.signal as sig


def best_of(fn, n=20):
    best = float("inf")
    for _ in range(n):
        t = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t)
    return best


def parallel(ax, u):
    y = ax["d"] * u
    for s in ax["sections"]:
        y = y + sig.sosfilt(np.array([s]), u)
    if ax["fir"]:
        y = y + sig.lfilter(np.concatenate([[0.0], ax["fir"]]), [1.0], u)
    return y


def term_scale(ax, u):
    """Per sample, the sum of the magnitudes of the terms the kernel adds up:
    |d u| + sum_i |section i's output| + sum_j |h_j u[k-j]|."""
    s = np.abs(ax["d"] * u)
    for sec in ax["sections"]:
        s = s + np.abs(sig.sosfilt(np.array([sec]), u))
    for j, h in enumerate(ax["fir"], start=1):
        s[j:] = s[j:] + np.abs(h * u[:-j])
    return s


def state_space(ax):
    """Sections plus the FIR delay chain as one (A, B, C, D)."""
    a_s = np.array(ax["A"], dtype=float).reshape(-1, len(ax["B"])) if ax["B"] else np.zeros((0, 0))
    n = a_s.shape[0]
    m = len(ax["fir"])
    a = np.zeros((n + m, n + m))
    a[:n, :n] = a_s
    b = np.zeros((n + m, 1))
    b[:n, 0] = ax["B"]
    c = np.zeros((1, n + m))
    c[0, :n] = ax["C"]
    if m:
        b[n, 0] = 1.0
        for j in range(1, m):
            a[n + j, n + j - 1] = 1.0
        c[0, n:] = ax["fir"]
    d = np.array([[ax["d"]]])
    return a, b, c, d


def true_cascade(ax):
    a, b, c, d = state_space(ax)
    n = a.shape[0]
    # Invariant zeros: finite generalized eigenvalues of the Rosenbrock pencil.
    m_pencil = np.block([[a, b], [c, d]])
    n_pencil = np.zeros_like(m_pencil)
    n_pencil[:n, :n] = np.eye(n)
    w = scipy.linalg.eigvals(m_pencil, n_pencil)
    zeros = w[np.isfinite(w) & (np.abs(w) < 1e8)]
    poles = np.linalg.eigvals(a)
    z0 = np.exp(0.3j)
    h = (c @ np.linalg.solve(z0 * np.eye(n) - a, b))[0, 0] + d[0, 0]
    k = h / (np.prod(z0 - zeros) / np.prod(z0 - poles))
    return sig.zpk2sos(zeros, poles, np.real(k))


def main():
    filt = json.load(open(sys.argv[1]))
    meas = np.genfromtxt(sys.argv[2], delimiter=",", names=True)
    comp = np.genfromtxt(sys.argv[3], delimiter=",", names=True)
    ours = {}
    for line in open(sys.argv[4]):
        parts = line.split()
        if parts and parts[0] == "compensate_samples_per_s":
            ours[int(parts[1])] = float(parts[2])
        if parts and parts[0] == "step_kernel_samples_per_s":
            ours["step"] = float(parts[2])
    names = ["fx", "fy", "fz"]
    axes = filt["axes"]
    inputs = [np.asarray(meas[names[ax["axis"]]], dtype=float) for ax in axes]
    n = len(inputs[0])
    print(f"scipy {scipy.__version__}, numpy {np.__version__}; {len(axes)} axes x {n} samples")

    ok = True
    print("cross-check, scipy parallel form (f64) vs dynocomp compensate (f32 kernel):")
    for ax, u in zip(axes, inputs):
        y_ref = parallel(ax, u)
        y_ours = np.asarray(comp[names[ax["axis"]]], dtype=float)
        diff = np.abs(y_ref - y_ours)
        scale = term_scale(ax, u)
        # f32 rounding of a sum of terms: a few ulps (2^-24) of the terms'
        # magnitudes; 16 ulps leave room for rounding in the section states.
        ulps = np.max(diff / (scale * 2.0**-24))
        good = ulps <= 16
        ok &= bool(good)
        print(f"  f{'xyz'[ax['axis']]}: {len(ax['sections'])} sections + {len(ax['fir'])} taps: "
              f"max |diff| = {np.max(diff):.2e} N = {np.max(diff) / np.ptp(y_ref):.1e} of peak-to-peak, "
              f"{ulps:.1f} f32 ulps of the terms' magnitude ({'ok' if good else 'FAIL'}, limit 16); "
              f"terms up to {np.max(scale):.3g} N for an output peak-to-peak of {np.ptp(y_ref):.3g} N")

    samples = n * len(axes)
    t_par = best_of(lambda: [parallel(ax, u) for ax, u in zip(axes, inputs)])
    casc = [np.array(ax["sections"]) for ax in axes]
    t_same_order = best_of(lambda: [sig.sosfilt(s, u) for s, u in zip(casc, inputs)])
    try:
        true_sos = [true_cascade(ax) for ax in axes]
        t_true = best_of(lambda: [sig.sosfilt(s, u) for s, u in zip(true_sos, inputs)])
        errs = []
        for ax, u, s in zip(axes, inputs, true_sos):
            y_ref = parallel(ax, u)
            errs.append(np.max(np.abs(sig.sosfilt(s, u) - y_ref)) / np.ptp(y_ref))
    except ValueError as e:  # zpk2sos: unpaired complex roots
        print(f"  true cascade could not be built: {e}")
        t_true, errs = float("nan"), []
    a, b, c, d = state_space(axes[0])
    n_dl = min(n, 5000)
    t_dl = best_of(lambda: sig.dlsim((a, b, c, d, 1.0), inputs[0][:n_dl]), n=2) * n / n_dl * len(axes)

    rate_ours = ours.get(3)
    print(f"our compensate (3 axes, in memory): {rate_ours:.3e} samples/s" if rate_ours else "our compensate: missing")
    if "step" in ours:
        print(f"our kernel, per-sample step (the box's path), 3 axes: {ours['step']:.3e} samples/s")
    rows = [
        ("sosfilt, parallel form (same filter)", t_par),
        ("sosfilt, the sections as one cascade, no FIR (timing only)", t_same_order),
        ("sosfilt, true cascade (zpk2sos)", t_true),
        ("dlsim (extrapolated from 5000 samples)", t_dl),
    ]
    for name, t in rows:
        rate = samples / t
        ratio = f"{rate_ours / rate:8.1f}x" if rate_ours else "   n/a"
        lock = f", step/scipy = {ours['step'] / rate:6.1f}x" if "step" in ours else ""
        print(f"  {name:<58} {rate:10.3e} samples/s   ours/scipy = {ratio}{lock}")
    print("  true cascade max |diff| / peak-to-peak per axis: " + ", ".join(f"{e:.1e}" for e in errs))
    if not ok:
        print("cross-check FAILED")
        sys.exit(1)


if __name__ == "__main__":
    main()
