//! Kernels and feature maps defined outside this crate (in user code, or in another language
//! through the Python bindings), and how estimates on them are stored and read back.
//!
//! A user kernel k(z₁, z₂) enters identification through [`crate::KernelDispersion`], a user
//! feature map ψ with weights λ (K = ΨΛΨᵀ) through [`FeatureDispersion`]; both then pose the
//! paper's problem min (1/L)·Σ|e_k|² + β·wᵀK⁻¹w like the built-in Gaussian or Fourier
//! dispersions, with every solver and criterion.
//!
//! Their code cannot be written to a file. Their stored form is a name,
//! [`StoredKernel::User`], next to the numbers of the estimate (the centres and α of
//! N̂(z) = Σ_k α_k k(z, z_k), or the coefficients c of N̂(z) = ψ(z)ᵀc). An estimate made in
//! memory keeps its kernels (they are gathered from the model's dispersions by
//! [`crate::Dispersion::user_kernels`]); an estimate read back from its stored form takes them
//! again, by name, from a [`UserKernels`] registry
//! ([`crate::Estimate::from_data_with_kernels`]).

use std::fmt;
use std::ops::Range;
use std::sync::Arc;

use faer::MatMut;
use structid_lti::Signal;

use crate::dispersion::fourier::FeaturePenalty;
use crate::dispersion::kernel::Kernel;
use crate::dispersion::{Dispersion, FeatureMap, Penalty};
use crate::error::{Error, Result};
use crate::stored::StoredKernel;

/// A user-defined kernel or feature map, as a registry holds it.
#[derive(Clone)]
pub enum UserKernel {
    /// A kernel k(z₁, z₂): estimates on it are kernel expansions.
    Kernel(SharedKernel),
    /// A feature map ψ with weights λ: estimates on it are feature expansions.
    Features(Arc<dyn FeatureMap>),
}

impl fmt::Debug for UserKernel {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            UserKernel::Kernel(k) => write!(f, "Kernel({})", k.kernel.describe()),
            UserKernel::Features(m) => write!(f, "Features(dim = {})", m.dim()),
        }
    }
}

/// The same kernel at another width, or `None` when it has none.
type AtWidth = dyn Fn(f64) -> Option<Result<Arc<dyn Kernel>>> + Send + Sync;

/// A kernel behind a trait object that can still be set to another width (what a stored
/// estimate whose σ was selected needs).
#[derive(Clone)]
pub struct SharedKernel {
    kernel: Arc<dyn Kernel>,
    at_width: Arc<AtWidth>,
}

impl SharedKernel {
    /// The kernel `kernel`.
    pub fn new<K: Kernel + 'static>(kernel: Arc<K>) -> Self {
        let base = Arc::clone(&kernel);
        Self {
            kernel,
            at_width: Arc::new(move |w| {
                base.with_width(w)
                    .map(|k| k.map(|k| Arc::new(k) as Arc<dyn Kernel>))
            }),
        }
    }

    /// The kernel as registered.
    pub fn kernel(&self) -> &Arc<dyn Kernel> {
        &self.kernel
    }

    /// The kernel at `width` (as registered for `None` or its own width).
    ///
    /// # Errors
    /// [`Error::InconsistentStored`] for a width given to a kernel without one, and the
    /// kernel's own error for a width it refuses.
    pub fn at_width(&self, name: &str, width: Option<f64>) -> Result<Arc<dyn Kernel>> {
        match width {
            None => Ok(Arc::clone(&self.kernel)),
            Some(w) if self.kernel.width() == Some(w) => Ok(Arc::clone(&self.kernel)),
            Some(w) => (self.at_width)(w).unwrap_or_else(|| {
                Err(Error::InconsistentStored {
                    item: format!("user kernel `{name}`"),
                    detail: format!(
                        "the estimate used it at width {w}, but the kernel given has no width"
                    ),
                })
            }),
        }
    }
}

/// User-defined kernels and feature maps by name: what reading an estimate on them back needs
/// (their stored form is the name only).
///
/// ```
/// use std::sync::Arc;
/// use structid_core::GaussianKernel;
/// use structid_core::dispersion::user::UserKernels;
/// let kernels = UserKernels::new().with_kernel("wide", Arc::new(GaussianKernel::new(2.0).unwrap()));
/// assert!(kernels.get("wide").is_ok());
/// assert!(kernels.get("narrow").unwrap_err().to_string().contains("`narrow`"));
/// ```
#[derive(Clone, Debug, Default)]
pub struct UserKernels {
    entries: Vec<(String, UserKernel)>,
}

impl UserKernels {
    /// An empty registry.
    pub fn new() -> Self {
        Self::default()
    }

    /// The registry with the kernel `kernel` under `name` (replacing one of that name). The
    /// name identifies the kernel: two different kernels need two names.
    pub fn with_kernel<K: Kernel + 'static>(self, name: impl Into<String>, kernel: Arc<K>) -> Self {
        self.with(name.into(), UserKernel::Kernel(SharedKernel::new(kernel)))
    }

    /// The registry with the feature map `features` under `name` (replacing one of that name).
    pub fn with_features(self, name: impl Into<String>, features: Arc<dyn FeatureMap>) -> Self {
        self.with(name.into(), UserKernel::Features(features))
    }

    fn with(mut self, name: String, entry: UserKernel) -> Self {
        self.entries.retain(|(n, _)| *n != name);
        self.entries.push((name, entry));
        self
    }

    /// Both registries; on a name in both, `other`'s entry.
    pub fn merged(self, other: UserKernels) -> Self {
        other
            .entries
            .into_iter()
            .fold(self, |acc, (name, entry)| acc.with(name, entry))
    }

    /// The entry named `name`.
    ///
    /// # Errors
    /// [`Error::UserKernelMissing`] when the registry has no such entry.
    pub fn get(&self, name: &str) -> Result<&UserKernel> {
        self.entries
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, e)| e)
            .ok_or_else(|| Error::UserKernelMissing { name: name.into() })
    }

    /// The names in the registry.
    pub fn names(&self) -> Vec<&str> {
        self.entries.iter().map(|(n, _)| n.as_str()).collect()
    }

    /// Whether the registry is empty.
    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }
}

/// The registry entry of a kernel whose stored form is [`StoredKernel::User`], if it is one.
pub(crate) fn user_kernel_of<K: Kernel + 'static>(kernel: &Arc<K>) -> UserKernels {
    match kernel.stored_kernel() {
        Some(StoredKernel::User { name, .. }) => {
            UserKernels::new().with_kernel(name, Arc::clone(kernel))
        }
        _ => UserKernels::new(),
    }
}

/// A kernel behind a trait object, as a sized [`Kernel`] (a rebuilt kernel expansion holds
/// it). Every method forwards, so batched overrides of the user's kernel keep working.
#[derive(Debug)]
pub(crate) struct DynKernel(pub(crate) Arc<dyn Kernel>);

impl Kernel for DynKernel {
    fn eval(&self, a: &[f64], b: &[f64]) -> f64 {
        self.0.eval(a, b)
    }
    fn describe(&self) -> String {
        self.0.describe()
    }
    fn parameters(&self) -> Vec<(String, f64)> {
        self.0.parameters()
    }
    fn width(&self) -> Option<f64> {
        self.0.width()
    }
    fn stored_kernel(&self) -> Option<StoredKernel> {
        self.0.stored_kernel()
    }
    fn fill_gram(&self, z: &Signal, out: MatMut<'_, f64>) {
        self.0.fill_gram(z, out)
    }
    fn fill_gram_columns(&self, z: &Signal, cols: Range<usize>, out: MatMut<'_, f64>) {
        self.0.fill_gram_columns(z, cols, out)
    }
    fn fill_cross(&self, rows: &Signal, cols: &Signal, out: MatMut<'_, f64>) {
        self.0.fill_cross(rows, cols, out)
    }
    fn eval_expansion(&self, z: &[f64], centres: &Signal, alpha: &[f64]) -> f64 {
        self.0.eval_expansion(z, centres, alpha)
    }
}

/// Any [`FeatureMap`] ψ with weights λ as a quadratic dispersion: D(z, w) = wᵀK⁻¹w with
/// K = ΨΛΨᵀ, solved in feature space (cost linear in L) by the feature solver.
///
/// ```
/// use structid_core::dispersion::user::FeatureDispersion;
/// use structid_core::{Dispersion, FeatureMap, Penalty, Signal};
///
/// /// ψ(z) = [1, z, z²] with weights 1, 1, 0.5.
/// struct Quadratic;
/// impl FeatureMap for Quadratic {
///     fn dim(&self) -> usize { 3 }
///     fn weights(&self) -> &[f64] { &[1.0, 1.0, 0.5] }
///     fn eval_into(&self, z: &[f64], out: &mut [f64]) {
///         out.copy_from_slice(&[1.0, z[0], z[0] * z[0]]);
///     }
/// }
///
/// let d = FeatureDispersion::new("quadratic", Quadratic);
/// let z = Signal::from_fn(10, 1, |k, _| k as f64 / 9.0);
/// let Penalty::Quadratic(p) = d.penalty(&z).unwrap() else { unreachable!() };
/// assert!(p.features().is_some());
/// ```
pub struct FeatureDispersion<F: FeatureMap> {
    map: Arc<Features<F>>,
}

impl<F: FeatureMap> fmt::Debug for FeatureDispersion<F> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "FeatureDispersion({})", self.map.name)
    }
}

impl<F: FeatureMap + 'static> FeatureDispersion<F> {
    /// The dispersion of the feature map `map`, described as `name` in reports.
    pub fn new(name: impl Into<String>, map: F) -> Self {
        Self {
            map: Arc::new(Features {
                map: Arc::new(map),
                name: name.into(),
            }),
        }
    }

    /// The feature map.
    pub fn features(&self) -> &F {
        &self.map.map
    }
}

impl<F: FeatureMap + 'static> Dispersion for FeatureDispersion<F> {
    fn describe(&self) -> String {
        self.map.name.clone()
    }

    fn penalty(&self, z: &Signal) -> Result<Penalty> {
        Ok(Penalty::Quadratic(Box::new(FeaturePenalty {
            map: Arc::clone(&self.map.map),
            kernel: Arc::clone(&self.map),
            z: z.clone(),
        })))
    }

    fn user_kernels(&self) -> UserKernels {
        match self.map.map.stored_features() {
            Some(StoredKernel::User { name, .. }) => UserKernels::new()
                .with_features(name, Arc::clone(&self.map.map) as Arc<dyn FeatureMap>),
            _ => UserKernels::new(),
        }
    }
}

/// A user's feature map with its name, as the [`Kernel`] K(a, b) = ψ(a)ᵀΛψ(b) that the
/// feature penalty takes its Gram columns from.
struct Features<F: FeatureMap> {
    map: Arc<F>,
    name: String,
}

impl<F: FeatureMap> fmt::Debug for Features<F> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "Features({})", self.name)
    }
}

impl<F: FeatureMap> Kernel for Features<F> {
    fn eval(&self, a: &[f64], b: &[f64]) -> f64 {
        crate::dispersion::feature_kernel(&*self.map, a, b)
    }

    /// K(a_i, b_j) = ψ(a_i)ᵀΛψ(b_j) as one product of the two feature matrices (each
    /// evaluated in one call), for the solvers that work with Gram matrices.
    fn fill_cross(&self, rows: &Signal, cols: &Signal, out: MatMut<'_, f64>) {
        let m = self.map.dim();
        let mut a = vec![0.0; rows.len() * m];
        self.map.eval_rows(rows, 0, self.map.weights(), &mut a);
        let mut b = vec![0.0; cols.len() * m];
        self.map.eval_rows(cols, 0, &vec![1.0; m], &mut b);
        faer::linalg::matmul::matmul(
            out,
            faer::Accum::Replace,
            faer::MatRef::from_row_major_slice(&a, rows.len(), m),
            faer::MatRef::from_row_major_slice(&b, cols.len(), m).transpose(),
            1.0,
            faer::get_global_parallelism(),
        );
    }

    fn fill_gram_columns(&self, z: &Signal, cols: Range<usize>, out: MatMut<'_, f64>) {
        let p = z.channels();
        let picked = Signal::new(p, z.as_slice()[cols.start * p..cols.end * p].to_vec())
            .expect("columns of a signal are a signal");
        self.fill_cross(z, &picked, out);
    }
    fn describe(&self) -> String {
        self.name.clone()
    }
    fn stored_kernel(&self) -> Option<StoredKernel> {
        self.map.stored_features()
    }
}
