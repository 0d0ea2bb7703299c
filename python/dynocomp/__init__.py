"""dynocomp from Python: the box's compensator, its design and the simulator
on numpy arrays.

Every computation is the Rust host library's or the core's (the extension
``dynocomp._dynocomp``): ``Image.compensate`` runs the box's own f32 kernel,
bit-exact with ``dynocomp compensate`` and the box; ``design`` and
``simulate`` run the CLI's commands in this process, with the CLI's
arguments, defaults and messages. Forces are in N, frequencies in Hz, times
in s, FRFs in N/N. Types and units: ``__init__.pyi``.

Errors: a bad file or value raises ``ValueError`` (``OSError`` when the file
cannot be read or written) with the CLI's one-line message; an array of the
wrong type raises ``TypeError`` saying what to pass.
"""

from __future__ import annotations

import html
import json
import os
import tempfile
from pathlib import Path

import numpy as np

from . import _dynocomp as _rs
from ._dynocomp import Compensator, Image, __version__

__all__ = [
    "FRF",
    "Record",
    "Design",
    "Simulation",
    "Image",
    "Compensator",
    "read_frf",
    "read_record",
    "design",
    "simulate",
    "nrmse",
    "__version__",
]

AXES = "xyz"


class FRF:
    """A measured FRF: ``freq_hz`` (n,) Hz; ``frf`` (n, 3) complex N/N, the
    direct FRFs G_xx, G_yy, G_zz in columns x, y, z (NaN for an axis not
    measured); ``coherence`` (n, 3) γ² (NaN where absent); ``axes`` the
    measured axes (0 = x); ``matrix`` (n, 3, 3) complex, G[k, i, j] for
    channel i and force direction j, when cross FRFs were measured, and
    ``matrix_coherence`` (n, 3, 3) their γ² (None where the file has none).

    Build one from arrays with ``FRF(freq_hz, frf, coherence=None)`` (and
    ``matrix=`` for the 3x3 design); ``read_frf`` reads a file (UFF58 or
    CSV).
    """

    def __init__(self, freq_hz, frf, coherence=None, axes=None, matrix=None, path=None, matrix_coherence=None):
        self.freq_hz = np.ascontiguousarray(freq_hz, dtype=np.float64)
        frf = np.asarray(frf, dtype=np.complex128)
        if frf.ndim == 1:
            frf = frf[:, None]
        if frf.ndim != 2 or frf.shape[0] != self.freq_hz.shape[0] or frf.shape[1] > 3:
            raise ValueError(
                f"frf: shape {frf.shape}; pass (n, 3) (columns x, y, z) or (n,) for one axis, "
                f"n = {self.freq_hz.shape[0]} lines of freq_hz"
            )
        if axes is None:
            axes = [a for a in range(frf.shape[1]) if not np.all(np.isnan(frf[:, a]))]
        full = np.full((frf.shape[0], 3), np.nan + 1j * np.nan, dtype=np.complex128)
        full[:, : frf.shape[1]] = frf
        self.frf = full
        self.axes = tuple(int(a) for a in axes)
        if coherence is not None:
            coh = np.asarray(coherence, dtype=np.float64)
            if coh.ndim == 1:
                coh = coh[:, None]
            c = np.full((coh.shape[0], 3), np.nan)
            c[:, : coh.shape[1]] = coh
            coherence = c
        self.coherence = coherence
        self.matrix = None if matrix is None else np.asarray(matrix, dtype=np.complex128)
        self.matrix_coherence = None if matrix_coherence is None else np.asarray(matrix_coherence, dtype=np.float64)
        self.path = path

    def __repr__(self):
        names = "".join(AXES[a] for a in self.axes)
        f = self.freq_hz
        span = f"{f[0]:g}-{f[-1]:g} Hz" if len(f) else "empty"
        return f"FRF(axes={names!r}, {len(f)} lines, {span}{', 3x3' if self.matrix is not None else ''})"

    def to_csv(self, path):
        """Write the FRFs as the project's FRF CSV (``freq_hz,x_re,...``), with
        the cross entries (``xy_re,...``, docs/frf-matrix.md) where ``matrix``
        holds them."""
        coh = None
        if self.coherence is not None:
            coh = np.ascontiguousarray(np.nan_to_num(self.coherence, nan=0.0))
        m = None if self.matrix is None else np.ascontiguousarray(self.matrix)
        mc = None if self.matrix_coherence is None else np.ascontiguousarray(self.matrix_coherence)
        _rs.write_frf_csv(os.fspath(path), self.freq_hz, np.ascontiguousarray(self.frf), list(self.axes), coh, m, mc)


def read_frf(path) -> FRF:
    """Read an FRF file (UFF58 ``.uff``/``.unv`` or CSV), as ``dynocomp design`` reads it."""
    d = _rs.read_frf(os.fspath(path))
    return FRF(
        d["freq_hz"], d["frf"], d["coherence"], d["axes"], d.get("matrix"), path=Path(path),
        matrix_coherence=d.get("matrix_coherence"),
    )


class Record:
    """A force record: ``forces`` (n, k) float64 in N, columns in the order of
    ``axes`` (0 = x); ``t_s`` (n,) s or None; ``fs`` Hz (declared by the file,
    or from ``t_s``; None if neither)."""

    def __init__(self, forces, axes, t_s=None, fs=None):
        self.forces = forces
        self.axes = tuple(int(a) for a in axes)
        self.t_s = t_s
        self.fs = fs

    def channel(self, axis):
        """The samples (N) of ``axis`` (0/1/2 or 'x'/'y'/'z')."""
        a = AXES.index(axis) if isinstance(axis, str) else int(axis)
        return self.forces[:, self.axes.index(a)]

    def __len__(self):
        return self.forces.shape[0]

    def __repr__(self):
        names = "".join(AXES[a] for a in self.axes)
        return f"Record(axes={names!r}, {len(self)} samples, fs={self.fs})"


def read_record(path, channels=None) -> Record:
    """Read a force record (CSV, UFF58 time histories or TDMS) as
    ``dynocomp compensate`` reads it; ``channels``: the CLI's ``--channels``
    map for UFF/TDMS files whose channel names do not say the axis."""
    d = _rs.read_record(os.fspath(path), channels)
    return Record(d["forces"], d["axes"], d["t_s"], d["fs"])


def _flags(options):
    """Keyword arguments as the CLI's flags: ``max_order=20`` → ``--max-order 20``,
    True → the flag alone, False/None → left out, a list → the flag repeated."""
    argv = []
    for key, value in options.items():
        flag = "--" + key.replace("_", "-")
        if value is None or value is False:
            continue
        if value is True:
            argv.append(flag)
        elif isinstance(value, (list, tuple)):
            for v in value:
                argv += [flag, str(v)]
        else:
            argv += [flag, str(value)]
    return argv


def _axes_of(x):
    a = np.asarray(x)
    return [0] if a.ndim == 1 else list(range(a.shape[1]))


class Design:
    """A designed compensator: ``summary`` (the ``dynocomp design --json``
    document as a dict), ``image`` (the coefficient image's bytes),
    ``sidecar`` (the model sidecar's text, for ``offline=True``; None for the
    paper's method) and ``report`` (name → SVG text of the report's plots)."""

    def __init__(self, summary, image, sidecar, report, summary_text=None):
        self.summary = summary
        self.image = image
        self.sidecar = sidecar
        self.report = report
        self._image = None

    @property
    def compensator_image(self) -> Image:
        """The design as an ``Image`` (with its sidecar)."""
        if self._image is None:
            self._image = Image.from_bytes(self.image, self.sidecar, "<designed image>")
        return self._image

    def compensate(self, x, **options):
        """``Image.compensate`` with this design's image."""
        return self.compensator_image.compensate(x, **options)

    def compensator(self, axes=None, raw_timing=False) -> Compensator:
        """A streaming ``Compensator`` of this design."""
        return Compensator(self.compensator_image, axes, raw_timing)

    def save(self, path):
        """Write the image to ``path`` (.dcimg) and its model sidecar beside it
        (``<path>.model.json``), each written whole or not at all."""
        path = os.fspath(path)
        _write_atomic(path, self.image)
        if self.sidecar is not None:
            _write_atomic(os.fspath(_rs.sidecar_path(path)), self.sidecar.encode())

    def frequency_response(self, f_hz):
        """The compensator's frequency response at ``f_hz`` (Hz): complex
        array (len(f_hz), number of designed axes), columns in the order of
        ``summary['axes']``, from the f32 coefficients the box runs (N/N)."""
        f = np.ascontiguousarray(np.atleast_1d(f_hz), dtype=np.float64)
        img = self.compensator_image
        return np.stack([img.frequency_response(f, a) for a in img.axes], axis=1)

    def _repr_html_(self):
        s = self.summary
        if s.get("kind") == "3x3":
            return _matrix_html(s, self.report)
        rows = "".join(
            "<tr>" + "".join(f"<td>{html.escape(str(cell(a)))}</td>" for _, cell in _SUMMARY_COLUMNS) + "</tr>"
            for a in s.get("axes", [])
        )
        head = "".join(f"<th>{k}</th>" for k, _ in _SUMMARY_COLUMNS)
        plots = "".join(
            _FIGURE.format(svg, html.escape(name))
            for name, svg in self.report.items()
            if name.endswith(("_frf_fit.svg", "_compensated.svg", "_look_ahead.svg"))
        )
        looks = "".join(f"<p>{html.escape(line)}</p>" for line in _look_ahead_lines(s, s.get("fs_hz")))
        return (
            f"<div><b>dynocomp design</b>: image {s.get('image_id')}, fs {s.get('fs_hz')} Hz, "
            f"latency {s.get('latency_samples')} samples, method {s.get('method')}"
            f"<table><tr>{head}</tr>{rows}</table>{looks}{plots}</div>"
        )

    def __repr__(self):
        s = self.summary
        return f"Design(image_id={s.get('image_id')}, fs_hz={s.get('fs_hz')}, axes={len(s.get('axes', []))})"


# The notebook view's columns: (heading, cell of an axis's summary). The
# predictions count the fit's uncertainty, as the text summary does.
_SUMMARY_COLUMNS = (
    ("axis", lambda a: a.get("axis", "")),
    ("model_order", lambda a: a.get("model_order", "")),
    ("q", lambda a: a.get("q", "")),
    ("flat_band_hz", lambda a: a.get("flat_band_hz", "")),
    ("noise_gain", lambda a: a.get("noise_gain", "")),
    ("predicted", lambda a: _pct(a.get("predicted_error_with_fit"))),
    ("compensate --offline", lambda a: _pct(a.get("offline_predicted_error"))),
    ("raw", lambda a: _pct(a.get("raw_predicted_error"))),
)


def _look_ahead_lines(s, fs_hz):
    """One line per axis whose longer look-aheads the design predicted
    (``summary['latency_choice']['look_ahead']``, a design for a cut's
    record whose box filter is far behind ``--offline``)."""
    lines = []
    for la in (s.get("latency_choice") or {}).get("look_ahead", []):
        tried = ", ".join(f"{_pct(e)} at {n}" for n, e in la.get("tried", []))
        ms = f" ({1e3 * la['box_latency'] / fs_hz:.2f} ms)" if fs_hz else ""
        lines.append(
            f"axis {'xyz'[la['axis']]}: the box filter predicts {_pct(la.get('box_predicted'))} at "
            f"{la.get('box_latency')} samples{ms}, compensate --offline {_pct(la.get('offline_predicted'))}; "
            f"a longer look-ahead, which the box ({la.get('box_longest')} samples at most) cannot run, would "
            f"predict {tried} samples"
        )
    return lines

# One plot of the notebook view: the SVG and its file name.
_FIGURE = "<figure style='display:inline-block;margin:4px'>{}<figcaption>{}</figcaption></figure>"


def _pct(e):
    """A predicted error (fraction, or a {"error": …} dict) in percent."""
    if isinstance(e, dict):
        e = e.get("error")
    return "-" if e is None else f"{100.0 * e:.3f} %"


def _matrix_html(s, report):
    """The notebook view of a 3x3 design: per output axis the row used and
    the predicted errors (crosstalk counted), the box load, the reduction to
    the box's limit where there is one, and the residual plot."""
    d = s.get("design", {})
    head = "".join(f"<th>{k}</th>" for k in ("axis", "row used", "predicted", "per axis", "raw", "why"))
    rows = "".join(
        "<tr>"
        + "".join(
            f"<td>{html.escape(str(v))}</td>"
            for v in (a.get("axis"), a.get("source"), _pct(a.get("chosen")), _pct(a.get("per_axis")),
                      _pct(a.get("raw")), a.get("reason", ""))
        )
        + "</tr>"
        for a in d.get("axes", [])
    )
    load = s.get("box_load", {})
    lines = [
        f"box load {load.get('load_pct', ['?', '?'])[1]} % of the sample period (limit {load.get('limit_pct')} %)"
        + ("; <b>offline-only image</b>" if s.get("offline_only") else "")
    ]
    red = d.get("reduction")
    if red and red.get("states"):
        full, now = (" / ".join(_pct(e) for e in red[k]) for k in ("full_predicted", "predicted"))
        verb = "reduced" if red.get("used") else "not reduced"
        lines.append(
            f"{verb} for the box: {red['full_states']} → {red['states']} states, predicted {full} → {now}; "
            + html.escape(red.get("reason", ""))
        )
    plots = "".join(_FIGURE.format(svg, html.escape(name)) for name, svg in report.items() if name == "matrix_rows.svg")
    return (
        f"<div><b>dynocomp 3x3 design</b>: image {s.get('image_id')}, fs {s.get('fs_hz')} Hz, "
        f"latency {s.get('latency_samples')} samples<table><tr>{head}</tr>{rows}</table>"
        + "".join(f"<p>{line}</p>" for line in lines)
        + f"{plots}</div>"
    )


def _write_atomic(path, data):
    d = os.path.dirname(os.path.abspath(path))
    fd, tmp = tempfile.mkstemp(dir=d, prefix=".dynocomp-", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def design(frf, *, fs, idle=None, noise_variance=None, report=True, **options) -> Design:
    """Design a compensator, as ``dynocomp design`` does.

    ``frf``: an ``FRF`` (from ``read_frf`` or arrays) or a file path; ``fs``:
    the box's sample rate (Hz); ``idle``: an idle record (path, ``Record`` or
    array (n, k) of N with columns x, y, z) whose variance is R, or
    ``noise_variance`` R (N²). Every other keyword is the CLI flag of the same
    name (``max_order=20`` is ``--max-order 20``, ``band=["900:1300"]`` repeats
    ``--band``), with the CLI's defaults, checks and messages. ``report``:
    also render the report's plots (``Design.report``, ``_repr_html_``).
    The GIL is released while it designs.
    """
    for reserved in ("out", "json", "frf_path"):
        if reserved in options:
            raise ValueError(f"design: {reserved}= is not an option here; use Design.save(path) to write the image")
    with tempfile.TemporaryDirectory(prefix="dynocomp-design-") as tmp:
        argv = ["--frf", _frf_path(frf, tmp), "--fs", str(fs)]
        if idle is not None:
            argv += ["--idle", _idle_path(idle, tmp)]
        if noise_variance is not None:
            argv += ["--noise-variance", str(noise_variance)]
        out = os.path.join(tmp, "design.dcimg")
        argv += ["--out", out, "--json"]
        rep = os.path.join(tmp, "report")
        if report:
            argv += ["--report", rep]
        argv += _flags(options)
        summary = json.loads(_rs.design_cli(argv))
        with open(out, "rb") as f:
            image = f.read()
        side = os.fspath(_rs.sidecar_path(out))
        sidecar = Path(side).read_text() if os.path.exists(side) else None
        plots = {}
        if report and os.path.isdir(rep):
            for name in sorted(os.listdir(rep)):
                if name.endswith(".svg"):
                    plots[name] = Path(rep, name).read_text()
        summary.pop("image", None)
        return Design(summary, image, sidecar, plots)


def _frf_path(frf, tmp):
    if isinstance(frf, (str, os.PathLike)):
        return os.fspath(frf)
    if isinstance(frf, FRF):
        if frf.path is not None:
            return os.fspath(frf.path)
        path = os.path.join(tmp, "frf.csv")
        frf.to_csv(path)
        return path
    raise TypeError(f"frf: a {type(frf).__name__}; pass an FRF (read_frf or FRF(freq_hz, frf)) or a file path")


def _idle_path(idle, tmp):
    if isinstance(idle, (str, os.PathLike)):
        return os.fspath(idle)
    path = os.path.join(tmp, "idle.csv")
    if isinstance(idle, Record):
        _rs.write_signal_csv(path, idle.forces, list(idle.axes))
    else:
        _rs.write_signal_csv(path, idle, _axes_of(idle))
    return path


def nrmse(estimate, truth, fs, band_hz=None):
    """The project's accuracy figure: RMS error / std of the band-limited
    true force, both low-passed at ``band_hz`` (Hz; default min(4 kHz,
    0.4 fs)) with the first and last 5 % dropped (the score of
    ``compensate --report`` and ``examples/score.rs``). 1-D: a float; (n, k):
    one per column."""
    e = np.asarray(estimate, dtype=np.float64)
    t = np.asarray(truth, dtype=np.float64)
    if e.shape != t.shape:
        raise ValueError(f"nrmse: estimate {e.shape} and truth {t.shape}; pass arrays of the same shape")
    if e.ndim == 1:
        return _rs.accuracy(np.ascontiguousarray(e), np.ascontiguousarray(t), float(fs), band_hz)[0]
    return np.array([nrmse(e[:, k], t[:, k], fs, band_hz) for k in range(e.shape[1])])


class Simulation:
    """A simulated dynamometer, impact test and milling record with known
    true force: ``fs`` (Hz), ``t_s`` (n,) s, ``measured`` and ``true_force``
    (n, 3) N (columns x, y, z), ``idle`` (m, 3) N, ``frf`` the impact test's
    ``FRF``, ``truth`` the simulator's parameters (``truth.json``)."""

    def __init__(self, fs, t_s, measured, true_force, idle, frf, truth):
        self.fs, self.t_s = fs, t_s
        self.measured, self.true_force, self.idle = measured, true_force, idle
        self.frf, self.truth = frf, truth

    def __repr__(self):
        return f"Simulation(fs={self.fs}, {self.measured.shape[0]} samples, axes={self.frf.axes})"


def simulate(*, seed=1, **options) -> Simulation:
    """Simulate as ``dynocomp simulate`` does: every keyword is the CLI flag
    of the same name (``preset="cut-1"``, ``duration=0.5``, ``dyno="plate"``),
    with its defaults. Returns the arrays of the files it writes."""
    if "out" in options:
        raise ValueError("simulate: out= is not an option here; the arrays are returned")
    with tempfile.TemporaryDirectory(prefix="dynocomp-simulate-") as tmp:
        _rs.simulate_cli(["--out", tmp, "--seed", str(seed)] + _flags(options))
        meas = read_record(os.path.join(tmp, "measured.csv"))
        truth_f = read_record(os.path.join(tmp, "true_force.csv"))
        idle = read_record(os.path.join(tmp, "idle.csv"))
        frf = read_frf(os.path.join(tmp, "frf.uff"))
        frf.path = None
        truth = json.loads(Path(tmp, "truth.json").read_text())
        return Simulation(meas.fs, meas.t_s, meas.forces, truth_f.forces, idle.forces, frf, truth)
