//! Nearest-neighbour search and scattered-data interpolation.
//!
//! * [`KdTree`]: exact k-nearest-neighbour queries (Euclidean) over a fixed point set.
//! * [`knn_graph`]: the symmetric k-NN graph of a point set.
//! * [`ScatteredInterpolant`]: nearest-node or inverse-distance-weighted interpolation of node values.
//! * [`PiecewiseLinear`]: 1-D piecewise-linear interpolation through sorted knots.
//!
//! Points are passed as one flat slice in point-major order: with dimension `dim`, point `i` is
//! `points[i * dim..(i + 1) * dim]`. Preconditions are documented on each item and checked with
//! `debug_assert!` only; callers that take user input are expected to validate it first.

/// Points per leaf. Small enough that a leaf scan is cheap, large enough that the tree has few
/// nodes and the per-node pruning work does not dominate in low dimensions.
const LEAF_SIZE: usize = 16;

/// One node of the [`KdTree`]; children are indices into `KdTree::nodes`.
#[derive(Clone, Debug)]
enum Node {
    /// Points `start..end` of the tree-ordered point array.
    Leaf { start: usize, end: usize },
    /// Points with `p[axis] <= value` are under `left`, points with `p[axis] >= value` under
    /// `right` (points equal to `value` may be on either side).
    Split {
        axis: usize,
        value: f64,
        left: usize,
        right: usize,
    },
}

/// A k-d tree over a set of points, for exact Euclidean k-nearest-neighbour queries.
///
/// Built in O(N log N) by median splits on the coordinate of widest spread, with about 16 points
/// per leaf. The tree owns a copy of the points (stored in tree order, for cache locality) and
/// reports results in terms of the caller's original point indices.
///
/// # Example
/// ```
/// use structid_core::dispersion::neighbours::KdTree;
///
/// // Four points in 2-D, point-major.
/// let points = [0.0, 0.0, 1.0, 0.0, 0.0, 2.0, 5.0, 5.0];
/// let tree = KdTree::new(&points, 2);
/// assert_eq!(tree.len(), 4);
///
/// let mut out = Vec::new();
/// tree.nearest(&[0.9, 0.1], 2, None, &mut out);
/// assert_eq!(out[0].0, 1); // (1, 0) is nearest
/// assert_eq!(out[1].0, 0); // then (0, 0)
/// ```
#[derive(Clone, Debug)]
pub struct KdTree {
    dim: usize,
    /// Point coordinates in tree order (leaf ranges are contiguous).
    points: Vec<f64>,
    /// `order[pos]` is the original index of the point stored at tree position `pos`.
    order: Vec<usize>,
    /// `rank[i]` is the tree position of original point `i` (inverse of `order`).
    rank: Vec<usize>,
    /// Node 0 is the root.
    nodes: Vec<Node>,
}

impl KdTree {
    /// Builds a tree over `points` (point-major, `dim` coordinates per point).
    ///
    /// Preconditions (the caller checks them; they are only `debug_assert!`ed): `dim >= 1`,
    /// `points.len() % dim == 0`, and every coordinate is finite. An empty `points` gives an empty
    /// tree. In release builds `dim == 0` also gives an empty tree and a trailing partial point is
    /// ignored. Distances are computed directly, so coordinates beyond about ±1e154 (whose
    /// squared differences overflow) give infinite distances and meaningless neighbours.
    ///
    /// # Example
    /// ```
    /// use structid_core::dispersion::neighbours::KdTree;
    ///
    /// let tree = KdTree::new(&[1.0, 2.0, 3.0], 1);
    /// assert_eq!((tree.len(), tree.dim()), (3, 1));
    /// ```
    pub fn new(points: &[f64], dim: usize) -> Self {
        Self::with_leaf_size(points, dim, LEAF_SIZE)
    }

    /// As [`KdTree::new`] with a chosen leaf size; the tests use tiny leaves to exercise deep trees.
    fn with_leaf_size(points: &[f64], dim: usize, leaf_size: usize) -> Self {
        debug_assert!(dim >= 1, "KdTree: dim must be at least 1");
        debug_assert!(
            points.len().is_multiple_of(dim),
            "KdTree: points.len() must be a multiple of dim"
        );
        debug_assert!(
            points.iter().all(|x| x.is_finite()),
            "KdTree: coordinates must be finite"
        );
        let n = points.len().checked_div(dim).unwrap_or(0);
        let leaf_size = leaf_size.max(1);

        let mut builder = Builder {
            dim,
            leaf_size,
            nodes: Vec::with_capacity(2 * n.div_ceil(leaf_size) + 1),
            // Column-major copy: transposed once here, back once below.
            cols: (0..dim)
                .flat_map(|d| points[..n * dim].iter().skip(d).step_by(dim).copied())
                .collect(),
            order: (0..n).collect(),
            keys: Vec::with_capacity(n),
            scratch_coords: Vec::with_capacity(n),
            scratch_indices: Vec::with_capacity(n),
        };
        builder.build(0, n);
        let Builder {
            nodes, cols, order, ..
        } = builder;
        // The tree's own copy, point-major in tree order, so that a leaf scan reads one
        // contiguous block.
        let mut tree_points = vec![0.0; n * dim];
        for (d, col) in cols.chunks_exact(n.max(1)).enumerate() {
            for (p, &x) in col.iter().enumerate() {
                tree_points[p * dim + d] = x;
            }
        }
        let mut rank = vec![0; n];
        for (pos, &i) in order.iter().enumerate() {
            rank[i] = pos;
        }
        KdTree {
            dim,
            points: tree_points,
            order,
            rank,
            nodes,
        }
    }

    /// The number of points N.
    ///
    /// ```
    /// use structid_core::dispersion::neighbours::KdTree;
    /// assert_eq!(KdTree::new(&[0.0; 6], 2).len(), 3);
    /// ```
    pub fn len(&self) -> usize {
        self.order.len()
    }

    /// Whether the tree holds no points.
    ///
    /// ```
    /// use structid_core::dispersion::neighbours::KdTree;
    /// assert!(KdTree::new(&[], 3).is_empty());
    /// ```
    pub fn is_empty(&self) -> bool {
        self.order.is_empty()
    }

    /// The dimension of the points.
    ///
    /// ```
    /// use structid_core::dispersion::neighbours::KdTree;
    /// assert_eq!(KdTree::new(&[0.0; 6], 3).dim(), 3);
    /// ```
    pub fn dim(&self) -> usize {
        self.dim
    }

    /// The coordinates of point `i` (original index, as passed to [`KdTree::new`]).
    ///
    /// # Panics
    /// If `i >= self.len()`, like slice indexing.
    ///
    /// ```
    /// use structid_core::dispersion::neighbours::KdTree;
    /// let tree = KdTree::new(&[0.0, 1.0, 2.0, 3.0], 2);
    /// assert_eq!(tree.point(1), &[2.0, 3.0]);
    /// ```
    pub fn point(&self, i: usize) -> &[f64] {
        let pos = self.rank[i];
        &self.points[pos * self.dim..(pos + 1) * self.dim]
    }

    /// Finds the `k` points nearest to `q` (Euclidean distance), nearest first.
    ///
    /// `out` is cleared and filled with `(index, distance)` pairs, where `index` is the original
    /// point index. The point `exclude` (if any) is never returned, which is how a point's
    /// neighbours other than itself are found. `out` holds `min(k, M)` entries, where M is N, or
    /// N − 1 when `exclude` names a point of the tree; `k = 0` gives none.
    /// Among points at equal distance the choice and order are unspecified (but deterministic);
    /// duplicate points are ordinary points at distance 0.
    ///
    /// Precondition (`debug_assert!`ed): `q.len() == self.dim()` and `q` is finite. (In release
    /// builds a shorter `q` may panic on indexing.)
    ///
    /// The returned distances are bit-for-bit those of a direct computation
    /// `sqrt(Σ_d (q_d − p_d)²)` summed in coordinate order, and the search is exact: pruning
    /// never discards a point strictly nearer than the current k-th (see the comment in the
    /// implementation).
    ///
    /// ```
    /// use structid_core::dispersion::neighbours::KdTree;
    ///
    /// let points = [0.0, 1.0, 3.0, 7.0]; // 1-D
    /// let tree = KdTree::new(&points, 1);
    /// let mut out = Vec::new();
    ///
    /// tree.nearest(&[2.5], 3, None, &mut out);
    /// assert_eq!(out, vec![(2, 0.5), (1, 1.5), (0, 2.5)]);
    ///
    /// // The neighbours of point 1 other than itself; k > N gives all of them.
    /// tree.nearest(tree.point(1), 10, Some(1), &mut out);
    /// let idx: Vec<usize> = out.iter().map(|&(i, _)| i).collect();
    /// assert_eq!(idx, vec![0, 2, 3]);
    /// ```
    pub fn nearest(
        &self,
        q: &[f64],
        k: usize,
        exclude: Option<usize>,
        out: &mut Vec<(usize, f64)>,
    ) {
        let mut off = vec![0.0; self.dim];
        self.nearest_with(q, k, exclude, &mut off, out);
    }

    /// [`KdTree::nearest`] with a caller-provided scratch buffer, so that many queries (as in
    /// [`knn_graph`]) do not allocate each time.
    fn nearest_with(
        &self,
        q: &[f64],
        k: usize,
        exclude: Option<usize>,
        off: &mut Vec<f64>,
        out: &mut Vec<(usize, f64)>,
    ) {
        debug_assert_eq!(
            q.len(),
            self.dim,
            "KdTree::nearest: query has the wrong dimension"
        );
        debug_assert!(
            q.iter().all(|x| x.is_finite()),
            "KdTree::nearest: query must be finite"
        );
        out.clear();
        // Capping k avoids reserving memory for a huge k and lets the search stop pruning only
        // when it must.
        let k = k.min(self.len());
        if k == 0 {
            return;
        }
        out.reserve(k);
        off.clear();
        off.resize(self.dim, 0.0);
        let mut query = Query {
            q,
            k,
            exclude,
            off,
            best: out,
        };
        self.search(0, &mut query);
        // The search works with squared distances; convert once at the end.
        for e in out.iter_mut() {
            e.1 = e.1.sqrt();
        }
    }

    /// Depth-first branch-and-bound search below `node`. The recursion depth is the tree depth,
    /// about log2(N / LEAF_SIZE), because the splits are at medians.
    fn search(&self, node: usize, s: &mut Query<'_>) {
        match self.nodes[node] {
            Node::Leaf { start, end } => {
                let dim = self.dim;
                let mut worst = s.worst();
                let coords = self.points[start * dim..end * dim].chunks_exact(dim);
                for (&i, p) in self.order[start..end].iter().zip(coords) {
                    let d2 = squared_distance(s.q, p);
                    // The exclusion test is second because it is rarely reached: most points
                    // fail `d2 < worst`.
                    if d2 < worst && s.exclude != Some(i) {
                        s.insert(i, d2);
                        worst = s.worst();
                    }
                }
            }
            Node::Split {
                axis,
                value,
                left,
                right,
            } => {
                let diff = s.q[axis] - value;
                let (near, far) = if diff < 0.0 {
                    (left, right)
                } else {
                    (right, left)
                };
                self.search(near, s);

                // `off[d]` is the offset from q to the far cell's slab along axis d (0 when q is
                // inside it), so Σ off² is a lower bound on the squared distance to any point in
                // the far cell. It is recomputed from scratch rather than updated incrementally
                // (rd − old² + diff²) because the incremental update can round *above* the
                // computed distance of a point in the cell and prune it wrongly; the fresh sum
                // cannot: |fl(q_d − p_d)| ≥ |fl(q_d − value_d)| by monotone rounding, termwise and
                // then through the same left-to-right summation as `squared_distance`.
                let old = s.off[axis];
                s.off[axis] = diff;
                let bound = s.off.iter().fold(0.0, |acc, &o| acc + o * o);
                // Strict `<`: a cell that can at best tie the current k-th is skipped. This is
                // what keeps queries fast among many duplicate points (a tie at distance 0
                // would otherwise force a visit of every duplicate).
                if bound < s.worst() {
                    self.search(far, s);
                }
                s.off[axis] = old;
            }
        }
    }
}

/// Tree construction state; the scratch buffers are shared by all nodes (each node is done with
/// them before it recurses), so building allocates only up front.
struct Builder {
    dim: usize,
    leaf_size: usize,
    nodes: Vec<Node>,
    /// The coordinates, column-major and permuted into tree order as the build proceeds:
    /// coordinate d of tree position p is `cols[d * N + p]`.
    cols: Vec<f64>,
    /// `order[p]`: the original index of the point at tree position p.
    order: Vec<usize>,
    /// (coordinate on the split axis, position within the node's range).
    keys: Vec<(f64, usize)>,
    scratch_coords: Vec<f64>,
    scratch_indices: Vec<usize>,
}

impl Builder {
    /// Builds the subtree over tree positions `base..base + len`, permuting that range of
    /// `cols` and `order` into the subtree's order. Returns the subtree's root node index.
    ///
    /// The coordinates are moved physically and column by column, so that every pass (spread,
    /// split keys, permutation) reads contiguous memory of this node's range only. Measured in
    /// 2-D (noisy shared machine): N = 1e5 in ~17 ms and N = 1e6 in ~255 ms, against ~25 ms and
    /// 365–540 ms when the coordinates were read through an index array (cache misses at large
    /// N) and ~27 ms and 375–560 ms for a point-major in-place permutation.
    fn build(&mut self, base: usize, len: usize) -> usize {
        let id = self.nodes.len();
        if len <= self.leaf_size {
            self.nodes.push(Node::Leaf {
                start: base,
                end: base + len,
            });
            return id;
        }
        let total = self.order.len();
        let range = |d: usize| d * total + base..d * total + base + len;
        // Split on the coordinate of widest spread: it gives the most nearly cubical cells, which
        // is what makes the distance bound prune well.
        let mut axis = 0;
        let mut widest = f64::NEG_INFINITY;
        for d in 0..self.dim {
            let (lo, hi) = self.cols[range(d)]
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &x| {
                    (lo.min(x), hi.max(x))
                });
            if hi - lo > widest {
                widest = hi - lo;
                axis = d;
            }
        }
        // Split at the median by count even when the spread is zero (all points equal): a
        // balanced tree keeps the recursion shallow and, with strict pruning, keeps queries among
        // many duplicates cheap, whereas one huge leaf would make every query scan it.
        let mid = len / 2;
        self.keys.clear();
        self.keys
            .extend(self.cols[range(axis)].iter().copied().zip(0..len));
        self.keys
            .select_nth_unstable_by(mid, |a, b| a.0.total_cmp(&b.0));
        let value = self.keys[mid].0;
        // Apply the permutation to each column and to `order`.
        for d in 0..self.dim {
            let col = &mut self.cols[range(d)];
            self.scratch_coords.clear();
            self.scratch_coords
                .extend(self.keys.iter().map(|&(_, j)| col[j]));
            col.copy_from_slice(&self.scratch_coords);
        }
        let order = &mut self.order[base..base + len];
        self.scratch_indices.clear();
        self.scratch_indices
            .extend(self.keys.iter().map(|&(_, j)| order[j]));
        order.copy_from_slice(&self.scratch_indices);

        self.nodes.push(Node::Leaf { start: 0, end: 0 }); // placeholder, replaced below
        let left = self.build(base, mid);
        let right = self.build(base + mid, len - mid);
        self.nodes[id] = Node::Split {
            axis,
            value,
            left,
            right,
        };
        id
    }
}

/// Per-query state of [`KdTree::search`], bundled to keep the recursion's signature short.
struct Query<'a> {
    q: &'a [f64],
    /// Number wanted, already capped at N and at least 1.
    k: usize,
    exclude: Option<usize>,
    /// Per-axis offset from `q` to the current cell (see `KdTree::search`).
    off: &'a mut Vec<f64>,
    /// The best candidates so far as (original index, squared distance), ascending.
    best: &'a mut Vec<(usize, f64)>,
}

impl Query<'_> {
    /// The squared distance a candidate must beat: the current k-th, or infinity until k are found.
    fn worst(&self) -> f64 {
        if self.best.len() < self.k {
            f64::INFINITY
        } else {
            self.best.last().map_or(f64::INFINITY, |e| e.1)
        }
    }

    /// Inserts a candidate known to beat `worst()`, keeping `best` sorted and at most `k` long.
    /// A sorted vector beats a heap here: k is small and the k-th is read on every candidate.
    fn insert(&mut self, i: usize, d2: f64) {
        if self.best.len() == self.k {
            self.best.pop();
        }
        // Shift the larger entries up in an inline loop rather than `Vec::insert`: for these
        // short lists the call to memmove cost ~10% of `knn_graph` in a profile. `>` (not `>=`)
        // puts a tie after the entries already there.
        self.best.push((i, d2));
        let best = &mut **self.best;
        let mut at = best.len() - 1;
        while at > 0 && best[at - 1].1 > d2 {
            best[at] = best[at - 1];
            at -= 1;
        }
        best[at] = (i, d2);
    }
}

/// Σ_d (a_d − b_d)², summed in coordinate order (the tests rely on that order for bit equality).
fn squared_distance(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).fold(0.0, |acc, (x, y)| {
        let t = x - y;
        acc + t * t
    })
}

/// The symmetric k-nearest-neighbour graph of `points` (point-major, `dim` coordinates each).
///
/// There is an edge {i, j} when j is among the k nearest points of i, or i among those of j.
/// Each edge appears once as `(min, max)`; the list is sorted and has no self loops. Duplicate
/// points are allowed and are neighbours at distance 0. With `k >= N − 1` the graph is complete.
/// Among points tied at the k-th distance the choice is unspecified (but deterministic).
///
/// Preconditions (`debug_assert!`ed): `k >= 1` and those of [`KdTree::new`]. In release builds
/// `k == 0` gives no edges.
///
/// Cost: O(N log N) to build the tree, then one query per point, roughly O(N k log N) in low
/// dimensions.
///
/// ```
/// use structid_core::dispersion::neighbours::knn_graph;
///
/// // Points 0..=3 on a line at 0, 1, 3, 10. Their nearest neighbours are points 1, 0, 1
/// // and 2; symmetrised and deduplicated:
/// let edges = knn_graph(&[0.0, 1.0, 3.0, 10.0], 1, 1);
/// assert_eq!(edges, vec![(0, 1), (1, 2), (2, 3)]);
/// ```
pub fn knn_graph(points: &[f64], dim: usize, k: usize) -> Vec<(usize, usize)> {
    debug_assert!(k >= 1, "knn_graph: k must be at least 1");
    let tree = KdTree::new(points, dim);
    let n = tree.len();
    let per_point = k.min(n.saturating_sub(1));
    let mut edges = Vec::with_capacity(n * per_point);
    let mut off = Vec::with_capacity(dim);
    let mut found = Vec::with_capacity(per_point);
    // Query in tree order: consecutive queries are spatially close, so they touch the same
    // nodes and leaves and stay in cache.
    for pos in 0..n {
        let i = tree.order[pos];
        let q = &tree.points[pos * dim..(pos + 1) * dim];
        tree.nearest_with(q, per_point, Some(i), &mut off, &mut found);
        edges.extend(found.iter().map(|&(j, _)| (i.min(j), i.max(j))));
    }
    // The union is the sorted, deduplicated list (a mutual pair appears twice). Rather than one
    // O(Nk log Nk) sort (~20% of the time at N = 1e5, k = 8), bucket the pairs by their smaller
    // endpoint (a counting sort, O(N + Nk)) and sort each short bucket by the larger one.
    let mut start = vec![0usize; n + 1];
    for &(a, _) in &edges {
        start[a + 1] += 1;
    }
    for a in 0..n {
        start[a + 1] += start[a];
    }
    let mut fill = start.clone();
    let mut larger = vec![0usize; edges.len()];
    for &(a, b) in &edges {
        larger[fill[a]] = b;
        fill[a] += 1;
    }
    // Reuse the pair buffer for the output: it is never longer than the input.
    edges.clear();
    for a in 0..n {
        let bucket = &mut larger[start[a]..start[a + 1]];
        bucket.sort_unstable();
        let mut previous = None;
        for &b in bucket.iter() {
            if previous != Some(b) {
                edges.push((a, b));
                previous = Some(b);
            }
        }
    }
    edges
}

/// How a [`ScatteredInterpolant`] combines node values.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Weighting {
    /// The value of the nearest node (piecewise constant on Voronoi cells).
    Nearest,
    /// Shepard's inverse-distance weighting over the nearest nodes: Σ v_j d_j^−p / Σ d_j^−p.
    InverseDistance {
        /// How many nearest nodes take part (capped at the number of nodes; 0 acts as 1).
        neighbours: usize,
        /// The exponent p; must be finite and ≥ 0 (2 is the classical choice; 0 gives the
        /// plain mean of the neighbours).
        power: f64,
    },
}

/// Interpolation of values given at scattered nodes, by nearest node or inverse distance.
///
/// # Example
/// ```
/// use structid_core::dispersion::neighbours::{KdTree, ScatteredInterpolant, Weighting};
///
/// let nodes = KdTree::new(&[0.0, 0.0, 1.0, 0.0, 0.0, 1.0], 2);
/// let f = ScatteredInterpolant::new(
///     nodes,
///     vec![1.0, 2.0, 3.0],
///     Weighting::InverseDistance { neighbours: 3, power: 2.0 },
/// );
/// assert_eq!(f.eval(&[1.0, 0.0]), 2.0); // exact at a node
/// let v = f.eval(&[0.4, 0.3]);
/// assert!(1.0 < v && v < 3.0); // a weighted mean of the node values
/// ```
#[derive(Clone, Debug)]
pub struct ScatteredInterpolant {
    tree: KdTree,
    values: Vec<f64>,
    weighting: Weighting,
}

impl ScatteredInterpolant {
    /// An interpolant of `values[i]` at node `tree.point(i)`.
    ///
    /// Preconditions (`debug_assert!`ed): `values.len() == tree.len()`, the tree is not empty,
    /// and for [`Weighting::InverseDistance`] `power` is finite and ≥ 0.
    ///
    /// ```
    /// use structid_core::dispersion::neighbours::{KdTree, ScatteredInterpolant, Weighting};
    ///
    /// let f = ScatteredInterpolant::new(KdTree::new(&[0.0, 1.0], 1), vec![5.0, 7.0], Weighting::Nearest);
    /// assert_eq!(f.eval(&[0.8]), 7.0);
    /// ```
    pub fn new(tree: KdTree, values: Vec<f64>, weighting: Weighting) -> Self {
        debug_assert_eq!(
            values.len(),
            tree.len(),
            "ScatteredInterpolant: one value per node is required"
        );
        debug_assert!(
            !tree.is_empty(),
            "ScatteredInterpolant: at least one node is required"
        );
        if let Weighting::InverseDistance { power, .. } = weighting {
            debug_assert!(
                power.is_finite() && power >= 0.0,
                "ScatteredInterpolant: power must be finite and non-negative"
            );
        }
        ScatteredInterpolant {
            tree,
            values,
            weighting,
        }
    }

    /// The nodes.
    pub fn tree(&self) -> &KdTree {
        &self.tree
    }

    /// The value at each node, in the nodes' original order.
    pub fn values(&self) -> &[f64] {
        &self.values
    }

    /// How node values are combined.
    pub fn weighting(&self) -> Weighting {
        self.weighting
    }

    /// The interpolated value at `q` (`q.len()` = the tree's dimension).
    ///
    /// * [`Weighting::Nearest`]: the value of the nearest node (any one of them if tied).
    /// * [`Weighting::InverseDistance`]: Σ v_j d_j^−p / Σ d_j^−p over the `neighbours` nearest
    ///   nodes. When `q` coincides with a node (d = 0) the result is exactly that node's value
    ///   (the mean of the coincident nodes' values if several coincident nodes are among the
    ///   neighbours). The result always lies in [min, max] of the contributing values, and a
    ///   constant is reproduced exactly.
    ///
    /// Returns NaN if the interpolant has no nodes (a precondition violation).
    ///
    /// ```
    /// use structid_core::dispersion::neighbours::{KdTree, ScatteredInterpolant, Weighting};
    ///
    /// let w = Weighting::InverseDistance { neighbours: 2, power: 1.0 };
    /// let f = ScatteredInterpolant::new(KdTree::new(&[0.0, 4.0], 1), vec![0.0, 8.0], w);
    /// // Distances 1 and 3: weights 1 and 1/3, so (0 + 8/3) / (4/3) = 2.
    /// assert!((f.eval(&[1.0]) - 2.0).abs() < 1e-15);
    /// ```
    pub fn eval(&self, q: &[f64]) -> f64 {
        let mut found = Vec::new();
        match self.weighting {
            Weighting::Nearest => {
                self.tree.nearest(q, 1, None, &mut found);
                found.first().map_or(f64::NAN, |&(j, _)| self.values[j])
            }
            Weighting::InverseDistance { neighbours, power } => {
                self.tree.nearest(q, neighbours.max(1), None, &mut found);
                let Some(&(_, d0)) = found.first() else {
                    return f64::NAN;
                };
                // Weights are taken relative to the nearest distance, w_j = (d_0 / d_j)^p ∈ (0, 1]
                // with w_0 = 1: mathematically the same ratio, but d^−p itself overflows to inf
                // for tiny d (1e-200^−2) and gives inf/inf = NaN. At d_0 = 0 the limit is the
                // mean over the coincident nodes.
                let weight = |d: f64| {
                    if d0 == 0.0 {
                        if d == 0.0 { 1.0 } else { 0.0 }
                    } else {
                        (d0 / d).powf(power)
                    }
                };
                let (mut num, mut den) = (0.0, 0.0);
                let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
                for &(j, d) in &found {
                    let w = weight(d);
                    if w > 0.0 {
                        let v = self.values[j];
                        num += w * v;
                        den += w;
                        lo = lo.min(v);
                        hi = hi.max(v);
                    }
                }
                let r = num / den;
                // The exact result is a convex combination; rounding can push it a few ulps
                // outside [lo, hi] (so a constant would not be reproduced exactly). Clamp by
                // comparison rather than f64::clamp, which panics on NaN bounds.
                if r < lo {
                    lo
                } else if r > hi {
                    hi
                } else {
                    r
                }
            }
        }
    }
}

/// Piecewise-linear interpolation through knots `(x_i, v_i)` with strictly increasing `x_i`,
/// constant (the end value) outside `[x_0, x_last]`.
///
/// ```
/// use structid_core::dispersion::neighbours::PiecewiseLinear;
///
/// let f = PiecewiseLinear::new(vec![0.0, 1.0, 3.0], vec![0.0, 2.0, 0.0]);
/// assert_eq!(f.eval(0.5), 1.0);
/// assert_eq!(f.eval(2.0), 1.0);
/// assert_eq!(f.eval(-5.0), 0.0); // constant outside
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct PiecewiseLinear {
    knots: Vec<f64>,
    values: Vec<f64>,
}

impl PiecewiseLinear {
    /// The interpolant through `(knots[i], values[i])`.
    ///
    /// Preconditions (`debug_assert!`ed): `knots.len() == values.len() >= 1`, knots finite and
    /// strictly increasing.
    ///
    /// ```
    /// use structid_core::dispersion::neighbours::PiecewiseLinear;
    /// let f = PiecewiseLinear::new(vec![1.0], vec![4.0]); // a single knot: a constant
    /// assert_eq!(f.eval(-1.0), 4.0);
    /// ```
    pub fn new(knots: Vec<f64>, values: Vec<f64>) -> Self {
        debug_assert_eq!(
            knots.len(),
            values.len(),
            "PiecewiseLinear: one value per knot"
        );
        debug_assert!(
            !knots.is_empty(),
            "PiecewiseLinear: at least one knot is required"
        );
        debug_assert!(
            knots.iter().all(|x| x.is_finite()),
            "PiecewiseLinear: knots must be finite"
        );
        debug_assert!(
            knots.windows(2).all(|w| w[0] < w[1]),
            "PiecewiseLinear: knots must be strictly increasing"
        );
        PiecewiseLinear { knots, values }
    }

    /// The value at `x`, located by binary search (O(log n)).
    ///
    /// Exactly `values[i]` at `knots[i]`; NaN for NaN `x` (or if there are no knots, a
    /// precondition violation).
    ///
    /// ```
    /// use structid_core::dispersion::neighbours::PiecewiseLinear;
    /// let f = PiecewiseLinear::new(vec![0.0, 2.0], vec![1.0, 5.0]);
    /// assert_eq!(f.eval(0.5), 2.0);
    /// assert_eq!(f.eval(9.0), 5.0);
    /// ```
    pub fn eval(&self, x: f64) -> f64 {
        let (knots, values) = (&self.knots, &self.values);
        let n = knots.len();
        if n == 0 || x.is_nan() {
            return f64::NAN;
        }
        if x <= knots[0] {
            return values[0];
        }
        if x >= knots[n - 1] {
            return values[n - 1];
        }
        // Here knots[0] < x < knots[n-1] (so n >= 2) and, for sorted knots, the partition point
        // is in 1..n. The saturation and clamp only matter for unsorted knots, where they keep
        // the indexing in bounds instead of panicking.
        let i = knots
            .partition_point(|&k| k <= x)
            .saturating_sub(1)
            .min(n - 2);
        let (x0, x1) = (knots[i], knots[i + 1]);
        let (v0, v1) = (values[i], values[i + 1]);
        // v0 + t (v1 − v0) rather than (1 − t) v0 + t v1: exact at the left knot (t = 0).
        v0 + (x - x0) / (x1 - x0) * (v1 - v0)
    }

    /// The knots, strictly increasing.
    ///
    /// ```
    /// use structid_core::dispersion::neighbours::PiecewiseLinear;
    /// let f = PiecewiseLinear::new(vec![0.0, 1.0], vec![3.0, 4.0]);
    /// assert_eq!(f.knots(), &[0.0, 1.0]);
    /// ```
    pub fn knots(&self) -> &[f64] {
        &self.knots
    }

    /// The values at the knots.
    ///
    /// ```
    /// use structid_core::dispersion::neighbours::PiecewiseLinear;
    /// let f = PiecewiseLinear::new(vec![0.0, 1.0], vec![3.0, 4.0]);
    /// assert_eq!(f.values(), &[3.0, 4.0]);
    /// ```
    pub fn values(&self) -> &[f64] {
        &self.values
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use structid_lti::testing::SplitMix64;

    /// `n` points of `dim` coordinates, each uniform in [−1, 1).
    fn points(rng: &mut SplitMix64, n: usize, dim: usize) -> Vec<f64> {
        (0..n * dim).map(|_| rng.uniform_in(-1.0, 1.0)).collect()
    }

    /// Brute-force distances from q to every point, as (index, distance) sorted by distance.
    fn brute(points: &[f64], dim: usize, q: &[f64], exclude: Option<usize>) -> Vec<(usize, f64)> {
        let mut all: Vec<(usize, f64)> = points
            .chunks_exact(dim)
            .enumerate()
            .filter(|&(i, _)| Some(i) != exclude)
            .map(|(i, p)| {
                let d2: f64 = q.iter().zip(p).map(|(a, b)| (a - b) * (a - b)).sum();
                (i, d2.sqrt())
            })
            .collect();
        all.sort_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)));
        all
    }

    /// Checks a k-NN answer against brute force, allowing any choice among ties at the k-th
    /// distance.
    fn check_knn(
        points: &[f64],
        dim: usize,
        q: &[f64],
        k: usize,
        exclude: Option<usize>,
        got: &[(usize, f64)],
    ) -> Result<(), TestCaseError> {
        let all = brute(points, dim, q, exclude);
        let want = k.min(all.len());
        prop_assert_eq!(got.len(), want);
        let true_dist: std::collections::HashMap<usize, f64> = all.iter().copied().collect();
        let mut seen = std::collections::HashSet::new();
        for (r, &(i, d)) in got.iter().enumerate() {
            prop_assert!(seen.insert(i), "index {} returned twice", i);
            prop_assert!(Some(i) != exclude, "excluded index returned");
            let td = *true_dist
                .get(&i)
                .ok_or_else(|| TestCaseError::fail("bad index"))?;
            prop_assert!(
                (d - td).abs() <= 1e-12,
                "distance of {}: {} vs {}",
                i,
                d,
                td
            );
            // The r-th distance equals the brute-force r-th: together with distinct indices and
            // true distances, this is "the same set up to ties", in the right order.
            prop_assert!(
                (d - all[r].1).abs() <= 1e-12,
                "rank {}: {} vs {}",
                r,
                d,
                all[r].1
            );
        }
        // And explicitly: everything strictly nearer than the last returned is returned.
        if let Some(&(_, last)) = got.last() {
            for &(i, d) in &all {
                if d < last {
                    prop_assert!(seen.contains(&i), "missed {} at {} < {}", i, d, last);
                }
            }
        }
        Ok(())
    }

    /// Brute-force symmetric k-NN graph check that tolerates ties: every edge must be justified by
    /// one endpoint's k-th distance, every strictly-closer pair must be an edge, and each point
    /// must have at least min(k, N − 1) neighbours.
    fn check_graph(
        points: &[f64],
        dim: usize,
        k: usize,
        edges: &[(usize, usize)],
    ) -> Result<(), TestCaseError> {
        let n = points.len() / dim;
        prop_assert!(
            edges.windows(2).all(|w| w[0] < w[1]),
            "not sorted and unique"
        );
        prop_assert!(
            edges.iter().all(|&(i, j)| i < j && j < n),
            "self loop or bad index"
        );
        let per = k.min(n.saturating_sub(1));
        let kth: Vec<f64> = (0..n)
            .map(|i| {
                let all = brute(points, dim, &points[i * dim..(i + 1) * dim], Some(i));
                if per == 0 {
                    f64::NEG_INFINITY
                } else {
                    all[per - 1].1
                }
            })
            .collect();
        let set: std::collections::HashSet<(usize, usize)> = edges.iter().copied().collect();
        let mut degree = vec![0usize; n];
        for &(i, j) in edges {
            degree[i] += 1;
            degree[j] += 1;
            let d = brute(points, dim, &points[i * dim..(i + 1) * dim], None)
                .iter()
                .find(|e| e.0 == j)
                .map_or(f64::NAN, |e| e.1);
            prop_assert!(
                d <= kth[i] || d <= kth[j],
                "edge ({}, {}) not a k-NN edge",
                i,
                j
            );
        }
        for i in 0..n {
            prop_assert!(
                degree[i] >= per,
                "point {} has degree {} < {}",
                i,
                degree[i],
                per
            );
            for &(j, d) in &brute(points, dim, &points[i * dim..(i + 1) * dim], Some(i)) {
                if d < kth[i] {
                    prop_assert!(
                        set.contains(&(i.min(j), i.max(j))),
                        "missing edge ({}, {})",
                        i,
                        j
                    );
                }
            }
        }
        Ok(())
    }

    /// (dim, points): 1..=4 dims, 0..=120 points, either continuous coordinates or a coarse
    /// integer grid that produces many duplicate points and exact distance ties.
    fn cloud() -> impl Strategy<Value = (usize, Vec<f64>)> {
        (1usize..=4, 0usize..=120, any::<bool>()).prop_flat_map(|(dim, n, grid)| {
            let coord = if grid {
                (-3i32..=3).prop_map(f64::from).boxed()
            } else {
                (-100.0f64..100.0).boxed()
            };
            (Just(dim), proptest::collection::vec(coord, n * dim))
        })
    }

    proptest! {
        #[test]
        fn kdtree_matches_brute_force(
            (dim, points) in cloud(),
            leaf in prop_oneof![Just(LEAF_SIZE), 1usize..=4],
            k in prop_oneof![0usize..=20, 0usize..=200],
            at_point in any::<bool>(),
            pick in any::<prop::sample::Index>(),
            qr in proptest::collection::vec(-110.0f64..110.0, 4),
            exclude in proptest::option::of(any::<prop::sample::Index>()),
        ) {
            let n = points.len() / dim;
            let tree = KdTree::with_leaf_size(&points, dim, leaf);
            prop_assert_eq!(tree.len(), n);
            // Query either at a data point (exact ties, d = 0) or anywhere.
            let q: Vec<f64> = if at_point && n > 0 {
                tree.point(pick.index(n)).to_vec()
            } else {
                qr[..dim].to_vec()
            };
            let exclude = exclude.map(|e| e.index(n + 2)); // sometimes out of range
            let mut out = vec![(7, 7.0)]; // must be cleared
            tree.nearest(&q, k, exclude, &mut out);
            check_knn(&points, dim, &q, k, exclude, &out)?;
        }

        #[test]
        fn knn_graph_union_semantics((dim, points) in cloud(), k in 1usize..=10) {
            let edges = knn_graph(&points, dim, k);
            check_graph(&points, dim, k, &edges)?;
        }

        #[test]
        fn idw_within_neighbour_range(
            (dim, points) in cloud(),
            values in proptest::collection::vec(-50.0f64..50.0, 120),
            neighbours in 0usize..=8,
            power in 0.0f64..6.0,
            qr in proptest::collection::vec(-110.0f64..110.0, 4),
        ) {
            let n = points.len() / dim;
            prop_assume!(n > 0);
            let tree = KdTree::new(&points, dim);
            let q = &qr[..dim];
            let mut near = Vec::new();
            tree.nearest(q, neighbours.max(1), None, &mut near);
            let f = ScatteredInterpolant::new(tree, values[..n].to_vec(),
                Weighting::InverseDistance { neighbours, power });
            let v = f.eval(q);
            let lo = near.iter().map(|&(j, _)| values[j]).fold(f64::INFINITY, f64::min);
            let hi = near.iter().map(|&(j, _)| values[j]).fold(f64::NEG_INFINITY, f64::max);
            prop_assert!(lo <= v && v <= hi, "{} not in [{}, {}]", v, lo, hi);
        }

        #[test]
        fn nearest_weighting_matches_brute_force(
            (dim, points) in cloud(),
            qr in proptest::collection::vec(-110.0f64..110.0, 4),
        ) {
            let n = points.len() / dim;
            prop_assume!(n > 0);
            // Distinct values per node so the returned value identifies the node.
            let values: Vec<f64> = (0..n).map(|i| i as f64).collect();
            let f = ScatteredInterpolant::new(KdTree::new(&points, dim), values, Weighting::Nearest);
            let q = &qr[..dim];
            let v = f.eval(q);
            let all = brute(&points, dim, q, None);
            let j = v as usize;
            prop_assert_eq!(j as f64, v);
            let dj = all.iter().find(|e| e.0 == j).map(|e| e.1);
            prop_assert_eq!(dj, Some(all[0].1), "node {} is not a nearest node", j);
        }

        #[test]
        fn piecewise_linear_exact_for_linear_data(
            mut knots in proptest::collection::vec(-1e3f64..1e3, 1..30),
            a in -10.0f64..10.0,
            b in -10.0f64..10.0,
            x in -2e3f64..2e3,
        ) {
            knots.sort_by(f64::total_cmp);
            knots.dedup();
            let values: Vec<f64> = knots.iter().map(|&t| a + b * t).collect();
            let f = PiecewiseLinear::new(knots.clone(), values.clone());
            let (x0, x1) = (knots[0], knots[knots.len() - 1]);
            let want = a + b * x.clamp(x0, x1);
            let scale = 1.0 + a.abs() + b.abs() * 2e3;
            prop_assert!((f.eval(x) - want).abs() <= 1e-12 * scale, "{} vs {}", f.eval(x), want);
            for (&t, &v) in knots.iter().zip(&values) {
                prop_assert_eq!(f.eval(t), v);
            }
        }
    }

    #[test]
    fn nearest_edge_cases() {
        let mut out = vec![(9, 9.0)];
        // Empty tree.
        let empty = KdTree::new(&[], 2);
        assert!(empty.is_empty());
        empty.nearest(&[0.0, 0.0], 3, None, &mut out);
        assert!(out.is_empty());

        let tree = KdTree::new(&[0.0, 1.0, 2.0], 1);
        // k = 0.
        tree.nearest(&[0.5], 0, None, &mut out);
        assert!(out.is_empty());
        // Huge k is capped at N (and must not try to reserve k entries).
        tree.nearest(&[0.4], usize::MAX, None, &mut out);
        assert_eq!(out.len(), 3);
        assert_eq!(out[0].0, 0);
        // Excluding the only point.
        let one = KdTree::new(&[1.0, 1.0], 2);
        one.nearest(&[1.0, 1.0], 5, Some(0), &mut out);
        assert!(out.is_empty());
        one.nearest(&[1.0, 1.0], 5, Some(3), &mut out);
        assert_eq!(out, vec![(0, 0.0)]);
    }

    #[test]
    fn point_round_trips_original_indices() {
        let mut rng = SplitMix64::new(1);
        for dim in 1..=4 {
            let pts = points(&mut rng, 500, dim);
            let tree = KdTree::new(&pts, dim);
            assert_eq!(tree.dim(), dim);
            for i in 0..500 {
                assert_eq!(tree.point(i), &pts[i * dim..(i + 1) * dim]);
            }
        }
    }

    #[test]
    fn kdtree_fixed_seed_large_matches_brute_force() {
        // Larger than the proptest clouds, so the tree is several levels deep with 16-leaves.
        let mut rng = SplitMix64::new(2);
        for dim in 1..=4 {
            let pts = points(&mut rng, 3000, dim);
            let tree = KdTree::new(&pts, dim);
            let mut out = Vec::new();
            for _ in 0..50 {
                let q: Vec<f64> = (0..dim).map(|_| rng.uniform_in(-1.2, 1.2)).collect();
                for k in [1, 8, 40] {
                    tree.nearest(&q, k, None, &mut out);
                    check_knn(&pts, dim, &q, k, None, &out).unwrap();
                }
            }
        }
    }

    #[test]
    fn all_identical_points() {
        // Many duplicates: every answer is at distance 0, and the tree must stay balanced
        // (otherwise this would be quadratic).
        let pts = vec![0.5; 2 * 5000];
        let tree = KdTree::new(&pts, 2);
        let mut out = Vec::new();
        tree.nearest(&[0.5, 0.5], 8, Some(3), &mut out);
        assert_eq!(out.len(), 8);
        assert!(out.iter().all(|&(i, d)| d == 0.0 && i != 3));
        let edges = knn_graph(&pts, 2, 4);
        assert!(edges.windows(2).all(|w| w[0] < w[1]));
        assert!(edges.iter().all(|&(i, j)| i < j));
        let mut degree = vec![0; 5000];
        for &(i, j) in &edges {
            degree[i] += 1;
            degree[j] += 1;
        }
        assert!(degree.iter().all(|&d| d >= 4));
    }

    #[test]
    fn knn_graph_matches_brute_force_exactly() {
        // Continuous random points: no ties, so the graph is unique and can be compared exactly.
        let mut rng = SplitMix64::new(3);
        for dim in 1..=3 {
            let n = 400;
            let pts = points(&mut rng, n, dim);
            for k in [1, 3, 8] {
                let mut want = Vec::new();
                for i in 0..n {
                    let all = brute(&pts, dim, &pts[i * dim..(i + 1) * dim], Some(i));
                    for &(j, _) in &all[..k] {
                        want.push((i.min(j), i.max(j)));
                    }
                }
                want.sort_unstable();
                want.dedup();
                assert_eq!(knn_graph(&pts, dim, k), want, "dim {dim}, k {k}");
            }
        }
    }

    #[test]
    fn knn_graph_small_cases() {
        assert!(knn_graph(&[], 2, 3).is_empty());
        assert!(knn_graph(&[1.0, 2.0], 2, 3).is_empty()); // one point
        assert_eq!(knn_graph(&[0.0, 5.0], 1, 1), vec![(0, 1)]);
        // k ≥ N − 1: complete graph.
        let complete: Vec<(usize, usize)> = (0..5)
            .flat_map(|i| (i + 1..5).map(move |j| (i, j)))
            .collect();
        assert_eq!(knn_graph(&[0.0, 1.0, 3.0, 7.0, 15.0], 1, 4), complete);
        assert_eq!(knn_graph(&[0.0, 1.0, 3.0, 7.0, 15.0], 1, 100), complete);
        // Duplicates are neighbours at distance 0; point 1's nearest is either copy (a tie).
        let e = knn_graph(&[0.0, 10.0, 0.0], 1, 1);
        assert!(
            e == vec![(0, 1), (0, 2)] || e == vec![(0, 2), (1, 2)],
            "{e:?}"
        );
    }

    #[test]
    fn interpolants_reproduce_node_values() {
        let mut rng = SplitMix64::new(4);
        for dim in 1..=3 {
            let pts = points(&mut rng, 300, dim);
            let values: Vec<f64> = (0..300).map(|_| rng.uniform_in(-5.0, 5.0)).collect();
            for w in [
                Weighting::Nearest,
                Weighting::InverseDistance {
                    neighbours: 1,
                    power: 2.0,
                },
                Weighting::InverseDistance {
                    neighbours: 8,
                    power: 2.0,
                },
                Weighting::InverseDistance {
                    neighbours: 300,
                    power: 0.5,
                },
            ] {
                let f = ScatteredInterpolant::new(KdTree::new(&pts, dim), values.clone(), w);
                for i in 0..300 {
                    assert_eq!(f.eval(&pts[i * dim..(i + 1) * dim]), values[i], "{w:?}");
                }
            }
        }
    }

    #[test]
    fn constant_stays_constant() {
        let mut rng = SplitMix64::new(5);
        let pts = points(&mut rng, 200, 2);
        // 0.1 is not exactly representable, so Σ w v / Σ w would drift by ulps without the clamp.
        for c in [0.1, -3.7, 1e300] {
            for w in [
                Weighting::Nearest,
                Weighting::InverseDistance {
                    neighbours: 6,
                    power: 2.0,
                },
                Weighting::InverseDistance {
                    neighbours: 200,
                    power: 1.3,
                },
            ] {
                let f = ScatteredInterpolant::new(KdTree::new(&pts, 2), vec![c; 200], w);
                for _ in 0..200 {
                    let q = [rng.uniform_in(-2.0, 2.0), rng.uniform_in(-2.0, 2.0)];
                    assert_eq!(f.eval(&q), c, "{w:?}");
                }
            }
        }
    }

    #[test]
    fn idw_values() {
        let tree = KdTree::new(&[0.0, 0.0, 2.0, 0.0], 2);
        // Power 0: the plain mean of the neighbours.
        let f = ScatteredInterpolant::new(
            tree.clone(),
            vec![1.0, 3.0],
            Weighting::InverseDistance {
                neighbours: 2,
                power: 0.0,
            },
        );
        assert_eq!(f.eval(&[0.1, 7.0]), 2.0);
        // Tiny distances: d^-2 would overflow to inf and give NaN; the relative weights do not.
        let f = ScatteredInterpolant::new(
            tree.clone(),
            vec![1.0, 3.0],
            Weighting::InverseDistance {
                neighbours: 2,
                power: 2.0,
            },
        );
        let v = f.eval(&[1e-200, 0.0]);
        assert_eq!(v, 1.0);
        // Midpoint: equal weights.
        assert_eq!(f.eval(&[1.0, 0.0]), 2.0);
        // Coincident duplicate nodes with different values: their mean.
        let dup = KdTree::new(&[0.0, 0.0, 0.0], 1);
        let f = ScatteredInterpolant::new(
            dup,
            vec![1.0, 2.0, 6.0],
            Weighting::InverseDistance {
                neighbours: 3,
                power: 2.0,
            },
        );
        assert_eq!(f.eval(&[0.0]), 3.0);
    }

    #[test]
    fn piecewise_linear_basics() {
        let f = PiecewiseLinear::new(vec![-1.0, 0.0, 2.0, 2.5], vec![4.0, 0.0, 1.0, -1.0]);
        // Reproduces knots.
        for (&x, &v) in f.knots().iter().zip(f.values()) {
            assert_eq!(f.eval(x), v);
        }
        // Linear between: midpoints and a non-midpoint.
        assert_eq!(f.eval(-0.5), 2.0);
        assert_eq!(f.eval(1.0), 0.5);
        assert_eq!(f.eval(2.25), 0.0);
        assert!((f.eval(0.5) - 0.25).abs() < 1e-15);
        // Constant outside.
        assert_eq!(f.eval(-1e300), 4.0);
        assert_eq!(f.eval(f64::NEG_INFINITY), 4.0);
        assert_eq!(f.eval(3.0), -1.0);
        assert_eq!(f.eval(f64::INFINITY), -1.0);
        assert!(f.eval(f64::NAN).is_nan());
        // Single knot: a constant.
        let g = PiecewiseLinear::new(vec![0.0], vec![2.5]);
        assert_eq!((g.eval(-1.0), g.eval(0.0), g.eval(1.0)), (2.5, 2.5, 2.5));
    }
}
