//! `gma` for Python: the workbench's read, fit, compare, diagnose and simulate with NumPy arrays
//! in and out. Every call goes through `host_sim::api`, so the checks, messages and result
//! fields are the CLI's; a refusal raises `gma.GmaError` (a `ValueError`) carrying the CLI's
//! message and where it points (`file`, `line`, `column`; `array`, `index` for array inputs).

use std::path::PathBuf;

use host_sim::api::{self, ArrayError, FitSettings, ParamsSource, Prediction, ReadSettings, Source};
use host_sim::error::Located;
use host_sim::files::escape_control;
use host_sim::loops::{LoopChannel, LoopFile};
use host_sim::recording::{Recording, COLUMNS};
use numpy::{PyArray1, PyReadonlyArray1};
use pyo3::create_exception;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyMapping};
use pyo3::BoundObject;

create_exception!(
    gma,
    GmaError,
    PyValueError,
    "A refused input or a failed command: the message is the `gma` CLI's; `file`, `line`, \
     `column` say where it points (None when it does not), `array` and `index` name the element \
     of an input array, `exit_code` is the CLI's exit status."
);

/// The CLI's exit status for a failed command.
const EXIT_FAILURE: u8 = 1;

/// A workbench error as `gma.GmaError`, with the fields of the CLI's `--json` error object.
fn to_py_err(py: Python<'_>, e: anyhow::Error) -> PyErr {
    let message = escape_control(&format!("{e:#}"));
    let located = e.chain().find_map(|c| c.downcast_ref::<Located>());
    let array = e.chain().find_map(|c| c.downcast_ref::<ArrayError>());
    let err = GmaError::new_err(message.clone());
    let value = err.value(py);
    // An array's fault points into the caller's arrays, not a file (even when the dict came
    // from `read_recording` and carries the file's name).
    let file = located.map(|l| l.file.clone());
    let attrs: [(&str, Py<PyAny>); 7] = [
        ("message", opt(py, Some(message))),
        ("file", opt(py, file.map(|f| escape_control(&f)))),
        ("line", opt(py, located.and_then(|l| l.line))),
        ("column", opt(py, located.and_then(|l| l.column))),
        ("array", opt(py, array.map(|a| a.array.clone()))),
        ("index", opt(py, array.and_then(|a| a.index))),
        ("exit_code", opt(py, Some(EXIT_FAILURE))),
    ];
    for (name, v) in attrs {
        if let Err(set_failed) = value.setattr(name, v) {
            return set_failed;
        }
    }
    err
}

fn opt<'py, T: IntoPyObject<'py>>(py: Python<'py>, v: Option<T>) -> Py<PyAny> {
    v.and_then(|v| v.into_pyobject(py).ok()).map(|o| o.into_any().unbind()).unwrap_or_else(|| py.None())
}

/// Doubts about what was read (`max_samples` cut the file short, columns not used) as Python
/// `UserWarning`s, which `warnings.catch_warnings` and notebooks see (stderr they may not).
/// Worded as every other call's notes and warnings (`note: …`, `warning: …`).
fn warn(py: Python<'_>, w: impl IntoIterator<Item = host_sim::warning::Warning>) -> PyResult<()> {
    let said: Vec<_> = w.into_iter().map(|w| w.said()).collect();
    say_as_warnings(py, &said)
}

/// The notes and warnings a call said (the CLI's `gma: note: …` and `gma: warning: …` lines) as
/// Python `UserWarning`s, each once: a notebook shows them under the cell, where it would not
/// show the process's stderr. With warnings turned into errors (`-W error`) the first raises.
fn say_as_warnings(py: Python<'_>, said: &[host_sim::warning::Said]) -> PyResult<()> {
    let mut seen = std::collections::HashSet::new();
    for s in said.iter().filter(|s| seen.insert(*s)) {
        let text = std::ffi::CString::new(escape_control(&s.to_string())).unwrap_or_default();
        PyErr::warn(py, &py.get_type::<pyo3::exceptions::PyUserWarning>(), &text, 1)?;
    }
    Ok(())
}

/// How often a running call looks for Ctrl-C.
const SIGNAL_POLL: std::time::Duration = std::time::Duration::from_millis(50);

/// Runs `f` without holding the GIL and maps its error to `gma.GmaError`. Ctrl-C (any signal
/// whose Python handler raises) stops it: `f` runs on a worker thread while this one, the
/// caller's, checks for signals; on one, every search is asked to stop
/// ([`host_sim::search::request_stop`]), the worker's result is discarded and the handler's
/// exception (`KeyboardInterrupt`) is raised. A call in another thread that the stop cut short
/// raises `GmaError` rather than return a truncated search.
fn run<T: Send>(py: Python<'_>, f: impl FnOnce() -> anyhow::Result<T> + Send) -> PyResult<T> {
    run_reporting(py, None, f)
}

/// Where a call's progress lines go (`progress=`), decided once per call.
enum ProgressTarget {
    /// A stream's `write` (True: Python's `sys.stderr`, which a notebook shows under the cell).
    Stream(Py<PyAny>),
    /// A callable, with each line.
    Call(Py<PyAny>),
}

impl ProgressTarget {
    /// What `progress=` asks for: nothing (None, False; True when `sys.stderr` is None, as under
    /// pythonw), `sys.stderr` (True), a callable, or an object with `write` (a file, sys.stdout).
    fn of(py: Python<'_>, progress: Option<&Bound<'_, PyAny>>) -> PyResult<Option<Self>> {
        let Some(p) = progress.filter(|p| !p.is_none()) else { return Ok(None) };
        if let Ok(on) = p.extract::<bool>() {
            if !on {
                return Ok(None);
            }
            let stderr = py.import("sys")?.getattr("stderr")?;
            return Ok((!stderr.is_none()).then(|| ProgressTarget::Stream(stderr.unbind())));
        }
        if p.is_callable() {
            return Ok(Some(ProgressTarget::Call(p.clone().unbind())));
        }
        if p.hasattr("write")? {
            return Ok(Some(ProgressTarget::Stream(p.clone().unbind())));
        }
        Err(to_py_err(
            py,
            anyhow::anyhow!(
                "progress must be None, True, False, a callable taking one str (a line) or a stream with \
                 write(), got {}",
                p.get_type().name().map(|n| n.to_string()).unwrap_or_else(|_| "an object".into())
            ),
        ))
    }

    /// Hands `line` over. A stream that fails to write (closed) is not the call's failure: the
    /// line is dropped; a callable that raises stops the call.
    fn say(&self, py: Python<'_>, line: &str) -> PyResult<()> {
        match self {
            ProgressTarget::Stream(stream) => {
                let stream = stream.bind(py);
                let written = stream.call_method1("write", (format!("{line}\n"),));
                if written.is_ok() && stream.hasattr("flush").unwrap_or(false) {
                    let _ = stream.call_method0("flush");
                }
                Ok(())
            }
            ProgressTarget::Call(f) => f.call1(py, (line,)).map(|_| ()),
        }
    }
}

/// [`run`], with the search's progress lines handed to `report` on the caller's thread, with the
/// GIL, as they come (the last ones once the work has ended). A callable that raises stops the
/// call like Ctrl-C, and its exception is raised. Calls with progress run one at a time
/// ([`host_sim::progress::to_sink`]); one interrupted while it waits for its turn never starts.
fn run_reporting<T: Send>(
    py: Python<'_>,
    report: Option<ProgressTarget>,
    f: impl FnOnce() -> anyhow::Result<T> + Send,
) -> PyResult<T> {
    let stops_before = host_sim::search::stops_requested();
    let (lines_tx, lines) = std::sync::mpsc::channel::<String>();
    let interrupted = std::sync::atomic::AtomicBool::new(false);
    // Moved in: the receiver is not shared, only this thread reads it.
    let outcome = py.detach(move || {
        std::thread::scope(|scope| {
            let caller = std::thread::current();
            let (reporting, interrupted) = (report.is_some(), &interrupted);
            let worker = scope.spawn(move || {
                // The notes and warnings the CLI writes to stderr, back to the caller's thread.
                let heard = host_sim::warning::heard(|| if reporting {
                    let say: host_sim::progress::Say = std::sync::Arc::new(move |line: &str| {
                        let _ = lines_tx.send(line.to_string());
                    });
                    host_sim::progress::to_sink(say, || {
                        if interrupted.load(std::sync::atomic::Ordering::Relaxed) {
                            anyhow::bail!("stopped before it started (interrupted while another call held the progress output)");
                        }
                        f()
                    })
                } else {
                    f()
                });
                caller.unpark(); // done: no need to wait out the poll
                heard
            });
            let mut interrupt = None;
            // The lines so far, with the GIL once per batch. `stop`: a callable that raises
            // stops the searches (not once the work has ended).
            let deliver = |interrupt: &mut Option<PyErr>, stop: bool| {
                let Some(target) = &report else { return };
                let batch: Vec<String> = lines.try_iter().collect();
                if batch.is_empty() || interrupt.is_some() {
                    return; // drained, not shown: the call is being stopped
                }
                Python::attach(|py| {
                    for line in &batch {
                        if let Err(e) = target.say(py, line) {
                            if stop {
                                host_sim::search::request_stop(true);
                            }
                            *interrupt = Some(e);
                            break;
                        }
                    }
                });
            };
            while !worker.is_finished() {
                std::thread::park_timeout(SIGNAL_POLL);
                deliver(&mut interrupt, true);
                if interrupt.is_none() {
                    if let Err(e) = Python::attach(|py| py.check_signals()) {
                        host_sim::search::request_stop(true);
                        interrupt = Some(e);
                    }
                }
                if interrupt.is_some() {
                    interrupted.store(true, std::sync::atomic::Ordering::Relaxed);
                }
            }
            let result = worker.join().unwrap_or_else(|panic| std::panic::resume_unwind(panic));
            deliver(&mut interrupt, false);
            host_sim::search::request_stop(false);
            match interrupt {
                Some(e) => Err(e),
                None => Ok(result),
            }
        })
    });
    let (result, said) = outcome?;
    say_as_warnings(py, &said)?;
    if host_sim::search::stops_requested() != stops_before {
        // Another thread's Ctrl-C stopped this call's searches too: its result is not a fit.
        return Err(to_py_err(
            py,
            anyhow::anyhow!(
                "stopped: an interrupt in another thread (Ctrl-C, or a progress callback that raised) stopped \
                 every running search"
            ),
        ));
    }
    result.map_err(|e| to_py_err(py, e))
}

/// An array-like as a 1-D float64 vector, or a `GmaError` naming it.
fn float_vec(py: Python<'_>, name: &str, array: &str, v: &Bound<'_, PyAny>) -> PyResult<Vec<f64>> {
    let bad = |why: String| {
        to_py_err(py, ArrayError { file: name.into(), array: array.into(), index: None, message: why }.into())
    };
    let np = py.import("numpy")?;
    // A masked array's data under its mask is not a sample: `asarray` would read it as one.
    let ma = np.getattr("ma")?;
    if ma.call_method1("isMaskedArray", (v,))?.extract::<bool>()? {
        let mask = ma.call_method1("getmaskarray", (v,))?;
        if mask.call_method0("any")?.extract::<bool>()? {
            let first: usize = np.call_method1("argmax", (mask.call_method0("ravel")?,))?.extract()?;
            let message = format!(
                "a masked array with masked samples (the first at index {first}): a masked sample is a missing \
                 one, and the data under the mask is not a measurement; fill or interpolate them, or cut the \
                 recording there, before the call"
            );
            return Err(to_py_err(
                py,
                ArrayError { file: name.into(), array: array.into(), index: Some(first), message }.into(),
            ));
        }
    }
    let as_given =
        np.call_method1("asarray", (v,)).map_err(|e| bad(format!("not an array of numbers ({e})")))?;
    // Integers and floats only: NumPy would turn booleans into 0/1, drop an imaginary part and
    // parse strings, each a different signal from the one meant.
    let dtype = as_given.getattr("dtype")?;
    let kind: String = dtype.getattr("kind")?.extract()?;
    if !matches!(kind.as_str(), "i" | "u" | "f") {
        return Err(bad(format!("not an array of real numbers (dtype {})", dtype.str()?)));
    }
    let kwargs = PyDict::new(py);
    kwargs.set_item("dtype", np.getattr("float64")?)?;
    let converted = np
        .call_method("asarray", (as_given,), Some(&kwargs))
        .map_err(|e| bad(format!("not an array of numbers ({e})")))?;
    let arr: PyReadonlyArray1<'_, f64> = converted
        .extract()
        .map_err(|_| bad(format!("must be one-dimensional, got {} dimensions", dims(&converted))))?;
    Ok(arr.as_array().to_vec())
}

fn dims(a: &Bound<'_, PyAny>) -> String {
    a.getattr("ndim").map(|d| d.to_string()).unwrap_or_else(|_| "?".into())
}

/// A recording given as a mapping of arrays named as the CSV columns (and an optional `name`).
fn recording_from_mapping(
    py: Python<'_>,
    m: &Bound<'_, PyMapping>,
    default_name: &str,
) -> PyResult<Recording> {
    let name = match m.get_item("name") {
        Ok(n) => n.extract::<String>()?,
        Err(_) => default_name.to_string(),
    };
    if m.contains("field_A_per_m")? {
        return Err(to_py_err(
            py,
            anyhow::anyhow!(
                "{name}: a magnetization loop given as arrays: loop files are fitted and compared from their \
                 paths only (pass the file's path; `read_loop`'s dict is for plotting)"
            ),
        ));
    }
    let mut arrays = Vec::new();
    for item in m.items()?.iter() {
        let (key, value): (String, Bound<'_, PyAny>) = item.extract()?;
        if key != "name" {
            let v = float_vec(py, &name, &key, &value)?;
            arrays.push((key, v));
        }
    }
    run(py, || api::recording_from_arrays(&name, arrays))
}

/// A fit or comparison input: a path, or a mapping of arrays.
fn source(py: Python<'_>, obj: &Bound<'_, PyAny>, k: usize) -> PyResult<Source> {
    if let Ok(m) = obj.cast::<PyMapping>() {
        return Ok(Source::Arrays(recording_from_mapping(py, m, &format!("<arrays {k}>"))?));
    }
    match obj.extract::<PathBuf>() {
        Ok(p) => Ok(Source::File(p)),
        Err(_) => Err(to_py_err(
            py,
            anyhow::anyhow!(
                "input {k}: expected a file path or a mapping of arrays (time_s, current_A, displacement_um, …), got {}",
                obj.get_type().name().map(|n| n.to_string()).unwrap_or_default()
            ),
        )),
    }
}

fn sources(py: Python<'_>, objs: &Bound<'_, PyAny>, first: usize) -> PyResult<Vec<Source>> {
    // A single path or mapping is one input, not a sequence of characters or keys.
    if objs.extract::<PathBuf>().is_ok() || objs.cast::<PyMapping>().is_ok() {
        return Ok(vec![source(py, objs, first)?]);
    }
    objs.try_iter()?.enumerate().map(|(k, o)| source(py, &o?, first + k)).collect()
}

/// `params`: None (the demo set), a parameter-file path, or a fit result (its `params_toml`).
fn params_source(py: Python<'_>, params: Option<&Bound<'_, PyAny>>) -> PyResult<ParamsSource> {
    let Some(p) = params.filter(|p| !p.is_none()) else { return Ok(ParamsSource::Demo) };
    if let Ok(m) = p.cast::<PyMapping>() {
        let text = m.get_item("params_toml").and_then(|t| t.extract::<String>()).map_err(|_| {
            to_py_err(
                py,
                anyhow::anyhow!("params: a mapping must be a fit result with a `params_toml` entry"),
            )
        })?;
        return Ok(ParamsSource::Text { name: "<fit result params_toml>".into(), text });
    }
    p.extract::<PathBuf>().map(ParamsSource::File).map_err(|_| {
        to_py_err(py, anyhow::anyhow!("params: expected None, a parameter-file path or a fit result"))
    })
}

/// A serialisable result as Python objects (through JSON: the fields of the CLI's `--json`).
fn json_to_py<'py>(py: Python<'py>, v: &impl serde::Serialize) -> PyResult<Bound<'py, PyAny>> {
    let text = serde_json::to_string(v).map_err(|e| to_py_err(py, e.into()))?;
    py.import("json")?.call_method1("loads", (text,))
}

fn array<'py>(py: Python<'py>, v: &[f64]) -> Bound<'py, PyArray1<f64>> {
    PyArray1::from_slice(py, v)
}

fn recording_dict<'py>(py: Python<'py>, r: &Recording) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("name", &r.name)?;
    let cols = [
        Some(&r.time_s),
        r.command_v.as_ref(),
        r.current_a.as_ref(),
        r.displacement_um.as_ref(),
        r.force_n.as_ref(),
        r.temperature_c.as_ref(),
        r.flux_density_t.as_ref(),
    ];
    for (name, col) in COLUMNS.iter().zip(cols) {
        if let Some(c) = col {
            d.set_item(*name, array(py, c))?;
        }
    }
    Ok(d)
}

fn loop_dict<'py>(py: Python<'py>, f: &LoopFile) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("name", &f.name)?;
    d.set_item("channel", f.channel.name())?;
    d.set_item("field_A_per_m", array(py, &f.h))?;
    let key = match f.channel {
        LoopChannel::FluxDensity => "flux_density_T",
        LoopChannel::Magnetization => "magnetization_A_per_m",
    };
    d.set_item(key, array(py, &f.value))?;
    Ok(d)
}

/// A whole-number keyword as the type the workbench takes, or a `GmaError` naming it (Python's
/// own conversion would raise `OverflowError` without the name).
fn whole<T: TryFrom<i128>>(py: Python<'_>, name: &str, v: Option<i128>, range: &str) -> PyResult<Option<T>> {
    v.map(|v| T::try_from(v).map_err(|_| to_py_err(py, anyhow::anyhow!("{name} must be {range}, got {v}"))))
        .transpose()
}

/// The read options; None is the CLI's default.
fn read_settings(
    py: Python<'_>,
    max_samples: Option<i128>,
    columns: Option<Vec<String>>,
    resample: Option<String>,
    trim_start_s: Option<f64>,
    skip_rows: Option<i128>,
) -> PyResult<ReadSettings> {
    let d = ReadSettings::default();
    let max_samples = whole(py, "max_samples", max_samples, "a whole number of at least 5")?;
    let skip_rows = whole(py, "skip_rows", skip_rows, "a whole number of at least 0")?;
    Ok(ReadSettings {
        max_samples: max_samples.unwrap_or(d.max_samples),
        columns: columns.unwrap_or_default(),
        resample,
        trim_start_s,
        skip_rows: skip_rows.unwrap_or(d.skip_rows),
    })
}

/// The search options; None is the CLI's default.
fn fit_settings(
    py: Python<'_>,
    seed: Option<i128>,
    effort: Option<f64>,
    time_limit_s: Option<f64>,
    fix: Option<Vec<String>>,
    bound: Option<Vec<String>>,
    progress: bool,
) -> PyResult<FitSettings> {
    let d = FitSettings::default();
    let seed = whole(py, "seed", seed, "a whole number in [0, 2^64)")?;
    Ok(FitSettings {
        seed: seed.unwrap_or(d.seed),
        effort: effort.unwrap_or(d.effort),
        time_limit_s,
        fix: fix.unwrap_or_default(),
        bound: bound.unwrap_or_default(),
        progress,
    })
}

/// Reads a measurement CSV (docs/formats.md) as the CLI does: a dict with `name` and one
/// float64 array per column present (`time_s` [s], `command_V` [V], `current_A` [A],
/// `displacement_um` [µm], `force_N` [N], `temperature_C` [°C], `flux_density_T` [T]). `columns`, `resample`, `trim_start_s`,
/// `skip_rows` and `max_samples` are the CLI's `--column`, `--resample`, `--trim-start`, `--skip-rows`,
/// `--max-samples`.
#[pyfunction]
#[pyo3(signature = (path, *, columns=None, resample=None, trim_start_s=None, skip_rows=None, max_samples=None))]
fn read_recording<'py>(
    py: Python<'py>,
    path: PathBuf,
    columns: Option<Vec<String>>,
    resample: Option<String>,
    trim_start_s: Option<f64>,
    skip_rows: Option<i128>,
    max_samples: Option<i128>,
) -> PyResult<Bound<'py, PyDict>> {
    let read = read_settings(py, max_samples, columns, resample, trim_start_s, skip_rows)?;
    let (r, cut) = run(py, || api::read_recording(path, &read))?;
    warn(py, cut)?;
    recording_dict(py, &r)
}

/// Reads a magnetization-loop file (B–H or M–H) as the CLI does: a dict with `name`, `channel`
/// (`flux_density` or `magnetization`), `field_A_per_m` and `flux_density_T` or
/// `magnetization_A_per_m` (SI units, converted from the file's).
#[pyfunction]
#[pyo3(signature = (path, *, max_samples=None))]
fn read_loop<'py>(py: Python<'py>, path: PathBuf, max_samples: Option<i128>) -> PyResult<Bound<'py, PyDict>> {
    let read = read_settings(py, max_samples, None, None, None, None)?;
    let (f, cut) = run(py, || api::read_loop(path, &read))?;
    warn(py, cut)?;
    loop_dict(py, &f)
}

/// Identifies `model` (a spec such as `ja+mech`) from `files` jointly — paths of recordings or
/// loop files, or dicts of arrays as `read_recording` returns — scored on `val`. Returns the
/// `gma fit --json` object as a dict, plus `params_toml` (the parameter file `--params-out`
/// writes; pass the result as `params=` to compare, diagnose, simulate). `progress=True` writes
/// the search's progress to `sys.stderr` as the CLI does (a line every few seconds; a notebook
/// shows it under the cell); a callable gets each line instead, a stream (`write`) is written to.
#[pyfunction]
#[pyo3(signature = (model, files, *, val=None, params=None, seed=None, effort=None, time_limit_s=None,
    fix=None, bound=None, columns=None, resample=None, trim_start_s=None, skip_rows=None, max_samples=None, progress=None))]
#[allow(clippy::too_many_arguments)]
fn fit<'py>(
    py: Python<'py>,
    model: String,
    files: &Bound<'py, PyAny>,
    val: Option<&Bound<'py, PyAny>>,
    params: Option<&Bound<'py, PyAny>>,
    seed: Option<i128>,
    effort: Option<f64>,
    time_limit_s: Option<f64>,
    fix: Option<Vec<String>>,
    bound: Option<Vec<String>>,
    columns: Option<Vec<String>>,
    resample: Option<String>,
    trim_start_s: Option<f64>,
    skip_rows: Option<i128>,
    max_samples: Option<i128>,
    progress: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyAny>> {
    let report = ProgressTarget::of(py, progress)?;
    let fit_src = sources(py, files, 0)?;
    let val_src = match val {
        Some(v) if !v.is_none() => sources(py, v, fit_src.len())?,
        _ => Vec::new(),
    };
    let ps = params_source(py, params)?;
    let settings = fit_settings(py, seed, effort, time_limit_s, fix, bound, report.is_some())?;
    let read = read_settings(py, max_samples, columns, resample, trim_start_s, skip_rows)?;
    let out = run_reporting(py, report, || api::fit(&model, &fit_src, &val_src, &ps, &settings, &read))?;
    let d = json_to_py(py, &out.summary)?;
    d.set_item("params_toml", out.params_toml)?;
    Ok(d)
}

/// Compares `model` with `params` against `files` (as `fit` takes them): the `gma compare
/// --json` object as a dict, plus `predictions`, one dict per input: for a recording `time_s`,
/// `displacement_um` (model, with the fitted offset), `current_A`, `field_A_per_m`,
/// `magnetization_A_per_m`; for a loop file `field_A_per_m` and the model's `flux_density_T` or
/// `magnetization_A_per_m`.
#[pyfunction]
#[pyo3(signature = (model, files, *, params=None, columns=None, resample=None, trim_start_s=None, skip_rows=None, max_samples=None))]
#[allow(clippy::too_many_arguments)]
fn compare<'py>(
    py: Python<'py>,
    model: String,
    files: &Bound<'py, PyAny>,
    params: Option<&Bound<'py, PyAny>>,
    columns: Option<Vec<String>>,
    resample: Option<String>,
    trim_start_s: Option<f64>,
    skip_rows: Option<i128>,
    max_samples: Option<i128>,
) -> PyResult<Bound<'py, PyAny>> {
    let src = sources(py, files, 0)?;
    let ps = params_source(py, params)?;
    let read = read_settings(py, max_samples, columns, resample, trim_start_s, skip_rows)?;
    let (summary, predictions) = run(py, || api::compare(&model, &ps, &src, &read))?;
    let d = json_to_py(py, &summary)?;
    let list: Vec<Bound<'py, PyDict>> =
        predictions.iter().map(|p| prediction_dict(py, p)).collect::<PyResult<_>>()?;
    d.set_item("predictions", list)?;
    Ok(d)
}

fn prediction_dict<'py>(py: Python<'py>, p: &Prediction) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    match p {
        Prediction::Recording { name, time_s, sim } => {
            d.set_item("name", name)?;
            d.set_item("time_s", array(py, time_s))?;
            simulation_items(py, &d, sim)?;
        }
        Prediction::Loop { name, field_a_per_m, channel, value } => {
            d.set_item("name", name)?;
            d.set_item("channel", *channel)?;
            d.set_item("field_A_per_m", array(py, field_a_per_m))?;
            let key = if *channel == "flux_density" { "flux_density_T" } else { "magnetization_A_per_m" };
            d.set_item(key, array(py, value))?;
        }
    }
    Ok(d)
}

fn simulation_items(
    py: Python<'_>,
    d: &Bound<'_, PyDict>,
    sim: &host_sim::simulated::Simulation,
) -> PyResult<()> {
    d.set_item("displacement_um", array(py, &sim.displacement_um))?;
    d.set_item("current_A", array(py, &sim.current_a))?;
    d.set_item("field_A_per_m", array(py, &sim.field_a_per_m))?;
    d.set_item("magnetization_A_per_m", array(py, &sim.magnetization_a_per_m))
}

/// Fits `model`, analyses what it leaves unexplained and names the missing effect: the `gma
/// diagnose --json` object as a dict (`verdict`, `candidates`, `findings`, …). `progress` as
/// for `fit` (a diagnosis refits the model once per candidate effect: a minute or more).
#[pyfunction]
#[pyo3(signature = (model, files, *, val=None, params=None, seed=None, effort=None, time_limit_s=None,
    columns=None, resample=None, trim_start_s=None, skip_rows=None, max_samples=None, progress=None))]
#[allow(clippy::too_many_arguments)]
fn diagnose<'py>(
    py: Python<'py>,
    model: String,
    files: &Bound<'py, PyAny>,
    val: Option<&Bound<'py, PyAny>>,
    params: Option<&Bound<'py, PyAny>>,
    seed: Option<i128>,
    effort: Option<f64>,
    time_limit_s: Option<f64>,
    columns: Option<Vec<String>>,
    resample: Option<String>,
    trim_start_s: Option<f64>,
    skip_rows: Option<i128>,
    max_samples: Option<i128>,
    progress: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyAny>> {
    let report = ProgressTarget::of(py, progress)?;
    let fit_src = sources(py, files, 0)?;
    let val_src = match val {
        Some(v) if !v.is_none() => sources(py, v, fit_src.len())?,
        _ => Vec::new(),
    };
    let ps = params_source(py, params)?;
    let settings = fit_settings(py, seed, effort, time_limit_s, None, None, report.is_some())?;
    let read = read_settings(py, max_samples, columns, resample, trim_start_s, skip_rows)?;
    let d = run_reporting(py, report, || api::diagnose(&model, &fit_src, &val_src, &ps, &settings, &read))?;
    json_to_py(py, &d)
}

/// A SIMULATED rig (the plant simulator) under a standard excitation: `gma simulate` with the
/// same options, units, defaults (an option left at None is the CLI's default) and refusals.
/// Returns a recording dict as `read_recording` does, named `name`.
#[pyfunction]
#[pyo3(signature = (model=None, *, params=None, waveform=None, freq_hz=None, amplitude=None, bias=None,
    duration_s=None, noise_um=None, quantum_um=None, offset_um=None, oversample=None, eddy_model=None,
    no_current=false, search_coil=false, flux_noise_mt=None, seed=None, name="simulated"))]
#[allow(clippy::too_many_arguments)]
fn simulate<'py>(
    py: Python<'py>,
    model: Option<&str>,
    params: Option<&Bound<'py, PyAny>>,
    waveform: Option<&str>,
    freq_hz: Option<f64>,
    amplitude: Option<f64>,
    bias: Option<f64>,
    duration_s: Option<f64>,
    noise_um: Option<f64>,
    quantum_um: Option<f64>,
    offset_um: Option<f64>,
    oversample: Option<i128>,
    eddy_model: Option<&str>,
    no_current: bool,
    search_coil: bool,
    flux_noise_mt: Option<f64>,
    seed: Option<i128>,
    name: &str,
) -> PyResult<Bound<'py, PyDict>> {
    let ps = params_source(py, params)?;
    let numbers = [
        ("--freq-hz", freq_hz),
        ("--amplitude", amplitude),
        ("--bias", bias),
        ("--duration-s", duration_s),
        ("--noise-um", noise_um),
        ("--quantum-um", quantum_um),
        ("--offset-um", offset_um),
        ("--flux-noise-mt", flux_noise_mt),
    ];
    let mut options: Vec<(String, Option<String>)> =
        numbers.iter().filter_map(|(o, v)| v.map(|v| (o.to_string(), Some(v.to_string())))).collect();
    for (o, v) in [("--waveform", waveform), ("--eddy-model", eddy_model)] {
        options.extend(v.map(|v| (o.to_string(), Some(v.to_string()))));
    }
    options.extend(oversample.map(|v| ("--oversample".to_string(), Some(v.to_string()))));
    options.extend(seed.map(|v| ("--seed".to_string(), Some(v.to_string()))));
    if no_current {
        options.push(("--no-current".into(), None));
    }
    if search_coil {
        options.push(("--search-coil".into(), None));
    }
    let r = run(py, || api::simulate_rig(model, &ps, &options, name))?;
    recording_dict(py, &r)
}

/// The model's response to a drive given as arrays: `drive` is a dict with `time_s` [s] and
/// `current_A` [A] (or `command_V` [V] for a model with `amp`). Returns `time_s`,
/// `displacement_um`, `current_A`, `field_A_per_m`, `magnetization_A_per_m`. The rod starts
/// demagnetised, or after `initial_excursion_a_per_m` [A/m] (the state `compare` estimated: its
/// `files[].initial_excursion_a_per_m`). `initial_excursion_A_per_m` is the same keyword under
/// its first name.
#[pyfunction]
#[pyo3(signature = (model, drive, *, params=None, initial_excursion_a_per_m=None, initial_excursion_A_per_m=None))]
#[allow(non_snake_case)]
fn model_response<'py>(
    py: Python<'py>,
    model: String,
    drive: &Bound<'py, PyAny>,
    params: Option<&Bound<'py, PyAny>>,
    initial_excursion_a_per_m: Option<f64>,
    initial_excursion_A_per_m: Option<f64>,
) -> PyResult<Bound<'py, PyDict>> {
    let initial_excursion = match (initial_excursion_a_per_m, initial_excursion_A_per_m) {
        (Some(_), Some(_)) => {
            return Err(to_py_err(
                py,
                anyhow::anyhow!(
                    "initial_excursion_a_per_m and initial_excursion_A_per_m are one keyword: give it once"
                ),
            ))
        }
        (a, b) => a.or(b),
    };
    let m = drive.cast::<PyMapping>().map_err(|_| {
        to_py_err(
            py,
            anyhow::anyhow!(
                "drive: expected a mapping of arrays with `time_s` and `current_A` or `command_V`"
            ),
        )
    })?;
    let rec = recording_from_mapping(py, m, "<drive>")?;
    let ps = params_source(py, params)?;
    let sim = run(py, || api::model_response(&model, &ps, &rec, initial_excursion))?;
    let d = PyDict::new(py);
    d.set_item("time_s", array(py, &rec.time_s))?;
    simulation_items(py, &d, &sim)?;
    Ok(d)
}

/// The gma workbench for giant-magnetostrictive (Terfenol-D) actuators, with NumPy arrays in and
/// out: `read_recording`, `read_loop`, `fit`, `compare`, `diagnose`, `simulate` (SIMULATED data)
/// and `model_response`, each the `gma` CLI's command with its checks, messages and result
/// fields (`help(gma.fit)`; the project's docs/cli.md). A refusal raises `GmaError`.
#[pymodule]
fn gma(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("GmaError", m.py().get_type::<GmaError>())?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add_function(wrap_pyfunction!(read_recording, m)?)?;
    m.add_function(wrap_pyfunction!(read_loop, m)?)?;
    m.add_function(wrap_pyfunction!(fit, m)?)?;
    m.add_function(wrap_pyfunction!(compare, m)?)?;
    m.add_function(wrap_pyfunction!(diagnose, m)?)?;
    m.add_function(wrap_pyfunction!(simulate, m)?)?;
    m.add_function(wrap_pyfunction!(model_response, m)?)?;
    Ok(())
}
