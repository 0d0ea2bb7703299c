//! `dynocomp._dynocomp`: the Python binding of the host library and the
//! core. Every computation is a call into `dynocomp` (host-tools) or
//! `dynocomp-core`; this crate only converts arrays and errors. The Python
//! layer (`python/dynocomp/__init__.py`) wraps it in the documented API.
//!
//! Errors: a failed library call raises `OSError` when an I/O error is in
//! its cause chain, else `ValueError`, with the CLI's one-line message
//! (the chain joined by `": "`, as `dynocomp` prints it). A panic never
//! crosses into Python: it is caught and raised as `RuntimeError`.

mod arrays;
mod image;

use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::PathBuf;

use clap::Parser;
use numpy::ndarray;
use numpy::{Complex64, PyArray1, PyArray2, PyArray3};
use pyo3::exceptions::{PyOSError, PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use dynocomp::cli::design_args::DesignArgs;
use dynocomp::cli::simulate::SimulateArgs;
use dynocomp::io::signal::{read_all, ChannelMap};
use dynocomp::io::signal_csv::SignalRecord;

/// An `anyhow` error as the Python exception of its kind, with the CLI's
/// one-line message.
pub(crate) fn py_err(e: anyhow::Error) -> PyErr {
    let msg: Vec<String> = e.chain().map(|c| c.to_string()).collect();
    let msg = msg.join(": ");
    if e.chain().any(|c| c.downcast_ref::<std::io::Error>().is_some()) {
        PyOSError::new_err(msg)
    } else {
        PyValueError::new_err(msg)
    }
}

/// Run `f`, turning its error into a Python exception and a panic into
/// `RuntimeError` (never unwinding into the interpreter).
pub(crate) fn guarded<T>(f: impl FnOnce() -> anyhow::Result<T>) -> PyResult<T> {
    match catch_unwind(AssertUnwindSafe(f)) {
        Ok(r) => r.map_err(py_err),
        Err(p) => {
            let what = p
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| p.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "unknown panic".into());
            Err(PyRuntimeError::new_err(format!("internal error in dynocomp (please report it): {what}")))
        }
    }
}

/// Parse `argv` (without the program name) with the CLI's own clap
/// definition of a command's arguments; a refusal is a `ValueError` with
/// clap's message (which names the flag).
fn parse_args<A: clap::Args>(command: &str, argv: Vec<String>) -> PyResult<A> {
    #[derive(Parser)]
    #[command(no_binary_name = true)]
    struct Wrap<A: clap::Args> {
        #[command(flatten)]
        args: A,
    }
    match Wrap::<A>::try_parse_from(argv) {
        Ok(w) => Ok(w.args),
        Err(e) => {
            let text = e.to_string();
            let first = text.lines().next().unwrap_or("invalid arguments").trim_start_matches("error: ");
            Err(PyValueError::new_err(format!("dynocomp {command}: {first}")))
        }
    }
}

/// `dynocomp design ARGV`, in this process: writes what the CLI writes
/// (image, sidecar, report) and returns what it prints on stdout. The GIL
/// is released while it designs.
#[pyfunction]
fn design_cli(py: Python<'_>, argv: Vec<String>) -> PyResult<String> {
    let args: DesignArgs = parse_args("design", argv)?;
    py.detach(|| guarded(|| dynocomp::cli::design::design(&args)))
}

/// `dynocomp simulate ARGV`, in this process: writes the CLI's files into
/// its `--out` directory. The GIL is released while it simulates.
#[pyfunction]
fn simulate_cli(py: Python<'_>, argv: Vec<String>) -> PyResult<()> {
    let args: SimulateArgs = parse_args("simulate", argv)?;
    py.detach(|| guarded(|| dynocomp::cli::simulate::run(&args)))
}

/// Read an FRF file (UFF58 or CSV) into a dict of arrays: `freq_hz` (n,),
/// `frf` (n, 3) complex N/N (NaN for an axis the file lacks), `coherence`
/// (n, 3) (NaN where absent), `axes` (list of 0-based axes present) and,
/// when the file holds cross FRFs, `matrix` (n, 3, 3) complex, G[k, i, j]:
/// channel i, force direction j (NaN where not measured).
#[pyfunction]
fn read_frf<'py>(py: Python<'py>, path: PathBuf) -> PyResult<Bound<'py, PyDict>> {
    let frf = py.detach(|| {
        guarded(|| {
            let bytes = std::fs::read(&path)
                .map_err(anyhow::Error::from)
                .map_err(|e| e.context(format!("{}: cannot read", path.display())))?;
            dynocomp::io::parse_frf(&path, &bytes)
        })
    })?;
    let n = frf.freq_hz.len();
    let nan_c = Complex64::new(f64::NAN, f64::NAN);
    let mut g = ndarray::Array2::from_elem((n, 3), nan_c);
    let mut coh = ndarray::Array2::from_elem((n, 3), f64::NAN);
    for a in &frf.axes {
        for (k, v) in a.frf.iter().enumerate() {
            g[(k, a.axis)] = *v;
        }
        if let Some(c) = &a.coherence {
            for (k, v) in c.iter().enumerate() {
                coh[(k, a.axis)] = *v;
            }
        }
    }
    let d = PyDict::new(py);
    d.set_item("freq_hz", PyArray1::from_slice(py, &frf.freq_hz))?;
    d.set_item("frf", PyArray2::from_owned_array(py, g))?;
    d.set_item("coherence", PyArray2::from_owned_array(py, coh))?;
    d.set_item("axes", frf.axes.iter().map(|a| a.axis).collect::<Vec<_>>())?;
    if !frf.cross.is_empty() {
        let mut m = ndarray::Array3::from_elem((n, 3, 3), nan_c);
        for a in &frf.axes {
            for (k, v) in a.frf.iter().enumerate() {
                m[(k, a.axis, a.axis)] = *v;
            }
        }
        for c in &frf.cross {
            for (k, v) in c.frf.iter().enumerate() {
                m[(k, c.channel, c.direction)] = *v;
            }
        }
        d.set_item("matrix", PyArray3::from_owned_array(py, m))?;
        let mut mc = ndarray::Array3::from_elem((n, 3, 3), f64::NAN);
        let mut any = false;
        for a in &frf.axes {
            for (k, v) in a.coherence.iter().flatten().enumerate() {
                mc[(k, a.axis, a.axis)] = *v;
            }
        }
        for c in &frf.cross {
            for (k, v) in c.coherence.iter().flatten().enumerate() {
                mc[(k, c.channel, c.direction)] = *v;
                any = true;
            }
        }
        if any {
            d.set_item("matrix_coherence", PyArray3::from_owned_array(py, mc))?;
        }
    }
    Ok(d)
}

/// Read a force record (CSV, UFF58 time histories or TDMS) as `compensate`
/// reads it: a dict with `forces` (n, k) float64 in N (Fortran order: each
/// channel contiguous), `axes` (the k 0-based axes), `t_s` (n,) or None,
/// and `fs` (Hz: declared by the file or from its `t_s`; None if neither).
#[pyfunction]
#[pyo3(signature = (path, channels=None))]
fn read_record<'py>(py: Python<'py>, path: PathBuf, channels: Option<String>) -> PyResult<Bound<'py, PyDict>> {
    let (rec, declared) = py.detach(|| {
        guarded(|| {
            let map = channels.as_deref().map(ChannelMap::parse).transpose().map_err(|e| e.context("channels"))?;
            let (mut reader, _) = dynocomp::io::signal_file::open_signal(&path, map.as_ref())?;
            let axes = reader.axes().to_vec();
            let declared = reader.declared_fs_hz();
            let (t_s, ch) = read_all(&mut *reader)?;
            Ok((SignalRecord { t_s, channels: axes.into_iter().zip(ch).collect() }, declared))
        })
    })?;
    let fs = declared.or_else(|| rec.sample_rate_from_time().map(|(f, _)| f));
    let cols: Vec<&[f64]> = rec.channels.iter().map(|c| c.1.as_slice()).collect();
    let d = PyDict::new(py);
    d.set_item("forces", arrays::columns_to_array(py, &cols, rec.len()))?;
    d.set_item("axes", rec.channels.iter().map(|c| c.0).collect::<Vec<_>>())?;
    d.set_item("t_s", rec.t_s.as_ref().map(|t| PyArray1::from_slice(py, t)))?;
    d.set_item("fs", fs)?;
    Ok(d)
}

/// Write an FRF (direct entries of `axes`) as the library's FRF CSV, for
/// `design` from arrays: `frf` (n, 3) complex N/N, `coherence` (n, 3) or
/// None; columns of axes not in `axes` are ignored. `matrix` (n, 3, 3)
/// adds the cross entries G_ij (channel i, force direction j) that hold a
/// finite value, with `matrix_coherence` (n, 3, 3) where given
/// (docs/frf-matrix.md).
#[pyfunction]
#[pyo3(signature = (path, freq_hz, frf, axes, coherence=None, matrix=None, matrix_coherence=None))]
#[allow(clippy::too_many_arguments)]
fn write_frf_csv(
    py: Python<'_>,
    path: PathBuf,
    freq_hz: numpy::PyReadonlyArray1<'_, f64>,
    frf: numpy::PyReadonlyArray2<'_, Complex64>,
    axes: Vec<usize>,
    coherence: Option<numpy::PyReadonlyArray2<'_, f64>>,
    matrix: Option<numpy::PyReadonlyArray3<'_, Complex64>>,
    matrix_coherence: Option<numpy::PyReadonlyArray3<'_, f64>>,
) -> PyResult<()> {
    let (f, g) = (freq_hz.as_array(), frf.as_array());
    let coh = coherence.as_ref().map(|c| c.as_array());
    let n = f.len();
    if g.shape() != [n, 3] || coh.as_ref().is_some_and(|c| c.shape() != [n, 3]) {
        return Err(PyValueError::new_err(format!(
            "frf: shape {:?}, coherence: {:?}; pass ({n}, 3) for the {n} lines of freq_hz (columns x, y, z)",
            g.shape(),
            coh.as_ref().map(|c| c.shape().to_vec())
        )));
    }
    if axes.is_empty() || axes.iter().any(|&a| a > 2) {
        return Err(PyValueError::new_err(format!(
            "axes {axes:?}: give the 0-based axes (0 = x, 1 = y, 2 = z) the FRF has"
        )));
    }
    let m = matrix.as_ref().map(|m| m.as_array());
    let mc = matrix_coherence.as_ref().map(|c| c.as_array());
    if m.as_ref().is_some_and(|m| m.shape() != [n, 3, 3]) || mc.as_ref().is_some_and(|c| c.shape() != [n, 3, 3]) {
        return Err(PyValueError::new_err(format!(
            "matrix: shape {:?}, matrix_coherence: {:?}; pass ({n}, 3, 3) for the {n} lines of freq_hz \
             (G[k, i, j]: channel i, force direction j)",
            m.as_ref().map(|m| m.shape().to_vec()),
            mc.as_ref().map(|c| c.shape().to_vec())
        )));
    }
    let mut cross = Vec::new();
    if let Some(m) = &m {
        for (i, j) in (0..3).flat_map(|i| (0..3).map(move |j| (i, j))).filter(|(i, j)| i != j) {
            let entry: Vec<Complex64> = (0..n).map(|k| m[(k, i, j)]).collect();
            if !entry.iter().any(|v| v.re.is_finite() && v.im.is_finite()) {
                continue; // not measured
            }
            let coherence = mc.as_ref().map(|c| (0..n).map(|k| c[(k, i, j)]).collect::<Vec<f64>>());
            cross.push(dynocomp::frf::CrossFrf {
                channel: i,
                direction: j,
                frf: entry,
                coherence: coherence.filter(|c| c.iter().all(|v| v.is_finite())),
            });
        }
    }
    let frf = dynocomp::frf::Frf {
        freq_hz: f.to_vec(),
        axes: axes
            .iter()
            .map(|&a| dynocomp::frf::AxisFrf {
                axis: a,
                frf: g.column(a).to_vec(),
                coherence: coh.as_ref().map(|c| c.column(a).to_vec()),
            })
            .collect(),
        cross,
    };
    py.detach(|| guarded(|| dynocomp::io::frf_csv::write_frf_csv(&path, &frf)))
}

/// Write force samples `x` ((n,) or (n, k), N) of `axes` as the library's
/// signal CSV (no `t_s` column), for `design` from an idle array.
#[pyfunction]
fn write_signal_csv(py: Python<'_>, path: PathBuf, x: &Bound<'_, PyAny>, axes: Vec<usize>) -> PyResult<()> {
    let samples = arrays::Samples::borrow(x, "idle")?;
    let view = samples.view();
    if axes.len() != view.channels() || axes.iter().any(|&a| a > 2) {
        return Err(PyValueError::new_err(format!(
            "axes {axes:?}: give one 0-based axis (0 = x, 1 = y, 2 = z) per column of the {} columns",
            view.channels()
        )));
    }
    let rec = SignalRecord { t_s: None, channels: axes.into_iter().zip(view.columns_f64()).collect() };
    py.detach(|| guarded(|| dynocomp::io::signal_csv::write_signal_csv(&path, &rec)))
}

/// The project's accuracy score (DESIGN.md, "Accuracy"): NRMSE of
/// `estimate` against `truth` (1-D, N, sampled at `fs_hz`), both low-passed
/// at `band_hz` (default: min(4 kHz, 0.4 fs)) with the first and last 5 %
/// dropped; returns (nrmse, nrmse_p2p, rms_error_n).
#[pyfunction]
#[pyo3(signature = (estimate, truth, fs_hz, band_hz=None))]
fn accuracy(
    py: Python<'_>,
    estimate: numpy::PyReadonlyArray1<'_, f64>,
    truth: numpy::PyReadonlyArray1<'_, f64>,
    fs_hz: f64,
    band_hz: Option<f64>,
) -> PyResult<(f64, f64, f64)> {
    let (e, t) = (estimate.as_slice()?, truth.as_slice()?);
    if e.len() != t.len() || e.len() < 40 || !(fs_hz > 0.0) {
        return Err(PyValueError::new_err(format!(
            "accuracy: {} estimated and {} true samples at fs {fs_hz} Hz; \
             pass two records of the same length (>= 40) and fs > 0",
            e.len(),
            t.len()
        )));
    }
    let band = band_hz.unwrap_or_else(|| dynocomp::metrics::scoring_band_hz(fs_hz));
    let a = py.detach(|| dynocomp::metrics::accuracy(e, t, fs_hz, band));
    Ok((a.nrmse, a.nrmse_p2p, a.rms_error_n))
}

/// Path of the model sidecar of the image at `path` (`<image>.model.json`).
#[pyfunction]
fn sidecar_path(path: PathBuf) -> PathBuf {
    dynocomp::offline::sidecar::sidecar_path(&path)
}

/// The extension module.
#[pymodule]
fn _dynocomp(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(design_cli, m)?)?;
    m.add_function(wrap_pyfunction!(simulate_cli, m)?)?;
    m.add_function(wrap_pyfunction!(read_frf, m)?)?;
    m.add_function(wrap_pyfunction!(read_record, m)?)?;
    m.add_function(wrap_pyfunction!(write_frf_csv, m)?)?;
    m.add_function(wrap_pyfunction!(write_signal_csv, m)?)?;
    m.add_function(wrap_pyfunction!(sidecar_path, m)?)?;
    m.add_function(wrap_pyfunction!(accuracy, m)?)?;
    m.add_class::<image::Image>()?;
    m.add_class::<image::Compensator>()?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
