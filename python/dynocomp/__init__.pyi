"""Types and units of the `dynocomp` package.

Units: force N, frequency Hz, time s, FRF N/N, noise variance N². Axes are
0 = x, 1 = y, 2 = z, or named by the letters ("xz").

Errors: a bad file, value or option raises ValueError and an unreadable or
unwritable file OSError, each with the message `dynocomp` (the CLI) prints
for the same input; an array of the wrong kind raises TypeError, and one of
the wrong shape ValueError, saying what to pass. A failure inside the
library never crashes the interpreter: an internal error is a RuntimeError.
"""

import os
from typing import Any, Literal, Sequence

import numpy as np
import numpy.typing as npt

__version__: str

# Arrays of force samples: float64 or float32, C or Fortran order or any
# strided view; (n,) is one channel, (n, k) k = 1..3 channels (columns).
# They are read in place, without a copy, into the kernel's f32 input.
Samples = npt.NDArray[np.float64] | npt.NDArray[np.float32]
Axes = str | Sequence[int]
PathLike = str | os.PathLike[str]

class FRF:
    """A measured FRF."""

    freq_hz: npt.NDArray[np.float64]
    """(n,) frequency lines, Hz, strictly ascending."""
    frf: npt.NDArray[np.complex128]
    """(n, 3) direct FRFs G_xx, G_yy, G_zz (N/N); NaN for an axis not measured."""
    coherence: npt.NDArray[np.float64] | None
    """(n, 3) ordinary coherence γ² (0..1); NaN where absent."""
    axes: tuple[int, ...]
    """The measured axes."""
    matrix: npt.NDArray[np.complex128] | None
    """(n, 3, 3) G[k, i, j]: channel i, force direction j (N/N), when cross FRFs were measured."""
    matrix_coherence: npt.NDArray[np.float64] | None
    """(n, 3, 3) γ² of the entries of `matrix` (NaN where absent); None without cross coherence."""
    path: os.PathLike[str] | None
    """The file it was read from (design() then reads that file, as the CLI does)."""

    def __init__(
        self,
        freq_hz: npt.ArrayLike,
        frf: npt.ArrayLike,
        coherence: npt.ArrayLike | None = None,
        axes: Sequence[int] | None = None,
        matrix: npt.ArrayLike | None = None,
        path: os.PathLike[str] | None = None,
        matrix_coherence: npt.ArrayLike | None = None,
    ) -> None: ...
    def to_csv(self, path: PathLike) -> None:
        """Write the direct FRFs as the project's FRF CSV."""

def read_frf(path: PathLike) -> FRF:
    """Read a UFF58 (.uff, .unv) or CSV FRF file as `dynocomp design` does.
    Raises OSError (unreadable) or ValueError (malformed, with file and line)."""

class Record:
    """A force record."""

    forces: npt.NDArray[np.float64]
    """(n, k) forces, N, columns in the order of `axes` (Fortran order)."""
    axes: tuple[int, ...]
    t_s: npt.NDArray[np.float64] | None
    """(n,) sample times, s, when the file has them."""
    fs: float | None
    """Sample rate, Hz: declared by the file or from t_s; None if neither."""

    def channel(self, axis: int | str) -> npt.NDArray[np.float64]:
        """The samples of one axis, N."""
    def __len__(self) -> int: ...

def read_record(path: PathLike, channels: str | None = None) -> Record:
    """Read a force record (CSV, UFF58 time histories, TDMS) as
    `dynocomp compensate` reads it. `channels`: the CLI's --channels map
    (e.g. "fx=1,fy=2,fz=3") for files whose channel names do not say the axis."""

class Image:
    """A coefficient image (.dcimg): the box's compensator per axis."""

    fs_hz: int
    """Sample rate the image was designed for, Hz."""
    id: str
    """Image id (CRC-32, 8 hex digits), as `dynocomp inspect` shows it."""
    latency_samples: int
    """Declared output latency L, samples (removed by compensate unless raw_timing)."""
    axes: list[int]
    """The axes it compensates."""
    parallel: bool
    """A parallel-elaboration image (offline only)."""
    offline_only: bool
    """Marked offline-only: the box would not run it."""

    @staticmethod
    def load(path: PathLike) -> Image:
        """Read and validate an image file; the model sidecar beside it
        (`<path>.model.json`) is read when offline=True needs it."""
    @staticmethod
    def from_bytes(data: bytes, sidecar: str | None = None, name: str | None = None) -> Image:
        """An image from its bytes; `sidecar`: the model sidecar's text, for offline=True."""
    def to_bytes(self) -> bytes: ...
    def compensate(
        self,
        x: Samples,
        axes: Axes | None = None,
        offline: bool = False,
        raw_timing: bool = False,
        force_prior: bool = True,
    ) -> npt.NDArray[np.float64]:
        """Compensate measured forces x (N) → force estimates (N), same shape.

        Default: the box's causal f32 filter, bit-exact with
        `dynocomp compensate` and the box; the output is shifted back by the
        declared latency (the last L samples are estimated with the
        record's predicted continuation as their look-ahead), or kept in the
        box's timing with raw_timing=True.
        offline=True: the zero-lag fixed-interval smoother in f64 (needs the
        model sidecar; `force_prior=False` ignores its harmonic prior).
        A parallel-elaboration image is run band by band; a 3x3 image
        (format 3) runs on fx, fy and fz together (x must have those three
        columns; offline=True is refused).
        `axes`: the axis of each column; default x, y, z for 3 columns, else
        the image's axes. The GIL is released while it computes.
        Raises TypeError (not a float64/float32 array), ValueError (shape,
        axes, a non-finite output with its sample)."""
    def frequency_response(self, f_hz: npt.NDArray[np.float64], axis: int) -> npt.NDArray[np.complex128]:
        """Response of the f32 compensator of `axis` at f_hz (Hz), N/N, from
        its coefficients, latency delay included."""
    def compensator(self, axes: Axes | None = None, raw_timing: bool = False) -> Compensator:
        """A streaming Compensator of this image."""

class Compensator:
    """The box's filter over a record in blocks, its state carried across
    them: the concatenated outputs of process() and finish() equal one
    Image.compensate() call bit for bit, whatever the block sizes."""

    latency_samples: int
    def __init__(self, image: Image, axes: Axes | None = None, raw_timing: bool = False) -> None: ...
    def process(self, block: Samples) -> npt.NDArray[np.float64]:
        """Compensate the next (m, k) block (N); returns the outputs it
        completes (N): m, fewer while the first L are being dropped."""
    def finish(self) -> npt.NDArray[np.float64]:
        """End of the record: the last L outputs (N); the compensator is then spent."""

class Design:
    """A designed compensator."""

    summary: dict[str, Any]
    """The `dynocomp design --json` document (without the image's path)."""
    image: bytes
    """The coefficient image."""
    sidecar: str | None
    """The model sidecar's text (default method), for offline=True."""
    report: dict[str, str]
    """The report's plots: file name → SVG text (empty with report=False)."""

    @property
    def compensator_image(self) -> Image: ...
    def compensate(self, x: Samples, **options: Any) -> npt.NDArray[np.float64]:
        """Image.compensate with this design."""
    def compensator(self, axes: Axes | None = None, raw_timing: bool = False) -> Compensator: ...
    def save(self, path: PathLike) -> None:
        """Write the image and its sidecar (`<path>.model.json`), each whole or not at all."""
    def frequency_response(self, f_hz: npt.ArrayLike) -> npt.NDArray[np.complex128]:
        """(len(f_hz), axes) compensator response, N/N, at f_hz (Hz)."""
    def _repr_html_(self) -> str: ...

def design(
    frf: FRF | PathLike,
    *,
    fs: float,
    idle: PathLike | Record | Samples | None = None,
    noise_variance: float | None = None,
    report: bool = True,
    **options: Any,
) -> Design:
    """Design a compensator as `dynocomp design` does, in this process.

    fs: the box's sample rate, Hz (whole, 1000..1000000). idle: an idle
    record (its variance per axis is R, N²) or noise_variance R (N²).
    Every other keyword is the CLI flag of the same name and meaning:
    latency (samples), max_order, force_rms (N), max_noise_gain,
    full_scale (N), method ("vf" | "paper"), spindle_rpm (rev/min), teeth,
    harmonics, band_width, band (["LO:HI", ...] Hz), parallel, max_load (%),
    discretization, force_prior, force_record, ... True is the bare flag.
    The GIL is released while it designs."""

def nrmse(estimate: npt.ArrayLike, truth: npt.ArrayLike, fs: float, band_hz: float | None = None) -> Any:
    """NRMSE (fraction, not %): RMS error / std of the band-limited true
    force, both low-passed at band_hz (Hz, default min(4 kHz, 0.4 fs)), the
    first and last 5 % dropped. 1-D: a float; (n, k): an array of k."""

class Simulation:
    fs: float
    """Sample rate, Hz."""
    t_s: npt.NDArray[np.float64]
    """(n,) sample times, s."""
    measured: npt.NDArray[np.float64]
    """(n, 3) measured (dynamometer) forces, N."""
    true_force: npt.NDArray[np.float64]
    """(n, 3) the true cutting force, N."""
    idle: npt.NDArray[np.float64]
    """(m, 3) idle record, N."""
    frf: FRF
    """The simulated impact test."""
    truth: dict[str, Any]
    """The simulator's parameters (truth.json)."""

def simulate(*, seed: int = 1, **options: Any) -> Simulation:
    """Simulate as `dynocomp simulate` does: every keyword is the CLI flag
    of the same name (preset, fs Hz, duration s, spindle_rpm, teeth,
    noise_variance N², dyno "diagonal" | "plate", ...)."""

AXES: Literal["xyz"]
