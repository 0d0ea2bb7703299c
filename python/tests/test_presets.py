"""`Image.compensate` bit-exact with `dynocomp compensate` on the
simulator's presets: the seed paper's six experiments (per-axis images) and
the plate dynamometer's three set-ups (3x3 images, crosstalk compensated).

Every reference file comes from the CLI: `simulate` writes the preset's
records and impact test, `design` the image (a plate set-up: see its test),
`compensate` the compensated record; the package only loads the image and compensates the CLI's own
measured record. Records are short (a fraction of a second) to keep the
tests fast. Each comparison has negative controls: one input sample moved
by one ADC step (on each axis in turn) gives other bits, and so does the
box's raw timing (latency not removed)."""

import os

import numpy as np
import pytest

import dynocomp
from conftest import ROOT, run_cli
from test_dynocomp import same_bits

PAPER = ["sine-1185", "chirp-650", "chirp-1300", "cut-1", "cut-2", "cut-3"]
PLATE = ["flat", "offcentre", "tall"]
# Seconds of cutting and idle record: enough for the filters' transients to
# pass and for idle to give R, short enough for the whole file to run in a
# few seconds.
DURATION, IDLE = 0.1, 0.05


def cli_case(tmp, flags, design_flags=(), image=None):
    """Simulate, design (unless `image` is given) and compensate with the
    CLI; returns (image path, the measured record, the CLI's compensated
    forces)."""
    run_cli("simulate", "--out", tmp, *flags, "--duration", DURATION, "--idle-duration", IDLE)
    measured = dynocomp.read_record(tmp / "measured.csv")
    if image is None:
        image = tmp / "c.dcimg"
        run_cli("design", "--frf", tmp / "frf.uff", "--fs", round(measured.fs), "--idle", tmp / "idle.csv",
                "--out", image, *design_flags)
    out = tmp / "compensated.csv"
    run_cli("compensate", "--coeffs", image, "--input", tmp / "measured.csv", "--output", out)
    return image, measured, dynocomp.read_record(out).forces


# One step of the simulator's ADC (16 bits over +-2000 N, its defaults): the
# smallest change the acquisition itself can make to a sample (N).
ADC_STEP_N = 2000.0 / 2**15


def one_adc_step(x, k, axis):
    """`x` with sample k of column `axis` moved up by one ADC step (a single
    f32 step can be lost in the f32 kernel's rounding of a large output)."""
    y = x.copy()
    y[k, axis] += ADC_STEP_N
    return y


def assert_bit_exact_with_controls(img_path, measured, want):
    img = dynocomp.Image.load(img_path)
    x = measured.forces
    got = img.compensate(x)
    assert got.shape == x.shape == want.shape
    assert np.all(np.isfinite(got))
    assert same_bits(got, want)
    # Negative control: one input sample, one ADC step away, on each axis
    # (the comparison sees a change that small on any column).
    k = x.shape[0] // 2
    for axis in range(x.shape[1]):
        assert not same_bits(img.compensate(one_adc_step(x, k, axis)), want), f"axis {axis}"
    assert not same_bits(img.compensate(x, raw_timing=True), want)
    return img, got


@pytest.mark.parametrize("preset", PAPER)
def test_paper_presets_are_bit_exact_with_the_cli(preset, tmp_path):
    img_path, measured, want = cli_case(tmp_path, ["--preset", preset])
    img, got = assert_bit_exact_with_controls(img_path, measured, want)
    assert img.axes == [0, 1, 2] and not img.parallel
    # Per-axis image: each output column depends on its own input column
    # only (the control of the plate test below, where it does not).
    x = measured.forces.copy()
    x[:, 0] = 0.0
    assert same_bits(img.compensate(x)[:, 1:], got[:, 1:])


@pytest.mark.parametrize("setup", PLATE)
def test_plate_presets_3x3_are_bit_exact_with_the_cli(setup, tmp_path):
    """The 3x3 image path on the plate set-ups' records. Designing a 3x3
    image takes about 20 s a set-up, so by default the bundled 3x3 image
    (fuzz/images/matrix.dcimg, 51.2 kHz) compensates each set-up's record;
    DYNOCOMP_SLOW_TESTS=1 designs each set-up's own image with the CLI."""
    flags = ["--dyno", "plate", "--dyno-preset", setup]
    if os.environ.get("DYNOCOMP_SLOW_TESTS") == "1":
        # A short impact test (513 lines of 8 Hz) and a fixed latency: the
        # 3x3 design's own cost is the fit and the choice of q.
        img_path, measured, want = cli_case(tmp_path, flags + ["--frf-lines", 513, "--frf-df", 8], ["--latency", 4])
    else:
        img_path, measured, want = cli_case(tmp_path, flags, image=ROOT / "fuzz" / "images" / "matrix.dcimg")
    assert dynocomp.Image.load(img_path).fs_hz == round(measured.fs)
    img, got = assert_bit_exact_with_controls(img_path, measured, want)
    # The 3x3 path: the bundled image has no model sidecar, so no smoother
    # (test_plate_3x3_smoother_is_bit_exact_with_the_cli has one)...
    if os.environ.get("DYNOCOMP_SLOW_TESTS") != "1":
        with pytest.raises(OSError, match="model sidecar"):
            img.compensate(measured.forces, offline=True)
    # ...and the x channel reaches the y and z outputs (crosstalk compensated),
    # which a per-axis image never does (the paper presets' test).
    x = measured.forces.copy()
    x[:, 0] = 0.0
    moved = img.compensate(x)
    assert not same_bits(moved[:, 1], got[:, 1]) and not same_bits(moved[:, 2], got[:, 2])


def test_plate_3x3_smoother_is_bit_exact_with_the_cli(tmp_path):
    """`offline=True` on a 3x3 image: the zero-lag smoother of the 3x3 model
    in the image's sidecar, the same bits as `compensate --offline`. A short
    impact test and a fixed latency keep the 3x3 design to a few seconds."""
    flags = ["--dyno", "plate", "--dyno-preset", "offcentre", "--frf-lines", 513, "--frf-df", 8]
    img_path, measured, _ = cli_case(tmp_path, flags, ["--latency", 4])
    out = tmp_path / "smoothed.csv"
    run_cli("compensate", "--coeffs", img_path, "--input", tmp_path / "measured.csv", "--output", out, "--offline")
    want = dynocomp.read_record(out).forces
    img = dynocomp.Image.load(img_path)
    x = measured.forces
    got = img.compensate(x, offline=True)
    assert got.shape == want.shape and same_bits(got, want)
    # Negative controls: the box's filter gives other bits, and so does one
    # ADC step on x, which reaches the y and z estimates too (crosstalk).
    assert not same_bits(img.compensate(x), want)
    moved = img.compensate(one_adc_step(x, x.shape[0] // 2, 0), offline=True)
    assert not same_bits(moved[:, 1], got[:, 1]) and not same_bits(moved[:, 2], got[:, 2])
