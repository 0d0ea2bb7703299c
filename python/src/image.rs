//! `Image` (a coefficient image, `.dcimg`) and the streaming `Compensator`:
//! the box's kernel through `dynocomp::offline::compensate` (bit-exact with
//! `dynocomp compensate` and the box), parallel elaboration and the zero-lag
//! smoother, and a 3x3 image's filter on fx, fy and fz together, through
//! the same library calls `compensate` makes.

use std::path::{Path, PathBuf};

use anyhow::bail;
use numpy::{Complex64, PyArray1, PyArrayMethods, PyReadonlyArray1};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyBytes;

use dynocomp::frf::axis_name;
use dynocomp::io::image_file::{parse_any_image, AnyImage};
use dynocomp::io::signal_csv::SignalRecord;
use dynocomp::offline::compensate::{
    compensate_f32, compensate_f32_into, compensate_matrix, compensate_parallel, StreamCompensator,
};
use dynocomp::offline::sidecar::{parse_sidecar, read_sidecar, ModelSidecar, SidecarOwner};
use dynocomp_core::image::CoeffImage;

use crate::arrays::{channels_to_array, Samples};
use crate::guarded;

/// Axes named `"xyz"` (any subset, in column order) or given as 0-based
/// indices.
#[derive(FromPyObject)]
pub enum AxesArg {
    Names(String),
    Indices(Vec<usize>),
}

impl AxesArg {
    fn indices(self) -> PyResult<Vec<usize>> {
        match self {
            AxesArg::Indices(v) => Ok(v),
            AxesArg::Names(s) => s
                .chars()
                .map(|c| match c.to_ascii_lowercase() {
                    'x' => Ok(0),
                    'y' => Ok(1),
                    'z' => Ok(2),
                    _ => Err(PyValueError::new_err(format!(
                        "axes {s:?}: name the columns' axes with x, y, z, e.g. \"xz\""
                    ))),
                })
                .collect(),
        }
    }
}

/// A coefficient image, its source and, for the zero-lag smoother, its
/// model sidecar.
#[pyclass(module = "dynocomp._dynocomp", frozen)]
pub struct Image {
    any: AnyImage,
    bytes: Vec<u8>,
    /// The file it was read from (its sidecar lies beside it).
    path: Option<PathBuf>,
    /// The sidecar's text, when the image came as bytes.
    sidecar: Option<String>,
    /// Its name in messages.
    source: String,
}

impl Image {
    /// The box image (format 1), or an error for a parallel image.
    fn inline(&self, what: &str) -> anyhow::Result<&CoeffImage> {
        match &self.any {
            AnyImage::Inline(i) => Ok(i),
            AnyImage::Parallel(_) => {
                bail!("{}: {what} needs a box image (format 1); this is a parallel-elaboration image", self.source)
            }
            AnyImage::Matrix(_) => bail!("{}: {what} needs a box image (format 1); this is a 3x3 image", self.source),
        }
    }

    /// The axes an image covers (0-based).
    fn covered(&self) -> Vec<usize> {
        let img = match &self.any {
            AnyImage::Inline(i) => i.clone(),
            AnyImage::Parallel(p) => match p.band_image(0) {
                Some(i) => i,
                None => return Vec::new(),
            },
            AnyImage::Matrix(_) => return vec![0, 1, 2],
        };
        img.axes.iter().flatten().map(|a| a.axis as usize).collect()
    }

    /// The axes of `k` channels: `axes` if given, else x, y, z for 3
    /// channels, else the image's axes when there are `k` of them.
    fn channel_axes(&self, k: usize, axes: Option<AxesArg>) -> PyResult<Vec<usize>> {
        let axes = match axes {
            Some(a) => a.indices()?,
            None if k == 3 => vec![0, 1, 2],
            None => {
                let c = self.covered();
                if c.len() != k {
                    return Err(PyValueError::new_err(format!(
                        "{} channels but the image covers {}: say which axis each column is, e.g. axes=\"{}\"",
                        k,
                        c.iter().map(|a| axis_name(*a)).collect::<Vec<_>>().join(", "),
                        c.iter().take(k).map(|a| axis_name(*a)).collect::<String>()
                    )));
                }
                c
            }
        };
        if axes.len() != k || axes.iter().any(|&a| a > 2) || (1..axes.len()).any(|i| axes[i..].contains(&axes[i - 1])) {
            return Err(PyValueError::new_err(format!(
                "axes {axes:?}: give one distinct axis (0 = x, 1 = y, 2 = z) per column of the {k} columns"
            )));
        }
        Ok(axes)
    }

    /// The model sidecar of the zero-lag smoother.
    fn model_sidecar(&self, image: &impl SidecarOwner) -> anyhow::Result<ModelSidecar> {
        match (&self.sidecar, &self.path) {
            (Some(text), _) => {
                let shown = format!("{} (model sidecar)", self.source);
                parse_sidecar(text, &shown, image, self.path.as_deref().unwrap_or(Path::new(&self.source)))
            }
            (None, Some(p)) => read_sidecar(p, image),
            (None, None) => bail!(
                "{}: offline=True needs the model sidecar that `design` writes with the image; \
                 pass it to Image.from_bytes(data, sidecar=...)",
                self.source
            ),
        }
    }
}

#[pymethods]
impl Image {
    /// Read and validate a coefficient image file (.dcimg, either format).
    #[staticmethod]
    fn load(py: Python<'_>, path: PathBuf) -> PyResult<Image> {
        py.detach(|| {
            guarded(|| {
                let source = path.display().to_string();
                let bytes = std::fs::read(&path)
                    .map_err(|e| anyhow::Error::from(e).context(format!("{source}: cannot read")))?;
                let any = parse_any_image(&bytes, &source)?;
                Ok(Image { any, bytes, path: Some(path), sidecar: None, source })
            })
        })
    }

    /// Validate an image held in memory; `sidecar`: the text of its model
    /// sidecar (`<image>.model.json`), needed by `offline=True`.
    #[staticmethod]
    #[pyo3(signature = (data, sidecar=None, name=None))]
    fn from_bytes(data: Vec<u8>, sidecar: Option<String>, name: Option<String>) -> PyResult<Image> {
        let source = name.unwrap_or_else(|| "<image bytes>".into());
        guarded(|| {
            let any = parse_any_image(&data, &source)?;
            Ok(Image { any, bytes: data, path: None, sidecar, source })
        })
    }

    /// The image's encoded bytes (what the box is flashed with).
    fn to_bytes<'py>(&self, py: Python<'py>) -> Bound<'py, PyBytes> {
        PyBytes::new(py, &self.bytes)
    }

    /// Sample rate (Hz).
    #[getter]
    fn fs_hz(&self) -> u32 {
        self.any.fs_hz()
    }

    /// Image id (its CRC-32), as `inspect` shows it.
    #[getter]
    fn id(&self) -> String {
        format!("{:08x}", self.any.id())
    }

    /// Declared output latency L (samples) that `compensate` removes.
    #[getter]
    fn latency_samples(&self) -> u32 {
        match &self.any {
            AnyImage::Inline(i) => u32::from(i.latency_samples),
            AnyImage::Parallel(p) => p.band_image(0).map_or(0, |i| u32::from(i.latency_samples)),
            AnyImage::Matrix(m) => u32::from(m.latency_samples),
        }
    }

    /// The axes the image compensates (0 = x, 1 = y, 2 = z).
    #[getter]
    fn axes(&self) -> Vec<usize> {
        self.covered()
    }

    /// A parallel-elaboration image (offline only, format 2).
    #[getter]
    fn parallel(&self) -> bool {
        matches!(self.any, AnyImage::Parallel(_))
    }

    /// Marked offline-only (the box would not run it).
    #[getter]
    fn offline_only(&self) -> bool {
        match &self.any {
            AnyImage::Inline(i) => i.is_offline_only(),
            AnyImage::Parallel(_) => true,
            AnyImage::Matrix(m) => m.flags & dynocomp_core::image::FLAG_OFFLINE_ONLY != 0,
        }
    }

    /// Compensate `x` (N): see the stub (`__init__.pyi`) for the contract.
    #[pyo3(signature = (x, axes=None, offline=false, raw_timing=false, force_prior=true))]
    fn compensate<'py>(
        &self,
        py: Python<'py>,
        x: &Bound<'py, PyAny>,
        axes: Option<AxesArg>,
        offline: bool,
        raw_timing: bool,
        force_prior: bool,
    ) -> PyResult<Bound<'py, PyAny>> {
        if offline && raw_timing {
            return Err(PyValueError::new_err(
                "offline=True has no latency to keep: raw_timing belongs to the box's filter",
            ));
        }
        let samples = Samples::borrow(x, "x")?;
        let view = samples.view();
        let (n, one_d) = (view.len(), view.shape().len() == 1);
        let axes = self.channel_axes(view.channels(), axes)?;
        let source = self.source.as_str();
        if let (AnyImage::Inline(image), false) = (&self.any, offline) {
            // The box's filter writes straight into the result array.
            let out = numpy::PyArray2::<f64>::zeros(py, [n, axes.len()], true);
            {
                let mut rw = out.readwrite();
                let flat = rw.as_slice_mut().expect("a new Fortran-order array is contiguous");
                let mut sinks: Vec<&mut [f64]> = if n == 0 {
                    std::iter::repeat_with(<&mut [f64]>::default).take(axes.len()).collect()
                } else {
                    flat.chunks_mut(n).collect()
                };
                py.detach(|| {
                    let inputs = view.columns_f32(usize::from(image.latency_samples));
                    guarded(|| compensate_f32_into(image, &axes, inputs, raw_timing, source, &mut sinks))
                })?;
            }
            return Ok(if one_d { out.into_any().call_method1("ravel", ("F",))? } else { out.into_any() });
        }
        let out = py.detach(|| {
            guarded(|| match (&self.any, offline) {
                (AnyImage::Inline(image), false) => compensate_f32(
                    image,
                    &axes,
                    view.columns_f32(usize::from(image.latency_samples)),
                    raw_timing,
                    source,
                ),
                (AnyImage::Parallel(p), false) => {
                    let rec =
                        SignalRecord { t_s: None, channels: axes.iter().copied().zip(view.columns_f64()).collect() };
                    Ok(compensate_parallel(p, &rec, raw_timing, source)?.channels.into_iter().map(|c| c.1).collect())
                }
                (AnyImage::Inline(image), true) => {
                    let mut sidecar = self.model_sidecar(image)?;
                    if !force_prior {
                        sidecar.axes.iter_mut().for_each(|m| m.force_prior = None);
                    }
                    let rec =
                        SignalRecord { t_s: None, channels: axes.iter().copied().zip(view.columns_f64()).collect() };
                    let out = dynocomp::offline::smoother::smooth_record(image, &sidecar, &rec, source)?;
                    Ok(out.channels.into_iter().map(|c| c.1).collect())
                }
                (AnyImage::Parallel(_), true) => self.inline("offline=True").map(|_| Vec::new()),
                (AnyImage::Matrix(m), false) => {
                    let rec =
                        SignalRecord { t_s: None, channels: axes.iter().copied().zip(view.columns_f64()).collect() };
                    Ok(compensate_matrix(m, &rec, raw_timing, source)?.channels.into_iter().map(|c| c.1).collect())
                }
                (AnyImage::Matrix(m), true) => {
                    let sidecar = self.model_sidecar(&**m)?;
                    let rec =
                        SignalRecord { t_s: None, channels: axes.iter().copied().zip(view.columns_f64()).collect() };
                    let out = dynocomp::offline::matrix_smoother::smooth_matrix_record(m, &sidecar, &rec, source)?;
                    Ok(out.channels.into_iter().map(|c| c.1).collect())
                }
            })
        })?;
        Ok(channels_to_array(py, &out, n, one_d))
    }

    /// Frequency response of the box's f32 compensator of `axis` at `f_hz`
    /// (Hz), from its coefficients: complex, force estimate per measured
    /// force (N/N), without the declared latency's delay removed.
    fn frequency_response<'py>(
        &self,
        py: Python<'py>,
        f_hz: PyReadonlyArray1<'py, f64>,
        axis: usize,
    ) -> PyResult<Bound<'py, PyArray1<Complex64>>> {
        let image = guarded(|| self.inline("frequency_response"))?;
        let Some(a) = image.axes.get(axis).and_then(Option::as_ref) else {
            return Err(PyValueError::new_err(format!("{}: no compensator for axis {axis}", self.source)));
        };
        let fs = f64::from(image.fs_hz);
        let h: Vec<Complex64> = f_hz
            .as_array()
            .iter()
            .map(|&f| {
                let v = dynocomp::realize::quantize::filter_response(&a.filter, f, fs);
                Complex64::new(v.re, v.im)
            })
            .collect();
        Ok(PyArray1::from_vec(py, h))
    }

    /// A streaming compensator for records of `axes` (default x, y, z).
    #[pyo3(signature = (axes=None, raw_timing=false))]
    fn compensator(&self, axes: Option<AxesArg>, raw_timing: bool) -> PyResult<Compensator> {
        Compensator::new(self, axes, raw_timing)
    }

    /// Benchmark helper: seconds the box kernel alone takes on `x` (the
    /// library call of `compensate`, on inputs converted to f32 before the
    /// clock starts; outputs dropped), for BENCHMARKS.md.
    #[pyo3(signature = (x, axes=None))]
    fn _kernel_seconds<'py>(&self, py: Python<'py>, x: &Bound<'py, PyAny>, axes: Option<AxesArg>) -> PyResult<f64> {
        let samples = Samples::borrow(x, "x")?;
        let view = samples.view();
        let axes = self.channel_axes(view.channels(), axes)?;
        let image = guarded(|| self.inline("_kernel_seconds"))?;
        let inputs = view.columns_f32(usize::from(image.latency_samples));
        py.detach(|| {
            guarded(|| {
                let t0 = std::time::Instant::now();
                let out = compensate_f32(image, &axes, inputs, false, &self.source)?;
                let dt = t0.elapsed().as_secs_f64();
                drop(out);
                Ok(dt)
            })
        })
    }

    fn __repr__(&self) -> String {
        format!(
            "Image(id={:08x}, fs_hz={}, axes={:?}, latency_samples={}{})",
            self.any.id(),
            self.any.fs_hz(),
            self.covered().iter().map(|a| axis_name(*a)).collect::<Vec<_>>(),
            self.latency_samples(),
            if self.parallel() { ", parallel" } else { "" }
        )
    }
}

/// The box's filter over a record in blocks, its state kept between them.
#[pyclass(module = "dynocomp._dynocomp")]
pub struct Compensator {
    /// `None` once finished.
    inner: Option<StreamCompensator>,
    channels: usize,
}

impl Compensator {
    fn run<'py>(&mut self, py: Python<'py>, block: Option<&Bound<'py, PyAny>>) -> PyResult<Bound<'py, PyAny>> {
        let k = self.channels;
        let Some(inner) = self.inner.as_mut() else {
            return Err(PyValueError::new_err("this Compensator is finished; make a new one with image.compensator()"));
        };
        let mut out = vec![Vec::new(); k];
        let n = match block {
            Some(b) => {
                let samples = Samples::borrow(b, "block")?;
                let view = samples.view();
                if view.channels() != k || view.shape().len() != 2 {
                    return Err(PyValueError::new_err(format!(
                        "block: shape {:?}; pass (n, {k}): this compensator has {k} channels",
                        view.shape()
                    )));
                }
                py.detach(|| guarded(|| inner.push(&view.columns_f64(), &mut out)))?
            }
            None => {
                let n = py.detach(|| guarded(|| inner.finish(&mut out)))?;
                self.inner = None;
                n
            }
        };
        Ok(channels_to_array(py, &out, n, false))
    }
}

#[pymethods]
impl Compensator {
    /// A streaming compensator of `image` for records of `axes` (default:
    /// the image's axes).
    #[new]
    #[pyo3(signature = (image, axes=None, raw_timing=false))]
    fn new(image: &Image, axes: Option<AxesArg>, raw_timing: bool) -> PyResult<Self> {
        let axes = match axes {
            Some(a) => {
                let a = a.indices()?;
                image.channel_axes(a.len(), Some(AxesArg::Indices(a)))?
            }
            None => image.covered(),
        };
        let img = guarded(|| image.inline("Compensator"))?;
        let inner = guarded(|| StreamCompensator::new(img, &axes, raw_timing, &image.source))?;
        Ok(Compensator { inner: Some(inner), channels: axes.len() })
    }

    /// Compensate the next block (n, k) and return the outputs it completes.
    fn process<'py>(&mut self, py: Python<'py>, block: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyAny>> {
        self.run(py, Some(block))
    }

    /// End of the record: the last `latency` outputs.
    fn finish<'py>(&mut self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        self.run(py, None)
    }

    /// Latency (samples) removed from the output.
    #[getter]
    fn latency_samples(&self) -> usize {
        self.inner.as_ref().map_or(0, StreamCompensator::latency)
    }
}
