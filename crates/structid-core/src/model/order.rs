//! The order in which the blocks of an LFT are evaluated when D_zw ≠ 0: maps in series.
//!
//! Within one sample, z_k = C_z·x_k + D_zu·u_k + D_ze·e_k + D_zw·w_k. When D_zw ≠ 0 a block's
//! input depends on other blocks' outputs of the same sample. Block i *depends on* block j when
//! some z channel that i reads has a non-zero D_zw entry in the column of the w channel that j
//! writes. If these dependencies form a directed acyclic graph, a topological order of it makes
//! D_zw strictly lower triangular (rows and columns permuted into that order): evaluating the
//! blocks in that order computes every z_k exactly, each from w's already computed. A cascade
//! such as an input dead zone feeding a sensor saturation through D_zw is of this kind.
//!
//! A cycle (a block reading, through D_zw, its own output of the same sample, directly or
//! through other blocks) is a true algebraic loop: z_k would solve a nonlinear equation. It is
//! refused with [`Error::AlgebraicLoop`], which names the blocks in the cycle.
//!
//! Entries of D_zw in rows that no block reads do not create a dependency: they change the
//! reported z but no map's input.

use crate::error::{Error, Result};
use crate::model::lft::Lft;

/// Where one block sits: the z channels it reads and the w channel it writes, with its name
/// for messages.
#[derive(Clone, Copy, Debug)]
pub struct BlockPlace<'a> {
    /// Name used in an error (a block's name, or a description such as `w[2]`).
    pub name: &'a str,
    /// z channels read.
    pub inputs: &'a [usize],
    /// w channel written.
    pub output: usize,
}

/// One dependency: the block read, and the (row, column, value) of a D_zw entry that makes it so.
type Dependency = (usize, (usize, usize, f64));

/// The blocks' dependencies through D_zw: `deps[i]` lists the blocks whose output block `i`
/// reads in the same sample, each with the (row, column, value) of one D_zw entry that makes it
/// so. Places must write distinct w channels within the LFT's range.
fn dependencies(lft: &Lft, places: &[BlockPlace<'_>]) -> Vec<Vec<Dependency>> {
    let dzw = &lft.matrices().dzw;
    let mut writer = vec![None; lft.dims().w];
    for (j, p) in places.iter().enumerate() {
        if p.output < writer.len() {
            writer[p.output] = Some(j);
        }
    }
    places
        .iter()
        .map(|p| {
            let mut deps: Vec<(usize, (usize, usize, f64))> = Vec::new();
            for &row in p.inputs {
                if row >= dzw.nrows() {
                    continue;
                }
                for (col, w) in writer.iter().enumerate() {
                    let v = dzw[(row, col)];
                    if let (true, Some(j)) = (v != 0.0, *w)
                        && !deps.iter().any(|(d, _)| *d == j)
                    {
                        deps.push((j, (row, col, v)));
                    }
                }
            }
            deps
        })
        .collect()
}

/// Follows dependencies from a block left over by the topological sort until a block repeats:
/// every block left over depends on another block left over, so the walk must close a cycle.
fn find_cycle(deps: &[Vec<Dependency>], left: &[bool]) -> Vec<(usize, (usize, usize, f64))> {
    let start = left.iter().position(|&l| l).expect("a block is left over");
    let mut path: Vec<(usize, (usize, usize, f64))> = Vec::new();
    let mut at = start;
    loop {
        let &(next, entry) = deps[at]
            .iter()
            .find(|(d, _)| left[*d])
            .expect("a block left over depends on another left over");
        if let Some(pos) = path.iter().position(|(b, _)| *b == at) {
            return path.split_off(pos);
        }
        path.push((at, entry));
        at = next;
    }
}

impl Lft {
    /// The order in which to evaluate the blocks at `places` within a sample (indices into
    /// `places`): every block after the blocks it reads through D_zw. With D_zw = 0 it is
    /// `0, 1, …` (the order given).
    ///
    /// # Errors
    /// [`Error::AlgebraicLoop`] when the blocks form a cycle through D_zw, naming them.
    ///
    /// ```
    /// use nalgebra::dmatrix;
    /// use structid_core::{BlockPlace, Lft, LftMatrices};
    /// // y = N₂(N₁(u)): z₁ = w₀, so the block writing w₀ comes first.
    /// let lft = Lft::new(LftMatrices {
    ///     a: dmatrix![0.0], bu: dmatrix![0.0], be: dmatrix![0.0], bw: dmatrix![0.0, 0.0],
    ///     cy: dmatrix![0.0], dyu: dmatrix![0.0], dye: dmatrix![1.0], dyw: dmatrix![0.0, 1.0],
    ///     cz: dmatrix![0.0; 0.0], dzu: dmatrix![1.0; 0.0], dze: dmatrix![0.0; 0.0],
    ///     dzw: dmatrix![0.0, 0.0; 1.0, 0.0],
    /// }).unwrap();
    /// let places = [
    ///     BlockPlace { name: "sensor", inputs: &[1], output: 1 },
    ///     BlockPlace { name: "actuator", inputs: &[0], output: 0 },
    /// ];
    /// assert_eq!(lft.evaluation_order(&places).unwrap(), vec![1, 0]);
    /// ```
    pub fn evaluation_order(&self, places: &[BlockPlace<'_>]) -> Result<Vec<usize>> {
        let deps = dependencies(self, places);
        let mut left = vec![true; places.len()];
        let mut order = Vec::with_capacity(places.len());
        // Repeated scans rather than Kahn's queue keep the given order among independent
        // blocks, so that D_zw = 0 leaves the model's order untouched; block counts are small.
        while order.len() < places.len() {
            let ready =
                (0..places.len()).find(|&i| left[i] && deps[i].iter().all(|(d, _)| !left[*d]));
            match ready {
                Some(i) => {
                    left[i] = false;
                    order.push(i);
                }
                None => {
                    let cycle = find_cycle(&deps, &left);
                    let (row, col, value) = cycle[0].1;
                    let mut names: Vec<String> = cycle
                        .iter()
                        .map(|(b, _)| places[*b].name.to_string())
                        .collect();
                    names.push(places[cycle[0].0].name.to_string());
                    return Err(Error::AlgebraicLoop {
                        row,
                        col,
                        value,
                        cycle: names,
                    });
                }
            }
        }
        Ok(order)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::lft::LftMatrices;
    use nalgebra::DMatrix;

    /// A static LFT with `nw` maps, each reading its own z channel, and the given D_zw.
    fn lft_with(dzw: DMatrix<f64>) -> Lft {
        let nw = dzw.ncols();
        Lft::new(LftMatrices {
            a: DMatrix::zeros(0, 0),
            bu: DMatrix::zeros(0, 1),
            be: DMatrix::zeros(0, 1),
            bw: DMatrix::zeros(0, nw),
            cy: DMatrix::zeros(1, 0),
            dyu: DMatrix::zeros(1, 1),
            dye: DMatrix::from_element(1, 1, 1.0),
            dyw: DMatrix::from_element(1, nw, 1.0),
            cz: DMatrix::zeros(nw, 0),
            dzu: DMatrix::from_element(nw, 1, 1.0),
            dze: DMatrix::zeros(nw, 1),
            dzw,
        })
        .unwrap()
    }

    const NAMES: [&str; 4] = ["a", "b", "c", "d"];

    fn places(n: usize) -> Vec<[usize; 1]> {
        (0..n).map(|i| [i]).collect()
    }

    fn order_of(dzw: DMatrix<f64>) -> Result<Vec<usize>> {
        let n = dzw.ncols();
        let inputs = places(n);
        let places: Vec<BlockPlace<'_>> = (0..n)
            .map(|i| BlockPlace {
                name: NAMES[i],
                inputs: &inputs[i],
                output: i,
            })
            .collect();
        lft_with(dzw).evaluation_order(&places)
    }

    #[test]
    fn no_coupling_keeps_the_given_order() {
        assert_eq!(order_of(DMatrix::zeros(3, 3)).unwrap(), vec![0, 1, 2]);
    }

    #[test]
    fn a_chain_is_ordered_so_that_every_block_follows_what_it_reads() {
        // d reads c, c reads a, b reads d.
        let mut dzw = DMatrix::zeros(4, 4);
        dzw[(3, 2)] = 1.0;
        dzw[(2, 0)] = -0.5;
        dzw[(1, 3)] = 2.0;
        let order = order_of(dzw.clone()).unwrap();
        let pos = |b: usize| order.iter().position(|&o| o == b).unwrap();
        for i in 0..4 {
            for j in 0..4 {
                if dzw[(i, j)] != 0.0 {
                    assert!(pos(j) < pos(i), "{order:?}");
                }
            }
        }
    }

    #[test]
    fn a_cycle_is_refused_naming_its_blocks_and_not_the_others() {
        // a → b → c → a, and d reads a (outside the cycle).
        let mut dzw = DMatrix::zeros(4, 4);
        dzw[(1, 0)] = 1.0;
        dzw[(2, 1)] = 1.0;
        dzw[(0, 2)] = 0.25;
        dzw[(3, 0)] = 1.0;
        let e = order_of(dzw).unwrap_err();
        let Error::AlgebraicLoop { cycle, value, .. } = &e else {
            panic!("{e}");
        };
        assert_eq!(cycle.len(), 4, "{cycle:?}");
        assert_eq!(cycle.first(), cycle.last());
        let mut inner: Vec<&str> = cycle[..3].iter().map(String::as_str).collect();
        inner.sort_unstable();
        assert_eq!(inner, ["a", "b", "c"]);
        assert!([1.0, 0.25].contains(value));
        let text = e.to_string();
        assert!(
            text.starts_with("algebraic loop: D_zw has a non-zero entry"),
            "{text}"
        );
        assert!(text.contains("`a`") && !text.contains("`d`"), "{text}");
    }

    #[test]
    fn a_block_reading_its_own_output_is_a_cycle_of_one() {
        let mut dzw = DMatrix::zeros(2, 2);
        dzw[(1, 1)] = 0.5;
        let e = order_of(dzw).unwrap_err();
        let Error::AlgebraicLoop {
            cycle, row, col, ..
        } = &e
        else {
            panic!("{e}");
        };
        assert_eq!(
            (cycle.as_slice(), *row, *col),
            (&["b".to_string(), "b".into()][..], 1, 1)
        );
    }
}
