//! Kernels and feature maps written in Python, plugged into the library's [`Kernel`] and
//! [`FeatureMap`] traits (the traits the Rust examples implement).
//!
//! Each evaluation is one vectorised call: a kernel k(Z₁, Z₂) returns the n₁ × n₂ Gram matrix
//! of two sets of points (one per row), a feature map φ(Z) the n × m features. The library
//! calls them from its worker threads, which take the GIL for the call; so every native call
//! that may evaluate them runs without the GIL ([`detach`]). A Python exception inside a call
//! cannot cross the library (whose traits return numbers); it is kept, the call yields NaN,
//! and [`detach`] raises the first one kept when the library returns.

use std::ops::Range;
use std::sync::{Arc, Mutex};

use numpy::PyReadonlyArray2;
use numpy::ndarray::Array2;
use numpy::{IntoPyArray, PyUntypedArrayMethods};
use pyo3::BoundObject;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use structid_core::dispersion::user::FeatureDispersion;
use structid_core::stored::StoredKernel;
use structid_core::{Dispersion, FeatureMap, Kernel, KernelDispersion, Signal};

use crate::convert::invalid;

/// The first exception a Python kernel raised during the running call.
static PENDING: Mutex<Option<PyErr>> = Mutex::new(None);

/// Held by the native call that may call Python kernels, so that such calls from several
/// Python threads run one at a time and each exception is raised by the call that caused it.
/// It is not reentrant: a Python kernel must not itself call a structid function that
/// evaluates Python kernels.
static CALLS: Mutex<()> = Mutex::new(());

fn keep(err: PyErr) {
    let mut pending = PENDING.lock().unwrap_or_else(|p| p.into_inner());
    if pending.is_none() {
        *pending = Some(err);
    }
}

fn take_pending() -> Option<PyErr> {
    PENDING.lock().unwrap_or_else(|p| p.into_inner()).take()
}

fn failed() -> bool {
    PENDING.lock().unwrap_or_else(|p| p.into_inner()).is_some()
}

/// Runs `f` without the GIL. With `python_kernels` (the call may evaluate a Python kernel),
/// it runs alone among such calls and raises the first exception a kernel raised during it,
/// before the library's own error, which it caused.
///
/// The library's worker threads take the GIL to call a Python kernel, so no native call may
/// hold the GIL while it uses them: every call that evaluates maps goes through here.
pub(crate) fn detach<T: Send>(
    py: Python<'_>,
    python_kernels: bool,
    f: impl FnOnce() -> PyResult<T> + Send,
) -> PyResult<T> {
    if !python_kernels {
        return py.detach(f);
    }
    py.detach(|| {
        let _alone = CALLS.lock().unwrap_or_else(|p| p.into_inner());
        take_pending();
        let out = f();
        match take_pending() {
            Some(e) => Err(e),
            None => out,
        }
    })
}

/// Rows `rows` of a signal as an n × p numpy array.
fn points<'py>(
    py: Python<'py>,
    z: &Signal,
    rows: Range<usize>,
) -> Bound<'py, numpy::PyArray2<f64>> {
    let p = z.channels();
    let data = z.as_slice()[rows.start * p..rows.end * p].to_vec();
    Array2::from_shape_vec((rows.len(), p), data)
        .expect("rows of a signal are rows × channels values")
        .into_pyarray(py)
}

/// Calls `func(args…)` and checks that it returned finite floats of shape `shape`; on any
/// failure keeps the exception and returns `None`.
fn call_matrix(
    name: &str,
    func: &Py<PyAny>,
    shape: (usize, usize),
    args: impl for<'py> FnOnce(Python<'py>) -> Vec<Bound<'py, PyAny>>,
) -> Option<Array2<f64>> {
    // After a first exception the call's result is discarded: spare the rest of the calls.
    if failed() {
        return None;
    }
    Python::attach(|py| {
        let run = || -> PyResult<Array2<f64>> {
            let args = pyo3::types::PyTuple::new(py, args(py))?;
            let out = func.call1(py, args)?;
            let out = py
                .import("numpy")?
                .getattr("asarray")?
                .call1((out, "float64"))?;
            let arr: PyReadonlyArray2<'_, f64> = out.extract().map_err(|_| {
                PyValueError::new_err(format!(
                    "{name} must return a 2-D array of numbers ({} × {} here)",
                    shape.0, shape.1
                ))
            })?;
            if arr.shape() != [shape.0, shape.1] {
                return Err(PyValueError::new_err(format!(
                    "{name} returned an array of shape {:?}; it must be {} × {}",
                    arr.shape(),
                    shape.0,
                    shape.1
                )));
            }
            let a = arr.as_array().to_owned();
            if let Some(bad) = a.iter().find(|v| !v.is_finite()) {
                return Err(PyValueError::new_err(format!(
                    "{name} returned the non-finite value {bad}"
                )));
            }
            Ok(a)
        };
        run().map_err(keep).ok()
    })
}

/// A kernel k(Z₁, Z₂) written in Python, with an optional width passed as a third argument
/// (what `sigma` and `sigma="auto"` set).
#[pyclass(module = "structid._structid", name = "Kernel", frozen)]
#[derive(Clone, Debug)]
pub struct PyKernel {
    func: Arc<Py<PyAny>>,
    name: String,
    width: Option<f64>,
}

#[pymethods]
impl PyKernel {
    /// `func(Z1, Z2)` (or `func(Z1, Z2, width)` when `width` is given) returns the Gram
    /// matrix of the rows of Z1 against those of Z2; `name` (by default the function's)
    /// identifies it in stored estimates.
    #[new]
    #[pyo3(signature = (func, name=None, width=None))]
    fn new(func: Bound<'_, PyAny>, name: Option<String>, width: Option<f64>) -> PyResult<Self> {
        let name = name_of(&func, name)?;
        if let Some(w) = width
            && !(w.is_finite() && w > 0.0)
        {
            return Err(invalid(format!(
                "invalid width {w}: it must be a finite number greater than zero"
            )));
        }
        Ok(Self {
            func: Arc::new(func.unbind()),
            name,
            width,
        })
    }

    fn __reduce__<'py>(&self, py: Python<'py>) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyAny>)> {
        let args = (self.func.clone_ref(py), self.name.clone(), self.width);
        reduce_to::<Self, _>(py, args)
    }

    /// The name it is stored under.
    #[getter]
    fn name(&self) -> &str {
        &self.name
    }

    /// The width, when it has one.
    #[getter]
    fn width(&self) -> Option<f64> {
        self.width
    }

    fn __repr__(&self) -> String {
        format!("Kernel({})", Kernel::describe(self))
    }
}

impl PyKernel {
    /// The matrix k(a_i, b_j), or `None` (exception kept).
    fn gram(&self, a: (&Signal, Range<usize>), b: (&Signal, Range<usize>)) -> Option<Array2<f64>> {
        let shape = (a.1.len(), b.1.len());
        call_matrix(
            &format!("kernel `{}`", self.name),
            &self.func,
            shape,
            |py| {
                let mut args = vec![
                    points(py, a.0, a.1.clone()).into_any(),
                    points(py, b.0, b.1.clone()).into_any(),
                ];
                if let Some(w) = self.width {
                    args.push(w.into_pyobject(py).expect("a float").into_any());
                }
                args
            },
        )
    }
}

fn copy_into(m: Option<Array2<f64>>, mut out: faer::MatMut<'_, f64>) {
    for i in 0..out.nrows() {
        for j in 0..out.ncols() {
            out[(i, j)] = m.as_ref().map_or(f64::NAN, |m| m[(i, j)]);
        }
    }
}

impl Kernel for PyKernel {
    fn eval(&self, a: &[f64], b: &[f64]) -> f64 {
        let a = Signal::new(a.len(), a.to_vec()).expect("one point");
        let b = Signal::new(b.len(), b.to_vec()).expect("one point");
        self.gram((&a, 0..1), (&b, 0..1))
            .map_or(f64::NAN, |m| m[(0, 0)])
    }

    fn describe(&self) -> String {
        match self.width {
            Some(w) => format!("{}(width={w})", self.name),
            None => self.name.clone(),
        }
    }

    fn parameters(&self) -> Vec<(String, f64)> {
        self.width
            .map(|w| ("width".into(), w))
            .into_iter()
            .collect()
    }

    fn width(&self) -> Option<f64> {
        self.width
    }

    fn with_width(&self, width: f64) -> Option<structid_core::Result<Self>> {
        self.width.map(|_| {
            Ok(Self {
                width: Some(width),
                ..self.clone()
            })
        })
    }

    fn stored_kernel(&self) -> Option<StoredKernel> {
        Some(StoredKernel::User {
            name: self.name.clone(),
            width: self.width,
        })
    }

    fn fill_gram_columns(&self, z: &Signal, cols: Range<usize>, out: faer::MatMut<'_, f64>) {
        copy_into(self.gram((z, 0..z.len()), (z, cols)), out);
    }

    fn fill_cross(&self, rows: &Signal, cols: &Signal, out: faer::MatMut<'_, f64>) {
        copy_into(self.gram((rows, 0..rows.len()), (cols, 0..cols.len())), out);
    }

    fn eval_expansion(&self, z: &[f64], centres: &Signal, alpha: &[f64]) -> f64 {
        let z = Signal::new(z.len(), z.to_vec()).expect("one point");
        match self.gram((&z, 0..1), (centres, 0..centres.len())) {
            Some(k) => alpha
                .iter()
                .zip(k.row(0))
                .filter(|(a, _)| **a != 0.0)
                .map(|(a, k)| a * k)
                .sum(),
            None => f64::NAN,
        }
    }
}

/// A feature map φ(Z) written in Python, with its weights λ: K = ΦΛΦᵀ.
#[pyclass(module = "structid._structid", name = "FeatureMap", frozen)]
#[derive(Clone)]
pub struct PyFeatures {
    func: Arc<Py<PyAny>>,
    name: String,
    weights: Vec<f64>,
}

#[pymethods]
impl PyFeatures {
    /// `func(Z)` returns the n × m features of the rows of Z; `weights` are the m weights
    /// λ > 0; `name` (by default the function's) identifies it in stored estimates.
    #[new]
    #[pyo3(signature = (func, weights, name=None))]
    fn new(func: Bound<'_, PyAny>, weights: Vec<f64>, name: Option<String>) -> PyResult<Self> {
        let name = name_of(&func, name)?;
        if weights.is_empty() {
            return Err(invalid("a feature map needs at least one weight"));
        }
        if let Some(w) = weights.iter().find(|w| !(w.is_finite() && **w > 0.0)) {
            return Err(invalid(format!(
                "invalid feature weight {w}: every weight must be a finite number greater than zero"
            )));
        }
        Ok(Self {
            func: Arc::new(func.unbind()),
            name,
            weights,
        })
    }

    fn __reduce__<'py>(&self, py: Python<'py>) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyAny>)> {
        let args = (
            self.func.clone_ref(py),
            self.weights.clone(),
            self.name.clone(),
        );
        reduce_to::<Self, _>(py, args)
    }

    /// The name it is stored under.
    #[getter]
    fn name(&self) -> &str {
        &self.name
    }

    /// The weights λ.
    #[getter]
    fn weights(&self) -> Vec<f64> {
        self.weights.clone()
    }

    fn __repr__(&self) -> String {
        format!("FeatureMap({}, {} features)", self.name, self.weights.len())
    }
}

impl PyFeatures {
    /// φ of the samples `t0..t0 + n` of `z` (n × m), or `None` (exception kept).
    fn features(&self, z: &Signal, t0: usize, n: usize) -> Option<Array2<f64>> {
        let shape = (n, self.weights.len());
        call_matrix(
            &format!("feature map `{}`", self.name),
            &self.func,
            shape,
            |py| vec![points(py, z, t0..t0 + n).into_any()],
        )
    }
}

impl FeatureMap for PyFeatures {
    fn dim(&self) -> usize {
        self.weights.len()
    }

    fn weights(&self) -> &[f64] {
        &self.weights
    }

    fn eval_into(&self, z: &[f64], out: &mut [f64]) {
        let z = Signal::new(z.len(), z.to_vec()).expect("one point");
        match self.features(&z, 0, 1) {
            Some(f) => out.iter_mut().zip(f.row(0)).for_each(|(o, v)| *o = *v),
            None => out.fill(f64::NAN),
        }
    }

    fn eval_rows(&self, z: &Signal, t0: usize, scale: &[f64], rows: &mut [f64]) {
        let m = self.dim();
        let f = self.features(z, t0, rows.len() / m);
        for (k, row) in rows.chunks_exact_mut(m).enumerate() {
            for (j, v) in row.iter_mut().enumerate() {
                *v = f.as_ref().map_or(f64::NAN, |f| f[(k, j)] * scale[j]);
            }
        }
    }

    /// The features of a block of samples, computed once for every column range the
    /// solver's threads ask for.
    fn prepared_len(&self) -> usize {
        self.dim()
    }

    fn prepare_rows(&self, z: &Signal, t0: usize, out: &mut [f64]) {
        self.eval_rows(z, t0, &vec![1.0; self.dim()], out);
    }

    fn eval_cols(
        &self,
        z: &Signal,
        t0: usize,
        cols: Range<usize>,
        scale: &[f64],
        rows: &mut [f64],
    ) {
        let w = cols.len().max(1);
        let mut prepared = vec![0.0; rows.len() / w * self.dim()];
        self.prepare_rows(z, t0, &mut prepared);
        self.eval_cols_prepared(z, t0, cols, scale, &prepared, rows);
    }

    fn eval_cols_prepared(
        &self,
        _z: &Signal,
        _t0: usize,
        cols: Range<usize>,
        scale: &[f64],
        prepared: &[f64],
        rows: &mut [f64],
    ) {
        let (m, w) = (self.dim(), cols.len());
        if w == 0 {
            return;
        }
        for (row, full) in rows.chunks_exact_mut(w).zip(prepared.chunks_exact(m)) {
            for (jj, v) in row.iter_mut().enumerate() {
                let j = cols.start + jj;
                *v = full[j] * scale[j];
            }
        }
    }

    fn combine_rows(&self, z: &Signal, t0: usize, coef: &[f64], out: &mut [f64]) {
        let f = self.features(z, t0, out.len());
        for (k, o) in out.iter_mut().enumerate() {
            *o = f.as_ref().map_or(f64::NAN, |f| {
                f.row(k).iter().zip(coef).map(|(p, c)| p * c).sum()
            });
        }
    }

    fn stored_features(&self) -> Option<StoredKernel> {
        Some(StoredKernel::User {
            name: self.name.clone(),
            width: None,
        })
    }
}

/// The name given, else the function's `__name__`; it must be callable and the name not
/// empty.
fn name_of(func: &Bound<'_, PyAny>, name: Option<String>) -> PyResult<String> {
    if !func.is_callable() {
        return Err(invalid("a kernel or feature map needs a callable"));
    }
    let name = match name {
        Some(n) => n,
        None => func
            .getattr("__name__")
            .and_then(|n| n.extract::<String>())
            .map_err(|_| invalid("the callable has no __name__; give a name"))?,
    };
    if name.trim().is_empty() {
        return Err(invalid("a user kernel needs a non-empty name"));
    }
    Ok(name)
}

/// A kernel or feature map object from Python, as the library's dispersion and as the
/// registry entry that reads estimates on it back.
#[derive(Clone)]
pub(crate) enum UserDispersion {
    Kernel(PyKernel),
    Features(PyFeatures),
}

impl UserDispersion {
    /// The object, if it is a `Kernel` or a `FeatureMap`.
    pub(crate) fn extract(obj: &Bound<'_, PyAny>) -> Option<Self> {
        if let Ok(k) = obj.cast::<PyKernel>() {
            return Some(Self::Kernel(k.get().clone()));
        }
        obj.cast::<PyFeatures>()
            .ok()
            .map(|f| Self::Features(f.get().clone()))
    }

    /// The dispersion.
    pub(crate) fn dispersion(&self) -> Arc<dyn Dispersion> {
        match self {
            Self::Kernel(k) => Arc::new(KernelDispersion::new(k.clone())),
            Self::Features(f) => Arc::new(FeatureDispersion::new(f.name.clone(), f.clone())),
        }
    }

    /// The name it is stored under.
    fn name(&self) -> &str {
        match self {
            Self::Kernel(k) => &k.name,
            Self::Features(f) => &f.name,
        }
    }

    /// The registry of these objects by name.
    pub(crate) fn registry(all: &[Self]) -> structid_core::dispersion::user::UserKernels {
        all.iter().fold(Default::default(), |acc, u| match u {
            Self::Kernel(k) => acc.with_kernel(k.name.clone(), Arc::new(k.clone())),
            Self::Features(f) => acc.with_features(f.name.clone(), Arc::new(f.clone())),
        })
    }

    /// The objects `objs` (with the blocks they are for), refusing two different callables
    /// under one name: the name is all an estimate stores of them.
    pub(crate) fn extract_all<'py, B: Clone>(
        objs: &[(B, Bound<'py, PyAny>)],
    ) -> PyResult<Vec<(B, Self)>> {
        let mut seen: Vec<(String, Bound<'py, PyAny>)> = Vec::new();
        let mut out = Vec::with_capacity(objs.len());
        for (b, obj) in objs {
            let u = Self::extract(obj).ok_or_else(|| {
                invalid("a kernel must be a structid.Kernel or a structid.FeatureMap")
            })?;
            let func = match &u {
                Self::Kernel(k) => k.func.bind(obj.py()).clone(),
                Self::Features(f) => f.func.bind(obj.py()).clone(),
            };
            if let Some((_, other)) = seen.iter().find(|(n, _)| n == u.name())
                && !other.is(&func)
            {
                return Err(invalid(format!(
                    "two different kernels are named `{}`; give each its own name= (an \
                     estimate stores kernels by name)",
                    u.name()
                )));
            }
            seen.push((u.name().to_string(), func));
            out.push((b.clone(), u));
        }
        Ok(out)
    }
}

/// The `__reduce__` pair (the class `T`, the arguments of its constructor) by which pickle
/// rebuilds a kernel or feature map from the Python function it wraps.
fn reduce_to<'py, T: pyo3::PyTypeInfo, A: IntoPyObject<'py>>(
    py: Python<'py>,
    args: A,
) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyAny>)> {
    Ok((
        py.get_type::<T>().into_any(),
        args.into_pyobject(py)
            .map_err(Into::into)?
            .into_bound()
            .into_any(),
    ))
}
