//! A graph total-variation penalty on node values, D(w) = Σ_(a,b)∈E c_ab·|v_a − v_b|: what the
//! total-variation dispersion ([`super::total_variation`]) becomes once its sample points are
//! known, and what the conic and ADMM solvers work on.

use std::fmt;
use std::sync::Arc;

use crate::error::{Error, Result};
use crate::model::interpolant::Interpolant;

/// Turns node values into an interpolant (the map between and beyond the nodes).
pub trait NodeInterpolation: Send + Sync {
    /// The interpolant through the node values `values` (one per node).
    fn interpolant(&self, values: Vec<f64>) -> Box<dyn Interpolant>;

    /// One line for reports.
    fn describe(&self) -> String;
}

/// A graph total-variation penalty D(w) = Σ_(a,b)∈E c_ab·|v_a − v_b| on node values v, with
/// every sample taking its node's value: w_k = v_node(k).
///
/// Solvers treat the node values as the unknowns, so samples that share a node share a value
/// exactly. When the edges are exactly (0,1), (1,2), …, (G−2, G−1) the graph is a chain and
/// solvers use the O(G) one-dimensional proximal operator ([`crate::solver::prox::tv1d`]).
///
/// ```
/// use std::sync::Arc;
/// use structid_core::{TvPenalty, NodeInterpolation, Interpolant};
/// struct Steps;
/// impl NodeInterpolation for Steps {
///     fn interpolant(&self, v: Vec<f64>) -> Box<dyn Interpolant> {
///         Box::new(move |z: &[f64]| v[(z[0].max(0.0) as usize).min(v.len() - 1)])
///     }
///     fn describe(&self) -> String { "steps".into() }
/// }
/// // Four samples on three nodes, a weighted chain.
/// let p = TvPenalty::new(vec![0, 1, 1, 2], 3, vec![(0, 1, 2.0), (1, 2, 1.0)], Arc::new(Steps)).unwrap();
/// assert!(p.is_chain());
/// assert_eq!(p.value(&[0.0, 1.0, 3.0]), 2.0 * 1.0 + 1.0 * 2.0);
/// ```
#[derive(Clone)]
pub struct TvPenalty {
    node_of_sample: Vec<usize>,
    nodes: usize,
    edges: Vec<(usize, usize, f64)>,
    chain: bool,
    counts: Vec<usize>,
    interpolation: Arc<dyn NodeInterpolation>,
}

impl fmt::Debug for TvPenalty {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("TvPenalty")
            .field("samples", &self.node_of_sample.len())
            .field("nodes", &self.nodes)
            .field("edges", &self.edges.len())
            .field("chain", &self.chain)
            .finish()
    }
}

fn tv_inconsistent(detail: String) -> Error {
    Error::InconsistentPenalty {
        penalty: "total-variation".into(),
        detail,
    }
}

impl TvPenalty {
    /// A penalty from the node of each sample, the number of nodes, the edges (a, b, c_ab) with
    /// a ≠ b and c_ab ≥ 0, and the interpolation rule. Every node must have a sample.
    ///
    /// # Errors
    /// [`Error::InconsistentPenalty`] when a sample's node is out of range, a node has no
    /// sample or an edge does not join two different nodes; [`Error::InvalidParameter`] for a
    /// negative or non-finite edge weight.
    pub fn new(
        node_of_sample: Vec<usize>,
        nodes: usize,
        edges: Vec<(usize, usize, f64)>,
        interpolation: Arc<dyn NodeInterpolation>,
    ) -> Result<Self> {
        let mut counts = vec![0usize; nodes];
        for (k, &g) in node_of_sample.iter().enumerate() {
            match counts.get_mut(g) {
                Some(c) => *c += 1,
                None => {
                    return Err(tv_inconsistent(format!(
                        "sample {k} belongs to node {g}, but there are only {nodes} nodes"
                    )));
                }
            }
        }
        if let Some(g) = counts.iter().position(|&c| c == 0) {
            return Err(tv_inconsistent(format!("node {g} has no sample")));
        }
        let mut edges = edges;
        for e in &mut edges {
            if e.0 >= nodes || e.1 >= nodes || e.0 == e.1 {
                return Err(tv_inconsistent(format!(
                    "edge ({}, {}) must join two different nodes below {nodes}",
                    e.0, e.1
                )));
            }
            if !(e.2.is_finite() && e.2 >= 0.0) {
                return Err(Error::InvalidParameter {
                    name: format!("weight of edge ({}, {})", e.0, e.1),
                    value: e.2,
                    reason: "edge weights must be finite and ≥ 0".into(),
                });
            }
            if e.0 > e.1 {
                *e = (e.1, e.0, e.2);
            }
        }
        edges.sort_by_key(|e| (e.0, e.1));
        let chain = edges.len() + 1 == nodes
            && edges
                .iter()
                .enumerate()
                .all(|(i, e)| e.0 == i && e.1 == i + 1);
        Ok(Self {
            node_of_sample,
            nodes,
            edges,
            chain,
            counts,
            interpolation,
        })
    }

    /// Number of samples L.
    pub fn len(&self) -> usize {
        self.node_of_sample.len()
    }

    /// Whether there are no samples.
    pub fn is_empty(&self) -> bool {
        self.node_of_sample.is_empty()
    }

    /// Number of nodes G.
    pub fn nodes(&self) -> usize {
        self.nodes
    }

    /// The node of each sample.
    pub fn node_of_sample(&self) -> &[usize] {
        &self.node_of_sample
    }

    /// Number of samples at each node.
    pub fn counts(&self) -> &[usize] {
        &self.counts
    }

    /// The edges (a, b, c_ab) with a < b, sorted.
    pub fn edges(&self) -> &[(usize, usize, f64)] {
        &self.edges
    }

    /// Whether the edges form the chain 0–1–…–(G−1).
    pub fn is_chain(&self) -> bool {
        self.chain
    }

    /// D = Σ c_ab·|v_a − v_b| for node values `v`.
    pub fn value(&self, v: &[f64]) -> f64 {
        self.edges
            .iter()
            .map(|&(a, b, c)| c * (v[a] - v[b]).abs())
            .sum()
    }

    /// The sample values w_k = v_node(k).
    pub fn sample_values(&self, v: &[f64]) -> Vec<f64> {
        self.node_of_sample.iter().map(|&g| v[g]).collect()
    }

    /// The interpolant through node values `v`.
    pub fn interpolant(&self, v: Vec<f64>) -> Box<dyn Interpolant> {
        self.interpolation.interpolant(v)
    }

    /// How the interpolant is built, for reports.
    pub fn describe_interpolation(&self) -> String {
        self.interpolation.describe()
    }
}
