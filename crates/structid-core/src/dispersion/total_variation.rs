//! The total-variation dispersion: D = Σ_(a,b)∈E c_ab·|v_a − v_b| over a graph on the sample points.
//!
//! Smooth dispersions (Gaussian, Fourier) round off corners and jumps. Many physical static
//! effects have them: Coulomb friction, relays, quantisers, dead zones, saturations. Total
//! variation charges for the *size* of changes, not their sharpness, so a jump costs no more than
//! a ramp of the same height and the estimate keeps it.
//!
//! # Scalar inputs (p = 1)
//! Sort the distinct values of z: ζ_1 < ζ_2 < … < ζ_G. Samples with **equal** z are one *node*:
//! they share one value v_g, because a static map takes one value at each point (the data then
//! decide v_g through all of them, in effect through their mean). The dispersion is the total
//! variation of the piecewise-linear interpolant through (ζ_g, v_g),
//!
//! ```text
//! D_TV(z, w) = Σ_g |v_(g+1) − v_g|,
//! ```
//!
//! and the [`Interpolant`] is that piecewise-linear function, held constant outside [ζ_1, ζ_G].
//! Distinct but close values stay distinct nodes; the penalty itself makes their values close.
//!
//! # Several inputs (p > 1)
//! Each input channel is scaled to [0, 1] by its range in the data (a channel with zero range is
//! ignored), duplicate points become one node as above, and the nodes are joined by the
//! symmetric k-nearest-neighbour graph (an edge when either point is among the other's k
//! nearest). The dispersion is the graph total variation Σ_(a,b)∈E |v_a − v_b| and the
//! interpolant weights the k nearest nodes by inverse squared distance in the scaled coordinates
//! ([`GraphInterpolation::InverseDistance`], exact at the nodes) or takes the nearest node's value
//! ([`GraphInterpolation::Nearest`]).
//!
//! # As a penalty
//! [`TotalVariation::penalty`] returns [`Penalty::TotalVariation`] with a [`TvPenalty`]: the
//! sample → node map, the weighted edges and the interpolation rule. Any other graph (weights by
//! distance, a user's own neighbourhoods) is a [`TvPenalty`] too, and runs through the same
//! solvers: the conic solver (Clarabel) and ADMM, see [`crate::solver`].
//!
//! # Example
//! ```
//! use std::sync::Arc;
//! use structid_core::scenarios::{hammerstein_map, Excitation};
//! use structid_core::{identify, IdentifySettings, TotalVariation};
//! // A relay behind a 2nd-order block, 300 samples, noise std 0.1.
//! let relay = |z: f64| if z >= 0.3 { 1.0 } else { -0.5 };
//! let exp = hammerstein_map(300, 2, 0.1, &relay, Excitation::White, Arc::new(TotalVariation::new()), 1)
//!     .unwrap();
//! let settings = IdentifySettings::builder().beta(0.003).build().unwrap();
//! let id = identify(&exp.model, &exp.data, &settings).unwrap();
//! assert_eq!(id.diagnostics.solver, "clarabel"); // chosen automatically at this size
//! let n = &id.blocks[0];
//! assert!((n.predict(&[-1.0]) + 0.5).abs() < 0.1 && (n.predict(&[1.0]) - 1.0).abs() < 0.1);
//! ```

use std::sync::Arc;

use structid_lti::Signal;

pub use super::graph::{NodeInterpolation, TvPenalty};
use crate::dispersion::neighbours::{
    KdTree, PiecewiseLinear, ScatteredInterpolant, Weighting, knn_graph,
};
use crate::dispersion::{Dispersion, Penalty};
use crate::error::{Error, Result};
use crate::model::interpolant::Interpolant;

/// How a multi-input total-variation estimate is evaluated between the nodes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum GraphInterpolation {
    /// The value of the nearest node (piecewise constant on Voronoi cells; keeps jumps sharp).
    Nearest,
    /// Σ_j v_j·d_j⁻² / Σ_j d_j⁻² over the k nearest nodes (continuous; exact at the nodes).
    #[default]
    InverseDistance,
}

/// The total-variation dispersion; see the [module documentation](self).
///
/// ```
/// use structid_core::{Dispersion, Penalty, Signal, TotalVariation};
/// let tv = TotalVariation::new();
/// let z = Signal::new(1, vec![0.3, -1.0, 0.3, 2.0]).unwrap();
/// let Penalty::TotalVariation(p) = tv.penalty(&z).unwrap() else { unreachable!() };
/// // Three distinct values: three nodes on a chain; the two samples at 0.3 share a node.
/// assert_eq!(p.nodes(), 3);
/// assert_eq!(p.node_of_sample(), &[1, 0, 1, 2]);
/// assert_eq!(p.value(&[0.0, 1.0, -1.0]), 3.0);
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct TotalVariation {
    neighbours: usize,
    interpolation: GraphInterpolation,
}

impl Default for TotalVariation {
    fn default() -> Self {
        Self::new()
    }
}

impl TotalVariation {
    /// Default number of neighbours k for p > 1.
    pub const DEFAULT_NEIGHBOURS: usize = 8;

    /// Total variation with the defaults: k = 8 neighbours and inverse-distance interpolation
    /// when p > 1 (both unused when p = 1).
    pub fn new() -> Self {
        Self {
            neighbours: Self::DEFAULT_NEIGHBOURS,
            interpolation: GraphInterpolation::default(),
        }
    }

    /// Largest k accepted (the graph has up to k·G edges).
    pub const MAX_NEIGHBOURS: usize = 1024;

    /// Sets k, the number of nearest neighbours of the graph for p > 1 (1 ≤ k ≤ 1024).
    pub fn with_neighbours(mut self, k: usize) -> Result<Self> {
        if !(1..=Self::MAX_NEIGHBOURS).contains(&k) {
            return Err(Error::InvalidParameter {
                name: "neighbours".into(),
                value: k as f64,
                reason: format!(
                    "the k-nearest-neighbour graph needs 1 ≤ k ≤ {}",
                    Self::MAX_NEIGHBOURS
                ),
            });
        }
        self.neighbours = k;
        Ok(self)
    }

    /// Sets the interpolation rule for p > 1.
    pub fn with_interpolation(mut self, interpolation: GraphInterpolation) -> Self {
        self.interpolation = interpolation;
        self
    }

    /// k.
    pub fn neighbours(&self) -> usize {
        self.neighbours
    }

    /// The interpolation rule for p > 1.
    pub fn interpolation(&self) -> GraphInterpolation {
        self.interpolation
    }
}

impl Dispersion for TotalVariation {
    fn describe(&self) -> String {
        format!("tv(k={})", self.neighbours)
    }

    fn parameters(&self) -> Vec<(String, f64)> {
        vec![("neighbours".into(), self.neighbours as f64)]
    }

    fn penalty(&self, z: &Signal) -> Result<Penalty> {
        check_points(z)?;
        let penalty = if z.channels() == 1 {
            chain_penalty(z)
        } else {
            graph_penalty(z, self.neighbours, self.interpolation)
        }?;
        Ok(Penalty::TotalVariation(penalty))
    }
}

fn check_points(z: &Signal) -> Result<()> {
    if z.channels() == 0 {
        return Err(Error::InvalidStructure(
            "a total-variation block needs at least one input channel".into(),
        ));
    }
    for k in 0..z.len() {
        for (c, v) in z.sample(k).iter().enumerate() {
            if !v.is_finite() {
                return Err(Error::NonFiniteData {
                    signal: "z".into(),
                    sample: k,
                    channel: c,
                    value: *v,
                });
            }
        }
    }
    Ok(())
}

/// Groups equal points (by `key`) into nodes numbered in sorted order; returns the node of each
/// sample and the first sample of each node.
fn group_equal(
    len: usize,
    cmp: impl Fn(usize, usize) -> std::cmp::Ordering,
) -> (Vec<usize>, Vec<usize>) {
    let mut order: Vec<usize> = (0..len).collect();
    order.sort_by(|&a, &b| cmp(a, b));
    let mut node_of_sample = vec![0; len];
    let mut representatives = Vec::new();
    for (pos, &k) in order.iter().enumerate() {
        if pos == 0 || cmp(order[pos - 1], k) != std::cmp::Ordering::Equal {
            representatives.push(k);
        }
        node_of_sample[k] = representatives.len() - 1;
    }
    (node_of_sample, representatives)
}

fn chain_penalty(z: &Signal) -> Result<TvPenalty> {
    // `+ 0.0` turns −0.0 into +0.0, so that the two zeros are one node.
    let zs: Vec<f64> = z.as_slice().iter().map(|v| v + 0.0).collect();
    let (node_of_sample, reps) = group_equal(zs.len(), |a, b| zs[a].total_cmp(&zs[b]));
    let knots: Vec<f64> = reps.iter().map(|&k| zs[k]).collect();
    let edges = (1..knots.len()).map(|g| (g - 1, g, 1.0)).collect();
    TvPenalty::new(
        node_of_sample,
        knots.len(),
        edges,
        Arc::new(ChainInterpolation { knots }),
    )
}

struct ChainInterpolation {
    knots: Vec<f64>,
}

impl NodeInterpolation for ChainInterpolation {
    fn interpolant(&self, values: Vec<f64>) -> Box<dyn Interpolant> {
        Box::new(PiecewiseLinearMap(PiecewiseLinear::new(
            self.knots.clone(),
            values,
        )))
    }

    fn describe(&self) -> String {
        "piecewise linear through the nodes, constant outside their range".into()
    }
}

pub(crate) struct PiecewiseLinearMap(pub(crate) PiecewiseLinear);

impl Interpolant for PiecewiseLinearMap {
    fn eval(&self, z: &[f64]) -> f64 {
        self.0.eval(z[0])
    }

    fn stored(&self) -> Option<crate::stored::StoredMap> {
        Some(crate::stored::StoredMap::PiecewiseLinear {
            knots: self.0.knots().to_vec(),
            values: self.0.values().to_vec(),
        })
    }
}

fn graph_penalty(z: &Signal, k: usize, interpolation: GraphInterpolation) -> Result<TvPenalty> {
    let p = z.channels();
    // Scale each channel to [0, 1] so that "nearest" does not depend on the units.
    let mut lo = vec![f64::INFINITY; p];
    let mut hi = vec![f64::NEG_INFINITY; p];
    for s in 0..z.len() {
        for (c, v) in z.sample(s).iter().enumerate() {
            lo[c] = lo[c].min(*v);
            hi[c] = hi[c].max(*v);
        }
    }
    let scale: Vec<f64> = lo
        .iter()
        .zip(&hi)
        .map(|(l, h)| if h > l { 1.0 / (h - l) } else { 0.0 })
        .collect();
    let scaled = Signal::from_fn(z.len(), p, |s, c| (z.get(s, c) - lo[c]) * scale[c] + 0.0);
    let (node_of_sample, reps) = group_equal(z.len(), |a, b| {
        let (x, y) = (scaled.sample(a), scaled.sample(b));
        x.iter()
            .zip(y)
            .map(|(u, v)| u.total_cmp(v))
            .find(|o| o.is_ne())
            .unwrap_or(std::cmp::Ordering::Equal)
    });
    let mut points = Vec::with_capacity(reps.len() * p);
    for &s in &reps {
        points.extend_from_slice(scaled.sample(s));
    }
    let edges = if reps.len() > 1 {
        knn_graph(&points, p, k)
            .into_iter()
            .map(|(a, b)| (a, b, 1.0))
            .collect()
    } else {
        Vec::new()
    };
    let weighting = match interpolation {
        GraphInterpolation::Nearest => Weighting::Nearest,
        GraphInterpolation::InverseDistance => Weighting::InverseDistance {
            neighbours: k,
            power: 2.0,
        },
    };
    TvPenalty::new(
        node_of_sample,
        reps.len(),
        edges,
        Arc::new(GraphNodes {
            tree: KdTree::new(&points, p),
            lo,
            scale,
            weighting,
        }),
    )
}

struct GraphNodes {
    tree: KdTree,
    lo: Vec<f64>,
    scale: Vec<f64>,
    weighting: Weighting,
}

impl NodeInterpolation for GraphNodes {
    fn interpolant(&self, values: Vec<f64>) -> Box<dyn Interpolant> {
        Box::new(ScaledScattered {
            inner: ScatteredInterpolant::new(self.tree.clone(), values, self.weighting),
            lo: self.lo.clone(),
            scale: self.scale.clone(),
        })
    }

    fn describe(&self) -> String {
        match self.weighting {
            Weighting::Nearest => "nearest node (inputs scaled to [0, 1])".into(),
            Weighting::InverseDistance { neighbours, .. } => format!(
                "inverse squared distance over the {neighbours} nearest nodes (inputs scaled to [0, 1])"
            ),
        }
    }
}

/// Scattered interpolation in inputs scaled to \[0, 1\]: q = (z − lo)·scale.
pub(crate) struct ScaledScattered {
    pub(crate) inner: ScatteredInterpolant,
    pub(crate) lo: Vec<f64>,
    pub(crate) scale: Vec<f64>,
}

impl Interpolant for ScaledScattered {
    fn eval(&self, z: &[f64]) -> f64 {
        let q: Vec<f64> = z
            .iter()
            .zip(self.lo.iter().zip(&self.scale))
            .map(|(v, (l, s))| (v - l) * s)
            .collect();
        self.inner.eval(&q)
    }

    fn stored(&self) -> Option<crate::stored::StoredMap> {
        let tree = self.inner.tree();
        let p = tree.dim();
        let mut data = Vec::with_capacity(tree.len() * p);
        for i in 0..tree.len() {
            data.extend_from_slice(tree.point(i));
        }
        Some(crate::stored::StoredMap::Scattered {
            nodes: crate::stored::StoredPoints { channels: p, data },
            values: self.inner.values().to_vec(),
            inverse_distance_neighbours: match self.inner.weighting() {
                Weighting::Nearest => None,
                Weighting::InverseDistance { neighbours, .. } => Some(neighbours),
            },
            lo: self.lo.clone(),
            scale: self.scale.clone(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn penalty(z: &Signal, tv: &TotalVariation) -> TvPenalty {
        match tv.penalty(z).unwrap() {
            Penalty::TotalVariation(p) => p,
            _ => unreachable!(),
        }
    }

    #[test]
    fn chain_sorts_and_merges_ties() {
        let z = Signal::new(1, vec![2.0, -1.0, 2.0, 0.5, -1.0]).unwrap();
        let p = penalty(&z, &TotalVariation::new());
        assert_eq!(p.nodes(), 3);
        assert_eq!(p.node_of_sample(), &[2, 0, 2, 1, 0]);
        assert_eq!(p.counts(), &[2, 1, 2]);
        assert!(p.is_chain());
        // TV of the piecewise-linear interpolant through sorted points.
        assert_eq!(p.value(&[1.0, -1.0, 0.0]), 3.0);
        let map = p.interpolant(vec![1.0, -1.0, 0.0]);
        assert_eq!(map.eval(&[-5.0]), 1.0);
        assert!((map.eval(&[-0.25]) - 0.0).abs() < 1e-12);
        assert_eq!(map.eval(&[9.0]), 0.0);
    }

    #[test]
    fn signed_zeros_are_one_node() {
        let z = Signal::new(1, vec![0.0, -0.0, 1.0]).unwrap();
        let p = penalty(&z, &TotalVariation::new());
        assert_eq!(p.nodes(), 2);
        assert_eq!(p.node_of_sample(), &[0, 0, 1]);
        let z2 = Signal::from_fn(3, 2, |s, c| if c == 0 { [0.0, -0.0, 1.0][s] } else { 0.0 });
        let p2 = penalty(&z2, &TotalVariation::new());
        assert_eq!(p2.nodes(), 2);
    }

    #[test]
    fn single_value_has_no_edges() {
        let z = Signal::new(1, vec![1.0; 4]).unwrap();
        let p = penalty(&z, &TotalVariation::new());
        assert_eq!((p.nodes(), p.edges().len()), (1, 0));
        assert_eq!(p.value(&[3.0]), 0.0);
    }

    #[test]
    fn bad_inputs_are_errors() {
        assert!(TotalVariation::new().with_neighbours(0).is_err());
        assert!(TotalVariation::new().with_neighbours(1025).is_err());
        let z = Signal::new(1, vec![1.0, f64::NAN]).unwrap();
        assert!(matches!(
            TotalVariation::new().penalty(&z),
            Err(Error::NonFiniteData { sample: 1, .. })
        ));
        let interp: Arc<dyn NodeInterpolation> = Arc::new(ChainInterpolation { knots: vec![] });
        assert!(TvPenalty::new(vec![0, 2], 2, vec![], interp.clone()).is_err());
        assert!(TvPenalty::new(vec![0, 0], 2, vec![], interp.clone()).is_err());
        assert!(TvPenalty::new(vec![0, 1], 2, vec![(0, 0, 1.0)], interp.clone()).is_err());
        assert!(TvPenalty::new(vec![0, 1], 2, vec![(0, 1, -1.0)], interp).is_err());
    }

    #[test]
    fn graph_merges_duplicates_and_is_symmetric() {
        // A 5×5 grid in two channels with different units, each point twice.
        let pts: Vec<(f64, f64)> = (0..50)
            .map(|s| ((s % 25 % 5) as f64, 100.0 * (s % 25 / 5) as f64))
            .collect();
        let z = Signal::from_fn(50, 2, |s, c| if c == 0 { pts[s].0 } else { pts[s].1 });
        let tv = TotalVariation::new().with_neighbours(4).unwrap();
        let p = penalty(&z, &tv);
        assert_eq!(p.nodes(), 25);
        assert!(p.counts().iter().all(|&c| c == 2));
        assert!(!p.is_chain());
        // Scaled to [0,1]² the 4 nearest neighbours of an interior point are its grid
        // neighbours, so every grid edge is present.
        let has = |a: usize, b: usize| p.edges().iter().any(|e| (e.0, e.1) == (a.min(b), a.max(b)));
        let node = |i: usize, j: usize| p.node_of_sample()[i + 5 * j];
        for j in 0..5 {
            for i in 0..4 {
                assert!(has(node(i, j), node(i + 1, j)));
                assert!(has(node(j, i), node(j, i + 1)));
            }
        }
        // Interpolation is exact at the nodes, in the original units.
        let v: Vec<f64> = (0..25).map(|g| g as f64).collect();
        let map = p.interpolant(v.clone());
        for s in 0..25 {
            assert!((map.eval(z.sample(s)) - v[p.node_of_sample()[s]]).abs() < 1e-12);
        }
    }
}
