"""The Python package against the CLI on the bundled example: the CLI's
outputs are the reference (the package must give the same bits), and every
comparison has a negative control that shows it can fail."""

import json

import numpy as np
import pytest

import dynocomp
from conftest import EXAMPLE, FS, ROOT, cli_error, run_cli


def bits(a):
    """The exact bits of a float64 array (NaN-safe, -0.0 ≠ 0.0)."""
    return np.ascontiguousarray(a, dtype=np.float64).view(np.uint64)


def same_bits(a, b):
    return a.shape == b.shape and np.array_equal(bits(a), bits(b))


@pytest.fixture(scope="module")
def measured():
    return dynocomp.read_record(EXAMPLE / "measured.csv")


# --- compensate: bit-exact with `dynocomp compensate` ----------------------


def test_compensate_is_bit_exact_with_the_cli(cli_design, cli_compensated, measured):
    img = dynocomp.Image.load(cli_design[0])
    want = dynocomp.read_record(cli_compensated).forces
    got = img.compensate(measured.forces)
    assert got.shape == measured.forces.shape == want.shape
    assert same_bits(got, want)
    # Negative controls: the box's timing (latency kept), and one input
    # sample changed by one f32 step, both give other bits.
    assert not same_bits(img.compensate(measured.forces, raw_timing=True), want)
    x = measured.forces.copy()
    k = x.shape[0] // 2
    x[k, 0] = np.nextafter(np.float32(x[k, 0]), np.float32(np.inf), dtype=np.float32)
    assert not same_bits(img.compensate(x), want)


def test_any_float_layout_gives_the_same_bits(cli_design, measured):
    img = dynocomp.Image.load(cli_design[0])
    ref = img.compensate(measured.forces)
    c = np.ascontiguousarray(measured.forces)
    f = np.asfortranarray(measured.forces)
    assert c.flags.c_contiguous and f.flags.f_contiguous
    assert same_bits(img.compensate(c), ref)
    assert same_bits(img.compensate(f), ref)
    # float32: the kernel's own input precision, so the same bits.
    assert same_bits(img.compensate(measured.forces.astype(np.float32)), ref)
    # A strided view (every column of a wider array) is read in place.
    wide = np.zeros((c.shape[0], 6))
    wide[:, ::2] = c
    assert same_bits(img.compensate(wide[:, ::2]), ref)
    # One channel alone, 1-D, with its axis named.
    assert same_bits(img.compensate(c[:, 1], axes="y"), ref[:, 1])
    assert same_bits(img.compensate(c[:, [0, 2]], axes="xz"), ref[:, [0, 2]])


def test_offline_smoother_matches_the_cli(cli_design, measured, tmp_path):
    img_path = cli_design[0]
    out = tmp_path / "smoothed.csv"
    run_cli("compensate", "--coeffs", img_path, "--input", EXAMPLE / "measured.csv", "--output", out, "--offline")
    want = dynocomp.read_record(out).forces
    img = dynocomp.Image.load(img_path)
    got = img.compensate(measured.forces, offline=True)
    assert same_bits(got, want)
    # Negative control: the box's causal filter is not the smoother.
    assert not same_bits(img.compensate(measured.forces), want)
    # The same image from bytes with its sidecar text gives the same.
    side = (img_path.parent / (img_path.name + ".model.json")).read_text()
    again = dynocomp.Image.from_bytes(img_path.read_bytes(), side)
    assert same_bits(again.compensate(measured.forces, offline=True), want)


# --- streaming --------------------------------------------------------------


def test_streaming_in_odd_blocks_equals_one_call(cli_design, measured):
    img = dynocomp.Image.load(cli_design[0])
    x = measured.forces
    ref = img.compensate(x)
    comp = img.compensator()
    assert comp.latency_samples == img.latency_samples > 0
    sizes = [1, 2, 3, 7, 333, 4097, 1]
    parts, s = [], 0
    while s < x.shape[0]:
        n = sizes[len(parts) % len(sizes)]
        parts.append(comp.process(x[s : s + n]))
        s += n
    parts.append(comp.finish())
    got = np.concatenate(parts)
    assert same_bits(got, ref)
    with pytest.raises(ValueError, match="finished"):
        comp.process(x[:10])
    # Negative control: a fresh compensator per block (state not carried
    # over) gives other outputs.
    chunks = []
    for s in range(0, x.shape[0], 4097):
        c = dynocomp.Compensator(img)
        chunks.append(np.concatenate([c.process(x[s : s + 4097]), c.finish()]))
    assert not same_bits(np.concatenate(chunks), ref)


# --- design: the summary of `dynocomp design --json` ---------------------


def strip_times(d):
    """The summary without what differs between two runs of the same
    design: times (s), the image's path and its id (the image records when
    it was made, so its CRC differs)."""
    if isinstance(d, dict):
        return {k: strip_times(v) for k, v in d.items() if not k.endswith("time_s") and k not in ("image", "image_id")}
    if isinstance(d, list):
        return [strip_times(v) for v in d]
    return d


def test_design_summary_and_image_equal_the_cli(cli_design, measured):
    img_path, cli_json = cli_design
    d = dynocomp.design(dynocomp.read_frf(EXAMPLE / "frf.uff"), fs=FS, idle=EXAMPLE / "idle.csv")
    assert strip_times(d.summary) == strip_times(cli_json)
    # The same coefficients: the same compensated bits on the example, and
    # the same model sidecar but for the image id.
    cli_img = dynocomp.Image.load(img_path)
    assert same_bits(d.compensate(measured.forces), cli_img.compensate(measured.forces))
    side = json.loads((img_path.parent / (img_path.name + ".model.json")).read_text())
    mine = json.loads(d.sidecar)
    assert mine.pop("image_id") == d.summary["image_id"] and side.pop("image_id") == cli_json["image_id"]
    assert mine == side
    # Negative control: the comparison sees one changed value.
    changed = json.loads(json.dumps(cli_json))
    changed["axes"][0]["q"] = np.nextafter(changed["axes"][0]["q"], np.inf)
    assert strip_times(changed) != strip_times(d.summary)
    html = d._repr_html_()
    assert "<svg" in html and d.summary["image_id"] in html
    # The notebook table shows each axis's predictions, the fit's
    # uncertainty counted, and what compensate --offline would reach.
    for a in d.summary["axes"]:
        for key in ("predicted_error_with_fit", "offline_predicted_error"):
            assert f"<td>{100.0 * a[key]:.3f} %</td>" in html, key
    # The example is designed for a flat force: no look-ahead lines.
    assert d.summary["latency_choice"]["look_ahead"] == [] and "longer look-ahead" not in html
    # A design for a cut that the box cannot follow (`latency_cli.rs`, seed
    # 26) carries them: the view states each one.
    s = json.loads(json.dumps(d.summary))
    s["latency_choice"]["look_ahead"] = [{"axis": 0, "box_latency": 6, "box_longest": 8, "box_predicted": 0.1716,
                                          "offline_predicted": 0.0119, "tried": [[16, 0.1243], [32, 0.0713], [64, None]]}]
    (line,) = dynocomp._look_ahead_lines(s, 10240.0)
    assert line.startswith("axis x: the box filter predicts 17.160 % at 6 samples (0.59 ms), compensate --offline 1.190 %")
    assert "would predict 12.430 % at 16, 7.130 % at 32, - at 64 samples" in line, line
    h = d.frequency_response([100.0, 1000.0])
    assert h.shape == (2, 3) and np.all(np.isfinite(h))


def test_design_from_arrays_equals_design_from_files(cli_design):
    """idle as an array and the FRF built from arrays give the CLI's design
    (the FRF's file hash aside, which an array does not have)."""
    _, cli_json = cli_design
    frf = dynocomp.read_frf(EXAMPLE / "frf.uff")
    idle = dynocomp.read_record(EXAMPLE / "idle.csv").forces
    d = dynocomp.design(dynocomp.FRF(frf.freq_hz, frf.frf, frf.coherence), fs=FS, idle=idle, report=False)
    assert strip_times(d.summary) == strip_times(cli_json)
    assert d.report == {}
    # Negative control: another noise variance is another design.
    d2 = dynocomp.design(frf, fs=FS, idle=idle * 2, report=False)
    assert strip_times(d2.summary) != strip_times(cli_json)


def test_design_save_round_trips(tmp_path, cli_design):
    img_path, _ = cli_design
    d = dynocomp.Design({}, img_path.read_bytes(), (img_path.parent / (img_path.name + ".model.json")).read_text(), {})
    d.save(tmp_path / "saved.dcimg")
    assert (tmp_path / "saved.dcimg").read_bytes() == img_path.read_bytes()
    assert (tmp_path / "saved.dcimg.model.json").exists()
    run_cli("inspect", tmp_path / "saved.dcimg")


# --- errors: the CLI's messages as the documented exceptions --------------


def test_missing_file_is_oserror_with_the_cli_message(tmp_path):
    missing = tmp_path / "nope.uff"
    with pytest.raises(OSError) as e:
        dynocomp.read_frf(missing)
    assert str(e.value).startswith(f"{missing}: cannot read")
    with pytest.raises(OSError):
        dynocomp.Image.load(tmp_path / "nope.dcimg")


def test_bad_files_are_valueerror_with_the_cli_message(tmp_path, cli_design):
    bad = tmp_path / "bad.csv"
    bad.write_text("freq_hz,x_re,x_im\n0,1,0\n1,oops,0\n")
    with pytest.raises(ValueError) as e:
        dynocomp.read_frf(bad)
    want = cli_error("design", "--frf", bad, "--fs", FS, "--noise-variance", "0.1", "--out", tmp_path / "o.dcimg")
    assert str(e.value) == want
    img = tmp_path / "bad.dcimg"
    img.write_bytes(b"not an image")
    with pytest.raises(ValueError) as e:
        dynocomp.Image.load(img)
    assert str(e.value) == cli_error("inspect", img)
    # Negative control: the good files read.
    assert dynocomp.read_frf(EXAMPLE / "frf.uff").axes == (0, 1, 2)
    assert dynocomp.Image.load(cli_design[0]).fs_hz == FS


def test_bad_options_are_valueerror(tmp_path):
    frf = EXAMPLE / "frf.uff"
    with pytest.raises(ValueError) as e:
        dynocomp.design(frf, fs=1234.5, noise_variance=0.1, report=False)
    want = cli_error("design", "--frf", frf, "--fs", "1234.5", "--noise-variance", "0.1", "--out", tmp_path / "o.dcimg")
    assert str(e.value) == want
    with pytest.raises(ValueError, match="--no-such-flag"):
        dynocomp.design(frf, fs=FS, noise_variance=0.1, no_such_flag=3)


def test_bad_arrays_are_refused_with_what_to_pass(cli_design, measured):
    img = dynocomp.Image.load(cli_design[0])
    x = measured.forces[:1000]
    with pytest.raises(TypeError, match="float64 or float32"):
        img.compensate(x.astype(np.int64))
    with pytest.raises(TypeError, match="not a numpy array"):
        img.compensate(x.tolist())
    with pytest.raises(ValueError, match=r"\(n, k\)"):
        img.compensate(np.zeros((10, 4)))
    with pytest.raises(ValueError, match=r"shape"):
        img.compensate(np.zeros((2, 3, 4)))
    with pytest.raises(ValueError, match="axes"):
        img.compensate(x[:, :2])
    with pytest.raises(ValueError, match="axes"):
        img.compensate(x, axes="xxz")
    bad = x.copy()
    bad[500, 1] = np.nan
    with pytest.raises(ValueError, match="non-finite at sample 500"):
        img.compensate(bad)
    with pytest.raises(ValueError, match=r"pass \(n, 3\)"):
        img.compensator().process(x[:, :2])
    # Negative control: the same array as float64 passes.
    assert img.compensate(x).shape == x.shape


# --- read_record and simulate ------------------------------------------------


def test_nrmse_is_the_project_score(cli_compensated, measured):
    truth = dynocomp.read_record(EXAMPLE / "true_force.csv").forces
    comp = dynocomp.read_record(cli_compensated).forces
    raw = dynocomp.nrmse(measured.forces, truth, FS)
    got = dynocomp.nrmse(comp, truth, FS)
    # The bundled example's figures (README, "What it achieves"): the
    # compensated force is within 1 % of the truth on every axis, the raw
    # force 50 % or more off; the truth scores 0 against itself.
    assert np.all(got < 0.01) and np.all(raw > 0.5)
    assert np.all(dynocomp.nrmse(truth, truth, FS) == 0.0)


def test_read_record_gives_the_file(measured):
    assert measured.axes == (0, 1, 2)
    assert measured.fs == pytest.approx(FS)
    first = np.array(open(EXAMPLE / "measured.csv").readlines()[1].split(","), dtype=float)
    assert same_bits(measured.forces[0], first[1:])
    assert measured.t_s[0] == first[0]


def test_simulate_returns_the_cli_files(tmp_path):
    opts = dict(duration=0.05, idle_duration=0.02, frf_lines=513)
    sim = dynocomp.simulate(seed=3, **opts)
    run_cli("simulate", "--out", tmp_path, "--seed", 3, "--duration", 0.05, "--idle-duration", 0.02,
            "--frf-lines", 513)
    want = dynocomp.read_record(tmp_path / "true_force.csv").forces
    assert same_bits(sim.true_force, want)
    assert same_bits(sim.measured, dynocomp.read_record(tmp_path / "measured.csv").forces)
    assert sim.frf.freq_hz.shape == (513,) and sim.fs == pytest.approx(FS)
    # Negative control: another seed is another dynamometer (the cut, and
    # so the true force, is the seed's too only through its parameters).
    meas = dynocomp.read_record(tmp_path / "measured.csv").forces
    assert not same_bits(dynocomp.simulate(seed=4, **opts).measured, meas)


# --- a 3x3 image (format 3) -------------------------------------------------


def test_a_3x3_image_runs_bit_exact_with_the_cli(measured, tmp_path):
    path = ROOT / "fuzz" / "images" / "matrix.dcimg"
    img = dynocomp.Image.load(path)
    assert img.axes == [0, 1, 2] and not img.parallel
    out = tmp_path / "c.csv"
    run_cli("compensate", "--coeffs", path, "--input", EXAMPLE / "measured.csv", "--output", out)
    want = dynocomp.read_record(out).forces
    got = img.compensate(measured.forces)
    assert same_bits(got, want)
    # Negative controls: the box's timing, and the columns fed in another
    # order (the 3x3 filter mixes them), give other bits.
    assert not same_bits(img.compensate(measured.forces, raw_timing=True), want)
    assert not same_bits(img.compensate(measured.forces[:, [1, 0, 2]]), want)
    # The bundled image has no model sidecar: the smoother says which file it
    # needs (an unreadable file: OSError).
    with pytest.raises(OSError, match="model sidecar"):
        img.compensate(measured.forces, offline=True)
    with pytest.raises(ValueError, match="fx, fy and fz together"):
        img.compensate(measured.forces[:, :2], axes="xy")


def test_an_frf_matrix_from_arrays_reaches_the_design_whole(tmp_path):
    """An FRF with cross entries, written for ``design`` (as an FRF built from
    arrays or by ``simulate`` is), keeps all nine entries and their
    coherence, to the bit. Negative control: without ``matrix`` only the
    direct entries are written."""
    sim = dynocomp.simulate(dyno="plate", dyno_preset="offcentre", fs=10240, duration=0.05,
                            idle_duration=0.02, frf_lines=257, frf_df=8)
    frf = sim.frf
    assert frf.matrix is not None and frf.matrix_coherence is not None
    frf.to_csv(tmp_path / "m.csv")
    back = dynocomp.read_frf(tmp_path / "m.csv")
    assert back.matrix is not None
    assert np.array_equal(back.matrix, frf.matrix) and np.array_equal(back.matrix_coherence, frf.matrix_coherence)
    direct = dynocomp.FRF(frf.freq_hz, frf.frf, frf.coherence)
    direct.to_csv(tmp_path / "d.csv")
    assert dynocomp.read_frf(tmp_path / "d.csv").matrix is None


def test_a_3x3_design_shows_its_rows_load_and_reduction_in_a_notebook():
    """A 3x3 design (off-centre plate at 25.6 kHz, whose full filter, at
    about 56 % of the sample period, is over a 40 % load limit) reduced to
    fit: the notebook view names each axis's row and prediction, the box
    load, the reduction and its cost, and draws the residual plot. Since the
    3x3 step runs in assembly, the full filter fits the box's own 60 %, so
    the limit is set with max_load (the CLI's --max-load)."""
    sim = dynocomp.simulate(dyno="plate", dyno_preset="offcentre", fs=25600, duration=0.1,
                            idle_duration=0.05, frf_lines=513, frf_df=8)
    d = dynocomp.design(sim.frf, fs=25600, idle=sim.idle, max_load=40)
    assert d.summary["kind"] == "3x3" and not d.summary["offline_only"]
    red = d.summary["design"]["reduction"]
    assert red["used"] and red["states"] < red["full_states"]
    assert red["full_load_permille"] > 400 >= red["load_permille"]
    html = d._repr_html_()
    assert "3x3 design" in html and "matrix" in html and "<svg" in html
    assert f"{red['full_states']} → {red['states']} states" in html and "reduced for the box" in html
    # Negative control: without a reduction the view does not claim one.
    s = json.loads(json.dumps(d.summary))
    s["design"]["reduction"] = None
    assert "reduced for the box" not in dynocomp._matrix_html(s, d.report)


# --- the GIL -------------------------------------------------------------------


def _longest_main_thread_stall(call):
    """Run `call` on a worker thread; returns the longest time (s) between
    the main thread's loop turns while the call ran, and the call's length."""
    import threading
    import time

    span = {}

    def worker():
        span["t0"] = time.perf_counter()
        call()
        span["t1"] = time.perf_counter()

    stamps = []
    th = threading.Thread(target=worker)
    th.start()
    while th.is_alive():
        stamps.append(time.perf_counter())
    th.join()
    t0, t1 = span["t0"], span["t1"]
    inside = [t0] + [s for s in stamps if t0 < s < t1] + [t1]
    return max(b - a for a, b in zip(inside, inside[1:])), t1 - t0


def test_compensate_lets_other_threads_run(cli_design):
    img = dynocomp.Image.load(cli_design[0])
    x = np.random.default_rng(3).normal(0.0, 50.0, (2_000_000, 3))
    stall, seconds = _longest_main_thread_stall(lambda: img.compensate(x))
    assert seconds > 0.05 and stall < 0.5 * seconds, f"the main thread stalled {stall:.3f} s of {seconds:.3f} s"
    # Negative control: a C call that holds the GIL (sorting Python floats)
    # stalls the main thread for most of its length.
    big = [float(v) for v in np.random.default_rng(4).random(1_500_000)]
    stall, seconds = _longest_main_thread_stall(big.sort)
    assert seconds > 0.05 and stall > 0.5 * seconds, f"control: stalled only {stall:.3f} s of {seconds:.3f} s"
